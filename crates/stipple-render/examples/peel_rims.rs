//! Measures depth-peeled transparency where it is hardest: a transparent torus (opacity 0.5,
//! unlit) seen obliquely over a white background, as in `examples/nested-tori.toml`, so
//! that rays graze the tube near its silhouettes and cross it two or four times. The
//! analytic composite of a pixel is (1 − 0.5ⁿ) s + 0.5ⁿ b for its n crossings (found by
//! marching the pixel's centre ray through the torus); pixels within 2 px of a change of n
//! are left out. Prints, per point spacing, the mean error (8-bit levels), the share of
//! pixels off by more than 12 levels (speckle) and the worst class's luminance deviation.
//! `cargo run --release -p stipple-render --example peel_rims [cpu|gpu]`
//! (`PEEL_RIMS_OUT=dir` writes the images, `PEEL_RIMS_SIZES=256,512` picks the sizes).
use glam::DVec3;
use stipple_core::{Camera, PointCloud, Projection};
use stipple_render::{gpu::GpuOptions, Backend, Pipeline, PreparedCloud, Renderer};

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
    let lut = stipple_render::srgb::srgb_to_linear_table();
    let lin = |c: [u8; 3]| c.map(|v| lut[v as usize]);
    let (s, b) = (lin(colour), lin(background));
    let sizes: Vec<u32> = std::env::var("PEEL_RIMS_SIZES")
        .ok()
        .map(|s| s.split(',').map(|v| v.parse().unwrap()).collect())
        .unwrap_or(vec![256, 384, 512, 768]);
    for size in sizes {
        let cam = Camera {
            eye: DVec3::new(0.0, 2.2, 3.0),
            target: DVec3::ZERO,
            up: DVec3::Y,
            projection: Projection::Perspective { fov_deg: 40.0 },
            width: size,
            height: size,
            near: 0.5,
            far: 10.0,
        };
        let pipe = Pipeline {
            layers: 4,
            lighting: false,
            background,
            keep_layers: std::env::var("PEEL_RIMS_OUT").is_ok(),
            ..Pipeline::default()
        };
        let mut pipe = pipe;
        if let Ok(its) = std::env::var("PEEL_RIMS_FILLS") {
            let its = stipple_render::Iterations::parse(&its).unwrap();
            for g in &mut pipe.geometry {
                if let stipple_render::GeometryPass::FillBackground { iterations, .. }
                | stipple_render::GeometryPass::FillOccluded { iterations, .. } = g
                {
                    *iterations = its
                }
            }
        }
        if let Ok(rad) = std::env::var("PEEL_RIMS_RADIUS") {
            for g in &mut pipe.geometry {
                if let stipple_render::GeometryPass::FillBackground { radius, .. }
                | stipple_render::GeometryPass::FillOccluded { radius, .. } = g
                {
                    *radius = rad.parse().unwrap()
                }
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
        let counts = crossings(&cam);
        let w = size as usize;
        let (mut err, mut total, mut bad) = (0.0, 0usize, 0usize);
        let mut lum: [Vec<f64>; 5] = Default::default();
        let mut bad_map = vec![0u8; w * w * 4];
        for j in 2..w - 2 {
            for i in 2..w - 2 {
                let n = counts[j * w + i];
                let uniform =
                    (j - 2..=j + 2).all(|y| (i - 2..=i + 2).all(|x| counts[y * w + x] == n));
                if !uniform || n == 0 {
                    continue;
                }
                let t = 0.5f32.powi(n as i32);
                let want = std::array::from_fn::<f32, 3, _>(|ch| (1.0 - t) * s[ch] + t * b[ch])
                    .map(stipple_render::srgb::linear_to_srgb8);
                let k = (j * w + i) * 4;
                let e: f64 = (0..3)
                    .map(|ch| (f.rgba[k + ch] as f64 - want[ch] as f64).abs())
                    .sum::<f64>()
                    / 3.0;
                err += e;
                total += 1;
                if e > 12.0 {
                    bad += 1;
                    bad_map[k..k + 4].copy_from_slice(&[255, 0, 0, 255]);
                } else {
                    bad_map[k..k + 4].copy_from_slice(&[
                        f.rgba[k],
                        f.rgba[k + 1],
                        f.rgba[k + 2],
                        255,
                    ]);
                }
                let l: f32 = (0..3)
                    .map(|ch| lut[f.rgba[k + ch] as usize] * [0.2126, 0.7152, 0.0722][ch])
                    .sum();
                lum[n.min(4) as usize].push(l as f64);
            }
        }
        if let Ok(dir) = std::env::var("PEEL_RIMS_OUT") {
            let out = std::path::Path::new(&dir).join(format!("rims-{size}-bad.png"));
            stipple_io::image::write_png(&out, size, size, &bad_map).unwrap();
        }
        let sd = lum
            .iter()
            .filter(|l| l.len() > 100)
            .map(|l| {
                let m = l.iter().sum::<f64>() / l.len() as f64;
                (l.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / l.len() as f64).sqrt()
            })
            .fold(0.0, f64::max);
        println!(
            "{size}²: points {:.2} px apart, {total} pixels, mean error {:.2} levels, {:.2}% off by > 12, worst sd {sd:.4}, layers {}",
            cloud.screen_spacing(&cam),
            err / total as f64,
            100.0 * bad as f64 / total as f64,
            f.layers_peeled
        );
    }
}

/// How many times each pixel's centre ray crosses the torus's surface.
fn crossings(cam: &Camera) -> Vec<u8> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let fwd = (cam.target - cam.eye).normalize();
    let right = fwd.cross(cam.up).normalize();
    let up = right.cross(fwd);
    let Projection::Perspective { fov_deg } = cam.projection else {
        unreachable!()
    };
    let th = (fov_deg.to_radians() / 2.0).tan();
    // Signed distance to the torus.
    let f = |p: DVec3| {
        (((p.x * p.x + p.z * p.z).sqrt() - MAJOR as f64).powi(2) + p.y * p.y).sqrt() - TUBE as f64
    };
    let mut out = vec![0u8; w * h];
    for j in 0..h {
        for i in 0..w {
            let x = ((i as f64 + 0.5) / w as f64 * 2.0 - 1.0) * th * w as f64 / h as f64;
            let y = (1.0 - (j as f64 + 0.5) / h as f64 * 2.0) * th;
            let d = (fwd + right * x + up * y).normalize();
            let (mut t, mut prev, mut n) = (1.0, f(cam.eye + d), 0u8);
            while t < 8.0 {
                t += prev.abs().max(0.0005);
                let v = f(cam.eye + d * t);
                if (v < 0.0) != (prev < 0.0) {
                    n += 1;
                }
                prev = v;
            }
            out[j * w + i] = n;
        }
    }
    out
}
