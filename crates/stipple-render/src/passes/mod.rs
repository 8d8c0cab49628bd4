//! Passes that own themselves: each folder holds the pass's parameters and shared maths
//! (`mod.rs`), its CPU kernel (`cpu.rs`), its GPU pipeline and recording (`gpu.rs`) and its
//! WGSL, side by side.

pub mod antialias;
pub mod blend_layers;
pub mod bucket_sort;
pub mod depiction;
pub mod depth_cue;
pub mod edl;
pub mod fill;
pub mod fill_anisotropic;
pub mod fill_background;
pub mod fill_occluded;
pub mod output;
pub mod pixel;
pub mod project;
mod registry;
pub mod shade;
pub mod shadow_texture;
pub mod smooth;
pub mod splat;
pub mod visibility;

use crate::device::context::GpuError;
use crate::device::frame::{Binder, Cursor};
use crate::device::record::Rec;
use crate::gbuffer::GBuffer;
use crate::params::ViewParams;
use crate::pipeline::Iterations;
use crate::stats::PassId;

/// Asks the processor to bring `v[i]` into the cache (nothing where `i` is out of range, or
/// off x86-64), for a read that comes later. The CPU passes read points and pixels at
/// addresses scattered over the cloud or an image; asked for as soon as the address is
/// known, such reads overlap each other and the work in between instead of each waiting for
/// its own (the occluded fill's plane reads cost a third of its time one candidate at a
/// time; see BENCHMARKS.md, "Scattered reads asked for ahead", for the projection's and
/// shade's).
#[inline(always)]
pub(crate) fn prefetch<T>(v: &[T], i: u32) {
    #[cfg(target_arch = "x86_64")]
    if let Some(p) = v.get(i as usize) {
        // SAFETY: a prefetch never faults, and the address is that of an element of `v`.
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                (p as *const T).cast(),
            )
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (v, i);
}

/// [`prefetch`] by address (for a buffer another closure holds mutably): a prefetch never
/// faults, whatever the address.
#[inline(always)]
pub(crate) fn prefetch_at<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch reads nothing architecturally and never faults.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast())
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// How many pixels ahead a pass that walks an image's pixels and reads each one's point
/// (shade, the peel planes) asks for the point it will read ([`prefetch`]).
pub(crate) const PREFETCH_AHEAD: usize = 16;

/// A cloud's positions and unit normals, indexed by the point ids of a G-buffer.
#[derive(Clone, Copy)]
pub(crate) struct Surfaces<'a> {
    pub positions: &'a [glam::Vec3],
    pub normals: &'a [glam::Vec3],
}

/// A geometry pass (between project and shade: it edits the G-buffer of depths and point
/// ids), as both backends run it. A [`crate::GeometryPass`] variant names its kernel in
/// [`crate::GeometryPass::kernel`], its one registration line.
pub(crate) trait GeometryKernel {
    /// Its key in statistics.
    fn id(&self) -> PassId;
    /// The CPU reference on `a` (with `b` as the other ping-pong image; the result ends in
    /// `a`), with the frame's layer gap `gap`: the iterations it ran and the pixels it changed.
    ///
    /// `surfaces`: the cloud's positions and normals, where it has normals (the occluded
    /// fill's slope-aware test reads them).
    fn cpu(
        &self,
        v: &ViewParams,
        a: &mut GBuffer,
        b: &mut GBuffer,
        gap: f32,
        surfaces: Option<Surfaces<'_>>,
    ) -> (u32, u64);
    /// Records the pass from the geometry image `cur.g`, moving `cur.g` to its result, and
    /// ends its statistics section.
    fn record(
        &self,
        rec: &mut Rec<'_>,
        b: Binder<'_>,
        cur: &mut Cursor,
        gap: f32,
        cloud: Option<&crate::device::cloud::GpuCloud>,
    ) -> Result<(), GpuError>;
}

/// The images a colour pass reads and writes on the CPU (row-major, `width × height`): the
/// pass leaves its result in `colour` (and `depth`, if it changes depth), using the `_b`
/// images and the scratch as it needs.
pub(crate) struct ColourImages<'a> {
    pub id: &'a [u32],
    /// Surface depth (+inf where nothing is).
    pub depth: &'a mut Vec<f32>,
    pub depth_b: &'a mut Vec<f32>,
    /// Linear RGB.
    pub colour: &'a mut Vec<[f32; 3]>,
    pub colour_b: &'a mut Vec<[f32; 3]>,
    pub scratch: &'a mut (Vec<f32>, Vec<f32>),
    pub shading: &'a mut Vec<f32>,
}

/// A colour pass (after shade: it edits the linear colour image), as both backends run it.
/// A [`crate::ColourPass`] variant names its kernel in [`crate::ColourPass::kernel`], its
/// one registration line.
pub(crate) trait ColourKernel {
    /// Its key in statistics.
    fn id(&self) -> PassId;
    /// The CPU reference: the iterations it ran and what its statistics count.
    fn cpu(&self, v: &ViewParams, img: ColourImages<'_>) -> (u32, u64);
    /// Records the pass from the colour image `cur.colour` (and the geometry image `cur.g`),
    /// moving the cursor to its result, and ends its statistics section.
    fn record(
        &self,
        rec: &mut Rec<'_>,
        b: Binder<'_>,
        cur: &mut Cursor,
        v: &ViewParams,
    ) -> Result<(), GpuError>;
}

/// A pixel pass as a colour pass (see [`pixel`]): the CPU calls [`pixel::PixelPass::cpu`],
/// the GPU dispatches its WGSL entry point over the shared pixel-pass bindings.
pub(crate) struct Pixel<P>(pub P);

impl<P: pixel::PixelPass> ColourKernel for Pixel<P> {
    fn id(&self) -> PassId {
        self.0.id()
    }

    fn cpu(&self, v: &ViewParams, img: ColourImages<'_>) -> (u32, u64) {
        let input = pixel::PixelImages {
            id: img.id,
            depth: img.depth,
            colour: img.colour,
        };
        let k = self.0.cpu(v, &input, img.colour_b);
        std::mem::swap(img.colour, img.colour_b);
        (1, k)
    }

    fn record(
        &self,
        rec: &mut Rec<'_>,
        b: Binder<'_>,
        cur: &mut Cursor,
        v: &ViewParams,
    ) -> Result<(), GpuError> {
        pixel::record(&self.0, rec, b, cur, v)
    }
}

/// Runs an iterative G-buffer step that works in place on `g`: the iterations run and the
/// pixels changed in all.
pub(crate) fn iterate_in_place(
    g: &mut GBuffer,
    its: Iterations,
    mut step: impl FnMut(&mut GBuffer) -> u64,
) -> (u32, u64) {
    let mut done = 0;
    let mut total = 0;
    while done < its.max() {
        let changed = step(g);
        done += 1;
        total += changed;
        if changed == 0 && matches!(its, Iterations::UntilStable { .. }) {
            break;
        }
    }
    (done, total)
}
