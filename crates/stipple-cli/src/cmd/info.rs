//! `stipple info`: point count, bounds, attributes and spacing of clouds and trees.

use crate::Result;
use crate::{args, lod};
use anyhow::anyhow;
use std::path::PathBuf;
use stipple_render::PreparedCloud;

pub fn info(files: &[PathBuf], verify: bool) -> Result<()> {
    let mut failed = 0;
    for f in files {
        if lod::is_tree(f) {
            if let Err(e) = lod::info(f, verify) {
                eprintln!("stipple: error: {e}");
                failed += 1;
            }
            continue;
        }
        // A COPC file's hierarchy is checked before its points are read.
        let copc = if stipple_io::copc::is_copc(f) {
            match stipple_io::copc::Copc::open(f) {
                Ok(c) => Some(c),
                Err(e) => {
                    eprintln!("stipple: error: {e}");
                    failed += 1;
                    continue;
                }
            }
        } else {
            None
        };
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
                let (blo, bhi, strays) = c.framing_bounds();
                if strays > 0 {
                    println!(
                        "  strays      {strays} point{} far outside the bulk ({:.4} {:.4} {:.4} \
                         to {:.4} {:.4} {:.4}), which the default view frames",
                        if strays == 1 { "" } else { "s" },
                        blo.x,
                        blo.y,
                        blo.z,
                        bhi.x,
                        bhi.y,
                        bhi.z
                    );
                }
                println!("  attributes  {}", c.attributes().join(", "));
                if !c.faces.is_empty() {
                    println!("  faces       {} triangles", c.faces.len());
                }
                if let Some(copc) = &copc {
                    let levels = copc.nodes.iter().map(|n| n.key.level).max().unwrap_or(0) + 1;
                    println!(
                        "  COPC        {} nodes on {levels} levels, {} hierarchy page{}, root spacing {:.6}, checked",
                        copc.nodes.len(),
                        copc.pages,
                        if copc.pages == 1 { "" } else { "s" },
                        copc.info.spacing
                    );
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
        Err(anyhow!(
            "{failed} of {} files could not be read",
            files.len()
        ))
    } else {
        Ok(())
    }
}
