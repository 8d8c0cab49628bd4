//! Runs the Python package's pytest suite (`tests/python`) against the extension this build
//! made (`lib_stipple.so`), so that `cargo test --workspace` tests the package too.
//!
//! The suite needs Python 3 with numpy, pytest and Pillow: a virtual environment is made once
//! under the target directory (`py-venv`) and they are installed there from PyPI. Where that is
//! impossible (no Python, no network) the test says why and skips, unless
//! `STIPPLE_REQUIRE_PYTHON=1` (CI) makes that a failure.

use std::path::{Path, PathBuf};
use std::process::Command;

/// target/<profile>, from this test binary's path (target/<profile>/deps/python-…).
fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    exe.parent()
        .and_then(Path::parent)
        .expect("target/<profile>/deps")
        .to_path_buf()
}

fn skip_or_fail(why: &str) {
    if std::env::var("STIPPLE_REQUIRE_PYTHON").is_ok_and(|v| v == "1") {
        panic!("STIPPLE_REQUIRE_PYTHON=1: {why}");
    }
    eprintln!("skipping the Python package's tests: {why}");
}

fn run(cmd: &mut Command) -> Result<String, String> {
    let out = cmd.output().map_err(|e| format!("{cmd:?}: {e}"))?;
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    if out.status.success() {
        Ok(text)
    } else {
        Err(format!("{cmd:?} failed ({}):\n{text}", out.status))
    }
}

/// A virtual environment with the suite's packages, made once.
fn venv(target: &Path) -> Result<PathBuf, String> {
    let dir = target.join("py-venv");
    let python = dir.join("bin/python");
    let ready = dir.join(".stipple-ready");
    if ready.exists() {
        return Ok(python);
    }
    let base = std::env::var("STIPPLE_PYTHON").unwrap_or_else(|_| "python3".into());
    run(Command::new(&base).args(["-m", "venv"]).arg(&dir))?;
    run(Command::new(&python).args([
        "-m",
        "pip",
        "install",
        "--quiet",
        "--disable-pip-version-check",
        "numpy",
        "pytest",
        "pillow",
    ]))?;
    std::fs::write(&ready, "numpy pytest pillow\n").map_err(|e| e.to_string())?;
    Ok(python)
}

#[test]
fn python_package_test_suite() {
    let profile = profile_dir();
    // `cargo test` builds the extension into deps/ (`cargo build` also copies it up a level):
    // the newer of the two is this build's.
    let modified = |p: &Path| p.metadata().and_then(|m| m.modified()).ok();
    let lib = [
        profile.join("deps/lib_stipple.so"),
        profile.join("lib_stipple.so"),
    ]
    .into_iter()
    .filter(|p| p.exists())
    .max_by_key(|p| modified(p))
    .unwrap_or_else(|| profile.join("deps/lib_stipple.so"));
    if !lib.exists() {
        skip_or_fail(&format!(
            "{} was not built (this platform names it otherwise?)",
            lib.display()
        ));
        return;
    }
    let python = match venv(profile.parent().expect("target dir")) {
        Ok(p) => p,
        Err(e) => {
            skip_or_fail(&format!("no Python environment for the suite: {e}"));
            return;
        }
    };
    // The package as it would be installed: python/stipple plus the extension module.
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let pkg_root = profile.join("py-pkg");
    let pkg = pkg_root.join("stipple");
    std::fs::create_dir_all(&pkg).unwrap();
    for f in std::fs::read_dir(crate_dir.join("python/stipple")).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, pkg.join(f.file_name().unwrap())).unwrap();
    }
    // Replaced by a rename, so a Python process still holding the old one is not disturbed.
    let tmp = pkg.join("_stipple.so.tmp");
    std::fs::copy(&lib, &tmp).unwrap();
    std::fs::rename(&tmp, pkg.join("_stipple.so")).unwrap();

    let mut cmd = Command::new(&python);
    cmd.args(["-m", "pytest", "-q", "-p", "no:cacheprovider", "-rs"])
        .arg(crate_dir.join("tests/python"))
        .env("PYTHONPATH", &pkg_root)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .current_dir(crate_dir);
    let cli = profile.join("stipple");
    if cli.exists() {
        cmd.env("STIPPLE_CLI", &cli);
    }
    let data = crate_dir.join("../../../shared/data");
    if data.exists() {
        cmd.env("STIPPLE_DATA", data.canonicalize().unwrap());
    }
    match run(&mut cmd) {
        Ok(text) => println!("{text}"),
        Err(e) => panic!("the Python package's tests failed:\n{e}"),
    }
}
