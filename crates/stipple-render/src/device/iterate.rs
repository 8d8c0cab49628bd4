//! # iterate: "until stable" iteration on the GPU without a CPU round trip
//!
//! Before each iteration after the first, one thread writes the indirect dispatch arguments
//! of the next fill iteration from the previous one's changed-pixel counter
//! (shaders/iterate.wgsl).

use crate::device::util::{Pass, DYNAMIC, READ, WRITE};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct IterateBlock {
    pub prev_slot: u32,
    pub args_slot: u32,
    pub groups_x: u32,
    pub groups_y: u32,
}

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &crate::device::shaders::ITERATE_MODULE,
        "iterate",
        &[DYNAMIC, READ, WRITE],
    )
}
