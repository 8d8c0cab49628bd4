//! The hole-filling step shared by the GPU fill_background and fill_occluded passes
//! (fill.wgsl + the pass's own file), with the window cells of masks::window.

use crate::device::context::GpuContext;
use crate::device::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};
use crate::masks::{window, MAX_RADIUS};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct FillBlock {
    pub first: u32,
    pub count: u32,
    pub gap: f32,
    pub slot: u32,
}

/// The pipeline of a fill pass: fill.wgsl with the pass's `candidate` and `solid`.
pub(crate) fn new(ctx: &GpuContext, m: &crate::device::shaders::ShaderModule) -> Pass {
    Pass::new(
        &ctx.device,
        m,
        "fill",
        &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE],
    )
}

/// Window cells (dx, dy, mask, ring) for radius 1, 2, …, MAX_RADIUS, concatenated; and where
/// each radius starts and how many cells it has.
pub(crate) fn window_cells() -> (Vec<[i32; 4]>, Vec<(u32, u32)>) {
    let mut cells = Vec::new();
    let mut ranges = vec![(0, 0)];
    for r in 1..=MAX_RADIUS {
        let w = window(r);
        ranges.push((cells.len() as u32, w.len() as u32));
        cells.extend(
            w.iter()
                .map(|&(dx, dy, m)| [dx, dy, m as i32, dx.abs().max(dy.abs())]),
        );
    }
    (cells, ranges)
}
