//! The hole-filling step shared by the GPU fill_background and fill_occluded passes
//! (fill.wgsl + the pass's own file), with the window cells of masks::window.

use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::iterate::IterateBlock;
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{self, Pass, Res, DYNAMIC, READ, UNIFORM, WRITE};
use crate::masks::{window, MAX_RADIUS};
use crate::pipeline::Iterations;
use crate::stats::PassId;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct FillBlock {
    pub first: u32,
    pub count: u32,
    pub gap: f32,
    pub slot: u32,
    /// fill_occluded: 1 when the frame's `peel_ref` holds each pixel's plane (fill_planes.wgsl).
    pub planes: u32,
    /// The step's index mod 2: which half of the planes it reads.
    pub parity: u32,
    pub pad: [u32; 2],
}

/// The pipeline of a fill pass: fill.wgsl with the pass's `candidate` and `solid`.
pub(crate) fn new(ctx: &GpuContext, m: &crate::device::shaders::ShaderModule) -> Pass {
    Pass::new(
        &ctx.device,
        m,
        "fill",
        &[
            UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE, WRITE,
        ],
    )
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

/// The window cells on the device, shared by both fill passes.
pub(crate) struct Cells {
    buffer: wgpu::Buffer,
    ranges: Vec<(u32, u32)>,
}

impl GpuPass for Cells {
    fn new(ctx: &GpuContext, _: &Shared) -> Cells {
        let (cells, ranges) = window_cells();
        Cells {
            buffer: util::storage_init(&ctx.device, "window cells", bytemuck::cast_slice(&cells)),
            ranges,
        }
    }
}

/// Records `its` iterations of the fill pipeline `fill` (the pass `id`) with window
/// `radius` and layer gap `gap` (with the planes fill_planes.wgsl left in `peel_ref`, when
/// `planes`); "until stable" iterations after the first are dispatched
/// indirectly from the previous one's changed-pixel count (see [`crate::device::iterate`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn record(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cur: &mut Cursor,
    fill: &Pass,
    id: PassId,
    its: Iterations,
    radius: u32,
    gap: f32,
    planes: bool,
) -> Result<(), GpuError> {
    let cells = b.pass::<Cells>();
    let (first, count) = *cells
        .ranges
        .get(radius as usize)
        .filter(|_| radius >= 1)
        .ok_or_else(|| GpuError::TooLarge(format!("fill radius {radius} (1 to {MAX_RADIUS})")))?;
    let q = rec.section();
    let (gx, gy) = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let stable = matches!(its, Iterations::UntilStable { .. });
    let mut steps = Vec::new();
    let mut slots = Vec::new();
    for k in 0..its.max() {
        let slot = rec.slot()?;
        let off = rec.arena.push(&FillBlock {
            first,
            count,
            gap,
            slot,
            planes: planes as u32,
            parity: k % 2,
            pad: [0; 2],
        })?;
        let it = if stable && k > 0 {
            Some(rec.arena.push(&IterateBlock {
                prev_slot: slot - 1,
                args_slot: slot,
                groups_x: gx,
                groups_y: gy,
            })?)
        } else {
            None
        };
        steps.push((cur.g, off, it, slot));
        slots.push(slot);
        cur.g = 1 - cur.g;
    }
    let (f, s) = (b.f, b.shared);
    let groups = [0, 1].map(|src| {
        let [view, block] = b.view_and::<FillBlock>();
        b.bind(
            "fill",
            &fill.bgl,
            &[
                view,
                block,
                Res::Buf(&cells.buffer),
                Res::Buf(&f.depth[src]),
                Res::Buf(&f.id[src]),
                Res::Buf(&f.depth[1 - src]),
                Res::Buf(&f.id[1 - src]),
                Res::Buf(&s.counters),
                Res::Buf(&f.peel_ref),
            ],
        )
    });
    let mut p = rec.timed_pass(q);
    for (src, off, it, slot) in steps {
        if let Some(ioff) = it {
            p.set_pipeline(&s.iterate.pipeline);
            p.set_bind_group(0, &s.iterate_group, &[ioff]);
            p.dispatch_workgroups(1, 1, 1);
            p.set_pipeline(&fill.pipeline);
            p.set_bind_group(0, &groups[src], &[off]);
            p.dispatch_workgroups_indirect(&s.indirect, slot as u64 * 12);
        } else {
            p.set_pipeline(&fill.pipeline);
            p.set_bind_group(0, &groups[src], &[off]);
            p.dispatch_workgroups(gx, gy, 1);
        }
    }
    drop(p);
    rec.end_iterated(id, its.max(), stable, slots, q)
}
