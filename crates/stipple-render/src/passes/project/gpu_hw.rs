//! # project_hw: the hardware baseline for project
//!
//! A `PointList` render pipeline with a depth test draws every point as one pixel into an id
//! target (R32Uint) and a view-depth target (R32Float); `copy_targets` moves them into the
//! G-buffer. Selected with `--projection hardware` to compare with the compute rasterizer.
//! It agrees with `project` except at pixel-boundary and depth-precision ties (the depth test
//! compares the 32-bit projected z, not the view depth).

use super::gpu::ChunkBlock;
use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError, DEPTH_FORMAT, ID_FORMAT};
use crate::device::frame::{block, Binder, GpuPass, Shared, Targets, Z_FORMAT};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{self, Res, Slot, DYNAMIC, UNIFORM, WRITE};
use crate::stats::PassId;
use wgpu::ShaderStages;

pub(crate) struct ProjectHw {
    pub pipeline: wgpu::RenderPipeline,
    pub copy_bgl: wgpu::BindGroupLayout,
    pub copy: wgpu::ComputePipeline,
    /// The draw's group (the view and the chunk blocks).
    group: wgpu::BindGroup,
}

impl GpuPass for ProjectHw {
    fn new(ctx: &GpuContext, shared: &Shared) -> ProjectHw {
        let d = &ctx.device;
        let module = util::module(d, &crate::device::shaders::PROJECT_HW_MODULE);
        let bgl = util::layout(
            d,
            "project_hw",
            &[UNIFORM, DYNAMIC],
            ShaderStages::VERTEX | ShaderStages::FRAGMENT,
        );
        let layout = d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("project_hw"),
            bind_group_layouts: &[Some(&bgl)],
            immediate_size: 0,
        });
        let attr = |location| {
            [wgpu::VertexAttribute {
                format: wgpu::VertexFormat::Float32x3,
                offset: 0,
                shader_location: location,
            }]
        };
        let (a0, a1) = (attr(0), attr(1));
        let buffers = [
            Some(wgpu::VertexBufferLayout {
                array_stride: 12,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &a0,
            }),
            Some(wgpu::VertexBufferLayout {
                array_stride: 12,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &a1,
            }),
        ];
        let pipeline = d.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("project_hw"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &buffers,
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::PointList,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: Z_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(ID_FORMAT.into()), Some(DEPTH_FORMAT.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let copy_bgl = util::layout(
            d,
            "project_hw copy",
            &[
                UNIFORM,
                Slot::Skip,
                Slot::Texture(wgpu::TextureSampleType::Uint),
                Slot::Texture(wgpu::TextureSampleType::Float { filterable: false }),
                WRITE,
                WRITE,
            ],
            ShaderStages::COMPUTE,
        );
        let copy = util::compute(d, &module, "copy_targets", &copy_bgl);
        let group = util::bind(
            d,
            "project_hw",
            &bgl,
            &[
                Res::Buf(&shared.view),
                Res::Arena(&shared.arena, block::<ChunkBlock>()),
            ],
        );
        ProjectHw {
            group,
            pipeline,
            copy_bgl,
            copy,
        }
    }
}

impl ProjectHw {
    /// The group that copies a frame's targets into geometry image 0.
    pub(crate) fn copy_group(&self, b: Binder<'_>, t: &Targets) -> wgpu::BindGroup {
        b.bind(
            "project_hw copy",
            &self.copy_bgl,
            &[
                Res::Buf(&b.shared.view),
                Res::Skip,
                Res::View(&t.id),
                Res::View(&t.depth),
                Res::Buf(&b.f.depth[0]),
                Res::Buf(&b.f.id[0]),
            ],
        )
    }
}

/// Draws every chunk of `cloud` as points into the frame's render targets (`targets`), then
/// copies them into geometry image 0.
pub(crate) fn record(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    targets: &Targets,
    cloud: &GpuCloud,
    cull: bool,
) -> Result<(), GpuError> {
    let q = rec.section();
    let cull = cull && cloud.has_normals;
    let hw = b.pass::<ProjectHw>();
    let copy = hw.copy_group(b, targets);
    let t = targets;
    let mut draws = Vec::new();
    for c in &cloud.chunks {
        let off = rec.arena.push(&ChunkBlock {
            base: c.base,
            count: c.count,
            cull: cull as u32,
            slot: 0,
            peel: 0,
            gap: 0.0,
            has_normals: 0,
            pad: 0,
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
            pass.set_bind_group(0, &hw.group, &[*off]);
            pass.set_vertex_buffer(0, c.positions.slice(..));
            let n = c.normals.as_ref().unwrap_or(&c.positions);
            pass.set_vertex_buffer(1, n.slice(..));
            pass.draw(0..c.count, 0..1);
        }
    }
    let mut pass = rec.cpass(None, q.map(|q| q.1));
    pass.set_pipeline(&hw.copy);
    pass.set_bind_group(0, &copy, &[]);
    let (gx, gy) = grid_2d(b.ctx, b.f.width, b.f.height)?;
    pass.dispatch_workgroups(gx, gy, 1);
    drop(pass);
    rec.end(PassId::Project, 1, vec![], q)
}
