//! `stipple build-lod`: a multi-resolution tree (.stlod) from clouds of any size (Pintus
//! et al. 2011, §7).

use crate::Result;
use anyhow::anyhow;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use stipple_lod::mem::{parse_count, parse_size};
use stipple_lod::Phase;

/// Testing aid: abort `build-lod` (no clean-up, as a kill would) after this many chunks.
const ABORT_ENV: &str = "STIPPLE_TEST_ABORT_BUILD_AFTER_CHUNKS";

fn parse_m(s: &str) -> std::result::Result<u32, String> {
    let v = parse_count(s).map_err(|e| e.to_string())?;
    if !(2..=1 << 24).contains(&v) {
        return Err(format!("`{s}`: the node size must lie in 2..16M"));
    }
    Ok(v as u32)
}

#[derive(clap::Args)]
pub struct BuildLodArgs {
    /// Input clouds, merged into one tree. LAS/LAZ are streamed, so they may be larger than
    /// memory; PLY and XYZ are read whole.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// The tree to write: .stlod (stipple's tree), or .copc.laz (a COPC file, the octree
    /// Potree, QGIS, PDAL and CloudCompare read; built in memory). Written under a temporary
    /// name and renamed when complete.
    #[arg(short, long)]
    output: PathBuf,
    /// M: a node with fewer points is a leaf; an inner node holds at most M samples taken
    /// out of its children (every point is stored once).
    #[arg(long, default_value = "32768", value_parser = parse_m, value_name = "M")]
    max_node_points: u32,
    /// Memory budget for the build, e.g. 512M or 4G: the process's peak, the memory it held
    /// before building (the program itself, a few MiB) included. Inputs of more than about
    /// 11 M points a GiB are built out of core, in chunks, through a spill file. Default:
    /// 1 GiB (less with under 4 GiB of RAM); a larger budget does not build faster.
    #[arg(long, value_parser = parse_size, value_name = "SIZE")]
    memory: Option<u64>,
    /// Directory for the spill file of an out-of-core build (default: beside the output).
    #[arg(long, value_name = "DIR")]
    temp_dir: Option<PathBuf>,
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = crate::lod::threads_1024)]
    threads: Option<usize>,
    /// Replace the output if it exists.
    #[arg(long)]
    force: bool,
    /// Store node payloads uncompressed (about 1.6x larger; a reader may then memory-map
    /// them). By default they are LZ4-compressed byte planes.
    #[arg(long)]
    uncompressed: bool,
}

pub fn build_lod(a: BuildLodArgs) -> Result<()> {
    build_lod_with(a, None)
}

/// [`build_lod`] that stops, leaving nothing, when `cancel` is set (the Python package sets it
/// on an interrupt).
pub fn build_lod_with(
    a: BuildLodArgs,
    cancel: Option<Arc<std::sync::atomic::AtomicBool>>,
) -> Result<()> {
    let inputs: Vec<&Path> = a.inputs.iter().map(PathBuf::as_path).collect();
    crate::output::check_output(&a.output, &inputs)?;
    let copc = is_copc_name(&a.output);
    if stipple_io::extension(&a.output) != "stlod" && !copc {
        return Err(anyhow!(
            "{}: the tree's name must end in .stlod (stipple's tree) or .copc.laz (COPC)",
            a.output.display()
        ));
    }
    if a.output.exists() && !a.force {
        return Err(anyhow!(
            "{}: already exists; pass --force to replace it",
            a.output.display()
        ));
    }
    if copc {
        return build_copc(&a, cancel);
    }
    if a.threads == Some(0) {
        return Err(anyhow!("--threads must be at least 1"));
    }
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{msg:9} [{bar:30}] {human_pos}/{human_len} points  {per_sec}  {elapsed} elapsed, ETA {eta}",
        )
        .unwrap()
        .progress_chars("=> "),
    );
    let b = bar.clone();
    let progress = move |phase: Phase, done: u64, total: u64| {
        let msg = match phase {
            Phase::Reading => "reading",
            Phase::Building => "building",
        };
        if b.message() != msg {
            b.set_message(msg);
            b.reset();
        }
        b.set_length(total);
        b.set_position(done);
    };
    let opts = stipple_lod::BuildOptions {
        max_node_points: a.max_node_points,
        memory: build_memory(a.memory)?,
        temp_dir: a.temp_dir.clone(),
        progress: Some(Arc::new(progress)),
        abort_after_chunks: std::env::var(ABORT_ENV).ok().and_then(|v| v.parse().ok()),
        replace: a.force,
        cancel,
        codec: if a.uncompressed {
            stipple_lod::format::CODEC_RAW
        } else {
            stipple_lod::format::CODEC_LZ4
        },
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()?;
    let t0 = Instant::now();
    let r = pool
        .install(|| stipple_lod::build(&a.inputs, &a.output, &opts))
        .map_err(anyhow::Error::from);
    bar.finish_and_clear();
    let r = r?;
    let s = t0.elapsed().as_secs_f64();
    print_wrote(&a, r.points, s);
    println!(
        "  {} nodes ({} leaves, depth {}), M = {}, {} MiB",
        r.nodes,
        r.leaves,
        r.depth,
        a.max_node_points,
        r.bytes >> 20
    );
    let how = if r.out_of_core {
        format!(
            "out of core: {} chunks (largest {} points), {} MiB spilled, {} dense spots redistributed",
            r.chunks,
            r.largest_chunk,
            r.spilled >> 20,
            r.redistributions
        )
    } else {
        "in memory".to_string()
    };
    let peak = stipple_lod::mem::peak_rss()
        .map(|p| format!("peak memory {} MiB", p >> 20))
        .unwrap_or_default();
    let budget = a.memory.unwrap_or(opts.memory);
    println!("  {how}; memory budget {} MiB; {peak}", budget >> 20);
    println!(
        "  reading {:.1} s, building and writing {:.1} s",
        r.read_seconds, r.build_seconds
    );
    Ok(())
}

/// Whether an output name asks for COPC (`*.copc.laz`, any case).
fn is_copc_name(p: &Path) -> bool {
    p.file_name()
        .map(|n| n.to_string_lossy().to_lowercase().ends_with(".copc.laz"))
        .unwrap_or(false)
}

/// `build-lod … -o out.copc.laz`: the inputs read whole and merged, then written as COPC
/// (`stipple_io::copc::write_copc`).
fn build_copc(a: &BuildLodArgs, cancel: Option<Arc<std::sync::atomic::AtomicBool>>) -> Result<()> {
    let stopped = || {
        cancel
            .as_ref()
            .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed))
    };
    if let Some(m) = a.memory {
        crate::memory::set_budget(m);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()?;
    let t0 = Instant::now();
    let mut cloud: Option<stipple_core::PointCloud> = None;
    for p in &a.inputs {
        if crate::lod::is_tree(p) {
            return Err(anyhow!(
                "{}: a .stlod tree is no input for a COPC file; give the clouds it was built from",
                p.display()
            ));
        }
        let c = pool.install(|| crate::args::read_with_progress(p))?;
        if stopped() {
            return Err(anyhow!("interrupted: the build stopped and left no file"));
        }
        match cloud.as_mut() {
            None => cloud = Some(c),
            Some(all) => {
                crate::memory::check_points(
                    &format!("merging {} into the COPC file", p.display()),
                    (all.len() + c.len()) as u64,
                    BYTES_PER_COPC_POINT,
                )?;
                all.append(&c)
            }
        }
    }
    let cloud = cloud.expect("clap requires an input");
    crate::memory::check_points(
        &format!("writing {} as COPC", a.output.display()),
        cloud.len() as u64,
        BYTES_PER_COPC_POINT,
    )?;
    let read_s = t0.elapsed().as_secs_f64();
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_message(format!("building and writing {}", a.output.display()));
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    let r = pool.install(|| stipple_io::copc::write_copc(&a.output, &cloud));
    bar.finish_and_clear();
    let r = r?;
    let s = t0.elapsed().as_secs_f64();
    print_wrote(a, r.points, s);
    println!(
        "  COPC: {} nodes on {} levels (at most {} points a node), {} MiB",
        r.nodes,
        r.levels,
        stipple_io::copc::MAX_NODE_POINTS,
        r.bytes >> 20
    );
    let peak = stipple_lod::mem::peak_rss()
        .map(|p| format!("; peak memory {} MiB", p >> 20))
        .unwrap_or_default();
    println!(
        "  reading {read_s:.1} s, building and writing {:.1} s (in memory{peak})",
        s - read_s
    );
    Ok(())
}

/// Memory per point while a COPC file is built: the cloud (position, colour, attributes),
/// the octree's indices and sort keys, and the node records before compression.
const BYTES_PER_COPC_POINT: u64 = 80;

/// The first line of a build's report: what was written, from how many files, how fast.
fn print_wrote(a: &BuildLodArgs, points: u64, seconds: f64) {
    println!(
        "wrote {}: {points} points from {} file{} in {seconds:.1} s ({:.2} M points/s)",
        a.output.display(),
        a.inputs.len(),
        if a.inputs.len() == 1 { "" } else { "s" },
        points as f64 / seconds / 1e6
    );
}

/// What the builder may use of a `--memory` budget: the budget less what this process holds
/// already (the budget bounds the process's peak, which the builder's own data alone did not:
/// a 24 MiB budget peaked at 22-25 MiB), but not below the builder's minimum (a budget that
/// small is the builder's to refuse or to keep to as well as it can); the default when none
/// is given.
fn build_memory(budget: Option<u64>) -> Result<u64> {
    let Some(m) = budget else {
        return Ok(stipple_lod::build::default_memory());
    };
    let held = stipple_core::sys::current_rss().unwrap_or(0);
    Ok(m.saturating_sub(held)
        .max(stipple_lod::build::MIN_MEMORY.min(m)))
}
