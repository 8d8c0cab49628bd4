//! # sorted splats (GPU twin of `sorted.rs`): the bucket sort's kernels
//! (`passes::bucket_sort::gpu::record_sort`, slices over the cloud's depth range from its
//! bounds), then sorted.wgsl: `sorted_points` per chunk (splat and shaded colour per point,
//! as `shade::cpu::shade_points`) and `sorted_composite` per 16×16 tile (the splats in
//! sorted order through workgroup memory, "over" per pixel). All in the frame's command
//! buffer; nothing is read back. The sort's buffers and the per-point splats are made once
//! per cloud and kept in [`SplatGpu`] from frame to frame; the uniform blocks are still made
//! per frame.
//!
//! Per-tile lists (sorted.wgsl `bin_count`, `bin_scan`, `bin_fill`, `bin_sort`), as the
//! CPU's bands: after the sort, each sorted splat is counted into every 16×16 tile its
//! footprint reaches, the counts become offsets, each splat writes its sorted position into
//! those tiles' lists (in any order), and one workgroup per tile sorts its list back into
//! the sorted order (a bitonic sort whose comparisons all go one way, so a list need not be
//! a power of two long). A composite's tile then walks only its list, in dispatches of
//! [`BATCH`] sorted positions (found by binary search), staging 128 or 256 entries at a
//! time and marking those that meet the tile, so that its pixels test only those. Lists
//! longer in all than [`BIN_ENTRIES_PER_POINT`] entries per point overflow, and the
//! composites then walk every splat instead (correct, slower); `STIPPLE_SPLAT_NO_BINS=1`
//! forces that, for comparison. On lavapipe the bunny at 512² went from 6.3 s to 0.93 s a
//! frame (transparent) and from 1.18 s to 0.14 s (sorted).

use super::gpu::SplatGpu;
use super::sorted::expected_overlap;
use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, GpuPass, Shared};
use crate::device::record::{flat_groups, Rec};
use crate::device::util::{Pass, Res, Slot, READ, UNIFORM, WRITE};
use crate::passes::bucket_sort::Slicing;
use crate::passes::shade::gpu::{MaterialTable, ShadeBlock};
use crate::stats::PassId;
use wgpu::util::DeviceExt;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct SortedChunk {
    pub base: u32,
    pub count: u32,
    pub scale: f32,
    pub overlap: f32,
    pub has_normals: u32,
    pub has_albedo: u32,
    pub has_style: u32,
    pub has_lit: u32,
    /// 0: sorted (Gunjee), 1: transparent (Zhang & Pajarola Algorithm 2).
    pub mode: u32,
    /// 1: the chunk's normals orient the discs (lit or not).
    pub disc_normals: u32,
    /// 1: transparent splats shaded per layer (deferred): the points give their albedo.
    pub deferred: u32,
    pub pad: u32,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct SortedComposite {
    pub n: u32,
    pub begin: u32,
    pub end: u32,
    pub first: u32,
    pub last: u32,
    /// Transparent splats: the number of groups and the culling ε.
    pub groups: u32,
    pub epsilon: f32,
    /// 1: each layer shaded from its blended normal (`transparent::Deferred`).
    pub deferred: u32,
    /// The environment (sorted.wgsl `env_sample`): 0 none, 1 sky, 2 image; its size; the
    /// index of refraction (0: no reflection or refraction); the up axis; the dispersion.
    pub env_kind: u32,
    pub env_w: u32,
    pub env_h: u32,
    pub ior: f32,
    pub env_up: [f32; 3],
    pub dispersion: f32,
    /// Bit 0: Algorithm 3 where the nearest layer's object does not choose
    /// (`SplatSettings::smooth_nearest`); bit 1: some pixel may take it (the frame or an
    /// object chooses it; the groups sum their current layer's colours).
    pub smooth_nearest: u32,
    /// `transparent::Phase`: 0 every fragment; with refraction 1 the opaque ones, then 2 the
    /// translucent ones.
    pub phase: u32,
    /// Transparent splats: this dispatch's band of tile rows (its first row) and how many
    /// tile rows the group images hold (the frame is drawn band by band where all of it
    /// would not fit a binding).
    pub band_ty: u32,
    pub band_tiles: u32,
}

/// sorted.wgsl `BinParams`: the per-tile lists' parameters.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct BinParams {
    pub n: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub capacity: u32,
    pub transparent: u32,
    pub pad: [u32; 3],
}

/// Entries of the per-tile lists per point (a splat reaching more tiles on average than
/// this overflows them, and the composites walk every splat instead).
const BIN_ENTRIES_PER_POINT: u64 = 8;

/// Splats a composite dispatch draws at most (see sorted.wgsl: on lavapipe one dispatch drew
/// only the first 65 536 splats of larger clouds).
pub(crate) const BATCH: u32 = 16384;

/// The kernels: sorted and transparent splats' points and composites.
pub(crate) struct SortedGpu {
    points: Pass,
    composite: Pass,
    t_points: Pass,
    t_composite: Pass,
    bin_count: Pass,
    bin_scan: Pass,
    bin_fill: Pass,
    bin_sort: Pass,
}

const SKIP: Slot = Slot::Skip;

impl GpuPass for SortedGpu {
    fn new(ctx: &GpuContext, _: &Shared) -> SortedGpu {
        let m = &crate::device::shaders::SORTED_MODULE;
        let d = &ctx.device;
        #[rustfmt::skip]
        let points = [
            UNIFORM, UNIFORM, SKIP, SKIP, SKIP, SKIP, READ, SKIP, SKIP, SKIP, UNIFORM,
            UNIFORM, READ, READ, READ, READ, READ, READ, WRITE, SKIP, SKIP, SKIP, SKIP, SKIP,
            SKIP, READ,
        ];
        #[rustfmt::skip]
        let composite = [
            UNIFORM, UNIFORM, SKIP, SKIP, SKIP, SKIP, SKIP, WRITE, WRITE, SKIP, SKIP,
            SKIP, SKIP, SKIP, SKIP, SKIP, SKIP, SKIP, WRITE, READ, READ, UNIFORM, WRITE, WRITE,
            WRITE,
        ];
        let mut t_points = points.to_vec();
        t_points.extend([SKIP, READ]);
        // Both composites read the per-tile lists (bindings 30–32).
        let mut composite = composite.to_vec();
        let mut t_composite = composite.clone();
        t_composite.extend([SKIP, WRITE, SKIP, READ, UNIFORM, WRITE, WRITE, UNIFORM]);
        // Deferred shading reads the material table.
        t_composite[10] = UNIFORM;
        composite.extend([SKIP, SKIP, SKIP, SKIP, SKIP, WRITE, WRITE, UNIFORM]);
        // The binning kernels: splats (18), order (19), counts (20), lists (30–32).
        let mut bins = vec![SKIP; 33];
        bins[18] = WRITE;
        bins[19] = READ;
        bins[20] = READ;
        bins[30] = WRITE;
        bins[31] = WRITE;
        bins[32] = UNIFORM;
        SortedGpu {
            points: Pass::new(d, m, "sorted_points", &points),
            composite: Pass::new(d, m, "sorted_composite", &composite),
            t_points: Pass::new(d, m, "transparent_points", &t_points),
            t_composite: Pass::new(d, m, "transparent_composite", &t_composite),
            bin_count: Pass::new(d, m, "bin_count", &bins),
            bin_scan: Pass::new(d, m, "bin_scan", &bins),
            bin_fill: Pass::new(d, m, "bin_fill", &bins),
            bin_sort: Pass::new(d, m, "bin_sort", &bins),
        }
    }
}

/// Records a frame of sorted (or transparent) splats into geometry image 0 (depth, id),
/// colour image 0 and the surface depth.
#[allow(clippy::too_many_arguments)]
pub(crate) fn record(
    rec: &mut Rec<'_>,
    b: Binder<'_>,
    splat: &mut SplatGpu,
    cloud: &GpuCloud,
    s: crate::SplatSettings,
    (block, env): (&ShadeBlock, Option<&crate::env::EnvSettings>),
    materials: &MaterialTable,
) -> Result<(), GpuError> {
    let (ctx, f) = (b.ctx, b.f);
    let d = &ctx.device;
    let (lo, hi) = s.depth_range.ok_or_else(|| {
        GpuError::Wgpu("sorted splats: the pipeline was not resolved for the view".into())
    })?;
    let slicing = Slicing::new(lo, hi, s.epsilon.unwrap_or(0.0));
    let transparent = s.mode == crate::SplatMode::Transparent;
    let q = rec.section();
    splat.make_sorted_buffers(ctx, cloud)?;
    // The environment: the image's texels, kept on the device between frames.
    let env = env.filter(|_| transparent);
    let (env_buf, env_w, env_h) = splat.env_texels(ctx, env.map(|e| &e.env))?;
    let env_buf = env_buf.clone();
    let env_kind = match env.map(|e| &*e.env) {
        None => 0,
        Some(crate::env::Environment::Sky) => 1,
        Some(crate::env::Environment::Image { .. }) => 2,
    };
    let masks = if transparent {
        let (m, k) = splat.masks(cloud)?;
        Some((m.clone(), k))
    } else {
        None
    };
    // With refraction the opaque points are drawn first, alone, then the translucent ones
    // (transparent::composite).
    // (As transparent::composite: only where opaque points are to be refracted.)
    // Transparent splats of a lit frame without shadow textures shade each layer from its
    // blended normal (as cpu::mod's `deferred`).
    let deferred = transparent
        && block.has_normals == 1
        && cloud.samples == [0; 4]
        && !crate::SPLAT_SHADE_POINTS.load(std::sync::atomic::Ordering::Relaxed);
    let refract = env.is_some_and(|e| {
        super::transparent::refracts_behind(e, cloud.optics.as_deref(), cloud.has_opaque)
    });
    // Per object (sorted.wgsl `t_optics`): (index of refraction, 0: the frame's; dispersion,
    // −1: the frame's; reflectivity; 0), (absorption; Algorithm 3 for its nearest layer,
    // 0: the frame's choice, 1: no, 2: yes).
    let mut optics = vec![[0.0f32; 4]; 2 * crate::MAX_OBJECTS];
    for (k, o) in cloud
        .optics
        .iter()
        .flatten()
        .enumerate()
        .take(crate::MAX_OBJECTS)
    {
        optics[2 * k] = [
            o.ior.unwrap_or(0.0),
            o.dispersion.unwrap_or(-1.0),
            o.reflectivity,
            0.0,
        ];
        let [r, g, b] = o.absorption;
        let smooth = match o.smooth_nearest {
            None => 0.0,
            Some(false) => 1.0,
            Some(true) => 2.0,
        };
        optics[2 * k + 1] = [r, g, b, smooth];
    }
    if cloud.optics.is_none() {
        optics[0] = [0.0, -1.0, 1.0, 0.0];
    }
    // Per-tile lists of the sorted splats (sorted.wgsl `bin_*`): each tile's composite then
    // walks only the splats that reach it, in order, instead of every splat.
    let (tiles_x, tiles_y) = (f.width.div_ceil(16), f.height.div_ceil(16));
    let tiles = tiles_x as u64 * tiles_y as u64;
    let (group_acc, band) = match &masks {
        Some((_, k)) => {
            // As sorted.wgsl: K group images of a band of tile rows, then the whole frame's
            // surface behind and farthest layer, a vec4 each per pixel. The frame is drawn
            // band by band where all its rows' group images would not fit a binding (on
            // lavapipe, 128 MiB: 1024² with four groups is 320 MiB).
            let k = (*k as u64).clamp(1, stipple_core::grouping::TRANSPARENT_GROUPS as u64);
            let behind = if refract { 32 } else { 0 } * f.width as u64 * f.height as u64;
            let row = 80 * k * 16 * f.width as u64;
            let limit = ctx.binding_limit();
            let mut band = (limit.saturating_sub(behind) / row).min(tiles_y as u64);
            let cap = crate::SPLAT_BAND_TILES.load(std::sync::atomic::Ordering::Relaxed);
            if cap > 0 && band > 0 {
                band = band.min(cap as u64);
            }
            if band == 0 {
                return Err(GpuError::TooLarge(format!(
                    "transparent splats: a row of 16-pixel tiles' group images ({} MiB) and \
                     the surface behind ({} MiB) exceed the device's binding limit of {} MiB \
                     (a narrower image, or --splat-c lower for fewer groups)",
                    row >> 20,
                    behind >> 20,
                    limit >> 20
                )));
            }
            let acc = splat.group_acc(ctx, row * band + behind)?.clone();
            (Some(acc), band as u32)
        }
        None => (None, tiles_y),
    };
    let limit = ctx.binding_limit();
    let capacity = (cloud.len as u64 * BIN_ENTRIES_PER_POINT)
        .max(1 << 16)
        .min(limit / 4)
        .min(u32::MAX as u64);
    let binp = d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("splat bins"),
        usage: wgpu::BufferUsages::UNIFORM,
        contents: bytemuck::bytes_of(&BinParams {
            n: slicing.n,
            tiles_x,
            tiles_y,
            capacity: if crate::SPLAT_NO_BINS.load(std::sync::atomic::Ordering::Relaxed)
                || std::env::var_os("STIPPLE_SPLAT_NO_BINS").is_some()
            {
                0
            } else {
                capacity as u32
            },
            transparent: transparent as u32,
            pad: [0; 3],
        }),
    });
    let (bin_cnt, bin_pairs) = splat.bins(ctx, (4 * (2 * tiles + 1), 4 * capacity));
    let (bin_cnt, bin_pairs) = (bin_cnt.clone(), bin_pairs.clone());
    let (shapes, _) = splat.shapes(cloud)?;
    let (sorted, splats) = splat.sorted_buffers(cloud)?;
    crate::passes::bucket_sort::gpu::record_sort(
        ctx,
        b.shared,
        &mut rec.enc,
        cloud,
        &b.shared.view,
        slicing,
        sorted,
    );
    let pass = b.shared.pass::<SortedGpu>(ctx);
    let (points_pass, composite_pass) = if transparent {
        (&pass.t_points, &pass.t_composite)
    } else {
        (&pass.points, &pass.composite)
    };
    let uniform = |label, bytes: &[u8]| {
        d.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage: wgpu::BufferUsages::UNIFORM,
        })
    };
    let sp = uniform("sorted shade", bytemuck::bytes_of(block));
    let mats = uniform("sorted materials", bytemuck::cast_slice(&materials[..]));
    let optics = uniform("transparent optics", bytemuck::cast_slice(&optics[..]));
    let overlap = expected_overlap() * s.scale * s.scale;
    {
        let mut c = rec.enc.begin_compute_pass(&Default::default());
        c.set_pipeline(&points_pass.pipeline);
        let mut keep = Vec::new();
        for (ch, shape) in cloud.chunks.iter().zip(shapes) {
            let sc = uniform(
                "sorted chunk",
                bytemuck::bytes_of(&SortedChunk {
                    base: ch.base,
                    count: ch.count,
                    scale: s.scale,
                    overlap,
                    // As shade: the frame's block says whether it lights and which albedo.
                    has_normals: (ch.normals.is_some() && block.has_normals == 1) as u32,
                    has_albedo: (ch.albedo.is_some() && block.has_albedo == 1) as u32,
                    has_style: ch.style.is_some() as u32,
                    has_lit: match (&ch.lit, &ch.lit_rb) {
                        _ if cloud.samples == [0; 4] => 0,
                        (Some(_), Some(_)) => 2,
                        (Some(_), None) => 1,
                        (None, _) => 0,
                    },
                    mode: transparent as u32,
                    disc_normals: ch.normals.is_some() as u32,
                    deferred: deferred as u32,
                    pad: 0,
                }),
            );
            let dummy = &cloud.dummy;
            let mut res = vec![
                Res::Buf(&b.shared.view),
                Res::Buf(&sp),
                Res::Skip,
                Res::Skip,
                Res::Skip,
                Res::Skip,
                Res::Buf(&b.shared.to_linear),
                Res::Skip,
                Res::Skip,
                Res::Skip,
                Res::Buf(&mats),
                Res::Buf(&sc),
                Res::Buf(&ch.positions),
                Res::Buf(ch.normals.as_ref().unwrap_or(dummy)),
                Res::Buf(ch.albedo.as_ref().unwrap_or(dummy)),
                Res::Buf(ch.style.as_ref().unwrap_or(dummy)),
                Res::Buf(ch.lit.as_ref().unwrap_or(dummy)),
                Res::Buf(shape),
                Res::Buf(splats),
                Res::Skip,
                Res::Skip,
                Res::Skip,
                Res::Skip,
                Res::Skip,
                Res::Skip,
                Res::Buf(ch.lit_rb.as_ref().unwrap_or(dummy)),
            ];
            if let Some((m, _)) = &masks {
                res.extend([Res::Skip, Res::Buf(m)]);
            }
            let g = points_pass.bind(d, &res);
            c.set_bind_group(0, &g, &[]);
            let (gx, gy) = flat_groups(ctx, ch.count as u64);
            c.dispatch_workgroups(gx, gy, 1);
            keep.push(sc);
        }
    }
    rec.enc.clear_buffer(&bin_cnt, 0, None);
    {
        let bins = |p: &Pass| {
            let mut res = vec![Res::Skip; 33];
            res[18] = Res::Buf(splats);
            res[19] = Res::Buf(&sorted.order);
            res[20] = Res::Buf(&sorted.counts);
            res[30] = Res::Buf(&bin_cnt);
            res[31] = Res::Buf(&bin_pairs);
            res[32] = Res::Buf(&binp);
            p.bind(d, &res)
        };
        let (gx, gy) = flat_groups(ctx, cloud.len as u64);
        let mut c = rec.enc.begin_compute_pass(&Default::default());
        for (p, (x, y)) in [
            (&pass.bin_count, (gx, gy)),
            (&pass.bin_scan, (1, 1)),
            (&pass.bin_fill, (gx, gy)),
            (&pass.bin_sort, (tiles_x, tiles_y)),
        ] {
            c.set_pipeline(&p.pipeline);
            c.set_bind_group(0, &bins(p), &[]);
            c.dispatch_workgroups(x, y, 1);
        }
    }
    // The kept points are counted on the device: as many dispatches as the cloud's points
    // could need, each drawing no further than those kept.
    let dispatches = (cloud.len as u32).div_ceil(BATCH).max(1);
    let phases: &[u32] = if refract { &[1, 2] } else { &[0] };
    // sorted.wgsl: bit 0 the frame's Algorithm 3, bit 1 some object's or the frame's.
    let smooth_nearest = s.smooth_nearest as u32
        | (super::transparent::smooth_anywhere(s.smooth_nearest, cloud.optics.as_deref()) as u32)
            << 1;
    // Per phase, band by band (the group images hold one band), all the batches of a band.
    let bands: Vec<u32> = (0..tiles_y).step_by(band.max(1) as usize).collect();
    let mut groups = Vec::with_capacity(dispatches as usize * phases.len() * bands.len());
    for (phase, band_ty, k) in phases.iter().flat_map(|&p| {
        bands
            .iter()
            .flat_map(move |&b| (0..dispatches).map(move |k| (p, b, k)))
    }) {
        let comp = uniform(
            "sorted composite",
            bytemuck::bytes_of(&SortedComposite {
                n: slicing.n,
                begin: k * BATCH,
                end: (k + 1) * BATCH,
                first: (k == 0) as u32,
                last: (k + 1 == dispatches) as u32,
                groups: masks.as_ref().map_or(0, |m| m.1 as u32),
                epsilon: s.epsilon.unwrap_or(0.0),
                deferred: deferred as u32,
                env_kind,
                env_w,
                env_h,
                ior: env.and_then(|e| e.ior).unwrap_or(0.0),
                env_up: env.map_or([0.0; 3], |e| e.up.to_array()),
                dispersion: env.map_or(0.0, |e| e.dispersion),
                smooth_nearest,
                phase,
                band_ty,
                band_tiles: band,
            }),
        );
        let mut res = vec![
            Res::Buf(&b.shared.view),
            Res::Buf(&sp),
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Buf(&f.colour[0]),
            Res::Buf(&f.surface),
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Skip,
            Res::Buf(splats),
            Res::Buf(&sorted.order),
            Res::Buf(&sorted.counts),
            Res::Buf(&comp),
            Res::Buf(&f.depth[0]),
            Res::Buf(&f.id[0]),
            Res::Buf(&f.acc),
        ];
        if transparent {
            res[10] = Res::Buf(&mats);
        }
        if let Some(acc) = &group_acc {
            res.extend([
                Res::Skip,
                Res::Buf(acc),
                Res::Skip,
                Res::Buf(&env_buf),
                Res::Buf(&optics),
            ]);
        } else {
            res.extend([Res::Skip; 5]);
        }
        res.extend([Res::Buf(&bin_cnt), Res::Buf(&bin_pairs), Res::Buf(&binp)]);
        groups.push((composite_pass.bind(d, &res), band.min(tiles_y - band_ty)));
    }
    {
        let mut c = rec.timed_pass(q);
        c.set_pipeline(&composite_pass.pipeline);
        for (g, rows) in &groups {
            c.set_bind_group(0, g, &[]);
            c.dispatch_workgroups(tiles_x, *rows, 1);
        }
    }
    rec.end(PassId::Splat, 1, vec![], q)
}
