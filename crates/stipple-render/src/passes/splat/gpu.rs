//! splat on the GPU (twin of `cpu.rs`; shader `splat.wgsl`): the Voronoi mode as four
//! dispatches over the points, one thread per splat, with 32-bit atomics only (so it runs on
//! every adapter, lavapipe included). The pass owns its pipelines, its per-pixel scratch
//! buffers and its per-point radius buffers; the frame schedule (`gpu/renderer.rs`) only
//! calls [`SplatGpu::record`].

use crate::gpu::cloud::GpuCloud;
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::shaders::SPLAT_MODULE;
use crate::gpu::util::{self, Arena, Res, DYNAMIC, READ, UNIFORM, WRITE};
use wgpu::{Buffer, ComputePipeline, ShaderStages};

/// Splats per workgroup (splat.wgsl's workgroup size).
const PER_GROUP: u32 = 64;

/// Keep in sync with `SplatBlock` in splat.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct SplatBlock {
    pub base: u32,
    pub count: u32,
    pub has_normals: u32,
    pub epsilon: f32,
    pub scale: f32,
    pub pad: [u32; 3],
}

const _: () = assert!(std::mem::size_of::<SplatBlock>() == 32);

struct Scratch {
    pixels: u64,
    z: Buffer,
    q: Buffer,
    i: Buffer,
}

pub(crate) struct SplatGpu {
    bgl: wgpu::BindGroupLayout,
    depth: ComputePipeline,
    select: ComputePipeline,
    index: ComputePipeline,
    write: ComputePipeline,
    clear: ComputePipeline,
    scratch: Option<Scratch>,
    /// Radii per chunk of the cloud uploaded last (keyed by its upload key).
    radii: Option<(u64, Vec<Buffer>)>,
}

impl SplatGpu {
    pub fn new(ctx: &GpuContext) -> SplatGpu {
        let d = &ctx.device;
        let bgl = util::layout(
            d,
            "splat",
            &[
                UNIFORM, DYNAMIC, READ, READ, READ, WRITE, WRITE, WRITE, WRITE, WRITE,
            ],
            ShaderStages::COMPUTE,
        );
        let m = util::module(d, &SPLAT_MODULE);
        let p = |e: &str| util::compute(d, &m, e, &bgl);
        SplatGpu {
            depth: p("splat_depth"),
            select: p("splat_select"),
            index: p("splat_index"),
            write: p("splat_write"),
            clear: p("splat_clear"),
            bgl,
            scratch: None,
            radii: None,
        }
    }

    /// Uploads the cloud's radii (unscaled) unless this upload already has them.
    pub fn set_radii(
        &mut self,
        ctx: &GpuContext,
        cloud: &GpuCloud,
        radii: &[f32],
    ) -> Result<(), GpuError> {
        if self.radii.as_ref().map(|r| r.0) == Some(cloud.key) {
            return Ok(());
        }
        if radii.len() != cloud.len {
            return Err(GpuError::Wgpu(format!(
                "splat: {} radii for a cloud of {} points",
                radii.len(),
                cloud.len
            )));
        }
        let bufs = cloud
            .chunks
            .iter()
            .map(|c| {
                util::storage_init(
                    &ctx.device,
                    "splat radii",
                    bytemuck::cast_slice(&radii[c.base as usize..(c.base + c.count) as usize]),
                )
            })
            .collect();
        self.radii = Some((cloud.key, bufs));
        ctx.take_errors()
    }

    /// Records the pass: clears, then the five dispatches, into `pass` (made by `begin`
    /// after the clears). `depth_out` and `id_out` receive the G-buffer.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &mut self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        arena: &mut Arena,
        view: &Buffer,
        cloud: &GpuCloud,
        (width, height): (u32, u32),
        (epsilon, scale): (f32, f32),
        outputs: (&Buffer, &Buffer),
        begin: &mut dyn FnMut(&mut wgpu::CommandEncoder) -> wgpu::ComputePass<'static>,
    ) -> Result<(), GpuError> {
        let d = &ctx.device;
        let pixels = width as u64 * height as u64;
        if self.scratch.as_ref().map(|s| s.pixels) != Some(pixels) {
            self.scratch = Some(Scratch {
                pixels,
                z: util::storage(d, "splat z", 4 * pixels),
                q: util::storage(d, "splat q", 4 * pixels),
                i: util::storage(d, "splat id", 4 * pixels),
            });
        }
        let radii = match &self.radii {
            Some((k, r)) if *k == cloud.key => r,
            _ => {
                return Err(GpuError::Wgpu(
                    "splat: the cloud's radii were not uploaded".into(),
                ))
            }
        };
        let s = self.scratch.as_ref().expect("made above");
        enc.clear_buffer(&s.z, 0, None);
        enc.clear_buffer(&s.q, 0, None);
        enc.clear_buffer(&s.i, 0, None);
        let size = std::mem::size_of::<SplatBlock>() as u64;
        let mut groups = Vec::new();
        for (c, r) in cloud.chunks.iter().zip(radii) {
            let off = arena.push(&SplatBlock {
                base: c.base,
                count: c.count,
                has_normals: c.normals.is_some() as u32,
                epsilon,
                scale,
                pad: [0; 3],
            })?;
            let bg = util::bind(
                d,
                "splat",
                &self.bgl,
                &[
                    Res::Buf(view),
                    Res::Arena(&arena.buffer, size),
                    Res::Buf(&c.positions),
                    Res::Buf(c.normals.as_ref().unwrap_or(&cloud.dummy)),
                    Res::Buf(r),
                    Res::Buf(&s.z),
                    Res::Buf(&s.q),
                    Res::Buf(&s.i),
                    Res::Buf(outputs.0),
                    Res::Buf(outputs.1),
                ],
            );
            groups.push((bg, off, ctx.grid(c.count.div_ceil(PER_GROUP))));
        }
        let mut pass = begin(enc);
        if let Some((bg, off, _)) = groups.first() {
            pass.set_pipeline(&self.clear);
            pass.set_bind_group(0, bg, &[*off]);
            let (gx, gy) = ctx.grid(pixels.div_ceil(256) as u32);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        for p in [&self.depth, &self.select, &self.index, &self.write] {
            pass.set_pipeline(p);
            for (bg, off, (gx, gy)) in &groups {
                pass.set_bind_group(0, bg, &[*off]);
                pass.dispatch_workgroups(*gx, *gy, 1);
            }
        }
        Ok(())
    }
}
