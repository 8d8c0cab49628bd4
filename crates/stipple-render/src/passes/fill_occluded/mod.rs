//! Filling occluded pixels (Dobrev §3.3): the CPU reference kernel ([`cpu`]; its module documentation explains the pass
//! against the paper), the GPU pipeline ([`gpu`]) and its WGSL, side by side.

pub mod cpu;
pub mod gpu;

use super::GeometryKernel;
use crate::device::context::GpuError;
use crate::device::frame::{Binder, Cursor};
use crate::device::record::Rec;
use crate::gbuffer::GBuffer;
use crate::params::ViewParams;
use crate::pipeline::Iterations;
use crate::stats::PassId;

/// Occluded-pixel filling (see [`crate::GeometryPass::FillOccluded`]).
pub(crate) struct FillOccluded {
    pub iterations: Iterations,
    /// None: the frame's layer gap.
    pub layer_gap: Option<f32>,
    pub radius: u32,
}

impl GeometryKernel for FillOccluded {
    fn id(&self) -> PassId {
        PassId::FillOccluded
    }

    fn cpu(&self, _v: &ViewParams, a: &mut GBuffer, _b: &mut GBuffer, gap: f32) -> (u32, u64) {
        let gap = self.layer_gap.unwrap_or(gap);
        let mut since = None;
        super::iterate_in_place(a, self.iterations, |g| {
            let (n, changed) = cpu::fill_occluded_step(g, gap, self.radius, since.as_ref());
            since = Some(changed);
            n
        })
    }

    fn record(
        &self,
        rec: &mut Rec<'_>,
        b: Binder<'_>,
        cur: &mut Cursor,
        gap: f32,
    ) -> Result<(), GpuError> {
        let pass = b.pass::<gpu::Gpu>();
        let (id, its, gap) = (self.id(), self.iterations, self.layer_gap.unwrap_or(gap));
        super::fill::gpu::record(rec, b, cur, &pass.0, id, its, self.radius, gap)
    }
}
