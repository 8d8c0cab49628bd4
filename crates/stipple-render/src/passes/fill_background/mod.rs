//! Filling background pixels (Dobrev §3.2): the CPU reference kernel ([`cpu`]; its module documentation explains the pass
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

/// Background filling (see [`crate::GeometryPass::FillBackground`]).
pub(crate) struct FillBackground {
    pub iterations: Iterations,
    pub radius: u32,
}

impl GeometryKernel for FillBackground {
    fn id(&self) -> PassId {
        PassId::FillBackground
    }

    fn cpu(
        &self,
        _v: &ViewParams,
        a: &mut GBuffer,
        _b: &mut GBuffer,
        _gap: f32,
        _surfaces: Option<super::Surfaces<'_>>,
    ) -> (u32, u64) {
        let mut since = None;
        super::iterate_in_place(a, self.iterations, |g| {
            let (n, changed) = cpu::fill_background_step(g, self.radius, since.as_ref());
            since = Some(changed);
            n
        })
    }

    fn record(
        &self,
        rec: &mut Rec<'_>,
        b: Binder<'_>,
        cur: &mut Cursor,
        _gap: f32,
        _cloud: Option<&crate::device::cloud::GpuCloud>,
    ) -> Result<(), GpuError> {
        let pass = b.pass::<gpu::Gpu>();
        let (id, its) = (self.id(), self.iterations);
        super::fill::gpu::record(rec, b, cur, &pass.0, id, its, self.radius, 0.0, false)
    }
}
