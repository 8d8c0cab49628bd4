//! # antialias (GPU twin of `cpu.rs`): antialias.wgsl with
//! src/shaders/weighted.wgsl.

use crate::device::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct AntialiasBlock {
    /// 1 / z_far, computed on the CPU as the reference does.
    pub inv_far: f32,
    pub threshold: f32,
    pub strength: f32,
    pub slot: u32,
}

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &crate::device::shaders::ANTIALIAS_MODULE,
        "antialias",
        &[UNIFORM, DYNAMIC, READ, READ, WRITE, WRITE],
    )
}
