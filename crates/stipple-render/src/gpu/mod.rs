//! The GPU backend (wgpu): scheduling and resources. The passes' pipelines and WGSL live in
//! their folders under [`crate::passes`], checked against the CPU reference by the parity
//! tests; this module makes the frame's buffers and bind groups (`resources`), records the
//! steps of [`crate::schedule`] (`exec`, `steps`, `record`) and reads the frame back.
//!
//! ```text
//! project (compute rasterizer | project_hw) → resolve → fill_background / fill_occluded
//!   | visibility → shade (gather per chunk, then shade)
//!   → smooth / antialias | fill_anisotropic / depiction / edl → output
//! ```
//!
//! With depth peeling the frame repeats project (with the previous layer's depth as
//! reference) through the colour passes per layer, blending each into an accumulator
//! (`blend_layers`); shadow textures run project and the fills from each light view, then
//! `shadow_texture` over the points.

pub(crate) mod exec;
pub(crate) mod record;
pub mod renderer;
pub(crate) mod resources;
pub(crate) mod steps;

pub use crate::device::cloud::GpuCloud;
pub use crate::device::context::{list_adapters, AdapterReport, GpuContext, GpuError, GpuOptions};
pub use renderer::{GpuRenderer, ProjectionPath};
