//! # Shading: from point ids to lit colour and surface depth (Dobrev §3.1)
//!
//! How it works: for each covered pixel, the point it shows gives an albedo (its colour, else
//! its LiDAR intensity as grey, else the material colour) and, where the cloud has normals,
//! Phong terms summed over the lights (at most four), each weighted by the point's lit value
//! m ∈ [0, 1] from its shadow texture (Dobrev §6, c = k_a + m (k_d + k_s)):
//! c = albedo · (k_a + Σ m_l k_d ⟨n, l⟩⁺) + Σ m_l k_s ⟨r_l, v⟩⁺^shininess, with normals turned
//! towards the viewer (two-sided, for when back-face culling is off). The material (k_a, k_d,
//! k_s, shininess) is the point's object's. Clouds without normals are shown unlit, or, with
//! a shadow texture, as albedo · (k_a + (1 − k_a) · mean m): lit points keep their colour and
//! shadowed ones fall to the ambient level. m_l = lit samples / samples taken (1 when the
//! light has no shadow texture). With a falloff distance d₀ (`Pipeline::falloff`), a point or
//! area light's m is multiplied by (d₀ / d)² at distance d (inverse-square law, Gunjee §4.1).
//! Maths is in linear RGB; sRGB conversion happens at output.
//!
//! Surface depth (a deviation from the paper, which keeps the point's own depth): where the
//! point has a normal, the pixel's depth is where the pixel's centre ray meets the point's
//! tangent plane. A filled pixel then carries the depth of the surface at that pixel instead
//! of a copy of its neighbour's, so depth output is accurate to second order in the point
//! spacing (see the fidelity test). The correction is skipped at grazing angles
//! (|⟨n, ray⟩| < 0.2) and when it would move the depth by more than d̃.

use crate::gbuffer::{is_point, GBuffer};
use crate::params::ViewParams;
use crate::passes::{prefetch, PREFETCH_AHEAD};
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

pub use crate::material::Terms;

#[derive(Clone, Debug)]
pub struct ShadeParams {
    /// One to four lights.
    pub lights: Vec<LocalLight>,
    /// Shadow samples taken per light (0: no shadow texture for that light, m = 1).
    pub samples: [u32; 4],
    /// Material terms by object (index 0 for a plain cloud).
    pub materials: Vec<Terms>,
    /// Largest depth correction accepted (d̃).
    pub max_correction: f32,
    /// Linear background colour.
    pub background: [f32; 3],
    /// Point lights' falloff distance d₀ (strength (d₀ / d)²); 0: no falloff.
    pub falloff: f32,
}

pub struct ShadeInput<'a> {
    pub positions: &'a [Vec3],
    /// Normals, when the pipeline lights (None: unlit).
    pub normals: Option<&'a [Vec3]>,
    pub albedo: Albedo<'a>,
    /// The object of each point (None: every point is object 0).
    pub objects: Option<&'a [u8]>,
    /// Shadow textures (see [`crate::LitTexture`]; None: none).
    pub lit: Option<&'a crate::LitTexture>,
    /// Per-pixel normal and linear albedo that replace the point's (splat blending: the
    /// depth is the blended one and is not corrected).
    pub pixel: Option<(&'a [Vec3], &'a [[f32; 3]])>,
}

/// The lit values m of a point's packed counts under `samples` per light.
#[inline]
pub fn lit_values(counts: [u16; 4], samples: &[u32; 4]) -> [f32; 4] {
    std::array::from_fn(|l| {
        if samples[l] == 0 {
            1.0
        } else {
            counts[l] as f32 / (samples[l] * crate::shadow::FULL as u32) as f32
        }
    })
}

/// Lit values per light and colour channel of point `i` (see [`crate::LitTexture`]): the
/// grey texture's m in every channel, or a coloured one's channels, each rounded to 8 bits
/// as the GPU packs them per pixel (q = round(sum / samples), m = q / 255, in integers).
#[inline]
pub fn lit_rgb(lit: &crate::LitTexture, i: usize, samples: &[u32; 4]) -> [[f32; 3]; 4] {
    match &lit.rb {
        None => lit_values(lit.counts[i], samples).map(|m| [m; 3]),
        Some(rb) => std::array::from_fn(|l| {
            let s = samples[l];
            if s == 0 {
                return [1.0; 3];
            }
            let q = |sum: u16| ((2 * sum as u32 + s) / (2 * s)).min(255) as f32 / 255.0;
            [q(rb[i][2 * l]), q(lit.counts[i][l]), q(rb[i][2 * l + 1])]
        }),
    }
}

pub use crate::srgb::{intensity_grey, linear_to_srgb8, srgb_to_linear_table, SrgbEncoder};

/// Phong terms for unit normal `n` and unit direction to the viewer `v`, summed over the
/// lights `l` (unit directions towards each light) weighted by their lit values `m`.
#[inline]
pub fn phong(
    albedo: [f32; 3],
    n: Vec3,
    v: Vec3,
    l: &[Vec3],
    m: &[[f32; 3]; 4],
    t: &Terms,
) -> [f32; 3] {
    let n = if n.dot(v) < 0.0 { -n } else { n };
    let mut k = [t.ambient; 3];
    let mut s = [0.0; 3];
    for (i, &l) in l.iter().enumerate() {
        let nl = n.dot(l);
        if nl > 0.0 {
            let r = 2.0 * nl * n - l;
            let spec = r.dot(v).max(0.0).powi(t.shininess as i32);
            for c in 0..3 {
                k[c] += m[i][c] * t.diffuse * nl;
                s[c] += m[i][c] * t.specular * spec;
            }
        }
    }
    std::array::from_fn(|c| albedo[c] * k[c] + s[c])
}

/// [`phong`] over the frame's lights for a surface at `hit` (directions towards each light,
/// point lights' falloff applied to their lit values `m`); shade.wgsl's `phong_lights`.
#[inline]
fn phong_lights(
    p: &ShadeParams,
    albedo: [f32; 3],
    n: Vec3,
    to_eye: Vec3,
    hit: Vec3,
    mut m: [[f32; 3]; 4],
    t: &Terms,
) -> [f32; 3] {
    let mut dirs = [Vec3::ZERO; 4];
    for ((d, light), m) in dirs.iter_mut().zip(&p.lights).zip(&mut m) {
        *d = match *light {
            LocalLight::Headlight => to_eye,
            LocalLight::Directional(d) => d,
            LocalLight::Point(lp) => {
                let lv = lp - hit;
                let f = falloff(p.falloff, lv.length_squared());
                for c in m.iter_mut() {
                    *c *= f;
                }
                lv.normalize_or_zero()
            }
        };
    }
    phong(albedo, n, to_eye, &dirs[..p.lights.len()], &m, t)
}

/// A point without a normal under shadow textures: its albedo times the ambient term plus
/// the rest scaled by the mean lit value over the lights (per channel).
#[inline]
fn unlit(albedo: [f32; 3], m: &[[f32; 3]; 4], lights: usize, t: &Terms) -> [f32; 3] {
    let n = lights.clamp(1, 4);
    std::array::from_fn(|c| {
        let mean = m[..n].iter().map(|m| m[c]).sum::<f32>() / n as f32;
        albedo[c] * (t.ambient + (1.0 - t.ambient) * mean)
    })
}

/// A point light's strength at squared distance `d2`: (d₀ / d)² with `d0` > 0, else 1.
#[inline]
pub fn falloff(d0: f32, d2: f32) -> f32 {
    if d0 > 0.0 {
        if d2 > 0.0 {
            d0 * d0 / d2
        } else {
            // At the light itself: no direction to light from (as the shader: l = 0).
            0.0
        }
    } else {
        1.0
    }
}

/// Every point's linear albedo, as [`shade_points`] reads it.
pub fn point_albedo(input: &ShadeInput) -> Vec<[f32; 3]> {
    let lut = srgb_to_linear_table();
    (0..input.positions.len())
        .into_par_iter()
        .with_min_len(4096)
        .map(|id| match input.albedo {
            Albedo::Colours(c) => c[id].map(|x| lut[x as usize]),
            Albedo::Intensity(t, s) => [lut[intensity_grey(t[id], s) as usize]; 3],
            Albedo::Constant(c) => c,
        })
        .collect()
}

/// A surface fragment shaded on its own (deferred shading, Zhang & Pajarola §5.2.4): albedo,
/// normal (either side; zero: the ambient term alone), the point `hit` (local), the object's
/// terms, seen from `eye` (`forward` for an orthographic view), no shadow textures.
/// sorted.wgsl's `t_shade`.
pub fn shade_fragment(
    p: &ShadeParams,
    albedo: [f32; 3],
    n: Vec3,
    (eye, forward): (Vec3, Option<Vec3>),
    hit: Vec3,
    object: usize,
) -> [f32; 3] {
    let to_eye = match forward {
        Some(f) => -f,
        None => (eye - hit).normalize_or_zero(),
    };
    let t = &p.materials[object.min(p.materials.len().saturating_sub(1))];
    phong_lights(p, albedo, n, to_eye, hit, [[1.0; 3]; 4], t)
}

/// Shades every point as seen from `eye` (local; `forward` for an orthographic view, else
/// None): linear RGB per point, as [`shade`] shades a pixel showing it (its own normal and
/// position: no ray, no depth correction). For splats blended in order (Gunjee §4.2), which
/// blend shaded colours.
pub fn shade_points(
    eye: Vec3,
    forward: Option<Vec3>,
    input: &ShadeInput,
    p: &ShadeParams,
) -> Vec<[f32; 3]> {
    let lut = srgb_to_linear_table();
    input
        .positions
        .par_iter()
        .enumerate()
        .with_min_len(4096)
        .map(|(id, &q)| {
            let albedo = match input.albedo {
                Albedo::Colours(c) => c[id].map(|x| lut[x as usize]),
                Albedo::Intensity(t, s) => [lut[intensity_grey(t[id], s) as usize]; 3],
                Albedo::Constant(c) => c,
            };
            let t = &p.materials[input.objects.map_or(0, |o| o[id] as usize)];
            let m = input
                .lit
                .map_or([[1.0; 3]; 4], |lit| lit_rgb(lit, id, &p.samples));
            let Some(normals) = input.normals else {
                return match input.lit {
                    Some(_) => unlit(albedo, &m, p.lights.len(), t),
                    None => albedo,
                };
            };
            let to_eye = match forward {
                Some(f) => -f,
                None => (eye - q).normalize_or_zero(),
            };
            phong_lights(p, albedo, normals[id], to_eye, q, m, t)
        })
        .collect()
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
            let ids = &g.id[j * w..(j + 1) * w];
            for i in 0..w {
                let k = j * w + i;
                // The point of a pixel a few ahead is asked for now, so that its reads
                // (scattered over the cloud) overlap this pixel's.
                if let Some(&a) = ids.get(i + PREFETCH_AHEAD).filter(|&&a| is_point(a)) {
                    prefetch(input.positions, a);
                    if let Some(n) = input.normals {
                        prefetch(n, a);
                    }
                    if let Albedo::Colours(c) = input.albedo {
                        prefetch(c, a);
                    }
                }
                let id = g.id[k];
                if !is_point(id) {
                    crow[i] = p.background;
                    drow[i] = f32::INFINITY;
                    continue;
                }
                let id = id as usize;
                let albedo = match (input.pixel, input.albedo) {
                    (Some((_, a)), _) => a[k],
                    (None, Albedo::Colours(c)) => c[id].map(|x| lut[x as usize]),
                    (None, Albedo::Intensity(t, s)) => [lut[intensity_grey(t[id], s) as usize]; 3],
                    (None, Albedo::Constant(c)) => c,
                };
                let mut depth = g.depth[k];
                let t = &p.materials[input.objects.map_or(0, |o| o[id] as usize)];
                let m = input
                    .lit
                    .map_or([[1.0; 3]; 4], |lit| lit_rgb(lit, id, &p.samples));
                let Some(normals) = input.normals else {
                    crow[i] = match input.lit {
                        Some(_) => unlit(albedo, &m, p.lights.len(), t),
                        None => albedo,
                    };
                    drow[i] = depth;
                    continue;
                };
                let n = input.pixel.map_or(normals[id], |(pn, _)| pn[k]);
                let (o, dir) = v.pixel_ray(i as u32, j as u32);
                let unit = dir.normalize();
                let q = input.positions[id];
                let nd = n.dot(dir);
                if input.pixel.is_none() && n.dot(unit).abs() >= 0.2 {
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
                crow[i] = phong_lights(p, albedo, n, -unit, hit, m, t);
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
        let t = Terms {
            ambient: 0.2,
            diffuse: 0.7,
            specular: 0.1,
            shininess: 8.0,
        };
        let v = Vec3::Z;
        let lit = [[1.0; 3]; 4];
        let facing = phong([0.5; 3], Vec3::Z, v, &[v], &lit, &t)[0];
        let tilted = phong([0.5; 3], Vec3::new(0.0, 0.6, 0.8), v, &[v], &lit, &t)[0];
        assert!((facing - (0.5 * 0.9 + 0.1)).abs() < 1e-6);
        assert!(tilted < facing);
        // Back-facing normals are lit as if turned towards the viewer (two-sided).
        assert_eq!(phong([0.5; 3], -Vec3::Z, v, &[v], &lit, &t)[0], facing);
        // In full shadow only the ambient term is left: c = k_a + m (k_d + k_s).
        let dark = phong([0.5; 3], Vec3::Z, v, &[v], &[[0.0; 3]; 4], &t)[0];
        assert!((dark - 0.5 * 0.2).abs() < 1e-6);
        let half = phong([0.5; 3], Vec3::Z, v, &[v], &[[0.5; 3]; 4], &t)[0];
        assert!((half - (0.1 + 0.5 * (0.35 + 0.1))).abs() < 1e-6);
    }

    #[test]
    fn lit_values_unpack_per_light() {
        let full = crate::shadow::FULL;
        let counts = [3 * full, 10 * full, 0, 255 * full];
        let m = lit_values(counts, &[6, 10, 0, 255]);
        assert_eq!(m, [0.5, 1.0, 1.0, 1.0]);
        assert_eq!(lit_values([0; 4], &[1, 0, 0, 0])[0], 0.0);
        // A sample through a surface of opacity 0.6 (transmittance 0.4, rounded to 102).
        assert!((lit_values([102, 0, 0, 0], &[1, 0, 0, 0])[0] - 0.4).abs() < 1e-6);
    }
}
