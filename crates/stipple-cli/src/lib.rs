//! The `stipple` command line as a library: every subcommand's arguments and what it does,
//! and [`api`], what `stipple render` does between reading its input and writing its
//! outputs, for programs that embed it (the Python package).

pub mod api;
pub mod args;
pub mod cmd;
pub mod figures;
pub mod lod;
pub mod look;
pub mod memory;
pub mod oom;
pub mod output;
pub mod view;

use clap::{Parser, Subcommand};
use cmd::{gen::GenArgs, normals::NormalsArgs, render::RenderArgs};
use std::path::PathBuf;
use std::process::ExitCode;

const ABOUT: &str =
    "Render point clouds (scans, LiDAR, simulations) fast and faithfully, with no preprocessing.";

const LONG_ABOUT: &str = "\
Render point clouds (scans, LiDAR, simulations) fast and faithfully, with no preprocessing.

Run with no arguments to render the built-in demo scene to stipple-demo.png.

Examples:
  stipple render bunny.ply                          frame the cloud, write bunny.png
  stipple render tile.laz --size 1920x1080 -o tile.png --depth-out tile.npy
  stipple render scan.ply --eye 0,0.1,0.3 --target 0,0.1,0 --fov 40
  stipple render --demo nested-tori --points 2000000
  stipple info tile.laz                             count, bounds, attributes, spacing
  stipple gen torus -o torus.ply --points 500000    write a demo scene
  stipple bench tile.laz --frames 20                ms per pass, points/s
  stipple render tile.laz --backend gpu             on the GPU (auto: GPU if usable, else CPU)
  stipple devices                                   GPU adapters and what they support
  stipple render tile.laz --raw --shading edl       raw-cloud pipeline with eye-dome lighting
  stipple render tile.laz --depth-cue 0.6           far points fade into the background
  stipple render sparse.xyz --normal-out n.npy      splats; world-space normals per pixel
  stipple normals scan.xyz -o scan-normals.ply      estimate normals and splat radii
  stipple eval bun_zipper.ply                       raw rendering of a mesh's vertices vs the mesh
  stipple build-lod tiles/*.laz -o area.stlod       a multi-resolution tree for clouds beyond memory
  stipple render area.stlod --point-budget 5M       draw a view-dependent cut of the tree
  stipple render scene.toml                         a scene file: clouds, lights, camera (docs/scenes.md)
  stipple render tori.ply --layers 6                depth peeling: six layers blended by opacity
  stipple render scan.ply --shadows --light disc:0,2,1,0.2   soft shadows from an area light
  stipple bench dragon.ply.gz --table3              Dobrev Table 3: illumination, transparency, shadows
  stipple bench dragon.ply.gz --zhang               Zhang & Pajarola Table 2: splat blending, grouping

The rendering pipeline (Dobrev et al. 2010, §3): points are projected (nearest wins),
holes are filled in image space (background fill, then occluded-pixel fill with the layer
gap d̃), the result is lit with Phong, smoothed and anti-aliased. Every step can be switched
off or iterated; see `stipple render --help`.

Where points land more than half a pixel apart on screen, each point is drawn as a surface
splat instead (Zhang & Pajarola 2007), bent to the surface and cut at creases: ε-z
visibility, then Gaussian blending with per-pixel shading (default), their single-pass
deferred blending over graph-coloured groups (--splat deferred) or Voronoi rasterization
(--splat voronoi), so sparse clouds come out whole. Clouds without normals (most LAS/LAZ) get
estimated ones (--viewpoint X,Y,Z orients them towards a known sensor); normals of
inconsistent sign are re-oriented (--save-normals or `stipple normals` saves them). `--raw` uses the screen-space operators of Pintus et al.
2011 instead: visibility, anisotropic filling and shape depiction from depth alone.
`--pipeline` chooses.

Transparency and shadows (Dobrev et al. 2010, §4-6): `--layers N` peels the N nearest
surface layers (each through the filters above) and blends them front to back with each
point's opacity; `--shadows` computes a per-point shadow texture from point or area lights
(soft shadows by Monte Carlo sampling), which scene files can cache.

Clouds larger than memory: `build-lod` builds a kd-tree whose inner nodes hold samples taken
out of their children, every point stored once (Pintus et al. 2011, §7); `render` and `bench` then draw a cut of it chosen by
projected size under a point budget, streaming nodes from disk.";

#[derive(Parser)]
#[command(name = "stipple", version, about = ABOUT, long_about = LONG_ABOUT)]
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Option<Cmd>,
}

#[derive(Subcommand)]
pub enum Cmd {
    /// Render a cloud, a scene file (.toml/.json) or a demo scene to PNG, with optional depth
    /// (.npy), camera (.json) and per-layer images.
    Render(RenderArgs),
    /// Print point count, bounds, attributes and point spacing of cloud files.
    Info {
        /// Files to inspect (.ply, .ply.gz, .las, .laz, .copc.laz, .xyz, .txt, .csv, .obj, .stl,
        /// .stlod).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// For a .stlod tree: read every node and check its checksum.
        #[arg(long)]
        verify: bool,
    },
    /// Write a demo scene to a cloud file (sphere, torus, nested-tori, plane-objects).
    Gen(GenArgs),
    /// Time whole frames: ms per pass and projection throughput.
    Bench(cmd::bench::BenchArgs),
    /// List the GPU adapters wgpu finds, their backends and the features stipple uses.
    Devices,
    /// Build a multi-resolution tree (.stlod) from clouds of any size, for `render` and
    /// `bench` to draw under a point budget (Pintus et al. 2011, §7).
    BuildLod(cmd::build_lod::BuildLodArgs),
    /// Estimate normals (PCA over k neighbours, oriented towards the sensor where the file
    /// says where it was, else by a spanning tree) and splat radii, or re-orient given
    /// normals whose signs disagree, and write a PLY with nx ny nz radius.
    Normals(NormalsArgs),
    /// Render a mesh's vertices as a raw cloud and compare the depth with the mesh's own
    /// (Pintus Fig. 4): error image and the share of pixels off by more than 0.5%.
    Eval(cmd::eval::EvalArgs),
    /// Sample a mesh's faces to points by area (normals and colours interpolated from the
    /// vertices) and write a cloud file (Gunjee et al. §3).
    Convert(cmd::convert::ConvertArgs),
    /// Open a window onto a cloud, a scene file or a demo scene: orbit, pan, zoom and fly
    /// with the mouse and keys, drawn with everything `render` takes (same options).
    View(cmd::view::ViewArgs),
}

/// Mesa's device-select Vulkan layer (installed with every Mesa Vulkan driver, lavapipe
/// included) asks the Wayland compositor which GPU drives the display. Where there is no
/// session to ask (`XDG_RUNTIME_DIR` unset: ssh, containers, CI), libwayland prints
/// "error: XDG_RUNTIME_DIR is invalid or not set in the environment." twice before every GPU
/// run, though nothing failed. stipple ranks the adapters itself, so there the layer adds
/// nothing: it is switched off with its own switch, `NODEVICE_SELECT`, unless the user set
/// that or asked the layer for a device (`MESA_VK_DEVICE_SELECT`). Called before any thread
/// starts, as changing the environment requires.
fn quiet_device_select() {
    let unset = |v: &str| std::env::var_os(v).is_none_or(|s| s.is_empty());
    if unset("XDG_RUNTIME_DIR") && unset("NODEVICE_SELECT") && unset("MESA_VK_DEVICE_SELECT") {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
}

/// Runs the command line (`std::env::args`) and returns the exit code.
pub fn run() -> ExitCode {
    // Like other command-line tools, end quietly when the reader of our output goes away
    // (`stipple info x.laz | head -2`); Rust's default turns that into a panic.
    #[cfg(unix)]
    // SAFETY: restoring the default action of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    quiet_device_select();
    let cli = Cli::parse();
    let memory = match &cli.cmd {
        Some(Cmd::Render(a)) => a.source.memory,
        Some(Cmd::Bench(a)) => a.source.memory,
        Some(Cmd::Gen(a)) => a.memory,
        Some(Cmd::Convert(a)) => a.memory,
        Some(Cmd::View(a)) => a.render.source.memory,
        _ => None,
    };
    if let Some(m) = memory {
        memory::set_budget(m);
    }
    let result = match cli.cmd {
        None => cmd::render::render(RenderArgs::demo()),
        Some(Cmd::Render(a)) => cmd::render::render(a),
        Some(Cmd::Info { files, verify }) => cmd::info::info(&files, verify),
        Some(Cmd::BuildLod(a)) => cmd::build_lod::build_lod(a),
        Some(Cmd::Gen(a)) => cmd::gen::gen(a),
        Some(Cmd::Bench(a)) => cmd::bench::run(a),
        Some(Cmd::Devices) => cmd::devices::devices(),
        Some(Cmd::Eval(a)) => cmd::eval::run(a),
        Some(Cmd::Normals(a)) => cmd::normals::normals(a),
        Some(Cmd::Convert(a)) => cmd::convert::convert(a),
        Some(Cmd::View(a)) => cmd::view::view(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("stipple: error: {}", message(&e));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes, each cause once: library errors that already name their
/// source in their message (`path: cause`) are not repeated by the chain.
pub fn message(e: &anyhow::Error) -> String {
    let mut msg = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !msg.contains(&c) {
            msg = format!("{msg}: {c}");
        }
    }
    msg
}

/// Errors carry what the user gave (the file, the flag) and the cause; printed by `message`.
pub type Result<T> = anyhow::Result<T>;
