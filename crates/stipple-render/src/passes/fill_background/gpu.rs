//! # fill_background (GPU twin of `cpu.rs`)
//!
//! fill_background.wgsl defines which pixels are candidates (background) and which
//! neighbours are solid (covered); the step itself is fill.wgsl (see [`crate::passes::fill::gpu`]).

use crate::device::context::GpuContext;
use crate::device::frame::{GpuPass, Shared};

/// The pass's pipeline.
pub(crate) struct Gpu(pub crate::device::util::Pass);

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        Gpu(crate::passes::fill::gpu::new(
            ctx,
            &crate::device::shaders::FILL_BACKGROUND_MODULE,
        ))
    }
}
