//! # shade (GPU twin of cpu/shade.rs)
//!
//! Two steps: `gather` (shaders/gather.wgsl), once per chunk of the cloud, copies each pixel's
//! point (position, normal, albedo) into per-pixel buffers; `shade` (shaders/shade.wgsl) then
//! lights every pixel and computes its surface depth, as the CPU does.

use super::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};
use super::GpuContext;
use crate::cpu::shade::{LocalLight, ShadeParams};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct GatherBlock {
    pub base: u32,
    pub count: u32,
    pub has_normals: u32,
    pub has_albedo: u32,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct ShadeBlock {
    pub light_kind: u32,
    pub has_normals: u32,
    pub has_albedo: u32,
    pub shininess: i32,
    pub light: [f32; 3],
    pub ambient: f32,
    pub base_colour: [f32; 3],
    pub diffuse: f32,
    pub background: [f32; 3],
    pub specular: f32,
    pub max_correction: f32,
    pub pad: [u32; 3],
}

const _: () = assert!(std::mem::size_of::<ShadeBlock>() == 80);

impl ShadeBlock {
    /// The block for a cloud under a pipeline: the CPU's shade parameters (cpu::shade_params)
    /// with the cloud's attributes.
    pub fn for_cloud(cloud: &super::GpuCloud, pipe: &crate::Pipeline) -> ShadeBlock {
        let gap = crate::pipeline::layer_gap(pipe, cloud.spacing);
        let params = crate::cpu::shade_params(cloud.origin, pipe, gap);
        let constant = (!cloud.has_albedo).then_some(pipe.material.base_colour);
        ShadeBlock::new(&params, cloud.has_normals && pipe.lighting, constant)
    }

    pub fn new(p: &ShadeParams, has_normals: bool, albedo: Option<[f32; 3]>) -> ShadeBlock {
        let (light_kind, light) = match p.light {
            LocalLight::Headlight => (0, [0.0; 3]),
            LocalLight::Directional(d) => (1, d.to_array()),
            LocalLight::Point(q) => (2, q.to_array()),
        };
        ShadeBlock {
            light_kind,
            has_normals: has_normals as u32,
            has_albedo: albedo.is_none() as u32,
            shininess: p.shininess as i32,
            light,
            ambient: p.ambient,
            base_colour: albedo.unwrap_or([0.0; 3]),
            diffuse: p.diffuse,
            background: p.background,
            specular: p.specular,
            max_correction: p.max_correction,
            pad: [0; 3],
        }
    }
}

pub(crate) struct Shade {
    pub gather: Pass,
    pub shade: Pass,
}

impl Shade {
    pub fn new(ctx: &GpuContext) -> Shade {
        let d = &ctx.device;
        Shade {
            gather: Pass::new(
                d,
                &super::shaders::GATHER_MODULE,
                "gather",
                &[UNIFORM, DYNAMIC, READ, READ, READ, READ, WRITE, WRITE],
            ),
            shade: Pass::new(
                d,
                &super::shaders::SHADE_MODULE,
                "shade",
                &[UNIFORM, DYNAMIC, READ, READ, READ, READ, READ, WRITE, WRITE],
            ),
        }
    }
}
