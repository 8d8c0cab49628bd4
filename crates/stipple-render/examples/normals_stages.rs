//! Times each stage of normal estimation on any cloud stipple reads:
//! `cargo run --release -p stipple-render --example normals_stages -- CLOUD [k [knn|orient|all [N]]]`
//! (the third argument stops after that stage; the fourth runs the k-nearest search, PCA and
//! orientation N times each and prints every time, to compare builds on a noisy machine).
//! (The criterion bench `normals` does the same on the Dragon, with statistics.) The stages
//! run as the estimators run them, on the points in the neighbour search's order
//! (`normals::sorted_neighbours`, whose time is the k-nearest stage's); `estimate` is the
//! whole estimation from the file's order.

use std::time::Instant;
use stipple_core::normals;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: normals_stages CLOUD [k [knn|orient]]");
        std::process::exit(2);
    };
    let k: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(16);
    // Optional third argument: stop after "knn" or after "orient".
    let upto = args.get(3).map_or("", String::as_str);
    let repeat: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(1).max(1);
    let t = Instant::now();
    let cloud = match stipple_io::read_cloud(std::path::Path::new(path)) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{path}: {e}");
            std::process::exit(1);
        }
    };
    let pts = &cloud.positions;
    let n = pts.len() as f64;
    println!(
        "{path}: {} points, read in {:.2} s",
        pts.len(),
        t.elapsed().as_secs_f64()
    );
    let stage = |name: &str, t: Instant| {
        let s = t.elapsed().as_secs_f64();
        println!(
            "  {name:<10} {:8.1} ms  {:6.2} M points/s",
            s * 1e3,
            n / s / 1e6
        );
        s
    };
    // As the estimators run: the neighbours found in the search grid's order, and every
    // stage on the points in that order.
    let (mut a, mut b, mut c) = (f64::MAX, f64::MAX, f64::MAX);
    let mut sorted = None;
    for _ in 0..repeat {
        let t = Instant::now();
        sorted = Some(normals::sorted_neighbours(pts, k).expect("neighbours"));
        a = a.min(stage("k-nearest", t));
    }
    let sorted = sorted.expect("at least one run");
    let (pts, nb) = (&sorted.sorted, &sorted.nb);
    if upto == "knn" {
        return;
    }
    let mut nm = Vec::new();
    for _ in 0..repeat {
        let t = Instant::now();
        nm = normals::pca_normals(pts, nb);
        b = b.min(stage("pca", t));
    }
    for r in 0..repeat {
        let mut m = nm.clone();
        let t = Instant::now();
        // The propagation as the estimation runs it for this cloud: without the test for
        // a sheet's two sides where z is up (LAS, LAZ: `normals::orient_above`).
        normals::orient_components(pts, &mut m, nb, !cloud.z_up);
        c = c.min(stage("orient", t));
        if r + 1 == repeat {
            nm = m;
        }
    }
    if repeat > 1 {
        println!(
            "  best of {repeat}: {:.1} + {:.1} + {:.1} ms = {:.2} M points/s",
            a * 1e3,
            b * 1e3,
            c * 1e3,
            n / (a + b + c) / 1e6
        );
    }
    if upto == "orient" {
        return;
    }
    let t = Instant::now();
    let mut above = normals::pca_normals(pts, nb);
    normals::orient_above(pts, &mut above, nb);
    stage("pca+above", t);
    let t = Instant::now();
    let crease = normals::robust_normals(pts, &mut nm, nb);
    stage("robust", t);
    let mut radii = normals::splat_radii(nb, 1.0);
    let t = Instant::now();
    normals::refine_and_shape(pts, &mut nm, &mut radii, nb, &crease);
    stage("refine+shp", t);
    println!(
        "  estimation proper (k-nearest, pca, orient): {:.1} ms, {:.2} M points/s",
        (a + b + c) * 1e3,
        n / (a + b + c) / 1e6
    );
    let t = Instant::now();
    normals::estimate(&cloud.positions, None, k, 1.0).expect("estimate");
    stage("estimate", t);
}
