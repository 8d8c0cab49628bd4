//! # Screen-space visibility (Pintus §4)
//!
//! How it works: a pixel's sample p₀ (the point it shows, or, for a background pixel, the far
//! plane on its ray) is visible when a wide enough cone around the ray towards the eye is free
//! of other samples. The neighbourhood, the disc of diameter k pixels, is cut into 8 sectors
//! of 45° (centred on the axes and diagonals). In each sector the horizon is the neighbour
//! with the largest v·c, v the unit vector from p₀ to the eye and c the unit vector from p₀
//! to the neighbour; the free cone sector then has the solid angle (2π/8)(1 − max(0, v·c)).
//! Their sum over the sectors, as a fraction of the hemisphere (2π), is compared with the
//! threshold. A sector without neighbours is fully open.
//!
//! Points judged invisible become [`HOLE`] (empty, mutable by the anisotropic fill). So do
//! background pixels judged invisible (holes inside a surface); background pixels judged
//! visible stay `BACKGROUND`, which the fill never changes, so it does not grow silhouettes.
//!
//! Deviation from the paper: the k×k neighbourhood is the disc of diameter k instead of the
//! square, so that every sector reaches as far (a square reaches √2 further along diagonals)
//! and even sizes (4×4, 6×6) are centred on the pixel.

use crate::gbuffer::{is_point, GBuffer, HOLE};
use crate::params::ViewParams;
use glam::Vec3;
use rayon::prelude::*;

/// Sectors around a pixel.
pub const SECTORS: usize = 8;

/// Smallest and largest kernel accepted.
pub use crate::pipeline::VISIBILITY_KERNELS as KERNELS;

/// Neighbour offsets of kernel `k`: (dx, dy, sector, 0), nearest first within a sector order
/// that both backends share (the GPU uploads this table).
pub fn kernel_offsets(k: u32) -> Vec<[i32; 4]> {
    let r = k as f64 / 2.0;
    let h = r.floor() as i32;
    let mut v = Vec::new();
    for dy in -h..=h {
        for dx in -h..=h {
            if (dx, dy) == (0, 0) || (dx * dx + dy * dy) as f64 > r * r {
                continue;
            }
            let a = (dy as f64).atan2(dx as f64) + std::f64::consts::PI / 8.0;
            let s = (a.rem_euclid(2.0 * std::f64::consts::PI) / (std::f64::consts::PI / 4.0))
                .floor() as i32
                % SECTORS as i32;
            v.push([dx, dy, s, 0]);
        }
    }
    v
}

/// The sample a pixel stands for: its point, or the far plane for an empty pixel.
#[inline]
fn sample(v: &ViewParams, g: &GBuffer, x: u32, y: u32) -> Vec3 {
    let k = (y * g.width + x) as usize;
    let z = if is_point(g.id[k]) { g.depth[k] } else { v.far };
    v.view_position(x, y, z)
}

/// The free fraction of the hemisphere above pixel (x, y): in [0, 1].
pub fn openness(v: &ViewParams, g: &GBuffer, offsets: &[[i32; 4]], x: u32, y: u32) -> f32 {
    let p0 = sample(v, g, x, y);
    let to_eye = if v.perspective == 1 {
        -p0 * (1.0 / p0.dot(p0).sqrt())
    } else {
        Vec3::new(0.0, 0.0, -1.0)
    };
    let mut horizon = [0.0f32; SECTORS];
    let (w, h) = (g.width as i32, g.height as i32);
    for &[dx, dy, s, _] in offsets {
        let (nx, ny) = (x as i32 + dx, y as i32 + dy);
        if nx < 0 || ny < 0 || nx >= w || ny >= h {
            continue;
        }
        let n = (ny * w + nx) as usize;
        if !is_point(g.id[n]) {
            continue;
        }
        let d = v.view_position(nx as u32, ny as u32, g.depth[n]) - p0;
        let len2 = dot3(d, d);
        if len2 <= 0.0 {
            continue;
        }
        let c = dot3(to_eye, d) / len2.sqrt();
        let s = s as usize;
        if c > horizon[s] {
            horizon[s] = c;
        }
    }
    let mut open = 0.0;
    for hs in horizon {
        open += 1.0 - hs;
    }
    open / SECTORS as f32
}

/// Dot product summed term by term (the WGSL twin's order).
#[inline]
fn dot3(a: Vec3, b: Vec3) -> f32 {
    a.x * b.x + a.y * b.y + a.z * b.z
}

/// One visibility pass from `src` into `dst`; returns the number of points judged invisible.
pub fn visibility(
    v: &ViewParams,
    src: &GBuffer,
    dst: &mut GBuffer,
    kernel: u32,
    threshold: f32,
) -> u64 {
    let offsets = kernel_offsets(kernel);
    let w = src.width as usize;
    dst.depth
        .par_chunks_mut(w)
        .zip(dst.id.par_chunks_mut(w))
        .enumerate()
        .map(|(y, (drow, irow))| {
            let mut hidden = 0;
            for x in 0..w {
                let k = y * w + x;
                let (d, id) = (src.depth[k], src.id[k]);
                let visible = openness(v, src, &offsets, x as u32, y as u32) >= threshold;
                if visible {
                    drow[x] = d;
                    irow[x] = id;
                } else {
                    hidden += is_point(id) as u64;
                    drow[x] = f32::INFINITY;
                    irow[x] = HOLE;
                }
            }
            hidden
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gbuffer::BACKGROUND;

    #[test]
    fn offsets_cover_the_disc_evenly() {
        for k in KERNELS {
            let o = kernel_offsets(k);
            let mut per = [0; SECTORS];
            for &[dx, dy, s, _] in &o {
                per[s as usize] += 1;
                // Point symmetry: the opposite offset lies in the opposite sector.
                assert!(o.contains(&[-dx, -dy, (s + 4) % 8, 0]), "k {k} ({dx},{dy})");
            }
            assert!(per.iter().all(|&c| c > 0), "k {k}: {per:?}");
            assert_eq!(per[0], per[4]);
        }
        assert_eq!(kernel_offsets(4).len(), 12);
        assert_eq!(kernel_offsets(3).len(), 8);
        // (1, 0) lies in sector 0, (1, 1) in sector 1, (0, 1) in sector 2.
        let o = kernel_offsets(3);
        assert!(
            o.contains(&[1, 0, 0, 0]) && o.contains(&[1, 1, 1, 0]) && o.contains(&[0, 1, 2, 0])
        );
    }

    #[test]
    fn a_flat_surface_is_open_and_a_pixel_between_nearer_points_is_not() {
        // A facing plane at depth 5 with every third pixel of a plane at depth 2 in front.
        let (w, h) = (24, 24);
        let v = ViewParams::axis_aligned(w, h, true, 1.0);
        let mut g = GBuffer::new(w, h);
        for k in 0..(w * h) as usize {
            let (x, y) = (k % w as usize, k / w as usize);
            let near = x % 3 == 0 && y % 3 == 0;
            g.depth[k] = if near { 2.0 } else { 5.0 };
            g.id[k] = k as u32;
        }
        // Kernel 9 reaches near points in 6 of the 8 sectors (kernel 7: only 4).
        let off = kernel_offsets(9);
        let seen_through = openness(&v, &g, &off, 13, 13);
        assert!(seen_through < 0.3, "{seen_through}");
        let front = openness(&v, &g, &off, 12, 12);
        assert!(front > 0.95, "{front}");
        let mut out = GBuffer::new(w, h);
        let hidden = visibility(&v, &g, &mut out, 9, 0.35);
        assert_eq!(out.id[13 * 24 + 13], HOLE);
        assert_eq!(out.id[12 * 24 + 12], (12 * 24 + 12) as u32);
        // Every far pixel at least 4 px from the border is hidden; near ones all stay.
        let interior_far = (4..20)
            .flat_map(|y| (4..20).map(move |x| (x, y)))
            .filter(|&(x, y)| !(x % 3 == 0 && y % 3 == 0))
            .count() as u64;
        assert!(hidden >= interior_far, "{hidden} < {interior_far}");
        assert!((0..(w * h) as usize)
            .filter(|k| (k % 24) % 3 == 0 && (k / 24) % 3 == 0)
            .all(|k| out.id[k] == k as u32));
    }

    #[test]
    fn background_outside_a_silhouette_stays_and_holes_inside_empty() {
        // A facing square of points with a 1-pixel hole in the middle.
        let (w, h) = (32, 32);
        let v = ViewParams::axis_aligned(w, h, true, 1.0);
        let mut g = GBuffer::new(w, h);
        for y in 8..24 {
            for x in 8..24 {
                if (x, y) != (16, 16) {
                    let k = (y * w + x) as usize;
                    g.depth[k] = 3.0;
                    g.id[k] = k as u32;
                }
            }
        }
        let mut out = GBuffer::new(w, h);
        visibility(&v, &g, &mut out, 5, 0.35);
        assert_eq!(out.id[16 * 32 + 16], HOLE, "hole inside the surface");
        // Just outside an edge (not a corner), half the sectors are open.
        assert_eq!(out.id[16 * 32 + 7], BACKGROUND);
        assert_eq!(out.id[0], BACKGROUND);
        assert_eq!(out.covered(), 16 * 16 - 1);
    }
}
