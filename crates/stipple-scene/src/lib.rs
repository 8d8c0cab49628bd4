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

pub use file::{build, load_with, LoadedScene, SceneFile};
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
    /// Reads a cloud file (volumes as `opt` says); the error is a message naming it.
    fn read(&mut self, path: &Path, opt: &stipple_io::ReadOptions) -> Result<PointCloud, String>;
    /// Whether `n` generated points (asked for as `what`) may be made.
    fn check_points(&mut self, what: &str, n: u64) -> Result<(), String>;
    /// Something the user should know (a fallback taken, a setting ignored).
    fn note(&mut self, message: &str);
}

/// The host of a program that only needs the defaults (see [`Host`]).
pub struct Plain;

impl Host for Plain {
    fn read(&mut self, path: &Path, opt: &stipple_io::ReadOptions) -> Result<PointCloud, String> {
        stipple_io::read_cloud_with(path, opt).map_err(|e| e.to_string())
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

/// Entry points for fuzzing (`fuzz/fuzz_targets/scene.rs`, `stshadow.rs`) and for replaying
/// their corpora in the tests: errors are fine, panics and runaway allocations are not.
#[doc(hidden)]
pub mod fuzzing {
    use super::*;

    /// A host that reads no files and allows at most 5 000 generated points in all: a larger
    /// budget spends the fuzzer's executions generating points rather than reading scenes.
    struct Sandbox(u64);

    impl Host for Sandbox {
        fn read(&mut self, path: &Path, _: &stipple_io::ReadOptions) -> Result<PointCloud, String> {
            Err(format!(
                "{}: files are not read while fuzzing",
                path.display()
            ))
        }

        fn check_points(&mut self, what: &str, n: u64) -> Result<(), String> {
            self.0 = self.0.saturating_add(n);
            if self.0 > 5_000 {
                return Err(format!("{what}: over the fuzzing budget"));
            }
            Ok(())
        }

        fn note(&mut self, _message: &str) {}
    }

    /// A scene file's text, as TOML and as JSON, built with no file access.
    pub fn scene_text(data: &[u8]) {
        let Ok(text) = std::str::from_utf8(data) else {
            return;
        };
        let specs = [
            toml::from_str::<SceneFile>(text).ok(),
            serde_json::from_str::<SceneFile>(text).ok(),
        ];
        for spec in specs.into_iter().flatten() {
            let _ = build(spec, Path::new("fuzz.toml"), &mut Sandbox(0));
        }
    }

    /// A `.stshadow` file's bytes, read for the point count its length implies and for a
    /// fixed one.
    pub fn stshadow_bytes(data: &[u8], scratch: &Path) {
        if std::fs::write(scratch, data).is_err() {
            return;
        }
        let implied = data.len().saturating_sub(52) / 4;
        for points in [implied, 1000] {
            let _ = cache::read(scratch, points);
        }
    }
}
