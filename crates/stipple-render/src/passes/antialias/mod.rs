//! Anti-aliasing (Dobrev §3.5): the CPU reference kernel ([`cpu`]; its module documentation explains the pass
//! against the paper), the GPU pipeline ([`gpu`]) and its WGSL, side by side.

pub mod cpu;
pub mod gpu;

use super::{ColourImages, ColourKernel};
use crate::device::context::GpuError;
use crate::device::frame::{Binder, Cursor};
use crate::device::record::Rec;
use crate::params::ViewParams;
use crate::stats::PassId;

/// Edge anti-aliasing (see [`crate::ColourPass::Antialias`]).
pub(crate) struct Antialias {
    pub threshold: f32,
    pub strength: f32,
}

impl ColourKernel for Antialias {
    fn id(&self) -> PassId {
        PassId::Antialias
    }

    fn cpu(&self, v: &ViewParams, img: ColourImages<'_>) -> (u32, u64) {
        let (w, h) = (v.width as usize, v.height as usize);
        let params = cpu::AaParams {
            far: v.far,
            threshold: self.threshold,
            strength: self.strength,
        };
        let k = cpu::antialias(w, h, img.depth, params, img.colour, img.colour_b);
        std::mem::swap(img.colour, img.colour_b);
        (1, k)
    }

    fn record(
        &self,
        rec: &mut Rec<'_>,
        b: Binder<'_>,
        cur: &mut Cursor,
        v: &ViewParams,
    ) -> Result<(), GpuError> {
        gpu::record(self, rec, b, cur, v)
    }
}
