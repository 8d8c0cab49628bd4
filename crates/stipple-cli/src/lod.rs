//! `.stlod` trees in `render`, `bench` and `info` (built by `cmd::build_lod`).

use crate::args::{CameraArgs, PipelineArgs};
use crate::Result;
use anyhow::{anyhow, Context};
use glam::DVec3;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use stipple_core::{Camera, PointCloud};
use stipple_lod::mem::{parse_count, parse_size};
use stipple_lod::stream::Payload;
use stipple_lod::{LodTree, SelectOptions, Selection, Streamer};
use stipple_render::{PreparedCloud, Renderer};

/// Options for drawing a tree, shared by `render` and `bench`.
#[derive(clap::Args, Clone)]
pub struct LodArgs {
    /// For a .stlod tree or a COPC file: the most points drawn in a frame (e.g. 5M).
    #[arg(long, default_value = "5M", value_parser = parse_count, value_name = "N")]
    pub point_budget: u64,
    /// For a .stlod tree or a COPC file: refine until samples are at most this many pixels
    /// apart on screen.
    #[arg(long, default_value_t = 1.0, value_name = "PX", value_parser = crate::args::finite_f32)]
    pub lod_error: f32,
    /// For a .stlod tree or a COPC file in `view`: memory for cached node payloads
    /// (default: 4 × the point budget's size, at least 1 GiB).
    #[arg(long, value_parser = parse_size, value_name = "SIZE")]
    pub cache: Option<u64>,
    /// For a .stlod tree: background threads loading nodes (1 to 64).
    #[arg(long, default_value_t = 2, value_name = "N", value_parser = loaders_64)]
    pub loaders: usize,
}

/// A thread count from 1 to `max`.
fn thread_count(s: &str, max: usize) -> std::result::Result<usize, String> {
    let n: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("`{}` is not a whole number", stipple_io::shown(s)))?;
    if (1..=max).contains(&n) {
        Ok(n)
    } else {
        Err(format!("{n} threads: give 1 to {max}"))
    }
}

pub fn threads_1024(s: &str) -> std::result::Result<usize, String> {
    thread_count(s, 1024)
}

fn loaders_64(s: &str) -> std::result::Result<usize, String> {
    thread_count(s, 64)
}

impl LodArgs {
    fn select_options(&self, tree: &LodTree) -> Result<SelectOptions> {
        let m = tree.header.max_node_points as u64;
        if self.point_budget < m {
            return Err(anyhow!(
                "--point-budget {} is smaller than one node of this tree ({m} points)",
                self.point_budget
            ));
        }
        if !(self.lod_error > 0.0 && self.lod_error.is_finite()) {
            return Err(anyhow!(
                "--lod-error {}: must be a positive number of pixels",
                self.lod_error
            ));
        }
        Ok(SelectOptions {
            point_budget: self.point_budget,
            max_error_px: self.lod_error,
        })
    }

    fn cache_bytes(&self) -> u64 {
        self.cache
            .unwrap_or((self.point_budget * 16 * 4).max(1 << 30))
            .max(self.point_budget * 16 * 2)
    }
}

/// Whether an input names a tree: by extension, or by its magic.
pub fn is_tree(p: &Path) -> bool {
    stipple_io::extension(p) == "stlod" || stipple_lod::is_tree(p)
}

pub fn open(p: &Path) -> Result<Arc<LodTree>> {
    Ok(LodTree::open(p).map(Arc::new)?)
}

/// The cloud to draw from resident payloads: positions relative to the tree's origin,
/// colours when the tree has them. The spacing is the point-weighted median of the projected
/// spacing each point is drawn at, expressed at the cloud's centre (what the automatic
/// settings expect). The tree is additive, so a point is drawn at the spacing of the deepest
/// drawn node whose box holds it: a drawn node's points count for its drawn children in
/// proportion to their boxes' points, and for itself only where its children are not drawn.
pub fn cut_cloud(tree: &LodTree, parts: &[(u32, Payload)], camera: &Camera) -> PreparedCloud {
    let n: usize = parts.iter().map(|p| p.1.len()).sum();
    let mut positions = Vec::with_capacity(n);
    let coloured = tree.header.has_colour();
    let mut colors = Vec::with_capacity(if coloured { n } else { 0 });
    for (_, recs) in parts {
        positions.extend(recs.iter().map(|r| r.p()));
        if coloured {
            colors.extend(recs.iter().map(|r| r.rgb));
        }
    }
    let b = camera.basis();
    let (_, sy) = camera.ndc_scale();
    let spacing_px = |node: &stipple_lod::Node| {
        let c = tree.header.origin + node.bounds.center().as_dvec3();
        let depth = (c - camera.eye).dot(b.forward).max(camera.near);
        let scale = match camera.projection {
            stipple_core::Projection::Perspective { .. } => sy * 0.5 * camera.height as f64 / depth,
            stipple_core::Projection::Orthographic { .. } => sy * 0.5 * camera.height as f64,
        };
        (node.spacing as f64 * scale) as f32
    };
    // Parents before children: node ids are breadth first.
    let mut order: Vec<(u32, usize)> = parts.iter().map(|(id, r)| (*id, r.len())).collect();
    order.sort_unstable_by_key(|p| p.0);
    let drawn: std::collections::HashMap<u32, usize> =
        order.iter().enumerate().map(|(k, p)| (p.0, k)).collect();
    let mut carried = vec![0f64; order.len()];
    let mut px: Vec<(f32, f64)> = Vec::with_capacity(order.len());
    for (k, &(id, len)) in order.iter().enumerate() {
        let node = &tree.nodes[id as usize];
        let mut own = len as f64 + carried[k];
        if !node.is_leaf() && node.subtree_points > 0 {
            for c in node.children {
                if let Some(&j) = drawn.get(&c) {
                    let share = own.min(
                        (len as f64 + carried[k]) * tree.nodes[c as usize].subtree_points as f64
                            / node.subtree_points as f64,
                    );
                    carried[j] += share;
                    own -= share;
                }
            }
        }
        px.push((spacing_px(node), own));
    }
    px.sort_by(|a, b| a.0.total_cmp(&b.0));
    let half = n as f64 / 2.0;
    let mut acc = 0.0;
    let median_px = px
        .iter()
        .find(|(_, k)| {
            acc += k;
            acc > half
        })
        .map(|p| p.0)
        .unwrap_or(1.0);
    let cloud = PointCloud {
        origin: tree.header.origin,
        positions,
        colors: coloured.then_some(colors),
        ..Default::default()
    };
    // World spacing that projects to `median_px` at the cloud's centre.
    let probe = PreparedCloud::with_spacing(cloud, 1.0);
    let px_per_unit = probe.screen_spacing(camera);
    let spacing = if px_per_unit.is_finite() && px_per_unit > 0.0 && median_px > 0.0 {
        median_px / px_per_unit
    } else {
        tree.nodes[0].spacing
    };
    PreparedCloud::with_spacing(probe.cloud, spacing)
}

/// Opens a tree and its camera.
pub fn open_with_camera(p: &Path, camera: &CameraArgs) -> Result<(Arc<LodTree>, Camera)> {
    let tree = open(p)?;
    let (lo, hi) = tree.world_bounds();
    let cam = camera
        .build_framed(lo, hi, tree.header.z_up())
        .with_context(|| p.display().to_string())?;
    Ok((tree, cam))
}

/// A tree streamed as the view moves (`stipple view`): nodes are requested for each camera
/// and loaded on background threads; a cut is drawn from what is resident, missing nodes
/// standing in by their nearest resident ancestor, so a frame never waits for the disk. A
/// COPC file beyond the point budget streams alike ([`CopcStream`]).
pub struct TreeStream {
    source: StreamSource,
}

enum StreamSource {
    Tree {
        tree: Arc<LodTree>,
        streamer: Streamer,
        opts: SelectOptions,
    },
    Copc(CopcStream),
}

impl TreeStream {
    /// A `.stlod` tree, or a COPC file (`stipple_io::copc::is_copc`).
    pub fn open(p: &Path, lod: &LodArgs) -> Result<TreeStream> {
        if stipple_io::copc::is_copc(p) && !is_tree(p) {
            return Ok(TreeStream {
                source: StreamSource::Copc(CopcStream::open(p, lod)?),
            });
        }
        let tree = open(p)?;
        let opts = lod.select_options(&tree)?;
        let streamer = Streamer::new(tree.clone(), lod.cache_bytes(), lod.loaders)?;
        Ok(TreeStream {
            source: StreamSource::Tree {
                tree,
                streamer,
                opts,
            },
        })
    }

    /// The point budget of a full cut.
    pub fn point_budget(&self) -> u64 {
        match &self.source {
            StreamSource::Tree { opts, .. } => opts.point_budget,
            StreamSource::Copc(c) => c.budget,
        }
    }

    /// The fewest points a cut can hold (one node).
    pub fn least_budget(&self) -> u64 {
        match &self.source {
            StreamSource::Tree { tree, .. } => tree.header.max_node_points as u64,
            StreamSource::Copc(c) => c.least,
        }
    }

    /// The cut for `camera` from the resident nodes (requesting the missing ones), within
    /// `budget` points when given (a coarser cut while the view moves), and how many of the
    /// cut's nodes are still loading.
    pub fn cut(&self, camera: &Camera, budget: Option<u64>) -> Result<(PreparedCloud, usize)> {
        let budget = budget.map(|b| b.clamp(self.least_budget(), self.point_budget()));
        let (tree, streamer, opts) = match &self.source {
            StreamSource::Tree {
                tree,
                streamer,
                opts,
            } => (tree, streamer, opts),
            StreamSource::Copc(c) => return c.cut(camera, budget),
        };
        if let Some(e) = streamer.error() {
            return Err(anyhow::Error::msg(e));
        }
        let mut opts = *opts;
        if let Some(b) = budget {
            opts.point_budget = b;
        }
        let sel = stipple_lod::select(tree, camera, &opts);
        streamer.request(&sel.nodes);
        let (parts, missing) = streamer.resident_cut(&sel.nodes);
        Ok((cut_cloud(tree, &parts, camera), missing))
    }

    /// Nodes loaded so far (a change means a better cut may be ready).
    pub fn loads(&self) -> u64 {
        match &self.source {
            StreamSource::Tree { streamer, .. } => streamer.stats().loads,
            StreamSource::Copc(c) => c.shared.loads.load(Ordering::Relaxed),
        }
    }
}

/// A COPC file streamed as the view moves: each camera's cut is chosen as `render` chooses
/// it ([`load_copc_cut`]); the nodes not yet decoded are decoded on a background thread
/// (nodes in parallel) while the frame draws the resident ones. COPC stores each point once,
/// so a node still loading leaves its part of the view sparser (its ancestors are drawn)
/// rather than standing in by an ancestor. Decoded nodes are kept up to `--cache`; beyond
/// it, nodes outside the latest cut are dropped.
pub struct CopcStream {
    copc: Arc<stipple_io::copc::Copc>,
    origin: DVec3,
    budget: u64,
    least: u64,
    root: usize,
    max_px: f64,
    cache_bytes: u64,
    shared: Arc<CopcShared>,
    requests: std::sync::mpsc::Sender<Vec<usize>>,
}

#[derive(Default)]
struct CopcShared {
    resident: std::sync::Mutex<std::collections::HashMap<usize, Arc<PointCloud>>>,
    pending: std::sync::Mutex<std::collections::HashSet<usize>>,
    loads: AtomicU64,
    error: std::sync::Mutex<Option<String>>,
}

/// Bytes a decoded point takes in the cache (position, attributes, colour).
const COPC_POINT_BYTES: u64 = 24;

impl CopcStream {
    fn open(p: &Path, lod: &LodArgs) -> Result<CopcStream> {
        let copc = Arc::new(stipple_io::copc::Copc::open(p)?);
        if !(lod.lod_error > 0.0 && lod.lod_error.is_finite()) {
            return Err(anyhow!(
                "--lod-error {}: must be a positive number of pixels",
                lod.lod_error
            ));
        }
        let least = copc.nodes.iter().map(|n| n.point_count).max().unwrap_or(1);
        let shift = copc.colour_shift()?;
        let origin = copc_origin(&copc);
        let shared = Arc::new(CopcShared::default());
        // The root, decoded now: the first frame draws it while the rest of its cut
        // decodes, and a cut that holds nothing else (the camera looks away) still has it.
        let root = copc
            .root()
            .ok_or_else(|| anyhow!("{}: the COPC hierarchy holds no points", p.display()))?;
        let c = copc.read_nodes_with(&[root], origin, Some(shift))?;
        shared.resident.lock().unwrap().insert(root, Arc::new(c));
        let (requests, rx) = std::sync::mpsc::channel::<Vec<usize>>();
        {
            let (copc, shared) = (copc.clone(), shared.clone());
            std::thread::Builder::new()
                .name("copc nodes".into())
                .spawn(move || {
                    use rayon::prelude::*;
                    // Ends when the stream (the sender) is dropped.
                    while let Ok(nodes) = rx.recv() {
                        nodes.par_iter().for_each(|&i| {
                            let r = copc.read_nodes_with(&[i], origin, Some(shift));
                            match r {
                                Ok(c) => {
                                    shared.resident.lock().unwrap().insert(i, Arc::new(c));
                                    shared.loads.fetch_add(1, Ordering::Relaxed);
                                }
                                Err(e) => *shared.error.lock().unwrap() = Some(e.to_string()),
                            }
                            shared.pending.lock().unwrap().remove(&i);
                        });
                    }
                })
                .context("starting the COPC node decoder")?;
        }
        Ok(CopcStream {
            copc,
            origin,
            budget: lod.point_budget.max(least),
            least,
            root,
            max_px: lod.lod_error as f64,
            cache_bytes: lod.cache_bytes(),
            shared,
            requests,
        })
    }

    fn cut(&self, camera: &Camera, budget: Option<u64>) -> Result<(PreparedCloud, usize)> {
        if let Some(e) = self.shared.error.lock().unwrap().clone() {
            return Err(anyhow::Error::msg(e));
        }
        let sel = copc_selection(
            &self.copc,
            camera,
            budget.unwrap_or(self.budget),
            self.max_px,
        );
        let mut resident = self.shared.resident.lock().unwrap();
        let missing: Vec<usize> = sel
            .iter()
            .copied()
            .filter(|i| !resident.contains_key(i))
            .collect();
        {
            let mut pending = self.shared.pending.lock().unwrap();
            let ask: Vec<usize> = missing
                .iter()
                .copied()
                .filter(|&i| pending.insert(i))
                .collect();
            if !ask.is_empty() && self.requests.send(ask).is_err() {
                return Err(anyhow!("the COPC node decoder stopped"));
            }
        }
        // The cut's resident nodes, taken under the lock and joined after it: decoding
        // threads wait on it, and the cloud's preparation below runs on the same pool.
        let mut parts: Vec<Arc<PointCloud>> = sel
            .iter()
            .filter_map(|i| resident.get(i).cloned())
            .collect();
        if parts.is_empty() {
            parts.extend(resident.get(&self.root).cloned());
        }
        // Over the cache's size: keep the nodes of this cut, and the root.
        let held: u64 = resident.values().map(|c| c.len() as u64).sum();
        if held * COPC_POINT_BYTES > self.cache_bytes {
            let keep: std::collections::HashSet<usize> = sel.iter().copied().collect();
            resident.retain(|i, _| *i == self.root || keep.contains(i));
        }
        drop(resident);
        let mut cloud = PointCloud {
            origin: self.origin,
            z_up: true,
            ..Default::default()
        };
        for c in &parts {
            cloud.append(c);
        }
        Ok((PreparedCloud::new(cloud), missing.len()))
    }
}

/// The origin a COPC file's clouds are expressed in: the centre of its header's bounds,
/// rounded (the same for every cut).
fn copc_origin(copc: &stipple_io::copc::Copc) -> DVec3 {
    ((copc.min + copc.max) * 0.5).round()
}

/// The nodes `render` and the viewer draw of a COPC file for `camera`: coarse levels first,
/// finer ones where they are close, until `budget` points or `max_px` pixels between samples.
fn copc_selection(
    copc: &stipple_io::copc::Copc,
    camera: &Camera,
    budget: u64,
    max_px: f64,
) -> Vec<usize> {
    stipple_io::copc::select_nodes(copc, budget, |lo, hi, s| {
        node_detail(camera, (lo + hi) * 0.5, (hi - lo).length() * 0.5, s, max_px)
    })
}

/// For `render`: the complete cut for the camera (waiting for its nodes, with a spinner).
pub fn load_cut(
    p: &Path,
    camera: &CameraArgs,
    lod: &LodArgs,
) -> Result<(PreparedCloud, String, Camera)> {
    let (tree, cam) = open_with_camera(p, camera)?;
    let opts = lod.select_options(&tree)?;
    let sel = stipple_lod::select(&tree, &cam, &opts);
    let streamer = Streamer::new(tree.clone(), lod.cache_bytes(), lod.loaders)?;
    streamer.request(&sel.nodes);
    let bar = indicatif::ProgressBar::new_spinner();
    bar.enable_steady_tick(Duration::from_millis(120));
    loop {
        let st = streamer.stats();
        bar.set_message(format!(
            "loading {} nodes ({} points): {} to go",
            sel.nodes.len(),
            sel.points,
            st.queued + st.in_flight
        ));
        if streamer.wait_idle(Duration::from_millis(200)) {
            break;
        }
    }
    bar.finish_and_clear();
    if let Some(e) = streamer.error() {
        return Err(anyhow::Error::msg(e));
    }
    let (parts, _) = streamer.resident_cut(&sel.nodes);
    let cloud = cut_cloud(&tree, &parts, &cam);
    let label = format!(
        "{} (cut of {} nodes{}, {} of {} points)",
        p.display(),
        sel.nodes.len(),
        if sel.budget_limited {
            ", limited by --point-budget"
        } else {
            ""
        },
        sel.points,
        tree.header.point_count
    );
    Ok((cloud, label, cam))
}

/// `stipple info` for a tree.
pub fn info(p: &Path, verify: bool) -> Result<()> {
    let tree = open(p)?;
    let h = &tree.header;
    let (lo, hi) = tree.world_bounds();
    let leaves = tree.nodes.iter().filter(|n| n.is_leaf()).count();
    let stored: u64 = tree.nodes.iter().map(|n| n.payload_bytes as u64).sum();
    let records = h.point_count * stipple_lod::Record::SIZE as u64;
    println!(
        "{} (stipple LOD tree, format {})",
        p.display(),
        stipple_lod::format::VERSION
    );
    println!("  points      {}", h.point_count);
    println!(
        "  nodes       {} ({leaves} leaves, depth {}), M = {}",
        h.node_count,
        tree.depth(),
        h.max_node_points
    );
    let size = |b: u64| {
        if b < 1 << 20 {
            format!("{:.1} KiB", b as f64 / 1024.0)
        } else {
            format!("{:.1} MiB", b as f64 / (1 << 20) as f64)
        }
    };
    println!(
        "  payloads    {}, each point stored once ({}: {:.2}× its {} of records)",
        size(stored),
        if h.codec == stipple_lod::format::CODEC_RAW {
            "uncompressed"
        } else {
            "LZ4"
        },
        stored as f64 / records.max(1) as f64,
        size(records)
    );
    println!("  bounds min  {:.4} {:.4} {:.4}", lo.x, lo.y, lo.z);
    println!("  bounds max  {:.4} {:.4} {:.4}", hi.x, hi.y, hi.z);
    println!(
        "  attributes  position{}",
        if h.has_colour() { ", color" } else { "" }
    );
    println!(
        "  root        {} samples, spacing {:.4}",
        tree.root().sample_count,
        tree.root().spacing
    );
    if verify {
        let t0 = Instant::now();
        tree.verify()?;
        println!(
            "  checksums   all {} payloads verified in {:.1} s",
            h.node_count,
            t0.elapsed().as_secs_f64()
        );
    } else {
        println!("  checksums   header and node table verified (--verify reads every payload)");
    }
    Ok(())
}

/// `stipple bench` for a tree: time to first image, frames until the cut is resident, and
/// steady frames.
pub fn bench(
    p: &Path,
    camera: &CameraArgs,
    pipeline: &PipelineArgs,
    lod: &LodArgs,
    r: &mut Renderer,
    frames: usize,
) -> Result<()> {
    let t0 = Instant::now();
    let (tree, cam) = open_with_camera(p, camera)?;
    let opts = lod.select_options(&tree)?;
    let streamer = Streamer::new(tree.clone(), lod.cache_bytes(), lod.loaders)?;
    let open_ms = t0.elapsed().as_secs_f64() * 1e3;
    let pipe = pipeline.build_for(false)?;
    let mut first_ms = None;
    let mut converged: Option<(usize, f64)> = None;
    let mut cloud: Option<(Vec<u32>, PreparedCloud)> = None;
    let mut sel = Selection::default();
    let mut select_ms = Vec::new();
    let mut compose_ms = Vec::new();
    let mut frame_ms = Vec::new();
    let mut k = 0;
    // Refining frames (bounded so that a cut that never fits the cache cannot loop forever).
    while converged.is_none() && k < 100_000 {
        let t = Instant::now();
        sel = stipple_lod::select(&tree, &cam, &opts);
        streamer.request(&sel.nodes);
        select_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let (parts, missing) = streamer.resident_cut(&sel.nodes);
        let ids: Vec<u32> = parts.iter().map(|p| p.0).collect();
        if cloud.as_ref().is_none_or(|c| c.0 != ids) {
            let t = Instant::now();
            cloud = Some((ids, cut_cloud(&tree, &parts, &cam)));
            compose_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        r.render(&cloud.as_ref().unwrap().1, &cam, &pipe)?;
        k += 1;
        if first_ms.is_none() {
            first_ms = Some(t0.elapsed().as_secs_f64() * 1e3);
        }
        if let Some(e) = streamer.error() {
            return Err(anyhow::Error::msg(e));
        }
        if missing == 0 {
            converged = Some((k, t0.elapsed().as_secs_f64() * 1e3));
        }
    }
    let (_, c) = cloud.unwrap();
    for _ in 0..frames {
        let t = Instant::now();
        let s = stipple_lod::select(&tree, &cam, &opts);
        streamer.request(&s.nodes);
        r.render(&c, &cam, &pipe)?;
        frame_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let med = |v: &mut Vec<f64>| crate::figures::median(v);
    let st = streamer.stats();
    println!(
        "stipple bench: {} ({} points, {} nodes), {}x{}, {}",
        p.display(),
        tree.header.point_count,
        tree.nodes.len(),
        cam.width,
        cam.height,
        r.describe()
    );
    println!(
        "  cut               {} nodes, {} points (budget {}{}), error ≤ {} px",
        sel.nodes.len(),
        sel.points,
        lod.point_budget,
        if sel.budget_limited { ", binding" } else { "" },
        lod.lod_error
    );
    println!("  open + root       {open_ms:>9.1} ms");
    println!(
        "  first image       {:>9.1} ms after start",
        first_ms.unwrap_or(f64::NAN)
    );
    if let Some((frames_to, ms)) = converged {
        println!("  cut resident      {ms:>9.1} ms after start, after {frames_to} frames");
    }
    println!(
        "  select            {:>9.3} ms (median)",
        med(&mut select_ms)
    );
    println!(
        "  compose cut       {:>9.1} ms (median over {} changes of the drawn set)",
        med(&mut compose_ms),
        compose_ms.len()
    );
    let t = med(&mut frame_ms);
    println!(
        "  frame             {t:>9.2} ms   ({:.1} fps; select + render of the resident cut, median of {frames})",
        1e3 / t
    );
    println!(
        "  cache             {} nodes, {} MiB, {} loads, {} evictions",
        st.resident_nodes,
        st.resident_bytes >> 20,
        st.loads,
        st.evictions
    );
    Ok(())
}

/// How much detail a node of `spacing` (world units) within the sphere (`centre`, `radius`)
/// adds to `camera`'s view: its spacing in pixels at the sphere's nearest depth, or −1 when
/// the sphere lies outside the view, or when the node's parent (twice the spacing) was
/// already at most `max_px` apart on screen.
pub fn node_detail(camera: &Camera, centre: DVec3, radius: f64, spacing: f64, max_px: f64) -> f64 {
    let b = camera.basis();
    let v = centre - camera.eye;
    let (x, y, z) = (v.dot(b.right), v.dot(b.up), v.dot(b.forward));
    let (sx, sy) = camera.ndc_scale();
    let half_h = 0.5 * camera.height as f64;
    let px = match camera.projection {
        stipple_core::Projection::Perspective { .. } => {
            if z + radius < camera.near {
                return -1.0;
            }
            // Outside a side plane (through the eye, where ndc = ±1) by more than the radius.
            let out = |a: f64, s: f64| (a.abs() - z / s) / (1.0 + 1.0 / (s * s)).sqrt() > radius;
            if out(x, sx) || out(y, sy) {
                return -1.0;
            }
            spacing * sy * half_h / (z - radius).max(camera.near)
        }
        stipple_core::Projection::Orthographic { .. } => {
            if x.abs() - radius > 1.0 / sx || y.abs() - radius > 1.0 / sy {
                return -1.0;
            }
            spacing * sy * half_h
        }
    };
    if 2.0 * px <= max_px {
        -1.0
    } else {
        px
    }
}

/// A COPC file that holds more points than `--point-budget`, opened and checked, with the
/// camera the arguments give for it (framing its header's bounds, Z up); None for a file
/// within the budget, which is read whole. Such a file is drawn as a tree is, a cut per
/// camera (the Python package renders it so).
pub fn open_copc_cut(
    p: &Path,
    camera: &CameraArgs,
    lod: &LodArgs,
) -> Result<Option<(stipple_io::copc::Copc, Camera)>> {
    let copc = stipple_io::copc::Copc::open(p)?;
    if copc.point_count <= lod.point_budget {
        return Ok(None);
    }
    if !(lod.lod_error > 0.0 && lod.lod_error.is_finite()) {
        return Err(anyhow!(
            "--lod-error {}: must be a positive number of pixels",
            lod.lod_error
        ));
    }
    let cam = camera
        .build_framed(copc.min, copc.max, true)
        .with_context(|| p.display().to_string())?;
    Ok(Some((copc, cam)))
}

/// A COPC file larger than the point budget, as `render` draws it: the nodes the camera
/// needs (coarse levels first, finer ones where they are close, until `--point-budget`
/// points or `--lod-error` pixels between samples), decoded alone instead of the whole
/// file. None when the file holds no more points than the budget (it is then read whole).
pub fn load_copc_cut(
    p: &Path,
    camera: &CameraArgs,
    lod: &LodArgs,
) -> Result<Option<(PreparedCloud, String, Camera)>> {
    let Some((copc, cam)) = open_copc_cut(p, camera, lod)? else {
        return Ok(None);
    };
    let sel = copc_selection(&copc, &cam, lod.point_budget, lod.lod_error as f64);
    let points: u64 = sel.iter().map(|&i| copc.nodes[i].point_count).sum();
    let bar = indicatif::ProgressBar::new_spinner();
    bar.enable_steady_tick(Duration::from_millis(120));
    bar.set_message(format!(
        "decoding {} of {} COPC nodes ({points} points)",
        sel.len(),
        copc.nodes.len()
    ));
    let origin = copc_origin(&copc);
    // The root's colour shift, as the viewer streams it node by node.
    let cloud = copc
        .colour_shift()
        .and_then(|shift| copc.read_nodes_with(&sel, origin, Some(shift)));
    bar.finish_and_clear();
    let cloud = cloud?;
    let label = format!(
        "{} (COPC: {} of {} nodes, {points} of {} points, for this view within --point-budget {})",
        p.display(),
        sel.len(),
        copc.nodes.len(),
        copc.point_count,
        lod.point_budget
    );
    Ok(Some((PreparedCloud::new(cloud), label, cam)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cut has the spacing of its frontier (its nodes without drawn children), where all
    /// points of a region are drawn: each point is drawn at its deepest drawn node's spacing, not at that of the
    /// inner node storing it (counting an inner node's points at its coarse spacing gave the
    /// visibility kernel and the fills a spacing up to 1.5× too large: Autzen's kernel 10
    /// instead of 8).
    #[test]
    fn a_cut_has_the_spacing_of_its_frontier() {
        let dir = std::env::temp_dir().join(format!("stipple-cut-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut rng = stipple_core::rng::Rng::new(3);
        let world: Vec<DVec3> = (0..200_000)
            .map(|_| {
                let (x, y) = (rng.f64() * 100.0, rng.f64() * 60.0);
                DVec3::new(637_000.0 + x, 850_000.0 + y, 100.0 + (x * 0.1).sin())
            })
            .collect();
        let cloud = PointCloud::from_world(&world);
        let las = dir.join("a.las");
        stipple_io::las_io::write_las(&las, &cloud, false).unwrap();
        let out = dir.join("t.stlod");
        let o = stipple_lod::BuildOptions {
            max_node_points: 2048,
            ..Default::default()
        };
        stipple_lod::build(&[las], &out, &o).unwrap();
        let tree = LodTree::open(&out).unwrap();
        let parts: Vec<(u32, Payload)> = (0..tree.nodes.len() as u32)
            .map(|i| (i, Arc::new(tree.read_node(i).unwrap())))
            .collect();
        // Inner nodes store a good share of the points, at coarser spacings.
        let inner: u64 = parts
            .iter()
            .filter(|p| !tree.nodes[p.0 as usize].is_leaf())
            .map(|p| p.1.len() as u64)
            .sum();
        assert!(inner > 200_000 / 5, "{inner} points in inner nodes");
        // Orthographic: one scale everywhere, so the cut's spacing is a node spacing.
        let (lo, hi) = tree.world_bounds();
        let mut cam = Camera::framing(lo, hi, 800, 600, 50.0);
        cam.projection = stipple_core::Projection::Orthographic { height: 80.0 };
        // The whole tree, and its top levels alone (the frontier's points then share their
        // regions with as many of their ancestors' points).
        let levels = tree.depth();
        for depth in [levels, 3, 5] {
            let cut: Vec<(u32, Payload)> = parts
                .iter()
                .filter(|p| tree.nodes[p.0 as usize].depth <= depth)
                .cloned()
                .collect();
            let got = cut_cloud(&tree, &cut, &cam).spacing;
            // The frontier's spacing, weighted by the points in its nodes' boxes.
            let mut front: Vec<(f32, u64)> = tree
                .nodes
                .iter()
                .filter(|n| (n.is_leaf() && n.depth <= depth) || n.depth == depth)
                .filter(|n| n.subtree_points > 0)
                .map(|n| (n.spacing, n.subtree_points))
                .collect();
            front.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut acc = 0;
            let want = front
                .iter()
                .find(|l| {
                    acc += l.1;
                    acc > 100_000
                })
                .unwrap()
                .0;
            let ratio = got / want;
            assert!(
                (0.9..1.1).contains(&ratio),
                "depth {depth}: cut spacing {got} against its frontier's {want}"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
