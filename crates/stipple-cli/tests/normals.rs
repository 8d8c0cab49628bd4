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

/// `--splat deferred` (Zhang & Pajarola's single pass) renders what `--splat blend` does
/// closely, bad `--splat-c` is a clear error, and `bench --zhang` prints its table.
#[test]
fn deferred_blending_and_the_zhang_table() {
    let dir = tempdir("splat-deferred");
    sparse_sphere(&dir, 4000);
    let render = |mode: &str, out: &str, extra: &[&str]| {
        let mut a = vec![
            "render",
            "sphere.xyz",
            "--size",
            "128x128",
            "--backend",
            "cpu",
            "--pipeline",
            "splat",
            "--splat",
            mode,
            "--depth-out",
            out,
            "-o",
        ];
        let png = format!("{out}.png");
        a.push(&png);
        a.extend_from_slice(extra);
        let o = stipple(&dir, &a);
        assert!(o.status.success(), "{}", text(&o));
        stipple_io::image::read_npy(&dir.join(out)).unwrap().2
    };
    let blend = render("blend", "b.npy", &[]);
    let deferred = render("deferred", "d.npy", &["--splat-c", "1"]);
    let (mut both, mut close) = (0, 0);
    for (x, y) in blend.iter().zip(&deferred) {
        assert_eq!(x.is_finite(), y.is_finite(), "same silhouette");
        if x.is_finite() {
            both += 1;
            close += ((x - y).abs() <= 1e-3 * x) as usize;
        }
    }
    assert!(
        both > 3000 && close as f64 >= 0.97 * both as f64,
        "{close} of {both}"
    );
    for bad in ["0", "1.5", "nan"] {
        let o = stipple(
            &dir,
            &[
                "render",
                "sphere.xyz",
                "--splat",
                "deferred",
                "--splat-c",
                bad,
                "-o",
                "x.png",
            ],
        );
        assert!(!o.status.success(), "--splat-c {bad} accepted");
        assert!(text(&o).contains("--splat-c"), "{}", text(&o));
    }
    let o = stipple(
        &dir,
        &[
            "bench",
            "sphere.xyz",
            "--zhang",
            "--frames",
            "1",
            "--warmup",
            "0",
            "--table-sizes",
            "64",
            "--backend",
            "cpu",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    for row in [
        "Zhang & Pajarola Table 2",
        "deferred, c = 0.4",
        "22.62",
        "groups c = 0.8: K = ",
    ] {
        assert!(t.contains(row), "missing {row:?}: {t}");
    }
    std::fs::remove_dir_all(dir).ok();
}

/// `render --save-normals` writes the estimated normals and radii beside, never over, the
/// input; the saved file renders without estimation.
#[test]
fn render_saves_estimated_normals_on_request() {
    let dir = tempdir("save-normals");
    let input = sparse_sphere(&dir, 3000);
    let before = std::fs::read(&input).unwrap();
    let args = |out: &str| {
        vec![
            "render".to_string(),
            "sphere.xyz".into(),
            "--size".into(),
            "64x64".into(),
            "--backend".into(),
            "cpu".into(),
            "--save-normals".into(),
            out.into(),
            "-o".into(),
            "s.png".into(),
        ]
    };
    let run = |a: Vec<String>| {
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        stipple(&dir, &a)
    };
    let o = run(args("saved.ply"));
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        std::fs::read(&input).unwrap(),
        before,
        "the input is untouched"
    );
    let c = stipple_io::read_cloud(&dir.join("saved.ply")).unwrap();
    assert_eq!(c.len(), 3000);
    let n = c.normals.as_ref().expect("normals saved");
    assert!(c.radius.is_some(), "radii saved");
    for i in 0..c.len() {
        assert!(
            n[i].dot(c.world(i).as_vec3().normalize()) > 0.99,
            "point {i}"
        );
    }
    // Not over an existing file, not over the input, only .ply.
    for out in ["saved.ply", "sphere.xyz", "x.npy"] {
        let o = run(args(out));
        assert!(!o.status.success(), "{out} accepted");
        assert!(!text(&o).contains("panicked"), "{}", text(&o));
    }
    assert_eq!(std::fs::read(&input).unwrap(), before);
    // The saved file needs no estimation.
    let o = stipple(
        &dir,
        &[
            "render",
            "saved.ply",
            "--size",
            "64x64",
            "--backend",
            "cpu",
            "-o",
            "t.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(!text(&o).contains("estimated normals"), "{}", text(&o));
    std::fs::remove_dir_all(dir).ok();
}

/// Autzen's trimmed tile (airborne LiDAR with GPS times and scan angles), or None with the
/// reason printed when the data folder is absent.
fn autzen_trim() -> Option<std::path::PathBuf> {
    let las = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/lidar/autzen_trim.las");
    if !las.exists() {
        eprintln!("skipping: {} is absent", las.display());
        return None;
    }
    Some(las)
}

/// Airborne LiDAR with GPS times and scan angles (Autzen's trimmed tile): `stipple normals`
/// orients towards the aircraft, and hardly any normal faces down (the aircraft above
/// cannot have seen a surface that faces down; the spanning tree turned 93% of them down).
#[test]
fn airborne_lidar_normals_face_the_aircraft() {
    let Some(las) = autzen_trim() else {
        return;
    };
    let dir = tempdir("airborne");
    let o = stipple(&dir, &["normals", las.to_str().unwrap(), "-o", "out.ply"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("towards the aircraft"), "{}", text(&o));
    let c = stipple_io::read_cloud(&dir.join("out.ply")).unwrap();
    let n = c.normals.as_ref().expect("normals written");
    let down = n.iter().filter(|n| n.z < -0.2).count();
    assert!(
        down * 200 < n.len(),
        "{down} of {} normals face down",
        n.len()
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A Z-up source without per-point sensor directions (the same tile with them dropped) is
/// oriented as seen from above: each connected component turned so that most of its
/// horizontal surfaces face up. By its highest point alone (a tree top, a pole) a component
/// can come out with most of its normals down: Autzen's tile did (more than half) until the
/// spanning tree stopped joining neighbours across two layers (`normals::one_layer`; now
/// 5%), and the terrestrial scan `lone-star.laz` still does (48%; from above, 15%).
#[test]
fn lidar_without_sensor_directions_is_oriented_from_above() {
    use stipple_core::normals::{estimate_from, Towards};
    let Some(las) = autzen_trim() else {
        return;
    };
    let down_of = |c: &stipple_core::PointCloud, t: Towards| {
        let e = estimate_from(&c.positions, None, 16, 1.0, t).unwrap();
        e.normals.iter().filter(|n| n.z < -0.2).count() as f64 / c.len() as f64
    };
    let c = stipple_io::read_cloud(&las).unwrap();
    assert!(c.z_up);
    let above = down_of(&c, Towards::Above);
    assert!(above < 0.1, "from above: {above} face down");
    let lone = las.with_file_name("lone-star.laz");
    let scan = stipple_io::read_cloud(&lone).unwrap();
    assert!(scan.z_up);
    let (above, tree) = (
        down_of(&scan, Towards::Above),
        down_of(&scan, Towards::Unknown),
    );
    assert!(above < 0.2, "lone-star from above: {above} face down");
    assert!(
        tree > 0.4,
        "lone-star by the highest point: {tree} face down (the test's premise)"
    );
    // Through the renderer: a Z-up cloud without directions takes Towards::Above.
    for (c, most) in [(c, 0.1), (scan, 0.2)] {
        let mut p = stipple_render::PreparedCloud::new(stipple_core::PointCloud {
            sensor_dirs: None,
            ..c
        });
        p.prepare_surface(16, true).unwrap();
        let n = p.cloud.normals.as_ref().unwrap();
        let share = n.iter().filter(|n| n.z < -0.2).count() as f64 / n.len() as f64;
        assert!(share < most, "rendered: {share} face down");
    }
}

/// Degenerate clouds through `render` and `normals` at default settings: every point the
/// same, a line, a plane. Each renders (or says why not) without a panic, and nothing the
/// user reads says "NaN" (100 copies of one point used to report that they "land NaN px
/// apart").
#[test]
fn degenerate_clouds_render_and_say_so_plainly() {
    let dir = tempdir("degenerate");
    let clouds: [(&str, Vec<[f64; 3]>); 3] = [
        ("copies", vec![[0.5, 0.5, 0.5]; 100]),
        (
            "line",
            (0..500).map(|i| [i as f64 * 0.01, 0.0, 0.0]).collect(),
        ),
        (
            "plane",
            (0..2000)
                .map(|i| [(i % 50) as f64 * 0.02, (i / 50) as f64 * 0.02, 0.0])
                .collect(),
        ),
    ];
    for (name, pts) in clouds {
        let body: String = pts
            .iter()
            .map(|p| format!("{} {} {}\n", p[0], p[1], p[2]))
            .collect();
        std::fs::write(dir.join(format!("{name}.xyz")), body).unwrap();
        let input = format!("{name}.xyz");
        for args in [
            vec!["render", &input, "-o", "out.png", "--backend", "cpu"],
            vec!["normals", &input, "-o", "out.ply", "--force"],
        ] {
            let o = stipple(&dir, &args);
            let t = text(&o);
            assert!(o.status.success(), "{name}: stipple {args:?}: {t}");
            assert!(!t.contains("NaN"), "{name}: stipple {args:?}: {t}");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
