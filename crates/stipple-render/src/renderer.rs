//! The long-lived renderer on one backend, and one-frame rendering.

use crate::*;
use stipple_core::Camera;

/// A long-lived renderer on one backend. The GPU one keeps the last cloud uploaded, so
/// repeated frames of the same cloud upload nothing.
pub struct Renderer {
    inner: Inner,
}

enum Inner {
    Cpu(Box<cpu::CpuRenderer>),
    Gpu {
        renderer: Box<gpu::GpuRenderer>,
        uploaded: Option<Box<(u64, gpu::GpuCloud)>>,
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

    /// The points of `cloud` seen by `camera`, back to front in slices of thickness `eps`
    /// (Gunjee §4.2, see [`passes::bucket_sort`]; `eps` ≤ 0: the smallest splat radius).
    pub fn bucket_sort(
        &mut self,
        cloud: &PreparedCloud,
        camera: &Camera,
        eps: f32,
    ) -> Result<passes::bucket_sort::cpu::Sorted, RenderError> {
        camera.validate()?;
        let v = ViewParams::new(camera, cloud.cloud.origin);
        let eps = if eps > 0.0 && eps.is_finite() {
            eps
        } else {
            cloud.least_splat_radius().min(f32::MAX)
        };
        match &mut self.inner {
            Inner::Cpu(_) => Ok(passes::bucket_sort::cpu::sort(
                &v,
                &cloud.cloud.positions,
                eps,
            )),
            Inner::Gpu { renderer, uploaded } => {
                let up = upload(renderer, uploaded, cloud)?;
                Ok(renderer.bucket_sort(up, &v, eps)?)
            }
        }
    }

    pub fn render(
        &mut self,
        cloud: &PreparedCloud,
        camera: &Camera,
        pipe: &Pipeline,
    ) -> Result<Frame, RenderError> {
        self.render_with(cloud, camera, pipe, true)
    }

    /// As [`Renderer::render`], except that on the GPU backend the images stay on the
    /// device: the frame's `rgba`, `depth` and `id` are empty and [`Renderer::image`] holds
    /// the colour (for a window to present without a copy). The CPU backend renders as
    /// `render` does.
    pub fn render_resident(
        &mut self,
        cloud: &PreparedCloud,
        camera: &Camera,
        pipe: &Pipeline,
    ) -> Result<Frame, RenderError> {
        self.render_with(cloud, camera, pipe, false)
    }

    /// The GPU backend's last frame colour on its device (see [`gpu::GpuRenderer::image`]).
    pub fn image(&self) -> Option<(&wgpu::Buffer, u32, u32)> {
        match &self.inner {
            Inner::Gpu { renderer, .. } => renderer.image(),
            Inner::Cpu(_) => None,
        }
    }

    /// The GPU backend's device (None on the CPU).
    pub fn gpu_context(&self) -> Option<&std::sync::Arc<gpu::GpuContext>> {
        match &self.inner {
            Inner::Gpu { renderer, .. } => Some(renderer.context()),
            Inner::Cpu(_) => None,
        }
    }

    fn render_with(
        &mut self,
        cloud: &PreparedCloud,
        camera: &Camera,
        pipe: &Pipeline,
        read: bool,
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
                    if let Some(sp) = pipe.splat.filter(|s| s.mode == SplatMode::Transparent) {
                        let cov = cloud.coverage(sp.c, sp.coverage);
                        renderer.set_splat_masks(up, (sp.c, sp.coverage), &cov)?;
                    }
                }
                let before = t0.elapsed().as_secs_f64() * 1e3;
                let mut f = if read {
                    renderer.render(up, &v, pipe)?
                } else {
                    renderer.render_resident(up, &v, pipe)?
                };
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
        let layers = crate::translucent::light_layers(cloud, settings);
        let coloured = layers > 1 && crate::translucent::coloured(cloud);
        if coloured && lit.rb.is_none() {
            // Samples taken grey so far (none, for a texture made here) count in every channel.
            lit.rb = Some(
                lit.counts
                    .iter()
                    .map(|c| [c[0], c[0], c[1], c[1], c[2], c[2], c[3], c[3]])
                    .collect(),
            );
        }
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
            up.write_rb(renderer.context(), lit.rb.as_deref())?;
            // The GPU copy now holds counts the cloud does not: rewrite it next frame.
            up.lit_key = 0;
        }
        for (done, &(l, k)) in todo.iter().enumerate() {
            let pos = shadow::sample_position(&lights[l], k).expect("lights with samples");
            let c = &cloud.cloud;
            let near = shadow::near_distance(&c.positions, c.origin, pos);
            let views = shadow::light_views(&bounds, c.origin, cloud.spacing, pos, near, settings);
            let params = |view: &shadow::LightView| {
                let v = &view.view;
                let z = far_depth(v, &bounds);
                passes::shadow_texture::cpu::MarkParams {
                    gap,
                    fill_gap: passes::shadow_texture::cpu::light_gap(v, gap, z),
                    slope_cap: settings.slope_cap,
                    face: view.face,
                    light: l as u32,
                    mode: Default::default(),
                    coloured,
                }
            };
            match &mut self.inner {
                Inner::Cpu(r) => {
                    for view in &views {
                        let p = params(view);
                        let light_pipe = settings.light_pipeline(p.fill_gap);
                        r.light_view(cloud, &view.view, &light_pipe, &p, layers, &mut lit);
                    }
                }
                Inner::Gpu { renderer, uploaded } => {
                    let up = &uploaded.as_ref().expect("uploaded above").1;
                    let marks: Vec<_> = views.iter().map(|v| (v.view, params(v))).collect();
                    renderer.shadow_views(up, &marks, settings, layers)?;
                }
            }
            lit.samples[l] = k + 1;
            progress(done as u32 + 1, total);
        }
        if let Inner::Gpu { renderer, uploaded } = &mut self.inner {
            let up = &uploaded.as_ref().expect("uploaded above").1;
            lit.counts = renderer.read_counts(up)?;
            if lit.rb.is_some() {
                lit.rb = renderer.read_rb(up)?;
            }
        }
        Ok(lit)
    }
}

/// The largest view depth of the cloud's bounds in a light view (at least its near plane):
/// the light image's fills use the light gap there, where a light pixel is widest.
fn far_depth(v: &crate::params::ViewParams, b: &stipple_core::Bounds) -> f32 {
    let (eye, fwd) = (glam::Vec3::from(v.eye), glam::Vec3::from(v.forward));
    let mut z = v.near;
    for k in 0..8 {
        let c = glam::Vec3::new(
            if k & 1 == 0 { b.min.x } else { b.max.x },
            if k & 2 == 0 { b.min.y } else { b.max.y },
            if k & 4 == 0 { b.min.z } else { b.max.z },
        );
        z = z.max((c - eye).dot(fwd));
    }
    z
}

/// The GPU copy of `cloud`, uploaded (or its shadow texture updated) when it changed.
fn upload<'a>(
    renderer: &gpu::GpuRenderer,
    uploaded: &'a mut Option<Box<(u64, gpu::GpuCloud)>>,
    cloud: &PreparedCloud,
) -> Result<&'a mut gpu::GpuCloud, RenderError> {
    if uploaded.as_ref().map(|u| u.0) != Some(cloud.key) {
        *uploaded = None;
        let up = gpu::GpuCloud::upload(renderer.context(), cloud)?;
        *uploaded = Some(Box::new((cloud.key, up)));
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
