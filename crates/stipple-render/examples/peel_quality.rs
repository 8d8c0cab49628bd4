//! Measures depth-peeled transparency against the analytic composite (issue "Depth-peeled
//! transparency without blotches"): a sphere of opacity 0.5 over an opaque plane, unlit,
//! seen from above, four layers. Prints, for several point spacings on screen, the mean
//! error of the sphere's interior (8-bit levels) and the standard deviation of its linear
//! luminance (the analytic composite is one flat colour).
//! `cargo run --release -p stipple-render --example peel_quality [cpu|gpu]`
use glam::{DVec3, Vec3};
use stipple_core::{Camera, PointCloud, Projection};
use stipple_render::{gpu::GpuOptions, Backend, Pipeline, PreparedCloud, Renderer};

fn main() {
    let backend = match std::env::args().nth(1).as_deref() {
        Some("gpu") => Backend::Gpu,
        _ => Backend::Cpu,
    };
    let mut r = Renderer::new(backend, GpuOptions::default()).unwrap();
    let (sphere_c, plane_c) = ([200u8, 120, 60], [40u8, 90, 200]);
    let mut rng = stipple_core::rng::Rng::new(3);
    let mut c = PointCloud::default();
    let (mut p, mut n, mut col, mut a) = (vec![], vec![], vec![], vec![]);
    for _ in 0..60_000 {
        let d = stipple_core::demo::sphere_point(&mut rng);
        p.push(d * 0.5);
        n.push(d);
        col.push(sphere_c);
        a.push(0.5f32);
    }
    let k = 280;
    for i in 0..k {
        for j in 0..k {
            let x = (i as f32 + rng.f32()) / k as f32 * 2.0 - 1.0;
            let y = (j as f32 + rng.f32()) / k as f32 * 2.0 - 1.0;
            p.push(Vec3::new(x, y, -1.0));
            n.push(Vec3::Z);
            col.push(plane_c);
            a.push(1.0);
        }
    }
    c.positions = p;
    c.normals = Some(n);
    c.colors = Some(col);
    c.opacity = Some(a);
    let cloud = PreparedCloud::new(c);
    let lut = stipple_render::srgb::srgb_to_linear_table();
    let lin = |c: [u8; 3]| c.map(|v| lut[v as usize]);
    let (s, pl) = (lin(sphere_c), lin(plane_c));
    let want: [f32; 3] = std::array::from_fn(|i| 0.5 * s[i] + 0.25 * s[i] + 0.25 * pl[i]);
    let want8 = want.map(stipple_render::srgb::linear_to_srgb8);
    for size in std::env::var("PEEL_QUALITY_SIZES")
        .ok()
        .map(|s| {
            s.split(",")
                .map(|v| v.parse().unwrap())
                .collect::<Vec<u32>>()
        })
        .unwrap_or(vec![200, 256, 320, 400])
    {
        let cam = Camera {
            eye: DVec3::new(0.0, 0.0, 4.0),
            target: DVec3::ZERO,
            up: DVec3::Y,
            projection: Projection::Perspective { fov_deg: 20.0 },
            width: size,
            height: size,
            near: 0.5,
            far: 10.0,
        };
        // The sphere points' spacing (area per point, square root) in pixels at its front.
        let spacing = (std::f64::consts::PI / 60_000.0).sqrt()
            / (2.0 * 3.5 * 10f64.to_radians().tan() / size as f64);
        let mut pipe = Pipeline {
            layers: 4,
            keep_layers: std::env::var("PEEL_QUALITY_OUT").is_ok(),
            lighting: false,
            ..Pipeline::default()
        };
        if let Ok(its) = std::env::var("PEEL_QUALITY_FILLS") {
            let its = stipple_render::Iterations::parse(&its).unwrap();
            for g in &mut pipe.geometry {
                match g {
                    stipple_render::GeometryPass::FillBackground { iterations, .. }
                    | stipple_render::GeometryPass::FillOccluded { iterations, .. } => {
                        *iterations = its
                    }
                    _ => {}
                }
            }
        }
        if let Ok(rad) = std::env::var("PEEL_QUALITY_RADIUS") {
            for g in &mut pipe.geometry {
                if let stipple_render::GeometryPass::FillBackground { radius, .. }
                | stipple_render::GeometryPass::FillOccluded { radius, .. } = g
                {
                    *radius = rad.parse().unwrap()
                }
            }
        }
        let f = r.render(&cloud, &cam, &pipe).unwrap();
        if let Ok(dir) = std::env::var("PEEL_QUALITY_OUT") {
            let out = std::path::Path::new(&dir).join(format!("peel-{size}.png"));
            stipple_io::image::write_png(&out, size, size, &f.rgba).unwrap();
            for (k, l) in f.layers.iter().enumerate() {
                let out = std::path::Path::new(&dir).join(format!("peel-{size}-layer{k}.png"));
                stipple_io::image::write_png(&out, size, size, l).unwrap();
            }
        }
        // The sphere's screen radius: 0.5 at distance ~4 under a 20° fov.
        let rad = 0.5 / (4.0 * (10f64.to_radians()).tan()) * size as f64 / 2.0;
        let (mut err, mut lum, mut count) = (0.0, Vec::new(), 0);
        let mut signed = [0.0f64; 3];
        for j in 0..size {
            for i in 0..size {
                let dx = i as f64 + 0.5 - size as f64 / 2.0;
                let dy = j as f64 + 0.5 - size as f64 / 2.0;
                if (dx * dx + dy * dy).sqrt() > 0.8 * rad {
                    continue;
                }
                let k = ((j * size + i) * 4) as usize;
                for ch in 0..3 {
                    let d = f.rgba[k + ch] as f64 - want8[ch] as f64;
                    err += d.abs();
                    signed[ch] += d;
                }
                let l: f32 = (0..3)
                    .map(|ch| lut[f.rgba[k + ch] as usize] * [0.2126, 0.7152, 0.0722][ch])
                    .sum();
                lum.push(l as f64);
                count += 1;
            }
        }
        let mean = lum.iter().sum::<f64>() / lum.len() as f64;
        let sd =
            (lum.iter().map(|l| (l - mean) * (l - mean)).sum::<f64>() / lum.len() as f64).sqrt();
        println!(
            "{size}²: points {spacing:.2} px apart (median neighbour {:.2} px), {count} interior pixels, mean error {:.2} levels (rgb bias {:.1} {:.1} {:.1}), sd of luminance {sd:.4}, layers {}",
            cloud.screen_spacing(&cam),
            err / (3 * count) as f64,
            signed[0] / count as f64,
            signed[1] / count as f64,
            signed[2] / count as f64,
            f.layers_peeled
        );
    }
}
