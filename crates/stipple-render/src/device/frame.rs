//! What a GPU frame records into: the long-lived buffers every pass shares ([`Shared`],
//! with the passes' own pipelines made on first use, [`GpuPass`]), the per-pixel buffers of
//! one frame size ([`FrameBuffers`]) and the bind groups over them ([`Binder`]).

use crate::device::cloud::GpuCloud;
use crate::device::context::GpuContext;
use crate::device::iterate::IterateBlock;
use crate::device::util::{self, Arena, Pass, Res};
use std::any::{Any, TypeId};
use std::cell::RefCell;
use std::collections::HashMap;
use std::mem::size_of;
use std::sync::Arc;
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

/// A pass's GPU state (pipelines, layouts, constant tables), made the first time a frame
/// records the pass and kept for the renderer's life (see [`Shared::pass`]).
pub(crate) trait GpuPass: Any + Send + Sync {
    fn new(ctx: &GpuContext, shared: &Shared) -> Self;
}

/// What every pass binds (the view block, the uniform arena, counters, the indirect
/// arguments of "until stable" iterations, timestamps, the sRGB table, the material table)
/// and the passes' own states, made when first asked for.
pub(crate) struct Shared {
    pub(crate) view: Buffer,
    /// The uniform arena's buffer (dynamic offsets per step).
    pub(crate) arena: Buffer,
    pub(crate) counters: Buffer,
    pub(crate) counters_read: Buffer,
    pub(crate) indirect: Buffer,
    pub(crate) timer: Option<Timer>,
    /// sRGB byte → linear (shade and the splats' blending).
    pub(crate) to_linear: Buffer,
    pub(crate) iterate: Pass,
    pub(crate) iterate_group: wgpu::BindGroup,
    passes: RefCell<HashMap<TypeId, Arc<dyn Any + Send + Sync>>>,
    /// Pixel passes' pipelines (by pass name; see [`crate::passes::pixel`]).
    pixel: RefCell<HashMap<&'static str, Arc<Pass>>>,
}

impl Shared {
    pub(crate) fn new(ctx: &GpuContext, arena: &Arena) -> Shared {
        let d = &ctx.device;
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
        let uniform = |label, size| {
            d.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let counters = util::storage(d, "counters", SLOTS * 4);
        let indirect = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("indirect"),
            size: SLOTS * 12,
            usage: BufferUsages::STORAGE | BufferUsages::INDIRECT,
            mapped_at_creation: false,
        });
        let iterate = crate::device::iterate::new(ctx);
        let iterate_group = iterate.bind(
            d,
            &[
                Res::Arena(&arena.buffer, block::<IterateBlock>()),
                Res::Buf(&counters),
                Res::Buf(&indirect),
            ],
        );
        Shared {
            view: uniform("view", size_of::<crate::params::ViewParams>() as u64),
            arena: arena.buffer.clone(),
            counters_read: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("counters read"),
                size: SLOTS * 4,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            counters,
            indirect,
            timer,
            to_linear: util::storage_init(
                d,
                "srgb to linear",
                bytemuck::cast_slice(&crate::srgb::srgb_to_linear_table()),
            ),
            iterate,
            iterate_group,
            passes: Default::default(),
            pixel: Default::default(),
        }
    }

    /// The state of pass `T`, made now if no frame has used the pass yet.
    pub(crate) fn pass<T: GpuPass>(&self, ctx: &GpuContext) -> Arc<T> {
        let key = TypeId::of::<T>();
        let found = self.passes.borrow().get(&key).cloned();
        let any = match found {
            Some(p) => p,
            None => {
                // Made outside the borrow: a pass may ask for another while it is made.
                let made: Arc<dyn Any + Send + Sync> = Arc::new(T::new(ctx, self));
                self.passes.borrow_mut().entry(key).or_insert(made).clone()
            }
        };
        any.downcast::<T>().expect("keyed by its own type")
    }

    /// A pixel pass's pipeline, made now if no frame has used the pass yet.
    pub(crate) fn pixel_pass(
        &self,
        ctx: &GpuContext,
        name: &'static str,
        module: &'static crate::device::shaders::ShaderModule,
    ) -> Arc<Pass> {
        use crate::device::util::{DYNAMIC, READ, UNIFORM, WRITE};
        self.pixel
            .borrow_mut()
            .entry(name)
            .or_insert_with(|| {
                Arc::new(Pass::new(
                    &ctx.device,
                    module,
                    name,
                    &[UNIFORM, DYNAMIC, READ, READ, READ, WRITE],
                ))
            })
            .clone()
    }
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
    /// Depth peeling: what the previous layer left (two vec4 per pixel, see
    /// `peel_reference.wgsl`), and the blend accumulator.
    pub(crate) peel_ref: Buffer,
    pub(crate) acc: Buffer,
    /// Each layer's image when the pipeline keeps them (made on demand).
    pub(crate) layers_read: Option<Buffer>,
    /// The splat pass's per-pixel normals, read back with a splat frame (made on demand).
    pub(crate) normals_read: Option<Buffer>,
    pub(crate) colour: [Buffer; 2],
    pub(crate) surface: Buffer,
    /// The anisotropic fill's second depth image; the depiction's level images and term.
    pub(crate) surface_b: Buffer,
    pub(crate) levels: [Buffer; 2],
    pub(crate) shading: Buffer,
    pub(crate) rgba: Buffer,
    pub(crate) read: Buffer,
    /// The hardware path's render targets (made when the path is first used).
    pub(crate) targets: Option<Targets>,
    /// Bind groups over these buffers, made when first used (see [`Binder`]).
    pub(crate) binds: util::BindCache,
    /// Bind groups over these buffers and the chunks of the cloud last rendered at this size
    /// (emptied when the cloud changes, so no dropped cloud stays alive through them).
    pub(crate) cloud_binds: util::BindCache,
    cloud_key: Option<u64>,
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
            attr_style: s("pixel styles", 16 * n),
            peel_ref: s("peel reference", 32 * n),
            acc: s("blend accumulator", 16 * n),
            layers_read: None,
            normals_read: None,
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
            cloud_binds: Default::default(),
            cloud_key: None,
        }
    }

    /// Drops the bind groups over another cloud's chunks when `cloud` is not the last one.
    pub(crate) fn use_cloud(&mut self, cloud: &GpuCloud) {
        if self.cloud_key != Some(cloud.key) {
            self.cloud_binds = Default::default();
            self.cloud_key = Some(cloud.key);
        }
    }

    /// Bind groups made so far over these buffers.
    pub(crate) fn groups_made(&self) -> usize {
        self.binds.len() + self.cloud_binds.len()
    }

    /// Pixels of one image.
    pub(crate) fn pixels(&self) -> u64 {
        self.width as u64 * self.height as u64
    }
}

/// Size of a uniform block as bound from the arena.
pub(crate) fn block<T>() -> u64 {
    size_of::<T>() as u64
}

/// The depth buffer format of the hardware projection's render pass.
pub(crate) const Z_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

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
            id: tex(crate::device::context::ID_FORMAT, u),
            depth: tex(crate::device::context::DEPTH_FORMAT, u),
            z: tex(Z_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT),
        }
    }
}

/// Where the geometry and colour images are after the passes recorded so far: index of the
/// current image of each ping-pong pair.
#[derive(Clone, Copy, Default)]
pub(crate) struct Cursor {
    pub(crate) g: usize,
    pub(crate) colour: usize,
}

/// What a pass records with besides the encoder: the device, the shared buffers, the frame
/// buffers, and the bind groups over them, made when a step first asks for them and cached
/// by the layout and the buffers they bind (so a frame size that never runs a pass never
/// makes its groups).
#[derive(Clone, Copy)]
pub(crate) struct Binder<'a> {
    pub(crate) ctx: &'a GpuContext,
    pub(crate) shared: &'a Shared,
    pub(crate) f: &'a FrameBuffers,
}

impl<'a> Binder<'a> {
    pub(crate) fn new(ctx: &'a GpuContext, shared: &'a Shared, f: &'a FrameBuffers) -> Binder<'a> {
        Binder { ctx, shared, f }
    }

    /// The cached group of `layout` over `res`, made now if it is not there.
    pub(crate) fn bind(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        res: &[Res],
    ) -> wgpu::BindGroup {
        self.f.binds.get(&self.ctx.device, label, layout, res)
    }

    /// As [`Binder::bind`], for groups that bind a chunk of the current cloud.
    pub(crate) fn bind_chunk(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        res: &[Res],
    ) -> wgpu::BindGroup {
        self.f.cloud_binds.get(&self.ctx.device, label, layout, res)
    }

    /// The state of pass `T` (see [`Shared::pass`]).
    pub(crate) fn pass<T: GpuPass>(&self) -> Arc<T> {
        self.shared.pass::<T>(self.ctx)
    }

    /// The view block and a uniform block of `T` in the arena: the first two bindings of
    /// most passes.
    pub(crate) fn view_and<T>(&self) -> [Res<'a>; 2] {
        [
            Res::Buf(&self.shared.view),
            Res::Arena(&self.shared.arena, block::<T>()),
        ]
    }
}
