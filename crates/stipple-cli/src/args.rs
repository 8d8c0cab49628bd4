//! Arguments shared by `render` and `bench`: the source cloud, the camera and the pipeline.

use crate::Result;
use anyhow::anyhow;
use glam::DVec3;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use stipple_core::demo::{self, DemoScene};
use stipple_core::{Camera, PointCloud};
use stipple_render::gpu::{GpuOptions, ProjectionPath};
use stipple_render::pipeline::{
    ColourPass, GeometryPass, Iterations, Kernel, Pipeline, RawSettings, RawShading,
};
use stipple_render::{Backend, Light, PreparedCloud, Renderer};
use stipple_render::{SplatMode, SplatSettings};

#[derive(clap::Args, Clone)]
pub struct SourceArgs {
    /// Cloud file (.ply, .ply.gz, .las, .laz, .copc.laz, .xyz, .txt, .csv; meshes .obj, .stl
    /// draw their vertices, `stipple convert` samples their faces), scene file
    /// (.toml, .json: see docs/scenes.md) or, for render and bench, a .stlod tree. Without
    /// one, a demo scene is rendered.
    pub input: Option<PathBuf>,
    /// Demo scene when no input is given: plane-objects, sphere, torus, nested-tori.
    #[arg(long, value_parser = parse_scene, default_value = "plane-objects")]
    pub demo: DemoScene,
    /// Number of demo points (default: 1 000 000; 1 500 000 for nested-tori).
    #[arg(long)]
    pub points: Option<usize>,
    /// Demo seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Memory budget (e.g. 16G): demo scenes, scene files and image sizes needing more are
    /// refused before any work. Default: the memory available (free memory, within
    /// `ulimit -v`).
    #[arg(long, value_parser = stipple_lod::mem::parse_size, value_name = "SIZE")]
    pub memory: Option<u64>,
    /// For a volume (.nrrd, .nii, .nii.gz, .raw): the value whose iso-surface is drawn as
    /// points (default: Otsu's threshold, which splits the values into object and
    /// background).
    #[arg(long, value_parser = finite_f64, allow_hyphen_values = true, value_name = "VALUE")]
    pub iso: Option<f64>,
    /// For a volume: a transfer function instead of an iso-surface (Gunjee et al. §3): every
    /// sample it gives an opacity above 0 becomes a point with its colour and opacity, lit by
    /// the volume's gradient. A file with a line `value r g b opacity` per control point
    /// (colour 0-255, opacity 0-1, linear between points), or the points inline:
    /// --transfer "300 255 200 150 0; 1200 255 255 255 0.4". See through it with --layers N.
    #[arg(
        long,
        conflicts_with = "iso",
        allow_hyphen_values = true,
        value_name = "FILE|POINTS"
    )]
    pub transfer: Option<String>,
}

impl SourceArgs {
    /// Loads (or generates) the cloud and prepares it; returns a label for messages.
    pub fn load(&self) -> Result<(PreparedCloud, String)> {
        let (cloud, label) = match &self.input {
            Some(p) => (
                read_with_options(
                    p,
                    &stipple_io::ReadOptions {
                        iso: self.iso,
                        transfer: self
                            .transfer
                            .as_deref()
                            .map(|t| stipple_io::transfer_function(t, None))
                            .transpose()
                            .map_err(|e| anyhow!("--transfer: {e}"))?,
                    },
                )?,
                p.display().to_string(),
            ),
            None => {
                let n = self.points.unwrap_or(self.demo.default_points());
                if n == 0 {
                    return Err(anyhow!("--points must be at least 1"));
                }
                crate::memory::check_points(
                    &format!("--points {n}"),
                    n as u64,
                    crate::memory::BYTES_PER_POINT,
                )?;
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
    read_with_options(path, &stipple_io::ReadOptions::default())
}

/// [`read_with_progress`] with the options for volumes.
pub fn read_with_options(path: &Path, opt: &stipple_io::ReadOptions) -> Result<PointCloud> {
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_message(format!("reading {}", path.display()));
    bar.enable_steady_tick(Duration::from_millis(120));
    let t0 = Instant::now();
    let r = stipple_io::read_cloud_with(path, opt);
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
    Ok(r?)
}

pub fn parse_vec3(s: &str) -> std::result::Result<DVec3, String> {
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

pub fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let err =
        || format!("`{s}` is not a size WxH such as 1024x768, or N for N×N (each side 1..=16384)");
    let (w, h) = s.split_once(['x', 'X']).unwrap_or((s, s));
    let (w, h): (u32, u32) = (w.parse().map_err(|_| err())?, h.parse().map_err(|_| err())?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(err());
    }
    Ok((w, h))
}

/// Below this address-space limit (`ulimit -v`) `--backend auto` does not probe GPU drivers.
pub const AUTO_PROBE_MIN_ADDRESS_SPACE: u64 = 8 << 30;

/// The background when neither the command line nor a scene gives one.
pub const DEFAULT_BACKGROUND: [u8; 3] = [24, 26, 31];

#[derive(clap::Args, Clone)]
pub struct CameraArgs {
    /// Image size in pixels, WxH or N for a square [default: 1024x1024, or a scene file's
    /// camera size].
    #[arg(long, value_parser = parse_size, value_name = "WxH")]
    pub size: Option<(u32, u32)>,
    /// Eye position x,y,z (world coordinates). Default: framing the whole cloud (or, for a
    /// file that records its sensor's pose, such as a PCD's VIEWPOINT, the sensor's view).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Point looked at, x,y,z. Default: the centre of the cloud's bounds.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<DVec3>,
    /// Up vector x,y,z. Default: +Z for LAS/LAZ/COPC (Z is elevation) and for clouds flat in
    /// Z; +Y for other files (scanned objects).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<DVec3>,
    /// The side the default framing looks from: three-quarter (front, a little from the
    /// right and above; LiDAR from the south, raised), three-quarter-back, front, back,
    /// left, right, top (a plan: for LiDAR a map, north up) or bottom. Front is south for
    /// LiDAR (Z up) and +Z for scanned objects (Y up), except that with no --view, --eye,
    /// --target or --up an object that shows more of its samples from −Z than from +Z (by
    /// over 5%: a scan is densest, a simplified mesh most detailed, at its front) is taken
    /// to face −Z and framed three-quarter-back, as the Stanford Lucy and Armadillo are.
    #[arg(long, value_enum, conflicts_with = "eye")]
    pub view: Option<stipple_core::camera::View>,
    /// Vertical field of view in degrees [default: 45, or a scene's].
    #[arg(long, value_parser = parse_fov)]
    pub fov: Option<f64>,
    /// Orthographic projection with this view height (world units) instead of perspective.
    #[arg(long, value_parser = positive_f64, value_name = "HEIGHT")]
    pub ortho: Option<f64>,
    /// Exactly the camera a JSON file holds (what --camera-out and `stipple view`'s C key
    /// write): eye, target, up, projection, size, near and far; --size still changes the
    /// size.
    #[arg(
        long,
        value_name = "FILE.json",
        conflicts_with_all = ["eye", "target", "up", "fov", "ortho", "view"]
    )]
    pub camera: Option<std::path::PathBuf>,
}

impl CameraArgs {
    /// The camera of `--camera FILE`, if given (with `--size` applied).
    fn file_camera(&self) -> Result<Option<Camera>> {
        let Some(p) = &self.camera else {
            return Ok(None);
        };
        let meta = std::fs::metadata(p).map_err(|e| anyhow!("{}: {e}", p.display()))?;
        if !meta.is_file() || meta.len() > 1 << 20 {
            return Err(anyhow!(
                "{}: not a camera file (a regular JSON file of at most 1 MiB)",
                p.display()
            ));
        }
        let text = std::fs::read_to_string(p).map_err(|e| anyhow!("{}: {e}", p.display()))?;
        let mut cam = Camera::from_json(&text).map_err(|e| anyhow!("{}: {e}", p.display()))?;
        if let Some((w, h)) = self.size {
            cam.width = w;
            cam.height = h;
        }
        cam.validate()
            .map_err(|e| anyhow!("{}: camera: {e}", p.display()))?;
        Ok(Some(cam))
    }

    /// The camera for a cloud: the default framing, then the overrides; near and far always
    /// come from the cloud's bounds.
    pub fn build(&self, cloud: &PointCloud) -> Result<Camera> {
        if let Some(cam) = self.file_camera()? {
            return Ok(cam);
        }
        let (lo, hi) = self.framed_bounds(cloud);
        if let (Some(s), None, None, None, None, None) = (
            cloud.sensor,
            self.eye,
            self.target,
            self.up,
            self.ortho,
            self.view,
        ) {
            // The cloud as its sensor saw it (a depth camera's frame): from its position,
            // along its view (turned to the points by the reader,
            // `PointCloud::face_sensor_to_points`), with a field of view that holds every
            // point in front of it.
            let step = (cloud.len() / 20_000).max(1);
            // Aimed at the points' centre (a cropped object off the sensor's axis is seen
            // in the middle of the image), the image up kept as near the sensor's as can be.
            let mut centre = glam::DVec3::ZERO;
            let mut seen = 0usize;
            for i in (0..cloud.len()).step_by(step) {
                let d = cloud.world(i) - s.position;
                if d.dot(s.forward) > 0.0 {
                    centre += d;
                    seen += 1;
                }
            }
            let forward = (centre / seen.max(1) as f64).normalize_or(s.forward);
            let up = (s.up - forward * s.up.dot(forward)).normalize_or(s.up);
            let s = stipple_core::cloud::Sensor { forward, up, ..s };
            let right = s.forward.cross(s.up).normalize();
            let (w, h) = self.size.unwrap_or(stipple_scene::file::DEFAULT_SIZE);
            let aspect = w as f64 / h.max(1) as f64;
            let mut tan = 0.0f64;
            for i in (0..cloud.len()).step_by(step) {
                let d = cloud.world(i) - s.position;
                let z = d.dot(s.forward);
                if z > 1e-9 {
                    tan = tan
                        .max(d.dot(s.up).abs() / z)
                        .max(d.dot(right).abs() / z / aspect);
                }
            }
            let fov = self
                .fov
                .unwrap_or_else(|| (2.0 * (tan * 1.03).atan().to_degrees()).clamp(10.0, 120.0));
            let mut cam = Camera {
                eye: s.position,
                target: s.position + s.forward,
                up: s.up,
                projection: stipple_core::Projection::Perspective { fov_deg: fov },
                width: w,
                height: h,
                near: 0.0,
                far: 0.0,
            };
            if tan > 0.0 {
                cam.validate().map_err(|e| anyhow!("camera: {e}"))?;
                cam.fit_clip(lo, hi);
                return Ok(cam);
            }
        }
        // A scanned object (Y up) that faces −Z is framed from that side (see
        // stipple_core::camera::faces_negative_z) unless the user named a side or a pose.
        if let (None, None, None, None) = (self.view, self.eye, self.up, self.target) {
            if !Camera::frames_z_up(lo, hi, cloud.z_up)
                && stipple_core::camera::faces_negative_z(&cloud.positions)
            {
                let back = CameraArgs {
                    view: Some(stipple_core::camera::View::ThreeQuarterBack),
                    ..self.clone()
                };
                return back.build_framed(lo, hi, false);
            }
        }
        self.build_framed(lo, hi, cloud.z_up)
    }

    /// The bounds the default camera frames: the whole cloud, or its bulk where a few points
    /// stray far from it ([`PointCloud::framing_bounds`]; said on stderr) and the user placed
    /// neither the eye nor the target.
    pub fn framed_bounds(&self, cloud: &PointCloud) -> (DVec3, DVec3) {
        if self.eye.is_some() || self.target.is_some() {
            return cloud.world_bounds();
        }
        let (lo, hi, strays) = cloud.framing_bounds();
        if strays > 0 {
            let (lie, them) = if strays == 1 {
                ("lies", "it")
            } else {
                ("lie", "them")
            };
            eprintln!(
                "stipple: the view frames the bulk of the cloud: {strays} of its {} points \
                 {lie} far outside it (place the camera with --eye and --target to see {them})",
                cloud.len()
            );
        }
        (lo, hi)
    }

    /// The camera for a scene with these world bounds (a LOD tree's root box): the default
    /// framing (Z-up when `z_up`), then the overrides.
    pub fn build_framed(&self, lo: DVec3, hi: DVec3, z_up: bool) -> Result<Camera> {
        if let Some(cam) = self.file_camera()? {
            return Ok(cam);
        }
        let spec = stipple_scene::file::CameraSpec {
            eye: self.eye.map(|v| v.to_array()),
            target: self.target.map(|v| v.to_array()),
            up: self.up.map(|v| v.to_array()),
            fov: self.fov,
            size: self.size.map(|(w, h)| [w, h]),
            view: self.view,
        };
        spec.camera(lo, hi, z_up, self.ortho)
            .map_err(|e| anyhow!("camera: {e}"))
    }
}

/// A number that is finite (NaN and infinities are refused before any range check).
pub fn finite_f64(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{}` is not a number", stipple_io::shown(s)))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{v} is not a finite number"))
    }
}

/// [`finite_f64`] as f32 (also refusing values beyond f32's range).
pub fn finite_f32(s: &str) -> std::result::Result<f32, String> {
    let v = finite_f64(s)? as f32;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{} is out of range", stipple_io::shown(s)))
    }
}

/// A vertical field of view in degrees, strictly between 0 and 180.
fn parse_fov(s: &str) -> std::result::Result<f64, String> {
    let v = finite_f64(s)?;
    if v > 0.0 && v < 180.0 {
        Ok(v)
    } else {
        Err(format!(
            "a field of view of {v}° is impossible: it must lie strictly between 0 and 180 degrees (45 is the default)"
        ))
    }
}

/// A finite number above zero.
fn positive_f64(s: &str) -> std::result::Result<f64, String> {
    let v = finite_f64(s)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{v} must be above zero"))
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
    if let Some(v) = s.strip_prefix("disc:") {
        let err = || format!("`{s}`: expected disc:x,y,z,radius");
        let (xyz, r) = v.rsplit_once(',').ok_or_else(err)?;
        let r: f64 = r.trim().parse().map_err(|_| err())?;
        if !(r > 0.0 && r.is_finite()) {
            return Err(format!("`{s}`: the radius must be positive"));
        }
        return Ok(Light::Area(stipple_render::AreaLight {
            centre: parse_vec3(xyz)?.to_array(),
            // Resolved to face the cloud's centre (see `aim_area_lights`).
            facing: [0.0; 3],
            shape: stipple_render::AreaShape::Disc { radius: r },
            samples: 16,
        }));
    }
    Err(format!(
        "`{s}`: expected headlight, dir:x,y,z, point:x,y,z or disc:x,y,z,radius"
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

/// Which pipeline renders the cloud.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PipelineChoice {
    /// Splats where points land apart on screen, Dobrev where they are dense (normals are
    /// estimated where missing); raw for trees.
    Auto,
    /// Image-space filters and Phong lighting (Dobrev et al.).
    Dobrev,
    /// Surface splats (Zhang & Pajarola).
    #[value(alias = "splats", alias = "zhang")]
    Splat,
    /// Visibility, anisotropic filling and shape depiction from depth alone (Pintus et al.).
    #[value(alias = "pintus")]
    Raw,
}

/// Shading of the raw pipeline.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ShadingChoice {
    /// Multi-level shape depiction (--depiction-levels).
    Depiction,
    /// One level: sharp lines and directional light.
    DepictionSingle,
    /// Eye-dome lighting.
    Edl,
    /// The colour only.
    None,
}

/// `--pipeline auto` draws splats when the cloud's median point spacing on screen exceeds
/// this many pixels. Dobrev's 3×3 fills close one-pixel gaps, but real clouds are not uniform
/// and the median understates their gaps: the Dragon (vrip) at 1024² is 0.9 px apart and
/// shows hundreds of holes to the background after the fills (45% of its pixels are filled),
/// the Armadillo at 512² (1.5 px) 41%. Splats close every gap at any spacing; single points
/// are only kept where they are dense enough for the fills (and project faster).
pub const SPLAT_ABOVE_PX: f32 = 0.5;

/// `--pipeline auto` estimates normals for clouds up to this many points; larger clouds
/// without normals (LiDAR tiles) are drawn raw, which needs none: estimation runs at
/// 0.2–0.3 M points/s on 2 cores (BENCHMARKS.md), a minute for a 10 M tile.
pub const AUTO_ESTIMATE_MAX: usize = 2_000_000;

/// Splats and normal estimation (Zhang & Pajarola 2007; normals by PCA, Hoppe et al. 1992).
#[derive(clap::Args, Clone)]
#[command(
    next_help_heading = "Splats and normals (Zhang & Pajarola; sparse clouds, clouds without normals)"
)]
pub struct SplatArgs {
    /// How splats make a pixel: blend (Gaussian-weighted mean of the nearest surface's
    /// splats' normals, colours and depths, shaded per pixel: smooth shading that averages
    /// out the noise of scanned normals; two passes over the splats), voronoi (the splat
    /// whose centre is nearest the pixel, relative to its radius, wins: sharp cells, each
    /// pixel shaded with the winning splat's normal where it meets the pixel's ray; a
    /// scan's normal noise shows cell by cell) or deferred (Zhang & Pajarola's single-pass deferred
    /// blending: splats graph-coloured into groups, one pass, per-pixel compositing; see
    /// --splat-c) or sorted (Gunjee et al.: every splat bucket-sorted back to front and
    /// blended over the ones behind it with its own opacity: volumes through --transfer,
    /// particle clouds) or transparent (Zhang & Pajarola's Algorithm 2: translucent surfaces
    /// in one pass, back to front into one image per group, each surface layer blended
    /// once per group, the groups averaged; see --opacity and scene opacities).
    #[arg(
        long = "splat",
        default_value = "blend",
        value_name = "MODE",
        value_enum
    )]
    pub splat_mode: SplatMode,
    /// Transparent splats: draw the nearest layer smoothly interpolated over its splats
    /// (Zhang & Pajarola's Algorithm 3, a scene's transparency = "splat-2pass") instead of
    /// each group's nearest splat (Algorithm 2): smoother colour on the surface in front.
    #[arg(long)]
    pub smooth_nearest: bool,
    /// Multiplies every splat radius (radii: 0.6 × the 16th-neighbour distance, or the
    /// file's `radius`).
    #[arg(long, value_parser = finite_f32, default_value_t = 1.0, value_name = "F")]
    pub splat_scale: f32,
    /// ε of the splats' ε-z test in world units: fragments this far behind the nearest one
    /// still blend [default: the median splat radius].
    #[arg(long, value_parser = finite_f32, value_name = "D")]
    pub splat_epsilon: Option<f32>,
    /// Overlap relaxation c of --splat deferred's grouping: splats closer than c × the sum
    /// of their radii go to different groups (1: every overlap; smaller: fewer groups, a
    /// little overlap inside a group). The paper's choice is 0.4.
    #[arg(long, value_parser = finite_f32, default_value_t = stipple_core::grouping::DEFAULT_C, value_name = "C")]
    pub splat_c: f32,
    /// Do not estimate normals for clouds without them (they are then drawn unlit: raw
    /// pipeline by default, or eye-facing splats).
    #[arg(long)]
    pub no_estimate_normals: bool,
    /// Where the sensor stood (x,y,z, the file's coordinates), for a single scan: estimated
    /// normals face it, and given ones are turned to face it, instead of the orientation
    /// propagated over the neighbour graph (which an open surface seen from below gets
    /// upside down).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true, value_name = "X,Y,Z")]
    pub viewpoint: Option<DVec3>,
    /// Neighbours per point for normal estimation and splat radii.
    #[arg(long, default_value_t = 16, value_name = "K",
          value_parser = clap::value_parser!(u32).range(3..=64))]
    pub normal_k: u32,
}

impl SplatArgs {
    pub fn settings(&self) -> Result<SplatSettings> {
        if !(self.splat_scale > 0.0 && self.splat_scale.is_finite()) {
            return Err(anyhow!(
                "--splat-scale {}: must be a positive number",
                self.splat_scale
            ));
        }
        if let Some(e) = self.splat_epsilon {
            if !(e >= 0.0 && e.is_finite()) {
                return Err(anyhow!("--splat-epsilon {e}: must be 0 or more"));
            }
        }
        if !(self.splat_c > 0.0 && self.splat_c <= 1.0) {
            return Err(anyhow!(
                "--splat-c {}: the overlap relaxation must lie in (0, 1]",
                self.splat_c
            ));
        }
        Ok(SplatSettings {
            mode: self.splat_mode,
            scale: self.splat_scale,
            epsilon: self.splat_epsilon,
            c: self.splat_c,
            depth_range: None,
            smooth_nearest: self.smooth_nearest,
            coverage: Default::default(),
        })
    }
}

fn parse_kernel(s: &str) -> std::result::Result<u32, String> {
    if s == "auto" {
        return Ok(0);
    }
    let k = stipple_render::pipeline::VISIBILITY_KERNELS;
    match s.parse::<u32>() {
        Ok(n) if k.contains(&n) => Ok(n),
        _ => Err(format!(
            "`{s}` is not a kernel size ({} to {}, or auto)",
            k.start(),
            k.end()
        )),
    }
}

/// Settings of the raw-cloud pipeline (Pintus et al. §4–6).
#[derive(clap::Args, Clone)]
#[command(next_help_heading = "Raw clouds (Pintus et al. §4-6; --raw, and .stlod trees)")]
pub struct RawArgs {
    /// Pipeline: auto (splat where points land more than half a pixel apart on screen or a
    /// --splat mode other than blend is given, else dobrev; normals are estimated for clouds
    /// without them; raw for .stlod trees), dobrev
    /// (image-space filters and Phong lighting), splat (surface splats, Zhang & Pajarola), or
    /// raw (screen-space visibility, anisotropic filling and shape depiction from depth alone,
    /// Pintus et al.; no normals needed).
    #[arg(long, default_value = "auto", value_enum, value_name = "NAME")]
    pub pipeline: PipelineChoice,
    /// Shorthand for --pipeline raw.
    #[arg(long)]
    pub raw: bool,
    /// Visibility kernel k (a k×k neighbourhood, 3 to 15; the paper used 4 to 9), or auto:
    /// 8 × the median point spacing on screen + 4. Sparser points need larger kernels.
    #[arg(long, default_value = "auto", value_parser = parse_kernel, value_name = "K|auto")]
    pub visibility_kernel: u32,
    /// Free fraction of the hemisphere above a pixel needed to count as visible (0..1).
    /// Higher removes more (fewer surfaces showing through, but eroded silhouettes).
    #[arg(long, value_parser = finite_f32, default_value_t = 0.4)]
    pub visibility_threshold: f32,
    /// Skip the visibility operator: every empty pixel is filled and nothing is removed, so
    /// hidden surfaces show through and silhouettes grow (Pintus Fig. 9a).
    #[arg(long)]
    pub no_visibility: bool,
    /// Anisotropic fill iterations (default: twice the kernel, the largest hole closed).
    #[arg(long, value_name = "N")]
    pub raw_fill_iterations: Option<u32>,
    /// Depth tolerance δ of the fill (Eq. 1), in pixel footprints: neighbours farther than
    /// this in depth do not blend.
    #[arg(long, value_parser = finite_f32, default_value_t = 8.0)]
    pub fill_delta: f32,
    /// Shading: depiction (multi-level shape depiction), depiction-single (one level: sharp
    /// lines and directional light), edl (eye-dome lighting), or none (colour only).
    #[arg(long, default_value = "depiction", value_enum)]
    pub shading: ShadingChoice,
    /// Levels of the multi-level depiction (more = broader, ambient-occlusion-like shading).
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=32))]
    pub depiction_levels: u32,
    /// ξ of Eq. 3: how fast the levels' weights fall (0 = equal; larger = sharper).
    #[arg(long, value_parser = finite_f32, default_value_t = 1.5)]
    pub depiction_xi: f32,
    /// ε of Eq. 2 in pixel footprints: larger = gentler shading of tilted surfaces.
    #[arg(long, value_parser = finite_f32, default_value_t = 2.0)]
    pub depiction_epsilon: f32,
    /// EDL strength (with --shading edl).
    #[arg(long, value_parser = finite_f32, default_value_t = 1.0)]
    pub edl_strength: f32,
    /// EDL neighbour radius in pixels (with --shading edl).
    #[arg(long, value_parser = finite_f32, default_value_t = 1.4)]
    pub edl_radius: f32,
}

impl RawArgs {
    /// The pipeline asked for (`--raw` is `--pipeline raw`).
    pub fn choice(&self) -> PipelineChoice {
        if self.raw {
            PipelineChoice::Raw
        } else {
            self.pipeline
        }
    }

    pub fn build(&self, background: [u8; 3]) -> Result<Pipeline> {
        let finite_pos = |v: f32, name: &str| {
            if v > 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(anyhow!("--{name} {v}: must be a positive number"))
            }
        };
        finite_pos(self.fill_delta, "fill-delta")?;
        finite_pos(self.depiction_epsilon, "depiction-epsilon")?;
        finite_pos(self.edl_strength, "edl-strength")?;
        finite_pos(self.edl_radius, "edl-radius")?;
        if !(0.0..=1.0).contains(&self.visibility_threshold) {
            return Err(anyhow!(
                "--visibility-threshold {}: must lie in 0..1",
                self.visibility_threshold
            ));
        }
        if !(self.depiction_xi >= 0.0 && self.depiction_xi.is_finite()) {
            return Err(anyhow!(
                "--depiction-xi {}: must be 0 or more",
                self.depiction_xi
            ));
        }
        let shading = match self.shading {
            ShadingChoice::Depiction => RawShading::Depiction(self.depiction_levels),
            ShadingChoice::DepictionSingle => RawShading::Depiction(1),
            ShadingChoice::Edl => RawShading::Edl,
            ShadingChoice::None => RawShading::None,
        };
        let mut p = Pipeline::raw(RawSettings {
            kernel: self.visibility_kernel,
            visibility: !self.no_visibility,
            threshold: self.visibility_threshold,
            fill_iterations: self.raw_fill_iterations,
            delta: self.fill_delta,
            shading,
            xi: self.depiction_xi,
            epsilon: self.depiction_epsilon,
            edl_strength: self.edl_strength,
            edl_radius: self.edl_radius,
        });
        p.background = background;
        Ok(p)
    }
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
    #[arg(long, value_parser = finite_f32, value_name = "D")]
    pub layer_gap: Option<f32>,
    /// Skip smoothing (§3.4).
    #[arg(long)]
    pub no_smooth: bool,
    /// Smoothing kernel: box, gauss, or alleviated (Gaussian with centre weight 16/28).
    #[arg(long, default_value = "alleviated", value_enum)]
    pub smooth_kernel: Kernel,
    /// Smoothing iterations.
    #[arg(long, default_value_t = 1)]
    pub smooth_iterations: u32,
    /// Skip anti-aliasing (§3.5).
    #[arg(long)]
    pub no_antialias: bool,
    /// Laplace threshold on depth / z_far: high = only silhouettes against the background,
    /// low = also edges between surface layers.
    #[arg(long, value_parser = finite_f32, default_value_t = 0.02)]
    pub aa_threshold: f32,
    /// How much an edge pixel takes of its blurred neighbourhood (0..1).
    #[arg(long, value_parser = finite_f32, default_value_t = 0.6)]
    pub aa_strength: f32,
    /// Discard points whose normals face away from the eye before projecting (Dobrev
    /// §3.1). Off by default: the hidden side's points fill the gaps that the 3×3 fills
    /// cannot close where a randomly sampled surface lands about one point per pixel (the
    /// occluded fill then replaces them with the front's points), and a patch of normals
    /// oriented wrongly is not cut out.
    #[arg(long)]
    pub backface_culling: bool,
    /// Kept for old command lines: culling is off unless --backface-culling asks for it.
    #[arg(long, hide = true)]
    pub no_backface_culling: bool,
    /// Show colours unlit even where normals exist.
    #[arg(long)]
    pub no_lighting: bool,
    /// The light: headlight, dir:x,y,z (towards the light), point:x,y,z, or disc:x,y,z,r (an
    /// area light of radius r facing the cloud, for soft shadows with --shadows).
    #[arg(long, default_value = "headlight", value_parser = parse_light, allow_hyphen_values = true)]
    pub light: Light,
    /// Point and area lights fall off with the square of the distance, at full strength D
    /// from the light (brighter nearer, 1/4 at 2D): lights inside or among objects light
    /// what is near them [default: no falloff, or a scene's `falloff`].
    #[arg(long, value_parser = positive_f64, value_name = "D")]
    pub light_falloff: Option<f64>,
    /// Background colour: r,g,b or #rrggbb [default: 24,26,31, or a scene's].
    #[arg(long, value_parser = parse_colour)]
    pub background: Option<[u8; 3]>,
    /// Depth cueing: far points fade into the background colour, by this fraction at the far
    /// plane (0 = off, 1 = the farthest points vanish); separates near from far at a glance,
    /// e.g. canopy from ground in LiDAR. Any pipeline.
    #[arg(long, value_parser = finite_f32, default_value_t = 0.0, value_name = "S")]
    pub depth_cue: f32,
    #[command(flatten)]
    pub raw: RawArgs,
    #[command(flatten)]
    pub splat: SplatArgs,
}

impl PipelineArgs {
    /// The pipeline for a cloud that is not prepared (no estimation, no camera): raw where
    /// the cloud has no normals and auto is asked for, else the pipeline named.
    pub fn build_for(&self, has_normals: bool) -> Result<Pipeline> {
        let background = self.background.unwrap_or(DEFAULT_BACKGROUND);
        match self.raw.choice() {
            PipelineChoice::Raw => self.raw_pipeline(background),
            PipelineChoice::Auto if !has_normals => self.raw_pipeline(background),
            PipelineChoice::Splat => {
                let mut p = self.build()?;
                p.geometry.clear();
                p.backface_culling = false;
                p.splat = Some(self.splat.settings()?);
                Ok(p)
            }
            _ => self.build(),
        }
    }

    /// Chooses the pipeline for a cloud seen by `camera` (see `--pipeline`) and prepares the
    /// cloud for it: estimates normals where a lit pipeline needs them, re-orients given
    /// normals of inconsistent sign, computes splat radii. `tree`: a cut of a .stlod tree
    /// (auto keeps the raw pipeline there). `see_through`: the frame asks for transparency
    /// without peeling (translucent points, an environment or an index of refraction), which
    /// only splats draw, so auto takes splats at any spacing. Returns the pipeline and lines
    /// to tell the user.
    pub fn choose(
        &self,
        cloud: &mut PreparedCloud,
        camera: &stipple_core::Camera,
        tree: bool,
        peeled: bool,
        see_through: bool,
    ) -> Result<(Pipeline, Vec<String>)> {
        let choice = self.raw.choice();
        let mut notes = Vec::new();
        let background = self.background.unwrap_or(DEFAULT_BACKGROUND);
        let splat = self.splat.settings()?;
        // Built (and so checked) whichever pipeline is chosen: a bad raw flag is an error.
        let mut raw = self.raw_pipeline(background)?;
        if self.points_only {
            // The points alone, in every pipeline.
            raw.geometry.clear();
            raw.colour.clear();
        }
        let b = cloud.bounds();
        if b.max == b.min {
            let at = cloud.cloud.origin + b.min.as_dvec3();
            notes.push(format!(
                "all {} point{} lie at one position ({:.6}, {:.6}, {:.6}): the image shows them \
                 as a single dot at its centre",
                cloud.cloud.len(),
                if cloud.cloud.len() == 1 { "" } else { "s" },
                at.x,
                at.y,
                at.z
            ));
        }
        if choice == PipelineChoice::Raw || (choice == PipelineChoice::Auto && tree) {
            return Ok((raw, notes));
        }
        let estimate = !self.splat.no_estimate_normals && !self.no_lighting;
        let had_normals = cloud.cloud.normals.is_some();
        let n = cloud.cloud.len();
        if choice == PipelineChoice::Auto && estimate && !had_normals && n > AUTO_ESTIMATE_MAX {
            notes.push(format!(
                "{:.1} M points without normals: drawn raw (screen-space operators, no normals \
                 needed); --pipeline splat or dobrev estimates normals first (about {:.0} s \
                 at 0.2-0.3 M points/s on 2 cores)",
                n as f64 / 1e6,
                n as f64 / 0.25e6
            ));
            return Ok((raw, notes));
        }
        if estimate && !had_normals && n > 1_000_000 {
            eprintln!(
                "stipple: estimating normals for {n} points (k = {}; --no-estimate-normals or \
                 --raw skip this)...",
                self.splat.normal_k
            );
        }
        // Normals face the sensor where the file says where it stood.
        let viewpoint = self
            .splat
            .viewpoint
            .or(cloud.cloud.sensor.map(|s| s.position));
        let report =
            match cloud.prepare_surface_from(self.splat.normal_k as usize, estimate, viewpoint) {
                Err(stipple_core::normals::NormalError::TooFew(n))
                    if choice == PipelineChoice::Auto =>
                {
                    notes.push(format!(
                        "{n} point{}: too few to estimate normals or splat sizes (3 are needed); \
                     drawn as single unlit points",
                        if n == 1 { "" } else { "s" }
                    ));
                    return Ok((raw, notes));
                }
                r => r.map_err(|e| anyhow!("normal estimation: {e}"))?,
            };
        if let (Some(note), false) = (report.dequantised_note(), report.repeated) {
            notes.push(note);
        }
        if report.estimated && !report.repeated {
            notes.push(format!(
                "estimated normals for {n} points (k = {}, oriented {}) in {:.2} s",
                self.splat.normal_k,
                report.oriented.describe(),
                report.seconds
            ));
        }
        if report.repeated {
            // Told when it was done.
        } else if report.reoriented > 0 && self.splat.viewpoint.is_some() {
            notes.push(format!(
                "turned {} of {n} given normals to face the viewpoint",
                report.reoriented
            ));
        } else if report.reoriented > 0 {
            notes.push(format!(
                "turned round {} of {n} given normals: their signs were inconsistent \
                 ({:.0}% of neighbouring normals disagreed)",
                report.reoriented,
                100.0 * report.inconsistency
            ));
        }
        let has_normals = cloud.cloud.normals.is_some();
        let pick = match choice {
            PipelineChoice::Auto if !has_normals => {
                // No normals and none estimated: the raw operators need none.
                return Ok((raw, notes));
            }
            // Single points asked for: Dobrev's pipeline without its passes. Depth peeling
            // (--layers N) is Dobrev's too: splats have no layers yet.
            PipelineChoice::Auto if self.points_only || peeled => PipelineChoice::Dobrev,
            // A splat mode other than the default (or Algorithm 3) asked for: splats at any
            // spacing (else `--splat transparent` on a dense view drew opaque points).
            PipelineChoice::Auto
                if self.splat.splat_mode != stipple_render::SplatMode::Blend
                    || self.splat.smooth_nearest
                    || see_through =>
            {
                PipelineChoice::Splat
            }
            PipelineChoice::Auto => {
                let px = cloud.screen_spacing(camera);
                if px.is_finite() && px <= SPLAT_ABOVE_PX {
                    PipelineChoice::Dobrev
                } else if !px.is_finite() {
                    notes.push(
                        "drawing splats: the points' spacing on screen is not known (the \
                         points coincide, or the camera is inside the cloud; --pipeline \
                         dobrev draws single points)"
                            .into(),
                    );
                    PipelineChoice::Splat
                } else {
                    notes.push(format!(
                        "drawing splats: the points land {px:.1} px apart on screen (more than \
                         {SPLAT_ABOVE_PX} px; --pipeline dobrev draws single points)"
                    ));
                    PipelineChoice::Splat
                }
            }
            c => c,
        };
        let mut p = self.build()?;
        if report.estimated || report.reoriented > 0 {
            // Orientation propagated over a neighbour graph can still be wrong in patches
            // (thin parts, where two sheets touch); culling would cut holes there (the Dragon
            // at 512²: specks all over its body). Depth visibility hides the back anyway.
            p.backface_culling = false;
        }
        if pick == PipelineChoice::Splat {
            p.geometry.clear();
            p.backface_culling = false;
            p.splat = Some(splat);
        }
        Ok((p, notes))
    }

    /// The raw pipeline, with depth cueing if asked for.
    fn raw_pipeline(&self, background: [u8; 3]) -> Result<Pipeline> {
        let mut p = self.raw.build(background)?;
        self.add_depth_cue(&mut p)?;
        Ok(p)
    }

    /// Appends `--depth-cue` to the colour passes (last: it fades the finished image).
    fn add_depth_cue(&self, p: &mut Pipeline) -> Result<()> {
        let s = self.depth_cue;
        if !(0.0..=1.0).contains(&s) {
            return Err(anyhow!("--depth-cue {s}: must lie in 0..1"));
        }
        if s > 0.0 {
            // Fades into the frame's background (a scene's, when it sets one).
            p.colour.push(ColourPass::DepthCue {
                strength: s,
                colour: None,
            });
        }
        Ok(())
    }

    /// The Dobrev pipeline.
    pub fn build(&self) -> Result<Pipeline> {
        if let Some(g) = self.layer_gap {
            if !(g > 0.0 && g.is_finite()) {
                return Err(anyhow!("--layer-gap {g}: must be a positive distance"));
            }
        }
        if !(0.0..=1.0).contains(&self.aa_strength) {
            return Err(anyhow!(
                "--aa-strength {}: must lie in 0..1",
                self.aa_strength
            ));
        }
        if let Some(d) = self.light_falloff.filter(|&d| !(d as f32).is_finite()) {
            return Err(anyhow!("--light-falloff {d}: too large"));
        }
        let mut p = Pipeline {
            backface_culling: self.backface_culling && !self.no_backface_culling,
            lighting: !self.no_lighting,
            lights: vec![self.light],
            falloff: self.light_falloff.map(|d| d as f32),
            background: self.background.unwrap_or(DEFAULT_BACKGROUND),
            geometry: vec![],
            colour: vec![],
            ..Pipeline::default()
        };
        if self.points_only {
            self.add_depth_cue(&mut p)?;
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
        self.add_depth_cue(&mut p)?;
        Ok(p)
    }
}

/// Depth peeling, transparency and shadows, shared by `render` and `bench`.
#[derive(clap::Args, Clone, Default)]
#[command(next_help_heading = "Transparency and shadows (Dobrev et al. §4-6)")]
pub struct LookArgs {
    /// Depth peeling: peel up to N surface layers and blend them front to back with each
    /// point's opacity (1 = the nearest surface only) [default: 1, or a scene's `layers`].
    #[arg(long, value_name = "N")]
    pub layers: Option<u32>,
    /// Give every point of a single cloud this opacity (0..1): see-through with --layers.
    #[arg(long, value_parser = finite_f32, value_name = "ALPHA")]
    pub opacity: Option<f32>,
    /// An environment behind transparent splats (Zhang & Pajarola §5.2.3): `sky` (a
    /// procedural sky over a checkered ground) or an equirectangular image: a PNG (sRGB)
    /// or a Radiance `.hdr` (linear, high dynamic range). Seen through every layer; with
    /// --ior the surfaces reflect it.
    #[arg(long, value_name = "sky|FILE.png|FILE.hdr")]
    pub env: Option<std::path::PathBuf>,
    /// Refractive index of transparent surfaces (e.g. 1.5 for glass): their nearest layer
    /// reflects the environment by Fresnel's law, more at grazing angles, and the layers
    /// refract it (Zhang & Pajarola's Eq. 12: more layers, more bending) [default: none,
    /// no reflection or refraction].
    #[arg(long, value_parser = finite_f32, value_name = "ETA")]
    pub ior: Option<f32>,
    /// Chromatic dispersion of --ior: red refracts with index η(1 − δ), blue with η(1 + δ)
    /// (0 to 0.2; glass about 0.01) [default: 0].
    #[arg(long, value_parser = finite_f32, value_name = "DELTA")]
    pub dispersion: Option<f32>,
    /// Transparent splats: how each group of splats covers the surface (Zhang & Pajarola
    /// §4.2.2): `duplicate` copies other groups' splats into it (sharp; the default),
    /// `enlarge` grows its splats instead (four balanced groups, no copies, softer
    /// silhouettes) [default: duplicate, or a scene's `coverage`].
    #[arg(long, value_enum, value_name = "METHOD")]
    pub coverage: Option<stipple_render::CoverageMethod>,
    /// Compute shadow textures for the lights that cast them (point and area lights, e.g.
    /// --light point:x,y,z or disc:x,y,z,r). Scene files have shadows on unless they say
    /// `shadows = false`.
    #[arg(long)]
    pub shadows: bool,
    /// No shadows, even where a scene asks for them.
    #[arg(long, conflicts_with = "shadows")]
    pub no_shadows: bool,
    /// Monte Carlo samples per area light, 1 to 255 (default: the light's own count: 16 for
    /// --light disc:..., a scene's `samples`). 1 = a hard shadow from the light's centre.
    #[arg(long, value_name = "N")]
    pub shadow_samples: Option<u32>,
    /// Side of the light images in pixels (default: about two point spacings per pixel).
    #[arg(long, value_name = "PX")]
    pub shadow_size: Option<u32>,
    /// Translucent shadows (Gunjee et al. §4.1): light layers peeled from each light image
    /// when some point has an opacity below 1, 1 to 64 [default: 8, or a scene's
    /// `shadow_layers`]. Each surface of opacity α in front of a point lets 1 − α of the light
    /// through; points behind the last layer get what the layers let through. 1 = every
    /// surface casts a full shadow, as an opaque one does.
    #[arg(long, value_name = "N")]
    pub shadow_layers: Option<u32>,
    /// Reuse shadow textures: load them from FILE when they were computed for the same clouds,
    /// placement and lights (the whole scene may have moved), else compute and save them there.
    #[arg(long, value_name = "FILE.stshadow")]
    pub shadow_cache: Option<PathBuf>,
}

/// Where the passes run, shared by `render` and `bench`.
#[derive(clap::Args, Clone)]
pub struct BackendArgs {
    /// Where the passes run: cpu, gpu, or auto (a suitable hardware GPU adapter if there is
    /// one, else the CPU, saying why once; software adapters like lavapipe only with gpu). `stipple devices` lists the adapters; WGPU_BACKEND=vulkan|gl|…
    /// restricts the search.
    #[arg(long, default_value = "auto", value_enum)]
    pub backend: Backend,
    /// GPU projection: compute (the compute rasterizer, 64-bit atomics or the 32-bit two-pass
    /// fallback) or hardware (a PointList render pipeline with a depth test, the baseline).
    #[arg(long, default_value = "compute", value_enum)]
    pub projection: ProjectionPath,
    /// GPU: use the 32-bit two-pass projection even where 64-bit atomics exist.
    #[arg(long)]
    pub gpu_32bit: bool,
}

impl BackendArgs {
    /// Opens the renderer; `--projection hardware` with the CPU backend is an error.
    /// Opens the renderer; `auto` under a small `ulimit -v` (below
    /// [`AUTO_PROBE_MIN_ADDRESS_SPACE`]) takes the CPU without probing GPU drivers.
    pub fn open(&self) -> Result<Renderer> {
        let options = GpuOptions {
            force_32bit: self.gpu_32bit,
            ..Default::default()
        };
        let mut backend = self.backend;
        if backend == Backend::Auto {
            if let Some(limit) = stipple_lod::mem::address_space_limit() {
                if limit < AUTO_PROBE_MIN_ADDRESS_SPACE {
                    // GPU drivers map large address ranges when probed, which a small
                    // `ulimit -v` cannot take: stay on the CPU.
                    eprintln!(
                        "stipple: note: ulimit -v is {} MiB: rendering on the CPU without \
                         probing GPU drivers (--backend gpu probes anyway)",
                        limit >> 20
                    );
                    backend = Backend::Cpu;
                }
            }
        }
        let mut r = Renderer::new(backend, options).map_err(|e| anyhow!("--backend gpu: {e}"))?;
        match r.gpu_mut() {
            Some(g) => g.projection = self.projection,
            None if self.projection == ProjectionPath::Hardware => {
                return Err(anyhow!("--projection hardware needs the GPU backend"))
            }
            None => {}
        }
        Ok(r)
    }
}

/// A demo scene by name.
pub fn parse_scene(s: &str) -> std::result::Result<stipple_core::demo::DemoScene, String> {
    stipple_core::demo::DemoScene::from_name(s).ok_or_else(|| {
        let names: Vec<_> = stipple_core::demo::DemoScene::ALL
            .iter()
            .map(|d| d.name())
            .collect();
        format!("unknown scene `{s}` (one of: {})", names.join(", "))
    })
}

/// Colour by attribute and lookup tables (`render`, and Python's `render`).
#[derive(clap::Args, Clone, Default)]
#[command(next_help_heading = "Colour by attribute, lookup tables (Gunjee et al. §3)")]
pub struct ColourArgs {
    /// Colour the points by an attribute instead of the file's colours: elevation (Z for
    /// LiDAR and clouds flat in Z, else Y), intensity, classification (the ASPRS class
    /// palette: ground brown, vegetation greens, buildings orange, water blue, …), return
    /// (the LiDAR return number: first returns light grey, second amber, third orange, fourth
    /// red, later purple: canopy against open ground), a world coordinate x, y, z, or any
    /// scalar field of the file by name (a PLY or PCD property such as curvature or
    /// confidence; `stipple info` lists them).
    #[arg(long, visible_alias = "color-by", value_name = "ATTR", value_parser = parse_colour_by)]
    pub colour_by: Option<stipple_core::colour_map::ColourBy>,
    /// Colour map for --colour-by: viridis (perceptually uniform, colour-blind safe),
    /// turbo (rainbow, for detail), grey, inferno.
    #[arg(
        long,
        visible_alias = "colormap",
        default_value = "viridis",
        value_name = "NAME"
    )]
    pub colour_map: stipple_core::colour_map::ColourMap,
    /// Values mapped to the two ends of the colour map, LO,HI (default: the 2nd and 98th
    /// percentiles of the attribute, so outliers do not flatten the rest).
    #[arg(long, value_parser = parse_range, value_name = "LO,HI", requires = "colour_by", allow_hyphen_values = true)]
    pub range: Option<(f64, f64)>,
    /// A lookup table (TOML): per value of an integer attribute (classification, return, or a
    /// field such as a material id), the colour, opacity, splat size, Phong material of
    /// those points, or `show = false` to leave them out; applied after --colour-by. See
    /// docs/lookup.md and examples/classes.toml.
    #[arg(long, value_name = "FILE")]
    pub lookup: Option<std::path::PathBuf>,
    /// Keep only the points inside this box, X0,Y0,Z0,X1,Y1,Z1 in world coordinates (the
    /// file's units, as `stipple info` prints the bounds): a clipping box to look inside a
    /// scan or cut a tile.
    #[arg(long, value_name = "X0,Y0,Z0,X1,Y1,Z1", value_parser = parse_box, allow_hyphen_values = true)]
    pub clip_box: Option<(DVec3, DVec3)>,
}

/// `--clip-box`: two corners, the low one first.
fn parse_box(s: &str) -> std::result::Result<(DVec3, DVec3), String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("`{s}`: expected six numbers X0,Y0,Z0,X1,Y1,Z1"))?;
    if v.len() != 6 || v.iter().any(|x| !x.is_finite()) {
        return Err(format!(
            "`{s}`: expected six finite numbers X0,Y0,Z0,X1,Y1,Z1"
        ));
    }
    let (lo, hi) = (DVec3::new(v[0], v[1], v[2]), DVec3::new(v[3], v[4], v[5]));
    if !lo.cmple(hi).all() {
        return Err(format!(
            "`{s}`: the first corner must be the low one (X0 ≤ X1, Y0 ≤ Y1, Z0 ≤ Z1)"
        ));
    }
    Ok((lo, hi))
}

/// `--colour-by`: a built-in attribute's name, else a scalar field's.
fn parse_colour_by(s: &str) -> std::result::Result<stipple_core::colour_map::ColourBy, String> {
    use clap::ValueEnum;
    use stipple_core::colour_map::{Attribute, ColourBy};
    if let Ok(a) = Attribute::from_str(s, true) {
        return Ok(ColourBy::Attribute(a));
    }
    let t = s.trim();
    if t.is_empty() || t.len() > 128 || t.chars().any(char::is_control) {
        return Err(format!(
            "`{s}`: name an attribute (elevation, intensity, classification, return, x, y, z) \
             or a scalar field of the file"
        ));
    }
    Ok(ColourBy::Field(t.to_string()))
}

fn parse_range(s: &str) -> std::result::Result<(f64, f64), String> {
    let v: Vec<&str> = s.split(',').collect();
    let bad = || format!("`{s}`: expected LO,HI with LO < HI, e.g. 10,250");
    if v.len() != 2 {
        return Err(bad());
    }
    let lo: f64 = v[0].trim().parse().map_err(|_| bad())?;
    let hi: f64 = v[1].trim().parse().map_err(|_| bad())?;
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(bad());
    }
    Ok((lo, hi))
}

impl ColourArgs {
    /// Colours the cloud and applies the clipping box and lookup table as asked; the lines
    /// to print. `what` names the input in errors.
    pub fn apply(
        &self,
        cloud: &mut stipple_render::PreparedCloud,
        what: &str,
    ) -> anyhow::Result<Vec<String>> {
        let table = self.load_lookup()?;
        self.apply_loaded(cloud, what, table.as_ref())
    }

    /// The `--lookup` table, read and checked (once, for clouds coloured many times: a
    /// streamed tree's cuts).
    pub fn load_lookup(
        &self,
    ) -> anyhow::Result<Option<(std::path::PathBuf, stipple_core::lookup::LookupTable)>> {
        let Some(path) = &self.lookup else {
            return Ok(None);
        };
        let table = stipple_io::lookup_table(path).map_err(|e| anyhow!("--lookup {e}"))?;
        Ok(Some((path.clone(), table)))
    }

    /// [`ColourArgs::apply`] with the lookup table already read.
    pub fn apply_loaded(
        &self,
        cloud: &mut stipple_render::PreparedCloud,
        what: &str,
        lookup: Option<&(std::path::PathBuf, stipple_core::lookup::LookupTable)>,
    ) -> anyhow::Result<Vec<String>> {
        let mut lines = Vec::new();
        if let Some((lo, hi)) = self.clip_box {
            let c = &cloud.cloud;
            let keep: Vec<bool> = (0..c.len())
                .map(|i| {
                    let w = c.world(i);
                    w.cmpge(lo).all() && w.cmple(hi).all()
                })
                .collect();
            let kept = keep.iter().filter(|&&k| k).count();
            if kept == 0 {
                return Err(anyhow!(
                    "{what}: --clip-box keeps none of the {} points (their bounds: {:.3?} … {:.3?})",
                    c.len(),
                    c.world_bounds().0.to_array(),
                    c.world_bounds().1.to_array()
                ));
            }
            if kept < c.len() {
                let n = c.len();
                let taken = std::mem::replace(
                    cloud,
                    stipple_render::PreparedCloud::new(Default::default()),
                );
                *cloud = taken
                    .retained(&keep)
                    .map_err(|e| anyhow!("{what}: --clip-box: {e}"))?;
                lines.push(format!("clip box: {kept} of {n} points inside"));
            }
        }
        if let Some(line) = self.colour(cloud, what)? {
            lines.push(line);
        }
        if let Some((path, table)) = lookup {
            let taken = std::mem::replace(
                cloud,
                stipple_render::PreparedCloud::new(Default::default()),
            );
            let (c, applied) = taken
                .with_lookup(table, &stipple_render::Material::default())
                .map_err(|e| anyhow!("{what}: --lookup {}: {e}", path.display()))?;
            *cloud = c;
            lines.push(stipple_core::lookup::summary(path, table, &applied));
        }
        Ok(lines)
    }

    fn colour(
        &self,
        cloud: &mut stipple_render::PreparedCloud,
        what: &str,
    ) -> anyhow::Result<Option<String>> {
        use stipple_core::colour_map::{colour_by_any, elevation_is_z, Attribute, ColourBy};
        let Some(by) = &self.colour_by else {
            // A placeholder intensity is not shown: say so, and how to show it.
            let c = &cloud.cloud;
            // Prepared already: the reason is looked for only where none is shown.
            let shown = cloud.intensity_scale.is_some();
            let hidden = match (&c.colors, &c.intensity, self.lookup.is_some() || shown) {
                (None, Some(i), false) => stipple_core::colour_map::intensity_scale_or_why(i).err(),
                _ => None,
            };
            return Ok(match hidden {
                Some(stipple_core::colour_map::IntensityHidden::Placeholder { share, .. }) => {
                    Some(format!(
                        "the intensity is one value for {:.0}% of the points (a placeholder): \
                         shown in the material's colour (--colour-by intensity shows it)",
                        100.0 * share
                    ))
                }
                _ => None,
            });
        };
        let (colours, (lo, hi)) = colour_by_any(&cloud.cloud, by, self.colour_map, self.range)
            .map_err(|e| anyhow!("{what}: --colour-by: {e}"))?;
        cloud.cloud.colors = Some(colours);
        use clap::ValueEnum;
        let value_name = |v: Option<clap::builder::PossibleValue>| {
            v.map_or(String::new(), |v| v.get_name().to_string())
        };
        let name = match by {
            ColourBy::Attribute(Attribute::Elevation) if elevation_is_z(&cloud.cloud) => {
                "elevation (z)".to_string()
            }
            ColourBy::Attribute(Attribute::Elevation) => "elevation (y)".to_string(),
            ColourBy::Attribute(a) => value_name(a.to_possible_value()),
            ColourBy::Field(f) => {
                let name = cloud.cloud.field(f).map_or(f.as_str(), |x| x.name.as_str());
                format!("the field `{name}`")
            }
        };
        Ok(Some(
            if *by == ColourBy::Attribute(Attribute::Classification) {
                "colouring by classification (ASPRS class palette)".to_string()
            } else if *by == ColourBy::Attribute(Attribute::Return) {
                "colouring by return number (first light grey, second amber, third orange, fourth \
             red, later purple)"
                    .to_string()
            } else {
                // Three significant digits of the range's width.
                let decimals = (3.0 - (hi - lo).log10().floor()).clamp(0.0, 9.0) as usize;
                format!(
                "colouring by {name}: {lo:.decimals$} … {hi:.decimals$} over the {} colour map{}",
                value_name(self.colour_map.to_possible_value()),
                if self.range.is_none() {
                    " (2nd to 98th percentile; --range LO,HI sets it)"
                } else {
                    ""
                }
            )
            },
        ))
    }
}
