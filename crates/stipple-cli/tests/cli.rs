//! End to end through the `stipple` binary (DESIGN.md testing ladder, step 6).

mod common;

use common::{camera_vec3, cube_ply, stipple, tempdir, text};
use std::path::{Path, PathBuf};
use std::process::Command;

fn data(name: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(name);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipped: {} is absent", p.display());
        None
    }
}

#[test]
fn no_arguments_renders_the_demo_and_says_where() {
    let dir = tempdir("demo");
    let o = stipple(&dir, &["render", "--points", "200000", "--size", "320x240"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("wrote stipple-demo.png"), "{}", text(&o));
    let (w, h, rgba) = stipple_io::image::read_png(&dir.join("stipple-demo.png")).unwrap();
    assert_eq!((w, h), (320, 240));
    // Not a blank image: both background and object colours are present.
    let bg = [24u8, 26, 31, 255];
    let object = rgba.chunks_exact(4).filter(|p| *p != bg).count();
    assert!(
        object > 320 * 240 / 20 && object < 320 * 240,
        "{object} object pixels"
    );

    // And truly with no arguments at all; the demo's normals are consistent as given, so
    // nothing is re-oriented.
    let o = stipple(&dir, &[]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("stipple-demo.png"));
    assert!(!text(&o).contains("turned round"), "{}", text(&o));
    std::fs::remove_dir_all(dir).ok();
}

/// Empty pixels inside a surface: background pixels with a covered pixel within 3 px in
/// each of the four axis directions.
fn holes_inside(npy: &Path) -> usize {
    let (w, h, depth) = stipple_io::image::read_npy(npy).unwrap();
    let (w, h) = (w as i64, h as i64);
    let covered = |x: i64, y: i64| {
        (0..w).contains(&x) && (0..h).contains(&y) && depth[(y * w + x) as usize].is_finite()
    };
    let mut n = 0;
    for y in 0..h {
        for x in 0..w {
            if !covered(x, y)
                && [(1, 0), (-1, 0), (0, 1), (0, -1)]
                    .iter()
                    .all(|(dx, dy)| (1..=3).any(|s| covered(x + dx * s, y + dy * s)))
            {
                n += 1;
            }
        }
    }
    n
}

/// A closed surface sampled at random, about one visible point per pixel (the demo sphere),
/// renders whole at the default settings: with Dobrev's back-face culling, clusters of
/// empty pixels that the 3×3 fill cannot close showed as thousands of dark specks.
#[test]
fn a_randomly_sampled_sphere_renders_without_specks() {
    let dir = tempdir("specks");
    let run = |extra: &[&str], name: &str| {
        let npy = format!("{name}.npy");
        let mut a = vec!["render", "--demo", "sphere", "--points", "250000"];
        a.extend(["--size", "512x512", "--backend", "cpu", "-o"]);
        a.push(name);
        a.extend(["--depth-out", &npy]);
        a.extend(extra);
        let o = stipple(&dir, &a);
        assert!(o.status.success(), "{}", text(&o));
        let (_, _, depth) = stipple_io::image::read_npy(&dir.join(&npy)).unwrap();
        let covered = depth.iter().filter(|d| d.is_finite()).count();
        (holes_inside(&dir.join(&npy)), covered)
    };
    let (holes, covered) = run(&[], "default.png");
    let (culled, _) = run(&["--backface-culling"], "culled.png");
    eprintln!("{holes} holes in {covered} covered pixels; {culled} with culling");
    assert!(covered > 40_000, "{covered}");
    assert!(
        holes * 10_000 <= covered,
        "{holes} holes in {covered} pixels"
    );
    // The scene is one the culled projection leaves holes in, so the check means something.
    assert!(culled > 20 * holes.max(1), "{culled} holes with culling");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn depth_and_camera_outputs_follow_the_conventions() {
    let dir = tempdir("outputs");
    let o = stipple(
        &dir,
        &[
            "render",
            "--demo",
            "sphere",
            "--points",
            "200000",
            "--size",
            "200x100",
            "--eye",
            "0,0,5",
            "--target",
            "0,0,0",
            "--fov",
            "30",
            "-o",
            "s.png",
            "--depth-out",
            "s.npy",
            "--camera-out",
            "s.json",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let (w, h, depth) = stipple_io::image::read_npy(&dir.join("s.npy")).unwrap();
    assert_eq!((w, h), (200, 100));
    // Background is +inf; the sphere's nearest point is at view depth 4 in the middle.
    assert_eq!(depth[0], f32::INFINITY);
    let centre = depth[50 * 200 + 100];
    assert!((centre - 4.0).abs() < 0.01, "centre depth {centre}");
    let cam: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("s.json")).unwrap()).unwrap();
    assert_eq!(cam["size"], serde_json::json!([200, 100]));
    assert_eq!(cam["fov"], serde_json::json!(30.0));
    assert_eq!(cam["eye"], serde_json::json!([0.0, 0.0, 5.0]));
    let far = cam["far"].as_f64().unwrap();
    let near = cam["near"].as_f64().unwrap();
    assert!(
        near > 0.0 && near < 4.0 && far > 6.0,
        "near {near} far {far}"
    );
    assert_eq!(cam["view"].as_array().unwrap().len(), 4);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn gen_then_info_then_render() {
    let dir = tempdir("gen");
    let o = stipple(
        &dir,
        &[
            "gen", "torus", "-o", "t.ply", "--points", "50000", "--seed", "4",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let o = stipple(&dir, &["info", "t.ply"]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("points      50000") && t.contains("normal") && t.contains("spacing"),
        "{t}"
    );
    // gen never overwrites without --force.
    let before = std::fs::read(dir.join("t.ply")).unwrap();
    let o = stipple(&dir, &["gen", "sphere", "-o", "t.ply"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("already exists"), "{}", text(&o));
    assert_eq!(std::fs::read(dir.join("t.ply")).unwrap(), before);
    let o = stipple(&dir, &["render", "t.ply", "--size", "128x128"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(dir.join("t.png").exists());
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn inputs_are_never_overwritten_and_errors_are_clear() {
    let dir = tempdir("errors");
    std::fs::write(dir.join("cloud.xyz"), "0 0 0\n1 0 0\n0 1 0\n1 1 1\n").unwrap();
    let before = std::fs::read(dir.join("cloud.xyz")).unwrap();
    // Writing the image over the input is refused (whatever the extension check says first).
    std::fs::copy(dir.join("cloud.xyz"), dir.join("cloud.png")).unwrap();
    let o = stipple(&dir, &["render", "cloud.png"]);
    assert!(!o.status.success());
    let o = stipple(&dir, &["render", "cloud.xyz", "--depth-out", "cloud.xyz"]);
    assert!(!o.status.success());
    let o = stipple(
        &dir,
        &["render", "cloud.xyz", "--camera-out", "./cloud.xyz"],
    );
    assert!(
        text(&o).contains("refusing to overwrite an input file"),
        "{}",
        text(&o)
    );
    assert_eq!(std::fs::read(dir.join("cloud.xyz")).unwrap(), before);

    // A malformed file: exit code 1, the file named, no panic.
    std::fs::write(dir.join("bad.ply"), "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n").unwrap();
    let o = stipple(&dir, &["render", "bad.ply"]);
    assert_eq!(o.status.code(), Some(1));
    let t = text(&o);
    assert!(
        t.contains("bad.ply") && t.contains("error") && !t.contains("panicked"),
        "{t}"
    );

    for (args, phrase) in [
        (vec!["render", "--size", "0x10"], "not a size"),
        (
            vec!["render", "--eye", "1,2"],
            "three comma-separated numbers",
        ),
        (vec!["render", "--demo", "teapot"], "unknown scene"),
        (
            vec!["render", "--fill-background-iterations", "many"],
            "not an iteration count",
        ),
        (
            vec!["render", "--backend", "cpu", "--projection", "hardware"],
            "needs the GPU backend",
        ),
        (
            vec!["render", "--eye", "0,0,0", "--target", "0,0,0"],
            "eye and target coincide",
        ),
        (vec!["info", "missing.laz"], "missing.laz"),
        // Numbers are checked where they are given, naming the flag and the reason.
        (
            vec!["render", "--fov", "0"],
            "strictly between 0 and 180 degrees",
        ),
        (vec!["render", "--fov", "180"], "--fov"),
        (
            vec!["render", "--aa-threshold", "nan"],
            "not a finite number",
        ),
        (vec!["render", "--opacity", "inf"], "--opacity"),
        (vec!["render", "--ortho", "0"], "must be above zero"),
        (vec!["render", "--lod-error", "NaN"], "--lod-error"),
        (vec!["render", "--loaders", "100000"], "give 1 to 64"),
        (
            vec![
                "build-lod",
                "cloud.xyz",
                "-o",
                "t.stlod",
                "--threads",
                "100000",
            ],
            "give 1 to 1024",
        ),
    ] {
        let o = stipple(&dir, &args);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(text(&o).contains(phrase), "{args:?}: {}", text(&o));
        assert!(!text(&o).contains("panicked"), "{args:?}: {}", text(&o));
    }
    std::fs::remove_dir_all(dir).ok();
}

/// Degenerate clouds render with a message, never a silent blank image: one point (too few
/// for normals: drawn as an unlit point) and points that all coincide.
#[test]
fn degenerate_clouds_say_what_the_image_shows() {
    let dir = tempdir("degenerate");
    std::fs::write(dir.join("one.xyz"), "1 2 3\n").unwrap();
    std::fs::write(dir.join("same.xyz"), "1 2 3\n".repeat(5000)).unwrap();
    for (name, phrases) in [
        (
            "one.xyz",
            &["1 point: too few to estimate normals", "a single dot"][..],
        ),
        ("same.xyz", &["all 5000 points lie at one position"][..]),
    ] {
        let o = stipple(&dir, &["render", name, "--size", "64", "-o", "x.png"]);
        let t = text(&o);
        assert!(o.status.success(), "{name}: {t}");
        for p in phrases {
            assert!(t.contains(p), "{name}: missing {p:?}: {t}");
        }
        let (w, _, rgba) = stipple_io::image::read_png(&dir.join("x.png")).unwrap();
        let bg = &rgba[..4];
        let centre = (32 * w as usize + 32) * 4;
        let lit = rgba.chunks(4).filter(|p| *p != bg).count();
        assert!(lit >= 1, "{name}: blank image");
        assert!(
            rgba[centre - 8..centre + 8].chunks(4).any(|p| p != bg),
            "{name}: the dot is not at the centre"
        );
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn pipeline_switches_change_the_image() {
    let dir = tempdir("switches");
    let base = [
        "render",
        "--demo",
        "torus",
        "--points",
        "40000",
        "--size",
        "256x256",
        "--pipeline",
        "dobrev",
    ];
    let run = |extra: &[&str], out: &str| {
        let npy = format!("{out}.npy");
        let mut a: Vec<&str> = base.to_vec();
        a.extend_from_slice(extra);
        a.extend_from_slice(&["-o", out, "--depth-out", &npy]);
        let o = stipple(&dir, &a);
        assert!(o.status.success(), "{}", text(&o));
        stipple_io::image::read_npy(&dir.join(format!("{out}.npy")))
            .unwrap()
            .2
    };
    let covered = |d: &[f32]| d.iter().filter(|v| v.is_finite()).count();
    let full = run(&[], "full.png");
    let raw = run(&["--points-only"], "raw.png");
    let auto = run(&["--fill-background-iterations", "3"], "more.png");
    assert!(covered(&raw) < covered(&full), "filling adds pixels");
    assert!(
        covered(&full) <= covered(&auto),
        "more iterations fill at least as much"
    );
    let no_bg = run(&["--no-fill-background"], "nobg.png");
    assert!(covered(&no_bg) < covered(&full));
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn real_files_render() {
    let dir = tempdir("real");
    for name in [
        "stanford/bunny/bun_zipper_res2.ply",
        "lidar/autzen_trim.laz",
    ] {
        let Some(p) = data(name) else { return };
        let o = stipple(
            &dir,
            &[
                "render",
                p.to_str().unwrap(),
                "--size",
                "256x192",
                "-o",
                "r.png",
            ],
        );
        assert!(o.status.success(), "{name}: {}", text(&o));
        let (_, _, rgba) = stipple_io::image::read_png(&dir.join("r.png")).unwrap();
        let bg = [24u8, 26, 31, 255];
        assert!(
            rgba.chunks_exact(4).filter(|p| *p != bg).count() > 256 * 192 / 20,
            "{name}: nearly empty"
        );
    }
    std::fs::remove_dir_all(dir).ok();
}

/// With no adapter (WGPU_BACKEND names a backend this build has no adapter for), `gpu` is a
/// clear error and `auto` renders on the CPU, saying so once.
#[test]
fn backend_choice_without_an_adapter() {
    let dir = tempdir("backend");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_stipple"))
            .args(args)
            .env("WGPU_BACKEND", "metal")
            .current_dir(&dir)
            .output()
            .unwrap()
    };
    let small = ["--points", "20000", "--size", "64x48"];
    let mut a = vec!["render", "--backend", "gpu"];
    a.extend(small);
    let o = run(&a);
    assert!(!o.status.success());
    assert!(text(&o).contains("no suitable GPU adapter"), "{}", text(&o));
    assert!(!text(&o).contains("panicked"), "{}", text(&o));
    let mut a = vec!["render", "--backend", "auto"];
    a.extend(small);
    let o = run(&a);
    assert!(o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.matches("rendering on the CPU").count(), 1, "{err}");
    assert!(String::from_utf8_lossy(&o.stdout).contains("on cpu"));
    let o = run(&["devices"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("no GPU adapters found"), "{}", text(&o));
    std::fs::remove_dir_all(dir).ok();
}

/// A GPU run on a machine with no desktop session (ssh, containers, CI: no `XDG_RUNTIME_DIR`)
/// prints nothing but its own lines: Mesa's device-select layer, which asked libwayland for a
/// compositor and printed "error: XDG_RUNTIME_DIR is invalid or not set" twice, is switched
/// off there.
#[test]
fn a_gpu_run_without_a_desktop_session_prints_no_wayland_errors() {
    if !common::gpu_available() {
        return;
    }
    let dir = tempdir("headless");
    let out = Command::new(env!("CARGO_BIN_EXE_stipple"))
        .args(["render", "--points", "20000", "--size", "64x48"])
        .args(["--backend", "gpu", "-o"])
        .arg(dir.join("a.png"))
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .env_remove("MESA_VK_DEVICE_SELECT")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(!err.contains("XDG_RUNTIME_DIR"), "{err}");
    assert!(!err.contains("error"), "{err}");
    std::fs::remove_dir_all(dir).ok();
}

/// On a machine whose only adapter is a software rasterizer (lavapipe, as in CI), `auto`
/// renders on the CPU and says why; `gpu` uses the software adapter.
#[test]
fn auto_passes_over_a_software_adapter() {
    let Ok(ctx) = stipple_render::gpu::GpuContext::new(Default::default()) else {
        eprintln!("skipped: no GPU adapter");
        return;
    };
    if !ctx.adapter.is_software() {
        eprintln!(
            "skipped: the adapter is a hardware GPU ({})",
            ctx.describe()
        );
        return;
    }
    let dir = tempdir("software");
    let o = stipple(&dir, &["render", "--points", "20000", "--size", "64x48"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("software rasterizer"), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("on cpu"));
    let o = stipple(
        &dir,
        &[
            "render",
            "--points",
            "20000",
            "--size",
            "64x48",
            "--backend",
            "gpu",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("on gpu"),
        "{}",
        text(&o)
    );
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn clouds_without_normals_get_estimated_normals_and_raw_on_request() {
    let Some(laz) = data("lidar/autzen_trim.laz") else {
        return;
    };
    let dir = tempdir("raw");
    let laz = laz.to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["render", laz, "--size", "200x150", "--stats", "-o", "r.png"];
        args.extend_from_slice(extra);
        let o = stipple(&dir, &args);
        assert!(o.status.success(), "{extra:?}: {}", text(&o));
        text(&o)
    };
    // Default: normals are estimated and the cloud is lit (splats or Dobrev by spacing).
    let auto = run(&["--backend", "cpu"]);
    assert!(auto.contains("estimated normals"), "{auto}");
    assert!(
        auto.contains("shade") && !auto.contains("visibility"),
        "{auto}"
    );
    let raw = run(&["--backend", "cpu", "--raw"]);
    for pass in ["visibility", "fill_anisotropic", "depiction"] {
        assert!(raw.contains(pass), "--raw lacks {pass}: {raw}");
    }
    // Without estimation a cloud without normals falls back to the raw operators.
    let unlit = run(&["--backend", "cpu", "--no-estimate-normals"]);
    assert!(
        unlit.contains("visibility") && !unlit.contains("estimated"),
        "{unlit}"
    );
    let dobrev = run(&["--backend", "cpu", "--pipeline", "dobrev"]);
    assert!(dobrev.contains("fill_background") && !dobrev.contains("visibility"));
    let splat = run(&["--backend", "cpu", "--pipeline", "splat"]);
    assert!(
        splat.contains("splat") && !splat.contains("fill_background"),
        "{splat}"
    );
    let edl = run(&[
        "--backend",
        "cpu",
        "--raw",
        "--shading",
        "edl",
        "--visibility-kernel",
        "5",
    ]);
    assert!(edl.contains("edl") && !edl.contains("depiction"), "{edl}");
    let off = run(&[
        "--backend",
        "cpu",
        "--raw",
        "--no-visibility",
        "--shading",
        "none",
    ]);
    assert!(!off.contains("visibility") && off.contains("fill_anisotropic"));
    for bad in [
        vec!["--visibility-kernel", "20"],
        vec!["--visibility-threshold", "1.5"],
        vec!["--pipeline", "fancy"],
        vec!["--fill-delta", "-1"],
        vec!["--splat", "fuzzy"],
        vec!["--splat-scale", "0"],
        vec!["--splat-epsilon", "-1"],
        vec!["--normal-k", "2"],
        vec!["--pipeline", "splat", "--layers", "3"],
        vec!["--normal-out", "n.png"],
    ] {
        let mut args = vec!["render", laz, "-o", "x.png"];
        args.extend_from_slice(&bad);
        let o = stipple(&dir, &args);
        assert!(!o.status.success(), "{bad:?} accepted");
        assert!(!text(&o).contains("panicked"), "{}", text(&o));
    }
    assert!(!dir.join("x.png").exists());
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn eval_compares_a_raw_rendering_with_the_mesh() {
    let Some(mesh) = data("stanford/bunny/bun_zipper.ply") else {
        return;
    };
    let dir = tempdir("eval");
    let o = stipple(
        &dir,
        &[
            "eval",
            mesh.to_str().unwrap(),
            "--size",
            "256x256",
            "--backend",
            "cpu",
            "--render-out",
            "raw.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("above 0.5%") && t.contains("wrote bun_zipper-error.png"),
        "{t}"
    );
    let (w, h, err) = stipple_io::image::read_png(&dir.join("bun_zipper-error.png")).unwrap();
    assert_eq!((w, h), (256, 256));
    // Black background and mostly small errors inside; white (error ≥ 0.5%) only along
    // contours, a small share.
    let grey = |p: &[u8]| p[0] == p[1] && p[1] == p[2];
    let dark = err.chunks_exact(4).filter(|p| grey(p) && p[0] < 40).count();
    let white = err
        .chunks_exact(4)
        .filter(|p| grey(p) && p[0] == 255)
        .count();
    assert!(dark > 256 * 256 * 3 / 4, "{dark}");
    assert!(white > 0 && white < 256 * 256 / 20, "{white}");
    assert!(dir.join("raw.png").exists());
    // A cloud without faces cannot be evaluated.
    if let Some(laz) = data("lidar/autzen_trim.laz") {
        let o = stipple(&dir, &["eval", laz.to_str().unwrap()]);
        assert!(!o.status.success());
        assert!(text(&o).contains("has no faces"), "{}", text(&o));
    }
    std::fs::remove_dir_all(dir).ok();
}

/// LAS/LAZ are framed Z-up (Z is elevation), other files Y-up unless flat in Z: the same
/// round cloud written as LAS and as PLY gets an up vector of +Z and +Y.
#[test]
fn lidar_formats_are_framed_z_up() {
    let dir = tempdir("z-up");
    for (file, up) in [("s.las", [0.0, 0.0, 1.0]), ("s.ply", [0.0, 1.0, 0.0])] {
        let o = stipple(
            &dir,
            &["gen", "sphere", "--points", "3000", "-o", file, "--force"],
        );
        assert!(o.status.success(), "{}", text(&o));
        let o = stipple(
            &dir,
            &[
                "render",
                file,
                "--size",
                "48",
                "-o",
                "x.png",
                "--camera-out",
                "c.json",
            ],
        );
        assert!(o.status.success(), "{}", text(&o));
        let got = camera_vec3(&dir.join("c.json"), "up");
        assert_eq!(got, up, "{file}");
    }
    std::fs::remove_dir_all(dir).ok();
}

/// `--shadow-samples` is honoured above a light's own count (it was silently capped at 16),
/// and shadows asked of the raw pipeline, which draws without lights, are refused with the
/// reason (it said "no light casts shadows" although a light was given).
#[test]
fn shadow_flags_are_honoured_or_explained() {
    let dir = tempdir("shadow-flags");
    let base = [
        "render",
        "--demo",
        "sphere",
        "--points",
        "4000",
        "--size",
        "48",
        "-o",
        "x.png",
        "--shadows",
        "--light",
        "disc:0,3,2,0.5",
    ];
    let o = stipple(&dir, &[&base[..], &["--shadow-samples", "30"]].concat());
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("30 light samples"), "{}", text(&o));
    let o = stipple(&dir, &[&base[..], &["--raw"]].concat());
    assert!(!o.status.success());
    assert!(text(&o).contains("raw pipeline"), "{}", text(&o));
    std::fs::remove_dir_all(dir).ok();
}

/// Needs beyond the memory budget are refused before any work, naming the need and the
/// budget (free memory, `ulimit -v`, or `--memory`); outputs into /dev are refused.
#[test]
fn memory_needs_are_checked_before_allocating() {
    let dir = tempdir("memory");
    for (args, want) in [
        (
            vec!["gen", "torus", "--points", "1000000000000", "-o", "t.ply"],
            "--points 1000000000000 needs about",
        ),
        (
            vec!["render", "--demo", "torus", "--points", "1000000000000"],
            "raise the budget with --memory",
        ),
        (
            vec![
                "render", "--demo", "sphere", "--points", "100000", "--memory", "1M",
            ],
            "more than the --memory budget (1 MiB)",
        ),
        (
            vec!["gen", "sphere", "-o", "/dev/stipple-test.ply"],
            "/dev holds devices",
        ),
    ] {
        let o = stipple(&dir, &args);
        assert!(!o.status.success(), "{args:?}: {}", text(&o));
        assert!(text(&o).contains(want), "{args:?}: {}", text(&o));
    }
    assert!(!Path::new("/dev/stipple-test.ply").exists());
    assert!(!dir.join("t.ply").exists());
    // Under `ulimit -v` the budget is what the limit leaves.
    let o = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v 1500000 && exec '{}' render --demo sphere --points 1000 --size 8192 -o x.png",
            env!("CARGO_BIN_EXE_stipple")
        ))
        .current_dir(&dir)
        .output()
        .unwrap();
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(
        t.contains("a 8192×8192 image needs about") && t.contains("ulimit -v"),
        "{t}"
    );
    // Within a limit that fits the frame, `auto` renders on the CPU without probing GPU
    // drivers (whose mappings exhausted the limit: an abort), and build-lod's default
    // budget stays inside the limit.
    let bin = env!("CARGO_BIN_EXE_stipple");
    let o = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v 600000 && '{bin}' gen sphere --points 20000 -o s.las && \
             '{bin}' render s.las --size 256 -o s.png && '{bin}' build-lod s.las -o s.stlod"
        ))
        .current_dir(&dir)
        .output()
        .unwrap();
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("without probing GPU drivers"), "{t}");
    let budget: u64 = t
        .split("memory budget ")
        .nth(1)
        .and_then(|r| r.split(" MiB").next())
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no budget in {t}"));
    assert!(budget < 600, "{t}");
    // A small .ply.gz that inflates to 600 MB of padding after its three vertices is read
    // only as far as its header's records reach: it fits a 500 MB limit.
    let o = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "printf 'ply\\nformat ascii 1.0\\nelement vertex 3\\nproperty float x\\n\
             property float y\\nproperty float z\\nend_header\\n0 0 0\\n1 0 0\\n0 1 0\\n' \
             > b.ply && (cat b.ply; head -c 600000000 /dev/zero) | gzip -c > bomb.ply.gz && \
             ulimit -v 500000 && '{bin}' info bomb.ply.gz"
        ))
        .current_dir(&dir)
        .output()
        .unwrap();
    let t = text(&o);
    assert!(o.status.success() && t.contains("points      3"), "{t}");
    // A --memory budget above what `ulimit -v` allows passes the estimate; the refused
    // allocation is then a one-line error with exit status 1, not an abort, and no output
    // appears.
    let o = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v 400000 && exec '{bin}' render --demo sphere --points 1000 --size 4096 \
             --memory 100G --backend cpu -o big.png"
        ))
        .env_remove("RUST_BACKTRACE")
        .current_dir(&dir)
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("stipple: error: out of memory"), "{t}");
    assert!(!dir.join("big.png").exists());
    std::fs::remove_dir_all(dir).ok();
}

/// A reader that goes away (`| head`) ends stipple quietly, as it does any Unix tool; it
/// used to panic with "failed printing to stdout: Broken pipe". (400 reports are more than
/// a pipe's buffer, so the write after `head` has gone is certain.)
#[test]
fn a_closed_pipe_is_not_a_panic() {
    let dir = tempdir("pipe");
    let bin = env!("CARGO_BIN_EXE_stipple");
    let o = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "'{bin}' gen sphere --points 500 -o s.xyz && \
             '{bin}' info $(for i in $(seq 400); do printf 's.xyz '; done) | head -c 1 >/dev/null"
        ))
        .current_dir(&dir)
        .output()
        .unwrap();
    let t = text(&o);
    assert!(!t.contains("panicked") && !t.contains("Broken pipe"), "{t}");
    std::fs::remove_dir_all(dir).ok();
}

/// `--points-only` holds for the raw pipeline too, and `--raw-fill-iterations 0` runs no
/// fill (both used to run every pass).
#[test]
fn raw_pipeline_honours_points_only_and_zero_fill_iterations() {
    let dir = tempdir("raw-flags");
    let passes = |extra: &[&str]| -> String {
        let base = [
            "render",
            "--demo",
            "sphere",
            "--points",
            "5000",
            "--size",
            "64",
            "--raw",
            "--stats",
            "--backend",
            "cpu",
            "-o",
            "r.png",
        ];
        let o = stipple(&dir, &[&base[..], extra].concat());
        assert!(o.status.success(), "{}", text(&o));
        text(&o)
    };
    let all = passes(&[]);
    assert!(
        all.contains("fill_anisotropic") && all.contains("visibility"),
        "{all}"
    );
    let points = passes(&["--points-only"]);
    for p in ["fill_anisotropic", "visibility", "depiction"] {
        assert!(!points.contains(p), "--points-only ran {p}: {points}");
    }
    let no_fill = passes(&["--raw-fill-iterations", "0"]);
    assert!(
        !no_fill.contains("fill_anisotropic") && no_fill.contains("visibility"),
        "{no_fill}"
    );
    std::fs::remove_dir_all(dir).ok();
}

/// `--colour-by x --colour-map grey` paints a plane from black on the left to white on the
/// right (the range given), through every pipeline's shading; a missing attribute is an
/// error naming the file; `--range` needs `--colour-by`.
#[test]
fn colour_by_attribute_maps_values_through_the_colour_map() {
    let dir = tempdir("colour-by");
    let mut s = String::new();
    for j in 0..120 {
        for i in 0..120 {
            s.push_str(&format!(
                "{} {} 0\n",
                i as f32 / 119.0 * 2.0 - 1.0,
                j as f32 / 119.0 * 2.0 - 1.0
            ));
        }
    }
    std::fs::write(dir.join("plane.xyz"), s).unwrap();
    let o = stipple(
        &dir,
        &[
            "render",
            "plane.xyz",
            "--size",
            "64",
            "--backend",
            "cpu",
            "--eye",
            "0,0,3",
            "--target",
            "0,0,0",
            "--up",
            "0,1,0",
            "--no-lighting",
            "--colour-by",
            "x",
            "--colour-map",
            "grey",
            "--range",
            "-1,1",
            "-o",
            "g.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("colouring by x: -1.000 … 1.000 over the grey colour map"),
        "{}",
        text(&o)
    );
    let (w, _, rgba) = stipple_io::image::read_png(&dir.join("g.png")).unwrap();
    let px = |x: usize, y: usize| rgba[4 * (y * w as usize + x)];
    // Left darker than the middle, the middle darker than the right, along a row.
    let row = 32;
    let (l, m, r) = (px(16, row), px(32, row), px(48, row));
    assert!(l + 40 < m && m + 40 < r, "{l} {m} {r}");
    for (bad, want) in [
        (
            vec!["--colour-by", "classification"],
            "plane.xyz: --colour-by: the cloud has no classification values",
        ),
        (vec!["--colour-by", "intensity"], "no intensity values"),
        (vec!["--colour-by", "return"], "no return-number values"),
        (vec!["--range", "0,1"], "--colour-by"),
        (vec!["--colour-by", "z", "--range", "3,1"], "LO < HI"),
        (vec!["--colour-by", "z", "--colour-map", "jet"], "viridis"),
    ] {
        let mut a = vec!["render", "plane.xyz", "--size", "32", "-o", "bad.png"];
        a.extend(bad.iter());
        let o = stipple(&dir, &a);
        assert!(!o.status.success(), "{bad:?} accepted");
        assert!(text(&o).contains(want), "{bad:?}: {}", text(&o));
        assert!(!dir.join("bad.png").exists());
    }
    std::fs::remove_dir_all(dir).ok();
}

/// A PLY's extra properties are scalar fields: `--colour-by segment` maps one through the
/// colour map, and `--lookup` colours, hides and sets the opacity of the points by its
/// integer value (three bands of a plane: red, hidden, blue); bad tables and keys are
/// errors naming the file.
#[test]
fn scalar_fields_colour_and_index_lookup_tables() {
    let dir = tempdir("lookup");
    let mut s = String::from(
        "ply\nformat ascii 1.0\nelement vertex 14400\nproperty float x\nproperty float y\n\
         property float z\nproperty uchar segment\nproperty float w\nend_header\n",
    );
    for j in 0..120 {
        for i in 0..120 {
            s.push_str(&format!(
                "{} {} 0 {} 0.5\n",
                i as f32 / 119.0 * 2.0 - 1.0,
                j as f32 / 119.0 * 2.0 - 1.0,
                1 + i / 40
            ));
        }
    }
    std::fs::write(dir.join("plane.ply"), s).unwrap();
    std::fs::write(
        dir.join("t.toml"),
        "key = \"segment\"\n[value.1]\nname = \"left\"\ncolour = [255, 0, 0]\n\
         [value.2]\nshow = false\n[value.3]\ncolor = [0, 0, 255]\n",
    )
    .unwrap();
    let view = [
        "--size",
        "64",
        "--backend",
        "cpu",
        "--eye",
        "0,0,3",
        "--target",
        "0,0,0",
        "--up",
        "0,1,0",
        "--no-lighting",
        "--background",
        "0,0,0",
    ];
    let render = |extra: &[&str], out: &str| {
        let mut a = vec!["render", "plane.ply", "-o", out];
        a.extend(view);
        a.extend(extra);
        let o = stipple(&dir, &a);
        assert!(o.status.success(), "{extra:?}: {}", text(&o));
        let (w, _, rgba) = stipple_io::image::read_png(&dir.join(out)).unwrap();
        (text(&o), move |x: usize, y: usize| {
            let i = 4 * (y * w as usize + x);
            [rgba[i], rgba[i + 1], rgba[i + 2]]
        })
    };
    let (out, px) = render(
        &[
            "--colour-by",
            "segment",
            "--colour-map",
            "grey",
            "--range",
            "1,3",
        ],
        "g.png",
    );
    assert!(out.contains("the field `segment`"), "{out}");
    let (l, m, r) = (px(14, 32)[0], px(32, 32)[0], px(50, 32)[0]);
    assert!(l + 60 < m && m + 60 < r, "{l} {m} {r}");
    let (out, px) = render(&["--lookup", "t.toml"], "l.png");
    assert!(
        out.contains("by segment") && out.contains("1 left 4800"),
        "{out}"
    );
    assert!(out.contains("4800 points hidden"), "{out}");
    let [r, g, b] = px(14, 32);
    assert!(r > 200 && g < 40 && b < 40, "left {r} {g} {b}");
    assert_eq!(
        px(32, 32),
        [0, 0, 0],
        "the hidden band shows the background"
    );
    let [r, g, b] = px(50, 32);
    assert!(b > 200 && r < 40 && g < 40, "right {r} {g} {b}");
    for (table, want) in [
        (
            "key = \"segment\"\n[value.x]\n",
            "t.toml: `[value.x]`: the key must be an integer",
        ),
        ("key = \"segment\"\n[value.1]\nopacity = 3\n", "opacity 3"),
        ("key = \"segment\"\nbogus = 1\n", "unknown field `bogus`"),
        (
            "key = \"labels\"\n",
            "no `labels` to look up (it has: position, segment, w)",
        ),
        ("key = \"w\"\n", "w = 0.5, not an integer"),
        (
            "key = \"segment\"\n[default]\nshow = false\n",
            "hides every point",
        ),
    ] {
        std::fs::write(dir.join("t.toml"), table).unwrap();
        let mut a = vec!["render", "plane.ply", "--lookup", "t.toml", "-o", "bad.png"];
        a.extend(view);
        let o = stipple(&dir, &a);
        assert!(!o.status.success(), "{table:?} accepted");
        assert!(text(&o).contains(want), "{table:?}: {}", text(&o));
        assert!(!dir.join("bad.png").exists());
    }
    let o = stipple(
        &dir,
        &[
            "render",
            "plane.ply",
            "--lookup",
            "none.toml",
            "-o",
            "bad.png",
        ],
    );
    assert!(
        !o.status.success() && text(&o).contains("none.toml"),
        "{}",
        text(&o)
    );
    std::fs::remove_dir_all(dir).ok();
}

/// `stipple convert` samples a mesh's faces to points: a cube's surface at the spacing
/// asked for, every point on a face with its outward normal; the input is only read, and
/// clouds without faces, existing outputs and impossible spacings are clear errors.
#[test]
fn convert_samples_a_mesh_to_points_on_its_faces() {
    let dir = tempdir("convert");
    let ply = cube_ply();
    std::fs::write(dir.join("cube.ply"), &ply).unwrap();
    let o = stipple(
        &dir,
        &["convert", "cube.ply", "-o", "pts.ply", "--spacing", "0.05"],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(std::fs::read_to_string(dir.join("cube.ply")).unwrap(), ply);
    let c = stipple_io::read_cloud(&dir.join("pts.ply")).unwrap();
    // 6 / 0.05² = 2 400 expected.
    assert!(
        (c.len() as f64 - 2400.0).abs() < 150.0,
        "{} points",
        c.len()
    );
    assert!(c.faces.is_empty());
    let n = c.normals.as_ref().expect("normals written");
    for i in 0..c.len() {
        let p = c.world(i);
        let on_face = (0..3).any(|a| p[a].abs() < 1e-6 || (p[a] - 1.0).abs() < 1e-6);
        assert!(
            on_face && p.min_element() > -1e-6 && p.max_element() < 1.0 + 1e-6,
            "{p}"
        );
        assert!(
            n[i].as_dvec3().dot(p - glam::DVec3::splat(0.5)) > 0.0,
            "normal {i} inward"
        );
    }
    for (bad, want) in [
        (
            vec!["convert", "pts.ply", "-o", "again.ply"],
            "has no faces",
        ),
        (
            vec!["convert", "cube.ply", "-o", "pts.ply"],
            "already exists",
        ),
        (
            vec!["convert", "cube.ply", "-o", "cube.ply", "--force"],
            "cube.ply",
        ),
        (
            vec!["convert", "cube.ply", "-o", "x.ply", "--spacing", "0"],
            "positive",
        ),
        (
            vec![
                "convert",
                "cube.ply",
                "-o",
                "x.ply",
                "--spacing",
                "1e-9",
                "--memory",
                "1G",
            ],
            "--memory",
        ),
        (vec!["convert", "cube.ply", "-o", "x.png"], ".ply, .las"),
    ] {
        let o = stipple(&dir, &bad);
        assert!(!o.status.success(), "{bad:?} accepted");
        assert!(text(&o).contains(want), "{bad:?}: {}", text(&o));
        assert!(!dir.join("x.ply").exists() && !dir.join("again.ply").exists());
    }
    std::fs::remove_dir_all(dir).ok();
}

/// OBJ and STL meshes render (their vertices) and convert (their faces) like PLY meshes.
#[test]
fn obj_and_stl_meshes_render_and_convert() {
    let dir = tempdir("obj-stl");
    // A square pyramid: OBJ with quads for the base, STL binary with its 6 triangles.
    let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 1\n\
               f 4 3 2 1\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n";
    std::fs::write(dir.join("pyramid.obj"), obj).unwrap();
    let c = stipple_io::read_cloud(&dir.join("pyramid.obj")).unwrap();
    let mut stl = vec![0u8; 80];
    stl.extend_from_slice(&(c.faces.len() as u32).to_le_bytes());
    for f in &c.faces {
        stl.extend_from_slice(&[0u8; 12]);
        for &v in f {
            for x in c.world(v as usize).to_array() {
                stl.extend_from_slice(&(x as f32).to_le_bytes());
            }
        }
        stl.extend_from_slice(&[0u8; 2]);
    }
    std::fs::write(dir.join("pyramid.stl"), stl).unwrap();
    for f in ["pyramid.obj", "pyramid.stl"] {
        let out = format!("{f}.ply");
        let o = stipple(&dir, &["convert", f, "-o", &out, "--spacing", "0.05"]);
        assert!(o.status.success(), "{f}: {}", text(&o));
        let pts = stipple_io::read_cloud(&dir.join(&out)).unwrap();
        // Base 1 + four sides of √1.25 / 2 each: about 3.24 / 0.05² = 1 300 points.
        assert!(
            (pts.len() as f64 - 1300.0).abs() < 120.0,
            "{f}: {}",
            pts.len()
        );
        let o = stipple(
            &dir,
            &[
                "render",
                f,
                "--size",
                "64",
                "--backend",
                "cpu",
                "-o",
                "r.png",
            ],
        );
        assert!(o.status.success(), "{f}: {}", text(&o));
    }
    std::fs::write(dir.join("bad.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let o = stipple(&dir, &["render", "bad.obj", "-o", "r.png"]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("bad.obj") && text(&o).contains("line 2"),
        "{}",
        text(&o)
    );
    std::fs::remove_dir_all(dir).ok();
}

/// A PCD that records its sensor (VIEWPOINT) is seen from the sensor by default, aimed at
/// its points, whichever way round the writer stored the pose (PCL's Kinect frames carry a
/// half turn about x with the points in front along +z); estimated normals face the sensor.
#[test]
fn a_pcd_is_seen_from_its_sensor() {
    let dir = tempdir("pcd-sensor");
    for (name, viewpoint) in [("a.pcd", "1 2 3 1 0 0 0"), ("b.pcd", "1 2 3 0 1 0 0")] {
        let mut s = format!(
            "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 400\nHEIGHT 1\n\
             VIEWPOINT {viewpoint}\nPOINTS 400\nDATA ascii\n"
        );
        // A wall 4 units in front of the sensor along +z.
        for k in 0..400 {
            s.push_str(&format!(
                "{} {} 7\n",
                1.0 + (k % 20) as f32 * 0.05,
                2.0 + (k / 20) as f32 * 0.05
            ));
        }
        std::fs::write(dir.join(name), s).unwrap();
        let o = stipple(
            &dir,
            &[
                "render",
                name,
                "--size",
                "64",
                "--backend",
                "cpu",
                "--camera-out",
                "c.json",
                "-o",
                "x.png",
            ],
        );
        assert!(o.status.success(), "{name}: {}", text(&o));
        let eye = camera_vec3(&dir.join("c.json"), "eye");
        assert!(
            (eye[0] - 1.0).abs() < 1e-9
                && (eye[1] - 2.0).abs() < 1e-9
                && (eye[2] - 3.0).abs() < 1e-9,
            "{name}: {eye:?}"
        );
        let (_, _, d) = {
            let o = stipple(
                &dir,
                &[
                    "render",
                    name,
                    "--size",
                    "64",
                    "--backend",
                    "cpu",
                    "--depth-out",
                    "d.npy",
                    "-o",
                    "x.png",
                ],
            );
            assert!(o.status.success());
            stipple_io::image::read_npy(&dir.join("d.npy")).unwrap()
        };
        // The wall fills most of the image, about 4 units away (the view is aimed at its
        // centre, a little off the sensor axis).
        let covered: Vec<f32> = d.iter().copied().filter(|x| x.is_finite()).collect();
        assert!(covered.len() > 64 * 64 / 3, "{name}: {} px", covered.len());
        assert!(covered.iter().all(|&z| z > 3.8 && z < 4.2), "{name}");
    }
    std::fs::remove_dir_all(dir).ok();
}

/// A volume renders as the points of an iso-surface: a ball in an NRRD, at the iso-value
/// given or at Otsu's threshold by default; an iso-value that nothing crosses is a clear
/// error naming the volume's range.
#[test]
fn volumes_render_their_iso_surface() {
    let dir = tempdir("volume");
    let n = 40usize;
    let mut b = format!(
        "NRRD0004\ntype: float\ndimension: 3\nsizes: {n} {n} {n}\nencoding: raw\nendian: little\n\
         spacings: 0.05 0.05 0.05\n\n"
    )
    .into_bytes();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let p = [x, y, z].map(|c| (c as f32 - 19.5) * 0.05);
                let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                b.extend_from_slice(&(if r < 0.7 { 1000.0f32 } else { 0.0 }).to_le_bytes());
            }
        }
    }
    std::fs::write(dir.join("ball.nrrd"), b).unwrap();
    for extra in [vec![], vec!["--iso", "500"]] {
        let mut a = vec![
            "render",
            "ball.nrrd",
            "--size",
            "96",
            "--backend",
            "cpu",
            "--depth-out",
            "d.npy",
            "--camera-out",
            "c.json",
            "-o",
            "ball.png",
        ];
        a.extend(extra.iter());
        let o = stipple(&dir, &a);
        assert!(o.status.success(), "{extra:?}: {}", text(&o));
        let (_, _, d) = stipple_io::image::read_npy(&dir.join("d.npy")).unwrap();
        let covered = d.iter().filter(|x| x.is_finite()).count();
        assert!(covered > 96 * 96 / 8, "{extra:?}: {covered} px");
    }
    let o = stipple(
        &dir,
        &["render", "ball.nrrd", "--iso", "5000", "-o", "x.png"],
    );
    assert!(!o.status.success());
    assert!(
        text(&o).contains("ball.nrrd") && text(&o).contains("0..1000"),
        "{}",
        text(&o)
    );
    std::fs::remove_dir_all(dir).ok();
}

/// `--camera FILE` renders exactly the camera `--camera-out` wrote (the same image), and a
/// missing or bad file, or one given with --eye, is a clear error naming it.
#[test]
fn a_saved_camera_renders_the_same_view() {
    let dir = tempdir("camera-file");
    let o = stipple(
        &dir,
        &[
            "render",
            "--size",
            "64x48",
            "--backend",
            "cpu",
            "--eye",
            "2,1.5,3",
            "--camera-out",
            "c.json",
            "-o",
            "a.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let o = stipple(
        &dir,
        &[
            "render",
            "--camera",
            "c.json",
            "--backend",
            "cpu",
            "-o",
            "b.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let a = std::fs::read(dir.join("a.png")).unwrap();
    assert_eq!(a, std::fs::read(dir.join("b.png")).unwrap());
    std::fs::write(dir.join("bad.json"), "{\"eye\": [0, 0]}").unwrap();
    for (args, want) in [
        (vec!["--camera", "none.json"], "none.json"),
        (vec!["--camera", "bad.json"], "bad.json"),
        (
            vec!["--camera", "c.json", "--eye", "1,1,1"],
            "cannot be used with",
        ),
    ] {
        let mut v = vec!["render", "--size", "32", "-o", "x.png"];
        v.extend(args.iter());
        let o = stipple(&dir, &v);
        assert!(
            !o.status.success() && text(&o).contains(want),
            "{args:?}: {}",
            text(&o)
        );
        assert!(!dir.join("x.png").exists());
    }
    std::fs::remove_dir_all(dir).ok();
}

/// `--clip-box` keeps the points inside a world-space box: the left half of a plane stays,
/// the right half shows the background; a box holding no point, or corners the wrong way
/// round, are errors.
#[test]
fn a_clipping_box_keeps_what_is_inside() {
    let dir = tempdir("clip-box");
    let mut s = String::new();
    for j in 0..100 {
        for i in 0..100 {
            s.push_str(&format!(
                "{} {} 0\n",
                i as f32 / 99.0 * 2.0 - 1.0,
                j as f32 / 99.0 * 2.0 - 1.0
            ));
        }
    }
    std::fs::write(dir.join("plane.xyz"), s).unwrap();
    let view = [
        "--size",
        "64",
        "--backend",
        "cpu",
        "--eye",
        "0,0,3",
        "--target",
        "0,0,0",
        "--up",
        "0,1,0",
        "--no-lighting",
        "--background",
        "0,0,0",
    ];
    let run = |extra: &[&str]| {
        let mut a = vec!["render", "plane.xyz", "-o", "c.png"];
        a.extend(view);
        a.extend(extra);
        stipple(&dir, &a)
    };
    let o = run(&["--clip-box", "-2,-2,-1,0,2,1"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("clip box: 5000 of 10000 points inside"),
        "{}",
        text(&o)
    );
    let (w, _, rgba) = stipple_io::image::read_png(&dir.join("c.png")).unwrap();
    let px = |x: usize, y: usize| rgba[4 * (y * w as usize + x)];
    assert!(px(20, 32) > 100, "the left half stays");
    assert_eq!(px(44, 32), 0, "the right half is gone");
    for (bad, want) in [
        (
            &["--clip-box", "5,5,5,6,6,6"][..],
            "keeps none of the 10000 points",
        ),
        (&["--clip-box", "1,0,0,0,1,1"][..], "low one"),
        (&["--clip-box", "1,2,3"][..], "six"),
    ] {
        std::fs::remove_file(dir.join("c.png")).ok();
        let o = run(bad);
        assert!(
            !o.status.success() && text(&o).contains(want),
            "{bad:?}: {}",
            text(&o)
        );
        assert!(!dir.join("c.png").exists());
    }
    std::fs::remove_dir_all(dir).ok();
}

/// `--view` frames the cloud from a named side, as does a scene's `[camera] view`: a plan of
/// a LiDAR tile from straight above with north up, a Y-up model from behind; it excludes
/// `--eye`, and an unknown name is an error naming the choices.
#[test]
fn views_frame_from_their_side() {
    use glam::DVec3;
    let dir = tempdir("views");
    let cam = |dir: &Path, args: &[&str]| -> (DVec3, DVec3, DVec3) {
        let mut a = vec!["render", "--size", "48", "--backend", "cpu"];
        a.extend_from_slice(args);
        a.extend_from_slice(&["-o", "v.png", "--camera-out", "v.json"]);
        let _ = std::fs::remove_file(dir.join("v.json"));
        let _ = std::fs::remove_file(dir.join("v.png"));
        let o = stipple(dir, &a);
        assert!(o.status.success(), "{args:?}: {}", text(&o));
        let v = |k: &str| DVec3::from_slice(&camera_vec3(&dir.join("v.json"), k));
        (v("eye"), v("target"), v("up"))
    };
    let o = stipple(
        &dir,
        &["gen", "sphere", "--points", "3000", "-o", "tile.las"],
    );
    assert!(o.status.success(), "{}", text(&o));
    let (eye, target, up) = cam(&dir, &["tile.las", "--view", "top"]);
    let d = (eye - target).normalize();
    assert!((d - DVec3::Z).length() < 1e-9, "{d}");
    assert!((up - DVec3::Y).length() < 1e-9, "north up: {up}");
    // A Y-up model: the default looks from +Z, `back` and a scene's view from −Z.
    let o = stipple(
        &dir,
        &["gen", "sphere", "--points", "3000", "-o", "ball.ply"],
    );
    assert!(o.status.success(), "{}", text(&o));
    let (eye, target, _) = cam(&dir, &["ball.ply"]);
    assert!((eye - target).z > 0.0);
    let (eye, target, _) = cam(&dir, &["ball.ply", "--view", "back"]);
    let d = (eye - target).normalize();
    assert!((d + DVec3::Z).length() < 1e-9, "{d}");
    std::fs::write(
        dir.join("s.toml"),
        "[camera]\nview = \"three-quarter-back\"\n[[cloud]]\nfile = \"ball.ply\"\n",
    )
    .unwrap();
    let (eye, target, _) = cam(&dir, &["s.toml"]);
    assert!((eye - target).z < 0.0 && (eye - target).y > 0.0);
    // The flag wins over the scene's view.
    let (eye, target, _) = cam(&dir, &["s.toml", "--view", "front"]);
    assert!(((eye - target).normalize() - DVec3::Z).length() < 1e-9);
    let o = stipple(
        &dir,
        &["render", "ball.ply", "--view", "top", "--eye", "1,2,3"],
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let o = stipple(&dir, &["render", "ball.ply", "--view", "sideways"]);
    assert!(
        !o.status.success() && text(&o).contains("three-quarter-back"),
        "{}",
        text(&o)
    );
    std::fs::write(
        dir.join("bad.toml"),
        "[camera]\nview = \"sideways\"\n[[cloud]]\nfile = \"ball.ply\"\n",
    )
    .unwrap();
    let o = stipple(&dir, &["render", "bad.toml", "-o", "b.png"]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("bad.toml") && text(&o).contains("sideways"),
        "{}",
        text(&o)
    );
    std::fs::remove_dir_all(dir).ok();
}

/// `--env` and `--ior`: a procedural sky or an equirectangular PNG behind transparent
/// splats (the top of the image shows the environment's zenith, not the background); a
/// bad file, a bad index or a pipeline without transparent splats are clear errors.
#[test]
fn an_environment_shows_behind_transparent_splats() {
    let dir = tempdir("env");
    // A 4×2 environment: red sky (top row), green ground.
    let mut rgba = Vec::new();
    for y in 0..2 {
        for _ in 0..4 {
            rgba.extend_from_slice(if y == 0 {
                &[255, 0, 0, 255]
            } else {
                &[0, 255, 0, 255]
            });
        }
    }
    stipple_io::image::write_png(&dir.join("env.png"), 4, 2, &rgba).unwrap();
    let base = [
        "render",
        "--demo",
        "sphere",
        "--points",
        "3000",
        "--opacity",
        "0.5",
        "--size",
        "64",
        "--backend",
        "cpu",
        "--pipeline",
        "splat",
        "--eye",
        "0,0,5",
        "--target",
        "0,0,0",
        "--fov",
        "100",
    ];
    let o = stipple(
        &dir,
        &[
            &base[..],
            &["--env", "env.png", "--ior", "1.5", "-o", "e.png"],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let (w, _, px) = stipple_io::image::read_png(&dir.join("e.png")).unwrap();
    let at = |x: u32, y: u32| &px[((y * w + x) * 4) as usize..((y * w + x) * 4 + 3) as usize];
    assert!(
        at(32, 0)[0] > 200 && at(32, 0)[1] < 60,
        "sky: {:?}",
        at(32, 0)
    );
    assert!(
        at(32, 63)[1] > 200 && at(32, 63)[0] < 60,
        "ground: {:?}",
        at(32, 63)
    );
    // The same environment as a Radiance HDR file (flat RGBE scanlines), its sky 4× over
    // white: still red above (clipped), green below.
    let mut hdr = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 4\n".to_vec();
    for y in 0..2 {
        for _ in 0..4 {
            // 4.0 = (128 + 0.5)·2^(131 − 136) ≈ 4.0; 1.0 = (128 + 0.5)·2^(129 − 136).
            hdr.extend(if y == 0 {
                [128, 0, 0, 131]
            } else {
                [0, 128, 0, 129]
            });
        }
    }
    std::fs::write(dir.join("env.hdr"), &hdr).unwrap();
    let o = stipple(
        &dir,
        &[&base[..], &["--env", "env.hdr", "-o", "h.png"]].concat(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let (w, _, px) = stipple_io::image::read_png(&dir.join("h.png")).unwrap();
    let at = |x: u32, y: u32| &px[((y * w + x) * 4) as usize..((y * w + x) * 4 + 3) as usize];
    assert!(
        at(32, 0)[0] == 255 && at(32, 0)[1] < 60,
        "HDR sky: {:?}",
        at(32, 0)
    );
    assert!(
        at(32, 63)[1] > 200 && at(32, 63)[0] < 60,
        "HDR ground: {:?}",
        at(32, 63)
    );
    std::fs::write(dir.join("bad.hdr"), b"#?RADIANCE\n\n-Y 9000 +X 9000\n").unwrap();
    for (args, want) in [
        (vec!["--env", "bad.hdr"], "bad.hdr"),
        (vec!["--env", "missing.png"], "missing.png"),
        (vec!["--env", "sky", "--ior=-1"], "--ior -1"),
        (
            vec!["--env", "sky", "--splat", "voronoi"],
            "transparent splats",
        ),
    ] {
        let o = stipple(&dir, &[&base[..], &args[..], &["-o", "x.png"]].concat());
        assert!(!o.status.success(), "{args:?}");
        assert!(text(&o).contains(want), "{args:?}: {}", text(&o));
        assert!(!dir.join("x.png").exists());
    }
    std::fs::remove_dir_all(dir).ok();
}

/// A splat mode asked for is drawn at any spacing: `--splat transparent` on a view where the
/// points land well under a pixel apart (where the automatic choice draws single points)
/// draws transparent splats, not the opaque points it drew before; so do translucent points
/// (`--opacity`) and an environment (`--env`, `--ior`) without any other flag, which before
/// drew opaque points with a note, or stopped with an error, telling the user which flags to
/// add. Asking for Dobrev's pipeline keeps it.
#[test]
fn an_explicit_splat_mode_is_drawn_even_where_points_are_dense() {
    let dir = tempdir("splat-mode");
    let base = [
        "render",
        "--demo",
        "sphere",
        "--points",
        "200000",
        "--size",
        "96",
        "--backend",
        "cpu",
    ];
    let drew = |t: &str| t.contains("transparent splats: ") && t.contains(" groups, ");
    let run = |extra: &[&str], out: &str| {
        let t = common::ok(&dir, &[&base[..], extra, &["-o", out]].concat());
        (t, std::fs::read(dir.join(out)).unwrap())
    };
    let (t, asked) = run(&["--opacity", "0.5", "--splat", "transparent"], "t.png");
    assert!(drew(&t), "{t}");
    let (t, translucent) = run(&["--opacity", "0.5"], "o.png");
    assert!(drew(&t), "{t}");
    let (t, env) = run(&["--env", "sky", "--ior", "1.5"], "e.png");
    assert!(drew(&t), "{t}");
    let (d, opaque) = run(&["--opacity", "0.5", "--pipeline", "dobrev"], "d.png");
    assert!(!drew(&d), "{d}");
    assert_ne!(
        asked, opaque,
        "the transparent splats drew the opaque image"
    );
    assert_ne!(translucent, opaque, "--opacity alone drew the opaque image");
    assert_ne!(env, opaque);
    std::fs::remove_dir_all(&dir).ok();
}

/// A few stray points far from the rest (an invalid return at a georeferenced tile's origin,
/// a point at 1e9) no longer shrink the default view to a dot: the camera frames the bulk,
/// exactly as without them, says so, and the image matches the one without the strays.
#[test]
fn stray_points_do_not_shrink_the_default_view() {
    let dir = tempdir("strays");
    let centre = [637_000.0, 851_000.0, 120.0];
    let mut bulk = String::new();
    let n = 3000;
    for i in 0..n {
        // A Fibonacci sphere of radius 5 around a georeferenced centre.
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let a = i as f64 * 2.399_963_229_728_653;
        let r = (1.0 - z * z).sqrt();
        let p = [r * a.cos(), r * a.sin(), z];
        bulk.push_str(&format!(
            "{:.4} {:.4} {:.4}\n",
            centre[0] + 5.0 * p[0],
            centre[1] + 5.0 * p[1],
            centre[2] + 5.0 * p[2]
        ));
    }
    std::fs::write(dir.join("bulk.xyz"), &bulk).unwrap();
    std::fs::write(
        dir.join("strays.xyz"),
        format!("{bulk}0 0 0\n1e9 1e9 1e9\n"),
    )
    .unwrap();
    let render = |name: &str| {
        let t = common::ok(
            &dir,
            &[
                "render",
                &format!("{name}.xyz"),
                "--size",
                "96",
                "--backend",
                "cpu",
                "--camera-out",
                &format!("{name}.json"),
                "-o",
                &format!("{name}.png"),
            ],
        );
        let (_, _, rgba) = stipple_io::image::read_png(&dir.join(format!("{name}.png"))).unwrap();
        (t, rgba)
    };
    let (t, clean) = render("bulk");
    assert!(!t.contains("far outside"), "{t}");
    let (t, strayed) = render("strays");
    assert!(t.contains("2 of its 3002 points lie far outside it"), "{t}");
    for key in ["eye", "target"] {
        let (a, b) = (
            camera_vec3(&dir.join("bulk.json"), key),
            camera_vec3(&dir.join("strays.json"), key),
        );
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-3, "{key}: {a:?} against {b:?}");
        }
    }
    let differ = clean
        .chunks(4)
        .zip(strayed.chunks(4))
        .filter(|(a, b)| a.iter().zip(b.iter()).any(|(x, y)| x.abs_diff(*y) > 8))
        .count();
    assert!(
        differ * 200 <= clean.len() / 4,
        "{differ} of {} pixels differ",
        clean.len() / 4
    );
    assert!(clean.chunks(4).filter(|p| p[..3] != clean[..3]).count() > 1000);
    let t = common::ok(&dir, &["info", "strays.xyz"]);
    assert!(
        t.contains("strays      2 points far outside the bulk"),
        "{t}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
