//! What `fill_background` and `fill_occluded` share: on the CPU the mask test and its
//! prechecks ([`cpu`]), on the GPU the window cells of the masks and the uniform block (the
//! masks themselves are in [`crate::masks`]).

pub mod cpu;
pub mod gpu;
