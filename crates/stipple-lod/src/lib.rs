//! Out-of-core multi-resolution point hierarchy (Pintus et al. 2011, §7): the coarse-grained
//! kd-tree whose inner nodes hold samples taken out of their children, so that every point is
//! stored once and any view can be drawn from a bounded number of points (a node with its
//! ancestors).
//!
//! - [`build()`]: inputs (LAS/LAZ streamed, others read whole) to a `.stlod` file, in memory or
//!   out of core within a memory budget, on all cores.
//! - [`LodTree`]: the file, opened and checked ([`format`](mod@format), documented in
//!   `docs/lod-format.md`).
//! - [`select()`]: a view-dependent cut under a point budget.
//! - [`Streamer`]: node payloads in an LRU cache, loaded by background threads.

pub mod build;
pub mod codec;
pub mod format;
pub mod kd;
pub mod mem;
pub mod record;
pub mod sample;
pub mod select;
pub mod source;
pub mod stream;

#[cfg(target_endian = "big")]
compile_error!("stipple-lod reads and writes little-endian records by casting");

pub use build::{build, BuildOptions, BuildReport, Phase};
pub use format::{LodTree, Node};
pub use record::Record;
pub use select::{select, SelectOptions, Selection};
pub use stream::Streamer;

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum LodError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {message}", path.display())]
    Corrupt { path: PathBuf, message: String },
    #[error(transparent)]
    Input(#[from] stipple_io::IoError),
    #[error("{0}")]
    Budget(String),
    #[error("{0}")]
    Invalid(String),
    /// The build was cancelled ([`BuildOptions::cancel`]); nothing was written.
    #[error("interrupted: the build stopped and left no tree")]
    Interrupted,
}

impl LodError {
    pub fn io(path: &Path, source: std::io::Error) -> LodError {
        LodError::Io {
            path: path.to_owned(),
            source,
        }
    }
}

/// Whether a file is a `.stlod` tree (by its magic; a missing or short file is not).
pub fn is_tree(path: &Path) -> bool {
    use std::io::Read;
    let mut m = [0u8; 8];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut m))
        .is_ok()
        && m == format::MAGIC
}
