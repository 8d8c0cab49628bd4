//! # Eye-dome lighting (comparison shading for raw clouds)
//!
//! How it works (the method Potree and CloudCompare ship): for a covered pixel at depth d₀,
//! eight neighbours at `radius` pixels (rounded to whole pixels) contribute
//! max(0, log₂ d₀ − log₂ dᵢ), i.e. how much nearer they are; a background neighbour
//! contributes [`BACKGROUND_RESPONSE`], which outlines silhouettes. The colour is scaled by
//! exp(−300 · strength · mean response). It needs no normals and no filling, only depth.

use crate::params::ViewParams;
use rayon::prelude::*;

/// Response of a background neighbour.
pub const BACKGROUND_RESPONSE: f32 = 100.0;
/// Scale of the mean response in the exponent (Potree's constant).
pub const SCALE: f32 = 300.0;

/// The eight neighbour offsets at `radius` pixels (at least one pixel away), as both
/// backends use them.
pub fn offsets(radius: f32) -> [[i32; 2]; 8] {
    let mut o = [[0; 2]; 8];
    for (k, v) in o.iter_mut().enumerate() {
        let a = k as f64 * std::f64::consts::FRAC_PI_4;
        let r = radius.max(1.0) as f64;
        *v = [(r * a.cos()).round() as i32, (r * a.sin()).round() as i32];
    }
    o
}

pub fn edl(
    v: &ViewParams,
    depth: &[f32],
    strength: f32,
    radius: f32,
    src: &[[f32; 3]],
    dst: &mut [[f32; 3]],
) {
    let (w, h) = (v.width as i32, v.height as i32);
    let off = offsets(radius);
    dst.par_chunks_mut(w as usize)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..w {
                let k = y * w as usize + x as usize;
                let d = depth[k];
                if !d.is_finite() {
                    row[x as usize] = src[k];
                    continue;
                }
                let l0 = d.log2();
                let mut sum = 0.0;
                for [dx, dy] in off {
                    let (nx, ny) = (x + dx, y as i32 + dy);
                    if nx < 0 || ny < 0 || nx >= w || ny >= h {
                        continue;
                    }
                    let z = depth[(ny * w + nx) as usize];
                    sum += if z.is_finite() {
                        (l0 - z.log2()).max(0.0)
                    } else {
                        BACKGROUND_RESPONSE
                    };
                }
                let s = (-SCALE * strength * (sum / 8.0)).exp();
                row[x as usize] = src[k].map(|c| c * s);
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_are_a_ring() {
        assert_eq!(offsets(1.4)[0], [1, 0]);
        assert_eq!(offsets(1.4)[1], [1, 1]);
        assert_eq!(offsets(2.0)[2], [0, 2]);
        assert_eq!(offsets(0.2)[4], [-1, 0]);
    }
}
