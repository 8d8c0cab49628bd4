//! # Anti-aliasing (Dobrev §3.5)
//!
//! How it works: the Laplace filter (0 −1 0 / −1 4 −1 / 0 −1 0) on depth/z_far, with
//! background at 1 and the image edge clamped, marks silhouette pixels (a high threshold keeps
//! only background/foreground edges, a low one also front/back layer edges). Marked pixels,
//! on both sides of the edge, are blended with the Gaussian-weighted mean of their 3×3
//! neighbourhood, background colour included: c ← (1 − s)·c + s·G(c).

use crate::passes::smooth::cpu::weighted_3x3;
use rayon::prelude::*;

/// Normalised depth used by the edge detector.
#[inline]
fn nd(depth: f32, inv_far: f32) -> f32 {
    if depth.is_finite() {
        (depth * inv_far).min(1.0)
    } else {
        1.0
    }
}

/// Edge detection and blending parameters.
#[derive(Clone, Copy, Debug)]
pub struct AaParams {
    /// The far plane: depth is normalised by it.
    pub far: f32,
    /// |Laplace(depth / far)| above this marks an edge.
    pub threshold: f32,
    /// Blend factor s towards the blurred neighbourhood.
    pub strength: f32,
}

/// Returns the number of pixels blended.
pub fn antialias(
    w: usize,
    h: usize,
    depth: &[f32],
    p: AaParams,
    src: &[[f32; 3]],
    dst: &mut [[f32; 3]],
) -> u64 {
    let AaParams {
        far,
        threshold,
        strength,
    } = p;
    let inv_far = 1.0 / far;
    const G: [f32; 9] = [1.0, 2.0, 1.0, 2.0, 4.0, 2.0, 1.0, 2.0, 1.0];
    dst.par_chunks_mut(w)
        .enumerate()
        .map(|(y, row)| {
            let mut blended = 0u64;
            for x in 0..w {
                let k = y * w + x;
                let at = |xx: usize, yy: usize| nd(depth[yy * w + xx], inv_far);
                let c = at(x, y);
                let l = at(x.saturating_sub(1), y);
                let r = at((x + 1).min(w - 1), y);
                let t = at(x, y.saturating_sub(1));
                let b = at(x, (y + 1).min(h - 1));
                let lap = 4.0 * c - l - r - t - b;
                if lap.abs() <= threshold {
                    row[x] = src[k];
                    continue;
                }
                let blur = weighted_3x3(w, h, x, y, &G, src, |_| true);
                let s = src[k];
                row[x] = [0, 1, 2].map(|i| (1.0 - strength) * s[i] + strength * blur[i]);
                blended += 1;
            }
            blended
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_edges_are_blended() {
        // A 6×6 image: a covered 2×2 block at depth 5 (far 10) on background.
        let (w, h) = (6, 6);
        let mut depth = vec![f32::INFINITY; 36];
        let mut src = vec![[1.0f32; 3]; 36];
        for y in 2..4 {
            for x in 2..4 {
                depth[y * w + x] = 5.0;
                src[y * w + x] = [0.0; 3];
            }
        }
        let mut dst = vec![[0.0; 3]; 36];
        let p = |threshold| AaParams {
            far: 10.0,
            threshold,
            strength: 1.0,
        };
        let n = antialias(w, h, &depth, p(0.1), &src, &mut dst);
        assert!(n > 0);
        assert_eq!(dst[0], [1.0; 3], "far from the edge: unchanged");
        assert!(dst[2 * w + 2][0] > 0.0, "object edge pixel lightened");
        assert!(dst[2 * w + 1][0] < 1.0, "background edge pixel darkened");
        // A high threshold leaves the image alone.
        assert_eq!(antialias(w, h, &depth, p(10.0), &src, &mut dst), 0);
        assert_eq!(dst, src);
    }
}
