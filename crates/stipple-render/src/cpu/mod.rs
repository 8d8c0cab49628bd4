//! The CPU backend: the steps of [`crate::schedule`] run by the passes' CPU kernels (rayon;
//! the executable reference the GPU backend is compared against), over buffers kept between
//! frames.

use crate::gbuffer::{GBuffer, BACKGROUND};
use crate::params::ViewParams;
use crate::passes::{
    blend_layers::cpu as blend_layers, project::cpu as project, shade::cpu as shade,
    shadow_texture::cpu as shadow_texture, Surfaces,
};
use crate::pipeline::{ColourPass, GeometryPass, Pipeline};
use crate::stats::{PassId, PassStat};
use crate::{Frame, PreparedCloud};
use shade::ShadeInput;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Long-lived CPU renderer: owns the per-frame buffers so repeated frames of the same size
/// allocate nothing.
#[derive(Default)]
pub struct CpuRenderer {
    vis: Vec<AtomicU64>,
    private: Vec<Vec<u64>>,
    g: Option<(GBuffer, GBuffer)>,
    colour: (Vec<[f32; 3]>, Vec<[f32; 3]>),
    surface_depth: Vec<f32>,
    /// The anisotropic fill's second depth image, the depiction's level images and term.
    depth_b: Vec<f32>,
    scratch: (Vec<f32>, Vec<f32>),
    shading: Vec<f32>,
    srgb: shade::SrgbEncoder,
    /// Depth peeling: the previous layer's surface depth, and the blend accumulator.
    peel_ref: Vec<f32>,
    peel_planes: Vec<project::Plane>,
    peel_own: Vec<f32>,
    /// One bit per point, set once a layer's test has peeled it (`PeelTest::done`).
    peel_done: Vec<AtomicU64>,
    acc: Vec<[f32; 4]>,
    /// Translucent light views: one bit per point, set once a light layer marked it.
    light_marked: Vec<AtomicU64>,
    /// The splat pass's blended normals and albedo (blend mode).
    blended: crate::passes::splat::cpu::Blended,
    blended_valid: bool,
}

/// What shade reads of `cloud` under `pipe` (`pixel`: the splat pass's blended normals and
/// albedo).
fn shade_input<'a>(
    cloud: &'a PreparedCloud,
    pipe: &Pipeline,
    pixel: Option<(&'a [glam::Vec3], &'a [[f32; 3]])>,
) -> ShadeInput<'a> {
    let c = &cloud.cloud;
    ShadeInput {
        positions: &c.positions,
        normals: c.normals.as_deref().filter(|_| pipe.lighting),
        albedo: cloud.albedo(pipe),
        objects: cloud.objects.as_ref().map(|o| &o.index[..]),
        lit: cloud.lit(),
        pixel,
    }
}

fn timed<T>(stats: &mut Vec<PassStat>, pass: PassId, f: impl FnOnce() -> (T, u32, u64)) -> T {
    let t0 = Instant::now();
    let (r, iterations, count) = f();
    stats.push(PassStat {
        pass,
        ms: t0.elapsed().as_secs_f64() * 1e3,
        iterations,
        count,
    });
    r
}

impl CpuRenderer {
    pub fn new() -> CpuRenderer {
        CpuRenderer::default()
    }

    /// Renders a frame (see [`crate::schedule::frame`]): one layer, or with
    /// [`Pipeline::layers`] > 1 the peeled layers blended front to back (Dobrev §4–5).
    pub fn render(&mut self, cloud: &PreparedCloud, v: &ViewParams, pipe: &Pipeline) -> Frame {
        let gap = cloud.layer_gap(pipe);
        let mut x = CpuExec::new(self, cloud, v, pipe, None);
        let peeled = match crate::schedule::frame(&mut x, pipe, gap) {
            Ok(p) => p,
            Err(never) => match never {},
        };
        let CpuExec {
            front,
            stats,
            layers,
            rgba,
            ..
        } = x;
        let n = v.pixels();
        let (depth, id) = front.unwrap_or_else(|| (vec![f32::INFINITY; n], vec![BACKGROUND; n]));
        Frame {
            width: v.width,
            height: v.height,
            rgba,
            depth,
            id,
            stats,
            layers,
            layers_peeled: peeled,
            // The splat pass's blended normals (one layer only: peeled layers overwrite them).
            normals: (pipe.layers <= 1 && self.blended_valid)
                .then(|| self.blended.normal.iter().map(|n| n.to_array()).collect()),
            host_ms: Vec::new(),
        }
    }

    /// Adds one light image's marks to `lit` (see [`crate::schedule::light_view`];
    /// `layers` > 1 peels it for a translucent cloud).
    pub fn light_view(
        &mut self,
        cloud: &PreparedCloud,
        v: &ViewParams,
        light_pipe: &Pipeline,
        params: &shadow_texture::MarkParams,
        layers: u32,
        lit: &mut crate::LitTexture,
    ) {
        let mut x = CpuExec::new(self, cloud, v, light_pipe, Some(&mut lit.counts));
        x.rb = lit.rb.as_deref_mut();
        match crate::schedule::light_view(&mut x, light_pipe, params, layers) {
            Ok(()) => {}
            Err(never) => match never {},
        }
    }

    fn encode(&self, n: usize, w: usize) -> Vec<u8> {
        use rayon::prelude::*;
        let srgb = &self.srgb;
        let mut out = vec![0u8; n * 4];
        out.par_chunks_mut(4 * w)
            .zip(self.colour.0.par_chunks(w))
            .for_each(|(o, c)| {
                for (px, c) in o.chunks_exact_mut(4).zip(c) {
                    px.copy_from_slice(&[
                        srgb.encode(c[0]),
                        srgb.encode(c[1]),
                        srgb.encode(c[2]),
                        255,
                    ]);
                }
            });
        out
    }

    /// The G-buffer left by the last projection and geometry passes.
    pub fn gbuffer(&self) -> Option<&GBuffer> {
        self.g.as_ref().map(|g| &g.0)
    }
}

/// One frame or light view on the CPU: the steps of [`crate::schedule`], each run when it
/// is called. The G-buffer ends in `g.0`, the colour in `colour.0` and the surface depth
/// in `surface_depth` of the renderer.
pub struct CpuExec<'a> {
    r: &'a mut CpuRenderer,
    cloud: &'a PreparedCloud,
    v: &'a ViewParams,
    /// The frame's pipeline (lighting, material, background).
    pipe: &'a Pipeline,
    stats: Vec<PassStat>,
    /// The first layer's surface depth and point ids.
    front: Option<(Vec<f32>, Vec<u32>)>,
    layers: Vec<Vec<u8>>,
    rgba: Vec<u8>,
    /// The shadow sums light views mark (grey or green, and a coloured texture's red and
    /// blue).
    counts: Option<&'a mut [[u16; 4]]>,
    rb: Option<&'a mut [[u16; 8]]>,
}

impl<'a> CpuExec<'a> {
    pub fn new(
        r: &'a mut CpuRenderer,
        cloud: &'a PreparedCloud,
        v: &'a ViewParams,
        pipe: &'a Pipeline,
        counts: Option<&'a mut [[u16; 4]]>,
    ) -> CpuExec<'a> {
        CpuExec {
            r,
            cloud,
            v,
            pipe,
            stats: Vec::new(),
            front: None,
            layers: Vec::new(),
            rgba: Vec::new(),
            counts,
            rb: None,
        }
    }
}

impl crate::schedule::PassExec for CpuExec<'_> {
    type Error = std::convert::Infallible;

    fn project(
        &mut self,
        splat: Option<&crate::SplatSettings>,
        peel: Option<f32>,
        cull: bool,
    ) -> Result<Option<u64>, Self::Error> {
        let (r, cloud, v, pipe) = (&mut *self.r, self.cloud, self.v, self.pipe);
        let stats = &mut self.stats;
        let n = v.pixels();
        let c = &cloud.cloud;
        // Buffers (reused across frames of the same size).
        // Up to 8 threads: private visibility buffers; beyond, one shared atomic buffer.
        let threads = rayon::current_num_threads();
        let private = threads <= 8;
        if private {
            r.private.resize_with(threads, Vec::new);
        } else if r.vis.len() != n {
            r.vis = (0..n).map(|_| AtomicU64::new(project::EMPTY_KEY)).collect();
        }
        if r.g
            .as_ref()
            .is_none_or(|(a, _)| a.width != v.width || a.height != v.height)
        {
            r.g = Some((
                GBuffer::new(v.width, v.height),
                GBuffer::new(v.width, v.height),
            ));
        }
        let ga = &mut r.g.as_mut().expect("made above").0;
        let vis = &r.vis;

        r.blended_valid = false;
        if let Some(sp) = splat.filter(|s| s.mode.is_ordered()) {
            // The images shade would size (the colour passes read them).
            let n = v.pixels();
            r.colour.0.resize(n, [0.0; 3]);
            r.colour.1.resize(n, [0.0; 3]);
            r.surface_depth.resize(n, 0.0);
            r.depth_b.resize(n, 0.0);
            let radii = cloud.splat_radii();
            let params = cloud.shade_params(pipe, cloud.layer_gap(pipe));
            let input = shade_input(cloud, pipe, None);
            // The resolved pipeline's slices (as the GPU's): the bounds' depths, as thick as
            // the smallest splat (`PreparedCloud::resolve`).
            let (lo, hi) = sp.depth_range.unwrap_or_else(|| cloud.depth_range(v));
            let eps = sp
                .epsilon
                .unwrap_or_else(|| cloud.least_splat_radius() * sp.scale);
            let slicing = crate::passes::bucket_sort::Slicing::new(lo, hi, eps);
            let sorted = timed(stats, PassId::BucketSort, || {
                let s = crate::passes::bucket_sort::cpu::sort_in(v, &c.positions, slicing);
                let k = s.order.len() as u64;
                (s, 1, k)
            });
            // Transparent splats of a lit frame without shadow textures shade each layer
            // from its blended normal (deferred, §5.2.4): the points give their albedo.
            let deferred = sp.mode == crate::SplatMode::Transparent
                && input.normals.is_some()
                && input.lit.is_none()
                && !crate::SPLAT_SHADE_POINTS.load(std::sync::atomic::Ordering::Relaxed);
            let colours = timed(stats, PassId::Shade, || {
                let forward = (v.perspective == 0).then(|| glam::Vec3::from(v.forward));
                let col = if deferred {
                    shade::point_albedo(&input)
                } else {
                    shade::shade_points(glam::Vec3::from(v.eye), forward, &input, &params)
                };
                (col, 1, 0)
            });
            let (col, sd) = (&mut r.colour.0, &mut r.surface_depth);
            if sp.mode == crate::SplatMode::Transparent {
                let cov = cloud.coverage(sp.c, sp.coverage);
                let optics = cloud.objects.as_ref().map(|t| {
                    let o: Vec<_> = t.materials.iter().map(|m| m.optics).collect();
                    (&t.index, o)
                });
                let ti = crate::passes::splat::transparent::TransparentInput {
                    positions: &c.positions,
                    normals: c.normals.as_deref(),
                    radii: &radii,
                    scale: sp.scale,
                    masks: &cov.masks,
                    groups: cov.groups,
                    alpha: cloud.alpha.as_deref(),
                    colour: &colours,
                    epsilon: eps,
                    smooth_nearest: sp.smooth_nearest,
                    optics: optics.as_ref().map(|(i, o)| (&i[..], &o[..])),
                    deferred: deferred.then_some(crate::passes::splat::transparent::Deferred {
                        params: &params,
                        objects: input.objects,
                    }),
                };
                timed(stats, PassId::Splat, || {
                    let f = crate::passes::splat::transparent::composite(
                        v,
                        &ti,
                        &sorted.order,
                        params.background,
                        pipe.environment.as_ref(),
                        col,
                        &mut ga.depth,
                        &mut ga.id,
                    );
                    ((), 1, f)
                });
            } else {
                let si = crate::passes::splat::sorted::SortedInput {
                    positions: &c.positions,
                    radii: &radii,
                    scale: sp.scale,
                    alpha: cloud.alpha.as_deref(),
                    colour: &colours,
                };
                timed(stats, PassId::Splat, || {
                    let f = crate::passes::splat::sorted::composite(
                        v,
                        &si,
                        &sorted.order,
                        params.background,
                        col,
                        &mut ga.depth,
                        &mut ga.id,
                    );
                    ((), 1, f)
                });
            }
            sd.copy_from_slice(&ga.depth);
            return Ok(Some(sorted.order.len() as u64));
        }
        if let Some(sp) = splat {
            let radii = cloud.splat_radii();
            let epsilon = cloud.splat_epsilon(sp);
            let deferred = sp.mode == crate::SplatMode::Deferred;
            let groups = deferred.then(|| cloud.groups(sp.c));
            let quant = deferred.then(|| {
                sp.quant().unwrap_or_else(|| {
                    let (lo, hi) = cloud.depth_range(v);
                    crate::passes::splat::DepthQuant::new(lo, hi, epsilon)
                })
            });
            let input = crate::passes::splat::cpu::SplatInput {
                positions: &c.positions,
                normals: c.normals.as_deref(),
                radii: &radii,
                scale: sp.scale,
                shapes: cloud
                    .shapes
                    .as_deref()
                    .filter(|s| s.len() == c.positions.len()),
                groups: groups.as_ref().map(|g| (&g.group[..], g.groups)),
                quant,
                epsilon,
            };
            // Every mode leaves a per-pixel normal and albedo (Voronoi: the winner's bent
            // splat at the hit).
            let lut = shade::srgb_to_linear_table();
            let albedo = Some((cloud.albedo(pipe), &lut));
            let blended = Some(&mut r.blended);
            let kept = timed(stats, PassId::Splat, || {
                let k = crate::passes::splat::cpu::splat(v, &input, sp.mode, albedo, ga, blended);
                (k, 1, k)
            });
            r.blended_valid = true;
            return Ok(Some(kept));
        }
        let planes = match c.normals.as_deref() {
            Some(n) if r.peel_planes.len() == v.pixels() => Some((&r.peel_planes[..], n)),
            _ => None,
        };
        if peel.is_none() {
            // A first layer: no point is peeled yet.
            let words = c.positions.len().div_ceil(64);
            r.peel_done.resize_with(words, || AtomicU64::new(0));
            r.peel_done.truncate(words);
            for w in &r.peel_done {
                w.store(0, Ordering::Relaxed);
            }
        }
        let peel = peel.map(|gap| project::PeelTest {
            reference: &r.peel_ref,
            own: &r.peel_own,
            planes,
            gap,
            done: Some(&r.peel_done),
        });
        let bufs = &mut r.private;
        let kept = timed(stats, PassId::Project, || {
            use rayon::prelude::*;
            let normals = c.normals.as_deref();
            let kept = if private {
                project::project_private(v, &c.positions, normals, cull, peel, bufs, ga)
            } else {
                vis.par_iter()
                    .for_each(|s| s.store(project::EMPTY_KEY, Ordering::Relaxed));
                let kept = project::project(v, &c.positions, normals, cull, peel, vis);
                project::resolve(vis, ga);
                kept
            };
            (kept, 1, kept)
        });
        Ok(Some(kept))
    }

    fn geometry(&mut self, pass: &GeometryPass, gap: f32) -> Result<(), Self::Error> {
        let v = self.v;
        let (ga, gb) = self.r.g.as_mut().expect("made by project");
        let kernel = pass.kernel();
        let c = &self.cloud.cloud;
        let surfaces = c.normals.as_deref().map(|normals| Surfaces {
            positions: &c.positions,
            normals,
        });
        timed(&mut self.stats, kernel.id(), || {
            let (its, changed) = kernel.cpu(v, ga, gb, gap, surfaces);
            ((), its, changed)
        });
        Ok(())
    }

    fn shade(&mut self) -> Result<(), Self::Error> {
        let (r, cloud, v, pipe) = (&mut *self.r, self.cloud, self.v, self.pipe);
        let n = v.pixels();
        let ga = &r.g.as_ref().expect("made by project").0;
        r.colour.0.resize(n, [0.0; 3]);
        r.colour.1.resize(n, [0.0; 3]);
        r.surface_depth.resize(n, 0.0);
        r.depth_b.resize(n, 0.0);
        let params = cloud.shade_params(pipe, cloud.layer_gap(pipe));
        let pixel = r
            .blended_valid
            .then(|| (&r.blended.normal[..], &r.blended.albedo[..]));
        let input = shade_input(cloud, pipe, pixel);
        let (ca, sd) = (&mut r.colour.0, &mut r.surface_depth);
        timed(&mut self.stats, PassId::Shade, || {
            shade::shade(v, ga, &input, &params, ca, sd);
            ((), 1, 0)
        });
        Ok(())
    }

    fn colour(&mut self, pass: &ColourPass) -> Result<(), Self::Error> {
        let (r, v) = (&mut *self.r, self.v);
        let ga = &r.g.as_ref().expect("made by project").0;
        let kernel = pass.kernel();
        let img = crate::passes::ColourImages {
            id: &ga.id,
            depth: &mut r.surface_depth,
            depth_b: &mut r.depth_b,
            colour: &mut r.colour.0,
            colour_b: &mut r.colour.1,
            scratch: &mut r.scratch,
            shading: &mut r.shading,
        };
        timed(&mut self.stats, kernel.id(), || {
            let (its, count) = kernel.cpu(v, img);
            ((), its, count)
        });
        Ok(())
    }

    fn keep_front(&mut self) -> Result<(), Self::Error> {
        let r = &*self.r;
        let ga = &r.g.as_ref().expect("made by project").0;
        self.front = Some((r.surface_depth.clone(), ga.id.clone()));
        Ok(())
    }

    fn begin_peel(&mut self) -> Result<(), Self::Error> {
        let n = self.v.pixels();
        let r = &mut *self.r;
        r.peel_ref.clear();
        r.peel_ref.resize(n, f32::INFINITY);
        r.acc.clear();
        r.acc.resize(n, [0.0, 0.0, 0.0, 1.0]);
        Ok(())
    }

    fn blend_layer(&mut self) -> Result<(), Self::Error> {
        let (r, cloud) = (&mut *self.r, self.cloud);
        let ga = &r.g.as_ref().expect("made by project").0;
        let (sd, ca, acc) = (&r.surface_depth, &r.colour.0, &mut r.acc);
        let alpha = cloud.alpha.as_deref();
        timed(&mut self.stats, PassId::BlendLayers, || {
            let covered = blend_layers::blend(&ga.id, sd, ca, alpha, cloud.mean_alpha, acc);
            ((), 1, covered)
        });
        Ok(())
    }

    fn transmit_layer(&mut self) -> Result<(), Self::Error> {
        let (r, cloud) = (&mut *self.r, self.cloud);
        let ga = &r.g.as_ref().expect("made by project").0;
        let (sd, acc) = (&r.surface_depth, &mut r.acc);
        let alpha = cloud.alpha.as_deref();
        let colours = cloud.cloud.colors.as_deref();
        timed(&mut self.stats, PassId::BlendLayers, || {
            let covered = blend_layers::transmit(&ga.id, sd, colours, alpha, cloud.mean_alpha, acc);
            ((), 1, covered)
        });
        Ok(())
    }

    fn keep_layer(&mut self, _k: u32) -> Result<(), Self::Error> {
        let v = self.v;
        self.layers
            .push(self.r.encode(v.pixels(), v.width as usize));
        Ok(())
    }

    fn peel_behind(&mut self, gap: f32) -> Result<(), Self::Error> {
        let (r, v) = (&mut *self.r, self.v);
        let bound = project::PEEL_NEIGHBOUR_GAPS * gap;
        let (w, h) = (v.width as usize, v.height as usize);
        let c = &self.cloud.cloud;
        let ga = &r.g.as_ref().expect("made by project").0;
        let (planes, own) = (&mut r.peel_planes, &mut r.peel_own);
        let (sd, pr) = (&mut r.surface_depth, &mut r.peel_ref);
        timed(&mut self.stats, PassId::PeelReference, || {
            if c.normals.is_some() {
                // The plane test needs no neighbourhood reference (see `PeelTest`). The
                // layer's surface depth becomes `own` (the next shade writes every pixel of
                // `surface_depth` anew); every plane is written, so none is cleared first.
                std::mem::swap(own, sd);
                planes.resize(w * h, [0.0; 4]);
                project::peel_planes(&ga.id, own, &c.positions, c.normals.as_deref(), planes);
            } else {
                project::peel_reference(w, h, sd, bound, pr);
            }
            ((), 1, 0)
        });
        Ok(())
    }

    fn compose(&mut self) -> Result<(), Self::Error> {
        let r = &mut *self.r;
        let lut = shade::srgb_to_linear_table();
        let bg = self.pipe.background.map(|c| lut[c as usize]);
        blend_layers::compose(&r.acc, bg, &mut r.colour.0);
        Ok(())
    }

    fn output(&mut self) -> Result<(), Self::Error> {
        let (r, v) = (&*self.r, self.v);
        self.rgba = timed(&mut self.stats, PassId::Output, || {
            (r.encode(v.pixels(), v.width as usize), 1, 0)
        });
        Ok(())
    }

    fn mark(&mut self, params: &shadow_texture::MarkParams) -> Result<(), Self::Error> {
        let (r, cloud, v) = (&*self.r, self.cloud, self.v);
        let g = &r.g.as_ref().expect("made by project").0;
        let counts = self
            .counts
            .as_deref_mut()
            .expect("a light view is given the counts it marks");
        let rb = self.rb.as_deref_mut();
        let transmit =
            (params.mode != shadow_texture::MarkMode::Opaque).then(|| shadow_texture::Transmit {
                acc: &r.acc,
                marked: &r.light_marked,
            });
        timed(&mut self.stats, PassId::ShadowTexture, || {
            let k = shadow_texture::mark(
                v,
                &g.depth,
                &cloud.cloud.positions,
                cloud.cloud.normals.as_deref(),
                params,
                shadow_texture::Sums { counts, rb },
                transmit,
            );
            ((), 1, k)
        });
        Ok(())
    }

    fn begin_transmit(&mut self) -> Result<(), Self::Error> {
        self.begin_peel()?;
        let words = self.cloud.cloud.len().div_ceil(64);
        let m = &mut self.r.light_marked;
        m.resize_with(words, || AtomicU64::new(0));
        m.truncate(words);
        for w in m.iter() {
            w.store(0, Ordering::Relaxed);
        }
        Ok(())
    }

    fn light_surface(&mut self) -> Result<(), Self::Error> {
        let (r, n) = (&mut *self.r, self.v.pixels());
        let ga = &r.g.as_ref().expect("made by project").0;
        r.surface_depth.clear();
        r.surface_depth.extend_from_slice(&ga.depth);
        // blend_layer reads a colour per pixel; a light image has none.
        r.colour.0.resize(n, [0.0; 3]);
        Ok(())
    }
}
