//! One module per subcommand: its arguments and what it does (argument types shared by
//! several are in `crate::args`).

pub mod bench;
pub mod build_lod;
pub mod convert;
pub mod devices;
pub mod eval;
pub mod gen;
pub mod info;
pub mod normals;
pub mod render;
pub mod view;
