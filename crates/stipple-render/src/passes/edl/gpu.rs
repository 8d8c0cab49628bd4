//! # edl (GPU twin of `cpu.rs`): edl.wgsl.

use crate::device::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct EdlBlock {
    /// The eight offsets of cpu::edl::offsets, flattened.
    pub offsets: [i32; 16],
    pub strength: f32,
    pub pad: [u32; 3],
}

impl EdlBlock {
    pub fn new(strength: f32, radius: f32) -> EdlBlock {
        let mut offsets = [0; 16];
        for (k, o) in crate::passes::edl::cpu::offsets(radius).iter().enumerate() {
            offsets[2 * k] = o[0];
            offsets[2 * k + 1] = o[1];
        }
        EdlBlock {
            offsets,
            strength,
            pad: [0; 3],
        }
    }
}

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &crate::device::shaders::EDL_MODULE,
        "edl",
        &[UNIFORM, DYNAMIC, READ, READ, WRITE],
    )
}
