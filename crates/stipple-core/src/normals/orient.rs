//! Step 3 of the module docs: consistent orientation over a minimum spanning forest
//! (Hoppe et al. 1992), built by Kruskal's algorithm.
//!
//! The graph joins each point to its [`TREE_K`] nearest neighbours on the same layer
//! ([`same_layer`]), with edge weight 1 − |nᵢ·nⱼ| in 1024 levels. Edges are taken in order of
//! weight (a counting sort over the levels), and each edge that joins two trees of the
//! forest is a tree edge, as in Kruskal's algorithm. Orientation then propagates along the
//! tree: every point takes the sign that agrees with its tree neighbours, smooth surface
//! first and sharp creases last. The sign is kept as a parity bit in a union–find structure
//! (the parity of a point relative to its set's root), so propagation costs nothing extra:
//! joining two sets along edge (i, j) fixes the root of the smaller set to the parity that
//! makes nᵢ and nⱼ agree. Finally the highest point of each component (the greatest z, then
//! the smallest index) is turned up (+z; or away from the cloud's centre where its normal
//! is nearly horizontal), and its component with it.
//!
//! This gives the same spanning forest as growing Prim's algorithm from each component's
//! highest point (ties between equal levels aside), and so the same orientation, but its
//! costly parts (the graph, the weights, the counting sort) run in parallel and the serial
//! part is a union–find over the sorted edges (on the Dragon, 437 645 points: 276 ms with
//! Prim, 75 ms now; BENCHMARKS.md).

use super::{same_layer, Neighbours, TREE_K};
use crate::cloud::Bounds;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

const LEVELS: usize = 1024;

/// Union–find with the parity of each element relative to its parent, kept in one word per
/// element (parent index, parity in the top bit: one memory access per step).
struct Forest {
    link: Vec<u32>,
    size: Vec<u32>,
}

const PARITY: u32 = 1 << 31;

impl Forest {
    fn new(n: usize) -> Forest {
        debug_assert!(n < PARITY as usize);
        Forest {
            link: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    /// The root of x's set and x's parity relative to it (with path compression).
    fn find(&mut self, x: u32) -> (u32, u8) {
        let (mut r, mut p) = (x, 0u32);
        loop {
            let l = self.link[r as usize];
            if l & !PARITY == r {
                break;
            }
            p ^= l & PARITY;
            r = l & !PARITY;
        }
        let (mut y, mut py) = (x, p);
        while y != r {
            let l = self.link[y as usize];
            self.link[y as usize] = r | py;
            py ^= l & PARITY;
            y = l & !PARITY;
        }
        (r, (p >> 31) as u8)
    }

    /// Joins the sets of i and j so that their parities differ by `rel`; false when they
    /// were one set already.
    fn join(&mut self, i: u32, j: u32, rel: u8) -> bool {
        let (ri, pi) = self.find(i);
        let (rj, pj) = self.find(j);
        if ri == rj {
            return false;
        }
        let (big, small) = if self.size[ri as usize] >= self.size[rj as usize] {
            (ri, rj)
        } else {
            (rj, ri)
        };
        self.link[small as usize] = big | (((pi ^ pj ^ rel) as u32) << 31);
        self.size[big as usize] += self.size[small as usize];
        true
    }
}

/// [`super::orient`], also returning each point's connected component (0, 1, ..., numbered
/// by their highest points, highest first).
pub fn orient_components(
    positions: &[Vec3],
    normals: &mut [Vec3],
    nb: &Neighbours,
) -> (usize, Vec<u32>) {
    let n = positions.len();
    if n == 0 {
        return (0, Vec::new());
    }
    // Each point's edges: (neighbour, weight level), u32::MAX for none.
    let nr: &[Vec3] = normals;
    let mut edges = vec![(u32::MAX, 0u16); n * TREE_K];
    edges
        .par_chunks_mut(TREE_K)
        .enumerate()
        .for_each(|(i, row)| {
            let all = nb.of(i);
            let mut at = 0;
            for &j in &all[..all.len().min(TREE_K)] {
                let j = j as usize;
                if j == i || !same_layer(positions, nr, i, j) {
                    continue;
                }
                let w = 1.0 - nr[i].dot(nr[j]).abs();
                let level = ((w.clamp(0.0, 1.0) * (LEVELS - 1) as f32) as usize).min(LEVELS - 1);
                row[at] = (j as u32, level as u16);
                at += 1;
            }
        });
    // Counting sort of the edges by level, in parallel: each chunk of points counts its
    // edges per level, and writes them from its own offsets within each level.
    const CHUNK: usize = 1 << 14;
    let counts: Vec<Vec<u32>> = edges
        .par_chunks(CHUNK * TREE_K)
        .map(|c| {
            let mut h = vec![0u32; LEVELS];
            for e in c.iter().filter(|e| e.0 != u32::MAX) {
                h[e.1 as usize] += 1;
            }
            h
        })
        .collect();
    let mut offsets = vec![vec![0u32; LEVELS]; counts.len()];
    let mut total = 0u32;
    for l in 0..LEVELS {
        for (c, h) in counts.iter().enumerate() {
            offsets[c][l] = total;
            total += h[l];
        }
    }
    let sorted: Vec<AtomicU64> = (0..total).map(|_| AtomicU64::new(0)).collect();
    edges
        .par_chunks(CHUNK * TREE_K)
        .zip(offsets)
        .enumerate()
        .for_each(|(c, (chunk, mut at))| {
            for (t, e) in chunk.iter().enumerate() {
                if e.0 != u32::MAX {
                    let i = (c * CHUNK + t / TREE_K) as u64;
                    let slot = &mut at[e.1 as usize];
                    sorted[*slot as usize].store(i << 32 | e.0 as u64, Ordering::Relaxed);
                    *slot += 1;
                }
            }
        });
    drop(edges);
    let mut forest = Forest::new(n);
    let mut joined = 0usize;
    for e in &sorted {
        let e = e.load(Ordering::Relaxed);
        let (i, j) = ((e >> 32) as u32, e as u32);
        let rel = (nr[i as usize].dot(nr[j as usize]) < 0.0) as u8;
        if forest.join(i, j, rel) {
            joined += 1;
            if joined + 1 == n {
                break;
            }
        }
    }
    drop(sorted);
    let found: Vec<(u32, u8)> = (0..n as u32).map(|i| forest.find(i)).collect();
    // Each component's highest point, and the sign that turns it up.
    let mut seed = vec![u32::MAX; n];
    for (i, &(r, _)) in found.iter().enumerate() {
        let s = &mut seed[r as usize];
        if *s == u32::MAX || positions[i].z > positions[*s as usize].z {
            *s = i as u32;
        }
    }
    let centre = Bounds::from_points(positions).center();
    let mut roots: Vec<u32> = (0..n as u32)
        .filter(|&r| seed[r as usize] != u32::MAX)
        .collect();
    roots.sort_unstable_by(|&a, &b| {
        let (sa, sb) = (seed[a as usize] as usize, seed[b as usize] as usize);
        positions[sb]
            .z
            .total_cmp(&positions[sa].z)
            .then(sa.cmp(&sb))
    });
    // Per root: its component's label and the root's own sign (1: turned round).
    let mut label_of = vec![0u32; n];
    let mut root_sign = vec![0u8; n];
    for (c, &r) in roots.iter().enumerate() {
        let s = seed[r as usize] as usize;
        label_of[r as usize] = c as u32;
        let ns = if found[s].1 == 1 { -nr[s] } else { nr[s] };
        let up = if ns.z.abs() > 0.3 {
            ns.z
        } else {
            ns.dot(positions[s] - centre)
        };
        root_sign[r as usize] = (up < 0.0) as u8;
    }
    let flips: usize = normals
        .par_iter_mut()
        .zip(found.par_iter())
        .map(|(nm, &(r, p))| {
            let flip = p ^ root_sign[r as usize] == 1;
            if flip {
                *nm = -*nm;
            }
            flip as usize
        })
        .sum();
    let label = found.iter().map(|&(r, _)| label_of[r as usize]).collect();
    (flips, label)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parities_compose_along_paths() {
        let mut f = Forest::new(5);
        assert!(f.join(0, 1, 1));
        assert!(f.join(1, 2, 1));
        assert!(f.join(3, 4, 0));
        assert!(f.join(4, 2, 1));
        assert!(!f.join(0, 2, 0));
        let p: Vec<u8> = (0..5).map(|i| f.find(i).1).collect();
        // 0 and 1 differ, 1 and 2 differ, 3 and 4 agree, 4 and 2 differ.
        assert_ne!(p[0], p[1]);
        assert_ne!(p[1], p[2]);
        assert_eq!(p[3], p[4]);
        assert_ne!(p[4], p[2]);
        let r = f.find(0).0;
        assert!((0..5).all(|i| f.find(i).0 == r));
    }
}
