//! # Projection (Dobrev §3.1): nearest point wins each pixel
//!
//! How it works: every point is transformed to view space, culled against the near/far range,
//! the image and (where normals exist) its back face, and written into a visibility buffer as
//! one 64-bit key `(depth bits << 32) | point index` with an atomic minimum. Positive f32
//! depths order like their bit patterns, so the minimum key is the nearest point and, among
//! equal depths, the smaller index: the frame is deterministic on any number of threads and
//! on the GPU twin, which uses the same key. A plain load before the atomic skips most
//! writes once the buffer fills (the early-out of compute rasterizers).
//!
//! On the CPU, with few threads, each thread owns a private (non-atomic) visibility buffer for
//! a contiguous share of the points, and one merge pass takes the per-pixel minimum and
//! unpacks it ([`project_private`]): no locked instructions in the hot loop. The minimum of
//! keys does not depend on the split, so the result is identical to the atomic version
//! ([`project`], the shape of the GPU kernel, used with many threads).
//!
//! Depth peeling (Dobrev §4–5, the `peel` argument): a later layer keeps only the points
//! farther than the previous layer's reference depth at their pixel plus d̃, so points of the
//! same surface layer that share a pixel (Fig. 11) are not peeled as layers of their own.
//!
//! Deviation from the paper (the reference): Dobrev compares with the previous layer's depth
//! at the pixel, plus d̃. That one depth fails in two ways (issue "Depth-peeled transparency
//! without blotches"). Where the layer is sloped, or where the fills closed a hole of it with
//! a nearer neighbour's depth, points of the same surface lie farther than that depth plus d̃
//! and come back as a layer of their own: on a transparent sphere a third and fourth
//! "sphere" layer fill a wide ring, and on a torus seen obliquely the grazing bands near its
//! silhouettes turn to speckle. Near a silhouette, the two crossings of a ray through a tube
//! are also closer than d̃ in depth, so a larger gap would merge them. Dobrev's shadow pass
//! scales d̃ by 1 / ⟨v, n⟩ (§6, Fig. 14): the layer's thickness is measured along the surface
//! normal, not the ray. The test here does the same exactly, per pixel, and adds the side:
//!
//! * [`peel_planes`] keeps, per pixel, the tangent plane of the point the layer shows there
//!   (after the fills, so a filled hole carries its neighbour's plane).
//! * [`PeelTest::peeled`]: a point at or in front of the layer's own depth at its pixel was
//!   peeled. A point whose normal faces the eye when the plane's does not (or the reverse) is
//!   on the other side of the surface, a new layer however close (the two crossings near a
//!   silhouette; the two sides of a thin sheet). A point facing the same way was peeled when it
//!   lies at most d̃ behind the plane (measured along the normal: the slope-scaled gap of
//!   Fig. 14, without the reference point's own depth error), within [`PEEL_SLOPE_CAP`] d̃ of
//!   the layer's depth (Dobrev's cap of the slope factor), of the plane at its pixel or of
//!   any of the 8 neighbours' planes that face the same way. The neighbours matter where a
//!   curved surface is seen at a grazing angle: a pixel then spans more of the surface than
//!   its one tangent plane follows within d̃, and the band of a tube just inside its
//!   silhouette came back as one more layer in dotted lines (seen through another surface in
//!   `examples/nested-tori.toml`). A neighbour counts only where the layer's own surface at
//!   the pixel lies within [`PEEL_NEIGHBOUR_GAPS`] d̃ of its plane: otherwise a single
//!   pixel of a deeper surface left in the layer (a speck) peeled that surface over its
//!   whole 3×3 neighbourhood, which turned specks into blotches where points are dense.
//!   Only grazing points (normal more than 60° from the ray, [`GRAZING_COS2`]) are tested
//!   so: elsewhere a pixel spans too little of the surface for its curvature to matter,
//!   and the eight reads cost every deeper point of a frame (nested-tori at 512²: 248 →
//!   219 ms a frame, the same errors below).
//!   With them the oblique torus errs by 0.65, 0.41 and 0.80 levels at 0.50, 0.83 and
//!   1.32 px between points, where the pixel's plane alone gave 0.68, 0.58 and 0.95.
//! * A point seen edge-on (normal within 6° of perpendicular to the ray, [`Facing::Edge`])
//!   starts no layer behind a pixel the layer covers: it lies on a silhouette's rim, where
//!   the front and back of a surface meet and the sign of ⟨v, n⟩ is noise. Tested by
//!   facing alone, such points came back behind filled pixels as lone specks, which the
//!   fills grew into dark dashes along the tubes' silhouettes of `examples/nested-tori.toml`
//!   at 1024².
//! * A point peeled once stays peeled ([`PeelTest::done`], one bit per point, on both
//!   backends): later layers skip it without projecting it. The test compares with the
//!   previous layer only, and a layer is not deeper than the one before it everywhere (the
//!   fills give a hole its neighbour's nearer depth), so without the bit a point judged part
//!   of one layer could be judged a layer of its own later. The deep layers of a frame,
//!   where most points were peeled before, cost half as much.
//! * The fills feed this test: a layer's hole filled by the occluded fill carries the plane of
//!   the neighbour that filled it. Where a tube is seen at a grazing angle that fill compared
//!   depths alone and replaced the layer's own points by a nearer surface's, which then came
//!   back one layer late (the dark blotches of `examples/nested-tori.toml`'s middle torus
//!   at 512²); it now compares with the pixel's tangent plane (see
//!   [`crate::passes::fill_occluded`]).
//! * Nothing is peeled behind a pixel the layer left empty (Dobrev's rule: a hole of a layer
//!   is filled or stays a hole). Without normals the reference is the largest depth of the
//!   layer over the pixel's 3×3 neighbourhood, counting neighbours at most 4 d̃ behind
//!   the pixel's own depth ([`peel_reference`]; a neighbour farther back belongs to another
//!   surface), plus d̃.
//!
//! Measured with `examples/peel_quality.rs` (a sphere of opacity 0.5 over a plane, interior)
//! and `examples/peel_rims.rs` (a torus of opacity 0.5 seen obliquely, every pixel but 2 px
//! around changes of the number of crossings), together with fills sized to each layer's
//! spacing ([`crate::pipeline::peel_fill_iterations`]): the torus's mean error to the analytic
//! composite drops from 3.2–11.9 levels (10–29% of its pixels off by more than 12) to
//! 0.4–0.9 levels (0.2–2.4%, all at the silhouettes) at 0.33–1.32 px between points, and the
//! sphere's interior from up to 4.5 levels to 0.00.
//!
//! Deviation from the paper: points are lit after visibility is resolved (in `shade`), not
//! before projection. The lit colour of the winning point is the same, and only visible
//! points pay for lighting.

use crate::gbuffer::{GBuffer, BACKGROUND};
use crate::params::ViewParams;
use crate::passes::{prefetch, prefetch_at, PREFETCH_AHEAD};
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

pub const EMPTY_KEY: u64 = u64::MAX;

/// The visibility key of a point at view depth `depth` (> 0) with index `index`.
#[inline]
pub fn key(depth: f32, index: u32) -> u64 {
    ((depth.to_bits() as u64) << 32) | index as u64
}

/// Maps a local position to (pixel index, view depth), or None when culled by the view
/// volume. Written to read the same as the shader.
#[inline(always)]
pub fn project_point(v: &ViewParams, p: Vec3) -> Option<(usize, f32)> {
    let d = p - Vec3::from(v.eye);
    let z = d.dot(Vec3::from(v.forward));
    if !(z >= v.near && z <= v.far) {
        return None;
    }
    let x = d.dot(Vec3::from(v.right));
    let y = d.dot(Vec3::from(v.up));
    let (nx, ny) = if v.perspective == 1 {
        let iz = 1.0 / z;
        (x * v.sx * iz, y * v.sy * iz)
    } else {
        (x * v.sx, y * v.sy)
    };
    let fx = (nx + 1.0) * 0.5 * v.width as f32;
    let fy = (1.0 - ny) * 0.5 * v.height as f32;
    if !(fx >= 0.0 && fx < v.width as f32 && fy >= 0.0 && fy < v.height as f32) {
        return None;
    }
    Some((fy as usize * v.width as usize + fx as usize, z))
}

/// Is the point's normal turned away from the eye?
#[inline(always)]
pub fn back_facing(v: &ViewParams, p: Vec3, n: Vec3) -> bool {
    n.dot(to_point(v, p)) > 0.0
}

/// The direction of the ray from the eye to the point at `p` (not normalised).
#[inline(always)]
fn to_point(v: &ViewParams, p: Vec3) -> Vec3 {
    if v.perspective == 1 {
        p - Vec3::from(v.eye)
    } else {
        Vec3::from(v.forward)
    }
}

/// Points per parallel task.
const BATCH: usize = 1 << 15;

/// How far a neighbour's surface may be from a pixel's and still count for the next peeled
/// layer's test, in layer gaps d̃ (see the module documentation): behind the pixel's own
/// depth, for the reference without normals; from the neighbour's tangent plane, for the
/// plane test.
pub const PEEL_NEIGHBOUR_GAPS: f32 = 4.0;

/// The reference depth of the next peeled layer from a layer's surface depth `surface`
/// (`w`×`h`, +inf where it shows nothing): per pixel the largest finite depth of its 3×3
/// neighbourhood that lies at most `bound` (= [`PEEL_NEIGHBOUR_GAPS`] d̃) behind the pixel's
/// own; +inf stays +inf (nothing lies behind an empty pixel).
pub fn peel_reference(w: usize, h: usize, surface: &[f32], bound: f32, out: &mut [f32]) {
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let d0 = surface[y * w + x];
            let mut m = d0;
            if d0.is_finite() {
                let limit = d0 + bound;
                for yy in y.saturating_sub(1)..(y + 2).min(h) {
                    for xx in x.saturating_sub(1)..(x + 2).min(w) {
                        let d = surface[yy * w + xx];
                        if d.is_finite() && d > m && d <= limit {
                            m = d;
                        }
                    }
                }
            }
            *o = m;
        }
    });
}

/// The tangent planes of a peeled layer (see [`peel_planes`]): per pixel the normal of the
/// layer's point there and its offset `n · x`; NaN offset where the layer shows nothing or
/// the cloud has no normals.
pub type Plane = [f32; 4];

/// Per pixel, the tangent plane of the point a layer shows there (`id`, where its surface
/// depth `surface` is finite), for the next layer's same-surface test (see the module
/// documentation).
pub fn peel_planes(
    id: &[u32],
    surface: &[f32],
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    out: &mut [Plane],
) {
    const ROWS: usize = 4096;
    out.par_chunks_mut(ROWS)
        .zip(id.par_chunks(ROWS).zip(surface.par_chunks(ROWS)))
        .for_each(|(o, (id, surface))| {
            for (k, (o, (&i, d))) in o.iter_mut().zip(id.iter().zip(surface)).enumerate() {
                // The points of pixels a few ahead are asked for now: their reads overlap
                // this pixel's.
                if let (Some(&j), Some(n)) = (id.get(k + PREFETCH_AHEAD), normals) {
                    prefetch(positions, j);
                    prefetch(n, j);
                }
                *o = match normals {
                    Some(n) if d.is_finite() && (i as usize) < positions.len() => {
                        let (n, x) = (n[i as usize], positions[i as usize]);
                        [n.x, n.y, n.z, dot3(n, x)]
                    }
                    _ => [0.0, 0.0, 0.0, f32::NAN],
                };
            }
        });
}

/// The dot product in the shaders' order of operations.
#[inline(always)]
pub(crate) fn dot3(a: Vec3, b: Vec3) -> f32 {
    a.x * b.x + a.y * b.y + a.z * b.z
}

/// What a later peeled layer compares its points with: with normals, the previous layer's
/// own depth (`own`), its tangent planes and the cloud's normals (`planes`); without, its
/// reference depth (`reference`, from [`peel_reference`]); and d̃ (`gap`).
#[derive(Clone, Copy)]
pub struct PeelTest<'a> {
    pub reference: &'a [f32],
    pub own: &'a [f32],
    pub planes: Option<(&'a [Plane], &'a [Vec3])>,
    pub gap: f32,
    /// One bit per point of the cloud (bit i % 64 of word i / 64), set when a layer's test
    /// peels the point: a point peeled once stays peeled, and later layers skip it without
    /// projecting it (see the module documentation). None: no memory between layers.
    pub done: Option<&'a [AtomicU64]>,
}

/// The most a plane test reaches behind the previous layer's own depth, in d̃ (Dobrev's
/// cap of the slope factor, §6).
pub const PEEL_SLOPE_CAP: f32 = 16.0;

impl PeelTest<'_> {
    /// Does the point `index` at `p`, depth `z` in pixel `pix`, belong to a layer already
    /// peeled?
    #[inline(always)]
    pub fn peeled(&self, v: &ViewParams, pix: usize, p: Vec3, z: f32, index: usize) -> bool {
        let depth = self.depth(pix);
        self.by_depth(z, depth)
            .unwrap_or_else(|| self.by_plane(v, pix, p, z, index, depth, self.plane(pix)))
    }

    /// The depth a test compares with first at `pix`: the previous layer's own depth with
    /// planes, its reference depth without.
    #[inline(always)]
    fn depth(&self, pix: usize) -> f32 {
        match self.planes {
            Some(_) => self.own[pix],
            None => self.reference[pix],
        }
    }

    /// Asks for the depth [`PeelTest::depth`] will read at `pix`.
    #[inline(always)]
    fn depth_ahead(&self, pix: usize) {
        match self.planes {
            Some(_) => prefetch(self.own, pix as u32),
            None => prefetch(self.reference, pix as u32),
        }
    }

    /// Asks for the plane [`PeelTest::plane`] will read at `pix`.
    #[inline(always)]
    fn plane_ahead(&self, pix: usize) {
        if let Some((planes, _)) = self.planes {
            prefetch(planes, pix as u32);
        }
    }

    /// The previous layer's plane at `pix` (none without normals).
    #[inline(always)]
    fn plane(&self, pix: usize) -> Plane {
        match self.planes {
            Some((planes, _)) => planes[pix],
            None => [0.0, 0.0, 0.0, f32::NAN],
        }
    }

    /// What the depth alone decides: `Some(peeled)`, or `None` when the plane must be read
    /// ([`PeelTest::by_plane`]; only with planes).
    #[inline(always)]
    fn by_depth(&self, z: f32, depth: f32) -> Option<bool> {
        match self.planes {
            // Also where the layer left the pixel empty (+inf): nothing lies behind it.
            Some(_) => (z <= depth).then_some(true),
            None => Some(z <= depth + self.gap),
        }
    }

    /// The rest of [`PeelTest::peeled`] where the depth did not decide: the previous layer's
    /// depth `d0` and plane `c` at `pix`, as [`PeelTest::depth`] and [`PeelTest::plane`] read
    /// them (the peeled projection reads them a batch of points at a time).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn by_plane(
        &self,
        v: &ViewParams,
        pix: usize,
        p: Vec3,
        z: f32,
        index: usize,
        d0: f32,
        c: Plane,
    ) -> bool {
        if let Some((planes, normals)) = self.planes {
            if !c[3].is_finite() {
                return false;
            }
            // A point facing the other way from the layer's point here is a new layer
            // however close (unless either is edge-on: see `Facing`). (The ray and its
            // squared length are shared by the facings below: `Facing::of`'s arithmetic.)
            let n = normals[index];
            let ray = to_point(v, p);
            let rr = dot3(ray, ray);
            let facing = |m: Vec3| Facing::of_cos(dot3(m, ray), dot3(m, m), rr);
            let own = facing(n);
            // An edge-on point behind a pixel the layer covers starts no layer of its own
            // (see `Facing::Edge`).
            if own == Facing::Edge {
                return true;
            }
            let facing_here = facing(Vec3::new(c[0], c[1], c[2]));
            if own.opposes(facing_here) {
                return false;
            }
            // On the tangent plane of the layer's point at pixel q, facing the same way:
            // at most d̃ behind it, along its normal (Fig. 14's slope-scaled gap, exactly),
            // and at most 16 d̃ behind the point's depth.
            let on_plane_with = |pl: Plane, depth: f32, known: Option<Facing>| {
                if !pl[3].is_finite() {
                    return false;
                }
                let m = Vec3::new(pl[0], pl[1], pl[2]);
                let facing = known.unwrap_or_else(|| facing(m));
                if own.opposes(facing) {
                    return false;
                }
                // Distance behind the plane, away from the eye (from an edge-on plane,
                // either side).
                let off = dot3(m, p) - pl[3];
                let behind = match facing {
                    Facing::Front => -off,
                    Facing::Back => off,
                    Facing::Edge => off.abs(),
                };
                behind <= self.gap && z <= depth + PEEL_SLOPE_CAP * self.gap
            };
            let on_plane = |q: usize| on_plane_with(planes[q], self.own[q], None);
            if on_plane_with(c, d0, Some(facing_here)) {
                return true;
            }
            // Or on a neighbour's plane: a curved surface seen at a grazing angle spreads
            // over a pixel farther than its tangent plane there follows it. A neighbour
            // counts only when the layer's surface here (the point on the ray through p at
            // the layer's depth) lies within 4 d̃ of its plane: a speck of a deeper surface
            // in the layer must not peel that surface around it. Only grazing points are
            // tested so (a point whose normal is within 60° of the ray sees the curvature
            // of less than a pixel): the others skip the eight reads.
            let c = dot3(n, ray);
            if c * c > GRAZING_COS2 * dot3(n, n) * rr {
                return false;
            }
            let here = if v.perspective == 1 {
                let eye = Vec3::from(v.eye);
                eye + (p - eye) * (d0 / z)
            } else {
                p - Vec3::from(v.forward) * (z - d0)
            };
            let (w, h) = (v.width as usize, v.height as usize);
            let (x, y) = (pix % w, pix / w);
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    let q = yy * w + xx;
                    if q == pix {
                        continue;
                    }
                    let pl = planes[q];
                    let m = Vec3::new(pl[0], pl[1], pl[2]);
                    if (dot3(m, here) - pl[3]).abs() <= PEEL_NEIGHBOUR_GAPS * self.gap
                        && on_plane(q)
                    {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// Which way a normal turns relative to the ray from the eye to its point.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Facing {
    Front,
    Back,
    /// Within [`EDGE_COS2`] of perpendicular to the ray: a point on a silhouette's rim,
    /// where the front and the back of a surface meet and the sign of ⟨v, n⟩ is noise. Such
    /// a point starts no later layer where the previous layer covers its pixel (it is the
    /// rim of a surface that layer already shows, or of one whose crossings merge there);
    /// an edge-on plane is compared with on either side (|n · p − offset| ≤ d̃), and the
    /// facing rule separates nothing from it.
    Edge,
}

impl Facing {
    /// The facing of a normal `n` at a point `p`.
    #[inline(always)]
    pub fn of(v: &ViewParams, p: Vec3, n: Vec3) -> Facing {
        let ray = to_point(v, p);
        Facing::of_cos(dot3(n, ray), dot3(n, n), dot3(ray, ray))
    }

    /// The facing of a normal n from `c` = n · ray, `nn` = n · n and `rr` = ray · ray (the
    /// ray to its point, as [`Facing::of`] takes it).
    #[inline(always)]
    fn of_cos(c: f32, nn: f32, rr: f32) -> Facing {
        if c * c < EDGE_COS2 * nn * rr {
            Facing::Edge
        } else if c > 0.0 {
            Facing::Back
        } else {
            Facing::Front
        }
    }

    /// Do the two face opposite ways (neither edge-on)?
    #[inline(always)]
    fn opposes(self, other: Facing) -> bool {
        matches!(
            (self, other),
            (Facing::Front, Facing::Back) | (Facing::Back, Facing::Front)
        )
    }
}

/// Normals within this squared cosine of perpendicular to the view ray are edge-on
/// ([`Facing::Edge`]): cos² 84.3°. Measured on `examples/nested-tori.toml` at 1024²: a
/// point on a tube's silhouette whose normal made cos −0.005 with the ray was peeled with
/// the front surface, then came back as a third layer behind a filled pixel whose plane
/// made cos 0.001 ("facing the other way", though 0.03 d̃ from that plane), and rim points
/// 0.1 behind a pixel that the occluded fill had given a nearer neighbour's depth came back
/// as a layer of their own; the fills grew such lone points into dark dashes along every
/// silhouette. Where the rim projects, this band is under half a pixel wide: a later layer's
/// silhouette loses no more than that. The oblique torus (`examples/peel_rims.rs`) errs by
/// 0.66, 0.37, 0.34 and 0.37 levels at 0.33, 0.50, 0.66 and 0.99 px (was 0.91, 0.43, 0.50
/// and 0.58); the sphere is unchanged.
pub const EDGE_COS2: f32 = 0.01;

/// Points whose normal makes a squared cosine above this with the view ray are not
/// tested against the neighbours' tangent planes (see [`PeelTest::peeled`]): cos² 60°.
pub const GRAZING_COS2: f32 = 0.25;

/// A peel test, or none for the first layer.
pub type Peel<'a> = Option<PeelTest<'a>>;

/// Projects `positions` into `vis` (length width × height, reset to [`EMPTY_KEY`] by the
/// caller). Returns the number of points that passed culling.
pub fn project(
    v: &ViewParams,
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    cull_backfaces: bool,
    peel: Peel,
    vis: &[AtomicU64],
) -> u64 {
    assert_eq!(vis.len(), v.pixels());
    let normals = normals.filter(|_| cull_backfaces);
    positions
        .par_chunks(BATCH)
        .enumerate()
        .map(|(b, chunk)| {
            let ahead = |pix: usize| prefetch(vis, pix as u32);
            project_range(v, chunk, normals, peel, b * BATCH, ahead, |pix, key| {
                let slot = &vis[pix];
                if key < slot.load(Ordering::Relaxed) {
                    slot.fetch_min(key, Ordering::Relaxed);
                }
            })
        })
        .sum()
}

/// The per-point loop shared by both strategies: calls `write(pixel, key)` for every point of
/// `positions` (indices from `base`) that survives culling; returns how many did. The first
/// layer's loop carries none of the peel test's code.
#[inline(always)]
fn project_range(
    v: &ViewParams,
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    peel: Peel,
    base: usize,
    ahead: impl Fn(usize),
    write: impl FnMut(usize, u64),
) -> u64 {
    match peel {
        None => project_loop(v, positions, normals, base, ahead, write),
        Some(t) => project_peeled(v, positions, normals, base, t, ahead, write),
    }
}

/// [`project_loop`] with a peel test, a batch of 64 points at a time, in four sweeps: the
/// points are projected and the depths at their pixels asked for (`depth_ahead`); the
/// depths are read and the points the depth decides are dropped, while the others ask for
/// their planes and the slots they may write; the planes are read; then those points are
/// tested. The reads land at pixels in the points' order, mostly outside the caches, and
/// the reads of a sweep are independent, so they overlap: read one point at a time, each
/// test waited for its own, and the peeled projections of the Dragon at 512² took 6.7 ms
/// where three sweeps took 5.0 ms (the first layer's, with no test, 2.5 ms); asking ahead
/// took the Dragon's second and third layers at 1024² from 11.3–12.9 and 10.2–11.0 ms to
/// 8.6–9.1 and 7.4–7.6 ms. Reading a plane only where the depth does not decide keeps deep
/// layers, where most points are peeled, from reading planes they never use.
#[inline(always)]
fn project_peeled(
    v: &ViewParams,
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    base: usize,
    t: PeelTest,
    ahead: impl Fn(usize),
    mut write: impl FnMut(usize, u64),
) -> u64 {
    const N: usize = 64;
    let mut kept = 0;
    // (pixel, depth, index in the chunk, the previous layer's depth and plane there)
    let mut batch = [(0usize, 0f32, 0usize, 0f32, [0f32; 4]); N];
    // (pixel, depth, index in the chunk) of the points in view
    let mut seen = [(0usize, 0f32, 0usize); N];
    let mark = |i: usize| {
        if let Some(d) = t.done {
            d[i / 64].fetch_or(1 << (i % 64), Ordering::Relaxed);
        }
    };
    for (c, chunk) in positions.chunks(N).enumerate() {
        let mut n = 0;
        // Points already peeled by an earlier layer.
        let first = base + c * N;
        let skip = |k: usize| {
            t.done.is_some_and(|d| {
                let i = first + k;
                d[i / 64].load(Ordering::Relaxed) & (1 << (i % 64)) != 0
            })
        };
        // The points in view, whose depths at their pixels are asked for.
        let mut m = 0;
        for (k, &p) in chunk.iter().enumerate() {
            if skip(k) {
                continue;
            }
            let Some((pix, z)) = project_point(v, p) else {
                continue;
            };
            t.depth_ahead(pix);
            seen[m] = (pix, z, k);
            m += 1;
        }
        for &(pix, z, k) in &seen[..m] {
            let p = chunk[k];
            let depth = t.depth(pix);
            match t.by_depth(z, depth) {
                Some(true) => mark(first + k),
                Some(false) => kept += emit(v, normals, p, pix, z, first + k, &mut write),
                None => {
                    // The plane it will be tested with, and the slot it may write.
                    t.plane_ahead(pix);
                    ahead(pix);
                    batch[n] = (pix, z, k, depth, [0.0; 4]);
                    n += 1;
                }
            }
        }
        for (pix, _, _, _, plane) in &mut batch[..n] {
            *plane = t.plane(*pix);
        }
        for &(pix, z, k, depth, plane) in &batch[..n] {
            let (p, index) = (chunk[k], first + k);
            if t.by_plane(v, pix, p, z, index, depth, plane) {
                mark(index);
            } else {
                kept += emit(v, normals, p, pix, z, index, &mut write);
            }
        }
    }
    kept
}

/// Writes the key of a point that passed the view and peel tests, unless culling (`normals`
/// given) finds it back-facing; returns 1 if written, else 0.
#[inline(always)]
fn emit(
    v: &ViewParams,
    normals: Option<&[Vec3]>,
    p: Vec3,
    pix: usize,
    z: f32,
    index: usize,
    write: &mut impl FnMut(usize, u64),
) -> u64 {
    if culled(v, normals, p, index) {
        return 0;
    }
    write(pix, key(z, index as u32));
    1
}

/// Does culling (`normals` given) find the point `index` at `p` back-facing?
#[inline(always)]
fn culled(v: &ViewParams, normals: Option<&[Vec3]>, p: Vec3, index: usize) -> bool {
    normals.is_some_and(|n| back_facing(v, p, n[index]))
}

/// The first layer's loop, 32 points at a time: the pixels of a batch's visible points are
/// found and their slots asked for (`ahead`), then the keys are written, so that the
/// scattered writes' cache misses overlap (the Dragon's first layer at 1024²: 9.4–9.8 →
/// 5.9–6.2 ms).
#[inline(always)]
fn project_loop(
    v: &ViewParams,
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    base: usize,
    ahead: impl Fn(usize),
    mut write: impl FnMut(usize, u64),
) -> u64 {
    const N: usize = 32;
    let mut kept = 0;
    let mut batch = [(0usize, 0u64); N];
    for (c, chunk) in positions.chunks(N).enumerate() {
        let mut n = 0;
        for (k, &p) in chunk.iter().enumerate() {
            let Some((pix, z)) = project_point(v, p) else {
                continue;
            };
            let index = base + c * N + k;
            if culled(v, normals, p, index) {
                continue;
            }
            ahead(pix);
            batch[n] = (pix, key(z, index as u32));
            n += 1;
        }
        for &(pix, key) in &batch[..n] {
            write(pix, key);
        }
        kept += n as u64;
    }
    kept
}

/// Projects with one private visibility buffer per share of the points (`bufs.len()`
/// shares), then merges the buffers into the G-buffer. Returns the points kept.
pub fn project_private(
    v: &ViewParams,
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    cull_backfaces: bool,
    peel: Peel,
    bufs: &mut [Vec<u64>],
    g: &mut GBuffer,
) -> u64 {
    let normals = normals.filter(|_| cull_backfaces);
    let shares = bufs.len().max(1);
    let per = positions.len().div_ceil(shares).max(1);
    let kept: u64 = bufs
        .par_iter_mut()
        .enumerate()
        .map(|(s, buf)| {
            buf.clear();
            buf.resize(v.pixels(), EMPTY_KEY);
            let lo = (s * per).min(positions.len());
            let hi = ((s + 1) * per).min(positions.len());
            let slots = buf.as_ptr();
            let ahead = |pix: usize| prefetch_at(slots.wrapping_add(pix));
            project_range(
                v,
                &positions[lo..hi],
                normals,
                peel,
                lo,
                ahead,
                |pix, key| {
                    let slot = &mut buf[pix];
                    if key < *slot {
                        *slot = key;
                    }
                },
            )
        })
        .sum();
    let bufs = &*bufs;
    let w = v.width as usize;
    g.depth
        .par_chunks_mut(w)
        .zip(g.id.par_chunks_mut(w))
        .enumerate()
        .for_each(|(j, (drow, irow))| {
            for i in 0..w {
                let k = j * w + i;
                let key = bufs.iter().map(|b| b[k]).min().unwrap_or(EMPTY_KEY);
                (drow[i], irow[i]) = unpack(key);
            }
        });
    kept
}

#[inline]
fn unpack(k: u64) -> (f32, u32) {
    if k == EMPTY_KEY {
        (f32::INFINITY, BACKGROUND)
    } else {
        (f32::from_bits((k >> 32) as u32), k as u32)
    }
}

/// Unpacks the visibility buffer into the G-buffer.
pub fn resolve(vis: &[AtomicU64], g: &mut GBuffer) {
    g.depth
        .par_iter_mut()
        .zip(g.id.par_iter_mut())
        .zip(vis.par_iter())
        .for_each(|((d, id), k)| (*d, *id) = unpack(k.load(Ordering::Relaxed)));
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use stipple_core::{Camera, Projection};

    fn view() -> ViewParams {
        let cam = Camera {
            eye: DVec3::new(0.0, 0.0, 10.0),
            target: DVec3::ZERO,
            up: DVec3::Y,
            projection: Projection::Orthographic { height: 8.0 },
            width: 8,
            height: 8,
            near: 1.0,
            far: 20.0,
        };
        ViewParams::new(&cam, DVec3::ZERO)
    }

    /// Runs both strategies and checks they agree.
    fn run(v: &ViewParams, pts: &[Vec3], normals: Option<&[Vec3]>) -> GBuffer {
        let vis: Vec<AtomicU64> = (0..v.pixels()).map(|_| AtomicU64::new(EMPTY_KEY)).collect();
        let kept = project(v, pts, normals, true, None, &vis);
        let mut g = GBuffer::new(v.width, v.height);
        resolve(&vis, &mut g);
        for shares in [1, 2, 3] {
            let mut bufs = vec![Vec::new(); shares];
            let mut g2 = GBuffer::new(v.width, v.height);
            assert_eq!(
                project_private(v, pts, normals, true, None, &mut bufs, &mut g2),
                kept
            );
            assert_eq!(g2, g, "{shares} private buffers");
        }
        g
    }

    #[test]
    fn strategies_agree_on_random_clouds() {
        let v = ViewParams {
            width: 64,
            height: 48,
            ..view()
        };
        let mut rng = stipple_core::rng::Rng::new(3);
        // Coarse depths so that many ties occur.
        let pts: Vec<Vec3> = (0..20_000)
            .map(|_| {
                Vec3::new(
                    rng.f32() * 8.0 - 4.0,
                    rng.f32() * 8.0 - 4.0,
                    (rng.f32() * 4.0).floor(),
                )
            })
            .collect();
        let normals: Vec<Vec3> = (0..20_000)
            .map(|i| if i % 3 == 0 { -Vec3::Z } else { Vec3::Z })
            .collect();
        let g = run(&v, &pts, Some(&normals));
        assert!(g.covered() > 0);
    }

    /// The batched peeled projection (`project_peeled`: depths, then planes, then tests)
    /// keeps exactly the points that the one-point test [`PeelTest::peeled`] keeps, with and
    /// without planes, on random layers (empty pixels, planes of either facing, grazing
    /// normals) and clouds whose length is not a multiple of the batch.
    #[test]
    fn batched_peeling_equals_the_point_test() {
        let v = ViewParams {
            width: 64,
            height: 48,
            ..view()
        };
        let mut rng = stipple_core::rng::Rng::new(7);
        let mut unit = || {
            let n = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5);
            n.normalize_or(Vec3::Z)
        };
        let mut rng = stipple_core::rng::Rng::new(8);
        let n_pts: usize = 20_000 + 37;
        let pts: Vec<Vec3> = (0..n_pts)
            .map(|_| {
                Vec3::new(
                    rng.f32() * 8.0 - 4.0,
                    rng.f32() * 8.0 - 4.0,
                    rng.f32() * 2.0,
                )
            })
            .collect();
        let normals: Vec<Vec3> = (0..n_pts).map(|_| unit()).collect();
        let own: Vec<f32> = (0..v.pixels())
            .map(|_| {
                if rng.f32() < 0.1 {
                    f32::INFINITY
                } else {
                    8.0 + rng.f32() * 1.5
                }
            })
            .collect();
        let planes: Vec<Plane> = own
            .iter()
            .map(|&d| {
                if !d.is_finite() {
                    return [0.0, 0.0, 0.0, f32::NAN];
                }
                let n = unit();
                let x = Vec3::new(rng.f32() * 8.0 - 4.0, rng.f32() * 8.0 - 4.0, 10.0 - d);
                [n.x, n.y, n.z, dot3(n, x)]
            })
            .collect();
        let reference: Vec<f32> = own.iter().map(|d| d + 0.05).collect();
        for with_planes in [true, false] {
            let t = PeelTest {
                reference: &reference,
                own: &own,
                planes: with_planes.then_some((&planes[..], &normals[..])),
                gap: 0.1,
                done: None,
            };
            // The one-point test, point by point.
            let mut want = vec![EMPTY_KEY; v.pixels()];
            let mut kept = 0;
            for (i, &p) in pts.iter().enumerate() {
                if let Some((pix, z)) = project_point(&v, p) {
                    if !t.peeled(&v, pix, p, z, i) {
                        kept += 1;
                        want[pix] = want[pix].min(key(z, i as u32));
                    }
                }
            }
            assert!(kept > 1000 && kept < n_pts as u64 - 1000, "kept {kept}");
            for shares in [1, 2, 3] {
                let mut bufs = vec![Vec::new(); shares];
                let mut g = GBuffer::new(v.width, v.height);
                let got = project_private(&v, &pts, None, false, Some(t), &mut bufs, &mut g);
                assert_eq!(got, kept, "planes {with_planes}, {shares} shares");
                for (k, &w) in want.iter().enumerate() {
                    assert_eq!((g.depth[k], g.id[k]), unpack(w), "pixel {k}");
                }
            }
            // With memory between layers: the points marked are exactly those the test
            // peels, and a later projection skips them whatever its own test says.
            let done: Vec<AtomicU64> = (0..n_pts.div_ceil(64)).map(|_| AtomicU64::new(0)).collect();
            let marked = PeelTest {
                done: Some(&done),
                ..t
            };
            let mut bufs = vec![Vec::new(); 2];
            let mut g = GBuffer::new(v.width, v.height);
            let got = project_private(&v, &pts, None, false, Some(marked), &mut bufs, &mut g);
            assert_eq!(got, kept);
            let mut peeled_now = 0;
            for (i, &p) in pts.iter().enumerate() {
                let bit = done[i / 64].load(Ordering::Relaxed) >> (i % 64) & 1 == 1;
                let want = project_point(&v, p).is_some_and(|(pix, z)| t.peeled(&v, pix, p, z, i));
                assert_eq!(bit, want, "point {i}");
                peeled_now += bit as u64;
            }
            // Against an empty previous layer (nothing peeled by the test itself), only
            // the unmarked points in view are kept.
            let open = vec![f32::NEG_INFINITY; v.pixels()];
            let again = PeelTest {
                reference: &open,
                own: &open,
                planes: None,
                gap: 0.1,
                done: Some(&done),
            };
            let in_view = pts
                .iter()
                .filter(|&&p| project_point(&v, p).is_some())
                .count() as u64;
            let got = project_private(&v, &pts, None, false, Some(again), &mut bufs, &mut g);
            assert_eq!(got, in_view - peeled_now, "planes {with_planes}");
        }
    }

    #[test]
    fn nearest_point_wins_and_ties_go_to_the_smaller_index() {
        let v = view();
        // Pixel (4, 3) holds world x in [0, 1), y in (0, 1].
        let p = |z: f32| Vec3::new(0.5, 0.5, z);
        let g = run(&v, &[p(0.0), p(2.0), p(-1.0), p(2.0)], None);
        let k = 3 * 8 + 4;
        assert_eq!(g.id[k], 1);
        assert_eq!(g.depth[k], 8.0);
        assert_eq!(g.covered(), 1);
        // Depth order decides, not submission order.
        let g = run(&v, &[p(2.0), p(3.0), p(3.0)], None);
        assert_eq!(g.id[k], 1, "equal depths: smaller index");
    }

    /// The same-surface test of a later peeled layer: behind a front-facing plane at depth 8
    /// (pixel (4, 3) of the 8×8 orthographic view, eye at z = 10), a point of the same
    /// facing belongs to the previous layer up to d̃ behind the plane, also where the plane
    /// is steep (its depth then runs far behind the pixel's own); a point facing the other
    /// way is a new layer however close; without a plane the depth rule of the paper holds.
    #[test]
    fn later_layers_keep_only_points_behind_the_previous_surface() {
        let v = view();
        let k = 3 * 8 + 4;
        let gap = 0.1;
        let own = vec![8.0f32; 64];
        let reference = vec![8.0f32; 64];
        let flat = [0.0, 0.0, 1.0, 2.0]; // z = 2
                                         // Steep: tilted 80° about y through (0.5, 0.5, 2).
        let m = Vec3::new(80f32.to_radians().sin(), 0.0, 80f32.to_radians().cos());
        let steep = [m.x, m.y, m.z, m.dot(Vec3::new(0.5, 0.5, 2.0))];
        let up = Vec3::Z;
        let down = -Vec3::Z;
        // The test for a point at p of normal n, the pixel's plane `centre` and its right
        // neighbour's plane `right`.
        let peeled = |centre: [f32; 4], right: [f32; 4], p: Vec3, n: Vec3| {
            let mut planes = vec![centre; 64];
            planes[k + 1] = right;
            let normals = vec![n];
            let t = PeelTest {
                reference: &reference,
                own: &own,
                planes: Some((&planes, &normals)),
                gap,
                done: None,
            };
            t.peeled(&v, k, p, 10.0 - p.z, 0)
        };
        let at = |plane: [f32; 4], p: Vec3, n: Vec3| peeled(plane, plane, p, n);
        let p = |x: f32, z: f32| Vec3::new(x, 0.5, z);
        assert!(at(flat, p(0.5, 1.95), up), "same surface, within d̃");
        assert!(!at(flat, p(0.5, 1.85), up), "same facing, beyond d̃");
        assert!(
            !at(flat, p(0.5, 1.95), down),
            "the other side of a thin sheet"
        );
        assert!(
            at(flat, p(0.5, 2.05), down),
            "in front of the layer's own depth"
        );
        // On the steep plane a point 0.5 deeper but on the plane is the same surface, and
        // one d̃ / 2 behind it too; 2 d̃ behind it is not.
        let on = |x: f32| 2.0 - (x - 0.5) * m.x / m.z;
        let x = 0.5 + 0.5 * m.z / m.x;
        assert!((on(x) - 1.5).abs() < 1e-4);
        assert!(at(steep, p(x, on(x)), up));
        assert!(at(steep, p(x, on(x) - 0.5 * gap / m.z), up));
        assert!(!at(steep, p(x, on(x) - 2.0 * gap / m.z), up));
        // The depth cap: far along a steep plane points count as a new layer.
        let far = 0.5 + 3.0 * m.z / m.x;
        assert!(10.0 - on(far) > 8.0 + PEEL_SLOPE_CAP * gap);
        assert!(!at(steep, p(far, on(far)), up));
        // A curved surface seen at a grazing angle: the point is beyond d̃ of its own
        // pixel's plane but on a neighbour's, facing the same way: the same surface. A
        // neighbour facing the other way, or the pixel's own point facing the other way,
        // does not count, nor does a point whose normal is within 60° of the ray.
        let graze = Vec3::new(1.0, 0.0, 0.3).normalize();
        let with = |centre, right, n| peeled(centre, right, p(0.5, 1.85), n);
        let lower = [0.0, 0.0, 1.0, 1.85]; // z = 1.85
        let lower_down = [0.0, 0.0, -1.0, -1.85];
        assert!(with(flat, lower, graze), "on the neighbour's plane");
        assert!(!with(flat, lower, up), "facing the eye: no neighbours");
        assert!(
            !with(flat, lower_down, graze),
            "the neighbour faces the other way"
        );
        assert!(
            !with(lower_down, lower, graze),
            "the pixel's point faces the other way"
        );
        assert!(!with(flat, flat, graze), "on no plane of the neighbourhood");
        // A neighbour showing a speck of a deeper surface (z = 1, 10 d̃ below the layer
        // here) does not peel that surface around it.
        let speck = [0.0, 0.0, 1.0, 1.0];
        assert!(
            !peeled(flat, speck, p(0.5, 1.0), graze),
            "a speck's surface"
        );
        // Edge-on: a point whose normal is perpendicular to the ray (a silhouette's rim)
        // starts no layer behind a covered pixel, however far; against an edge-on plane a
        // point of either facing is the same surface within d̃ on either side of it, and
        // the facing rule does not apply.
        let side = Vec3::X;
        assert_eq!(Facing::of(&v, p(0.5, 1.0), side), Facing::Edge);
        assert_eq!(Facing::of(&v, p(0.5, 1.0), up), Facing::Front);
        assert_eq!(Facing::of(&v, p(0.5, 1.0), down), Facing::Back);
        assert!(at(flat, p(0.5, 0.0), side), "edge-on, 20 d̃ behind");
        let edge_plane = [1.0, 0.0, 0.0, 0.5]; // x = 0.5, edge-on
        assert!(
            at(edge_plane, p(0.52, 1.5), down),
            "back-facing, d̃/5 beside it"
        );
        assert!(
            at(edge_plane, p(0.48, 1.5), up),
            "front-facing, d̃/5 the other side"
        );
        assert!(!at(edge_plane, p(0.7, 1.5), up), "2 d̃ beside it");
        // A pixel the layer left empty: nothing behind it is a new layer.
        let empty = vec![f32::INFINITY; 64];
        let planes = vec![[0.0, 0.0, 0.0, f32::NAN]; 64];
        let normals = vec![up];
        let t = PeelTest {
            reference: &reference,
            own: &empty,
            planes: Some((&planes, &normals)),
            gap,
            done: None,
        };
        assert!(t.peeled(&v, k, p(0.5, -5.0), 15.0, 0));
        // No normals: the paper's depth rule.
        let t = PeelTest {
            reference: &reference,
            own: &own,
            planes: None,
            gap,
            done: None,
        };
        assert!(t.peeled(&v, k, p(0.5, 1.95), 8.05, 0));
        assert!(!t.peeled(&v, k, p(0.5, 1.85), 8.15, 0));
    }

    #[test]
    fn culling() {
        let v = view();
        let pts = [
            Vec3::new(0.5, 0.5, 0.0),
            Vec3::new(0.5, 0.5, 9.5),    // in front of near
            Vec3::new(-1.5, 2.5, -15.0), // beyond far
            Vec3::new(100.0, 0.0, 0.0),  // outside the image
            Vec3::new(-2.5, -2.5, 1.0),  // back-facing
        ];
        let normals = [Vec3::Z, Vec3::Z, Vec3::Z, Vec3::Z, -Vec3::Z];
        let g = run(&v, &pts, Some(&normals));
        assert_eq!(g.covered(), 1);
    }
}
