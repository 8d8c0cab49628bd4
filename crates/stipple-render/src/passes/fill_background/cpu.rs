//! # Filling background pixels (Dobrev §3.2)
//!
//! How it works: a background pixel with at least one covered neighbour is tested against the
//! eight silhouette masks (`masks.rs`): if some mask sees only background, the pixel lies
//! beyond the silhouette and stays background; otherwise it is a hole and takes the point of
//! the covered neighbour with the smallest depth (ties: smaller point id). Pixels outside the
//! image count as background. One iteration reads the previous image only (Jacobi order), so
//! the result does not depend on the traversal and matches the GPU twin; a hole of diameter n
//! closes within n iterations.
//!
//! On the CPU a step works in place and skips pixels whose masks cannot all be blocked (see
//! `passes::fill::cpu`).
//!
//! Limit and extension: the 3×3 rule needs the pixels around a hole to be covered. Where
//! points are 3 or more pixels apart (a sparse cloud, or a close-up), a gap pixel can see a
//! clear half-plane inside the surface; on a regular lattice with 2-pixel gaps no iteration
//! ever fills. `radius` 2 applies the same half-plane masks to the 5×5 window (`masks.rs`),
//! which closes such gaps while silhouettes still keep a clear half-plane outside.

use crate::gbuffer::{is_point, GBuffer};
use crate::masks::MAX_RADIUS;
pub use crate::passes::fill::cpu::Changed;
use crate::passes::fill::cpu::{apply, fill_changes, point_spans, within, Coverage, Precheck};

/// One iteration from `src` into `dst` with masks over the (2·radius+1)² window (radius 1 is
/// the paper's 3×3); returns the number of pixels filled.
pub fn fill_background(src: &GBuffer, dst: &mut GBuffer, radius: u32) -> u64 {
    dst.clone_from(src);
    fill_background_in_place(dst, radius)
}

/// [`fill_background`] on `g` itself: every pixel is decided from `g` as it was (the same
/// Jacobi step), then the filled pixels are written; no copy of the image is made.
pub fn fill_background_in_place(g: &mut GBuffer, radius: u32) -> u64 {
    fill_background_step(g, radius, None).0
}

/// [`fill_background_in_place`], after a step that changed `since` (when given): only
/// pixels within `radius` of a change are examined, since every other pixel sees the
/// window it saw then and decides as it did (it stayed as it was). Returns the pixels
/// filled and where they are.
pub fn fill_background_step(
    g: &mut GBuffer,
    radius: u32,
    since: Option<&Changed>,
) -> (u64, Changed) {
    let spans = within(point_spans(g, radius), since, radius);
    let pre = if radius <= MAX_RADIUS {
        Precheck::Coverage(Coverage::new(g, radius))
    } else {
        Precheck::None
    };
    let changes = fill_changes(
        g,
        radius,
        Some(&spans),
        |_, id| !is_point(id),
        pre,
        |_| {},
        |_, _| |_: f32, nid: u32, _: i32, _: i32| is_point(nid),
    );
    apply(g, changes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gbuffer::BACKGROUND;
    use crate::masks::{MASKS, OFFSETS};

    fn step(g: &GBuffer) -> (GBuffer, u64) {
        let mut out = GBuffer::new(g.width, g.height);
        let n = fill_background(g, &mut out, 1);
        (out, n)
    }

    #[test]
    fn a_pixel_beyond_the_silhouette_stays_background_under_each_mask() {
        for m in MASKS {
            // Centre background; cells of mask m background; all other cells covered.
            let mut g = GBuffer::new(3, 3);
            for (b, &(dx, dy)) in OFFSETS.iter().enumerate() {
                if m & (1 << b) == 0 {
                    let k = ((1 + dy) * 3 + 1 + dx) as usize;
                    g.id[k] = b as u32;
                    g.depth[k] = 1.0;
                }
            }
            // Embed in a larger background image so the outside is background too.
            let (out, n) = step(&g);
            assert_eq!(out.id[4], BACKGROUND, "mask {m:08b} must keep the centre");
            assert_eq!(n, 0);
        }
    }

    #[test]
    fn a_one_pixel_hole_is_filled_from_the_nearest_neighbour() {
        let g = GBuffer::from_ascii(&["55555", "55555", "55.35", "55555", "55555"]);
        let (out, n) = step(&g);
        assert_eq!(n, 1);
        assert_eq!(out.depth[12], 3.0, "nearest neighbour's depth");
        assert_eq!(out.id[12], g.id[13]);
    }

    #[test]
    fn silhouettes_do_not_grow() {
        let g = GBuffer::from_ascii(&[
            "..........",
            "..####....",
            "..#####...",
            "..######..",
            "..#####...",
            "..........",
        ]);
        let mut cur = g.clone();
        for _ in 0..5 {
            cur = step(&cur).0;
        }
        assert_eq!(cur, g, "\n{}", cur.to_ascii());
    }

    /// A disc of diameter n cut out of a covered square closes within n iterations.
    #[test]
    fn a_hole_of_diameter_n_closes_within_n_iterations() {
        for n in 1..=14 {
            let size = n + 8;
            let c = size as f32 / 2.0;
            let mut g = GBuffer::new(size as u32, size as u32);
            let mut holes = 0;
            for j in 0..size {
                for i in 0..size {
                    let (dx, dy) = (i as f32 + 0.5 - c, j as f32 + 0.5 - c);
                    let k = j * size + i;
                    if (dx * dx + dy * dy).sqrt() < n as f32 / 2.0 {
                        holes += 1;
                        continue;
                    }
                    g.id[k] = k as u32;
                    g.depth[k] = 1.0;
                }
            }
            assert!(holes > 0);
            let mut it = 0;
            while g.covered() < size * size {
                g = step(&g).0;
                it += 1;
                assert!(
                    it <= n,
                    "diameter {n}: not closed after {n} iterations\n{}",
                    g.to_ascii()
                );
            }
        }
    }

    #[test]
    fn radius_two_closes_a_lattice_with_two_pixel_gaps() {
        // Points every third pixel: every gap pixel sees a clear 3×3 half-plane.
        let mut g = GBuffer::new(16, 16);
        for j in (2..14).step_by(3) {
            for i in (2..14).step_by(3) {
                g.id[j * 16 + i] = (j * 16 + i) as u32;
                g.depth[j * 16 + i] = 1.0;
            }
        }
        let mut out = GBuffer::new(16, 16);
        assert_eq!(
            fill_background(&g, &mut out, 1),
            0,
            "3×3 masks cannot close it"
        );
        let mut cur = g.clone();
        for _ in 0..2 {
            fill_background(&cur, &mut out, 2);
            std::mem::swap(&mut cur, &mut out);
        }
        for j in 2..=11 {
            for i in 2..=11 {
                assert_ne!(
                    cur.id[j * 16 + i],
                    BACKGROUND,
                    "({i}, {j})\n{}",
                    cur.to_ascii()
                );
            }
        }
        // ...and the lattice's outline does not grow.
        assert!((0..16).all(|k| cur.id[k] == BACKGROUND && cur.id[k * 16] == BACKGROUND));
    }

    #[test]
    fn a_square_hole_closes() {
        let mut g = GBuffer::from_ascii(&[
            "#########",
            "#########",
            "##.....##",
            "##.....##",
            "##.....##",
            "##.....##",
            "##.....##",
            "#########",
            "#########",
        ]);
        let mut it = 0;
        while g.covered() < 81 {
            g = step(&g).0;
            it += 1;
            assert!(it <= 8, "\n{}", g.to_ascii());
        }
    }
}
