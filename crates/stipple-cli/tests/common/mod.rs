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

/// A unit cube as an ASCII PLY mesh: its 8 corners and 12 outward-wound triangles.
pub fn cube_ply() -> String {
    let mut ply = String::from(
        "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\n\
         property float z\nelement face 12\nproperty list uchar int vertex_indices\nend_header\n",
    );
    for k in 0..8 {
        ply.push_str(&format!("{} {} {}\n", k & 1, k >> 1 & 1, k >> 2 & 1));
    }
    for f in [
        [0, 2, 3],
        [0, 3, 1],
        [4, 5, 7],
        [4, 7, 6],
        [0, 1, 5],
        [0, 5, 4],
        [2, 6, 7],
        [2, 7, 3],
        [0, 4, 6],
        [0, 6, 2],
        [1, 3, 7],
        [1, 7, 5],
    ] {
        ply.push_str(&format!("3 {} {} {}\n", f[0], f[1], f[2]));
    }
    ply
}

/// A three-number field (`eye`, `up`, …) of a camera JSON written by `--camera-out`.
pub fn camera_vec3(path: &Path, key: &str) -> Vec<f64> {
    let cam: serde_json::Value =
        serde_json::from_slice(&std::fs::read(path).expect("camera JSON")).expect("valid JSON");
    cam[key]
        .as_array()
        .unwrap_or_else(|| panic!("no `{key}` in {cam}"))
        .iter()
        .map(|v| v.as_f64().expect("a number"))
        .collect()
}
