//! # project_hw: the hardware baseline for project
//!
//! A `PointList` render pipeline with a depth test draws every point as one pixel into an id
//! target (R32Uint) and a view-depth target (R32Float); `copy_targets` moves them into the
//! G-buffer. Selected with `--projection hardware` to compare with the compute rasterizer.
//! It agrees with `project` except at pixel-boundary and depth-precision ties (the depth test
//! compares the 32-bit projected z, not the view depth).

use crate::device::context::GpuContext;
use crate::device::util::{self, Slot, DYNAMIC, UNIFORM, WRITE};
use wgpu::{ShaderStages, TextureFormat};

pub(crate) use crate::device::context::{DEPTH_FORMAT, ID_FORMAT};
pub(crate) const Z_FORMAT: TextureFormat = TextureFormat::Depth32Float;

pub(crate) struct ProjectHw {
    pub bgl: wgpu::BindGroupLayout,
    pub pipeline: wgpu::RenderPipeline,
    pub copy_bgl: wgpu::BindGroupLayout,
    pub copy: wgpu::ComputePipeline,
}

impl ProjectHw {
    pub fn new(ctx: &GpuContext) -> ProjectHw {
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
        ProjectHw {
            bgl,
            pipeline,
            copy_bgl,
            copy,
        }
    }
}

/// The render targets of the hardware path for one frame size.
pub(crate) struct Targets {
    pub id: wgpu::TextureView,
    pub depth: wgpu::TextureView,
    pub z: wgpu::TextureView,
}

impl Targets {
    pub fn new(ctx: &GpuContext, w: u32, h: u32) -> Targets {
        let tex = |format, usage| {
            ctx.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some("project_hw target"),
                    size: wgpu::Extent3d {
                        width: w,
                        height: h,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        };
        let u = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        Targets {
            id: tex(ID_FORMAT, u),
            depth: tex(DEPTH_FORMAT, u),
            z: tex(Z_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT),
        }
    }
}
