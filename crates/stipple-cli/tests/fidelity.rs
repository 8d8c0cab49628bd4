//! Sparse analytic surfaces rendered by the binary at its default settings (only the size,
//! the camera and the outputs given), measured against ray-traced truth: the silhouette, the
//! depth (`--depth-out`) and the normals (`--normal-out`), with normals given, without
//! normals, and with normals of random sign. Surfaces here differ from the render crate's
//! (sphere, torus, box, plate): an open wavy sheet whose boundary is seen, and a rotated
//! ellipsoid whose curvature varies along the silhouette.

mod common;
use common::{stipple, tempdir, text};
use glam::DVec3;
use stipple_core::rng::Rng;
use stipple_core::{Camera, Projection};

/// A surface: points on it with outward normals, and the first hit of a ray.
trait Surface {
    fn sample(&self, r: &mut Rng) -> (DVec3, DVec3);
    /// Ray parameter and unit normal of the first hit.
    fn hit(&self, o: DVec3, d: DVec3) -> Option<(f64, DVec3)>;
}

/// z = a sin(3x) cos(2y) over [-1, 1]², normals upwards.
struct Sheet {
    a: f64,
}

impl Sheet {
    fn h(&self, x: f64, y: f64) -> f64 {
        self.a * (3.0 * x).sin() * (2.0 * y).cos()
    }
    fn normal(&self, x: f64, y: f64) -> DVec3 {
        let hx = 3.0 * self.a * (3.0 * x).cos() * (2.0 * y).cos();
        let hy = -2.0 * self.a * (3.0 * x).sin() * (2.0 * y).sin();
        DVec3::new(-hx, -hy, 1.0).normalize()
    }
}

impl Surface for Sheet {
    fn sample(&self, r: &mut Rng) -> (DVec3, DVec3) {
        let (x, y) = (r.f64() * 2.0 - 1.0, r.f64() * 2.0 - 1.0);
        (DVec3::new(x, y, self.h(x, y)), self.normal(x, y))
    }

    fn hit(&self, o: DVec3, d: DVec3) -> Option<(f64, DVec3)> {
        // March in small steps for a sign change of z − h inside the square, then bisect.
        let f = |t: f64| {
            let p = o + d * t;
            p.z - self.h(p.x, p.y)
        };
        let inside = |t: f64| {
            let p = o + d * t;
            p.x.abs() <= 1.0 && p.y.abs() <= 1.0
        };
        let (mut t0, step) = (0.0, 0.002);
        while t0 < 20.0 {
            let t1 = t0 + step;
            if inside(t0) && inside(t1) && f(t0).signum() != f(t1).signum() {
                let (mut a, mut b) = (t0, t1);
                for _ in 0..60 {
                    let m = 0.5 * (a + b);
                    if f(a).signum() == f(m).signum() {
                        a = m;
                    } else {
                        b = m;
                    }
                }
                let p = o + d * a;
                return Some((a, self.normal(p.x, p.y)));
            }
            t0 = t1;
        }
        None
    }
}

/// An ellipsoid with semi-axes `s`, rotated about a tilted axis.
struct Ellipsoid {
    s: DVec3,
    rot: glam::DQuat,
}

impl Ellipsoid {
    fn local_normal(&self, q: DVec3) -> DVec3 {
        (q / (self.s * self.s)).normalize()
    }
}

impl Surface for Ellipsoid {
    fn sample(&self, r: &mut Rng) -> (DVec3, DVec3) {
        // Area-weighted by rejection: a direction on the sphere, kept with probability
        // proportional to the area element of the map to the ellipsoid.
        loop {
            let z = r.f64() * 2.0 - 1.0;
            let phi = r.f64() * std::f64::consts::TAU;
            let u = DVec3::new(
                (1.0 - z * z).sqrt() * phi.cos(),
                (1.0 - z * z).sqrt() * phi.sin(),
                z,
            );
            let q = u * self.s;
            let g = (q / (self.s * self.s)).length() * self.s.x * self.s.y * self.s.z;
            let gmax = self.s.max_element().powi(2);
            if r.f64() * gmax <= g {
                return (self.rot * q, self.rot * self.local_normal(q));
            }
        }
    }

    fn hit(&self, o: DVec3, d: DVec3) -> Option<(f64, DVec3)> {
        let inv = self.rot.inverse();
        let (lo, ld) = ((inv * o) / self.s, (inv * d) / self.s);
        let (a, b, c) = (ld.dot(ld), 2.0 * lo.dot(ld), lo.dot(lo) - 1.0);
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 {
            return None;
        }
        let t = (-b - disc.sqrt()) / (2.0 * a);
        (t > 0.0).then(|| {
            let q = (inv * (o + d * t)).clamp(-self.s, self.s);
            (t, self.rot * self.local_normal(q))
        })
    }
}

/// Writes `n` points of `s` as binary-free ASCII PLY, with the normals as `how` says.
fn write_ply(path: &std::path::Path, s: &dyn Surface, n: usize, how: &str, seed: u64) {
    let mut r = Rng::new(seed);
    let normals = how != "none";
    let mut out = format!(
        "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n\
         property float z\n{}end_header\n",
        if normals {
            "property float nx\nproperty float ny\nproperty float nz\n"
        } else {
            ""
        }
    );
    for _ in 0..n {
        let (p, mut nr) = s.sample(&mut r);
        if how == "random" && r.f32() < 0.5 {
            nr = -nr;
        }
        out.push_str(&format!("{} {} {}", p.x, p.y, p.z));
        if normals {
            out.push_str(&format!(" {} {} {}", nr.x, nr.y, nr.z));
        }
        out.push('\n');
    }
    std::fs::write(path, out).unwrap();
}

fn v3(v: DVec3) -> String {
    format!("{},{},{}", v.x, v.y, v.z)
}

#[derive(Debug)]
struct Report {
    iou: f64,
    depth_within: f64,
    behind: f64,
    normal_median: f64,
    normal_p90: f64,
}

/// Renders `file` with the binary's defaults from `cam` and measures it against `s`.
fn measure(dir: &std::path::Path, file: &str, cam: &Camera, s: &dyn Surface) -> Report {
    let size = format!("{}x{}", cam.width, cam.height);
    let fov = match cam.projection {
        Projection::Perspective { fov_deg } => fov_deg,
        Projection::Orthographic { .. } => unreachable!(),
    };
    let (eye, target, up, fov) = (v3(cam.eye), v3(cam.target), v3(cam.up), fov.to_string());
    let png = format!("{file}.png");
    let o = stipple(
        dir,
        &[
            "render",
            file,
            "--size",
            &size,
            "--eye",
            &eye,
            "--target",
            &target,
            "--up",
            &up,
            "--fov",
            &fov,
            "--backend",
            "cpu",
            "--depth-out",
            "d.npy",
            "--normal-out",
            "n.npy",
            "-o",
            &png,
        ],
    );
    assert!(o.status.success(), "{file}: {}", text(&o));
    // Keep the image for a person to look at.
    let keep = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/test-output");
    let _ = std::fs::create_dir_all(&keep);
    let _ = std::fs::copy(dir.join(&png), keep.join(format!("cli-fidelity-{png}")));
    let (_, _, depth) = stipple_io::image::read_npy(&dir.join("d.npy")).unwrap();
    let (_, normals) = stipple_io::image::read_npy_shaped(&dir.join("n.npy")).unwrap();
    let (w, h) = (cam.width, cam.height);
    let fwd = cam.basis().forward;
    let truth: Vec<Option<(f64, DVec3)>> = (0..w * h)
        .map(|k| {
            let (o, d) = cam.pixel_ray(k % w, k / w);
            s.hit(o, d).map(|(t, n)| {
                // View-axis depth; the normal that faces the eye.
                let n = if n.dot(d) > 0.0 { -n } else { n };
                (t * d.dot(fwd), n)
            })
        })
        .collect();
    let depths: Vec<f64> = truth.iter().flatten().map(|t| t.0).collect();
    let range = depths.iter().cloned().fold(f64::MIN, f64::max)
        - depths.iter().cloned().fold(f64::MAX, f64::min);
    let (mut inter, mut uni, mut within, mut behind) = (0usize, 0usize, 0usize, 0usize);
    let mut errs = Vec::new();
    let (mut over, mut under) = (0, 0);
    for (k, t) in truth.iter().enumerate() {
        let covered = depth[k].is_finite();
        uni += (covered || t.is_some()) as usize;
        over += (covered && t.is_none()) as usize;
        under += (!covered && t.is_some()) as usize;
        let (Some((td, tn)), true) = (*t, covered) else {
            continue;
        };
        inter += 1;
        let d = depth[k] as f64;
        within += ((d - td).abs() <= 0.005 * range) as usize;
        behind += (d > td + 0.05 * range) as usize;
        let n = DVec3::new(
            normals[3 * k] as f64,
            normals[3 * k + 1] as f64,
            normals[3 * k + 2] as f64,
        );
        errs.push(n.dot(tn).clamp(-1.0, 1.0).acos().to_degrees());
    }
    if std::env::var("FIDELITY_DEBUG").is_ok() {
        // Silhouette error map: grey both, red covered outside, blue missing inside.
        let mut img = vec![0u8; (w * h * 4) as usize];
        for (k, t) in truth.iter().enumerate() {
            let px = match (depth[k].is_finite(), t.is_some()) {
                (true, true) => [128, 128, 128],
                (true, false) => [255, 0, 0],
                (false, true) => [0, 0, 255],
                _ => [0, 0, 0],
            };
            img[4 * k..4 * k + 3].copy_from_slice(&px);
            img[4 * k + 3] = 255;
        }
        let _ = stipple_io::image::write_png(
            &keep.join(format!("cli-fidelity-{file}-sil.png")),
            w,
            h,
            &img,
        );
    }
    errs.sort_by(f64::total_cmp);
    eprintln!("{file}: {over} px covered outside the silhouette, {under} inside not covered");
    Report {
        iou: inter as f64 / uni.max(1) as f64,
        depth_within: within as f64 / inter.max(1) as f64,
        behind: behind as f64 / inter.max(1) as f64,
        normal_median: errs[errs.len() / 2],
        normal_p90: errs[errs.len() * 9 / 10],
    }
}

/// `min_iou`: 0.99 for closed surfaces; an open one is cut where its samples end, which a
/// random sample leaves ragged by a fraction of the spacing all along the rim (see
/// `stipple_core::normals::share_boundaries`).
fn check(what: &str, r: &Report, min_iou: f64) {
    eprintln!("{what}: {r:?}");
    assert!(r.iou >= min_iou, "{what}: silhouette {r:?}");
    assert!(r.depth_within >= 0.95, "{what}: depth {r:?}");
    assert!(r.behind <= 0.02, "{what}: surfaces behind {r:?}");
    assert!(r.normal_median <= 5.0, "{what}: normals {r:?}");
    assert!(r.normal_p90 <= 15.0, "{what}: normals {r:?}");
}

fn camera(eye: DVec3, up: DVec3, size: u32) -> Camera {
    Camera {
        eye,
        target: DVec3::ZERO,
        up,
        projection: Projection::Perspective { fov_deg: 40.0 },
        width: size,
        height: size,
        near: 0.1,
        far: 100.0,
    }
}

#[test]
fn a_sparse_wavy_sheet_renders_whole_at_default_settings() {
    let dir = tempdir("fidelity-sheet");
    let sheet = Sheet { a: 0.2 };
    let cam = camera(DVec3::new(0.9, -2.2, 2.4), DVec3::Z, 256);
    for how in ["given", "none", "random"] {
        let file = format!("sheet-{how}.ply");
        write_ply(&dir.join(&file), &sheet, 2500, how, 7);
        let r = measure(&dir, &file, &cam, &sheet);
        check(&format!("sheet, normals {how}"), &r, 0.95);
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_sparse_rotated_ellipsoid_renders_whole_at_default_settings() {
    let dir = tempdir("fidelity-ellipsoid");
    let e = Ellipsoid {
        s: DVec3::new(1.0, 0.55, 0.35),
        rot: glam::DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 0.5).normalize(), 0.9),
    };
    let cam = camera(DVec3::new(-0.6, 0.8, 3.0), DVec3::Y, 256);
    for how in ["given", "none", "random"] {
        let file = format!("ellipsoid-{how}.ply");
        write_ply(&dir.join(&file), &e, 2500, how, 9);
        check(
            &format!("ellipsoid, normals {how}"),
            &measure(&dir, &file, &cam, &e),
            0.99,
        );
    }
    std::fs::remove_dir_all(dir).ok();
}

/// Degenerate sparse clouds draw something, never a blank image: five points (splats as
/// large as the cloud, reaching in front of the near plane), and a lattice whose every
/// point is repeated 40 times (the copies are no neighbours of each other).
#[test]
fn degenerate_sparse_clouds_are_not_blank() {
    let dir = tempdir("fidelity-degenerate");
    let mut r = Rng::new(3);
    let five: String = (0..5)
        .map(|_| format!("{} {} {}\n", r.f32(), r.f32(), r.f32()))
        .collect();
    std::fs::write(dir.join("five.xyz"), five).unwrap();
    let lattice: String = (0..4000)
        .map(|i| {
            format!(
                "{} {} {}\n",
                (i / 40) % 10,
                (i / 400) % 10,
                0.1 * (i / 40 % 7) as f32
            )
        })
        .collect();
    std::fs::write(dir.join("lattice.xyz"), lattice).unwrap();
    for f in ["five.xyz", "lattice.xyz"] {
        let o = stipple(
            &dir,
            &[
                "render",
                f,
                "--size",
                "128",
                "--backend",
                "cpu",
                "--depth-out",
                "d.npy",
                "-o",
                "x.png",
            ],
        );
        assert!(o.status.success(), "{f}: {}", text(&o));
        let (_, _, d) = stipple_io::image::read_npy(&dir.join("d.npy")).unwrap();
        let covered = d.iter().filter(|x| x.is_finite()).count();
        assert!(covered > 500, "{f}: {covered} pixels covered\n{}", text(&o));
    }
    std::fs::remove_dir_all(dir).ok();
}
