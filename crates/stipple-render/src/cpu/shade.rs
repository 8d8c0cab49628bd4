//! # Shading: from point ids to lit colour and surface depth (Dobrev §3.1)
//!
//! How it works: for each covered pixel, the point it shows gives an albedo (its colour, else
//! its LiDAR intensity as grey, else the material colour) and, where the cloud has normals, a
//! Phong term with one light: c = albedo · (k_a + k_d ⟨n, l⟩⁺) + k_s ⟨r, v⟩⁺^shininess, with
//! normals turned towards the viewer (two-sided, for when back-face culling is off). Clouds
//! without normals are shown unlit. Maths is in linear RGB; sRGB conversion happens at output.
//!
//! Surface depth (a deviation from the paper, which keeps the point's own depth): where the
//! point has a normal, the pixel's depth is where the pixel's centre ray meets the point's
//! tangent plane. A filled pixel then carries the depth of the surface at that pixel instead
//! of a copy of its neighbour's, so depth output is accurate to second order in the point
//! spacing (see the fidelity test). The correction is skipped at grazing angles
//! (|⟨n, ray⟩| < 0.2) and when it would move the depth by more than d̃.

use crate::gbuffer::{is_point, GBuffer};
use crate::params::ViewParams;
use glam::Vec3;
use rayon::prelude::*;

/// Where a pixel's albedo comes from.
#[derive(Clone, Copy)]
pub enum Albedo<'a> {
    /// sRGB 8-bit colours per point.
    Colours(&'a [[u8; 3]]),
    /// LiDAR intensity per point, shown as grey; the scale maps intensity to [0, 1].
    Intensity(&'a [u16], f32),
    /// One linear colour for every point.
    Constant([f32; 3]),
}

/// Light in the cloud's local frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LocalLight {
    Headlight,
    /// Unit direction towards the light.
    Directional(Vec3),
    Point(Vec3),
}

#[derive(Clone, Copy, Debug)]
pub struct ShadeParams {
    pub light: LocalLight,
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    /// Phong exponent (used as an integer: the specular term is a repeated product).
    pub shininess: f32,
    /// Largest depth correction accepted (d̃).
    pub max_correction: f32,
    /// Linear background colour.
    pub background: [f32; 3],
}

pub struct ShadeInput<'a> {
    pub positions: &'a [Vec3],
    /// Normals, when the pipeline lights (None: unlit).
    pub normals: Option<&'a [Vec3]>,
    pub albedo: Albedo<'a>,
}

/// sRGB 8-bit → linear.
/// The sRGB 8-bit grey level that shows LiDAR intensity `t` under `scale` (1 / p99).
#[inline]
pub fn intensity_grey(t: u16, scale: f32) -> u8 {
    ((t as f32 * scale).min(1.0) * 255.0) as u8
}

pub fn srgb_to_linear_table() -> [f32; 256] {
    let mut t = [0.0; 256];
    for (i, v) in t.iter_mut().enumerate() {
        let c = i as f32 / 255.0;
        *v = if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        };
    }
    t
}

/// Linear → sRGB 8-bit through a 16384-entry table (error under 0.5 of an 8-bit level
/// beyond rounding).
pub struct SrgbEncoder(Vec<u8>);

impl SrgbEncoder {
    const N: usize = 16384;

    pub fn new() -> SrgbEncoder {
        SrgbEncoder(
            (0..Self::N)
                .map(|i| linear_to_srgb8(i as f32 / (Self::N - 1) as f32))
                .collect(),
        )
    }

    /// The table itself: entry i encodes the linear value i / (N − 1) (the GPU output pass
    /// uploads it, so both backends encode identically).
    pub fn table(&self) -> &[u8] {
        &self.0
    }

    #[inline]
    pub fn encode(&self, c: f32) -> u8 {
        let i = (c.clamp(0.0, 1.0) * (Self::N - 1) as f32 + 0.5) as usize;
        self.0[i]
    }
}

impl Default for SrgbEncoder {
    fn default() -> Self {
        Self::new()
    }
}

/// Linear → sRGB 8-bit (exact).
pub fn linear_to_srgb8(c: f32) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Phong term for unit normal `n`, unit direction to the viewer `v` and to the light `l`.
#[inline]
pub fn phong(albedo: [f32; 3], n: Vec3, v: Vec3, l: Vec3, p: &ShadeParams) -> [f32; 3] {
    let n = if n.dot(v) < 0.0 { -n } else { n };
    let nl = n.dot(l);
    let (diff, spec) = if nl > 0.0 {
        let r = 2.0 * nl * n - l;
        (nl, r.dot(v).max(0.0).powi(p.shininess as i32))
    } else {
        (0.0, 0.0)
    };
    let k = p.ambient + p.diffuse * diff;
    albedo.map(|a| a * k + p.specular * spec)
}

/// Shades every pixel: `colour` gets linear RGB (background colour where no point is),
/// `surface_depth` the view depth of the surface (+inf on background).
pub fn shade(
    v: &ViewParams,
    g: &GBuffer,
    input: &ShadeInput,
    p: &ShadeParams,
    colour: &mut [[f32; 3]],
    surface_depth: &mut [f32],
) {
    let w = v.width as usize;
    let lut = srgb_to_linear_table();
    colour
        .par_chunks_mut(w)
        .zip(surface_depth.par_chunks_mut(w))
        .enumerate()
        .for_each(|(j, (crow, drow))| {
            for i in 0..w {
                let k = j * w + i;
                let id = g.id[k];
                if !is_point(id) {
                    crow[i] = p.background;
                    drow[i] = f32::INFINITY;
                    continue;
                }
                let id = id as usize;
                let albedo = match input.albedo {
                    Albedo::Colours(c) => c[id].map(|x| lut[x as usize]),
                    Albedo::Intensity(t, s) => [lut[intensity_grey(t[id], s) as usize]; 3],
                    Albedo::Constant(c) => c,
                };
                let mut depth = g.depth[k];
                let Some(normals) = input.normals else {
                    crow[i] = albedo;
                    drow[i] = depth;
                    continue;
                };
                let n = normals[id];
                let (o, dir) = v.pixel_ray(i as u32, j as u32);
                let unit = dir.normalize();
                let q = input.positions[id];
                let nd = n.dot(dir);
                if n.dot(unit).abs() >= 0.2 {
                    // View depth of the ray/tangent-plane hit, relative to the eye plane.
                    let t = n.dot(q - o) / nd;
                    let t = if v.perspective == 1 {
                        t
                    } else {
                        t + (o - Vec3::from(v.eye)).dot(Vec3::from(v.forward))
                    };
                    if (t - depth).abs() <= p.max_correction {
                        depth = t;
                    }
                }
                let hit = if v.perspective == 1 {
                    o + dir * depth
                } else {
                    o + dir * (depth - (o - Vec3::from(v.eye)).dot(Vec3::from(v.forward)))
                };
                let to_eye = -unit;
                let l = match p.light {
                    LocalLight::Headlight => to_eye,
                    LocalLight::Directional(d) => d,
                    LocalLight::Point(lp) => (lp - hit).normalize_or_zero(),
                };
                crow[i] = phong(albedo, n, to_eye, l, p);
                drow[i] = depth;
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_table_agrees_with_the_formula() {
        let e = SrgbEncoder::new();
        for i in 0..=10_000 {
            let c = i as f32 / 10_000.0;
            assert!(
                (e.encode(c) as i32 - linear_to_srgb8(c) as i32).abs() <= 1,
                "{c}"
            );
        }
        let lut = srgb_to_linear_table();
        for v in 0..=255u8 {
            assert_eq!(e.encode(lut[v as usize]), v);
        }
    }

    #[test]
    fn phong_headlight_facing_is_brightest() {
        let p = ShadeParams {
            light: LocalLight::Headlight,
            ambient: 0.2,
            diffuse: 0.7,
            specular: 0.1,
            shininess: 8.0,
            max_correction: 1.0,
            background: [0.0; 3],
        };
        let v = Vec3::Z;
        let facing = phong([0.5; 3], Vec3::Z, v, v, &p)[0];
        let tilted = phong([0.5; 3], Vec3::new(0.0, 0.6, 0.8), v, v, &p)[0];
        assert!((facing - (0.5 * 0.9 + 0.1)).abs() < 1e-6);
        assert!(tilted < facing);
        // Back-facing normals are lit as if turned towards the viewer (two-sided).
        assert_eq!(phong([0.5; 3], -Vec3::Z, v, v, &p)[0], facing);
    }
}
