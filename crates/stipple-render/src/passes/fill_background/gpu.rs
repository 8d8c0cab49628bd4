//! # fill_background (GPU twin of `cpu.rs`)
//!
//! fill_background.wgsl defines which pixels are candidates (background) and which
//! neighbours are solid (covered); the step itself is fill.wgsl (see [`crate::passes::fill::gpu`]).

pub(crate) fn new(ctx: &crate::device::context::GpuContext) -> crate::device::util::Pass {
    crate::passes::fill::gpu::new(ctx, &crate::device::shaders::FILL_BACKGROUND_MODULE)
}
