//! # antialias (GPU twin of `cpu.rs`): antialias.wgsl with
//! src/shaders/weighted.wgsl.

use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::params::ViewParams;
use crate::stats::PassId;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct AntialiasBlock {
    /// 1 / z_far, computed on the CPU as the reference does.
    pub inv_far: f32,
    pub threshold: f32,
    pub strength: f32,
    pub slot: u32,
}

/// The pass's pipeline.
pub(crate) struct Gpu(Pass);

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        Gpu(Pass::new(
            &ctx.device,
            &crate::device::shaders::ANTIALIAS_MODULE,
            "antialias",
            &[UNIFORM, DYNAMIC, READ, READ, WRITE, WRITE],
        ))
    }
}

pub(crate) fn record(
    a: &super::Antialias,
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &mut Cursor,
    v: &ViewParams,
) -> Result<(), GpuError> {
    let q = rec.section();
    let grid = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let slot = rec.slot()?;
    let off = rec.arena.push(&AntialiasBlock {
        inv_far: 1.0 / v.far,
        threshold: a.threshold,
        strength: a.strength,
        slot,
    })?;
    let pass = b.pass::<Gpu>();
    let [view, block] = b.view_and::<AntialiasBlock>();
    let group = b.bind(
        "antialias",
        &pass.0.bgl,
        &[
            view,
            block,
            Res::Buf(&b.f.surface),
            Res::Buf(&b.f.colour[cur.colour]),
            Res::Buf(&b.f.colour[1 - cur.colour]),
            Res::Buf(&b.shared.counters),
        ],
    );
    rec.image_pass(q, &pass.0.pipeline, &group, &[off], grid);
    cur.colour = 1 - cur.colour;
    rec.end(PassId::Antialias, 1, vec![slot], q)
}
