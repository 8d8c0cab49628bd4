//! # splat: surface splats with ε-z visibility (Zhang & Pajarola §3.1, §3.2, §5.1)
//!
//! How it works: every point is a disc of radius r (its `radius`, see
//! `stipple_core::normals`) in the plane through it normal to its normal. A disc covers the
//! pixels whose centre ray meets its plane within r of the point ([`fragment`]). Per pixel:
//!
//! 1. **visibility**: the nearest fragment depth z_min;
//! 2. **ε-z test**: only fragments with depth ≤ z_min + ε count (ε = the median splat
//!    radius: fragments of one surface layer at a pixel differ by far less, see [`epsilon`]);
//! 3. a choice among them, by mode ([`SplatMode`]):
//!    - **Voronoi rasterization** (§5.1): the fragment with the smallest d/r wins the pixel
//!      (ties: the smaller point index). The pixel shows that point, at the depth where its
//!      disc meets the pixel's ray: sharp, hole-free surfaces with no blending. The result
//!      is a visibility G-buffer (depth + point id), so shading, smoothing and antialiasing
//!      are the same passes as Dobrev's pipeline on both backends.
//!    - **Blend** (§3.1, Eq. 1): the Gaussian-weighted mean w = exp(−3 (d/r)²) of the
//!      counting fragments' albedo, normal (each turned towards the eye first, so normals of
//!      random sign do not cancel) and depth, normalised per pixel, and shaded per pixel from
//!      the blended normal (deferred shading). The pixel's id is the fragment of largest
//!      weight (its object, material and shadow texture apply).
//!
//! Deviations from the paper, and why:
//! - The paper's single-pass deferred blending (§3.2, graph-coloured groups) exists because a
//!   2008 GPU had no fuzzy depth test; with compute shaders and atomics (and tiles on the
//!   CPU) the exact ε-z test above costs two passes over the points, keeps no K group images,
//!   and needs no colouring pre-process. Voronoi uses the exact z_min + ε test instead of the
//!   paper's quantised depth of Eq. 10, which shows bands where fragments of one surface fall
//!   on either side of a quantisation step.
//! - Clouds without normals get discs facing the eye.
//! - A disc whose footprint would exceed [`MAX_FOOTPRINT`] pixels across is clipped to that
//!   square (a camera inside a splat).

pub mod cpu;
pub mod gpu;

use crate::params::ViewParams;
use glam::Vec3;

/// How splat fragments that pass the ε-z test make a pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SplatMode {
    /// The fragment nearest its splat's centre (relative to its radius) wins.
    #[default]
    Voronoi,
    /// Gaussian-weighted mean of albedo, normal and depth, shaded per pixel.
    Blend,
}

impl std::str::FromStr for SplatMode {
    type Err = String;
    fn from_str(s: &str) -> Result<SplatMode, String> {
        match s {
            "voronoi" => Ok(SplatMode::Voronoi),
            "blend" => Ok(SplatMode::Blend),
            _ => Err(format!("unknown splat mode `{s}` (voronoi, blend)")),
        }
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
}

impl Default for SplatSettings {
    fn default() -> Self {
        SplatSettings {
            mode: SplatMode::Voronoi,
            scale: 1.0,
            epsilon: None,
        }
    }
}

/// Largest footprint side in pixels.
pub const MAX_FOOTPRINT: f32 = 256.0;

/// The default ε: the median radius.
pub fn epsilon(median_radius: f32) -> f32 {
    median_radius
}

/// The pixel rectangle (x0, y0, x1, y1), inclusive, that may hold fragments of the disc of
/// radius `r` at `p`; None when it is off screen or not in front of the near plane.
#[inline]
pub fn footprint(v: &ViewParams, p: Vec3, r: f32) -> Option<[u32; 4]> {
    let d = p - Vec3::from(v.eye);
    let z = d.dot(Vec3::from(v.forward));
    let (w, h) = (v.width as f32, v.height as f32);
    let (cx, cy, rx, ry);
    let x = d.dot(Vec3::from(v.right));
    let y = d.dot(Vec3::from(v.up));
    if v.perspective == 1 {
        if z - r <= v.near {
            return None;
        }
        cx = (x * v.sx / z + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * v.sy / z) * 0.5 * h - 0.5;
        rx = r * v.sx * 0.5 * w / (z - r);
        ry = r * v.sy * 0.5 * h / (z - r);
    } else {
        if z <= v.near {
            return None;
        }
        cx = (x * v.sx + 1.0) * 0.5 * w - 0.5;
        cy = (1.0 - y * v.sy) * 0.5 * h - 0.5;
        rx = r * v.sx * 0.5 * w;
        ry = r * v.sy * 0.5 * h;
    }
    let half = MAX_FOOTPRINT * 0.5;
    let (rx, ry) = (rx.min(half), ry.min(half));
    let x0 = (cx - rx).ceil().max(0.0);
    let x1 = (cx + rx).floor().min(w - 1.0);
    let y0 = (cy - ry).ceil().max(0.0);
    let y1 = (cy + ry).floor().min(h - 1.0);
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

/// Where pixel (i, j)'s centre ray meets the disc at `p` with normal `n` and squared radius
/// `r2`: the view depth and (d/r)², or None when it misses. Written as the WGSL twin
/// computes it.
#[inline]
pub fn fragment(v: &ViewParams, i: u32, j: u32, p: Vec3, n: Vec3, r2: f32) -> Option<(f32, f32)> {
    let (o, dir) = v.pixel_ray(i, j);
    let nd = n.dot(dir);
    if nd.abs() < 1e-6 * dir.length() {
        return None;
    }
    let t = n.dot(p - o) / nd;
    let hit = o + dir * t;
    let d2 = (hit - p).length_squared();
    // NaN (a degenerate disc) misses too.
    if d2 >= r2 || d2.is_nan() {
        return None;
    }
    let depth = if v.perspective == 1 {
        t
    } else {
        t + (o - Vec3::from(v.eye)).dot(Vec3::from(v.forward))
    };
    if depth <= v.near || depth.is_nan() {
        return None;
    }
    Some((depth, d2 / r2))
}

/// The blending kernel at (d/r)² = `q`.
#[inline]
pub fn weight(q: f32) -> f32 {
    (-3.0 * q).exp()
}
