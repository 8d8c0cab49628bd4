//! Inner-node filtering (Pintus §7): a parent's samples are its children's samples merged on a
//! grid, one sample per occupied cell, with the cell's average position and colour.
//!
//! Deviation: the paper divides the node into a fixed grid of M cells. A scanned surface
//! crosses only a 2-D slice of a 3-D grid, so M cubic cells leave a surface node with about
//! M^(2/3) samples (≈ 1 000 for M = 32 K), and coarse levels look far sparser than their
//! budget allows. Here the cells are cubes whose size is chosen (a few counting rounds, each a
//! hash of the cell keys) so that as many cells as possible, but at most M, are occupied. The
//! cell size is stored as the node's spacing and drives the screen-space error of the
//! selection.

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

/// Merges `points` (all inside `bounds`) into at most `m` samples; returns them and the cell
/// size. `guess` is a cell size to try first (see [`first_guess`]). Deterministic: samples
/// come out in the order their cells were first met.
pub fn filter(
    points: &[Record],
    bounds: &Bounds,
    m: usize,
    guess: Option<f32>,
) -> (Vec<Record>, f32) {
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
    let mut best: Option<(Vec<Record>, f32)> = None;
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

fn key(p: [f32; 3], min: glam::Vec3, inv: f32) -> u64 {
    let c = |v: f32, lo: f32| (((v - lo) * inv) as u64).min((1 << 21) - 1);
    c(p[0], min.x) | c(p[1], min.y) << 21 | c(p[2], min.z) << 42
}

/// Open-addressing table of cell keys, reused across counting rounds.
struct CellTable {
    keys: Vec<u64>,
    slot: Vec<u32>,
    mask: usize,
    /// Multiplicative hashing keeps the product's top bits: 64 − log2(capacity).
    shift: u32,
}

const EMPTY: u64 = u64::MAX;

impl CellTable {
    fn with_capacity(n: usize) -> CellTable {
        let cap = (n.max(8) * 2).next_power_of_two();
        CellTable {
            keys: vec![EMPTY; cap],
            slot: vec![0; cap],
            mask: cap - 1,
            shift: 64 - cap.trailing_zeros(),
        }
    }

    fn find(&mut self, k: u64) -> (usize, bool) {
        let mut h = (k.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> self.shift) as usize;
        loop {
            if self.keys[h] == k {
                return (h, false);
            }
            if self.keys[h] == EMPTY {
                self.keys[h] = k;
                return (h, true);
            }
            h = (h + 1) & self.mask;
        }
    }

    /// One sample per occupied cell of size `s`, or, when more than `limit` cells are
    /// occupied, an estimate of how many would be (extrapolated from where it stopped).
    fn merge(
        &mut self,
        points: &[Record],
        min: glam::Vec3,
        s: f32,
        limit: usize,
    ) -> Result<Vec<Record>, usize> {
        self.keys.fill(EMPTY);
        let inv = 1.0 / s;
        // Sums per occupied cell: position (f64), colour, count.
        let mut acc: Vec<([f64; 3], [u32; 3], u32)> = Vec::with_capacity(limit.min(points.len()));
        for (i, r) in points.iter().enumerate() {
            let (h, new) = self.find(key(r.pos, min, inv));
            if new {
                if acc.len() == limit {
                    return Err((limit as f64 * points.len() as f64 / (i + 1) as f64) as usize + 1);
                }
                self.slot[h] = acc.len() as u32;
                acc.push(([0.0; 3], [0; 3], 0));
            }
            let a = &mut acc[self.slot[h] as usize];
            for i in 0..3 {
                a.0[i] += r.pos[i] as f64;
                a.1[i] += r.rgb[i] as u32;
            }
            a.2 += 1;
        }
        Ok(acc
            .iter()
            .map(|(p, c, n)| {
                let k = *n as f64;
                Record {
                    pos: [(p[0] / k) as f32, (p[1] / k) as f32, (p[2] / k) as f32],
                    rgb: c.map(|v| ((v + n / 2) / n) as u8),
                    reserved: 0,
                }
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

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
    fn a_plane_keeps_close_to_m_samples_inside_the_box() {
        let pts = grid_plane(300); // 90 000 points
        let b = Bounds {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        let (s, cell) = filter(&pts, &b, 4096, None);
        assert!(s.len() <= 4096, "{} samples", s.len());
        // A literal 4096-cell cube grid would give 16² = 256 samples on this plane.
        assert!(s.len() >= 2000, "only {} samples", s.len());
        assert!(cell > 0.0 && cell < 0.05, "cell {cell}");
        for r in &s {
            let p = r.p();
            assert!(p.cmpge(b.min).all() && p.cmple(b.max).all(), "{p}");
            assert_eq!(p.z, 0.5);
            assert_eq!(r.rgb[1], 100);
        }
    }

    #[test]
    fn merging_averages_position_and_colour() {
        let pts = vec![
            Record::new(Vec3::new(0.1, 0.1, 0.1), [0, 0, 0]),
            Record::new(Vec3::new(0.2, 0.1, 0.1), [100, 200, 50]),
            Record::new(Vec3::new(0.9, 0.9, 0.9), [10, 10, 10]),
        ];
        let b = Bounds {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        let (s, _) = filter(&pts, &b, 2, None);
        assert_eq!(s.len(), 2);
        let a = s.iter().find(|r| r.pos[0] < 0.5).unwrap();
        assert!((a.pos[0] - 0.15).abs() < 1e-6);
        assert_eq!(a.rgb, [50, 100, 25]);
        // Few points: every point keeps its own cell.
        let (s, _) = filter(&pts, &b, 10, None);
        assert_eq!(s.len(), 3);
    }
}
