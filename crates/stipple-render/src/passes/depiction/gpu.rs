//! # depiction (GPU twin of `cpu.rs`): depiction.wgsl (one level) and
//! depiction_apply.wgsl (colour × term).

use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::stats::PassId;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct DepictionBlock {
    pub weight: f32,
    pub epsilon: f32,
    pub first: u32,
    pub pad: u32,
}

/// The pass's pipelines: one level, and the term applied to the colour.
pub(crate) struct Gpu {
    level: Pass,
    apply: Pass,
}

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        Gpu {
            level: Pass::new(
                &ctx.device,
                &crate::device::shaders::DEPICTION_MODULE,
                "depiction_level",
                &[UNIFORM, DYNAMIC, READ, WRITE, WRITE],
            ),
            apply: Pass::new(
                &ctx.device,
                &crate::device::shaders::DEPICTION_APPLY_MODULE,
                "depiction_apply",
                &[UNIFORM, READ, READ, READ, WRITE],
            ),
        }
    }
}

pub(crate) fn record(
    d: &super::Depiction,
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &mut Cursor,
) -> Result<(), GpuError> {
    let q = rec.section();
    let (gx, gy) = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let mut offs = Vec::new();
    for (k, weight) in super::cpu::level_weights(d.levels, d.xi)
        .into_iter()
        .enumerate()
    {
        offs.push(rec.arena.push(&DepictionBlock {
            weight,
            epsilon: d.epsilon,
            first: (k == 0) as u32,
            pad: 0,
        })?);
    }
    let (f, pass) = (b.f, b.pass::<Gpu>());
    let level = |l: usize| {
        let [view, block] = b.view_and::<DepictionBlock>();
        b.bind(
            "level",
            &pass.level.bgl,
            &[
                view,
                block,
                Res::Buf(&f.levels[l]),
                Res::Buf(&f.levels[1 - l]),
                Res::Buf(&f.shading),
            ],
        )
    };
    let apply = b.bind(
        "apply",
        &pass.apply.bgl,
        &[
            Res::Buf(&b.shared.view),
            Res::Buf(&f.surface),
            Res::Buf(&f.shading),
            Res::Buf(&f.colour[cur.colour]),
            Res::Buf(&f.colour[1 - cur.colour]),
        ],
    );
    rec.enc
        .copy_buffer_to_buffer(&f.surface, 0, &f.levels[0], 0, 4 * f.pixels());
    let mut p = rec.timed_pass(q);
    p.set_pipeline(&pass.level.pipeline);
    for (k, off) in offs.iter().enumerate() {
        p.set_bind_group(0, &level(k % 2), &[*off]);
        p.dispatch_workgroups(gx, gy, 1);
    }
    p.set_pipeline(&pass.apply.pipeline);
    p.set_bind_group(0, &apply, &[]);
    p.dispatch_workgroups(gx, gy, 1);
    drop(p);
    cur.colour = 1 - cur.colour;
    rec.end(PassId::Depiction, d.levels, vec![], q)
}
