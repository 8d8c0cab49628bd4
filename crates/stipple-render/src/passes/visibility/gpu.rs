//! # visibility (GPU twin of `cpu.rs`): visibility.wgsl.

use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{self, Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::passes::visibility::cpu::{kernel_offsets, KERNELS};
use crate::stats::PassId;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct VisibilityBlock {
    pub first: u32,
    pub count: u32,
    pub threshold: f32,
    pub slot: u32,
}

/// Every kernel's offsets in one table, and each kernel's (first, count), indexed by size.
pub(crate) fn offset_table() -> (Vec<[i32; 4]>, Vec<(u32, u32)>) {
    let mut table = Vec::new();
    let mut ranges = vec![(0, 0); *KERNELS.end() as usize + 1];
    for k in KERNELS {
        let o = kernel_offsets(k);
        ranges[k as usize] = (table.len() as u32, o.len() as u32);
        table.extend(o);
    }
    (table, ranges)
}

/// The pass's pipeline and its kernels' offset table.
pub(crate) struct Gpu {
    pass: Pass,
    offsets: wgpu::Buffer,
    ranges: Vec<(u32, u32)>,
}

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        let (table, ranges) = offset_table();
        Gpu {
            pass: Pass::new(
                &ctx.device,
                &crate::device::shaders::VISIBILITY_MODULE,
                "visibility",
                &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE],
            ),
            offsets: util::storage_init(
                &ctx.device,
                "visibility offsets",
                bytemuck::cast_slice(&table),
            ),
            ranges,
        }
    }
}

pub(crate) fn record(
    vis: &super::Visibility,
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &mut Cursor,
) -> Result<(), GpuError> {
    let gpu = b.pass::<Gpu>();
    let kernel = vis.kernel;
    let (first, count) = *gpu
        .ranges
        .get(kernel as usize)
        .filter(|r| r.1 > 0)
        .ok_or_else(|| {
            GpuError::TooLarge(format!(
                "visibility kernel {kernel} ({} to {})",
                KERNELS.start(),
                KERNELS.end()
            ))
        })?;
    let q = rec.section();
    let grid = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let slot = rec.slot()?;
    let off = rec.arena.push(&VisibilityBlock {
        first,
        count,
        threshold: vis.threshold,
        slot,
    })?;
    let (f, g) = (b.f, cur.g);
    let [view, block] = b.view_and::<VisibilityBlock>();
    let group = b.bind(
        "visibility",
        &gpu.pass.bgl,
        &[
            view,
            block,
            Res::Buf(&gpu.offsets),
            Res::Buf(&f.depth[g]),
            Res::Buf(&f.id[g]),
            Res::Buf(&f.depth[1 - g]),
            Res::Buf(&f.id[1 - g]),
            Res::Buf(&b.shared.counters),
        ],
    );
    rec.image_pass(q, &gpu.pass.pipeline, &group, &[off], grid);
    cur.g = 1 - g;
    rec.end(PassId::Visibility, 1, vec![slot], q)
}
