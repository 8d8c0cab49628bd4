//! # Shape depiction (Pintus §6)
//!
//! How it works: a screen-space shading term from the filled depth alone, no normals. At level
//! k each pixel's 3×3 neighbourhood (covered pixels only) gives the mean μ and deviation σ of
//! the depth; the interval [μ − σ, μ + σ] is robust to outliers. Eq. 2:
//! ω = clamp(1 − |d − (μ − σ)| / (2σ + ε)) is 1 on a surface facing the viewer and falls
//! towards ½ as it tilts (directional light); at depth steps it saturates into dark or bright
//! lines (line drawing). The next level's depth is (μ + μ − σ)/2, a smoothing that also lowers
//! the depth towards the near side, so coarser levels add an ambient-occlusion-like term.
//! Eq. 3 merges the levels with weights 1/(k + 1)^ξ.
//!
//! Deviations from the paper, and why:
//! - the merged term is divided by the sum of the weights, so a flat facing surface shades to
//!   exactly 1 (its colour unchanged) whatever the number of levels;
//! - depth is the linear view depth, and ε is given in pixel footprints at the pixel's depth:
//!   the paper's "very small" ε lives in a non-linear [0, 1] depth buffer where it is in
//!   effect comparable to a pixel's depth step; made explicit, the directional-light falloff
//!   is the same at every distance;
//! - background neighbours are left out of μ and σ (the paper's background depth of 1 would
//!   pull the smoothed levels of every silhouette towards the far plane).

use crate::params::ViewParams;
use rayon::prelude::*;

/// The normalised level weights of Eq. 3: 1/(k + 1)^ξ over their sum.
pub fn level_weights(levels: u32, xi: f32) -> Vec<f32> {
    let w: Vec<f64> = (0..levels)
        .map(|k| 1.0 / ((k + 1) as f64).powf(xi as f64))
        .collect();
    let s: f64 = w.iter().sum();
    w.iter().map(|x| (x / s) as f32).collect()
}

/// ω of Eq. 2 and the next level's depth for a pixel of depth `d` with 3×3 mean `mu` and
/// deviation `sigma`, `eps` = ε in world units.
#[inline]
pub fn omega(d: f32, mu: f32, sigma: f32, eps: f32) -> (f32, f32) {
    let lo = mu - sigma;
    let hi = mu + sigma;
    let om = (1.0 - (d - lo).abs() / (hi - lo + eps)).clamp(0.0, 1.0);
    (om, 0.5 * (mu + lo))
}

/// One level: reads `src` depth, writes the next level's depth to `dst` and adds
/// `weight` · ω to `acc` (or sets it, at the first level).
pub fn level(
    v: &ViewParams,
    src: &[f32],
    dst: &mut [f32],
    acc: &mut [f32],
    weight: f32,
    epsilon: f32,
    first: bool,
) {
    let (w, h) = (v.width as usize, v.height as usize);
    dst.par_chunks_mut(w)
        .zip(acc.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (drow, arow))| {
            for x in 0..w {
                let d = src[y * w + x];
                if !d.is_finite() {
                    drow[x] = d;
                    if first {
                        arow[x] = 0.0;
                    }
                    continue;
                }
                let mut vals = [0.0f32; 9];
                let mut n = 0;
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
                        let z = src[ny as usize * w + nx as usize];
                        if z.is_finite() {
                            vals[n] = z;
                            n += 1;
                        }
                    }
                }
                let mut sum = 0.0;
                for &z in &vals[..n] {
                    sum += z;
                }
                let mu = sum / n as f32;
                let mut var = 0.0;
                for &z in &vals[..n] {
                    var += (z - mu) * (z - mu);
                }
                let sigma = (var / n as f32).sqrt();
                let (om, next) = omega(d, mu, sigma, epsilon * v.footprint(d));
                drow[x] = next;
                arow[x] = if first {
                    weight * om
                } else {
                    arow[x] + weight * om
                };
            }
        });
}

/// Multiplies the colour of covered pixels by the shading term.
pub fn apply(depth: &[f32], shading: &[f32], src: &[[f32; 3]], dst: &mut [[f32; 3]]) {
    dst.par_iter_mut().enumerate().for_each(|(k, c)| {
        let s = if depth[k].is_finite() {
            shading[k]
        } else {
            1.0
        };
        *c = src[k].map(|x| x * s);
    });
}

/// The whole operator: `scratch` holds two depth images.
#[allow(clippy::too_many_arguments)]
pub fn depiction(
    v: &ViewParams,
    depth: &[f32],
    levels: u32,
    xi: f32,
    epsilon: f32,
    scratch: &mut (Vec<f32>, Vec<f32>),
    shading: &mut Vec<f32>,
    src: &[[f32; 3]],
    dst: &mut [[f32; 3]],
) {
    let n = depth.len();
    shading.resize(n, 0.0);
    scratch.0.clear();
    scratch.0.extend_from_slice(depth);
    scratch.1.resize(n, 0.0);
    for (k, wt) in level_weights(levels, xi).into_iter().enumerate() {
        level(v, &scratch.0, &mut scratch.1, shading, wt, epsilon, k == 0);
        std::mem::swap(&mut scratch.0, &mut scratch.1);
    }
    apply(depth, shading, src, dst);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_follow_eq3_and_sum_to_one() {
        let w = level_weights(4, 1.5);
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert!((w[0] / w[1] - 2f32.powf(1.5)).abs() < 1e-4);
        assert_eq!(level_weights(3, 0.0), vec![1.0 / 3.0; 3]);
    }

    #[test]
    fn eq2_is_one_on_a_flat_neighbourhood_and_half_on_a_steep_one() {
        assert_eq!(omega(5.0, 5.0, 0.0, 0.01).0, 1.0);
        let steep = omega(5.0, 5.0, 100.0, 0.01).0;
        assert!((steep - 0.5).abs() < 1e-3, "{steep}");
    }
}
