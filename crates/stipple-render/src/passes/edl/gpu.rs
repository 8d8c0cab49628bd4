//! # edl (GPU twin of `cpu.rs`): edl.wgsl.

use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::stats::PassId;

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

/// The pass's pipeline.
pub(crate) struct Gpu(Pass);

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        Gpu(Pass::new(
            &ctx.device,
            &crate::device::shaders::EDL_MODULE,
            "edl",
            &[UNIFORM, DYNAMIC, READ, READ, WRITE],
        ))
    }
}

pub(crate) fn record(
    e: &super::Edl,
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &mut Cursor,
) -> Result<(), GpuError> {
    let q = rec.section();
    let grid = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let off = rec.arena.push(&EdlBlock::new(e.strength, e.radius))?;
    let pass = b.pass::<Gpu>();
    let [view, block] = b.view_and::<EdlBlock>();
    let group = b.bind(
        "edl",
        &pass.0.bgl,
        &[
            view,
            block,
            Res::Buf(&b.f.surface),
            Res::Buf(&b.f.colour[cur.colour]),
            Res::Buf(&b.f.colour[1 - cur.colour]),
        ],
    );
    rec.image_pass(q, &pass.0.pipeline, &group, &[off], grid);
    cur.colour = 1 - cur.colour;
    rec.end(PassId::Edl, 1, vec![], q)
}
