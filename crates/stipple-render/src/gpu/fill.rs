//! The hole-filling step shared by the GPU fill_background and fill_occluded passes
//! (shaders/fill.wgsl + the pass's own file), with the window cells of masks::window.

use super::util::{self, Res, DYNAMIC, READ, UNIFORM, WRITE};
use super::GpuContext;
use crate::masks::{window, MAX_RADIUS};
use wgpu::ShaderStages;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct FillBlock {
    pub first: u32,
    pub count: u32,
    pub gap: f32,
    pub slot: u32,
}

pub(crate) struct Fill {
    pub bgl: wgpu::BindGroupLayout,
    pub pipeline: wgpu::ComputePipeline,
}

impl Fill {
    pub fn new(ctx: &GpuContext, m: &super::shaders::ShaderModule) -> Fill {
        let d = &ctx.device;
        let bgl = util::layout(
            d,
            m.name,
            &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE],
            ShaderStages::COMPUTE,
        );
        let module = util::module(d, m);
        let pipeline = util::compute(d, &module, "fill", &bgl);
        Fill { bgl, pipeline }
    }

    #[allow(clippy::too_many_arguments)]
    pub fn bind(
        &self,
        ctx: &GpuContext,
        view: &wgpu::Buffer,
        arena: &wgpu::Buffer,
        cells: &wgpu::Buffer,
        src: (&wgpu::Buffer, &wgpu::Buffer),
        dst: (&wgpu::Buffer, &wgpu::Buffer),
        counters: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        util::bind(
            &ctx.device,
            "fill",
            &self.bgl,
            &[
                Res::Buf(view),
                Res::Arena(arena, std::mem::size_of::<FillBlock>() as u64),
                Res::Buf(cells),
                Res::Buf(src.0),
                Res::Buf(src.1),
                Res::Buf(dst.0),
                Res::Buf(dst.1),
                Res::Buf(counters),
            ],
        )
    }
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
