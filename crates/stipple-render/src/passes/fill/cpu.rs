//! The mask test that `fill_background` and `fill_occluded` share on the CPU (Dobrev
//! §3.2–3.3; GPU twin: `fill.wgsl`), and what makes it cheap: a step works in place (every
//! pixel is decided from the image as it was, then the pixels replaced are written: no copy
//! of the image per iteration); pixels whose masks cannot all be blocked skip the mask test
//! (`Precheck`); and a step after another examines only the pixels within the window's
//! radius of the other's changes (`within`), since every other pixel sees the window it
//! saw then. None of this changes a pixel of the result (`the_prechecks_change_no_pixel`).

use crate::gbuffer::{is_point, GBuffer, BACKGROUND};
use crate::masks::{window, MAX_RADIUS};
use crate::params::ViewParams;
use crate::passes::project::cpu::{dot3, Facing};
use crate::passes::{prefetch, Surfaces};
use glam::Vec3;
use rayon::prelude::*;

/// Per row, the first and last column a step changed (`None`: none).
pub type Changed = Vec<Option<(i32, i32)>>;

/// `spans` narrowed to the columns within `radius` of a change in `since` (when given).
pub(crate) fn within(mut spans: Changed, since: Option<&Changed>, radius: u32) -> Changed {
    if let Some(since) = since {
        let near = dilate(since, radius);
        for (s, n) in spans.iter_mut().zip(near) {
            *s = match (*s, n) {
                (Some((a, b)), Some((c, d))) if a.max(c) <= b.min(d) => Some((a.max(c), b.min(d))),
                _ => None,
            };
        }
    }
    spans
}

/// Per row, the columns within `radius` (rows and columns) of a row's span in `rows`.
pub(crate) fn dilate(rows: &[Option<(i32, i32)>], radius: u32) -> Changed {
    let (h, r) = (rows.len() as i32, radius as i32);
    (0..h)
        .map(|y| {
            let mut span: Option<(i32, i32)> = None;
            for yy in (y - r).max(0)..=(y + r).min(h - 1) {
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

/// Which pixels may skip the mask test of [`MaskTest::fill`] (the result is the same: a skipped
/// pixel is one whose masks could not all be blocked), and whether a pixel that goes on is
/// known to have all its masks blocked.
pub(crate) enum Precheck {
    /// Solid cells are the points (the background fill): the blocked masks come from the
    /// coverage bits, a few table lookups a pixel.
    Coverage(Coverage),
    /// Solid cells are those at least `gap` nearer than the pixel (the occluded fill): no
    /// solid cell when the least depth of the window is farther than that; otherwise the
    /// blocked masks come from the cells' comparisons, a pattern a row (`rows`).
    /// `exact`: the cells' depths decide solidity alone (a test that also reads the points
    /// takes the depths' verdict as a necessary condition only).
    Nearer {
        gap: f32,
        rows: Option<MaskRows>,
        exact: bool,
    },
    /// Every candidate runs the mask test.
    None,
}

/// For each row of a (2r+1)² window (r ≤ [`MAX_RADIUS`]) and each pattern of its 2r + 1
/// cells (bit i: column x − r + i), the masks those cells block (`masks::window`).
pub(crate) struct MaskRows {
    radius: u32,
    blocks: Vec<[u8; 128]>,
}

impl MaskRows {
    pub(crate) fn new(radius: u32) -> Option<MaskRows> {
        if radius > MAX_RADIUS {
            return None;
        }
        let r = radius as i32;
        let mut blocks = vec![[0u8; 128]; (2 * r + 1) as usize];
        for &(dx, dy, m) in &window(radius) {
            let bit = 1usize << (dx + r);
            for (p, b) in blocks[(dy + r) as usize].iter_mut().enumerate() {
                if p & bit != 0 {
                    *b |= m;
                }
            }
        }
        Some(MaskRows { radius, blocks })
    }

    /// The masks blocked by the cells of (x, y)'s window for which `solid(depth)` holds
    /// (cells outside the image never do).
    #[inline]
    fn blocked(&self, src: &GBuffer, x: i32, y: i32, solid: impl Fn(f32) -> bool) -> u8 {
        let (w, h) = (src.width as i32, src.height as i32);
        let r = self.radius as i32;
        if x >= r && y >= r && x + r < w && y + r < h {
            // Inside the image: rows of a fixed length the compiler unrolls (this precheck
            // runs for every candidate with a nearer cell around it).
            let first = ((y - r) * w + x - r) as usize;
            return match self.radius {
                1 => self.blocked_inside::<3>(&src.depth, first, w as usize, solid),
                2 => self.blocked_inside::<5>(&src.depth, first, w as usize, solid),
                _ => self.blocked_inside::<7>(&src.depth, first, w as usize, solid),
            };
        }
        let (a, b) = ((x - r).max(0), (x + r).min(w - 1));
        let mut blocked = 0u8;
        for yy in (y - r).max(0)..=(y + r).min(h - 1) {
            let row = &src.depth[(yy * w + a) as usize..=(yy * w + b) as usize];
            let shift = (a - (x - r)) as usize;
            let mut p = 0usize;
            for (i, &d) in row.iter().enumerate() {
                p |= (solid(d) as usize) << (i + shift);
            }
            blocked |= self.blocks[(yy - y + r) as usize][p];
        }
        blocked
    }

    /// [`MaskRows::blocked`] for a window of N = 2r + 1 columns and rows inside the image,
    /// whose top-left cell is `depth[first]` (rows `w` apart).
    #[inline(always)]
    fn blocked_inside<const N: usize>(
        &self,
        depth: &[f32],
        first: usize,
        w: usize,
        solid: impl Fn(f32) -> bool,
    ) -> u8 {
        debug_assert_eq!(N, 2 * self.radius as usize + 1);
        let mut blocked = 0u8;
        for (dy, masks) in self.blocks.iter().enumerate().take(N) {
            let start = first + dy * w;
            let row: &[f32; N] = depth[start..start + N].try_into().expect("N cells");
            let mut p = 0usize;
            for (i, &d) in row.iter().enumerate() {
                p |= (solid(d) as usize) << i;
            }
            blocked |= masks[p];
        }
        blocked
    }
}

/// Covered pixels as bits, each row padded with [`MAX_RADIUS`] empty bits on both sides, and
/// the masks they block ([`MaskRows`]).
pub(crate) struct Coverage {
    bits: Vec<u64>,
    stride: usize,
    rows: MaskRows,
}

impl Coverage {
    const PAD: usize = MAX_RADIUS as usize;

    pub(crate) fn new(g: &GBuffer, radius: u32) -> Coverage {
        let rows = MaskRows::new(radius).expect("radius at most MAX_RADIUS");
        let w = g.width as usize;
        let stride = (w + 2 * Self::PAD).div_ceil(64) + 1;
        let mut bits = vec![0u64; stride * g.height as usize];
        if w > 0 {
            bits.par_chunks_mut(stride)
                .zip(g.id.par_chunks(w))
                .for_each(|(row, ids)| {
                    for (x, &id) in ids.iter().enumerate() {
                        if is_point(id) {
                            let b = x + Self::PAD;
                            row[b / 64] |= 1 << (b % 64);
                        }
                    }
                });
        }
        Coverage { bits, stride, rows }
    }

    /// The masks the points of (x, y)'s window block (0xFF: all eight).
    #[inline]
    fn blocked(&self, x: i32, y: i32, h: i32) -> u8 {
        let r = self.rows.radius as i32;
        let n = 2 * self.rows.radius + 1;
        // Bits x − r ..= x + r of a row, at x − r + PAD ≥ 0.
        let s = (x - r + Self::PAD as i32) as usize;
        let (word, off) = (s / 64, s % 64);
        if y >= r && y + r < h {
            // All rows inside the image: a fixed count the compiler unrolls.
            let first = (y - r) as usize * self.stride + word;
            return match self.rows.radius {
                1 => self.blocked_inside::<3>(first, off),
                2 => self.blocked_inside::<5>(first, off),
                _ => self.blocked_inside::<7>(first, off),
            };
        }
        let mut blocked = 0u8;
        for yy in (y - r).max(0)..=(y + r).min(h - 1) {
            let row = &self.bits[yy as usize * self.stride..];
            let mut v = row[word] >> off;
            if off > 0 {
                v |= row[word + 1] << (64 - off);
            }
            let p = (v as usize) & ((1 << n) - 1);
            blocked |= self.rows.blocks[(yy - y + r) as usize][p];
        }
        blocked
    }

    /// [`Coverage::blocked`] for N = 2r + 1 rows inside the image, the first row's window
    /// starting at bit `off` of `bits[first]`.
    #[inline(always)]
    fn blocked_inside<const N: usize>(&self, first: usize, off: usize) -> u8 {
        debug_assert_eq!(N, 2 * self.rows.radius as usize + 1);
        let mut blocked = 0u8;
        for (dy, masks) in self.rows.blocks.iter().enumerate().take(N) {
            let k = first + dy * self.stride;
            // Two words always exist: each row ends with a spare one.
            let pair = (self.bits[k] as u128) | ((self.bits[k + 1] as u128) << 64);
            let p = ((pair >> off) as usize) & ((1 << N) - 1);
            blocked |= masks[p];
        }
        blocked
    }
}

/// Per row, the columns within `radius` of a point in rows `y − radius ..= y + radius`
/// (`None`: no point that near): a background pixel outside that span has no point in its
/// window, so no mask is blocked and it is never filled; the row loop skips the mask test
/// there (the same result, much less work on a frame that is mostly background).
pub(crate) fn point_spans(g: &GBuffer, radius: u32) -> Changed {
    let w = g.width as usize;
    if w == 0 {
        return vec![None; g.height as usize];
    }
    let rows: Changed =
        g.id.par_chunks(w)
            .map(|row| {
                let lo = row.iter().position(|&id| is_point(id))?;
                let hi = row.iter().rposition(|&id| is_point(id))?;
                Some((lo as i32, hi as i32))
            })
            .collect();
    dilate(&rows, radius)
}

/// The occluded fill's step (see `passes::fill_occluded`) on `g` in place: every point runs
/// the mask test, where a cell is solid when its depth is at most the point's less `gap`;
/// after a step that changed `since`, only pixels within `radius` of a change (as
/// `fill_background_step`). Returns the pixels replaced and where they are.
pub(crate) fn fill_points(
    g: &mut GBuffer,
    radius: u32,
    gap: f32,
    since: Option<&Changed>,
    slope: Option<(&ViewParams, Surfaces<'_>)>,
) -> (u64, Changed) {
    // Only the columns between a row's first and last point hold candidates.
    let spans = within(point_spans(g, 0), since, radius);
    let changes = fill_changes(
        g,
        radius,
        Some(&spans),
        |_, id| is_point(id),
        Precheck::Nearer {
            gap,
            rows: MaskRows::new(radius),
            exact: slope.is_none(),
        },
        |id| {
            if let Some((_, s)) = slope {
                prefetch(s.positions, id);
                prefetch(s.normals, id);
            }
        },
        |d, id| {
            let plane = slope.and_then(|(v, s)| FillPlane::of(v, s, id));
            move |cd: f32, _: u32, x: i32, y: i32| {
                cd <= d - gap && plane.as_ref().is_none_or(|p| p.in_front(x, y, cd, gap))
            }
        },
    );
    apply(g, changes)
}

/// The slope-aware part of the occluded fill's test (see `passes::fill_occluded`): the
/// tangent plane of a candidate's point, turned to face the eye, against which a cell's
/// surface is placed at its pixel's centre and depth.
pub(crate) struct FillPlane {
    /// `coefficients(v, n, x)`.
    k: [f32; 4],
    /// 2 / width, 2 / height.
    step: [f32; 2],
    perspective: bool,
}

/// The tangent plane of a point x with normal n (facing the eye) as the occluded fill reads
/// it at pixel (i, j), depth z: with the pixel's NDC (u, v) = ((i + ½) 2 / w − 1,
/// 1 − (j + ½) 2 / h) and its ray `ViewParams::pixel_ray` (origin o, direction d), the
/// surface there lies `n · (o + d z) − n · x` in front of the plane, which is
/// `k3 + z (k2 + u k0 + v k1)` in perspective and `k3 + u k0 + v k1 + z k2` in orthographic
/// views, for k = (n · right / sx, n · up / sy, n · forward, n · eye − n · x). GPU twin:
/// fill_planes.wgsl writes the same four numbers, fill_occluded.wgsl reads them.
pub(crate) fn plane_coefficients(v: &ViewParams, n: Vec3, x: Vec3) -> [f32; 4] {
    [
        dot3(n, Vec3::from(v.right)) / v.sx,
        dot3(n, Vec3::from(v.up)) / v.sy,
        dot3(n, Vec3::from(v.forward)),
        dot3(n, Vec3::from(v.eye)) - dot3(n, x),
    ]
}

impl FillPlane {
    /// The plane of the point `id`, or None where it says nothing: a point seen edge-on (its
    /// plane holds the ray) or an id out of range.
    #[inline]
    pub(crate) fn of(v: &ViewParams, s: Surfaces<'_>, id: u32) -> Option<FillPlane> {
        let i = id as usize;
        let (x, n) = (*s.positions.get(i)?, *s.normals.get(i)?);
        let n = match Facing::of(v, x, n) {
            Facing::Front => n,
            Facing::Back => -n,
            Facing::Edge => return None,
        };
        Some(FillPlane {
            k: plane_coefficients(v, n, x),
            step: [2.0 / v.width as f32, 2.0 / v.height as f32],
            perspective: v.perspective == 1,
        })
    }

    /// Does the surface at depth `cd` in pixel (x, y) lie more than `gap` in front of the
    /// plane, along its normal?
    #[inline]
    pub(crate) fn in_front(&self, x: i32, y: i32, cd: f32, gap: f32) -> bool {
        let k = self.k;
        let u = (x as f32 + 0.5) * self.step[0] - 1.0;
        let v = 1.0 - (y as f32 + 0.5) * self.step[1];
        let off = if self.perspective {
            k[3] + cd * (k[2] + u * k[0] + v * k[1])
        } else {
            k[3] + u * k[0] + v * k[1] + cd * k[2]
        };
        off > gap
    }
}

/// One row's replaced pixels: (column, depth, id).
pub(crate) type RowChanges = Vec<(u32, f32, u32)>;

/// Writes each row's replacements into `g`; returns how many there were and where.
pub(crate) fn apply(g: &mut GBuffer, changes: Vec<RowChanges>) -> (u64, Changed) {
    let w = g.width as usize;
    if w == 0 {
        return (0, vec![None; g.height as usize]);
    }
    let where_: Changed = g
        .depth
        .par_chunks_mut(w)
        .zip(g.id.par_chunks_mut(w))
        .zip(changes.par_iter())
        .map(|((drow, irow), ch)| {
            for &(x, d, id) in ch {
                drow[x as usize] = d;
                irow[x as usize] = id;
            }
            // Rows list their changes left to right.
            Some((ch.first()?.0 as i32, ch.last()?.0 as i32))
        })
        .collect();
    let n = changes.iter().map(|c| c.len() as u64).sum();
    (n, where_)
}

/// The pixels a fill step replaces, per row (candidates: pixels where `candidate(depth,
/// id)` holds), testing only the columns of each row's span when `spans` is given (the
/// caller knows no mask can be blocked outside it).
///
/// The mask test reads up to 24 scattered cells; most candidates stop before it (see
/// [`Precheck`]). The background fill's coverage bits give the blocked masks exactly, from
/// 2r + 1 table lookups; the occluded fill's least depth over the window comes from a
/// separable minimum (the window's rows, then its columns: contiguous reads), and a
/// surface's own pixels, with no point d̃ nearer around them, stop there.
pub(crate) fn fill_changes<S: Fn(f32, u32, i32, i32) -> bool>(
    src: &GBuffer,
    radius: u32,
    spans: Option<&[Option<(i32, i32)>]>,
    candidate: impl Fn(f32, u32) -> bool + Sync,
    pre: Precheck,
    touch: impl Fn(u32) + Sync,
    solid: impl Fn(f32, u32) -> S + Sync,
) -> Vec<RowChanges> {
    let (w, h) = (src.width as i32, src.height as i32);
    let win = window(radius);
    let test = MaskTest { src, win: &win };
    let r = radius as i32;
    (0..h)
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new(), Vec::new()),
            |(column_min, window_min, batch), y| {
                let mut changed = RowChanges::new();
                let (x0, x1) = match spans {
                    Some(s) => match s[y as usize] {
                        Some((lo, hi)) => (lo.max(0), (hi + 1).min(w)),
                        None => return changed,
                    },
                    None => (0, w),
                };
                if x0 >= x1 {
                    return changed;
                }
                if let Precheck::Nearer { .. } = pre {
                    // Least depth of each column over the window's rows, for columns x0 − r ..
                    // x1 + r (+inf outside the image), then over each pixel's 2r + 1 columns.
                    let (c0, c1) = ((x0 - r).max(0), (x1 + r).min(w));
                    column_min.clear();
                    column_min.resize((c0 - (x0 - r)) as usize, f32::INFINITY);
                    column_min.extend_from_slice(
                        &src.depth[(y * w + c0) as usize..(y * w + c1) as usize],
                    );
                    column_min.resize((x1 - x0 + 2 * r) as usize, f32::INFINITY);
                    let start = (c0 - (x0 - r)) as usize;
                    for yy in (y - r).max(0)..=(y + r).min(h - 1) {
                        if yy == y {
                            continue;
                        }
                        let other = &src.depth[(yy * w + c0) as usize..(yy * w + c1) as usize];
                        for (m, &d) in column_min[start..].iter_mut().zip(other) {
                            *m = m.min(d);
                        }
                    }
                    window_min.clear();
                    window_min.extend_from_slice(&column_min[..(x1 - x0) as usize]);
                    for o in 1..=(2 * r) as usize {
                        for (m, &c) in window_min.iter_mut().zip(&column_min[o..]) {
                            *m = m.min(c);
                        }
                    }
                }
                for x in x0..x1 {
                    let k = (y * w + x) as usize;
                    let (d, id) = (src.depth[k], src.id[k]);
                    if !candidate(d, id) {
                        continue;
                    }
                    let known = match &pre {
                        Precheck::Coverage(c) => {
                            if c.blocked(x, y, h) != 0xFF {
                                continue;
                            }
                            0xFF
                        }
                        Precheck::Nearer { gap, rows, exact } => {
                            // The window's least depth includes the pixel's own, which is
                            // never solid for a positive gap.
                            let t = d - gap;
                            let reach = window_min[(x - x0) as usize] <= t;
                            if !reach {
                                continue;
                            }
                            match rows {
                                Some(rows) => {
                                    if rows.blocked(src, x, y, |cd| cd <= t) != 0xFF {
                                        continue;
                                    }
                                    if *exact {
                                        0xFF
                                    } else {
                                        0
                                    }
                                }
                                None => 0,
                            }
                        }
                        Precheck::None => 0,
                    };
                    // The row's tests come after its prechecks: `solid(d, id)` may read the
                    // pixel's point (the occluded fill's plane), which is asked for now, so
                    // that it arrives while the rest of the row is prechecked; reads that do
                    // not wait on each other overlap (one candidate at a time, they took a
                    // third of the occluded fill's time).
                    touch(id);
                    batch.push((x, known));
                }
                let tests: Vec<S> = batch
                    .iter()
                    .map(|&(x, _)| {
                        let k = (y * w + x) as usize;
                        solid(src.depth[k], src.id[k])
                    })
                    .collect();
                for (&(x, known), s) in batch.iter().zip(tests) {
                    if let Some((nd, nid)) = test.fill(x, y, known, s) {
                        changed.push((x as u32, nd, nid));
                    }
                }
                batch.clear();
                changed
            },
        )
        .collect()
}

/// The shared mask test over the window `win` of an image `src`: cells for which
/// `solid(depth, id)` holds block the masks they belong to (cells outside the image never
/// do).
pub(crate) struct MaskTest<'a> {
    pub src: &'a GBuffer,
    pub win: &'a [(i32, i32, u8)],
}

impl MaskTest<'_> {
    /// At pixel (x, y): when all eight masks are blocked, the solid cell of minimum (depth,
    /// id) on the nearest ring that has one; otherwise None (a border pixel). `known`: masks
    /// already known to be blocked (0xFF when the caller has established that all are: the
    /// scan then stops after the first ring holding a solid cell).
    #[inline]
    pub(crate) fn fill(
        &self,
        x: i32,
        y: i32,
        known: u8,
        solid: impl Fn(f32, u32, i32, i32) -> bool,
    ) -> Option<(f32, u32)> {
        let (w, h) = (self.src.width as i32, self.src.height as i32);
        let r = self.win.last().map_or(0, |c| c.1.abs().max(c.0.abs()));
        if x >= r && y >= r && x < w - r && y < h - r {
            self.fill_in::<false>(x, y, known, solid)
        } else {
            self.fill_in::<true>(x, y, known, solid)
        }
    }

    #[inline(always)]
    fn fill_in<const CHECK: bool>(
        &self,
        x: i32,
        y: i32,
        known: u8,
        solid: impl Fn(f32, u32, i32, i32) -> bool,
    ) -> Option<(f32, u32)> {
        let (src, win) = (self.src, self.win);
        let (w, h) = (src.width as i32, src.height as i32);
        let mut blocked = known;
        let mut best = (f32::INFINITY, BACKGROUND);
        let mut best_ring = i32::MAX;
        for &(dx, dy, m) in win {
            let ring = dx.abs().max(dy.abs());
            // Cells come ring by ring: once every mask is blocked, a farther ring cannot win.
            if blocked == 0xFF && best_ring < ring {
                break;
            }
            let (nx, ny) = (x + dx, y + dy);
            if CHECK && (nx < 0 || ny < 0 || nx >= w || ny >= h) {
                continue;
            }
            let n = (ny * w + nx) as usize;
            let (nd, nid) = (src.depth[n], src.id[n]);
            if !solid(nd, nid, nx, ny) {
                continue;
            }
            blocked |= m;
            if ring < best_ring
                || (ring == best_ring && (nd < best.0 || (nd == best.0 && nid < best.1)))
            {
                best = (nd, nid);
                best_ring = ring;
            }
        }
        (blocked == 0xFF).then_some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::passes::fill_background::cpu::{fill_background, fill_background_step};
    use crate::passes::fill_occluded::cpu::{fill_occluded, fill_occluded_step};

    /// Random G-buffers: 5% to 90% of the pixels covered, depths 1 to 9.
    fn random_gbuffer(w: u32, h: u32, seed: u64) -> GBuffer {
        let mut x = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = move || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 33) as u32
        };
        let density = 5 + next() % 86;
        let mut g = GBuffer::new(w, h);
        for k in 0..(w * h) as usize {
            if next() % 100 < density {
                g.id[k] = next() % 1000;
                g.depth[k] = 1.0 + (next() % 64) as f32 / 8.0;
            }
        }
        g
    }

    /// The mask test on every candidate, with no precheck: what the fills must equal.
    fn reference(
        src: &GBuffer,
        radius: u32,
        candidate: impl Fn(f32, u32) -> bool,
        solid: impl Fn(f32, f32, u32) -> bool,
    ) -> GBuffer {
        let (w, h) = (src.width as i32, src.height as i32);
        let win = window(radius);
        let test = MaskTest { src, win: &win };
        let mut out = src.clone();
        for y in 0..h {
            for x in 0..w {
                let k = (y * w + x) as usize;
                let d = src.depth[k];
                if !candidate(d, src.id[k]) {
                    continue;
                }
                if let Some((nd, nid)) = test.fill(x, y, 0, |cd, cid, _, _| solid(d, cd, cid)) {
                    out.depth[k] = nd;
                    out.id[k] = nid;
                }
            }
        }
        out
    }

    /// The prechecks (coverage bits for the background fill, the window's least depth for
    /// the occluded fill) skip only pixels the mask test would keep: both fills equal the
    /// plain mask test on every pixel, for every radius, at image borders and across the
    /// 64-bit words of the coverage rows.
    #[test]
    fn the_prechecks_change_no_pixel() {
        let sizes = [
            (1, 1),
            (2, 7),
            (5, 5),
            (37, 23),
            (64, 3),
            (65, 9),
            (130, 6),
            (200, 2),
        ];
        for (i, &(w, h)) in sizes.iter().enumerate() {
            for seed in 0..6u64 {
                let g = random_gbuffer(w, h, seed * 31 + i as u64);
                for radius in 1..=crate::masks::MAX_RADIUS {
                    let mut out = GBuffer::new(w, h);
                    let n = fill_background(&g, &mut out, radius);
                    let want =
                        reference(&g, radius, |_, id| !is_point(id), |_, _, id| is_point(id));
                    assert_eq!(out, want, "background {w}x{h} seed {seed} radius {radius}");
                    let filled = (0..g.id.len()).filter(|&k| g.id[k] != want.id[k]).count();
                    assert_eq!(n as usize, filled);
                    for gap in [0.0, 0.5, 2.0] {
                        let n = fill_occluded(&g, &mut out, gap, radius);
                        let want =
                            reference(&g, radius, |_, id| is_point(id), |d, cd, _| cd <= d - gap);
                        assert_eq!(
                            out, want,
                            "occluded {w}x{h} seed {seed} r {radius} gap {gap}"
                        );
                        let replaced = (0..g.id.len())
                            .filter(|&k| (g.id[k], g.depth[k]) != (want.id[k], want.depth[k]))
                            .count();
                        assert!(n as usize >= replaced);
                    }
                    // Later steps look only near the previous step's changes: four steps
                    // equal four plain Jacobi steps.
                    let (mut cur, mut want) = (g.clone(), g.clone());
                    let mut since = None;
                    for step in 0..4 {
                        let (_, c) = fill_background_step(&mut cur, radius, since.as_ref());
                        since = Some(c);
                        want = reference(
                            &want,
                            radius,
                            |_, id| !is_point(id),
                            |_, _, id| is_point(id),
                        );
                        assert_eq!(
                            cur, want,
                            "background {w}x{h} seed {seed} r {radius} step {step}"
                        );
                    }
                    let (mut cur, mut want) = (g.clone(), g.clone());
                    let mut since = None;
                    for step in 0..4 {
                        let (_, c) =
                            fill_occluded_step(&mut cur, 0.5, radius, since.as_ref(), None);
                        since = Some(c);
                        want = reference(
                            &want,
                            radius,
                            |_, id| is_point(id),
                            |d, cd, _| cd <= d - 0.5,
                        );
                        assert_eq!(
                            cur, want,
                            "occluded {w}x{h} seed {seed} r {radius} step {step}"
                        );
                    }
                }
            }
        }
    }
}
