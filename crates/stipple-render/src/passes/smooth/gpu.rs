//! # smooth (GPU twin of `cpu.rs`): smooth.wgsl with src/shaders/weighted.wgsl.

use crate::device::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};
use crate::pipeline::Kernel;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct SmoothBlock {
    pub weights: [f32; 12],
}

impl SmoothBlock {
    pub fn new(k: Kernel) -> SmoothBlock {
        let mut weights = [0.0; 12];
        weights[..9].copy_from_slice(&k.weights());
        SmoothBlock { weights }
    }
}

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &crate::device::shaders::SMOOTH_MODULE,
        "smooth_pass",
        &[UNIFORM, DYNAMIC, READ, READ, WRITE],
    )
}
