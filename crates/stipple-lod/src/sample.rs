//! Inner-node sampling (Pintus §7, stored once as Potree does): a parent takes its samples
//! out of its children's payloads, one point per occupied cell of a grid, the point nearest
//! the cell's centre. The points it takes leave the children, so every input point is stored
//! exactly once in the tree, and a node drawn with its ancestors has the density of its cell
//! size.
//!
//! Deviation: the paper divides the node into a fixed grid of M cells. A scanned surface
//! crosses only a 2-D slice of a 3-D grid, so M cubic cells leave a surface node with about
//! M^(2/3) samples (≈ 1 000 for M = 32 K), and coarse levels look far sparser than their
//! budget allows. Here the cells are cubes whose size is chosen (a few counting rounds, each a
//! hash of the cell keys) so that as many cells as possible, but at most M, are occupied. The
//! cell size is stored as the node's spacing and drives the screen-space error of the
//! selection. The paper's samples average their cell; ours are input points, so nothing is
//! stored twice and a sample never floats between two surfaces.

use crate::record::Record;
use stipple_core::Bounds;

/// Counting rounds before settling for the best valid cell size.
const ROUNDS: usize = 4;
/// Target occupancy as a share of M: a little below, so one round usually suffices.
const TARGET: f64 = 0.85;
/// Occupancy accepted without another round.
const ACCEPT: f64 = 0.6;

/// The cell size to try first for `n` samples that are `child_spacing` apart on a surface:
/// the size at which they would fill `TARGET` × m cells.
pub fn first_guess(child_spacing: f32, n: usize, m: usize) -> Option<f32> {
    let s = child_spacing * ((n as f64 / (TARGET * m as f64)).max(1.0).sqrt() as f32);
    (s.is_finite() && s > 0.0).then_some(s)
}

/// Picks at most `m` of `points` (all inside `bounds`), one per occupied cell; returns their
/// indices and the cell size. `guess` is a cell size to try first (see [`first_guess`]).
/// Deterministic: indices come out in the order their cells were first met; within a cell
/// the point nearest its centre wins, the first one on a tie.
pub fn pick(points: &[Record], bounds: &Bounds, m: usize, guess: Option<f32>) -> (Vec<u32>, f32) {
    let m = m.max(1);
    let e = bounds.extent();
    let emax = e.max_element().max(f32::MIN_POSITIVE);
    // Cell keys hold 21 bits per axis.
    let min_cell = emax / (1 << 20) as f32;
    // A merge stops at m + 1 cells, so the table never holds more keys.
    let mut table = CellTable::with_capacity(points.len().min(m + 1));
    // First guess: the samples cover a surface spanning the two largest extents.
    let mut ext = e.to_array();
    ext.sort_by(f32::total_cmp);
    let area = (ext[2] * ext[1]).max(ext[2] * ext[2] * 1e-6);
    let mut s = guess
        .unwrap_or_else(|| (area / (TARGET * m as f64) as f32).sqrt())
        .max(min_cell);
    // Each round merges at a cell size; a round that overflows M stops early and estimates
    // the occupancy it would have reached.
    let mut best: Option<(Vec<u32>, f32)> = None;
    for _ in 0..ROUNDS {
        let occ = match table.merge(points, bounds.min, s, m) {
            Ok(v) => {
                let occ = v.len();
                if best.as_ref().is_none_or(|b| s < b.1) {
                    best = Some((v, s));
                }
                if occ as f64 >= ACCEPT * m as f64 || occ == points.len() || s <= min_cell {
                    break;
                }
                occ
            }
            Err(estimate) => estimate,
        };
        // Occupancy of a surface scales with 1/s².
        let next = s * ((occ.max(1) as f64 / (TARGET * m as f64)).sqrt() as f32);
        s = next.clamp(min_cell, emax * 2.0);
        if best.as_ref().is_some_and(|b| s >= b.1) {
            break;
        }
    }
    if let Some(b) = best {
        return b;
    }
    loop {
        s *= 1.25;
        if let Ok(v) = table.merge(points, bounds.min, s, m) {
            return (v, s);
        }
    }
}

/// A point's cell key (21 bits an axis) and its squared distance from the cell's centre, in
/// cells. Coordinates are never negative inside the box, so truncation is the floor.
#[inline]
fn key_and_distance2(p: [f32; 3], min: glam::Vec3, inv: f32) -> (u64, f32) {
    let mut key = 0;
    let mut d2 = 0.0;
    for (a, lo) in [min.x, min.y, min.z].into_iter().enumerate() {
        let x = ((p[a] - lo) * inv).max(0.0);
        let c = (x as u64).min((1 << 21) - 1);
        let f = x - c as f32 - 0.5;
        key |= c << (21 * a);
        d2 += f * f;
    }
    (key, d2)
}

/// Open-addressing table of cells, reused across counting rounds. Each entry holds its
/// cell's key and best point, so a point costs one probe of one cache line.
struct CellTable {
    cells: Vec<Cell>,
    /// Table positions in the order their cells were first met (the output order, and what
    /// the next round clears).
    order: Vec<u32>,
    mask: usize,
    /// Multiplicative hashing keeps the product's top bits: 64 − log2(capacity).
    shift: u32,
}

#[derive(Clone, Copy)]
struct Cell {
    key: u64,
    /// The point nearest the centre so far, and its squared distance (in cells).
    best: u32,
    d2: f32,
}

const EMPTY: u64 = u64::MAX;

impl CellTable {
    /// A table for up to `n` cells, at most half full.
    fn with_capacity(n: usize) -> CellTable {
        let cap = (n.max(8) * 2).next_power_of_two();
        CellTable {
            cells: vec![
                Cell {
                    key: EMPTY,
                    best: 0,
                    d2: 0.0,
                };
                cap
            ],
            order: Vec::with_capacity(n),
            mask: cap - 1,
            shift: 64 - cap.trailing_zeros(),
        }
    }

    /// One sample per occupied cell of size `s` (the index of the point nearest the cell's
    /// centre), or, when more than `limit` cells are occupied, an estimate of how many would
    /// be (extrapolated from where it stopped).
    fn merge(
        &mut self,
        points: &[Record],
        min: glam::Vec3,
        s: f32,
        limit: usize,
    ) -> Result<Vec<u32>, usize> {
        for &h in &self.order {
            self.cells[h as usize].key = EMPTY;
        }
        self.order.clear();
        let inv = 1.0 / s;
        // Blocks of points: keys and slots first, with the slots' cache lines fetched ahead
        // (a table of M cells outgrows the L2 cache, and a point costs one miss otherwise),
        // then the probes.
        const BLOCK: usize = 32;
        let mut keys = [(0u64, 0f32, 0usize); BLOCK];
        for (b, block) in points.chunks(BLOCK).enumerate() {
            for (slot, r) in keys.iter_mut().zip(block) {
                let (k, d2) = key_and_distance2(r.pos, min, inv);
                let h = (k.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> self.shift) as usize;
                prefetch(&self.cells[h]);
                *slot = (k, d2, h);
            }
            for (j, &(k, d2, mut h)) in keys[..block.len()].iter().enumerate() {
                let i = b * BLOCK + j;
                loop {
                    let c = &mut self.cells[h];
                    if c.key == k {
                        if d2 < c.d2 {
                            c.best = i as u32;
                            c.d2 = d2;
                        }
                        break;
                    }
                    if c.key == EMPTY {
                        if self.order.len() == limit {
                            return Err((limit as f64 * points.len() as f64 / (i + 1) as f64)
                                as usize
                                + 1);
                        }
                        *c = Cell {
                            key: k,
                            best: i as u32,
                            d2,
                        };
                        self.order.push(h as u32);
                        break;
                    }
                    h = (h + 1) & self.mask;
                }
            }
        }
        Ok(self
            .order
            .iter()
            .map(|&h| self.cells[h as usize].best)
            .collect())
    }
}

/// Asks for the cache line of `c` ahead of its use (a hint; nothing on other targets).
#[inline(always)]
fn prefetch<T>(c: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: prefetching is a hint that never faults, and `c` is a valid reference.
    unsafe {
        std::arch::x86_64::_mm_prefetch(c as *const T as *const i8, std::arch::x86_64::_MM_HINT_T0);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = c;
}

/// What a parent takes out of its two children's payloads.
pub struct Taken {
    /// The parent's samples, in the order [`pick`] gives them.
    pub samples: Vec<Record>,
    /// Their cell size: the parent's spacing.
    pub spacing: f32,
    /// Which records of the left and of the right child were taken.
    pub left: Vec<bool>,
    pub right: Vec<bool>,
}

/// Takes at most `m` samples out of two children's payloads (`left`, `right`; all inside
/// `bounds`), whose spacings are at most `child_spacing` (the first guess of the cell size).
pub fn take(
    left: &[Record],
    right: &[Record],
    bounds: &Bounds,
    m: usize,
    child_spacing: f32,
) -> Taken {
    let mut merged = Vec::with_capacity(left.len() + right.len());
    merged.extend_from_slice(left);
    merged.extend_from_slice(right);
    let guess = first_guess(child_spacing, merged.len(), m);
    let (chosen, spacing) = pick(&merged, bounds, m, guess);
    let (l, r) = taken_masks(&chosen, left.len(), merged.len());
    Taken {
        samples: chosen.iter().map(|&i| merged[i as usize]).collect(),
        spacing,
        left: l,
        right: r,
    }
}

/// Which of the two children's records `chosen` (indices into their concatenation, `left`
/// records first) names.
fn taken_masks(chosen: &[u32], left: usize, total: usize) -> (Vec<bool>, Vec<bool>) {
    let mut l = vec![false; left];
    let mut r = vec![false; total - left];
    for &i in chosen {
        let i = i as usize;
        if i < left {
            l[i] = true;
        } else {
            r[i - left] = true;
        }
    }
    (l, r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use std::collections::HashSet;

    fn grid_plane(n: usize) -> Vec<Record> {
        let mut v = Vec::new();
        for i in 0..n {
            for j in 0..n {
                v.push(Record::new(
                    Vec3::new(i as f32 / n as f32, j as f32 / n as f32, 0.5),
                    [(i % 256) as u8, 100, 7],
                ));
            }
        }
        v
    }

    #[test]
    fn a_plane_keeps_close_to_m_samples_one_per_cell() {
        let pts = grid_plane(300); // 90 000 points
        let b = Bounds {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        let (idx, cell) = pick(&pts, &b, 4096, None);
        assert!(idx.len() <= 4096, "{} samples", idx.len());
        // A literal 4096-cell cube grid would give 16² = 256 samples on this plane.
        assert!(idx.len() >= 2000, "only {} samples", idx.len());
        assert!(cell > 0.0 && cell < 0.05, "cell {cell}");
        let (mut seen, mut cells) = (HashSet::new(), HashSet::new());
        for &i in &idx {
            assert!(seen.insert(i), "index {i} picked twice");
            let c = ((pts[i as usize].p() - b.min) / cell).floor().as_ivec3();
            assert!(cells.insert(c.to_array()), "two samples in cell {c}");
        }
    }

    #[test]
    fn each_cell_keeps_the_point_nearest_its_centre() {
        let pts = vec![
            Record::new(Vec3::new(0.05, 0.1, 0.1), [0, 0, 0]),
            Record::new(Vec3::new(0.2, 0.2, 0.2), [100, 200, 50]),
            Record::new(Vec3::new(0.9, 0.9, 0.9), [10, 10, 10]),
        ];
        let b = Bounds {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        let (idx, s) = pick(&pts, &b, 2, None);
        assert!(s >= 0.45, "cell {s}");
        assert_eq!(idx.len(), 2);
        // The first and second points share a cell; the second is nearer its centre.
        assert!(idx.contains(&1) && idx.contains(&2), "{idx:?}");
        // Few points: every point keeps its own cell.
        let (idx, _) = pick(&pts, &b, 10, None);
        assert_eq!(idx, vec![0, 1, 2]);
        let (l, r) = taken_masks(&[0, 2], 2, 3);
        assert_eq!((l, r), (vec![true, false], vec![true]));
    }
}
