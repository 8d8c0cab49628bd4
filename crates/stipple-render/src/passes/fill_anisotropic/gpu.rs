//! # fill_anisotropic (GPU twin of `cpu.rs`): fill_anisotropic.wgsl.

use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::stats::PassId;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct FillAnisotropicBlock {
    pub delta: f32,
    pub all_empty: u32,
    pub slot: u32,
    pub pad: u32,
}

/// The pass's pipeline.
pub(crate) struct Gpu(Pass);

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        Gpu(Pass::new(
            &ctx.device,
            &crate::device::shaders::FILL_ANISOTROPIC_MODULE,
            "fill_anisotropic",
            &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE],
        ))
    }
}

/// The iterations ping-pong the colour and the surface depth (`surface` ↔ `surface_b`);
/// the filled depth is copied back into `surface`, which every later pass reads.
pub(crate) fn record(
    a: &super::FillAnisotropic,
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &mut Cursor,
) -> Result<(), GpuError> {
    let q = rec.section();
    let (gx, gy) = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let mut steps = Vec::new();
    let mut slots = Vec::new();
    for _ in 0..a.iterations {
        let slot = rec.slot()?;
        steps.push(rec.arena.push(&FillAnisotropicBlock {
            delta: a.delta,
            all_empty: a.all_empty as u32,
            slot,
            pad: 0,
        })?);
        slots.push(slot);
    }
    let (f, pass) = (b.f, b.pass::<Gpu>());
    let depth = [&f.surface, &f.surface_b];
    let mut s = 0;
    let mut p = rec.timed_pass(q);
    p.set_pipeline(&pass.0.pipeline);
    for off in steps {
        let [view, block] = b.view_and::<FillAnisotropicBlock>();
        let group = b.bind(
            "fill_anisotropic",
            &pass.0.bgl,
            &[
                view,
                block,
                Res::Buf(&f.id[cur.g]),
                Res::Buf(depth[s]),
                Res::Buf(&f.colour[cur.colour]),
                Res::Buf(depth[1 - s]),
                Res::Buf(&f.colour[1 - cur.colour]),
                Res::Buf(&b.shared.counters),
            ],
        );
        p.set_bind_group(0, &group, &[off]);
        p.dispatch_workgroups(gx, gy, 1);
        cur.colour = 1 - cur.colour;
        s = 1 - s;
    }
    drop(p);
    if s == 1 {
        rec.enc
            .copy_buffer_to_buffer(&f.surface_b, 0, &f.surface, 0, 4 * f.pixels());
    }
    rec.end(PassId::FillAnisotropic, a.iterations, slots, q)
}
