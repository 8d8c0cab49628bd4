//! Kernel benchmarks (criterion): each CPU pass on a 1024×1024 frame of the 1 M point
//! `plane-objects` demo scene. Whole-frame figures come from `stipple bench`.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use stipple_core::demo::{generate, DemoScene};
use stipple_core::Camera;
use stipple_render::passes::{
    antialias::cpu as antialias, fill_background::cpu as fill_background,
    fill_occluded::cpu as fill_occluded, project::cpu as project, smooth::cpu as smooth,
};
use stipple_render::{GBuffer, Kernel, PreparedCloud, ViewParams};

fn setup() -> (PreparedCloud, ViewParams) {
    let cloud = PreparedCloud::new(generate(DemoScene::PlaneObjects, 1_000_000, 1));
    let (lo, hi) = cloud.cloud.world_bounds();
    let cam = Camera::framing(lo, hi, 1024, 1024, 45.0);
    let v = ViewParams::new(&cam, cloud.cloud.origin);
    (cloud, v)
}

fn passes(c: &mut Criterion) {
    let (cloud, v) = setup();
    let pts = &cloud.cloud.positions;
    let normals = cloud.cloud.normals.as_deref();
    let threads = rayon::current_num_threads();
    let mut bufs = vec![Vec::new(); threads];
    let mut g = GBuffer::new(v.width, v.height);
    let mut group = c.benchmark_group("cpu");
    group.throughput(Throughput::Elements(pts.len() as u64));
    group.bench_function("project_1M_points", |b| {
        b.iter(|| project::project_private(&v, pts, normals, true, None, &mut bufs, &mut g))
    });
    group.throughput(Throughput::Elements(v.pixels() as u64));
    // The fills work in place: each iteration gets a fresh copy of the G-buffer (not timed).
    for r in [1, 2] {
        group.bench_function(format!("fill_background_r{r}_1024"), |b| {
            b.iter_batched_ref(
                || g.clone(),
                |h| fill_background::fill_background_in_place(h, r),
                BatchSize::LargeInput,
            )
        });
    }
    let gap = 3.0 * cloud.spacing;
    for r in [1, 2] {
        group.bench_function(format!("fill_occluded_r{r}_1024"), |b| {
            b.iter_batched_ref(
                || g.clone(),
                |h| fill_occluded::fill_occluded_in_place(h, gap, r),
                BatchSize::LargeInput,
            )
        });
    }
    let colour = vec![[0.5f32; 3]; v.pixels()];
    let mut dst = colour.clone();
    let (w, h) = (v.width as usize, v.height as usize);
    group.bench_function("smooth_1024", |b| {
        b.iter(|| smooth::smooth(w, h, &g.id, Kernel::Alleviated, &colour, &mut dst))
    });
    group.bench_function("antialias_1024", |b| {
        let p = antialias::AaParams {
            far: v.far,
            threshold: 0.02,
            strength: 0.6,
        };
        b.iter(|| antialias::antialias(w, h, &g.depth, p, &colour, &mut dst))
    });
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(3));
    targets = passes
}
criterion_main!(benches);
