//! # shade (GPU twin of `cpu.rs`)
//!
//! Two steps: `gather` (gather.wgsl), once per chunk of the cloud, copies each pixel's
//! point (position, normal, albedo, object and opacity, shadow counts) into per-pixel buffers; `shade` (shade.wgsl) then
//! lights every pixel and computes its surface depth, as the CPU does.

use crate::device::context::GpuContext;
use crate::device::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};
use crate::passes::shade::cpu::{LocalLight, ShadeParams};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct GatherBlock {
    pub base: u32,
    pub count: u32,
    pub has_normals: u32,
    pub has_albedo: u32,
    pub has_style: u32,
    pub has_lit: u32,
    pub pad: [u32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct ShadeBlock {
    pub light_count: u32,
    pub has_normals: u32,
    pub has_albedo: u32,
    pub has_lit: u32,
    pub base_colour: [f32; 3],
    pub max_correction: f32,
    pub background: [f32; 3],
    pub pad: u32,
    pub samples: [u32; 4],
    /// xyz and kind (0 headlight, 1 directional, 2 point).
    pub lights: [[f32; 4]; 4],
}

const _: () = assert!(std::mem::size_of::<ShadeBlock>() == 128);

/// Material terms by object as the shader's uniform array holds them.
pub(crate) type MaterialTable = [[f32; 4]; crate::MAX_OBJECTS];

impl ShadeBlock {
    /// The block and material table for a cloud under a pipeline: the CPU's shade
    /// parameters (cpu::shade_params) with the cloud's attributes.
    pub fn for_cloud(
        cloud: &crate::device::cloud::GpuCloud,
        pipe: &crate::Pipeline,
    ) -> (ShadeBlock, Box<MaterialTable>) {
        let gap = crate::pipeline::layer_gap(pipe, cloud.spacing);
        let materials = cloud.materials.clone().unwrap_or_else(|| {
            vec![crate::passes::shade::cpu::Terms {
                ambient: pipe.material.ambient,
                diffuse: pipe.material.diffuse,
                specular: pipe.material.specular,
                shininess: pipe.material.shininess,
            }]
        });
        let params =
            crate::passes::shade::shade_params(cloud.origin, pipe, gap, materials, cloud.samples);
        let constant = (!cloud.has_albedo).then_some(pipe.material.base_colour);
        let has_lit = cloud.chunks.iter().any(|c| c.lit.is_some()) && cloud.samples != [0; 4];
        (
            ShadeBlock::new(
                &params,
                cloud.has_normals && pipe.lighting,
                constant,
                has_lit,
            ),
            material_table(&params),
        )
    }

    pub fn new(
        p: &ShadeParams,
        has_normals: bool,
        albedo: Option<[f32; 3]>,
        has_lit: bool,
    ) -> ShadeBlock {
        let mut lights = [[0.0; 4]; 4];
        for (slot, l) in lights.iter_mut().zip(&p.lights) {
            *slot = match *l {
                LocalLight::Headlight => [0.0; 4],
                LocalLight::Directional(d) => [d.x, d.y, d.z, 1.0],
                LocalLight::Point(q) => [q.x, q.y, q.z, 2.0],
            };
        }
        ShadeBlock {
            light_count: p.lights.len().min(4) as u32,
            has_normals: has_normals as u32,
            has_albedo: albedo.is_none() as u32,
            has_lit: has_lit as u32,
            base_colour: albedo.unwrap_or([0.0; 3]),
            max_correction: p.max_correction,
            background: p.background,
            pad: 0,
            samples: p.samples,
            lights,
        }
    }
}

/// The shader's material table for shade parameters.
pub(crate) fn material_table(p: &ShadeParams) -> Box<MaterialTable> {
    let mut t = Box::new([[0.0f32; 4]; crate::MAX_OBJECTS]);
    for (slot, m) in t.iter_mut().zip(&p.materials) {
        *slot = [m.ambient, m.diffuse, m.specular, m.shininess];
    }
    t
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
                &crate::device::shaders::GATHER_MODULE,
                "gather",
                &[
                    UNIFORM, DYNAMIC, READ, READ, READ, READ, WRITE, WRITE, READ, READ, WRITE,
                ],
            ),
            shade: Pass::new(
                d,
                &crate::device::shaders::SHADE_MODULE,
                "shade",
                &[
                    UNIFORM, DYNAMIC, READ, READ, READ, READ, READ, WRITE, WRITE, READ, UNIFORM,
                ],
            ),
        }
    }
}
