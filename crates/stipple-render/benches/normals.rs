//! Normal estimation benchmarks (criterion): each stage of `stipple_core::normals::estimate`
//! and the whole, on the Stanford Dragon (437 645 points, `../shared/data`), k = 16. Skips
//! with a message when the data is absent. The stages run as the estimators run them: the
//! neighbours found in the search grid's order (`sorted_neighbours`), every later stage on
//! the points in that order; `neighbours_k16` is the search alone in the file's order.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use stipple_core::normals;

fn dragon() -> Option<Vec<glam::Vec3>> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/stanford/dragon/dragon_vrip.ply.gz");
    match stipple_io::read_cloud(&p) {
        Ok(c) => Some(c.positions),
        Err(e) => {
            eprintln!("normals bench skipped: {} ({e})", p.display());
            None
        }
    }
}

fn bench(c: &mut Criterion) {
    let Some(original) = dragon() else {
        return;
    };
    let pts = &original;
    let mut g = c.benchmark_group("normals_dragon");
    g.sample_size(10);
    g.throughput(Throughput::Elements(pts.len() as u64));
    g.bench_function("neighbours_k16", |b| {
        b.iter(|| normals::neighbours(pts, 16).unwrap())
    });
    g.bench_function("sorted_neighbours_k16", |b| {
        b.iter(|| normals::sorted_neighbours(pts, 16).unwrap())
    });
    let sorted = normals::sorted_neighbours(pts, 16).unwrap();
    let (pts, nb) = (&sorted.sorted, &sorted.nb);
    g.bench_function("pca", |b| b.iter(|| normals::pca_normals(pts, nb)));
    let pca = normals::pca_normals(pts, nb);
    g.bench_function("orient", |b| {
        b.iter(|| {
            let mut n = pca.clone();
            normals::orient(pts, &mut n, nb)
        })
    });
    let mut n = pca.clone();
    normals::orient(pts, &mut n, nb);
    g.bench_function("robust", |b| {
        b.iter(|| {
            let mut m = n.clone();
            normals::robust_normals(pts, &mut m, nb)
        })
    });
    g.bench_function("refine", |b| {
        b.iter(|| {
            let mut m = n.clone();
            normals::refine_normals(pts, &mut m, nb)
        })
    });
    let radii = normals::splat_radii(nb, 1.0);
    g.bench_function("shapes", |b| {
        b.iter(|| normals::shapes(pts, &n, &mut radii.clone(), nb))
    });
    g.bench_function("estimate_all", |b| {
        b.iter(|| normals::estimate(&original, None, 16, 1.0).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
