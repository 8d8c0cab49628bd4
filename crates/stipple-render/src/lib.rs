//! The stipple frame: image-space point rendering (Dobrev et al. §3) as a pipeline of named
//! passes, on the CPU (rayon; the reference) and, later, on the GPU.
//!
//! ```text
//! project → [fill_background, fill_occluded]* → shade → [smooth, antialias]* → output
//! ```
//! See [`pipeline::Pipeline`] for the description a frame is built from and the `cpu` module
//! for the passes.

pub mod cpu;
pub mod gbuffer;
pub mod masks;
pub mod params;
pub mod pipeline;

pub use gbuffer::{GBuffer, PassStat, BACKGROUND};
pub use params::ViewParams;
pub use pipeline::{ColourPass, GeometryPass, Iterations, Kernel, Light, Material, Pipeline};

use stipple_core::camera::CameraError;
use stipple_core::{Camera, PointCloud};

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("camera: {0}")]
    Camera(#[from] CameraError),
    #[error("the cloud has no points")]
    EmptyCloud,
    #[error("{0}")]
    NoGpu(String),
}

/// Which implementation runs the passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Cpu,
    Gpu,
    /// A GPU when one with the needed features exists, else the CPU.
    Auto,
}

impl Backend {
    pub fn parse(s: &str) -> Result<Backend, String> {
        match s {
            "cpu" => Ok(Backend::Cpu),
            "gpu" => Ok(Backend::Gpu),
            "auto" => Ok(Backend::Auto),
            _ => Err(format!("unknown backend `{s}` (cpu, gpu, auto)")),
        }
    }
}

/// A cloud with what every frame needs computed once: the point spacing (for d̃) and the
/// intensity scale.
pub struct PreparedCloud {
    pub cloud: PointCloud,
    /// Median nearest-neighbour distance, world units.
    pub spacing: f32,
    /// Maps intensity to [0, 1] (1 / the 99th percentile), when the cloud has intensity.
    pub intensity_scale: Option<f32>,
}

impl PreparedCloud {
    pub fn new(cloud: PointCloud) -> PreparedCloud {
        let spacing = cloud.estimate_spacing();
        let intensity_scale = cloud.intensity.as_ref().and_then(|v| {
            let mut hist = vec![0u64; 65536];
            for &i in v {
                hist[i as usize] += 1;
            }
            let target = (v.len() as f64 * 0.99) as u64;
            let mut acc = 0;
            let p99 = hist.iter().position(|&c| {
                acc += c;
                acc >= target
            })?;
            (p99 > 0).then(|| 1.0 / p99 as f32)
        });
        PreparedCloud {
            cloud,
            spacing,
            intensity_scale,
        }
    }

    /// The layer gap d̃ a pipeline uses for this cloud: its own, else derived from spacing.
    pub fn layer_gap(&self, pipe: &Pipeline) -> f32 {
        pipe.geometry
            .iter()
            .find_map(|p| match p {
                GeometryPass::FillOccluded { layer_gap, .. } => *layer_gap,
                _ => None,
            })
            .unwrap_or_else(|| pipeline::default_layer_gap(self.spacing))
    }
}

/// A rendered frame.
#[derive(Clone, Debug)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// sRGB 8-bit RGBA, row 0 at the top.
    pub rgba: Vec<u8>,
    /// View-axis depth of the surface per pixel, +inf on background.
    pub depth: Vec<f32>,
    /// Point shown per pixel ([`BACKGROUND`] where none).
    pub id: Vec<u32>,
    pub stats: Vec<PassStat>,
}

/// Renders one frame with a fresh renderer (for repeated frames keep a [`cpu::CpuRenderer`]).
pub fn render(
    cloud: &PreparedCloud,
    camera: &Camera,
    pipe: &Pipeline,
    backend: Backend,
) -> Result<Frame, RenderError> {
    camera.validate()?;
    if cloud.cloud.is_empty() {
        return Err(RenderError::EmptyCloud);
    }
    match backend {
        Backend::Cpu | Backend::Auto => {
            let v = ViewParams::new(camera, cloud.cloud.origin);
            Ok(cpu::CpuRenderer::new().render(cloud, &v, pipe))
        }
        Backend::Gpu => Err(RenderError::NoGpu(
            "the GPU backend is not implemented yet in this build (planned: wgpu compute passes); use --backend cpu".into(),
        )),
    }
}
