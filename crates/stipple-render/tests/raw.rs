//! The raw-cloud pipeline (Pintus §4–6) on clouds without normals: visibility, anisotropic
//! filling and shape depiction, against known surfaces.

mod common;

use glam::DVec3;
use stipple_core::{Camera, PointCloud, Projection};
use stipple_render::eval::{compare, mesh_depth, DepthError};
use stipple_render::passes::{depiction::cpu as depiction, edl::cpu as edl};
use stipple_render::pipeline::{RawSettings, RawShading};
use stipple_render::{render, Backend, Pipeline, PreparedCloud, ViewParams, HOLE};

fn data_dir() -> Option<std::path::PathBuf> {
    let d = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    d.is_dir().then_some(d)
}

fn framing(cloud: &PointCloud, size: u32, dir: DVec3) -> Camera {
    let (lo, hi) = cloud.world_bounds();
    let mut c = Camera::framing(lo, hi, size, size, 40.0);
    let dist = (c.eye - c.target).length();
    c.eye = c.target + dir.normalize() * dist;
    c.fit_clip(lo, hi);
    c
}

/// Renders the cloud's vertices raw and compares with its mesh, leaving out pixels within 2 of
/// a contour (silhouettes and depth discontinuities of the mesh, where Pintus Fig. 4 shows the
/// error concentrates and point positions legitimately differ from the mesh's edges).
fn fidelity(name: &str, cloud: &PointCloud, cam: &Camera, pipe: &Pipeline) -> DepthError {
    let v = ViewParams::new(cam, cloud.origin);
    let truth = mesh_depth(&v, &cloud.positions, &cloud.faces);
    let mut points = cloud.clone();
    points.faces.clear();
    points.normals = None;
    let frame = render(&PreparedCloud::new(points), cam, pipe, Backend::Cpu).unwrap();
    common::dump(name, &frame);
    let e = compare(&frame.depth, &truth, cam.width as usize, 2);
    let img = stipple_render::eval::error_image(&frame.depth, &truth, e.tolerance);
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/test-output");
    let _ = stipple_io::image::write_png(
        &dir.join(format!("{name}-error.png")),
        cam.width,
        cam.height,
        &img,
    );
    eprintln!(
        "{name}: {} px inside: {} holes, {:.2}% within 0.5%, {:.2}% behind, {:.2}% leaks",
        e.inside,
        e.holes,
        100.0 * e.within_share(),
        100.0 * e.behind_share(),
        100.0 * e.leak_share()
    );
    e
}

fn raw(visibility: bool) -> Pipeline {
    Pipeline::raw(RawSettings {
        visibility,
        ..RawSettings::default()
    })
}

#[test]
fn bunny_vertices_without_normals_render_to_the_mesh_surface() {
    let Some(dir) = data_dir() else {
        eprintln!("skipped: ../shared/data is absent");
        return;
    };
    let mesh = stipple_io::read_cloud(&dir.join("stanford/bunny/bun_zipper.ply")).unwrap();
    assert!(!mesh.faces.is_empty());
    // From the side and above, points about 2 px apart: the far flank lies behind the near
    // one and shows through its gaps unless visibility removes it.
    let cam = framing(&mesh, 512, DVec3::new(1.0, 0.5, 0.3));
    let on = fidelity("raw-bunny", &mesh, &cam, &raw(true));
    assert_eq!(on.holes, 0, "background inside the silhouette");
    assert!(on.within_share() >= 0.98, "{on:?}");
    assert!(on.behind_share() <= 0.01, "{on:?}");
    let off = fidelity("raw-bunny-no-visibility", &mesh, &cam, &raw(false));
    assert!(off.behind_share() > 0.01, "{off:?}");
}

/// A dense plane (z = 0, 1 px spacing) behind a sparse layer (z = 8, one point per 3 × 3
/// pixels), seen orthographically from +z: the gap is 8 pixels' worth, so through the 2-pixel
/// gaps between the layer's points only a narrow cone reaches the plane.
fn plane_behind_sparse_layer() -> (PointCloud, Camera) {
    let n = 96;
    let mut pts = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let p = |z: f64| DVec3::new(i as f64 + 0.5 - 48.0, 47.5 - j as f64, z);
            pts.push(p(0.0));
            // The sparse layer covers the middle third.
            if (32..64).contains(&i) && (32..64).contains(&j) && i % 3 == 1 && j % 3 == 1 {
                pts.push(p(8.0));
            }
        }
    }
    let cloud = PointCloud::from_world(&pts);
    let mut cam = Camera {
        eye: DVec3::new(0.0, 0.0, 10.0),
        target: DVec3::ZERO,
        up: DVec3::Y,
        projection: Projection::Orthographic { height: 96.0 },
        width: 96,
        height: 96,
        near: 0.1,
        far: 100.0,
    };
    cam.fit_clip(DVec3::new(-48.0, -48.0, 0.0), DVec3::new(48.0, 48.0, 8.0));
    (cloud, cam)
}

#[test]
fn a_plane_seen_through_a_sparse_nearer_layer_is_judged_invisible() {
    let (cloud, cam) = plane_behind_sparse_layer();
    let prepared = PreparedCloud::new(cloud);
    let front = |id: u32| prepared.cloud.positions[id as usize].z > 0.5;
    let settings = RawSettings {
        kernel: 9,
        shading: RawShading::None,
        ..RawSettings::default()
    };
    let mut r = stipple_render::Renderer::new(Backend::Cpu, Default::default()).unwrap();
    let on = r.render(&prepared, &cam, &Pipeline::raw(settings)).unwrap();
    let off = r
        .render(
            &prepared,
            &cam,
            &Pipeline::raw(RawSettings {
                visibility: false,
                ..settings
            }),
        )
        .unwrap();
    // Inside the layer (away from its border), every pixel not showing a layer point.
    let inner = |k: usize| (38..58).contains(&(k % 96)) && (38..58).contains(&(k / 96));
    let mut through = 0;
    for k in (0..96 * 96).filter(|&k| inner(k)) {
        if stipple_render::is_point(off.id[k]) && !front(off.id[k]) {
            through += 1;
            assert_eq!(on.id[k], HOLE, "pixel {k} still shows the plane");
            // Filled from the layer: depth near the layer's, not the plane's.
            assert!((on.depth[k] - off.depth[k]).abs() > 7.0, "pixel {k}");
        }
    }
    assert!(
        through > 300,
        "{through} plane pixels between the layer's points"
    );
    // Outside the layer the plane is visible and kept.
    for k in [5 * 96 + 5, 90 * 96 + 50] {
        assert!(stipple_render::is_point(on.id[k]) && !front(on.id[k]));
    }
}

fn ortho_view(w: u32, h: u32) -> ViewParams {
    ViewParams::axis_aligned(w, h, false, 1.0 / 16.0)
}

/// The depiction term of a depth image (levels, ξ = 1.5, ε = 2 footprints).
fn shading(v: &ViewParams, depth: &[f32], levels: u32) -> Vec<f32> {
    let white = vec![[1.0f32; 3]; depth.len()];
    let mut out = white.clone();
    let mut scratch = (Vec::new(), Vec::new());
    let mut term = Vec::new();
    depiction::depiction(
        v,
        depth,
        levels,
        1.5,
        2.0,
        &mut scratch,
        &mut term,
        &white,
        &mut out,
    );
    out.iter().map(|c| c[0]).collect()
}

#[test]
fn depiction_shades_a_facing_plane_to_one_and_darkens_as_it_tilts() {
    let v = ortho_view(32, 32);
    let fp = v.footprint(5.0);
    for levels in [1, 4] {
        let mut last = f32::INFINITY;
        for slope in [0.0f32, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0] {
            let depth: Vec<f32> = (0..32 * 32)
                .map(|k| 5.0 + slope * fp * (k % 32) as f32)
                .collect();
            let s = shading(&v, &depth, levels)[16 * 32 + 16];
            if slope == 0.0 {
                assert_eq!(s, 1.0);
            } else {
                assert!(
                    s < last,
                    "levels {levels}: slope {slope} gives {s} ≥ {last}"
                );
            }
            assert!(s >= 0.5 - 1e-4, "{s}");
            last = s;
        }
    }
}

#[test]
fn depiction_draws_a_line_along_a_step_and_edl_darkens_its_far_side() {
    // Depth 5 left of column 16, 21 from it on: a step of 16 pixel footprints.
    let v = ortho_view(32, 32);
    assert_eq!(v.footprint(5.0), 1.0);
    let depth: Vec<f32> = (0..32 * 32)
        .map(|k| if k % 32 < 16 { 5.0 } else { 21.0 })
        .collect();
    let s = shading(&v, &depth, 1);
    let row = 16 * 32;
    assert!(s[row + 16] < 0.3, "far side of the edge: {}", s[row + 16]);
    assert!(
        s[row + 15] > s[row + 16] + 0.4,
        "near side: {}",
        s[row + 15]
    );
    assert_eq!(s[row + 8], 1.0);
    assert_eq!(s[row + 24], 1.0);
    let white = vec![[1.0f32; 3]; depth.len()];
    let mut out = white.clone();
    edl::edl(&v, &depth, 1.0, 1.4, &white, &mut out);
    assert!(out[row + 16][0] < 0.01, "{}", out[row + 16][0]);
    assert_eq!(out[row + 15][0], 1.0);
    assert_eq!(out[row + 8][0], 1.0);
}
