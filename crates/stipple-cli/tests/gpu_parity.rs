//! End-to-end parity: `stipple render` on `--backend gpu` and `--backend cpu` writes the same
//! image and depth (colour within 1/255, depth within 1e-5 relative) for the demo scenes, a
//! peeled transparent scene, a scene with shadow textures, and files from `../shared/data/`.
//!
//! Tolerance: per-pass parity (stipple-render/tests/parity.rs) is exact for ids; a whole
//! frame of a real cloud also holds points that fall within rounding distance of a pixel edge,
//! and a GPU may round 1/z or fuse a multiply-add differently (Vulkan allows both), moving
//! such a point to the neighbouring pixel. So at most 0.1% of pixels may differ. Skipped
//! without a GPU adapter unless STIPPLE_REQUIRE_GPU=1.

mod common;

use common::gpu_available;
use std::path::Path;
use std::process::Command;

fn render(dir: &Path, tag: &str, backend: &str, args: &[&str]) -> (Vec<u8>, Vec<f32>) {
    let name = tag.replace(['/', '.'], "_");
    let png = dir.join(format!("{name}-{backend}.png"));
    let npy = dir.join(format!("{name}-{backend}.npy"));
    let out = Command::new(env!("CARGO_BIN_EXE_stipple"))
        .arg("render")
        .args(args)
        .args(["--backend", backend, "-o"])
        .arg(&png)
        .arg("--depth-out")
        .arg(&npy)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{tag} on {backend}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (_, _, rgba) = stipple_io::image::read_png(&png).unwrap();
    let (_, _, depth) = stipple_io::image::read_npy(&npy).unwrap();
    (rgba, depth)
}

fn compare(dir: &Path, tag: &str, args: &[&str]) {
    let (gc, gd) = render(dir, tag, "gpu", args);
    let (cc, cd) = render(dir, tag, "cpu", args);
    assert_eq!(gd.len(), cd.len());
    let n = cd.len();
    let mut bad = 0;
    let mut covered = 0;
    for k in 0..n {
        let colour_ok = (0..4).all(|i| gc[4 * k + i].abs_diff(cc[4 * k + i]) <= 1);
        let (a, b) = (gd[k], cd[k]);
        let depth_ok = a == b || (a - b).abs() <= 1e-5 * b.abs();
        covered += b.is_finite() as usize;
        bad += !(colour_ok && depth_ok) as usize;
    }
    eprintln!("{tag}: {bad} of {n} pixels differ ({covered} covered)");
    assert!(covered * 20 > n, "{tag}: the frame shows the cloud");
    assert!(bad * 1000 <= n, "{tag}: {bad} of {n} pixels differ");
}

#[test]
fn gpu_and_cpu_render_the_same_frames() {
    if !gpu_available() {
        return;
    }
    let dir = common::tempdir("gpu-parity");
    let size = ["--size", "384x288"];
    for scene in ["plane-objects", "sphere", "torus", "nested-tori"] {
        let mut a = vec!["--demo", scene, "--points", "150000"];
        a.extend(size);
        compare(&dir, scene, &a);
    }
    // Depth peeling and transparency: Fig. 17's tori through six layers.
    let mut a = vec![
        "--demo",
        "nested-tori",
        "--points",
        "150000",
        "--layers",
        "6",
    ];
    a.extend(size);
    compare(&dir, "nested-tori-6-layers", &a);
    // A scene with shadow textures from a point light and an area light, and materials.
    let scene = dir.join("shadows.toml");
    std::fs::write(
        &scene,
        r#"
[camera]
eye = [2.5, 2.5, 3.5]
target = [0.0, 0.3, 0.0]
[[cloud]]
demo = "plane"
points = 200000
scale = 4
colour = [200, 200, 190]
[[cloud]]
demo = "sphere"
points = 60000
scale = 0.5
translate = [0.0, 0.8, 0.0]
colour = [200, 60, 50]
material = { specular = 0.5, shininess = 40 }
[[light]]
type = "point"
position = [1.0, 4.0, 1.0]
[[light]]
type = "area"
position = [-2.0, 3.0, 1.0]
radius = 0.5
samples = 4
"#,
    )
    .unwrap();
    let s = scene.to_string_lossy().into_owned();
    let mut a = vec![s.as_str()];
    a.extend(size);
    compare(&dir, "scene-shadows", &a);
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    for file in ["stanford/bunny/bun_zipper.ply", "lidar/autzen_trim.laz"] {
        let p = data.join(file);
        if !p.exists() {
            eprintln!("skipped {file}: {} is absent", p.display());
            continue;
        }
        let p = p.to_string_lossy().into_owned();
        let mut a = vec![p.as_str()];
        a.extend(size);
        compare(&dir, file, &a);
    }
    // A LOD tree's cut, mixing levels under a budget that binds.
    let p = data.join("lidar/autzen_trim.laz");
    if p.exists() {
        let tree = dir.join("autzen.stlod");
        let out = Command::new(env!("CARGO_BIN_EXE_stipple"))
            .arg("build-lod")
            .arg(&p)
            .arg("-o")
            .arg(&tree)
            .args(["--max-node-points", "4096"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let t = tree.to_string_lossy().into_owned();
        let mut a = vec![t.as_str(), "--point-budget", "60000"];
        a.extend(size);
        compare(&dir, "autzen.stlod", &a);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `stipple bench --backend gpu` prints the host-side steps of a frame beside the passes'
/// GPU times, and compares the projection paths only where the pipeline projects points
/// (a splat frame has no projection pass: this once printed "NaN× faster").
#[test]
fn gpu_bench_reports_host_steps_and_compares_projections_only_when_projecting() {
    if !gpu_available() {
        return;
    }
    let bench = |extra: &[&str]| -> String {
        let out = Command::new(env!("CARGO_BIN_EXE_stipple"))
            .args([
                "bench", "--demo", "sphere", "--points", "20000", "--size", "96",
            ])
            .args(["--frames", "2", "--warmup", "0", "--backend", "gpu"])
            .args(extra)
            .output()
            .unwrap();
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.status.success(), "{text}");
        assert!(!text.contains("NaN"), "{text}");
        for step in ["of which host", "submit + wait", "read back"] {
            assert!(text.contains(step), "missing {step:?}: {text}");
        }
        text
    };
    let dobrev = bench(&["--pipeline", "dobrev"]);
    assert!(dobrev.contains("project (Hardware)"), "{dobrev}");
    let splat = bench(&["--pipeline", "splat"]);
    assert!(!splat.contains("project ("), "{splat}");
}

/// On a GL adapter (Mesa's llvmpipe through EGL, `WGPU_BACKEND=gl`), whose R32Float targets
/// are not renderable, `stipple devices` names what the adapter lacks, the default frame
/// renders (the hardware projection used to be built up front and failed with a raw wgpu
/// validation error), and `--projection hardware` is refused in one line.
#[test]
fn a_gl_adapter_renders_and_says_what_it_lacks() {
    let run = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_stipple"))
            .args(args)
            .env("WGPU_BACKEND", "gl")
            .current_dir(std::env::temp_dir())
            .output()
            .unwrap();
        let t = format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        (o.status.success(), t)
    };
    let (_, devices) = run(&["devices"]);
    if !devices.contains("(Gl, ") {
        eprintln!("skipped: no GL adapter (install libegl-mesa0): {devices}");
        return;
    }
    let png = std::env::temp_dir().join(format!("stipple-gl-{}.png", std::process::id()));
    let png = png.to_str().unwrap();
    let base = [
        "render", "--demo", "sphere", "--points", "3000", "--size", "48",
    ];
    let (ok, t) = run(&[&base[..], &["--backend", "gpu", "-o", png]].concat());
    assert!(ok && t.contains("(Gl, "), "{t}");
    if devices.contains("--projection hardware: unavailable") {
        let (ok, t) = run(&[
            &base[..],
            &["--backend", "gpu", "--projection", "hardware", "-o", png],
        ]
        .concat());
        assert!(!ok, "{t}");
        assert!(
            t.contains("this adapter cannot run --projection hardware"),
            "{t}"
        );
        assert!(!t.contains("Validation Error"), "{t}");
    }
    let _ = std::fs::remove_file(png);
}
