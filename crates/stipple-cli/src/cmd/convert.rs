//! `stipple convert`: a mesh's faces sampled to points (Gunjee et al. §3), written as a
//! cloud file.

use crate::args;
use crate::output::*;
use crate::Result;
use anyhow::anyhow;
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args)]
pub struct ConvertArgs {
    /// The mesh (.obj, .stl, or a PLY with faces: .ply, .ply.gz). It is only read.
    pub input: PathBuf,
    /// The cloud to write (.ply, .las, .laz, .xyz): positions, normals (interpolated from
    /// the vertices', or the faces'), and colours where the vertices have them.
    #[arg(short, long, value_name = "OUT")]
    pub output: PathBuf,
    /// Distance between samples, in the mesh's units (points per unit area: 1 / spacing²).
    #[arg(long, value_parser = args::finite_f64, conflicts_with = "points", value_name = "S")]
    pub spacing: Option<f64>,
    /// About this many points over the whole surface [default: 4 × the mesh's vertices].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub points: Option<u64>,
    /// Seed of the sampling (the same seed gives the same points).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Overwrite OUT if it exists (never the input).
    #[arg(long)]
    pub force: bool,
    /// Memory budget (e.g. 16G): a sampling needing more is refused before any work.
    /// Default: the memory available (free memory, within `ulimit -v`).
    #[arg(long, value_parser = stipple_lod::mem::parse_size, value_name = "SIZE")]
    pub memory: Option<u64>,
}

/// The most points a conversion writes.
const LIMIT: usize = 1 << 31;
/// Memory per sampled point while sampling and writing.
const BYTES_PER_POINT: u64 = 64;

pub fn convert(a: ConvertArgs) -> Result<()> {
    check_output(&a.output, &[&a.input])?;
    if a.output.exists() && !a.force {
        return Err(anyhow!(
            "{}: already exists; pass --force to overwrite it",
            a.output.display()
        ));
    }
    if !matches!(
        stipple_io::extension(&a.output).as_str(),
        "ply" | "las" | "laz" | "xyz" | "txt" | "csv"
    ) {
        return Err(anyhow!(
            "{}: write .ply, .las, .laz or .xyz",
            a.output.display()
        ));
    }
    let mesh = args::read_with_progress(&a.input)?;
    let what = a.input.display();
    if mesh.faces.is_empty() {
        return Err(anyhow!(
            "{what}: has no faces: it is a point cloud already (render it directly)"
        ));
    }
    let spacing = match (a.spacing, a.points) {
        (Some(s), _) => s,
        (None, Some(n)) => stipple_core::mesh::spacing_for(&mesh, n.min(LIMIT as u64) as usize),
        (None, None) => stipple_core::mesh::spacing_for(&mesh, 4 * mesh.len()),
    };
    if !(spacing > 0.0 && spacing.is_finite()) {
        return Err(anyhow!(
            "{what}: spacing {spacing}: it must be a positive distance"
        ));
    }
    // Before any work: the points this asks for fit the memory budget (sampling holds world
    // and local positions, normals, colours and faces; the writer streams them).
    let expected = stipple_core::mesh::area(&mesh) / (spacing * spacing);
    crate::memory::check_points(
        &format!("sampling {what} at spacing {spacing} ({expected:.3e} points)"),
        expected.min(u64::MAX as f64 / 2.0) as u64,
        BYTES_PER_POINT,
    )?;
    let t0 = Instant::now();
    let s = stipple_core::mesh::sample(&mesh, spacing, LIMIT, a.seed)
        .map_err(|e| anyhow!("{what}: {e}"))?;
    let n = s.cloud.len();
    println!(
        "sampled {n} points from {} faces (spacing {spacing:.4}) in {:.2} s",
        mesh.faces.len(),
        t0.elapsed().as_secs_f64()
    );
    stipple_io::write_cloud(&a.output, &s.cloud)?;
    println!("wrote {}", a.output.display());
    Ok(())
}
