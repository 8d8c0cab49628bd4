//! The stipple frame: image-space point rendering (Dobrev et al. §3) as a pipeline of named
//! passes, on the CPU (rayon; the reference) and, later, on the GPU.
//!
//! ```text
//! project → [fill_background, fill_occluded]* → shade → [smooth, antialias]* → output
//! ```
//! See [`pipeline::Pipeline`] for the description a frame is built from and the `cpu` module
//! for the passes.

pub mod cpu;
pub mod eval;
pub mod gbuffer;
pub mod gpu;
pub mod masks;
pub mod params;
pub mod pipeline;

pub use gbuffer::{is_point, GBuffer, PassStat, BACKGROUND, HOLE};
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
    #[error(transparent)]
    Gpu(#[from] gpu::GpuError),
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
    /// Unique per preparation: the GPU backend re-uploads when it changes.
    pub key: u64,
}

static NEXT_CLOUD_KEY: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

impl PreparedCloud {
    pub fn new(cloud: PointCloud) -> PreparedCloud {
        let spacing = cloud.estimate_spacing();
        PreparedCloud::with_spacing(cloud, spacing)
    }

    /// Prepares a cloud whose point spacing is already known (a LOD cut knows it from its
    /// nodes; estimating it would cost a neighbour search per frame).
    pub fn with_spacing(cloud: PointCloud, spacing: f32) -> PreparedCloud {
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
            key: NEXT_CLOUD_KEY.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        }
    }

    /// The pipeline with its automatic settings resolved for this cloud and view.
    pub fn resolve(&self, pipe: &Pipeline, v: &ViewParams) -> Pipeline {
        pipe.resolved(v, self.spacing, self.centre_depth(v))
    }

    /// View depth of the centre of the cloud's bounds.
    fn centre_depth(&self, v: &ViewParams) -> f32 {
        let c = self.cloud.bounds().center();
        (c - glam::Vec3::from(v.eye)).dot(glam::Vec3::from(v.forward))
    }

    /// The median point spacing in pixels at the centre of the cloud (NaN when the camera is
    /// inside the cloud's bounds centre plane).
    pub fn screen_spacing(&self, camera: &Camera) -> f32 {
        let v = ViewParams::new(camera, self.cloud.origin);
        let d = self.centre_depth(&v);
        if d > v.near {
            self.spacing / v.footprint(d)
        } else {
            f32::NAN
        }
    }

    /// The layer gap d̃ a pipeline uses for this cloud: its own, else derived from spacing.
    pub fn layer_gap(&self, pipe: &Pipeline) -> f32 {
        pipeline::layer_gap(pipe, self.spacing)
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

/// A long-lived renderer on one backend. The GPU one keeps the last cloud uploaded, so
/// repeated frames of the same cloud upload nothing.
pub struct Renderer {
    inner: Inner,
}

enum Inner {
    Cpu(Box<cpu::CpuRenderer>),
    Gpu {
        renderer: Box<gpu::GpuRenderer>,
        uploaded: Option<(u64, gpu::GpuCloud)>,
    },
}

impl Renderer {
    /// Opens a renderer. `Auto` takes a suitable hardware GPU adapter when there is one and
    /// otherwise falls back to the CPU, saying why once on stderr (a software adapter such as
    /// lavapipe is slower than the CPU backend, so `Auto` passes it over); `Gpu` takes any
    /// suitable adapter, and without one is an error.
    pub fn new(backend: Backend, options: gpu::GpuOptions) -> Result<Renderer, RenderError> {
        let open = || -> Result<Renderer, gpu::GpuError> {
            let ctx = gpu::GpuContext::new(options)?;
            Ok(Renderer {
                inner: Inner::Gpu {
                    renderer: Box::new(gpu::GpuRenderer::new(ctx)?),
                    uploaded: None,
                },
            })
        };
        let cpu = || Renderer {
            inner: Inner::Cpu(Box::default()),
        };
        match backend {
            Backend::Cpu => Ok(cpu()),
            Backend::Gpu => Ok(open()?),
            Backend::Auto => match open() {
                Ok(r) if !r.is_software_gpu() => Ok(r),
                Ok(r) => {
                    eprintln!(
                        "note: rendering on the CPU (the only GPU adapter, {}, is a software \
                         rasterizer, slower than the CPU backend; --backend gpu uses it anyway)",
                        r.describe()
                    );
                    Ok(cpu())
                }
                Err(e) => {
                    eprintln!("note: rendering on the CPU ({e})");
                    Ok(cpu())
                }
            },
        }
    }

    /// "cpu (N threads)" or the GPU adapter and projection path.
    pub fn describe(&self) -> String {
        match &self.inner {
            Inner::Cpu(_) => format!("cpu ({} threads)", rayon::current_num_threads()),
            Inner::Gpu { renderer, .. } => format!("gpu: {}", renderer.context().describe()),
        }
    }

    /// A GPU backend on a software adapter (lavapipe, llvmpipe, WARP).
    fn is_software_gpu(&self) -> bool {
        match &self.inner {
            Inner::Gpu { renderer, .. } => renderer.context().adapter.is_software(),
            Inner::Cpu(_) => false,
        }
    }

    pub fn is_gpu(&self) -> bool {
        matches!(self.inner, Inner::Gpu { .. })
    }

    /// The GPU renderer, for options such as the projection path and timing mode.
    pub fn gpu_mut(&mut self) -> Option<&mut gpu::GpuRenderer> {
        match &mut self.inner {
            Inner::Gpu { renderer, .. } => Some(renderer),
            Inner::Cpu(_) => None,
        }
    }

    pub fn render(
        &mut self,
        cloud: &PreparedCloud,
        camera: &Camera,
        pipe: &Pipeline,
    ) -> Result<Frame, RenderError> {
        camera.validate()?;
        if cloud.cloud.is_empty() {
            return Err(RenderError::EmptyCloud);
        }
        let v = ViewParams::new(camera, cloud.cloud.origin);
        let pipe = &cloud.resolve(pipe, &v);
        match &mut self.inner {
            Inner::Cpu(r) => Ok(r.render(cloud, &v, pipe)),
            Inner::Gpu { renderer, uploaded } => {
                if uploaded.as_ref().map(|u| u.0) != Some(cloud.key) {
                    *uploaded = None;
                    let up = gpu::GpuCloud::upload(renderer.context(), cloud)?;
                    *uploaded = Some((cloud.key, up));
                }
                let up = &uploaded.as_ref().expect("uploaded").1;
                Ok(renderer.render(up, &v, pipe)?)
            }
        }
    }
}

/// Renders one frame with a fresh renderer (for repeated frames keep a [`Renderer`]).
pub fn render(
    cloud: &PreparedCloud,
    camera: &Camera,
    pipe: &Pipeline,
    backend: Backend,
) -> Result<Frame, RenderError> {
    Renderer::new(backend, gpu::GpuOptions::default())?.render(cloud, camera, pipe)
}
