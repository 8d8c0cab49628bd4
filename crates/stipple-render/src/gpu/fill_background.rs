//! # fill_background (GPU twin of cpu/fill_background.rs)
//!
//! shaders/fill_background.wgsl defines which pixels are candidates (background) and which
//! neighbours are solid (covered); the step itself is shaders/fill.wgsl (see [`super::fill`]).

pub(crate) fn new(ctx: &super::GpuContext) -> super::util::Pass {
    super::fill::new(ctx, &super::shaders::FILL_BACKGROUND_MODULE)
}
