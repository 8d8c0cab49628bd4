//! The GPU frame's long-lived resources: pipelines and tables made once (`Kit`), the
//! per-pixel buffers of one frame size and the bind groups over them.

use crate::device::cloud::GpuCloud;
use crate::device::context::GpuContext;
use crate::device::util::{self, Pass, Res};
use crate::passes::antialias::gpu::AntialiasBlock;
use crate::passes::blend_layers::gpu::{BlendBlock, BlendLayers};
use crate::passes::depiction::gpu::{Depiction, DepictionBlock};
use crate::passes::edl::gpu::EdlBlock;
use crate::passes::fill::gpu::FillBlock;
use crate::passes::fill_anisotropic::gpu::FillAnisotropicBlock;
use crate::passes::project::gpu::{ChunkBlock, Project, ResolveBlock};
use crate::passes::project::gpu_hw::{ProjectHw, Targets};
use crate::passes::shade::gpu::{GatherBlock, Shade, ShadeBlock};
use crate::passes::shadow_texture::gpu::MarkBlock;
use crate::passes::smooth::gpu::SmoothBlock;
use crate::passes::visibility::gpu::VisibilityBlock;
use std::mem::size_of;
use wgpu::{Buffer, BufferUsages};

/// Counter slots per frame (points kept, changed pixels per iteration, blended pixels).
pub(crate) const SLOTS: u64 = 4096;
/// Timestamp queries per frame (two per section).
pub(crate) const QUERIES: u32 = 256;

pub(crate) struct Timer {
    pub(crate) set: wgpu::QuerySet,
    pub(crate) resolve: Buffer,
    pub(crate) read: Buffer,
    pub(crate) period_ns: f64,
}

pub(crate) struct Kit {
    pub(crate) view: Buffer,
    /// The uniform arena's buffer (dynamic offsets per step).
    pub(crate) arena: Buffer,
    pub(crate) cells: Buffer,
    pub(crate) cell_ranges: Vec<(u32, u32)>,
    pub(crate) to_linear: Buffer,
    pub(crate) encode_table: Buffer,
    pub(crate) counters: Buffer,
    pub(crate) counters_read: Buffer,
    pub(crate) indirect: Buffer,
    pub(crate) timer: Option<Timer>,
    pub(crate) project: Project,
    /// The hardware projection's pipelines and bind group, made when first used (their
    /// targets are not renderable everywhere, e.g. R32Float on GL).
    pub(crate) project_hw: Option<(ProjectHw, wgpu::BindGroup)>,
    pub(crate) fill_background: Pass,
    pub(crate) fill_occluded: Pass,
    pub(crate) iterate: Pass,
    /// The bind groups that depend on nothing but the set-up.
    pub(crate) iterate_group: wgpu::BindGroup,
    pub(crate) shade: Shade,
    pub(crate) smooth: Pass,
    pub(crate) antialias: Pass,
    pub(crate) output: Pass,
    pub(crate) visibility: Pass,
    pub(crate) vis_offsets: Buffer,
    pub(crate) vis_ranges: Vec<(u32, u32)>,
    pub(crate) fill_anisotropic: Pass,
    pub(crate) depiction: Depiction,
    pub(crate) edl: Pass,
    /// Material terms by object (uniform array, written per frame).
    pub(crate) materials: Buffer,
    pub(crate) blend: BlendLayers,
    pub(crate) mark: Pass,
    /// The next peeled layer's reference depth.
    pub(crate) peel_reference: Pass,
    /// Pixel passes' pipelines, made when a frame first uses them (by pass name).
    pub(crate) pixel: std::collections::HashMap<&'static str, Pass>,
}

pub(crate) struct FrameBuffers {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) vis: Buffer,
    pub(crate) vis_id: Buffer,
    pub(crate) depth: [Buffer; 2],
    pub(crate) id: [Buffer; 2],
    pub(crate) attr_pos: Buffer,
    pub(crate) attr_normal: Buffer,
    /// (object | opacity << 8, shadow counts) of each pixel's point.
    pub(crate) attr_style: Buffer,
    /// Depth peeling: the previous layer's surface depth, and the blend accumulator.
    pub(crate) peel_ref: Buffer,
    pub(crate) acc: Buffer,
    /// Each layer's image when the pipeline keeps them (made on demand).
    pub(crate) layers_read: Option<Buffer>,
    pub(crate) colour: [Buffer; 2],
    pub(crate) surface: Buffer,
    /// The anisotropic fill's second depth image; the depiction's level images and term.
    pub(crate) surface_b: Buffer,
    pub(crate) levels: [Buffer; 2],
    pub(crate) shading: Buffer,
    pub(crate) rgba: Buffer,
    pub(crate) read: Buffer,
    /// The hardware path's render targets and the group that copies them out.
    pub(crate) targets: Option<(Targets, wgpu::BindGroup)>,
    /// Bind groups over these buffers, made when first used (see [`Binder`]).
    pub(crate) binds: util::BindCache,
    /// The per-chunk groups of the last cloud rendered at this size.
    pub(crate) cloud: Option<CloudGroups>,
}

impl FrameBuffers {
    pub(crate) fn new(ctx: &GpuContext, w: u32, h: u32) -> FrameBuffers {
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
            binds: Default::default(),
            cloud: None,
        }
    }

    pub(crate) fn cloud_groups(&self) -> &CloudGroups {
        self.cloud.as_ref().expect("made before recording")
    }
}

/// Size of a uniform block as bound from the arena.
pub(crate) fn block<T>() -> u64 {
    size_of::<T>() as u64
}

/// Bind groups over the frame buffers, made when a step first asks for them and cached by
/// the layout and the buffers they bind (`FrameBuffers::binds`), so a frame size that never
/// runs a pass never makes its groups. Indices say which ping-pong image is the source
/// (`g`: geometry, `c`: colour).
pub(crate) struct Binder<'a> {
    d: &'a wgpu::Device,
    kit: &'a Kit,
    f: &'a FrameBuffers,
}

impl<'a> Binder<'a> {
    pub(crate) fn new(ctx: &'a GpuContext, kit: &'a Kit, f: &'a FrameBuffers) -> Binder<'a> {
        Binder {
            d: &ctx.device,
            kit,
            f,
        }
    }
    pub(crate) fn fill(&self, pass: &Pass, src: usize) -> wgpu::BindGroup {
        self.bind(
            "fill",
            &pass.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<FillBlock>()),
                Res::Buf(&self.kit.cells),
                Res::Buf(&self.f.depth[src]),
                Res::Buf(&self.f.id[src]),
                Res::Buf(&self.f.depth[1 - src]),
                Res::Buf(&self.f.id[1 - src]),
                Res::Buf(&self.kit.counters),
            ],
        )
    }
    pub(crate) fn shade(&self, g: usize) -> wgpu::BindGroup {
        self.bind(
            "shade",
            &self.kit.shade.shade.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<ShadeBlock>()),
                Res::Buf(&self.f.depth[g]),
                Res::Buf(&self.f.id[g]),
                Res::Buf(&self.f.attr_pos),
                Res::Buf(&self.f.attr_normal),
                Res::Buf(&self.kit.to_linear),
                Res::Buf(&self.f.colour[0]),
                Res::Buf(&self.f.surface),
                Res::Buf(&self.f.attr_style),
                Res::Buf(&self.kit.materials),
            ],
        )
    }
    pub(crate) fn blend(&self, g: usize, c: usize) -> wgpu::BindGroup {
        self.bind(
            "blend_layers",
            &self.kit.blend.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<BlendBlock>()),
                Res::Buf(&self.f.id[g]),
                Res::Buf(&self.f.surface),
                Res::Buf(&self.f.attr_style),
                Res::Buf(&self.f.colour[c]),
                Res::Buf(&self.f.acc),
                Res::Buf(&self.kit.counters),
            ],
        )
    }
    pub(crate) fn smooth(&self, g: usize, c: usize) -> wgpu::BindGroup {
        self.bind(
            "smooth",
            &self.kit.smooth.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<SmoothBlock>()),
                Res::Buf(&self.f.id[g]),
                Res::Buf(&self.f.colour[c]),
                Res::Buf(&self.f.colour[1 - c]),
            ],
        )
    }
    pub(crate) fn antialias(&self, c: usize) -> wgpu::BindGroup {
        self.bind(
            "antialias",
            &self.kit.antialias.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<AntialiasBlock>()),
                Res::Buf(&self.f.surface),
                Res::Buf(&self.f.colour[c]),
                Res::Buf(&self.f.colour[1 - c]),
                Res::Buf(&self.kit.counters),
            ],
        )
    }
    pub(crate) fn output(&self, c: usize) -> wgpu::BindGroup {
        self.bind(
            "output",
            &self.kit.output.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Buf(&self.f.colour[c]),
                Res::Buf(&self.kit.encode_table),
                Res::Buf(&self.f.rgba),
            ],
        )
    }
    pub(crate) fn visibility(&self, g: usize) -> wgpu::BindGroup {
        self.bind(
            "visibility",
            &self.kit.visibility.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<VisibilityBlock>()),
                Res::Buf(&self.kit.vis_offsets),
                Res::Buf(&self.f.depth[g]),
                Res::Buf(&self.f.id[g]),
                Res::Buf(&self.f.depth[1 - g]),
                Res::Buf(&self.f.id[1 - g]),
                Res::Buf(&self.kit.counters),
            ],
        )
    }
    pub(crate) fn fill_anisotropic(&self, g: usize, c: usize, s: usize) -> wgpu::BindGroup {
        self.bind(
            "fill_anisotropic",
            &self.kit.fill_anisotropic.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<FillAnisotropicBlock>()),
                Res::Buf(&self.f.id[g]),
                Res::Buf([&self.f.surface, &self.f.surface_b][s]),
                Res::Buf(&self.f.colour[c]),
                Res::Buf([&self.f.surface, &self.f.surface_b][1 - s]),
                Res::Buf(&self.f.colour[1 - c]),
                Res::Buf(&self.kit.counters),
            ],
        )
    }
    pub(crate) fn level(&self, l: usize) -> wgpu::BindGroup {
        self.bind(
            "level",
            &self.kit.depiction.level.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<DepictionBlock>()),
                Res::Buf(&self.f.levels[l]),
                Res::Buf(&self.f.levels[1 - l]),
                Res::Buf(&self.f.shading),
            ],
        )
    }
    pub(crate) fn apply(&self, c: usize) -> wgpu::BindGroup {
        self.bind(
            "apply",
            &self.kit.depiction.apply.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Buf(&self.f.surface),
                Res::Buf(&self.f.shading),
                Res::Buf(&self.f.colour[c]),
                Res::Buf(&self.f.colour[1 - c]),
            ],
        )
    }
    pub(crate) fn edl(&self, c: usize) -> wgpu::BindGroup {
        self.bind(
            "edl",
            &self.kit.edl.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<EdlBlock>()),
                Res::Buf(&self.f.surface),
                Res::Buf(&self.f.colour[c]),
                Res::Buf(&self.f.colour[1 - c]),
            ],
        )
    }
    pub(crate) fn resolve(&self) -> wgpu::BindGroup {
        self.bind(
            "resolve",
            &self.kit.project.resolve_bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, block::<ResolveBlock>()),
                Res::Buf(&self.f.vis),
                Res::Buf(&self.f.vis_id),
                Res::Buf(&self.f.depth[0]),
                Res::Buf(&self.f.id[0]),
            ],
        )
    }

    pub(crate) fn peel_reference(&self) -> wgpu::BindGroup {
        self.bind(
            "peel_reference",
            &self.kit.peel_reference.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(
                    &self.kit.arena,
                    block::<crate::passes::project::gpu::PeelReferenceBlock>(),
                ),
                Res::Buf(&self.f.surface),
                Res::Buf(&self.f.peel_ref),
            ],
        )
    }

    /// A pixel pass's group (see [`crate::passes::pixel`]).
    pub(crate) fn pixel(&self, name: &str, pass: &Pass, g: usize, c: usize) -> wgpu::BindGroup {
        self.bind(
            name,
            &pass.bgl,
            &[
                Res::Buf(&self.kit.view),
                Res::Arena(&self.kit.arena, util::BLOCK),
                Res::Buf(&self.f.id[g]),
                Res::Buf(&self.f.surface),
                Res::Buf(&self.f.colour[c]),
                Res::Buf(&self.f.colour[1 - c]),
            ],
        )
    }

    /// The cached group of `layout` over `res`, made now if it is not there.
    fn bind(&self, label: &str, layout: &wgpu::BindGroupLayout, res: &[Res]) -> wgpu::BindGroup {
        self.f.binds.get(self.d, label, layout, res)
    }
}

/// Bind groups over one uploaded cloud's chunks and the frame buffers, made when the cloud or
/// the frame size changes.
pub(crate) struct CloudGroups {
    pub(crate) key: u64,
    pub(crate) project: Vec<wgpu::BindGroup>,
    /// Per chunk, by geometry image.
    pub(crate) gather: Vec<[wgpu::BindGroup; 2]>,
    /// Per chunk with shadow counts, by geometry image (the light image's filled depth).
    pub(crate) mark: Vec<Option<[wgpu::BindGroup; 2]>>,
}

impl CloudGroups {
    pub(crate) fn new(
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

/// Makes the cloud's bind groups unless the frame buffers already hold them.
pub(crate) fn ensure_cloud(
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

/// Makes the pipelines of the pixel passes in `passes` unless they exist (see
/// [`crate::passes::pixel`]; their bind groups are made by [`Binder::pixel`] when recorded).
pub(crate) fn ensure_pixel_passes(
    ctx: &GpuContext,
    kit: &mut Kit,
    passes: &[crate::pipeline::ColourPass],
) {
    use crate::device::util::{DYNAMIC, READ, UNIFORM, WRITE};
    for pp in passes.iter().filter_map(|p| p.pixel()) {
        kit.pixel.entry(pp.name()).or_insert_with(|| {
            Pass::new(
                &ctx.device,
                pp.module(),
                pp.name(),
                &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE],
            )
        });
    }
}
