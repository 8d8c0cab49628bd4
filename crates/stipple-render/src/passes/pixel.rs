//! Pixel passes: colour passes that compute each pixel's new colour from the shaded image
//! around it (its colour, surface depth and point id). Such a pass implements [`PixelPass`]
//! in its own folder (CPU kernel, uniform block, WGSL entry point) and is registered by one
//! match arm in `ColourPass::kernel` (passes/registry.rs); both backends then run it without
//! any code of their own: the CPU calls [`PixelPass::cpu`], the GPU makes the pipeline and
//! the bind groups over its ping-pong images when the pass is first used and dispatches one
//! thread per pixel (8×8 workgroups).
//!
//! The WGSL side: the pass's file is appended to `common.wgsl` and `shaders/pixel_pass.wgsl`
//! (bindings 0 view, 2 point ids, 3 surface depth, 4 colour in, 5 colour out); it declares
//! its uniform block at binding 1 and an entry point named as the pass.

use crate::device::shaders::ShaderModule;
use crate::params::ViewParams;

/// The images a pixel pass reads (row-major, `width × height`).
pub struct PixelImages<'a> {
    pub id: &'a [u32],
    /// Surface depth (+inf where nothing is).
    pub depth: &'a [f32],
    /// Linear RGB.
    pub colour: &'a [[f32; 3]],
}

/// A colour pass computed per pixel (see the module documentation).
pub trait PixelPass: Send + Sync {
    /// Its key in statistics.
    fn id(&self) -> crate::stats::PassId;
    /// Its WGSL entry point and label (its statistics name).
    fn name(&self) -> &'static str {
        self.id().name()
    }
    /// The CPU reference: writes every pixel of `dst`; returns what the statistics count
    /// (pixels changed, or 0).
    fn cpu(&self, v: &ViewParams, input: &PixelImages<'_>, dst: &mut [[f32; 3]]) -> u64;
    /// The WGSL module: `ShaderModule::new(name, &[PIXEL_PASS, include_str!(its file)])`.
    fn module(&self) -> &'static ShaderModule;
    /// The pass's uniform block (binding 1; at most 128 bytes).
    fn block(&self, v: &ViewParams) -> Vec<u8>;
}

/// Records a pixel pass: one dispatch of 8×8 workgroups over the frame, from colour image
/// `cur.colour` into the other.
pub(crate) fn record<P: PixelPass + ?Sized>(
    pp: &P,
    rec: &mut crate::device::record::Rec<'_>,
    b: crate::device::frame::Binder<'_>,
    cur: &mut crate::device::frame::Cursor,
    v: &ViewParams,
) -> Result<(), crate::device::context::GpuError> {
    use crate::device::util::{Res, BLOCK};
    let q = rec.section();
    let grid = crate::device::record::grid_2d(b.ctx, b.f.width, b.f.height)?;
    let off = rec.arena.push_bytes(&pp.block(v))?;
    let pass = b.shared.pixel_pass(b.ctx, pp.name(), pp.module());
    let (s, f) = (b.shared, b.f);
    let group = b.bind(
        pp.name(),
        &pass.bgl,
        &[
            Res::Buf(&s.view),
            Res::Arena(&s.arena, BLOCK),
            Res::Buf(&f.id[cur.g]),
            Res::Buf(&f.surface),
            Res::Buf(&f.colour[cur.colour]),
            Res::Buf(&f.colour[1 - cur.colour]),
        ],
    );
    rec.image_pass(q, &pass.pipeline, &group, &[off], grid);
    cur.colour = 1 - cur.colour;
    rec.end(pp.id(), 1, vec![], q)
}
