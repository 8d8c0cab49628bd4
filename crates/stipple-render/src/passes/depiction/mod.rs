//! Shape depiction (Pintus §6): the CPU reference kernel ([`cpu`]; its module documentation explains the pass
//! against the paper), the GPU pipeline ([`gpu`]) and its WGSL, side by side.

pub mod cpu;
pub mod gpu;

use super::{ColourImages, ColourKernel};
use crate::device::context::GpuError;
use crate::device::frame::{Binder, Cursor};
use crate::device::record::Rec;
use crate::params::ViewParams;
use crate::stats::PassId;

/// Multi-level shape depiction (see [`crate::ColourPass::Depiction`]).
pub(crate) struct Depiction {
    pub levels: u32,
    pub xi: f32,
    pub epsilon: f32,
}

impl ColourKernel for Depiction {
    fn id(&self) -> PassId {
        PassId::Depiction
    }

    fn cpu(&self, v: &ViewParams, img: ColourImages<'_>) -> (u32, u64) {
        let (levels, xi, eps) = (self.levels, self.xi, self.epsilon);
        let (sc, sh) = (img.scratch, img.shading);
        cpu::depiction(
            v,
            img.depth,
            levels,
            xi,
            eps,
            sc,
            sh,
            img.colour,
            img.colour_b,
        );
        std::mem::swap(img.colour, img.colour_b);
        (levels, 0)
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
