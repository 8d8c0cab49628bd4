//! `stipple build-lod` and trees in `render`, `bench` and `info`, through the binary.

mod common;

use common::{ok, stipple, stipple_env, text};
use std::path::{Path, PathBuf};

fn tempdir(tag: &str) -> PathBuf {
    common::tempdir(&format!("lod-{tag}"))
}

/// Runs stipple in `dir`, expecting it to fail with `want` in its output and no panic.
fn fails_with(dir: &Path, args: &[&str], want: &str) {
    let o = stipple(dir, args);
    assert!(!o.status.success(), "{args:?} succeeded");
    let t = text(&o);
    assert!(t.contains(want), "{args:?}: expected `{want}` in: {t}");
    assert!(!t.contains("panicked"), "{t}");
}

fn covered(png: &Path) -> usize {
    let (_, _, rgba) = stipple_io::image::read_png(png).unwrap();
    let bg = [24u8, 26, 31, 255];
    rgba.chunks_exact(4).filter(|p| *p != bg).count()
}

#[test]
fn a_tree_renders_like_its_cloud_and_reports_itself() {
    let dir = tempdir("roundtrip");
    ok(
        &dir,
        &["gen", "plane-objects", "-o", "p.las", "--points", "300000"],
    );
    let out = ok(
        &dir,
        &[
            "build-lod",
            "p.las",
            "-o",
            "p.stlod",
            "--max-node-points",
            "4096",
        ],
    );
    assert!(
        out.contains("300000 points") && out.contains("in memory"),
        "{out}"
    );
    let info = ok(&dir, &["info", "p.stlod", "--verify"]);
    assert!(
        info.contains("points      300000") && info.contains("verified"),
        "{info}"
    );
    let size = ["--size", "320x240", "--backend", "cpu"];
    // Trees draw raw (they carry no normals): compare with the cloud drawn raw.
    let mut a = vec!["render", "p.las", "-o", "cloud.png", "--raw"];
    a.extend(size);
    ok(&dir, &a);
    let mut a = vec!["render", "p.stlod", "-o", "tree.png"];
    a.extend(size);
    let out = ok(&dir, &a);
    assert!(out.contains("cut of"), "{out}");
    // At ≤ 1 px error the cut covers the same pixels as the whole cloud, within 3%.
    let (c, t) = (
        covered(&dir.join("cloud.png")),
        covered(&dir.join("tree.png")),
    );
    assert!(c > 320 * 240 / 10);
    assert!(t.abs_diff(c) * 100 <= 3 * c, "cloud {c} px, tree {t} px");
    // A tight budget draws fewer points but still the whole scene.
    let mut a = vec![
        "render",
        "p.stlod",
        "-o",
        "coarse.png",
        "--point-budget",
        "8192",
    ];
    a.extend(size);
    let out = ok(&dir, &a);
    assert!(out.contains("limited by --point-budget"), "{out}");
    assert!(covered(&dir.join("coarse.png")) * 10 > c * 7);
    let mut a = vec!["bench", "p.stlod", "--frames", "2"];
    a.extend(size);
    let out = ok(&dir, &a);
    assert!(
        out.contains("first image") && out.contains("cut resident"),
        "{out}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn build_lod_stays_within_its_memory_budget() {
    let dir = tempdir("budget");
    // 3 M points = 46 MiB of records (78 MB of LAS), built within 24 MiB.
    ok(
        &dir,
        &["gen", "sphere", "-o", "s.las", "--points", "3000000"],
    );
    let out = ok(
        &dir,
        &[
            "build-lod",
            "s.las",
            "-o",
            "s.stlod",
            "--memory",
            "24M",
            "--max-node-points",
            "4096",
        ],
    );
    assert!(out.contains("out of core"), "{out}");
    let peak: u64 = out
        .split("peak memory ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no peak memory in {out}"));
    assert!(
        peak <= 24,
        "peak resident memory {peak} MiB over the 24 MiB budget"
    );
    ok(&dir, &["info", "s.stlod", "--verify"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_killed_build_leaves_no_tree_and_the_previous_one_intact() {
    let dir = tempdir("killed");
    ok(
        &dir,
        &["gen", "sphere", "-o", "s.las", "--points", "600000"],
    );
    let build = [
        "build-lod",
        "s.las",
        "-o",
        "s.stlod",
        "--memory",
        "16M",
        "--max-node-points",
        "2048",
    ];
    ok(&dir, &build);
    let before = std::fs::read(dir.join("s.stlod")).unwrap();
    let abort = [("STIPPLE_TEST_ABORT_BUILD_AFTER_CHUNKS", "1")];
    // A rebuild killed part-way: the previous tree stays as it was.
    let mut again = build.to_vec();
    again.push("--force");
    let o = stipple_env(&dir, &again, &abort);
    assert!(
        !o.status.success(),
        "the build was not aborted: {}",
        text(&o)
    );
    assert!(std::fs::read(dir.join("s.stlod")).unwrap() == before);
    ok(&dir, &["info", "s.stlod", "--verify"]);
    // A first build killed part-way: no tree, and its leftover does not open as one.
    let o = stipple_env(
        &dir,
        &[
            "build-lod",
            "s.las",
            "-o",
            "new.stlod",
            "--memory",
            "16M",
            "--max-node-points",
            "2048",
        ],
        &abort,
    );
    assert!(!o.status.success());
    assert!(!dir.join("new.stlod").exists());
    let leftovers: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(
        !leftovers.is_empty(),
        "expected the killed build's temporary files"
    );
    for l in &leftovers {
        let e = stipple_lod::LodTree::open(l).unwrap_err().to_string();
        assert!(e.contains("interrupted"), "{e}");
        // Even under a tree's name.
        let renamed = dir.join("renamed.stlod");
        std::fs::copy(l, &renamed).unwrap();
        let o = stipple(&dir, &["render", "renamed.stlod"]);
        assert!(
            !o.status.success() && text(&o).contains("interrupted"),
            "{}",
            text(&o)
        );
    }
    // The next build of that output clears the dead build's leftovers.
    ok(
        &dir,
        &[
            "build-lod",
            "s.las",
            "-o",
            "new.stlod",
            "--memory",
            "16M",
            "--max-node-points",
            "2048",
        ],
    );
    for l in leftovers
        .iter()
        .filter(|l| l.to_string_lossy().contains(".new.stlod."))
    {
        assert!(!l.exists(), "{} was left behind", l.display());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_trees_and_bad_options_are_clear_errors() {
    let dir = tempdir("errors");
    ok(
        &dir,
        &["gen", "sphere", "-o", "s.las", "--points", "100000"],
    );
    ok(
        &dir,
        &[
            "build-lod",
            "s.las",
            "-o",
            "s.stlod",
            "--max-node-points",
            "2048",
        ],
    );
    let err = |args: &[&str], want: &str| fails_with(&dir, args, want);
    err(&["build-lod", "s.las", "-o", "s.stlod"], "--force");
    err(
        &["build-lod", "s.las", "-o", "s.las"],
        "refusing to overwrite",
    );
    err(&["build-lod", "s.las", "-o", "t.bin"], ".stlod");
    err(
        &["build-lod", "missing.las", "-o", "m.stlod"],
        "missing.las",
    );
    err(
        &["build-lod", "s.las", "-o", "m.stlod", "--memory", "1M"],
        "too small",
    );
    err(
        &["render", "s.stlod", "--point-budget", "100"],
        "smaller than one node",
    );
    // A camera error names the tree.
    err(
        &["render", "s.stlod", "--eye", "1,1,1", "--target", "1,1,1"],
        "s.stlod: camera: eye and target coincide",
    );
    let bytes = std::fs::read(dir.join("s.stlod")).unwrap();
    std::fs::write(dir.join("cut.stlod"), &bytes[..bytes.len() * 2 / 3]).unwrap();
    err(&["render", "cut.stlod"], "cut short");
    let mut b = bytes.clone();
    let n = b.len();
    // A byte in the first node payloads (the root's or a deep leaf's): the render reads it.
    for at in (256..n / 2).step_by(4096) {
        b[at] ^= 0x40;
    }
    std::fs::write(dir.join("flip.stlod"), &b).unwrap();
    err(&["render", "flip.stlod", "--size", "256x256"], "checksum");
    err(&["info", "flip.stlod", "--verify"], "checksum");
    assert!(std::fs::read(dir.join("s.las")).is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `build-lod -o x.copc.laz` writes a COPC file that `info` checks and that `render` draws
/// from the nodes its view needs when the file holds more than the point budget.
#[test]
fn a_copc_file_is_written_and_drawn_from_a_cut() {
    let dir = tempdir("copc");
    ok(
        &dir,
        &["gen", "plane-objects", "-o", "p.las", "--points", "400000"],
    );
    let out = ok(&dir, &["build-lod", "p.las", "-o", "p.copc.laz"]);
    assert!(
        out.contains("400000 points") && out.contains("COPC:"),
        "{out}"
    );
    let info = ok(&dir, &["info", "p.copc.laz"]);
    assert!(
        info.contains("points      400000") && info.contains("COPC ") && info.contains("checked"),
        "{info}"
    );
    let size = ["--size", "320x240", "--backend", "cpu", "--raw"];
    let mut a = vec!["render", "p.las", "-o", "cloud.png"];
    a.extend(size);
    ok(&dir, &a);
    // Within the default budget: read whole, as any LAZ.
    let mut a = vec!["render", "p.copc.laz", "-o", "whole.png"];
    a.extend(size);
    let out = ok(&dir, &a);
    assert!(!out.contains("COPC:"), "{out}");
    // Beyond a budget of 150 000: a cut of the nodes, at most that many points.
    let mut a = vec![
        "render",
        "p.copc.laz",
        "-o",
        "cut.png",
        "--point-budget",
        "150000",
    ];
    a.extend(size);
    let out = ok(&dir, &a);
    let drawn: u64 = out
        .split("nodes, ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no point count in: {out}"));
    assert!(
        out.contains("COPC:") && drawn <= 150_000 && drawn > 10_000,
        "{out}"
    );
    // The cut covers about what the whole cloud covers.
    let (c, w, t) = (
        covered(&dir.join("cloud.png")),
        covered(&dir.join("whole.png")),
        covered(&dir.join("cut.png")),
    );
    assert_eq!(c, w);
    assert!(t * 10 > c * 7, "cloud {c} px, cut {t} px");
    // Not over an existing file without --force; a tree is no input for COPC.
    let err = |args: &[&str], want: &str| fails_with(&dir, args, want);
    err(
        &["build-lod", "p.las", "-o", "p.copc.laz"],
        "already exists",
    );
    ok(&dir, &["build-lod", "p.las", "-o", "p.stlod"]);
    err(
        &["build-lod", "p.stlod", "-o", "q.copc.laz"],
        "no input for a COPC file",
    );
    assert!(!dir.join("q.copc.laz").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
