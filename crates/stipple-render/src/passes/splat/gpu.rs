//! splat on the GPU (twin of `cpu.rs`; shader `splat.wgsl`): the Voronoi mode as four
//! dispatches over the points, one thread per splat, with 32-bit atomics only (so it runs on
//! every adapter, lavapipe included); blend mode adds an accumulation dispatch over the
//! points (fixed-point sums with integer atomics) and a per-pixel resolve that runs inside
//! shade, after its gather. The pass owns its pipelines, its per-pixel scratch buffers and
//! its per-point shape buffers; the frame schedule (`gpu/renderer.rs`) only calls
//! `SplatGpu::record` and `SplatGpu::record_resolve`.

use crate::device::cloud::GpuCloud;

use crate::device::context::{GpuContext, GpuError};
use crate::device::shaders::SPLAT_MODULE;
use crate::device::util::{self, Arena, Res, Slot, DYNAMIC, READ, UNIFORM, WRITE};
use wgpu::util::DeviceExt;
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
    /// 1: the shapes buffer holds bent splats (else flat discs).
    pub has_shapes: u32,
    /// 1: the chunk has per-point albedo (blend mode).
    pub has_albedo: u32,
    /// Deferred blending: the number of groups and the depth quantisation (`DepthQuant`).
    pub groups: u32,
    pub qmin: f32,
    pub qscale: f32,
    /// 0 Voronoi, 1 blend, 2 deferred.
    pub mode: u32,
    pub pad: u32,
}

const _: () = assert!(std::mem::size_of::<SplatBlock>() == 48);

struct Scratch {
    pixels: u64,
    z: Buffer,
    q: Buffer,
    i: Buffer,
    /// Blend sums, 8 per pixel (made on the first blend frame).
    acc: Option<Buffer>,
    /// Deferred blending's group images (key, id), K per pixel, and their K.
    group_images: Option<(usize, Buffer, Buffer)>,
}

/// Targets of the blend mode's resolve: shade's per-pixel position/albedo and normal.
pub(crate) struct BlendTargets<'a> {
    pub attr_pos: &'a Buffer,
    pub attr_normal: &'a Buffer,
    /// Shade's gathered styles (a pinhole takes its neighbour's).
    pub attr_style: &'a Buffer,
    pub to_linear: &'a Buffer,
}

pub(crate) struct SplatGpu {
    bgl: wgpu::BindGroupLayout,
    depth: ComputePipeline,
    select: ComputePipeline,
    index: ComputePipeline,
    write: ComputePipeline,
    clear: ComputePipeline,
    accum_bgl: wgpu::BindGroupLayout,
    accum: ComputePipeline,
    resolve_bgl: wgpu::BindGroupLayout,
    resolve: ComputePipeline,
    /// Pinholes filled after the resolve (`cpu::fill_pinholes`).
    pinholes: ComputePipeline,
    /// The resolve of the blend frame recorded last, until shade runs it.
    pending: Option<(wgpu::BindGroup, u32, (u32, u32))>,
    group_bgl: wgpu::BindGroupLayout,
    group_key: ComputePipeline,
    group_id: ComputePipeline,
    composite_bgl: wgpu::BindGroupLayout,
    composite: ComputePipeline,
    /// The groups of the cloud uploaded last: (upload key, c bits, packed groups, K).
    groups: Option<(u64, u32, Buffer, usize)>,
    /// The sRGB → linear table as a uniform (the composite's ninth buffer would exceed the
    /// eight storage bindings every adapter has).
    lin: Buffer,
    scratch: Option<Scratch>,
    /// (radius, A, B, C) per point, per chunk of the cloud uploaded last (keyed by its
    /// upload key), and whether it has shapes.
    radii: Option<(u64, Vec<Buffer>, bool)>,
    /// Sorted splats: the bucket sort's buffers and the per-point splats (four vec4 each)
    /// of the cloud uploaded last (keyed by its upload key), made on its first sorted frame.
    sorted: Option<(u64, crate::passes::bucket_sort::gpu::SortBuffers, Buffer)>,
    /// Transparent splats: the group masks of the cloud uploaded last (upload key, c bits,
    /// masks, K), and the K images per pixel kept between dispatches (its size in bytes).
    masks: Option<(u64, (u32, crate::CoverageMethod), Buffer, usize)>,
    group_acc: Option<(u64, Buffer)>,
    /// Sorted and transparent splats' per-tile lists (sorted.wgsl `bin_cnt`, `bin_pairs`)
    /// with their sizes in bytes, kept between frames of one size and cloud size.
    bins: Option<((u64, u64), Buffer, Buffer)>,
    /// Transparent splats: the environment's texels (vec4 each; one dummy texel for the
    /// sky), kept while the frame's environment is the same one.
    env: Option<(std::sync::Arc<crate::env::Environment>, Buffer)>,
}

impl SplatGpu {
    /// Makes the sorted splats' buffers for `cloud` unless they are there already (they are
    /// kept from frame to frame).
    pub(crate) fn make_sorted_buffers(
        &mut self,
        ctx: &GpuContext,
        cloud: &GpuCloud,
    ) -> Result<(), GpuError> {
        if self.sorted.as_ref().is_some_and(|s| s.0 == cloud.key) {
            return Ok(());
        }
        self.sorted = None;
        let bytes = 64 * cloud.len as u64;
        let limit = ctx.binding_limit();
        if bytes > limit {
            return Err(GpuError::TooLarge(format!(
                "sorted splats of {} points: their per-point buffer of {} MiB exceeds the \
                 device's binding limit of {} MiB",
                cloud.len,
                bytes >> 20,
                limit >> 20
            )));
        }
        let sort = crate::passes::bucket_sort::gpu::SortBuffers::new(ctx, cloud)?;
        let splats = util::storage(&ctx.device, "sorted splats", bytes);
        self.sorted = Some((cloud.key, sort, splats));
        Ok(())
    }

    /// The sorted splats' buffers of `cloud` (see [`SplatGpu::make_sorted_buffers`]).
    pub(crate) fn sorted_buffers(
        &self,
        cloud: &GpuCloud,
    ) -> Result<(&crate::passes::bucket_sort::gpu::SortBuffers, &Buffer), GpuError> {
        match &self.sorted {
            Some((k, s, b)) if *k == cloud.key => Ok((s, b)),
            _ => Err(GpuError::Wgpu(
                "sorted splats: the cloud's buffers were not made".into(),
            )),
        }
    }

    /// The uploaded per-chunk shape buffers of `cloud` ((radius, bend…), clip planes, their
    /// bends: four vec4 per point) and whether they hold shapes.
    pub(crate) fn shapes(&self, cloud: &GpuCloud) -> Result<(&[Buffer], bool), GpuError> {
        match &self.radii {
            Some((k, r, s)) if *k == cloud.key => Ok((r, *s)),
            _ => Err(GpuError::Wgpu(
                "splat: the cloud's radii were not uploaded".into(),
            )),
        }
    }

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
        const NO: Slot = Slot::Skip;
        let accum_bgl = util::layout(
            d,
            "splat accum",
            &[
                UNIFORM, DYNAMIC, READ, READ, READ, WRITE, NO, WRITE, NO, NO, READ, READ, WRITE,
            ],
            ShaderStages::COMPUTE,
        );
        let resolve_bgl = util::layout(
            d,
            "splat resolve",
            &[
                UNIFORM, DYNAMIC, NO, NO, NO, WRITE, NO, NO, WRITE, WRITE, NO, NO, WRITE, WRITE,
                WRITE, NO, NO, NO, NO, WRITE,
            ],
            ShaderStages::COMPUTE,
        );
        let group_bgl = util::layout(
            d,
            "splat groups",
            &[
                UNIFORM, DYNAMIC, READ, READ, READ, NO, NO, NO, NO, NO, NO, NO, NO, NO, NO, READ,
                WRITE, WRITE,
            ],
            ShaderStages::COMPUTE,
        );
        let composite_bgl = util::layout(
            d,
            "splat composite",
            &[
                UNIFORM, DYNAMIC, READ, READ, READ, NO, NO, NO, WRITE, WRITE, READ, NO, WRITE, NO,
                NO, NO, NO, WRITE, UNIFORM,
            ],
            ShaderStages::COMPUTE,
        );
        let table = crate::srgb::srgb_to_linear_table();
        SplatGpu {
            group_key: util::compute(d, &m, "splat_group_key", &group_bgl),
            group_id: util::compute(d, &m, "splat_group_id", &group_bgl),
            composite: util::compute(d, &m, "splat_group_composite", &composite_bgl),
            group_bgl,
            composite_bgl,
            groups: None,
            lin: wgpu::util::DeviceExt::create_buffer_init(
                d,
                &wgpu::util::BufferInitDescriptor {
                    label: Some("splat srgb to linear"),
                    contents: bytemuck::cast_slice(&table),
                    usage: wgpu::BufferUsages::UNIFORM,
                },
            ),
            accum: util::compute(d, &m, "splat_accum", &accum_bgl),
            resolve: util::compute(d, &m, "splat_resolve", &resolve_bgl),
            pinholes: util::compute(d, &m, "splat_pinholes", &resolve_bgl),
            accum_bgl,
            resolve_bgl,
            pending: None,
            depth: p("splat_depth"),
            select: p("splat_select"),
            index: p("splat_index"),
            write: p("splat_write"),
            clear: p("splat_clear"),
            bgl,
            scratch: None,
            radii: None,
            sorted: None,
            masks: None,
            group_acc: None,
            bins: None,
            env: None,
        }
    }

    /// Uploads the cloud's radii (unscaled) and shapes (see `Disc`) unless this upload
    /// already has them.
    pub fn set_shapes(
        &mut self,
        ctx: &GpuContext,
        cloud: &GpuCloud,
        radii: &[f32],
        shapes: Option<&[crate::passes::splat::SplatShape]>,
    ) -> Result<(), GpuError> {
        if self.radii.as_ref().map(|r| r.0) == Some(cloud.key) {
            return Ok(());
        }
        if radii.len() != cloud.len || shapes.is_some_and(|s| s.len() != cloud.len) {
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
                let range = c.base as usize..(c.base + c.count) as usize;
                // Four vec4 per point: (r, A, B, C), the clip planes, their bends into their
                // rims (κ₀, s₀, κ₁, s₁).
                let packed: Vec<[f32; 4]> = range
                    .flat_map(|i| {
                        let s = shapes.map_or_else(Default::default, |s| s[i]);
                        let [a, b, k] = s.bend;
                        let [[k0, s0], [k1, s1]] = s.curve;
                        [[radii[i], a, b, k], s.clip[0], s.clip[1], [k0, s0, k1, s1]]
                    })
                    .collect();
                util::storage_init(&ctx.device, "splat shapes", bytemuck::cast_slice(&packed))
            })
            .collect();
        self.radii = Some((cloud.key, bufs, shapes.is_some()));
        ctx.take_errors()
    }

    /// Uploads the cloud's splat groups (deferred blending) unless this upload has them.
    pub fn set_groups(
        &mut self,
        ctx: &GpuContext,
        cloud: &GpuCloud,
        g: &stipple_core::grouping::Grouping,
    ) -> Result<(), GpuError> {
        if self
            .groups
            .as_ref()
            .is_some_and(|x| x.0 == cloud.key && x.1 == g.c.to_bits())
        {
            return Ok(());
        }
        if cloud.chunks.len() != 1 {
            return Err(GpuError::Unsupported(format!(
                "deferred splat blending on the GPU takes clouds that fit one buffer binding; \
                 this one has {} points in {} chunks (--splat blend, or --backend cpu)",
                cloud.len,
                cloud.chunks.len()
            )));
        }
        if g.group.len() != cloud.len {
            return Err(GpuError::Wgpu(format!(
                "splat: {} groups for a cloud of {} points",
                g.group.len(),
                cloud.len
            )));
        }
        let mut packed = vec![0u32; g.group.len().div_ceil(4).max(1)];
        for (i, &x) in g.group.iter().enumerate() {
            packed[i / 4] |= (x as u32) << (8 * (i % 4));
        }
        let buf = util::storage_init(&ctx.device, "splat groups", bytemuck::cast_slice(&packed));
        self.groups = Some((cloud.key, g.c.to_bits(), buf, g.groups));
        ctx.take_errors()
    }

    /// Uploads an uploaded cloud's transparent-splat group masks
    /// (`PreparedCloud::coverage`), unless they are there.
    pub fn set_masks(
        &mut self,
        ctx: &GpuContext,
        cloud: &GpuCloud,
        (c, method): (f32, crate::CoverageMethod),
        cov: &crate::Coverage,
    ) -> Result<(), GpuError> {
        if self
            .masks
            .as_ref()
            .is_some_and(|x| x.0 == cloud.key && x.1 == (c.to_bits(), method))
        {
            return Ok(());
        }
        if cov.masks.len() != cloud.len {
            return Err(GpuError::Wgpu(format!(
                "splat: {} group masks for a cloud of {} points",
                cov.masks.len(),
                cloud.len
            )));
        }
        let data: &[u32] = if cov.masks.is_empty() {
            &[0]
        } else {
            &cov.masks
        };
        let buf = util::storage_init(&ctx.device, "transparent masks", bytemuck::cast_slice(data));
        self.masks = Some((cloud.key, (c.to_bits(), method), buf, cov.groups));
        ctx.take_errors()
    }

    /// The transparent splats' masks of `cloud` and its K.
    pub(crate) fn masks(&self, cloud: &GpuCloud) -> Result<(&Buffer, usize), GpuError> {
        match &self.masks {
            Some((k, _, b, g)) if *k == cloud.key => Ok((b, *g)),
            _ => Err(GpuError::Wgpu(
                "transparent splats: the cloud's group masks were not uploaded".into(),
            )),
        }
    }

    /// The K images per pixel of transparent splats (kept between frames of one size).
    pub(crate) fn group_acc(&mut self, ctx: &GpuContext, bytes: u64) -> Result<&Buffer, GpuError> {
        let limit = ctx.binding_limit();
        if bytes > limit {
            return Err(GpuError::TooLarge(format!(
                "transparent splats: the group images need {} MiB, more than the device's \
                 binding limit of {} MiB (a smaller image, or --splat-c lower for fewer groups)",
                bytes >> 20,
                limit >> 20
            )));
        }
        if self.group_acc.as_ref().map(|x| x.0) != Some(bytes) {
            self.group_acc = Some((
                bytes,
                util::storage(&ctx.device, "transparent images", bytes),
            ));
        }
        Ok(&self.group_acc.as_ref().expect("made above").1)
    }

    /// The per-tile lists' buffers (counts and offsets, entries) of these sizes in bytes
    /// (kept between frames of the same sizes).
    pub(crate) fn bins(
        &mut self,
        ctx: &GpuContext,
        (cnt, pairs): (u64, u64),
    ) -> (&Buffer, &Buffer) {
        if self.bins.as_ref().map(|b| b.0) != Some((cnt, pairs)) {
            self.bins = Some((
                (cnt, pairs),
                util::storage(&ctx.device, "splat tile counts", cnt),
                util::storage(&ctx.device, "splat tile lists", pairs),
            ));
        }
        let b = self.bins.as_ref().expect("made above");
        (&b.1, &b.2)
    }

    /// The environment's texels on the device (uploaded when the environment changes), and
    /// the image's size (0 × 0: the sky, or none).
    pub(crate) fn env_texels(
        &mut self,
        ctx: &GpuContext,
        env: Option<&std::sync::Arc<crate::env::Environment>>,
    ) -> Result<(&Buffer, u32, u32), GpuError> {
        use crate::env::Environment;
        // The sky and no environment both bind one dummy texel.
        let image = |e: &Environment| matches!(e, Environment::Image { .. });
        let same = match (&self.env, env) {
            (Some((a, _)), Some(b)) if image(b) => std::sync::Arc::ptr_eq(a, b),
            (Some((a, _)), _) => !image(a),
            (None, _) => false,
        };
        let (w, h) = match env.map(|e| &**e) {
            Some(Environment::Image { width, height, .. }) => (*width, *height),
            _ => (0, 0),
        };
        if !same {
            let texels: Vec<[f32; 4]> = match env.map(|e| &**e) {
                Some(Environment::Image { texels, .. }) => {
                    texels.iter().map(|t| [t[0], t[1], t[2], 0.0]).collect()
                }
                _ => vec![[0.0; 4]],
            };
            let bytes = 16 * texels.len() as u64;
            let limit = ctx.binding_limit();
            if bytes > limit {
                return Err(GpuError::TooLarge(format!(
                    "the environment image's {} MiB exceed the device's binding limit of {} MiB",
                    bytes >> 20,
                    limit >> 20
                )));
            }
            let buf = ctx
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("environment"),
                    contents: bytemuck::cast_slice(&texels),
                    usage: wgpu::BufferUsages::STORAGE,
                });
            let key = env
                .cloned()
                .unwrap_or_else(|| std::sync::Arc::new(Environment::Sky));
            self.env = Some((key, buf));
        }
        Ok((&self.env.as_ref().expect("made above").1, w, h))
    }

    /// Records the pass: clears, then the five dispatches (six with `blend`), into `pass`
    /// (made by `begin` after the clears). `depth_out` and `id_out` receive the G-buffer; with
    /// `blend` the resolve waits for [`SplatGpu::record_resolve`].
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
        (mode, quant): (crate::SplatMode, Option<super::DepthQuant>),
        blend: Option<BlendTargets>,
        begin: &mut dyn FnMut(&mut wgpu::CommandEncoder) -> wgpu::ComputePass<'static>,
    ) -> Result<(), GpuError> {
        let d = &ctx.device;
        let pixels = width as u64 * height as u64;
        self.pending = None;
        let deferred = mode == crate::SplatMode::Deferred;
        let k_groups = match (&self.groups, deferred) {
            (Some(g), true) if g.0 == cloud.key => g.3,
            (_, true) => {
                return Err(GpuError::Wgpu(
                    "splat: the cloud's groups were not uploaded".into(),
                ))
            }
            _ => 0,
        };
        let max = ctx.binding_limit();
        if self.scratch.as_ref().map(|s| s.pixels) != Some(pixels) {
            self.scratch = Some(Scratch {
                pixels,
                // Two per pixel: nearest over all fragments and over eye-facing ones.
                z: util::storage(d, "splat z", 8 * pixels),
                q: util::storage(d, "splat q", 4 * pixels),
                i: util::storage(d, "splat id", 4 * pixels),
                acc: None,
                group_images: None,
            });
        }
        if deferred {
            let bytes = 4 * k_groups as u64 * pixels;
            if bytes > max {
                return Err(GpuError::TooLarge(format!(
                    "deferred splat blending at {width}x{height} with {k_groups} groups needs \
                     {} MiB per group image set, more than this adapter binds ({} MiB): a \
                     smaller --splat-c, a smaller --size, --splat blend or --backend cpu",
                    bytes >> 20,
                    max >> 20
                )));
            }
            let s = self.scratch.as_mut().expect("made above");
            if s.group_images.as_ref().map(|g| g.0) != Some(k_groups) {
                s.group_images = Some((
                    k_groups,
                    util::storage(d, "splat group keys", bytes),
                    util::storage(d, "splat group ids", bytes),
                ));
            }
        }
        // Voronoi's per-pixel normals (the winner's bent splat at the hit) use the sums too;
        // where they do not fit, its pixels show their points' normals.
        let blend =
            blend.filter(|_| mode != crate::SplatMode::Voronoi || 4 * ACC_WORDS * pixels <= max);
        if blend.is_some() {
            let bytes = 4 * ACC_WORDS * pixels;
            if bytes > max {
                return Err(GpuError::TooLarge(format!(
                    "splat blending at {width}x{height} needs {} MiB of sums per frame, more \
                     than this adapter binds ({} MiB): --splat voronoi, a smaller --size or \
                     --backend cpu",
                    bytes >> 20,
                    max >> 20
                )));
            }
            let s = self.scratch.as_mut().expect("made above");
            if s.acc.is_none() {
                s.acc = Some(util::storage(d, "splat sums", bytes));
            }
        }
        let (radii, has_shapes) = match &self.radii {
            Some((k, r, s)) if *k == cloud.key => (r, *s),
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
        if let (Some(acc), true) = (&s.acc, blend.is_some()) {
            enc.clear_buffer(acc, 0, None);
        }
        if let (Some((_, gk, gi)), true) = (&s.group_images, deferred) {
            enc.clear_buffer(gk, 0, None);
            enc.clear_buffer(gi, 0, None);
        }
        let (qmin, qscale) = quant.map_or((0.0, 0.0), |q| (q.dmin, q.scale));
        let size = std::mem::size_of::<SplatBlock>() as u64;
        let mut groups = Vec::new();
        let mut accums = Vec::new();
        let mut deferred_groups = None;
        let mut first_off = 0;
        for (c, r) in cloud.chunks.iter().zip(radii) {
            let off = arena.push(&SplatBlock {
                base: c.base,
                count: c.count,
                has_normals: c.normals.is_some() as u32,
                epsilon,
                scale,
                has_shapes: (has_shapes && c.normals.is_some()) as u32,
                has_albedo: c.albedo.is_some() as u32,
                groups: k_groups as u32,
                qmin,
                qscale,
                mode: match mode {
                    crate::SplatMode::Voronoi => 0,
                    crate::SplatMode::Blend => 1,
                    crate::SplatMode::Deferred => 2,
                    crate::SplatMode::Sorted | crate::SplatMode::Transparent => {
                        return Err(GpuError::Wgpu(
                            "ordered splats are drawn by sorted_gpu, not the splat pass".into(),
                        ))
                    }
                },
                pad: 0,
            })?;
            if groups.is_empty() {
                first_off = off;
            }
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
            let grid = ctx.grid(c.count.div_ceil(PER_GROUP));
            if let (Some((_, gk, gi)), Some((_, _, gbuf, _)), Some(b), Some(acc), true) =
                (&s.group_images, &self.groups, &blend, &s.acc, deferred)
            {
                let gg = util::bind(
                    d,
                    "splat groups",
                    &self.group_bgl,
                    &[
                        Res::Buf(view),
                        Res::Arena(&arena.buffer, size),
                        Res::Buf(&c.positions),
                        Res::Buf(c.normals.as_ref().unwrap_or(&cloud.dummy)),
                        Res::Buf(r),
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Buf(gbuf),
                        Res::Buf(gk),
                        Res::Buf(gi),
                    ],
                );
                let cg = util::bind(
                    d,
                    "splat composite",
                    &self.composite_bgl,
                    &[
                        Res::Buf(view),
                        Res::Arena(&arena.buffer, size),
                        Res::Buf(&c.positions),
                        Res::Buf(c.normals.as_ref().unwrap_or(&cloud.dummy)),
                        Res::Buf(r),
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Buf(outputs.0),
                        Res::Buf(outputs.1),
                        Res::Buf(c.albedo.as_ref().unwrap_or(&cloud.dummy)),
                        Res::Skip,
                        Res::Buf(acc),
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Skip,
                        Res::Buf(gi),
                        Res::Buf(&self.lin),
                    ],
                );
                let _ = b;
                deferred_groups = Some((gg, cg, off, grid));
            } else if let (Some(b), Some(acc), false) = (&blend, &s.acc, deferred) {
                let ag = util::bind(
                    d,
                    "splat accum",
                    &self.accum_bgl,
                    &[
                        Res::Buf(view),
                        Res::Arena(&arena.buffer, size),
                        Res::Buf(&c.positions),
                        Res::Buf(c.normals.as_ref().unwrap_or(&cloud.dummy)),
                        Res::Buf(r),
                        Res::Buf(&s.z),
                        Res::Skip,
                        Res::Buf(&s.i),
                        Res::Skip,
                        Res::Skip,
                        Res::Buf(c.albedo.as_ref().unwrap_or(&cloud.dummy)),
                        Res::Buf(b.to_linear),
                        Res::Buf(acc),
                    ],
                );
                accums.push((ag, off, grid));
            }
            groups.push((bg, off, grid));
        }
        if let (Some(b), Some(acc)) = (&blend, &s.acc) {
            let rg = util::bind(
                d,
                "splat resolve",
                &self.resolve_bgl,
                &[
                    Res::Buf(view),
                    Res::Arena(&arena.buffer, size),
                    Res::Skip,
                    Res::Skip,
                    Res::Skip,
                    Res::Buf(&s.z),
                    Res::Skip,
                    Res::Skip,
                    Res::Buf(outputs.0),
                    Res::Buf(outputs.1),
                    Res::Skip,
                    Res::Skip,
                    Res::Buf(acc),
                    Res::Buf(b.attr_pos),
                    Res::Buf(b.attr_normal),
                    Res::Skip,
                    Res::Skip,
                    Res::Skip,
                    Res::Skip,
                    Res::Buf(b.attr_style),
                ],
            );
            self.pending = Some((rg, first_off, ctx.grid(pixels.div_ceil(256) as u32)));
        }
        let mut pass = begin(enc);
        if let Some((bg, off, _)) = groups.first() {
            pass.set_pipeline(&self.clear);
            pass.set_bind_group(0, bg, &[*off]);
            let (gx, gy) = ctx.grid(pixels.div_ceil(256) as u32);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        if let Some((gg, cg, off, (gx, gy))) = &deferred_groups {
            // One pass over the splats (the key; the id pass only settles equal keys), then
            // the compositing per pixel.
            for p in [&self.group_key, &self.group_id] {
                pass.set_pipeline(p);
                pass.set_bind_group(0, gg, &[*off]);
                pass.dispatch_workgroups(*gx, *gy, 1);
            }
            pass.set_pipeline(&self.composite);
            pass.set_bind_group(0, cg, &[*off]);
            pass.dispatch_workgroups(width.div_ceil(8), height.div_ceil(8), 1);
            return Ok(());
        }
        for p in [&self.depth, &self.select, &self.index, &self.write] {
            pass.set_pipeline(p);
            for (bg, off, (gx, gy)) in &groups {
                pass.set_bind_group(0, bg, &[*off]);
                pass.dispatch_workgroups(*gx, *gy, 1);
            }
        }
        pass.set_pipeline(&self.accum);
        for (bg, off, (gx, gy)) in &accums {
            pass.set_bind_group(0, bg, &[*off]);
            pass.dispatch_workgroups(*gx, *gy, 1);
        }
        Ok(())
    }

    /// Records the blend resolve of the frame recorded last (if it blends) into `pass`: after
    /// shade's gather, before its shading.
    pub fn record_resolve(&mut self, pass: &mut wgpu::ComputePass<'_>) {
        if let Some((bg, off, (gx, gy))) = self.pending.take() {
            pass.set_pipeline(&self.resolve);
            pass.set_bind_group(0, &bg, &[off]);
            pass.dispatch_workgroups(gx, gy, 1);
            pass.set_pipeline(&self.pinholes);
            pass.dispatch_workgroups(gx, gy, 1);
        }
    }
}

/// Blend sums per pixel.
const ACC_WORDS: u64 = 8;

/// Records the splat pass of a frame into geometry image 0 (and, blending, into shade's
/// per-pixel position and normal buffers), timed as one section.
pub(crate) fn record_step(
    rec: &mut crate::device::record::Rec<'_>,
    b: crate::device::frame::Binder<'_>,
    splat: &mut SplatGpu,
    cloud: &GpuCloud,
    s: crate::SplatSettings,
) -> Result<(), GpuError> {
    let q = rec.section();
    let timer = rec.timer;
    let mut begin = |enc: &mut wgpu::CommandEncoder| {
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
    let f = b.f;
    splat.record(
        b.ctx,
        &mut rec.enc,
        rec.arena,
        &b.shared.view,
        cloud,
        (f.width, f.height),
        (s.epsilon.unwrap_or(0.0), s.scale),
        (&f.depth[0], &f.id[0]),
        (s.mode, s.quant()),
        Some(BlendTargets {
            attr_pos: &f.attr_pos,
            attr_normal: &f.attr_normal,
            attr_style: &f.attr_style,
            to_linear: &b.shared.to_linear,
        }),
        &mut begin,
    )?;
    rec.end(crate::stats::PassId::Splat, 1, vec![], q)
}
