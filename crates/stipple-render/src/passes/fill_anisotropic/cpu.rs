//! # Anisotropic filling (Pintus §5)
//!
//! How it works: only pixels the visibility pass emptied ([`HOLE`]) change; points and the
//! background it kept are fixed. A pixel is valid when it has a finite depth. Each iteration
//! reads the previous one (Jacobi, ping-pong) over the 3×3 neighbourhood:
//! - an empty pixel with valid neighbours takes the median of their depths (the lower median
//!   for an even count; ties in reading order) and that neighbour's colour: the median, not
//!   the mean, so a hole on an edge takes one side's value instead of a blend of both;
//! - a filled pixel is re-estimated as the weighted mean of itself (weight 1) and its valid
//!   neighbours with Eq. 1, w = (1 − r/2)·[1 − min(1, |z − z₀|/δ)], r = 1 or √2 pixels.
//!
//! δ is given in pixel footprints at the pixel's depth (the world size of a pixel there), so
//! one value suits near and far surfaces alike. Pixels still empty at the end stay
//! background. With `all_empty` (no visibility pass ran) every empty pixel is mutable.

use crate::gbuffer::{is_point, HOLE};
use crate::params::ViewParams;
use rayon::prelude::*;

/// 1 − r/2 for an edge neighbour (r = 1) and a corner neighbour (r = √2).
pub const EDGE_WEIGHT: f32 = 0.5;
pub const CORNER_WEIGHT: f32 = 1.0 - std::f32::consts::SQRT_2 / 2.0;

/// One iteration; returns the number of pixels that went from empty to filled.
#[allow(clippy::too_many_arguments)]
pub fn fill_anisotropic(
    v: &ViewParams,
    id: &[u32],
    delta: f32,
    all_empty: bool,
    src_depth: &[f32],
    src_colour: &[[f32; 3]],
    dst_depth: &mut [f32],
    dst_colour: &mut [[f32; 3]],
) -> u64 {
    let (w, h) = (v.width as usize, v.height as usize);
    dst_depth
        .par_chunks_mut(w)
        .zip(dst_colour.par_chunks_mut(w))
        .enumerate()
        .map(|(y, (drow, crow))| {
            let mut filled = 0;
            for x in 0..w {
                let k = y * w + x;
                let (z0, c0) = (src_depth[k], src_colour[k]);
                (drow[x], crow[x]) = (z0, c0);
                if !(id[k] == HOLE || all_empty && !is_point(id[k])) {
                    continue;
                }
                // Valid neighbours in reading order: (depth, index, corner?).
                let mut nb = [(0.0f32, 0usize, false); 8];
                let mut count = 0;
                for dy in -1i32..=1 {
                    let ny = y as i32 + dy;
                    if ny < 0 || ny >= h as i32 {
                        continue;
                    }
                    for dx in -1i32..=1 {
                        let nx = x as i32 + dx;
                        if (dx, dy) == (0, 0) || nx < 0 || nx >= w as i32 {
                            continue;
                        }
                        let n = ny as usize * w + nx as usize;
                        if src_depth[n].is_finite() {
                            nb[count] = (src_depth[n], n, dx != 0 && dy != 0);
                            count += 1;
                        }
                    }
                }
                if count == 0 {
                    continue;
                }
                if !z0.is_finite() {
                    // Insertion sort by depth (stable: ties keep reading order).
                    let s = &mut nb[..count];
                    for i in 1..count {
                        let mut j = i;
                        while j > 0 && s[j].0 < s[j - 1].0 {
                            s.swap(j, j - 1);
                            j -= 1;
                        }
                    }
                    let (z, n, _) = s[(count - 1) / 2];
                    (drow[x], crow[x]) = (z, src_colour[n]);
                    filled += 1;
                    continue;
                }
                let inv_delta = 1.0 / (delta * v.footprint(z0));
                let (mut sz, mut sc, mut sw) = (z0, c0, 1.0f32);
                for &(z, n, corner) in &nb[..count] {
                    let radial = if corner { CORNER_WEIGHT } else { EDGE_WEIGHT };
                    let wt = radial * (1.0 - ((z - z0).abs() * inv_delta).min(1.0));
                    if wt > 0.0 {
                        let c = src_colour[n];
                        sz += wt * z;
                        sc = [sc[0] + wt * c[0], sc[1] + wt * c[1], sc[2] + wt * c[2]];
                        sw += wt;
                    }
                }
                drow[x] = sz / sw;
                crow[x] = sc.map(|c| c / sw);
            }
            filled
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gbuffer::BACKGROUND;

    /// A narrow field of view: one pixel is 1/100 of the depth.
    fn view(w: u32, h: u32) -> ViewParams {
        ViewParams::axis_aligned(w, h, true, 200.0)
    }

    /// Runs `its` iterations.
    fn run(
        v: &ViewParams,
        id: &[u32],
        depth: &[f32],
        colour: &[[f32; 3]],
        its: u32,
    ) -> (Vec<f32>, Vec<[f32; 3]>, u64) {
        let (mut d, mut c) = (depth.to_vec(), colour.to_vec());
        let (mut d2, mut c2) = (d.clone(), c.clone());
        let mut filled = 0;
        for _ in 0..its {
            filled += fill_anisotropic(v, id, 8.0, false, &d, &c, &mut d2, &mut c2);
            std::mem::swap(&mut d, &mut d2);
            std::mem::swap(&mut c, &mut c2);
        }
        (d, c, filled)
    }

    #[test]
    fn a_hole_on_an_edge_takes_one_side_not_a_blend() {
        // 1 row: near (depth 1, red) | hole | far (depth 9, blue) ×2 — median picks a side.
        let v = view(5, 1);
        let id = [0, 1, HOLE, 3, 4];
        let depth = [1.0, 1.0, f32::INFINITY, 9.0, 9.0];
        let red = [1.0, 0.0, 0.0];
        let blue = [0.0, 0.0, 1.0];
        let colour = [red, red, [0.0; 3], blue, blue];
        let (d, c, filled) = run(&v, &id, &depth, &colour, 1);
        assert_eq!(filled, 1);
        // Lower median of {1, 9} is 1, with the red neighbour's colour.
        assert_eq!((d[2], c[2]), (1.0, red));
        // Later iterations leave it: the far side differs by far more than δ.
        let (d, c, _) = run(&v, &id, &depth, &colour, 4);
        assert_eq!((d[2], c[2]), (1.0, red));
    }

    #[test]
    fn a_gap_in_a_ramp_is_interpolated_and_background_is_kept() {
        // Depth ramps 10, 10.01, ..; pixels 3..6 are holes; pixel 9 is kept background.
        let v = view(10, 1);
        let mut id: Vec<u32> = (0..10).collect();
        let mut depth: Vec<f32> = (0..10).map(|i| 10.0 + 0.01 * i as f32).collect();
        for k in 3..6 {
            id[k] = HOLE;
            depth[k] = f32::INFINITY;
        }
        id[9] = BACKGROUND;
        depth[9] = f32::INFINITY;
        let colour = vec![[0.5; 3]; 10];
        let (d, _, filled) = run(&v, &id, &depth, &colour, 6);
        assert_eq!(filled, 3);
        for k in 3..6 {
            let truth = 10.0 + 0.01 * k as f32;
            assert!((d[k] - truth).abs() < 0.012, "{k}: {} vs {truth}", d[k]);
        }
        assert!(d[9].is_infinite());
        // Immutable pixels never change.
        for k in [0, 1, 2, 6, 7, 8] {
            assert_eq!(d[k], depth[k]);
        }
    }
}
