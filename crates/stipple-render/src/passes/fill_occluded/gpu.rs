//! # fill_occluded (GPU twin of `cpu.rs`)
//!
//! fill_occluded.wgsl: candidates are covered pixels, solid neighbours are at least d̃
//! nearer; the step itself is fill.wgsl (see [`crate::passes::fill::gpu`]).

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> crate::device::util::Pass {
    crate::passes::fill::gpu::new(ctx, &crate::device::shaders::FILL_OCCLUDED_MODULE)
}
