//! # fill_occluded (GPU twin of `cpu.rs`)
//!
//! fill_occluded.wgsl: candidates are covered pixels, solid neighbours are at least d̃
//! nearer; the step itself is fill.wgsl (see [`crate::passes::fill::gpu`]).

use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::stats::PassId;

/// The pass's pipeline.
pub(crate) struct Gpu(pub crate::device::util::Pass);

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        Gpu(crate::passes::fill::gpu::new(
            ctx,
            &crate::device::shaders::FILL_OCCLUDED_MODULE,
        ))
    }
}

/// fill_planes.wgsl: each pixel's tangent plane for the slope-aware test.
pub(crate) struct Planes(Pass);

impl GpuPass for Planes {
    fn new(ctx: &GpuContext, _: &Shared) -> Planes {
        Planes(Pass::new(
            &ctx.device,
            &crate::device::shaders::FILL_PLANES_MODULE,
            "fill_planes",
            &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE],
        ))
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PlanesBlock {
    pad: [u32; 4],
}

/// Records the planes of geometry image `cur.g`'s points into the first half of the frame's
/// `peel_ref` (free between a layer's projection and its shade): gather (their positions and
/// normals, chunk by chunk), then fill_planes.wgsl.
pub(crate) fn record_planes(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &Cursor,
    cloud: &GpuCloud,
) -> Result<(), GpuError> {
    crate::passes::shade::gpu::record_gather(rec, b, cur, cloud, PassId::FillOccluded)?;
    let q = rec.section();
    let grid = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let off = rec.arena.push(&PlanesBlock { pad: [0; 4] })?;
    let pass = b.pass::<Planes>();
    let [view, block] = b.view_and::<PlanesBlock>();
    let f = b.f;
    let group = b.bind(
        "fill_planes",
        &pass.0.bgl,
        &[
            view,
            block,
            Res::Buf(&f.id[cur.g]),
            Res::Buf(&f.attr_pos),
            Res::Buf(&f.attr_normal),
            Res::Buf(&f.peel_ref),
        ],
    );
    rec.image_pass(q, &pass.0.pipeline, &group, &[off], grid);
    rec.end(PassId::FillOccluded, 1, vec![], q)
}
