//! # blend_layers (GPU twin of `cpu.rs`): blend_layers.wgsl, three entry
//! points over one layout: `begin` clears the accumulator, `blend` adds a layer, `compose`
//! writes the composite over the background into the colour image.

use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{self, Res, Slot, DYNAMIC, READ, UNIFORM, WRITE};
use crate::stats::PassId;
use wgpu::ShaderStages;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct BlendBlock {
    pub hole_alpha: f32,
    pub slot: u32,
    pub pad: [u32; 2],
    pub background: [f32; 3],
    pub pad2: u32,
}

pub(crate) struct BlendLayers {
    bgl: wgpu::BindGroupLayout,
    begin: wgpu::ComputePipeline,
    blend: wgpu::ComputePipeline,
    transmit: wgpu::ComputePipeline,
    compose: wgpu::ComputePipeline,
}

const SLOTS: [Slot; 9] = [
    UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE, READ,
];

impl GpuPass for BlendLayers {
    fn new(ctx: &GpuContext, _: &Shared) -> BlendLayers {
        let d = &ctx.device;
        let bgl = util::layout(d, "blend_layers", &SLOTS, ShaderStages::COMPUTE);
        let m = util::module(d, &crate::device::shaders::BLEND_LAYERS_MODULE);
        BlendLayers {
            begin: util::compute(d, &m, "begin", &bgl),
            blend: util::compute(d, &m, "blend", &bgl),
            transmit: util::compute(d, &m, "transmit", &bgl),
            compose: util::compute(d, &m, "compose", &bgl),
            bgl,
        }
    }
}

impl BlendLayers {
    fn group(&self, b: Binder<'_>, g: usize, c: usize) -> wgpu::BindGroup {
        let (f, s) = (b.f, b.shared);
        let [view, block] = b.view_and::<BlendBlock>();
        b.bind(
            "blend_layers",
            &self.bgl,
            &[
                view,
                block,
                Res::Buf(&f.id[g]),
                Res::Buf(&f.surface),
                Res::Buf(&f.attr_style),
                Res::Buf(&f.colour[c]),
                Res::Buf(&f.acc),
                Res::Buf(&s.counters),
                Res::Buf(&f.attr_pos),
            ],
        )
    }
}

/// `begin` (no `hole_alpha`: clears the accumulator) or `blend` of the current layer.
pub(crate) fn record_blend(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &Cursor,
    hole_alpha: Option<f32>,
    background: [f32; 3],
) -> Result<(), GpuError> {
    let q = rec.section();
    let grid = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let slot = rec.slot()?;
    let off = rec.arena.push(&BlendBlock {
        hole_alpha: hole_alpha.unwrap_or(0.0),
        slot,
        pad: [0; 2],
        background,
        pad2: 0,
    })?;
    let pass = b.pass::<BlendLayers>();
    let pipeline = match hole_alpha {
        Some(_) => &pass.blend,
        None => &pass.begin,
    };
    let group = pass.group(b, cur.g, cur.colour);
    rec.image_pass(q, pipeline, &group, &[off], grid);
    match hole_alpha {
        Some(_) => rec.end(PassId::BlendLayers, 1, vec![slot], q),
        None => rec.end(PassId::BlendBegin, 1, vec![], q),
    }
}

/// `transmit` of the current light layer (coloured translucent shadows).
pub(crate) fn record_transmit(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &Cursor,
    hole_alpha: f32,
) -> Result<(), GpuError> {
    let q = rec.section();
    let grid = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let slot = rec.slot()?;
    let off = rec.arena.push(&BlendBlock {
        hole_alpha,
        slot,
        pad: [0; 2],
        background: [0.0; 3],
        pad2: 0,
    })?;
    let pass = b.pass::<BlendLayers>();
    let group = pass.group(b, cur.g, cur.colour);
    rec.image_pass(q, &pass.transmit, &group, &[off], grid);
    rec.end(PassId::BlendLayers, 1, vec![slot], q)
}

/// The composite over the background into colour image 0.
pub(crate) fn record_compose(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    background: [f32; 3],
) -> Result<(), GpuError> {
    let q = rec.section();
    let grid = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let off = rec.arena.push(&BlendBlock {
        hole_alpha: 0.0,
        slot: 0,
        pad: [0; 2],
        background,
        pad2: 0,
    })?;
    let pass = b.pass::<BlendLayers>();
    let group = pass.group(b, 0, 0);
    rec.image_pass(q, &pass.compose, &group, &[off], grid);
    rec.end(PassId::Compose, 1, vec![], q)
}
