//! Scene files, depth peeling, transparency and shadow caches through the `stipple` binary.

mod common;
use common::{cube_ply, ok, stipple, tempdir, text};
use std::path::Path;

const SCENE: &str = r#"
[camera]
eye = [2.5, 2.5, 3.5]
target = [0.0, 0.3, 0.0]
size = [200, 150]

[render]
shadow_cache = "s.stshadow"

[[cloud]]
demo = "plane"
points = 120000
scale = 4
translate = [TX, 0.0, 0.0]
colour = [200, 200, 190]

[[cloud]]
demo = "sphere"
points = 40000
scale = 0.5
translate = [TX, 0.8, 0.0]
colour = [200, 60, 50]

[[light]]
type = "area"
position = [LX, 4.0, 1.0]
radius = 0.3
samples = 4
"#;

fn scene(dir: &Path, tx: f64, lx: f64) {
    let s = SCENE
        .replace("TX", &format!("{tx:.1}"))
        .replace("LX", &format!("{lx:.1}"));
    std::fs::write(dir.join("s.toml"), s).unwrap();
}

#[test]
fn shadow_textures_are_cached_and_reused_until_light_and_clouds_move_apart() {
    let dir = tempdir("scene-cache");
    scene(&dir, 0.0, 1.0);
    let args = ["render", "s.toml", "-o", "a.png", "--backend", "cpu"];
    let t = ok(&dir, &args);
    assert!(
        t.contains("4 light samples") && t.contains("saved to"),
        "{t}"
    );
    let first = std::fs::read(dir.join("s.stshadow")).unwrap();
    // Unchanged: loaded, not recomputed.
    let t = ok(&dir, &args);
    assert!(t.contains("shadows loaded from"), "{t}");
    let a = std::fs::read(dir.join("a.png")).unwrap();
    // The whole scene (clouds and light) moved by 3: still the same shadows.
    scene(&dir, 3.0, 4.0);
    let t = ok(&dir, &args);
    assert!(t.contains("shadows loaded from"), "moved together: {t}");
    // The light moved relative to the clouds: recomputed, and the cache replaced.
    scene(&dir, 3.0, 2.0);
    let t = ok(&dir, &args);
    assert!(
        t.contains("light samples") && t.contains("made for other"),
        "light moved: {t}"
    );
    assert_ne!(std::fs::read(dir.join("s.stshadow")).unwrap(), first);
    // More samples than cached: refined, not recomputed from scratch.
    scene(&dir, 0.0, 1.0);
    ok(&dir, &args);
    let t = ok(
        &dir,
        &[
            "render",
            "s.toml",
            "-o",
            "b.png",
            "--backend",
            "cpu",
            "--shadow-samples",
            "2",
        ],
    );
    assert!(
        t.contains("shadows loaded"),
        "fewer samples than cached: {t}"
    );
    // --no-shadows: the plane under the sphere is lit.
    ok(
        &dir,
        &[
            "render",
            "s.toml",
            "-o",
            "c.png",
            "--backend",
            "cpu",
            "--no-shadows",
        ],
    );
    let c = std::fs::read(dir.join("c.png")).unwrap();
    assert_ne!(a, c);
    // A cache path holding something else is never overwritten.
    std::fs::write(dir.join("notes.stshadow"), b"mine").unwrap();
    let o = stipple(
        &dir,
        &[
            "render",
            "s.toml",
            "-o",
            "d.png",
            "--backend",
            "cpu",
            "--shadow-cache",
            "notes.stshadow",
        ],
    );
    assert!(!o.status.success());
    assert!(text(&o).contains("refusing to overwrite"), "{}", text(&o));
    assert_eq!(std::fs::read(dir.join("notes.stshadow")).unwrap(), b"mine");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn layers_are_peeled_and_written() {
    let dir = tempdir("scene-layers");
    let t = ok(
        &dir,
        &[
            "render",
            "--demo",
            "torus",
            "--points",
            "200000",
            "--size",
            "160x120",
            "--layers",
            "4",
            "--opacity",
            "0.5",
            "--layer-images",
            "layer",
            "-o",
            "t.png",
            "--backend",
            "cpu",
        ],
    );
    // A torus seen from the side has up to four surfaces along a ray.
    assert!(t.contains("peeled 4 of at most 4 layers"), "{t}");
    for k in 1..=4 {
        assert!(dir.join(format!("layer-{k}.png")).exists(), "{t}");
    }
    assert!(!dir.join("layer-5.png").exists());
    // The nested tori scene of Fig. 17 from `stipple gen`: a PLY with opacities.
    ok(
        &dir,
        &["gen", "nested-tori", "-o", "tori.ply", "--points", "120000"],
    );
    let t = ok(
        &dir,
        &[
            "render",
            "tori.ply",
            "--layers",
            "6",
            "--size",
            "160x120",
            "--backend",
            "cpu",
        ],
    );
    assert!(t.contains("peeled 6 of at most 6 layers"), "{t}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_look_options_are_clear_errors() {
    let dir = tempdir("scene-errors");
    for (args, want) in [
        (vec!["--layer-images", "x"], "--layer-images needs --layers"),
        (vec!["--layers", "0"], "--layers 0"),
        (vec!["--opacity", "1.5"], "--opacity 1.5"),
        (vec!["--shadows"], "no light casts shadows"),
        (
            vec![
                "--shadows",
                "--light",
                "point:0,5,0",
                "--shadow-samples",
                "0",
            ],
            "--shadow-samples 0",
        ),
        (vec!["--light", "disc:0,5,0,-1"], "radius must be positive"),
        (
            vec![
                "--shadows",
                "--light",
                "point:0,5,0",
                "--shadow-cache",
                "x.txt",
            ],
            "must be a .stshadow",
        ),
    ] {
        let mut a = vec![
            "render", "--demo", "sphere", "--points", "2000", "--size", "64x64",
        ];
        a.extend(args.iter().copied());
        let o = stipple(&dir, &a);
        let t = text(&o);
        assert!(!o.status.success() && t.contains(want), "{args:?}: {t}");
        assert!(!t.contains("panicked"), "{t}");
    }
    std::fs::write(
        dir.join("bad.toml"),
        "[[cloud]]\ndemo = \"sphere\"\nscale = -1\n",
    )
    .unwrap();
    let o = stipple(&dir, &["render", "bad.toml"]);
    assert!(
        text(&o).contains("bad.toml") && text(&o).contains("scale"),
        "{}",
        text(&o)
    );
    // A scene's missing file: named, with its cause said once.
    std::fs::write(dir.join("gone.toml"), "[[cloud]]\nfile = \"gone.ply\"\n").unwrap();
    let o = stipple(&dir, &["render", "gone.toml", "-o", "g.png"]);
    let t = text(&o);
    assert!(
        !o.status.success() && t.contains("gone.toml: cloud 1: gone.ply"),
        "{t}"
    );
    let line = t.lines().find(|l| l.contains("gone.ply")).unwrap_or("");
    let cause = line.rsplit(": ").next().unwrap_or("");
    assert!(
        !cause.is_empty() && line.matches(cause).count() == 1,
        "the cause repeated: {line}"
    );
    // A scene's impossible camera names the file and the cause.
    for (camera, want) in [
        (
            "eye = [0.0, 0.0, 3.0]\ntarget = [0.0, 0.0, 3.0]",
            "eye and target coincide",
        ),
        ("fov = 0", "field of view 0"),
    ] {
        std::fs::write(
            dir.join("cam.toml"),
            format!("[camera]\n{camera}\n\n[[cloud]]\ndemo = \"sphere\"\npoints = 500\n"),
        )
        .unwrap();
        let o = stipple(&dir, &["render", "cam.toml", "-o", "cam.png"]);
        let t = text(&o);
        assert!(!o.status.success(), "{camera}: {t}");
        assert!(t.contains("cam.toml") && t.contains(want), "{camera}: {t}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_example_scenes_load() {
    // The examples in the repository parse and name existing demos (rendered small).
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    let dir = tempdir("scene-examples");
    for name in [
        "nested-tori.toml",
        "shadows.toml",
        "translucent-shadows.toml",
        "mixed.toml",
        "glass-bunny.toml",
        "glass-objects.toml",
    ] {
        let p = root.join(name);
        let text = std::fs::read_to_string(&p).unwrap();
        let data = root.join("../../shared/data");
        if text.contains("shared/data") && !data.is_dir() {
            eprintln!("skipped {name}: {} is absent", data.display());
            continue;
        }
        // Fewer points and no cache: a quick run of the same scene.
        let small = text
            .lines()
            .map(|l| {
                if l.starts_with("points") {
                    "points = 20000".to_string()
                } else if let Some(rel) = l.strip_prefix("file = \"") {
                    // Files relative to the example, from the temporary copy.
                    format!("file = {:?}", root.join(rel.trim_end_matches('"')))
                } else if l.starts_with("shadow_cache") || l.starts_with("size") {
                    String::new()
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        std::fs::write(dir.join(name), small).unwrap();
        let t = ok(
            &dir,
            &[
                "render",
                name,
                "--size",
                "96x72",
                "--backend",
                "cpu",
                "--shadow-samples",
                "2",
            ],
        );
        assert!(t.contains("wrote"), "{t}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// One scene mixes a point cloud, a mesh sampled over its faces and a volume's iso-surface
/// (Gunjee et al. §3).
#[test]
fn a_scene_mixes_clouds_meshes_and_volumes() {
    let dir = tempdir("scene-mixed");
    // A unit cube mesh (12 triangles, 8 vertices).
    let ply = cube_ply();
    std::fs::write(dir.join("cube.ply"), ply).unwrap();
    // A ball in a 24³ volume.
    let mut nrrd =
        b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 24 24 24\nencoding: raw\n\n".to_vec();
    for z in 0..24 {
        for y in 0..24 {
            for x in 0..24 {
                let d = [x, y, z].map(|c| c as f32 - 11.5);
                let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                nrrd.push(if r < 9.0 { 200 } else { 10 });
            }
        }
    }
    std::fs::write(dir.join("ball.nrrd"), nrrd).unwrap();
    std::fs::write(
        dir.join("mixed.toml"),
        "[camera]\nsize = [128, 96]\n\n\
         [[cloud]]\nfile = \"cube.ply\"\nsample = 0.02\ntranslate = [-2.0, 0.0, 0.0]\n\n\
         [[cloud]]\nfile = \"ball.nrrd\"\niso = 100\nscale = 0.05\ntranslate = [1.0, 0.0, 0.0]\n\n\
         [[cloud]]\ndemo = \"sphere\"\npoints = 3000\ntranslate = [0.0, 2.0, 0.0]\n",
    )
    .unwrap();
    let o = stipple(
        &dir,
        &[
            "render",
            "mixed.toml",
            "--backend",
            "cpu",
            "--depth-out",
            "d.npy",
            "-o",
            "m.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    // The cube's 6 / 0.02² = 15 000 samples, not its 8 vertices, are in the scene.
    let t = text(&o);
    let n: usize = t
        .split(" from ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    assert!(n > 15_000, "{n} points: {t}");
    let (_, _, d) = stipple_io::image::read_npy(&dir.join("d.npy")).unwrap();
    assert!(d.iter().filter(|x| x.is_finite()).count() > 128 * 96 / 10);
    // A bad sample spacing names the file and the field.
    std::fs::write(
        dir.join("bad.toml"),
        "[[cloud]]\nfile = \"cube.ply\"\nsample = -1.0\n",
    )
    .unwrap();
    let o = stipple(&dir, &["render", "bad.toml", "-o", "b.png"]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("cube.ply") && text(&o).contains("sample"),
        "{}",
        text(&o)
    );
    std::fs::remove_dir_all(dir).ok();
}

/// Light falloff from the command line and from a scene's `[render] falloff`: the same image
/// either way, darker than without falloff where the light is farther than the distance
/// given; bad distances refused with the flag or field named.
#[test]
fn light_falloff_from_the_flag_and_the_scene_agree() {
    let dir = tempdir("falloff");
    let scene = |falloff: &str| {
        format!(
            "[camera]\neye = [0.0, 3.0, 3.0]\ntarget = [0.0, 0.0, 0.0]\nsize = [96, 96]\n\
             [render]\nshadows = false\n{falloff}\n[[cloud]]\ndemo = \"plane\"\npoints = 60000\nscale = 3\n\
             colour = [200, 200, 200]\n[[light]]\ntype = \"point\"\nposition = [0.0, 2.0, 0.0]\n"
        )
    };
    let mean = |png: &Path| -> f64 {
        let (_, _, rgba) = stipple_io::image::read_png(png).unwrap();
        rgba.chunks(4).map(|p| p[0] as f64).sum::<f64>() / (rgba.len() / 4) as f64
    };
    std::fs::write(dir.join("none.toml"), scene("")).unwrap();
    std::fs::write(dir.join("half.toml"), scene("falloff = 1.0")).unwrap();
    ok(
        &dir,
        &["render", "none.toml", "-o", "none.png", "--backend", "cpu"],
    );
    ok(
        &dir,
        &["render", "half.toml", "-o", "half.png", "--backend", "cpu"],
    );
    ok(
        &dir,
        &[
            "render",
            "none.toml",
            "-o",
            "flag.png",
            "--backend",
            "cpu",
            "--light-falloff",
            "1",
        ],
    );
    let (none, half, flag) = (
        mean(&dir.join("none.png")),
        mean(&dir.join("half.png")),
        mean(&dir.join("flag.png")),
    );
    assert!(
        half < none - 5.0,
        "falloff at 1 with the light 2 away: {half} vs {none}"
    );
    assert_eq!(
        half, flag,
        "the flag and the scene field give the same image"
    );
    let out = stipple(
        &dir,
        &["render", "none.toml", "--light-falloff", "0", "-o", "x.png"],
    );
    assert!(
        !out.status.success() && text(&out).contains("--light-falloff"),
        "{}",
        text(&out)
    );
    std::fs::write(dir.join("bad.toml"), scene("falloff = -2")).unwrap();
    let out = stipple(&dir, &["render", "bad.toml", "-o", "x.png"]);
    assert!(
        !out.status.success() && text(&out).contains("falloff = -2"),
        "{}",
        text(&out)
    );
}

/// Translucent shadows from the command line and from a scene's `[render] shadow_layers`:
/// the same image either way; a translucent ball's shadow lets light through (a brighter
/// image than with `--shadow-layers 1`, where it casts a full shadow); counts outside 1–64
/// refused with the flag or field named.
#[test]
fn translucent_shadows_from_the_flag_and_the_scene_agree() {
    let dir = tempdir("translucent");
    let scene = |layers: &str| {
        format!(
            "[camera]\neye = [0.0, 3.0, 2.0]\ntarget = [0.0, 0.0, 0.0]\nsize = [96, 96]\n\
             [render]\n{layers}\n[[cloud]]\ndemo = \"plane\"\npoints = 80000\nscale = 3\n\
             colour = [200, 200, 200]\n[[cloud]]\ndemo = \"sphere\"\npoints = 40000\n\
             scale = 0.5\ntranslate = [0.0, 0.8, 0.0]\ncolour = [90, 120, 220]\nopacity = 0.4\n\
             [[light]]\ntype = \"point\"\nposition = [0.6, 3.0, 0.0]\n"
        )
    };
    let mean = |png: &Path| -> f64 {
        let (_, _, rgba) = stipple_io::image::read_png(png).unwrap();
        rgba.chunks(4).map(|p| p[0] as f64).sum::<f64>() / (rgba.len() / 4) as f64
    };
    std::fs::write(dir.join("default.toml"), scene("")).unwrap();
    std::fs::write(dir.join("one.toml"), scene("shadow_layers = 1")).unwrap();
    let render = |file: &str, out: &str, extra: &[&str]| {
        let mut args = vec!["render", file, "-o", out, "--backend", "cpu"];
        args.extend_from_slice(extra);
        ok(&dir, &args);
        mean(&dir.join(out))
    };
    let translucent = render("default.toml", "t.png", &[]);
    let full = render("one.toml", "full.png", &[]);
    let flag = render("default.toml", "flag.png", &["--shadow-layers", "1"]);
    assert!(
        translucent > full + 1.0,
        "a translucent ball's shadow lets light through: {translucent} vs {full}"
    );
    assert_eq!(
        full, flag,
        "the flag and the scene field give the same image"
    );
    let out = stipple(
        &dir,
        &[
            "render",
            "default.toml",
            "--shadow-layers",
            "0",
            "-o",
            "x.png",
        ],
    );
    assert!(
        !out.status.success() && text(&out).contains("--shadow-layers"),
        "{}",
        text(&out)
    );
    std::fs::write(dir.join("bad.toml"), scene("shadow_layers = 65")).unwrap();
    let out = stipple(&dir, &["render", "bad.toml", "-o", "x.png"]);
    assert!(
        !out.status.success() && text(&out).contains("shadow_layers"),
        "{}",
        text(&out)
    );
    std::fs::remove_dir_all(dir).ok();
}

/// A volume through a transfer function (Gunjee §3), from the command line (a file and the
/// inline form) and from a scene: every sample the function shows becomes a point with its
/// colour; `--iso` and `--transfer` together, or a bad function, are refused naming the flag.
#[test]
fn a_volume_renders_through_a_transfer_function() {
    let dir = tempdir("transfer");
    // A 24³ ball, values 0 outside and 200 inside (radius 8 samples).
    let n = 24usize;
    let mut data = Vec::with_capacity(n * n * n);
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let d = ((x as f64 - 11.5).powi(2)
                    + (y as f64 - 11.5).powi(2)
                    + (z as f64 - 11.5).powi(2))
                .sqrt();
                data.push(if d < 8.0 { 200u8 } else { 0 });
            }
        }
    }
    std::fs::write(dir.join("ball_24x24x24_uint8.raw"), &data).unwrap();
    let inside = data.iter().filter(|&&v| v > 0).count();
    std::fs::write(
        dir.join("tf.txt"),
        "# value r g b opacity\n100 40 200 60 0\n150 40 200 60 0.5\n",
    )
    .unwrap();
    let points = |transfer: &str| {
        let out = ok(
            &dir,
            &[
                "render",
                "ball_24x24x24_uint8.raw",
                "--transfer",
                transfer,
                "--size",
                "32x32",
                "-o",
                "n.png",
                "--backend",
                "cpu",
            ],
        );
        assert!(out.contains(&format!("from {inside} points")), "{out}");
    };
    points("tf.txt");
    points("100 40 200 60 0; 150 40 200 60 0.5");
    // A render shows the function's green.
    ok(
        &dir,
        &[
            "render",
            "ball_24x24x24_uint8.raw",
            "--transfer",
            "tf.txt",
            "--layers",
            "3",
            "--size",
            "64x64",
            "-o",
            "t.png",
            "--backend",
            "cpu",
        ],
    );
    let (_, _, rgba) = stipple_io::image::read_png(&dir.join("t.png")).unwrap();
    let centre = (32 * 64 + 32) * 4;
    assert!(
        rgba[centre + 1] > rgba[centre] + 40 && rgba[centre + 1] > rgba[centre + 2] + 40,
        "the ball is green: {:?}",
        &rgba[centre..centre + 3]
    );
    // A scene names its transfer function relative to itself.
    std::fs::write(
        dir.join("s.toml"),
        "[camera]\nsize = [64, 64]\n[[cloud]]\nfile = \"ball_24x24x24_uint8.raw\"\ntransfer = \"tf.txt\"\n",
    )
    .unwrap();
    ok(
        &dir,
        &["render", "s.toml", "-o", "s.png", "--backend", "cpu"],
    );
    for (args, says) in [
        (vec!["--transfer", "tf.txt", "--iso", "100"], "--iso"),
        (vec!["--transfer", "1 2 3"], "--transfer"),
        (vec!["--transfer", "0 0 0 0 0"], "no sample has an opacity"),
    ] {
        let mut a = vec!["render", "ball_24x24x24_uint8.raw", "-o", "x.png"];
        a.extend(args);
        let out = stipple(&dir, &a);
        assert!(
            !out.status.success() && text(&out).contains(says),
            "{a:?}: {}",
            text(&out)
        );
    }
    std::fs::remove_dir_all(dir).ok();
}

/// Transparent splats from the command line and from a scene: a translucent sphere drawn as
/// transparent splats is the depth-peeled sphere within a level or so on average (two
/// algorithms, one composite), and far from the opaque one; the shipped example with
/// `transparency = "splat-1pass"` renders its tori through one another.
#[test]
fn transparent_splats_from_the_command_line_and_a_scene() {
    let dir = tempdir("transparent-splats");
    let base = [
        "render",
        "--demo",
        "sphere",
        "--points",
        "20000",
        "--size",
        "128x128",
        "--backend",
        "cpu",
    ];
    let shot = |extra: &[&str], out: &str| {
        let mut a = base.to_vec();
        a.extend(extra);
        a.extend(["-o", out]);
        ok(&dir, &a);
        stipple_io::image::read_png(&dir.join(out)).unwrap().2
    };
    let splats = shot(
        &[
            "--opacity",
            "0.5",
            "--pipeline",
            "splat",
            "--splat",
            "transparent",
        ],
        "t.png",
    );
    // The default: a translucent cloud that the automatic choice draws as splats is drawn
    // as transparent splats (peeling only when --layers asks for it).
    let sparse = |extra: &[&str], out: &str| {
        let mut a = vec![
            "render",
            "--demo",
            "sphere",
            "--points",
            "3000",
            "--opacity",
            "0.5",
        ];
        a.extend(["--size", "128x128", "--backend", "cpu", "-o", out]);
        a.extend(extra);
        let said = ok(&dir, &a);
        (stipple_io::image::read_png(&dir.join(out)).unwrap().2, said)
    };
    // (Algorithm 3, the nearest layer smoothly interpolated.)
    let (auto, said) = sparse(&[], "a.png");
    let (explicit, _) = sparse(
        &[
            "--pipeline",
            "splat",
            "--splat",
            "transparent",
            "--smooth-nearest",
        ],
        "e.png",
    );
    assert!(
        auto == explicit && said.contains("drawn as transparent splats"),
        "--opacity alone draws transparent splats: {said}"
    );
    // Algorithm 3 against Algorithm 2: the same surfaces, a smoother front.
    let (two, _) = sparse(
        &["--pipeline", "splat", "--splat", "transparent"],
        "two.png",
    );
    assert!(auto != two);
    let peeled = shot(&["--opacity", "0.5", "--layers", "2"], "p.png");
    let opaque = shot(&["--pipeline", "splat", "--splat", "transparent"], "o.png");
    let mean_diff = |a: &[u8], b: &[u8]| {
        let (mut sum, mut n) = (0u64, 0u64);
        for y in 34..94usize {
            for x in 34..94usize {
                if (x as i32 - 64).pow(2) + (y as i32 - 64).pow(2) < 900 {
                    let q = (y * 128 + x) * 4;
                    for c in 0..3 {
                        sum += a[q + c].abs_diff(b[q + c]) as u64;
                        n += 1;
                    }
                }
            }
        }
        sum as f64 / n as f64
    };
    let d = mean_diff(&splats, &peeled);
    assert!(
        d < 2.5,
        "transparent splats against peeling: {d} levels on average"
    );
    let o = mean_diff(&splats, &opaque);
    assert!(
        o > 10.0,
        "the translucent sphere differs from the opaque one: {o}"
    );
    // Enlarged radii (§4.2.2 method 2) instead of duplicates: the same composite within
    // a level or so, said in the statistics; from a scene's `coverage` too.
    let mut a = base.to_vec();
    a.extend([
        "--opacity",
        "0.5",
        "--pipeline",
        "splat",
        "--splat",
        "transparent",
        "--coverage",
        "enlarge",
        "-o",
        "en.png",
    ]);
    let said = ok(&dir, &a);
    assert!(said.contains("splats enlarged"), "{said}");
    let enlarged = stipple_io::image::read_png(&dir.join("en.png")).unwrap().2;
    let d = mean_diff(&splats, &enlarged);
    assert!(
        d < 1.5,
        "enlarged radii against duplicates: {d} levels on average"
    );
    std::fs::write(
        dir.join("en.toml"),
        "[render]\ntransparency = \"splat-1pass\"\ncoverage = \"enlarge\"\n\n[[cloud]]\n\
         demo = \"sphere\"\npoints = 20000\nopacity = 0.5\n",
    )
    .unwrap();
    let said = ok(
        &dir,
        &[
            "render",
            "en.toml",
            "--size",
            "64x64",
            "--backend",
            "cpu",
            "-o",
            "s.png",
        ],
    );
    assert!(
        said.contains("splats enlarged"),
        "the scene's coverage: {said}"
    );
    let said = ok(
        &dir,
        &[
            "render",
            "en.toml",
            "--coverage",
            "duplicate",
            "--size",
            "64x64",
            "--backend",
            "cpu",
            "-o",
            "s2.png",
        ],
    );
    assert!(
        said.contains("splats duplicated"),
        "--coverage wins over the scene: {said}"
    );
    let example =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/nested-tori-splats.toml");
    let o = stipple(
        &dir,
        &[
            "render",
            example.to_str().unwrap(),
            "--size",
            "96x96",
            "--backend",
            "cpu",
            "-o",
            "tori.png",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let (_, _, tori) = stipple_io::image::read_png(&dir.join("tori.png")).unwrap();
    let covered = (0..96 * 96).filter(|&k| tori[4 * k] < 240).count();
    assert!(covered > 96 * 96 / 4, "the tori fill the view: {covered}");
    std::fs::remove_dir_all(&dir).ok();
}
