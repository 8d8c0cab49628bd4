//! Projection (Dobrev §3.1): nearest point wins each pixel: the CPU reference kernel ([`cpu`]; its module documentation explains the pass
//! against the paper), the GPU pipeline ([`gpu`]) and its WGSL, side by side.

pub mod cpu;
pub mod gpu;
pub mod gpu_hw;
