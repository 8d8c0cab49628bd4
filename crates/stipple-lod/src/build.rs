//! Building a tree from input files, in memory when the input fits the budget and out of core
//! when it does not.
//!
//! **Out of core** (Pintus §7 builds in an external memory array; this is our version):
//! 1. *Distribute.* One pass over the inputs bins every point into a grid of buckets over the
//!    root box, appending full bucket buffers to one spill file. The grid's cut planes are
//!    the kd-tree's own split planes: each axis is halved in the order the kd-tree would halve
//!    it (the longest side first), so the top of the tree is a union of buckets.
//! 2. *Plan.* Walking the kd rule over the grid's counts (3-D prefix sums) finds the subtrees
//!    ("chunks") small enough to build in memory.
//! 3. *Build.* Chunks are loaded one at a time and built in memory by [`crate::kd`] on all
//!    cores; their payloads are appended to the output in preorder, all but the chunk's root,
//!    whose records the chunk returns: the inner nodes above take their samples out of their
//!    children's records ([`crate::sample`]), and only then are the children's payloads final
//!    and written. Every point is stored once.
//!
//! A node that is larger than a chunk but whose longest axis the grid cannot split any more
//! is distributed again into a finer grid over its own box (the same code, reading its
//! buckets instead of the inputs), so any density works.
//!
//! The output is written under a temporary name with a zeroed header, and the header is
//! written, synced and the file renamed only when everything else is on disk. The result is
//! the same file for the same inputs and options (payload order, node numbering and samples
//! do not depend on thread timing).

use crate::format::{
    Header, Node, CODEC_LZ4, CODEC_RAW, FLAG_COLOUR, FLAG_Z_UP, HEADER_SIZE, NODE_SIZE, NONE,
};
use crate::kd::{self, LocalNode};
use crate::record::Record;
use crate::source::open_inputs;
use crate::{codec, sample, LodError};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use stipple_core::Bounds;

/// Default M: leaves hold fewer points, inner nodes at most this many samples.
pub const DEFAULT_MAX_NODE_POINTS: u32 = 32_768;
/// The default memory budget where the machine has room for it ([`default_memory`]).
pub const DEFAULT_MEMORY: u64 = 1 << 30;
/// Smallest memory budget accepted.
pub const MIN_MEMORY: u64 = 16 << 20;
/// Bytes per point of an in-memory build: the record, its share of inner-node samples, and
/// the filter's scratch.
const IN_CORE_BYTES: u64 = 48;
/// The smallest bucket block written to the spill file, in records.
const MIN_BLOCK: u64 = 256;

/// What the build is doing, for progress bars.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Reading the inputs (and, out of core, binning them to the spill file).
    Reading,
    /// Building nodes and writing payloads.
    Building,
}

pub type ProgressFn = Arc<dyn Fn(Phase, u64, u64) + Send + Sync>;

#[derive(Clone)]
pub struct BuildOptions {
    /// M (default [`DEFAULT_MAX_NODE_POINTS`]).
    pub max_node_points: u32,
    /// Memory budget in bytes for the build's data (inputs are streamed through it).
    pub memory: u64,
    /// Where the spill file goes (default: beside the output).
    pub temp_dir: Option<PathBuf>,
    /// Called with (phase, done, total) points.
    pub progress: Option<ProgressFn>,
    /// Testing aid: abort the process (no clean-up, like a kill) after this many chunks
    /// have been written.
    pub abort_after_chunks: Option<usize>,
    /// Replace an existing output (`--force`). Without it a tree that exists when the
    /// build finishes (another build to the same output finished first) is kept and this
    /// build fails: the finished file is linked into place, never renamed over another.
    pub replace: bool,
    /// Set to stop the build (an interrupt in the Python package): it ends with
    /// [`LodError::Interrupted`] at the next batch of input or node written, and removes what it
    /// wrote.
    pub cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// How payloads are stored (default [`CODEC_LZ4`]; [`crate::format::CODEC_RAW`] keeps
    /// them as records, readable by a memory map).
    pub codec: u32,
}

fn check_cancel(c: &Option<std::sync::Arc<std::sync::atomic::AtomicBool>>) -> Result<(), LodError> {
    match c {
        Some(c) if c.load(std::sync::atomic::Ordering::Relaxed) => Err(LodError::Interrupted),
        _ => Ok(()),
    }
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            max_node_points: DEFAULT_MAX_NODE_POINTS,
            memory: default_memory(),
            temp_dir: None,
            progress: None,
            abort_after_chunks: None,
            replace: false,
            cancel: None,
            codec: CODEC_LZ4,
        }
    }
}

/// 1 GiB, or less where that is more than a quarter of the machine's memory or three quarters
/// of what this process can still take (free memory, within `ulimit -v`).
///
/// Not more: a larger budget makes larger chunks, and a 100 M-point build took 14.9 s at
/// 1 GiB (15 chunks, 0.44 GiB peak) and 23.1 s at 6 GiB (2 chunks, 2.3 GiB peak): large
/// chunks partition their top levels on one core and touch fresh pages (`BENCHMARKS.md`).
pub fn default_memory() -> u64 {
    let total = crate::mem::total_memory().unwrap_or(8 << 30);
    // Within what this process can still take (free memory, `ulimit -v`).
    let free = crate::mem::available_memory().map_or(u64::MAX, |a| a / 4 * 3);
    (total / 4).min(free).clamp(MIN_MEMORY, DEFAULT_MEMORY)
}

#[derive(Clone, Debug, Default)]
pub struct BuildReport {
    pub points: u64,
    pub nodes: u32,
    pub leaves: u32,
    pub depth: u16,
    /// Subtrees built in memory (1 for an in-memory build).
    pub chunks: usize,
    pub out_of_core: bool,
    /// Bytes written to the spill file (0 in memory).
    pub spilled: u64,
    /// Size of the tree file.
    pub bytes: u64,
    /// Largest chunk, in points.
    pub largest_chunk: u64,
    /// Nodes distributed a second time into a finer grid (dense spots).
    pub redistributions: usize,
    /// Seconds reading the inputs (and distributing them, out of core).
    pub read_seconds: f64,
    /// Seconds building nodes and writing the tree.
    pub build_seconds: f64,
}

/// Builds a tree from `inputs` into `output` (replacing it only when the build succeeded).
pub fn build(inputs: &[PathBuf], output: &Path, o: &BuildOptions) -> Result<BuildReport, LodError> {
    if o.codec != CODEC_RAW && o.codec != CODEC_LZ4 {
        return Err(LodError::Invalid(format!(
            "unknown payload codec {}",
            o.codec
        )));
    }
    if o.max_node_points < 2 {
        return Err(LodError::Invalid(
            "the node size M must be at least 2".into(),
        ));
    }
    if o.memory < MIN_MEMORY {
        return Err(LodError::Budget(format!(
            "a memory budget of {} MiB is too small (at least {} MiB)",
            o.memory >> 20,
            MIN_MEMORY >> 20
        )));
    }
    let m = o.max_node_points as u64;
    let chunk_cap = o.memory / 2 / IN_CORE_BYTES;
    if chunk_cap < 4 * m {
        return Err(LodError::Budget(format!(
            "a memory budget of {} MiB is too small for nodes of {m} points (it needs at least {} MiB); raise --memory or lower --max-node-points",
            o.memory >> 20,
            (8 * m * IN_CORE_BYTES) >> 20
        )));
    }
    let z_up = inputs
        .iter()
        .all(|p| matches!(stipple_io::extension(p).as_str(), "las" | "laz"));
    let inputs = open_inputs(inputs, o.memory)?;
    let total: u64 = inputs.iter().map(|i| i.count).sum();
    let (lo, hi) = inputs.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), i| (lo.min(i.lo), hi.max(i.hi)),
    );
    let origin = ((lo + hi) * 0.5).round();
    let coloured = inputs.iter().any(|i| i.coloured);
    remove_dead_leftovers(output, o.temp_dir.as_deref());
    let tmp = temp_name(output)?;
    let mut guard = RemoveOnDrop(vec![tmp.clone()]);
    let file = File::create(&tmp).map_err(|e| LodError::io(output, e))?;
    let mut out = Out {
        w: BufWriter::with_capacity(1 << 20, file),
        codec: o.codec,
        offset: 0,
        arena: Vec::new(),
        path: output.to_owned(),
        chunks: 0,
        abort_after: o.abort_after_chunks,
        cancel: o.cancel.clone(),
    };
    out.write(&[0u8; HEADER_SIZE as usize])?;
    let mut report = BuildReport {
        points: total,
        ..Default::default()
    };
    let progress = |p: Phase, d: u64| {
        if let Some(f) = &o.progress {
            f(p, d, total)
        }
    };
    // About a tenth of the budget for a batch of input records (LAS bytes + our record); LAZ
    // decompresses in parallel per batch, so batches should not be small.
    let batch = (o.memory / 512).clamp(1 << 14, 1 << 20) as usize;
    let t0 = std::time::Instant::now();
    let (root, bounds) = if total.saturating_mul(IN_CORE_BYTES) <= o.memory / 2 {
        // In memory: read everything, build one chunk.
        let mut recs: Vec<Record> = Vec::with_capacity(total as usize);
        for i in &inputs {
            i.read(origin, batch, &mut |b| {
                recs.extend_from_slice(b);
                progress(Phase::Reading, recs.len() as u64);
                check_cancel(&o.cancel)
            })?;
        }
        let bounds = bounds_of(&recs);
        report.read_seconds = t0.elapsed().as_secs_f64();
        progress(Phase::Building, 0);
        let nodes = kd::build(&mut recs, bounds, 0, m as usize);
        let (root, samples) = out.chunk(&nodes, &recs)?;
        out.finish(root, &samples)?;
        report.largest_chunk = recs.len() as u64;
        progress(Phase::Building, total);
        (root, bounds)
    } else {
        report.out_of_core = true;
        let dir = o
            .temp_dir
            .clone()
            .or_else(|| output.parent().map(Path::to_path_buf))
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or_else(|| PathBuf::from("."));
        let spill_path = dir.join(format!(
            ".{}.{}.spill",
            output
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            std::process::id()
        ));
        guard.0.push(spill_path.clone());
        let mut ctx = OutOfCore {
            spill: Spill::create(&spill_path)?,
            m: m as usize,
            chunk_cap,
            memory: o.memory,
            done: 0,
            progress: &progress,
            largest: 0,
            redistributions: 0,
        };
        let header_box = Bounds {
            min: (lo - origin).as_vec3(),
            max: (hi - origin).as_vec3(),
        };
        let mut bounds = widen(header_box);
        let buckets = loop {
            let grid = ctx.grid(bounds, total);
            let mut seen = 0u64;
            let r = ctx.distribute(grid, &mut |f| {
                for i in &inputs {
                    i.read(origin, batch, &mut |b| {
                        seen += b.len() as u64;
                        progress(Phase::Reading, seen);
                        check_cancel(&o.cancel)?;
                        f(b)
                    })?;
                }
                Ok(())
            });
            match r {
                Ok(b) => break b,
                Err(Distribute::Outside(actual)) if actual.union(bounds) != bounds => {
                    // A header's bounds were wrong: start again with the true bounds.
                    bounds = widen(actual.union(bounds));
                    ctx.spill.reset()?;
                }
                Err(Distribute::Outside(_)) => {
                    return Err(LodError::Invalid(
                        "internal error: a point outside the root box was also inside it".into(),
                    ))
                }
                Err(Distribute::Fail(e)) => return Err(e),
            }
        };
        report.read_seconds = t0.elapsed().as_secs_f64();
        let full = buckets.grid.full();
        let (root, samples) = ctx.node(&mut out, &buckets, full, bounds, 0)?;
        out.finish(root, &samples)?;
        report.spilled = ctx.spill.len;
        report.largest_chunk = ctx.largest;
        report.redistributions = ctx.redistributions;
        (root, bounds)
    };
    report.chunks = out.chunks;
    // Number the nodes breadth first from the root.
    let mut order = vec![root];
    let mut id = vec![NONE; out.arena.len()];
    id[root] = 0;
    let mut k = 0;
    while k < order.len() {
        if let Some(c) = out.arena[order[k]].children {
            for a in c {
                id[a] = order.len() as u32;
                order.push(a);
            }
        }
        k += 1;
    }
    let mut table = vec![0u8; order.len() * NODE_SIZE as usize];
    for (slot, &a) in table.chunks_exact_mut(NODE_SIZE as usize).zip(&order) {
        let n = &out.arena[a];
        let node = Node {
            bounds: n.bounds,
            subtree_points: n.subtree_points,
            sample_count: n.samples,
            children: n.children.map(|c| c.map(|a| id[a])).unwrap_or([NONE; 2]),
            spacing: n.spacing,
            payload_offset: n.offset,
            payload_bytes: n.bytes,
            payload_crc: n.crc,
            depth: n.depth,
        };
        report.leaves += node.is_leaf() as u32;
        report.depth = report.depth.max(n.depth);
        node.encode(slot);
    }
    let table_offset = out.offset;
    out.write(&table)?;
    let header = Header {
        flags: if coloured { FLAG_COLOUR } else { 0 } | if z_up { FLAG_Z_UP } else { 0 },
        max_node_points: m as u32,
        point_count: total,
        node_count: order.len() as u32,
        origin,
        bounds,
        table_offset,
        table_size: table.len() as u64,
        table_crc: crc32fast::hash(&table),
        codec: o.codec,
    };
    report.nodes = header.node_count;
    report.bytes = out.offset;
    let file = out
        .w
        .into_inner()
        .map_err(|e| LodError::io(output, e.into_error()))?;
    file.write_all_at(&header.encode(), 0)
        .and_then(|_| file.sync_all())
        .map_err(|e| LodError::io(output, e))?;
    drop(file);
    check_cancel(&o.cancel)?;
    if o.replace {
        std::fs::rename(&tmp, output).map_err(|e| LodError::io(output, e))?;
    } else {
        // A hard link fails if the output exists, atomically (rename would replace it).
        match std::fs::hard_link(&tmp, output) {
            Ok(()) => std::fs::remove_file(&tmp).map_err(|e| LodError::io(&tmp, e))?,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                return Err(LodError::Invalid(format!(
                    "{}: appeared while this build ran (another build to the same output \
                     finished first?); it is kept, and this build's tree was discarded. \
                     Pass --force to replace it",
                    output.display()
                )));
            }
            // File systems without hard links: check, then rename (a small window).
            Err(_) if !output.exists() => {
                std::fs::rename(&tmp, output).map_err(|e| LodError::io(output, e))?
            }
            Err(e) => return Err(LodError::io(output, e)),
        }
    }
    guard.0.retain(|p| p != &tmp);
    report.build_seconds = t0.elapsed().as_secs_f64() - report.read_seconds;
    Ok(report)
}

fn temp_name(output: &Path) -> Result<PathBuf, LodError> {
    let name = output
        .file_name()
        .ok_or_else(|| LodError::Invalid(format!("{}: no file name", output.display())))?;
    let mut t = std::ffi::OsString::from(".");
    t.push(name);
    t.push(format!(".{}.tmp", std::process::id()));
    Ok(output.with_file_name(t))
}

/// Removes the temporary and spill files of earlier builds of `output` whose process is gone
/// (killed builds cannot clean up after themselves). Only on Linux, where `/proc` tells.
fn remove_dead_leftovers(output: &Path, temp_dir: Option<&Path>) {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Some(name) = output.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return;
    };
    let prefix = format!(".{name}.");
    let dirs = [output.parent(), temp_dir];
    for dir in dirs.into_iter().flatten() {
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            let f = e.file_name().to_string_lossy().into_owned();
            let Some(rest) = f.strip_prefix(&prefix) else {
                continue;
            };
            let Some((pid, ext)) = rest.split_once('.') else {
                continue;
            };
            let dead = pid
                .parse::<u32>()
                .is_ok_and(|p| !Path::new(&format!("/proc/{p}")).exists());
            if dead && (ext == "tmp" || ext == "spill") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// Removes temporary files however the build ends (except by a kill).
struct RemoveOnDrop(Vec<PathBuf>);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        for p in &self.0 {
            let _ = std::fs::remove_file(p);
        }
    }
}

pub fn bounds_of(recs: &[Record]) -> Bounds {
    recs.par_chunks(1 << 16)
        .map(|c| c.iter().fold(Bounds::EMPTY, |b, r| b.including(r.p())))
        .reduce(|| Bounds::EMPTY, Bounds::union)
}

/// Widens a box by a few ulps so that rounding in the readers cannot put a point outside.
fn widen(b: Bounds) -> Bounds {
    let pad = (b.extent().max_element() * 1e-6).max(1e-6);
    Bounds {
        min: b.min - Vec3::splat(pad),
        max: b.max + Vec3::splat(pad),
    }
}

/// A node being assembled: the arena holds nodes in build order until they are numbered.
struct ArenaNode {
    bounds: Bounds,
    subtree_points: u64,
    samples: u32,
    children: Option<[usize; 2]>,
    spacing: f32,
    offset: u64,
    bytes: u32,
    crc: u32,
    depth: u16,
}

struct Out {
    w: BufWriter<File>,
    codec: u32,
    offset: u64,
    arena: Vec<ArenaNode>,
    path: PathBuf,
    chunks: usize,
    abort_after: Option<usize>,
    cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

impl Out {
    fn write(&mut self, b: &[u8]) -> Result<(), LodError> {
        check_cancel(&self.cancel)?;
        self.w
            .write_all(b)
            .map_err(|e| LodError::io(&self.path, e))?;
        self.offset += b.len() as u64;
        Ok(())
    }

    /// Adds a node whose payload is not final yet (its parent will take samples out of it):
    /// [`Out::finish`] writes it. Returns its arena index.
    fn pending(
        &mut self,
        bounds: Bounds,
        subtree_points: u64,
        children: Option<[usize; 2]>,
        spacing: f32,
        depth: u16,
    ) -> usize {
        self.arena.push(ArenaNode {
            bounds,
            subtree_points,
            samples: 0,
            children,
            spacing,
            offset: 0,
            bytes: 0,
            crc: 0,
            depth,
        });
        self.arena.len() - 1
    }

    /// Appends the final payload of node `i` (made by [`Out::pending`]).
    fn finish(&mut self, i: usize, samples: &[Record]) -> Result<(), LodError> {
        let stored = codec::encode(self.codec, samples);
        self.finish_encoded(i, samples.len(), &stored)
    }

    fn finish_encoded(&mut self, i: usize, count: usize, stored: &[u8]) -> Result<(), LodError> {
        let offset = self.offset;
        let bytes = u32::try_from(stored.len()).map_err(|_| {
            LodError::Invalid("internal error: a node's payload exceeds 4 GiB".into())
        })?;
        self.write(stored)?;
        let a = &mut self.arena[i];
        a.samples = count as u32;
        a.offset = offset;
        a.bytes = bytes;
        a.crc = crc32fast::hash(stored);
        Ok(())
    }

    /// Appends an in-memory subtree (preorder), all but its root, whose payload is returned
    /// with its arena index: the parent above takes its samples out of it.
    fn chunk(
        &mut self,
        nodes: &[LocalNode],
        recs: &[Record],
    ) -> Result<(usize, Vec<Record>), LodError> {
        let base = self.arena.len();
        for n in nodes {
            self.pending(
                n.bounds,
                n.subtree_points,
                n.children.map(|c| c.map(|k| base + k)),
                n.spacing,
                n.depth,
            );
        }
        // Encoded on all cores, a batch at a time (memory), written in order.
        let codec = self.codec;
        let batch = 4 * rayon::current_num_threads();
        for (b, group) in nodes[1..].chunks(batch).enumerate() {
            let stored: Vec<Vec<u8>> = group
                .par_iter()
                .map(|n| codec::encode(codec, n.samples(recs)))
                .collect();
            for (k, (n, s)) in group.iter().zip(&stored).enumerate() {
                self.finish_encoded(base + 1 + b * batch + k, n.samples(recs).len(), s)?;
            }
        }
        self.chunks += 1;
        if self.abort_after == Some(self.chunks) {
            let _ = self.w.flush();
            std::process::abort();
        }
        Ok((base, nodes[0].samples(recs).to_vec()))
    }

    /// The samples of a node above the chunks: taken out of its children's payloads (`li`
    /// and `ri`, still pending), which are then written. Returns the node's arena index, still
    /// pending, and its samples.
    #[allow(clippy::too_many_arguments)]
    fn parent(
        &mut self,
        bounds: Bounds,
        count: u64,
        depth: u16,
        m: usize,
        (li, ls): (usize, Vec<Record>),
        (ri, rs): (usize, Vec<Record>),
    ) -> Result<(usize, Vec<Record>), LodError> {
        let child = self.arena[li].spacing.max(self.arena[ri].spacing);
        let t = sample::take(&ls, &rs, &bounds, m, child);
        let kept = |part: &[Record], taken: &[bool]| -> Vec<Record> {
            part.iter()
                .zip(taken)
                .filter(|(_, &t)| !t)
                .map(|(r, _)| *r)
                .collect()
        };
        self.finish(li, &kept(&ls, &t.left))?;
        self.finish(ri, &kept(&rs, &t.right))?;
        let (samples, spacing) = (t.samples, t.spacing);
        let i = self.pending(bounds, count, Some([li, ri]), spacing, depth);
        Ok((i, samples))
    }
}

/// The append-only scratch file of bucket blocks.
struct Spill {
    file: File,
    path: PathBuf,
    len: u64,
}

impl Spill {
    fn create(path: &Path) -> Result<Spill, LodError> {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(path)
            .map_err(|e| LodError::io(path, e))?;
        Ok(Spill {
            file,
            path: path.to_owned(),
            len: 0,
        })
    }

    fn reset(&mut self) -> Result<(), LodError> {
        self.file
            .set_len(0)
            .map_err(|e| LodError::io(&self.path, e))?;
        self.len = 0;
        Ok(())
    }

    fn append(&mut self, recs: &[Record]) -> Result<(u64, u32), LodError> {
        let bytes: &[u8] = bytemuck::cast_slice(recs);
        self.file
            .write_all_at(bytes, self.len)
            .map_err(|e| LodError::io(&self.path, e))?;
        let at = self.len;
        self.len += bytes.len() as u64;
        Ok((at, recs.len() as u32))
    }
}

/// A grid whose cut planes are kd split planes: `planes[a]` are the 2^levels[a] − 1 interior
/// planes of axis a, made by halving recursively exactly as [`kd::split_plane`] does.
struct Grid {
    bounds: Bounds,
    planes: [Vec<f32>; 3],
}

fn planes(lo: f32, hi: f32, levels: u32, out: &mut Vec<f32>) {
    if levels == 0 {
        return;
    }
    let mid = (lo + hi) * 0.5;
    planes(lo, mid, levels - 1, out);
    out.push(mid);
    planes(mid, hi, levels - 1, out);
}

impl Grid {
    /// Halves the axes in kd order (longest cell side first) until there are `target` cells.
    fn new(bounds: Bounds, target: u64) -> Grid {
        let mut levels = [0u32; 3];
        let mut cell = bounds.extent();
        let mut cells = 1u64;
        while cells < target {
            let b = Bounds {
                min: Vec3::ZERO,
                max: cell,
            };
            let a = kd::longest_axis(&b);
            if cell[a] <= bounds.extent().max_element() * 1e-6 || levels[a] >= 16 {
                break;
            }
            levels[a] += 1;
            cell[a] *= 0.5;
            cells *= 2;
        }
        let mut p: [Vec<f32>; 3] = Default::default();
        for a in 0..3 {
            planes(bounds.min[a], bounds.max[a], levels[a], &mut p[a]);
        }
        Grid { bounds, planes: p }
    }

    fn dims(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| self.planes[a].len() + 1)
    }

    fn full(&self) -> [Range<usize>; 3] {
        self.dims().map(|n| 0..n)
    }

    /// The cell of a point: a point on a plane goes to the upper side, as in [`kd::build`].
    fn cell(&self, p: [f32; 3]) -> usize {
        let d = self.dims();
        let c = |a: usize| self.planes[a].partition_point(|&b| b <= p[a]);
        (c(0) * d[1] + c(1)) * d[2] + c(2)
    }

    /// The box of a range of cells.
    fn range_bounds(&self, r: &[Range<usize>; 3]) -> Bounds {
        let mut b = self.bounds;
        for a in 0..3 {
            if r[a].start > 0 {
                b.min[a] = self.planes[a][r[a].start - 1];
            }
            if r[a].end < self.planes[a].len() + 1 {
                b.max[a] = self.planes[a][r[a].end - 1];
            }
        }
        b
    }
}

/// Buckets of a distributed point set: blocks in the spill file, counts, prefix sums.
struct Buckets {
    grid: Grid,
    blocks: Vec<Vec<(u64, u32)>>,
    /// 3-D prefix sums of the counts, (nx+1)(ny+1)(nz+1).
    prefix: Vec<u64>,
}

impl Buckets {
    fn count(&self, r: &[Range<usize>; 3]) -> u64 {
        let d = self.grid.dims();
        let (sy, sz) = ((d[2] + 1), (d[1] + 1) * (d[2] + 1));
        let at = |x: usize, y: usize, z: usize| self.prefix[x * sz + y * sy + z] as i128;
        let (x0, x1, y0, y1, z0, z1) = (
            r[0].start, r[0].end, r[1].start, r[1].end, r[2].start, r[2].end,
        );
        let v = at(x1, y1, z1) - at(x0, y1, z1) - at(x1, y0, z1) - at(x1, y1, z0)
            + at(x0, y0, z1)
            + at(x0, y1, z0)
            + at(x1, y0, z0)
            - at(x0, y0, z0);
        v as u64
    }

    fn cells(&self, r: &[Range<usize>; 3]) -> impl Iterator<Item = usize> + '_ {
        let d = self.grid.dims();
        let r = r.clone();
        r[0].clone().flat_map(move |x| {
            let (ry, rz) = (r[1].clone(), r[2].clone());
            ry.flat_map(move |y| rz.clone().map(move |z| (x * d[1] + y) * d[2] + z))
        })
    }
}

enum Distribute {
    /// A point lay outside the grid; the bounds of everything read so far.
    Outside(Bounds),
    Fail(LodError),
}

impl From<LodError> for Distribute {
    fn from(e: LodError) -> Self {
        Distribute::Fail(e)
    }
}

type Source<'s> =
    dyn FnMut(&mut dyn FnMut(&[Record]) -> Result<(), LodError>) -> Result<(), LodError> + 's;

struct OutOfCore<'p> {
    spill: Spill,
    m: usize,
    chunk_cap: u64,
    memory: u64,
    done: u64,
    progress: &'p dyn Fn(Phase, u64),
    largest: u64,
    redistributions: usize,
}

impl OutOfCore<'_> {
    /// A grid fine enough that chunk-sized nodes are unions of cells, with at most as many
    /// cells as a quarter of the budget can buffer `MIN_BLOCK` records for.
    fn grid(&self, bounds: Bounds, points: u64) -> Grid {
        let max_cells = (self.memory / 4 / Record::SIZE as u64 / MIN_BLOCK).clamp(8, 1 << 18);
        let want = (points / self.chunk_cap.max(1)).saturating_mul(64).max(64);
        Grid::new(bounds, want.min(max_cells))
    }

    /// Bins everything `source` yields into buckets of `grid`.
    fn distribute(&mut self, grid: Grid, source: &mut Source) -> Result<Buckets, Distribute> {
        let d = grid.dims();
        let n = d[0] * d[1] * d[2];
        let cap =
            ((self.memory / 4 / Record::SIZE as u64) / n as u64).clamp(MIN_BLOCK, 1 << 16) as usize;
        let mut bufs: Vec<Vec<Record>> = (0..n).map(|_| Vec::new()).collect();
        let mut blocks: Vec<Vec<(u64, u32)>> = vec![Vec::new(); n];
        let mut counts = vec![0u64; n];
        let mut outside = Bounds::EMPTY;
        let mut cells: Vec<u32> = Vec::new();
        let spill = &mut self.spill;
        let r = source(&mut |b: &[Record]| {
            b.par_iter()
                .map(|r| {
                    if kd::contains(&grid.bounds, r.p()) {
                        grid.cell(r.pos) as u32
                    } else {
                        u32::MAX
                    }
                })
                .collect_into_vec(&mut cells);
            for (r, &c) in b.iter().zip(&cells) {
                if c == u32::MAX {
                    outside = outside.including(r.p());
                    continue;
                }
                let buf = &mut bufs[c as usize];
                if buf.capacity() == 0 {
                    buf.reserve_exact(cap);
                }
                buf.push(*r);
                counts[c as usize] += 1;
                if buf.len() == cap {
                    blocks[c as usize].push(spill.append(buf)?);
                    buf.clear();
                }
            }
            Ok(())
        });
        r?;
        if !outside.is_empty() {
            return Err(Distribute::Outside(outside));
        }
        for (c, buf) in bufs.into_iter().enumerate() {
            if !buf.is_empty() {
                blocks[c].push(spill.append(&buf)?);
            }
        }
        let mut prefix = vec![0u64; (d[0] + 1) * (d[1] + 1) * (d[2] + 1)];
        let (sy, sx) = (d[2] + 1, (d[1] + 1) * (d[2] + 1));
        for x in 0..d[0] {
            for y in 0..d[1] {
                for z in 0..d[2] {
                    let c = counts[(x * d[1] + y) * d[2] + z];
                    let i = (x + 1) * sx + (y + 1) * sy + (z + 1);
                    prefix[i] = c + prefix[i - sx] + prefix[i - sy] + prefix[i - 1]
                        - prefix[i - sx - sy]
                        - prefix[i - sx - 1]
                        - prefix[i - sy - 1]
                        + prefix[i - sx - sy - 1];
                }
            }
        }
        Ok(Buckets {
            grid,
            blocks,
            prefix,
        })
    }

    /// Reads the records of a range of buckets, in cell order.
    fn load(
        &self,
        b: &Buckets,
        r: &[Range<usize>; 3],
        count: u64,
    ) -> Result<Vec<Record>, LodError> {
        let mut recs = Vec::with_capacity(count as usize);
        for c in b.cells(r) {
            for &(off, n) in &b.blocks[c] {
                read_at(&self.spill.file, &self.spill.path, off, n, &mut recs)?;
            }
        }
        Ok(recs)
    }

    /// Builds the node for cells `r` of `b` (box `bounds`); returns its arena index and
    /// samples.
    fn node(
        &mut self,
        out: &mut Out,
        b: &Buckets,
        r: [Range<usize>; 3],
        bounds: Bounds,
        depth: u16,
    ) -> Result<(usize, Vec<Record>), LodError> {
        let count = b.count(&r);
        let plane = kd::split_plane(&bounds).filter(|_| depth < kd::MAX_DEPTH);
        if count <= self.chunk_cap || plane.is_none() {
            let mut recs = self.load(b, &r, count)?;
            let nodes = kd::build(&mut recs, bounds, depth, self.m);
            self.largest = self.largest.max(count);
            let res = out.chunk(&nodes, &recs)?;
            self.done += count;
            (self.progress)(Phase::Building, self.done);
            return Ok(res);
        }
        let (axis, mid) = plane.unwrap();
        let ra = &r[axis];
        let split_at = ra.start + ra.len() / 2;
        if ra.len() >= 2 && b.grid.planes[axis][split_at - 1] == mid {
            let (lb, rb) = kd::halves(&bounds, axis, mid);
            let (mut left, mut right) = (r.clone(), r.clone());
            left[axis] = ra.start..split_at;
            right[axis] = split_at..ra.end;
            let l = self.node(out, b, left, lb, depth + 1)?;
            let r = self.node(out, b, right, rb, depth + 1)?;
            return out.parent(bounds, count, depth, self.m, l, r);
        }
        // The grid cannot split this node's longest axis: distribute it again, finer, reading
        // its buckets through a second handle while the new blocks are appended.
        debug_assert_eq!(b.grid.range_bounds(&r), bounds);
        let grid = self.grid(bounds, count);
        self.redistributions += 1;
        let reader = self
            .spill
            .file
            .try_clone()
            .map_err(|e| LodError::io(&self.spill.path, e))?;
        let path = self.spill.path.clone();
        let cells: Vec<usize> = b.cells(&r).collect();
        let mut source = |f: &mut dyn FnMut(&[Record]) -> Result<(), LodError>| {
            let mut buf = Vec::new();
            for &c in &cells {
                for &(off, n) in &b.blocks[c] {
                    buf.clear();
                    read_at(&reader, &path, off, n, &mut buf)?;
                    f(&buf)?;
                }
            }
            Ok(())
        };
        let sub = match self.distribute(grid, &mut source) {
            Ok(s) => s,
            Err(Distribute::Fail(e)) => return Err(e),
            Err(Distribute::Outside(_)) => {
                return Err(LodError::Invalid(
                    "internal error: a point left its node's box while refining".into(),
                ))
            }
        };
        let full = sub.grid.full();
        self.node(out, &sub, full, bounds, depth)
    }
}

fn read_at(
    file: &File,
    path: &Path,
    offset: u64,
    count: u32,
    into: &mut Vec<Record>,
) -> Result<(), LodError> {
    let start = into.len();
    into.resize(start + count as usize, Record::zeroed());
    let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut into[start..]);
    file.read_exact_at(bytes, offset)
        .map_err(|e| LodError::io(path, e))
}
