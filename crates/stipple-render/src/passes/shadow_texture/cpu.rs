//! # shadow_texture: mark the points a light sample reaches (Dobrev §6)
//!
//! How it works: after the cloud has been projected from the light and the light image's
//! holes filled (`fill_background`, `fill_occluded`: the reference depth), every point is
//! projected again; a point is lit by this sample when its light-space depth is at most the
//! reference depth at its pixel plus Δd = d̃' · min(1 / |⟨v, n⟩|, cap) (v: the unit direction
//! from the light to the point, n: its normal; d̃' alone without normals; d̃' is d̃ widened to
//! at least three light pixels, see [`light_gap`]), and then its count
//! for this light goes up by one. With a cube of views, a point is tested only by the face of
//! its dominant direction, so it is counted once. See `shadow.rs` for the whole algorithm.

use crate::params::ViewParams;
use crate::shadow::{dominant_face, ALL_FACES};
use glam::Vec3;
use rayon::prelude::*;

#[derive(Clone, Copy, Debug)]
pub struct MarkParams {
    /// d̃.
    pub gap: f32,
    /// The fills' d̃ on the light image (see [`light_gap`]).
    pub fill_gap: f32,
    /// The largest 1/⟨v, n⟩.
    pub slope_cap: f32,
    /// The cube face this view marks ([`ALL_FACES`] for a single view).
    pub face: u32,
    /// Which light's byte to count in (0–3).
    pub light: u32,
}

/// The layer gap on a light image at view depth `z`: d̃, but at least three light pixels.
///
/// Why: the reference depth of a pixel is its nearest point, and after a fill it may be a
/// neighbour's, a pixel or two away across the surface; on a surface tilted by θ that is
/// nearer than the pixel's own points, which themselves spread over a pixel's width of
/// depth (pixel · tan θ each). The paper's Δd = d̃ / cos θ covers it only while the light
/// pixel is well below d̃; two pixels were measured to leave 3% of a plane under a low point
/// light unlit in specks (its grazing far side), three leave none (the test
/// `a_plane_under_a_low_point_light_has_no_shadow_acne`).
#[inline]
pub fn light_gap(v: &ViewParams, gap: f32, z: f32) -> f32 {
    gap.max(3.0 * v.footprint(z))
}

/// Δd for a point at `d` from the light (local direction, not normalised) with normal `n`,
/// for the layer gap `gap`.
#[inline]
pub fn offset(d: Vec3, n: Option<Vec3>, gap: f32, cap: f32) -> f32 {
    match n {
        Some(n) => {
            let c = (d * (1.0 / d.dot(d).sqrt())).dot(n).abs();
            if c * cap > 1.0 {
                gap * (1.0 / c)
            } else {
                gap * cap
            }
        }
        None => gap,
    }
}

/// Adds one to the count of every point this view lights. `reference` is the filled depth of
/// the light image. Returns the points lit.
pub fn mark(
    v: &ViewParams,
    reference: &[f32],
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    p: &MarkParams,
    counts: &mut [u32],
) -> u64 {
    let eye = Vec3::from(v.eye);
    let add = 1u32 << (8 * p.light);
    counts
        .par_iter_mut()
        .enumerate()
        .with_min_len(4096)
        .map(|(i, c)| {
            let q = positions[i];
            let d = q - eye;
            if p.face != ALL_FACES && dominant_face(d) != p.face {
                return 0;
            }
            let Some((pix, z)) = crate::passes::project::cpu::project_point(v, q) else {
                return 0;
            };
            let gap = light_gap(v, p.gap, z);
            let dd = offset(d, normals.map(|n| n[i]), gap, p.slope_cap);
            if z <= reference[pix] + dd {
                *c += add;
                1
            } else {
                0
            }
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_offset_grows_with_the_slope_up_to_the_cap() {
        let d = Vec3::new(0.0, 0.0, 5.0);
        assert_eq!(offset(d, Some(Vec3::Z), 0.1, 16.0), 0.1);
        let tilted = Vec3::new(0.8, 0.0, 0.6);
        assert!((offset(d, Some(tilted), 0.1, 16.0) - 0.1 / 0.6).abs() < 1e-6);
        assert_eq!(offset(d, Some(Vec3::X), 0.1, 16.0), 0.1 * 16.0);
        assert_eq!(offset(d, None, 0.1, 16.0), 0.1);
    }

    #[test]
    fn marks_the_nearest_layer_only() {
        // Looking down +z at a 64 × 64 image of pixels 1/16 wide (so d̃' = max(0.1, 3/16)
        // = 0.1875); two points in one pixel 0.05 apart (one surface) and one 1.0 behind
        // (another surface).
        let v = ViewParams::axis_aligned(64, 64, false, 0.5);
        let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let pts = [p(0.53, 0.53, 2.0), p(0.54, 0.54, 2.05), p(0.55, 0.53, 3.0)];
        let mut reference = vec![f32::INFINITY; 64 * 64];
        let (pix, _) = crate::passes::project::cpu::project_point(&v, pts[0]).unwrap();
        for q in &pts {
            assert_eq!(
                crate::passes::project::cpu::project_point(&v, *q)
                    .unwrap()
                    .0,
                pix
            );
        }
        reference[pix] = 2.0;
        assert_eq!(light_gap(&v, 0.1, 2.0), 0.1875);
        let mut counts = vec![0u32; 3];
        let params = MarkParams {
            gap: 0.1,
            fill_gap: 0.1,
            slope_cap: 16.0,
            face: ALL_FACES,
            light: 1,
        };
        assert_eq!(mark(&v, &reference, &pts, None, &params, &mut counts), 2);
        assert_eq!(counts, vec![256, 256, 0]);
    }
}
