//! # Shadow textures (Dobrev §6)
//!
//! A shadow texture stores per point whether a light reaches it: m ∈ [0, 1], the fraction of
//! the light's sample positions that see the point. Shading then uses c = k_a + m (k_d + k_s)
//! (see `passes/shade/cpu.rs`).
//!
//! For each sample position of a light:
//! 1. the cloud is rendered from the light ([`light_views`]: one perspective view framing the
//!    cloud when it lies within a 60° cone of the light, else the six faces of a cube around
//!    it, each point belonging to exactly one face): `project` with no back-face culling, then
//!    `fill_background` until stable and one `fill_occluded` (see
//!    [`ShadowSettings::occluded_fill_iterations`]), so points seen through holes of a nearer
//!    surface are covered by it and stay unlit;
//! 2. `shadow_texture` marks every point whose light-space depth is within
//!    Δd = d̃' · min(1 / |⟨v, n⟩|, cap) of that filled depth at its pixel, where v is the
//!    direction from the light to the point and n its normal ([`ShadowSettings::slope_cap`];
//!    clouds without normals use Δd = d̃'). d̃' is d̃ widened to at least three light pixels
//!    (`cpu::shadow_texture::light_gap`, a deviation: with the paper's d̃ alone a light image
//!    whose pixels exceed d̃ / 2 shows acne on tilted surfaces); the light image's
//!    `fill_occluded` uses d̃' at the far side of the cloud's bounds in that view, where its
//!    pixels are widest (at the cloud's centre, which lies beside or behind a cube's side
//!    face, the gap was d̃ alone and the fill took a grazing plane for holes: specks of acne).
//!
//! The paper marks the nearest unmarked point per pixel, excludes marked points and repeats
//! until no point is newly marked, because a 2011 fragment shader could output one index per
//! pixel. Against a fixed reference depth (the paper keeps the first pass's), that loop ends
//! with exactly the points within Δd of the reference marked. A compute pass tests every
//! point against the reference at once, so here one pass over the points does what the loop
//! converges to, with no readback per iteration.
//!
//! The cap on 1/⟨v, n⟩ (default 16, i.e. down to 3.6° of grazing) matters at a lit object's
//! rim as seen from the light, where one light pixel spans a deep sliver of surface: a small
//! cap leaves that sliver unlit (self-shadow acne along the terminator). A point can only be
//! wrongly lit through a large cap if its own normal is grazing to the light, where its
//! diffuse term is at most k_d / cap anyway.
//!
//! Area lights (rectangles and discs) are sampled by Monte Carlo with a deterministic
//! low-discrepancy sequence whose first sample is the centre ([`sample_position`]), so a
//! texture can be refined progressively: one sample first, then more towards N, each new
//! sample adding to the counts (m = lit samples / samples taken).
//!
//! A texture holds up to [`MAX_LIGHTS`] lights and [`MAX_SAMPLES`] samples each: 16 bits per
//! point and light, the light its samples brought in units of [`FULL`] per fully lit sample
//! (an opaque cloud's points take 0 or [`FULL`] per sample; a point behind translucent
//! surfaces takes its transmittance times [`FULL`], rounded; see [`crate::translucent`]), so
//! m = sum / ([`FULL`] · samples).

pub use crate::lights::{light_samples, sample_position};
use crate::params::ViewParams;
use crate::pipeline::{GeometryPass, Iterations, Pipeline};
use glam::{DVec3, Vec3};
use stipple_core::{Bounds, Camera, Projection};

pub use crate::lights::{MAX_LIGHTS, MAX_SAMPLES};

/// What one sample that reaches a point unattenuated adds to its lit sum.
pub const FULL: u16 = 255;

/// Per-point lit sums for up to four lights, and the samples taken for each.
#[derive(Clone, Debug, PartialEq)]
pub struct LitTexture {
    /// Light l's sum in element l ([`FULL`] per fully lit sample); with [`LitTexture::rb`],
    /// the green channel's. In memory (little-endian) this is what the GPU reads as two u32
    /// words per point: lights 0 | 1 << 16 and 2 | 3 << 16.
    pub counts: Vec<[u16; 4]>,
    /// Samples taken per light (0: no shadow texture for that light, m = 1).
    pub samples: [u32; 4],
    /// Coloured shadows (light through translucent coloured surfaces, see
    /// [`crate::translucent`]): per point the red and blue sums of each light, `[r0, b0, r1,
    /// b1, …]` (on the GPU four words, r_l | b_l << 16). None: grey, every channel `counts`.
    pub rb: Option<Vec<[u16; 8]>>,
}

impl LitTexture {
    pub fn new(points: usize) -> LitTexture {
        LitTexture {
            counts: vec![[0; 4]; points],
            samples: [0; 4],
            rb: None,
        }
    }

    /// A texture whose channels are kept apart (see [`LitTexture::rb`]).
    pub fn coloured(points: usize) -> LitTexture {
        LitTexture {
            rb: Some(vec![[0; 8]; points]),
            ..LitTexture::new(points)
        }
    }

    /// The lit value m of point `i` under light `l` (green, for a coloured texture).
    pub fn value(&self, i: usize, l: usize) -> f32 {
        crate::passes::shade::cpu::lit_values(self.counts[i], &self.samples)[l]
    }

    /// The lit values (red, green, blue) of point `i` under light `l`, unrounded.
    pub fn value_rgb(&self, i: usize, l: usize) -> [f32; 3] {
        let g = self.value(i, l);
        match &self.rb {
            None => [g; 3],
            Some(rb) => {
                let s = self.samples[l];
                if s == 0 {
                    return [1.0; 3];
                }
                let m = |sum: u16| sum as f32 / (s * FULL as u32) as f32;
                [m(rb[i][2 * l]), g, m(rb[i][2 * l + 1])]
            }
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowSettings {
    /// Side of the (square) light image in pixels; 0 = automatic: a light pixel about twice
    /// the point spacing at the cloud's centre (a surface facing the light then puts one to
    /// four points in each pixel: few holes, and shadow edges as sharp as the points allow),
    /// within 64 to [`MAX_AUTO_SIZE`].
    pub size: u32,
    /// The largest 1/⟨v, n⟩ (see the module notes).
    pub slope_cap: f32,
    /// d̃ (None: the cloud's default, 2.5 × spacing).
    pub layer_gap: Option<f32>,
    /// `fill_background` on the light image runs until stable, at most this many iterations.
    pub background_fill_iterations: u32,
    /// `fill_occluded` iterations on the light image (the paper's 1 by default). Each one
    /// more closes larger holes but also pushes a nearer surface's silhouette outwards by up
    /// to a pixel (a noisy rim is closed towards its hull), which grows shadows: on the
    /// sphere-over-plane test 1 iteration gives an IoU of 0.98 with the analytic shadow, 2
    /// give 0.975, 8 give 0.95.
    pub occluded_fill_iterations: u32,
    /// Light layers peeled for a translucent cloud (one with an opacity below 1; see
    /// [`crate::translucent`]); an opaque cloud takes one light image whatever this says.
    /// Points behind the last layer get the light the layers let through.
    pub layers: u32,
}

impl Default for ShadowSettings {
    fn default() -> Self {
        ShadowSettings {
            size: 0,
            slope_cap: 16.0,
            layer_gap: None,
            background_fill_iterations: 8,
            occluded_fill_iterations: 1,
            layers: 8,
        }
    }
}

impl ShadowSettings {
    /// The passes run on the light image.
    pub fn light_pipeline(&self, gap: f32) -> Pipeline {
        let bgi = Iterations::UntilStable {
            max: self.background_fill_iterations,
        };
        let oci = Iterations::Fixed(self.occluded_fill_iterations);
        Pipeline {
            backface_culling: false,
            geometry: vec![
                GeometryPass::FillBackground {
                    iterations: bgi,
                    radius: 1,
                },
                GeometryPass::FillOccluded {
                    iterations: oci,
                    layer_gap: Some(gap),
                    radius: 1,
                },
            ],
            colour: vec![],
            ..Pipeline::default()
        }
    }

    pub fn validate(&self) -> Result<(), ShadowError> {
        if self.size != 0 && !(16..=8192).contains(&self.size) {
            return Err(ShadowError::MapSize(self.size));
        }
        if !(self.slope_cap >= 1.0 && self.slope_cap.is_finite()) {
            return Err(ShadowError::SlopeCap(self.slope_cap));
        }
        if !(1..=MAX_LIGHT_LAYERS).contains(&self.layers) {
            return Err(ShadowError::Layers(self.layers));
        }
        if let Some(g) = self.layer_gap {
            if !(g > 0.0 && g.is_finite()) {
                return Err(ShadowError::LayerGap(g));
            }
        }
        Ok(())
    }
}

/// What a shadow texture cannot be made or used with.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ShadowError {
    #[error("shadow map size {0}: must be 16 to 8192 (or 0 for automatic)")]
    MapSize(u32),
    #[error("slope cap {0}: must be at least 1")]
    SlopeCap(f32),
    #[error("{0} light layers: must be 1 to {MAX_LIGHT_LAYERS}")]
    Layers(u32),
    #[error("layer gap {0}: must be a positive distance")]
    LayerGap(f32),
    #[error("shadow texture for {texture} points, but the cloud has {cloud}")]
    Points { texture: usize, cloud: usize },
}

/// One rendering from a light position.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightView {
    pub view: ViewParams,
    /// 0–5: a cube face (+x, −x, +y, −y, +z, −z), which marks only the points whose
    /// direction from the light has that dominant axis; [`ALL_FACES`]: one view sees all.
    pub face: u32,
}

pub const ALL_FACES: u32 = 6;

/// The largest automatic light image side: its per-pixel buffers (16 bytes a pixel, 32 for
/// the planes of translucent layers) fit the 128 MiB storage binding that every GPU adapter
/// offers, so both backends use the same light images (at 4096 the GPU refused
/// `examples/shadows.toml`). A larger `size` can be asked for explicitly.
pub const MAX_AUTO_SIZE: u32 = 2048;

/// The most light layers a translucent shadow peels ([`ShadowSettings::layers`]).
pub const MAX_LIGHT_LAYERS: u32 = 64;

/// The cube face of direction `d` (as the shader computes it).
#[inline]
pub fn dominant_face(d: Vec3) -> u32 {
    let a = d.abs();
    if a.x >= a.y && a.x >= a.z {
        if d.x >= 0.0 {
            0
        } else {
            1
        }
    } else if a.y >= a.z {
        if d.y >= 0.0 {
            2
        } else {
            3
        }
    } else if d.z >= 0.0 {
        4
    } else {
        5
    }
}

/// The distance from `light` (world) within which a tenth of the points (local positions,
/// `origin`) lie, from a strided sample of at most 4096 of them.
pub fn near_distance(positions: &[Vec3], origin: DVec3, light: DVec3) -> f64 {
    if positions.is_empty() {
        return 0.0;
    }
    let step = positions.len().div_ceil(4096);
    let local = light - origin;
    let mut d: Vec<f64> = positions
        .iter()
        .step_by(step)
        .map(|p| (p.as_dvec3() - local).length())
        .collect();
    let k = d.len() / 10;
    *d.select_nth_unstable_by(k, f64::total_cmp).1
}

/// The views that see a cloud (local bounds `bounds`, origin `origin`, median spacing
/// `spacing`) from world position `light`; `near` is the distance within which a tenth of
/// the points lie ([`near_distance`]), which sizes a cube's faces.
pub fn light_views(
    bounds: &Bounds,
    origin: DVec3,
    spacing: f32,
    light: DVec3,
    near: f64,
    settings: &ShadowSettings,
) -> Vec<LightView> {
    let lo = origin + bounds.min.as_dvec3();
    let hi = origin + bounds.max.as_dvec3();
    let centre = (lo + hi) * 0.5;
    let diag = (hi - lo).length().max(1e-9);
    let corners: Vec<DVec3> = (0..8)
        .map(|i| {
            DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect();
    let to_centre = centre - light;
    let dist = to_centre.length();
    let far = corners
        .iter()
        .map(|c| (*c - light).length())
        .fold(0.0, f64::max)
        * 1.01
        + 1e-9;
    let spacing = (spacing as f64).max(diag * 1e-6);
    let side = |extent: f64| -> u32 {
        if settings.size > 0 {
            settings.size
        } else {
            (extent / (2.0 * spacing))
                .ceil()
                .clamp(64.0, MAX_AUTO_SIZE as f64) as u32
        }
    };
    let up_for = |f: DVec3| {
        if f.normalize().cross(DVec3::Y).length() > 0.1 {
            DVec3::Y
        } else {
            DVec3::Z
        }
    };
    if dist > 1e-9 {
        let f = to_centre / dist;
        let half_angle = corners
            .iter()
            .map(|c| {
                let d = (*c - light).normalize_or_zero();
                d.dot(f).clamp(-1.0, 1.0).acos()
            })
            .fold(0.0, f64::max);
        if half_angle < 60f64.to_radians() {
            let near = corners
                .iter()
                .map(|c| (*c - light).dot(f))
                .fold(f64::INFINITY, f64::min)
                * 0.5;
            let fov = (2.0 * half_angle * 1.05).max(1f64.to_radians());
            let s = side(2.0 * dist * (fov / 2.0).tan());
            let cam = Camera {
                eye: light,
                target: centre,
                up: up_for(f),
                projection: Projection::Perspective {
                    fov_deg: fov.to_degrees(),
                },
                width: s,
                height: s,
                near: near.max(diag * 1e-6),
                far,
            };
            return vec![LightView {
                view: ViewParams::new(&cam, origin),
                face: ALL_FACES,
            }];
        }
    }
    // A cube around the light; faces overlap slightly, and each point is marked only by the
    // face of its dominant axis. A light pixel at a face's corners is about twice the
    // spacing at the distance within which a tenth of the points lie: a surface near the
    // light (a lamp's shade, the wall of a room around it) must cover its pixels without
    // holes, or light passes through it (the cloud's centre, used before, can lie far beyond
    // it or beside the light). A corner pixel subtends (1/3)^(3/2) of the solid angle of a
    // centre pixel, so it holds that fraction of the points: the side is scaled by
    // (1/3)^(3/4) of what the centre alone would ask.
    let fov = 2.0 * 1.02f64.atan();
    let corner = (1.0f64 / 3.0).powf(0.75);
    let s = side(2.0 * near.max(1e-3 * diag) * 1.02 * corner);
    let axes = [
        (DVec3::X, DVec3::Y),
        (-DVec3::X, DVec3::Y),
        (DVec3::Y, DVec3::Z),
        (-DVec3::Y, DVec3::Z),
        (DVec3::Z, DVec3::Y),
        (-DVec3::Z, DVec3::Y),
    ];
    axes.iter()
        .enumerate()
        .map(|(face, &(f, up))| {
            let cam = Camera {
                eye: light,
                target: light + f,
                up,
                projection: Projection::Perspective {
                    fov_deg: fov.to_degrees(),
                },
                width: s,
                height: s,
                near: diag * 1e-5,
                far,
            };
            LightView {
                view: ViewParams::new(&cam, origin),
                face: face as u32,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_distant_light_gets_one_view_a_light_inside_gets_a_cube() {
        let b = Bounds {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let s = ShadowSettings::default();
        let v = light_views(&b, DVec3::ZERO, 0.01, DVec3::new(0.0, 10.0, 0.0), 10.0, &s);
        assert_eq!(v.len(), 1);
        assert_eq!(v[0].face, ALL_FACES);
        let v = light_views(&b, DVec3::ZERO, 0.01, DVec3::new(0.2, 0.1, 0.0), 0.5, &s);
        // Faces sized for the surfaces near the light: twice as near, twice as fine.
        let inside = DVec3::new(0.2, 0.1, 0.0);
        let side = |near| {
            light_views(&b, DVec3::ZERO, 0.001, inside, near, &s)[0]
                .view
                .width
        };
        assert_eq!((side(0.5), side(0.25)), (224, 112));
        assert_eq!(v.len(), 6);
        // Every direction falls in the view of its own face.
        let mut rng = stipple_core::rng::Rng::new(1);
        for _ in 0..1000 {
            let p = Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 2.0 - 1.0;
            let d = p - Vec3::from(v[0].view.eye);
            let face = dominant_face(d) as usize;
            assert!(
                crate::passes::project::cpu::project_point(&v[face].view, p).is_some(),
                "{p} in face {face}"
            );
        }
    }
}
