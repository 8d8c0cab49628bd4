//! # blend_layers: front-to-back compositing of peeled layers (Dobrev §5)
//!
//! How it works: an accumulator holds, per pixel, the colour gathered so far and the
//! transmittance T left for what lies behind (starting at black and T = 1). Each layer, in
//! the order peeling extracts them (nearest first), adds its colour under what is already
//! there: acc += T · α · c and T ← T · (1 − α) ("under" compositing, Porter–Duff). After the
//! last layer, [`compose`] adds the background through what is left: c = acc + T · bg. All
//! in linear RGB.
//!
//! α of a pixel: the opacity of the point it shows (8 bits, [`crate::alpha8`]; 1 for a cloud
//! without opacities); a pixel with a surface but no point of its own (filled by the
//! anisotropic fill) takes the cloud's mean opacity; background is 0.

use crate::gbuffer::is_point;
use rayon::prelude::*;

/// The opacity of pixel `id` with surface depth `depth`.
#[inline]
pub fn pixel_alpha(id: u32, depth: f32, alpha: Option<&[u8]>, hole_alpha: f32) -> f32 {
    if is_point(id) {
        alpha.map_or(1.0, |a| a[id as usize] as f32 / 255.0)
    } else if depth < f32::INFINITY {
        hole_alpha
    } else {
        0.0
    }
}

/// Adds one layer under the accumulator. Returns the pixels it covered (α > 0).
pub fn blend(
    id: &[u32],
    depth: &[f32],
    colour: &[[f32; 3]],
    alpha: Option<&[u8]>,
    hole_alpha: f32,
    acc: &mut [[f32; 4]],
) -> u64 {
    acc.par_iter_mut()
        .enumerate()
        .map(|(k, a)| {
            let al = pixel_alpha(id[k], depth[k], alpha, hole_alpha);
            if al <= 0.0 {
                return 0;
            }
            let t = a[3];
            let w = t * al;
            for i in 0..3 {
                a[i] += w * colour[k][i];
            }
            a[3] = t * (1.0 - al);
            1
        })
        .sum()
}

/// A light view's layer for coloured translucent shadows (see [`crate::translucent`]): the
/// accumulator's colour gathers the optical depth per channel, τ · w_c of the pixel's point
/// (grey weights for a pixel without a point of its own), and T ← T · (1 − α) as [`blend`].
/// Returns the pixels it covered.
pub fn transmit(
    id: &[u32],
    depth: &[f32],
    colours: Option<&[[u8; 3]]>,
    alpha: Option<&[u8]>,
    hole_alpha: f32,
    acc: &mut [[f32; 4]],
) -> u64 {
    use crate::translucent::{optical_depth, weights};
    acc.par_iter_mut()
        .enumerate()
        .map(|(k, a)| {
            let al = pixel_alpha(id[k], depth[k], alpha, hole_alpha);
            if al <= 0.0 {
                return 0;
            }
            let w = match colours {
                Some(c) if is_point(id[k]) => weights(c[id[k] as usize]),
                _ => [1.0; 3],
            };
            let tau = optical_depth(al);
            for i in 0..3 {
                a[i] += tau * w[i];
            }
            a[3] *= 1.0 - al;
            1
        })
        .sum()
}

/// The composite over the (linear) background colour.
pub fn compose(acc: &[[f32; 4]], background: [f32; 3], out: &mut [[f32; 3]]) {
    out.par_iter_mut().zip(acc).for_each(|(o, a)| {
        *o = std::array::from_fn(|i| a[i] + a[3] * background[i]);
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gbuffer::BACKGROUND;

    #[test]
    fn under_compositing_of_three_layers() {
        // One pixel: red α 0.5 over green α 0.25 over blue α 1, on a grey background.
        let mut acc = vec![[0.0, 0.0, 0.0, 1.0]];
        let alpha = [128u8, 64, 255];
        for (k, c) in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
            .into_iter()
            .enumerate()
        {
            blend(&[k as u32], &[1.0], &[c], Some(&alpha), 1.0, &mut acc);
        }
        let mut out = vec![[0.0; 3]];
        compose(&acc, [0.5; 3], &mut out);
        let (a0, a1) = (128.0 / 255.0, 64.0 / 255.0);
        let want = [a0, (1.0 - a0) * a1, (1.0 - a0) * (1.0 - a1)];
        for i in 0..3 {
            assert!((out[0][i] - want[i]).abs() < 1e-6, "{out:?} vs {want:?}");
        }
    }

    #[test]
    fn background_pixels_let_everything_through() {
        let mut acc = vec![[0.0, 0.0, 0.0, 1.0]; 2];
        let n = blend(
            &[BACKGROUND, crate::HOLE],
            &[f32::INFINITY, 2.0],
            &[[1.0; 3], [1.0; 3]],
            None,
            0.25,
            &mut acc,
        );
        assert_eq!(n, 1);
        assert_eq!(acc[0], [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(acc[1], [0.25, 0.25, 0.25, 0.75]);
    }
}
