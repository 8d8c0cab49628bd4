//! # shadow_texture (GPU twin of `cpu.rs`): shadow_texture.wgsl, one
//! thread per point of a chunk, adding to the point's count of the light's byte.

use crate::device::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct MarkBlock {
    pub base: u32,
    pub count: u32,
    pub gap: f32,
    pub slope_cap: f32,
    pub face: u32,
    pub shift: u32,
    pub has_normals: u32,
    pub slot: u32,
}

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &crate::device::shaders::SHADOW_TEXTURE_MODULE,
        "mark",
        &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE],
    )
}
