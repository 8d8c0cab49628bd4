//! Hierarchical bucket sorting (Gunjee §4.2) on the CPU and (where an adapter exists;
//! required with STIPPLE_REQUIRE_GPU=1) the GPU: the order differs from a full sort by depth
//! only within a slice, every point in view is there once, and both backends agree.

mod common;

use glam::{DVec3, Vec3};
use stipple_core::rng::Rng;
use stipple_core::{Camera, PointCloud, Projection};
use stipple_render::passes::bucket_sort::cpu::Sorted;
use stipple_render::{PreparedCloud, ViewParams};

fn camera() -> Camera {
    Camera {
        eye: DVec3::new(0.3, 0.2, 6.0),
        target: DVec3::ZERO,
        up: DVec3::Y,
        projection: Projection::Perspective { fov_deg: 40.0 },
        width: 320,
        height: 240,
        near: 0.5,
        far: 20.0,
    }
}

/// Random points in a box wider than the view (some fall outside it, some behind the eye).
fn cloud(n: usize, seed: u64) -> PreparedCloud {
    let mut rng = Rng::new(seed);
    let positions = (0..n)
        .map(|_| {
            Vec3::new(
                rng.f32() * 8.0 - 4.0,
                rng.f32() * 6.0 - 3.0,
                rng.f32() * 9.0 - 3.0,
            )
        })
        .collect();
    PreparedCloud::new(PointCloud {
        positions,
        ..Default::default()
    })
}

fn check(sorted: &Sorted, c: &PreparedCloud, v: &ViewParams, eps: f32, who: &str) {
    let depth = |i: u32| {
        stipple_render::passes::project::cpu::project_point(v, c.cloud.positions[i as usize])
            .map(|(_, z)| z)
    };
    // Every point in view, once.
    let mut seen = vec![false; c.cloud.len()];
    for &i in &sorted.order {
        assert!(!seen[i as usize], "{who}: point {i} twice");
        seen[i as usize] = true;
    }
    let in_view = (0..c.cloud.len() as u32)
        .filter(|&i| depth(i).is_some())
        .count();
    assert_eq!(sorted.order.len(), in_view, "{who}: points in view");
    assert!(sorted.order.iter().all(|&i| depth(i).is_some()));
    // Slices far to near, each point in its own slice.
    assert!(
        sorted.slices.windows(2).all(|w| w[0] >= w[1]),
        "{who}: slices out of order"
    );
    // A backend's own rounding of a depth (a GPU's fused multiply-adds and division) may
    // put a point on a slice's boundary into the next one: within 1e-5 of the depth (about
    // a hundred float steps, what a division of 2.5 ulp in the slice index can move it)
    // either side is right, farther none is.
    let s = &sorted.slicing;
    let wrong: Vec<(u32, f32, u32)> = sorted
        .order
        .iter()
        .zip(&sorted.slices)
        .map(|(&i, &sl)| (i, depth(i).unwrap(), sl))
        .filter(|&(_, z, sl)| {
            let d = 1e-5 * z.abs().max(1.0);
            !(s.slice(z - d)..=s.slice(z + d)).contains(&sl)
        })
        .collect();
    assert!(
        wrong.is_empty(),
        "{who}: {} points in another slice, e.g. (point, depth, slice) {:?}",
        wrong.len(),
        &wrong[..wrong.len().min(4)]
    );
    // Against a full sort: a point may come before a farther one only within a slice.
    let mut least = f32::INFINITY;
    let mut inversions = 0u64;
    for &i in &sorted.order {
        let z = depth(i).unwrap();
        assert!(
            z <= least + s.eps * 1.001,
            "{who}: depth {z} after {least}, more than a slice ({}) nearer",
            s.eps
        );
        inversions += (z > least) as u64;
        least = least.min(z);
    }
    assert!(s.eps >= eps * 0.999);
    eprintln!(
        "{who}: {} points in view, {} × {} buckets ({} slices of {}), {inversions} inversions \
         within slices",
        in_view,
        s.n,
        s.k,
        s.slices(),
        s.eps
    );
}

#[test]
fn bucket_sorted_order_differs_from_a_full_sort_only_within_a_slice() {
    let cam = camera();
    let mut results = Vec::new();
    for mut r in common::backends() {
        for (n, eps) in [
            (1usize, 0.01f32),
            (200_000, 0.002),
            (50_000, 0.5),
            (50_000, 1e-9),
        ] {
            let c = cloud(n, n as u64);
            let v = ViewParams::new(&cam, c.cloud.origin);
            let sorted = r.bucket_sort(&c, &cam, eps).unwrap();
            check(
                &sorted,
                &c,
                &v,
                eps,
                &format!("{} ({n} points, ε {eps})", r.describe()),
            );
            results.push(sorted);
        }
        // Nothing in view: an empty order.
        let mut far = cam.clone();
        far.eye = DVec3::new(0.0, 0.0, 100.0);
        far.target = DVec3::new(0.0, 0.0, 200.0);
        let c = cloud(1000, 3);
        assert!(r.bucket_sort(&c, &far, 0.01).unwrap().order.is_empty());
    }
    let half = results.len() / 2;
    if results.len() == 8 {
        for (a, b) in results[..half].iter().zip(&results[half..]) {
            // The same buckets; the nearest depth and the slice thickness as each backend
            // rounds them (a GPU's fused multiply-adds move their last bits).
            let (sa, sb) = (&a.slicing, &b.slicing);
            assert_eq!((sa.n, sa.k), (sb.n, sb.k), "both backends bucket alike");
            let close = |x: f32, y: f32| (x - y).abs() <= 1e-5 * x.abs().max(1.0);
            assert!(
                close(sa.near, sb.near) && close(sa.eps, sb.eps),
                "both backends slice alike: {sa:?} against {sb:?}"
            );
            // The same points, each in the slice of its depth (check() bounds each
            // backend's slice by the depth, a boundary's rounding either side); their order
            // within a slice is the GPU's atomics'.
            let slice_of = |s: &Sorted| {
                let mut m: Vec<(u32, u32)> = s
                    .order
                    .iter()
                    .copied()
                    .zip(s.slices.iter().copied())
                    .collect();
                m.sort_unstable();
                m
            };
            let (pa, pb) = (slice_of(a), slice_of(b));
            assert!(
                pa.iter().map(|p| p.0).eq(pb.iter().map(|p| p.0)),
                "both backends keep the same points"
            );
            let differ = pa.iter().zip(&pb).filter(|(x, y)| x.1 != y.1).count();
            eprintln!("parity: {differ} of {} points in another slice", pa.len());
        }
    }
}
