//! The GPU backend (wgpu): every pass of the CPU pipeline as a WGSL compute pass, one module
//! per pass with its shader of the same name in `src/shaders/`, checked against the CPU
//! reference by the parity tests.
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

pub mod antialias;
pub mod blend_layers;
pub mod cloud;
pub mod context;
pub mod depiction;
pub mod edl;
pub(crate) mod exec;
pub mod fill;
pub mod fill_anisotropic;
pub mod fill_background;
pub mod fill_occluded;
pub mod iterate;
pub mod output;
pub mod project;
pub mod project_hw;
pub(crate) mod record;
pub mod renderer;
pub(crate) mod resources;
pub mod shade;
pub mod shaders;
pub mod shadow_texture;
pub mod smooth;
pub(crate) mod steps;
pub(crate) mod util;
pub mod visibility;

pub use cloud::GpuCloud;
pub use context::{list_adapters, AdapterReport, GpuContext, GpuError, GpuOptions};
pub use renderer::{GpuRenderer, ProjectionPath};
