//! # project (GPU twin of `cpu.rs`): the compute rasterizer
//!
//! With `SHADER_INT64_ATOMIC_MIN_MAX`, each point does one 64-bit `atomicMax` of its
//! complemented key ~(depth bits << 32 | index) after an early-out read (shaders/
//! project_atomic64.wgsl); without it, two passes of 32-bit atomics (depth, then the smallest
//! index at that depth; project_atomic32.wgsl). A workgroup handles 256 × 8 consecutive points.
//! The cloud is projected chunk by chunk (one storage binding each) and dispatches beyond the
//! per-dimension limit are split in 2-D. `resolve` then unpacks the keys into the G-buffer.

use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, GpuPass, Shared};
use crate::device::record::{flat_groups, grid_2d, Rec};
use crate::device::util::{self, Pass, Res, Slot, DYNAMIC, READ, UNIFORM, WRITE};
use crate::stats::PassId;
use wgpu::ShaderStages;

/// Points one workgroup projects (project.wgsl WG × BATCH).
pub const POINTS_PER_GROUP: u32 = 256 * 8;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct ChunkBlock {
    pub base: u32,
    pub count: u32,
    pub cull: u32,
    pub slot: u32,
    /// 1: depth peeling against the previous layer (see `cpu::PeelTest`), with `gap` = d̃.
    pub peel: u32,
    pub gap: f32,
    /// 1: the cloud has normals.
    pub has_normals: u32,
    pub pad: u32,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct ResolveBlock {
    pub wide: u32,
    pub pad: [u32; 3],
}

/// The uniform block of `peel_reference.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct PeelReferenceBlock {
    pub bound: f32,
    pub has_normals: u32,
    pub pad: [u32; 2],
}

/// The peel reference pass's pipeline (see `cpu::peel_reference`).
pub(crate) struct PeelReference(Pass);

impl GpuPass for PeelReference {
    fn new(ctx: &GpuContext, _: &Shared) -> PeelReference {
        PeelReference(Pass::new(
            &ctx.device,
            &crate::device::shaders::PEEL_REFERENCE_MODULE,
            "peel_reference",
            &[UNIFORM, DYNAMIC, READ, WRITE, READ, READ],
        ))
    }
}

/// What the next peeled layer is compared with, from the current layer's surface depth and
/// its points' positions and normals as shade gathered them (see `cpu::peel_reference`,
/// `cpu::peel_planes`); `bound` = 4 d̃.
pub(crate) fn record_peel_reference(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    bound: f32,
    has_normals: bool,
) -> Result<(), GpuError> {
    let q = rec.section();
    let grid = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let off = rec.arena.push(&PeelReferenceBlock {
        bound,
        has_normals: has_normals as u32,
        pad: [0; 2],
    })?;
    let pass = b.pass::<PeelReference>();
    let [view, block] = b.view_and::<PeelReferenceBlock>();
    let f = b.f;
    let group = b.bind(
        "peel_reference",
        &pass.0.bgl,
        &[
            view,
            block,
            Res::Buf(&f.surface),
            Res::Buf(&f.peel_ref),
            Res::Buf(&f.attr_pos),
            Res::Buf(&f.attr_normal),
        ],
    );
    rec.image_pass(q, &pass.0.pipeline, &group, &[off], grid);
    rec.end(PassId::PeelReference, 1, vec![], q)
}

pub(crate) struct Project {
    pub wide: Option<(wgpu::BindGroupLayout, wgpu::ComputePipeline)>,
    pub narrow_bgl: wgpu::BindGroupLayout,
    pub narrow_depth: wgpu::ComputePipeline,
    pub narrow_index: wgpu::ComputePipeline,
    pub resolve_bgl: wgpu::BindGroupLayout,
    pub resolve: wgpu::ComputePipeline,
}

const BASE: [Slot; 7] = [UNIFORM, DYNAMIC, READ, READ, WRITE, READ, WRITE];

impl GpuPass for Project {
    fn new(ctx: &GpuContext, _: &Shared) -> Project {
        let d = &ctx.device;
        let c = ShaderStages::COMPUTE;
        let wide = ctx.int64_atomics.then(|| {
            let mut slots = BASE.to_vec();
            slots.push(WRITE);
            let bgl = util::layout(d, "project64", &slots, c);
            let m = util::module(d, &crate::device::shaders::PROJECT64);
            let p = util::compute(d, &m, "project", &bgl);
            (bgl, p)
        });
        let mut slots = BASE.to_vec();
        slots.extend([WRITE, WRITE]);
        let narrow_bgl = util::layout(d, "project32", &slots, c);
        let m = util::module(d, &crate::device::shaders::PROJECT32);
        let narrow_depth = util::compute(d, &m, "project_depth", &narrow_bgl);
        let narrow_index = util::compute(d, &m, "project_index", &narrow_bgl);
        let resolve_bgl = util::layout(
            d,
            "resolve",
            &[UNIFORM, DYNAMIC, READ, READ, WRITE, WRITE],
            c,
        );
        let m = util::module(d, &crate::device::shaders::RESOLVE_MODULE);
        let resolve = util::compute(d, &m, "resolve", &resolve_bgl);
        Project {
            wide,
            narrow_bgl,
            narrow_depth,
            narrow_index,
            resolve_bgl,
            resolve,
        }
    }
}

impl Project {
    /// The layout of the projection in use: view, chunk block (arena), positions, normals,
    /// counters, the peeling reference depth, the peeled points' bits, then the visibility
    /// buffer(s).
    pub fn bgl(&self) -> &wgpu::BindGroupLayout {
        match &self.wide {
            Some((bgl, _)) => bgl,
            None => &self.narrow_bgl,
        }
    }
}

/// Projects every chunk of `cloud` into the visibility buffer (culling back faces where
/// `cull` and the cloud has normals; behind the reference depth by `peel` = d̃ when
/// peeling), then resolves it into geometry image 0.
pub(crate) fn record(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    cloud: &GpuCloud,
    cull: bool,
    peel: Option<f32>,
) -> Result<(), GpuError> {
    let (ctx, f, s) = (b.ctx, b.f, b.shared);
    let q = rec.section();
    rec.enc.clear_buffer(&f.vis, 0, None);
    rec.enc.clear_buffer(&f.vis_id, 0, None);
    if peel.is_none() {
        // A first layer: no point is peeled yet.
        rec.enc.clear_buffer(&cloud.done, 0, None);
    }
    let slot = rec.slot()?;
    let cull = cull && cloud.has_normals;
    let proj = b.pass::<Project>();
    let mut chunks = Vec::new();
    for c in &cloud.chunks {
        let off = rec.arena.push(&ChunkBlock {
            base: c.base,
            count: c.count,
            cull: cull as u32,
            slot,
            peel: peel.is_some() as u32,
            gap: peel.unwrap_or(0.0),
            has_normals: cloud.has_normals as u32,
            pad: 0,
        })?;
        let [view, block] = b.view_and::<ChunkBlock>();
        let mut res = vec![
            view,
            block,
            Res::Buf(&c.positions),
            Res::Buf(c.normals.as_ref().unwrap_or(&cloud.dummy)),
            Res::Buf(&s.counters),
            Res::Buf(&f.peel_ref),
            Res::Buf(&cloud.done),
            Res::Buf(&f.vis),
        ];
        if proj.wide.is_none() {
            res.push(Res::Buf(&f.vis_id));
        }
        let group = b.bind_chunk("project", proj.bgl(), &res);
        chunks.push((group, off, ctx.grid(c.count.div_ceil(POINTS_PER_GROUP))));
    }
    let roff = rec.arena.push(&ResolveBlock {
        wide: proj.wide.is_some() as u32,
        pad: [0; 3],
    })?;
    let [view, block] = b.view_and::<ResolveBlock>();
    let resolve = b.bind(
        "resolve",
        &proj.resolve_bgl,
        &[
            view,
            block,
            Res::Buf(&f.vis),
            Res::Buf(&f.vis_id),
            Res::Buf(&f.depth[0]),
            Res::Buf(&f.id[0]),
        ],
    );
    let mut pass = rec.timed_pass(q);
    let stages: Vec<&wgpu::ComputePipeline> = match &proj.wide {
        Some((_, p)) => vec![p],
        None => vec![&proj.narrow_depth, &proj.narrow_index],
    };
    for p in stages {
        pass.set_pipeline(p);
        for (bg, off, (gx, gy)) in &chunks {
            pass.set_bind_group(0, bg, &[*off]);
            pass.dispatch_workgroups(*gx, *gy, 1);
        }
    }
    pass.set_pipeline(&proj.resolve);
    pass.set_bind_group(0, &resolve, &[roff]);
    let (gx, gy) = flat_groups(ctx, f.pixels());
    pass.dispatch_workgroups(gx, gy, 1);
    drop(pass);
    rec.end(PassId::Project, 1, vec![slot], q)
}
