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

    fn cpu(
        &self,
        v: &ViewParams,
        a: &mut GBuffer,
        _b: &mut GBuffer,
        gap: f32,
        surfaces: Option<super::Surfaces<'_>>,
    ) -> (u32, u64) {
        let gap = self.layer_gap.unwrap_or(gap);
        let mut since = None;
        super::iterate_in_place(a, self.iterations, |g| {
            let slope = surfaces.map(|s| (v, s));
            let (n, changed) = cpu::fill_occluded_step(g, gap, self.radius, since.as_ref(), slope);
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
        cloud: Option<&crate::device::cloud::GpuCloud>,
    ) -> Result<(), GpuError> {
        let (id, its, gap) = (self.id(), self.iterations, self.layer_gap.unwrap_or(gap));
        let cloud = cloud.filter(|c| c.has_normals);
        if let Some(cloud) = cloud {
            gpu::record_planes(rec, b, cur, cloud)?;
        }
        let planes = cloud.is_some();
        let pass = b.pass::<gpu::Gpu>();
        super::fill::gpu::record(rec, b, cur, &pass.0, id, its, self.radius, gap, planes)
    }
}
