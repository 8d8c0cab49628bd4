//! Small helpers shared by the passes: bind group layouts, pipelines, the per-frame uniform
//! arena and buffers.

use crate::device::shaders::ShaderModule;
use wgpu::util::DeviceExt;
use wgpu::{BindGroupLayout, BufferUsages, Device, ShaderStages};

/// One binding of a layout, in binding order.
#[derive(Clone, Copy)]
pub(crate) enum Slot {
    /// A uniform block; `dynamic` ones take an offset into the frame's uniform arena.
    Uniform {
        dynamic: bool,
    },
    Storage {
        read_only: bool,
    },
    /// A 2-D texture read with textureLoad.
    Texture(wgpu::TextureSampleType),
    /// A gap in the numbering.
    Skip,
}

pub(crate) const UNIFORM: Slot = Slot::Uniform { dynamic: false };
pub(crate) const DYNAMIC: Slot = Slot::Uniform { dynamic: true };
pub(crate) const READ: Slot = Slot::Storage { read_only: true };
pub(crate) const WRITE: Slot = Slot::Storage { read_only: false };

pub(crate) fn layout(
    device: &Device,
    label: &str,
    slots: &[Slot],
    vis: ShaderStages,
) -> BindGroupLayout {
    let entries: Vec<wgpu::BindGroupLayoutEntry> = slots
        .iter()
        .enumerate()
        .filter_map(|(i, s)| {
            let ty = match *s {
                Slot::Uniform { dynamic } => wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: dynamic,
                    min_binding_size: None,
                },
                Slot::Storage { read_only } => wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                Slot::Texture(sample_type) => wgpu::BindingType::Texture {
                    sample_type,
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                Slot::Skip => return None,
            };
            Some(wgpu::BindGroupLayoutEntry {
                binding: i as u32,
                visibility: vis,
                ty,
                count: None,
            })
        })
        .collect();
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &entries,
    })
}

pub(crate) fn module(device: &Device, m: &ShaderModule) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(m.name),
        source: wgpu::ShaderSource::Wgsl(m.source().into()),
    })
}

pub(crate) fn compute(
    device: &Device,
    module: &wgpu::ShaderModule,
    entry: &str,
    bgl: &BindGroupLayout,
) -> wgpu::ComputePipeline {
    let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(entry),
        bind_group_layouts: &[Some(bgl)],
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: Some(&pl),
        module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// A bind group from buffers (and texture views) in binding order; `None` skips a number.
#[derive(Clone, Copy)]
pub(crate) enum Res<'a> {
    Buf(&'a wgpu::Buffer),
    /// A uniform block of `size` bytes inside the arena (offset given at dispatch).
    Arena(&'a wgpu::Buffer, u64),
    View(&'a wgpu::TextureView),
    Skip,
}

/// What identifies a bound resource (wgpu's handles compare by identity).
#[derive(Clone, PartialEq, Eq, Hash)]
enum ResKey {
    Buf(wgpu::Buffer),
    Arena(wgpu::Buffer, u64),
    View(wgpu::TextureView),
    Skip,
}

/// Bind groups made when first asked for and kept, keyed by the layout and the resources
/// they bind. Owned by the frame buffers they bind (dropped with them), so it never keeps a
/// resource alive longer than its frame size.
#[derive(Default)]
pub(crate) struct BindCache {
    map: std::cell::RefCell<
        std::collections::HashMap<(wgpu::BindGroupLayout, Vec<ResKey>), wgpu::BindGroup>,
    >,
}

impl BindCache {
    /// The group of `layout` over `res`, from the cache or made now.
    pub(crate) fn get(
        &self,
        device: &Device,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        res: &[Res],
    ) -> wgpu::BindGroup {
        let key = (
            layout.clone(),
            res.iter()
                .map(|r| match r {
                    Res::Buf(b) => ResKey::Buf((*b).clone()),
                    Res::Arena(b, size) => ResKey::Arena((*b).clone(), *size),
                    Res::View(v) => ResKey::View((*v).clone()),
                    Res::Skip => ResKey::Skip,
                })
                .collect::<Vec<_>>(),
        );
        if let Some(g) = self.map.borrow().get(&key) {
            return g.clone();
        }
        let g = bind(device, label, layout, res);
        self.map.borrow_mut().insert(key, g.clone());
        g
    }

    /// Groups made so far.
    pub(crate) fn len(&self) -> usize {
        self.map.borrow().len()
    }
}

pub(crate) fn bind(
    device: &Device,
    label: &str,
    bgl: &BindGroupLayout,
    res: &[Res],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = res
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let resource = match *r {
                Res::Buf(b) => b.as_entire_binding(),
                Res::Arena(b, size) => wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: b,
                    offset: 0,
                    size: wgpu::BufferSize::new(size),
                }),
                Res::View(v) => wgpu::BindingResource::TextureView(v),
                Res::Skip => return None,
            };
            Some(wgpu::BindGroupEntry {
                binding: i as u32,
                resource,
            })
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: bgl,
        entries: &entries,
    })
}

pub(crate) fn storage(device: &Device, label: &str, bytes: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16),
        usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

pub(crate) fn storage_init(device: &Device, label: &str, data: &[u8]) -> wgpu::Buffer {
    if data.len() < 16 {
        let mut padded = data.to_vec();
        padded.resize(16, 0);
        return storage_init(device, label, &padded);
    }
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: data,
        usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC | BufferUsages::COPY_DST,
    })
}

/// Uniform blocks for one frame, each in its own aligned slot of one buffer (bound with
/// dynamic offsets), written with a single `write_buffer` before the frame is submitted.
pub(crate) struct Arena {
    pub buffer: wgpu::Buffer,
    align: u64,
    data: Vec<u8>,
}

/// The largest uniform block a pass uses (bytes); every dynamic binding has this size.
pub(crate) const BLOCK: u64 = 128;
const ARENA_BYTES: u64 = 1 << 20;

impl Arena {
    pub fn new(device: &Device, align: u32) -> Arena {
        Arena {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("uniform arena"),
                size: ARENA_BYTES,
                usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            align: (align as u64).max(BLOCK),
            data: Vec::new(),
        }
    }

    pub fn clear(&mut self) {
        self.data.clear();
    }

    /// Stores a block; returns its dynamic offset.
    pub fn push<T: bytemuck::Pod>(
        &mut self,
        v: &T,
    ) -> Result<u32, crate::device::context::GpuError> {
        self.push_bytes(bytemuck::bytes_of(v))
    }

    /// Stores a block given as bytes (at most [`BLOCK`]); returns its dynamic offset.
    pub fn push_bytes(&mut self, bytes: &[u8]) -> Result<u32, crate::device::context::GpuError> {
        let off = self.data.len() as u64;
        if bytes.len() as u64 > BLOCK {
            return Err(crate::device::context::GpuError::TooLarge(format!(
                "a uniform block of {} bytes (at most {BLOCK})",
                bytes.len()
            )));
        }
        if off + self.align > ARENA_BYTES {
            return Err(crate::device::context::GpuError::TooLarge(
                "the pipeline has too many passes for one frame's uniform arena".into(),
            ));
        }
        self.data.extend_from_slice(bytes);
        self.data.resize((off + self.align) as usize, 0);
        Ok(off as u32)
    }

    pub fn upload(&self, queue: &wgpu::Queue) {
        if !self.data.is_empty() {
            queue.write_buffer(&self.buffer, 0, &self.data);
        }
    }
}

/// A compute pipeline with its bind group layout.
pub(crate) struct Pass {
    pub bgl: BindGroupLayout,
    pub pipeline: wgpu::ComputePipeline,
}

impl Pass {
    pub fn new(device: &Device, m: &ShaderModule, entry: &str, slots: &[Slot]) -> Pass {
        let bgl = layout(device, m.name, slots, ShaderStages::COMPUTE);
        let module = module(device, m);
        let pipeline = compute(device, &module, entry, &bgl);
        Pass { bgl, pipeline }
    }

    pub fn bind(&self, device: &Device, res: &[Res]) -> wgpu::BindGroup {
        bind(device, "pass", &self.bgl, res)
    }
}
