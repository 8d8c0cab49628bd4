//! Translucent shadow maps (Gunjee §4.1, see `stipple_render::translucent`) on scenes with
//! known answers, on the CPU and (where an adapter exists; required with
//! STIPPLE_REQUIRE_GPU=1) the GPU, and their parity.

mod common;

use glam::Vec3;
use stipple_core::PointCloud;
use stipple_render::shadow::ShadowSettings;
use stipple_render::{alpha8, Light, LitTexture, PreparedCloud, Renderer};

/// A plane (opaque) under a sphere shell of opacity `alpha`; returns the cloud and the
/// number of plane points (they come first).
fn shell_over_plane(alpha: f32, centre: Vec3, radius: f32) -> (PreparedCloud, usize) {
    let pp = common::jittered_square(400_000, 4.0, 0.0, 3);
    let (sp, sn) = common::sphere(150_000, centre, radius, 4);
    let mut c = PointCloud::default();
    let np = pp.len();
    c.normals = Some(
        std::iter::repeat_n(Vec3::Z, np)
            .chain(sn.iter().copied())
            .collect(),
    );
    c.opacity = Some(
        std::iter::repeat_n(1.0, np)
            .chain(std::iter::repeat_n(alpha, sp.len()))
            .collect(),
    );
    c.positions = pp.into_iter().chain(sp).collect();
    (PreparedCloud::new(c), np)
}

fn shadows(r: &mut Renderer, c: &PreparedCloud, light: Vec3) -> LitTexture {
    let light = Light::Point(light.as_dvec3().to_array());
    r.shadow_texture(
        c,
        &[light],
        &ShadowSettings::default(),
        None,
        1,
        &mut |_, _| {},
    )
    .unwrap()
}

/// The mean lit value of light 0 over the points `which` selects.
fn mean_lit(lit: &LitTexture, which: impl Iterator<Item = usize>) -> (f64, usize) {
    let (mut sum, mut n) = (0.0, 0);
    for i in which {
        sum += lit.value(i, 0) as f64;
        n += 1;
    }
    (sum / n.max(1) as f64, n)
}

/// Where the ray from `light` through `p` meets the plane z = 0.
fn on_floor(light: Vec3, p: Vec3) -> Vec3 {
    let t = light.z / (light.z - p.z);
    light + (p - light) * t
}

#[test]
fn a_translucent_shell_lets_one_minus_alpha_squared_through() {
    let (centre, radius) = (Vec3::new(0.1, -0.2, 1.2), 0.5);
    let light = Vec3::new(0.3, 0.1, 4.0);
    // The shadow's centre on the floor and a radius well inside it (the shadow of a sphere
    // seen from a point light is at least as wide as the sphere's own).
    let core = on_floor(light, centre);
    let core_r = 0.5 * radius;
    let mut per_backend: Vec<Vec<LitTexture>> = Vec::new();
    for mut r in common::backends() {
        let mut lits = Vec::new();
        for alpha in [0.3f32, 0.5, 0.8, 1.0] {
            let (c, np) = shell_over_plane(alpha, centre, radius);
            let pos = &c.cloud.positions;
            let lit = shadows(&mut r, &c, light);
            let a = alpha8(alpha) as f64 / 255.0;
            let want = (1.0 - a) * (1.0 - a);
            let (core_m, n) =
                mean_lit(&lit, (0..np).filter(|&i| (pos[i] - core).length() < core_r));
            assert!(n > 1000, "{n} floor points in the core");
            assert!(
                (core_m - want).abs() <= 0.02,
                "{}: α {alpha}: the shadow's core gets {core_m:.4} of the light, (1 − α)² = {want:.4}",
                r.describe()
            );
            // Every core point, not only on average (no specks of full light or full shadow).
            let worst = (0..np)
                .filter(|&i| (pos[i] - core).length() < core_r)
                .map(|i| (lit.value(i, 0) as f64 - want).abs())
                .fold(0.0, f64::max);
            assert!(
                worst <= 0.05,
                "{}: α {alpha}: a core point is {worst:.3} off (1 − α)²",
                r.describe()
            );
            // The floor outside the shadow is lit in full.
            let (open, n) = mean_lit(
                &lit,
                (0..np).filter(|&i| {
                    let p = pos[i];
                    (p - core).length() > 3.0 * radius && p.x.abs() < 1.8 && p.y.abs() < 1.8
                }),
            );
            assert!(
                n > 1000 && open > 0.999,
                "{}: open floor {open:.4}",
                r.describe()
            );
            // The shell's wall facing the light is lit in full; the far wall's inside gets
            // what the near wall lets through (1 − α), measured where the ray from the light
            // crosses the near wall well inside the silhouette.
            let axis = (centre - light).normalize();
            let near_cap =
                (np..pos.len()).filter(|&i| (pos[i] - centre).normalize().dot(axis) < -0.9);
            let far_cap =
                (np..pos.len()).filter(|&i| (pos[i] - centre).normalize().dot(axis) > 0.9);
            let (near_m, _) = mean_lit(&lit, near_cap);
            let (far_m, _) = mean_lit(&lit, far_cap);
            assert!(
                near_m > 0.99,
                "{}: α {alpha}: near cap {near_m:.4}",
                r.describe()
            );
            assert!(
                (far_m - (1.0 - a)).abs() <= 0.02,
                "{}: α {alpha}: far cap {far_m:.4}, 1 − α = {:.4}",
                r.describe(),
                1.0 - a
            );
            eprintln!(
                "{}: α {alpha}: core {core_m:.4} (want {want:.4}, worst {worst:.3}), far cap {far_m:.4}",
                r.describe()
            );
            lits.push(lit);
        }
        per_backend.push(lits);
    }
    if let [cpu, gpu] = &per_backend[..] {
        for (a, b) in cpu.iter().zip(gpu) {
            let differ = a
                .counts
                .iter()
                .zip(&b.counts)
                .filter(|(x, y)| x != y)
                .count();
            assert!(
                differ as f64 <= 1e-3 * a.counts.len() as f64,
                "translucent shadow parity: {differ} of {} points differ",
                a.counts.len()
            );
        }
    }
}

#[test]
fn a_light_inside_a_translucent_sphere_lights_it_and_dims_the_world_outside() {
    let (centre, radius) = (Vec3::new(0.0, 0.0, 1.2), 0.5);
    for mut r in common::backends() {
        for alpha in [0.4f32, 1.0] {
            let (c, np) = shell_over_plane(alpha, centre, radius);
            let pos = &c.cloud.positions;
            // Off-centre inside the sphere: a cube of light views.
            let light = centre + Vec3::new(0.1, 0.05, -0.1);
            let lit = shadows(&mut r, &c, light);
            let a = alpha8(alpha) as f64 / 255.0;
            let (inside, _) = mean_lit(&lit, np..pos.len());
            assert!(
                inside > 0.99,
                "{}: α {alpha}: the sphere's inside gets {inside:.4}",
                r.describe()
            );
            let (floor, n) = mean_lit(
                &lit,
                (0..np).filter(|&i| pos[i].x.abs() < 1.5 && pos[i].y.abs() < 1.5),
            );
            assert!(n > 10_000);
            // Nowhere does light pass the wall in full, nor is a floor point left dark
            // (but for a few at the cube's corners, where light pixels are finest).
            let off = (0..np)
                .filter(|&i| pos[i].x.abs() < 1.5 && pos[i].y.abs() < 1.5)
                .filter(|&i| (lit.value(i, 0) as f64 - (1.0 - a)).abs() > 0.05)
                .count();
            assert!(
                off * 1000 < n,
                "{}: α {alpha}: {off} of {n} floor points are not lit by 1 − α",
                r.describe()
            );
            assert!(
                (floor - (1.0 - a)).abs() <= 0.02,
                "{}: α {alpha}: the floor gets {floor:.4}, 1 − α = {:.4}",
                r.describe(),
                1.0 - a
            );
            eprintln!(
                "{}: α {alpha}: inside {inside:.4}, floor {floor:.4}",
                r.describe()
            );
        }
    }
}

/// A coloured translucent shell over a white floor under a point light casts a shadow of its
/// colour: each channel of the core gets (1 − α)^(2 w_c) of the light, with w the weights of
/// the shell's colour (`translucent::weights`), the far wall's inside (1 − α)^(w_c); an
/// opaque shell of the same colour passes nothing. Both backends agree on the sums, and a
/// frame shows the shadow tinted (red over green) where a grey shell's is neutral.
#[test]
fn a_coloured_shell_casts_a_shadow_of_its_colour() {
    use stipple_core::{Camera, Projection};
    use stipple_render::translucent::weights;
    let (centre, radius) = (Vec3::new(0.1, -0.2, 1.2), 0.5);
    let light = Vec3::new(0.3, 0.1, 4.0);
    let core = on_floor(light, centre);
    let core_r = 0.5 * radius;
    let red = [230u8, 60, 40];
    let coloured = |alpha: f32, colour: [u8; 3]| {
        let (mut c, np) = shell_over_plane(alpha, centre, radius);
        let n = c.cloud.len();
        c.cloud.colors = Some(
            (0..n)
                .map(|i| if i < np { [255; 3] } else { colour })
                .collect(),
        );
        (PreparedCloud::new(c.cloud), np)
    };
    let cam = Camera {
        eye: (core + Vec3::new(0.0, 0.0, 3.0)).as_dvec3(),
        target: core.as_dvec3(),
        up: glam::DVec3::Y,
        projection: Projection::Perspective { fov_deg: 20.0 },
        width: 64,
        height: 64,
        near: 0.5,
        far: 20.0,
    };
    let pipe = stipple_render::Pipeline {
        lights: vec![Light::Point(light.as_dvec3().to_array())],
        ..stipple_render::Pipeline::default()
    };
    let mut per_backend = Vec::new();
    for mut r in common::backends() {
        let (c, np) = coloured(0.5, red);
        let pos = c.cloud.positions.clone();
        let lit = shadows(&mut r, &c, light);
        assert!(lit.rb.is_some(), "{}: a coloured texture", r.describe());
        let a = alpha8(0.5) as f64 / 255.0;
        let w = weights(red);
        let core_pts: Vec<usize> = (0..np)
            .filter(|&i| (pos[i] - core).length() < core_r)
            .collect();
        let axis = (centre - light).normalize();
        let far_cap: Vec<usize> = (np..pos.len())
            .filter(|&i| (pos[i] - centre).normalize().dot(axis) > 0.9)
            .collect();
        for ch in 0..3 {
            let mean = |pts: &[usize]| {
                pts.iter()
                    .map(|&i| lit.value_rgb(i, 0)[ch] as f64)
                    .sum::<f64>()
                    / pts.len() as f64
            };
            let want = (1.0 - a).powf(2.0 * w[ch] as f64);
            let got = mean(&core_pts);
            assert!(
                (got - want).abs() <= 0.02,
                "{}: channel {ch}: the core gets {got:.4}, (1 − α)^(2 w) = {want:.4}",
                r.describe()
            );
            let want_far = (1.0 - a).powf(w[ch] as f64);
            let got_far = mean(&far_cap);
            assert!(
                (got_far - want_far).abs() <= 0.02,
                "{}: channel {ch}: the far cap gets {got_far:.4}, want {want_far:.4}",
                r.describe()
            );
        }
        // An opaque shell of the same colour: nothing in any channel.
        let (opaque, _) = coloured(1.0, red);
        let dark = shadows(&mut r, &opaque, light);
        let worst = core_pts
            .iter()
            .flat_map(|&i| dark.value_rgb(i, 0))
            .fold(0.0f32, f32::max);
        assert!(
            worst <= 0.01,
            "{}: an opaque shell passes {worst}",
            r.describe()
        );
        // The frame of the floor alone with its shadow: red-tinted, and a grey shell's not.
        let floor = |c: &PreparedCloud, lit: &LitTexture| {
            let mut f = c.cloud.clone();
            f.positions.truncate(np);
            f.normals.as_mut().unwrap().truncate(np);
            f.colors.as_mut().unwrap().truncate(np);
            f.opacity = None;
            let mut f = PreparedCloud::new(f);
            f.set_lit(Some(LitTexture {
                counts: lit.counts[..np].to_vec(),
                samples: lit.samples,
                rb: lit.rb.as_ref().map(|rb| rb[..np].to_vec()),
            }))
            .unwrap();
            f
        };
        let f = r.render(&floor(&c, &lit), &cam, &pipe).unwrap();
        let px = f.rgba[(32 * 64 + 32) * 4..][..3].to_vec();
        assert!(
            px[0] as i32 > px[1] as i32 + 40 && (px[1] as i32 - px[2] as i32).abs() < 20,
            "{}: the shadow's centre is {px:?}",
            r.describe()
        );
        let (grey, _) = coloured(0.5, [128, 128, 128]);
        let glit = shadows(&mut r, &grey, light);
        assert!(glit.rb.is_none(), "a grey shell's texture stays grey");
        let g = r.render(&floor(&grey, &glit), &cam, &pipe).unwrap();
        let gp = &g.rgba[(32 * 64 + 32) * 4..][..3];
        assert!(
            (gp[0] as i32 - gp[1] as i32).abs() <= 2,
            "{}: a grey shell's shadow is {gp:?}",
            r.describe()
        );
        eprintln!(
            "{}: coloured shadow pixel {px:?}, grey {gp:?}",
            r.describe()
        );
        per_backend.push((lit, f));
    }
    if let [(a, fa), (b, fb)] = &per_backend[..] {
        let (ra, rb) = (a.rb.as_ref().unwrap(), b.rb.as_ref().unwrap());
        let differ = (0..a.counts.len())
            .filter(|&i| a.counts[i] != b.counts[i] || ra[i] != rb[i])
            .count();
        assert!(
            differ as f64 <= 1e-3 * a.counts.len() as f64,
            "coloured shadow parity: {differ} of {} points differ",
            a.counts.len()
        );
        let off = fa
            .rgba
            .chunks(4)
            .zip(fb.rgba.chunks(4))
            .filter(|(x, y)| (0..3).any(|i| (x[i] as i32 - y[i] as i32).abs() > 2))
            .count();
        assert!(off <= 8, "coloured shadow frames: {off} pixels differ");
    }
}

/// Sorted splats shade per point: a coloured shadow texture tints them as it tints pixels,
/// the same on both backends (a small scene: a floor under a red translucent ball; one
/// texture for both, since splats of one slice may blend in either order, and the frames
/// compared in blocks and by the shadow's mean colour).
#[test]
fn sorted_splats_show_coloured_shadows_on_both_backends() {
    use stipple_core::{Camera, Projection};
    use stipple_render::{Pipeline, SplatMode, SplatSettings};
    let floor = common::jittered_square(40_000, 2.0, 0.0, 9);
    let (ball, bn) = common::sphere(30_000, Vec3::new(0.0, 0.0, 0.8), 0.35, 5);
    let np = floor.len();
    let c = PointCloud {
        normals: Some(std::iter::repeat_n(Vec3::Z, np).chain(bn).collect()),
        colors: Some(
            std::iter::repeat_n([255; 3], np)
                .chain(std::iter::repeat_n([230, 60, 40], ball.len()))
                .collect(),
        ),
        opacity: Some(
            std::iter::repeat_n(1.0, np)
                .chain(std::iter::repeat_n(0.5, ball.len()))
                .collect(),
        ),
        positions: floor.into_iter().chain(ball).collect(),
        ..Default::default()
    };
    let light = Vec3::new(0.0, 0.0, 3.0);
    let lit = shadows(&mut common::cpu(), &PreparedCloud::new(c.clone()), light);
    assert!(lit.rb.is_some());
    // The floor alone, seen from above: the ball's shadow in the middle.
    let mut f = c.clone();
    f.positions.truncate(np);
    f.normals.as_mut().unwrap().truncate(np);
    f.colors.as_mut().unwrap().truncate(np);
    f.opacity = None;
    let mut f = PreparedCloud::new(f);
    f.set_lit(Some(LitTexture {
        counts: lit.counts[..np].to_vec(),
        samples: lit.samples,
        rb: lit.rb.as_ref().map(|rb| rb[..np].to_vec()),
    }))
    .unwrap();
    let cam = Camera {
        eye: glam::DVec3::new(0.0, -0.01, 2.5),
        target: glam::DVec3::ZERO,
        up: glam::DVec3::Y,
        projection: Projection::Perspective { fov_deg: 30.0 },
        width: 48,
        height: 48,
        near: 0.5,
        far: 20.0,
    };
    let pipe = Pipeline {
        lights: vec![Light::Point(light.as_dvec3().to_array())],
        ..Pipeline::splats(SplatSettings {
            mode: SplatMode::Sorted,
            ..SplatSettings::default()
        })
    };
    let mut frames = Vec::new();
    for mut r in common::backends() {
        let frame = r.render(&f, &cam, &pipe).unwrap();
        // The shadow's middle (8 × 8 pixels) and the open floor at a corner.
        let mean = |x0: usize, y0: usize| -> [f64; 3] {
            let mut m = [0.0; 3];
            for y in y0..y0 + 8 {
                for x in x0..x0 + 8 {
                    for (c, m) in m.iter_mut().enumerate() {
                        *m += frame.rgba[(y * 48 + x) * 4 + c] as f64 / 64.0;
                    }
                }
            }
            m
        };
        let (shadow, open) = (mean(20, 20), mean(2, 2));
        assert!(
            shadow[0] > shadow[1] + 30.0 && (open[0] - open[1]).abs() <= 2.0,
            "{}: shadow {shadow:?}, open floor {open:?}",
            r.describe()
        );
        frames.push((frame, shadow));
    }
    if let [(a, sa), (b, sb)] = &frames[..] {
        // Splats of one slice blend in either order (per-point lit values differ a little
        // within a slice), so pixels are compared in 8 × 8 blocks: every block's mean colour
        // within 8 levels (the floor's rim against the background moves most), the shadow's
        // within 2.
        let block = |f: &stipple_render::Frame, bx: usize, by: usize, c: usize| {
            let mut m = 0.0;
            for y in 8 * by..8 * by + 8 {
                for x in 8 * bx..8 * bx + 8 {
                    m += f.rgba[(y * 48 + x) * 4 + c] as f64 / 64.0;
                }
            }
            m
        };
        for by in 0..6 {
            for bx in 0..6 {
                for c in 0..3 {
                    let (p, q) = (block(a, bx, by, c), block(b, bx, by, c));
                    assert!(
                        (p - q).abs() <= 8.0,
                        "block ({bx}, {by}) channel {c}: {p:.1} (CPU) vs {q:.1} (GPU)"
                    );
                }
            }
        }
        for c in 0..3 {
            assert!(
                (sa[c] - sb[c]).abs() <= 2.0,
                "shadow means {sa:?} vs {sb:?}"
            );
        }
    }
}
