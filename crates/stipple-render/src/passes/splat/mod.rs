//! # splat: surface splats with ε-z visibility (Zhang & Pajarola §3.1, §3.2, §4.1, §5.1)
//!
//! How it works: every point is a splat of radius r (its `radius`, see
//! `stipple_core::normals`): a disc in the plane through it normal to its normal, bent to the
//! surface's curvature and cut at creases ([`Disc`], `stipple_core::normals::shapes`). A splat
//! covers the pixels whose centre ray meets it within r of the point ([`Raster`]). Per
//! pixel:
//!
//! 1. **visibility**: the nearest fragment depth z_min;
//! 2. **ε-z test**: only fragments with depth ≤ z_min + ε count (ε = the median splat
//!    radius: fragments of one surface layer at a pixel differ by far less, see [`epsilon`]),
//!    and where a fragment faces the eye and nothing lies more than ε in front of it, only
//!    fragments facing the eye count ([`reference`](fn@reference)): the far side of a sheet thinner than ε
//!    (walls, leaves, plates scanned from both sides) does not blend into its near side;
//! 3. a choice among them, by mode ([`SplatMode`]):
//!    - **Voronoi rasterization** (§5.1): the fragment with the smallest d/r wins the pixel
//!      (ties: the smaller point index). The pixel shows that point, at the depth where its
//!      disc meets the pixel's ray, shaded with the bent splat's normal there (not the
//!      point's flat normal, which gave sparse curved surfaces a faceted look, 3° off):
//!      sharp, hole-free surfaces with no blending. The result is a visibility G-buffer
//!      (depth + point id) with a per-pixel normal, so shading, smoothing and antialiasing
//!      are the same passes as Dobrev's pipeline on both backends.
//!    - **Blend** (§3.1, Eq. 1; the default): the Gaussian-weighted mean
//!      w = exp(−3 (d/r)²) of the counting fragments' albedo, normal (the bent splat's normal
//!      at the hit, turned towards the eye first, so normals of random sign do not cancel)
//!      and depth, normalised per pixel, and shaded per pixel from the blended normal
//!      (deferred shading). The pixel's id is the fragment of largest weight (its object,
//!      material and shadow texture apply). Two passes over the splats (z_min, then the
//!      sums): the paper's "2+1-pass" reference.
//!    - **Deferred** (§3.2 deferred blending, §4.1 grouping, §5.1 Algorithm 1): splats are
//!      graph-coloured into K groups whose splats do not overlap
//!      (`stipple_core::grouping`, relaxation c); ONE pass over the splats keeps, per group
//!      and pixel, the fragment of smallest Eq. 10 key (the low-precision depth of Eq. 6,
//!      then the Voronoi distance, [`DepthQuant`]); the compositing of Fig. 5 then takes the
//!      nearest depth over the K winners and blends those within ε, as Blend does. Equal to
//!      Blend where no two splats of a group overlap a pixel (tested); with c < 1 a group's
//!      overlapping splats keep only the Voronoi winner, as in the paper.
//!
//! On the GPU the sums are fixed-point integer atomics (2⁻¹⁶ of a weight; exact and
//! independent of thread order), the K group images are u32 keys and ids, and the blended
//! albedo is stored as 8-bit sRGB on both backends.
//!
//! Deviations from the paper, and why:
//! - The paper's single-pass deferred blending exists because a 2008 GPU had no fuzzy depth
//!   test. It is here (`deferred`), but the default is the exact two-pass ε-z blend: with
//!   compute shaders and atomics (and tiles on the CPU) it keeps no K group images, needs no
//!   colouring pre-process (0.5–0.9 s on the Dragon), and measured as fast or faster
//!   (`stipple bench --zhang`, BENCHMARKS.md). The Voronoi mode uses the exact z_min + ε
//!   test instead of the quantised depth of Eq. 10, which shows bands where fragments of one
//!   surface fall on either side of a quantisation step.
//! - The grouping allows at most `stipple_core::grouping::MAX_GROUPS` groups (the paper's
//!   16-sampler limit no longer applies; memory does) and says how many points had to
//!   share a group with an overlapping neighbour.
//! - The paper's splats are flat discs. Flat discs stick out of a curved silhouette by
//!   r²κ/2 and sit off the surface between samples by d²κ/2, which on sparse clouds (points
//!   3–6 px apart) costs 1–2% of the silhouette and puts 5–15% of depths more than 0.5% of
//!   the depth range off. Bent splats (the osculating quadric of the neighbourhood) meet a
//!   ray where the surface is to fourth order; at creases discs are cut by the neighbouring
//!   face's tangent plane instead of sticking out by up to r. Measured on random samples of
//!   a sphere, torus, box and two spheres (tests/splat.rs): IoU 0.990–0.9995, depth within
//!   0.5% of the range on 97–99.9% of pixels.
//! - Clouds without normals get flat discs facing the eye.
//! - A disc whose footprint would exceed [`MAX_FOOTPRINT`] pixels across is clipped to that
//!   square (a camera inside a splat).

pub mod cpu;
pub mod gpu;
pub mod sorted;
pub(crate) mod sorted_gpu;
pub mod transparent;

use crate::params::ViewParams;
use glam::Vec3;
pub use stipple_core::normals::SplatShape;

/// How splat fragments that pass the ε-z test make a pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum SplatMode {
    /// The fragment nearest its splat's centre (relative to its radius) wins.
    Voronoi,
    /// Gaussian-weighted mean of albedo, normal and depth, shaded per pixel. The default:
    /// on scans (the Stanford bunny, 2 px apart) Voronoi shows each point's normal noise as
    /// a darker or lighter cell; blending averages it out.
    #[default]
    Blend,
    /// The paper's deferred blending (§3.2, §5.1 Algorithm 1): splats graph-coloured into
    /// groups of non-overlapping splats (`stipple_core::grouping`), ONE geometry pass that
    /// keeps per group and pixel the splat of smallest Eq. 10 key (low-precision depth, then
    /// the Voronoi distance), then per pixel the compositing of Fig. 5 over the groups.
    /// Equals `Blend` where no two splats of a group overlap a pixel.
    Deferred,
    /// Gunjee et al. §4.2: the points bucket-sorted back to front and drawn as Gaussian
    /// splats with the "over" operator, each with its own opacity and shading ([`sorted`]):
    /// for volumes, transfer functions and particle clouds.
    Sorted,
    /// Zhang & Pajarola's transparent splats (§4.2, §5.2.1 Algorithm 2): the deferred
    /// mode's groups, each duplicated until it covers the surface, drawn back to front as
    /// flat discs with per-point opacity into one image per group (a fragment within ε of
    /// the last one blended there is of the same layer and culled), then averaged
    /// ([`transparent`]).
    Transparent,
}

/// How transparent splats make each group cover the surface (Zhang & Pajarola §4.2.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum CoverageMethod {
    /// Method (1): splats of other groups are duplicated into a group until its splats reach
    /// every sample (`stipple_core::grouping::coverage_masks`). The default: sharp, each
    /// splat at its own size.
    #[default]
    Duplicate,
    /// Method (2): every splat stays in one of four groups balanced in every neighbourhood,
    /// and is enlarged until its group reaches every sample
    /// (`stipple_core::grouping::coverage_by_radii`): no duplicates, larger splats (softer
    /// silhouettes).
    Enlarge,
}

impl SplatMode {
    /// Drawn back to front in one pass, shaded per point (no shade pass, no ε-z test).
    pub fn is_ordered(self) -> bool {
        matches!(self, SplatMode::Sorted | SplatMode::Transparent)
    }
}

/// Settings of the splat pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplatSettings {
    pub mode: SplatMode,
    /// Multiplies every radius.
    pub scale: f32,
    /// ε of the ε-z test, world units (None: [`epsilon`]).
    pub epsilon: Option<f32>,
    /// Overlap relaxation c of the grouping (deferred mode; Zhang & Pajarola §4.1).
    pub c: f32,
    /// The view-depth range of the cloud, for Eq. 6 (deferred mode; set when the pipeline
    /// is resolved for a cloud and view).
    pub depth_range: Option<(f32, f32)>,
    /// Transparent mode: the nearest layer smoothly interpolated (Zhang & Pajarola's
    /// Algorithm 3, §5.2.2) instead of each group's nearest fragment (Algorithm 2).
    pub smooth_nearest: bool,
    /// Transparent mode: how each group covers the surface.
    pub coverage: CoverageMethod,
}

impl SplatSettings {
    /// Deferred blending's depth quantisation (None before the pipeline is resolved).
    pub fn quant(&self) -> Option<DepthQuant> {
        let (lo, hi) = self.depth_range?;
        Some(DepthQuant::new(lo, hi, self.epsilon.unwrap_or(0.0)))
    }
}

impl Default for SplatSettings {
    fn default() -> Self {
        SplatSettings {
            mode: SplatMode::Blend,
            scale: 1.0,
            epsilon: None,
            c: stipple_core::grouping::DEFAULT_C,
            depth_range: None,
            smooth_nearest: false,
            coverage: CoverageMethod::Duplicate,
        }
    }
}

/// The low-precision depth of Eq. 6 and the key of Eq. 10 that deferred blending's geometry
/// pass z-tests with: level = ⌊(d − d_min)·n/(d_max − d_min)⌋ with n = ⌈(d_max − d_min)/ε⌉
/// (at most 65 535 levels), so that fragments of one surface layer share a level or two and
/// layers ε apart differ; the key is level · 2¹⁶ + facing away · 2¹⁵ + ⌊(d/r)² · 2¹⁵⌋: the
/// nearest layer first, then the side facing the eye, then the splat whose centre is
/// nearest (Voronoi rasterization inside a group).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthQuant {
    pub dmin: f32,
    /// n / (d_max − d_min).
    pub scale: f32,
}

impl DepthQuant {
    /// For depths in [dmin, dmax] and the ε of the ε-z test.
    pub fn new(dmin: f32, dmax: f32, epsilon: f32) -> DepthQuant {
        let range = (dmax - dmin).max(f32::MIN_POSITIVE);
        let levels = (range / epsilon.max(f32::MIN_POSITIVE))
            .ceil()
            .clamp(1.0, 65535.0);
        DepthQuant {
            dmin,
            scale: levels / range,
        }
    }

    /// Written as the WGSL twin computes it. Within a level, a fragment facing the eye wins
    /// over one facing away (see [`reference`](fn@reference)): bit 15, then 15 bits of (d/r)².
    #[inline]
    pub fn key(&self, depth: f32, q: f32, front: bool) -> u32 {
        let level = ((depth - self.dmin) * self.scale)
            .floor()
            .clamp(0.0, 65535.0) as u32;
        let vor = (q * 32768.0).floor().clamp(0.0, 32767.0) as u32;
        (level << 16) | ((!front as u32) << 15) | vor
    }
}

/// Largest footprint side in pixels.
pub const MAX_FOOTPRINT: f32 = 256.0;

/// The default ε: the median radius.
pub fn epsilon(median_radius: f32) -> f32 {
    median_radius
}

/// The pixel rectangle (x0, y0, x1, y1), inclusive, that may hold fragments of splat `s`;
/// None when it is off screen or wholly behind the near plane. The splat lies in the box
/// about its point with half-extent r·√(1 − (n·a)²) + h·|n·a| along each camera axis a
/// (a disc of radius r about n, bent at most h = ½κ_max·r² off its plane), whose
/// perspective image is bounded by dividing each side by the nearest or farthest depth:
/// tilted splats get narrow rectangles (a sphere bound would test up to twice the pixels).
/// Written as the WGSL twin computes it.
#[inline(always)]
pub fn footprint(v: &ViewParams, s: &Disc) -> Option<[u32; 4]> {
    let (right, up, fwd) = (Vec3::from(v.right), Vec3::from(v.up), Vec3::from(v.forward));
    let d = s.p - Vec3::from(v.eye);
    let (x, y, z) = (d.dot(right), d.dot(up), d.dot(fwd));
    let r = s.r2.sqrt();
    let h = stipple_core::normals::patch_height(s.shape, s.r2, s.close);
    let ext = |a: Vec3| {
        let c = s.n.dot(a).abs().min(1.0);
        r * (1.0 - c * c).max(0.0).sqrt() + h * c
    };
    let (ex, ey, ez) = (ext(right), ext(up), ext(fwd));
    let (w, hgt) = (v.width as f32, v.height as f32);
    let (x0, x1, y0, y1, cx, cy);
    if v.perspective == 1 {
        // A splat reaching in front of the near plane is bounded by its visible part
        // (fragments nearer than the plane are dropped per pixel): large splats of sparse
        // clouds seen close must not vanish whole.
        let (zn, zf) = ((z - ez).max(v.near), z + ez);
        if zf <= v.near {
            return None;
        }
        let z = z.max(zn);
        // The extreme of (x ± e)/z over z in [zn, zf].
        let lo = |c: f32| if c >= 0.0 { c / zf } else { c / zn };
        let hi = |c: f32| if c >= 0.0 { c / zn } else { c / zf };
        x0 = (lo(x - ex) * v.sx + 1.0) * 0.5 * w - 0.5;
        x1 = (hi(x + ex) * v.sx + 1.0) * 0.5 * w - 0.5;
        y0 = (1.0 - hi(y + ey) * v.sy) * 0.5 * hgt - 0.5;
        y1 = (1.0 - lo(y - ey) * v.sy) * 0.5 * hgt - 0.5;
        cx = (x * v.sx / z + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * v.sy / z) * 0.5 * hgt - 0.5;
    } else {
        if z + ez <= v.near {
            return None;
        }
        x0 = ((x - ex) * v.sx + 1.0) * 0.5 * w - 0.5;
        x1 = ((x + ex) * v.sx + 1.0) * 0.5 * w - 0.5;
        y0 = (1.0 - (y + ey) * v.sy) * 0.5 * hgt - 0.5;
        y1 = (1.0 - (y - ey) * v.sy) * 0.5 * hgt - 0.5;
        cx = (x * v.sx + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * v.sy) * 0.5 * hgt - 0.5;
    }
    let half = MAX_FOOTPRINT * 0.5;
    let x0 = x0.max(cx - half).ceil().max(0.0);
    let x1 = x1.min(cx + half).floor().min(w - 1.0);
    let y0 = y0.max(cy - half).ceil().max(0.0);
    let y1 = y1.min(cy + half).floor().min(hgt - 1.0);
    if !(x0 <= x1 && y0 <= y1) {
        return None;
    }
    Some([x0 as u32, y0 as u32, x1 as u32, y1 as u32])
}

/// The disc's normal: its own, or facing the eye where the cloud has none.
#[inline]
pub fn splat_normal(v: &ViewParams, p: Vec3, n: Option<Vec3>) -> Vec3 {
    match n {
        Some(n) => n,
        None if v.perspective == 1 => (Vec3::from(v.eye) - p).normalize_or_zero(),
        None => -Vec3::from(v.forward),
    }
}

/// One splat, ready to intersect with pixel rays: its point, unit normal, tangent frame
/// (`stipple_core::normals::tangent_frame`), squared radius and shape
/// (`stipple_core::normals::SplatShape`): the patch h = ½(A u² + 2B uv + C v²) over the
/// disc u² + v² < r² of its tangent plane (all zero: a flat disc), cut by its clip plane.
#[derive(Clone, Copy, Debug)]
pub struct Disc {
    pub p: Vec3,
    pub n: Vec3,
    pub t1: Vec3,
    pub t2: Vec3,
    pub r2: f32,
    pub shape: [f32; 3],
    pub clip: [[f32; 4]; 2],
    /// The clip planes bent into their rims (`SplatShape::curve`).
    pub curve: [[f32; 2]; 2],
    /// The curvature D that closes the patch into a sphere or cylinder where it is one
    /// (`stipple_core::normals::closing_curvature`): ½(A u² + 2B uv + C v²) + ½D h² = h.
    pub close: f32,
}

impl Disc {
    /// The splat at `p` with normal `n` (None: facing the eye, flat), radius `r` and shape.
    #[inline]
    pub fn new(
        v: &ViewParams,
        p: Vec3,
        n: Option<Vec3>,
        r: f32,
        shape: Option<SplatShape>,
    ) -> Disc {
        let (n, shape) = match n {
            Some(n) => (n.normalize_or_zero(), shape.unwrap_or_default()),
            None => (splat_normal(v, p, None), SplatShape::default()),
        };
        let (t1, t2) = stipple_core::normals::tangent_frame(n);
        Disc {
            p,
            n,
            t1,
            t2,
            r2: r * r,
            shape: shape.bend,
            clip: shape.clip,
            curve: shape.curve,
            close: stipple_core::normals::closing_curvature(shape.bend, r),
        }
    }

    /// The patch's unit normal at tangent coordinates (u, v) (on the side of `n`).
    #[inline]
    pub fn normal_at(&self, u: f32, w: f32) -> Vec3 {
        let [a, b, c] = self.shape;
        // ∇ of ½(A u² + 2B uv + C v²) + ½D h² − h, where 1 − D h = √(1 − 2D·Q(u, v)).
        let mut n = self.n;
        if self.close != 0.0 {
            let q = 0.5 * (a * u * u + c * w * w) + b * u * w;
            n *= (1.0 - 2.0 * self.close * q).max(0.0).sqrt();
        }
        (n - (a * u + b * w) * self.t1 - (b * u + c * w) * self.t2).normalize_or_zero()
    }

    /// The patch's unit normal at fragment `fr`, turned against the pixel ray's direction
    /// `dir` (towards the eye), as blending and Voronoi shade it (splat.wgsl `blend_normal`).
    #[inline]
    pub fn normal_facing(&self, fr: &Frag, dir: Vec3) -> Vec3 {
        let n = self.normal_at(fr.u, fr.v);
        if n.dot(dir) > 0.0 {
            -n
        } else {
            n
        }
    }
}

/// A ray's hit on a splat: view depth, (d/r)² and the hit's tangent coordinates, and whether
/// the splat faces the eye there (its normal against the ray).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frag {
    pub depth: f32,
    pub q: f32,
    pub u: f32,
    pub v: f32,
    pub front: bool,
}

/// The ε-z test with a preference for surfaces that face the eye: `z_all` and `z_front` are
/// the nearest fragment depth over all fragments of a pixel and over those facing the eye.
/// Returns the reference depth and whether only eye-facing fragments count. Where an
/// eye-facing fragment exists and nothing lies more than ε in front of it, only eye-facing
/// fragments within ε of it count: the back face of a sheet thinner than ε (a wall, a leaf,
/// a thin plate, both sides sampled) does not blend into its front. Where something lies
/// further in front (a patch whose normals point the wrong way), everything counts, so
/// wrong normals never uncover what is behind.
#[inline]
pub fn reference(z_all: f32, z_front: f32, epsilon: f32) -> (f32, bool) {
    if z_front.is_finite() && z_all >= z_front - epsilon {
        (z_front, true)
    } else {
        (z_all, false)
    }
}

/// A splat set up for the pixel rays of a frame ([`Raster::eval`] gives the fragment of a
/// pixel). The ray o + t·dir meets the patch where
/// Q(d) t² + (L − d_h) t + (Q(a) − a_h) = 0, with a = o − p and d = dir in the splat's frame,
/// Q the shape's quadratic form and L its polar form of a and d: the numerically stable root
/// pair, nearer first, within the radius and not beyond a clip plane. Every quantity taken
/// from the ray (its origin and direction in the splat's frame, the clip planes' m·o and
/// m·dir, the orthographic depth offset) is affine in the pixel coordinates, c₀ + c_x·x +
/// c_y·y, so the set-up is per splat and a flat splat's hit is one division per pixel. The
/// WGSL twin (`raster_setup`, `fragment` in splat.wgsl) computes it operation for operation.
/// Pixels [`Raster::eval_rect`] evaluates at a time.
pub const LANES: usize = 8;

#[derive(Clone, Copy, Debug)]
pub struct Raster {
    /// au, av, ah, du, dv, dh, off as [c₀, c_x, c_y].
    lin: [[f32; 3]; 7],
    /// Per clip plane: m·o, m·dir as [c₀, c_x, c_y], and c.
    clip: [([f32; 3], [f32; 3], f32); 2],
    /// Per clip plane its bend into the rim: (½κ, w·t₁, w·t₂, s) (`Disc::curve`).
    rim: [[f32; 4]; 2],
    clips: u8,
    shape: [f32; 3],
    close: f32,
    bent: bool,
    r2: f32,
    near: f32,
}

impl Raster {
    #[inline(always)]
    pub fn new(v: &ViewParams, s: &Disc) -> Raster {
        let (w, h) = (v.width as f32, v.height as f32);
        let (r, u, f) = (Vec3::from(v.right), Vec3::from(v.up), Vec3::from(v.forward));
        let eye = Vec3::from(v.eye);
        // pixel_ray's offset: o0 + x·ox + y·oy.
        let ox = r * (2.0 / w / v.sx);
        let oy = u * (-2.0 / h / v.sy);
        let o0 = r * ((1.0 / w - 1.0) / v.sx) + u * ((1.0 - 1.0 / h) / v.sy);
        // Origin and direction as affine vectors [v0, vx, vy].
        let (orig, dir) = if v.perspective == 1 {
            ([eye, Vec3::ZERO, Vec3::ZERO], [f + o0, ox, oy])
        } else {
            ([eye + o0, ox, oy], [f, Vec3::ZERO, Vec3::ZERO])
        };
        let a = [orig[0] - s.p, orig[1], orig[2]];
        let proj = |vv: &[Vec3; 3], axis: Vec3| [vv[0].dot(axis), vv[1].dot(axis), vv[2].dot(axis)];
        let off = if v.perspective == 1 {
            [0.0; 3]
        } else {
            proj(&[orig[0] - eye, orig[1], orig[2]], f)
        };
        let mut clip = [([0.0; 3], [0.0; 3], 0.0); 2];
        let mut rim = [[0.0; 4]; 2];
        let mut clips = 0;
        for (c, k) in s.clip.iter().zip(&s.curve) {
            if *c != [0.0; 4] {
                let m = Vec3::new(c[0], c[1], c[2]);
                clip[clips] = (proj(&orig, m), proj(&dir, m), c[3]);
                if k[0] != 0.0 {
                    let w = s.n.cross(m).normalize_or_zero();
                    rim[clips] = [0.5 * k[0], w.dot(s.t1), w.dot(s.t2), k[1]];
                }
                clips += 1;
            }
        }
        Raster {
            lin: [
                proj(&a, s.t1),
                proj(&a, s.t2),
                proj(&a, s.n),
                proj(&dir, s.t1),
                proj(&dir, s.t2),
                proj(&dir, s.n),
                off,
            ],
            clip,
            rim,
            clips: clips as u8,
            shape: s.shape,
            close: s.close,
            bent: s.shape != [0.0; 3],
            r2: s.r2,
            near: v.near,
        }
    }

    /// The fragment of pixel (x, y)'s centre ray, or None when it misses.
    #[inline(always)]
    pub fn eval(&self, x: u32, y: u32) -> Option<Frag> {
        let (xf, yf) = (x as f32, y as f32);
        let at = |c: &[f32; 3]| c[0] + c[1] * xf + c[2] * yf;
        let [au, av, ah, du, dv, dh, off] = self.lin.each_ref().map(at);
        let t = if self.bent {
            let [ka, kb, kc] = self.shape;
            let kd = self.close;
            let mut qd = 0.5 * (ka * du * du + kc * dv * dv) + kb * du * dv;
            let mut l = ka * au * du + kb * (au * dv + av * du) + kc * av * dv;
            let mut qa = 0.5 * (ka * au * au + kc * av * av) + kb * au * av;
            if kd != 0.0 {
                // The closing term ½D h², h = ah + t·dh.
                qd += 0.5 * kd * dh * dh;
                l += kd * ah * dh;
                qa += 0.5 * kd * ah * ah;
            }
            let b = l - dh;
            let c = qa - ah;
            let disc = b * b - 4.0 * qd * c;
            if disc.is_nan() || disc < 0.0 {
                return None;
            }
            let root = -0.5 * (b + if b >= 0.0 { disc.sqrt() } else { -disc.sqrt() });
            if root == 0.0 {
                return None;
            }
            let (t0, t1) = (c / root, root / qd);
            let (t0, t1) = if t1 < t0 { (t1, t0) } else { (t0, t1) };
            // The closed surface's near half, D h < 1 (the far half of its sphere is not
            // the splat's).
            let near_half = |t: f32| kd == 0.0 || kd * (ah + t * dh) < 1.0;
            if near_half(t0) {
                if let Some(f) = self.hit(t0, [au, av, du, dv, dh, off], xf, yf) {
                    return Some(f);
                }
            }
            if !near_half(t1) {
                return None;
            }
            t1
        } else {
            -ah / dh
        };
        self.hit(t, [au, av, du, dv, dh, off], xf, yf)
    }

    /// [`Raster::eval`] for the pixels of the rectangle x0..=x1 × y0..=y1, row by row, calling
    /// `emit` with each fragment: the same arithmetic, operation for operation, so the same
    /// fragments to the bit. A bent splat without clip planes (nearly every test on a real
    /// cloud's estimated splats: 6.36 M of the Dragon's 6.96 M at 1024²) is evaluated
    /// [`LANES`] pixels at a time, each step a plain loop over the lanes without branches,
    /// which the compiler turns into vector instructions; other splats pixel by pixel.
    #[inline(always)]
    pub fn eval_rect(&self, [x0, y0, x1, y1]: [u32; 4], mut emit: impl FnMut(u32, u32, Frag)) {
        if x0 > x1 || y0 > y1 {
            return;
        }
        let w = (x1 - x0) as u64 + 1;
        let total = w * ((y1 - y0) as u64 + 1);
        // (The lanes count pixels and coordinates in i32.)
        if !self.bent || self.clips != 0 || total >= 1 << 30 || x1.max(y1) >= 1 << 30 {
            for y in y0..=y1 {
                for x in x0..=x1 {
                    if let Some(fr) = self.eval(x, y) {
                        emit(x, y, fr);
                    }
                }
            }
            return;
        }
        // A closed splat's extra terms only where it has them: the paraboloid's lanes run
        // as fast as before.
        if self.close == 0.0 {
            self.eval_lanes::<false>([x0, y0, x1, y1], w as u32, total as u32, emit)
        } else {
            self.eval_lanes::<true>([x0, y0, x1, y1], w as u32, total as u32, emit)
        }
    }

    /// [`Raster::eval_rect`]'s lanes over the `total` pixels of a rectangle `w` wide, with
    /// the closing term where `CLOSED`.
    #[inline(always)]
    fn eval_lanes<const CLOSED: bool>(
        &self,
        [x0, y0, _, _]: [u32; 4],
        w: u32,
        total: u32,
        mut emit: impl FnMut(u32, u32, Frag),
    ) {
        const L: usize = LANES;
        let [ka, kb, kc] = self.shape;
        let kd = self.close;
        let (near, r2) = (self.near, self.r2);
        // The lanes' pixels, walking the rectangle row by row (lanes past its end are not
        // emitted): column and row per lane, advanced by L pixels at a time with at most
        // ⌈L/w⌉ wraps. In the lanes, not lane by lane: a vector read of lanes written one
        // at a time waits for the stores.
        let (w, x0, y0) = (w as i32, x0 as i32, y0 as i32);
        let wraps = (L as i32 + w - 1) / w;
        let wrap = |col: &mut [i32; L], row: &mut [i32; L]| {
            for _ in 0..wraps {
                for l in 0..L {
                    let past = col[l] >= w;
                    col[l] -= if past { w } else { 0 };
                    row[l] += past as i32;
                }
            }
        };
        let (mut col, mut row) = ([0i32; L], [0i32; L]);
        for (l, c) in col.iter_mut().enumerate() {
            *c = l as i32;
        }
        wrap(&mut col, &mut row);
        let mut base = 0u32;
        while base < total {
            let (mut px, mut py) = ([0i32; L], [0i32; L]);
            let (mut xf, mut yf) = ([0.0f32; L], [0.0f32; L]);
            for l in 0..L {
                (px[l], py[l]) = (x0 + col[l], y0 + row[l]);
                (xf[l], yf[l]) = (px[l] as f32, py[l] as f32);
                col[l] += L as i32;
            }
            wrap(&mut col, &mut row);
            let mut lin = [[0.0f32; L]; 7];
            for (k, c) in self.lin.iter().enumerate() {
                for l in 0..L {
                    lin[k][l] = c[0] + c[1] * xf[l] + c[2] * yf[l];
                }
            }
            let [au, av, ah, du, dv, dh, off] = lin;
            let (mut b, mut c, mut qd, mut disc) =
                ([0.0f32; L], [0.0f32; L], [0.0f32; L], [0.0f32; L]);
            for l in 0..L {
                qd[l] = 0.5 * (ka * du[l] * du[l] + kc * dv[l] * dv[l]) + kb * du[l] * dv[l];
                let mut li =
                    ka * au[l] * du[l] + kb * (au[l] * dv[l] + av[l] * du[l]) + kc * av[l] * dv[l];
                let mut qa = 0.5 * (ka * au[l] * au[l] + kc * av[l] * av[l]) + kb * au[l] * av[l];
                if CLOSED {
                    qd[l] += 0.5 * kd * dh[l] * dh[l];
                    li += kd * ah[l] * dh[l];
                    qa += 0.5 * kd * ah[l] * ah[l];
                }
                b[l] = li - dh[l];
                c[l] = qa - ah[l];
                disc[l] = b[l] * b[l] - 4.0 * qd[l] * c[l];
            }
            let (mut root, mut t0, mut t1) = ([0.0f32; L], [0.0f32; L], [0.0f32; L]);
            for l in 0..L {
                let sq = disc[l].sqrt();
                root[l] = -0.5 * (b[l] + if b[l] >= 0.0 { sq } else { -sq });
                let (a, z) = (c[l] / root[l], root[l] / qd[l]);
                t0[l] = if z < a { z } else { a };
                t1[l] = if z < a { a } else { z };
            }
            let mut hit = [[0.0f32; L]; 4];
            let (mut ok, mut front) = ([false; L], [false; L]);
            for l in 0..L {
                let (d0, d1) = (t0[l] + off[l], t1[l] + off[l]);
                let (u0, w0) = (au[l] + t0[l] * du[l], av[l] + t0[l] * dv[l]);
                let (u1, w1) = (au[l] + t1[l] * du[l], av[l] + t1[l] * dv[l]);
                let (q0, q1) = (u0 * u0 + w0 * w0, u1 * u1 + w1 * w1);
                let half0 = !CLOSED || kd * (ah[l] + t0[l] * dh[l]) < 1.0;
                let half1 = !CLOSED || kd * (ah[l] + t1[l] * dh[l]) < 1.0;
                let ok0 = (d0 > near) & (q0 < r2) & half0;
                let ok1 = (d1 > near) & (q1 < r2) & half1;
                // `eval`: no root (disc < 0 or NaN) or a zero root misses; else the nearer
                // hit, else the farther.
                // (`&` and `|`, not `&&` and `||`: no branches in the lanes.)
                ok[l] = (disc[l] >= 0.0) & (root[l] != 0.0) & (ok0 | ok1);
                front[l] = dh[l] < 0.0;
                hit[0][l] = if ok0 { d0 } else { d1 };
                hit[1][l] = (if ok0 { q0 } else { q1 }) / r2;
                hit[2][l] = if ok0 { u0 } else { u1 };
                hit[3][l] = if ok0 { w0 } else { w1 };
            }
            for l in 0..(total - base).min(L as u32) as usize {
                if ok[l] {
                    emit(
                        px[l] as u32,
                        py[l] as u32,
                        Frag {
                            depth: hit[0][l],
                            q: hit[1][l],
                            u: hit[2][l],
                            v: hit[3][l],
                            front: front[l],
                        },
                    );
                }
            }
            base += L as u32;
        }
    }

    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn hit(&self, t: f32, [au, av, du, dv, dh, off]: [f32; 6], x: f32, y: f32) -> Option<Frag> {
        let depth = t + off;
        let (u, w) = (au + t * du, av + t * dv);
        let d2 = u * u + w * w;
        if !(depth > self.near && d2 < self.r2) {
            return None;
        }
        for ((mo, md, c), [hk, wu, wv, s]) in self.clip[..self.clips as usize].iter().zip(self.rim)
        {
            let at = |k: &[f32; 3]| k[0] + k[1] * x + k[2] * y;
            let along = wu * u + wv * w - s;
            if at(mo) + t * at(md) + hk * along * along > *c {
                return None;
            }
        }
        Some(Frag {
            depth,
            q: d2 / self.r2,
            u,
            v: w,
            front: dh < 0.0,
        })
    }
}

/// The blending kernel at (d/r)² = `q`.
#[inline]
pub fn weight(q: f32) -> f32 {
    (-3.0 * q).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A splat reaching in front of the near plane keeps the footprint of its visible part
    /// (large splats of a sparse cloud seen close used to vanish whole).
    #[test]
    fn a_splat_across_the_near_plane_keeps_its_visible_part() {
        let v = ViewParams::axis_aligned(64, 64, true, 1.0);
        // Near is 0.1: a disc at depth 0.5 tilted 60° with radius 1 reaches depth −0.37.
        let n = Vec3::new(0.0, (60f32).to_radians().sin(), -(60f32).to_radians().cos());
        let d = Disc::new(&v, Vec3::new(0.0, 0.0, 0.5), Some(n), 1.0, None);
        let f = footprint(&v, &d).expect("the visible part has a footprint");
        let r = Raster::new(&v, &d);
        let hits = (f[1]..=f[3])
            .flat_map(|y| (f[0]..=f[2]).map(move |x| (x, y)))
            .filter_map(|(x, y)| r.eval(x, y))
            .count();
        assert!(hits > 100, "{hits} fragments in {f:?}");
        // Wholly behind the near plane: nothing.
        let behind = Disc::new(&v, Vec3::new(0.0, 0.0, -1.0), Some(-Vec3::Z), 0.5, None);
        assert_eq!(footprint(&v, &behind), None);
    }

    /// A splat bent like the unit sphere it sits on meets pixel rays where the sphere does
    /// (to fourth order), a flat one does not; its clip plane cuts it.
    #[test]
    fn bent_splats_follow_the_sphere_and_clip_planes_cut() {
        let v = ViewParams::axis_aligned(64, 64, false, 3.125);
        // Orthographic view along +z, pixels 0.01 apart (x from −0.315 to 0.315).
        let p = Vec3::new(0.0, 0.0, 5.0);
        let n = -Vec3::Z;
        let bent = SplatShape {
            bend: [-1.0, 0.0, -1.0],
            clip: [[0.0; 4]; 2],
            curve: [[0.0; 2]; 2],
        };
        let d = Disc::new(&v, p, Some(n), 0.3, Some(bent));
        let flat = Disc::new(&v, p, Some(n), 0.3, None);
        let (mut worst_bent, mut worst_flat) = (0.0f32, 0.0f32);
        for i in 4..60 {
            let (o, _) = v.pixel_ray(i, 32);
            // The unit sphere tangent at p, behind it.
            let c = p + Vec3::Z;
            let (x, y) = (o.x - c.x, o.y - c.y);
            let truth = c.z - (1.0 - x * x - y * y).sqrt();
            let a = Raster::new(&v, &d).eval(i, 32).expect("inside the radius");
            let b = Raster::new(&v, &flat)
                .eval(i, 32)
                .expect("inside the radius");
            worst_bent = worst_bent.max((a.depth - truth).abs());
            worst_flat = worst_flat.max((b.depth - truth).abs());
        }
        assert!(
            worst_bent < 1e-3,
            "bent splat off the sphere by {worst_bent}"
        );
        assert!(
            worst_flat > 0.02,
            "a flat disc is off by r²/2: {worst_flat}"
        );
        // Clip at x ≤ 0.05: pixels right of it miss.
        let clipped = Disc::new(
            &v,
            p,
            Some(n),
            0.3,
            Some(SplatShape {
                clip: [[1.0, 0.0, 0.0, 0.05], [0.0; 4]],
                curve: [[0.0; 2]; 2],
                ..bent
            }),
        );
        for i in 4..60 {
            let (o, _) = v.pixel_ray(i, 32);
            assert_eq!(Raster::new(&v, &clipped).eval(i, 32).is_some(), o.x <= 0.05);
        }
    }

    /// A splat bent like the unit sphere or cylinder it sits on is closed into it
    /// (`Disc::close`): it meets pixel rays where the surface does across a radius wider
    /// than the surface (where a paraboloid would stand off by up to r⁴κ³/8 and reach past
    /// the silhouette), takes the surface's normal there, and meets no ray beyond the
    /// silhouette (the closed surface's far half is not the splat's). A saddle stays a
    /// paraboloid.
    #[test]
    fn closed_splats_are_the_sphere_or_cylinder_they_bend_like() {
        let v = ViewParams::axis_aligned(120, 120, false, 2.0 / 2.4);
        let p = Vec3::new(0.0, 0.0, 5.0);
        let c = p + Vec3::Z;
        for cylinder in [false, true] {
            let bend = if cylinder {
                [-1.0, 0.0, 0.0]
            } else {
                [-1.0, 0.0, -1.0]
            };
            let shape = SplatShape {
                bend,
                ..Default::default()
            };
            let d = Disc::new(&v, p, Some(-Vec3::Z), 1.1, Some(shape));
            assert_eq!(d.close, -1.0);
            // The frame's u axis is world x or y: the cylinder's axis along the other.
            let along_x = d.t1.x.abs() < 0.5;
            let r = Raster::new(&v, &d);
            let (mut worst_depth, mut worst_normal, mut hits) = (0.0f32, 1.0f32, 0);
            for j in 0..120 {
                for i in 0..120 {
                    let (o, _) = v.pixel_ray(i, j);
                    let (mut x, mut y) = (o.x - c.x, o.y - c.y);
                    if cylinder && along_x {
                        x = 0.0;
                    } else if cylinder {
                        y = 0.0;
                    }
                    let rho2 = x * x + y * y;
                    let in_disc = (o.x - p.x).powi(2) + (o.y - p.y).powi(2) < 1.1 * 1.1;
                    match r.eval(i, j) {
                        Some(f) => {
                            hits += 1;
                            assert!(rho2 < 1.0 + 1e-3, "a hit past the silhouette at {o:?}");
                            if rho2 < 0.9 {
                                let truth = c.z - (1.0 - rho2).sqrt();
                                worst_depth = worst_depth.max((f.depth - truth).abs());
                                let on = Vec3::new(x, y, f.depth - c.z).normalize();
                                worst_normal = worst_normal.min(d.normal_at(f.u, f.v).dot(on));
                            }
                        }
                        None => assert!(!(rho2 < 0.98 && in_disc), "a miss at {o:?}"),
                    }
                }
            }
            assert!(hits > 1000, "{hits}");
            assert!(worst_depth < 1e-4, "off the surface by {worst_depth}");
            assert!(worst_normal > 0.9999, "normal off: cos {worst_normal}");
        }
        let saddle = SplatShape {
            bend: [-1.0, 0.0, 0.5],
            ..Default::default()
        };
        assert_eq!(
            Disc::new(&v, p, Some(-Vec3::Z), 1.0, Some(saddle)).close,
            0.0
        );
        // Under CLOSE_FROM (|D|·r = 0.4) the paraboloid is near enough: not closed.
        let small = SplatShape {
            bend: [-1.0, 0.0, -1.0],
            ..Default::default()
        };
        assert_eq!(
            Disc::new(&v, p, Some(-Vec3::Z), 0.4, Some(small)).close,
            0.0
        );
    }

    /// `eval_rect` emits exactly the fragments `eval` gives pixel by pixel, in the same
    /// order, for bent splats of either sign seen from many sides, near and far, in both
    /// projections, rectangles of every shape (a lane count's multiple or not).
    #[test]
    fn a_rectangle_of_pixels_gives_what_each_pixel_gives() {
        let mut rng = stipple_core::rng::Rng::new(7);
        let (mut emitted, mut tests) = (0usize, 0usize);
        for case in 0..400 {
            let v = ViewParams::axis_aligned(48, 40, case % 2 == 0, 1.0);
            let p = Vec3::new(
                rng.f32() - 0.5,
                rng.f32() - 0.5,
                if case % 2 == 0 {
                    1.0 + 2.0 * rng.f32()
                } else {
                    3.0
                },
            );
            let n = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, -rng.f32()).normalize();
            let bend = [0.0f32; 3].map(|_| 4.0 * rng.f32() - 2.0);
            let shape = SplatShape {
                bend,
                clip: [[0.0; 4]; 2],
                curve: [[0.0; 2]; 2],
            };
            let d = Disc::new(&v, p, Some(n), 0.1 + 0.4 * rng.f32(), Some(shape));
            let r = Raster::new(&v, &d);
            let Some(f) = footprint(&v, &d) else {
                continue;
            };
            let want: Vec<(u32, u32, Frag)> = (f[1]..=f[3])
                .flat_map(|y| (f[0]..=f[2]).map(move |x| (x, y)))
                .filter_map(|(x, y)| r.eval(x, y).map(|fr| (x, y, fr)))
                .collect();
            let mut got = Vec::new();
            r.eval_rect(f, |x, y, fr| got.push((x, y, fr)));
            assert_eq!(got.len(), want.len(), "case {case}");
            for (a, b) in got.iter().zip(&want) {
                assert_eq!((a.0, a.1), (b.0, b.1), "case {case}");
                let bits = |fr: &Frag| [fr.depth, fr.q, fr.u, fr.v].map(f32::to_bits);
                assert_eq!(bits(&a.2), bits(&b.2), "case {case} at {:?}", (a.0, a.1));
                assert_eq!(a.2.front, b.2.front);
            }
            emitted += got.len();
            tests += ((f[2] - f[0] + 1) * (f[3] - f[1] + 1)) as usize;
        }
        assert!(emitted > 10_000 && tests > emitted, "{emitted} of {tests}");
    }
}
