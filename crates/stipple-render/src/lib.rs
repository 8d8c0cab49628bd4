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
pub mod eval;
pub mod gbuffer;
pub mod gpu;
pub mod lights;
pub mod masks;
pub mod material;
pub mod params;
pub mod passes;
pub mod pipeline;
pub mod schedule;
pub mod shadow;
pub mod srgb;
pub mod stats;

pub use gbuffer::{is_point, GBuffer, BACKGROUND, HOLE};
pub use lights::{AreaLight, AreaShape, Light};
pub use params::ViewParams;
pub use passes::splat::{SplatMode, SplatSettings};
pub use pipeline::{ColourPass, GeometryPass, Iterations, Kernel, Material, Pipeline};
pub use shadow::LitTexture;
pub use stats::{PassId, PassStat};

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
    #[error(transparent)]
    Pipeline(#[from] pipeline::PipelineError),
    #[error(transparent)]
    Lights(#[from] lights::LightError),
    #[error(transparent)]
    Shadow(#[from] shadow::ShadowError),
    #[error(transparent)]
    Objects(#[from] ObjectError),
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

/// A scene's objects: the object of each point and each object's material.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectTable {
    /// Object per point (at most [`MAX_OBJECTS`] objects).
    pub index: Vec<u8>,
    pub materials: Vec<Material>,
}

/// Objects a scene may hold (the object index is 8 bits per point).
pub const MAX_OBJECTS: usize = 256;

/// A point's opacity as blending uses it: 8 bits, as in an sRGBA file (α = a / 255).
#[inline]
pub fn alpha8(opacity: f32) -> u8 {
    (opacity.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// The scale that maps LiDAR intensities to [0, 1]: 1 / their 99th percentile (None when
/// that is 0).
pub fn intensity_scale(v: &[u16]) -> Option<f32> {
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
}

/// A cloud with what every frame needs computed once: the point spacing (for d̃), the
/// intensity scale, opacities, and (for scenes) objects and shadow textures.
pub struct PreparedCloud {
    pub cloud: PointCloud,
    /// Median nearest-neighbour distance, world units.
    pub spacing: f32,
    /// Maps intensity to [0, 1] (1 / the 99th percentile), when the cloud has intensity.
    pub intensity_scale: Option<f32>,
    /// Per-point opacity in 8 bits (None: every point is opaque).
    pub alpha: Option<Vec<u8>>,
    /// The mean opacity: what a pixel filled by the anisotropic fill (no point of its own)
    /// blends with.
    pub mean_alpha: f32,
    /// Objects and their materials (None: one object with the pipeline's material).
    pub objects: Option<ObjectTable>,
    /// Surface shape per point relative to the cloud's normals (quadric splats; see
    /// `stipple_core::normals::shapes`), from [`PreparedCloud::prepare_surface`]. None: flat
    /// splats. Valid only for the normals it was fitted to.
    pub shapes: Option<Vec<passes::splat::SplatShape>>,
    /// Deferred blending's splat groups, computed on first use (see
    /// [`PreparedCloud::groups`]), with the key and c they were made for.
    groups: std::sync::Mutex<Option<(u64, u32, std::sync::Arc<stipple_core::grouping::Grouping>)>>,
    /// The cloud's bounds, computed on first use for the key they were made for (a frame
    /// needs them; recomputing them read every point, 30 ms a frame at 100 M points).
    bounds: std::sync::Mutex<Option<(u64, stipple_core::Bounds)>>,
    /// The shadow texture in use (see [`PreparedCloud::set_lit`]).
    lit: Option<LitTexture>,
    /// Unique per preparation: the GPU backend re-uploads when it changes.
    pub key: u64,
    /// Changes whenever the shadow texture does (the GPU backend re-uploads it alone).
    pub lit_key: u64,
}

static NEXT_CLOUD_KEY: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

fn next_key() -> u64 {
    NEXT_CLOUD_KEY.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

impl PreparedCloud {
    pub fn new(cloud: PointCloud) -> PreparedCloud {
        let spacing = cloud.estimate_spacing();
        PreparedCloud::with_spacing(cloud, spacing)
    }

    /// Prepares a cloud whose point spacing is already known (a LOD cut knows it from its
    /// nodes; estimating it would cost a neighbour search per frame).
    pub fn with_spacing(cloud: PointCloud, spacing: f32) -> PreparedCloud {
        let intensity_scale = cloud.intensity.as_deref().and_then(intensity_scale);
        let alpha: Option<Vec<u8>> = cloud
            .opacity
            .as_ref()
            .map(|o| o.iter().map(|&a| alpha8(a)).collect());
        let mean_alpha = match &alpha {
            Some(a) if !a.is_empty() => {
                a.iter().map(|&x| x as f64).sum::<f64>() / (255.0 * a.len() as f64)
            }
            _ => 1.0,
        } as f32;
        PreparedCloud {
            cloud,
            spacing,
            intensity_scale,
            alpha,
            mean_alpha,
            objects: None,
            shapes: None,
            groups: Default::default(),
            bounds: Default::default(),
            lit: None,
            key: next_key(),
            lit_key: next_key(),
        }
    }

    /// Gives every point the same opacity.
    pub fn set_opacity(&mut self, opacity: f32) {
        let a = alpha8(opacity);
        self.alpha = Some(vec![a; self.cloud.len()]);
        self.mean_alpha = a as f32 / 255.0;
        self.key = next_key();
    }

    /// Gives the points objects with their own materials. Errors when the table does not
    /// match the cloud.
    pub fn with_objects(mut self, objects: ObjectTable) -> Result<PreparedCloud, RenderError> {
        if objects.index.len() != self.cloud.len() {
            return Err(ObjectError::Points {
                table: objects.index.len(),
                cloud: self.cloud.len(),
            }
            .into());
        }
        if objects.materials.is_empty() || objects.materials.len() > MAX_OBJECTS {
            return Err(ObjectError::Count(objects.materials.len()).into());
        }
        if let Some(&o) = objects
            .index
            .iter()
            .find(|&&o| o as usize >= objects.materials.len())
        {
            return Err(ObjectError::Material {
                object: o as u32,
                materials: objects.materials.len(),
            }
            .into());
        }
        self.objects = Some(objects);
        self.key = next_key();
        Ok(self)
    }

    /// Sets (or clears) the shadow texture shading uses. Errors when it does not match.
    pub fn set_lit(&mut self, lit: Option<LitTexture>) -> Result<(), RenderError> {
        if let Some(l) = &lit {
            if l.counts.len() != self.cloud.len() {
                return Err(shadow::ShadowError::Points {
                    texture: l.counts.len(),
                    cloud: self.cloud.len(),
                }
                .into());
            }
        }
        self.lit = lit;
        self.lit_key = next_key();
        Ok(())
    }

    pub fn lit(&self) -> Option<&LitTexture> {
        self.lit.as_ref()
    }

    /// The Phong terms by object.
    pub fn terms(&self, pipe: &Pipeline) -> Vec<passes::shade::cpu::Terms> {
        let t = |m: &Material| passes::shade::cpu::Terms {
            ambient: m.ambient,
            diffuse: m.diffuse,
            specular: m.specular,
            shininess: m.shininess,
        };
        match &self.objects {
            Some(o) => o.materials.iter().map(t).collect(),
            None => vec![t(&pipe.material)],
        }
    }

    /// The pipeline with its automatic settings resolved for this cloud and view.
    pub fn resolve(&self, pipe: &Pipeline, v: &ViewParams) -> Pipeline {
        let mut p = pipe.resolved(v, self.spacing, self.centre_depth(v));
        if let Some(s) = &mut p.splat {
            s.epsilon = Some(self.splat_epsilon(s));
            if s.mode == SplatMode::Deferred {
                s.depth_range = Some(self.depth_range(v));
            }
        }
        p
    }

    /// View depth of the centre of the cloud's bounds.
    fn centre_depth(&self, v: &ViewParams) -> f32 {
        let c = self.bounds().center();
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

    /// Splat radii, unscaled: the cloud's own (PLY `radius`, or from
    /// [`PreparedCloud::prepare_surface`]), else [`FALLBACK_RADIUS`] × the point spacing for
    /// every point.
    pub fn splat_radii(&self) -> std::borrow::Cow<'_, [f32]> {
        match &self.cloud.radius {
            Some(r) => std::borrow::Cow::Borrowed(r),
            None => std::borrow::Cow::Owned(vec![
                FALLBACK_RADIUS
                    * self.spacing.max(f32::MIN_POSITIVE);
                self.cloud.len()
            ]),
        }
    }

    /// The ε of the splat pass's ε-z test: the pipeline's own, else the median scaled radius.
    pub fn splat_epsilon(&self, s: &SplatSettings) -> f32 {
        s.epsilon.unwrap_or_else(|| {
            let r = self.splat_radii();
            let mut v: Vec<f32> = r.iter().step_by((r.len() / 4096).max(1)).copied().collect();
            let m = v.len() / 2;
            let median = if v.is_empty() {
                0.0
            } else {
                *v.select_nth_unstable_by(m, f32::total_cmp).1
            };
            passes::splat::epsilon(median * s.scale)
        })
    }

    /// Makes the cloud ready for lit and splat rendering: estimates normals where it has
    /// none (`estimate`), re-orients given normals whose signs are inconsistent, and
    /// computes splat radii where it has none (see `stipple_core::normals`). Does nothing
    /// that is already there; the GPU copy is refreshed on the next frame.
    pub fn prepare_surface(
        &mut self,
        k: usize,
        estimate: bool,
    ) -> Result<SurfaceReport, stipple_core::normals::NormalError> {
        self.prepare_surface_from(k, estimate, None)
    }

    /// [`PreparedCloud::prepare_surface`] with the sensor's position (world coordinates)
    /// when it is known: normals then face it (`stipple_core::normals::estimate_from`).
    pub fn prepare_surface_from(
        &mut self,
        k: usize,
        estimate: bool,
        viewpoint: Option<glam::DVec3>,
    ) -> Result<SurfaceReport, stipple_core::normals::NormalError> {
        let vp = viewpoint.map(|v| (v - self.cloud.origin).as_vec3());
        let c = &mut self.cloud;
        let need_normals = c.normals.is_none() && estimate;
        let mut report = SurfaceReport::default();
        if c.normals.is_none() && !need_normals && c.radius.is_some() {
            return Ok(report);
        }
        let t0 = std::time::Instant::now();
        let need_radii = c.radius.is_none();
        let e =
            stipple_core::normals::estimate_from(&c.positions, c.normals.as_deref(), k, 1.0, vp)?;
        if need_normals {
            c.normals = Some(e.normals);
            report.estimated = true;
        } else if c.normals.is_some() && e.flipped > 0 {
            c.normals = Some(e.normals);
            report.reoriented = e.flipped;
        }
        report.inconsistency = e.inconsistency;
        if need_radii {
            c.radius = Some(e.radii);
            report.radii = true;
        }
        if c.normals.is_some() {
            self.shapes = Some(e.shapes);
        }
        report.seconds = t0.elapsed().as_secs_f64();
        self.key = next_key();
        Ok(report)
    }
}

impl PreparedCloud {
    /// The splat groups of deferred blending for overlap relaxation `c` (Zhang & Pajarola
    /// §4.1; `stipple_core::grouping`), computed on first use and kept until the cloud or
    /// c changes. A cloud too small to group gets one group.
    pub fn groups(&self, c: f32) -> std::sync::Arc<stipple_core::grouping::Grouping> {
        let mut g = self.groups.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((k, cb, gr)) = g.as_ref() {
            if *k == self.key && *cb == c.to_bits() {
                return gr.clone();
            }
        }
        let radii = self.splat_radii();
        let normals = self.cloud.normals.as_deref();
        let gr = std::sync::Arc::new(
            stipple_core::grouping::grouping(&self.cloud.positions, normals, &radii, c)
                .unwrap_or_else(|_| stipple_core::grouping::Grouping {
                    group: vec![0; self.cloud.len()],
                    groups: 1,
                    max_degree: 0,
                    mean_degree: 0.0,
                    conflicts: 0,
                    c,
                }),
        );
        *g = Some((self.key, c.to_bits(), gr.clone()));
        gr
    }

    /// The cloud's bounds (local coordinates), cached per [`PreparedCloud::key`]: code that
    /// moves points must give the cloud a new key, as the GPU copy needs anyway.
    pub fn bounds(&self) -> stipple_core::Bounds {
        let mut b = self.bounds.lock().unwrap_or_else(|e| e.into_inner());
        match *b {
            Some((key, bounds)) if key == self.key => bounds,
            _ => {
                let bounds = self.cloud.bounds();
                *b = Some((self.key, bounds));
                bounds
            }
        }
    }

    /// The view-depth range [min, max] of the cloud's bounds (min at least the near plane).
    pub fn depth_range(&self, v: &ViewParams) -> (f32, f32) {
        let b = self.bounds();
        let (eye, fwd) = (glam::Vec3::from(v.eye), glam::Vec3::from(v.forward));
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for i in 0..8 {
            let c = glam::Vec3::new(
                if i & 1 == 0 { b.min.x } else { b.max.x },
                if i & 2 == 0 { b.min.y } else { b.max.y },
                if i & 4 == 0 { b.min.z } else { b.max.z },
            );
            let d = (c - eye).dot(fwd);
            lo = lo.min(d);
            hi = hi.max(d);
        }
        (lo.max(v.near), hi.max(lo.max(v.near)))
    }
}

/// Splat radius in point spacings for clouds without radii (about what
/// `stipple_core::normals` gives a regular sampling).
pub const FALLBACK_RADIUS: f32 = 2.0;

/// What [`PreparedCloud::prepare_surface`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceReport {
    /// Normals were estimated (the cloud had none).
    pub estimated: bool,
    /// Given normals turned round (their signs were inconsistent).
    pub reoriented: usize,
    /// The given normals' share of inconsistent neighbour pairs.
    pub inconsistency: f32,
    /// Splat radii were computed.
    pub radii: bool,
    pub seconds: f64,
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
    /// With depth peeling: how many layers held points, and (with
    /// [`Pipeline::keep_layers`]) each layer's own image, sRGB 8-bit RGBA, front first.
    pub layers: Vec<Vec<u8>>,
    pub layers_peeled: u32,
    /// Per-pixel unit normals where the frame blended them (splat blend mode); otherwise
    /// [`Frame::normal_image`] derives them from the points shown.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Host-side wall time of the frame outside the passes, in ms, by step (GPU backend:
    /// recording, waiting for the device, reading back; empty on the CPU backend, whose
    /// passes are all of its time). `stipple bench` prints them.
    pub host_ms: Vec<(&'static str, f64)>,
}

impl Frame {
    /// World-space unit normals of the visible surface, facing the eye, row 0 at the top,
    /// NaN on background: the blended normal where the frame has one, else the normal of the
    /// point the pixel shows, else (no normals, or a pixel a fill made) the normal of the
    /// depth image's surface from its neighbouring pixels.
    pub fn normal_image(&self, cloud: &PreparedCloud, camera: &Camera) -> Vec<[f32; 3]> {
        use glam::Vec3;
        let v = ViewParams::new(camera, cloud.cloud.origin);
        let (w, h) = (self.width as usize, self.height as usize);
        let (right, up, fwd) = (Vec3::from(v.right), Vec3::from(v.up), Vec3::from(v.forward));
        let view_to_world = |n: Vec3| right * n.x + up * n.y + fwd * n.z;
        let pos = |i: usize, j: usize| -> Option<Vec3> {
            let d = self.depth[j * w + i];
            d.is_finite()
                .then(|| v.view_position(i as u32, j as u32, d))
        };
        let nan = [f32::NAN; 3];
        let mut out = vec![nan; w * h];
        for j in 0..h {
            for i in 0..w {
                let k = j * w + i;
                if !self.depth[k].is_finite() {
                    continue;
                }
                let (_, dir) = v.pixel_ray(i as u32, j as u32);
                let face = |n: Vec3| {
                    let n = n.normalize_or_zero();
                    if n.dot(dir) > 0.0 {
                        -n
                    } else {
                        n
                    }
                };
                if let Some(b) = &self.normals {
                    let n = Vec3::from(b[k]);
                    if n != Vec3::ZERO {
                        out[k] = face(n).to_array();
                        continue;
                    }
                }
                let id = self.id[k];
                if let (true, Some(ns)) = (is_point(id), &cloud.cloud.normals) {
                    let n = ns[id as usize];
                    if n != Vec3::ZERO {
                        out[k] = face(n).to_array();
                        continue;
                    }
                }
                // From the depth image: the smaller one-sided difference on each axis.
                let Some(c) = pos(i, j) else { continue };
                let pick = |a: Option<Vec3>, b: Option<Vec3>| -> Option<Vec3> {
                    match (a.map(|a| c - a), b.map(|b| b - c)) {
                        (Some(x), Some(y)) => Some(if x.length_squared() < y.length_squared() {
                            x
                        } else {
                            y
                        }),
                        (x, y) => x.or(y),
                    }
                };
                let dx = pick(
                    (i > 0).then(|| pos(i - 1, j)).flatten(),
                    (i + 1 < w).then(|| pos(i + 1, j)).flatten(),
                );
                // Rows grow downwards; view y grows upwards.
                let dy = pick(
                    (j + 1 < h).then(|| pos(i, j + 1)).flatten(),
                    (j > 0).then(|| pos(i, j - 1)).flatten(),
                );
                if let (Some(dx), Some(dy)) = (dx, dy) {
                    let n = dx.cross(dy);
                    if n != Vec3::ZERO {
                        out[k] = face(view_to_world(n.normalize())).to_array();
                    }
                }
            }
        }
        out
    }
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
        pipe.validate()?;
        let t0 = std::time::Instant::now();
        let v = ViewParams::new(camera, cloud.cloud.origin);
        let pipe = &cloud.resolve(pipe, &v);
        match &mut self.inner {
            Inner::Cpu(r) => Ok(r.render(cloud, &v, pipe)),
            Inner::Gpu { renderer, uploaded } => {
                let up = upload(renderer, uploaded, cloud)?;
                if pipe.splat.is_some() {
                    let shapes = cloud
                        .shapes
                        .as_deref()
                        .filter(|s| s.len() == cloud.cloud.len());
                    renderer.set_splat_shapes(up, &cloud.splat_radii(), shapes)?;
                    if let Some(sp) = pipe.splat.filter(|s| s.mode == SplatMode::Deferred) {
                        renderer.set_splat_groups(up, &cloud.groups(sp.c))?;
                    }
                }
                let before = t0.elapsed().as_secs_f64() * 1e3;
                let mut f = renderer.render(up, &v, pipe)?;
                f.host_ms.insert(0, ("resolve + upload", before));
                Ok(f)
            }
        }
    }

    /// Computes a shadow texture (Dobrev §6, see [`shadow`]) for `lights`, or refines
    /// `start`: each light gets samples up to `min(its samples, max_samples)` (a point light
    /// takes 1, an area light its own count; headlights and directional lights take none).
    /// `progress(done, total)` is called after each sample.
    pub fn shadow_texture(
        &mut self,
        cloud: &PreparedCloud,
        lights: &[Light],
        settings: &shadow::ShadowSettings,
        start: Option<LitTexture>,
        max_samples: u32,
        progress: &mut dyn FnMut(u32, u32),
    ) -> Result<LitTexture, RenderError> {
        if cloud.cloud.is_empty() {
            return Err(RenderError::EmptyCloud);
        }
        lights::validate(lights)?;
        settings.validate()?;
        let mut lit = start.unwrap_or_else(|| LitTexture::new(cloud.cloud.len()));
        if lit.counts.len() != cloud.cloud.len() {
            return Err(shadow::ShadowError::Points {
                texture: lit.counts.len(),
                cloud: cloud.cloud.len(),
            }
            .into());
        }
        let gap = settings
            .layer_gap
            .unwrap_or_else(|| cloud.layer_gap(&Pipeline::default()));
        let bounds = cloud.bounds();
        let mut todo = Vec::new();
        for (l, light) in lights.iter().enumerate() {
            let target = shadow::light_samples(light).min(max_samples);
            for k in lit.samples[l]..target {
                todo.push((l, k));
            }
        }
        let total = todo.len() as u32;
        if total == 0 {
            return Ok(lit);
        }
        // On the GPU the counts stay on the device from the first sample to the last: one
        // upload before, one readback after.
        if let Inner::Gpu { renderer, uploaded } = &mut self.inner {
            let up = upload(renderer, uploaded, cloud)?;
            up.write_counts(renderer.context(), &lit.counts)?;
            // The GPU copy now holds counts the cloud does not: rewrite it next frame.
            up.lit_key = 0;
        }
        let centre = bounds.center().as_dvec3();
        for (done, &(l, k)) in todo.iter().enumerate() {
            let pos = shadow::sample_position(&lights[l], k).expect("lights with samples");
            let views =
                shadow::light_views(&bounds, cloud.cloud.origin, cloud.spacing, pos, settings);
            let params = |view: &shadow::LightView| {
                let v = &view.view;
                let z = (centre - glam::Vec3::from(v.eye).as_dvec3())
                    .dot(glam::Vec3::from(v.forward).as_dvec3())
                    .max(v.near as f64) as f32;
                passes::shadow_texture::cpu::MarkParams {
                    gap,
                    fill_gap: passes::shadow_texture::cpu::light_gap(v, gap, z),
                    slope_cap: settings.slope_cap,
                    face: view.face,
                    light: l as u32,
                }
            };
            match &mut self.inner {
                Inner::Cpu(r) => {
                    for view in &views {
                        let p = params(view);
                        let light_pipe = settings.light_pipeline(p.fill_gap);
                        r.light_view(cloud, &view.view, &light_pipe, &p, &mut lit.counts);
                    }
                }
                Inner::Gpu { renderer, uploaded } => {
                    let up = &uploaded.as_ref().expect("uploaded above").1;
                    let marks: Vec<_> = views.iter().map(|v| (v.view, params(v))).collect();
                    renderer.shadow_views(up, &marks, settings)?;
                }
            }
            lit.samples[l] = k + 1;
            progress(done as u32 + 1, total);
        }
        if let Inner::Gpu { renderer, uploaded } = &mut self.inner {
            let up = &uploaded.as_ref().expect("uploaded above").1;
            lit.counts = renderer.read_counts(up)?;
        }
        Ok(lit)
    }
}

/// The GPU copy of `cloud`, uploaded (or its shadow texture updated) when it changed.
fn upload<'a>(
    renderer: &gpu::GpuRenderer,
    uploaded: &'a mut Option<(u64, gpu::GpuCloud)>,
    cloud: &PreparedCloud,
) -> Result<&'a mut gpu::GpuCloud, RenderError> {
    if uploaded.as_ref().map(|u| u.0) != Some(cloud.key) {
        *uploaded = None;
        let up = gpu::GpuCloud::upload(renderer.context(), cloud)?;
        *uploaded = Some((cloud.key, up));
    }
    let up = &mut uploaded.as_mut().expect("uploaded").1;
    if up.lit_key != cloud.lit_key {
        up.set_lit(renderer.context(), cloud.lit(), cloud.lit_key)?;
    }
    Ok(up)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The cached bounds are the cloud's, and a new key (what moving points requires, for
    /// the GPU copy too) recomputes them.
    #[test]
    fn cached_bounds_follow_the_key() {
        let positions: Vec<glam::Vec3> = (0..1000)
            .map(|i| glam::Vec3::new(i as f32 * 0.01, (i % 7) as f32, -((i % 13) as f32)))
            .collect();
        let mut p = PreparedCloud::with_spacing(PointCloud::from_positions(positions), 0.01);
        let b = p.bounds();
        assert_eq!(b, p.cloud.bounds());
        p.cloud.positions[3] = glam::Vec3::splat(100.0);
        assert_eq!(p.bounds(), b, "same key: the cached bounds");
        p.key = next_key();
        let moved = p.bounds();
        assert_eq!(moved, p.cloud.bounds());
        assert_eq!(moved.max, glam::Vec3::splat(100.0));
    }
}
