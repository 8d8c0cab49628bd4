//! Smoothing (Dobrev §3.4): the CPU reference kernel ([`cpu`]; its module documentation explains the pass
//! against the paper), the GPU pipeline ([`gpu`]) and its WGSL, side by side.

pub mod cpu;
pub mod gpu;

use super::{ColourImages, ColourKernel};
use crate::device::context::GpuError;
use crate::device::frame::{Binder, Cursor};
use crate::device::record::Rec;
use crate::params::ViewParams;
use crate::pipeline::Kernel;
use crate::stats::PassId;

/// `iterations` of the smoothing filter `kernel` (see [`crate::ColourPass::Smooth`]).
pub(crate) struct Smooth {
    pub kernel: Kernel,
    pub iterations: u32,
}

impl ColourKernel for Smooth {
    fn id(&self) -> PassId {
        PassId::Smooth
    }

    fn cpu(&self, v: &ViewParams, img: ColourImages<'_>) -> (u32, u64) {
        let (w, h) = (v.width as usize, v.height as usize);
        for _ in 0..self.iterations {
            cpu::smooth(w, h, img.id, self.kernel, img.colour, img.colour_b);
            std::mem::swap(img.colour, img.colour_b);
        }
        (self.iterations, 0)
    }

    fn record(
        &self,
        rec: &mut Rec<'_>,
        b: Binder<'_>,
        cur: &mut Cursor,
        _v: &ViewParams,
    ) -> Result<(), GpuError> {
        gpu::record(self, rec, b, cur)
    }
}
