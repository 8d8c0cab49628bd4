//! # fill_occluded (GPU twin of cpu/fill_occluded.rs)
//!
//! shaders/fill_occluded.wgsl: candidates are covered pixels, solid neighbours are at least d̃
//! nearer; the step itself is shaders/fill.wgsl (see [`super::fill`]).

pub(crate) fn new(ctx: &super::GpuContext) -> super::util::Pass {
    super::fill::new(ctx, &super::shaders::FILL_OCCLUDED_MODULE)
}
