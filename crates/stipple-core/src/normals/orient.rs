//! Step 3 of the module docs: consistent orientation over a minimum spanning forest
//! (Hoppe et al. 1992), built by Kruskal's algorithm.
//!
//! The graph joins each point to its [`TREE_K`] nearest neighbours on the same layer
//! ([`same_layer`]; or, whatever the normals' signs, [`one_layer`]), with edge weight
//! 1 − |nᵢ·nⱼ| in 1024 levels (lower across a sharp crease where the points' places say
//! clearly how the signs relate: `relation`). Edges are taken in order of
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
//! costly parts run in parallel: each chunk of points lists its edges and counting-sorts
//! them by level on its own, and the serial loop takes level after level from every chunk
//! in turn (no global array of edges). An edge that both of its ends list (each is among
//! the other's nearest, as most are) is listed once, which halves the serial loop's work.
//! Each chunk runs Kruskal's loop on its own edges first: by the cycle property, an edge
//! that closes a cycle within the chunk is dropped by the serial loop too, so only the
//! chunk's own spanning-forest edges and the edges that leave it go on (Autzen: 59 M edges
//! → 12 M). Where the points' order keeps neighbours together (the neighbour search's
//! order, in which the estimators run; meshes; most scans) chunks are wide runs of that
//! order, from which few edges leave. Where it scatters them (LiDAR flight lines, COPC
//! nodes: the serial loop's union–find would miss the cache on every edge), chunks are
//! runs of points in a spatial order (a coarse Morton grid).
//! On the Dragon (437 645 points): 276 ms with Prim, 84 ms with one global counting sort,
//! 55 ms with chunks in the file's order and no loop of their own, 54 ms now; on Autzen
//! (10.65 M), 6.3 → 2.8 → 2.0–2.5 → 1.8–2.0 → 1.5–1.6 s (BENCHMARKS.md).

use super::{layer_scatter, one_layer, same_layer, Neighbours, TREE_K};
use crate::cloud::Bounds;
use glam::Vec3;
use rayon::prelude::*;

const LEVELS: usize = 1024;
/// How many edges ahead the serial loop asks for the links of an edge's ends, which lie
/// anywhere in its 4 bytes a point (Autzen: 0.32 → 0.28 s).
const AHEAD: usize = 16;

/// Points per chunk of the parallel edge listing.
const CHUNK: usize = 1 << 14;

/// Points per chunk at most where the points' own order keeps neighbours together.
const WIDE: usize = 1 << 18;

/// One thread's buffers for listing a chunk's edges, kept from chunk to chunk: fresh ones
/// (a few MB a chunk) were mapped and zeroed by the kernel page by page each time, which
/// cost Autzen's orientation more than the listing and the counting sort themselves.
#[derive(Default)]
struct Scratch {
    /// The edges as listed.
    edges: Vec<u64>,
    /// Their levels (apart: a pair would take 16 bytes, not 10).
    levels: Vec<u16>,
    /// The edges in order of level.
    sorted: Vec<u64>,
    /// The chunk's own spanning forest.
    local: Forest,
}

/// Union–find with the parity of each element relative to its parent, kept in one word per
/// element (parent index, parity in the top bit: one memory access per step).
#[derive(Default)]
struct Forest {
    link: Vec<u32>,
    size: Vec<u32>,
}

const PARITY: u32 = 1 << 31;

impl Forest {
    fn new(n: usize) -> Forest {
        let mut f = Forest::default();
        f.reset(n);
        f
    }

    /// n elements, each its own set (the buffers kept).
    fn reset(&mut self, n: usize) {
        debug_assert!(n < PARITY as usize);
        self.link.clear();
        self.link.extend(0..n as u32);
        self.size.clear();
        self.size.resize(n, 1);
    }

    /// The root of x's set and x's parity relative to it (with path compression).
    fn find(&mut self, x: u32) -> (u32, u8) {
        let (r, parity) = self.root(x);
        let (mut y, mut py) = (x, (parity as u32) << 31);
        while y != r {
            let l = self.link[y as usize];
            self.link[y as usize] = r | py;
            py ^= l & PARITY;
            y = l & !PARITY;
        }
        (r, parity)
    }

    /// Asks the processor to bring x's link into the cache.
    #[inline(always)]
    fn prefetch(&self, x: u32) {
        #[cfg(target_arch = "x86_64")]
        if let Some(l) = self.link.get(x as usize) {
            // SAFETY: a prefetch only hints; the address is x's link, in the array.
            unsafe {
                std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                    (l as *const u32).cast::<i8>(),
                )
            };
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = x;
    }

    /// [`Forest::find`] without path compression, so that many threads may ask at once.
    fn root(&self, x: u32) -> (u32, u8) {
        let (mut r, mut p) = (x, 0u32);
        loop {
            let l = self.link[r as usize];
            if l & !PARITY == r {
                return (r, (p >> 31) as u8);
            }
            p ^= l & PARITY;
            r = l & !PARITY;
        }
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

/// Normals this near parallel (or antiparallel; cosine) go by their dot product.
const PARALLEL: f32 = 0.5;
/// A point this far off the other's tangent plane (over their distance) is off it.
const OFF: f32 = 0.1;

/// At a sharp crease (normals 60–120° apart), each point's offset from the other's tangent
/// plane (nᵢ·d, nⱼ·d), when both are clearly off it; None elsewhere.
pub(super) fn crease_sides(
    positions: &[Vec3],
    normals: &[Vec3],
    i: usize,
    j: usize,
) -> Option<(f32, f32)> {
    let (a, b) = (normals[i], normals[j]);
    if a.dot(b).abs() >= PARALLEL {
        return None;
    }
    let d = positions[j] - positions[i];
    let len = d.length();
    let (ha, hb) = (a.dot(d), b.dot(d));
    (ha.abs() > OFF * len && hb.abs() > OFF * len).then_some((ha, hb))
}

/// An edge's weight in the spanning tree, and whether normal j must turn round to agree
/// with normal i (the edge's flip), from one look at the two points. The edge listing,
/// which runs in parallel, carries the flip to the serial loop in the edge's top bit
/// ([`FLIP`]), so that loop reads no normals or positions.
///
/// The weight is 1 − |nᵢ·nⱼ| (Hoppe et al.), lowered across a sharp crease by how clearly
/// the points lie off each other's planes (there the flip goes by their places, surely
/// when they are far off), so that the tree crosses creases where the evidence is clear
/// rather than where a point sits on the edge itself.
///
/// The flip: nearly parallel normals (less than 60° apart, or more than 120°) agree when
/// they point the same way (Hoppe et al.). At a sharp crease, normals 60–120° apart (a
/// box's edge; a tetrahedron's, 109°) say little by their dot product, which the noise of
/// a fit or the crease's angle can turn either way (a tetrahedron's consistent normals have
/// a negative one). There the points' places decide: across a convex edge each point lies
/// behind the other's tangent plane, across a concave one in front of it, so consistent
/// normals put each on opposite sides ((nᵢ·d)(nⱼ·d) < 0, d = pⱼ − pᵢ), when both points lie
/// clearly off the other's plane.
#[inline]
fn relation(positions: &[Vec3], normals: &[Vec3], i: usize, j: usize) -> (f32, bool) {
    let c = normals[i].dot(normals[j]);
    match crease_sides(positions, normals, i, j) {
        Some((ha, hb)) => {
            let len = (positions[j] - positions[i]).length();
            (
                1.0 - c.abs().max(ha.abs().min(hb.abs()) / len),
                ha * hb > 0.0,
            )
        }
        None => (1.0 - c.abs(), c < 0.0),
    }
}

/// The top bit of a listed edge (i << 32 | j, i < 2^31): set where j's normal must turn
/// round to agree with i's.
const FLIP: u64 = 1 << 63;

/// [`super::orient`], also returning each point's connected component (0, 1, ..., numbered
/// by their highest points, highest first). With `layers`, neighbours on the two sides of
/// a sheet are told apart whatever their normals' signs ([`one_layer`]), else only where
/// both face out ([`same_layer`]). The test reads every neighbour's position, which the
/// rest of the listing mostly does not, and on noisy points the scatter: Autzen's
/// orientation 1.5–1.6 → 1.9 s. It is left out for clouds whose z is up
/// ([`super::orient_above`]: LiDAR, whose signs the vote from above sets; with it, the
/// share of normals facing down went from 5.8% to 5.4% on Autzen's trimmed tile and hardly
/// moved on the IGN tile and the terrestrial `lone-star.laz`).
pub fn orient_components(
    positions: &[Vec3],
    normals: &mut [Vec3],
    nb: &Neighbours,
    layers: bool,
) -> (usize, Vec<u32>) {
    let n = positions.len();
    if n == 0 {
        return (0, Vec::new());
    }
    // Each chunk of points lists its edges and counting-sorts them by level, in parallel;
    // Kruskal's loop then takes level after level from every chunk in turn, so the edges
    // never move into one global array. An edge that both ends list (each is among the
    // other's nearest) is kept once, by the end with the smaller index.
    let nr: &[Vec3] = normals;
    // Each chunk drops the edges that close a cycle within it (below), which leaves the
    // serial loop a fifth of the edges. Where the points' order scatters neighbours (LiDAR
    // in flight order, COPC in node order; the serial loop's union–find would miss the
    // cache on every edge: Autzen, 37 ns an edge against 11 on the Dragon), chunks are
    // runs of points in a spatial order (Morton order of a coarse grid). Elsewhere they are
    // wide runs of the points' own order (up to 2^18 points, at least four a thread): few
    // edges leave them, and no order or rank is computed (the Dragon: 63 → 54 ms).
    let wide = (n / (4 * rayon::current_num_threads())).clamp(CHUNK, WIDE);
    let spatial = local_fraction(nb, wide / 2) < 0.9;
    let (order, chunk): (Vec<u32>, usize) = if spatial {
        (spatial_order(positions), CHUNK)
    } else {
        ((0..n as u32).collect(), wide)
    };
    let mut rank = Vec::new();
    if spatial {
        rank = vec![0u32; n];
        for (r, &i) in order.iter().enumerate() {
            rank[i as usize] = r as u32;
        }
    }
    let chunks: Vec<(Vec<u64>, Vec<u32>)> = order
        .par_chunks(chunk)
        .enumerate()
        .map_init(Scratch::default, |scratch, (c, members)| {
            let first = c * chunk;
            let Scratch {
                edges,
                levels,
                sorted,
                local,
            } = scratch;
            edges.clear();
            levels.clear();
            let mut count = vec![0u32; LEVELS + 1];
            for &i in members {
                let i = i as usize;
                let all = nb.of(i);
                // Point i's scatter, computed at most once and only where an edge needs it.
                let mut scatter = None;
                for &j in &all[..all.len().min(TREE_K)] {
                    let j = j as usize;
                    if j == i {
                        continue;
                    }
                    if j < i {
                        // (Without an early exit: the compiler compares the ten at once.)
                        let back = nb.of(j);
                        let listed = back[..back.len().min(TREE_K)]
                            .iter()
                            .fold(false, |a, &x| a | (x == i as u32));
                        if listed {
                            continue;
                        }
                    }
                    let apart = if layers {
                        let sc =
                            || *scatter.get_or_insert_with(|| layer_scatter(positions, nr, nb, i));
                        !one_layer(positions, nr, i, j, sc)
                    } else {
                        !same_layer(positions, nr, i, j)
                    };
                    if apart {
                        continue;
                    }
                    let (w, flip) = relation(positions, nr, i, j);
                    let level =
                        ((w.clamp(0.0, 1.0) * (LEVELS - 1) as f32) as usize).min(LEVELS - 1);
                    let e = (flip as u64) << 63 | (i as u64) << 32 | j as u64;
                    edges.push(e);
                    levels.push(level as u16);
                    count[level + 1] += 1;
                }
            }
            for l in 0..LEVELS {
                count[l + 1] += count[l];
            }
            let mut at = count.clone();
            sorted.clear();
            sorted.resize(edges.len(), 0);
            for (&e, &l) in edges.iter().zip(levels.iter()) {
                sorted[at[l as usize] as usize] = e;
                at[l as usize] += 1;
            }
            // Kruskal's loop within the chunk first: an edge between two of its points that
            // closes a cycle of edges taken before it (lighter, or as light and earlier)
            // closes the same cycle in the whole graph, where the serial loop would drop
            // it. So only the chunk's own spanning-forest edges and the edges that leave
            // the chunk go on, in the same order, and the forest is the same.
            local.reset(members.len());
            let within = |x: usize| {
                let r = if spatial { rank[x] as usize } else { x };
                (first..first + members.len())
                    .contains(&r)
                    .then(|| (r - first) as u32)
            };
            let mut kept = 0;
            let mut start = vec![0u32; LEVELS + 1];
            for l in 0..LEVELS {
                start[l] = kept as u32;
                for s in count[l] as usize..count[l + 1] as usize {
                    let e = sorted[s];
                    let (i, j) = (((e & !FLIP) >> 32) as usize, (e as u32) as usize);
                    let keep = match (within(i), within(j)) {
                        (Some(a), Some(b)) => local.join(a, b, 0),
                        _ => true,
                    };
                    if keep {
                        sorted[kept] = e;
                        kept += 1;
                    }
                }
            }
            start[LEVELS] = kept as u32;
            (sorted[..kept].to_vec(), start)
        })
        .collect();
    drop(rank);
    let mut forest = Forest::new(n);
    let mut joined = 0usize;
    'levels: for l in 0..LEVELS {
        for (sorted, start) in &chunks {
            let run = &sorted[start[l] as usize..start[l + 1] as usize];
            for (s, &e) in run.iter().enumerate() {
                if let Some(&ahead) = run.get(s + AHEAD) {
                    forest.prefetch(((ahead & !FLIP) >> 32) as u32);
                    forest.prefetch(ahead as u32);
                }
                let (i, j) = (((e & !FLIP) >> 32) as u32, e as u32);
                if forest.join(i, j, (e >> 63) as u8) {
                    joined += 1;
                    if joined + 1 == n {
                        break 'levels;
                    }
                }
            }
        }
    }
    drop(chunks);
    let found: Vec<(u32, u8)> = (0..n as u32)
        .into_par_iter()
        .map(|i| forest.root(i))
        .collect();
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
    let label = found
        .par_iter()
        .map(|&(r, _)| label_of[r as usize])
        .collect();
    (flips, label)
}

/// The fraction of (a sample of) points' tree neighbours whose index lies within `reach`
/// of the point's own: how well the file's order keeps neighbours together.
pub(super) fn local_fraction(nb: &Neighbours, reach: usize) -> f32 {
    let n = nb.found.len();
    let step = (n / 4096).max(1);
    let (mut near, mut all) = (0usize, 0usize);
    for i in (0..n).step_by(step) {
        let row = nb.of(i);
        for &j in &row[..row.len().min(TREE_K)] {
            near += ((j as usize).abs_diff(i) < reach) as usize;
            all += 1;
        }
    }
    if all == 0 {
        1.0
    } else {
        near as f32 / all as f32
    }
}

/// The points in Morton order of a grid of cubic cells, at least n / 16 of them (a counting
/// sort; within a cell, in index order). Cubic, so that a flat cloud (LiDAR) spends the
/// code's bits on its two long axes.
pub(super) fn spatial_order(positions: &[Vec3]) -> Vec<u32> {
    let n = positions.len();
    let b = Bounds::from_points(positions);
    // 2^bits cells per axis, 3 × bits ≤ 24 (16 M counters at most).
    let bits = ((n / 16).max(1).ilog2() / 3 + 1).clamp(1, 8);
    let cells = 1usize << (3 * bits);
    let scale = (1u32 << bits) as f32 / b.extent().max_element().max(1e-30);
    let top = (1u32 << bits) - 1;
    let code: Vec<u32> = positions
        .par_iter()
        .map(|&p| {
            let c = ((p - b.min) * scale).max(Vec3::ZERO);
            let q = |v: f32| (v as u32).min(top);
            crate::cloud::morton3([q(c.x), q(c.y), q(c.z)])
        })
        .collect();
    let mut at = vec![0u32; cells + 1];
    for &c in &code {
        at[c as usize + 1] += 1;
    }
    for c in 0..cells {
        at[c + 1] += at[c];
    }
    let mut order = vec![0u32; n];
    for (i, &c) in code.iter().enumerate() {
        order[at[c as usize] as usize] = i as u32;
        at[c as usize] += 1;
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every point once, and a run of the order stays in a small region however the input
    /// is ordered (here: shuffled).
    #[test]
    fn spatial_order_is_a_permutation_in_compact_runs() {
        let mut r = crate::rng::Rng::new(4);
        let pts: Vec<Vec3> = (0..40_000)
            .map(|_| Vec3::new(r.f32() * 100.0, r.f32() * 100.0, r.f32()))
            .collect();
        let order = spatial_order(&pts);
        let mut seen = vec![false; pts.len()];
        for &i in &order {
            assert!(!seen[i as usize], "{i} twice");
            seen[i as usize] = true;
        }
        assert!(seen.iter().all(|&s| s));
        // A run of 1/16 of the points covers a small part of the square (its diagonal: 141;
        // a square of 1/16 of it: 35); runs across a jump of the Morton curve span more.
        let mut spans: Vec<f32> = order
            .chunks(2500)
            .map(|run| {
                let p: Vec<Vec3> = run.iter().map(|&i| pts[i as usize]).collect();
                Bounds::from_points(&p).diagonal()
            })
            .collect();
        spans.sort_by(f32::total_cmp);
        assert!(spans[spans.len() / 2] < 45.0, "runs span {spans:?}");
    }

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
