//! # output (GPU twin of the CPU's final sRGB encoding in cpu/mod.rs): linear colour → sRGB
//! 8-bit RGBA through the CPU's own encoding table (output.wgsl).

use crate::device::util::{Pass, READ, UNIFORM, WRITE};

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &crate::device::shaders::OUTPUT_MODULE,
        "output",
        &[UNIFORM, READ, READ, WRITE],
    )
}
