//! The GPU frame: the pipeline description recorded as compute passes into one command
//! buffer (no CPU round trip between passes), with every pipeline, layout and buffer created
//! once and reused while the frame size stays the same.

use super::exec::{GpuExec, Shading};
use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, FrameBuffers, Shared, Targets};
use crate::device::record::*;
use crate::device::util::Arena;
use crate::gbuffer::GBuffer;
use crate::params::ViewParams;
use crate::passes::project::gpu_hw::ProjectHw;
use crate::passes::shade::gpu::ShadeBlock;
use crate::pipeline::{ColourPass, GeometryPass, Pipeline};
use crate::srgb::srgb_to_linear_table;
use crate::stats::{PassId, PassStat};
use crate::Frame;
use std::sync::Arc;
use std::time::Instant;
use wgpu::BufferUsages;

/// How `project` runs on the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ProjectionPath {
    /// The compute rasterizer (64-bit atomics, or the 32-bit two-pass fallback).
    #[default]
    Compute,
    /// The hardware PointList baseline.
    #[cfg_attr(feature = "clap", value(alias = "hw"))]
    Hardware,
}

/// What [`GpuRenderer::colour_pass`] returns: colour, surface depth and statistics.
pub type ColourPassResult = (Vec<[f32; 3]>, Vec<f32>, PassStat);

/// The long-lived GPU renderer.
pub struct GpuRenderer {
    ctx: Arc<GpuContext>,
    shared: Shared,
    arena: Arena,
    frame: Option<FrameBuffers>,
    /// The light images' buffers (shadow textures), kept apart from the camera's.
    shadow_frame: Option<FrameBuffers>,
    pub projection: ProjectionPath,
    /// The splat pass (owns its pipelines, scratch and radii).
    splat: crate::passes::splat::gpu::SplatGpu,
    /// Without timestamp queries, submit and wait after each pass to time it (benchmarks).
    pub sync_timing: bool,
}

impl GpuRenderer {
    pub fn new(ctx: Arc<GpuContext>) -> Result<GpuRenderer, GpuError> {
        let arena = Arena::new(&ctx.device, ctx.limits.min_uniform_buffer_offset_alignment);
        let shared = Shared::new(&ctx, &arena);
        let splat = crate::passes::splat::gpu::SplatGpu::new(&ctx);
        ctx.take_errors()?;
        Ok(GpuRenderer {
            ctx,
            shared,
            arena,
            frame: None,
            shadow_frame: None,
            projection: ProjectionPath::Compute,
            splat,
            sync_timing: false,
        })
    }

    /// Bind groups made over the current frame buffers so far (they are made when a step
    /// first needs them and reused by later frames of the same size).
    pub fn bind_groups_made(&self) -> usize {
        self.frame.as_ref().map_or(0, |f| f.groups_made())
    }

    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// Uploads an uploaded cloud's splat groups (deferred blending), unless they are there.
    pub fn set_splat_groups(
        &mut self,
        cloud: &GpuCloud,
        groups: &stipple_core::grouping::Grouping,
    ) -> Result<(), GpuError> {
        self.splat.set_groups(&self.ctx, cloud, groups)
    }

    /// Uploads an uploaded cloud's transparent-splat group masks, unless they are there.
    pub fn set_splat_masks(
        &mut self,
        cloud: &GpuCloud,
        c: (f32, crate::CoverageMethod),
        cov: &crate::Coverage,
    ) -> Result<(), GpuError> {
        self.splat.set_masks(&self.ctx, cloud, c, cov)
    }

    /// Uploads an uploaded cloud's splat radii (unscaled) and shapes (None: flat splats)
    /// for the splat pass, unless they are there already.
    pub fn set_splat_shapes(
        &mut self,
        cloud: &GpuCloud,
        radii: &[f32],
        shapes: Option<&[crate::passes::splat::SplatShape]>,
    ) -> Result<(), GpuError> {
        self.splat.set_shapes(&self.ctx, cloud, radii, shapes)
    }

    fn prepare(&mut self, v: &ViewParams) -> Result<(), GpuError> {
        let n = v.width as u64 * v.height as u64;
        let max = self.ctx.limits.max_storage_buffer_binding_size;
        if 16 * n > max || 16 * n > self.ctx.limits.max_buffer_size {
            return Err(GpuError::TooLarge(format!(
                "{}×{} pixels: per-pixel buffers of {} MiB exceed the device's binding limit of \
                 {} MiB",
                v.width,
                v.height,
                (16 * n) >> 20,
                max >> 20
            )));
        }
        grid_2d(&self.ctx, v.width, v.height)?;
        let f = match self.frame.take() {
            Some(f) if f.width == v.width && f.height == v.height => f,
            _ => FrameBuffers::new(&self.ctx, v.width, v.height),
        };
        let f = self.frame.insert(f);
        if self.projection == ProjectionPath::Hardware && f.targets.is_none() {
            self.ctx.adapter.hardware_projection.clone().map_err(|e| {
                GpuError::AdapterLacks(format!(
                    "--projection hardware ({e}); leave the flag out for the compute projection"
                ))
            })?;
            // Made now, so a device that cannot make it fails here and not mid-frame.
            self.shared.pass::<ProjectHw>(&self.ctx);
            f.targets = Some(Targets::new(&self.ctx, v.width, v.height));
        }
        self.ctx
            .queue
            .write_buffer(&self.shared.view, 0, bytemuck::bytes_of(v));
        self.arena.clear();
        Ok(())
    }
}

impl GpuRenderer {
    /// Renders one frame of an uploaded cloud: one layer, or with [`Pipeline::layers`] > 1
    /// the peeled layers blended front to back (all layers are recorded into one command
    /// buffer; a layer after an empty one is empty and blends nothing).
    pub fn render(
        &mut self,
        cloud: &GpuCloud,
        v: &ViewParams,
        pipe: &Pipeline,
    ) -> Result<Frame, GpuError> {
        self.render_with(cloud, v, pipe, true)
    }

    /// As [`GpuRenderer::render`], but the images stay on the device: the frame's `rgba`,
    /// `depth` and `id` are empty, and [`GpuRenderer::image`] holds the colour until the
    /// next frame (a window presents it from there without a copy to the host).
    pub fn render_resident(
        &mut self,
        cloud: &GpuCloud,
        v: &ViewParams,
        pipe: &Pipeline,
    ) -> Result<Frame, GpuError> {
        self.render_with(cloud, v, pipe, false)
    }

    /// The last frame's colour on the device (one `u32` per pixel, row 0 at the top, the
    /// bytes of the PNG's red, green, blue and alpha from the lowest byte up), its width and
    /// height; None before the first frame.
    pub fn image(&self) -> Option<(&wgpu::Buffer, u32, u32)> {
        self.frame.as_ref().map(|f| (&f.rgba, f.width, f.height))
    }

    fn render_with(
        &mut self,
        cloud: &GpuCloud,
        v: &ViewParams,
        pipe: &Pipeline,
        read: bool,
    ) -> Result<Frame, GpuError> {
        let t_start = Instant::now();
        self.prepare(v)?;
        let gap = crate::pipeline::layer_gap(pipe, cloud.spacing);
        let (shade_block, materials) = ShadeBlock::for_cloud(cloud, pipe);
        let layers = pipe.layers.max(1);
        // Peeling runs on the compute rasterizer (the hardware path has no reference test).
        let projection = if layers > 1 {
            ProjectionPath::Compute
        } else {
            self.projection
        };
        let mut f = self.frame.take().expect("prepared");
        f.use_cloud(cloud);
        let n = v.width as u64 * v.height as u64;
        if layers > 1 && pipe.keep_layers {
            let bytes = 4 * n * layers as u64;
            if f.layers_read.as_ref().map(|b| b.size()) != Some(bytes) {
                f.layers_read = Some(self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("layers readback"),
                    size: bytes,
                    usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }));
            }
        }
        // A splat frame's per-pixel normals (blended, or the Voronoi winner's at the hit) are
        // what its pixels were shaded with: read back with the frame, as the CPU keeps them
        // (`Frame::normals`, `--normal-out`).
        let want_normals =
            read && layers == 1 && pipe.splat.as_ref().is_some_and(|s| !s.mode.is_ordered());
        if want_normals && f.normals_read.as_ref().map(|b| b.size()) != Some(16 * n) {
            f.normals_read = Some(self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("normals readback"),
                size: 16 * n,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let result = (|| {
            let shared = &self.shared;
            let rec = recorder(&self.ctx, shared, &mut self.arena, self.sync_timing);
            let lut = srgb_to_linear_table();
            let shading = Shading {
                block: shade_block,
                materials: Some(materials),
                background: pipe.background.map(|c| lut[c as usize]),
                env: pipe.environment.clone(),
            };
            let mut x = GpuExec::new(
                rec,
                (&self.ctx, shared, &f),
                cloud,
                v,
                projection,
                Some(&mut self.splat),
                Some(shading),
            );
            crate::schedule::frame(&mut x, pipe, gap)?;
            let mut rec = x.rec;
            if let (true, Some(nr)) = (want_normals, &f.normals_read) {
                rec.enc
                    .copy_buffer_to_buffer(&f.attr_normal, 0, nr, 0, 16 * n);
            }
            let t_record = Instant::now();
            let sections = finish(rec, shared)?;
            let t_wait = Instant::now();
            let nu = n as usize;
            let (rgba, depth, id) = if read {
                read_back_with(&self.ctx, &f.read, 12 * n, |b| {
                    (
                        b[..4 * nu].to_vec(),
                        bytemuck::pod_collect_to_vec::<u8, f32>(&b[4 * nu..8 * nu]),
                        bytemuck::pod_collect_to_vec::<u8, u32>(&b[8 * nu..12 * nu]),
                    )
                })?
            } else {
                Default::default()
            };
            let normals = match (want_normals, &f.normals_read) {
                (true, Some(nr)) => Some(read_back_with(&self.ctx, nr, 16 * n, |b| {
                    bytemuck::pod_collect_to_vec::<u8, f32>(b)
                        .chunks_exact(4)
                        .map(|v| [v[0], v[1], v[2]])
                        .collect::<Vec<[f32; 3]>>()
                })?),
                _ => None,
            };
            let t_read = Instant::now();
            let stats = stats(&self.ctx, shared, &sections)?;
            let peeled = stats
                .iter()
                .filter(|s| s.pass == PassId::Project)
                .take_while(|s| s.count > 0)
                .count() as u32;
            let mut layer_images = Vec::new();
            if let (true, true, Some(lr)) = (layers > 1, pipe.keep_layers, &f.layers_read) {
                let all = read_back(&self.ctx, lr, 4 * n * layers as u64)?;
                layer_images = all
                    .chunks(4 * n as usize)
                    .take(peeled as usize)
                    .map(|c| c.to_vec())
                    .collect();
            }
            Ok(Frame {
                width: v.width,
                height: v.height,
                rgba,
                depth,
                id,
                stats,
                layers: layer_images,
                layers_peeled: if layers > 1 { peeled } else { 1 },
                normals,
                host_ms: {
                    let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
                    let t_end = Instant::now();
                    vec![
                        ("record", ms(t_start, t_record)),
                        ("submit + wait", ms(t_record, t_wait)),
                        ("read back", ms(t_wait, t_read)),
                        ("stats + copy", ms(t_read, t_end)),
                    ]
                },
            })
        })();
        self.frame = Some(f);
        result
    }

    /// Adds one shadow sample's marks to an uploaded cloud's shadow counts on the device
    /// (which must exist, see [`GpuCloud::write_counts`]): per light view, project and the
    /// light pipeline's fills, then `shadow_texture` over every chunk. Nothing is read back
    /// ([`GpuRenderer::read_counts`] does).
    pub fn shadow_views(
        &mut self,
        cloud: &GpuCloud,
        marks: &[(ViewParams, crate::passes::shadow_texture::cpu::MarkParams)],
        settings: &crate::shadow::ShadowSettings,
        layers: u32,
    ) -> Result<(), GpuError> {
        if cloud.chunks.iter().any(|c| c.lit.is_none()) {
            return Err(GpuError::Wgpu(
                "shadow_texture: the cloud has no shadow counts uploaded".into(),
            ));
        }
        std::mem::swap(&mut self.frame, &mut self.shadow_frame);
        let r = (|| {
            for (v, mp) in marks {
                self.prepare(v)?;
                let mut f = self.frame.take().expect("prepared");
                f.use_cloud(cloud);
                let r = (|| {
                    let shared = &self.shared;
                    let rec = recorder(&self.ctx, shared, &mut self.arena, self.sync_timing);
                    let projection = ProjectionPath::Compute;
                    let frame = (&*self.ctx, shared, &f);
                    let mut x = GpuExec::new(rec, frame, cloud, v, projection, None, None);
                    let light_pipe = settings.light_pipeline(mp.fill_gap);
                    crate::schedule::light_view(&mut x, &light_pipe, mp, layers)?;
                    finish(x.rec, shared)?;
                    Ok(())
                })();
                self.frame = Some(f);
                r?;
            }
            Ok(())
        })();
        std::mem::swap(&mut self.frame, &mut self.shadow_frame);
        r
    }

    /// Reads an uploaded cloud's shadow sums back.
    pub fn read_counts(&self, cloud: &GpuCloud) -> Result<Vec<[u16; 4]>, GpuError> {
        let mut counts = Vec::with_capacity(cloud.len);
        for c in &cloud.chunks {
            let lit = c.lit.as_ref().ok_or_else(|| {
                GpuError::Wgpu("read_counts: the cloud has no shadow counts uploaded".into())
            })?;
            let raw = copy_out(&self.ctx, lit, 8 * c.count as u64)?;
            counts
                .extend(raw.chunks_exact(8).map(|w| {
                    std::array::from_fn(|l| u16::from_le_bytes([w[2 * l], w[2 * l + 1]]))
                }));
        }
        Ok(counts)
    }

    /// Reads a coloured shadow texture's red and blue sums back (None for a grey one).
    pub fn read_rb(&self, cloud: &GpuCloud) -> Result<Option<Vec<[u16; 8]>>, GpuError> {
        if cloud.chunks.iter().any(|c| c.lit_rb.is_none()) {
            return Ok(None);
        }
        let mut rb = Vec::with_capacity(cloud.len);
        for c in &cloud.chunks {
            let b = c.lit_rb.as_ref().expect("checked above");
            let raw = copy_out(&self.ctx, b, 16 * c.count as u64)?;
            rb.extend(
                raw.chunks_exact(16)
                    .map(|w| std::array::from_fn(|k| u16::from_le_bytes([w[2 * k], w[2 * k + 1]]))),
            );
        }
        Ok(Some(rb))
    }

    /// The points of an uploaded cloud seen in `v`, back to front in slices of thickness
    /// `eps` (see `passes::bucket_sort`).
    pub fn bucket_sort(
        &self,
        cloud: &GpuCloud,
        v: &ViewParams,
        eps: f32,
    ) -> Result<crate::passes::bucket_sort::cpu::Sorted, GpuError> {
        crate::passes::bucket_sort::gpu::sort(&self.ctx, &self.shared, cloud, v, eps)
    }

    /// Runs project (and resolve) only: the G-buffer of the nearest points, and points kept.
    pub fn project(
        &mut self,
        cloud: &GpuCloud,
        v: &ViewParams,
        cull: bool,
    ) -> Result<(GBuffer, u64), GpuError> {
        self.prepare(v)?;
        let mut f = self.frame.take().expect("prepared");
        f.use_cloud(cloud);
        let r = (|| {
            let shared = &self.shared;
            let mut rec = recorder(&self.ctx, shared, &mut self.arena, self.sync_timing);
            let b = Binder::new(&self.ctx, shared, &f);
            match (self.projection, &f.targets) {
                (ProjectionPath::Hardware, Some(t)) => {
                    crate::passes::project::gpu_hw::record(&mut rec, b, t, cloud, cull)?
                }
                _ => crate::passes::project::gpu::record(&mut rec, b, cloud, cull, None)?,
            }
            let sections = finish(rec, shared)?;
            let stats = stats(&self.ctx, shared, &sections)?;
            let g = read_g(&self.ctx, &f, 0)?;
            Ok((g, stats[0].count))
        })();
        self.frame = Some(f);
        r
    }

    /// Runs one geometry pass on a G-buffer: the result and the changed-pixel statistics.
    pub fn geometry_pass(
        &mut self,
        v: &ViewParams,
        g: &GBuffer,
        pass: &GeometryPass,
        default_gap: f32,
    ) -> Result<(GBuffer, PassStat), GpuError> {
        self.prepare(v)?;
        let f = self.frame.take().expect("prepared");
        let r = (|| {
            let shared = &self.shared;
            let q = &self.ctx.queue;
            q.write_buffer(&f.depth[0], 0, bytemuck::cast_slice(&g.depth));
            q.write_buffer(&f.id[0], 0, bytemuck::cast_slice(&g.id));
            let mut rec = recorder(&self.ctx, shared, &mut self.arena, self.sync_timing);
            let mut cur = Cursor::default();
            let b = Binder::new(&self.ctx, shared, &f);
            pass.kernel()
                .record(&mut rec, b, &mut cur, default_gap, None)?;
            let sections = finish(rec, shared)?;
            let stats = stats(&self.ctx, shared, &sections)?;
            Ok((read_g(&self.ctx, &f, cur.g)?, stats[0].clone()))
        })();
        self.frame = Some(f);
        r
    }

    /// Runs shade (gather + shade) on a G-buffer: linear colour and surface depth per pixel.
    pub fn shade(
        &mut self,
        cloud: &GpuCloud,
        v: &ViewParams,
        g: &GBuffer,
        pipe: &Pipeline,
    ) -> Result<(Vec<[f32; 3]>, Vec<f32>), GpuError> {
        self.prepare(v)?;
        let (block, materials) = ShadeBlock::for_cloud(cloud, pipe);
        let mut f = self.frame.take().expect("prepared");
        f.use_cloud(cloud);
        let r = (|| {
            let shared = &self.shared;
            let q = &self.ctx.queue;
            q.write_buffer(&f.depth[0], 0, bytemuck::cast_slice(&g.depth));
            q.write_buffer(&f.id[0], 0, bytemuck::cast_slice(&g.id));
            let mut rec = recorder(&self.ctx, shared, &mut self.arena, self.sync_timing);
            let b = Binder::new(&self.ctx, shared, &f);
            let cur = Cursor::default();
            let shading = (block, Some(&*materials));
            crate::passes::shade::gpu::record(&mut rec, b, &cur, cloud, shading, None)?;
            finish(rec, shared)?;
            let colour = read_colour(&self.ctx, &f.colour[0], v.pixels())?;
            let depth = read_f32(&self.ctx, &f.surface, v.pixels())?;
            Ok((colour, depth))
        })();
        self.frame = Some(f);
        r
    }

    /// Runs one colour pass: `id` (for smooth and fill_anisotropic) and `depth` (surface
    /// depth) with a linear colour image; returns the new colour, the surface depth after the
    /// pass (fill_anisotropic changes it) and the pass statistics.
    pub fn colour_pass(
        &mut self,
        v: &ViewParams,
        id: &[u32],
        depth: &[f32],
        colour: &[[f32; 3]],
        pass: &ColourPass,
    ) -> Result<ColourPassResult, GpuError> {
        self.prepare(v)?;
        let f = self.frame.take().expect("prepared");
        let r = (|| {
            let shared = &self.shared;
            let q = &self.ctx.queue;
            q.write_buffer(&f.id[0], 0, bytemuck::cast_slice(id));
            q.write_buffer(&f.surface, 0, bytemuck::cast_slice(depth));
            let c4: Vec<[f32; 4]> = colour.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
            q.write_buffer(&f.colour[0], 0, bytemuck::cast_slice(&c4));
            let mut rec = recorder(&self.ctx, shared, &mut self.arena, self.sync_timing);
            let mut cur = Cursor::default();
            let b = Binder::new(&self.ctx, shared, &f);
            pass.kernel().record(&mut rec, b, &mut cur, v)?;
            let sections = finish(rec, shared)?;
            let stats = stats(&self.ctx, shared, &sections)?;
            Ok((
                read_colour(&self.ctx, &f.colour[cur.colour], v.pixels())?,
                read_f32(&self.ctx, &f.surface, v.pixels())?,
                stats[0].clone(),
            ))
        })();
        self.frame = Some(f);
        r
    }
}
