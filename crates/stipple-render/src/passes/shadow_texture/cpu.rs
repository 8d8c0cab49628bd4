//! # shadow_texture: mark the points a light sample reaches (Dobrev §6)
//!
//! How it works: after the cloud has been projected from the light and the light image's
//! holes filled (`fill_background`, `fill_occluded`: the reference depth), every point is
//! projected again; a point is lit by this sample when its light-space depth is at most the
//! reference depth at its pixel plus Δd = d̃' · min(1 / |⟨v, n⟩|, cap) (v: the unit direction
//! from the light to the point, n: its normal; d̃' alone without normals; d̃' is d̃ widened to
//! at least three light pixels, see [`light_gap`]), and then its count
//! for this light goes up by [`FULL`]. With a cube of views, a point is tested only by the face of
//! its dominant direction, so it is counted once. See `shadow.rs` for the whole algorithm.
//!
//! Translucent clouds ([`MarkMode::Layer`], [`MarkMode::Rest`]; see [`crate::translucent`]):
//! the light image is peeled into layers, and a point not yet marked by this sample that lies
//! within Δd of layer k's depth gets the light that the layers in front of it let through,
//! T = Π (1 − α) over layers 1 … k − 1 at its pixel (the blend accumulator's transmittance),
//! as T · [`FULL`] rounded. After the last layer every point still unmarked gets what is
//! left at its pixel.

use crate::params::ViewParams;
use crate::shadow::{dominant_face, ALL_FACES, FULL};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// What a mark step tests (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MarkMode {
    /// An opaque cloud's single light image: points within Δd of it get [`FULL`].
    #[default]
    Opaque,
    /// A peeled layer of a translucent cloud's light image: points within Δd of it that no
    /// earlier layer marked get the light left at their pixel.
    Layer,
    /// After the last layer: every point no layer marked gets the light left at its pixel.
    Rest,
}

impl MarkMode {
    /// The shader's code for the mode.
    pub fn code(self) -> u32 {
        match self {
            MarkMode::Opaque => 0,
            MarkMode::Layer => 1,
            MarkMode::Rest => 2,
        }
    }
}

/// A translucent light view's state for [`mark`]: per light pixel the blend accumulator
/// (transmittance in `.3`; with coloured shadows the optical depth per channel in `.0..3`),
/// and one bit per point set once this sample has marked it.
pub struct Transmit<'a> {
    pub acc: &'a [[f32; 4]],
    pub marked: &'a [AtomicU64],
}

/// The sums [`mark`] adds to: per point the grey (or green) sum of each light, and a
/// coloured texture's red and blue ones (see [`crate::LitTexture`]).
pub struct Sums<'a> {
    pub counts: &'a mut [[u16; 4]],
    pub rb: Option<&'a mut [[u16; 8]]>,
}

/// What a sample that reaches a point through transmittance `t` adds to its sum.
#[inline]
pub fn amount(t: f32) -> u16 {
    (t.clamp(0.0, 1.0) * FULL as f32 + 0.5) as u16
}

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
    /// Which light's sum to add to (0–3).
    pub light: u32,
    /// Opaque, or a translucent layer (set by [`crate::schedule::light_view`]).
    pub mode: MarkMode,
    /// Coloured translucent shadows (see [`crate::translucent`]): layers blend optical
    /// depths per channel and marks add to three sums.
    pub coloured: bool,
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

/// Adds to the sum of every point this view lights ([`FULL`], or with `transmit` the light
/// left at its pixel, see the module documentation). `reference` is the filled depth of the
/// light image. Returns the points marked.
pub fn mark(
    v: &ViewParams,
    reference: &[f32],
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    p: &MarkParams,
    sums: Sums<'_>,
    transmit: Option<Transmit<'_>>,
) -> u64 {
    let Sums { counts, rb } = sums;
    let eye = Vec3::from(v.eye);
    let l = p.light as usize;
    let coloured = p.coloured && rb.is_some();
    let mut none: Vec<[u16; 8]> = Vec::new();
    let rb: &mut [[u16; 8]] = match rb {
        Some(rb) => rb,
        None => &mut none,
    };
    let mark_one = |i: usize, c: &mut [u16; 4], rb: Option<&mut [u16; 8]>| -> u64 {
        let (word, bit) = (i / 64, 1u64 << (i % 64));
        if let Some(t) = &transmit {
            if t.marked[word].load(Ordering::Relaxed) & bit != 0 {
                return 0;
            }
        }
        let q = positions[i];
        let d = q - eye;
        if p.face != ALL_FACES && dominant_face(d) != p.face {
            return 0;
        }
        let Some((pix, z)) = crate::passes::project::cpu::project_point(v, q) else {
            return 0;
        };
        if p.mode != MarkMode::Rest {
            let gap = light_gap(v, p.gap, z);
            let dd = offset(d, normals.map(|n| n[i]), gap, p.slope_cap);
            if z > reference[pix] + dd {
                return 0;
            }
        }
        match (&transmit, rb) {
            (Some(t), Some(rb)) if coloured => {
                t.marked[word].fetch_or(bit, Ordering::Relaxed);
                let a = t.acc[pix];
                rb[2 * l] += amount((-a[0]).exp());
                c[l] += amount((-a[1]).exp());
                rb[2 * l + 1] += amount((-a[2]).exp());
            }
            (Some(t), _) => {
                t.marked[word].fetch_or(bit, Ordering::Relaxed);
                c[l] += amount(t.acc[pix][3]);
            }
            (None, rb) => {
                c[l] += FULL;
                if let Some(rb) = rb {
                    rb[2 * l] += FULL;
                    rb[2 * l + 1] += FULL;
                }
            }
        }
        1
    };
    if rb.is_empty() {
        counts
            .par_iter_mut()
            .enumerate()
            .with_min_len(4096)
            .map(|(i, c)| mark_one(i, c, None))
            .sum()
    } else {
        counts
            .par_iter_mut()
            .zip(rb.par_iter_mut())
            .enumerate()
            .with_min_len(4096)
            .map(|(i, (c, rb))| mark_one(i, c, Some(rb)))
            .sum()
    }
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
        let params = MarkParams {
            gap: 0.1,
            fill_gap: 0.1,
            slope_cap: 16.0,
            face: ALL_FACES,
            light: 1,
            mode: MarkMode::Opaque,
            coloured: false,
        };
        let mut counts = vec![[0u16; 4]; 3];
        assert_eq!(
            mark(
                &v,
                &reference,
                &pts,
                None,
                &params,
                Sums {
                    counts: &mut counts,
                    rb: None
                },
                None
            ),
            2
        );
        assert_eq!(counts, vec![[0, FULL, 0, 0], [0, FULL, 0, 0], [0; 4]]);

        // Translucent: the first point was marked by an earlier layer, and the pixel lets
        // 0.3 through; a layer marks the second point only, then the rest takes the third.
        let mut acc = vec![[0.0, 0.0, 0.0, 1.0]; 64 * 64];
        acc[pix][3] = 0.3;
        let marked = vec![AtomicU64::new(1)];
        let mut counts = vec![[0u16; 4]; 3];
        let t = || Transmit {
            acc: &acc,
            marked: &marked,
        };
        let layer = MarkParams {
            mode: MarkMode::Layer,
            ..params
        };
        assert_eq!(
            mark(
                &v,
                &reference,
                &pts,
                None,
                &layer,
                Sums {
                    counts: &mut counts,
                    rb: None
                },
                Some(t())
            ),
            1
        );
        assert_eq!(counts, vec![[0; 4], [0, 77, 0, 0], [0; 4]]);
        let rest = MarkParams {
            mode: MarkMode::Rest,
            ..params
        };
        assert_eq!(
            mark(
                &v,
                &reference,
                &pts,
                None,
                &rest,
                Sums {
                    counts: &mut counts,
                    rb: None
                },
                Some(t())
            ),
            1
        );
        assert_eq!(counts, vec![[0; 4], [0, 77, 0, 0], [0, 77, 0, 0]]);
        assert_eq!(marked[0].load(Ordering::Relaxed), 0b111);
    }
}
