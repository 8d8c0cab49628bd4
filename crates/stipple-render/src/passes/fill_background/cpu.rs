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
//! Limit and extension: the 3×3 rule needs the pixels around a hole to be covered. Where
//! points are 3 or more pixels apart (a sparse cloud, or a close-up), a gap pixel can see a
//! clear half-plane inside the surface; on a regular lattice with 2-pixel gaps no iteration
//! ever fills. `radius` 2 applies the same half-plane masks to the 5×5 window (`masks.rs`),
//! which closes such gaps while silhouettes still keep a clear half-plane outside.

use crate::gbuffer::{is_point, GBuffer, BACKGROUND};
use crate::masks::window;
use rayon::prelude::*;

/// One iteration from `src` into `dst` with masks over the (2·radius+1)² window (radius 1 is
/// the paper's 3×3); returns the number of pixels filled.
pub fn fill_background(src: &GBuffer, dst: &mut GBuffer, radius: u32) -> u64 {
    let spans = point_spans(src, radius);
    fill_pass_in(
        src,
        dst,
        radius,
        Some(&spans),
        |_, id| !is_point(id),
        |_, _, _, nid| is_point(nid),
    )
}

/// Per row, the columns within `radius` of a point in rows `y − radius ..= y + radius`
/// (`None`: no point that near): a background pixel outside that span has no point in its
/// window, so no mask is blocked and it is never filled; the row loop skips the mask test
/// there (the same result, much less work on a frame that is mostly background).
fn point_spans(g: &GBuffer, radius: u32) -> Vec<Option<(i32, i32)>> {
    let (w, h) = (g.width as usize, g.height as usize);
    let rows: Vec<Option<(i32, i32)>> =
        g.id.par_chunks(w)
            .map(|row| {
                let lo = row.iter().position(|&id| is_point(id))?;
                let hi = row.iter().rposition(|&id| is_point(id))?;
                Some((lo as i32, hi as i32))
            })
            .collect();
    let r = radius as i32;
    (0..h as i32)
        .map(|y| {
            let mut span: Option<(i32, i32)> = None;
            for yy in (y - r).max(0)..=(y + r).min(h as i32 - 1) {
                if let Some((lo, hi)) = rows[yy as usize] {
                    span = Some(match span {
                        None => (lo, hi),
                        Some((a, b)) => (a.min(lo), b.max(hi)),
                    });
                }
            }
            span.map(|(lo, hi)| (lo - r, hi + r))
        })
        .collect()
}

/// The row loop both fill passes share: every pixel for which `candidate(depth, id)` holds
/// runs the mask test, where a cell is solid when `solid(depth, cell depth, id, cell id)`;
/// other pixels are copied. Returns the number of pixels replaced.
pub(crate) fn fill_pass(
    src: &GBuffer,
    dst: &mut GBuffer,
    radius: u32,
    candidate: impl Fn(f32, u32) -> bool + Sync,
    solid: impl Fn(f32, f32, u32, u32) -> bool + Sync,
) -> u64 {
    fill_pass_in(src, dst, radius, None, candidate, solid)
}

/// [`fill_pass`], testing only the columns of each row's span when `spans` is given (pixels
/// outside it are copied: the caller knows no mask can be blocked there).
fn fill_pass_in(
    src: &GBuffer,
    dst: &mut GBuffer,
    radius: u32,
    spans: Option<&[Option<(i32, i32)>]>,
    candidate: impl Fn(f32, u32) -> bool + Sync,
    solid: impl Fn(f32, f32, u32, u32) -> bool + Sync,
) -> u64 {
    let (w, h) = (src.width as i32, src.height as i32);
    let win = window(radius);
    dst.depth
        .par_chunks_mut(w as usize)
        .zip(dst.id.par_chunks_mut(w as usize))
        .enumerate()
        .map(|(y, (drow, irow))| {
            let y = y as i32;
            let mut changed = 0u64;
            let row = (y * w) as usize..((y + 1) * w) as usize;
            drow.copy_from_slice(&src.depth[row.clone()]);
            irow.copy_from_slice(&src.id[row]);
            let (x0, x1) = match spans {
                Some(s) => match s[y as usize] {
                    Some((lo, hi)) => (lo.max(0), (hi + 1).min(w)),
                    None => return 0,
                },
                None => (0, w),
            };
            for x in x0..x1 {
                let k = (y * w + x) as usize;
                let (d, id) = (src.depth[k], src.id[k]);
                if !candidate(d, id) {
                    continue;
                }
                if let Some((nd, nid)) =
                    hole_fill(src, &win, x, y, w, h, |cd, cid| solid(d, cd, id, cid))
                {
                    drow[x as usize] = nd;
                    irow[x as usize] = nid;
                    changed += 1;
                }
            }
            changed
        })
        .sum()
}

/// The shared mask test: cells for which `solid(depth, id)` holds block the masks they belong
/// to (cells outside the image never do). When all eight masks are blocked, returns the solid
/// cell of minimum (depth, id), preferring the 3×3 ring; otherwise None (a border pixel).
#[inline]
pub(crate) fn hole_fill(
    src: &GBuffer,
    win: &[(i32, i32, u8)],
    x: i32,
    y: i32,
    w: i32,
    h: i32,
    solid: impl Fn(f32, u32) -> bool,
) -> Option<(f32, u32)> {
    let r = win.last().map_or(0, |c| c.1.abs().max(c.0.abs()));
    if x >= r && y >= r && x < w - r && y < h - r {
        hole_fill_in::<false>(src, win, x, y, w, h, solid)
    } else {
        hole_fill_in::<true>(src, win, x, y, w, h, solid)
    }
}

#[inline(always)]
fn hole_fill_in<const CHECK: bool>(
    src: &GBuffer,
    win: &[(i32, i32, u8)],
    x: i32,
    y: i32,
    w: i32,
    h: i32,
    solid: impl Fn(f32, u32) -> bool,
) -> Option<(f32, u32)> {
    let mut blocked = 0u8;
    let mut best = (f32::INFINITY, BACKGROUND);
    let mut best_ring = i32::MAX;
    for (c, &(dx, dy, m)) in win.iter().enumerate() {
        if c == 8 && blocked == 0xFF && best_ring == 1 {
            break;
        }
        let (nx, ny) = (x + dx, y + dy);
        if CHECK && (nx < 0 || ny < 0 || nx >= w || ny >= h) {
            continue;
        }
        let n = (ny * w + nx) as usize;
        let (nd, nid) = (src.depth[n], src.id[n]);
        if !solid(nd, nid) {
            continue;
        }
        blocked |= m;
        let ring = dx.abs().max(dy.abs());
        if ring < best_ring
            || (ring == best_ring && (nd < best.0 || (nd == best.0 && nid < best.1)))
        {
            best = (nd, nid);
            best_ring = ring;
        }
    }
    (blocked == 0xFF).then_some(best)
}

#[cfg(test)]
mod tests {
    use super::*;
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
