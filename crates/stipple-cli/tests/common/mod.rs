//! Helpers shared by the tests that run the `stipple` binary.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn stipple(dir: &Path, args: &[&str]) -> Output {
    stipple_env(dir, args, &[])
}

pub fn stipple_env(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_stipple"))
        .args(args)
        .envs(env.iter().copied())
        .current_dir(dir)
        .output()
        .expect("run stipple")
}

/// Standard output and error together.
pub fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A fresh directory under the system's temporary directory.
pub fn tempdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("stipple-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs stipple and returns its output text, failing the test (with that text) on an error.
pub fn ok(dir: &Path, args: &[&str]) -> String {
    let o = stipple(dir, args);
    let t = text(&o);
    assert!(o.status.success(), "stipple {args:?}: {t}");
    t
}

/// Whether a GPU adapter exists; without one the test skips, with a printed reason, unless
/// STIPPLE_REQUIRE_GPU=1 makes that a failure.
pub fn gpu_available() -> bool {
    match stipple_render::gpu::GpuContext::new(Default::default()) {
        Ok(_) => true,
        Err(e) => {
            if std::env::var("STIPPLE_REQUIRE_GPU").is_ok_and(|v| v == "1") {
                panic!("STIPPLE_REQUIRE_GPU=1 but there is no usable GPU adapter: {e}");
            }
            eprintln!("skipped: no GPU adapter ({e})");
            false
        }
    }
}
