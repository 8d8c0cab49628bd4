//! Measures depth-peeled transparency where it is hardest: a transparent torus (opacity 0.5,
//! unlit) seen obliquely over a white background, as in `examples/nested-tori.toml`, so
//! that rays graze the tube near its silhouettes and cross it two or four times. The
//! analytic composite of a pixel is (1 − 0.5ⁿ) s + 0.5ⁿ b for its n crossings (found by
//! marching the pixel's centre ray through the torus); pixels within 2 px of a change of n
//! are left out. Prints, per point spacing, the mean error (8-bit levels), the share of
//! pixels off by more than 12 levels (speckle) and the worst class's luminance deviation.
//! `cargo run --release -p stipple-render --example peel_rims [cpu|gpu]`
//! (`PEEL_RIMS_OUT=dir` writes the images, `PEEL_RIMS_SIZES=256,512` picks the sizes).
use stipple_core::PointCloud;
use stipple_render::{gpu::GpuOptions, Backend, Pipeline, PreparedCloud, Renderer};

#[allow(dead_code)] // shared with the tests; each example uses part of it
#[path = "../tests/common/rims.rs"]
mod rims;

const MAJOR: f32 = 1.0;
const TUBE: f32 = 0.4;

fn main() {
    let backend = match std::env::args().nth(1).as_deref() {
        Some("gpu") => Backend::Gpu,
        _ => Backend::Cpu,
    };
    let points: usize = std::env::var("PEEL_RIMS_POINTS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(300_000);
    let mut r = Renderer::new(backend, GpuOptions::default()).unwrap();
    let colour = [60u8, 100, 210];
    let background = [250u8, 250, 250];
    let mut rng = stipple_core::rng::Rng::new(5);
    let (mut p, mut n) = (Vec::new(), Vec::new());
    for _ in 0..points {
        let (q, m) = stipple_core::demo::torus_point(&mut rng, MAJOR, TUBE);
        p.push(q);
        n.push(m);
    }
    let c = PointCloud {
        colors: Some(vec![colour; p.len()]),
        opacity: Some(vec![0.5; p.len()]),
        normals: Some(n),
        positions: p,
        ..Default::default()
    };
    let cloud = PreparedCloud::new(c);
    let sizes: Vec<u32> = std::env::var("PEEL_RIMS_SIZES")
        .ok()
        .map(|s| s.split(',').map(|v| v.parse().unwrap()).collect())
        .unwrap_or(vec![256, 384, 512, 768]);
    for size in sizes {
        let cam = rims::oblique(size);
        let mut pipe = Pipeline {
            layers: 4,
            lighting: false,
            background,
            keep_layers: std::env::var("PEEL_RIMS_OUT").is_ok(),
            ..Pipeline::default()
        };
        // Calibration: more fill iterations or wider masks than the automatic ones (the
        // frame resolves them upwards only).
        let fills = std::env::var("PEEL_RIMS_FILLS").ok();
        let fills = fills.map(|v| stipple_render::Iterations::parse(&v).unwrap());
        let wide = std::env::var("PEEL_RIMS_RADIUS").ok();
        let wide: Option<u32> = wide.map(|v| v.parse().unwrap());
        for g in &mut pipe.geometry {
            if let stipple_render::GeometryPass::FillBackground { iterations, radius }
            | stipple_render::GeometryPass::FillOccluded {
                iterations, radius, ..
            } = g
            {
                *iterations = fills.unwrap_or(*iterations);
                *radius = wide.unwrap_or(*radius);
            }
        }
        let f = r.render(&cloud, &cam, &pipe).unwrap();
        if let Ok(dir) = std::env::var("PEEL_RIMS_OUT") {
            let dir = std::path::Path::new(&dir);
            stipple_io::image::write_png(
                &dir.join(format!("rims-{size}.png")),
                size,
                size,
                &f.rgba,
            )
            .unwrap();
            for (k, l) in f.layers.iter().enumerate() {
                let out = dir.join(format!("rims-{size}-layer{k}.png"));
                stipple_io::image::write_png(&out, size, size, l).unwrap();
            }
        }
        let counts = rims::crossings(&cam, &rims::torus_sdf(MAJOR as f64, TUBE as f64));
        let w = size as usize;
        let sc = rims::score(&f.rgba, w, &counts, colour, background);
        if let Ok(dir) = std::env::var("PEEL_RIMS_OUT") {
            let mut map = f.rgba.clone();
            for (px, _) in map.chunks_mut(4).zip(&sc.bad_map).filter(|(_, b)| **b) {
                px.copy_from_slice(&[255, 0, 0, 255]);
            }
            let out = std::path::Path::new(&dir).join(format!("rims-{size}-bad.png"));
            stipple_io::image::write_png(&out, size, size, &map).unwrap();
        }
        println!(
            "{size}²: points {:.2} px apart, {} pixels, mean error {:.2} levels, {:.2}% off by > 12, worst sd {:.4}, layers {}",
            cloud.screen_spacing(&cam),
            sc.pixels,
            sc.error,
            100.0 * sc.bad,
            sc.worst_sd,
            f.layers_peeled
        );
    }
}
