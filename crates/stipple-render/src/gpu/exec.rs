//! The GPU's side of [`crate::schedule`]: each step of the frame recorded into one command
//! buffer, with the cursor of which ping-pong images hold the current G-buffer and colour.

use super::record::{Cursor, Rec};
use super::renderer::ProjectionPath;
use super::resources::{FrameBuffers, Kit};
use super::steps::*;
use crate::device::cloud::GpuCloud;
use crate::device::context::GpuError;
use crate::params::ViewParams;
use crate::passes::shade::gpu::ShadeBlock;
use crate::passes::shadow_texture::cpu::MarkParams;
use crate::passes::splat::gpu::SplatGpu;
use crate::pipeline::{ColourPass, GeometryPass};
use crate::schedule::PassExec;
use crate::SplatSettings;

/// What a camera frame shades with (a light view shades nothing).
pub(crate) struct Shading {
    pub block: ShadeBlock,
    /// Linear RGB.
    pub background: [f32; 3],
    /// The opacity of pixels that no point covers (see `blend_layers`).
    pub mean_alpha: f32,
}

/// One frame or light view being recorded.
pub(crate) struct GpuExec<'a> {
    pub rec: Rec<'a>,
    kit: &'a Kit,
    f: &'a FrameBuffers,
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
        kit: &'a Kit,
        f: &'a FrameBuffers,
        cloud: &'a GpuCloud,
        v: &'a ViewParams,
        projection: ProjectionPath,
        splat: Option<&'a mut SplatGpu>,
        shading: Option<Shading>,
    ) -> GpuExec<'a> {
        GpuExec {
            rec,
            kit,
            f,
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
        4 * self.f.width as u64 * self.f.height as u64
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
        let (rec, kit, f, cloud) = (&mut self.rec, self.kit, self.f, self.cloud);
        match (splat, self.projection, &f.targets) {
            (Some(sp), _, _) => {
                let sg = self.splat.as_deref_mut().ok_or_else(|| {
                    GpuError::Wgpu("splats asked for where the splat pass is not set up".into())
                })?;
                record_splat(rec, sg, kit, &kit.view, f, cloud, *sp)?
            }
            (None, ProjectionPath::Hardware, Some((t, copy))) if peel.is_none() => {
                record_project_hw(rec, kit, f, t, copy, cloud, cull)?
            }
            _ => record_project(rec, kit, f, cloud, cull, peel)?,
        }
        // Counted on the device: known once the frame has run.
        Ok(None)
    }

    fn geometry(&mut self, pass: &GeometryPass, gap: f32) -> Result<(), GpuError> {
        record_geometry(&mut self.rec, self.kit, self.f, &mut self.cur, pass, gap)
    }

    fn shade(&mut self) -> Result<(), GpuError> {
        let block = self
            .shading
            .as_ref()
            .ok_or_else(|| GpuError::Wgpu("shade recorded in a light view".into()))?
            .block;
        let splat = self.splat.as_deref_mut();
        record_shade(
            &mut self.rec,
            self.kit,
            self.f,
            &self.cur,
            self.cloud,
            block,
            splat,
        )
    }

    fn colour(&mut self, pass: &ColourPass) -> Result<(), GpuError> {
        record_colour(&mut self.rec, self.kit, self.f, &mut self.cur, pass, self.v)
    }

    fn keep_front(&mut self) -> Result<(), GpuError> {
        let (n4, f) = (self.image_bytes(), self.f);
        let enc = &mut self.rec.enc;
        enc.copy_buffer_to_buffer(&f.surface, 0, &f.read, n4, n4);
        enc.copy_buffer_to_buffer(&f.id[self.cur.g], 0, &f.read, 2 * n4, n4);
        Ok(())
    }

    fn begin_peel(&mut self) -> Result<(), GpuError> {
        let bg = self.background();
        record_blend(&mut self.rec, self.kit, self.f, &self.cur, None, bg)
    }

    fn blend_layer(&mut self) -> Result<(), GpuError> {
        let bg = self.background();
        let hole = self.shading.as_ref().map_or(1.0, |s| s.mean_alpha);
        record_blend(&mut self.rec, self.kit, self.f, &self.cur, Some(hole), bg)
    }

    fn keep_layer(&mut self, k: u32) -> Result<(), GpuError> {
        let (n4, f) = (self.image_bytes(), self.f);
        let lr = f.layers_read.as_ref().ok_or_else(|| {
            GpuError::Wgpu("keep_layer: no layer readback buffer was made".into())
        })?;
        record_output(&mut self.rec, self.kit, f, &self.cur)?;
        self.rec
            .enc
            .copy_buffer_to_buffer(&f.rgba, 0, lr, n4 * k as u64, n4);
        Ok(())
    }

    fn peel_behind(&mut self, gap: f32) -> Result<(), GpuError> {
        let bound = crate::passes::project::cpu::PEEL_NEIGHBOUR_GAPS * gap;
        record_peel_reference(&mut self.rec, self.kit, self.f, bound)
    }

    fn compose(&mut self) -> Result<(), GpuError> {
        let bg = self.background();
        record_compose(&mut self.rec, self.kit, self.f, bg)?;
        self.cur.colour = 0;
        Ok(())
    }

    fn output(&mut self) -> Result<(), GpuError> {
        let (n4, f) = (self.image_bytes(), self.f);
        record_output(&mut self.rec, self.kit, f, &self.cur)?;
        self.rec
            .enc
            .copy_buffer_to_buffer(&f.rgba, 0, &f.read, 0, n4);
        Ok(())
    }

    fn mark(&mut self, params: &MarkParams) -> Result<(), GpuError> {
        record_mark(
            &mut self.rec,
            self.kit,
            self.f,
            &self.cur,
            self.cloud,
            params,
        )
    }
}
