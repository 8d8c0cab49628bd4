//! Splats on sparse clouds (Zhang & Pajarola; issue "Surfaces from any cloud"): random
//! uniform samples of analytic surfaces, landing 3–6 px apart on screen, rendered at default
//! splat settings with normals given, estimated (none given) and given with random signs.
//!
//! Truth per pixel: the centre ray sphere-traced against the exact signed distance function
//! (depth) and its gradient (normal). Measures, over the whole image:
//! * silhouette IoU ≥ 0.99;
//! * depth within 0.5% of the depth range on ≥ 95% of the pixels both cover;
//! * surfaces behind showing through (a pixel deeper than the truth by more than 5% of the
//!   range) on ≤ 2% of them;
//! * normal error median ≤ 5°, 90th percentile ≤ 15°.
//!
//! `SPLAT_DEBUG=1` prints each scene's surface report and writes depth-error maps (green
//! within 0.5%, red nearer, blue deeper) and silhouette maps (red: covered outside the
//! silhouette; blue: inside it, not covered) beside the renders in `target/test-output/`.
//!
//! The GPU twin of the splat pass must agree with the CPU (Voronoi ids on ≥ 99% of pixels:
//! GPUs may fuse multiply-adds, so a near tie between two splats can go either way).

mod common;

use glam::{DVec3, Vec3};
use stipple_core::rng::Rng;
use stipple_core::{Camera, PointCloud, Projection};
use stipple_render::{
    render, Backend, Pipeline, PreparedCloud, SplatMode, SplatSettings, BACKGROUND,
};

type Sdf = fn(DVec3) -> f64;

fn sphere_sdf(p: DVec3) -> f64 {
    p.length() - 1.0
}

fn torus_sdf(p: DVec3) -> f64 {
    let q = ((p.x * p.x + p.z * p.z).sqrt() - 1.0, p.y);
    (q.0 * q.0 + q.1 * q.1).sqrt() - 0.4
}

/// A small sphere in front of a large one: two objects, one hiding part of the other.
fn sphere_wall_sdf(p: DVec3) -> f64 {
    let a = (p - DVec3::new(0.2, 0.1, 0.9)).length() - 0.4;
    let b = (p - DVec3::new(0.0, 0.0, -0.4)).length() - 0.9;
    a.min(b)
}

/// A box with edges rounded to radius 0.01 (sharp at the point spacing, ~0.04).
fn box_sdf(p: DVec3) -> f64 {
    let q = p.abs() - DVec3::splat(0.79);
    q.max(DVec3::ZERO).length() + q.max_element().min(0.0) - 0.01
}

/// A closed cylinder (radius 0.7, height 1.2, axis y) with rims rounded to 0.01 (sharp at
/// the point spacing; as for the box, the rounding keeps the sampler from piling points
/// onto the edge itself with the two faces' mean normal): a curved face meeting flat ones
/// at right angles.
fn cylinder_sdf(p: DVec3) -> f64 {
    let d = (DVec3::new(p.x, 0.0, p.z).length() - 0.69, p.y.abs() - 0.59);
    d.0.max(d.1).min(0.0) + (d.0.max(0.0).powi(2) + d.1.max(0.0).powi(2)).sqrt() - 0.01
}

/// A box of half-sizes `h` centred at `c`, edges rounded to 0.01.
fn cuboid(p: DVec3, c: DVec3, h: DVec3) -> f64 {
    let q = (p - c).abs() - h + DVec3::splat(0.01);
    q.max(DVec3::ZERO).length() + q.max_element().min(0.0) - 0.01
}

/// A step: a long low box and a tall one overlapping it (so that the union has no inner
/// face), sharp convex edges meeting a concave one (the inner corner of the step).
fn step_sdf(p: DVec3) -> f64 {
    let low = cuboid(p, DVec3::new(0.0, -0.35, 0.0), DVec3::new(0.8, 0.35, 0.6));
    let high = cuboid(p, DVec3::new(-0.4, 0.1, 0.0), DVec3::new(0.4, 0.5, 0.6));
    low.min(high)
}

/// A thin square plate (1.6 × 1.6, 0.01 thick: far thinner than ε), tilted, sampled on both
/// sides: the back side must not blend into the front.
fn plate_sdf(p: DVec3) -> f64 {
    let (c, s) = (0.5f64.cos(), 0.5f64.sin());
    let q = DVec3::new(p.x, c * p.y - s * p.z, s * p.y + c * p.z);
    let d = q.abs() - DVec3::new(0.8, 0.8, 0.005);
    d.max(DVec3::ZERO).length() + d.max_element().min(0.0)
}

fn gradient(sdf: Sdf, p: DVec3) -> DVec3 {
    let e = 1e-6;
    DVec3::new(
        sdf(p + DVec3::X * e) - sdf(p - DVec3::X * e),
        sdf(p + DVec3::Y * e) - sdf(p - DVec3::Y * e),
        sdf(p + DVec3::Z * e) - sdf(p - DVec3::Z * e),
    )
    .normalize()
}

/// View depth and normal of the first hit of pixel (i, j)'s centre ray.
fn trace(cam: &Camera, sdf: Sdf, i: u32, j: u32) -> Option<(f64, DVec3)> {
    let (o, d) = cam.pixel_ray(i, j);
    let f = cam.basis().forward;
    let mut t = 0.0;
    let mut last = 0.0;
    // Rays that graze a face (a box's side seen edge-on) step along it in tiny steps: with
    // 600 steps they ran out before reaching the surface and counted as misses, so splats
    // that covered such pixels rightly counted as outside the silhouette (a box 4.8 px
    // apart: 678 such pixels, IoU 0.983 instead of 0.996).
    for _ in 0..20_000 {
        let p = o + d * t;
        let s = sdf(p);
        if s < -1e-9 {
            // Stepped through (a distance that is exact only near the surface): bisect
            // back between the last point outside and this one.
            let (mut a, mut b) = (last, t);
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                if sdf(o + d * m) > 0.0 {
                    a = m;
                } else {
                    b = m;
                }
            }
            let p = o + d * b;
            return Some(((p - cam.eye).dot(f), gradient(sdf, p)));
        }
        if s < 1e-9 {
            return Some(((p - cam.eye).dot(f), gradient(sdf, p)));
        }
        last = t;
        t += s;
        if t > 100.0 {
            break;
        }
    }
    None
}

/// `n` random points on the zero set of `sdf` inside the cube [-lim, lim]³ (rejection in the
/// cube, then projected onto the surface along the gradient), with exact normals.
fn sample(sdf: Sdf, n: usize, lim: f64, seed: u64) -> PointCloud {
    sample_with(sdf, n, lim, seed, false)
}

/// [`sample`], without the points that land exactly on a sharp edge when `skip_edges`.
fn sample_with(sdf: Sdf, n: usize, lim: f64, seed: u64, skip_edges: bool) -> PointCloud {
    let mut r = Rng::new(seed);
    let mut pts = Vec::with_capacity(n);
    let mut nrm = Vec::with_capacity(n);
    let band = 0.01;
    while pts.len() < n {
        let p = DVec3::new(
            (r.f64() * 2.0 - 1.0) * lim,
            (r.f64() * 2.0 - 1.0) * lim,
            (r.f64() * 2.0 - 1.0) * lim,
        );
        if sdf(p).abs() > band {
            continue;
        }
        let mut q = p;
        for _ in 0..8 {
            q -= gradient(sdf, q) * sdf(q);
        }
        let g = gradient(sdf, q);
        if !(q.is_finite() && g.is_finite() && sdf(q).abs() < 1e-6) {
            continue;
        }
        // On a sharp edge (a kink of the distance, where one-sided differences disagree)
        // the projection piles points up with the faces' mean normal: with `skip_edges`,
        // none is taken there.
        let e = 1e-4;
        let s0 = sdf(q);
        let ahead = DVec3::new(
            sdf(q + DVec3::X * e) - s0,
            sdf(q + DVec3::Y * e) - s0,
            sdf(q + DVec3::Z * e) - s0,
        );
        let behind = DVec3::new(
            s0 - sdf(q - DVec3::X * e),
            s0 - sdf(q - DVec3::Y * e),
            s0 - sdf(q - DVec3::Z * e),
        );
        if skip_edges && (ahead - behind).length() > 0.05 * e {
            continue;
        }
        pts.push(q);
        nrm.push(g.as_vec3());
    }
    let mut c = PointCloud::from_world(&pts);
    c.normals = Some(nrm);
    c
}

fn camera(eye: DVec3, size: u32) -> Camera {
    let mut c = Camera {
        eye,
        target: DVec3::ZERO,
        up: DVec3::Y,
        projection: Projection::Perspective { fov_deg: 40.0 },
        width: size,
        height: size,
        near: 0.1,
        far: 10.0,
    };
    c.fit_clip(DVec3::splat(-1.5), DVec3::splat(1.5));
    c
}

#[derive(Debug)]
struct Report {
    iou: f64,
    depth_within: f64,
    behind: f64,
    normal_median: f64,
    normal_p90: f64,
    spacing_px: f32,
    /// Pixels that no splat covers and the background around the surface does not reach:
    /// holes in the surface.
    holes: usize,
}

impl Report {
    fn check(&self, what: &str) {
        self.check_shape(what);
        assert!(self.normal_median <= 5.0, "{what}: {self:?}");
        assert!(self.normal_p90 <= 15.0, "{what}: {self:?}");
    }

    /// The silhouette and depth bounds of [`Report::check`], not the normals'.
    fn check_shape(&self, what: &str) {
        eprintln!("{what}: {self:?}");
        assert!(self.iou >= 0.99, "{what}: {self:?}");
        assert!(self.depth_within >= 0.95, "{what}: {self:?}");
        assert!(self.behind <= 0.02, "{what}: {self:?}");
    }
}

/// Renders `cloud` the way the CLI's defaults do for a sparse cloud (surface preparation,
/// then the splat pipeline) and measures it against the truth.
fn measure(name: &str, cam: &Camera, sdf: Sdf, cloud: PointCloud, mode: SplatMode) -> Report {
    let scale: f32 = std::env::var("SPLAT_SCALE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let (w, h) = (cam.width as usize, cam.height as usize);
    let truth: Vec<Option<(f64, DVec3)>> = (0..w * h)
        .map(|k| trace(cam, sdf, (k % w) as u32, (k / w) as u32))
        .collect();
    let depths: Vec<f64> = truth.iter().flatten().map(|t| t.0).collect();
    let range = depths.iter().cloned().fold(f64::MIN, f64::max)
        - depths.iter().cloned().fold(f64::MAX, f64::min);
    let mut prepared = PreparedCloud::new(cloud);
    let rep = prepared.prepare_surface(16, true).unwrap();
    if std::env::var("SPLAT_DEBUG").is_ok() {
        let f = cam.basis().forward.as_vec3();
        let n = prepared.cloud.normals.as_ref().unwrap();
        let facing = n.iter().filter(|v| v.dot(f) < 0.0).count();
        eprintln!("{name}: {rep:?}, {facing} of {} facing the eye", n.len());
    }
    let pipe = Pipeline::splats(SplatSettings {
        mode,
        scale,
        ..Default::default()
    });
    let frame = render(&prepared, cam, &pipe, Backend::Cpu).unwrap();
    common::dump(name, &frame);
    let normals = frame.normal_image(&prepared, cam);
    let (mut inter, mut uni, mut within, mut behind) = (0usize, 0usize, 0usize, 0usize);
    let (mut over, mut under) = (0, 0);
    let mut errs = Vec::new();
    for k in 0..w * h {
        let covered = frame.id[k] != BACKGROUND;
        let t = truth[k];
        if covered || t.is_some() {
            uni += 1;
        }
        over += (covered && t.is_none()) as usize;
        under += (!covered && t.is_some()) as usize;
        let (Some((td, tn)), true) = (t, covered) else {
            continue;
        };
        inter += 1;
        let d = frame.depth[k] as f64;
        if (d - td).abs() <= 0.005 * range {
            within += 1;
        }
        if d > td + 0.05 * range {
            behind += 1;
        }
        let n = Vec3::from(normals[k]).as_dvec3();
        // The truth faces the eye: the first hit's outward normal does.
        errs.push(n.dot(tn).clamp(-1.0, 1.0).acos().to_degrees());
    }
    if std::env::var("SPLAT_DEBUG").is_ok() {
        // Depth error map: green within, red nearer, blue deeper than the truth; and the
        // silhouette: grey both, red covered outside it, blue inside it not covered.
        let mut img = vec![0u8; w * h * 4];
        let mut sil = vec![0u8; w * h * 4];
        for k in 0..w * h {
            let covered = frame.id[k] != BACKGROUND;
            if let (Some((td, _)), true) = (truth[k], covered) {
                let e = (frame.depth[k] as f64 - td) / (0.005 * range);
                let px = if e.abs() <= 1.0 {
                    [0, 160, 0]
                } else if e < 0.0 {
                    [255, 0, 0]
                } else {
                    [0, 0, 255]
                };
                img[4 * k..4 * k + 3].copy_from_slice(&px);
            }
            let px = match (covered, truth[k].is_some()) {
                (true, true) => [200, 200, 200],
                (true, false) => [255, 0, 0],
                (false, true) => [0, 0, 255],
                _ => [0, 0, 0],
            };
            sil[4 * k..4 * k + 3].copy_from_slice(&px);
            img[4 * k + 3] = 255;
            sil[4 * k + 3] = 255;
        }
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/test-output");
        for (what, px) in [("deptherr", &img), ("silhouette", &sil)] {
            let _ = stipple_io::image::write_png(
                &dir.join(format!("{name}-{what}.png")),
                w as u32,
                h as u32,
                px,
            );
        }
    }
    errs.sort_by(f64::total_cmp);
    eprintln!("{name}: {over} px covered outside the silhouette, {under} inside not covered");
    // Uncovered pixels that the background reaches (through uncovered pixels, from the
    // image's border) are outside the surface or in a bay of its rim; the others are holes.
    let mut outside = vec![false; w * h];
    let mut stack: Vec<usize> = (0..w * h)
        .filter(|&k| k % w == 0 || k % w == w - 1 || k / w == 0 || k / w == h - 1)
        .collect();
    while let Some(k) = stack.pop() {
        if outside[k] || frame.id[k] != BACKGROUND {
            continue;
        }
        outside[k] = true;
        let (x, y) = (k % w, k / w);
        if x > 0 {
            stack.push(k - 1);
        }
        if x + 1 < w {
            stack.push(k + 1);
        }
        if y > 0 {
            stack.push(k - w);
        }
        if y + 1 < h {
            stack.push(k + w);
        }
    }
    let holes = (0..w * h)
        .filter(|&k| frame.id[k] == BACKGROUND && !outside[k])
        .count();
    Report {
        iou: inter as f64 / uni.max(1) as f64,
        depth_within: within as f64 / inter.max(1) as f64,
        behind: behind as f64 / inter.max(1) as f64,
        normal_median: errs[errs.len() / 2],
        normal_p90: errs[errs.len() * 9 / 10],
        spacing_px: prepared.screen_spacing(cam),
        holes,
    }
}

fn variants(c: &PointCloud, seed: u64) -> [(&'static str, PointCloud); 3] {
    let mut none = c.clone();
    none.normals = None;
    let mut random = c.clone();
    let mut r = Rng::new(seed);
    for n in random.normals.as_mut().unwrap() {
        if r.f32() < 0.5 {
            *n = -*n;
        }
    }
    [
        ("given", c.clone()),
        ("estimated", none),
        ("random-sign", random),
    ]
}

/// Every variant in every splat mode.
fn modes(v: [(&'static str, PointCloud); 3]) -> Vec<((&'static str, PointCloud), SplatMode)> {
    v.into_iter()
        .flat_map(|x| {
            [
                (x.clone(), SplatMode::Voronoi),
                (x.clone(), SplatMode::Blend),
                (x, SplatMode::Deferred),
            ]
        })
        .collect()
}

#[test]
fn sparse_sphere_is_whole_and_accurate() {
    let cam = camera(DVec3::new(0.4, 0.5, 3.2), 256);
    let c = sample(sphere_sdf, 2000, 1.05, 1);
    for ((what, cloud), mode) in modes(variants(&c, 2)) {
        let r = measure(
            &format!("splat-sphere-{what}-{mode:?}"),
            &cam,
            sphere_sdf,
            cloud,
            mode,
        );
        assert!(
            (3.0..=6.0).contains(&r.spacing_px),
            "the scene must put points 3-6 px apart: {r:?}"
        );
        r.check(&format!("sphere, normals {what}, {mode:?}"));
    }
}

#[test]
fn sparse_torus_is_whole_and_accurate() {
    let cam = camera(DVec3::new(0.3, 2.2, 2.4), 256);
    let c = sample(torus_sdf, 2700, 1.45, 3);
    for ((what, cloud), mode) in modes(variants(&c, 4)) {
        let r = measure(
            &format!("splat-torus-{what}-{mode:?}"),
            &cam,
            torus_sdf,
            cloud,
            mode,
        );
        assert!((3.0..=6.0).contains(&r.spacing_px), "{r:?}");
        r.check(&format!("torus, normals {what}, {mode:?}"));
    }
}

#[test]
fn sparse_box_keeps_its_edges() {
    let cam = camera(DVec3::new(1.9, 1.5, 2.3), 256);
    let c = sample(box_sdf, 3600, 0.85, 9);
    for ((what, cloud), mode) in modes(variants(&c, 10)) {
        let r = measure(
            &format!("splat-box-{what}-{mode:?}"),
            &cam,
            box_sdf,
            cloud,
            mode,
        );
        assert!((3.0..=6.0).contains(&r.spacing_px), "{r:?}");
        r.check(&format!("box, normals {what}, {mode:?}"));
    }
}

/// Sharp convex rims between a curved face and flat ones, and a concave crease, without
/// normals as with them: each point next to an edge must take the face it lies on
/// (`stipple_core::normals::robust_normals`), or its splat stands off the other face.
#[test]
fn sparse_cylinder_and_step_keep_their_edges() {
    let scenes: [Scene; 2] = [
        (
            "cylinder",
            cylinder_sdf,
            DVec3::new(1.6, 1.7, 2.2),
            1800,
            0.8,
        ),
        ("step", step_sdf, DVec3::new(1.5, 1.4, 2.4), 2000, 0.9),
    ];
    measure_all(&scenes, 20, false, |_, what, r| r.check(what));
}

/// A scene: name, distance function, eye, points, half-size of the sampling cube.
type Scene = (&'static str, Sdf, DVec3, usize, f64);

/// Each scene sampled (seeds from `seed`; see [`sample_with`] for `skip_edges`) and
/// measured in every variant and splat mode at 3–6 px spacing; `check` judges each report
/// (the scene's name, a description, the report).
fn measure_all(scenes: &[Scene], seed: u64, skip_edges: bool, check: impl Fn(&str, &str, Report)) {
    for (k, &(name, sdf, eye, n, lim)) in scenes.iter().enumerate() {
        let cam = camera(eye, 256);
        let c = sample_with(sdf, n, lim, seed + k as u64, skip_edges);
        for ((what, cloud), mode) in modes(variants(&c, seed + 10 + k as u64)) {
            let r = measure(
                &format!("splat-{name}-{what}-{mode:?}"),
                &cam,
                sdf,
                cloud,
                mode,
            );
            assert!((3.0..=6.0).contains(&r.spacing_px), "{name}: {r:?}");
            check(name, &format!("{name}, normals {what}, {mode:?}"), r);
        }
    }
}

/// Voronoi rasterization shades each pixel with its winning splat's normal where the
/// pixel's ray meets the bent splat, as blending does: with each point's flat normal this
/// torus (3.5 px apart) came out 3.2° off (median) and 7.4° (90th), a faceted look; on both
/// backends (`splats_match_on_both_backends` compares their colours).
#[test]
fn voronoi_pixels_show_the_surface_normal_at_the_hit() {
    let cam = camera(DVec3::new(0.5, 2.4, 2.6), 256);
    let c = sample(torus_sdf, 2700, 1.45, 17);
    for (what, cloud) in variants(&c, 5) {
        let r = measure(
            &format!("splat-voronoi-torus-{what}"),
            &cam,
            torus_sdf,
            cloud,
            SplatMode::Voronoi,
        );
        eprintln!("torus, normals {what}, Voronoi: {r:?}");
        assert!((3.0..=6.0).contains(&r.spacing_px), "{r:?}");
        assert!(
            r.normal_median <= 1.0 && r.normal_p90 <= 3.0,
            "{what}: {r:?}"
        );
    }
}

/// A sheet far thinner than ε with both sides sampled and normals given: the side facing
/// away must not blend into the side facing the eye (`passes::splat::reference`), and the
/// given normals are not "repaired" into one side (`stipple_core::normals::same_layer`).
/// At the plate's rim, the far side's planes cut nothing, and the rim is looked for
/// (`stipple_core::normals`, `shape_at`): they had kept it from being found, and the splats
/// ran a radius past the rim (IoU 0.977, then 0.982); a point whose own face holds only 6
/// of its 16 neighbours traces the rim with its own face's points within twice its reach
/// (`boundary_planes`; 0.984); a point 0.012 in from the rim leaves a gap of 112°, now
/// enough (`BOUNDARY_GAP` 115° → 109°; 0.986). Without normals (or with random signs) the two sides
/// cannot be told apart and blend, and the rim still overshoots in places: known gaps.
#[test]
fn a_thin_sheet_shows_its_front_side() {
    let cam = camera(DVec3::new(0.3, 1.2, 3.0), 256);
    let c = sample(plate_sdf, 3000, 0.9, 11);
    for mode in [SplatMode::Voronoi, SplatMode::Blend, SplatMode::Deferred] {
        let r = measure(
            &format!("splat-plate-{mode:?}"),
            &cam,
            plate_sdf,
            c.clone(),
            mode,
        );
        eprintln!("plate, normals given, {mode:?}: {r:?}");
        assert!(r.depth_within >= 0.93, "{mode:?}: {r:?}");
        assert!(r.iou >= 0.985 && r.behind <= 0.02, "{mode:?}: {r:?}");
    }
}

#[test]
fn a_sphere_in_front_of_a_wall_hides_it() {
    let cam = camera(DVec3::new(0.2, 0.3, 3.4), 256);
    let c = sample(sphere_wall_sdf, 2600, 1.45, 5);
    for (what, cloud) in variants(&c, 6) {
        for mode in [SplatMode::Voronoi, SplatMode::Blend, SplatMode::Deferred] {
            let r = measure(
                &format!("splat-wall-{what}-{mode:?}"),
                &cam,
                sphere_wall_sdf,
                cloud.clone(),
                mode,
            );
            assert!((3.0..=6.0).contains(&r.spacing_px), "{r:?}");
            r.check(&format!("sphere and wall, normals {what}, {mode:?}"));
        }
    }
}

/// The same splat frame on the GPU (lavapipe in CI) as on the CPU, Voronoi and blend, with
/// bent splats and with eye-facing discs (no normals).
#[test]
fn gpu_splats_match_the_cpu() {
    let ctx = match stipple_render::gpu::GpuContext::new(Default::default()) {
        Ok(c) => c,
        Err(e) => {
            if std::env::var("STIPPLE_REQUIRE_GPU").is_ok_and(|v| v == "1") {
                panic!("STIPPLE_REQUIRE_GPU=1 but there is no usable GPU adapter: {e}");
            }
            eprintln!("skipped: no GPU adapter ({e})");
            return;
        }
    };
    drop(ctx);
    // Smooth surfaces (bent splats, no clip planes), and a cylinder and a box whose splats
    // are cut at their rims and edges: flat crease planes, planes bent into a curved rim,
    // and the planes where a splat stops following its face.
    let scenes: [(&str, Sdf, DVec3, usize, f64); 3] = [
        (
            "sphere-wall",
            sphere_wall_sdf,
            DVec3::new(0.2, 0.3, 3.4),
            3000,
            1.45,
        ),
        (
            "cylinder",
            cylinder_sdf,
            DVec3::new(1.6, 1.7, 2.2),
            1800,
            0.8,
        ),
        ("box", box_sdf, DVec3::new(1.9, 1.5, 2.3), 2400, 0.85),
    ];
    for (k, (name, sdf, eye, n, lim)) in scenes.into_iter().enumerate() {
        let cam = camera(eye, 200);
        let mut c = sample(sdf, n, lim, 7 + k as u64);
        // Colours so that the shaded images compare more than geometry.
        let mut r = Rng::new(8);
        c.colors = Some(
            (0..c.len())
                .map(|_| [r.below(256) as u8, 128, 200])
                .collect(),
        );
        let mut prepared = PreparedCloud::new(c);
        prepared.prepare_surface(16, true).unwrap();
        let shapes = prepared.shapes.as_ref().unwrap();
        let bent_rims = shapes.iter().filter(|s| s.curve != [[0.0; 2]; 2]).count();
        let cut = shapes.iter().filter(|s| s.clip != [[0.0; 4]; 2]).count();
        eprintln!("{name}: {cut} splats cut, {bent_rims} at a bent rim");
        if name == "cylinder" {
            assert!(bent_rims > 0, "the cylinder's rims bend their clip planes");
        }
        if name != "sphere-wall" {
            assert!(cut > 0, "{name}: its edges cut splats");
        }
        splats_match_on_both_backends(name, &prepared, &cam);
    }
}

/// [`gpu_splats_match_the_cpu`] for one prepared scene: every splat mode, with normals (and
/// the splat shapes) and without.
fn splats_match_on_both_backends(name: &str, prepared: &PreparedCloud, cam: &Camera) {
    for (no_normals, mode) in [
        (false, SplatMode::Voronoi),
        (true, SplatMode::Voronoi),
        (false, SplatMode::Blend),
        (true, SplatMode::Blend),
        (false, SplatMode::Deferred),
        (true, SplatMode::Deferred),
    ] {
        let mut p = PreparedCloud::new(prepared.cloud.clone());
        if no_normals {
            p.cloud.normals = None;
        } else {
            p.shapes = prepared.shapes.clone();
        }
        let pipe = Pipeline::splats(SplatSettings {
            mode,
            ..Default::default()
        });
        let a = render(&p, cam, &pipe, Backend::Cpu).unwrap();
        let b = render(&p, cam, &pipe, Backend::Gpu).unwrap();
        let n = a.id.len();
        let same = a.id.iter().zip(&b.id).filter(|(x, y)| x == y).count();
        assert!(
            same as f64 >= 0.99 * n as f64,
            "{name}, {mode:?}: ids agree on {same} of {n} pixels"
        );
        let cov_a = a.id.iter().filter(|&&i| i != BACKGROUND).count();
        assert!(cov_a > n / 4, "the frame shows the scene");
        // The CPU kernel evaluates the fragment maths in affine form (`Raster`), the GPU as
        // written in `fragment`: rounding can move a fragment at the edge of a splat or of
        // the ε band in or out, which shifts a blended depth a little on a few pixels.
        let mut off = 0;
        for k in 0..n {
            if a.id[k] == b.id[k] && a.id[k] != BACKGROUND {
                let (x, y) = (a.depth[k], b.depth[k]);
                if (x - y).abs() > 1e-4 * x.abs() {
                    off += 1;
                    assert!(
                        (x - y).abs() <= 0.01 * x.abs(),
                        "{name}, {mode:?}: depth {x} vs {y} at {k}"
                    );
                }
            }
        }
        assert!(
            off as f64 <= 0.002 * cov_a as f64,
            "{name}, {mode:?}: {off} of {cov_a} depths differ"
        );
        let close = a
            .rgba
            .chunks(4)
            .zip(b.rgba.chunks(4))
            .filter(|(p, q)| {
                p.iter()
                    .zip(*q)
                    .all(|(u, v)| (*u as i32 - *v as i32).abs() <= 2)
            })
            .count();
        assert!(
            close as f64 >= 0.98 * n as f64,
            "{name}, {mode:?}: colour agrees on {close} of {n}"
        );
        // The per-pixel normals the pixels were shaded with (`--normal-out`) come back from
        // both backends and agree where the pixels show the same point.
        let (Some(na), Some(nb)) = (&a.normals, &b.normals) else {
            panic!("{name}, {mode:?}: a splat frame keeps its per-pixel normals on both backends");
        };
        let (mut shown, mut near) = (0, 0);
        for k in 0..n {
            if a.id[k] == b.id[k] && a.id[k] != BACKGROUND {
                shown += 1;
                let (u, v) = (glam::Vec3::from(na[k]), glam::Vec3::from(nb[k]));
                near += (u.dot(v) >= 0.9998) as usize;
            }
        }
        assert!(
            near as f64 >= 0.99 * shown as f64,
            "{name}, {mode:?}: normals within 1.1° on {near} of {shown} pixels"
        );
    }
}

/// A regular tetrahedron (faces 0.45 from the centre): edges of 70.5°, sharper than a
/// right angle, where neighbouring normals are 109.5° apart.
fn tetra_sdf(p: DVec3) -> f64 {
    let s = 3f64.sqrt();
    [
        DVec3::new(1.0, 1.0, 1.0),
        DVec3::new(-1.0, -1.0, 1.0),
        DVec3::new(-1.0, 1.0, -1.0),
        DVec3::new(1.0, -1.0, -1.0),
    ]
    .iter()
    .map(|n| p.dot(*n) / s - 0.45)
    .fold(f64::MIN, f64::max)
}

/// A regular octahedron: four faces at each vertex.
fn octa_sdf(p: DVec3) -> f64 {
    (p.x.abs() + p.y.abs() + p.z.abs() - 1.0) / 3f64.sqrt()
}

/// A cone along y (apex at y = 0.8, base of radius 0.7 at y = −0.6), with its base.
fn cone_sdf(p: DVec3) -> f64 {
    let q = DVec3::new(p.x, 0.0, p.z).length();
    let (h, r, y) = (1.4, 0.7, p.y + 0.6);
    let side = (q * h + (y - h) * r) / (h * h + r * r).sqrt();
    side.max(-y)
}

/// A wavy slab 2 × 2, 0.4 thick (a bent sheet with sharp sides).
fn wave_sdf(p: DVec3) -> f64 {
    let h = 0.15 * (3.0 * p.x).sin() * (2.5 * p.z).cos();
    let top = (p.y - h) * 0.8;
    let bottom = (h - 0.4 - p.y) * 0.8;
    top.max(bottom).max(p.x.abs() - 1.0).max(p.z.abs() - 1.0)
}

/// Sharp polyhedra (a tetrahedron's edges are sharper than a right angle; an octahedron
/// has four faces at a vertex), a cone's apex and rim, a bent slab: with normals given, of
/// random sign (the orientation must cross edges whose normals are more than 90° apart:
/// `stipple_core::normals::orient`), and estimated. Without normals, the polyhedra's
/// vertices (three or four sharp faces meet) and the cone's apex overshoot the silhouette a
/// little (measured over four seeds: IoU 0.986–0.998, every other bound met): a known gap,
/// held here at IoU ≥ 0.98 so that it cannot grow.
#[test]
fn sparse_polyhedra_cone_and_slab_are_whole_and_accurate() {
    let scenes: [Scene; 4] = [
        ("tetra", tetra_sdf, DVec3::new(1.3, 1.0, 2.6), 1400, 1.0),
        ("octa", octa_sdf, DVec3::new(1.4, 1.2, 2.4), 2200, 1.05),
        ("cone", cone_sdf, DVec3::new(1.5, 1.2, 2.4), 1500, 0.9),
        ("wave", wave_sdf, DVec3::new(0.8, 1.9, 2.2), 2200, 1.05),
    ];
    measure_all(&scenes, 40, true, |name, what, r| {
        if what.contains("estimated") && name != "wave" {
            eprintln!("{what} (IoU held at 0.98): {r:?}");
            assert!(r.iou >= 0.98, "{what}: {r:?}");
            Report { iou: 1.0, ..r }.check(what);
        } else {
            r.check(what);
        }
    });
}

/// A cone without normals, at three samplings whose point next to the apex got an estimated
/// normal 50° off (its neighbours' normals point all round the cone) and a splat curled out
/// past the silhouette (IoU 0.9865–0.9883 before its splat was shrunk:
/// `stipple_core::normals::normal_spread`), and one (110) whose point a quarter of a
/// spacing from the apex got one 15° off, averaged all round, that spread too little for
/// the first threshold (IoU 0.9862 before `SINGULAR_SPREAD` went from 0.1 to 0.05). And one
/// at half the density (750 points, 4–4.5 px apart) whose point 0.03 below the apex kept
/// its whole radius between crease planes that do not bound it past the apex (IoU 0.988
/// before its radius was capped there). Every bound holds.
#[test]
fn a_cone_without_normals_keeps_its_apex_inside_the_silhouette() {
    let cone: Scene = ("cone", cone_sdf, DVec3::new(1.5, 1.2, 2.4), 1500, 0.9);
    let sparse: Scene = ("cone", cone_sdf, DVec3::new(1.5, 1.2, 2.4), 750, 0.9);
    for (scene, seed) in [
        (cone, 109),
        (cone, 110),
        (cone, 123),
        (cone, 125),
        (sparse, 111),
    ] {
        measure_all(std::slice::from_ref(&scene), seed, false, |_, what, r| {
            if what.contains("estimated") {
                r.check(&format!("seed {seed}, {} points, {what}", scene.3));
            }
        });
    }
}

/// Normals of random sign carry no orientation (`stipple_core::normals::RANDOM_SIGNS`). On
/// this cone (seed 125) the propagation took the majority of the random signs, inwards,
/// and the region of signs that differed faced outwards at four of its six extreme points,
/// so every random sign was kept: surfaces behind 2.7%, depth within 0.5% on 0.93 of the
/// pixels. Now it ends as the cone with its normals given does.
#[test]
fn a_cone_with_normals_of_random_sign_ends_outward() {
    let cone: Scene = ("cone", cone_sdf, DVec3::new(1.5, 1.2, 2.4), 1500, 0.9);
    for seed in [125, 126] {
        measure_all(std::slice::from_ref(&cone), seed, false, |_, what, r| {
            if what.contains("random") {
                r.check(&format!("seed {seed}, {what}"));
            }
        });
    }
}

/// A ball in front of a wall 0.16 thick, about 2.5 point spacings: each side's nearest
/// neighbours include points of the other side.
fn ball_and_wall_sdf(p: DVec3) -> f64 {
    let wall = cuboid(p, DVec3::new(0.0, 0.0, -0.6), DVec3::new(1.0, 0.9, 0.08));
    let ball = (p - DVec3::new(0.1, 0.1, 0.3)).length() - 0.4;
    wall.min(ball)
}

/// The wall's two sides with normals of random sign. The orientation told two sides apart
/// only where both normals faced out, and joined them through pairs whose normals both
/// faced in (or the same way): the wall's back came out facing in, and splats stood out
/// past its rims (IoU 0.94–0.97). The sides are now told apart whatever the signs
/// (`stipple_core::normals::one_layer`), and every bound holds as with the normals given.
#[test]
fn a_wall_with_normals_of_random_sign_faces_out_on_both_sides() {
    let wall: Scene = (
        "wall",
        ball_and_wall_sdf,
        DVec3::new(0.7, 0.9, 2.6),
        2400,
        1.1,
    );
    for seed in [74, 75, 76] {
        measure_all(std::slice::from_ref(&wall), seed, false, |_, what, r| {
            if what.contains("random") {
                assert!((3.0..=6.0).contains(&r.spacing_px), "{r:?}");
                r.check(&format!("seed {seed}, {what}"));
            }
        });
    }
}

/// A box of half-sizes 0.85, 0.65 and 0.55 whose edges and corners are rounded to 0.15,
/// about two point spacings at the sparse sampling below.
fn rounded_box_sdf(p: DVec3) -> f64 {
    let q = p.abs() - DVec3::new(0.7, 0.5, 0.4);
    q.max(DVec3::ZERO).length() + q.max_element().min(0.0) - 0.15
}

/// Where a rounded box's flat faces turn into roundings two spacings across, its splats
/// stay inside the silhouette: the faces' flat splats and the roundings' bent ones had run
/// on to the tangent planes of neighbours 37° round and stuck out by a pixel all along the
/// outline (normals given: IoU 0.9881–0.9892 at these seeds); nearer neighbours' planes
/// now cut them where the surface is convex (`stipple_core::normals::CONVEX_CUT_COS`).
/// Without normals, a point whose neighbourhood runs from a face across its seam with a
/// rounding lies on no quadric, and was taken for a crease's and given a face's normal,
/// 5–11° off (seed 86: depth within 0.5% of the range on 0.944–0.948 of the pixels); a
/// cubic fits it, and it stays smooth (`stipple_core::normals::robust_normals`).
/// Every variant and mode.
#[test]
fn a_rounded_box_keeps_its_outline() {
    let rounded: Scene = (
        "rounded-box",
        rounded_box_sdf,
        DVec3::new(1.5, 1.3, 2.2),
        2000,
        0.95,
    );
    for seed in [82, 84, 86, 93] {
        measure_all(std::slice::from_ref(&rounded), seed, false, |_, what, r| {
            r.check(&format!("seed {seed}, {what}"))
        });
    }
}

/// An ellipsoid of semi-axes 1, 0.6 and 0.45 (first-order distance).
fn ellipsoid_sdf(p: DVec3) -> f64 {
    let r = DVec3::new(1.0, 0.6, 0.45);
    let k0 = (p / r).length();
    let k1 = (p / (r * r)).length();
    k0 * (k0 - 1.0) / k1
}

/// A capsule: a segment 1.2 long along x, radius 0.4.
fn capsule_sdf(p: DVec3) -> f64 {
    let x = p.x.clamp(-0.6, 0.6);
    (p - DVec3::new(x, 0.0, 0.0)).length() - 0.4
}

/// A torus in the xy plane whose tube (radius 0.2) is about two point spacings across its
/// radius: neighbours' normals differ by up to 45°, as across a crease.
fn thin_torus_sdf(p: DVec3) -> f64 {
    let q = ((p.x * p.x + p.y * p.y).sqrt() - 0.9, p.z);
    (q.0 * q.0 + q.1 * q.1).sqrt() - 0.2
}

/// A hexagonal prism (half-width 0.7 across flats, half-height 0.5) along z: edges of 120°.
fn hex_prism_sdf(p: DVec3) -> f64 {
    let k = DVec3::new(-0.866_025_4, 0.5, 0.577_35);
    let mut q = p.abs();
    let d = 2.0 * (k.x * q.x + k.y * q.y).min(0.0);
    q.x -= d * k.x;
    q.y -= d * k.y;
    let h = (0.7, 0.5);
    let dx = (q.x - q.x.clamp(-k.z * h.0, k.z * h.0), q.y - h.0);
    let d0 = (dx.0 * dx.0 + dx.1 * dx.1).sqrt() * (q.y - h.0).signum();
    let d1 = q.z - h.1;
    d0.max(d1).min(0.0) + (d0.max(0.0).powi(2) + d1.max(0.0).powi(2)).sqrt()
}

/// Curved surfaces, strongly curved at the point spacing (the thin torus: a tube two
/// spacings in radius), and a prism of obtuse edges, in every variant and mode: without
/// normals, a neighbourhood that a quadric fits is smooth however far its neighbours lie
/// off the tangent plane (`stipple_core::normals::robust_normals`), not a crease whose
/// faces would be fitted apart (thin torus: IoU 0.981, ellipsoid: 0.992 before). Voronoi
/// shades each cell with its point's normal (flat cells), so its normal error is not held
/// on the thin tube (median 5.4° with normals given).
#[test]
fn sparse_curved_surfaces_are_whole_and_accurate() {
    let scenes: [Scene; 4] = [
        (
            "ellipsoid",
            ellipsoid_sdf,
            DVec3::new(0.9, 1.1, 2.6),
            1400,
            1.05,
        ),
        (
            "capsule",
            capsule_sdf,
            DVec3::new(0.5, 1.3, 2.6),
            1400,
            1.05,
        ),
        (
            "thin-torus",
            thin_torus_sdf,
            DVec3::new(0.6, 1.3, 2.6),
            1500,
            1.15,
        ),
        (
            "hex-prism",
            hex_prism_sdf,
            DVec3::new(1.3, 1.5, 2.2),
            2000,
            0.9,
        ),
    ];
    measure_all(&scenes, 70, false, |name, what, r| {
        if name == "thin-torus" && what.contains("Voronoi") {
            r.check_shape(what);
        } else {
            r.check(what);
        }
    });
}

/// The thin torus sampled half as densely (750 points, about 5.4 px apart), without normals:
/// a point's neighbours have turned by up to 60° around the tube, where PCA's plane leans
/// and few neighbours lie within `CREASE_COS` of it. Points were taken for creases, and
/// splats left flat or tilted (`stipple_core::normals`: the closed quadric tried in the
/// frame its slope turns to, the wider fits of `refine_and_shape`). Twelve samples, three
/// modes: depth within 0.5% of the range 0.892 → 0.929 on average, the silhouette's IoU at
/// worst 0.982 → 0.992. The goals (0.95 on every sample) are not met at this density.
#[test]
fn a_sparser_thin_tube_without_normals_keeps_its_depth() {
    let scenes: [Scene; 1] = [(
        "thin-torus-sparser",
        thin_torus_sdf,
        DVec3::new(0.6, 1.3, 2.6),
        750,
        1.15,
    )];
    let got = std::sync::Mutex::new(Vec::new());
    for seed in 70..82 {
        measure_all(&scenes, seed, false, |_, what, r| {
            if what.contains("estimated") {
                got.lock().unwrap().push((r.depth_within, r.iou));
            }
        });
    }
    let got = got.into_inner().unwrap();
    let mean = got.iter().map(|g| g.0).sum::<f64>() / got.len() as f64;
    let iou = got.iter().map(|g| g.1).fold(1.0, f64::min);
    eprintln!("depth within 0.5%: mean {mean:.4}; IoU at worst {iou:.4}");
    assert!(mean >= 0.915 && iou >= 0.99, "{got:?}");
}

/// Two overlapping spheres (radius 0.6, centres 0.81 apart): a concave crease of 85°
/// between two convex faces.
fn two_spheres_sdf(p: DVec3) -> f64 {
    let a = (p - DVec3::new(0.4, 0.0, 0.0)).length() - 0.6;
    let b = (p - DVec3::new(-0.4, 0.1, 0.0)).length() - 0.6;
    a.min(b)
}

/// A union's concave crease without normals: a point beside it takes the face whose
/// quadric passes nearest it (`stipple_core::normals::robust_normals`); by the faces'
/// tangent planes alone, the other sphere's (which curve away from the point) looked
/// nearer, 1–2% of the points took it, and their splats stood in front of it (depth
/// within 0.5% on 0.937–0.950 of the pixels over three samples).
#[test]
fn sparse_union_keeps_its_concave_crease() {
    let scenes: [Scene; 1] = [(
        "two-spheres",
        two_spheres_sdf,
        DVec3::new(0.3, 1.0, 2.9),
        2200,
        1.1,
    )];
    measure_all(&scenes, 90, false, |_, what, r| r.check(what));
}

/// A wavy open sheet over the square [-0.9, 0.9]² (the top of a slab 0.01 thick).
fn sheet_sdf(p: DVec3) -> f64 {
    let h = 0.2 * (2.0 * p.x).sin() * (1.5 * p.z).cos();
    let top = (p.y - h) * 0.85;
    let bottom = (h - 0.01 - p.y) * 0.85;
    top.max(bottom).max(p.x.abs() - 0.9).max(p.z.abs() - 0.9)
}

/// A flat open disc of radius 0.9 (the top of a slab 0.01 thick).
fn disc_sdf(p: DVec3) -> f64 {
    p.y.max(-0.01 - p.y)
        .max(DVec3::new(p.x, 0.0, p.z).length() - 0.9)
}

/// The points of a thin slab's sample (`n` in all, edges skipped) on its top side: an
/// open sheet.
fn top_side(sdf: Sdf, n: usize, lim: f64, seed: u64) -> PointCloud {
    let both = sample_with(sdf, n, lim, seed, true);
    let normals = both.normals.as_ref().unwrap();
    let top: Vec<usize> = (0..both.len()).filter(|&i| normals[i].y > 0.3).collect();
    let pos: Vec<DVec3> = top.iter().map(|&i| both.world(i)).collect();
    let mut c = PointCloud::from_world(&pos);
    c.normals = Some(top.iter().map(|&i| normals[i]).collect());
    c
}

/// Open surfaces: only the top of each thin slab is sampled, so the cloud ends at a rim.
/// A splat there must stop just beyond the rim its neighbours trace
/// (`stipple_core::normals::boundary_planes`) instead of reaching a whole radius past the
/// surface's end (IoU 0.90–0.94 over five samples before; 0.95–0.98 now). The rim of a
/// random sample cannot be placed closer than its gaps between points (half the error left
/// is a chord across a gap in the rim), so IoU is held at 0.945 here, not 0.99.
#[test]
fn open_sheets_end_at_their_rims() {
    let scenes: [Scene; 2] = [
        ("sheet", sheet_sdf, DVec3::new(0.5, 2.2, 2.0), 1800, 1.0),
        ("disc", disc_sdf, DVec3::new(0.5, 2.2, 2.0), 1400, 1.0),
    ];
    for (k, &(name, sdf, eye, n, lim)) in scenes.iter().enumerate() {
        let cam = camera(eye, 256);
        let c = top_side(sdf, n, lim, 110 + k as u64);
        for ((what, cloud), mode) in modes(variants(&c, 120 + k as u64)) {
            let r = measure(
                &format!("splat-open-{name}-{what}-{mode:?}"),
                &cam,
                sdf,
                cloud,
                mode,
            );
            assert!((3.0..=6.0).contains(&r.spacing_px), "{name}: {r:?}");
            let what = format!("open {name}, normals {what}, {mode:?}");
            eprintln!("{what}: IoU {:.4}", r.iou);
            assert!(r.iou >= 0.945, "{what}: {r:?}");
            Report { iou: 1.0, ..r }.check(&what);
        }
    }
}

/// A flat open square (the top of a slab 0.01 thick).
fn square_sdf(p: DVec3) -> f64 {
    p.y.max(-0.01 - p.y)
        .max(p.x.abs() - 0.9)
        .max(p.z.abs() - 0.9)
}

/// A random sample leaves holes wider than the splats' radius (0.6 × the 16th neighbour's
/// distance): on this square, one about 16 px across (6 spacings) showed the background
/// through, in every mode and variant. The splats around such a hole grow to reach its
/// centre (`stipple_core::normals::shapes`).
#[test]
fn holes_in_a_random_sample_are_covered() {
    let cam = camera(DVec3::new(0.5, 2.2, 2.0), 256);
    let c = top_side(square_sdf, 2600, 1.0, 70);
    for ((what, cloud), mode) in modes(variants(&c, 80)) {
        let r = measure(
            &format!("splat-holes-{what}-{mode:?}"),
            &cam,
            square_sdf,
            cloud,
            mode,
        );
        assert!((2.5..=6.0).contains(&r.spacing_px), "{r:?}");
        assert_eq!(r.holes, 0, "normals {what}, {mode:?}: {r:?}");
    }
}

/// Random views of the basic shapes (a sphere, a torus, a box and a cylinder, normals
/// given, estimated and of random sign; default settings): the eye in a random direction,
/// the sample thinned to 30–100% (3–7.3 px apart). View `v` of shape `s` is the same on every
/// run. Fixed views along the axes hid two defects these views found: splats of points on
/// a box's or cylinder's edge whose normals are the faces' mean rose in front of one face
/// (box view 4: IoU 0.989; `stipple_core::normals::shapes`' planes where a splat stops
/// following its face), and cap splats past a curved rim (cylinder view 4: 0.988; clip
/// planes bent into the rim), and the box of view 2 (5.3 px apart) without normals, whose
/// far faces showed through 2.2% of it (front points a fraction of a spacing from an edge
/// took the other face's normal; `stipple_core::normals` now measures a flat face's offset
/// from the plane through its members).
#[test]
fn random_views_of_basic_shapes() {
    let shapes: [(&str, Sdf, usize, f64, f64); 4] = [
        ("sphere", sphere_sdf, 2000, 1.05, 3.3),
        ("torus", torus_sdf, 2700, 1.45, 3.6),
        ("box", box_sdf, 3600, 0.85, 3.4),
        ("cylinder", cylinder_sdf, 1800, 0.8, 3.0),
    ];
    for v in 0u64..6 {
        for (si, &(name, sdf, n, lim, dist)) in shapes.iter().enumerate() {
            let (cam, cloud) = random_view(sdf, n, lim, dist, 500 + v, si as u64);
            for (what, cloud) in variants(&cloud, 507 + v) {
                let r = measure(
                    &format!("random-view-{name}-{v}-{what}"),
                    &cam,
                    sdf,
                    cloud,
                    SplatMode::Blend,
                );
                assert!((3.0..=7.5).contains(&r.spacing_px), "{name} {v}: {r:?}");
                r.check(&format!("{name}, view {v}, normals {what}"));
            }
        }
    }
}

/// Later views of the same sweep whose sparse edges failed without normals: a box (view
/// 11: depth within 0.5% of the range on 94.4% of the pixels) whose points beside an edge
/// took the other face's normal; a cylinder (view 17: 0.937) whose side points just below
/// the rim took the cap's plane (the cap's members, a band along the rim, now count as
/// flat); and a box and a cylinder (views 21 and 20: IoU 0.988, and 0.990, 0.989 with the
/// first fix alone) where a point 0.05 from the edge had none of the other face's points
/// among its neighbours, and its splat stood past the edge uncut (its neighbours nearer the
/// edge now lend it that face's plane); and a box (view 16, 5.5 px apart: IoU 0.9896) whose
/// points by a corner had neighbours on their face with normals blended of two or three
/// faces, none of them the face's plane (planes through a point and two neighbours are now
/// candidates of the re-fit, `stipple_core::normals`).
#[test]
fn random_views_with_sparse_edges_without_normals() {
    for (name, sdf, n, lim, dist, v, si) in [
        ("box", box_sdf as Sdf, 3600, 0.85, 3.4, 11, 2),
        ("box", box_sdf, 3600, 0.85, 3.4, 16, 2),
        ("box", box_sdf, 3600, 0.85, 3.4, 21, 2),
        ("cylinder", cylinder_sdf, 1800, 0.8, 3.0, 17, 3),
        ("cylinder", cylinder_sdf, 1800, 0.8, 3.0, 20, 3),
    ] {
        let (cam, cloud) = random_view(sdf, n, lim, dist, 500 + v, si);
        let [_, (what, cloud), _] = variants(&cloud, 507 + v);
        let r = measure(
            &format!("random-view-{name}-{v}-{what}"),
            &cam,
            sdf,
            cloud,
            SplatMode::Blend,
        );
        r.check(&format!("{name}, view {v}, normals {what}"));
    }
}

/// View `v`'s camera on shape `si` (the eye `dist` from the centre in a random direction)
/// and its sample of `n` points thinned to a random 30–100%.
fn random_view(sdf: Sdf, n: usize, lim: f64, dist: f64, v: u64, si: u64) -> (Camera, PointCloud) {
    random_view_of(sdf, n, lim, dist, 500, v - 500, si)
}

/// [`random_view`] of sweep `seed` (the sweeps of `BENCHMARKS.md`: views 0–29 of seeds 1000
/// and 2000): view `v` of shape `si`.
fn random_view_of(
    sdf: Sdf,
    n: usize,
    lim: f64,
    dist: f64,
    seed: u64,
    v: u64,
    si: u64,
) -> (Camera, PointCloud) {
    let mut r = Rng::new((seed + v) * 8 + si);
    let dir = loop {
        let d = DVec3::new(
            r.f64() * 2.0 - 1.0,
            r.f64() * 2.0 - 1.0,
            r.f64() * 2.0 - 1.0,
        );
        if d.length() > 0.2 && d.length() < 1.0 && d.normalize().y.abs() < 0.97 {
            break d.normalize();
        }
    };
    let frac = 0.3 + 0.7 * r.f64();
    let cam = camera(dir * dist, 256);
    let cloud = sample_with(sdf, (n as f64 * frac) as usize, lim, seed * 31 + v, false);
    (cam, cloud)
}

/// A cylinder with its normals (given, or of random sign) from two random views whose cap
/// splats stuck out past the rim (IoU 0.9894 and 0.9897): the first clip plane was a rim
/// point's own (its normal between cap and side), the second the side's, left straight, so
/// the splat reached past the rim at both ends of that chord. Both planes are now bent into
/// the rim's circle (`stipple_core::normals::shapes`).
#[test]
fn a_cylinder_with_normals_keeps_its_rim_from_random_views() {
    for (seed, v) in [(1000, 3), (2000, 20)] {
        let (cam, cloud) = random_view_of(cylinder_sdf, 1800, 0.8, 3.0, seed, v, 3);
        for (what, cloud) in variants(&cloud, seed + v + 7) {
            if what == "estimated" {
                continue;
            }
            let r = measure(
                &format!("random-view-cylinder-{seed}-{v}-{what}"),
                &cam,
                cylinder_sdf,
                cloud,
                SplatMode::Blend,
            );
            r.check(&format!("cylinder, sweep {seed} view {v}, normals {what}"));
        }
    }
}

/// Pixels left to no splat inside one surface: background, with two opposite neighbours
/// covered at depths within a thousandth of each other (`passes::splat::cpu::fill_pinholes`
/// fills them; its ε is wider).
fn cracks(f: &stipple_render::Frame, w: usize, h: usize) -> usize {
    let on = |k: usize| f.id[k] != BACKGROUND;
    let pair = |a: usize, b: usize| {
        on(a) && on(b) && (f.depth[a] - f.depth[b]).abs() <= 1e-3 * f.depth[a].abs()
    };
    (1..h - 1)
        .flat_map(|y| (1..w - 1).map(move |x| y * w + x))
        .filter(|&k| !on(k) && (pair(k - w, k + w) || pair(k - 1, k + 1)))
        .count()
}

/// The Stanford Armadillo's vertices with the mesh's normals (random signs), as the default
/// render draws them: splats cut by clip planes that meet along a line left the pixels on
/// it to neither (78 pinholes at 1024²; here 31 cracks one pixel wide). Now they are closed
/// on both backends, and the backends cover the same pixels.
#[test]
fn a_real_scan_s_splats_leave_no_crack_on_either_backend() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let file = dir.join("stanford/armadillo/Armadillo_38k_normals.ply");
    if !file.is_file() {
        eprintln!("skipped: {} is absent", file.display());
        return;
    }
    let cloud = stipple_io::read_cloud(&file).unwrap();
    let (lo, hi) = cloud.world_bounds();
    let size = 768;
    let mut cam = Camera::framing(lo, hi, size, size, 45.0);
    let dist = (cam.eye - cam.target).length();
    cam.eye = cam.target + DVec3::new(-0.4, 0.3, -0.87).normalize() * dist;
    cam.fit_clip(lo, hi);
    let mut p = PreparedCloud::new(cloud);
    p.prepare_surface(16, true).unwrap();
    let (w, h) = (size as usize, size as usize);
    let mut gpu = common::gpu();
    for mode in [SplatMode::Blend, SplatMode::Voronoi, SplatMode::Deferred] {
        let pipe = Pipeline::splats(SplatSettings {
            mode,
            ..Default::default()
        });
        let a = render(&p, &cam, &pipe, Backend::Cpu).unwrap();
        let covered = a.id.iter().filter(|&&i| i != BACKGROUND).count();
        assert!(
            covered > w * h / 10,
            "the frame shows the armadillo: {covered}"
        );
        // 31 without the fill (blend); a crack beside a filled one (two wide, one across)
        // may stay.
        let open = cracks(&a, w, h);
        assert!(open <= 3, "cpu, {mode:?}: {open} cracks");
        let Some(r) = gpu.as_mut() else { continue };
        let b = r.render(&p, &cam, &pipe).unwrap();
        let open = cracks(&b, w, h);
        assert!(open <= 3, "gpu, {mode:?}: {open} cracks");
        let differ =
            a.id.iter()
                .zip(&b.id)
                .filter(|(x, y)| (**x == BACKGROUND) != (**y == BACKGROUND))
                .count();
        assert!(
            differ <= covered / 1000,
            "{mode:?}: coverage differs on {differ} of {covered} pixels"
        );
    }
}
