//! # output (GPU twin of the CPU's final sRGB encoding in cpu/mod.rs): linear colour → sRGB
//! 8-bit RGBA through the CPU's own encoding table (shaders/output.wgsl).

use super::util::{Pass, READ, UNIFORM, WRITE};

pub(crate) fn new(ctx: &super::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &super::shaders::OUTPUT_MODULE,
        "output",
        &[UNIFORM, READ, READ, WRITE],
    )
}
