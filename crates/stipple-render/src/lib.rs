//! The stipple frame: image-space point rendering (Dobrev et al. §3) as a pipeline of named
//! passes, on the CPU (rayon; the reference) and, later, on the GPU.
//!
//! ```text
//! project → [fill_background, fill_occluded]* → shade → [smooth, antialias]* → output
//! ```
//! See [`pipeline::Pipeline`] for the description a frame is built from and the `cpu` module
//! for the passes.

pub mod cpu;
pub mod device;
pub mod env;
pub mod eval;
mod frame;
pub mod gbuffer;
pub mod gpu;
pub mod lights;
pub mod masks;
pub mod material;
pub mod params;
pub mod passes;
pub mod pipeline;
mod prepared;
mod renderer;
pub mod schedule;
pub mod shadow;
pub mod srgb;
pub mod stats;
pub mod translucent;

pub use frame::Frame;
pub use gbuffer::{is_point, GBuffer, BACKGROUND, HOLE};
pub use lights::{AreaLight, AreaShape, Light};
pub use params::ViewParams;
pub use passes::splat::{CoverageMethod, SplatMode, SplatSettings};

/// For comparison and tests: the GPU's sorted and transparent splats walk every splat per
/// tile instead of the tile's list, as `STIPPLE_SPLAT_NO_BINS=1` does (see
/// `passes::splat::sorted_gpu`).
#[doc(hidden)]
pub static SPLAT_NO_BINS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// For tests: the GPU's transparent splats draw the frame in bands of at most this many
/// 16-pixel tile rows (0: as many as the device's binding limit allows; see
/// `passes::splat::sorted_gpu`).
#[doc(hidden)]
pub static SPLAT_BAND_TILES: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);

/// For comparison and tests: transparent splats shade each point on its own (forward) even
/// where they would shade each layer from its blended normal (deferred, §5.2.4).
#[doc(hidden)]
pub static SPLAT_SHADE_POINTS: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);
pub use pipeline::{ColourPass, GeometryPass, Iterations, Kernel, Material, Pipeline};
pub use prepared::*;
pub use renderer::{render, Renderer};
pub use shadow::LitTexture;
pub use stats::{PassId, PassStat};

use stipple_core::camera::CameraError;

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("camera: {0}")]
    Camera(#[from] CameraError),
    #[error("the cloud has no points")]
    EmptyCloud,
    #[error(transparent)]
    Gpu(#[from] gpu::GpuError),
    #[error(transparent)]
    Pipeline(#[from] pipeline::PipelineError),
    #[error(transparent)]
    Lights(#[from] lights::LightError),
    #[error(transparent)]
    Shadow(#[from] shadow::ShadowError),
    #[error(transparent)]
    Objects(#[from] ObjectError),
    #[error("lookup table: {0}")]
    Lookup(#[from] stipple_core::lookup::LookupError),
}

/// An [`ObjectTable`] that does not fit its cloud.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ObjectError {
    #[error("object table for {table} points, but the cloud has {cloud}")]
    Points { table: usize, cloud: usize },
    #[error("{0} objects (1 to {MAX_OBJECTS})")]
    Count(usize),
    #[error("a point belongs to object {object}, but there are {materials} materials")]
    Material { object: u32, materials: usize },
}

/// Which implementation runs the passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Backend {
    /// The CPU reference backend, on all cores.
    Cpu,
    /// A GPU adapter, software ones (lavapipe) included; none is an error.
    Gpu,
    /// A GPU when one with the needed features exists, else the CPU.
    Auto,
}
