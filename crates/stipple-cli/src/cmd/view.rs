//! `stipple view`: a window onto a cloud, a scene file or a demo scene, moved with the mouse
//! and keys, drawn by the same library and the same pipeline as `stipple render` (every
//! `render` option applies, with the same names and ranges). See `crate::view` for the
//! navigation and the presentation.

use crate::cmd::render::RenderArgs;
use crate::view::nav::{pick, Nav};
use crate::view::present::{Presenter, Source};
use crate::Result;
use anyhow::anyhow;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use stipple_render::{Pipeline, PreparedCloud, Renderer};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

#[derive(clap::Args)]
#[command(after_help = "\
Mouse: left drag orbits about the target, right or middle drag (or shift + left) pans, the \
wheel zooms, a double click centres the orbit on the point under the cursor (its \
coordinates and attributes are printed, and the distance to the previous pick).
Keys: W A S D fly (Q E down and up, shift faster), F frames everything again, U switches \
the up axis between Z (LiDAR) and Y (scanned objects), P saves a \
screenshot (PNG, the window's size or --screenshot-size), C saves the camera as JSON (`stipple render --camera \
FILE` renders exactly that view), Tab shows the panel of every `render` option (Apply redraws \
with them; Screenshot, with a size field, and Save camera do what P and C do), Escape quits.
Files: screenshots and cameras are written as stipple-view-N.png / .json in the current \
directory, or PREFIX-N.… with -o PREFIX; never over an existing file.")]
pub struct ViewArgs {
    #[command(flatten)]
    pub render: RenderArgs,
    /// While the view moves, a tree's cut is made coarser until a frame takes at most this
    /// many milliseconds [default: 16 on a GPU, 60 on the CPU]; at rest it refines to the full
    /// cut (--point-budget, --lod-error).
    #[arg(long, value_name = "MS", value_parser = crate::args::finite_f64)]
    pub frame_budget: Option<f64>,
    /// Fly along a camera path: a JSON list of cameras as --camera-out writes them
    /// (keyframes), interpolated over --exit-after frames (default: one frame per camera).
    #[arg(long, value_name = "PATH.json")]
    pub camera_path: Option<PathBuf>,
    /// Close the window after this many frames, printing frame-time statistics (scripted
    /// runs and benchmarks).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..=10_000_000))]
    pub exit_after: Option<u64>,
    /// Write every frame shown as DIR/frame-NNNNN.png (the directory must exist; existing
    /// files are not replaced).
    #[arg(long, value_name = "DIR")]
    pub screenshot_dir: Option<PathBuf>,
    /// P saves screenshots of this size (WxH) instead of the window's: the current view
    /// rendered again at that size (the vertical field of view kept).
    #[arg(long, value_name = "WxH", value_parser = crate::args::parse_size)]
    pub screenshot_size: Option<(u32, u32)>,
    /// Close the window after this many seconds (scripts and tests).
    #[arg(long, value_name = "SECONDS", value_parser = crate::args::finite_f64)]
    pub quit_after: Option<f64>,
}

/// What the window shows and what it was drawn with.
struct Scene {
    cloud: PreparedCloud,
    pipe: Pipeline,
    renderer: Renderer,
    label: String,
    /// Where screenshots and cameras go: `<prefix>-N.png` / `.json`.
    prefix: PathBuf,
    /// The input as `stipple render` takes it (empty for a demo), for the camera hint.
    input: String,
    /// Shadow samples still to take while the view rests.
    refine: Option<crate::look::ShadowRefinement>,
    /// A tree streamed as the view moves, with the camera and node loads the cloud was cut
    /// for, the cut's nodes still loading, and what each new cut is coloured with.
    stream: Option<Stream>,
}

struct Stream {
    tree: crate::lod::TreeStream,
    /// The camera, node loads and point budget (None: the full cut) the cloud was cut for.
    cut_for: Option<(stipple_core::Camera, u64, Option<u64>)>,
    /// The budget of cuts while the view moves, adapted to the frame-time target.
    moving_budget: u64,
    /// Why the tree can no longer be streamed (the last cut stays on screen).
    failed: Option<String>,
    missing: usize,
    colour: crate::args::ColourArgs,
    /// The `--lookup` table, read once for every cut.
    lookup: Option<(PathBuf, stipple_core::lookup::LookupTable)>,
    opacity: Option<f32>,
}

/// How long the view must rest before shadows are refined.
const REST: Duration = Duration::from_millis(300);

/// The last frame drawn (for the window, screenshots and picking).
struct Shown {
    w: u32,
    h: u32,
    /// The images, empty while they are on the GPU only (presented in place): picking and
    /// screenshots then render the camera again with a read-back.
    rgba: Vec<u8>,
    depth: Vec<f32>,
    /// The point each pixel shows (or a background/hole marker).
    id: Vec<u32>,
    camera: stipple_core::Camera,
}

struct App {
    scene: Scene,
    /// The side panel (Tab) of `render`'s options.
    panel: crate::view::panel::Panel,
    egui: egui::Context,
    egui_state: Option<egui_winit::State>,
    nav: Nav,
    window: Option<(Arc<Window>, Presenter)>,
    /// For presenters made again (Apply, a lost device).
    display: Option<winit::event_loop::OwnedDisplayHandle>,
    /// Tests: destroy the GPU device after this many frames (STIPPLE_VIEW_LOSE_DEVICE).
    lose_device_after: Option<u64>,
    shown: Option<Shown>,
    /// The view changed since the last frame.
    dirty: bool,
    frames: u64,
    cursor: (f64, f64),
    drag: Option<(MouseButton, (f64, f64))>,
    shift: bool,
    last_click: Option<(Instant, (f64, f64))>,
    /// Fly keys held: forward, right, up.
    fly: [i8; 6],
    last_tick: Instant,
    /// When the view last moved (refinement waits for it to rest).
    last_input: Instant,
    /// What is still refining, for the title.
    status: String,
    /// The last picked point (the next pick measures from it).
    picked: Option<glam::DVec3>,
    /// Milliseconds a frame may take while the view moves (trees coarsen their cut).
    frame_budget: f64,
    /// The window's size and the open panel's width, in pixels.
    window_size: (u32, u32),
    panel_px: u32,
    /// A scripted run: the camera path's keyframes and its frames, frames to show before
    /// closing, where to write every frame.
    path: Option<(Vec<stipple_core::Camera>, usize)>,
    exit_after: Option<u64>,
    screenshot_dir: Option<PathBuf>,
    /// Per frame shown: milliseconds of the render, and per pass the milliseconds summed.
    times: Vec<f64>,
    /// When each frame was presented (the intervals are what a person sees).
    presented: Vec<Instant>,
    pass_ms: Vec<(&'static str, f64)>,
    done: bool,
    quit_at: Option<Instant>,
    error: Option<anyhow::Error>,
}

pub fn view(a: ViewArgs) -> Result<()> {
    if std::env::var_os("DISPLAY").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
        return Err(anyhow!(
            "stipple view opens a window, and there is no display (DISPLAY is not set); on a \
             machine without one, `stipple render` writes images, or run a virtual display \
             (Xvfb :1 & DISPLAY=:1 stipple view …)"
        ));
    }
    let r = &a.render;
    let (scene, camera) = build(r, None)?;
    let (lo, hi, _) = scene.cloud.cloud.framing_bounds();
    let z_up = camera.up.z.abs() > camera.up.y.abs();
    // The panel starts with the options given after `view` (the input aside).
    let given: Vec<String> = std::env::args()
        .skip_while(|t| t != "view")
        .skip(1)
        .collect();
    let mut panel = crate::view::panel::Panel::new(
        &given,
        r.source.input.as_ref().map(|p| p.display().to_string()),
    );
    // One screenshot size for P and the panel's button.
    if let Some((w, h)) = a.screenshot_size {
        panel.shot_size = format!("{w}x{h}");
    }
    let path = match &a.camera_path {
        Some(p) => {
            let meta = std::fs::metadata(p).map_err(|e| anyhow!("{}: {e}", p.display()))?;
            if !meta.is_file() || meta.len() > 64 << 20 {
                return Err(anyhow!(
                    "{}: not a camera path (a regular JSON file of at most 64 MiB)",
                    p.display()
                ));
            }
            let text = std::fs::read_to_string(p).map_err(|e| anyhow!("{}: {e}", p.display()))?;
            let keys =
                crate::view::nav::read_path(&text).map_err(|e| anyhow!("{}: {e}", p.display()))?;
            let frames = a.exit_after.map_or(keys.len(), |n| n as usize);
            Some((keys, frames))
        }
        None => None,
    };
    if let Some(d) = &a.screenshot_dir {
        if !d.is_dir() {
            return Err(anyhow!(
                "--screenshot-dir {}: not a directory (make it first)",
                d.display()
            ));
        }
    }
    let event_loop = EventLoop::new().map_err(|e| {
        anyhow!("stipple view cannot open a window ({e}); `stipple render` writes images")
    })?;
    let mut app = App {
        scene,
        panel,
        egui: egui::Context::default(),
        egui_state: None,
        nav: Nav::new(camera.clone(), z_up, lo, hi),
        last_input: Instant::now(),
        window: None,
        display: None,
        lose_device_after: std::env::var("STIPPLE_VIEW_LOSE_DEVICE")
            .ok()
            .and_then(|v| v.parse().ok()),
        shown: None,
        dirty: true,
        frames: 0,
        cursor: (0.0, 0.0),
        drag: None,
        shift: false,
        last_click: None,
        fly: [0; 6],
        last_tick: Instant::now(),
        status: String::new(),
        picked: None,
        frame_budget: a.frame_budget.unwrap_or(0.0),
        window_size: (camera.width, camera.height),
        panel_px: 0,
        path,
        exit_after: a.exit_after,
        screenshot_dir: a.screenshot_dir.clone(),
        times: Vec::new(),
        presented: Vec::new(),
        pass_ms: Vec::new(),
        done: false,
        quit_at: a
            .quit_after
            .map(|s| Instant::now() + Duration::from_secs_f64(s.clamp(0.0, 1e6))),
        error: None,
    };
    app.path_step(0);
    event_loop
        .run_app(&mut app)
        .map_err(|e| anyhow!("the window's event loop failed: {e}"))?;
    app.print_stats();
    match app.error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Reads the input and prepares what every frame shares, as `stipple render` does: for the
/// opening view, or (Apply in the panel) with new options for the current `camera`.
fn build(
    r: &RenderArgs,
    camera: Option<&stipple_core::Camera>,
) -> Result<(Scene, stipple_core::Camera)> {
    if let Some((w, h)) = r.camera.size {
        crate::memory::check_frame(w, h, r.look.layers.unwrap_or(1))?;
    }
    let crate::api::Loaded {
        mut cloud,
        label,
        camera: opening,
        scene,
        tree,
    } = crate::api::load(r)?;
    let camera = camera.cloned().unwrap_or(opening);
    crate::memory::check_frame(
        camera.width,
        camera.height,
        crate::look::layers(&r.look, scene.as_ref()),
    )?;
    let mut renderer = r.backend.open()?;
    // Shadows: one sample per light now, the rest while the view rests (Dobrev §7).
    let (prepared, refine) = crate::api::prepare_progressively(
        r,
        &mut cloud,
        &crate::api::View {
            camera: &camera,
            scene: scene.as_ref(),
            tree,
            label: &label,
        },
        &mut renderer,
        &mut |n| eprintln!("stipple: {n}"),
        Some(1),
    )?;
    if let Some(line) = &prepared.shadow_line {
        println!("{line}");
    }
    let stream = match (&r.source.input, tree) {
        (Some(p), true) => Some({
            let tree = crate::lod::TreeStream::open(p, &r.lod)?;
            Stream {
                moving_budget: tree.point_budget(),
                failed: None,
                tree,
                cut_for: None,
                missing: 0,
                colour: r.colour.clone(),
                lookup: r.colour.load_lookup()?,
                opacity: r.look.opacity,
            }
        }),
        _ => None,
    };
    let prefix = match &r.output {
        Some(o) => o.with_extension(""),
        None => PathBuf::from("stipple-view"),
    };
    Ok((
        Scene {
            cloud,
            pipe: prepared.pipeline,
            renderer,
            label,
            prefix,
            input: r
                .source
                .input
                .as_ref()
                .map_or(String::new(), |p| format!("{} ", p.display())),
            refine,
            stream,
        },
        camera,
    ))
}

impl App {
    /// Apply in the panel: the options parsed as the command line parses them, the input
    /// read and prepared again, the camera kept.
    fn apply(&mut self) {
        let argv = self.panel.args();
        let r = match crate::api::parse_render_args(&argv) {
            Ok(r) => r,
            Err(e) => {
                self.panel.error = Some(e.to_string().trim().to_string());
                return;
            }
        };
        match build(&r, Some(&self.nav.camera)) {
            Ok((mut scene, _)) => {
                // Screenshots and cameras keep going where they went.
                scene.prefix = std::mem::take(&mut self.scene.prefix);
                self.scene = scene;
                self.panel.error = None;
                let (lo, hi, _) = self.scene.cloud.cloud.framing_bounds();
                self.nav.lo = lo;
                self.nav.hi = hi;
                self.shown = None;
                println!("applied: {}", argv.join(" "));
                // A new GPU renderer has a device of its own: the window presents from it.
                let reopen = match (&self.window, self.scene.renderer.gpu_context()) {
                    (Some((_, p)), ctx) => p.in_place() || ctx.is_some(),
                    (None, _) => false,
                };
                if reopen {
                    if let Err(e) = self.reopen_presenter() {
                        self.error = Some(e);
                        self.done = true;
                    }
                }
                self.changed();
            }
            Err(e) => self.panel.error = Some(crate::message(&e)),
        }
    }

    /// The panel's triangles for this frame (None while it is hidden), and what its buttons
    /// asked for.
    fn overlay(
        &mut self,
    ) -> (
        Option<crate::view::present::Overlay>,
        crate::view::panel::Actions,
    ) {
        let (Some((window, _)), Some(state), true) =
            (&self.window, &mut self.egui_state, self.panel.visible)
        else {
            return (None, Default::default());
        };
        let raw = state.take_egui_input(window);
        let panel = &mut self.panel;
        let mut act = crate::view::panel::Actions::default();
        let mut width = 0.0;
        let out = self.egui.run_ui(raw, |ui| {
            let (a, w) = panel.ui(ui);
            act = a;
            width = w;
        });
        self.panel_px = (width * out.pixels_per_point).ceil().max(0.0) as u32;
        state.handle_platform_output(window, out.platform_output);
        let primitives = self.egui.tessellate(out.shapes, out.pixels_per_point);
        (
            Some(crate::view::present::Overlay {
                primitives,
                textures: out.textures_delta,
                pixels_per_point: out.pixels_per_point,
            }),
            act,
        )
    }

    fn fail(&mut self, el: &ActiveEventLoop, e: anyhow::Error) {
        self.error = Some(e);
        el.exit();
    }

    /// Renders the current view and shows it.
    fn draw(&mut self) -> Result<()> {
        let (mut overlay, act) = self.overlay();
        if act.apply {
            self.apply();
        }
        if act.frame_all {
            self.nav.frame_all();
            self.changed();
        }
        // The panel's screenshot and camera buttons do what P and C do (after this frame's
        // camera is settled: the shot is of the view as shown).
        for (asked, r) in [
            (
                act.screenshot,
                Self::screenshot as fn(&mut Self) -> Result<()>,
            ),
            (act.save_camera, Self::save_camera),
        ] {
            if asked {
                if let Err(e) = r(self) {
                    let m = crate::message(&e);
                    eprintln!("stipple: {m}");
                    self.panel.error = Some(m);
                }
            }
        }
        let moving = self.moving();
        // The frame fills the window right of the panel.
        let left = if self.panel.visible { self.panel_px } else { 0 };
        let (ww, wh) = self.window_size;
        let fw = ww.saturating_sub(left).max(1);
        if (fw, wh.max(1)) != (self.nav.camera.width, self.nav.camera.height) {
            self.nav.resize(fw, wh.max(1));
            self.dirty = true;
        }
        self.recover_lost_device()?;
        let Some((window, presenter)) = &mut self.window else {
            return Ok(());
        };
        if let (false, Some(s)) = (self.dirty, &self.shown) {
            // Nothing moved (the window was uncovered, the panel changed): show the last
            // frame again, from the device where it stayed there.
            let source = if !s.rgba.is_empty() {
                Some(Source::Bytes(&s.rgba))
            } else {
                match self.scene.renderer.image() {
                    Some((b, w, h)) if (w, h) == (s.w, s.h) => Some(Source::Device(b)),
                    _ => None,
                }
            };
            if let Some(source) = source {
                if !presenter.show(s.w, s.h, source, left, overlay.as_mut())? {
                    window.request_redraw();
                }
                return Ok(());
            }
            // The device's image was replaced (a screenshot of another size): render again.
            self.dirty = true;
        }
        let cam = self.nav.camera.clone();
        // A tree: cut again for a new camera, or when nodes it waited for have loaded.
        if let Some(st) = &mut self.scene.stream {
            let loads = st.tree.loads();
            let budget = moving.then_some(st.moving_budget);
            if st.failed.is_none() && st.cut_for.as_ref() != Some(&(cam.clone(), loads, budget)) {
                // A tree that can no longer be read (a node damaged, the file gone): the
                // cut drawn so far stays, and the title says why.
                let (mut cloud, missing) = match st.tree.cut(&cam, budget) {
                    Ok(c) => c,
                    Err(e) => {
                        let m = crate::message(&e);
                        eprintln!("stipple: {m}");
                        self.status = format!(" — {m}");
                        st.failed = Some(m);
                        st.missing = 0;
                        return self.draw();
                    }
                };
                st.colour
                    .apply_loaded(&mut cloud, &self.scene.label, st.lookup.as_ref())?;
                if let Some(o) = st.opacity {
                    cloud.set_opacity(o);
                }
                self.scene.cloud = cloud;
                st.missing = missing;
                st.cut_for = Some((cam.clone(), loads, budget));
                self.status = match (missing, budget) {
                    (0, None) => String::new(),
                    (0, Some(b)) => format!(" — moving: at most {b} points"),
                    (m, _) => format!(" — loading {m} nodes"),
                };
            }
        }
        let t0 = Instant::now();
        // In place: the GPU's image goes to the window without a read-back (every frame
        // is read back only when written to --screenshot-dir).
        let in_place = presenter.in_place() && self.screenshot_dir.is_none();
        let frame = match if in_place {
            self.scene
                .renderer
                .render_resident(&self.scene.cloud, &cam, &self.scene.pipe)
        } else {
            self.scene
                .renderer
                .render(&self.scene.cloud, &cam, &self.scene.pipe)
        } {
            Ok(f) => f,
            Err(e) => {
                if self
                    .scene
                    .renderer
                    .gpu_context()
                    .and_then(|c| c.lost())
                    .is_some()
                {
                    // The device went during the frame: on the CPU from now on.
                    return self.draw();
                }
                return Err(e.into());
            }
        };
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        // While moving, the next cut's budget follows the frame-time target.
        if let (true, Some(st)) = (moving, &mut self.scene.stream) {
            let target = if self.frame_budget > 0.0 {
                self.frame_budget
            } else if !self.scene.renderer.is_gpu() {
                60.0
            } else {
                16.0
            };
            let points = self.scene.cloud.cloud.len() as f64;
            let next = if ms > target {
                points * target / ms * 0.9
            } else if ms < 0.5 * target {
                st.moving_budget as f64 * 1.25
            } else {
                st.moving_budget as f64
            };
            st.moving_budget = (next as u64).clamp(st.tree.least_budget(), st.tree.point_budget());
        }
        let source = match (frame.rgba.is_empty(), self.scene.renderer.image()) {
            (true, Some((b, _, _))) => Source::Device(b),
            (true, None) => return Err(anyhow!("the GPU frame has no image on the device")),
            (false, _) => Source::Bytes(&frame.rgba),
        };
        let shown = presenter.show(frame.width, frame.height, source, left, overlay.as_mut())?;
        if !shown {
            window.request_redraw();
            return Ok(());
        }
        self.dirty = false;
        self.frames += 1;
        self.times.push(ms);
        self.presented.push(Instant::now());
        for st in &frame.stats {
            match self.pass_ms.iter_mut().find(|p| p.0 == st.name()) {
                Some(p) => p.1 += st.ms,
                None => self.pass_ms.push((st.name(), st.ms)),
            }
        }
        if let Some(d) = &self.screenshot_dir {
            let p = d.join(format!("frame-{:05}.png", self.frames));
            if p.exists() {
                return Err(anyhow!("{}: exists; not replaced", p.display()));
            }
            stipple_io::image::write_png(&p, frame.width, frame.height, &frame.rgba)?;
        }
        let advance = if self.exit_after.is_some_and(|n| self.frames >= n) {
            self.done = true;
            false
        } else if self.path.is_none() && self.exit_after.is_some() {
            // A benchmark of one view: the same camera again until N frames.
            self.dirty = true;
            window.request_redraw();
            false
        } else {
            self.path.is_some()
        };
        window.set_title(&format!(
            "stipple view — {} — {}×{} — {ms:.0} ms on {}{}",
            self.scene.label,
            frame.width,
            frame.height,
            self.scene.renderer.describe(),
            self.status
        ));
        if self.frames == 1 {
            println!(
                "showing {} ({}x{}, {ms:.0} ms on {}, presented by {}{})",
                self.scene.label,
                frame.width,
                frame.height,
                self.scene.renderer.describe(),
                presenter.adapter_name,
                if in_place {
                    " in place"
                } else {
                    " from a copy"
                }
            );
            use std::io::Write;
            let _ = std::io::stdout().flush();
        }
        self.shown = Some(Shown {
            w: frame.width,
            h: frame.height,
            rgba: frame.rgba,
            depth: frame.depth,
            id: frame.id,
            camera: cam,
        });
        if advance {
            self.path_step(self.frames as usize);
        }
        if self.lose_device_after == Some(self.frames) {
            // Tests: the device goes as a driver reset would take it.
            println!(
                "test: destroying the GPU device after frame {}",
                self.frames
            );
            match (self.scene.renderer.gpu_context(), &self.window) {
                (Some(c), _) => c.device.destroy(),
                (None, Some((_, p))) => p.destroy_device(),
                _ => {}
            }
            self.dirty = true;
            if let Some((w, _)) = &self.window {
                w.request_redraw();
            }
        }
        Ok(())
    }

    /// A device lost (a driver reset, a removed GPU): the renderer's moves to the CPU, the
    /// window gets a presenter of its own, and the title says so. Nothing is lost but time.
    fn recover_lost_device(&mut self) -> Result<()> {
        let renderer_lost = self.scene.renderer.gpu_context().and_then(|c| c.lost());
        let presenter_lost = self.window.as_ref().and_then(|(_, p)| p.lost());
        let Some(why) = renderer_lost.clone().or(presenter_lost) else {
            return Ok(());
        };
        if renderer_lost.is_some() {
            self.scene.renderer =
                stipple_render::Renderer::new(stipple_render::Backend::Cpu, Default::default())?;
            self.status = format!(" — the GPU device was lost ({why}); rendering on the CPU");
        } else {
            self.status = format!(" — the window's GPU device was lost ({why}); reopened");
        }
        eprintln!("stipple:{}", self.status.trim_start_matches(" —"));
        self.shown = None;
        self.dirty = true;
        self.reopen_presenter()
    }

    /// A new presenter for the window (the old one dropped first: a window has one
    /// swap chain), in place on the renderer's device where it can be.
    fn reopen_presenter(&mut self) -> Result<()> {
        let Some((window, presenter)) = self.window.take() else {
            return Ok(());
        };
        drop(presenter);
        let display = self
            .display
            .clone()
            .ok_or_else(|| anyhow!("the window's display handle is gone"))?;
        let p = Presenter::new(window.clone(), display, self.scene.renderer.gpu_context())?;
        // The panel's textures (its font atlas) lived on the old device: a new context sends
        // them again.
        self.egui = egui::Context::default();
        self.egui_state = Some(new_egui_state(&self.egui, &window));
        self.window = Some((window.clone(), p));
        window.request_redraw();
        Ok(())
    }

    /// A scripted run: the camera of frame `k` of the path (nothing past its end).
    fn path_step(&mut self, k: usize) {
        let Some((keys, frames)) = &self.path else {
            return;
        };
        if k >= *frames {
            if k == *frames {
                println!("camera path done ({frames} frames)");
            }
            return;
        }
        let mut c = crate::view::nav::path_camera(keys, k, *frames);
        c.width = self.nav.camera.width;
        c.height = self.nav.camera.height;
        self.nav.camera = c;
        self.nav
            .resize(self.nav.camera.width, self.nav.camera.height);
        self.dirty = true;
        if let Some((w, _)) = &self.window {
            w.request_redraw();
        }
    }

    /// Frame times at exit: median, 95th and 99th percentile, and the passes that took the
    /// time (mean per frame).
    fn print_stats(&self) {
        if self.times.is_empty() {
            return;
        }
        let mut t = self.times.clone();
        t.sort_by(f64::total_cmp);
        let at = |q: f64| crate::figures::percentile(&t, q);
        let n = t.len() as f64;
        // From one frame on screen to the next: the render, the presentation and the
        // event loop (what a person sees; the first frame's is not known).
        let mut gaps: Vec<f64> = self
            .presented
            .windows(2)
            .map(|p| (p[1] - p[0]).as_secs_f64() * 1e3)
            .collect();
        gaps.sort_by(f64::total_cmp);
        let interval = match gaps.len() {
            0 => String::new(),
            k => format!(
                "; presented every {:.2} ms (median), p99 {:.2}",
                gaps[k / 2],
                crate::figures::percentile(&gaps, 0.99)
            ),
        };
        let mut passes = self.pass_ms.clone();
        passes.sort_by(|a, b| b.1.total_cmp(&a.1));
        let top: Vec<String> = passes
            .iter()
            .take(6)
            .map(|(name, ms)| format!("{name} {:.2}", ms / n))
            .collect();
        println!(
            "{} frames on {}: render median {:.2} ms, p95 {:.2}, p99 {:.2}, max {:.2}; per frame: {} ms{interval}",
            t.len(),
            self.scene.renderer.describe(),
            at(0.5),
            at(0.95),
            at(0.99),
            t[t.len() - 1],
            top.join(", ")
        );
    }

    /// The view is moving (or rested less than [`REST`]).
    fn moving(&self) -> bool {
        self.last_input.elapsed() < REST || self.drag.is_some() || self.fly != [0; 6]
    }

    fn changed(&mut self) {
        self.dirty = true;
        self.last_input = Instant::now();
        if let Some((w, _)) = &self.window {
            w.request_redraw();
        }
    }

    /// The first `<prefix>-N.<ext>` that does not exist.
    fn free_name(&self, ext: &str) -> PathBuf {
        let p = &self.scene.prefix;
        (1..)
            .map(|n| PathBuf::from(format!("{}-{n}.{ext}", p.display())))
            .find(|c| !c.exists())
            .expect("some number is free")
    }

    /// The shown frame's images on the host: read back by rendering its camera again
    /// where they stayed on the GPU (the same image: rendering is deterministic).
    fn shown_on_host(&mut self) -> Result<()> {
        let Some(s) = &mut self.shown else {
            return Ok(());
        };
        if s.rgba.is_empty() {
            let f = self
                .scene
                .renderer
                .render(&self.scene.cloud, &s.camera, &self.scene.pipe)?;
            (s.rgba, s.depth, s.id) = (f.rgba, f.depth, f.id);
        }
        Ok(())
    }

    fn screenshot(&mut self) -> Result<()> {
        let size = self.panel.screenshot_size().map_err(|e| anyhow!(e))?;
        if size.is_none() {
            self.shown_on_host()?;
        }
        let Some(s) = &self.shown else {
            return Ok(());
        };
        let path = self.free_name("png");
        let mut staged = crate::output::Staged::default();
        match size {
            Some((w, h)) => {
                crate::memory::check_frame(w, h, self.scene.pipe.layers)?;
                let mut cam = s.camera.clone();
                cam.width = w;
                cam.height = h;
                let f = self
                    .scene
                    .renderer
                    .render(&self.scene.cloud, &cam, &self.scene.pipe)?;
                staged.write(&path, |t| stipple_io::image::write_png(t, w, h, &f.rgba))?;
            }
            None => staged.write(&path, |t| {
                stipple_io::image::write_png(t, s.w, s.h, &s.rgba)
            })?,
        }
        staged.commit()?;
        println!("wrote {}", path.display());
        Ok(())
    }

    fn save_camera(&mut self) -> Result<()> {
        let path = self.free_name("json");
        let json = self.nav.camera.to_json();
        let mut staged = crate::output::Staged::default();
        staged.write(&path, |t| {
            std::fs::write(t, &json).map_err(|e| stipple_io::IoError::io(t, e))
        })?;
        staged.commit()?;
        println!(
            "wrote {} (stipple render {}--camera {} renders this view)",
            path.display(),
            self.scene.input,
            path.display()
        );
        Ok(())
    }

    fn double_click(&mut self) {
        if let Err(e) = self.shown_on_host() {
            return eprintln!("stipple: picking: {}", crate::message(&e));
        }
        let Some(s) = &self.shown else { return };
        let (x, y) = self.cursor;
        if x < 0.0 || y < 0.0 || x >= s.w as f64 || y >= s.h as f64 {
            return;
        }
        let (i, j) = (x as u32, y as u32);
        if let Some(p) = pick(&s.camera, &s.depth, i, j) {
            let id = s.id[(j * s.w + i) as usize];
            let about = crate::view::nav::describe_point(&self.scene.cloud.cloud, id);
            println!("picked {:.4} {:.4} {:.4}{about}", p.x, p.y, p.z);
            if let Some(q) = self.picked {
                println!(
                    "distance to the previous pick: {:.4} (dx {:.4}, dy {:.4}, dz {:.4})",
                    (p - q).length(),
                    p.x - q.x,
                    p.y - q.y,
                    p.z - q.z
                );
            }
            self.picked = Some(p);
            self.nav.centre_on(p);
            self.changed();
        }
    }

    fn key(&mut self, el: &ActiveEventLoop, code: KeyCode, pressed: bool) {
        let fly = |c: KeyCode| match c {
            KeyCode::KeyW => Some(0),
            KeyCode::KeyS => Some(1),
            KeyCode::KeyD => Some(2),
            KeyCode::KeyA => Some(3),
            KeyCode::KeyE => Some(4),
            KeyCode::KeyQ => Some(5),
            _ => None,
        };
        if let Some(k) = fly(code) {
            self.fly[k] = pressed as i8;
            self.last_tick = Instant::now();
            return;
        }
        if !pressed {
            return;
        }
        let r = match code {
            KeyCode::Escape => {
                el.exit();
                Ok(())
            }
            KeyCode::KeyF => {
                self.nav.frame_all();
                self.changed();
                Ok(())
            }
            KeyCode::KeyU => {
                self.nav.toggle_up();
                println!(
                    "orbiting about {}",
                    if self.nav.up.z != 0.0 {
                        "Z (up)"
                    } else {
                        "Y (up)"
                    }
                );
                self.changed();
                Ok(())
            }
            KeyCode::KeyP => self.screenshot(),
            KeyCode::KeyC => self.save_camera(),
            _ => Ok(()),
        };
        if let Err(e) = r {
            eprintln!("stipple: {}", crate::message(&e));
        }
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let c = &self.nav.camera;
        let attrs = Window::default_attributes()
            .with_title(format!("stipple view — {}", self.scene.label))
            .with_inner_size(winit::dpi::PhysicalSize::new(c.width, c.height))
            .with_position(winit::dpi::PhysicalPosition::new(0, 0));
        let window = match el.create_window(attrs) {
            Ok(w) => Arc::new(w),
            Err(e) => return self.fail(el, anyhow!("cannot open a window: {e}")),
        };
        self.display = Some(el.owned_display_handle());
        match Presenter::new(
            window.clone(),
            el.owned_display_handle(),
            self.scene.renderer.gpu_context(),
        ) {
            Ok(p) => self.window = Some((window.clone(), p)),
            Err(e) => return self.fail(el, e),
        }
        self.egui_state = Some(new_egui_state(&self.egui, &window));
        // Keys reach the window without a window manager too (a virtual display).
        window.focus_window();
        window.request_redraw();
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        // Tab shows and hides the panel whatever has the keyboard.
        if let WindowEvent::KeyboardInput { event: k, .. } = &event {
            if k.physical_key == PhysicalKey::Code(KeyCode::Tab)
                && k.state == ElementState::Pressed
                && !k.repeat
            {
                self.panel.visible = !self.panel.visible;
                if let Some((w, _)) = &self.window {
                    w.request_redraw();
                }
                return;
            }
        }
        if self.panel.visible {
            if let (Some((w, _)), Some(state)) = (&self.window, &mut self.egui_state) {
                let r = state.on_window_event(w, &event);
                if r.repaint {
                    w.request_redraw();
                }
                let pointer = matches!(
                    event,
                    WindowEvent::CursorMoved { .. }
                        | WindowEvent::MouseInput { .. }
                        | WindowEvent::MouseWheel { .. }
                ) && self.drag.is_none()
                    && self.egui.is_pointer_over_egui();
                if r.consumed || pointer {
                    if let WindowEvent::CursorMoved { position, .. } = event {
                        self.cursor = (position.x, position.y);
                    }
                    return;
                }
            }
        }
        match event {
            WindowEvent::CloseRequested => el.exit(),
            WindowEvent::Resized(size) if size.width > 0 && size.height > 0 => {
                if let Some((_, p)) = &mut self.window {
                    p.resize(size.width, size.height);
                }
                // The frame's size follows in `draw` (beside the panel when it is open).
                self.window_size = (size.width, size.height);
                self.changed();
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.draw() {
                    self.fail(el, e);
                }
            }
            WindowEvent::ModifiersChanged(m) => self.shift = m.state().shift_key(),
            WindowEvent::KeyboardInput { event, .. } => {
                if let PhysicalKey::Code(code) = event.physical_key {
                    if !event.repeat || event.state == ElementState::Released {
                        self.key(el, code, event.state == ElementState::Pressed);
                    }
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                let (x, y) = (position.x, position.y);
                let (dx, dy) = (x - self.cursor.0, y - self.cursor.1);
                self.cursor = (x, y);
                match self.drag {
                    Some((MouseButton::Left, _)) if !self.shift => {
                        self.nav.orbit(dx, dy);
                        self.changed();
                    }
                    Some((MouseButton::Left | MouseButton::Right | MouseButton::Middle, _)) => {
                        self.nav.pan(dx, dy);
                        self.changed();
                    }
                    _ => {}
                }
            }
            WindowEvent::MouseInput { state, button, .. } => match state {
                ElementState::Pressed => {
                    self.drag = Some((button, self.cursor));
                    if button == MouseButton::Left {
                        let now = Instant::now();
                        let near = |p: (f64, f64)| {
                            (p.0 - self.cursor.0).abs() < 4.0 && (p.1 - self.cursor.1).abs() < 4.0
                        };
                        let double = self.last_click.is_some_and(|(t, p)| {
                            now.duration_since(t) < Duration::from_millis(400) && near(p)
                        });
                        self.last_click = Some((now, self.cursor));
                        if double {
                            self.last_click = None;
                            self.double_click();
                        }
                    }
                }
                ElementState::Released => self.drag = None,
            },
            WindowEvent::MouseWheel { delta, .. } => {
                let notches = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y as f64,
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                self.nav.zoom(notches);
                self.changed();
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        if self.done || self.quit_at.is_some_and(|t| Instant::now() >= t) {
            el.exit();
            return;
        }
        let axis = |a: usize, b: usize| (self.fly[a] - self.fly[b]) as f64;
        let (f, r, u) = (axis(0, 1), axis(2, 3), axis(4, 5));
        if (f, r, u) != (0.0, 0.0, 0.0) {
            let now = Instant::now();
            let dt = now.duration_since(self.last_tick).as_secs_f64().min(0.25);
            self.last_tick = now;
            self.nav.fly(f, r, u, dt, self.shift);
            self.changed();
            el.set_control_flow(ControlFlow::Poll);
            return;
        }
        let mut wake = self.quit_at;
        // A tree's nodes still loading: look again shortly, and draw when some arrived; a
        // coarse cut made while moving: the full one once the view rests.
        if let Some(st) = &self.scene.stream {
            if st.cut_for.as_ref().is_some_and(|c| c.2.is_some()) {
                if self.moving() {
                    let at = self.last_input + REST;
                    wake = Some(wake.map_or(at, |q| q.min(at)));
                } else {
                    self.dirty = true;
                    if let Some((w, _)) = &self.window {
                        w.request_redraw();
                    }
                }
            }
            if st.missing > 0 {
                if st
                    .cut_for
                    .as_ref()
                    .is_some_and(|(_, l, _)| *l != st.tree.loads())
                {
                    self.dirty = true;
                    if let Some((w, _)) = &self.window {
                        w.request_redraw();
                    }
                }
                let soon = Instant::now() + Duration::from_millis(100);
                wake = Some(wake.map_or(soon, |q| q.min(soon)));
            }
        }
        // Resting: one more shadow sample per light, then draw again (Dobrev §7).
        if let Some(refine) = self.scene.refine.clone() {
            let rest_at = self.last_input + REST;
            if Instant::now() < rest_at || self.drag.is_some() {
                wake = Some(wake.map_or(rest_at, |q| q.min(rest_at)));
            } else if !self.dirty {
                match refine.step(&mut self.scene.cloud, &mut self.scene.renderer) {
                    Ok((done, all)) => {
                        self.status = if done < all {
                            format!(" — refining shadows: {done} of {all} light samples")
                        } else {
                            println!("shadows refined: {all} light samples");
                            self.scene.refine = None;
                            String::new()
                        };
                        self.dirty = true;
                        if let Some((w, _)) = &self.window {
                            w.request_redraw();
                        }
                    }
                    Err(e) => return self.fail(el, e),
                }
            }
        }
        el.set_control_flow(match wake {
            Some(t) => ControlFlow::WaitUntil(t),
            None => ControlFlow::Wait,
        });
    }
}

/// The panel's input state for `window`.
fn new_egui_state(ctx: &egui::Context, window: &Window) -> egui_winit::State {
    egui_winit::State::new(
        ctx.clone(),
        egui::ViewportId::ROOT,
        window,
        Some(window.scale_factor() as f32),
        None,
        None,
    )
}
