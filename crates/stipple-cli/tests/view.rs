//! `stipple view` tested as a person sees it: on a virtual X display (Xvfb, with lavapipe
//! presenting), the window is dragged with the mouse and sent keys (xdotool), the screen is
//! captured (xwd), and what the window shows is compared with `stipple render` of the camera
//! the viewer saved. Skipped with a printed reason where Xvfb, xwd or xdotool is missing;
//! with STIPPLE_REQUIRE_GPU=1 (CI, which installs them) a missing one is a failure.

mod common;

use common::*;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

fn tool(name: &str) -> Option<PathBuf> {
    std::env::var_os("PATH")?
        .to_str()?
        .split(':')
        .map(|d| Path::new(d).join(name))
        .find(|p| p.is_file())
}

fn tools() -> Option<[PathBuf; 3]> {
    let found = ["Xvfb", "xwd", "xdotool"].map(tool);
    if let [Some(a), Some(b), Some(c)] = found {
        return Some([a, b, c]);
    }
    let why = "Xvfb, xwd and xdotool are needed (apt-get install xvfb x11-apps xdotool)";
    if std::env::var("STIPPLE_REQUIRE_GPU").as_deref() == Ok("1") {
        panic!("{why}");
    }
    eprintln!("skipped: {why}");
    None
}

/// A virtual display, stopped when dropped.
struct Display {
    server: Child,
    name: String,
}

impl Drop for Display {
    fn drop(&mut self) {
        let _ = self.server.kill();
        let _ = self.server.wait();
    }
}

fn start_display(xvfb: &Path) -> Display {
    // Xvfb picks a free display number and writes it to its standard output (-displayfd),
    // so tests running at once never share a screen.
    let mut server = Command::new(xvfb)
        .args([
            "-displayfd",
            "1",
            "-screen",
            "0",
            "640x480x24",
            "-nolisten",
            "tcp",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("Xvfb starts");
    let mut line = String::new();
    std::io::BufReader::new(server.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let n: u32 = line.trim().parse().expect("Xvfb says its display number");
    Display {
        server,
        name: format!(":{n}"),
    }
}

/// An XWD screen dump (xwd -root) as RGB rows: 32-bit TrueColor pixels through their masks.
fn read_xwd(bytes: &[u8]) -> (usize, usize, Vec<[u8; 3]>) {
    let u = |k: usize| u32::from_be_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap()) as usize;
    let (header, w, h) = (u(0), u(4), u(5));
    let (byte_order, bpp, bpl) = (u(7), u(11), u(12));
    let masks = [u(14) as u32, u(15) as u32, u(16) as u32];
    let ncolors = u(19);
    assert_eq!(bpp, 32, "a 24-bit screen stores 32 bits a pixel");
    let data = &bytes[header + 12 * ncolors..];
    let mut px = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let b: [u8; 4] = data[y * bpl + 4 * x..][..4].try_into().unwrap();
            let v = if byte_order == 0 {
                u32::from_le_bytes(b)
            } else {
                u32::from_be_bytes(b)
            };
            px.push(masks.map(|m| ((v & m) >> m.trailing_zeros()) as u8));
        }
    }
    (w, h, px)
}

/// Pixels of the window (w × h at the screen's top-left corner) more than a level off
/// `reference` (RGBA), once the screen has settled: captured again until it matches or
/// 20 s pass (a loaded machine may draw late), and the last count returned.
fn settled_difference(xwd: &Path, display: &str, reference: &[u8], w: usize, h: usize) -> usize {
    let t0 = Instant::now();
    loop {
        let o = Command::new(xwd)
            .args(["-root", "-silent"])
            .env("DISPLAY", display)
            .output()
            .unwrap();
        let (dw, _, screen) = read_xwd(&o.stdout);
        let off = (0..w * h)
            .filter(|&k| {
                let s = screen[(k / w) * dw + k % w];
                (0..3).any(|c| s[c].abs_diff(reference[4 * k + c]) > 1)
            })
            .count();
        if off * 1000 <= w * h || t0.elapsed() > Duration::from_secs(20) {
            return off;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn wait_for(path: &Path, what: &str) {
    let t0 = Instant::now();
    while !path.exists() {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "{what}: {} never appeared",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // Written through a temporary file and renamed: complete once it exists.
}

/// A viewer on its own virtual display: its standard output read line by line (kept open:
/// a closed pipe would end it), the display's mouse, keys and screen.
struct Session {
    viewer: Child,
    out: std::io::Lines<std::io::BufReader<ChildStdout>>,
    /// What the viewer printed up to its first frame ("showing …" last).
    said: Vec<String>,
    xdotool: PathBuf,
    xwd: PathBuf,
    window: String,
    // Dropped last: the display outlives the viewer's window.
    display: Display,
}

impl Session {
    /// Starts `stipple view ARGS` in `dir` on a display of its own and waits for its first
    /// frame; the window has the keyboard.
    fn start(tools: &[PathBuf; 3], dir: &Path, args: &[&str]) -> Session {
        let [xvfb, xwd, xdotool] = tools.clone();
        let display = start_display(&xvfb);
        let mut viewer = Command::new(env!("CARGO_BIN_EXE_stipple"))
            .arg("view")
            .args(args)
            .args(["--quit-after", "120"])
            .current_dir(dir)
            .env("DISPLAY", &display.name)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let out = std::io::BufReader::new(viewer.stdout.take().unwrap()).lines();
        let mut s = Session {
            viewer,
            out,
            said: Vec::new(),
            xdotool,
            xwd,
            window: String::new(),
            display,
        };
        let first = s.line("showing");
        assert!(first.starts_with("showing"), "the viewer said {:?}", s.said);
        let id = s.x(&["search", "--sync", "--name", "stipple view"]);
        s.window = id.lines().next().unwrap().to_string();
        s.x(&["windowfocus", "--sync", &s.window.clone()]);
        s
    }

    /// xdotool on this display; its output.
    fn x(&self, args: &[&str]) -> String {
        let o = Command::new(&self.xdotool)
            .args(args)
            .env("DISPLAY", &self.display.name)
            .output()
            .unwrap();
        assert!(o.status.success(), "xdotool {args:?}: {}", text(&o));
        String::from_utf8_lossy(&o.stdout).trim().to_string()
    }

    /// The next line the viewer prints that starts with `prefix` ("" if it ends first).
    fn line(&mut self, prefix: &str) -> String {
        for l in self.out.by_ref().map_while(|l| l.ok()) {
            self.said.push(l.clone());
            if l.starts_with(prefix) {
                return l;
            }
        }
        String::new()
    }

    /// Waits while the window's title says `what` (nodes loading, shadows refining).
    fn wait_title_without(&self, what: &str) {
        let t0 = Instant::now();
        while self.x(&["getwindowname", &self.window]).contains(what) {
            assert!(
                t0.elapsed() < Duration::from_secs(60),
                "the title kept saying {what}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// The window's pixels more than a level off `reference` once the screen settled.
    fn settled(&self, reference: &[u8], w: usize, h: usize) -> usize {
        settled_difference(&self.xwd, &self.display.name, reference, w, h)
    }

    /// The whole screen now.
    fn screen(&self) -> (usize, usize, Vec<[u8; 3]>) {
        let o = Command::new(&self.xwd)
            .args(["-root", "-silent"])
            .env("DISPLAY", &self.display.name)
            .output()
            .unwrap();
        read_xwd(&o.stdout)
    }

    /// Escape, and the viewer's exit.
    fn close(mut self) -> ExitStatus {
        self.x(&["key", "Escape"]);
        let t0 = Instant::now();
        loop {
            if let Some(s) = self.viewer.try_wait().unwrap() {
                return s;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(30),
                "Escape did not close the viewer"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// `stipple render ARGS` in `dir`, which must succeed; the image it wrote to `out`.
fn render(dir: &Path, args: &[&str], out: &str) -> Vec<u8> {
    render_on(dir, args, out, "cpu")
}

/// As `render`, on a chosen backend.
fn render_on(dir: &Path, args: &[&str], out: &str, backend: &str) -> Vec<u8> {
    let mut a = vec!["render"];
    a.extend(args);
    a.extend(["--backend", backend, "-o", out]);
    let o = stipple(dir, &a);
    assert!(o.status.success(), "{}", text(&o));
    stipple_io::image::read_png(&dir.join(out)).unwrap().2
}

#[test]
fn the_window_shows_what_render_draws_for_the_camera_it_saves() {
    let Some(tools) = tools() else { return };
    let dir = tempdir("view");
    let (w, h) = (200usize, 150usize);
    let size = format!("{w}x{h}");
    let mut s = Session::start(
        &tools,
        &dir,
        &["--size", &size, "--backend", "cpu", "-o", "shot"],
    );
    // Orbit: a drag to the right and down with the left button.
    s.x(&["mousemove", "--sync", "60", "60"]);
    s.x(&["mousedown", "1"]);
    s.x(&["mousemove", "--sync", "110", "75"]);
    s.x(&["mouseup", "1"]);
    std::thread::sleep(Duration::from_millis(500));
    // A double click in the middle picks a point: its coordinates and the point's own
    // position and colour are printed, and the orbit centres on it.
    s.x(&["mousemove", "--sync", "100", "75"]);
    s.x(&["click", "--repeat", "2", "--delay", "80", "1"]);
    let picked = s.line("picked");
    let xyz: Vec<f64> = picked
        .split_whitespace()
        .skip(1)
        .take(3)
        .filter_map(|t| t.parse().ok())
        .collect();
    assert!(
        xyz.len() == 3 && xyz.iter().all(|v| v.abs() < 5.0) && picked.contains("colour"),
        "the viewer said {picked:?}"
    );
    std::thread::sleep(Duration::from_millis(500));
    // Save the camera (C) and the viewer's own screenshot (P).
    s.x(&["key", "c"]);
    wait_for(&dir.join("shot-1.json"), "the camera");
    s.x(&["key", "p"]);
    let shot = dir.join("shot-1.png");
    wait_for(&shot, "the screenshot");
    // What render draws for the saved camera, and the window as a person sees it.
    let reference = render(&dir, &["--camera", "shot-1.json"], "ref.png");
    let off = s.settled(&reference, w, h);
    assert!(s.close().success(), "the viewer failed");
    assert!(
        off * 1000 <= w * h,
        "{off} of {} window pixels differ from render's image of the saved camera",
        w * h
    );
    let (_, _, own) = stipple_io::image::read_png(&shot).unwrap();
    assert!(
        own == reference,
        "the viewer's screenshot is the render of its camera"
    );
    // The camera moved: neither its eye nor its image is the opening one.
    let opening = render(
        &dir,
        &["--size", &size, "--camera-out", "home.json"],
        "home.png",
    );
    let eye = |f: &str| {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(f)).unwrap()).unwrap();
        v["eye"].clone()
    };
    assert_ne!(
        eye("shot-1.json"),
        eye("home.json"),
        "the drag orbited the camera"
    );
    assert!(
        opening != reference,
        "the window moved away from the opening view"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Shadows come progressively (Dobrev §7): the window opens with one sample per light and
/// takes the rest while the view rests; once refined, what it shows is what `render` draws
/// with every sample for the same camera.
#[test]
fn shadows_refine_while_the_view_rests() {
    let Some(tools) = tools() else { return };
    let dir = tempdir("view-shadows");
    std::fs::write(
        dir.join("s.toml"),
        "[camera]\neye = [2.0, 2.5, 3.0]\ntarget = [0.0, 0.3, 0.0]\n\n\
         [[cloud]]\ndemo = \"plane\"\npoints = 40000\nscale = 4\n\n\
         [[cloud]]\ndemo = \"sphere\"\npoints = 20000\nscale = 0.5\ntranslate = [0, 0.8, 0]\n\n\
         [[light]]\ntype = \"area\"\nposition = [0.5, 3, 0.5]\nshape = \"disc\"\nradius = 0.4\n\
         samples = 6\n",
    )
    .unwrap();
    let (w, h) = (160usize, 120usize);
    let size = format!("{w}x{h}");
    let mut s = Session::start(
        &tools,
        &dir,
        &["s.toml", "--size", &size, "--backend", "cpu", "-o", "shot"],
    );
    assert!(
        s.said[0].starts_with("shadows: 1 light samples"),
        "the window opens with one sample: {:?}",
        s.said
    );
    assert_eq!(
        s.line("shadows refined"),
        "shadows refined: 6 light samples"
    );
    std::thread::sleep(Duration::from_millis(500));
    s.x(&["key", "c"]);
    wait_for(&dir.join("shot-1.json"), "the camera");
    let reference = render(&dir, &["s.toml", "--camera", "shot-1.json"], "ref.png");
    let off = s.settled(&reference, w, h);
    s.close();
    assert!(
        off * 1000 <= w * h,
        "{off} pixels differ from render's fully sampled shadows"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Builds `file` from a generated torus of `points` with `build-lod`, opens it in the viewer
/// with `extra` arguments, zooms in `notches` wheel notches, waits until no node is loading
/// and the view rests, and checks the window against `render`'s image of the same file for
/// the camera the viewer saved.
fn streams_into_the_window(name: &str, file: &str, points: &str, extra: &[&str], notches: usize) {
    let Some(tools) = tools() else { return };
    let dir = tempdir(name);
    for args in [
        &["gen", "torus", "-o", "t.ply", "--points", points][..],
        &["build-lod", "t.ply", "-o", file][..],
    ] {
        let o = stipple(&dir, args);
        assert!(o.status.success(), "{args:?}: {}", text(&o));
    }
    let (w, h) = (160usize, 120usize);
    let size = format!("{w}x{h}");
    let mut args = vec![file, "--size", &size, "--backend", "cpu", "-o", "shot"];
    args.extend(extra);
    let s = Session::start(&tools, &dir, &args);
    s.wait_title_without("loading");
    // Zoom in: a new cut, coarse while moving, streamed and refined at rest.
    s.x(&["mousemove", "--sync", "80", "60"]);
    for _ in 0..notches {
        s.x(&["click", "4"]);
    }
    std::thread::sleep(Duration::from_millis(300));
    s.wait_title_without("loading");
    s.wait_title_without("moving");
    s.x(&["key", "c"]);
    wait_for(&dir.join("shot-1.json"), "the camera");
    let mut args = vec![file, "--camera", "shot-1.json"];
    args.extend(extra);
    let reference = render(&dir, &args, "ref.png");
    let off = s.settled(&reference, w, h);
    s.close();
    assert!(
        off * 1000 <= w * h,
        "{off} pixels differ from render's cut of {file}"
    );
    let covered = (0..w * h)
        .filter(|&k| reference[4 * k..4 * k + 3] != reference[..3])
        .count();
    assert!(covered > w * h / 10, "the torus covers the window");
    std::fs::remove_dir_all(&dir).ok();
}

/// A tree streams: the window opens at once with what is resident (the root first) and
/// cuts again as nodes arrive, and the finished view is what `render` draws from the tree
/// for the same camera (which waits for the whole cut).
#[test]
fn a_tree_streams_into_the_window() {
    streams_into_the_window("view-tree", "t.stlod", "300000", &[], 1);
}

/// A COPC file beyond the point budget streams as a tree does: the window cuts again for a
/// new camera while its nodes decode in the background, and the finished view is what
/// `render` draws from the file for the same camera.
#[test]
fn a_copc_file_streams_into_the_window() {
    let budget = ["--point-budget", "150000"];
    streams_into_the_window("view-copc", "t.copc.laz", "400000", &budget, 2);
}

/// A tree whose file is damaged while it streams: the last cut stays on screen, the title
/// says why, and the viewer goes on (and closes cleanly).
#[test]
fn a_tree_damaged_while_streaming_keeps_the_window() {
    let Some(tools) = tools() else { return };
    let dir = tempdir("view-tree-gone");
    for args in [
        &["gen", "torus", "-o", "t.ply", "--points", "300000"][..],
        &[
            "build-lod",
            "t.ply",
            "-o",
            "t.stlod",
            "--max-node-points",
            "4096",
        ][..],
    ] {
        let o = stipple(&dir, args);
        assert!(o.status.success(), "{args:?}: {}", text(&o));
    }
    let s = Session::start(
        &tools,
        &dir,
        &[
            "t.stlod",
            "--size",
            "160x120",
            "--backend",
            "cpu",
            "--point-budget",
            "20000",
        ],
    );
    s.wait_title_without("loading");
    // The tree's bytes replaced by garbage of the same length (the open file sees them).
    let len = std::fs::metadata(dir.join("t.stlod")).unwrap().len();
    std::fs::OpenOptions::new()
        .write(true)
        .open(dir.join("t.stlod"))
        .and_then(|mut f| {
            use std::io::Write;
            f.write_all(&vec![0x5a; len as usize])
        })
        .unwrap();
    // Zoom in: the finer cut needs nodes that can no longer be read.
    s.x(&["mousemove", "--sync", "80", "60"]);
    let t0 = Instant::now();
    let title = loop {
        s.x(&["click", "4"]);
        std::thread::sleep(Duration::from_millis(400));
        let t = s.x(&["getwindowname", &s.window]);
        if t.contains("corrupt") || t0.elapsed().as_secs() > 40 {
            break t;
        }
    };
    let screen = s.screen();
    assert!(
        s.close().success(),
        "the viewer ended cleanly after the failure"
    );
    assert!(
        title.contains("do not match their checksum: the file is corrupt"),
        "the title says why the tree stopped streaming: {title:?}"
    );
    let lit = (0..120)
        .flat_map(|y| (0..160).map(move |x| (x, y)))
        .filter(|&(x, y)| screen.2[y * screen.0 + x] != screen.2[0])
        .count();
    assert!(lit > 160 * 120 / 20, "the last cut stays on screen ({lit})");
    std::fs::remove_dir_all(&dir).ok();
}

/// The window resized, then unmapped and mapped again (minimised and restored): the frame
/// follows the new size, and what the window shows is `render` of the camera it saves.
#[test]
fn resizing_and_restoring_the_window() {
    let Some(tools) = tools() else { return };
    let dir = tempdir("view-resize");
    let s = Session::start(
        &tools,
        &dir,
        &["--size", "160x120", "--backend", "cpu", "-o", "shot"],
    );
    s.x(&["windowsize", "--sync", &s.window, "240", "180"]);
    std::thread::sleep(Duration::from_millis(500));
    s.x(&["windowunmap", "--sync", &s.window]);
    std::thread::sleep(Duration::from_millis(300));
    s.x(&["windowmap", "--sync", &s.window]);
    s.x(&["windowfocus", "--sync", &s.window]);
    std::thread::sleep(Duration::from_millis(500));
    s.x(&["key", "c"]);
    wait_for(&dir.join("shot-1.json"), "the camera");
    let cam: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("shot-1.json")).unwrap()).unwrap();
    assert_eq!(cam["size"], serde_json::json!([240, 180]), "{cam}");
    let reference = render(&dir, &["--camera", "shot-1.json"], "ref.png");
    let off = s.settled(&reference, 240, 180);
    assert!(s.close().success(), "the viewer failed");
    assert!(
        off * 1000 <= 240 * 180,
        "{off} pixels differ from render after the resize"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The panel (Tab) holds every `render` option by its flag's name: filtered to
/// `no-lighting`, ticked and applied, the window shows what `render --no-lighting` draws for
/// the same camera; the panel opens beside the image and closes again.
#[test]
fn the_panel_applies_render_options() {
    let Some(tools) = tools() else { return };
    let dir = tempdir("view-panel");
    let (w, h) = (400usize, 300usize);
    let size = format!("{w}x{h}");
    let mut s = Session::start(
        &tools,
        &dir,
        &["--size", &size, "--backend", "cpu", "-o", "shot"],
    );
    let before = s.screen();
    s.x(&["key", "Tab"]);
    std::thread::sleep(Duration::from_millis(700));
    let with_panel = s.screen();
    let changed = (0..h)
        .flat_map(|y| (0..120).map(move |x| (x, y)))
        .filter(|&(x, y)| before.2[y * before.0 + x] != with_panel.2[y * with_panel.0 + x])
        .count();
    assert!(
        changed > 1000,
        "Tab shows the panel on the left ({changed} pixels changed)"
    );
    // Filter (the text field at the top), tick the one option left, Apply.
    s.x(&["mousemove", "--sync", "165", "69", "click", "1"]);
    s.x(&["type", "--delay", "20", "no-lighting"]);
    std::thread::sleep(Duration::from_millis(400));
    s.x(&["mousemove", "--sync", "15", "147", "click", "1"]);
    std::thread::sleep(Duration::from_millis(300));
    s.x(&["mousemove", "--sync", "32", "92", "click", "1"]);
    let applied = s.line("applied");
    assert!(
        applied.contains("--no-lighting"),
        "the viewer said {:?}",
        s.said
    );
    // The panel's screenshot menu: a size typed into its field, Screenshot, Save camera.
    s.x(&["mousemove", "--sync", "130", "115", "click", "1"]);
    s.x(&["type", "--delay", "20", "120x90"]);
    std::thread::sleep(Duration::from_millis(300));
    s.x(&["mousemove", "--sync", "48", "115", "click", "1"]);
    wait_for(&dir.join("shot-1.png"), "the panel's screenshot");
    s.x(&["mousemove", "--sync", "218", "115", "click", "1"]);
    wait_for(&dir.join("shot-1.json"), "the panel's camera");
    let shot = render(
        &dir,
        &[
            "--camera",
            "shot-1.json",
            "--no-lighting",
            "--size",
            "120x90",
        ],
        "ref-shot.png",
    );
    let (sw, sh, own) = stipple_io::image::read_png(&dir.join("shot-1.png")).unwrap();
    assert_eq!((sw, sh), (120, 90), "the screenshot has the size typed");
    assert!(own == shot, "the panel's screenshot is render's image");
    // Hide the panel (a click on the image first takes the keyboard from the text field),
    // save the camera, look at the window.
    s.x(&["mousemove", "--sync", "380", "280", "click", "1"]);
    s.x(&["key", "Tab"]);
    std::thread::sleep(Duration::from_millis(500));
    s.x(&["key", "c"]);
    wait_for(&dir.join("shot-2.json"), "the camera");
    let reference = render(
        &dir,
        &["--camera", "shot-2.json", "--no-lighting"],
        "ref.png",
    );
    let off = s.settled(&reference, w, h);
    s.close();
    assert!(
        off * 1000 <= w * h,
        "{off} pixels differ from render --no-lighting"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A scripted run on real data: 30 frames of the Stanford bunny along a camera path (an
/// orbit of keyframes), every frame written to a folder; the window's last frame on the
/// screen, and the last file, equal `stipple render` of the path's last camera.
#[test]
fn a_camera_path_on_real_data_ends_where_render_draws() {
    let Some(tools) = tools() else { return };
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let bunny = data.join("stanford/bunny/bun_zipper.ply");
    if !bunny.is_file() {
        eprintln!("skipped: {} is absent", bunny.display());
        return;
    }
    let dir = tempdir("view-path");
    let (w, h) = (200usize, 150usize);
    let size = format!("{w}x{h}");
    let bunny = bunny.to_str().unwrap();
    let opening = render(
        &dir,
        &[bunny, "--size", &size, "--camera-out", "home.json"],
        "home.png",
    );
    let home =
        stipple_core::Camera::from_json(&std::fs::read_to_string(dir.join("home.json")).unwrap())
            .unwrap();
    // 30 keyframes orbiting the target by 90° about +Y.
    let keys: Vec<String> = (0..30)
        .map(|k| {
            let a = (k as f64 / 29.0) * std::f64::consts::FRAC_PI_2;
            let mut c = home.clone();
            let o = c.eye - c.target;
            c.eye = c.target
                + glam::DVec3::new(
                    o.x * a.cos() + o.z * a.sin(),
                    o.y,
                    -o.x * a.sin() + o.z * a.cos(),
                );
            c.to_json()
        })
        .collect();
    std::fs::write(dir.join("path.json"), format!("[{}]", keys.join(","))).unwrap();
    std::fs::write(dir.join("last.json"), &keys[29]).unwrap();
    std::fs::create_dir_all(dir.join("frames")).unwrap();
    let mut s = Session::start(
        &tools,
        &dir,
        &[
            bunny,
            "--size",
            &size,
            "--backend",
            "cpu",
            "--camera-path",
            "path.json",
            "--screenshot-dir",
            "frames",
        ],
    );
    assert_eq!(s.line("camera path done"), "camera path done (30 frames)");
    let reference = render(&dir, &[bunny, "--camera", "last.json"], "ref.png");
    let off = s.settled(&reference, w, h);
    s.close();
    assert!(
        off * 1000 <= w * h,
        "{off} pixels of the last frame differ from render"
    );
    assert_eq!(
        std::fs::read_dir(dir.join("frames")).unwrap().count(),
        30,
        "every frame written"
    );
    // The files: the last is render's image of the last camera, the first of the first
    // (within the screen's tolerance: the viewer fits near and far to the cloud for every
    // camera of the path, where the keyframes carry the opening camera's).
    let differ = |a: &[u8], b: &[u8]| {
        (0..w * h)
            .filter(|&k| (0..3).any(|c| a[4 * k + c].abs_diff(b[4 * k + c]) > 1))
            .count()
    };
    let frame = |n: u32| {
        stipple_io::image::read_png(&dir.join(format!("frames/frame-{n:05}.png")))
            .unwrap()
            .2
    };
    let (first, last) = (frame(1), frame(30));
    let d = differ(&last, &reference);
    assert!(
        d * 1000 <= w * h,
        "the last frame written: {d} pixels differ from render"
    );
    let d = differ(&first, &opening);
    assert!(
        d * 1000 <= w * h,
        "the first frame: {d} pixels differ from the first camera's"
    );
    assert!(
        differ(&first, &last) > w * h / 50,
        "the path moved the camera"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `--screenshot-size` makes P render the current view at another size: the file is
/// `render`'s image of the saved camera at that size.
#[test]
fn screenshots_at_a_chosen_size() {
    let Some(tools) = tools() else { return };
    let dir = tempdir("view-shot-size");
    let s = Session::start(
        &tools,
        &dir,
        &[
            "--size",
            "160x120",
            "--backend",
            "cpu",
            "-o",
            "shot",
            "--screenshot-size",
            "96x40",
        ],
    );
    s.x(&["key", "c"]);
    wait_for(&dir.join("shot-1.json"), "the camera");
    s.x(&["key", "p"]);
    wait_for(&dir.join("shot-1.png"), "the screenshot");
    s.close();
    let reference = render(
        &dir,
        &["--camera", "shot-1.json", "--size", "96x40"],
        "ref.png",
    );
    let (w, h, shot) = stipple_io::image::read_png(&dir.join("shot-1.png")).unwrap();
    assert_eq!((w, h), (96, 40));
    assert!(
        shot == reference,
        "the screenshot is render's image at that size"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The GPU backend presents in place: the window's surface is made on the renderer's own
/// device and the frame never crosses to the host. What the window shows is still `render
/// --backend gpu` of the camera it saves; a double click (which reads the frame back) picks
/// a point, and P's screenshot is that render's image too.
#[test]
fn the_gpu_backend_presents_in_place() {
    let Some(tools) = tools() else { return };
    if !gpu_available() {
        return;
    }
    let dir = tempdir("view-gpu");
    let (w, h) = (200usize, 150usize);
    let size = format!("{w}x{h}");
    let mut s = Session::start(
        &tools,
        &dir,
        &["--size", &size, "--backend", "gpu", "-o", "shot"],
    );
    let first = s.said.last().unwrap().clone();
    assert!(
        first.contains("on gpu") && first.contains("in place"),
        "the viewer said {first:?}"
    );
    // A double click on pixel (100, 75) of the opening view picks the surface point that
    // `render --depth-out` puts there: the pixel's ray at that depth.
    s.x(&["mousemove", "--sync", "100", "75"]);
    s.x(&["click", "--repeat", "2", "--delay", "80", "1"]);
    let picked = s.line("picked");
    let xyz: Vec<f64> = picked
        .split_whitespace()
        .skip(1)
        .take(3)
        .filter_map(|t| t.parse().ok())
        .collect();
    let o = stipple(
        &dir,
        &[
            "render",
            "--size",
            &size,
            "--backend",
            "gpu",
            "-o",
            "home.png",
            "--camera-out",
            "home.json",
            "--depth-out",
            "home.npy",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let home =
        stipple_core::Camera::from_json(&std::fs::read_to_string(dir.join("home.json")).unwrap())
            .unwrap();
    let (_, _, depth) = stipple_io::image::read_npy(&dir.join("home.npy")).unwrap();
    let d = depth[75 * w + 100] as f64;
    let (origin, ray) = home.pixel_ray(100, 75);
    let known = origin + ray * (d / ray.dot(home.basis().forward));
    assert!(
        xyz.len() == 3 && (glam::DVec3::new(xyz[0], xyz[1], xyz[2]) - known).length() < 1e-3,
        "picked {picked:?}, the surface there is {known}"
    );
    std::thread::sleep(Duration::from_millis(500));
    s.x(&["mousemove", "--sync", "60", "60"]);
    s.x(&["mousedown", "1"]);
    s.x(&["mousemove", "--sync", "100", "70"]);
    s.x(&["mouseup", "1"]);
    std::thread::sleep(Duration::from_millis(500));
    s.x(&["key", "c"]);
    wait_for(&dir.join("shot-1.json"), "the camera");
    s.x(&["key", "p"]);
    wait_for(&dir.join("shot-1.png"), "the screenshot");
    let reference = render_on(&dir, &["--camera", "shot-1.json"], "ref.png", "gpu");
    let off = s.settled(&reference, w, h);
    assert!(s.close().success(), "the viewer failed");
    assert!(
        off * 1000 <= w * h,
        "{off} of {} window pixels differ from render's image of the saved camera",
        w * h
    );
    let (_, _, own) = stipple_io::image::read_png(&dir.join("shot-1.png")).unwrap();
    assert!(own == reference, "the screenshot is render's image");
    std::fs::remove_dir_all(&dir).ok();
}

/// `stipple view --size 96x72 --backend BACKEND --exit-after FRAMES` of the demo scene on a
/// display of its own, with `env`; it must succeed; what it printed.
fn scripted(xvfb: &Path, dir: &Path, backend: &str, frames: u32, env: &[(&str, &str)]) -> String {
    let display = start_display(xvfb);
    let frames = frames.to_string();
    let o = Command::new(env!("CARGO_BIN_EXE_stipple"))
        .args(["view", "--size", "96x72", "--backend", backend])
        .args(["--exit-after", &frames, "--quit-after", "120"])
        .current_dir(dir)
        .env("DISPLAY", &display.name)
        .envs(env.iter().copied())
        .output()
        .unwrap();
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    t
}

/// The GPU device lost mid-run (destroyed as a driver reset would, through a test hook):
/// the viewer says so, goes on rendering on the CPU with a presenter of its own, and
/// finishes its frames.
#[test]
fn a_lost_gpu_device_moves_the_viewer_to_the_cpu() {
    let Some([xvfb, _, _]) = tools() else { return };
    if !gpu_available() {
        return;
    }
    let dir = tempdir("view-lost");
    let t = scripted(&xvfb, &dir, "gpu", 6, &[("STIPPLE_VIEW_LOSE_DEVICE", "2")]);
    assert!(
        t.contains("destroying the GPU device after frame 2")
            && t.contains("the GPU device was lost")
            && t.contains("rendering on the CPU")
            && t.contains("6 frames on cpu"),
        "{t}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `--exit-after N` closes the window after N frames and prints frame-time statistics.
#[test]
fn a_scripted_run_prints_frame_statistics() {
    let Some([xvfb, _, _]) = tools() else { return };
    let dir = tempdir("view-stats");
    let t = scripted(&xvfb, &dir, "cpu", 5, &[]);
    assert!(
        t.contains("5 frames on cpu") && t.contains("median") && t.contains("p99"),
        "{t}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn without_a_display_view_says_what_to_do() {
    let dir = tempdir("view-nodisplay");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_stipple"))
        .args(["view", "--size", "64x48"])
        .current_dir(&dir)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let t = text(&o);
    assert!(
        t.contains("no display") && t.contains("stipple render"),
        "{t}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
