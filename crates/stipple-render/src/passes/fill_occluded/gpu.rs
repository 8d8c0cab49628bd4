//! # fill_occluded (GPU twin of `cpu.rs`)
//!
//! fill_occluded.wgsl: candidates are covered pixels, solid neighbours are at least d̃
//! nearer; the step itself is fill.wgsl (see [`crate::passes::fill::gpu`]).

use crate::device::context::GpuContext;
use crate::device::frame::{GpuPass, Shared};

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
