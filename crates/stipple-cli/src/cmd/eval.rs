//! `stipple eval`: surface reconstruction error of the raw pipeline against a mesh (Pintus
//! Fig. 4). The mesh's vertices, without normals, are rendered with the raw pipeline; the mesh
//! itself is rasterized for the reference depth; the error image shows |depth − mesh depth|
//! (white = 0.5% of the depth range or more, red = background inside the mesh's silhouette,
//! blue = covered outside it).

use crate::args::{BackendArgs, CameraArgs, RawArgs};
use crate::Result;
use anyhow::anyhow;
use std::path::PathBuf;
use stipple_render::eval::{compare, error_image, mesh_depth, DepthError};
use stipple_render::{PreparedCloud, ViewParams};

#[derive(clap::Args)]
pub struct EvalArgs {
    /// A mesh with faces (.ply, .ply.gz).
    pub mesh: PathBuf,
    /// Error image (PNG). Default: `<mesh name>`-error.png.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Also write the raw rendering (PNG).
    #[arg(long, value_name = "FILE.png")]
    pub render_out: Option<PathBuf>,
    #[command(flatten)]
    pub camera: CameraArgs,
    #[command(flatten)]
    pub raw: RawArgs,
    #[command(flatten)]
    pub backend: BackendArgs,
}

fn line(name: &str, e: &DepthError) {
    println!(
        "  {name:<28} {:>8} px   {:>6.2}% above 0.5%   {:>5.2}% behind   {:>4} holes   {:>5.2}% leaks",
        e.inside,
        100.0 * e.above_share(),
        100.0 * e.behind_share(),
        e.holes,
        100.0 * e.leak_share()
    );
}

pub fn run(a: EvalArgs) -> Result<()> {
    let mesh = crate::args::read_with_progress(&a.mesh)?;
    if mesh.faces.is_empty() {
        return Err(anyhow!(
            "{}: has no faces; `stipple eval` needs a mesh to compare with",
            a.mesh.display()
        ));
    }
    let stem = crate::cmd::render::stem(&a.mesh);
    let output = a
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{stem}-error.png")));
    for o in [Some(&output), a.render_out.as_ref()].into_iter().flatten() {
        if stipple_io::extension(o) != "png" {
            return Err(anyhow!("{}: must be a .png file", o.display()));
        }
        crate::output::check_output(o, &[a.mesh.as_path()])?;
    }
    let camera = a.camera.build(&mesh)?;
    let v = ViewParams::new(&camera, mesh.origin);
    let truth = mesh_depth(&v, &mesh.positions, &mesh.faces);
    let mut points = mesh.clone();
    points.faces.clear();
    points.normals = None;
    let cloud = PreparedCloud::new(points);
    let mut r = a.backend.open()?;
    let pipe = a.raw.build([0, 0, 0])?;
    let frame = r.render(&cloud, &camera, &pipe)?;
    let all = compare(&frame.depth, &truth, camera.width as usize, 0);
    let interior = compare(&frame.depth, &truth, camera.width as usize, 2);
    let img = error_image(&frame.depth, &truth, all.tolerance);
    stipple_io::image::write_png(&output, camera.width, camera.height, &img)?;
    if let Some(p) = &a.render_out {
        stipple_io::image::write_png(p, frame.width, frame.height, &frame.rgba)?;
    }
    println!(
        "stipple eval: {} ({} vertices, {} faces), {}x{}, {:.1} px point spacing, {}",
        a.mesh.display(),
        mesh.len(),
        mesh.faces.len(),
        camera.width,
        camera.height,
        cloud.screen_spacing(&camera),
        r.describe()
    );
    println!(
        "  depth range {:.6}, tolerance 0.5% = {:.6}, behind = more than 2% = {:.6}",
        all.range, all.tolerance, all.behind_margin
    );
    line("all covered pixels", &all);
    line("away from contours (2 px)", &interior);
    println!("wrote {}", output.display());
    if let Some(p) = &a.render_out {
        println!("wrote {}", p.display());
    }
    Ok(())
}
