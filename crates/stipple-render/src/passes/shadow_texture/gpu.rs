//! # shadow_texture (GPU twin of `cpu.rs`): shadow_texture.wgsl, one
//! thread per point of a chunk, adding to the point's sum for the light (16 bits of its two
//! words); translucent modes read the light left per pixel (the blend accumulator) and the
//! cloud's bits of points already marked.

use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{flat_groups, Rec};
use crate::device::util::{Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::stats::PassId;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct MarkBlock {
    pub base: u32,
    pub count: u32,
    pub gap: f32,
    pub slope_cap: f32,
    pub face: u32,
    pub light: u32,
    pub has_normals: u32,
    pub slot: u32,
    /// [`super::cpu::MarkMode::code`].
    pub mode: u32,
    /// Coloured shadows: red and blue sums into `lit_rb` too.
    pub coloured: u32,
    pub pad: [u32; 2],
}

/// The pass's pipeline.
pub(crate) struct Gpu(Pass);

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        Gpu(Pass::new(
            &ctx.device,
            &crate::device::shaders::SHADOW_TEXTURE_MODULE,
            "mark",
            &[
                UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, READ, WRITE, WRITE,
            ],
        ))
    }
}

/// `mark` over every chunk against the light image in `cur.g`.
pub(crate) fn record(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &Cursor,
    cloud: &GpuCloud,
    mp: &super::cpu::MarkParams,
) -> Result<(), GpuError> {
    let q = rec.section();
    let slot = rec.slot()?;
    let pass = b.pass::<Gpu>();
    let mut work = Vec::new();
    for c in &cloud.chunks {
        let lit = c
            .lit
            .as_ref()
            .ok_or_else(|| GpuError::Wgpu("shadow_texture: a chunk has no shadow counts".into()))?;
        let off = rec.arena.push(&MarkBlock {
            base: c.base,
            count: c.count,
            gap: mp.gap,
            slope_cap: mp.slope_cap,
            face: mp.face,
            light: mp.light,
            has_normals: c.normals.is_some() as u32,
            slot,
            mode: mp.mode.code(),
            coloured: (mp.coloured && c.lit_rb.is_some()) as u32,
            pad: [0; 2],
        })?;
        let [view, block] = b.view_and::<MarkBlock>();
        let group = b.bind_chunk(
            "shadow_texture",
            &pass.0.bgl,
            &[
                view,
                block,
                Res::Buf(&c.positions),
                Res::Buf(c.normals.as_ref().unwrap_or(&cloud.dummy)),
                Res::Buf(&b.f.depth[cur.g]),
                Res::Buf(lit),
                Res::Buf(&b.shared.counters),
                Res::Buf(&b.f.acc),
                Res::Buf(&cloud.marked),
                Res::Buf(c.lit_rb.as_ref().unwrap_or(&cloud.dummy_rw)),
            ],
        );
        work.push((group, off, flat_groups(b.ctx, c.count as u64)));
    }
    let mut p = rec.timed_pass(q);
    p.set_pipeline(&pass.0.pipeline);
    for (bg, off, (gx, gy)) in &work {
        p.set_bind_group(0, bg, &[*off]);
        p.dispatch_workgroups(*gx, *gy, 1);
    }
    drop(p);
    rec.end(PassId::ShadowTexture, 1, vec![slot], q)
}
