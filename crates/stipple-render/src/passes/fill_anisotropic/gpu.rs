//! # fill_anisotropic (GPU twin of `cpu.rs`): fill_anisotropic.wgsl.

use crate::device::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct FillAnisotropicBlock {
    pub delta: f32,
    pub all_empty: u32,
    pub slot: u32,
    pub pad: u32,
}

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &crate::device::shaders::FILL_ANISOTROPIC_MODULE,
        "fill_anisotropic",
        &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE],
    )
}
