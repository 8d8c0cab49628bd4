//! The CPU backend: rayon implementations of every pass, the executable reference the GPU
//! backend is compared against. One module per pass, named as the pass.

pub mod antialias;
pub mod depiction;
pub mod edl;
pub mod fill_anisotropic;
pub mod fill_background;
pub mod fill_occluded;
pub mod project;
pub mod shade;
pub mod smooth;
pub mod visibility;

use crate::gbuffer::{GBuffer, PassStat};
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

    pub fn render(&mut self, cloud: &PreparedCloud, v: &ViewParams, pipe: &Pipeline) -> Frame {
        let (w, h) = (v.width as usize, v.height as usize);
        let n = w * h;
        let mut stats = Vec::new();
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

        let bufs = &mut self.private;
        timed(&mut stats, "project", || {
            use rayon::prelude::*;
            let normals = c.normals.as_deref();
            let kept = if private {
                project::project_private(v, &c.positions, normals, pipe.backface_culling, bufs, ga)
            } else {
                vis.par_iter()
                    .for_each(|s| s.store(project::EMPTY_KEY, Ordering::Relaxed));
                let kept = project::project(v, &c.positions, normals, pipe.backface_culling, vis);
                project::resolve(vis, ga);
                kept
            };
            ((), 1, kept)
        });

        let gap = cloud.layer_gap(pipe);
        for pass in &pipe.geometry {
            timed(&mut stats, pass.name(), || {
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

        self.colour.0.resize(n, [0.0; 3]);
        self.colour.1.resize(n, [0.0; 3]);
        self.surface_depth.resize(n, 0.0);
        let params = shade_params(cloud.cloud.origin, pipe, gap);
        let input = ShadeInput {
            positions: &c.positions,
            normals: c.normals.as_deref().filter(|_| pipe.lighting),
            albedo: cloud.albedo(pipe),
        };
        let (ca, cb) = (&mut self.colour.0, &mut self.colour.1);
        let sd = &mut self.surface_depth;
        let sd_b = &mut self.depth_b;
        sd_b.resize(n, 0.0);
        let (scratch, shading) = (&mut self.scratch, &mut self.shading);
        timed(&mut stats, "shade", || {
            shade::shade(v, ga, &input, &params, ca, sd);
            ((), 1, 0)
        });

        for pass in &pipe.colour {
            timed(&mut stats, pass.name(), || match *pass {
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

        let srgb = &self.srgb;
        let rgba = timed(&mut stats, "output", || {
            use rayon::prelude::*;
            let mut out = vec![0u8; n * 4];
            out.par_chunks_mut(4 * w)
                .zip(ca.par_chunks(w))
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
            (out, 1, 0)
        });
        Frame {
            width: v.width,
            height: v.height,
            rgba,
            depth: sd.clone(),
            id: ga.id.clone(),
            stats,
        }
    }
}

pub fn shade_params(origin: DVec3, pipe: &Pipeline, gap: f32) -> ShadeParams {
    let light = match pipe.light {
        Light::Headlight => LocalLight::Headlight,
        Light::Directional(d) => {
            LocalLight::Directional(DVec3::from(d).normalize_or_zero().as_vec3())
        }
        Light::Point(p) => LocalLight::Point((DVec3::from(p) - origin).as_vec3()),
    };
    let lut = shade::srgb_to_linear_table();
    let m = &pipe.material;
    ShadeParams {
        light,
        ambient: m.ambient,
        diffuse: m.diffuse,
        specular: m.specular,
        shininess: m.shininess,
        max_correction: gap,
        background: pipe.background.map(|c| lut[c as usize]),
    }
}

impl PreparedCloud {
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
