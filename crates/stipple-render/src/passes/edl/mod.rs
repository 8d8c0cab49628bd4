//! Eye-dome lighting (comparison shading for raw clouds): the CPU reference kernel ([`cpu`]; its module documentation explains the pass
//! against the paper), the GPU pipeline ([`gpu`]) and its WGSL, side by side.

pub mod cpu;
pub mod gpu;

use super::{ColourImages, ColourKernel};
use crate::device::context::GpuError;
use crate::device::frame::{Binder, Cursor};
use crate::device::record::Rec;
use crate::params::ViewParams;
use crate::stats::PassId;

/// Eye-dome lighting (see [`crate::ColourPass::Edl`]).
pub(crate) struct Edl {
    pub strength: f32,
    pub radius: f32,
}

impl ColourKernel for Edl {
    fn id(&self) -> PassId {
        PassId::Edl
    }

    fn cpu(&self, v: &ViewParams, img: ColourImages<'_>) -> (u32, u64) {
        cpu::edl(
            v,
            img.depth,
            self.strength,
            self.radius,
            img.colour,
            img.colour_b,
        );
        std::mem::swap(img.colour, img.colour_b);
        (1, 0)
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
