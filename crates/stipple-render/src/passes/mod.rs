//! Passes that own themselves: each folder holds the pass's parameters and shared maths
//! (`mod.rs`), its CPU kernel (`cpu.rs`), its GPU pipeline and recording (`gpu.rs`) and its
//! WGSL, side by side.

pub mod antialias;
pub mod blend_layers;
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
pub mod shade;
pub mod shadow_texture;
pub mod smooth;
pub mod splat;
pub mod visibility;
