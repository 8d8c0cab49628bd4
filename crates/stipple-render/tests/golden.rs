//! Whole-frame golden images: five small CPU frames, one per kind of pipeline (Dobrev's
//! default, Pintus's raw preset, Zhang & Pajarola's splats, depth-peeled transparency and
//! soft shadows from an area light), compared with the PNGs committed in `tests/golden/`.
//!
//! The comparison tolerates what another CPU's floating point could change (a few pixels
//! whose nearest point is a tie, a rounding step of colour) and nothing more; with
//! `STIPPLE_GOLDEN_EXACT=1` it demands bit-identical images (what a refactoring must keep).
//! On failure the actual image and a difference image are written to `target/test-output/`.
//! `STIPPLE_BLESS=1` rewrites the committed images (only when a change of output is meant:
//! say why in the commit).

mod common;

use glam::DVec3;
use std::path::PathBuf;
use stipple_core::demo::{generate, DemoScene};
use stipple_core::{Camera, Projection};
use stipple_render::pipeline::RawSettings;
use stipple_render::shadow::ShadowSettings;
use stipple_render::{
    AreaLight, AreaShape, Light, Pipeline, PreparedCloud, SplatMode, SplatSettings,
};

const W: u32 = 160;
const H: u32 = 120;

fn camera(eye: [f64; 3], target: [f64; 3]) -> Camera {
    Camera {
        eye: DVec3::from(eye),
        target: DVec3::from(target),
        up: DVec3::Y,
        projection: Projection::Perspective { fov_deg: 40.0 },
        width: W,
        height: H,
        near: 0.1,
        far: 30.0,
    }
}

fn golden_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

/// Compares `rgba` with `tests/golden/NAME.png` (see the module documentation).
fn check(name: &str, rgba: &[u8]) {
    let path = golden_dir().join(format!("{name}.png"));
    if std::env::var("STIPPLE_BLESS").is_ok_and(|v| v == "1") {
        stipple_io::image::write_png(&path, W, H, rgba).unwrap();
        eprintln!("blessed {}", path.display());
        return;
    }
    let (w, h, want) = stipple_io::image::read_png(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (STIPPLE_BLESS=1 makes it)", path.display()));
    assert_eq!((w, h), (W, H), "{name}: golden image size");
    let n = (W * H) as usize;
    let mut diff = vec![0u8; 4 * n];
    let (mut differing, mut large, mut sum) = (0usize, 0usize, 0u64);
    for i in 0..n {
        let d = (0..3)
            .map(|c| rgba[4 * i + c].abs_diff(want[4 * i + c]))
            .max()
            .unwrap();
        differing += (d > 0) as usize;
        large += (d > 8) as usize;
        sum += d as u64;
        let v = d.saturating_mul(8);
        diff[4 * i..4 * i + 4].copy_from_slice(&[v, v, v, 255]);
    }
    let exact = std::env::var("STIPPLE_GOLDEN_EXACT").is_ok_and(|v| v == "1");
    let mean = sum as f64 / n as f64;
    let ok = if exact {
        differing == 0
    } else {
        large as f64 <= 0.005 * n as f64 && mean <= 0.5
    };
    if !ok {
        let out = common::test_output_dir();
        let (a, d) = (
            out.join(format!("golden-{name}-actual.png")),
            out.join(format!("golden-{name}-diff.png")),
        );
        stipple_io::image::write_png(&a, W, H, rgba).unwrap();
        stipple_io::image::write_png(&d, W, H, &diff).unwrap();
        panic!(
            "{name}: {differing} pixels differ from {} ({large} by more than 8 levels, mean \
             difference {mean:.3}{}); actual image {}, difference ×8 {}",
            path.display(),
            if exact {
                ", exact comparison asked"
            } else {
                ""
            },
            a.display(),
            d.display()
        );
    }
}

fn plane_objects() -> PreparedCloud {
    PreparedCloud::new(generate(DemoScene::PlaneObjects, 60_000, 7))
}

#[test]
fn golden_dobrev_default_pipeline() {
    let c = plane_objects();
    let f = common::cpu()
        .render(
            &c,
            &camera([3.0, 2.4, 4.0], [0.0, 0.3, 0.0]),
            &Pipeline::default(),
        )
        .unwrap();
    check("dobrev", &f.rgba);
}

#[test]
fn golden_raw_preset_without_normals() {
    let mut cloud = generate(DemoScene::Torus, 40_000, 3);
    cloud.normals = None;
    let c = PreparedCloud::new(cloud);
    let f = common::cpu()
        .render(
            &c,
            &camera([0.0, 2.2, 2.6], [0.0, 0.0, 0.0]),
            &Pipeline::raw(RawSettings::default()),
        )
        .unwrap();
    check("raw", &f.rgba);
}

#[test]
fn golden_deferred_splats() {
    // Sparse: the points land several pixels apart, which only splats close.
    let mut c = PreparedCloud::new(generate(DemoScene::Sphere, 3_000, 5));
    c.prepare_surface(16, true).unwrap();
    let pipe = Pipeline::splats(SplatSettings {
        mode: SplatMode::Deferred,
        ..SplatSettings::default()
    });
    let f = common::cpu()
        .render(&c, &camera([0.0, 0.8, 3.2], [0.0, 0.0, 0.0]), &pipe)
        .unwrap();
    check("splats", &f.rgba);
}

#[test]
fn golden_peeled_transparency() {
    let c = PreparedCloud::new(generate(DemoScene::NestedTori, 120_000, 11));
    let pipe = Pipeline {
        layers: 4,
        ..Pipeline::default()
    };
    let f = common::cpu()
        .render(&c, &camera([0.0, 1.6, 3.4], [0.0, 0.0, 0.0]), &pipe)
        .unwrap();
    check("peel", &f.rgba);
}

#[test]
fn golden_area_light_shadows() {
    let mut c = plane_objects();
    let light = Light::Area(AreaLight {
        centre: [-2.5, 2.2, 1.5],
        facing: [2.5, -2.0, -1.5],
        shape: AreaShape::Disc { radius: 0.4 },
        samples: 4,
    });
    let mut r = common::cpu();
    let lit = r
        .shadow_texture(
            &c,
            &[light],
            &ShadowSettings::default(),
            None,
            64,
            &mut |_, _| {},
        )
        .unwrap();
    c.set_lit(Some(lit)).unwrap();
    let pipe = Pipeline {
        lights: vec![light],
        ..Pipeline::default()
    };
    let f = r
        .render(&c, &camera([3.0, 2.4, 4.0], [0.0, 0.3, 0.0]), &pipe)
        .unwrap();
    check("shadows", &f.rgba);
}
