//! What `fill_background` and `fill_occluded` share on the GPU: the window cells of the
//! masks and the uniform block (the masks themselves are in [`crate::masks`]).

pub mod gpu;
