//! Measures depth-peeled transparency on `examples/nested-tori.toml`'s geometry, unlit:
//! three tori sharing a centre line (tubes 0.2 opaque brown, 0.3 green α = 0.5, 0.4 blue
//! α = 0.3) seen obliquely over a white background, six layers. The analytic composite of a
//! pixel blends, front to back, the tori its centre ray crosses (found by marching the ray
//! through each torus); pixels within 2 px of a change of that sequence are left out.
//! Prints, per image size, the mean error (8-bit levels) and the share of pixels off by more
//! than 12 levels (blotches).
//! `cargo run --release -p stipple-render --example peel_nested [cpu|gpu]`
//! (`PEEL_NESTED_OUT=dir` writes the images and a map of the bad pixels in red,
//! `PEEL_NESTED_SIZES=512,1024` picks the sizes, `PEEL_NESTED_SCALE=0.5` scales the point
//! counts, `PEEL_NESTED_ONLY=1,2` keeps some tori, `PEEL_NESTED_FILLS=2,2` fixes the fills'
//! iterations, `PEEL_NESTED_RAW=1` drops the colour passes, `PEEL_NESTED_COL=256` prints a
//! column's pixels and layers, `PEEL_NESTED_GRID=x,y,w,h,layer` a layer's patch).
use glam::DVec3;
use stipple_core::PointCloud;
use stipple_render::{gpu::GpuOptions, Backend, Pipeline, PreparedCloud, Renderer};

#[allow(dead_code)] // shared with the tests; each example uses part of it
#[path = "../tests/common/rims.rs"]
mod rims;

const TUBES: [f32; 3] = [0.2, 0.3, 0.4];
const POINTS: [usize; 3] = [400_000, 600_000, 800_000];
const COLOURS: [[u8; 3]; 3] = [[120, 72, 40], [60, 170, 70], [60, 100, 210]];
const ALPHA: [f32; 3] = [1.0, 0.5, 0.3];
const BACKGROUND: [u8; 3] = [250, 250, 250];

fn main() {
    let backend = match std::env::args().nth(1).as_deref() {
        Some("gpu") => Backend::Gpu,
        _ => Backend::Cpu,
    };
    let scale: f64 = std::env::var("PEEL_NESTED_SCALE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let mut r = Renderer::new(backend, GpuOptions::default()).unwrap();
    let mut c = PointCloud::default();
    let (mut colours, mut opacity, mut normals) = (Vec::new(), Vec::new(), Vec::new());
    let only: Option<Vec<usize>> = std::env::var("PEEL_NESTED_ONLY")
        .ok()
        .map(|v| v.split(',').map(|k| k.parse().unwrap()).collect());
    let used = |k: usize| only.as_ref().is_none_or(|o| o.contains(&k));
    for k in (0..3).filter(|&k| used(k)) {
        let mut rng = stipple_core::rng::Rng::new(k as u64 + 1);
        for _ in 0..(POINTS[k] as f64 * scale) as usize {
            let (q, m) = stipple_core::demo::torus_point(&mut rng, 1.0, TUBES[k]);
            c.positions.push(q);
            normals.push(m);
            colours.push(COLOURS[k]);
            opacity.push(ALPHA[k]);
        }
    }
    c.colors = Some(colours);
    c.opacity = Some(opacity);
    c.normals = Some(normals);
    let cloud = PreparedCloud::new(c);
    let sizes: Vec<u32> = std::env::var("PEEL_NESTED_SIZES")
        .ok()
        .map(|s| s.split(',').map(|v| v.parse().unwrap()).collect())
        .unwrap_or(vec![512, 1024]);
    for size in sizes {
        let cam = rims::oblique(size);
        let mut pipe = Pipeline {
            layers: 6,
            lighting: false,
            background: BACKGROUND,
            keep_layers: std::env::var("PEEL_NESTED_COL").is_ok(),
            ..Pipeline::default()
        };
        if std::env::var("PEEL_NESTED_RAW").is_ok() {
            pipe.colour.clear();
        }
        // Experiments: `PEEL_NESTED_FILLS=background,occluded` fixes the fills' iterations.
        if let Ok(v) = std::env::var("PEEL_NESTED_FILLS") {
            let its: Vec<u32> = v.split(',').map(|n| n.parse().unwrap()).collect();
            for g in &mut pipe.geometry {
                match g {
                    stipple_render::GeometryPass::FillBackground { iterations, .. } => {
                        *iterations = stipple_render::Iterations::UntilStable { max: its[0] }
                    }
                    stipple_render::GeometryPass::FillOccluded { iterations, .. } => {
                        *iterations = stipple_render::Iterations::UntilStable { max: its[1] }
                    }
                    _ => {}
                }
            }
        }
        if let Ok(col) = std::env::var("PEEL_NESTED_COL") {
            let col: f64 = col.parse().unwrap();
            let mut rows = [f64::INFINITY; 3];
            let mut k0 = 0;
            for k in (0..3).filter(|&k| used(k)) {
                let n = (POINTS[k] as f64 * scale) as usize;
                for q in &cloud.cloud.positions[k0..k0 + n] {
                    if let Some((x, y, _)) = cam.project(q.as_dvec3()) {
                        if x >= col && x < col + 1.0 && y < 200.0 {
                            rows[k] = rows[k].min(y);
                        }
                    }
                }
                k0 += n;
            }
            println!("topmost point rows at column {col}: {rows:?}");
        }
        let t = std::time::Instant::now();
        let f = r.render(&cloud, &cam, &pipe).unwrap();
        let ms = t.elapsed().as_secs_f64() * 1e3;
        if let Ok(g) = std::env::var("PEEL_NESTED_GRID") {
            let v: Vec<usize> = g.split(',').map(|n| n.parse().unwrap()).collect();
            let l = &f.layers[v[4]];
            for y in v[1]..v[1] + v[3] {
                let row: String = (v[0]..v[0] + v[2])
                    .map(|x| match l[(y * size as usize + x) * 4 + 1] {
                        100 => 'b',
                        170 => 'G',
                        72 => '#',
                        250 => '.',
                        _ => '?',
                    })
                    .collect();
                println!("{y:4} {row}");
            }
        }
        let w = size as usize;
        let sdfs: Vec<_> = TUBES
            .iter()
            .map(|&t| rims::torus_sdf(1.0, t as f64))
            .collect();
        let surfaces: Vec<rims::Surface> = (0..3)
            .filter(|&k| used(k))
            .map(|k| (&sdfs[k] as &dyn Fn(DVec3) -> f64, COLOURS[k], ALPHA[k]))
            .collect();
        let (seq, want) = rims::composite(&cam, &surfaces, BACKGROUND);
        let sc = rims::score_composite(&f.rgba, w, &seq, &want);
        let mut map = f.rgba.clone();
        for (px, _) in map.chunks_mut(4).zip(&sc.bad_map).filter(|(_, b)| **b) {
            px[..3].copy_from_slice(&[255, 0, 0]);
        }
        if let Ok(col) = std::env::var("PEEL_NESTED_COL") {
            let i: usize = col.parse().unwrap();
            for j in 0..w {
                let p = j * w + i;
                println!(
                    "  ({i},{j}) seq {:o} want {:?} got {:?}",
                    seq[p],
                    want[p],
                    &f.rgba[p * 4..p * 4 + 3]
                );
                for (k, l) in f.layers.iter().enumerate() {
                    println!("     layer {k}: {:?}", &l[p * 4..p * 4 + 4]);
                }
            }
        }
        if let Ok(dir) = std::env::var("PEEL_NESTED_OUT") {
            let dir = std::path::Path::new(&dir);
            stipple_io::image::write_png(
                &dir.join(format!("nested-{size}.png")),
                size,
                size,
                &f.rgba,
            )
            .unwrap();
            stipple_io::image::write_png(
                &dir.join(format!("nested-{size}-bad.png")),
                size,
                size,
                &map,
            )
            .unwrap();
        }
        println!(
            "{size}²: {ms:.0} ms, {} pixels, mean error {:.2} levels, {:.2}% off by > 12; layers {}",
            sc.pixels,
            sc.error,
            100.0 * sc.bad,
            f.layers_peeled
        );
    }
}
