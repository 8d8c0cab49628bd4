//! Build, storage, selection and streaming of LOD trees on synthetic LAS inputs.

use glam::{DVec3, Vec3};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use stipple_core::{Camera, PointCloud};
use stipple_lod::format::NONE;
use stipple_lod::select::select_nodes;
use stipple_lod::{build, BuildOptions, LodTree, Record, SelectOptions, Streamer};

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("stipple-lod-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A terrain-like cloud (a wavy 200 m × 120 m sheet) plus a dense cluster (a small ball),
/// in LiDAR-like world coordinates, with colours.
fn terrain(n_sheet: usize, n_ball: usize, seed: u64) -> PointCloud {
    let mut rng = stipple_core::rng::Rng::new(seed);
    let base = DVec3::new(637_000.0, 850_000.0, 100.0);
    let mut pts = Vec::new();
    let mut cols = Vec::new();
    for _ in 0..n_sheet {
        let (x, y) = (rng.f64() * 200.0, rng.f64() * 120.0);
        let z = 3.0 * (x * 0.05).sin() * (y * 0.07).cos();
        pts.push(base + DVec3::new(x, y, z));
        cols.push([(x * 1.2) as u8, (y * 2.0) as u8, 90]);
    }
    for _ in 0..n_ball {
        let d = DVec3::new(rng.f64() - 0.5, rng.f64() - 0.5, rng.f64() - 0.5) * 0.4;
        pts.push(base + DVec3::new(61.3, 41.7, 5.0) + d);
        cols.push([250, 20, 20]);
    }
    let mut c = PointCloud::from_world(&pts);
    c.colors = Some(cols);
    c
}

fn write_las(dir: &Path, name: &str, c: &PointCloud) -> PathBuf {
    let p = dir.join(name);
    stipple_io::las_io::write_las(&p, c, false).unwrap();
    p
}

/// The records the build reads from `inputs`, relative to `origin`, sorted.
fn input_records(inputs: &[PathBuf], origin: DVec3) -> Vec<Record> {
    let mut all = Vec::new();
    for i in stipple_lod::source::open_inputs(inputs, 1 << 30).unwrap() {
        i.read(origin, 1 << 16, &mut |b| {
            all.extend_from_slice(b);
            Ok(())
        })
        .unwrap();
    }
    sort(&mut all);
    all
}

fn sort(v: &mut [Record]) {
    v.sort_by_key(|r| (r.pos.map(f32::to_bits), r.rgb));
}

fn inside(b: &stipple_core::Bounds, p: Vec3) -> bool {
    p.cmpge(b.min).all() && p.cmple(b.max).all()
}

/// Checks the tree invariants of the issue against the inputs.
fn check_invariants(tree: &LodTree, inputs: &[PathBuf]) {
    let m = tree.header.max_node_points;
    let mut stored = Vec::new();
    for (i, n) in tree.nodes.iter().enumerate() {
        let recs = tree.read_node(i as u32).unwrap();
        assert_eq!(recs.len(), n.sample_count as usize);
        for r in &recs {
            assert!(
                inside(&n.bounds, r.p()),
                "node {i}: {} outside {:?}",
                r.p(),
                n.bounds
            );
        }
        if n.is_leaf() {
            assert!(
                n.sample_count < m || n.depth >= stipple_lod::kd::MAX_DEPTH,
                "leaf {i} has {} ≥ M points",
                n.sample_count
            );
        } else {
            assert!(
                n.sample_count <= m,
                "inner node {i}: {} > M samples",
                n.sample_count
            );
            // At most one sample per cell of the node's spacing.
            let mut cells = std::collections::HashSet::new();
            for r in &recs {
                let c = ((r.p() - n.bounds.min) / n.spacing).floor().as_ivec3();
                assert!(
                    cells.insert(c.to_array()),
                    "node {i}: two samples in cell {c}"
                );
            }
            let [a, b] = n.children;
            let (ca, cb) = (&tree.nodes[a as usize], &tree.nodes[b as usize]);
            assert_eq!(
                ca.subtree_points + cb.subtree_points,
                n.subtree_points,
                "node {i}"
            );
            // The children are the two halves of the box at the midpoint of its longest axis.
            let (axis, mid) = stipple_lod::kd::split_plane(&n.bounds).unwrap();
            let (l, r) = stipple_lod::kd::halves(&n.bounds, axis, mid);
            assert_eq!((ca.bounds, cb.bounds), (l, r), "node {i}'s children");
            assert!(n.subtree_points >= m as u64);
        }
        stored.extend(recs);
    }
    assert_eq!(tree.root().subtree_points, tree.header.point_count);
    // Every input point is stored exactly once: the nodes' records are the input's.
    sort(&mut stored);
    let want = input_records(inputs, tree.header.origin);
    assert_eq!(stored.len(), want.len());
    assert!(
        stored == want,
        "the nodes do not hold exactly the input points, each once"
    );
}

#[test]
fn in_memory_build_keeps_the_invariants_and_is_deterministic() {
    let dir = scratch("inmem");
    let a = write_las(&dir, "a.las", &terrain(60_000, 5_000, 1));
    let b = write_las(&dir, "b.las", &terrain(30_000, 0, 2));
    let inputs = vec![a, b];
    let o = BuildOptions {
        max_node_points: 1024,
        ..Default::default()
    };
    let r = build(&inputs, &dir.join("t1.stlod"), &o).unwrap();
    assert!(!r.out_of_core);
    assert_eq!(r.points, 95_000);
    let tree = LodTree::open(&dir.join("t1.stlod")).unwrap();
    assert!(tree.nodes.len() > 100, "{} nodes", tree.nodes.len());
    assert!(tree.header.has_colour());
    check_invariants(&tree, &inputs);
    build(&inputs, &dir.join("t2.stlod"), &o).unwrap();
    let (x, y) = (
        std::fs::read(dir.join("t1.stlod")).unwrap(),
        std::fs::read(dir.join("t2.stlod")).unwrap(),
    );
    assert!(x == y, "two builds of the same input differ");
    // Uncompressed: the same tree, records stored as they are, and larger.
    let o = BuildOptions {
        codec: stipple_lod::format::CODEC_RAW,
        ..o
    };
    build(&inputs, &dir.join("raw.stlod"), &o).unwrap();
    let raw = LodTree::open(&dir.join("raw.stlod")).unwrap();
    assert_eq!(raw.nodes.len(), tree.nodes.len());
    for (i, (a, b)) in raw.nodes.iter().zip(&tree.nodes).enumerate() {
        assert_eq!((a.sample_count, a.spacing), (b.sample_count, b.spacing));
        assert_eq!(a.payload_bytes as u64, a.records_size());
        assert_eq!(
            raw.read_node(i as u32).unwrap(),
            tree.read_node(i as u32).unwrap()
        );
    }
    let raw_size = std::fs::metadata(dir.join("raw.stlod")).unwrap().len();
    assert!(
        raw_size > x.len() as u64 * 5 / 4,
        "{raw_size} vs {}",
        x.len()
    );
    // Each point once: the tree is the records and the node table, nothing more.
    assert_eq!(
        raw_size,
        256 + 95_000 * 16 + raw.nodes.len() as u64 * stipple_lod::format::NODE_SIZE
    );
    // No temporary files remain.
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn out_of_core_build_keeps_the_invariants_and_refines_dense_clusters() {
    let dir = scratch("ooc");
    // 16 MiB budget: chunks of at most ~170 K points, so 420 K points go out of core, and the
    // 220 K-point ball (inside one grid cell) must be distributed a second time.
    let a = write_las(&dir, "a.las", &terrain(200_000, 220_000, 3));
    let inputs = vec![a];
    let o = BuildOptions {
        max_node_points: 2048,
        memory: 16 << 20,
        ..Default::default()
    };
    let r = build(&inputs, &dir.join("t.stlod"), &o).unwrap();
    assert!(r.out_of_core);
    assert!(r.chunks > 2, "{r:?}");
    assert!(r.redistributions > 0, "{r:?}");
    assert!(r.largest_chunk <= (16 << 20) / 96, "{r:?}");
    let tree = LodTree::open(&dir.join("t.stlod")).unwrap();
    check_invariants(&tree, &inputs);
    build(&inputs, &dir.join("t2.stlod"), &o).unwrap();
    assert!(
        std::fs::read(dir.join("t.stlod")).unwrap() == std::fs::read(dir.join("t2.stlod")).unwrap(),
        "two out-of-core builds of the same input differ"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn wrong_header_bounds_are_survived_out_of_core() {
    let dir = scratch("bounds");
    let a = write_las(&dir, "a.las", &terrain(300_000, 0, 5));
    // LAS 1.2 header: max X is the f64 at byte 179, min X at 187. Claim the points end
    // half-way along x.
    let mut b = std::fs::read(&a).unwrap();
    let max_x = f64::from_le_bytes(b[179..187].try_into().unwrap());
    let min_x = f64::from_le_bytes(b[187..195].try_into().unwrap());
    b[179..187].copy_from_slice(&((min_x + max_x) * 0.5).to_le_bytes());
    std::fs::write(&a, &b).unwrap();
    let inputs = vec![a];
    let o = BuildOptions {
        max_node_points: 2048,
        memory: 16 << 20,
        ..Default::default()
    };
    let r = build(&inputs, &dir.join("t.stlod"), &o).unwrap();
    assert!(r.out_of_core);
    let tree = LodTree::open(&dir.join("t.stlod")).unwrap();
    let (lo, hi) = tree.world_bounds();
    assert!(hi.x >= max_x && lo.x <= min_x, "root box {lo}..{hi}");
    check_invariants(&tree, &inputs);
    let _ = std::fs::remove_dir_all(&dir);
}

fn small_tree(dir: &Path) -> PathBuf {
    let a = write_las(dir, "a.las", &terrain(40_000, 0, 4));
    let out = dir.join("t.stlod");
    build(
        &[a],
        &out,
        &BuildOptions {
            max_node_points: 1024,
            ..Default::default()
        },
    )
    .unwrap();
    out
}

fn open_err(p: &Path) -> String {
    LodTree::open(p).unwrap_err().to_string()
}

#[test]
fn corrupt_or_truncated_trees_fail_to_open_with_a_reason() {
    let dir = scratch("corrupt");
    let good = small_tree(&dir);
    let bytes = std::fs::read(&good).unwrap();
    let tree = LodTree::open(&good).unwrap();
    tree.verify().unwrap();
    let bad = dir.join("bad.stlod");
    let flip = |at: usize| {
        let mut b = bytes.clone();
        b[at] ^= 0x10;
        std::fs::write(&bad, &b).unwrap();
    };
    // Header.
    flip(40);
    assert!(
        open_err(&bad).contains("header's checksum"),
        "{}",
        open_err(&bad)
    );
    flip(2);
    assert!(open_err(&bad).contains("not a stipple LOD tree"));
    // Node table.
    flip(tree.header.table_offset as usize + 70);
    assert!(
        open_err(&bad).contains("node table's checksum"),
        "{}",
        open_err(&bad)
    );
    // A payload: the table is intact, so the tree opens, but reading the node (and verify)
    // reports it.
    let n = &tree.nodes[tree.nodes.len() / 2];
    flip(n.payload_offset as usize + 5);
    let t = LodTree::open(&bad).unwrap();
    let e = t.verify().unwrap_err().to_string();
    assert!(e.contains("checksum") && e.contains("bad.stlod"), "{e}");
    // Cut short, by one byte and by half.
    for len in [bytes.len() - 1, bytes.len() / 2, 100] {
        std::fs::write(&bad, &bytes[..len]).unwrap();
        let e = open_err(&bad);
        assert!(e.contains("cut short"), "{len}: {e}");
    }
    // Trailing garbage.
    let mut b = bytes.clone();
    b.extend_from_slice(&[0; 16]);
    std::fs::write(&bad, &b).unwrap();
    assert!(open_err(&bad).contains("after its end"));
    // An unfinished build's file: zeroed header.
    let mut b = bytes.clone();
    b[..256].fill(0);
    std::fs::write(&bad, &b).unwrap();
    assert!(open_err(&bad).contains("interrupted"), "{}", open_err(&bad));
    // A tree of an older format: refused, saying what to do.
    let mut b = bytes.clone();
    b[8..12].copy_from_slice(&1u32.to_le_bytes());
    std::fs::write(&bad, &b).unwrap();
    let e = open_err(&bad);
    assert!(e.contains("version 1") && e.contains("build-lod"), "{e}");
    // Not a tree at all.
    assert!(open_err(&dir.join("a.las")).contains("not a stipple LOD tree"));
    let _ = std::fs::remove_dir_all(&dir);
}

fn looking_down(eye: DVec3, target: DVec3) -> Camera {
    let mut c = Camera::framing(target, target, 800, 600, 50.0);
    c.eye = eye;
    c.target = target;
    c.up = DVec3::Y;
    c.near = 0.01;
    c.far = 1e6;
    c
}

#[test]
fn selection_respects_the_budget_refines_monotonically_and_culls() {
    let dir = scratch("select");
    let out = small_tree(&dir);
    let tree = LodTree::open(&out).unwrap();
    let (lo, hi) = tree.world_bounds();
    let c = (lo + hi) * 0.5;
    let parent = {
        let mut p = vec![NONE; tree.nodes.len()];
        for (i, n) in tree.nodes.iter().enumerate() {
            if !n.is_leaf() {
                p[n.children[0] as usize] = i as u32;
                p[n.children[1] as usize] = i as u32;
            }
        }
        p
    };
    let m = tree.header.max_node_points as u64;
    // Budgets: every cut fits, and a larger budget never selects fewer points.
    for h in [400.0, 150.0, 40.0, 10.0] {
        let cam = looking_down(c + DVec3::new(0.0, 0.0, h), c);
        let mut last = 0;
        for budget in [m, 3 * m, 10 * m, 40 * m, u64::MAX] {
            let s = tree_select(&tree, &cam, budget);
            assert!(s.points <= budget, "{} > {budget} at h = {h}", s.points);
            let sum: u64 = s
                .nodes
                .iter()
                .map(|&i| tree.nodes[i as usize].sample_count as u64)
                .sum();
            assert_eq!(sum, s.points);
            assert!(s.points >= last, "budget {budget}: {} < {last}", s.points);
            last = s.points;
            assert_eq!(s, tree_select(&tree, &cam, budget), "not deterministic");
            // A cut of an additive tree: a subtree, every node drawn with its parent.
            for &n in &s.nodes {
                let p = parent[n as usize];
                assert!(n == 0 || s.nodes.contains(&p), "{n} without its parent {p}");
            }
        }
    }
    // Approaching (descending over the centre): the cut only gets finer where still visible,
    // and the error order puts the nearest, largest nodes first.
    let mut prev: Option<Vec<u32>> = None;
    let mut refined = 0;
    let depth = |s: &[u32]| s.iter().map(|&i| tree.nodes[i as usize].depth).max();
    for h in [2000.0, 800.0, 300.0, 120.0, 50.0, 20.0, 8.0] {
        let cam = looking_down(c + DVec3::new(0.0, 0.0, h), c);
        let s = tree_select(&tree, &cam, u64::MAX);
        assert!(!s.budget_limited);
        assert!(s.errors.windows(2).all(|w| w[0] >= w[1]));
        if let Some(p) = &prev {
            assert!(
                depth(&s.nodes) >= depth(p),
                "at h = {h}, the cut got coarser"
            );
            // The centre's nodes stay, and gain children.
            let centre = |s: &[u32]| -> Vec<u32> {
                let at = (c - tree.header.origin).as_vec3();
                s.iter()
                    .copied()
                    .filter(|&i| inside(&tree.nodes[i as usize].bounds, at))
                    .collect()
            };
            let (was, now) = (centre(p), centre(&s.nodes));
            assert!(was.iter().all(|n| now.contains(n)), "at h = {h}");
            assert!(now.len() >= was.len());
            refined += s.nodes.iter().filter(|n| !p.contains(n)).count();
        }
        prev = Some(s.nodes);
    }
    assert!(refined > 10, "the cut hardly changed while approaching");
    // Looking away: nothing.
    let cam = looking_down(
        c + DVec3::new(0.0, 0.0, 50.0),
        c + DVec3::new(0.0, 0.0, 100.0),
    );
    assert!(tree_select(&tree, &cam, u64::MAX).nodes.is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

fn tree_select(tree: &LodTree, cam: &Camera, budget: u64) -> stipple_lod::Selection {
    select_nodes(
        &tree.nodes,
        tree.header.origin,
        cam,
        &SelectOptions {
            point_budget: budget,
            max_error_px: 1.0,
        },
    )
}

#[test]
fn streaming_draws_ancestors_until_nodes_arrive_and_stays_in_budget() {
    let dir = scratch("stream");
    let out = small_tree(&dir);
    let tree = Arc::new(LodTree::open(&out).unwrap());
    let (lo, hi) = tree.world_bounds();
    let c = (lo + hi) * 0.5;
    let cam = looking_down(c + DVec3::new(0.0, 0.0, 30.0), c);
    let sel = stipple_lod::select(&tree, &cam, &SelectOptions::default());
    assert!(sel.nodes.len() > 4);
    let cut_bytes: u64 = sel
        .nodes
        .iter()
        .map(|&i| tree.nodes[i as usize].records_size())
        .sum();
    // Room for this cut: the next one's new nodes must evict some of it.
    let budget = cut_bytes;
    let s = Streamer::new(tree.clone(), budget, 2).unwrap();
    // Nothing requested yet: the root (always resident) stands in for the whole cut.
    let (parts, missing) = s.resident_cut(&sel.nodes);
    assert_eq!(sel.nodes[0], 0);
    assert_eq!(missing, sel.nodes.len() - 1);
    assert_eq!(parts.iter().map(|p| p.0).collect::<Vec<_>>(), vec![0]);
    s.request(&sel.nodes);
    assert!(s.wait_idle(Duration::from_secs(30)));
    assert_eq!(s.error(), None);
    let (parts, missing) = s.resident_cut(&sel.nodes);
    assert_eq!(missing, 0);
    assert_eq!(parts.len(), sel.nodes.len());
    for (id, data) in &parts {
        assert_eq!(**data, tree.read_node(*id).unwrap());
    }
    // Another view: the new cut loads, and the cache evicts unpinned nodes to stay in budget.
    let cam2 = looking_down(
        lo + DVec3::new(10.0, 10.0, 15.0),
        lo + DVec3::new(10.0, 10.0, 0.0),
    );
    let sel2 = stipple_lod::select(&tree, &cam2, &SelectOptions::default());
    s.request(&sel2.nodes);
    assert!(s.wait_idle(Duration::from_secs(30)));
    let st = s.stats();
    assert!(
        st.resident_bytes
            <= budget.max(
                sel2.nodes
                    .iter()
                    .map(|&i| tree.nodes[i as usize].records_size())
                    .sum::<u64>()
                    + tree.nodes[0].records_size()
            ),
        "{st:?}"
    );
    assert!(st.evictions > 0, "{st:?}");
    assert_eq!(s.resident_cut(&sel2.nodes).1, 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_corrupt_payload_is_reported_by_the_streamer() {
    let dir = scratch("stream-bad");
    let out = small_tree(&dir);
    let tree = LodTree::open(&out).unwrap();
    let victim = tree.nodes.iter().position(|n| n.is_leaf()).unwrap();
    let mut b = std::fs::read(&out).unwrap();
    b[tree.nodes[victim].payload_offset as usize] ^= 1;
    std::fs::write(&out, &b).unwrap();
    let tree = Arc::new(LodTree::open(&out).unwrap());
    let s = Streamer::new(tree, 1 << 30, 1).unwrap();
    s.request(&[victim as u32]);
    assert!(s.wait_idle(Duration::from_secs(30)));
    let e = s.error().expect("no error reported");
    assert!(
        e.contains(&format!("node {victim}")) && e.contains("checksum"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A tree that exists when a build finishes (another build to the same output finished
/// first) is kept and the build fails, leaving no temporary file; `replace` replaces it.
#[test]
fn a_finished_build_never_replaces_an_existing_tree_unless_asked() {
    let dir = scratch("no-clobber");
    let input = write_las(&dir, "in.las", &terrain(5_000, 0, 3));
    let out = dir.join("t.stlod");
    std::fs::write(&out, b"another build's tree").unwrap();
    let o = BuildOptions {
        max_node_points: 1024,
        ..Default::default()
    };
    let e = build(std::slice::from_ref(&input), &out, &o)
        .unwrap_err()
        .to_string();
    assert!(e.contains("--force") && e.contains("t.stlod"), "{e}");
    assert_eq!(std::fs::read(&out).unwrap(), b"another build's tree");
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left.len(), 2, "temporary files left behind: {left:?}");
    let o = BuildOptions { replace: true, ..o };
    build(&[input], &out, &o).unwrap();
    assert!(LodTree::open(&out).is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_cancelled_build_stops_and_leaves_nothing() {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    let dir = scratch("cancel");
    let a = write_las(&dir, "a.las", &terrain(420_000, 5_000, 3));
    for memory in [64 << 20, 16 << 20] {
        // In memory, then out of core; cancelled once the build is under way (a progress
        // callback sets the flag, as the Python package's interrupt does).
        let cancel = Arc::new(AtomicBool::new(false));
        let c = cancel.clone();
        let o = BuildOptions {
            max_node_points: 1024,
            memory,
            progress: Some(Arc::new(move |_, done, _| {
                if done > 100_000 {
                    c.store(true, Ordering::Relaxed)
                }
            })),
            cancel: Some(cancel),
            ..Default::default()
        };
        let out = dir.join("t.stlod");
        let e = build(std::slice::from_ref(&a), &out, &o).unwrap_err();
        assert!(matches!(e, stipple_lod::LodError::Interrupted), "{e}");
        assert!(!out.exists(), "a cancelled build left its output");
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.'))
            .collect();
        assert!(left.is_empty(), "left behind: {left:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Hostile trees whose checksums are all valid (a checksum is no protection against intent):
/// random bytes changed anywhere, then the header's, the table's and every payload's
/// checksum recomputed. Opening and reading every node must fail with an error or succeed,
/// never panic or allocate what the file cannot hold (the LZ4 payloads included).
#[test]
fn mutated_trees_with_valid_checksums_fail_cleanly() {
    let dir = scratch("mutate");
    let a = write_las(&dir, "a.las", &terrain(3_000, 300, 9));
    for codec in [
        stipple_lod::format::CODEC_LZ4,
        stipple_lod::format::CODEC_RAW,
    ] {
        let out = dir.join("t.stlod");
        let o = BuildOptions {
            max_node_points: 64,
            codec,
            replace: true,
            ..Default::default()
        };
        build(std::slice::from_ref(&a), &out, &o).unwrap();
        let good = std::fs::read(&out).unwrap();
        let bad = dir.join("bad.stlod");
        let mut rng = stipple_core::rng::Rng::new(codec as u64 + 1);
        let (mut opened, mut failed_reads) = (0, 0);
        for _ in 0..1500 {
            let mut b = good.clone();
            for _ in 0..1 + (rng.f64() * 4.0) as usize {
                let at = (rng.f64() * b.len() as f64) as usize;
                // Half the time a small change (a count off by a little), else any byte.
                let v = if rng.f64() < 0.5 {
                    b[at].wrapping_add(1)
                } else {
                    (rng.f64() * 256.0) as u8
                };
                b[at] = v;
            }
            reseal(&mut b);
            std::fs::write(&bad, &b).unwrap();
            if let Ok(t) = LodTree::open(&bad) {
                opened += 1;
                for id in 0..t.nodes.len() as u32 {
                    if t.read_node(id).is_err() {
                        failed_reads += 1;
                    }
                }
            }
        }
        // A node claiming 2^30 points (16 GiB of records) in a payload of a few bytes, under
        // a header that allows such nodes: refused at opening, before anything is allocated.
        let mut b = good.clone();
        b[20..24].copy_from_slice(&u32::MAX.to_le_bytes());
        let t = LodTree::open(&out).unwrap();
        let leaf = t.nodes.iter().rposition(|n| n.is_leaf()).unwrap();
        let add = (1u64 << 30) - t.nodes[leaf].sample_count as u64;
        let table = t.header.table_offset as usize;
        let at = |i: usize| table + i * stipple_lod::format::NODE_SIZE as usize;
        // The counts stay consistent: the leaf's box, its ancestors' and the header's.
        let mut path = vec![leaf];
        while let Some(p) = t
            .nodes
            .iter()
            .position(|n| n.children.contains(&(path[0] as u32)))
        {
            path.insert(0, p);
        }
        for &i in &path {
            let n = at(i) + 24;
            let v = u64::from_le_bytes(b[n..n + 8].try_into().unwrap()) + add;
            b[n..n + 8].copy_from_slice(&v.to_le_bytes());
        }
        b[at(leaf) + 32..at(leaf) + 36].copy_from_slice(&(1u32 << 30).to_le_bytes());
        b[24..32].copy_from_slice(&(t.header.point_count + add).to_le_bytes());
        reseal(&mut b);
        std::fs::write(&bad, &b).unwrap();
        let e = open_err(&bad);
        assert!(e.contains("points in"), "codec {codec}: {e}");
        // The mutations reached the payload decoder, not only the checks at opening.
        assert!(opened > 100, "codec {codec}: only {opened} mutants opened");
        assert!(
            codec == stipple_lod::format::CODEC_RAW || failed_reads > 10,
            "codec {codec}: {failed_reads} failed reads"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Recomputes every checksum of a (possibly damaged) tree's bytes where its offsets allow.
fn reseal(b: &mut [u8]) {
    use stipple_lod::format::NODE_SIZE;
    let u64_at = |b: &[u8], at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    let u32_at = |b: &[u8], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    let (table, size) = (u64_at(b, 88) as usize, u64_at(b, 96) as usize);
    if table.checked_add(size).is_some_and(|e| e <= b.len()) {
        for n in (table..table + size).step_by(NODE_SIZE as usize) {
            if n + NODE_SIZE as usize > b.len() {
                break;
            }
            let (off, len) = (u64_at(b, n + 48) as usize, u32_at(b, n + 56) as usize);
            if off.checked_add(len).is_some_and(|e| e <= b.len()) {
                let crc = crc32fast::hash(&b[off..off + len]);
                b[n + 60..n + 64].copy_from_slice(&crc.to_le_bytes());
            }
        }
        let crc = crc32fast::hash(&b[table..table + size]);
        b[104..108].copy_from_slice(&crc.to_le_bytes());
    }
    let crc = crc32fast::hash(&b[..252]);
    b[252..256].copy_from_slice(&crc.to_le_bytes());
}
