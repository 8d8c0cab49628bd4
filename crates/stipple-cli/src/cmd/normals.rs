//! `stipple normals`: estimate or re-orient normals and splat radii, write a PLY.

use crate::args;
use crate::output::*;
use crate::Result;
use anyhow::{anyhow, Context};
use std::path::PathBuf;
use std::time::Instant;
use stipple_render::PreparedCloud;

#[derive(clap::Args)]
pub struct NormalsArgs {
    /// The cloud (.ply, .ply.gz, .las, .laz, .xyz, ...). It is only read.
    pub input: PathBuf,
    /// The PLY to write (positions, colours and the other attributes of the input, plus
    /// nx ny nz and radius).
    #[arg(short, long, value_name = "OUT.ply")]
    pub output: PathBuf,
    /// Neighbours per point.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(3..=64))]
    pub k: u32,
    /// Estimate new normals even where the file has some (by default given normals are kept
    /// and only turned round where their signs are inconsistent).
    #[arg(long)]
    pub reestimate: bool,
    /// Where the sensor stood (x,y,z in the file's coordinates), for a single scan: normals
    /// face it instead of taking the orientation propagated over the neighbour graph.
    /// Without it, a PCD's VIEWPOINT is used, and airborne LiDAR (LAS/LAZ with GPS times
    /// and scan angles spanning 5° or more) faces each point's normal towards the aircraft
    /// where it measured the point (its flight line's track, from the pulses nearest nadir).
    #[arg(long, value_parser = args::parse_vec3, allow_hyphen_values = true, value_name = "X,Y,Z")]
    pub viewpoint: Option<glam::DVec3>,
    /// Overwrite OUT.ply if it exists (never the input).
    #[arg(long)]
    pub force: bool,
}

pub fn normals(a: NormalsArgs) -> Result<()> {
    if !matches!(stipple_io::extension(&a.output).as_str(), "ply") {
        return Err(anyhow!(
            "{}: the output must be a .ply file (it carries nx ny nz radius)",
            a.output.display()
        ));
    }
    check_output(&a.output, &[&a.input])?;
    if a.output.exists() && !a.force {
        return Err(anyhow!(
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
    // The viewpoint given, else the file's sensor (a PCD's VIEWPOINT).
    let viewpoint = a.viewpoint.or(p.cloud.sensor.map(|s| s.position));
    let r = p
        .prepare_normals_from(a.k as usize, viewpoint)
        .with_context(|| a.input.display().to_string())?;
    let s = t0.elapsed().as_secs_f64();
    if let Some(note) = r.dequantised_note() {
        println!("{note}");
    }
    if had {
        println!(
            "kept the file's normals; {} of {n} turned round ({:.1}% of neighbouring normals \
             disagreed before)",
            r.reoriented,
            100.0 * r.inconsistency
        );
    } else {
        println!(
            "estimated normals for {n} points (k = {}, oriented {}) in {s:.2} s ({:.2} M \
             points/s)",
            a.k,
            r.oriented.describe(),
            n as f64 / s.max(1e-9) / 1e6
        );
    }
    stipple_io::write_atomically(&a.output, |tmp| {
        stipple_io::ply::write_ply(tmp, &p.cloud, stipple_io::ply::Encoding::BinaryLittleEndian)
    })?;
    println!("wrote {} (nx ny nz radius)", a.output.display());
    Ok(())
}
