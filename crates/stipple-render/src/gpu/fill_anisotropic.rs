//! # fill_anisotropic (GPU twin of cpu/fill_anisotropic.rs): shaders/fill_anisotropic.wgsl.

use super::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct FillAnisotropicBlock {
    pub delta: f32,
    pub all_empty: u32,
    pub slot: u32,
    pub pad: u32,
}

pub(crate) fn new(ctx: &super::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &super::shaders::FILL_ANISOTROPIC_MODULE,
        "fill_anisotropic",
        &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE],
    )
}
