//! What every GPU pass builds on: the device and its limits ([`context`]), the uploaded
//! cloud ([`cloud`]), shader sources ([`shaders`]), pipeline and bind-group helpers and the
//! uniform arena (`util`), and the indirect "until stable" iteration ([`iterate`]).
//! Passes depend on this module; the GPU backend ([`crate::gpu`]) depends on both.

pub mod cloud;
pub mod context;
pub(crate) mod frame;
pub mod iterate;
pub(crate) mod record;
pub mod shaders;
pub(crate) mod util;
