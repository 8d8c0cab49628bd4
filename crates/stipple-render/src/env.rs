//! # Environments and Fresnel reflection (Zhang & Pajarola §5.2.3)
//!
//! An environment is the light arriving from every direction at infinity: a procedural sky
//! (a gradient over a checkered ground, so reflections are visible without any file) or an
//! equirectangular image. Transparent splats show it behind the cloud (the background
//! becomes the environment in the pixel's direction, seen through every layer), and with a
//! refractive index η the nearest layer reflects it: the pixel becomes
//! F·E(r) + (1 − F)·C, with C the composite of the layers, r the view ray reflected about
//! the nearest fragment's normal (turned towards the eye) and F the Fresnel reflectance of
//! an uncoated dielectric for unpolarised light, the exact formula (not Schlick's):
//! F = (r_s² + r_p²) / 2 with r_s = (cos i − η cos t)/(cos i + η cos t) and
//! r_p = (η cos i − cos t)/(η cos i + cos t), sin t = sin i / η, 1 beyond the critical
//! angle. At normal incidence F = ((η − 1)/(η + 1))².
//!
//! Refraction (§5.2.3, Eq. 12): the layers composite over black while counting how many
//! there are (l, averaged over the groups) and how much they let through (T = Π(1 − α):
//! the absorption of Eq. 11, exact per pixel rather than from a constant α); the
//! environment is then added as T·E(t), with t the view ray bent at the nearest layer by
//! sin θ_T = (1/η)^l sin θ_I, the paper's heuristic of equal refraction at every interface.
//! Chromatic dispersion refracts red with η(1 − δ) and blue with η(1 + δ).
//!
//! Opaque geometry behind the layers (a frame with opaque points and an index) is refracted
//! too, by a model the paper does not have: the opaque points are drawn first, alone; a
//! pixel's ray is refracted in at its nearest layer and out at its farthest (Snell's law at
//! both, the farthest layer taken as the plane through its point with its blended normal),
//! and what the layers let through is looked up where that ray meets the opaque surface
//! (`passes::splat::transparent::refract_behind`), or in the environment along it where it
//! passes the surface. A slab of thickness t shifts what lies behind it by
//! t·sin(θ − θ_t)/cos θ_t, exactly (tested). In such a frame the environment is seen along
//! the same ray, so the two never disagree at an opaque silhouette; Eq. 12 serves frames of
//! transparent points alone, the paper's setting.
//!
//! Per object (a scene's `[cloud.material]`, `crate::material::Optics`) the index,
//! dispersion, a factor on the Fresnel reflectance and a per-channel absorption
//! (what l layers let through is multiplied by (1 − a)^l: tinted glass) are those of the
//! nearest layer's object ([`Surface`]); the frame's `--ior` and `--dispersion` otherwise.
//!
//! Directions are world directions; the environment's frame has the scene's up axis (+Y for
//! scanned objects, +Z for LiDAR) and +X as its reference east. The WGSL twin
//! (`env_sample`, `fresnel` in sorted.wgsl) computes the same operations.

use crate::params::ViewParams;
use glam::Vec3;
use std::sync::Arc;

/// What a frame takes from its surroundings (`Pipeline::environment`).
#[derive(Clone, Debug, PartialEq)]
pub struct EnvSettings {
    pub env: Arc<Environment>,
    /// The scene's up axis (+Y for scanned objects, +Z for LiDAR).
    pub up: Vec3,
    /// Refractive index of the transparent surfaces: their nearest layer reflects the
    /// environment by Fresnel's law, and the layers refract it (None: neither).
    pub ior: Option<f32>,
    /// Chromatic dispersion: red is refracted with index η(1 − δ), green η, blue η(1 + δ).
    pub dispersion: f32,
}

/// The optics of the surface a pixel's nearest layer belongs to: its object's
/// (`crate::material::Optics::resolve`), else the frame's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Refractive index (None: the surface neither reflects nor refracts).
    pub eta: Option<f32>,
    pub dispersion: f32,
    /// Multiplies the Fresnel reflectance.
    pub reflectivity: f32,
    /// The share of each channel each layer absorbs besides its opacity.
    pub absorption: [f32; 3],
}

impl Surface {
    /// The frame's settings alone.
    pub fn of_frame(e: &EnvSettings) -> Surface {
        crate::material::Optics::default().resolve(e)
    }

    /// Per channel, what `layers` layers that let `through` pass by their opacity let
    /// through with the absorption: through · (1 − a)^l.
    pub fn passed(&self, through: f32, layers: f32) -> [f32; 3] {
        self.absorption.map(|a| {
            if a > 0.0 {
                through * (1.0 - a).max(1e-6).powf(layers)
            } else {
                through
            }
        })
    }
}

/// The light from every direction.
#[derive(Clone, Debug, PartialEq)]
pub enum Environment {
    /// A procedural sky: zenith blue to a pale horizon, a grey checkered ground below.
    Sky,
    /// An equirectangular image (linear RGB, row 0 at the zenith, the left edge at −east).
    Image {
        width: u32,
        height: u32,
        texels: Vec<[f32; 3]>,
    },
}

/// The most texels an environment image keeps (4096 × 2048: 128 MiB on the GPU, where
/// each is a vec4 of f32, the storage binding every adapter allows); larger images are
/// halved until they fit.
pub const MAX_ENV_TEXELS: usize = 4096 * 2048;

/// Sky colours (linear RGB).
pub const ZENITH: [f32; 3] = [0.18, 0.36, 0.75];
pub const HORIZON: [f32; 3] = [0.80, 0.85, 0.92];
pub const GROUND: [[f32; 3]; 2] = [[0.30, 0.30, 0.30], [0.12, 0.12, 0.12]];

/// The environment's frame for up axis `up`: (east, north, up), orthonormal.
pub fn frame(up: Vec3) -> (Vec3, Vec3, Vec3) {
    let u = up.normalize_or(Vec3::Y);
    let east = (Vec3::X - u * u.dot(Vec3::X)).normalize_or(Vec3::Z);
    (east, u.cross(east), u)
}

fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    std::array::from_fn(|c| a[c] + (b[c] - a[c]) * t)
}

impl Environment {
    /// An equirectangular image from 8-bit sRGB RGBA rows (turned linear).
    pub fn from_rgba8(width: u32, height: u32, rgba: &[u8]) -> Result<Environment, String> {
        if width < 2 || height < 2 || rgba.len() != 4 * width as usize * height as usize {
            return Err(format!(
                "an environment image needs at least 2×2 pixels of RGBA ({width}×{height}, {} bytes)",
                rgba.len()
            ));
        }
        let lut = crate::srgb::srgb_to_linear_table();
        let texels: Vec<[f32; 3]> = rgba
            .chunks_exact(4)
            .map(|p| [lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize]])
            .collect();
        Environment::from_linear(width, height, texels)
    }

    /// An equirectangular image from linear RGB rows (a high-dynamic-range file's), halved
    /// (2 × 2 means) until it fits what every GPU binds.
    pub fn from_linear(
        width: u32,
        height: u32,
        mut texels: Vec<[f32; 3]>,
    ) -> Result<Environment, String> {
        if width < 2 || height < 2 || texels.len() != width as usize * height as usize {
            return Err(format!(
                "an environment image needs at least 2×2 pixels ({width}×{height}, {} texels)",
                texels.len()
            ));
        }
        if let Some(t) = texels
            .iter()
            .find(|t| !t.iter().all(|v| v.is_finite() && *v >= 0.0))
        {
            return Err(format!(
                "a texel is not a finite, non-negative colour: {t:?}"
            ));
        }
        let (mut w, mut h) = (width as usize, height as usize);
        // Halved (2 × 2 means in linear colour) until it fits what every GPU binds.
        while w * h > MAX_ENV_TEXELS && w >= 2 && h >= 2 {
            let (nw, nh) = (w / 2, h / 2);
            let at = |x: usize, y: usize| texels[y.min(h - 1) * w + x.min(w - 1)];
            texels = (0..nh)
                .flat_map(|y| (0..nw).map(move |x| (x, y)))
                .map(|(x, y)| {
                    let q = [
                        at(2 * x, 2 * y),
                        at(2 * x + 1, 2 * y),
                        at(2 * x, 2 * y + 1),
                        at(2 * x + 1, 2 * y + 1),
                    ];
                    std::array::from_fn(|c| 0.25 * (q[0][c] + q[1][c] + q[2][c] + q[3][c]))
                })
                .collect();
            (w, h) = (nw, nh);
        }
        Ok(Environment::Image {
            width: w as u32,
            height: h as u32,
            texels,
        })
    }

    /// The light arriving from direction `d` (any length), with the scene's up axis `up`,
    /// seen by a pixel `cone` radians across ([`pixel_cone`]; 0: a single ray). The sky's
    /// checkered ground is averaged over that cone (exactly, for the box filter over the
    /// spot the cone makes on the ground), so that squares smaller than a pixel near the
    /// horizon turn to their mean grey instead of aliasing into moiré, and so that the last
    /// bit of a ray's direction no longer picks a pixel's square: the CPU and a GPU agree.
    /// Images are sampled bilinearly whatever the cone.
    pub fn sample(&self, d: Vec3, up: Vec3, cone: f32) -> [f32; 3] {
        let (east, north, u) = frame(up);
        let d = d.normalize_or(u);
        let (x, y, z) = (d.dot(east), d.dot(north), d.dot(u));
        match self {
            Environment::Sky => {
                if z >= 0.0 {
                    mix(HORIZON, ZENITH, z.sqrt())
                } else {
                    // The ground plane one unit below, in squares of ½; the cone's spot on
                    // it is cone / z² across along the ray's azimuth (narrower across it:
                    // filtered as wide both ways).
                    let (gx, gy) = (x / -z, y / -z);
                    let c = checker(gx, gy, cone / (z * z));
                    let g = std::array::from_fn(|ch| {
                        0.5 * (GROUND[0][ch] + GROUND[1][ch])
                            + 0.5 * (GROUND[0][ch] - GROUND[1][ch]) * c
                    });
                    mix(HORIZON, g, (-8.0 * z).min(1.0))
                }
            }
            Environment::Image {
                width,
                height,
                texels,
            } => {
                let (w, h) = (*width as f32, *height as f32);
                let lon = y.atan2(x);
                let lat = z.clamp(-1.0, 1.0).acos();
                let s = (0.5 - lon / std::f32::consts::TAU) * w - 0.5;
                let t = lat / std::f32::consts::PI * h - 0.5;
                let (s0, t0) = (s.floor(), t.floor());
                let (fs, ft) = (s - s0, t - t0);
                let at = |i: f32, j: f32| {
                    let i = (i as i64).rem_euclid(*width as i64) as usize;
                    let j = (j as i64).clamp(0, *height as i64 - 1) as usize;
                    texels[j * *width as usize + i]
                };
                let top = mix(at(s0, t0), at(s0 + 1.0, t0), fs);
                let bottom = mix(at(s0, t0 + 1.0), at(s0 + 1.0, t0 + 1.0), fs);
                mix(top, bottom, ft)
            }
        }
    }
}

/// The angle a pixel spans at the centre of the view (perspective; 0 for orthographic
/// views, whose rays are parallel): the cone over which [`Environment::sample`] averages.
/// As sorted.wgsl `pixel_cone`.
pub fn pixel_cone(v: &ViewParams) -> f32 {
    if v.perspective == 1 {
        2.0 / (v.height.max(1) as f32 * v.sy)
    } else {
        0.0
    }
}

/// The sky's ground checker at (gx, gy) on the plane one unit below (squares of ½): +1 on
/// [`GROUND`]`[0]`'s squares, −1 on the others', box-filtered over a square `w` ground
/// units wide: the product of two filtered square waves, each the difference of its
/// integral (a triangle wave) across the box over the box's width. Below a thousandth of a
/// square the filter is skipped (the difference would be rounding). As sorted.wgsl
/// `checker`.
pub fn checker(gx: f32, gy: f32, w: f32) -> f32 {
    // In units of one square: the wave is +1 on [0, 1), −1 on [1, 2), of period 2.
    let w = 2.0 * w.max(0.0);
    let wave = |u: f32| {
        if w < 1e-3 {
            1.0 - 2.0 * u.floor().rem_euclid(2.0)
        } else {
            let tri = |t: f32| 1.0 - (t.rem_euclid(2.0) - 1.0).abs();
            (tri(u + 0.5 * w) - tri(u - 0.5 * w)) / w
        }
    };
    wave(2.0 * gx) * wave(2.0 * gy)
}

/// The Fresnel reflectance of a dielectric of relative index `eta` for unpolarised light
/// arriving at `cos_i` from the normal (see the module documentation).
pub fn fresnel(cos_i: f32, eta: f32) -> f32 {
    let ci = cos_i.clamp(0.0, 1.0);
    let si2 = (1.0 - ci * ci).max(0.0);
    let st2 = si2 / (eta * eta);
    if st2 >= 1.0 {
        return 1.0;
    }
    let ct = (1.0 - st2).sqrt();
    let rs = (ci - eta * ct) / (ci + eta * ct);
    let rp = (eta * ci - ct) / (eta * ci + ct);
    0.5 * (rs * rs + rp * rp)
}

/// The direction the environment is seen in through `layers` layers (a mean over the
/// groups, so fractional) of index `eta` along the ray `d` (unit) meeting the nearest layer
/// with unit normal `n` facing the eye: Eq. 12's heuristic, sin θ_T = (1/η)^l sin θ_I (equal
/// refraction at every interface, bending towards the normal layer after layer); the ray
/// itself without layers or with η = 1.
pub fn refracted(d: Vec3, n: Vec3, eta: f32, layers: f32) -> Vec3 {
    let cos_i = (-n.dot(d)).clamp(-1.0, 1.0);
    let sin_i = (1.0 - cos_i * cos_i).max(0.0).sqrt();
    if layers <= 0.0 || sin_i < 1e-6 || eta <= 0.0 {
        return d;
    }
    let sin_t = (1.0 / eta).powf(layers) * sin_i;
    if sin_t >= 1.0 {
        return d;
    }
    let tangent = (d + n * cos_i) / sin_i;
    tangent * sin_t - n * (1.0 - sin_t * sin_t).sqrt()
}

/// A pixel's finished colour: `c`, the composite of its layers over black, plus what they
/// let through (`through`, the mean over the groups) of the environment seen along the ray
/// `dir` (a pixel [`pixel_cone`] `cone` across) refracted by `layers` layers (per colour
/// channel with the settings' dispersion), and, with an index of refraction, the
/// environment reflected by the nearest layer (normal `n`, either side; None where no
/// layer is).
pub fn finish(
    c: [f32; 3],
    e: &EnvSettings,
    surface: &Surface,
    (dir, cone): (Vec3, f32),
    n: Option<Vec3>,
    through: f32,
    layers: f32,
) -> [f32; 3] {
    let d = dir.normalize_or_zero();
    let n = n
        .map(|n| n.normalize_or_zero())
        .filter(|n| *n != Vec3::ZERO && d != Vec3::ZERO);
    let n = n.map(|n| if n.dot(d) > 0.0 { -n } else { n });
    let mut out = c;
    let pass = surface.passed(through, layers);
    match (n, surface.eta) {
        (Some(n), Some(eta)) if through > 0.0 => {
            let seen = per_channel(eta, surface.dispersion, |eta| {
                e.env.sample(refracted(d, n, eta, layers), e.up, cone)
            });
            for ch in 0..3 {
                out[ch] += pass[ch] * seen[ch];
            }
        }
        _ if through > 0.0 => {
            let s = e.env.sample(d, e.up, cone);
            for ch in 0..3 {
                out[ch] += pass[ch] * s[ch];
            }
        }
        _ => {}
    }
    match (n, surface.eta) {
        (Some(n), Some(eta)) => {
            let optics = (eta, surface.reflectivity);
            reflect_into(out, &e.env, e.up, optics, d, n, cone)
        }
        _ => out,
    }
}

/// What is seen through a refracting surface of index `eta` with chromatic dispersion δ:
/// per colour channel, that channel of `seen(η_c)` with η_c = η(1 − δ) for red, η for green
/// and η(1 + δ) for blue (one look without dispersion).
pub fn per_channel(eta: f32, dispersion: f32, seen: impl Fn(f32) -> [f32; 3]) -> [f32; 3] {
    if dispersion == 0.0 {
        return seen(eta);
    }
    std::array::from_fn(|ch| seen(eta * (1.0 + dispersion * (ch as f32 - 1.0)))[ch])
}

/// A pixel's colour `c` (the composite of its layers) with the environment reflected by its
/// nearest layer: ray direction `dir`, that layer's normal `n` (either side).
pub fn reflect_into(
    c: [f32; 3],
    env: &Environment,
    up: Vec3,
    (eta, reflectivity): (f32, f32),
    dir: Vec3,
    n: Vec3,
    cone: f32,
) -> [f32; 3] {
    let d = dir.normalize_or_zero();
    let mut n = n.normalize_or_zero();
    if d == Vec3::ZERO || n == Vec3::ZERO {
        return c;
    }
    if n.dot(d) > 0.0 {
        n = -n;
    }
    let cos_i = -n.dot(d);
    let f = fresnel(cos_i, eta) * reflectivity;
    let r = d + 2.0 * cos_i * n;
    let e = env.sample(r, up, cone);
    std::array::from_fn(|k| f * e[k] + (1.0 - f) * c[k])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_meets_the_known_values() {
        for eta in [1.33f32, 1.5, 2.4] {
            let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
            assert!((fresnel(1.0, eta) - f0).abs() < 1e-6 * f0.max(1.0), "{eta}");
            // Grazing: everything is reflected.
            assert!((fresnel(0.0, eta) - 1.0).abs() < 1e-6);
            // Brewster's angle: r_p = 0, F = r_s² / 2.
            let b = eta.atan();
            let (ci, ct) = (b.cos(), (b.sin() / eta).asin().cos());
            let rs = (ci - eta * ct) / (ci + eta * ct);
            assert!((fresnel(ci, eta) - 0.5 * rs * rs).abs() < 1e-5, "{eta}");
        }
        // From inside a denser medium (η < 1) beyond the critical angle: total reflection.
        assert_eq!(fresnel(0.2, 1.0 / 1.5), 1.0);
    }

    #[test]
    fn the_sky_is_blue_above_and_checkered_below() {
        let up = Vec3::Y;
        let z = Environment::Sky.sample(Vec3::Y, up, 0.0);
        assert_eq!(z, ZENITH);
        let h = Environment::Sky.sample(Vec3::X, up, 0.0);
        assert_eq!(h, HORIZON);
        let a = Environment::Sky.sample(Vec3::new(0.1, -1.0, 0.1), up, 0.0);
        let b = Environment::Sky.sample(Vec3::new(0.6, -1.0, 0.1), up, 0.0);
        assert_ne!(a, b, "neighbouring squares differ");
        // Z up: the same sky about +Z.
        assert_eq!(Environment::Sky.sample(Vec3::Z, Vec3::Z, 0.0), ZENITH);
    }

    /// The filtered checker is the mean of the sharp one over its box, and the sky's
    /// ground turns to the squares' mean grey where they are far smaller than the pixel.
    #[test]
    fn the_ground_checker_is_the_mean_over_the_pixel() {
        let sharp = |gx: f32, gy: f32| checker(gx, gy, 0.0);
        for &(gx, gy, w) in &[
            (0.1f32, 0.2f32, 0.05f32),
            (0.49, 0.26, 0.1),
            (-1.3, 2.7, 0.35),
            (3.0, -0.75, 1.7),
            (10.2, 5.1, 0.02),
        ] {
            // The box's mean by the midpoint rule, 400 × 400 samples.
            let n = 400;
            let mut sum = 0.0f64;
            for i in 0..n {
                for j in 0..n {
                    let u = gx + w * ((i as f32 + 0.5) / n as f32 - 0.5);
                    let v = gy + w * ((j as f32 + 0.5) / n as f32 - 0.5);
                    sum += sharp(u, v) as f64;
                }
            }
            let mean = (sum / (n * n) as f64) as f32;
            let got = checker(gx, gy, w);
            assert!(
                (got - mean).abs() < 0.01,
                "({gx}, {gy}) w {w}: {got} vs {mean}"
            );
        }
        assert_eq!(sharp(0.1, 0.1), 1.0);
        assert_eq!(sharp(0.6, 0.1), -1.0);
        // A pixel of 1/500 rad: at 1° below the horizon the squares are a 150th of it.
        let up = Vec3::Y;
        let grey: [f32; 3] = std::array::from_fn(|c| 0.5 * (GROUND[0][c] + GROUND[1][c]));
        let d = Vec3::new(0.3, -(1f32.to_radians().sin()), 1.0);
        let far = Environment::Sky.sample(d, up, 0.002);
        let haze = (8.0 * d.normalize().y.abs()).min(1.0);
        for c in 0..3 {
            let want = HORIZON[c] + (grey[c] - HORIZON[c]) * haze;
            assert!((far[c] - want).abs() < 1e-3, "{far:?}");
        }
        // Straight down the squares are 250 pixels across: sharp, one or the other.
        let near = Environment::Sky.sample(Vec3::new(0.1, -1.0, 0.1), up, 0.002);
        let off = |g: [f32; 3]| (0..3).map(|c| (near[c] - g[c]).abs()).fold(0.0, f32::max);
        assert!(off(GROUND[0]).min(off(GROUND[1])) < 1e-4, "{near:?}");
    }

    #[test]
    fn an_image_is_sampled_by_longitude_and_latitude() {
        // 4×2: the top row red, the bottom row blue.
        let mut texels = vec![[1.0, 0.0, 0.0]; 4];
        texels.extend(vec![[0.0, 0.0, 1.0]; 4]);
        let e = Environment::Image {
            width: 4,
            height: 2,
            texels,
        };
        let up = Vec3::Z;
        assert_eq!(e.sample(Vec3::Z, up, 0.0), [1.0, 0.0, 0.0]);
        assert_eq!(e.sample(-Vec3::Z, up, 0.0), [0.0, 0.0, 1.0]);
        let side = e.sample(Vec3::X, up, 0.0);
        assert!((side[0] - 0.5).abs() < 1e-5 && (side[2] - 0.5).abs() < 1e-5);
    }

    /// Eq. 12: through l layers sin θ_T = (1/η)^l sin θ_I, in the plane of the ray and the
    /// normal, on the far side; no layers or normal incidence: the ray itself.
    #[test]
    fn refraction_bends_more_with_every_layer() {
        let n = Vec3::Z;
        let d = Vec3::new(45f32.to_radians().sin(), 0.0, -45f32.to_radians().cos());
        for l in [1.0f32, 2.0, 3.5] {
            let t = refracted(d, n, 1.5, l);
            assert!((t.length() - 1.0).abs() < 1e-5);
            let want = (1.0 / 1.5f32).powf(l) * 45f32.to_radians().sin();
            assert!((t.x - want).abs() < 1e-5, "{l}: {t}");
            assert!(t.y.abs() < 1e-6 && t.z < 0.0);
        }
        assert_eq!(refracted(d, n, 1.5, 0.0), d);
        assert_eq!(refracted(-Vec3::Z, n, 1.5, 2.0), -Vec3::Z);
    }

    /// An image over the limit is halved (2 × 2 means) until it fits; one within it is kept.
    #[test]
    fn large_images_are_halved_to_fit() {
        let (w, h) = (8192u32, 2050u32);
        let mut rgba = vec![0u8; (w * h * 4) as usize];
        for (k, p) in rgba.chunks_exact_mut(4).enumerate() {
            let v = if (k as u32 % w).is_multiple_of(2) {
                255
            } else {
                0
            };
            p.copy_from_slice(&[v, v, v, 255]);
        }
        let Environment::Image {
            width,
            height,
            texels,
        } = Environment::from_rgba8(w, h, &rgba).unwrap()
        else {
            panic!("an image");
        };
        assert_eq!((width, height), (4096, 1025));
        assert!(texels.len() <= MAX_ENV_TEXELS);
        // Alternating columns of white and black mean to a grey of half white.
        assert!(texels.iter().all(|t| (t[0] - 0.5).abs() < 1e-6));
        let small = Environment::from_rgba8(4, 2, &[9u8; 32]).unwrap();
        assert!(matches!(
            small,
            Environment::Image {
                width: 4,
                height: 2,
                ..
            }
        ));
    }

    #[test]
    fn a_mirror_view_at_normal_incidence_reflects_f0() {
        let white = Environment::Image {
            width: 2,
            height: 2,
            texels: vec![[1.0; 3]; 4],
        };
        let c = reflect_into([0.0; 3], &white, Vec3::Y, (1.5, 1.0), Vec3::Z, Vec3::Z, 0.0);
        assert!((c[0] - 0.04).abs() < 1e-6, "{c:?}");
    }
}
