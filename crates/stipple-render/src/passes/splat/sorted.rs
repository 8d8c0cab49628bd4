//! # Sorted splats: Gaussian splats blended back to front (Gunjee et al. §4.2)
//!
//! How it works: the points are bucket-sorted back to front (`passes::bucket_sort`, slices
//! as thick as the smallest splat radius, the paper's ε), shaded one by one (their own normal
//! and position, `shade::cpu::shade_points`), and drawn in that order as round Gaussian
//! splats with the "over" operator: a splat of radius r (its splat radius times the scale) at
//! view depth z covers the pixels whose centres lie within ρ = r · f / z pixels of its
//! projected centre (f: the focal length in pixels; ρ at least half a pixel's diagonal, so
//! every point reaches its own pixel) with weight w = exp(−3 (d/ρ)²) (d: the pixel's
//! distance from the centre; the weight of the blending splats, see `passes::splat`), and
//! C ← a c + (1 − a) C with the fragment's opacity a = 1 − (1 − α)^(w / W).
//!
//! Why that opacity (a deviation from the paper's a = α · w, measured): splats overlap, so
//! a pixel of a surface gets the fragments of about πr²ρ_s ≈ 5.8 splats (radii 0.6 × the
//! 16th neighbour's distance, see `stipple_core::normals`), whose weights add up to
//! W = 0.6² · 16 · (1 − e⁻³)/3 ≈ 1.82 on average (times the square of `--splat-scale`, and
//! of how much a footprint was widened to reach its pixel). With a = α · w an opaque dense
//! surface let 14% of what lies behind it through (1 − 0.317)^5.8) and a translucent one
//! came out far more opaque than its α. Sharing the surface's optical depth −ln(1 − α)
//! among the fragments in proportion to their weights makes a surface of opacity α let
//! 1 − α through whatever its density (α = 1 is taken as 0.999), as depth peeling and the
//! translucent shadows do, and a volume's samples each count as one layer of their opacity.
//!
//! No depth test, no ε-z visibility: every splat counts, as in the paper's volume splatting.
//! The frame's depth and point id are those of the last splat (the nearest) whose weight at
//! the pixel is at least 0.1.
//!
//! The CPU draws bands of rows in parallel: each band takes, in order, the splats that reach
//! it, so every pixel sees its splats in the sorted order. The GPU (`sorted_gpu.rs`,
//! `sorted.wgsl`) sorts with the bucket sort's kernels and draws one 16×16 tile per
//! workgroup, one pixel per thread, the splats in order through workgroup memory. Both take
//! the slices over the cloud's depth range from its bounds (the pipeline's `depth_range`)
//! and the slice thickness `epsilon`, both set when the pipeline is resolved; within a
//! slice the CPU keeps the points' order and the GPU its atomics' order.

use crate::gbuffer::BACKGROUND;
use crate::params::ViewParams;
use glam::Vec3;
use rayon::prelude::*;

/// A sorted frame's points.
pub struct SortedInput<'a> {
    pub positions: &'a [Vec3],
    /// Splat radii (world units), before `scale`.
    pub radii: &'a [f32],
    pub scale: f32,
    /// 8-bit opacity per point (None: opaque).
    pub alpha: Option<&'a [u8]>,
    /// Shaded linear colour per point.
    pub colour: &'a [[f32; 3]],
}

/// Rows per band of the parallel compositing.
pub(super) const BAND: usize = 16;

/// Per band of [`BAND`] rows of an image `h` rows high, the splats (their index in
/// `rows`, in order) whose inclusive row span reaches it (None: off screen).
pub(super) fn band_lists(
    h: usize,
    rows: impl Iterator<Item = Option<(usize, usize)>>,
) -> Vec<Vec<u32>> {
    let bands = h.div_ceil(BAND);
    let mut per_band: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (k, span) in rows.enumerate() {
        if let Some((y0, y1)) = span {
            for b in (y0 / BAND)..=(y1 / BAND).min(bands - 1) {
                per_band[b].push(k as u32);
            }
        }
    }
    per_band
}

/// The weights of a surface's splats at a pixel add up to this on average (see the module
/// documentation): RADIUS_FACTOR² · 16 · (1 − e⁻³) / 3.
pub fn expected_overlap() -> f32 {
    let r = stipple_core::normals::RADIUS_FACTOR;
    r * r * 16.0 * (1.0 - (-3.0f32).exp()) / 3.0
}

/// The most opaque a splat may be (α = 1 shares a finite optical depth).
pub(crate) const MAX_ALPHA: f32 = 0.999;

/// A weight below which a fragment sets no depth or id.
pub(crate) const ID_WEIGHT: f32 = 0.1;

/// Draws the points of `order` (back to front) over `background`; writes linear colour,
/// depth and id per pixel. Returns the fragments drawn.
pub fn composite(
    v: &ViewParams,
    input: &SortedInput,
    order: &[u32],
    background: [f32; 3],
    colour: &mut [[f32; 3]],
    depth: &mut [f32],
    id: &mut [u32],
) -> u64 {
    let (w, h) = (v.width as usize, v.height as usize);
    let eye = Vec3::from(v.eye);
    let (fwd, right, up) = (Vec3::from(v.forward), Vec3::from(v.right), Vec3::from(v.up));
    // Pixels per world unit at depth 1 (perspective) or anywhere (orthographic).
    let focal = 0.5 * v.height as f32 * v.sy;
    let overlap = expected_overlap() * input.scale * input.scale;
    // Projected centre (pixel coordinates), footprint radius (pixels), depth and optical
    // depth per unit weight, in order.
    let splats: Vec<[f32; 5]> = order
        .par_iter()
        .with_min_len(4096)
        .map(|&i| {
            let q = input.positions[i as usize];
            let d = q - eye;
            let z = d.dot(fwd);
            let (x, y) = (d.dot(right), d.dot(up));
            let (nx, ny, per) = if v.perspective == 1 {
                (x * v.sx / z, y * v.sy / z, focal / z)
            } else {
                (x * v.sx, y * v.sy, focal)
            };
            let fx = (nx + 1.0) * 0.5 * w as f32;
            let fy = (1.0 - ny) * 0.5 * h as f32;
            let raw = input.radii[i as usize] * input.scale * per;
            let rho = raw.clamp(
                std::f32::consts::FRAC_1_SQRT_2,
                crate::passes::splat::MAX_FOOTPRINT / 2.0,
            );
            let alpha = input.alpha.map_or(1.0, |a| a[i as usize] as f32 / 255.0);
            let widened = if raw > 0.0 { rho / raw } else { 1.0 };
            let w_sum = overlap * widened * widened;
            let tau = -(1.0 - alpha.min(MAX_ALPHA)).ln() / w_sum.max(1e-6);
            [fx, fy, rho, z, tau]
        })
        .collect();
    // Each band's splats, in order.
    let per_band = band_lists(
        h,
        splats.iter().map(|s| {
            let y0 = (s[1] - s[2]).floor().max(0.0);
            let y1 = (s[1] + s[2]).ceil().min(h as f32 - 1.0);
            let inside = y0 <= y1 && s[0] + s[2] >= 0.0 && s[0] - s[2] <= w as f32;
            inside.then_some((y0 as usize, y1 as usize))
        }),
    );
    colour
        .par_chunks_mut(w * BAND)
        .zip(depth.par_chunks_mut(w * BAND))
        .zip(id.par_chunks_mut(w * BAND))
        .zip(per_band.par_iter())
        .enumerate()
        .map(|(b, (((crow, drow), irow), list))| {
            let rows = crow.len() / w;
            let mut acc = vec![[0.0f32; 4]; crow.len()];
            drow.fill(f32::INFINITY);
            irow.fill(BACKGROUND);
            let mut frags = 0u64;
            for &k in list {
                let [cx, cy, rho, z, tau] = splats[k as usize];
                let i = order[k as usize] as usize;
                let c = input.colour[i];
                let y_lo = ((cy - rho).floor().max((b * BAND) as f32)) as usize;
                let y_hi = ((cy + rho).ceil().min((b * BAND + rows) as f32 - 1.0)) as isize;
                let x_lo = (cx - rho).floor().max(0.0) as usize;
                let x_hi = (cx + rho).ceil().min(w as f32 - 1.0) as isize;
                let inv = 1.0 / (rho * rho);
                for y in y_lo as isize..=y_hi {
                    let dy = y as f32 + 0.5 - cy;
                    for x in x_lo as isize..=x_hi {
                        let dx = x as f32 + 0.5 - cx;
                        let d2 = (dx * dx + dy * dy) * inv;
                        if d2 > 1.0 {
                            continue;
                        }
                        let wgt = (-3.0 * d2).exp();
                        let a = 1.0 - (-tau * wgt).exp();
                        let p = (y as usize - b * BAND) * w + x as usize;
                        let s = &mut acc[p];
                        for ch in 0..3 {
                            s[ch] = a * c[ch] + (1.0 - a) * s[ch];
                        }
                        s[3] = a + (1.0 - a) * s[3];
                        if wgt >= ID_WEIGHT {
                            drow[p] = z;
                            irow[p] = i as u32;
                        }
                        frags += 1;
                    }
                }
            }
            for (o, s) in crow.iter_mut().zip(&acc) {
                *o = std::array::from_fn(|ch| s[ch] + (1.0 - s[3]) * background[ch]);
            }
            frags
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearer_splats_cover_farther_ones_and_translucent_ones_blend() {
        let v = ViewParams::axis_aligned(64, 64, false, 1.0);
        // Looking down +z: a red splat at z 2 behind a green one at z 1 (same x, y), and a
        // half-transparent blue one alone.
        let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let positions = [p(0.3, 0.3, 2.0), p(0.3, 0.3, 1.0), p(0.7, 0.6, 1.5)];
        let colour = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let alpha = [255u8, 255, 128];
        let input = SortedInput {
            positions: &positions,
            radii: &[0.05; 3],
            scale: 1.0,
            alpha: Some(&alpha),
            colour: &colour,
        };
        let bg = [0.5, 0.5, 0.5];
        let n = v.pixels();
        let (mut c, mut d, mut id) = (vec![[0.0; 3]; n], vec![0.0; n], vec![0; n]);
        composite(&v, &input, &[0, 1, 2], bg, &mut c, &mut d, &mut id);
        let at = |x: f32, y: f32| {
            let (k, _) = crate::passes::project::cpu::project_point(&v, p(x, y, 1.0)).unwrap();
            k
        };
        let k = at(0.3, 0.3);
        assert_eq!(id[k], 1, "the nearer splat's id");
        assert!(
            c[k][1] > 0.95 && c[k][0] < 0.05,
            "green over red: {:?}",
            c[k]
        );
        // Drawn in the wrong order, red would cover green.
        let (mut c2, mut d2, mut id2) = (vec![[0.0; 3]; n], vec![0.0; n], vec![0; n]);
        composite(&v, &input, &[1, 0, 2], bg, &mut c2, &mut d2, &mut id2);
        assert!(c2[k][0] > 0.95, "{:?}", c2[k]);
        // The translucent splat's centre: α ≈ 0.5 of blue over the grey background.
        let k = at(0.7, 0.6);
        // One splat alone: a = 1 − (1 − α)^(w / W) at its centre (w ≈ 1).
        let a = 1.0 - (1.0 - 128.0f32 / 255.0).powf(1.0 / expected_overlap());
        for (ch, want) in [(0, (1.0 - a) * 0.5), (2, a + (1.0 - a) * 0.5)] {
            assert!((c[k][ch] - want).abs() < 0.05, "channel {ch}: {:?}", c[k]);
        }
        // Background elsewhere, with no depth or id.
        assert_eq!(c[0], bg);
        assert_eq!((d[0], id[0]), (f32::INFINITY, BACKGROUND));
    }
}
