//! The GPU frame: the pipeline description recorded as compute passes into one command
//! buffer (no CPU round trip between passes), with every pipeline, layout and buffer created
//! once and reused while the frame size stays the same.

use super::antialias::AntialiasBlock;
use super::blend_layers::{BlendBlock, BlendLayers};
use super::cloud::GpuCloud;
use super::context::{GpuContext, GpuError};
use super::depiction::{Depiction, DepictionBlock};
use super::edl::EdlBlock;
use super::fill::{window_cells, FillBlock};
use super::fill_anisotropic::FillAnisotropicBlock;
use super::iterate::IterateBlock;
use super::project::{ChunkBlock, Project, ResolveBlock, POINTS_PER_GROUP};
use super::project_hw::{ProjectHw, Targets};
use super::shade::{GatherBlock, Shade, ShadeBlock};
use super::shadow_texture::MarkBlock;
use super::smooth::SmoothBlock;
use super::util::{self, Arena, Pass, Res};
use super::visibility::VisibilityBlock;
use crate::cpu::shade::{srgb_to_linear_table, SrgbEncoder};
use crate::gbuffer::{GBuffer, PassStat};
use crate::params::ViewParams;
use crate::pipeline::{ColourPass, GeometryPass, Iterations, Pipeline};
use crate::Frame;
use std::mem::size_of;
use std::sync::Arc;
use std::time::Instant;
use wgpu::{Buffer, BufferUsages, CommandEncoder};

/// How `project` runs on the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ProjectionPath {
    /// The compute rasterizer (64-bit atomics, or the 32-bit two-pass fallback).
    #[default]
    Compute,
    /// The hardware PointList baseline.
    Hardware,
}

/// Counter slots per frame (points kept, changed pixels per iteration, blended pixels).
const SLOTS: u64 = 4096;
/// Timestamp queries per frame (two per section).
const QUERIES: u32 = 256;

struct Timer {
    set: wgpu::QuerySet,
    resolve: Buffer,
    read: Buffer,
    period_ns: f64,
}

struct Kit {
    view: Buffer,
    cells: Buffer,
    cell_ranges: Vec<(u32, u32)>,
    to_linear: Buffer,
    encode_table: Buffer,
    counters: Buffer,
    counters_read: Buffer,
    indirect: Buffer,
    timer: Option<Timer>,
    project: Project,
    /// The hardware projection's pipelines and bind group, made when first used (their
    /// targets are not renderable everywhere, e.g. R32Float on GL).
    project_hw: Option<(ProjectHw, wgpu::BindGroup)>,
    fill_background: Pass,
    fill_occluded: Pass,
    iterate: Pass,
    /// The bind groups that depend on nothing but the set-up.
    iterate_group: wgpu::BindGroup,
    shade: Shade,
    smooth: Pass,
    antialias: Pass,
    output: Pass,
    visibility: Pass,
    vis_offsets: Buffer,
    vis_ranges: Vec<(u32, u32)>,
    fill_anisotropic: Pass,
    depiction: Depiction,
    edl: Pass,
    /// Material terms by object (uniform array, written per frame).
    materials: Buffer,
    blend: BlendLayers,
    mark: Pass,
}

struct FrameBuffers {
    width: u32,
    height: u32,
    vis: Buffer,
    vis_id: Buffer,
    depth: [Buffer; 2],
    id: [Buffer; 2],
    attr_pos: Buffer,
    attr_normal: Buffer,
    /// (object | opacity << 8, shadow counts) of each pixel's point.
    attr_style: Buffer,
    /// Depth peeling: the previous layer's surface depth, and the blend accumulator.
    peel_ref: Buffer,
    acc: Buffer,
    /// Each layer's image when the pipeline keeps them (made on demand).
    layers_read: Option<Buffer>,
    colour: [Buffer; 2],
    surface: Buffer,
    /// The anisotropic fill's second depth image; the depiction's level images and term.
    surface_b: Buffer,
    levels: [Buffer; 2],
    shading: Buffer,
    rgba: Buffer,
    read: Buffer,
    /// The hardware path's render targets and the group that copies them out.
    targets: Option<(Targets, wgpu::BindGroup)>,
    /// Made with the buffers (see [`FrameGroups`]).
    groups: Option<FrameGroups>,
    /// The per-chunk groups of the last cloud rendered at this size.
    cloud: Option<CloudGroups>,
}

impl FrameBuffers {
    fn new(ctx: &GpuContext, w: u32, h: u32) -> FrameBuffers {
        let d = &ctx.device;
        let n = w as u64 * h as u64;
        let s = |label, bytes| util::storage(d, label, bytes);
        FrameBuffers {
            width: w,
            height: h,
            vis: s("visibility", 8 * n),
            vis_id: s("visibility ids", 4 * n),
            depth: [s("depth a", 4 * n), s("depth b", 4 * n)],
            id: [s("id a", 4 * n), s("id b", 4 * n)],
            attr_pos: s("pixel positions", 16 * n),
            attr_normal: s("pixel normals", 16 * n),
            attr_style: s("pixel styles", 8 * n),
            peel_ref: s("peel reference", 4 * n),
            acc: s("blend accumulator", 16 * n),
            layers_read: None,
            colour: [s("colour a", 16 * n), s("colour b", 16 * n)],
            surface: s("surface depth", 4 * n),
            surface_b: s("surface depth b", 4 * n),
            levels: [s("depiction level a", 4 * n), s("depiction level b", 4 * n)],
            shading: s("depiction term", 4 * n),
            rgba: s("rgba", 4 * n),
            read: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback"),
                size: 12 * n,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            targets: None,
            groups: None,
            cloud: None,
        }
    }

    fn groups(&self) -> &FrameGroups {
        self.groups.as_ref().expect("made with the buffers")
    }

    fn cloud_groups(&self) -> &CloudGroups {
        self.cloud.as_ref().expect("made before recording")
    }
}

/// Size of a uniform block as bound from the arena.
fn block<T>() -> u64 {
    size_of::<T>() as u64
}

/// Bind groups over the frame buffers, made once per frame size. Arrays are indexed by which
/// ping-pong image is the source (`g`: geometry, `c`: colour).
struct FrameGroups {
    resolve: wgpu::BindGroup,
    fill_background: [wgpu::BindGroup; 2],
    fill_occluded: [wgpu::BindGroup; 2],
    shade: [wgpu::BindGroup; 2],
    smooth: [[wgpu::BindGroup; 2]; 2],
    antialias: [wgpu::BindGroup; 2],
    output: [wgpu::BindGroup; 2],
    visibility: [wgpu::BindGroup; 2],
    /// By geometry image, colour image and depth image (0: surface, 1: surface_b).
    fill_anisotropic: [[[wgpu::BindGroup; 2]; 2]; 2],
    /// By source level image.
    depiction_level: [wgpu::BindGroup; 2],
    depiction_apply: [wgpu::BindGroup; 2],
    edl: [wgpu::BindGroup; 2],
    /// By geometry image and colour image (compose writes colour 0 through `[g][0]`).
    blend: [[wgpu::BindGroup; 2]; 2],
}

impl FrameGroups {
    fn new(ctx: &GpuContext, kit: &Kit, arena: &Buffer, f: &FrameBuffers) -> FrameGroups {
        let d = &ctx.device;
        let fill = |pass: &Pass, src: usize| {
            pass.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<FillBlock>()),
                    Res::Buf(&kit.cells),
                    Res::Buf(&f.depth[src]),
                    Res::Buf(&f.id[src]),
                    Res::Buf(&f.depth[1 - src]),
                    Res::Buf(&f.id[1 - src]),
                    Res::Buf(&kit.counters),
                ],
            )
        };
        let shade = |g: usize| {
            kit.shade.shade.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<ShadeBlock>()),
                    Res::Buf(&f.depth[g]),
                    Res::Buf(&f.id[g]),
                    Res::Buf(&f.attr_pos),
                    Res::Buf(&f.attr_normal),
                    Res::Buf(&kit.to_linear),
                    Res::Buf(&f.colour[0]),
                    Res::Buf(&f.surface),
                    Res::Buf(&f.attr_style),
                    Res::Buf(&kit.materials),
                ],
            )
        };
        let blend = |g: usize, c: usize| {
            util::bind(
                d,
                "blend_layers",
                &kit.blend.bgl,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<BlendBlock>()),
                    Res::Buf(&f.id[g]),
                    Res::Buf(&f.surface),
                    Res::Buf(&f.attr_style),
                    Res::Buf(&f.colour[c]),
                    Res::Buf(&f.acc),
                    Res::Buf(&kit.counters),
                ],
            )
        };
        let smooth = |g: usize, c: usize| {
            kit.smooth.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<SmoothBlock>()),
                    Res::Buf(&f.id[g]),
                    Res::Buf(&f.colour[c]),
                    Res::Buf(&f.colour[1 - c]),
                ],
            )
        };
        let antialias = |c: usize| {
            kit.antialias.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<AntialiasBlock>()),
                    Res::Buf(&f.surface),
                    Res::Buf(&f.colour[c]),
                    Res::Buf(&f.colour[1 - c]),
                    Res::Buf(&kit.counters),
                ],
            )
        };
        let output = |c: usize| {
            kit.output.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Buf(&f.colour[c]),
                    Res::Buf(&kit.encode_table),
                    Res::Buf(&f.rgba),
                ],
            )
        };
        let visibility = |g: usize| {
            kit.visibility.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<VisibilityBlock>()),
                    Res::Buf(&kit.vis_offsets),
                    Res::Buf(&f.depth[g]),
                    Res::Buf(&f.id[g]),
                    Res::Buf(&f.depth[1 - g]),
                    Res::Buf(&f.id[1 - g]),
                    Res::Buf(&kit.counters),
                ],
            )
        };
        let surfaces = [&f.surface, &f.surface_b];
        let fill_anisotropic = |g: usize, c: usize, s: usize| {
            kit.fill_anisotropic.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<FillAnisotropicBlock>()),
                    Res::Buf(&f.id[g]),
                    Res::Buf(surfaces[s]),
                    Res::Buf(&f.colour[c]),
                    Res::Buf(surfaces[1 - s]),
                    Res::Buf(&f.colour[1 - c]),
                    Res::Buf(&kit.counters),
                ],
            )
        };
        let level = |l: usize| {
            kit.depiction.level.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<DepictionBlock>()),
                    Res::Buf(&f.levels[l]),
                    Res::Buf(&f.levels[1 - l]),
                    Res::Buf(&f.shading),
                ],
            )
        };
        let apply = |c: usize| {
            kit.depiction.apply.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Buf(&f.surface),
                    Res::Buf(&f.shading),
                    Res::Buf(&f.colour[c]),
                    Res::Buf(&f.colour[1 - c]),
                ],
            )
        };
        let edl = |c: usize| {
            kit.edl.bind(
                d,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<EdlBlock>()),
                    Res::Buf(&f.surface),
                    Res::Buf(&f.colour[c]),
                    Res::Buf(&f.colour[1 - c]),
                ],
            )
        };
        let fa = |g: usize| {
            [
                [fill_anisotropic(g, 0, 0), fill_anisotropic(g, 0, 1)],
                [fill_anisotropic(g, 1, 0), fill_anisotropic(g, 1, 1)],
            ]
        };
        FrameGroups {
            blend: [[blend(0, 0), blend(0, 1)], [blend(1, 0), blend(1, 1)]],
            visibility: [visibility(0), visibility(1)],
            fill_anisotropic: [fa(0), fa(1)],
            depiction_level: [level(0), level(1)],
            depiction_apply: [apply(0), apply(1)],
            edl: [edl(0), edl(1)],
            resolve: util::bind(
                d,
                "resolve",
                &kit.project.resolve_bgl,
                &[
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<ResolveBlock>()),
                    Res::Buf(&f.vis),
                    Res::Buf(&f.vis_id),
                    Res::Buf(&f.depth[0]),
                    Res::Buf(&f.id[0]),
                ],
            ),
            fill_background: [fill(&kit.fill_background, 0), fill(&kit.fill_background, 1)],
            fill_occluded: [fill(&kit.fill_occluded, 0), fill(&kit.fill_occluded, 1)],
            shade: [shade(0), shade(1)],
            smooth: [[smooth(0, 0), smooth(0, 1)], [smooth(1, 0), smooth(1, 1)]],
            antialias: [antialias(0), antialias(1)],
            output: [output(0), output(1)],
        }
    }
}

/// Bind groups over one uploaded cloud's chunks and the frame buffers, made when the cloud or
/// the frame size changes.
struct CloudGroups {
    key: u64,
    project: Vec<wgpu::BindGroup>,
    /// Per chunk, by geometry image.
    gather: Vec<[wgpu::BindGroup; 2]>,
    /// Per chunk with shadow counts, by geometry image (the light image's filled depth).
    mark: Vec<Option<[wgpu::BindGroup; 2]>>,
}

impl CloudGroups {
    fn new(
        ctx: &GpuContext,
        kit: &Kit,
        arena: &Buffer,
        f: &FrameBuffers,
        cloud: &GpuCloud,
    ) -> CloudGroups {
        let d = &ctx.device;
        let project = cloud
            .chunks
            .iter()
            .map(|c| {
                let mut res = vec![
                    Res::Buf(&kit.view),
                    Res::Arena(arena, block::<ChunkBlock>()),
                    Res::Buf(&c.positions),
                    Res::Buf(c.normals.as_ref().unwrap_or(&cloud.dummy)),
                    Res::Buf(&kit.counters),
                    Res::Buf(&f.peel_ref),
                    Res::Buf(&f.vis),
                ];
                if kit.project.wide.is_none() {
                    res.push(Res::Buf(&f.vis_id));
                }
                util::bind(d, "project", kit.project.bgl(), &res)
            })
            .collect();
        let gather = cloud
            .chunks
            .iter()
            .map(|c| {
                [0, 1].map(|g| {
                    kit.shade.gather.bind(
                        d,
                        &[
                            Res::Buf(&kit.view),
                            Res::Arena(arena, block::<GatherBlock>()),
                            Res::Buf(&f.id[g]),
                            Res::Buf(&c.positions),
                            Res::Buf(c.normals.as_ref().unwrap_or(&cloud.dummy)),
                            Res::Buf(c.albedo.as_ref().unwrap_or(&cloud.dummy)),
                            Res::Buf(&f.attr_pos),
                            Res::Buf(&f.attr_normal),
                            Res::Buf(c.style.as_ref().unwrap_or(&cloud.dummy)),
                            Res::Buf(c.lit.as_ref().unwrap_or(&cloud.dummy)),
                            Res::Buf(&f.attr_style),
                        ],
                    )
                })
            })
            .collect();
        let mark = cloud
            .chunks
            .iter()
            .map(|c| {
                let lit = c.lit.as_ref()?;
                Some([0, 1].map(|g| {
                    kit.mark.bind(
                        d,
                        &[
                            Res::Buf(&kit.view),
                            Res::Arena(arena, block::<MarkBlock>()),
                            Res::Buf(&c.positions),
                            Res::Buf(c.normals.as_ref().unwrap_or(&cloud.dummy)),
                            Res::Buf(&f.depth[g]),
                            Res::Buf(lit),
                            Res::Buf(&kit.counters),
                        ],
                    )
                }))
            })
            .collect();
        CloudGroups {
            key: cloud.key,
            project,
            gather,
            mark,
        }
    }
}

/// A section of the frame: one named pass as the statistics report it.
struct Section {
    name: &'static str,
    iterations: u32,
    until_stable: bool,
    slots: Vec<u32>,
    queries: Option<(u32, u32)>,
    wall_ms: f64,
}

/// Records the frame's passes; in synchronised timing mode submits and waits after each.
struct Rec<'a> {
    ctx: &'a GpuContext,
    enc: CommandEncoder,
    timer: Option<&'a Timer>,
    sync: bool,
    arena: &'a mut Arena,
    sections: Vec<Section>,
    next_query: u32,
    next_slot: u32,
    started: Instant,
}

impl<'a> Rec<'a> {
    fn slot(&mut self) -> Result<u32, GpuError> {
        let s = self.next_slot;
        if s as u64 >= SLOTS {
            return Err(GpuError::TooLarge(
                "too many pass iterations in one frame".into(),
            ));
        }
        self.next_slot += 1;
        Ok(s)
    }

    /// Timestamp query indices for the next section, when timestamps are available.
    fn queries(&mut self) -> Option<(u32, u32)> {
        let _ = self.timer?;
        if self.next_query + 2 > QUERIES {
            return None;
        }
        let q = (self.next_query, self.next_query + 1);
        self.next_query += 2;
        Some(q)
    }

    fn cpass(&mut self, begin: Option<u32>, end: Option<u32>) -> wgpu::ComputePass<'static> {
        let timestamp_writes = match (self.timer, begin.or(end)) {
            (Some(t), Some(_)) => Some(wgpu::ComputePassTimestampWrites {
                query_set: &t.set,
                beginning_of_pass_write_index: begin,
                end_of_pass_write_index: end,
            }),
            _ => None,
        };
        self.enc
            .begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes,
            })
            .forget_lifetime()
    }

    fn start(&mut self) {
        self.started = Instant::now();
    }

    fn end(
        &mut self,
        name: &'static str,
        iterations: u32,
        slots: Vec<u32>,
        queries: Option<(u32, u32)>,
    ) -> Result<(), GpuError> {
        self.end_iterated(name, iterations, false, slots, queries)
    }

    fn end_iterated(
        &mut self,
        name: &'static str,
        iterations: u32,
        until_stable: bool,
        slots: Vec<u32>,
        queries: Option<(u32, u32)>,
    ) -> Result<(), GpuError> {
        let mut wall_ms = f64::NAN;
        if self.sync {
            self.submit_and_wait()?;
            wall_ms = self.started.elapsed().as_secs_f64() * 1e3;
        }
        self.sections.push(Section {
            name,
            iterations,
            until_stable,
            slots,
            queries,
            wall_ms,
        });
        Ok(())
    }

    fn submit_and_wait(&mut self) -> Result<(), GpuError> {
        let enc = std::mem::replace(
            &mut self.enc,
            self.ctx.device.create_command_encoder(&Default::default()),
        );
        self.arena.upload(&self.ctx.queue);
        self.ctx.queue.submit([enc.finish()]);
        wait(self.ctx)
    }
}

fn wait(ctx: &GpuContext) -> Result<(), GpuError> {
    ctx.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| GpuError::Wgpu(e.to_string()))?;
    ctx.take_errors()
}

/// Reads a mappable buffer's first `bytes` bytes.
fn read_back(ctx: &GpuContext, buf: &Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
    read_back_with(ctx, buf, bytes, |b| b.to_vec())
}

/// Maps a mappable buffer's first `bytes` bytes and hands them to `take` (which copies out
/// what it needs: one copy instead of two for a frame's images).
fn read_back_with<T>(
    ctx: &GpuContext,
    buf: &Buffer,
    bytes: u64,
    take: impl FnOnce(&[u8]) -> T,
) -> Result<T, GpuError> {
    let slice = buf.slice(..bytes);
    let status = Arc::new(std::sync::Mutex::new(None));
    let s = status.clone();
    slice.map_async(wgpu::MapMode::Read, move |r| *s.lock().unwrap() = Some(r));
    wait(ctx)?;
    match status.lock().unwrap().take() {
        Some(Ok(())) => {}
        other => {
            return Err(GpuError::Wgpu(format!(
                "mapping the readback buffer failed: {other:?}"
            )))
        }
    }
    let out = take(
        &slice
            .get_mapped_range()
            .map_err(|e| GpuError::Wgpu(e.to_string()))?,
    );
    buf.unmap();
    Ok(out)
}

fn grid_2d(ctx: &GpuContext, w: u32, h: u32) -> Result<(u32, u32), GpuError> {
    let (gx, gy) = (w.div_ceil(8), h.div_ceil(8));
    let m = ctx.limits.max_compute_workgroups_per_dimension;
    if gx > m || gy > m {
        return Err(GpuError::TooLarge(format!(
            "{w}×{h} pixels needs {gx}×{gy} workgroups (the device allows {m} per dimension)"
        )));
    }
    Ok((gx, gy))
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

/// Where the geometry and colour images are after the passes recorded so far.
#[derive(Clone, Copy, Default)]
struct Cursor {
    g: usize,
    colour: usize,
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
        let iterate = super::iterate::new(&ctx);
        let (vis_table, vis_ranges) = super::visibility::offset_table();
        let kit = Kit {
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
            fill_background: super::fill_background::new(&ctx),
            fill_occluded: super::fill_occluded::new(&ctx),
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
            smooth: super::smooth::new(&ctx),
            antialias: super::antialias::new(&ctx),
            output: super::output::new(&ctx),
            visibility: super::visibility::new(&ctx),
            vis_offsets: util::storage_init(
                d,
                "visibility offsets",
                bytemuck::cast_slice(&vis_table),
            ),
            vis_ranges,
            fill_anisotropic: super::fill_anisotropic::new(&ctx),
            depiction: Depiction::new(&ctx),
            edl: super::edl::new(&ctx),
            materials: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("materials"),
                size: std::mem::size_of::<super::shade::MaterialTable>() as u64,
                usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            blend: BlendLayers::new(&ctx),
            mark: super::shadow_texture::new(&ctx),
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
            _ => {
                let mut f = FrameBuffers::new(&self.ctx, v.width, v.height);
                f.groups = Some(FrameGroups::new(
                    &self.ctx,
                    &self.kit,
                    &self.arena.buffer,
                    &f,
                ));
                f
            }
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

/// Makes the cloud's bind groups unless the frame buffers already hold them.
fn ensure_cloud(
    ctx: &GpuContext,
    kit: &Kit,
    arena: &Buffer,
    f: &mut FrameBuffers,
    cloud: &GpuCloud,
) {
    if f.cloud.as_ref().map(|c| c.key) != Some(cloud.key) {
        f.cloud = Some(CloudGroups::new(ctx, kit, arena, f, cloud));
    }
}

fn recorder<'a>(ctx: &'a GpuContext, kit: &'a Kit, arena: &'a mut Arena, sync: bool) -> Rec<'a> {
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    enc.clear_buffer(&kit.counters, 0, None);
    Rec {
        ctx,
        enc,
        timer: kit.timer.as_ref(),
        sync: sync && kit.timer.is_none(),
        arena,
        sections: Vec::new(),
        next_query: 0,
        next_slot: 0,
        started: Instant::now(),
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
        let splat = pipe.splat;
        let result = (|| {
            let splat_gpu = &mut self.splat;
            let kit = &self.kit;
            let mut rec = recorder(&self.ctx, kit, &mut self.arena, self.sync_timing);
            let mut cur = Cursor::default();
            let cull = pipe.backface_culling && layers == 1;
            let background = {
                let lut = srgb_to_linear_table();
                pipe.background.map(|c| lut[c as usize])
            };
            if layers > 1 {
                record_blend(&mut rec, kit, &f, &cur, None, background)?;
            }
            for k in 0..layers {
                cur = Cursor::default();
                if k > 0 {
                    rec.enc
                        .copy_buffer_to_buffer(&f.surface, 0, &f.peel_ref, 0, 4 * n);
                }
                let peel = (k > 0).then_some(gap);
                match (splat, projection, &f.targets) {
                    (Some(sp), _, _) => {
                        record_splat(&mut rec, splat_gpu, kit, &kit.view, &f, cloud, sp)?
                    }
                    (None, ProjectionPath::Hardware, Some((t, copy))) => {
                        record_project_hw(&mut rec, kit, &f, t, copy, cloud, cull)?
                    }
                    _ => record_project(&mut rec, kit, &f, cloud, cull, peel)?,
                }
                for pass in &pipe.geometry {
                    record_geometry(&mut rec, kit, &f, &mut cur, pass, gap)?;
                }
                record_shade(&mut rec, kit, &f, &cur, cloud, shade_block, Some(splat_gpu))?;
                for pass in &pipe.colour {
                    record_colour(&mut rec, kit, &f, &mut cur, pass, v)?;
                }
                if k == 0 {
                    rec.enc
                        .copy_buffer_to_buffer(&f.surface, 0, &f.read, 4 * n, 4 * n);
                    rec.enc
                        .copy_buffer_to_buffer(&f.id[cur.g], 0, &f.read, 8 * n, 4 * n);
                }
                if layers > 1 {
                    record_blend(&mut rec, kit, &f, &cur, Some(cloud.mean_alpha), background)?;
                    if let Some(lr) = &f.layers_read {
                        if pipe.keep_layers {
                            record_output(&mut rec, kit, &f, &cur)?;
                            rec.enc
                                .copy_buffer_to_buffer(&f.rgba, 0, lr, 4 * n * k as u64, 4 * n);
                        }
                    }
                }
            }
            if layers > 1 {
                record_compose(&mut rec, kit, &f, background)?;
                cur.colour = 0;
            }
            record_output(&mut rec, kit, &f, &cur)?;
            rec.enc.copy_buffer_to_buffer(&f.rgba, 0, &f.read, 0, 4 * n);
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
                .filter(|s| s.name == "project")
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
        marks: &[(ViewParams, crate::cpu::shadow_texture::MarkParams)],
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
                    let mut rec = recorder(&self.ctx, kit, &mut self.arena, self.sync_timing);
                    let mut cur = Cursor::default();
                    record_project(&mut rec, kit, &f, cloud, false, None)?;
                    for pass in &settings.light_pipeline(mp.fill_gap).geometry {
                        record_geometry(&mut rec, kit, &f, &mut cur, pass, mp.fill_gap)?;
                    }
                    record_mark(&mut rec, kit, &f, &cur, cloud, mp)?;
                    finish(rec, kit)?;
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

fn read_f32(ctx: &GpuContext, buf: &Buffer, n: usize) -> Result<Vec<f32>, GpuError> {
    Ok(bytemuck::cast_slice(&copy_out(ctx, buf, 4 * n as u64)?).to_vec())
}

fn read_colour(ctx: &GpuContext, buf: &Buffer, n: usize) -> Result<Vec<[f32; 3]>, GpuError> {
    let raw = copy_out(ctx, buf, 16 * n as u64)?;
    let c4: &[[f32; 4]] = bytemuck::cast_slice(&raw);
    Ok(c4.iter().map(|c| [c[0], c[1], c[2]]).collect())
}

fn read_g(ctx: &GpuContext, f: &FrameBuffers, which: usize) -> Result<GBuffer, GpuError> {
    let n = f.width as usize * f.height as usize;
    let mut g = GBuffer::new(f.width, f.height);
    g.depth = read_f32(ctx, &f.depth[which], n)?;
    g.id = bytemuck::cast_slice(&copy_out(ctx, &f.id[which], 4 * n as u64)?).to_vec();
    Ok(g)
}

/// Copies a storage buffer out through a temporary mappable buffer (tests and tools).
fn copy_out(ctx: &GpuContext, buf: &Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
    let tmp = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("copy out"),
        size: bytes.max(4),
        usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(buf, 0, &tmp, 0, bytes);
    ctx.queue.submit([enc.finish()]);
    read_back(ctx, &tmp, bytes)
}

/// Submits the recorded frame (with the counter and timestamp readbacks).
fn finish(mut rec: Rec<'_>, kit: &Kit) -> Result<Vec<Section>, GpuError> {
    rec.enc
        .copy_buffer_to_buffer(&kit.counters, 0, &kit.counters_read, 0, SLOTS * 4);
    if let (Some(t), true) = (rec.timer, rec.next_query > 0) {
        rec.enc
            .resolve_query_set(&t.set, 0..rec.next_query, &t.resolve, 0);
        rec.enc
            .copy_buffer_to_buffer(&t.resolve, 0, &t.read, 0, rec.next_query as u64 * 8);
    }
    rec.submit_and_wait()?;
    Ok(rec.sections)
}

fn stats(ctx: &GpuContext, kit: &Kit, sections: &[Section]) -> Result<Vec<PassStat>, GpuError> {
    let counters: Vec<u32> =
        bytemuck::cast_slice(&read_back(ctx, &kit.counters_read, SLOTS * 4)?).to_vec();
    let stamps: Option<(Vec<u64>, f64)> = match &kit.timer {
        Some(t) if sections.iter().any(|s| s.queries.is_some()) => Some((
            bytemuck::cast_slice(&read_back(ctx, &t.read, QUERIES as u64 * 8)?).to_vec(),
            t.period_ns,
        )),
        _ => None,
    };
    Ok(sections
        .iter()
        .map(|s| {
            let ms = match (&stamps, s.queries) {
                (Some((ts, period)), Some((b, e))) => {
                    ts[e as usize].saturating_sub(ts[b as usize]) as f64 * period / 1e6
                }
                _ => s.wall_ms,
            };
            // Iterations "until stable" stop after the first that changed nothing.
            let mut iterations = s.iterations;
            if s.until_stable {
                if let Some(k) = s.slots.iter().position(|&k| counters[k as usize] == 0) {
                    iterations = iterations.min(k as u32 + 1);
                }
            }
            PassStat {
                name: s.name,
                ms,
                iterations,
                count: s.slots.iter().map(|&k| counters[k as usize] as u64).sum(),
            }
        })
        .collect())
}

fn flat_groups(ctx: &GpuContext, n: u64) -> (u32, u32) {
    ctx.grid(n.div_ceil(256) as u32)
}

fn record_project(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cloud: &GpuCloud,
    cull: bool,
    peel: Option<f32>,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    rec.enc.clear_buffer(&f.vis, 0, None);
    rec.enc.clear_buffer(&f.vis_id, 0, None);
    let slot = rec.slot()?;
    let q = rec.queries();
    let cull = cull && cloud.has_normals;
    let mut chunks = Vec::new();
    for (c, bg) in cloud.chunks.iter().zip(&f.cloud_groups().project) {
        let off = rec.arena.push(&ChunkBlock {
            base: c.base,
            count: c.count,
            cull: cull as u32,
            slot,
            peel: peel.is_some() as u32,
            gap: peel.unwrap_or(0.0),
            pad: [0; 2],
        })?;
        chunks.push((bg, off, ctx.grid(c.count.div_ceil(POINTS_PER_GROUP))));
    }
    let roff = rec.arena.push(&ResolveBlock {
        wide: kit.project.wide.is_some() as u32,
        pad: [0; 3],
    })?;
    let mut pass = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    let stages: Vec<&wgpu::ComputePipeline> = match &kit.project.wide {
        Some((_, p)) => vec![p],
        None => vec![&kit.project.narrow_depth, &kit.project.narrow_index],
    };
    for p in stages {
        pass.set_pipeline(p);
        for (bg, off, (gx, gy)) in &chunks {
            pass.set_bind_group(0, *bg, &[*off]);
            pass.dispatch_workgroups(*gx, *gy, 1);
        }
    }
    pass.set_pipeline(&kit.project.resolve);
    pass.set_bind_group(0, &f.groups().resolve, &[roff]);
    let (gx, gy) = flat_groups(ctx, f.width as u64 * f.height as u64);
    pass.dispatch_workgroups(gx, gy, 1);
    drop(pass);
    rec.end("project", 1, vec![slot], q)
}

fn record_splat(
    rec: &mut Rec<'_>,
    splat: &mut crate::passes::splat::gpu::SplatGpu,
    kit: &Kit,
    view: &Buffer,
    f: &FrameBuffers,
    cloud: &GpuCloud,
    s: crate::SplatSettings,
) -> Result<(), GpuError> {
    rec.start();
    let q = rec.queries();
    let timer = rec.timer;
    let mut begin = |enc: &mut CommandEncoder| {
        let timestamp_writes = match (timer, q) {
            (Some(t), Some((b, e))) => Some(wgpu::ComputePassTimestampWrites {
                query_set: &t.set,
                beginning_of_pass_write_index: Some(b),
                end_of_pass_write_index: Some(e),
            }),
            _ => None,
        };
        enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("splat"),
            timestamp_writes,
        })
        .forget_lifetime()
    };
    splat.record(
        rec.ctx,
        &mut rec.enc,
        rec.arena,
        view,
        cloud,
        (f.width, f.height),
        (s.epsilon.unwrap_or(0.0), s.scale),
        (&f.depth[0], &f.id[0]),
        (s.mode, s.quant()),
        (s.mode != crate::SplatMode::Voronoi).then_some(crate::passes::splat::gpu::BlendTargets {
            attr_pos: &f.attr_pos,
            attr_normal: &f.attr_normal,
            to_linear: &kit.to_linear,
        }),
        &mut begin,
    )?;
    rec.end("splat", 1, vec![], q)
}

fn record_project_hw(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    t: &Targets,
    copy: &wgpu::BindGroup,
    cloud: &GpuCloud,
    cull: bool,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let q = rec.queries();
    let cull = cull && cloud.has_normals;
    let (hw, hw_group) = kit
        .project_hw
        .as_ref()
        .ok_or_else(|| GpuError::Wgpu("the hardware projection was not set up".into()))?;
    let mut draws = Vec::new();
    for c in &cloud.chunks {
        let off = rec.arena.push(&ChunkBlock {
            base: c.base,
            count: c.count,
            cull: cull as u32,
            slot: 0,
            peel: 0,
            gap: 0.0,
            pad: [0; 2],
        })?;
        draws.push((off, c));
    }
    {
        let clear = |c: wgpu::Color| wgpu::Operations {
            load: wgpu::LoadOp::Clear(c),
            store: wgpu::StoreOp::Store,
        };
        let timestamp_writes = match (rec.timer, q) {
            (Some(tm), Some((b, _))) => Some(wgpu::RenderPassTimestampWrites {
                query_set: &tm.set,
                beginning_of_pass_write_index: Some(b),
                end_of_pass_write_index: None,
            }),
            _ => None,
        };
        let mut pass = rec.enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("project_hw"),
            color_attachments: &[
                Some(wgpu::RenderPassColorAttachment {
                    view: &t.id,
                    depth_slice: None,
                    resolve_target: None,
                    ops: clear(wgpu::Color {
                        r: u32::MAX as f64,
                        g: 0.0,
                        b: 0.0,
                        a: 0.0,
                    }),
                }),
                Some(wgpu::RenderPassColorAttachment {
                    view: &t.depth,
                    depth_slice: None,
                    resolve_target: None,
                    ops: clear(wgpu::Color::TRANSPARENT),
                }),
            ],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &t.z,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&hw.pipeline);
        for (off, c) in &draws {
            pass.set_bind_group(0, hw_group, &[*off]);
            pass.set_vertex_buffer(0, c.positions.slice(..));
            let n = c.normals.as_ref().unwrap_or(&c.positions);
            pass.set_vertex_buffer(1, n.slice(..));
            pass.draw(0..c.count, 0..1);
        }
    }
    let mut pass = rec.cpass(None, q.map(|q| q.1));
    pass.set_pipeline(&hw.copy);
    pass.set_bind_group(0, copy, &[]);
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    pass.dispatch_workgroups(gx, gy, 1);
    drop(pass);
    rec.end("project", 1, vec![], q)
}

fn record_geometry(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &mut Cursor,
    pass: &GeometryPass,
    default_gap: f32,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let (fill, groups, its, radius, gap) = match *pass {
        GeometryPass::FillBackground { iterations, radius } => (
            &kit.fill_background,
            &f.groups().fill_background,
            iterations,
            radius,
            0.0,
        ),
        GeometryPass::FillOccluded {
            iterations,
            layer_gap,
            radius,
        } => (
            &kit.fill_occluded,
            &f.groups().fill_occluded,
            iterations,
            radius,
            layer_gap.unwrap_or(default_gap),
        ),
        GeometryPass::Visibility { kernel, threshold } => {
            let (first, count) = *kit
                .vis_ranges
                .get(kernel as usize)
                .filter(|r| r.1 > 0)
                .ok_or_else(|| {
                    GpuError::TooLarge(format!("visibility kernel {kernel} (3 to 15)"))
                })?;
            let slot = rec.slot()?;
            let off = rec.arena.push(&VisibilityBlock {
                first,
                count,
                threshold,
                slot,
            })?;
            let q = rec.queries();
            let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
            let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
            p.set_pipeline(&kit.visibility.pipeline);
            p.set_bind_group(0, &f.groups().visibility[cur.g], &[off]);
            p.dispatch_workgroups(gx, gy, 1);
            drop(p);
            cur.g = 1 - cur.g;
            return rec.end(pass.name(), 1, vec![slot], q);
        }
    };
    let (first, count) = *kit
        .cell_ranges
        .get(radius as usize)
        .filter(|_| radius >= 1)
        .ok_or_else(|| GpuError::TooLarge(format!("fill radius {radius} (1 to 3)")))?;
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let stable = matches!(its, Iterations::UntilStable { .. });
    let mut steps = Vec::new();
    let mut slots = Vec::new();
    for k in 0..its.max() {
        let slot = rec.slot()?;
        let off = rec.arena.push(&FillBlock {
            first,
            count,
            gap,
            slot,
        })?;
        let it = if stable && k > 0 {
            Some(rec.arena.push(&IterateBlock {
                prev_slot: slot - 1,
                args_slot: slot,
                groups_x: gx,
                groups_y: gy,
            })?)
        } else {
            None
        };
        steps.push((cur.g, off, it, slot));
        slots.push(slot);
        cur.g = 1 - cur.g;
    }
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    for (src, off, it, slot) in steps {
        if let Some(ioff) = it {
            p.set_pipeline(&kit.iterate.pipeline);
            p.set_bind_group(0, &kit.iterate_group, &[ioff]);
            p.dispatch_workgroups(1, 1, 1);
            p.set_pipeline(&fill.pipeline);
            p.set_bind_group(0, &groups[src], &[off]);
            p.dispatch_workgroups_indirect(&kit.indirect, slot as u64 * 12);
        } else {
            p.set_pipeline(&fill.pipeline);
            p.set_bind_group(0, &groups[src], &[off]);
            p.dispatch_workgroups(gx, gy, 1);
        }
    }
    drop(p);
    rec.end_iterated(pass.name(), its.max(), stable, slots, q)
}

fn record_shade(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &Cursor,
    cloud: &GpuCloud,
    block: ShadeBlock,
    splat: Option<&mut crate::passes::splat::gpu::SplatGpu>,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let q = rec.queries();
    let mut gathers = Vec::new();
    for (c, groups) in cloud.chunks.iter().zip(&f.cloud_groups().gather) {
        let off = rec.arena.push(&GatherBlock {
            base: c.base,
            count: c.count,
            has_normals: c.normals.is_some() as u32,
            has_albedo: c.albedo.is_some() as u32,
            has_style: c.style.is_some() as u32,
            has_lit: c.lit.is_some() as u32,
            pad: [0; 2],
        })?;
        gathers.push((&groups[cur.g], off));
    }
    let soff = rec.arena.push(&block)?;
    let (fx, fy) = flat_groups(ctx, f.width as u64 * f.height as u64);
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    p.set_pipeline(&kit.shade.gather.pipeline);
    for (bg, off) in &gathers {
        p.set_bind_group(0, *bg, &[*off]);
        p.dispatch_workgroups(fx, fy, 1);
    }
    if let Some(sg) = splat {
        sg.record_resolve(&mut p);
    }
    p.set_pipeline(&kit.shade.shade.pipeline);
    p.set_bind_group(0, &f.groups().shade[cur.g], &[soff]);
    p.dispatch_workgroups(gx, gy, 1);
    drop(p);
    rec.end("shade", 1, vec![], q)
}

fn record_colour(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &mut Cursor,
    pass: &ColourPass,
    v: &ViewParams,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    match *pass {
        ColourPass::Smooth { kernel, iterations } => {
            let off = rec.arena.push(&SmoothBlock::new(kernel))?;
            let groups = &f.groups().smooth[cur.g];
            let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
            p.set_pipeline(&kit.smooth.pipeline);
            for _ in 0..iterations {
                p.set_bind_group(0, &groups[cur.colour], &[off]);
                p.dispatch_workgroups(gx, gy, 1);
                cur.colour = 1 - cur.colour;
            }
            drop(p);
            rec.end("smooth", iterations, vec![], q)
        }
        ColourPass::Antialias {
            threshold,
            strength,
        } => {
            let slot = rec.slot()?;
            let off = rec.arena.push(&AntialiasBlock {
                inv_far: 1.0 / v.far,
                threshold,
                strength,
                slot,
            })?;
            let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
            p.set_pipeline(&kit.antialias.pipeline);
            p.set_bind_group(0, &f.groups().antialias[cur.colour], &[off]);
            p.dispatch_workgroups(gx, gy, 1);
            drop(p);
            cur.colour = 1 - cur.colour;
            rec.end("antialias", 1, vec![slot], q)
        }
        ColourPass::FillAnisotropic {
            iterations,
            delta,
            all_empty,
        } => {
            let mut steps = Vec::new();
            let mut slots = Vec::new();
            for _ in 0..iterations {
                let slot = rec.slot()?;
                steps.push(rec.arena.push(&FillAnisotropicBlock {
                    delta,
                    all_empty: all_empty as u32,
                    slot,
                    pad: 0,
                })?);
                slots.push(slot);
            }
            let groups = &f.groups().fill_anisotropic[cur.g];
            let mut s = 0;
            let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
            p.set_pipeline(&kit.fill_anisotropic.pipeline);
            for off in steps {
                p.set_bind_group(0, &groups[cur.colour][s], &[off]);
                p.dispatch_workgroups(gx, gy, 1);
                cur.colour = 1 - cur.colour;
                s = 1 - s;
            }
            drop(p);
            if s == 1 {
                // The filled depth ended in surface_b: every later pass reads `surface`.
                let n = f.width as u64 * f.height as u64;
                rec.enc
                    .copy_buffer_to_buffer(&f.surface_b, 0, &f.surface, 0, 4 * n);
            }
            rec.end("fill_anisotropic", iterations, slots, q)
        }
        ColourPass::Depiction {
            levels,
            xi,
            epsilon,
        } => {
            let mut offs = Vec::new();
            for (k, weight) in crate::cpu::depiction::level_weights(levels, xi)
                .into_iter()
                .enumerate()
            {
                offs.push(rec.arena.push(&DepictionBlock {
                    weight,
                    epsilon,
                    first: (k == 0) as u32,
                    pad: 0,
                })?);
            }
            let n = f.width as u64 * f.height as u64;
            rec.enc
                .copy_buffer_to_buffer(&f.surface, 0, &f.levels[0], 0, 4 * n);
            let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
            p.set_pipeline(&kit.depiction.level.pipeline);
            for (k, off) in offs.iter().enumerate() {
                p.set_bind_group(0, &f.groups().depiction_level[k % 2], &[*off]);
                p.dispatch_workgroups(gx, gy, 1);
            }
            p.set_pipeline(&kit.depiction.apply.pipeline);
            p.set_bind_group(0, &f.groups().depiction_apply[cur.colour], &[]);
            p.dispatch_workgroups(gx, gy, 1);
            drop(p);
            cur.colour = 1 - cur.colour;
            rec.end("depiction", levels, vec![], q)
        }
        ColourPass::Edl { strength, radius } => {
            let off = rec.arena.push(&EdlBlock::new(strength, radius))?;
            let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
            p.set_pipeline(&kit.edl.pipeline);
            p.set_bind_group(0, &f.groups().edl[cur.colour], &[off]);
            p.dispatch_workgroups(gx, gy, 1);
            drop(p);
            cur.colour = 1 - cur.colour;
            rec.end("edl", 1, vec![], q)
        }
    }
}

/// `begin` (no `hole_alpha`: clears the accumulator) or `blend` of the current layer.
fn record_blend(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &Cursor,
    hole_alpha: Option<f32>,
    background: [f32; 3],
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let slot = rec.slot()?;
    let off = rec.arena.push(&BlendBlock {
        hole_alpha: hole_alpha.unwrap_or(0.0),
        slot,
        pad: [0; 2],
        background,
        pad2: 0,
    })?;
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    p.set_pipeline(match hole_alpha {
        Some(_) => &kit.blend.blend,
        None => &kit.blend.begin,
    });
    p.set_bind_group(0, &f.groups().blend[cur.g][cur.colour], &[off]);
    p.dispatch_workgroups(gx, gy, 1);
    drop(p);
    match hole_alpha {
        Some(_) => rec.end("blend_layers", 1, vec![slot], q),
        None => rec.end("blend_begin", 1, vec![], q),
    }
}

/// The composite over the background into colour image 0.
fn record_compose(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    background: [f32; 3],
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let off = rec.arena.push(&BlendBlock {
        hole_alpha: 0.0,
        slot: 0,
        pad: [0; 2],
        background,
        pad2: 0,
    })?;
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    p.set_pipeline(&kit.blend.compose);
    p.set_bind_group(0, &f.groups().blend[0][0], &[off]);
    p.dispatch_workgroups(gx, gy, 1);
    drop(p);
    rec.end("compose", 1, vec![], q)
}

/// `shadow_texture` over every chunk against the light image in `cur.g`.
fn record_mark(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &Cursor,
    cloud: &GpuCloud,
    mp: &crate::cpu::shadow_texture::MarkParams,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let slot = rec.slot()?;
    let q = rec.queries();
    let mut work = Vec::new();
    for (c, groups) in cloud.chunks.iter().zip(&f.cloud_groups().mark) {
        let groups = groups
            .as_ref()
            .ok_or_else(|| GpuError::Wgpu("shadow_texture: a chunk has no shadow counts".into()))?;
        let off = rec.arena.push(&MarkBlock {
            base: c.base,
            count: c.count,
            gap: mp.gap,
            slope_cap: mp.slope_cap,
            face: mp.face,
            shift: 8 * mp.light,
            has_normals: c.normals.is_some() as u32,
            slot,
        })?;
        work.push((&groups[cur.g], off, flat_groups(ctx, c.count as u64)));
    }
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    p.set_pipeline(&kit.mark.pipeline);
    for (bg, off, (gx, gy)) in work {
        p.set_bind_group(0, bg, &[off]);
        p.dispatch_workgroups(gx, gy, 1);
    }
    drop(p);
    rec.end("shadow_texture", 1, vec![slot], q)
}

fn record_output(
    rec: &mut Rec<'_>,
    kit: &Kit,
    f: &FrameBuffers,
    cur: &Cursor,
) -> Result<(), GpuError> {
    let ctx = rec.ctx;
    rec.start();
    let q = rec.queries();
    let (gx, gy) = grid_2d(ctx, f.width, f.height)?;
    let mut p = rec.cpass(q.map(|q| q.0), q.map(|q| q.1));
    p.set_pipeline(&kit.output.pipeline);
    p.set_bind_group(0, &f.groups().output[cur.colour], &[]);
    p.dispatch_workgroups(gx, gy, 1);
    drop(p);
    rec.end("output", 1, vec![], q)
}
