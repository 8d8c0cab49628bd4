//! The GPU backend (wgpu): scheduling only. The passes' pipelines, bind groups, recording
//! functions and WGSL live in their folders under [`crate::passes`] (checked against the
//! CPU reference by the parity tests) and build on [`crate::device`] (frame buffers, the
//! recorder, shared buffers); this module keeps the renderer's buffers between frames,
//! records the steps of [`crate::schedule`] through the passes (`exec`) and reads the frame
//! back.
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
pub mod renderer;

pub use crate::device::cloud::GpuCloud;
pub use crate::device::context::{list_adapters, AdapterReport, GpuContext, GpuError, GpuOptions};
pub use renderer::{GpuRenderer, ProjectionPath};
