//! A cloud uploaded to the GPU: positions, normals and albedo in chunks that each fit one
//! storage binding (128 MiB on lavapipe), so clouds of any size project chunk by chunk.

use super::context::{GpuContext, GpuError};
use crate::cpu::shade::intensity_grey;
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
}

pub struct GpuCloud {
    /// Distinguishes uploads (bind-group caches key on it).
    pub key: u64,
    pub len: usize,
    pub origin: DVec3,
    pub spacing: f32,
    pub has_normals: bool,
    pub has_albedo: bool,
    pub chunks: Vec<Chunk>,
    /// Bound where a chunk has no normals or albedo (never read then).
    pub dummy: wgpu::Buffer,
}

static NEXT_KEY: AtomicU64 = AtomicU64::new(1);

/// Bytes per point of the largest per-point buffer (positions and normals, 3 × f32).
const STRIDE: u64 = 12;

impl GpuCloud {
    pub fn upload(ctx: &GpuContext, cloud: &PreparedCloud) -> Result<GpuCloud, GpuError> {
        let c = &cloud.cloud;
        if c.len() > u32::MAX as usize - 1 {
            return Err(GpuError::TooLarge(format!(
                "{} points; the GPU backend indexes points with 32 bits",
                c.len()
            )));
        }
        let binding = ctx
            .limits
            .max_storage_buffer_binding_size
            .min(ctx.limits.max_buffer_size);
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
            });
            base = end;
        }
        let dummy = init("dummy", &[0u8; 16]);
        ctx.take_errors()?;
        Ok(GpuCloud {
            key: NEXT_KEY.fetch_add(1, Ordering::Relaxed),
            len: c.len(),
            origin: c.origin,
            spacing: cloud.spacing,
            has_normals: c.normals.is_some(),
            has_albedo: albedo.is_some(),
            chunks,
            dummy,
        })
    }
}
