//! Anisotropic filling (Pintus §5): the CPU reference kernel ([`cpu`]; its module documentation explains the pass
//! against the paper), the GPU pipeline ([`gpu`]) and its WGSL, side by side.

pub mod cpu;
pub mod gpu;

use super::{ColourImages, ColourKernel};
use crate::device::context::GpuError;
use crate::device::frame::{Binder, Cursor};
use crate::device::record::Rec;
use crate::params::ViewParams;
use crate::stats::PassId;

/// Pintus's anisotropic filling (see [`crate::ColourPass::FillAnisotropic`]).
pub(crate) struct FillAnisotropic {
    pub iterations: u32,
    pub delta: f32,
    pub all_empty: bool,
}

impl ColourKernel for FillAnisotropic {
    fn id(&self) -> PassId {
        PassId::FillAnisotropic
    }

    fn cpu(&self, v: &ViewParams, img: ColourImages<'_>) -> (u32, u64) {
        let mut filled = 0;
        for _ in 0..self.iterations {
            filled += cpu::fill_anisotropic(
                v,
                img.id,
                self.delta,
                self.all_empty,
                img.depth,
                img.colour,
                img.depth_b,
                img.colour_b,
            );
            std::mem::swap(img.depth, img.depth_b);
            std::mem::swap(img.colour, img.colour_b);
        }
        (self.iterations, filled)
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
