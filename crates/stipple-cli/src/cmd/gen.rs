//! `stipple gen`: write a demo scene to a cloud file.

use crate::output::*;
use crate::Result;
use crate::{args::parse_scene, memory};
use anyhow::anyhow;
use std::path::PathBuf;
use stipple_core::demo::{self, DemoScene};

#[derive(clap::Args)]
pub struct GenArgs {
    /// Scene: sphere, torus, nested-tori (Dobrev Fig. 17), plane-objects.
    #[arg(value_parser = parse_scene)]
    pub scene: DemoScene,
    /// Output cloud file (.ply, .las, .laz, .xyz).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Number of points (default: 1 000 000; 1 500 000 for nested-tori).
    #[arg(long)]
    pub points: Option<usize>,
    /// Random seed: the same seed gives the same cloud.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Overwrite the output file if it exists.
    #[arg(long)]
    pub force: bool,
    /// Memory budget (e.g. 16G): a scene needing more is refused before any work. Default:
    /// the memory available (free memory, within `ulimit -v`).
    #[arg(long, value_parser = stipple_lod::mem::parse_size, value_name = "SIZE")]
    pub memory: Option<u64>,
}

pub fn gen(a: GenArgs) -> Result<()> {
    if a.output.exists() && !a.force {
        return Err(anyhow!(
            "{}: already exists; pass --force to overwrite it",
            a.output.display()
        ));
    }
    check_output(&a.output, &[])?;
    let n = a.points.unwrap_or(a.scene.default_points());
    if n == 0 {
        return Err(anyhow!("--points must be at least 1"));
    }
    memory::check_points(
        &format!("--points {n}"),
        n as u64,
        memory::GEN_BYTES_PER_POINT,
    )?;
    let c = demo::generate(a.scene, n, a.seed);
    stipple_io::write_cloud(&a.output, &c)?;
    println!(
        "wrote {} ({} points of {})",
        a.output.display(),
        c.len(),
        a.scene.name()
    );
    Ok(())
}
