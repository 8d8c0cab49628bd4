//! The GPU's side of [`crate::schedule`]: each step of the frame recorded into one command
//! buffer, with the cursor of which ping-pong images hold the current G-buffer and colour.

use super::renderer::ProjectionPath;
use crate::device::cloud::GpuCloud;
use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, FrameBuffers, Shared};
use crate::device::record::Rec;
use crate::params::ViewParams;
use crate::passes::shade::gpu::{MaterialTable, ShadeBlock};
use crate::passes::shadow_texture::cpu::MarkParams;
use crate::passes::splat::gpu::SplatGpu;
use crate::passes::{blend_layers, output, project, shade, shadow_texture, splat};
use crate::pipeline::{ColourPass, GeometryPass};
use crate::schedule::PassExec;
use crate::SplatSettings;

/// What a camera frame shades with (a light view shades nothing).
pub(crate) struct Shading {
    pub block: ShadeBlock,
    /// Written by the frame's first shade (taken then).
    pub materials: Option<Box<MaterialTable>>,
    /// Linear RGB.
    pub background: [f32; 3],
    /// Transparent splats' environment.
    pub env: Option<crate::env::EnvSettings>,
}

/// One frame or light view being recorded.
pub(crate) struct GpuExec<'a> {
    pub rec: Rec<'a>,
    b: Binder<'a>,
    cloud: &'a GpuCloud,
    v: &'a ViewParams,
    projection: ProjectionPath,
    splat: Option<&'a mut SplatGpu>,
    shading: Option<Shading>,
    cur: Cursor,
}

impl<'a> GpuExec<'a> {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        rec: Rec<'a>,
        (ctx, shared, f): (&'a GpuContext, &'a Shared, &'a FrameBuffers),
        cloud: &'a GpuCloud,
        v: &'a ViewParams,
        projection: ProjectionPath,
        splat: Option<&'a mut SplatGpu>,
        shading: Option<Shading>,
    ) -> GpuExec<'a> {
        GpuExec {
            rec,
            b: Binder::new(ctx, shared, f),
            cloud,
            v,
            projection,
            splat,
            shading,
            cur: Cursor::default(),
        }
    }

    /// Bytes of one frame-sized image of 32-bit values.
    fn image_bytes(&self) -> u64 {
        4 * self.b.f.pixels()
    }

    fn background(&self) -> [f32; 3] {
        self.shading.as_ref().map_or([0.0; 3], |s| s.background)
    }
}

impl PassExec for GpuExec<'_> {
    type Error = GpuError;

    fn project(
        &mut self,
        splat: Option<&SplatSettings>,
        peel: Option<f32>,
        cull: bool,
    ) -> Result<Option<u64>, GpuError> {
        // Each layer starts from image 0 of each ping-pong pair.
        self.cur = Cursor::default();
        let (rec, b, cloud) = (&mut self.rec, self.b, self.cloud);
        match (splat, self.projection, &b.f.targets) {
            (Some(sp), _, _) if sp.mode.is_ordered() => {
                let sg = self.splat.as_deref_mut().ok_or_else(|| {
                    GpuError::Wgpu("sorted splats asked for where splats are not set up".into())
                })?;
                let s = self.shading.as_mut().ok_or_else(|| {
                    GpuError::Wgpu("sorted splats recorded in a light view".into())
                })?;
                // The material table (once a frame: shade, which takes it otherwise, is not
                // run for sorted splats).
                let materials = s.materials.take().ok_or_else(|| {
                    GpuError::Wgpu("sorted splats: the frame's materials were taken".into())
                })?;
                splat::sorted_gpu::record(
                    rec,
                    b,
                    sg,
                    cloud,
                    *sp,
                    (&s.block, s.env.as_ref()),
                    &materials,
                )?
            }
            (Some(sp), _, _) => {
                let sg = self.splat.as_deref_mut().ok_or_else(|| {
                    GpuError::Wgpu("splats asked for where the splat pass is not set up".into())
                })?;
                splat::gpu::record_step(rec, b, sg, cloud, *sp)?
            }
            (None, ProjectionPath::Hardware, Some(t)) if peel.is_none() => {
                project::gpu_hw::record(rec, b, t, cloud, cull)?
            }
            _ => project::gpu::record(rec, b, cloud, cull, peel)?,
        }
        // Counted on the device: known once the frame has run.
        Ok(None)
    }

    fn geometry(&mut self, pass: &GeometryPass, gap: f32) -> Result<(), GpuError> {
        pass.kernel()
            .record(&mut self.rec, self.b, &mut self.cur, gap, Some(self.cloud))
    }

    fn shade(&mut self) -> Result<(), GpuError> {
        let s = self
            .shading
            .as_mut()
            .ok_or_else(|| GpuError::Wgpu("shade recorded in a light view".into()))?;
        let (block, materials) = (s.block, s.materials.take());
        let mut resolve = self
            .splat
            .as_deref_mut()
            .map(|sg| move |p: &mut wgpu::ComputePass<'static>| sg.record_resolve(p));
        let before = resolve
            .as_mut()
            .map(|f| f as &mut dyn FnMut(&mut wgpu::ComputePass<'static>));
        let (rec, b, cur, cloud) = (&mut self.rec, self.b, &self.cur, self.cloud);
        shade::gpu::record(rec, b, cur, cloud, (block, materials.as_deref()), before)
    }

    fn colour(&mut self, pass: &ColourPass) -> Result<(), GpuError> {
        pass.kernel()
            .record(&mut self.rec, self.b, &mut self.cur, self.v)
    }

    fn keep_front(&mut self) -> Result<(), GpuError> {
        let (n4, f) = (self.image_bytes(), self.b.f);
        let enc = &mut self.rec.enc;
        enc.copy_buffer_to_buffer(&f.surface, 0, &f.read, n4, n4);
        enc.copy_buffer_to_buffer(&f.id[self.cur.g], 0, &f.read, 2 * n4, n4);
        Ok(())
    }

    fn begin_peel(&mut self) -> Result<(), GpuError> {
        let bg = self.background();
        blend_layers::gpu::record_blend(&mut self.rec, self.b, &self.cur, None, bg)
    }

    fn blend_layer(&mut self) -> Result<(), GpuError> {
        let bg = self.background();
        // As the CPU: a pixel with a surface but no point takes the cloud's mean opacity (a
        // translucent light view, which has no shading, included).
        let hole = self.cloud.mean_alpha;
        let (rec, b, cur) = (&mut self.rec, self.b, &self.cur);
        blend_layers::gpu::record_blend(rec, b, cur, Some(hole), bg)
    }

    fn transmit_layer(&mut self) -> Result<(), GpuError> {
        let hole = self.cloud.mean_alpha;
        let (rec, b, cur) = (&mut self.rec, self.b, &self.cur);
        blend_layers::gpu::record_transmit(rec, b, cur, hole)
    }

    fn keep_layer(&mut self, k: u32) -> Result<(), GpuError> {
        let (n4, f) = (self.image_bytes(), self.b.f);
        let lr = f.layers_read.as_ref().ok_or_else(|| {
            GpuError::Wgpu("keep_layer: no layer readback buffer was made".into())
        })?;
        output::gpu::record(&mut self.rec, self.b, &self.cur)?;
        self.rec
            .enc
            .copy_buffer_to_buffer(&f.rgba, 0, lr, n4 * k as u64, n4);
        Ok(())
    }

    fn peel_behind(&mut self, gap: f32) -> Result<(), GpuError> {
        let bound = project::cpu::PEEL_NEIGHBOUR_GAPS * gap;
        let normals = self.cloud.has_normals;
        project::gpu::record_peel_reference(&mut self.rec, self.b, bound, normals)
    }

    fn compose(&mut self) -> Result<(), GpuError> {
        let bg = self.background();
        blend_layers::gpu::record_compose(&mut self.rec, self.b, bg)?;
        self.cur.colour = 0;
        Ok(())
    }

    fn output(&mut self) -> Result<(), GpuError> {
        let (n4, f) = (self.image_bytes(), self.b.f);
        output::gpu::record(&mut self.rec, self.b, &self.cur)?;
        self.rec
            .enc
            .copy_buffer_to_buffer(&f.rgba, 0, &f.read, 0, n4);
        Ok(())
    }

    fn mark(&mut self, params: &MarkParams) -> Result<(), GpuError> {
        let (rec, b, cur, cloud) = (&mut self.rec, self.b, &self.cur, self.cloud);
        shadow_texture::gpu::record(rec, b, cur, cloud, params)
    }

    fn begin_transmit(&mut self) -> Result<(), GpuError> {
        self.begin_peel()?;
        self.rec.enc.clear_buffer(&self.cloud.marked, 0, None);
        Ok(())
    }

    fn light_surface(&mut self) -> Result<(), GpuError> {
        let (rec, b, cur, cloud) = (&mut self.rec, self.b, &self.cur, self.cloud);
        shade::gpu::record_gather(rec, b, cur, cloud, crate::stats::PassId::Shade)?;
        let n4 = 4 * b.f.pixels();
        rec.enc
            .copy_buffer_to_buffer(&b.f.depth[cur.g], 0, &b.f.surface, 0, n4);
        Ok(())
    }
}
