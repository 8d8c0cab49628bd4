//! Helpers shared by the render crate's integration tests (each test file includes this
//! module with `mod common;`; not every file uses every helper).
#![allow(dead_code)]

pub mod rims;

use glam::Vec3;
use stipple_core::rng::Rng;
use stipple_render::gpu::GpuOptions;
use stipple_render::{Backend, Renderer};

/// Whether STIPPLE_REQUIRE_GPU=1 makes a missing adapter a failure.
pub fn gpu_required() -> bool {
    std::env::var("STIPPLE_REQUIRE_GPU").is_ok_and(|v| v == "1")
}

/// A GPU renderer, or None (with the reason printed) where there is no adapter; a missing
/// adapter panics under STIPPLE_REQUIRE_GPU=1.
pub fn gpu() -> Option<Renderer> {
    match Renderer::new(Backend::Gpu, GpuOptions::default()) {
        Ok(r) => Some(r),
        Err(e) => {
            if gpu_required() {
                panic!("STIPPLE_REQUIRE_GPU=1 but there is no usable GPU adapter: {e}");
            }
            eprintln!("GPU part skipped: no GPU adapter ({e})");
            None
        }
    }
}

pub fn cpu() -> Renderer {
    Renderer::new(Backend::Cpu, GpuOptions::default()).expect("the CPU backend always opens")
}

/// The CPU renderer, then the GPU one where an adapter exists (see [`gpu`]).
pub fn backends() -> Vec<Renderer> {
    let mut r = vec![cpu()];
    r.extend(gpu());
    r
}

/// A square of side `side` at height z (in the xy plane), ⌈√n⌉² jittered-grid points.
pub fn jittered_square(n: usize, side: f32, z: f32, seed: u64) -> Vec<Vec3> {
    let mut rng = Rng::new(seed);
    let k = (n as f32).sqrt().ceil() as usize;
    let mut p = Vec::with_capacity(k * k);
    for i in 0..k {
        for j in 0..k {
            let x = (i as f32 + rng.f32()) / k as f32 - 0.5;
            let y = (j as f32 + rng.f32()) / k as f32 - 0.5;
            p.push(Vec3::new(x * side, y * side, z));
        }
    }
    p
}

/// `n` points uniformly on a sphere, with outward normals.
pub fn sphere(n: usize, centre: Vec3, r: f32, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut rng = Rng::new(seed);
    let mut p = Vec::with_capacity(n);
    let mut nn = Vec::with_capacity(n);
    for _ in 0..n {
        let d = stipple_core::demo::sphere_point(&mut rng);
        p.push(centre + d * r);
        nn.push(d);
    }
    (p, nn)
}

/// Where a test writes what a person should look at when it fails: `target/test-output/`.
pub fn test_output_dir() -> std::path::PathBuf {
    let d = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/test-output");
    std::fs::create_dir_all(&d).expect("create target/test-output");
    d
}

/// Writes a frame's image to `target/test-output/NAME.png` for a person to look at (errors
/// are ignored: the image is an aid, not the test).
pub fn dump(name: &str, f: &stipple_render::Frame) {
    let dir = test_output_dir();
    let _ =
        stipple_io::image::write_png(&dir.join(format!("{name}.png")), f.width, f.height, &f.rgba);
}

/// The same frame on the CPU and, where an adapter exists, on the GPU (see [`gpu`]): any
/// pipeline runs through both backends' one schedule.
pub fn both(
    cloud: &stipple_render::PreparedCloud,
    camera: &stipple_core::Camera,
    pipe: &stipple_render::Pipeline,
) -> Option<(stipple_render::Frame, stipple_render::Frame)> {
    let mut g = gpu()?;
    let a = cpu().render(cloud, camera, pipe).expect("cpu frame");
    let b = g.render(cloud, camera, pipe).expect("gpu frame");
    Some((a, b))
}

/// Share of pixels whose colours differ by at most `levels` in every channel.
pub fn agreeing(a: &[u8], b: &[u8], levels: u8) -> f64 {
    let n = a.len() / 4;
    let ok = (0..n)
        .filter(|&k| (0..3).all(|i| a[4 * k + i].abs_diff(b[4 * k + i]) <= levels))
        .count();
    ok as f64 / n as f64
}
