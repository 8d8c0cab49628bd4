//! `stipple`: render point clouds from the command line.

mod args;
mod bench;
mod eval;
mod figures;
mod lod;
mod look;
mod memory;
mod scene;
mod shadow_cache;

use args::{BackendArgs, CameraArgs, LookArgs, PipelineArgs, SourceArgs};
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;
use stipple_core::demo::{self, DemoScene};
use stipple_render::PreparedCloud;

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

Clouds larger than memory: `build-lod` builds a kd-tree whose inner nodes hold filtered
samples (Pintus et al. 2011, §7); `render` and `bench` then draw a cut of it chosen by
projected size under a point budget, streaming nodes from disk.";

#[derive(Parser)]
#[command(name = "stipple", version, about = ABOUT, long_about = LONG_ABOUT)]
struct Cli {
    #[command(subcommand)]
    cmd: Option<Cmd>,
}

#[derive(Subcommand)]
enum Cmd {
    /// Render a cloud, a scene file (.toml/.json) or a demo scene to PNG, with optional depth
    /// (.npy), camera (.json) and per-layer images.
    Render(RenderArgs),
    /// Print point count, bounds, attributes and point spacing of cloud files.
    Info {
        /// Files to inspect (.ply, .ply.gz, .las, .laz, .copc.laz, .xyz, .txt, .csv, .stlod).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// For a .stlod tree: read every node and check its checksum.
        #[arg(long)]
        verify: bool,
    },
    /// Write a demo scene to a cloud file (sphere, torus, nested-tori, plane-objects).
    Gen(GenArgs),
    /// Time whole frames: ms per pass and projection throughput.
    Bench(bench::BenchArgs),
    /// List the GPU adapters wgpu finds, their backends and the features stipple uses.
    Devices,
    /// Build a multi-resolution tree (.stlod) from clouds of any size, for `render` and
    /// `bench` to draw under a point budget (Pintus et al. 2011, §7).
    BuildLod(lod::BuildLodArgs),
    /// Estimate normals (PCA over k neighbours, oriented by a spanning tree) and splat radii,
    /// or re-orient given normals whose signs disagree, and write a PLY with nx ny nz radius.
    Normals(NormalsArgs),
    /// Render a mesh's vertices as a raw cloud and compare the depth with the mesh's own
    /// (Pintus Fig. 4): error image and the share of pixels off by more than 0.5%.
    Eval(eval::EvalArgs),
}

#[derive(clap::Args)]
struct RenderArgs {
    #[command(flatten)]
    source: SourceArgs,
    /// Output image (PNG). Default: <input name>.png in the current directory, or
    /// stipple-demo.png for a demo scene.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Also write the per-pixel view-axis depth as float32 NumPy (H, W), background = +inf.
    #[arg(long, value_name = "FILE.npy")]
    depth_out: Option<PathBuf>,
    /// Also write the camera (eye, target, up, fov, size, near, far, matrices) as JSON.
    #[arg(long, value_name = "FILE.json")]
    camera_out: Option<PathBuf>,
    /// Also write world-space unit normals of the visible surface as float32 NumPy
    /// (H, W, 3), facing the eye, NaN on background, row 0 at the top.
    #[arg(long, value_name = "FILE.npy")]
    normal_out: Option<PathBuf>,
    /// Save the cloud with the normals and splat radii this render estimated (or
    /// re-oriented) as a new PLY (nx ny nz radius and the file's other attributes), so that
    /// the next render of it skips the estimation. Never written into the input; an existing
    /// file is not replaced.
    #[arg(long, value_name = "FILE.ply")]
    save_normals: Option<PathBuf>,
    #[command(flatten)]
    camera: CameraArgs,
    #[command(flatten)]
    pipeline: PipelineArgs,
    #[command(flatten)]
    backend: BackendArgs,
    #[command(flatten)]
    look: LookArgs,
    /// With --layers: also write each peeled layer's own image, PREFIX-1.png (nearest),
    /// PREFIX-2.png, ...
    #[arg(long, value_name = "PREFIX")]
    layer_images: Option<PathBuf>,
    #[command(flatten)]
    lod: lod::LodArgs,
    /// Print the time each pass took.
    #[arg(long)]
    stats: bool,
}

#[derive(clap::Args)]
struct NormalsArgs {
    /// The cloud (.ply, .ply.gz, .las, .laz, .xyz, ...). It is only read.
    input: PathBuf,
    /// The PLY to write (positions, colours and the other attributes of the input, plus
    /// nx ny nz and radius).
    #[arg(short, long, value_name = "OUT.ply")]
    output: PathBuf,
    /// Neighbours per point.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(3..=64))]
    k: u32,
    /// Estimate new normals even where the file has some (by default given normals are kept
    /// and only turned round where their signs are inconsistent).
    #[arg(long)]
    reestimate: bool,
    /// Where the sensor stood (x,y,z in the file's coordinates), for a single scan: normals
    /// face it instead of taking the orientation propagated over the neighbour graph.
    #[arg(long, value_parser = args::parse_vec3, allow_hyphen_values = true, value_name = "X,Y,Z")]
    viewpoint: Option<glam::DVec3>,
    /// Overwrite OUT.ply if it exists (never the input).
    #[arg(long)]
    force: bool,
}

#[derive(clap::Args)]
struct GenArgs {
    /// Scene: sphere, torus, nested-tori (Dobrev Fig. 17), plane-objects.
    #[arg(value_parser = parse_scene)]
    scene: DemoScene,
    /// Output cloud file (.ply, .las, .laz, .xyz).
    #[arg(short, long)]
    output: PathBuf,
    /// Number of points (default: 1 000 000; 1 500 000 for nested-tori).
    #[arg(long)]
    points: Option<usize>,
    /// Random seed: the same seed gives the same cloud.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Overwrite the output file if it exists.
    #[arg(long)]
    force: bool,
    /// Memory budget (e.g. 16G): a scene needing more is refused before any work. Default:
    /// the memory available (free memory, within `ulimit -v`).
    #[arg(long, value_parser = stipple_lod::mem::parse_size, value_name = "SIZE")]
    memory: Option<u64>,
}

pub fn parse_scene(s: &str) -> Result<DemoScene> {
    DemoScene::from_name(s).ok_or_else(|| {
        let names: Vec<_> = DemoScene::ALL.iter().map(|d| d.name()).collect();
        format!("unknown scene `{s}` (one of: {})", names.join(", "))
    })
}

fn main() -> ExitCode {
    // Like other command-line tools, end quietly when the reader of our output goes away
    // (`stipple info x.laz | head -2`); Rust's default turns that into a panic.
    #[cfg(unix)]
    // SAFETY: restoring the default action of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    let memory = match &cli.cmd {
        Some(Cmd::Render(a)) => a.source.memory,
        Some(Cmd::Bench(a)) => a.source.memory,
        Some(Cmd::Gen(a)) => a.memory,
        _ => None,
    };
    if let Some(m) = memory {
        memory::set_budget(m);
    }
    let result = match cli.cmd {
        None => render(RenderArgs::demo()),
        Some(Cmd::Render(a)) => render(a),
        Some(Cmd::Info { files, verify }) => info(&files, verify),
        Some(Cmd::BuildLod(a)) => lod::build_lod(a),
        Some(Cmd::Gen(a)) => gen(a),
        Some(Cmd::Bench(a)) => bench::run(a),
        Some(Cmd::Devices) => devices(),
        Some(Cmd::Eval(a)) => eval::run(a),
        Some(Cmd::Normals(a)) => normals(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("stipple: error: {e}");
            ExitCode::FAILURE
        }
    }
}

type Result<T> = std::result::Result<T, String>;

impl RenderArgs {
    fn demo() -> RenderArgs {
        RenderArgs::parse_from_args(&["render"])
    }

    fn parse_from_args(a: &[&str]) -> RenderArgs {
        #[derive(Parser)]
        struct Wrap {
            #[command(subcommand)]
            cmd: Cmd,
        }
        let mut v = vec!["stipple"];
        v.extend_from_slice(a);
        match Wrap::parse_from(v).cmd {
            Cmd::Render(r) => r,
            _ => unreachable!(),
        }
    }
}

/// Refuses to write over any input.
/// Refuses an output that is one of the inputs: the same path after resolving symbolic
/// links, or (Unix) the same file under another name (a hard link: same device and inode).
fn check_output(out: &Path, inputs: &[&Path]) -> Result<()> {
    not_special(out)?;
    let canon = |p: &Path| std::fs::canonicalize(p).ok();
    let same_file = |a: &Path, b: &Path| -> bool {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
                return x.dev() == y.dev() && x.ino() == y.ino();
            }
        }
        match (canon(a), canon(b)) {
            (Some(x), Some(y)) => x == y,
            _ => false,
        }
    };
    for i in inputs {
        if same_file(out, i) {
            return Err(format!(
                "{}: refusing to overwrite an input file ({})",
                out.display(),
                i.display()
            ));
        }
    }
    Ok(())
}

/// Refuses an output path that exists and is not a regular file (a device such as
/// /dev/full, a directory, a pipe): outputs are written beside it and renamed over it, which
/// would replace the device itself.
fn not_special(out: &Path) -> Result<()> {
    let dir = out.parent().filter(|d| !d.as_os_str().is_empty());
    let dir = std::fs::canonicalize(dir.unwrap_or(Path::new("."))).ok();
    if let Some(d) = dir {
        for sys in ["/dev", "/proc", "/sys"] {
            if d.starts_with(sys) {
                return Err(format!(
                    "{}: {sys} holds devices and kernel files, not user files; write the \
                     output somewhere else",
                    out.display()
                ));
            }
        }
    }
    match std::fs::metadata(out) {
        Ok(m) if !m.is_file() => Err(format!(
            "{}: exists and is not a regular file (a device, directory or pipe); outputs are \
             written as regular files only",
            out.display()
        )),
        _ => Ok(()),
    }
}

/// Refuses two outputs of one command at the same place (they would overwrite each other):
/// compared by their absolute path with `.` and `..` resolved in the directory part.
fn distinct_outputs(outs: &[&Path]) -> Result<()> {
    let key = |p: &Path| -> PathBuf {
        let dir = p.parent().filter(|d| !d.as_os_str().is_empty());
        let dir = dir
            .map(|d| std::fs::canonicalize(d).unwrap_or_else(|_| d.to_path_buf()))
            .unwrap_or_else(|| std::env::current_dir().unwrap_or_default());
        dir.join(p.file_name().unwrap_or_default())
    };
    for (k, a) in outs.iter().enumerate() {
        for b in &outs[k + 1..] {
            if key(a) == key(b) {
                return Err(format!(
                    "{}: given for two outputs of this command; each output needs its own file",
                    a.display()
                ));
            }
        }
    }
    Ok(())
}

/// The process id of another running stipple process writing `path` (its temporary file
/// `.NAME.PID.stipple-tmp` is beside it and that process is alive), if any.
fn other_writer(path: &Path) -> Option<u32> {
    let name = path.file_name()?.to_string_lossy().into_owned();
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
    let prefix = format!(".{name}.");
    std::fs::read_dir(dir.unwrap_or(Path::new(".")))
        .ok()?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            let pid = n.strip_prefix(&prefix)?.strip_suffix(".stipple-tmp")?;
            pid.parse::<u32>().ok()
        })
        .find(|&pid| pid != std::process::id() && Path::new(&format!("/proc/{pid}")).exists())
}

/// Outputs of one command, written to temporary files beside their places and renamed into
/// place together by [`Staged::commit`]; dropped uncommitted (an error on the way), the
/// temporary files are removed and no output appears or changes.
#[derive(Default)]
struct Staged {
    files: Vec<(PathBuf, PathBuf)>,
}

impl Staged {
    fn write(
        &mut self,
        path: &Path,
        f: impl FnOnce(&Path) -> std::result::Result<(), stipple_io::IoError>,
    ) -> Result<()> {
        let name = path
            .file_name()
            .ok_or_else(|| format!("{}: the output path has no file name", path.display()))?;
        let mut tmp = std::ffi::OsString::from(".");
        tmp.push(name);
        tmp.push(format!(".{}.stipple-tmp", std::process::id()));
        let tmp = path.with_file_name(tmp);
        not_special(path)?;
        // Our temporary file first, then a look for another live process's: of two
        // processes writing one output at once, at least the later one stops here.
        std::fs::File::create(&tmp).map_err(|e| format!("{}: {e}", path.display()))?;
        self.files.push((tmp.clone(), path.to_path_buf()));
        if let Some(pid) = other_writer(path) {
            return Err(format!(
                "{}: another stipple process (pid {pid}) is writing it right now; wait for it \
                 to finish or choose another output",
                path.display()
            ));
        }
        f(&tmp).map_err(|e| match e {
            stipple_io::IoError::Io { source, .. } => format!("{}: {source}", path.display()),
            other => other
                .to_string()
                .replace(&*tmp.to_string_lossy(), &path.to_string_lossy()),
        })
    }

    fn commit(mut self) -> Result<()> {
        let files = std::mem::take(&mut self.files);
        for (k, (tmp, path)) in files.iter().enumerate() {
            if let Err(e) = std::fs::rename(tmp, path) {
                for (t, _) in &files[k..] {
                    let _ = std::fs::remove_file(t);
                }
                return Err(format!("{}: {e}", path.display()));
            }
        }
        Ok(())
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        for (tmp, _) in &self.files {
            let _ = std::fs::remove_file(tmp);
        }
    }
}

fn render(a: RenderArgs) -> Result<()> {
    if let Some((w, h)) = a.camera.size {
        // Before reading anything: an image too large for memory fails at once.
        memory::check_frame(w, h, a.look.layers.unwrap_or(1))?;
    }
    let tree = a.source.input.as_deref().filter(|p| lod::is_tree(p));
    let scene_file = a.source.input.as_deref().filter(|p| scene::is_scene(p));
    let (mut cloud, label, camera, scene) = match (tree, scene_file) {
        (Some(p), _) => {
            let (cloud, label, camera) = lod::load_cut(p, &a.camera, &a.lod)?;
            (cloud, label, camera, None)
        }
        (None, Some(p)) => {
            let (cloud, s, camera) = look::load_scene(p, &a.camera)?;
            (cloud, s.label.clone(), camera, Some(s))
        }
        (None, None) => {
            let (cloud, label) = a.source.load()?;
            let camera = a.camera.build(&cloud.cloud)?;
            (cloud, label, camera, None)
        }
    };
    memory::check_frame(
        camera.width,
        camera.height,
        look::layers(&a.look, scene.as_ref()),
    )?;
    let output = match &a.output {
        Some(o) => o.clone(),
        None => match &a.source.input {
            Some(i) => PathBuf::from(format!("{}.png", stem(i))),
            None => PathBuf::from("stipple-demo.png"),
        },
    };
    if stipple_io::extension(&output) != "png" {
        return Err(format!(
            "{}: the image output must be a .png file",
            output.display()
        ));
    }
    if let Some(d) = &a.depth_out {
        if stipple_io::extension(d) != "npy" {
            return Err(format!(
                "{}: --depth-out must name a .npy file",
                d.display()
            ));
        }
    }
    let mut inputs: Vec<&Path> = a.source.input.iter().map(PathBuf::as_path).collect();
    if let Some(s) = &scene {
        inputs.extend(s.files.iter().map(PathBuf::as_path));
    }
    for o in [Some(&output), a.depth_out.as_ref(), a.camera_out.as_ref()]
        .into_iter()
        .flatten()
    {
        check_output(o, &inputs)?;
    }
    let layer_outs: Vec<PathBuf> = match &a.layer_images {
        Some(prefix) => (1..=stipple_render::pipeline::MAX_LAYERS as usize)
            .map(|k| PathBuf::from(format!("{}-{k}.png", prefix.display())))
            .collect(),
        None => vec![],
    };
    let all_outs: Vec<&Path> = [
        Some(&output),
        a.depth_out.as_ref(),
        a.camera_out.as_ref(),
        a.normal_out.as_ref(),
        a.save_normals.as_ref(),
    ]
    .into_iter()
    .flatten()
    .map(PathBuf::as_path)
    .chain(layer_outs.iter().map(PathBuf::as_path))
    .collect();
    distinct_outputs(&all_outs)?;
    let layer_paths = |n: usize| -> Vec<PathBuf> {
        let prefix = a.layer_images.as_ref().expect("asked for");
        (1..=n)
            .map(|k| PathBuf::from(format!("{}-{k}.png", prefix.display())))
            .collect()
    };
    if a.layer_images.is_some() {
        for o in layer_paths(stipple_render::pipeline::MAX_LAYERS as usize) {
            check_output(&o, &inputs)?;
        }
    }
    if let Some(d) = &a.normal_out {
        if stipple_io::extension(d) != "npy" {
            return Err(format!(
                "{}: --normal-out must name a .npy file",
                d.display()
            ));
        }
        check_output(d, &inputs)?;
    }
    if let Some(d) = &a.save_normals {
        if stipple_io::extension(d) != "ply" {
            return Err(format!(
                "{}: --save-normals must name a .ply file",
                d.display()
            ));
        }
        if tree.is_some() || scene.is_some() || a.source.input.is_none() {
            return Err(
                "--save-normals saves a single cloud file's normals (not a scene, tree or demo)"
                    .into(),
            );
        }
        check_output(d, &inputs)?;
        if d.exists() {
            return Err(format!(
                "{}: already exists; remove it or choose another name",
                d.display()
            ));
        }
    }
    let peeled = crate::look::layers(&a.look, scene.as_ref()) > 1;
    let (mut pipe, notes) = a
        .pipeline
        .choose(&mut cloud, &camera, tree.is_some(), peeled)?;
    for n in &notes {
        eprintln!("stipple: {n}");
    }
    let mut renderer = a.backend.open()?;
    let shadow_line = look::apply(
        &mut cloud,
        &mut pipe,
        scene.as_ref(),
        &a.look,
        a.pipeline.background.is_some(),
        &mut renderer,
    )?;
    if a.layer_images.is_some() {
        if pipe.layers == 1 {
            return Err("--layer-images needs --layers N (N > 1)".into());
        }
        pipe.keep_layers = true;
    }
    let t0 = Instant::now();
    let frame = renderer
        .render(&cloud, &camera, &pipe)
        .map_err(|e| e.to_string())?;
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    if let (Some(d), None) = (&a.save_normals, &cloud.cloud.normals) {
        return Err(format!(
            "{}: not written: this render estimated no normals (--no-estimate-normals, \
             --no-lighting or --raw)",
            d.display()
        ));
    }
    // All or nothing: every output goes to a temporary file beside it first, and only when
    // all of them are written are they renamed into place.
    let mut staged = Staged::default();
    staged.write(&output, |t| {
        stipple_io::image::write_png(t, frame.width, frame.height, &frame.rgba)
    })?;
    if let Some(d) = &a.depth_out {
        staged.write(d, |t| {
            stipple_io::image::write_npy(t, frame.width, frame.height, &frame.depth)
        })?;
    }
    if let Some(c) = &a.camera_out {
        staged.write(c, |t| {
            std::fs::write(t, camera.to_json()).map_err(|e| stipple_io::IoError::io(t, e))
        })?;
    }
    if let Some(d) = &a.save_normals {
        staged.write(d, |t| {
            stipple_io::ply::write_ply(
                t,
                &cloud.cloud,
                stipple_io::ply::Encoding::BinaryLittleEndian,
            )
        })?;
    }
    if let Some(d) = &a.normal_out {
        let normals = frame.normal_image(&cloud, &camera);
        staged.write(d, |t| {
            stipple_io::image::write_npy3(t, frame.width, frame.height, &normals)
        })?;
    }
    let layer_files = if a.layer_images.is_some() {
        layer_paths(frame.layers.len())
    } else {
        vec![]
    };
    for (p, img) in layer_files.iter().zip(&frame.layers) {
        staged.write(p, |t| {
            stipple_io::image::write_png(t, frame.width, frame.height, img)
        })?;
    }
    staged.commit()?;
    if let Some(line) = &shadow_line {
        println!("{line}");
    }
    if pipe.layers > 1 {
        println!(
            "peeled {} of at most {} layers (each through the image-space filters), blended              front to back",
            frame.layers_peeled, pipe.layers
        );
    }
    if a.stats {
        for s in &frame.stats {
            eprintln!(
                "  {:<16} {:>9.2} ms  ({} it, {})",
                s.name(),
                s.ms,
                s.iterations,
                s.count
            );
        }
    }
    hint_if_sparse(&frame);
    if frame
        .stats
        .iter()
        .any(|s| s.pass == stipple_render::PassId::Visibility)
    {
        let px = cloud.screen_spacing(&camera);
        if px > 2.5 && stipple_render::pipeline::auto_kernel(px) == 15 {
            eprintln!(
                "stipple: hint: the points are {px:.1} px apart at this size; the raw pipeline's \
                 largest visibility kernel closes gaps up to about 2.5 px, so surfaces may show \
                 holes or what lies behind them: try a smaller --size"
            );
        }
    }
    println!(
        "wrote {} ({}x{}, {} from {} points, {:.0} ms on {})",
        output.display(),
        frame.width,
        frame.height,
        label,
        cloud.cloud.len(),
        ms,
        renderer.describe()
    );
    if let Some(d) = &a.depth_out {
        println!("wrote {}", d.display());
    }
    if let Some(c) = &a.camera_out {
        println!("wrote {}", c.display());
    }
    if let Some(d) = &a.normal_out {
        println!("wrote {}", d.display());
    }
    if let Some(d) = &a.save_normals {
        println!(
            "wrote {} (nx ny nz radius): render it next time to skip normal estimation",
            d.display()
        );
    }
    for p in &layer_files {
        println!("wrote {}", p.display());
    }
    Ok(())
}

fn devices() -> Result<()> {
    let list = stipple_render::gpu::list_adapters();
    if list.is_empty() {
        println!(
            "no GPU adapters found (on Linux without a GPU, install mesa-vulkan-drivers for the \
             lavapipe software adapter); rendering uses the CPU"
        );
        return Ok(());
    }
    for (i, a) in list.iter().enumerate() {
        println!("{i}: {} ({:?}, {:?})", a.name, a.backend, a.device_type);
        if !a.driver.is_empty() {
            println!("   driver: {}", a.driver);
        }
        println!(
            "   64-bit atomics: {}   timestamps: {}   max storage binding: {} MiB   max buffer: {} MiB",
            if a.int64_atomics { "yes (one-pass projection)" } else { "no (32-bit two-pass projection)" },
            if a.timestamps { "yes" } else { "no" },
            a.max_storage_binding >> 20,
            a.max_buffer >> 20
        );
        match &a.suitable {
            Ok(()) => println!("   usable by stipple: yes"),
            Err(why) => println!("   usable by stipple: no ({why})"),
        }
        if let Err(why) = &a.hardware_projection {
            println!(
                "   --projection hardware: unavailable ({why}); the default compute path runs"
            );
        }
    }
    match stipple_render::gpu::GpuContext::new(Default::default()) {
        Ok(c) => println!("--backend auto/gpu uses: {}", c.describe()),
        Err(e) => println!("--backend auto uses the CPU: {e}"),
    }
    Ok(())
}

/// One fill iteration closes holes one pixel wide; when it still had a lot to do, the cloud is
/// sparse at this image size and more iterations would close the rest.
fn hint_if_sparse(frame: &stipple_render::Frame) {
    let covered = frame
        .id
        .iter()
        .filter(|&&i| i != stipple_render::BACKGROUND)
        .count() as u64;
    if let Some(s) = frame
        .stats
        .iter()
        .find(|s| s.pass == stipple_render::PassId::FillBackground)
    {
        if s.iterations == 1 && s.count * 5 > covered {
            eprintln!(
                "stipple: hint: the points are sparse at this size ({}% of the image was hole-filled); \
                 try --fill-radius 2 (gaps up to 4 px), --fill-background-iterations 2, or a smaller --size",
                s.count * 100 / covered.max(1)
            );
        }
    }
}

fn stem(p: &Path) -> String {
    let name = p
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    let name = name.strip_suffix(".copc.laz").unwrap_or(name);
    match name.rsplit_once('.') {
        Some((s, _)) if !s.is_empty() => s.to_owned(),
        _ => name.to_owned(),
    }
}

fn info(files: &[PathBuf], verify: bool) -> Result<()> {
    let mut failed = 0;
    for f in files {
        if lod::is_tree(f) {
            if let Err(e) = lod::info(f, verify) {
                eprintln!("stipple: error: {e}");
                failed += 1;
            }
            continue;
        }
        match args::read_with_progress(f) {
            Ok(c) => {
                let p = PreparedCloud::new(c);
                let c = &p.cloud;
                let (lo, hi) = c.world_bounds();
                println!("{}", f.display());
                println!("  points      {}", c.len());
                println!("  bounds min  {:.4} {:.4} {:.4}", lo.x, lo.y, lo.z);
                println!("  bounds max  {:.4} {:.4} {:.4}", hi.x, hi.y, hi.z);
                let e = hi - lo;
                println!("  extent      {:.4} {:.4} {:.4}", e.x, e.y, e.z);
                println!("  attributes  {}", c.attributes().join(", "));
                if !c.faces.is_empty() {
                    println!("  faces       {} triangles", c.faces.len());
                }
                println!(
                    "  spacing     {:.6} (median nearest-neighbour distance)",
                    p.spacing
                );
                println!(
                    "  layer gap   {:.6} (default d̃ = 2.5 × spacing)",
                    stipple_render::pipeline::default_layer_gap(p.spacing)
                );
            }
            Err(e) => {
                eprintln!("stipple: error: {e}");
                failed += 1;
            }
        }
    }
    if failed > 0 {
        Err(format!(
            "{failed} of {} files could not be read",
            files.len()
        ))
    } else {
        Ok(())
    }
}

fn normals(a: NormalsArgs) -> Result<()> {
    if !matches!(stipple_io::extension(&a.output).as_str(), "ply") {
        return Err(format!(
            "{}: the output must be a .ply file (it carries nx ny nz radius)",
            a.output.display()
        ));
    }
    check_output(&a.output, &[&a.input])?;
    if a.output.exists() && !a.force {
        return Err(format!(
            "{}: already exists; pass --force to overwrite it",
            a.output.display()
        ));
    }
    let mut c = args::read_with_progress(&a.input)?;
    if a.reestimate {
        c.normals = None;
    }
    let had = c.normals.is_some();
    c.radius = None;
    let n = c.len();
    let mut p = PreparedCloud::with_spacing(c, 0.0);
    let t0 = Instant::now();
    let r = p
        .prepare_surface_from(a.k as usize, true, a.viewpoint)
        .map_err(|e| format!("{}: {e}", a.input.display()))?;
    let s = t0.elapsed().as_secs_f64();
    if had {
        println!(
            "kept the file's normals; {} of {n} turned round ({:.1}% of neighbouring normals \
             disagreed before)",
            r.reoriented,
            100.0 * r.inconsistency
        );
    } else {
        println!(
            "estimated normals for {n} points (k = {}) in {s:.2} s ({:.2} M points/s)",
            a.k,
            n as f64 / s.max(1e-9) / 1e6
        );
    }
    stipple_io::write_atomically(&a.output, |tmp| {
        stipple_io::ply::write_ply(tmp, &p.cloud, stipple_io::ply::Encoding::BinaryLittleEndian)
    })
    .map_err(|e| e.to_string())?;
    println!("wrote {} (nx ny nz radius)", a.output.display());
    Ok(())
}

fn gen(a: GenArgs) -> Result<()> {
    if a.output.exists() && !a.force {
        return Err(format!(
            "{}: already exists; pass --force to overwrite it",
            a.output.display()
        ));
    }
    check_output(&a.output, &[])?;
    let n = a.points.unwrap_or(a.scene.default_points());
    if n == 0 {
        return Err("--points must be at least 1".into());
    }
    memory::check_points(
        &format!("--points {n}"),
        n as u64,
        memory::GEN_BYTES_PER_POINT,
    )?;
    let c = demo::generate(a.scene, n, a.seed);
    stipple_io::write_cloud(&a.output, &c).map_err(|e| e.to_string())?;
    println!(
        "wrote {} ({} points of {})",
        a.output.display(),
        c.len(),
        a.scene.name()
    );
    Ok(())
}
