//! The CPU backend: rayon implementations of every pass, the executable reference the GPU
//! backend is compared against. One module per pass, named as the pass.

pub mod antialias;
pub mod blend_layers;
pub mod depiction;
pub mod edl;
pub mod fill_anisotropic;
pub mod fill_background;
pub mod fill_occluded;
pub mod project;
pub mod shade;
pub mod shadow_texture;
pub mod smooth;
pub mod visibility;

use crate::gbuffer::{GBuffer, PassStat, BACKGROUND};
use crate::params::ViewParams;
use crate::pipeline::{ColourPass, GeometryPass, Iterations, Light, Pipeline};
use crate::{Frame, PreparedCloud};
use glam::DVec3;
use shade::{Albedo, LocalLight, ShadeInput, ShadeParams};
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
    acc: Vec<[f32; 4]>,
    /// The splat pass's blended normals and albedo (blend mode).
    blended: crate::passes::splat::cpu::Blended,
    blended_valid: bool,
}

fn timed<T>(stats: &mut Vec<PassStat>, name: &'static str, f: impl FnOnce() -> (T, u32, u64)) -> T {
    let t0 = Instant::now();
    let (r, iterations, count) = f();
    stats.push(PassStat {
        name,
        ms: t0.elapsed().as_secs_f64() * 1e3,
        iterations,
        count,
    });
    r
}

/// Runs an iterative G-buffer pass with ping-pong buffers; the result ends in `a`.
fn iterate(
    a: &mut GBuffer,
    b: &mut GBuffer,
    its: Iterations,
    mut step: impl FnMut(&GBuffer, &mut GBuffer) -> u64,
) -> (u32, u64) {
    let mut done = 0;
    let mut total = 0;
    while done < its.max() {
        let changed = step(a, b);
        std::mem::swap(a, b);
        done += 1;
        total += changed;
        if changed == 0 && matches!(its, Iterations::UntilStable { .. }) {
            break;
        }
    }
    (done, total)
}

impl CpuRenderer {
    pub fn new() -> CpuRenderer {
        CpuRenderer::default()
    }

    /// Renders a frame: one layer, or with [`Pipeline::layers`] > 1 the peeled layers
    /// blended front to back (Dobrev §4–5).
    pub fn render(&mut self, cloud: &PreparedCloud, v: &ViewParams, pipe: &Pipeline) -> Frame {
        let n = v.pixels();
        let mut stats = Vec::new();
        if pipe.layers <= 1 {
            self.layer(cloud, pipe, v, None, &mut stats);
            let rgba = self.output(n, v.width as usize, &mut stats);
            let ga = &self.g.as_ref().expect("made by layer").0;
            return Frame {
                width: v.width,
                height: v.height,
                rgba,
                depth: self.surface_depth.clone(),
                id: ga.id.clone(),
                stats,
                layers: vec![],
                layers_peeled: 1,
                normals: self
                    .blended_valid
                    .then(|| self.blended.normal.iter().map(|n| n.to_array()).collect()),
                host_ms: Vec::new(),
            };
        }
        // Back faces are kept: the back of a closed surface is a layer of its own.
        let peel_pipe = Pipeline {
            backface_culling: false,
            ..pipe.clone()
        };
        let gap = cloud.layer_gap(pipe);
        let mut reference = std::mem::take(&mut self.peel_ref);
        reference.clear();
        reference.resize(n, f32::INFINITY);
        let mut acc = std::mem::take(&mut self.acc);
        acc.clear();
        acc.resize(n, [0.0, 0.0, 0.0, 1.0]);
        let mut layers = Vec::new();
        let mut first: Option<(Vec<f32>, Vec<u32>)> = None;
        let mut peeled = 0;
        for k in 0..pipe.layers {
            let peel = (k > 0).then_some((&reference[..], gap));
            let kept = self.layer(cloud, &peel_pipe, v, peel, &mut stats);
            if kept == 0 {
                break;
            }
            peeled += 1;
            let ga = &self.g.as_ref().expect("made by layer").0;
            let (sd, ca) = (&self.surface_depth, &self.colour.0);
            let alpha = cloud.alpha.as_deref();
            timed(&mut stats, "blend_layers", || {
                let covered =
                    blend_layers::blend(&ga.id, sd, ca, alpha, cloud.mean_alpha, &mut acc);
                ((), 1, covered)
            });
            if pipe.keep_layers {
                layers.push(self.encode(n, v.width as usize));
            }
            if first.is_none() {
                first = Some((sd.clone(), ga.id.clone()));
            }
            reference.copy_from_slice(sd);
        }
        let background = shade::srgb_to_linear_table();
        let bg = pipe.background.map(|c| background[c as usize]);
        blend_layers::compose(&acc, bg, &mut self.colour.0);
        let rgba = self.output(n, v.width as usize, &mut stats);
        self.peel_ref = reference;
        self.acc = acc;
        let (depth, id) = first.unwrap_or_else(|| (vec![f32::INFINITY; n], vec![BACKGROUND; n]));
        Frame {
            width: v.width,
            height: v.height,
            rgba,
            depth,
            id,
            stats,
            layers,
            layers_peeled: peeled,
            normals: None,
            host_ms: Vec::new(),
        }
    }

    /// sRGB-encodes the current colour image (timed as `output`).
    fn output(&mut self, n: usize, w: usize, stats: &mut Vec<PassStat>) -> Vec<u8> {
        timed(stats, "output", || (self.encode(n, w), 1, 0))
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

    /// One layer: project (keeping, with `peel`, only points farther than the reference depth
    /// plus d̃ at their pixel), the geometry passes, shade and the colour passes. The G-buffer
    /// ends in `g.0`, the colour in `colour.0` and the surface depth in `surface_depth`.
    /// Returns the points projected.
    pub fn layer(
        &mut self,
        cloud: &PreparedCloud,
        pipe: &Pipeline,
        v: &ViewParams,
        peel: Option<(&[f32], f32)>,
        stats: &mut Vec<PassStat>,
    ) -> u64 {
        let (w, h) = (v.width as usize, v.height as usize);
        let n = w * h;
        let c = &cloud.cloud;
        let kept = self.geometry(cloud, pipe, v, peel, stats);
        let ga = &mut self.g.as_mut().expect("made by geometry").0;

        self.colour.0.resize(n, [0.0; 3]);
        self.colour.1.resize(n, [0.0; 3]);
        self.surface_depth.resize(n, 0.0);
        let gap = cloud.layer_gap(pipe);
        let params = cloud.shade_params(pipe, gap);
        let input = ShadeInput {
            positions: &c.positions,
            normals: c.normals.as_deref().filter(|_| pipe.lighting),
            albedo: cloud.albedo(pipe),
            objects: cloud.objects.as_ref().map(|o| &o.index[..]),
            lit: cloud.lit().map(|l| &l.counts[..]),
            pixel: self
                .blended_valid
                .then(|| (&self.blended.normal[..], &self.blended.albedo[..])),
        };
        let (ca, cb) = (&mut self.colour.0, &mut self.colour.1);
        let sd = &mut self.surface_depth;
        let sd_b = &mut self.depth_b;
        sd_b.resize(n, 0.0);
        let (scratch, shading) = (&mut self.scratch, &mut self.shading);
        timed(stats, "shade", || {
            shade::shade(v, ga, &input, &params, ca, sd);
            ((), 1, 0)
        });

        for pass in &pipe.colour {
            timed(stats, pass.name(), || match *pass {
                ColourPass::Smooth { kernel, iterations } => {
                    for _ in 0..iterations {
                        smooth::smooth(w, h, &ga.id, kernel, ca, cb);
                        std::mem::swap(ca, cb);
                    }
                    ((), iterations, 0)
                }
                ColourPass::Antialias {
                    threshold,
                    strength,
                } => {
                    let k = antialias::antialias(
                        w,
                        h,
                        sd,
                        antialias::AaParams {
                            far: v.far,
                            threshold,
                            strength,
                        },
                        ca,
                        cb,
                    );
                    std::mem::swap(ca, cb);
                    ((), 1, k)
                }
                ColourPass::FillAnisotropic {
                    iterations,
                    delta,
                    all_empty,
                } => {
                    let mut filled = 0;
                    for _ in 0..iterations {
                        filled += fill_anisotropic::fill_anisotropic(
                            v, &ga.id, delta, all_empty, sd, ca, sd_b, cb,
                        );
                        std::mem::swap(sd, sd_b);
                        std::mem::swap(ca, cb);
                    }
                    ((), iterations, filled)
                }
                ColourPass::Depiction {
                    levels,
                    xi,
                    epsilon,
                } => {
                    depiction::depiction(v, sd, levels, xi, epsilon, scratch, shading, ca, cb);
                    std::mem::swap(ca, cb);
                    ((), levels, 0)
                }
                ColourPass::Edl { strength, radius } => {
                    edl::edl(v, sd, strength, radius, ca, cb);
                    std::mem::swap(ca, cb);
                    ((), 1, 0)
                }
            });
        }
        kept
    }

    /// Project (optionally peeling) and the geometry passes: the G-buffer ends in `g.0`.
    /// Returns the points projected.
    pub fn geometry(
        &mut self,
        cloud: &PreparedCloud,
        pipe: &Pipeline,
        v: &ViewParams,
        peel: Option<(&[f32], f32)>,
        stats: &mut Vec<PassStat>,
    ) -> u64 {
        let n = v.pixels();
        let c = &cloud.cloud;
        // Buffers (reused across frames of the same size).
        // Up to 8 threads: private visibility buffers; beyond, one shared atomic buffer.
        let threads = rayon::current_num_threads();
        let private = threads <= 8;
        if private {
            self.private.resize_with(threads, Vec::new);
        } else if self.vis.len() != n {
            self.vis = (0..n).map(|_| AtomicU64::new(project::EMPTY_KEY)).collect();
        }
        let (ga, gb) = self.g.get_or_insert_with(|| {
            (
                GBuffer::new(v.width, v.height),
                GBuffer::new(v.width, v.height),
            )
        });
        if ga.width != v.width || ga.height != v.height {
            *ga = GBuffer::new(v.width, v.height);
            *gb = GBuffer::new(v.width, v.height);
        }
        let vis = &self.vis;

        self.blended_valid = false;
        if let Some(sp) = &pipe.splat {
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
            let blend = sp.mode != crate::SplatMode::Voronoi;
            let lut = shade::srgb_to_linear_table();
            let albedo = blend.then(|| (cloud.albedo(pipe), &lut));
            let blended = blend.then_some(&mut self.blended);
            let kept = timed(stats, "splat", || {
                let k = crate::passes::splat::cpu::splat(v, &input, sp.mode, albedo, ga, blended);
                (k, 1, k)
            });
            self.blended_valid = blend;
            return kept;
        }
        let bufs = &mut self.private;
        let kept = timed(stats, "project", || {
            use rayon::prelude::*;
            let normals = c.normals.as_deref();
            let cull = pipe.backface_culling;
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

        let gap = cloud.layer_gap(pipe);
        for pass in &pipe.geometry {
            timed(stats, pass.name(), || {
                let (its, changed) = match *pass {
                    GeometryPass::FillBackground { iterations, radius } => {
                        iterate(ga, gb, iterations, |s, d| {
                            fill_background::fill_background(s, d, radius)
                        })
                    }
                    GeometryPass::FillOccluded {
                        iterations,
                        layer_gap,
                        radius,
                    } => {
                        let gap = layer_gap.unwrap_or(gap);
                        iterate(ga, gb, iterations, |s, d| {
                            fill_occluded::fill_occluded(s, d, gap, radius)
                        })
                    }
                    GeometryPass::Visibility { kernel, threshold } => {
                        iterate(ga, gb, Iterations::Fixed(1), |s, d| {
                            visibility::visibility(v, s, d, kernel, threshold)
                        })
                    }
                };
                ((), its, changed)
            });
        }
        kept
    }

    /// The G-buffer left by the last [`CpuRenderer::geometry`].
    pub fn gbuffer(&self) -> Option<&GBuffer> {
        self.g.as_ref().map(|g| &g.0)
    }
}

/// The shade pass's parameters: the pipeline's lights in the cloud's local frame (`origin`),
/// the material terms by object and the shadow samples taken per light.
pub fn shade_params(
    origin: DVec3,
    pipe: &Pipeline,
    gap: f32,
    materials: Vec<shade::Terms>,
    samples: [u32; 4],
) -> ShadeParams {
    let lights = pipe
        .lights
        .iter()
        .take(crate::shadow::MAX_LIGHTS)
        .map(|l| match *l {
            Light::Headlight => LocalLight::Headlight,
            Light::Directional(d) => {
                LocalLight::Directional(DVec3::from(d).normalize_or_zero().as_vec3())
            }
            Light::Point(p) => LocalLight::Point((DVec3::from(p) - origin).as_vec3()),
            Light::Area(a) => LocalLight::Point((DVec3::from(a.centre) - origin).as_vec3()),
        })
        .collect();
    let lut = shade::srgb_to_linear_table();
    ShadeParams {
        lights,
        samples,
        materials,
        // Splats hit their own (bent) surface already: the tangent-plane correction would
        // only flatten it again.
        max_correction: if pipe.splat.is_some() { -1.0 } else { gap },
        background: pipe.background.map(|c| lut[c as usize]),
    }
}

impl PreparedCloud {
    /// [`shade_params`] for this cloud (its objects' materials, its shadow texture's samples).
    pub fn shade_params(&self, pipe: &Pipeline, gap: f32) -> ShadeParams {
        let samples = self.lit().map_or([0; 4], |l| l.samples);
        shade_params(self.cloud.origin, pipe, gap, self.terms(pipe), samples)
    }

    pub fn albedo(&self, pipe: &Pipeline) -> Albedo<'_> {
        let c = &self.cloud;
        if let Some(col) = &c.colors {
            Albedo::Colours(col)
        } else if let (Some(i), Some(s)) = (&c.intensity, self.intensity_scale) {
            Albedo::Intensity(i, s)
        } else {
            Albedo::Constant(pipe.material.base_colour)
        }
    }
}
