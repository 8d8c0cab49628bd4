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
    /// Made with the buffers (see [`FrameGroups`]).
    pub(crate) groups: Option<FrameGroups>,
    /// The per-chunk groups of the last cloud rendered at this size.
    pub(crate) cloud: Option<CloudGroups>,
    /// Pixel passes' bind groups over these buffers, made when first used, by pass name,
    /// geometry image and colour image.
    pub(crate) pixel: std::collections::HashMap<(&'static str, usize, usize), wgpu::BindGroup>,
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
            groups: None,
            cloud: None,
            pixel: Default::default(),
        }
    }

    pub(crate) fn groups(&self) -> &FrameGroups {
        self.groups.as_ref().expect("made with the buffers")
    }

    pub(crate) fn cloud_groups(&self) -> &CloudGroups {
        self.cloud.as_ref().expect("made before recording")
    }
}

/// Size of a uniform block as bound from the arena.
pub(crate) fn block<T>() -> u64 {
    size_of::<T>() as u64
}

/// Bind groups over the frame buffers, made once per frame size. Arrays are indexed by which
/// ping-pong image is the source (`g`: geometry, `c`: colour).
pub(crate) struct FrameGroups {
    pub(crate) resolve: wgpu::BindGroup,
    pub(crate) fill_background: [wgpu::BindGroup; 2],
    pub(crate) fill_occluded: [wgpu::BindGroup; 2],
    pub(crate) shade: [wgpu::BindGroup; 2],
    pub(crate) smooth: [[wgpu::BindGroup; 2]; 2],
    pub(crate) antialias: [wgpu::BindGroup; 2],
    pub(crate) output: [wgpu::BindGroup; 2],
    pub(crate) visibility: [wgpu::BindGroup; 2],
    /// By geometry image, colour image and depth image (0: surface, 1: surface_b).
    pub(crate) fill_anisotropic: [[[wgpu::BindGroup; 2]; 2]; 2],
    /// By source level image.
    pub(crate) depiction_level: [wgpu::BindGroup; 2],
    pub(crate) depiction_apply: [wgpu::BindGroup; 2],
    pub(crate) edl: [wgpu::BindGroup; 2],
    /// By geometry image and colour image (compose writes colour 0 through `[g][0]`).
    pub(crate) blend: [[wgpu::BindGroup; 2]; 2],
}

impl FrameGroups {
    pub(crate) fn new(
        ctx: &GpuContext,
        kit: &Kit,
        arena: &Buffer,
        f: &FrameBuffers,
    ) -> FrameGroups {
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

/// Makes the pipelines of the pixel passes in `passes` and their bind groups over `f`
/// unless they exist (see [`crate::passes::pixel`]).
pub(crate) fn ensure_pixel_passes(
    ctx: &GpuContext,
    kit: &mut Kit,
    arena: &Buffer,
    f: &mut FrameBuffers,
    passes: &[crate::pipeline::ColourPass],
) {
    use crate::device::util::{DYNAMIC, READ, UNIFORM, WRITE};
    let d = &ctx.device;
    for pp in passes.iter().filter_map(|p| p.pixel()) {
        let name = pp.name();
        let pass = kit.pixel.entry(name).or_insert_with(|| {
            Pass::new(
                d,
                pp.module(),
                name,
                &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE],
            )
        });
        for g in 0..2 {
            for c in 0..2 {
                f.pixel.entry((name, g, c)).or_insert_with(|| {
                    pass.bind(
                        d,
                        &[
                            Res::Buf(&kit.view),
                            Res::Arena(arena, crate::device::util::BLOCK),
                            Res::Buf(&f.id[g]),
                            Res::Buf(&f.surface),
                            Res::Buf(&f.colour[c]),
                            Res::Buf(&f.colour[1 - c]),
                        ],
                    )
                });
            }
        }
    }
}
