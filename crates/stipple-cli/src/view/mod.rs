//! The interactive viewer's parts that `cmd::view` puts together: camera navigation
//! ([`nav`]) and showing frames in the window ([`present`]).

pub mod nav;
pub mod present;
