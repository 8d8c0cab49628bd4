//! # visibility (GPU twin of `cpu.rs`): visibility.wgsl.

use crate::device::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};
use crate::passes::visibility::cpu::{kernel_offsets, KERNELS};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct VisibilityBlock {
    pub first: u32,
    pub count: u32,
    pub threshold: f32,
    pub slot: u32,
}

/// Every kernel's offsets in one table, and each kernel's (first, count), indexed by size.
pub(crate) fn offset_table() -> (Vec<[i32; 4]>, Vec<(u32, u32)>) {
    let mut table = Vec::new();
    let mut ranges = vec![(0, 0); *KERNELS.end() as usize + 1];
    for k in KERNELS {
        let o = kernel_offsets(k);
        ranges[k as usize] = (table.len() as u32, o.len() as u32);
        table.extend(o);
    }
    (table, ranges)
}

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> Pass {
    Pass::new(
        &ctx.device,
        &crate::device::shaders::VISIBILITY_MODULE,
        "visibility",
        &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE],
    )
}
