//! # bucket_sort (GPU twin of `cpu.rs`): bucket_sort.wgsl, a compute sort in two
//! submissions: the depth range first (read back: the slicing is made on the host by the
//! same code as the CPU's), then the slices, the two levels of buckets and the order.

use super::cpu::Sorted;
use super::Slicing;
use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{GpuPass, Shared};
use crate::device::record::{copy_out, flat_groups};
use crate::device::util::{self, Pass, Res, READ, UNIFORM, WRITE};
use crate::params::ViewParams;
use wgpu::util::DeviceExt;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct SortBlock {
    pub base: u32,
    pub count: u32,
    pub near: f32,
    pub eps: f32,
    pub n: u32,
    pub k: u32,
    pub pad: [u32; 2],
}

/// The five kernels.
pub(crate) struct BucketSort {
    depth_range: Pass,
    classify: Pass,
    scan: Pass,
    scatter: Pass,
    refine: Pass,
}

const SLOTS: [util::Slot; 7] = [UNIFORM, UNIFORM, READ, WRITE, WRITE, WRITE, WRITE];

impl GpuPass for BucketSort {
    fn new(ctx: &GpuContext, _: &Shared) -> BucketSort {
        let m = &crate::device::shaders::BUCKET_SORT_MODULE;
        let p = |entry| Pass::new(&ctx.device, m, entry, &SLOTS);
        BucketSort {
            depth_range: p("depth_range"),
            classify: p("classify"),
            scan: p("scan"),
            scatter: p("scatter"),
            refine: p("refine"),
        }
    }
}

/// A sort's buffers, made once for a cloud and reused by every sort of it: after a sort,
/// `order` holds the kept points' indices back to front and `counts[2 n]` how many were kept
/// (see bucket_sort.wgsl).
pub(crate) struct SortBuffers {
    pub key: wgpu::Buffer,
    first: wgpu::Buffer,
    pub order: wgpu::Buffer,
    /// Room for the counters of [`super::MAX_N`] first-level buckets.
    pub counts: wgpu::Buffer,
}

impl SortBuffers {
    pub fn new(ctx: &GpuContext, cloud: &GpuCloud) -> Result<SortBuffers, GpuError> {
        let bytes = index_bytes(ctx, cloud)?;
        let d = &ctx.device;
        Ok(SortBuffers {
            key: util::storage(d, "sort keys", bytes),
            first: util::storage(d, "sort first level", bytes),
            order: util::storage(d, "sort order", bytes),
            counts: util::storage(d, "sort counts", 4 * (2 * super::MAX_N as u64 + 3)),
        })
    }

    /// Sets the counters of a sort with `n` first-level buckets (zero, and the depth range's
    /// least at its largest value), before the next submission.
    fn reset_counts(&self, ctx: &GpuContext, n: u32) {
        let mut c = vec![0u32; 2 * n as usize + 3];
        c[2 * n as usize + 1] = u32::MAX;
        ctx.queue
            .write_buffer(&self.counts, 0, bytemuck::cast_slice(&c));
    }
}

/// The index buffers' size for `cloud`, or the error when they exceed a binding.
fn index_bytes(ctx: &GpuContext, cloud: &GpuCloud) -> Result<u64, GpuError> {
    let n_points = cloud.len as u64;
    let max = ctx.binding_limit();
    if 4 * n_points > max {
        return Err(GpuError::TooLarge(format!(
            "bucket sort of {n_points} points: its index buffers of {} MiB exceed the device's \
             binding limit of {} MiB",
            (4 * n_points) >> 20,
            max >> 20
        )));
    }
    Ok((4 * n_points).max(16))
}

/// A uniform block of the sort's kernels.
fn block(ctx: &GpuContext, s: &Slicing, base: u32, count: u32) -> wgpu::Buffer {
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("sort block"),
            contents: bytemuck::bytes_of(&SortBlock {
                base,
                count,
                near: s.near,
                eps: s.eps,
                n: s.n,
                k: s.k,
                pad: [0; 2],
            }),
            usage: wgpu::BufferUsages::UNIFORM,
        })
}

/// Records the kernels of `names` over every chunk (per-point kernels), or once over one
/// group or `s.n` groups (scan, refine).
#[allow(clippy::too_many_arguments)]
fn record_kernels(
    ctx: &GpuContext,
    pass: &BucketSort,
    enc: &mut wgpu::CommandEncoder,
    cloud: &GpuCloud,
    view: &wgpu::Buffer,
    s: &Slicing,
    bufs: (&wgpu::Buffer, &wgpu::Buffer, &wgpu::Buffer, &wgpu::Buffer),
    names: &[&str],
) {
    let (key, counts, first, order) = bufs;
    let bind = |p: &Pass, block: &wgpu::Buffer, positions: &wgpu::Buffer| {
        p.bind(
            &ctx.device,
            &[
                Res::Buf(view),
                Res::Buf(block),
                Res::Buf(positions),
                Res::Buf(key),
                Res::Buf(counts),
                Res::Buf(first),
                Res::Buf(order),
            ],
        )
    };
    for name in names {
        let (p, per_point) = match *name {
            "depth_range" => (&pass.depth_range, true),
            "classify" => (&pass.classify, true),
            "scatter" => (&pass.scatter, true),
            "scan" => (&pass.scan, false),
            _ => (&pass.refine, false),
        };
        let mut c = enc.begin_compute_pass(&Default::default());
        c.set_pipeline(&p.pipeline);
        if per_point {
            for ch in &cloud.chunks {
                let b = block(ctx, s, ch.base, ch.count);
                c.set_bind_group(0, &bind(p, &b, &ch.positions), &[]);
                let (gx, gy) = flat_groups(ctx, ch.count as u64);
                c.dispatch_workgroups(gx, gy, 1);
            }
        } else {
            let b = block(ctx, s, 0, 0);
            c.set_bind_group(0, &bind(p, &b, &cloud.chunks[0].positions), &[]);
            let groups = if *name == "scan" { 1 } else { s.n };
            c.dispatch_workgroups(groups, 1, 1);
        }
    }
}

/// Records a whole sort of the points seen in the view of `view` (a uniform [`ViewParams`]
/// buffer) with slicing `s` given by the host (a range at least as wide as the points'),
/// into `bufs` (made for `cloud`). Only one sort may be recorded per submission.
pub(crate) fn record_sort(
    ctx: &GpuContext,
    shared: &Shared,
    enc: &mut wgpu::CommandEncoder,
    cloud: &GpuCloud,
    view: &wgpu::Buffer,
    s: Slicing,
    bufs: &SortBuffers,
) {
    let pass = shared.pass::<BucketSort>(ctx);
    bufs.reset_counts(ctx, s.n);
    record_kernels(
        ctx,
        &pass,
        enc,
        cloud,
        view,
        &s,
        (&bufs.key, &bufs.counts, &bufs.first, &bufs.order),
        &["depth_range", "classify", "scan", "scatter", "refine"],
    );
}

/// Sorts the points of `cloud` seen in `v` back to front in slices of thickness `eps` (see
/// the module documentation of [`super`]); the order within a slice is the atomics'. The
/// depth range is read back first, so the slices are the CPU's.
pub(crate) fn sort(
    ctx: &GpuContext,
    shared: &Shared,
    cloud: &GpuCloud,
    v: &ViewParams,
    eps: f32,
) -> Result<Sorted, GpuError> {
    let bufs = SortBuffers::new(ctx, cloud)?;
    let pass = shared.pass::<BucketSort>(ctx);
    let d = &ctx.device;
    let view = d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("sort view"),
        contents: bytemuck::bytes_of(v),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    // 1. Depths and their range.
    let none = Slicing {
        near: 0.0,
        eps: 1.0,
        n: 1,
        k: 1,
    };
    bufs.reset_counts(ctx, none.n);
    let mut enc = d.create_command_encoder(&Default::default());
    record_kernels(
        ctx,
        &pass,
        &mut enc,
        cloud,
        &view,
        &none,
        (&bufs.key, &bufs.counts, &bufs.first, &bufs.order),
        &["depth_range"],
    );
    ctx.queue.submit([enc.finish()]);
    let raw = copy_out(ctx, &bufs.counts, 4 * (2 * none.n as u64 + 3))?;
    let words: Vec<u32> = bytemuck::pod_collect_to_vec(&raw);
    let (lo, hi) = (
        words[2 * none.n as usize + 1],
        words[2 * none.n as usize + 2],
    );
    if lo > hi {
        return Ok(Sorted {
            order: Vec::new(),
            slices: Vec::new(),
            slicing: Slicing::new(0.0, 0.0, eps),
        });
    }
    let unordered = |b: u32| {
        f32::from_bits(if b & 0x8000_0000 != 0 {
            b & 0x7fff_ffff
        } else {
            !b
        })
    };
    let s = Slicing::new(unordered(lo), unordered(hi), eps);
    // 2. Slices, first level, scan, scatter, refine.
    let mut enc = d.create_command_encoder(&Default::default());
    record_sort(ctx, shared, &mut enc, cloud, &view, s, &bufs);
    ctx.queue.submit([enc.finish()]);
    let raw = copy_out(ctx, &bufs.counts, 4 * (2 * s.n as u64 + 3))?;
    let kept = bytemuck::pod_collect_to_vec::<u8, u32>(&raw)[2 * s.n as usize] as usize;
    let order: Vec<u32> = if kept == 0 {
        Vec::new()
    } else {
        bytemuck::pod_collect_to_vec(&copy_out(ctx, &bufs.order, 4 * kept as u64)?)
    };
    let keys: Vec<u32> =
        bytemuck::pod_collect_to_vec(&copy_out(ctx, &bufs.key, 4 * cloud.len as u64)?);
    let slices = order.iter().map(|&i| keys[i as usize]).collect();
    ctx.take_errors()?;
    Ok(Sorted {
        order,
        slices,
        slicing: s,
    })
}
