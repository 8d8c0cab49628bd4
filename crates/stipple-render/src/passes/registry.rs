//! The registration of geometry and colour passes: the one match arm per pass that turns a
//! [`GeometryPass`] or [`ColourPass`] of the pipeline into the kernel both backends run
//! (see `docs/architecture.md`, "How to add a pass"), and the CPU reference of one pass
//! for parity tests.

use super::{ColourKernel, GeometryKernel};
use crate::pipeline::{ColourPass, GeometryPass};
use crate::stats::{PassId, PassStat};

impl GeometryPass {
    /// The statistics' key of this pass.
    pub fn id(&self) -> PassId {
        self.kernel().id()
    }

    pub fn name(&self) -> &'static str {
        self.id().name()
    }

    /// The pass as both backends run it: a new geometry pass is registered here (one line;
    /// see `docs/architecture.md`).
    pub(crate) fn kernel(&self) -> Box<dyn GeometryKernel> {
        use crate::passes::*;
        match *self {
            GeometryPass::FillBackground { iterations, radius } => {
                Box::new(fill_background::FillBackground { iterations, radius })
            }
            GeometryPass::FillOccluded {
                iterations,
                layer_gap,
                radius,
            } => Box::new(fill_occluded::FillOccluded {
                iterations,
                layer_gap,
                radius,
            }),
            GeometryPass::Visibility { kernel, threshold } => {
                Box::new(visibility::Visibility { kernel, threshold })
            }
        }
    }
}

impl ColourPass {
    /// The statistics' key of this pass.
    pub fn id(&self) -> PassId {
        self.kernel().id()
    }

    pub fn name(&self) -> &'static str {
        self.id().name()
    }

    /// The pass as both backends run it: a new colour pass is registered here (one line;
    /// a pixel pass, see [`crate::passes::pixel`], is wrapped in [`Pixel`]).
    pub(crate) fn kernel(&self) -> Box<dyn ColourKernel> {
        use crate::passes::*;
        match *self {
            ColourPass::Smooth { kernel, iterations } => {
                Box::new(smooth::Smooth { kernel, iterations })
            }
            ColourPass::Antialias {
                threshold,
                strength,
            } => Box::new(antialias::Antialias {
                threshold,
                strength,
            }),
            ColourPass::FillAnisotropic {
                iterations,
                delta,
                all_empty,
            } => Box::new(fill_anisotropic::FillAnisotropic {
                iterations,
                delta,
                all_empty,
            }),
            ColourPass::Depiction {
                levels,
                xi,
                epsilon,
            } => Box::new(depiction::Depiction {
                levels,
                xi,
                epsilon,
            }),
            ColourPass::Edl { strength, radius } => Box::new(edl::Edl { strength, radius }),
            ColourPass::DepthCue { strength, colour } => Box::new(Pixel(depth_cue::DepthCue {
                strength,
                colour: colour.unwrap_or([0.0; 3]),
            })),
        }
    }

    /// The CPU reference of this pass on a linear colour image (`id`: the frame's point ids,
    /// `depth`: its surface depth, which passes such as fill_anisotropic change): what the
    /// backends' parity tests compare against. Returns the pass's statistics count.
    pub fn run_cpu(
        &self,
        v: &crate::ViewParams,
        id: &[u32],
        depth: &mut Vec<f32>,
        colour: &mut Vec<[f32; 3]>,
    ) -> u64 {
        let n = colour.len();
        let kernel = self.kernel();
        let (mut depth_b, mut colour_b) = (vec![0.0; n], vec![[0.0; 3]; n]);
        let (mut scratch, mut shading) = Default::default();
        let img = crate::passes::ColourImages {
            id,
            depth,
            depth_b: &mut depth_b,
            colour,
            colour_b: &mut colour_b,
            scratch: &mut scratch,
            shading: &mut shading,
        };
        kernel.cpu(v, img).1
    }
}

impl GeometryPass {
    /// The CPU reference of this pass on a G-buffer, with the frame's layer gap `gap`: the
    /// result and the pass's statistics (what the backends' parity tests compare against).
    pub fn run_cpu(
        &self,
        v: &crate::ViewParams,
        g: &crate::GBuffer,
        gap: f32,
    ) -> (crate::GBuffer, PassStat) {
        let kernel = self.kernel();
        let (mut a, mut b) = (g.clone(), g.clone());
        let t0 = std::time::Instant::now();
        let (iterations, count) = kernel.cpu(v, &mut a, &mut b, gap, None);
        let stat = PassStat {
            pass: kernel.id(),
            ms: t0.elapsed().as_secs_f64() * 1e3,
            iterations,
            count,
        };
        (a, stat)
    }
}
