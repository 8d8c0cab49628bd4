//! # Smoothing (Dobrev §3.4)
//!
//! How it works: a 3×3 low-pass filter (box, Gaussian, or the paper's alleviated Gaussian with
//! the centre weighted 16/28) over the colour of covered pixels only: a covered pixel becomes
//! the weighted mean of its covered neighbours (weights renormalised over those present), so
//! background never bleeds into the surface; background pixels are untouched.

use crate::gbuffer::is_point;
use crate::pipeline::Kernel;
use rayon::prelude::*;

/// One iteration from `src` into `dst`.
pub fn smooth(
    w: usize,
    h: usize,
    id: &[u32],
    kernel: Kernel,
    src: &[[f32; 3]],
    dst: &mut [[f32; 3]],
) {
    let wt = kernel.weights();
    dst.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            let k = y * w + x;
            if !is_point(id[k]) {
                row[x] = src[k];
                continue;
            }
            row[x] = weighted_3x3(w, h, x, y, &wt, src, |n| is_point(id[n]));
        }
    });
}

/// The `weights`-weighted mean (row order, 9 values) of the colours around (x, y) over the
/// in-image pixels `n` for which `include(n)` holds, renormalised over those present.
#[inline]
pub(crate) fn weighted_3x3(
    w: usize,
    h: usize,
    x: usize,
    y: usize,
    weights: &[f32; 9],
    src: &[[f32; 3]],
    include: impl Fn(usize) -> bool,
) -> [f32; 3] {
    let mut acc = [0.0f32; 3];
    let mut sum = 0.0f32;
    for dy in -1i32..=1 {
        let ny = y as i32 + dy;
        if ny < 0 || ny >= h as i32 {
            continue;
        }
        for dx in -1i32..=1 {
            let nx = x as i32 + dx;
            if nx < 0 || nx >= w as i32 {
                continue;
            }
            let n = ny as usize * w + nx as usize;
            if !include(n) {
                continue;
            }
            let f = weights[((dy + 1) * 3 + dx + 1) as usize];
            let c = src[n];
            acc[0] += f * c[0];
            acc[1] += f * c[1];
            acc[2] += f * c[2];
            sum += f;
        }
    }
    acc.map(|a| a / sum)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_match_table_1() {
        let s = |k: Kernel| k.weights().iter().sum::<f32>();
        assert_eq!(s(Kernel::Box), 9.0);
        assert_eq!(s(Kernel::Gauss), 16.0);
        assert_eq!(s(Kernel::Alleviated), 28.0);
        assert_eq!(Kernel::Alleviated.weights()[4] / 28.0, 16.0 / 28.0);
    }

    #[test]
    fn smoothing_ignores_background_and_averages_the_rest() {
        // 3×3, centre bright, others dark; top-left background (colour 100 must not leak).
        let mut id = vec![1u32; 9];
        id[0] = crate::gbuffer::BACKGROUND;
        let mut src = vec![[0.0f32; 3]; 9];
        src[0] = [100.0; 3];
        src[4] = [1.0; 3];
        let mut dst = vec![[0.0f32; 3]; 9];
        smooth(3, 3, &id, Kernel::Gauss, &src, &mut dst);
        assert_eq!(dst[0], [100.0; 3], "background untouched");
        // Centre: weight 4 of the 15 present (16 − 1 for the background corner).
        assert!((dst[4][0] - 4.0 / 15.0).abs() < 1e-6);
        // Right-middle neighbour: sees the centre with weight 2 of 2+4+1+2+1... = 12 present.
        assert!((dst[5][0] - 2.0 / 12.0).abs() < 1e-6);
        smooth(3, 3, &id, Kernel::Alleviated, &src, &mut dst);
        assert!((dst[4][0] - 16.0 / 27.0).abs() < 1e-6);
    }
}
