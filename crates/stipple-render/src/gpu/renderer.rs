//! The GPU frame: the pipeline description recorded as compute passes into one command
//! buffer (no CPU round trip between passes), with every pipeline, layout and buffer created
//! once and reused while the frame size stays the same.

use super::exec::{GpuExec, Shading};
use super::record::*;
use super::resources::*;
use super::steps::*;
use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError};
use crate::device::iterate::IterateBlock;
use crate::device::util::{self, Arena, Res};
use crate::gbuffer::GBuffer;
use crate::params::ViewParams;
use crate::passes::blend_layers::gpu::BlendLayers;
use crate::passes::depiction::gpu::Depiction;
use crate::passes::fill::gpu::window_cells;
use crate::passes::project::gpu::{ChunkBlock, Project};
use crate::passes::project::gpu_hw::{ProjectHw, Targets};
use crate::passes::shade::cpu::{srgb_to_linear_table, SrgbEncoder};
use crate::passes::shade::gpu::{Shade, ShadeBlock};
use crate::pipeline::{ColourPass, GeometryPass, Pipeline};
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
    kit: Kit,
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
        let d = &ctx.device;
        let (cells, cell_ranges) = window_cells();
        let table: Vec<u32> = SrgbEncoder::new()
            .table()
            .iter()
            .map(|&b| b as u32)
            .collect();
        let timer = ctx.timestamps.then(|| Timer {
            set: d.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: QUERIES,
            }),
            resolve: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: QUERIES as u64 * 8,
                usage: BufferUsages::QUERY_RESOLVE | BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            read: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps read"),
                size: QUERIES as u64 * 8,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            period_ns: ctx.queue.get_timestamp_period() as f64,
        });
        let arena = Arena::new(d, ctx.limits.min_uniform_buffer_offset_alignment);
        let view = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("view"),
            size: std::mem::size_of::<ViewParams>() as u64,
            usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let counters = util::storage(d, "counters", SLOTS * 4);
        let indirect = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("indirect"),
            size: SLOTS * 12,
            usage: BufferUsages::STORAGE | BufferUsages::INDIRECT,
            mapped_at_creation: false,
        });
        let iterate = crate::device::iterate::new(&ctx);
        let (vis_table, vis_ranges) = crate::passes::visibility::gpu::offset_table();
        let kit = Kit {
            arena: arena.buffer.clone(),
            cells: util::storage_init(d, "window cells", bytemuck::cast_slice(&cells)),
            cell_ranges,
            to_linear: util::storage_init(
                d,
                "srgb to linear",
                bytemuck::cast_slice(&srgb_to_linear_table()),
            ),
            encode_table: util::storage_init(d, "srgb encode", bytemuck::cast_slice(&table)),
            counters_read: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("counters read"),
                size: SLOTS * 4,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            timer,
            project: Project::new(&ctx),
            fill_background: crate::passes::fill_background::gpu::new(&ctx),
            fill_occluded: crate::passes::fill_occluded::gpu::new(&ctx),
            iterate_group: iterate.bind(
                d,
                &[
                    Res::Arena(&arena.buffer, block::<IterateBlock>()),
                    Res::Buf(&counters),
                    Res::Buf(&indirect),
                ],
            ),
            iterate,
            project_hw: None,
            counters,
            indirect,
            view,
            shade: Shade::new(&ctx),
            smooth: crate::passes::smooth::gpu::new(&ctx),
            antialias: crate::passes::antialias::gpu::new(&ctx),
            output: crate::passes::output::gpu::new(&ctx),
            visibility: crate::passes::visibility::gpu::new(&ctx),
            vis_offsets: util::storage_init(
                d,
                "visibility offsets",
                bytemuck::cast_slice(&vis_table),
            ),
            vis_ranges,
            fill_anisotropic: crate::passes::fill_anisotropic::gpu::new(&ctx),
            depiction: Depiction::new(&ctx),
            edl: crate::passes::edl::gpu::new(&ctx),
            materials: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("materials"),
                size: std::mem::size_of::<crate::passes::shade::gpu::MaterialTable>() as u64,
                usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            blend: BlendLayers::new(&ctx),
            mark: crate::passes::shadow_texture::gpu::new(&ctx),
            peel_reference: crate::passes::project::gpu::peel_reference(&ctx),
            pixel: Default::default(),
        };
        let splat = crate::passes::splat::gpu::SplatGpu::new(&ctx);
        ctx.take_errors()?;
        Ok(GpuRenderer {
            ctx,
            kit,
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
        self.frame.as_ref().map_or(0, |f| f.binds.len())
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
        if self.projection == ProjectionPath::Hardware && self.kit.project_hw.is_none() {
            self.ctx.adapter.hardware_projection.clone().map_err(|e| {
                GpuError::AdapterLacks(format!(
                    "--projection hardware ({e}); leave the flag out for the compute projection"
                ))
            })?;
            let hw = ProjectHw::new(&self.ctx);
            let group = util::bind(
                &self.ctx.device,
                "project_hw",
                &hw.bgl,
                &[
                    Res::Buf(&self.kit.view),
                    Res::Arena(&self.arena.buffer, block::<ChunkBlock>()),
                ],
            );
            self.kit.project_hw = Some((hw, group));
        }
        if self.projection == ProjectionPath::Hardware && f.targets.is_none() {
            let t = Targets::new(&self.ctx, v.width, v.height);
            let hw = &self.kit.project_hw.as_ref().expect("made above").0;
            let copy = util::bind(
                &self.ctx.device,
                "project_hw copy",
                &hw.copy_bgl,
                &[
                    Res::Buf(&self.kit.view),
                    Res::Skip,
                    Res::View(&t.id),
                    Res::View(&t.depth),
                    Res::Buf(&f.depth[0]),
                    Res::Buf(&f.id[0]),
                ],
            );
            f.targets = Some((t, copy));
        }
        self.ctx
            .queue
            .write_buffer(&self.kit.view, 0, bytemuck::bytes_of(v));
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
        let t_start = Instant::now();
        self.prepare(v)?;
        let gap = crate::pipeline::layer_gap(pipe, cloud.spacing);
        let (shade_block, materials) = ShadeBlock::for_cloud(cloud, pipe);
        self.ctx
            .queue
            .write_buffer(&self.kit.materials, 0, bytemuck::cast_slice(&materials[..]));
        let layers = pipe.layers.max(1);
        // Peeling runs on the compute rasterizer (the hardware path has no reference test).
        let projection = if layers > 1 {
            ProjectionPath::Compute
        } else {
            self.projection
        };
        let mut f = self.frame.take().expect("prepared");
        ensure_cloud(&self.ctx, &self.kit, &self.arena.buffer, &mut f, cloud);
        ensure_pixel_passes(&self.ctx, &mut self.kit, &pipe.colour);
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
        let result = (|| {
            let kit = &self.kit;
            let rec = recorder(&self.ctx, kit, &mut self.arena, self.sync_timing);
            let lut = srgb_to_linear_table();
            let shading = Shading {
                block: shade_block,
                background: pipe.background.map(|c| lut[c as usize]),
                mean_alpha: cloud.mean_alpha,
            };
            let mut x = GpuExec::new(
                rec,
                kit,
                &f,
                cloud,
                v,
                projection,
                Some(&mut self.splat),
                Some(shading),
            );
            crate::schedule::frame(&mut x, pipe, gap)?;
            let rec = x.rec;
            let t_record = Instant::now();
            let sections = finish(rec, kit)?;
            let t_wait = Instant::now();
            let nu = n as usize;
            let (rgba, depth, id) = read_back_with(&self.ctx, &f.read, 12 * n, |b| {
                (
                    b[..4 * nu].to_vec(),
                    bytemuck::pod_collect_to_vec::<u8, f32>(&b[4 * nu..8 * nu]),
                    bytemuck::pod_collect_to_vec::<u8, u32>(&b[8 * nu..12 * nu]),
                )
            })?;
            let t_read = Instant::now();
            let stats = stats(&self.ctx, kit, &sections)?;
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
                normals: None,
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
                ensure_cloud(&self.ctx, &self.kit, &self.arena.buffer, &mut f, cloud);
                let r = (|| {
                    let kit = &self.kit;
                    let rec = recorder(&self.ctx, kit, &mut self.arena, self.sync_timing);
                    let projection = ProjectionPath::Compute;
                    let mut x = GpuExec::new(rec, kit, &f, cloud, v, projection, None, None);
                    let light_pipe = settings.light_pipeline(mp.fill_gap);
                    crate::schedule::light_view(&mut x, &light_pipe, mp)?;
                    finish(x.rec, kit)?;
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

    /// Reads an uploaded cloud's shadow counts back.
    pub fn read_counts(&self, cloud: &GpuCloud) -> Result<Vec<u32>, GpuError> {
        let mut counts = Vec::with_capacity(cloud.len);
        for c in &cloud.chunks {
            let lit = c.lit.as_ref().ok_or_else(|| {
                GpuError::Wgpu("read_counts: the cloud has no shadow counts uploaded".into())
            })?;
            let raw = copy_out(&self.ctx, lit, 4 * c.count as u64)?;
            counts.extend_from_slice(bytemuck::cast_slice::<u8, u32>(&raw));
        }
        Ok(counts)
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
        ensure_cloud(&self.ctx, &self.kit, &self.arena.buffer, &mut f, cloud);
        let r = (|| {
            let kit = &self.kit;
            let projection = self.projection;
            let mut rec = recorder(&self.ctx, kit, &mut self.arena, self.sync_timing);
            match (projection, &f.targets) {
                (ProjectionPath::Hardware, Some((t, copy))) => {
                    record_project_hw(&mut rec, kit, &f, t, copy, cloud, cull)?
                }
                _ => record_project(&mut rec, kit, &f, cloud, cull, None)?,
            }
            let sections = finish(rec, kit)?;
            let stats = stats(&self.ctx, kit, &sections)?;
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
            let kit = &self.kit;
            self.ctx
                .queue
                .write_buffer(&f.depth[0], 0, bytemuck::cast_slice(&g.depth));
            self.ctx
                .queue
                .write_buffer(&f.id[0], 0, bytemuck::cast_slice(&g.id));
            let mut rec = recorder(&self.ctx, kit, &mut self.arena, self.sync_timing);
            let mut cur = Cursor::default();
            record_geometry(&mut rec, kit, &f, &mut cur, pass, default_gap)?;
            let sections = finish(rec, kit)?;
            let stats = stats(&self.ctx, kit, &sections)?;
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
        self.ctx
            .queue
            .write_buffer(&self.kit.materials, 0, bytemuck::cast_slice(&materials[..]));
        let mut f = self.frame.take().expect("prepared");
        ensure_cloud(&self.ctx, &self.kit, &self.arena.buffer, &mut f, cloud);
        let r = (|| {
            let kit = &self.kit;
            let q = &self.ctx.queue;
            q.write_buffer(&f.depth[0], 0, bytemuck::cast_slice(&g.depth));
            q.write_buffer(&f.id[0], 0, bytemuck::cast_slice(&g.id));
            let mut rec = recorder(&self.ctx, kit, &mut self.arena, self.sync_timing);
            record_shade(&mut rec, kit, &f, &Cursor::default(), cloud, block, None)?;
            finish(rec, kit)?;
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
        ensure_pixel_passes(&self.ctx, &mut self.kit, std::slice::from_ref(pass));
        let r = (|| {
            let kit = &self.kit;
            let q = &self.ctx.queue;
            q.write_buffer(&f.id[0], 0, bytemuck::cast_slice(id));
            q.write_buffer(&f.surface, 0, bytemuck::cast_slice(depth));
            let c4: Vec<[f32; 4]> = colour.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
            q.write_buffer(&f.colour[0], 0, bytemuck::cast_slice(&c4));
            let mut rec = recorder(&self.ctx, kit, &mut self.arena, self.sync_timing);
            let mut cur = Cursor::default();
            record_colour(&mut rec, kit, &f, &mut cur, pass, v)?;
            let sections = finish(rec, kit)?;
            let stats = stats(&self.ctx, kit, &sections)?;
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
