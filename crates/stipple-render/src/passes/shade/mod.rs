//! Shading: from point ids to lit colour and surface depth (Dobrev §3.1): the CPU reference kernel ([`cpu`]; its module documentation explains the pass
//! against the paper), the GPU pipeline ([`gpu`]) and its WGSL, side by side.

pub mod cpu;
pub mod gpu;

use crate::lights::Light;
use crate::pipeline::Pipeline;
use crate::PreparedCloud;
use cpu::{Albedo, LocalLight, ShadeParams};
use glam::DVec3;

/// The shade pass's parameters: the pipeline's lights in the cloud's local frame (`origin`),
/// the material terms by object and the shadow samples taken per light.
pub fn shade_params(
    origin: DVec3,
    pipe: &Pipeline,
    gap: f32,
    materials: Vec<cpu::Terms>,
    samples: [u32; 4],
) -> ShadeParams {
    let lights = pipe
        .lights
        .iter()
        .take(crate::lights::MAX_LIGHTS)
        .map(|l| match *l {
            Light::Headlight => LocalLight::Headlight,
            Light::Directional(d) => {
                LocalLight::Directional(DVec3::from(d).normalize_or_zero().as_vec3())
            }
            Light::Point(p) => LocalLight::Point((DVec3::from(p) - origin).as_vec3()),
            Light::Area(a) => LocalLight::Point((DVec3::from(a.centre) - origin).as_vec3()),
        })
        .collect();
    let lut = crate::srgb::srgb_to_linear_table();
    ShadeParams {
        lights,
        samples,
        materials,
        // Splats hit their own (bent) surface already: the tangent-plane correction would
        // only flatten it again.
        max_correction: if pipe.splat.is_some() { -1.0 } else { gap },
        background: pipe.background.map(|c| lut[c as usize]),
        falloff: pipe.falloff.unwrap_or(0.0),
    }
}

impl PreparedCloud {
    /// [`shade_params`] for this cloud (its objects' materials, its shadow texture's samples).
    pub fn shade_params(&self, pipe: &Pipeline, gap: f32) -> ShadeParams {
        let samples = self.lit().map_or([0; 4], |l| l.samples);
        shade_params(self.cloud.origin, pipe, gap, self.terms(pipe), samples)
    }

    pub fn albedo(&self, pipe: &Pipeline) -> Albedo<'_> {
        let c = &self.cloud;
        if let Some(col) = &c.colors {
            Albedo::Colours(col)
        } else if let (Some(i), Some(s)) = (&c.intensity, self.intensity_scale) {
            Albedo::Intensity(i, s)
        } else {
            Albedo::Constant(pipe.material.base_colour)
        }
    }
}
