//! # depiction (GPU twin of `cpu.rs`): depiction.wgsl (one level) and
//! depiction_apply.wgsl (colour × term).

use crate::device::util::{Pass, DYNAMIC, READ, UNIFORM, WRITE};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct DepictionBlock {
    pub weight: f32,
    pub epsilon: f32,
    pub first: u32,
    pub pad: u32,
}

pub(crate) struct Depiction {
    pub level: Pass,
    pub apply: Pass,
}

impl Depiction {
    pub fn new(ctx: &crate::device::context::GpuContext) -> Depiction {
        Depiction {
            level: Pass::new(
                &ctx.device,
                &crate::device::shaders::DEPICTION_MODULE,
                "depiction_level",
                &[UNIFORM, DYNAMIC, READ, WRITE, WRITE],
            ),
            apply: Pass::new(
                &ctx.device,
                &crate::device::shaders::DEPICTION_APPLY_MODULE,
                "depiction_apply",
                &[UNIFORM, READ, READ, READ, WRITE],
            ),
        }
    }
}
