//! # project (GPU twin of `cpu.rs`): the compute rasterizer
//!
//! With `SHADER_INT64_ATOMIC_MIN_MAX`, each point does one 64-bit `atomicMax` of its
//! complemented key ~(depth bits << 32 | index) after an early-out read (shaders/
//! project_atomic64.wgsl); without it, two passes of 32-bit atomics (depth, then the smallest
//! index at that depth; project_atomic32.wgsl). A workgroup handles 256 × 8 consecutive points.
//! The cloud is projected chunk by chunk (one storage binding each) and dispatches beyond the
//! per-dimension limit are split in 2-D. `resolve` then unpacks the keys into the G-buffer.

use crate::device::context::GpuContext;
use crate::device::util::{self, Slot, DYNAMIC, READ, UNIFORM, WRITE};
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
    /// 1: depth peeling against the reference depth, with `gap` = d̃.
    pub peel: u32,
    pub gap: f32,
    pub pad: [u32; 2],
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
    pub pad: [u32; 3],
}

/// The peel reference pass (see `cpu::peel_reference`).
pub(crate) fn peel_reference(ctx: &GpuContext) -> crate::device::util::Pass {
    crate::device::util::Pass::new(
        &ctx.device,
        &crate::device::shaders::PEEL_REFERENCE_MODULE,
        "peel_reference",
        &[UNIFORM, DYNAMIC, READ, WRITE],
    )
}

pub(crate) struct Project {
    pub wide: Option<(wgpu::BindGroupLayout, wgpu::ComputePipeline)>,
    pub narrow_bgl: wgpu::BindGroupLayout,
    pub narrow_depth: wgpu::ComputePipeline,
    pub narrow_index: wgpu::ComputePipeline,
    pub resolve_bgl: wgpu::BindGroupLayout,
    pub resolve: wgpu::ComputePipeline,
}

const BASE: [Slot; 6] = [UNIFORM, DYNAMIC, READ, READ, WRITE, READ];

impl Project {
    pub fn new(ctx: &GpuContext) -> Project {
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

    /// The layout of the projection in use: view, chunk block (arena), positions, normals,
    /// counters, the peeling reference depth, then the visibility buffer(s).
    pub fn bgl(&self) -> &wgpu::BindGroupLayout {
        match &self.wide {
            Some((bgl, _)) => bgl,
            None => &self.narrow_bgl,
        }
    }
}
