//! Hierarchical bucket sort (Gunjee §4.2) against a full sort, on the Stanford Dragon
//! (437 645 points, `../shared/data`) seen whole at 1024²: view culling (depths and range)
//! alone, the bucket sort with ε = the smallest splat radius (the paper's choice) and with
//! ε = the median spacing, and a full comparison sort of the culled points by depth (rayon's
//! parallel unstable sort). Skips with a message when the data is absent.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayon::prelude::*;
use stipple_render::passes::bucket_sort::cpu;
use stipple_render::{PreparedCloud, ViewParams};

fn dragon() -> Option<PreparedCloud> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/stanford/dragon/dragon_vrip.ply.gz");
    match stipple_io::read_cloud(&p) {
        Ok(c) => Some(PreparedCloud::new(c)),
        Err(e) => {
            eprintln!("sort bench skipped: {} ({e})", p.display());
            None
        }
    }
}

fn bench(c: &mut Criterion) {
    let Some(cloud) = dragon() else {
        return;
    };
    let (lo, hi) = cloud.cloud.world_bounds();
    let cam = stipple_core::Camera::framing(lo, hi, 1024, 1024, 40.0);
    let v = ViewParams::new(&cam, cloud.cloud.origin);
    let pts = &cloud.cloud.positions;
    let min_radius = cloud.least_splat_radius();
    let mut g = c.benchmark_group("sort_dragon");
    g.sample_size(20);
    g.throughput(Throughput::Elements(pts.len() as u64));
    g.bench_function("cull", |b| b.iter(|| cpu::cull(&v, pts)));
    g.bench_function("bucket_min_radius", |b| {
        b.iter(|| cpu::sort(&v, pts, min_radius))
    });
    g.bench_function("bucket_spacing", |b| {
        b.iter(|| cpu::sort(&v, pts, cloud.spacing))
    });
    g.bench_function("full_sort", |b| {
        b.iter(|| {
            let (depth, _) = cpu::cull(&v, pts);
            let mut kept: Vec<(f32, u32)> = depth
                .iter()
                .enumerate()
                .filter_map(|(i, z)| z.map(|z| (z, i as u32)))
                .collect();
            kept.par_sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
            kept
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
