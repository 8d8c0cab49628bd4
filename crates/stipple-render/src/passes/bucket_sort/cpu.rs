//! # bucket_sort (CPU reference): two stable counting sorts (see the module documentation
//! of [`super`]).

use super::Slicing;
use crate::params::ViewParams;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

/// Points in back-to-front order and the slicing that ordered them.
#[derive(Clone, Debug, PartialEq)]
pub struct Sorted {
    /// Indices of the kept points, farthest slice first.
    pub order: Vec<u32>,
    /// Each kept point's slice, in the order of `order`.
    pub slices: Vec<u32>,
    pub slicing: Slicing,
}

/// Step 1: the view depth of every point that projects into the image (None for the others),
/// and the kept points' nearest and farthest depths (None when no point is kept).
pub fn cull(v: &ViewParams, positions: &[Vec3]) -> (Vec<Option<f32>>, Option<(f32, f32)>) {
    let depth: Vec<Option<f32>> = positions
        .par_iter()
        .with_min_len(4096)
        .map(|&p| crate::passes::project::cpu::project_point(v, p).map(|(_, z)| z))
        .collect();
    let range = depth
        .par_iter()
        .with_min_len(4096)
        .filter_map(|z| z.map(|z| (z, z)))
        .reduce_with(|a, b| (a.0.min(b.0), a.1.max(b.1)));
    (depth, range)
}

/// Sorts the points of `positions` seen in `v` back to front in slices of thickness `eps`
/// over the depths of the points kept.
pub fn sort(v: &ViewParams, positions: &[Vec3], eps: f32) -> Sorted {
    let (depth, range) = cull(v, positions);
    let Some((near, far)) = range else {
        return Sorted {
            order: Vec::new(),
            slices: Vec::new(),
            slicing: Slicing::new(0.0, 0.0, eps),
        };
    };
    in_slices(&depth, Slicing::new(near, far, eps))
}

/// Sorts the points of `positions` seen in `v` back to front in the slices `slicing` (over
/// a range at least as wide as the kept points' depths, e.g. the bounds').
pub fn sort_in(v: &ViewParams, positions: &[Vec3], slicing: Slicing) -> Sorted {
    in_slices(&cull(v, positions).0, slicing)
}

fn in_slices(depth: &[Option<f32>], slicing: Slicing) -> Sorted {
    // The slice of each kept point, u32::MAX for the others.
    let key: Vec<u32> = depth
        .par_iter()
        .with_min_len(4096)
        .map(|z| z.map_or(u32::MAX, |z| slicing.slice(z)))
        .collect();
    let order = by_slices(&key, &slicing);
    let slices = order.iter().map(|&i| key[i as usize]).collect();
    Sorted {
        order,
        slices,
        slicing,
    }
}

/// The indices of the points whose `key` (slice) is not u32::MAX, farthest slice first and by
/// index within a slice: a first-level counting sort into N buckets, then each bucket's
/// counting sort into K.
pub fn by_slices(key: &[u32], s: &Slicing) -> Vec<u32> {
    let (n, k) = (s.n as usize, s.k as usize);
    // Bucket b (0 = the farthest) of slice `slice` at level 1.
    let level1 = |slice: u32| n - 1 - slice as usize / k;
    // Per-thread chunks: histograms, then each chunk's start in each bucket (stable).
    let chunk = key
        .len()
        .div_ceil(rayon::current_num_threads().max(1) * 4)
        .max(4096);
    let hist: Vec<Vec<u32>> = key
        .par_chunks(chunk)
        .map(|c| {
            let mut h = vec![0u32; n];
            for &s in c {
                if s != u32::MAX {
                    h[level1(s)] += 1;
                }
            }
            h
        })
        .collect();
    let mut start = vec![0usize; n + 1];
    for b in 0..n {
        start[b + 1] = start[b] + hist.iter().map(|h| h[b] as usize).sum::<usize>();
    }
    let kept = start[n];
    // Each chunk's write position in each bucket.
    let mut at: Vec<Vec<usize>> = Vec::with_capacity(hist.len());
    let mut next = start[..n].to_vec();
    for h in &hist {
        at.push(next.clone());
        for b in 0..n {
            next[b] += h[b] as usize;
        }
    }
    // Chunks write disjoint positions (each owns its own range in each bucket); relaxed
    // atomic stores are plain stores.
    let first: Vec<AtomicU32> = (0..kept).map(|_| AtomicU32::new(0)).collect();
    key.par_chunks(chunk)
        .zip(at.into_par_iter())
        .enumerate()
        .for_each(|(ci, (c, mut pos))| {
            for (j, &s) in c.iter().enumerate() {
                if s != u32::MAX {
                    let b = level1(s);
                    first[pos[b]].store((ci * chunk + j) as u32, Ordering::Relaxed);
                    pos[b] += 1;
                }
            }
        });
    // Level 2: within each first-level bucket, a counting sort into K, farthest first.
    let mut order = vec![0u32; kept];
    let mut ranges: Vec<(&[AtomicU32], &mut [u32])> = Vec::with_capacity(n);
    let mut rest = &mut order[..];
    for b in 0..n {
        let len = start[b + 1] - start[b];
        let (head, tail) = rest.split_at_mut(len);
        ranges.push((&first[start[b]..start[b + 1]], head));
        rest = tail;
    }
    ranges.into_par_iter().for_each(|(src, dst)| {
        if src.is_empty() {
            return;
        }
        let mut count = vec![0usize; k + 1];
        let level2 = |i: u32| k - 1 - key[i as usize] as usize % k;
        for i in src {
            count[level2(i.load(Ordering::Relaxed)) + 1] += 1;
        }
        for b in 0..k {
            count[b + 1] += count[b];
        }
        for i in src {
            let i = i.load(Ordering::Relaxed);
            let b = level2(i);
            dst[count[b]] = i;
            count[b] += 1;
        }
    });
    order
}

#[cfg(test)]
mod tests {
    use super::*;
    use stipple_core::rng::Rng;

    #[test]
    fn slices_come_back_to_front_and_by_index_within_a_slice() {
        let mut rng = Rng::new(7);
        for (len, n, k) in [(0, 3, 4), (1, 1, 1), (5000, 7, 13), (100_000, 64, 64)] {
            let s = Slicing {
                near: 0.0,
                eps: 1.0,
                n,
                k,
            };
            let key: Vec<u32> = (0..len)
                .map(|_| {
                    if rng.f32() < 0.1 {
                        u32::MAX
                    } else {
                        (rng.f32() * (n * k) as f32) as u32 % (n * k)
                    }
                })
                .collect();
            let got = by_slices(&key, &s);
            let mut want: Vec<u32> = (0..len as u32)
                .filter(|&i| key[i as usize] != u32::MAX)
                .collect();
            want.sort_by_key(|&i| std::cmp::Reverse(key[i as usize]));
            assert_eq!(got, want, "{len} points, {n} × {k} buckets");
        }
    }
}
