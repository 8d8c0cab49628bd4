//! Passes that own themselves: each folder holds the pass's parameters and shared maths
//! (`mod.rs`), its CPU kernel (`cpu.rs`), its GPU pipeline and recording (`gpu.rs`) and its
//! WGSL, side by side.

pub mod splat;
