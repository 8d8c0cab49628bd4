//! Output: the linear colour image encoded to 8-bit sRGB (the GPU pipeline; the CPU encodes
//! with [`crate::srgb::SrgbEncoder`]).

pub mod gpu;
