//! # blend_layers (GPU twin of `cpu.rs`): blend_layers.wgsl, three entry
//! points over one layout: `begin` clears the accumulator, `blend` adds a layer, `compose`
//! writes the composite over the background into the colour image.

use crate::device::util::{self, Slot, DYNAMIC, READ, UNIFORM, WRITE};
use wgpu::ShaderStages;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct BlendBlock {
    pub hole_alpha: f32,
    pub slot: u32,
    pub pad: [u32; 2],
    pub background: [f32; 3],
    pub pad2: u32,
}

pub(crate) struct BlendLayers {
    pub bgl: wgpu::BindGroupLayout,
    pub begin: wgpu::ComputePipeline,
    pub blend: wgpu::ComputePipeline,
    pub compose: wgpu::ComputePipeline,
}

const SLOTS: [Slot; 8] = [UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE];

impl BlendLayers {
    pub fn new(ctx: &crate::device::context::GpuContext) -> BlendLayers {
        let d = &ctx.device;
        let bgl = util::layout(d, "blend_layers", &SLOTS, ShaderStages::COMPUTE);
        let m = util::module(d, &crate::device::shaders::BLEND_LAYERS_MODULE);
        BlendLayers {
            begin: util::compute(d, &m, "begin", &bgl),
            blend: util::compute(d, &m, "blend", &bgl),
            compose: util::compute(d, &m, "compose", &bgl),
            bgl,
        }
    }
}
