//! The interactive viewer's parts that `cmd::view` puts together: camera navigation
//! ([`nav`]), the side panel of `render`'s options ([`panel`]) and showing frames in the
//! window ([`present`]).

pub mod nav;
pub mod panel;
pub mod present;
