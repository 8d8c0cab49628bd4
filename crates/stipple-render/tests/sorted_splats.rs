//! Sorted Gaussian splats (Gunjee §4.2, `--splat sorted`): nearer surfaces cover farther
//! ones whatever the points' order in the cloud, a closed surface comes out with the
//! silhouette and depth of the blending splats, a translucent surface lets 1 − α through,
//! and the GPU (where an adapter exists; required with STIPPLE_REQUIRE_GPU=1) draws the
//! CPU's images.

mod common;

use glam::{DVec3, Vec3};
use stipple_core::{Camera, PointCloud, Projection};
use stipple_render::{Pipeline, PreparedCloud, SplatMode, SplatSettings, BACKGROUND};

fn camera(size: u32) -> Camera {
    Camera {
        eye: DVec3::new(0.2, 0.3, 4.0),
        target: DVec3::ZERO,
        up: DVec3::Y,
        projection: Projection::Perspective { fov_deg: 35.0 },
        width: size,
        height: size,
        near: 0.5,
        far: 20.0,
    }
}

fn sorted() -> Pipeline {
    Pipeline::splats(SplatSettings {
        mode: SplatMode::Sorted,
        ..SplatSettings::default()
    })
}

/// A jittered square of side 2 at depth z (normal +z), `k`² points.
fn square(k: usize, z: f32, seed: u64) -> Vec<Vec3> {
    common::jittered_square(k * k, 2.0, z, seed)
}

#[test]
fn nearer_surfaces_cover_farther_ones_whatever_the_cloud_order() {
    let cam = camera(128);
    let mut r = common::cpu();
    // Green at z = 0.5 and red at z = 0; then the same with the planes' depths swapped. The
    // near plane comes first in the cloud both times, so only the sort can get it right.
    for (green_z, red_z, want_green) in [(0.5, 0.0, true), (0.0, 0.5, false)] {
        let (g, red) = (square(200, green_z, 1), square(200, red_z, 2));
        let (first, second, first_green) = if green_z > red_z {
            (g, red, true)
        } else {
            (red, g, false)
        };
        let colour = |green: bool| {
            if green {
                [40u8, 200, 60]
            } else {
                [210, 40, 40]
            }
        };
        let n = first.len();
        let mut c = PointCloud {
            positions: first.into_iter().chain(second).collect(),
            ..Default::default()
        };
        c.colors = Some(
            std::iter::repeat_n(colour(first_green), n)
                .chain(std::iter::repeat_n(colour(!first_green), n))
                .collect(),
        );
        c.normals = Some(vec![Vec3::Z; 2 * n]);
        let pipe = Pipeline {
            lighting: false,
            ..sorted()
        };
        let f = r.render(&PreparedCloud::new(c), &cam, &pipe).unwrap();
        let k = (64 * 128 + 64) * 4;
        let px = &f.rgba[k..k + 3];
        if want_green {
            assert!(px[1] > 180 && px[0] < 80, "green in front: {px:?}");
        } else {
            assert!(px[0] > 190 && px[1] < 80, "red in front: {px:?}");
        }
    }
}

#[test]
fn a_closed_surface_has_the_silhouette_and_depth_of_blending_splats() {
    let cam = camera(160);
    let (p, n) = common::sphere(60_000, Vec3::ZERO, 1.0, 5);
    let c = PreparedCloud::new(PointCloud {
        positions: p,
        normals: Some(n),
        ..Default::default()
    });
    let mut r = common::cpu();
    let s = r.render(&c, &cam, &sorted()).unwrap();
    let b = r
        .render(&c, &cam, &Pipeline::splats(SplatSettings::default()))
        .unwrap();
    let (mut inter, mut union) = (0, 0);
    let mut errs = Vec::new();
    for k in 0..s.id.len() {
        let (a, bb) = (s.id[k] != BACKGROUND, b.id[k] != BACKGROUND);
        inter += (a && bb) as u32;
        union += (a || bb) as u32;
        if a && bb {
            errs.push(((s.depth[k] - b.depth[k]) / b.depth[k]).abs());
        }
    }
    let iou = inter as f64 / union as f64;
    errs.sort_by(f32::total_cmp);
    let median = errs[errs.len() / 2];
    assert!(iou > 0.97, "silhouette IoU {iou}");
    assert!(median < 0.005, "median relative depth difference {median}");
    // The sphere is lit: brighter towards the headlight than at its rim.
    let at = |x: usize, y: usize| s.rgba[(y * 160 + x) * 4] as i32;
    assert!(at(80, 80) > at(80, 80 + 35) + 10);
    // The GPU twin draws the same image (within a slice the two orders may differ).
    if let Some(mut g) = common::gpu() {
        let gf = g.render(&c, &cam, &sorted()).unwrap();
        // A second frame reuses the sort's buffers (made once per cloud): the same image.
        let again = g.render(&c, &cam, &sorted()).unwrap();
        let same = common::agreeing(&gf.rgba, &again.rgba, 1);
        assert!(
            same >= 0.999,
            "second GPU frame: {same} of pixels within a level"
        );
        let agree = common::agreeing(&s.rgba, &gf.rgba, 2);
        assert!(
            agree >= 0.995,
            "{}: {agree} of pixels within 2 levels",
            g.describe()
        );
        // Depths: the nearest splat weighing enough, which within a slice may be another.
        let close = s
            .depth
            .iter()
            .zip(&gf.depth)
            .filter(|(a, b)| a == b || (*a - *b).abs() <= 0.01 * a.abs())
            .count();
        assert!(
            close as f64 >= 0.99 * s.depth.len() as f64,
            "depths: {close} of {} agree",
            s.depth.len()
        );
    }
}

#[test]
fn a_translucent_surface_lets_one_minus_alpha_through_whatever_its_density() {
    let cam = camera(128);
    let mut r = common::cpu();
    let lut = stipple_render::passes::shade::cpu::srgb_to_linear_table();
    for (k, alpha, random) in [
        (150usize, 0.5f32, false),
        (300, 0.5, false),
        (250, 0.3, false),
        (250, 0.5, true),
    ] {
        let p = if random {
            // Uniform random points, not a jittered grid.
            let mut rng = stipple_core::rng::Rng::new(9);
            (0..k * k)
                .map(|_| Vec3::new(rng.f32() * 2.0 - 1.0, rng.f32() * 2.0 - 1.0, 0.0))
                .collect()
        } else {
            square(k, 0.0, 7)
        };
        let n = p.len();
        let c = PointCloud {
            positions: p,
            normals: Some(vec![Vec3::Z; n]),
            colors: Some(vec![[40, 90, 220]; n]),
            opacity: Some(vec![alpha; n]),
            ..Default::default()
        };
        let pipe = Pipeline {
            lighting: false,
            background: [250, 250, 250],
            colour: vec![],
            ..sorted()
        };
        // Radii as the command line computes them (0.6 × the 16th neighbour's distance).
        let mut c = PreparedCloud::new(c);
        c.prepare_surface(16, false).unwrap();
        let f = r.render(&c, &cam, &pipe).unwrap();
        if let Some(mut g) = common::gpu() {
            let gf = g.render(&c, &cam, &pipe).unwrap();
            let agree = common::agreeing(&f.rgba, &gf.rgba, 2);
            assert!(
                agree >= 0.99,
                "{}: {agree} of pixels within 2 levels",
                g.describe()
            );
        }
        // The mean linear red and blue over the middle of the square.
        let (mut red, mut blue, mut m) = (0.0, 0.0, 0.0);
        for y in 44..84 {
            for x in 44..84 {
                let q = (y * 128 + x) * 4;
                red += lut[f.rgba[q] as usize] as f64;
                blue += lut[f.rgba[q + 2] as usize] as f64;
                m += 1.0;
            }
        }
        let a = stipple_render::alpha8(alpha) as f64 / 255.0;
        let want = |c: u8| a * lut[c as usize] as f64 + (1.0 - a) * lut[250] as f64;
        let (red, blue) = (red / m, blue / m);
        assert!(
            (red - want(40)).abs() < 0.03 && (blue - want(220)).abs() < 0.03,
            "{k}² points, α {alpha}: red {red:.3} (want {:.3}), blue {blue:.3} (want {:.3})",
            want(40),
            want(220)
        );
    }
}
