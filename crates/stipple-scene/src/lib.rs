//! Scenes: what turns a scene (a file, or one cloud) into something to render.
//!
//! - [`file`](mod@file): scene files (TOML or JSON, `docs/scenes.md`): several clouds, each placed by
//!   a transform with its colour, opacity and material, merged into one [`PreparedCloud`]
//!   with an object table; lights; the camera; render settings.
//! - [`shadows`]: the shadow texture of a scene or a cloud under its lights (Dobrev §6):
//!   computed, refined or loaded from a [`cache`] file keyed by the clouds' contents and
//!   their placement relative to each other and to the lights.
//!
//! The command-line tool, the viewer and the Python package use this crate the same way;
//! what differs between them (progress display, a memory budget) comes in through [`Host`].

pub mod cache;
pub mod file;
pub mod shadows;

pub use file::{load_with, LoadedScene};
use std::path::{Path, PathBuf};
use stipple_core::PointCloud;
use stipple_render::PreparedCloud;

/// What a scene cannot be loaded or lit with; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{}: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {message}", path.display())]
    Parse { path: PathBuf, message: String },
    /// An entry of the scene (a cloud, a light, a setting) that cannot be used.
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
    #[error("{}: {message}", path.display())]
    Cache { path: PathBuf, message: String },
    #[error(transparent)]
    Write(#[from] stipple_io::IoError),
    #[error(transparent)]
    Render(#[from] stipple_render::RenderError),
}

/// What the application does for a scene: read its cloud files, judge what generated clouds
/// may allocate, and tell the user things. [`Plain`] reads with `stipple_io`, allows any
/// size and prints notes on stderr.
pub trait Host {
    /// Reads a cloud file; the error is a message naming it.
    fn read(&mut self, path: &Path) -> Result<PointCloud, String>;
    /// Whether `n` generated points (asked for as `what`) may be made.
    fn check_points(&mut self, what: &str, n: u64) -> Result<(), String>;
    /// Something the user should know (a fallback taken, a setting ignored).
    fn note(&mut self, message: &str);
}

/// The host of a program that only needs the defaults (see [`Host`]).
pub struct Plain;

impl Host for Plain {
    fn read(&mut self, path: &Path) -> Result<PointCloud, String> {
        stipple_io::read_cloud(path).map_err(|e| e.to_string())
    }

    fn check_points(&mut self, _what: &str, _n: u64) -> Result<(), String> {
        Ok(())
    }

    fn note(&mut self, message: &str) {
        eprintln!("note: {message}");
    }
}

/// Loads a scene file with the [`Plain`] host (see [`file::load_with`]).
pub fn load(path: &Path) -> Result<(PreparedCloud, LoadedScene), SceneError> {
    load_with(path, &mut Plain)
}

/// Whether a path names a scene file (by extension: `.toml` or `.json`).
pub fn is_scene(p: &Path) -> bool {
    file::is_scene(p)
}
