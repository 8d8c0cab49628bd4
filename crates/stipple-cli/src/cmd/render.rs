//! `stipple render`: a cloud, a tree, a scene file or a demo scene to PNG (and depth, normals, camera, layers).

use crate::args::{BackendArgs, CameraArgs, LookArgs, PipelineArgs, SourceArgs};
use crate::output::*;
use crate::Result;
use crate::{lod, look, memory, Cmd};
use anyhow::anyhow;
use clap::Parser;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub source: SourceArgs,
    /// Output image (PNG). Default: <input name>.png in the current directory, or
    /// stipple-demo.png for a demo scene.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Also write the per-pixel view-axis depth as float32 NumPy (H, W), background = +inf.
    #[arg(long, value_name = "FILE.npy")]
    pub depth_out: Option<PathBuf>,
    /// Also write the camera (eye, target, up, fov, size, near, far, matrices) as JSON.
    #[arg(long, value_name = "FILE.json")]
    pub camera_out: Option<PathBuf>,
    /// Also write world-space unit normals of the visible surface as float32 NumPy
    /// (H, W, 3), facing the eye, NaN on background, row 0 at the top.
    #[arg(long, value_name = "FILE.npy")]
    pub normal_out: Option<PathBuf>,
    /// Save the cloud with the normals and splat radii this render estimated (or
    /// re-oriented) as a new PLY (nx ny nz radius and the file's other attributes), so that
    /// the next render of it skips the estimation. Never written into the input; an existing
    /// file is not replaced.
    #[arg(long, value_name = "FILE.ply")]
    pub save_normals: Option<PathBuf>,
    #[command(flatten)]
    pub camera: CameraArgs,
    #[command(flatten)]
    pub pipeline: PipelineArgs,
    #[command(flatten)]
    pub backend: BackendArgs,
    #[command(flatten)]
    pub look: LookArgs,
    #[command(flatten)]
    pub colour: crate::args::ColourArgs,
    /// With --layers: also write each peeled layer's own image, PREFIX-1.png (nearest),
    /// PREFIX-2.png, ...
    #[arg(long, value_name = "PREFIX")]
    pub layer_images: Option<PathBuf>,
    #[command(flatten)]
    pub lod: lod::LodArgs,
    /// Print the time each pass took.
    #[arg(long)]
    pub stats: bool,
}

impl RenderArgs {
    pub fn demo() -> RenderArgs {
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

pub fn render(a: RenderArgs) -> Result<()> {
    if let Some((w, h)) = a.camera.size {
        // Before reading anything: an image too large for memory fails at once.
        memory::check_frame(w, h, a.look.layers.unwrap_or(1))?;
    }
    let crate::api::Loaded {
        mut cloud,
        label,
        camera,
        scene,
        tree,
    } = crate::api::load(&a)?;
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
        return Err(anyhow!(
            "{}: the image output must be a .png file",
            output.display()
        ));
    }
    if let Some(d) = &a.depth_out {
        if stipple_io::extension(d) != "npy" {
            return Err(anyhow!(
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
            return Err(anyhow!(
                "{}: --normal-out must name a .npy file",
                d.display()
            ));
        }
        check_output(d, &inputs)?;
    }
    if let Some(d) = &a.save_normals {
        if stipple_io::extension(d) != "ply" {
            return Err(anyhow!(
                "{}: --save-normals must name a .ply file",
                d.display()
            ));
        }
        if tree || scene.is_some() || a.source.input.is_none() {
            return Err(anyhow!(
                "--save-normals saves a single cloud file's normals (not a scene, tree or demo)"
            ));
        }
        check_output(d, &inputs)?;
        if d.exists() {
            return Err(anyhow!(
                "{}: already exists; remove it or choose another name",
                d.display()
            ));
        }
    }
    let mut renderer = a.backend.open()?;
    let crate::api::Rendered {
        frame,
        pipeline: pipe,
        shadow_line,
        ms,
    } = crate::api::render_prepared(
        &a,
        &mut cloud,
        &crate::api::View {
            camera: &camera,
            scene: scene.as_ref(),
            tree,
            label: &label,
        },
        &mut renderer,
        &mut |n| eprintln!("stipple: {n}"),
    )?;
    if let (Some(d), None) = (&a.save_normals, &cloud.cloud.normals) {
        return Err(anyhow!(
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
            "peeled {} of at most {} layers (each through the image-space filters), blended front to back",
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

/// One fill iteration closes holes one pixel wide; when it still had a lot to do, the cloud is
/// sparse at this image size and more iterations would close the rest.
pub fn hint_if_sparse(frame: &stipple_render::Frame) {
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

pub fn stem(p: &Path) -> String {
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
