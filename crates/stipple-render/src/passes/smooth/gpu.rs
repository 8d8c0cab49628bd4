//! # smooth (GPU twin of `cpu.rs`): smooth.wgsl with src/shaders/weighted.wgsl.

use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::pipeline::Kernel;
use crate::stats::PassId;

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

/// The pass's pipeline.
pub(crate) struct Gpu(Pass);

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        Gpu(Pass::new(
            &ctx.device,
            &crate::device::shaders::SMOOTH_MODULE,
            "smooth_pass",
            &[UNIFORM, DYNAMIC, READ, READ, WRITE],
        ))
    }
}

pub(crate) fn record(
    s: &super::Smooth,
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &mut Cursor,
) -> Result<(), GpuError> {
    let q = rec.section();
    let (gx, gy) = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let off = rec.arena.push(&SmoothBlock::new(s.kernel))?;
    let pass = b.pass::<Gpu>();
    let mut p = rec.timed_pass(q);
    p.set_pipeline(&pass.0.pipeline);
    for _ in 0..s.iterations {
        let [view, block] = b.view_and::<SmoothBlock>();
        let group = b.bind(
            "smooth",
            &pass.0.bgl,
            &[
                view,
                block,
                Res::Buf(&b.f.id[cur.g]),
                Res::Buf(&b.f.colour[cur.colour]),
                Res::Buf(&b.f.colour[1 - cur.colour]),
            ],
        );
        p.set_bind_group(0, &group, &[off]);
        p.dispatch_workgroups(gx, gy, 1);
        cur.colour = 1 - cur.colour;
    }
    drop(p);
    rec.end(PassId::Smooth, s.iterations, vec![], q)
}
