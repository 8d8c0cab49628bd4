//! Kernels of the LOD hierarchy: inner-node sampling, the in-memory kd build, selection.
//! Whole builds and frames are timed by `stipple build-lod` and `stipple bench tree.stlod`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::{DVec3, Vec3};
use stipple_core::{Bounds, Camera};
use stipple_lod::{kd, sample, Record, SelectOptions};

/// A wavy sheet of `n` points in a 100 × 60 box.
fn sheet(n: usize) -> Vec<Record> {
    let mut rng = stipple_core::rng::Rng::new(7);
    (0..n)
        .map(|_| {
            let (x, y) = (rng.f32() * 100.0, rng.f32() * 60.0);
            Record::new(
                Vec3::new(x, y, 2.0 * (x * 0.1).sin() + 3.0),
                [x as u8, y as u8, 9],
            )
        })
        .collect()
}

fn bounds() -> Bounds {
    Bounds {
        min: Vec3::new(0.0, 0.0, 0.0),
        max: Vec3::new(100.0, 60.0, 6.0),
    }
}

fn sample_pick(c: &mut Criterion) {
    let mut g = c.benchmark_group("sample");
    for m in [8_192usize, 32_768] {
        let pts = sheet(2 * m);
        g.throughput(Throughput::Elements(pts.len() as u64));
        g.bench_with_input(BenchmarkId::new("2M points to M", m), &m, |b, &m| {
            b.iter(|| sample::pick(&pts, &bounds(), m, None))
        });
    }
    g.finish();
}

fn build(c: &mut Criterion) {
    let mut g = c.benchmark_group("kd_build");
    g.sample_size(10);
    let pts = sheet(1_000_000);
    g.throughput(Throughput::Elements(pts.len() as u64));
    g.bench_function("1M points, M = 32768", |b| {
        b.iter_batched(
            || pts.clone(),
            |mut p| kd::build(&mut p, bounds(), 0, 32_768).len(),
            criterion::BatchSize::LargeInput,
        )
    });
    g.finish();
}

fn select(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("stipple-lod-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let world: Vec<DVec3> = sheet(2_000_000).iter().map(|r| r.p().as_dvec3()).collect();
    let cloud = stipple_core::PointCloud::from_world(&world);
    let input = dir.join("sheet.las");
    stipple_io::las_io::write_las(&input, &cloud, false).unwrap();
    let out = dir.join("sheet.stlod");
    let opts = stipple_lod::BuildOptions {
        max_node_points: 4096,
        ..Default::default()
    };
    stipple_lod::build(&[input], &out, &opts).unwrap();
    let tree = stipple_lod::LodTree::open(&out).unwrap();
    let (lo, hi) = tree.world_bounds();
    let mut cam = Camera::framing(lo, hi, 1920, 1080, 45.0);
    cam.eye = (lo + hi) * 0.5 + DVec3::new(0.0, -20.0, 15.0);
    cam.fit_clip(lo, hi);
    c.bench_function("select 1920x1080, budget 1M", |b| {
        b.iter(|| {
            stipple_lod::select(
                &tree,
                &cam,
                &SelectOptions {
                    point_budget: 1_000_000,
                    max_error_px: 1.0,
                },
            )
            .points
        })
    });
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, sample_pick, build, select);
criterion_main!(benches);
