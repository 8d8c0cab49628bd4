//! A cloud uploaded to the GPU: positions, normals and albedo in chunks that each fit one
//! storage binding (128 MiB on lavapipe), so clouds of any size project chunk by chunk.

use crate::device::context::{GpuContext, GpuError};
use crate::srgb::intensity_grey;
use crate::PreparedCloud;
use glam::DVec3;
use std::sync::atomic::{AtomicU64, Ordering};
use wgpu::util::DeviceExt;
use wgpu::BufferUsages;

pub struct Chunk {
    /// Index of the first point in the whole cloud.
    pub base: u32,
    pub count: u32,
    pub positions: wgpu::Buffer,
    pub normals: Option<wgpu::Buffer>,
    /// sRGB 8-bit albedo per point packed r | g << 8 | b << 16 (colours, or intensity as grey).
    pub albedo: Option<wgpu::Buffer>,
    /// Object index | 8-bit opacity << 8, per point (absent: object 0, opaque).
    pub style: Option<wgpu::Buffer>,
    /// Shadow texture sums per point, two u32 words each (lights 0 | 1 << 16, 2 | 3 << 16;
    /// absent: no shadow texture).
    pub lit: Option<wgpu::Buffer>,
    /// A coloured shadow texture's red and blue sums, four words per point (light l:
    /// red | blue << 16; absent: grey).
    pub lit_rb: Option<wgpu::Buffer>,
}

pub struct GpuCloud {
    /// Distinguishes uploads (bind-group caches key on it).
    pub key: u64,
    pub len: usize,
    pub origin: DVec3,
    pub spacing: f32,
    pub has_normals: bool,
    pub has_albedo: bool,
    /// Material terms by object, for a scene (None: the pipeline's material).
    pub materials: Option<Vec<crate::material::Terms>>,
    /// Optics by object, for a scene (None: the frame's).
    pub optics: Option<Vec<crate::material::Optics>>,
    /// Whether any point is opaque (transparent splats refract them, `transparent`).
    pub has_opaque: bool,
    /// Samples per light of the uploaded shadow texture ([0; 4]: none).
    pub samples: [u32; 4],
    /// The mean opacity (see [`PreparedCloud::mean_alpha`]).
    pub mean_alpha: f32,
    /// The [`PreparedCloud::lit_key`] of the shadow texture uploaded.
    pub lit_key: u64,
    pub chunks: Vec<Chunk>,
    /// Bound where a chunk has no normals or albedo (never read then).
    pub dummy: wgpu::Buffer,
    /// Bound writable where a grey shadow texture has no red and blue sums (never written
    /// then; apart from `dummy`, which may be bound read-only in the same pass).
    pub dummy_rw: wgpu::Buffer,
    /// Depth peeling: one bit per point, set once a layer's test has peeled it (see
    /// `passes::project::cpu::PeelTest::done`); cleared by the first layer.
    pub done: wgpu::Buffer,
    /// Translucent light views: one bit per point, set once a light layer marked it (see
    /// `passes::shadow_texture::cpu::Transmit`).
    pub marked: wgpu::Buffer,
}

static NEXT_KEY: AtomicU64 = AtomicU64::new(1);

/// Bytes per point of the largest per-point buffer (a coloured shadow texture's red and
/// blue sums, 4 × u32).
const STRIDE: u64 = 16;

impl GpuCloud {
    pub fn upload(ctx: &GpuContext, cloud: &PreparedCloud) -> Result<GpuCloud, GpuError> {
        let c = &cloud.cloud;
        if c.len() > u32::MAX as usize - 1 {
            return Err(GpuError::TooLarge(format!(
                "{} points; the GPU backend indexes points with 32 bits",
                c.len()
            )));
        }
        let binding = ctx.binding_limit();
        let mut per = (binding / STRIDE) as usize;
        if let Some(m) = ctx.options.max_chunk_points {
            per = per.min(m);
        }
        let per = per.max(1);
        let albedo: Option<Vec<u32>> = if let Some(col) = &c.colors {
            Some(
                col.iter()
                    .map(|p| p[0] as u32 | (p[1] as u32) << 8 | (p[2] as u32) << 16)
                    .collect(),
            )
        } else if let (Some(i), Some(s)) = (&c.intensity, cloud.intensity_scale) {
            Some(
                i.iter()
                    .map(|&t| intensity_grey(t, s) as u32 * 0x01_01_01)
                    .collect(),
            )
        } else {
            None
        };
        let style: Option<Vec<u32>> = if cloud.objects.is_some() || cloud.alpha.is_some() {
            Some(
                (0..c.len())
                    .map(|i| {
                        let o = cloud.objects.as_ref().map_or(0, |o| o.index[i] as u32);
                        let a = cloud.alpha.as_ref().map_or(255, |a| a[i] as u32);
                        o | a << 8
                    })
                    .collect(),
            )
        } else {
            None
        };
        let d = &ctx.device;
        let usage = BufferUsages::STORAGE | BufferUsages::VERTEX;
        let init = |label: &str, bytes: &[u8]| {
            d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage,
            })
        };
        let mut chunks = Vec::new();
        let mut base = 0usize;
        while base < c.len() {
            let end = (base + per).min(c.len());
            chunks.push(Chunk {
                base: base as u32,
                count: (end - base) as u32,
                positions: init("positions", bytemuck::cast_slice(&c.positions[base..end])),
                normals: c
                    .normals
                    .as_ref()
                    .map(|n| init("normals", bytemuck::cast_slice(&n[base..end]))),
                albedo: albedo
                    .as_ref()
                    .map(|a| init("albedo", bytemuck::cast_slice(&a[base..end]))),
                style: style
                    .as_ref()
                    .map(|a| init("style", bytemuck::cast_slice(&a[base..end]))),
                lit: None,
                lit_rb: None,
            });
            base = end;
        }
        let dummy = init("dummy", &[0u8; 16]);
        let dummy_rw = init("dummy (writable)", &[0u8; 16]);
        let done = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("peeled points"),
            size: (c.len().div_ceil(32).max(1) * 4) as u64,
            usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let marked = d.create_buffer(&wgpu::BufferDescriptor {
            label: Some("light-marked points"),
            size: (c.len().div_ceil(32).max(1) * 4) as u64,
            usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        ctx.take_errors()?;
        let mut up = GpuCloud {
            key: NEXT_KEY.fetch_add(1, Ordering::Relaxed),
            len: c.len(),
            origin: c.origin,
            spacing: cloud.spacing,
            has_normals: c.normals.is_some(),
            has_albedo: albedo.is_some(),
            materials: cloud
                .objects
                .as_ref()
                .map(|_| cloud.terms(&crate::Pipeline::default())),
            has_opaque: crate::passes::splat::transparent::any_opaque(cloud.alpha.as_deref()),
            optics: cloud
                .objects
                .as_ref()
                .map(|t| t.materials.iter().map(|m| m.optics).collect()),
            samples: [0; 4],
            mean_alpha: cloud.mean_alpha,
            lit_key: 0,
            chunks,
            dummy,
            dummy_rw,
            done,
            marked,
        };
        up.set_lit(ctx, cloud.lit(), cloud.lit_key)?;
        Ok(up)
    }

    /// Uploads a shadow texture's counts (or drops them), creating the per-chunk buffers the
    /// first time (a new key then, so bind groups are made anew).
    pub fn set_lit(
        &mut self,
        ctx: &GpuContext,
        lit: Option<&crate::LitTexture>,
        lit_key: u64,
    ) -> Result<(), GpuError> {
        match lit {
            Some(l) => {
                self.write_counts(ctx, &l.counts)?;
                self.write_rb(ctx, l.rb.as_deref())?;
                self.samples = l.samples;
            }
            None => {
                if self
                    .chunks
                    .iter()
                    .any(|c| c.lit.is_some() || c.lit_rb.is_some())
                {
                    for c in &mut self.chunks {
                        c.lit = None;
                        c.lit_rb = None;
                    }
                    self.key = NEXT_KEY.fetch_add(1, Ordering::Relaxed);
                }
                self.samples = [0; 4];
            }
        }
        self.lit_key = lit_key;
        Ok(())
    }

    /// Writes a coloured texture's red and blue sums into the chunks' buffers (made when
    /// missing), or drops them for a grey texture.
    pub fn write_rb(&mut self, ctx: &GpuContext, rb: Option<&[[u16; 8]]>) -> Result<(), GpuError> {
        let Some(rb) = rb else {
            if self.chunks.iter().any(|c| c.lit_rb.is_some()) {
                for c in &mut self.chunks {
                    c.lit_rb = None;
                }
                self.key = NEXT_KEY.fetch_add(1, Ordering::Relaxed);
            }
            return Ok(());
        };
        self.write_per_point(ctx, rb, "lit red and blue", |c| &mut c.lit_rb)
    }

    /// Writes per-point lit sums into the chunks' buffers (made when missing).
    pub fn write_counts(&mut self, ctx: &GpuContext, counts: &[[u16; 4]]) -> Result<(), GpuError> {
        self.write_per_point(ctx, counts, "lit", |c| &mut c.lit)
    }

    /// Writes one value per point into each chunk's buffer that `slot` picks, making the
    /// buffers the first time (a new key then, so bind groups are made anew).
    fn write_per_point<T: bytemuck::Pod>(
        &mut self,
        ctx: &GpuContext,
        values: &[T],
        label: &'static str,
        slot: impl Fn(&mut Chunk) -> &mut Option<wgpu::Buffer>,
    ) -> Result<(), GpuError> {
        if values.len() != self.len {
            return Err(GpuError::TooLarge(format!(
                "{label} for {} points, the cloud has {}",
                values.len(),
                self.len
            )));
        }
        let mut made = false;
        for c in &mut self.chunks {
            let data = bytemuck::cast_slice(&values[c.base as usize..(c.base + c.count) as usize]);
            let buf = slot(c);
            match buf {
                Some(b) => ctx.queue.write_buffer(b, 0, data),
                None => {
                    *buf = Some(
                        ctx.device
                            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                                label: Some(label),
                                contents: data,
                                usage: BufferUsages::STORAGE
                                    | BufferUsages::COPY_SRC
                                    | BufferUsages::COPY_DST,
                            }),
                    );
                    made = true;
                }
            }
        }
        if made {
            self.key = NEXT_KEY.fetch_add(1, Ordering::Relaxed);
        }
        ctx.take_errors()
    }
}
