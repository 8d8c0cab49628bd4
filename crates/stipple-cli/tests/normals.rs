//! `stipple normals`, `--normal-out` and the automatic choice of splats, through the binary.

mod common;
use common::{stipple, tempdir, text};

/// A sparse sphere of radius 1 without normals, written as XYZ text.
fn sparse_sphere(dir: &std::path::Path, n: usize) -> std::path::PathBuf {
    let mut s = String::new();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for k in 0..n {
        let y = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
        let r = (1.0 - y * y).sqrt();
        let t = golden * k as f64;
        s.push_str(&format!("{} {} {}\n", r * t.cos(), y, r * t.sin()));
    }
    let p = dir.join("sphere.xyz");
    std::fs::write(&p, s).unwrap();
    p
}

#[test]
fn normals_command_writes_oriented_normals_and_radii() {
    let dir = tempdir("normals");
    let input = sparse_sphere(&dir, 3000);
    let before = std::fs::read(&input).unwrap();
    let o = stipple(&dir, &["normals", "sphere.xyz", "-o", "out.ply"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("estimated normals for 3000 points"),
        "{}",
        text(&o)
    );
    // The input is untouched; the output carries nx ny nz radius, outward.
    assert_eq!(std::fs::read(&input).unwrap(), before);
    let c = stipple_io::read_cloud(&dir.join("out.ply")).unwrap();
    let n = c.normals.as_ref().expect("normals written");
    let r = c.radius.as_ref().expect("radii written");
    for i in 0..c.len() {
        let p = c.world(i).as_vec3().normalize();
        assert!(n[i].dot(p) > 0.99, "point {i}: normal {:?}", n[i]);
        assert!(r[i] > 0.0 && r[i] < 0.2);
    }
    // Refuses to overwrite an existing output or the input; bad k is an error, not a panic.
    for bad in [
        vec!["normals", "sphere.xyz", "-o", "out.ply"],
        vec!["normals", "out.ply", "-o", "out.ply", "--force"],
        vec!["normals", "sphere.xyz", "-o", "x.ply", "--k", "1"],
        vec!["normals", "sphere.xyz", "-o", "x.xyz"],
        vec!["normals", "missing.ply", "-o", "x.ply"],
    ] {
        let o = stipple(&dir, &bad);
        assert!(!o.status.success(), "{bad:?} accepted");
        assert!(!text(&o).contains("panicked"), "{}", text(&o));
    }
    // Two points: a clear error naming the file.
    std::fs::write(dir.join("two.xyz"), "0 0 0\n1 0 0\n").unwrap();
    let o = stipple(&dir, &["normals", "two.xyz", "-o", "two.ply"]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("two.xyz") && text(&o).contains("at least 3 points"),
        "{}",
        text(&o)
    );
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn sparse_clouds_default_to_splats_and_write_normals() {
    let dir = tempdir("splat-default");
    sparse_sphere(&dir, 4000);
    let o = stipple(
        &dir,
        &[
            "render",
            "sphere.xyz",
            "--size",
            "256x256",
            "--backend",
            "cpu",
            "--stats",
            "--normal-out",
            "n.npy",
            "--depth-out",
            "d.npy",
            "-o",
            "s.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("estimated normals") && t.contains("drawing splats"),
        "{t}"
    );
    let (dims, n) = stipple_io::image::read_npy_shaped(&dir.join("n.npy")).unwrap();
    assert_eq!(dims, vec![256, 256, 3]);
    let (_, _, d) = stipple_io::image::read_npy(&dir.join("d.npy")).unwrap();
    let mut fg = 0;
    for k in 0..256 * 256 {
        let v = [n[3 * k], n[3 * k + 1], n[3 * k + 2]];
        if d[k].is_finite() {
            fg += 1;
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-3, "pixel {k}: {v:?}");
        } else {
            assert!(v.iter().all(|x| x.is_nan()), "background pixel {k}: {v:?}");
        }
    }
    // The sphere fills a disc: no holes in the middle.
    let mid = 128 * 256 + 128;
    assert!(d[mid].is_finite() && fg > 5000, "{fg} px");
    // Dense enough clouds keep Dobrev's pipeline.
    let o = stipple(
        &dir,
        &[
            "render",
            "sphere.xyz",
            "--size",
            "32x32",
            "--backend",
            "cpu",
            "--stats",
            "-o",
            "t.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("fill_background"), "{}", text(&o));
    std::fs::remove_dir_all(dir).ok();
}
