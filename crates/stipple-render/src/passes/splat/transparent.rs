//! # Transparent splats: Zhang & Pajarola's Algorithms 2 and 3 (§3.3, §4.2, §5.2)
//!
//! How it works: the splats are graph-coloured into K groups (`stipple_core::grouping`, the
//! deferred mode's groups) and drawn back to front (the bucket sort, slices ε thick) as flat
//! discs, each group into its own image I_k that starts as the background. A fragment
//! (where a pixel's centre ray meets a disc within its radius) of opacity α that lies more
//! than ε in front of I_k's current layer at that pixel starts a new layer: the current one
//! is composited, I_k ← α c + (1 − α) I_k, and the fragment becomes current. A fragment
//! within ε is of the current layer (§4.2.1, fragment culling): of the two, the one nearer
//! its splat's centre relative to its radius stays (Voronoi rasterization, §5.1, Eq. 10's
//! second term; ties: the smaller point), so each layer blends once per group image however
//! many splats overlap there, with the colour of the sample nearest the pixel.
//! The pixel is the mean of the K images (§3.3, Fig. 6: the mean interpolates between
//! neighbouring splats, which sit in different groups; the α-blending inside each image
//! composites the layers).
//!
//! Algorithm 3 (§5.2.2, `smooth_nearest`): each group also sums its current layer's
//! fragments' colours and opacities weighted by the splat kernel, all of them, not only the
//! Voronoi winner. At the end the groups at the nearest layer give its smoothly interpolated
//! colour C_F and opacity α (the paper's first geometry pass), everything behind it (and the
//! other groups' images) averages to C_O (its second pass), and I = α·C_F + (1 − α)·C_O.
//! The paper needs two passes over the points because a GPU of 2008 could not keep a
//! layer's sums while blending; here the sums restart whenever a nearer layer starts, so
//! one pass suffices. Colours are each point's own Phong shading
//! (`shade::cpu::shade_points`, as the sorted splats).
//!
//! Surface coverage (§4.2.2): a group holds splats that barely overlap, so alone it leaves
//! holes, and a hole lets one K-th of the background through. Splats of other groups are
//! duplicated into each group until its splats reach every sample of the cloud, the paper's
//! method (1) (`stipple_core::grouping::coverage_masks`; a point is drawn once per group it
//! belongs to). The overlap this adds is harmless: culling keeps one fragment per layer.
//! The paper's method (2), enlarged radii (`CoverageMethod::Enlarge`, `--coverage
//! enlarge`), keeps each splat in one group and grows it until its group reaches every
//! sample (`stipple_core::grouping::coverage_by_radii`). Its groups are not the
//! colouring's, whose last groups hold a handful of points that no radius makes cover the
//! surface, but four groups balanced in every neighbourhood (each point takes the group
//! least present among its neighbours already placed), so that a group's splats lie about
//! twice as far apart as the cloud's and grow about 1.7× on average. The factor per splat
//! travels in its mask's upper 16 bits (1/256 steps), read alike by both backends.
//!
//! Deviations from the paper, and why:
//! - Fragment culling compares depths (within ε of the current layer) instead of quantising
//!   them (Eq. 6): two fragments of one layer on either side of a quantisation step would
//!   both blend, a speckle of double opacity along every step. Keeping the current layer's
//!   fragment until a nearer layer comes makes the Voronoi choice inside a layer
//!   independent of the order of its fragments (the back-to-front order only separates
//!   layers), so the two backends agree although their sorts order a slice differently.
//! - The slices of the back-to-front order are ε thick (the paper uses a BSP tree): layers
//!   more than ε apart never share a slice, and closer ones are one layer to the culling.
//! - Shading is deferred per layer (§5.2.4) where the frame is lit and has no shadow
//!   textures ([`Deferred`]): the points give their albedo, each layer sums its fragments'
//!   normals (turned to the eye) weighted by the splat kernel, and when the layer is
//!   composited it is shaded (Phong, `shade::cpu::shade_fragment`) from that blended
//!   normal at its depth on the pixel's ray, with its nearest fragment's albedo and
//!   object; Algorithm 3's nearest layer from its blended albedo. On a plane with normals
//!   ±20° off this removes about a third of the per-point shading noise. With shadow
//!   textures each point is shaded on its own (forward), since a layer's shadow
//!   visibility would need each light's texture per fragment. An environment
//!   ([`crate::env`]) shows behind the layers, and with an index of refraction the layers
//!   refract it (Eq. 12, with the layer count of each pixel) and the nearest one reflects it
//!   (Fresnel), both with that layer's blended normal, and with the optics of the nearest
//!   layer's object.
//! - Opaque geometry behind the layers is refracted as well (the paper refracts only the
//!   environment): with an index of refraction and opaque points, the opaque points are
//!   drawn first, alone (`Phase::Opaque`), into the surface behind; the translucent ones
//!   are drawn over black with those behind that surface culled, keeping per pixel the
//!   farthest layer's depth and blended normal; the ray refracted in at the nearest layer
//!   and out at the farthest ([`refract_behind`]) then finds what they let through. The GPU
//!   runs its dispatches twice (a phase each) and keeps the surface behind and the
//!   farthest layer in two more vec4 per pixel after the group images.
//!
//! The CPU draws bands of rows in parallel (each band takes, in order, the splats that reach
//! it); the GPU (`transparent_composite` in sorted.wgsl's module) draws one 16×16 tile per
//! workgroup, one pixel per thread, with the tile's list of splats (`sorted_gpu`'s per-tile
//! lists) in order through workgroup memory, and keeps the K images per pixel between its
//! dispatches. Both compute a pixel's ray and a
//! disc's hit with the same operations ([`pixel_ray`], [`flat_hit`]).

use super::sorted::{band_lists, BAND};
use super::MAX_FOOTPRINT;
use crate::gbuffer::BACKGROUND;
use crate::params::ViewParams;
use glam::Vec3;
use rayon::prelude::*;

/// A transparent frame's points.
pub struct TransparentInput<'a> {
    pub positions: &'a [Vec3],
    /// Unit normals (None: discs face the eye).
    pub normals: Option<&'a [Vec3]>,
    /// Splat radii (world units), before `scale`.
    pub radii: &'a [f32],
    pub scale: f32,
    /// The groups each point is drawn in (bit k: group k) with its radius factor
    /// ([`crate::Coverage`]), and the number of groups.
    pub masks: &'a [u32],
    pub groups: usize,
    /// 8-bit opacity per point (None: opaque).
    pub alpha: Option<&'a [u8]>,
    /// Shaded linear colour per point.
    pub colour: &'a [[f32; 3]],
    /// Fragments within this depth of the last one blended into their group's image at a
    /// pixel are of its layer and culled.
    pub epsilon: f32,
    /// Algorithm 3: the nearest layer smoothly interpolated (see the module docs), where
    /// the nearest layer's object does not choose for itself (`Optics::smooth_nearest`).
    pub smooth_nearest: bool,
    /// Per point its object, and per object its optics (None: the frame's for all).
    pub optics: Option<(&'a [u8], &'a [crate::material::Optics])>,
    /// Deferred per-fragment shading (§5.2.4): `colour` holds each point's albedo, and
    /// each layer is shaded from its fragments' kernel-weighted normal at its depth on the
    /// pixel's ray (None: `colour` holds each point's own shading).
    pub deferred: Option<Deferred<'a>>,
}

/// What deferred shading reads: the frame's lights and materials, and each point's object.
#[derive(Clone, Copy)]
pub struct Deferred<'a> {
    pub params: &'a crate::passes::shade::cpu::ShadeParams,
    pub objects: Option<&'a [u8]>,
}

impl TransparentInput<'_> {
    /// The optics of point `id`'s object (None: the background, or no objects).
    fn optics_of(&self, id: u32) -> Option<&crate::material::Optics> {
        let (index, optics) = self.optics.filter(|_| id != BACKGROUND)?;
        optics.get(*index.get(id as usize)? as usize)
    }

    /// The optics of point `id`'s object in a frame with environment settings `e`.
    pub fn surface(&self, id: u32, e: &crate::env::EnvSettings) -> crate::env::Surface {
        self.optics_of(id)
            .map_or_else(|| crate::env::Surface::of_frame(e), |o| o.resolve(e))
    }

    /// Whether a pixel whose nearest layer is point `id`'s takes Algorithm 3: its object's
    /// choice, else the frame's.
    pub fn smooth_at(&self, id: u32) -> bool {
        self.optics_of(id)
            .and_then(|o| o.smooth_nearest)
            .unwrap_or(self.smooth_nearest)
    }

    /// Whether any pixel may take Algorithm 3 ([`smooth_anywhere`]).
    pub fn any_smooth(&self) -> bool {
        smooth_anywhere(self.smooth_nearest, self.optics.map(|(_, o)| o))
    }

    /// A layer's colour: with deferred shading, `albedo` shaded from the normal `n` (a
    /// kernel-weighted sum, either side) at view depth `depth` on the pixel's ray `(o, d)`
    /// with point `id`'s object; else `albedo` itself (the point's own shading).
    #[inline]
    pub fn layer_colour(
        &self,
        v: &ViewParams,
        (o, d): (Vec3, Vec3),
        albedo: [f32; 3],
        n: Vec3,
        depth: f32,
        id: u32,
    ) -> [f32; 3] {
        let Some(df) = self.deferred else {
            return albedo;
        };
        let object = df
            .objects
            .and_then(|o| o.get(id as usize))
            .map_or(0, |&o| o as usize);
        let eye = Vec3::from(v.eye);
        let forward = (v.perspective == 0).then(|| Vec3::from(v.forward));
        crate::passes::shade::cpu::shade_fragment(
            df.params,
            albedo,
            n.normalize_or_zero(),
            (eye, forward),
            o + d * depth,
            object,
        )
    }
}

/// Whether any pixel of a frame may take Algorithm 3 (both backends): the frame chooses it
/// (`frame_smooth`) or an object's optics do (the groups then also sum their current
/// layer's kernel-weighted colours).
pub fn smooth_anywhere(frame_smooth: bool, optics: Option<&[crate::material::Optics]>) -> bool {
    frame_smooth || optics.is_some_and(|o| o.iter().any(|o| o.smooth_nearest == Some(true)))
}

/// Whether points of these 8-bit opacities (None: all opaque) include opaque ones.
pub fn any_opaque(alpha: Option<&[u8]>) -> bool {
    alpha.is_none_or(|a| a.contains(&255))
}

/// Whether a frame of environment settings `e` refracts opaque geometry behind its
/// transparent splats (the two drawings of [`composite`], both backends): it has an index
/// of refraction (its own, or an object's among `optics`) and opaque points.
pub fn refracts_behind(
    e: &crate::env::EnvSettings,
    optics: Option<&[crate::material::Optics]>,
    any_opaque: bool,
) -> bool {
    any_opaque && (e.ior.is_some() || optics.is_some_and(|o| o.iter().any(|o| o.ior.is_some())))
}

/// A disc ready to draw: point, unit normal, squared radius, pixel rectangle.
type FlatDisc = (Vec3, Vec3, f32, [u32; 4]);

/// Transparent splats are drawn this much larger than their radius: the blend modes'
/// radii (0.6 × the 16th neighbour's distance) leave rare gaps in randomly sampled
/// surfaces, which the image-space passes never see there (no fill runs after the splats)
/// and a translucent surface shows as spots (measured on random spheres: at 1.15 none left;
/// overlap costs nothing, culling keeps one fragment per layer).
pub const DRAW_SCALE: f32 = 1.2;

/// The ray through pixel (x, y)'s centre: origin and direction, the direction's component
/// along the view axis 1 (so a hit's parameter is its view depth). As transparent.wgsl.
#[inline]
pub fn pixel_ray(v: &ViewParams, x: u32, y: u32) -> (Vec3, Vec3) {
    let (w, h) = (v.width as f32, v.height as f32);
    let (r, u, f) = (Vec3::from(v.right), Vec3::from(v.up), Vec3::from(v.forward));
    let eye = Vec3::from(v.eye);
    let sx = (2.0 * x as f32 + 1.0) / w - 1.0;
    let sy = 1.0 - (2.0 * y as f32 + 1.0) / h;
    let offset = r * (sx / v.sx) + u * (sy / v.sy);
    if v.perspective == 1 {
        (eye, f + offset)
    } else {
        (eye + offset, f)
    }
}

/// The pixel rectangle (x0, y0, x1, y1), inclusive, that may hold fragments of a disc of
/// radius `r` about `p`: its bounding sphere's box projected, one pixel wider on each side
/// (so that rounding never decides a pixel: the hit test does), at most [`MAX_FOOTPRINT`]
/// pixels across about the centre; None when off screen or behind the near plane. As
/// transparent.wgsl.
#[inline]
pub fn bound(v: &ViewParams, p: Vec3, r: f32) -> Option<[u32; 4]> {
    let d = p - Vec3::from(v.eye);
    let x = d.dot(Vec3::from(v.right));
    let y = d.dot(Vec3::from(v.up));
    let z = d.dot(Vec3::from(v.forward));
    let (w, h) = (v.width as f32, v.height as f32);
    let (x0, x1, y0, y1, cx, cy);
    if z + r <= v.near {
        return None;
    }
    if v.perspective == 1 {
        let zn = (z - r).max(v.near);
        let zf = z + r;
        let zc = z.max(zn);
        let lo = |c: f32| if c >= 0.0 { c / zf } else { c / zn };
        let hi = |c: f32| if c >= 0.0 { c / zn } else { c / zf };
        x0 = (lo(x - r) * v.sx + 1.0) * 0.5 * w - 0.5;
        x1 = (hi(x + r) * v.sx + 1.0) * 0.5 * w - 0.5;
        y0 = (1.0 - hi(y + r) * v.sy) * 0.5 * h - 0.5;
        y1 = (1.0 - lo(y - r) * v.sy) * 0.5 * h - 0.5;
        cx = (x * v.sx / zc + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * v.sy / zc) * 0.5 * h - 0.5;
    } else {
        x0 = ((x - r) * v.sx + 1.0) * 0.5 * w - 0.5;
        x1 = ((x + r) * v.sx + 1.0) * 0.5 * w - 0.5;
        y0 = (1.0 - (y + r) * v.sy) * 0.5 * h - 0.5;
        y1 = (1.0 - (y - r) * v.sy) * 0.5 * h - 0.5;
        cx = (x * v.sx + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * v.sy) * 0.5 * h - 0.5;
    }
    let half = MAX_FOOTPRINT * 0.5;
    let x0 = (x0.max(cx - half).floor() - 1.0).max(0.0);
    let x1 = (x1.min(cx + half).ceil() + 1.0).min(w - 1.0);
    let y0 = (y0.max(cy - half).floor() - 1.0).max(0.0);
    let y1 = (y1.min(cy + half).ceil() + 1.0).min(h - 1.0);
    if !(x0 <= x1 && y0 <= y1) {
        return None;
    }
    Some([x0 as u32, y0 as u32, x1 as u32, y1 as u32])
}

/// Where the ray (o, d) meets the flat disc about `p` with unit normal `n` and squared radius
/// `r2`: the hit's view depth, if it is within the disc and beyond `near`. As
/// transparent.wgsl.
#[inline]
pub fn flat_hit(o: Vec3, d: Vec3, p: Vec3, n: Vec3, r2: f32, near: f32) -> Option<(f32, f32)> {
    let dn = d.dot(n);
    if dn == 0.0 {
        return None;
    }
    let a = o - p;
    let t = -a.dot(n) / dn;
    let hit = a + d * t;
    let d2 = hit.dot(hit);
    (t > near && d2 < r2).then_some((t, d2 / r2))
}

/// One group image at one pixel: the colour of the layers composited so far behind the
/// current one, and the current (nearest) layer's fragment: colour, opacity, depth, (d/r)²
/// and point.
#[derive(Clone, Copy, Debug)]
struct Layered {
    behind: [f32; 3],
    colour: [f32; 3],
    alpha: f32,
    depth: f32,
    q: f32,
    id: u32,
    /// What the layers behind the current one let through of the background, and how many
    /// they are.
    through: f32,
    behind_layers: f32,
    /// The current layer's kernel-weighted sum of normals (turned to the eye).
    normal: Vec3,
    /// Algorithm 3: the current layer's kernel-weighted sums of colour and opacity, and of
    /// the weights.
    smooth: [f32; 4],
    weight: f32,
}

impl Layered {
    fn new(background: [f32; 3]) -> Layered {
        Layered {
            behind: background,
            colour: [0.0; 3],
            alpha: 0.0,
            depth: f32::INFINITY,
            q: 0.0,
            id: BACKGROUND,
            through: 1.0,
            behind_layers: 0.0,
            normal: Vec3::ZERO,
            smooth: [0.0; 4],
            weight: 0.0,
        }
    }

    /// What all the layers let through of the background, and how many they are.
    fn transmission(&self) -> (f32, f32) {
        if self.depth.is_finite() {
            (self.through * (1.0 - self.alpha), self.behind_layers + 1.0)
        } else {
            (self.through, self.behind_layers)
        }
    }

    /// A fragment, in back-to-front order: nearer than the current layer by more than ε, it
    /// starts a new layer (the current one composited behind it); otherwise it is of the
    /// current layer, and of the two the fragment nearer its splat's centre (relative to its
    /// radius; ties: the smaller point) stays, Voronoi rasterization (§5.1) within the layer.
    ///
    /// With `normal` (an environment is refracted and reflected), the current layer's
    /// fragments also sum their normals weighted by the splat kernel, whichever of them
    /// wins: the layer's smooth normal (the per-fragment attribute interpolation of §5.2.4).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn add(
        &mut self,
        z: f32,
        q: f32,
        id: u32,
        colour: [f32; 3],
        alpha: f32,
        epsilon: f32,
        normal: Option<Vec3>,
        smooth: bool,
        shade: &dyn Fn(&Layered) -> [f32; 3],
    ) {
        let w = super::weight(q);
        let wn = normal.map_or(Vec3::ZERO, |n| n * w);
        let wc = if smooth {
            [w * colour[0], w * colour[1], w * colour[2], w * alpha]
        } else {
            [0.0; 4]
        };
        if z < self.depth - epsilon {
            if self.depth.is_finite() {
                self.behind = self.composite(shade);
                self.through *= 1.0 - self.alpha;
                self.behind_layers += 1.0;
            }
            self.normal = wn;
            (self.smooth, self.weight) = (wc, w);
        } else {
            self.normal += wn;
            if smooth {
                for (s, c) in self.smooth.iter_mut().zip(wc) {
                    *s += c;
                }
                self.weight += w;
            }
            if (q, id) >= (self.q, self.id) {
                return;
            }
        }
        (self.colour, self.alpha, self.depth, self.q, self.id) = (colour, alpha, z, q, id);
    }

    /// The layers composited, the current one's colour given by `colour` (its fragment's
    /// own, or deferred shading's).
    #[inline]
    fn composite(&self, colour: &dyn Fn(&Layered) -> [f32; 3]) -> [f32; 3] {
        if !self.depth.is_finite() {
            return self.behind;
        }
        let c = colour(self);
        std::array::from_fn(|k| self.alpha * c[k] + (1.0 - self.alpha) * self.behind[k])
    }
}

/// Which fragments a drawing of the splats takes (see [`composite`]).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Phase {
    /// Every fragment: the layers' composite over the background (no refraction).
    All,
    /// Opaque fragments only (α = 1): the surface behind the transparent layers.
    Opaque,
    /// Translucent fragments only, those behind the opaque surface culled: the layers in
    /// front of it, composited over black.
    Translucent,
}

/// The opaque surface behind the transparent layers, drawn alone (refraction's first
/// drawing), per pixel: its colour over the environment, its depth (∞: none) and point.
struct Behind {
    colour: Vec<[f32; 3]>,
    depth: Vec<f32>,
    id: Vec<u32>,
}

impl Behind {
    /// The colour at continuous pixel coordinates (pixel centres at integers), bilinear,
    /// clamped to the frame.
    fn colour_at(&self, v: &ViewParams, x: f32, y: f32) -> [f32; 3] {
        let (w, h) = (v.width as i64, v.height as i64);
        let (x, y) = (x.clamp(0.0, (w - 1) as f32), y.clamp(0.0, (h - 1) as f32));
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |i: f32, j: f32| {
            let i = (i as i64).min(w - 1) as usize;
            let j = (j as i64).min(h - 1) as usize;
            self.colour[j * w as usize + i]
        };
        let lerp = |a: [f32; 3], b: [f32; 3], t: f32| -> [f32; 3] {
            std::array::from_fn(|c| a[c] + (b[c] - a[c]) * t)
        };
        let top = lerp(at(x0, y0), at(x0 + 1.0, y0), fx);
        let bottom = lerp(at(x0, y0 + 1.0), at(x0 + 1.0, y0 + 1.0), fx);
        lerp(top, bottom, fy)
    }

    /// The depth at the pixel nearest continuous pixel coordinates, clamped to the frame.
    fn depth_at(&self, v: &ViewParams, x: f32, y: f32) -> f32 {
        let i = ((x + 0.5).floor().clamp(0.0, v.width as f32 - 1.0)) as usize;
        let j = ((y + 0.5).floor().clamp(0.0, v.height as f32 - 1.0)) as usize;
        self.depth[j * v.width as usize + i]
    }
}

/// The continuous pixel coordinates of a point (pixel centres at integers, as
/// [`bound`]'s), None behind the eye.
#[inline]
pub fn to_pixel(v: &ViewParams, p: Vec3) -> Option<(f32, f32)> {
    let d = p - Vec3::from(v.eye);
    let x = d.dot(Vec3::from(v.right));
    let y = d.dot(Vec3::from(v.up));
    let z = d.dot(Vec3::from(v.forward));
    let (w, h) = (v.width as f32, v.height as f32);
    if v.perspective == 1 {
        (z > 0.0).then(|| {
            (
                (x * v.sx / z + 1.0) * 0.5 * w - 0.5,
                (1.0 - y * v.sy / z) * 0.5 * h - 0.5,
            )
        })
    } else {
        Some((
            (x * v.sx + 1.0) * 0.5 * w - 0.5,
            (1.0 - y * v.sy) * 0.5 * h - 0.5,
        ))
    }
}

/// Steps of the search for where a refracted ray meets the opaque surface behind.
pub const BEHIND_STEPS: u32 = 4;

/// Where the ray through a pixel (origin `o`, direction `d` of unit view-axis component),
/// refracted into a transparent surface of index `eta` at its nearest layer (view depth
/// `z_near`, unit normal `n_near` facing the eye) and out of it at its farthest (view depth
/// and unit normal, None: the nearest layer is the only one, a thin sheet that bends the
/// ray in and back out at the same place), meets the opaque surface behind, whose view
/// depth at continuous pixel coordinates `depth_at` gives (`z_start`: the depth to start
/// from where the exit point's own pixel has none): those pixel coordinates, or the exit
/// ray's direction where it passes the opaque surface (it meets a pixel without one, or
/// turns away from the eye's depth axis).
///
/// In at the nearest layer by Snell's law; straight through the surface to the plane of
/// the farthest layer (through its point on the pixel's ray, with its normal); out there
/// by Snell's law (total internal reflection: on along the inner ray); then along the
/// exit ray to the opaque surface, found by [`BEHIND_STEPS`] steps: the ray's point at the
/// depth the opaque surface has where the previous point projects (exact for a surface of
/// constant depth, the screen-space refraction of Wyman 2005). As transparent.wgsl.
#[allow(clippy::too_many_arguments)]
pub fn refract_behind(
    v: &ViewParams,
    o: Vec3,
    d: Vec3,
    z_near: f32,
    n_near: Vec3,
    far: Option<(f32, Vec3)>,
    eta: f32,
    z_start: f32,
    depth_at: impl Fn(f32, f32) -> f32,
) -> Result<(f32, f32), Vec3> {
    let u = d.normalize_or_zero();
    let entry = o + d * z_near;
    let (exit, out) = match far {
        Some((z_far, n_far)) => {
            let inner = crate::env::refracted(u, n_near, eta, 1.0);
            // The far layer's normal, facing along the inner ray (out of the surface).
            let nf = if n_far.dot(inner) < 0.0 {
                -n_far
            } else {
                n_far
            };
            let den = inner.dot(nf);
            let s = if den > 1e-4 {
                ((o + d * z_far - entry).dot(nf) / den).max(0.0)
            } else {
                0.0
            };
            (
                entry + inner * s,
                crate::env::refracted(inner, -nf, 1.0 / eta, 1.0),
            )
        }
        None => (entry, u),
    };
    let f = Vec3::from(v.forward);
    let eye = Vec3::from(v.eye);
    let (z_exit, along) = ((exit - eye).dot(f), out.dot(f));
    if along <= 1e-6 {
        return Err(out);
    }
    let Some(mut at) = to_pixel(v, exit) else {
        return Err(out);
    };
    let mut z_hit = depth_at(at.0, at.1);
    if !z_hit.is_finite() {
        z_hit = z_start;
    }
    if !z_hit.is_finite() {
        return Err(out);
    }
    for _ in 0..BEHIND_STEPS {
        let s = ((z_hit - z_exit) / along).max(0.0);
        let Some(p) = to_pixel(v, exit + out * s) else {
            return Err(out);
        };
        at = p;
        z_hit = depth_at(at.0, at.1);
        if !z_hit.is_finite() {
            return Err(out);
        }
    }
    Ok(at)
}

/// Draws the points of `order` (back to front) over `background` (or the environment in
/// each pixel's direction) into K group images and writes their mean (linear colour), with
/// the environment reflected by the nearest layer where `env` has an index of refraction
/// ([`crate::env`]); and per pixel the nearest blended fragment's depth and point. Returns
/// the fragments blended.
///
/// With an index of refraction the opaque points (α = 1) are drawn first, alone, into the
/// surface behind the transparent layers; the translucent points are then drawn over
/// black (those behind that surface culled), and what their layers let through of it is
/// looked up where each pixel's ray, refracted in at the nearest layer and out at the
/// farthest, meets it ([`refract_behind`]); where no opaque surface lies behind, the
/// environment along Eq. 12's refracted ray, as without opaque points.
#[allow(clippy::too_many_arguments)]
pub fn composite(
    v: &ViewParams,
    input: &TransparentInput,
    order: &[u32],
    background: [f32; 3],
    env: Option<&crate::env::EnvSettings>,
    colour: &mut [[f32; 3]],
    depth: &mut [f32],
    id: &mut [u32],
) -> u64 {
    let eye = Vec3::from(v.eye);
    // Per splat in order: the disc (point, normal, squared radius) and its pixel rectangle.
    let discs: Vec<Option<FlatDisc>> = order
        .par_iter()
        .with_min_len(4096)
        .map(|&i| {
            let i = i as usize;
            let p = input.positions[i];
            let mask = input.masks[i];
            let r = input.radii[i] * input.scale * DRAW_SCALE * crate::Coverage::factor(mask);
            if r.is_nan() || r <= 0.0 || crate::Coverage::groups_of(mask) == 0 {
                return None;
            }
            let n = match input.normals {
                Some(n) => n[i].normalize_or_zero(),
                None if v.perspective == 1 => (eye - p).normalize_or_zero(),
                None => -Vec3::from(v.forward),
            };
            if n == Vec3::ZERO {
                return None;
            }
            bound(v, p, r).map(|rect| (p, n, r * r, rect))
        })
        .collect();
    let per_band = band_lists(
        v.height as usize,
        discs
            .iter()
            .map(|d| d.map(|(_, _, _, [_, y0, _, y1])| (y0 as usize, y1 as usize))),
    );
    let draw = Drawing {
        v,
        input,
        order,
        discs: &discs,
        per_band: &per_band,
        background,
        env,
    };
    // Opaque points to refract (else the environment alone, by Eq. 12).
    let opaque = any_opaque(input.alpha);
    match env.filter(|e| refracts_behind(e, input.optics.map(|(_, o)| o), opaque)) {
        None => draw.run(Phase::All, None, colour, depth, id),
        Some(_) => {
            let n = v.pixels();
            let mut behind = Behind {
                colour: vec![[0.0; 3]; n],
                depth: vec![f32::INFINITY; n],
                id: vec![BACKGROUND; n],
            };
            let f = draw.run(
                Phase::Opaque,
                None,
                &mut behind.colour,
                &mut behind.depth,
                &mut behind.id,
            );
            f + draw.run(Phase::Translucent, Some(&behind), colour, depth, id)
        }
    }
}

/// What one drawing of the splats reads.
struct Drawing<'a> {
    v: &'a ViewParams,
    input: &'a TransparentInput<'a>,
    order: &'a [u32],
    discs: &'a [Option<FlatDisc>],
    per_band: &'a [Vec<u32>],
    background: [f32; 3],
    env: Option<&'a crate::env::EnvSettings>,
}

impl Drawing<'_> {
    /// Draws the fragments of `phase` into the K group images of each band and writes the
    /// pixels; returns the fragments blended.
    fn run(
        &self,
        phase: Phase,
        behind: Option<&Behind>,
        colour: &mut [[f32; 3]],
        depth: &mut [f32],
        id: &mut [u32],
    ) -> u64 {
        let (v, input, env) = (self.v, self.input, self.env);
        let w = v.width as usize;
        let k_groups = input.groups.max(1);
        let smooth = input.any_smooth();
        // The angle a pixel spans, over which the environment is averaged.
        let cone = crate::env::pixel_cone(v);
        colour
            .par_chunks_mut(w * BAND)
            .zip(depth.par_chunks_mut(w * BAND))
            .zip(id.par_chunks_mut(w * BAND))
            .zip(self.per_band.par_iter())
            .enumerate()
            .map(|(b, (((crow, drow), irow), list))| {
                let rows = crow.len() / w;
                let y_base = b * BAND;
                let first = y_base * w;
                drow.fill(f32::INFINITY);
                irow.fill(BACKGROUND);
                let rays: Vec<(Vec3, Vec3)> = (0..crow.len())
                    .map(|p| pixel_ray(v, (p % w) as u32, (y_base + p / w) as u32))
                    .collect();
                // Per group and pixel: the layers behind and the current layer's fragment,
                // over the background (with an environment: over black, what they let
                // through of it added at the end, looked up along the refracted ray).
                let start = env.map_or(self.background, |_| [0.0; 3]);
                let mut acc = vec![Layered::new(start); k_groups * crow.len()];
                // Refraction: per pixel, the farthest translucent layer's depth and its
                // fragments' kernel-weighted normals (the first fragments in back-to-front
                // order, and those within ε of them).
                let mut far = if phase == Phase::Translucent {
                    vec![(f32::INFINITY, Vec3::ZERO); crow.len()]
                } else {
                    Vec::new()
                };
                let mut frags = 0u64;
                for &k in list {
                    let Some((p, n, r2, [x0, y0, x1, y1])) = self.discs[k as usize] else {
                        continue;
                    };
                    let i = self.order[k as usize] as usize;
                    let c = input.colour[i];
                    let a8 = input.alpha.map_or(255, |a| a[i]);
                    match phase {
                        Phase::Opaque if a8 != 255 => continue,
                        Phase::Translucent if a8 == 255 => continue,
                        _ => {}
                    }
                    let alpha = a8 as f32 / 255.0;
                    let mask = crate::Coverage::groups_of(input.masks[i]);
                    let ylo = (y0 as usize).max(y_base);
                    let yhi = (y1 as usize).min(y_base + rows - 1);
                    for y in ylo..=yhi {
                        for x in x0 as usize..=x1 as usize {
                            let pix = (y - y_base) * w + x;
                            let (o, d) = rays[pix];
                            let Some((z, q)) = flat_hit(o, d, p, n, r2, v.near) else {
                                continue;
                            };
                            // The fragment's normal turned to the eye, summed per layer for the
                            // environment and for deferred shading.
                            let facing = (env.is_some() || input.deferred.is_some()).then(|| {
                                if n.dot(d) > 0.0 {
                                    -n
                                } else {
                                    n
                                }
                            });
                            let shade = |l: &Layered| {
                                input.layer_colour(v, (o, d), l.colour, l.normal, l.depth, l.id)
                            };
                            if let Some(bh) = behind {
                                // Behind the opaque surface: hidden.
                                if z > bh.depth[first + pix] {
                                    continue;
                                }
                                let (fz, fnorm) = &mut far[pix];
                                let wn = facing.unwrap_or(Vec3::ZERO) * super::weight(q);
                                if !fz.is_finite() {
                                    (*fz, *fnorm) = (z, wn);
                                } else if z >= *fz - input.epsilon {
                                    *fnorm += wn;
                                }
                            }
                            let mut bits = mask;
                            while bits != 0 {
                                let g = bits.trailing_zeros() as usize;
                                bits &= bits - 1;
                                if g >= k_groups {
                                    break;
                                }
                                acc[g * crow.len() + pix].add(
                                    z,
                                    q,
                                    i as u32,
                                    c,
                                    alpha,
                                    input.epsilon,
                                    facing,
                                    smooth,
                                    &shade,
                                );
                                frags += 1;
                            }
                        }
                    }
                }
                for (pix, o) in crow.iter_mut().enumerate() {
                    let groups = (0..k_groups).map(|g| &acc[g * rows * w + pix]);
                    let (c, through, layers) = finish_layers(
                        groups.clone(),
                        (v, input, rays[pix]),
                        &mut drow[pix],
                        &mut irow[pix],
                    );
                    *o = c;
                    let Some(e) = env else { continue };
                    let (ro, d) = rays[pix];
                    // The nearest layer's normal: its fragments' kernel-weighted normals
                    // summed over the groups (one splat's normal alone would show every
                    // splat as a facet in the refracted image).
                    let n: Vec3 = groups
                        .filter(|s| s.id != BACKGROUND && s.depth <= drow[pix] + input.epsilon)
                        .map(|s| s.normal)
                        .sum();
                    let n = (irow[pix] != BACKGROUND).then_some(n);
                    // The optics of the nearest layer's object.
                    let surface = input.surface(irow[pix], e);
                    if phase == Phase::Opaque {
                        // The surface behind over the environment along the pixel's ray,
                        // reflecting it.
                        *o = crate::env::finish(*o, e, &surface, (d, cone), n, through, 0.0);
                        continue;
                    }
                    match behind {
                        Some(bh) => {
                            let gp = first + pix;
                            let Some(nn) = n else {
                                // No translucent layer: the surface behind as it is.
                                (*o, drow[pix], irow[pix]) =
                                    (bh.colour[gp], bh.depth[gp], bh.id[gp]);
                                continue;
                            };
                            let u = d.normalize_or_zero();
                            let nn = nn.normalize_or_zero();
                            let nn = if nn.dot(u) > 0.0 { -nn } else { nn };
                            let (fz, fnorm) = far[pix];
                            let far_layer = (fz > drow[pix] + input.epsilon)
                                .then(|| (fz, fnorm.normalize_or_zero()))
                                .filter(|(_, n)| *n != Vec3::ZERO);
                            let eta = surface.eta.unwrap_or(1.0);
                            let lookup = |eta: f32| {
                                let z0 = bh.depth[gp];
                                let depth_at = |x, y| bh.depth_at(v, x, y);
                                match refract_behind(
                                    v, ro, d, drow[pix], nn, far_layer, eta, z0, depth_at,
                                ) {
                                    Ok((x, y)) => bh.colour_at(v, x, y),
                                    Err(dir) => e.env.sample(dir, e.up, cone),
                                }
                            };
                            let seen = crate::env::per_channel(eta, surface.dispersion, lookup);
                            let pass = surface.passed(through, layers);
                            *o = std::array::from_fn(|ch| o[ch] + pass[ch] * seen[ch]);
                            if surface.eta.is_some() {
                                let f = (eta, surface.reflectivity);
                                *o = crate::env::reflect_into(*o, &e.env, e.up, f, d, nn, cone);
                            }
                        }
                        _ => {
                            *o = crate::env::finish(*o, e, &surface, (d, cone), n, through, layers)
                        }
                    }
                }
                frags
            })
            .sum()
    }
}

/// A pixel's K group images finished: the mean of their composites, what they let through
/// of what lies behind (mean) and how many layers they hold (mean); sets the nearest
/// layer's depth and point (ties: the first group). With Algorithm 3 the nearest layer's
/// colour C_F and opacity α come from all its fragments, kernel-weighted over the groups
/// that reached it; the rest (what lies behind it in those groups, everything in the
/// others) averages to C_O; I = α·C_F + (1 − α)·C_O.
fn finish_layers<'a>(
    groups: impl Iterator<Item = &'a Layered> + Clone,
    (v, input, ray): (&ViewParams, &TransparentInput, (Vec3, Vec3)),
    depth: &mut f32,
    id: &mut u32,
) -> ([f32; 3], f32, f32) {
    let shade = |l: &Layered| input.layer_colour(v, ray, l.colour, l.normal, l.depth, l.id);
    let k = input.groups.max(1);
    let inv = 1.0 / k as f32;
    let mut sum = [0.0f32; 3];
    let (mut through, mut layers) = (0.0f32, 0.0f32);
    for s in groups.clone() {
        let c = s.composite(&shade);
        for ch in 0..3 {
            sum[ch] += c[ch];
        }
        let (t, l) = s.transmission();
        through += t;
        layers += l;
        if s.depth < *depth {
            (*depth, *id) = (s.depth, s.id);
        }
    }
    let mut out = sum.map(|s| s * inv);
    if depth.is_finite() && input.smooth_at(*id) {
        let near = *depth + input.epsilon;
        let (mut f, mut wsum, mut nsum) = ([0.0f32; 4], 0.0f32, Vec3::ZERO);
        let (mut co, mut to, mut lo) = ([0.0f32; 3], 0.0f32, 0.0f32);
        for s in groups {
            let (c, t, l) = if s.depth <= near {
                for (a, b) in f.iter_mut().zip(s.smooth) {
                    *a += b;
                }
                wsum += s.weight;
                nsum += s.normal;
                (s.behind, s.through, s.behind_layers)
            } else {
                let (t, l) = s.transmission();
                (s.composite(&shade), t, l)
            };
            for ch in 0..3 {
                co[ch] += c[ch];
            }
            to += t;
            lo += l;
        }
        if wsum > 0.0 {
            let af = f[3] / wsum;
            // C_F: the blended colours (deferred: the blended albedo, shaded from the
            // blended normal).
            let cf = [f[0] / wsum, f[1] / wsum, f[2] / wsum];
            let cf = input.layer_colour(v, ray, cf, nsum, *depth, *id);
            out = std::array::from_fn(|ch| af * cf[ch] + (1.0 - af) * (co[ch] * inv));
            through = (1.0 - af) * to;
            layers = lo + k as f32;
        }
    }
    (out, through * inv, layers * inv)
}
#[cfg(test)]
mod tests {
    use super::*;

    /// Two parallel translucent planes over a background, each sampled densely in two
    /// groups: every pixel of their overlap is the analytic front-to-back composite, a
    /// pixel of one plane alone that plane over the background.
    #[test]
    fn two_translucent_planes_composite_exactly() {
        let v = ViewParams::axis_aligned(48, 48, false, 1.0);
        let mut positions = Vec::new();
        let mut colour = Vec::new();
        let mut alpha = Vec::new();
        let mut masks = Vec::new();
        // Plane A (far, z 2, red, α 0.6) over x in [0, 1]; plane B (near, z 1, blue,
        // α 0.5) over x in [0, 0.5]; points 0.02 apart in a grid, groups by checkerboard.
        for (z, xmax, c, a) in [
            (2.0, 1.0, [1.0, 0.0, 0.0], 153u8),
            (1.0, 0.5, [0.0, 0.0, 1.0], 128),
        ] {
            for iy in 0..=50 {
                for ix in 0..=(xmax * 50.0) as i32 {
                    positions.push(Vec3::new(ix as f32 * 0.02, iy as f32 * 0.02, z));
                    colour.push(c);
                    alpha.push(a);
                    masks.push(1u32 << ((ix + iy) % 2));
                }
            }
        }
        let normals = vec![Vec3::new(0.0, 0.0, -1.0); positions.len()];
        let radii = vec![0.03; positions.len()];
        let input = TransparentInput {
            positions: &positions,
            normals: Some(&normals),
            radii: &radii,
            scale: 1.0,
            masks: &masks,
            groups: 2,
            alpha: Some(&alpha),
            colour: &colour,
            epsilon: 0.05,
            smooth_nearest: false,
            optics: None,
            deferred: None,
        };
        // Back to front: plane A, then B.
        let order: Vec<u32> = (0..positions.len() as u32).collect();
        let bg = [0.2, 0.6, 0.2];
        let n = v.pixels();
        let (mut c, mut d, mut id) = (vec![[0.0; 3]; n], vec![0.0; n], vec![0; n]);
        composite(&v, &input, &order, bg, None, &mut c, &mut d, &mut id);
        let (aa, ab) = (153.0 / 255.0f32, 128.0 / 255.0f32);
        let over_a: [f32; 3] =
            std::array::from_fn(|k| aa * [1.0, 0.0, 0.0][k] + (1.0 - aa) * bg[k]);
        let both: [f32; 3] =
            std::array::from_fn(|k| ab * [0.0, 0.0, 1.0][k] + (1.0 - ab) * over_a[k]);
        let at = |x: f32, y: f32| {
            crate::passes::project::cpu::project_point(&v, Vec3::new(x, y, 1.0))
                .unwrap()
                .0
        };
        for (x, y, want) in [
            (0.25, 0.5, both),
            (0.1, 0.8, both),
            (0.75, 0.5, over_a),
            (0.9, 0.3, over_a),
        ] {
            let k = at(x, y);
            for ch in 0..3 {
                assert!(
                    (c[k][ch] - want[ch]).abs() < 0.5 / 255.0,
                    "({x}, {y}) channel {ch}: {:?} vs {want:?}",
                    c[k]
                );
            }
        }
        // The nearest layer's depth where both are, the far one's elsewhere.
        assert!((d[at(0.25, 0.5)] - 1.0).abs() < 1e-5);
        assert!((d[at(0.75, 0.5)] - 2.0).abs() < 1e-5);
        // Drawn in the wrong order (front first), the far plane is culled behind the near one.
        let rev: Vec<u32> = order.iter().rev().copied().collect();
        let (mut c2, mut d2, mut id2) = (vec![[0.0; 3]; n], vec![0.0; n], vec![0; n]);
        composite(&v, &input, &rev, bg, None, &mut c2, &mut d2, &mut id2);
        assert!((c2[at(0.25, 0.5)][0] - both[0]).abs() > 0.05);
    }
}
