//! Arguments shared by `render` and `bench`: the source cloud, the camera and the pipeline.

use crate::Result;
use glam::DVec3;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use stipple_core::demo::{self, DemoScene};
use stipple_core::{Camera, PointCloud, Projection};
use stipple_render::gpu::{GpuOptions, ProjectionPath};
use stipple_render::pipeline::{ColourPass, GeometryPass, Iterations, Kernel, Light, Pipeline};
use stipple_render::{Backend, PreparedCloud, Renderer};

#[derive(clap::Args, Clone)]
pub struct SourceArgs {
    /// Cloud file (.ply, .ply.gz, .las, .laz, .copc.laz, .xyz, .txt, .csv). Without one, a
    /// demo scene is rendered.
    pub input: Option<PathBuf>,
    /// Demo scene when no input is given: plane-objects, sphere, torus, nested-tori.
    #[arg(long, value_parser = crate::parse_scene, default_value = "plane-objects")]
    pub demo: DemoScene,
    /// Number of demo points (default: 1 000 000; 1 500 000 for nested-tori).
    #[arg(long)]
    pub points: Option<usize>,
    /// Demo seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

impl SourceArgs {
    /// Loads (or generates) the cloud and prepares it; returns a label for messages.
    pub fn load(&self) -> Result<(PreparedCloud, String)> {
        let (cloud, label) = match &self.input {
            Some(p) => (read_with_progress(p)?, p.display().to_string()),
            None => {
                let n = self.points.unwrap_or(self.demo.default_points());
                if n == 0 {
                    return Err("--points must be at least 1".into());
                }
                (
                    demo::generate(self.demo, n, self.seed),
                    format!("demo scene `{}`", self.demo.name()),
                )
            }
        };
        Ok((PreparedCloud::new(cloud), label))
    }
}

/// Reads a cloud, with a spinner on a terminal for reads that take a while.
pub fn read_with_progress(path: &Path) -> Result<PointCloud> {
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_message(format!("reading {}", path.display()));
    bar.enable_steady_tick(Duration::from_millis(120));
    let t0 = Instant::now();
    let r = stipple_io::read_cloud(path).map_err(|e| e.to_string());
    bar.finish_and_clear();
    if let Ok(c) = &r {
        let s = t0.elapsed().as_secs_f64();
        if s > 1.0 {
            eprintln!(
                "read {} points from {} in {s:.1} s ({:.1} M points/s)",
                c.len(),
                path.display(),
                c.len() as f64 / s / 1e6
            );
        }
    }
    r
}

fn parse_vec3(s: &str) -> std::result::Result<DVec3, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("`{s}` is not three comma-separated numbers (x,y,z)"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(x, y, z)),
        _ => Err(format!(
            "`{s}` is not three comma-separated numbers (x,y,z)"
        )),
    }
}

fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let err = || format!("`{s}` is not a size WxH such as 1024x768 (each side 1..=16384)");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(err)?;
    let (w, h): (u32, u32) = (w.parse().map_err(|_| err())?, h.parse().map_err(|_| err())?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(err());
    }
    Ok((w, h))
}

#[derive(clap::Args, Clone)]
pub struct CameraArgs {
    /// Image size in pixels.
    #[arg(long, default_value = "1024x1024", value_parser = parse_size, value_name = "WxH")]
    pub size: (u32, u32),
    /// Eye position x,y,z (world coordinates). Default: framing the whole cloud.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Point looked at, x,y,z. Default: the centre of the cloud's bounds.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<DVec3>,
    /// Up vector x,y,z. Default: +Y, or +Z for flat (LiDAR-like) clouds.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<DVec3>,
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = 45.0)]
    pub fov: f64,
    /// Orthographic projection with this view height (world units) instead of perspective.
    #[arg(long, value_name = "HEIGHT")]
    pub ortho: Option<f64>,
}

impl CameraArgs {
    /// The camera for a cloud: the default framing, then the overrides; near and far always
    /// come from the cloud's bounds.
    pub fn build(&self, cloud: &PointCloud) -> Result<Camera> {
        let (lo, hi) = cloud.world_bounds();
        let (w, h) = self.size;
        let mut cam = Camera::framing(lo, hi, w, h, self.fov);
        let framed_dir = cam.eye - cam.target;
        if let Some(t) = self.target {
            cam.target = t;
            if self.eye.is_none() {
                cam.eye = t + framed_dir;
            }
        }
        if let Some(e) = self.eye {
            cam.eye = e;
        }
        if let Some(u) = self.up {
            cam.up = u;
        }
        if let Some(hh) = self.ortho {
            cam.projection = Projection::Orthographic { height: hh };
        }
        cam.validate().map_err(|e| format!("camera: {e}"))?;
        cam.fit_clip(lo, hi);
        Ok(cam)
    }
}

fn parse_light(s: &str) -> std::result::Result<Light, String> {
    if s == "headlight" {
        return Ok(Light::Headlight);
    }
    if let Some(v) = s.strip_prefix("dir:") {
        return Ok(Light::Directional(parse_vec3(v)?.to_array()));
    }
    if let Some(v) = s.strip_prefix("point:") {
        return Ok(Light::Point(parse_vec3(v)?.to_array()));
    }
    Err(format!(
        "`{s}`: expected headlight, dir:x,y,z or point:x,y,z"
    ))
}

fn parse_colour(s: &str) -> std::result::Result<[u8; 3], String> {
    let err = || format!("`{s}` is not a colour (r,g,b with 0-255 values, or #rrggbb)");
    if let Some(hex) = s.strip_prefix('#') {
        if hex.len() != 6 {
            return Err(err());
        }
        let v = u32::from_str_radix(hex, 16).map_err(|_| err())?;
        return Ok([(v >> 16) as u8, (v >> 8) as u8, v as u8]);
    }
    let v: Vec<u8> = s
        .split(',')
        .map(|t| t.trim().parse::<u8>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| err())?;
    v.try_into().map_err(|_| err())
}

#[derive(clap::Args, Clone)]
#[command(next_help_heading = "Pipeline (Dobrev et al. §3; defaults: one iteration of each step)")]
pub struct PipelineArgs {
    /// Only project the points: no filling, smoothing or anti-aliasing (Dobrev Fig. 1).
    #[arg(long)]
    pub points_only: bool,
    /// Skip filling background pixels inside the silhouette (§3.2).
    #[arg(long)]
    pub no_fill_background: bool,
    /// Iterations of the background fill: a number, or `auto` to run until nothing changes.
    /// A hole n pixels across closes within n iterations, but each iteration also fills one
    /// more pixel of concave silhouette corners: `auto` grows silhouettes towards their
    /// octagonal hull. For sparse clouds prefer 2 or 3.
    #[arg(long, default_value = "1", value_parser = Iterations::parse, value_name = "N|auto")]
    pub fill_background_iterations: Iterations,
    /// Window radius of the fill masks: 1 = the paper's 3×3 masks; 2 = the same half-plane
    /// rule on 5×5, which closes gaps between points up to about 4 pixels (sparse clouds).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=3))]
    pub fill_radius: u32,
    /// Skip filling pixels that show an occluded surface (§3.3).
    #[arg(long)]
    pub no_fill_occluded: bool,
    /// Iterations of the occluded-pixel fill: a number or `auto`.
    #[arg(long, default_value = "1", value_parser = Iterations::parse, value_name = "N|auto")]
    pub fill_occluded_iterations: Iterations,
    /// Minimum gap d̃ between two surface layers, in world units. Default: 2.5 × the cloud's
    /// median point spacing (see `stipple info`).
    #[arg(long, value_name = "D")]
    pub layer_gap: Option<f32>,
    /// Skip smoothing (§3.4).
    #[arg(long)]
    pub no_smooth: bool,
    /// Smoothing kernel: box, gauss, or alleviated (Gaussian with centre weight 16/28).
    #[arg(long, default_value = "alleviated", value_parser = Kernel::parse)]
    pub smooth_kernel: Kernel,
    /// Smoothing iterations.
    #[arg(long, default_value_t = 1)]
    pub smooth_iterations: u32,
    /// Skip anti-aliasing (§3.5).
    #[arg(long)]
    pub no_antialias: bool,
    /// Laplace threshold on depth / z_far: high = only silhouettes against the background,
    /// low = also edges between surface layers.
    #[arg(long, default_value_t = 0.02)]
    pub aa_threshold: f32,
    /// How much an edge pixel takes of its blurred neighbourhood (0..1).
    #[arg(long, default_value_t = 0.6)]
    pub aa_strength: f32,
    /// Keep points whose normals face away from the eye.
    #[arg(long)]
    pub no_backface_culling: bool,
    /// Show colours unlit even where normals exist.
    #[arg(long)]
    pub no_lighting: bool,
    /// The light: headlight, dir:x,y,z (towards the light) or point:x,y,z.
    #[arg(long, default_value = "headlight", value_parser = parse_light, allow_hyphen_values = true)]
    pub light: Light,
    /// Background colour: r,g,b or #rrggbb.
    #[arg(long, default_value = "24,26,31", value_parser = parse_colour)]
    pub background: [u8; 3],
}

impl PipelineArgs {
    pub fn build(&self) -> Result<Pipeline> {
        if let Some(g) = self.layer_gap {
            if !(g > 0.0 && g.is_finite()) {
                return Err(format!("--layer-gap {g}: must be a positive distance"));
            }
        }
        if !(0.0..=1.0).contains(&self.aa_strength) {
            return Err(format!(
                "--aa-strength {}: must lie in 0..1",
                self.aa_strength
            ));
        }
        let mut p = Pipeline {
            backface_culling: !self.no_backface_culling,
            lighting: !self.no_lighting,
            light: self.light,
            background: self.background,
            geometry: vec![],
            colour: vec![],
            ..Pipeline::default()
        };
        if self.points_only {
            return Ok(p);
        }
        if !self.no_fill_background {
            p.geometry.push(GeometryPass::FillBackground {
                iterations: self.fill_background_iterations,
                radius: self.fill_radius,
            });
        }
        if !self.no_fill_occluded {
            p.geometry.push(GeometryPass::FillOccluded {
                iterations: self.fill_occluded_iterations,
                layer_gap: self.layer_gap,
                radius: self.fill_radius,
            });
        }
        if !self.no_smooth && self.smooth_iterations > 0 {
            p.colour.push(ColourPass::Smooth {
                kernel: self.smooth_kernel,
                iterations: self.smooth_iterations,
            });
        }
        if !self.no_antialias {
            p.colour.push(ColourPass::Antialias {
                threshold: self.aa_threshold,
                strength: self.aa_strength,
            });
        }
        Ok(p)
    }
}

/// Where the passes run, shared by `render` and `bench`.
#[derive(clap::Args, Clone)]
pub struct BackendArgs {
    /// Where the passes run: cpu, gpu, or auto (a suitable hardware GPU adapter if there is
    /// one, else the CPU, saying why once; software adapters like lavapipe only with gpu). `stipple devices` lists the adapters; WGPU_BACKEND=vulkan|gl|…
    /// restricts the search.
    #[arg(long, default_value = "auto", value_parser = Backend::parse)]
    pub backend: Backend,
    /// GPU projection: compute (the compute rasterizer, 64-bit atomics or the 32-bit two-pass
    /// fallback) or hardware (a PointList render pipeline with a depth test, the baseline).
    #[arg(long, default_value = "compute", value_parser = parse_projection)]
    pub projection: ProjectionPath,
    /// GPU: use the 32-bit two-pass projection even where 64-bit atomics exist.
    #[arg(long)]
    pub gpu_32bit: bool,
}

fn parse_projection(s: &str) -> std::result::Result<ProjectionPath, String> {
    match s {
        "compute" => Ok(ProjectionPath::Compute),
        "hardware" | "hw" => Ok(ProjectionPath::Hardware),
        _ => Err(format!("unknown projection `{s}` (compute, hardware)")),
    }
}

impl BackendArgs {
    /// Opens the renderer; `--projection hardware` with the CPU backend is an error.
    pub fn open(&self) -> Result<Renderer> {
        let options = GpuOptions {
            force_32bit: self.gpu_32bit,
            ..Default::default()
        };
        let mut r =
            Renderer::new(self.backend, options).map_err(|e| format!("--backend gpu: {e}"))?;
        match r.gpu_mut() {
            Some(g) => g.projection = self.projection,
            None if self.projection == ProjectionPath::Hardware => {
                return Err("--projection hardware needs the GPU backend".into())
            }
            None => {}
        }
        Ok(r)
    }
}
