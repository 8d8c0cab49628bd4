//! # output (GPU twin of the CPU's final sRGB encoding in cpu/mod.rs): linear colour → sRGB
//! 8-bit RGBA through the CPU's own encoding table (output.wgsl).

use crate::device::context::{GpuContext, GpuError};
use crate::device::frame::{Binder, Cursor, GpuPass, Shared};
use crate::device::record::{grid_2d, Rec};
use crate::device::util::{self, Pass, Res, READ, UNIFORM, WRITE};
use crate::stats::PassId;

/// The pass's pipeline and the encoding table.
pub(crate) struct Gpu {
    pass: Pass,
    table: wgpu::Buffer,
}

impl GpuPass for Gpu {
    fn new(ctx: &GpuContext, _: &Shared) -> Gpu {
        let table: Vec<u32> = crate::srgb::SrgbEncoder::new()
            .table()
            .iter()
            .map(|&b| b as u32)
            .collect();
        Gpu {
            pass: Pass::new(
                &ctx.device,
                &crate::device::shaders::OUTPUT_MODULE,
                "output",
                &[UNIFORM, READ, READ, WRITE],
            ),
            table: util::storage_init(&ctx.device, "srgb encode", bytemuck::cast_slice(&table)),
        }
    }
}

/// Encodes colour image `cur.colour` into the frame's RGBA bytes.
pub(crate) fn record(rec: &mut Rec<'_>, b: Binder<'_>, cur: &Cursor) -> Result<(), GpuError> {
    let q = rec.section();
    let grid = grid_2d(b.ctx, b.f.width, b.f.height)?;
    let gpu = b.pass::<Gpu>();
    let group = b.bind(
        "output",
        &gpu.pass.bgl,
        &[
            Res::Buf(&b.shared.view),
            Res::Buf(&b.f.colour[cur.colour]),
            Res::Buf(&gpu.table),
            Res::Buf(&b.f.rgba),
        ],
    );
    rec.image_pass(q, &gpu.pass.pipeline, &group, &[], grid);
    rec.end(PassId::Output, 1, vec![], q)
}
