//! Screen-space visibility (Pintus §4): the CPU reference kernel ([`cpu`]; its module documentation explains the pass
//! against the paper), the GPU pipeline ([`gpu`]) and its WGSL, side by side.

pub mod cpu;
pub mod gpu;

use super::GeometryKernel;
use crate::device::context::GpuError;
use crate::device::frame::{Binder, Cursor};
use crate::device::record::Rec;
use crate::gbuffer::GBuffer;
use crate::params::ViewParams;
use crate::stats::PassId;

/// Screen-space visibility (see [`crate::GeometryPass::Visibility`]).
pub(crate) struct Visibility {
    pub kernel: u32,
    pub threshold: f32,
}

impl GeometryKernel for Visibility {
    fn id(&self) -> PassId {
        PassId::Visibility
    }

    fn cpu(
        &self,
        v: &ViewParams,
        a: &mut GBuffer,
        b: &mut GBuffer,
        _gap: f32,
        _surfaces: Option<super::Surfaces<'_>>,
    ) -> (u32, u64) {
        let changed = cpu::visibility(v, a, b, self.kernel, self.threshold);
        std::mem::swap(a, b);
        (1, changed)
    }

    fn record(
        &self,
        rec: &mut Rec<'_>,
        b: Binder<'_>,
        cur: &mut Cursor,
        _gap: f32,
        _cloud: Option<&crate::device::cloud::GpuCloud>,
    ) -> Result<(), GpuError> {
        gpu::record(self, rec, b, cur)
    }
}
