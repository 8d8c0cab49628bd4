//! Every file in `../shared/data/` that the readers cover reads without error, with the
//! counts its README states. Skipped with a printed reason when the folder is absent.

use std::path::PathBuf;

fn data_dir() -> Option<PathBuf> {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    if d.is_dir() {
        Some(d)
    } else {
        eprintln!("skipped: {} is absent", d.display());
        None
    }
}

/// (file, points, has normals, has colours)
const FILES: &[(&str, usize, bool, bool)] = &[
    ("stanford/bunny/bun_zipper.ply", 35_947, false, false),
    ("stanford/bunny/bun_zipper_res4.ply", 453, false, false),
    (
        "stanford/dragon/dragon_vrip_res3.ply.gz",
        22_998,
        false,
        false,
    ),
    ("stanford/dragon/dragon_vrip.ply.gz", 437_645, false, false),
    (
        "stanford/armadillo/Armadillo_38k_normals.ply",
        38_294,
        true,
        false,
    ),
    (
        "stanford/buddha/happy_rawscan_78k.xyz",
        78_056,
        false,
        false,
    ),
    ("stanford/lucy/Lucy100k.ply", 50_002, false, false),
    ("lidar/autzen_trim.las", 110_000, false, true),
    ("lidar/autzen_trim.laz", 110_000, false, true),
    (
        "lidar/ign_lidarhd_extrabytes_698k.laz",
        697_721,
        false,
        true,
    ),
    ("lidar/lone-star.laz", 518_862, false, false),
    ("colored/lion_takanawa.copc.laz", 341_989, false, true),
];

#[test]
fn every_covered_data_file_reads() {
    let Some(dir) = data_dir() else { return };
    for &(name, count, normals, colors) in FILES {
        let path = dir.join(name);
        let c = stipple_io::read_cloud(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.len(), count, "{name}");
        assert_eq!(c.normals.is_some(), normals, "{name} normals");
        assert_eq!(c.colors.is_some(), colors, "{name} colours");
        let s = c.estimate_spacing();
        assert!(s > 0.0, "{name} spacing");
        eprintln!("{name}: {} points, spacing {s:.5}", c.len());
    }
}

#[test]
fn bunny_faces_are_kept() {
    let Some(dir) = data_dir() else { return };
    let c = stipple_io::read_cloud(&dir.join("stanford/bunny/bun_zipper.ply")).unwrap();
    assert_eq!(c.faces.len(), 69_451);
    let l = stipple_io::read_cloud(&dir.join("stanford/lucy/Lucy100k.ply")).unwrap();
    assert_eq!(l.faces.len(), 100_000);
}

#[test]
fn lidar_keeps_millimetre_precision() {
    let Some(dir) = data_dir() else { return };
    let path = dir.join("lidar/autzen_trim.las");
    let c = stipple_io::read_cloud(&path).unwrap();
    let mut r = las::Reader::from_path(&path).unwrap();
    let pts = r.read_points(1000).unwrap();
    for (i, ((x, y), z)) in pts.x().zip(pts.y()).zip(pts.z()).enumerate() {
        let w = c.world(i);
        assert!((w.x - x).abs() < 1e-3 && (w.y - y).abs() < 1e-3 && (w.z - z).abs() < 1e-3);
    }
    assert!(c.origin.x.abs() > 1e5, "LiDAR origin kept in f64");
}

/// LAS extra bytes become scalar fields by the names their VLR gives: the IGN tile's
/// `Deviation` (an unsigned 16-bit value, no scale) equals the raw bytes the `las` crate
/// hands out per point.
#[test]
fn las_extra_bytes_become_scalar_fields() {
    let Some(dir) = data_dir() else { return };
    let path = dir.join("lidar/ign_lidarhd_extrabytes_698k.laz");
    let c = stipple_io::read_cloud(&path).unwrap();
    let f = c.field("deviation").expect("the Deviation field");
    assert_eq!(f.name, "Deviation");
    let mut r = las::Reader::from_path(&path).unwrap();
    let mut distinct = std::collections::BTreeSet::new();
    let data = r.read_points(5000).unwrap();
    for (i, p) in data.points().enumerate() {
        let p = p.unwrap();
        let raw = u16::from_le_bytes([p.extra_bytes[0], p.extra_bytes[1]]) as f64;
        assert_eq!(f.value(i), raw, "point {i}");
        distinct.insert(raw as u64);
    }
    assert!(distinct.len() > 1, "the values vary");
}

/// The E57 bunny (two scans placed by their poses) covers what the PLY bunny does.
#[test]
fn the_e57_bunny_matches_the_ply_bunny() {
    let Some(dir) = data_dir() else { return };
    let e57 = stipple_io::read_cloud(&dir.join("stanford/bunny_e57/bunnyDouble.e57")).unwrap();
    let ply = stipple_io::read_cloud(&dir.join("stanford/bunny/bun_zipper.ply")).unwrap();
    let ((a0, a1), (b0, b1)) = (e57.world_bounds(), ply.world_bounds());
    let extent = (b1 - b0).max_element();
    let off = (a0 - b0).abs().max((a1 - b1).abs()).max_element();
    eprintln!("e57 {} points, bounds {a0} {a1}; ply {b0} {b1}", e57.len());
    assert!(
        off < 0.05 * extent,
        "bounds differ by {off} (extent {extent})"
    );
    assert!(e57.len() > 10_000);
}

/// The lion (a COPC file written by another tool) opens as COPC: its hierarchy checks out,
/// and decoding all its nodes gives the points a flat LAZ read gives. Written again by
/// stipple, it opens as COPC with the same points.
#[test]
fn the_lion_copc_reads_node_by_node_and_writes_back() {
    let Some(dir) = data_dir() else { return };
    let path = dir.join("colored/lion_takanawa.copc.laz");
    assert!(stipple_io::copc::is_copc(&path));
    let copc = stipple_io::copc::Copc::open(&path).unwrap();
    let flat = stipple_io::read_cloud(&path).unwrap();
    assert_eq!(copc.point_count as usize, flat.len());
    assert!(copc.nodes.len() > 1, "{} nodes", copc.nodes.len());
    let all: Vec<usize> = (0..copc.nodes.len()).collect();
    let ours = copc.read_nodes(&all, flat.origin).unwrap();
    let key = |c: &stipple_core::PointCloud| {
        let mut v: Vec<[i64; 3]> = (0..c.len())
            .map(|i| {
                let w = c.world(i) / copc.scale;
                [w.x.round() as i64, w.y.round() as i64, w.z.round() as i64]
            })
            .collect();
        v.sort_unstable();
        v
    };
    assert_eq!(key(&ours), key(&flat));
    assert_eq!(ours.colors.is_some(), flat.colors.is_some());
    let out = std::env::temp_dir().join(format!("stipple-lion-{}.copc.laz", std::process::id()));
    let report = stipple_io::copc::write_copc(&out, &flat).unwrap();
    let again = stipple_io::copc::Copc::open(&out).unwrap();
    assert_eq!(again.point_count, report.points);
    assert_eq!(again.point_count as usize, flat.len());
    let back = stipple_io::read_cloud(&out).unwrap();
    let _ = std::fs::remove_file(&out);
    // The rewritten file's scale is at least as fine as the lion's.
    assert!(
        again.scale.x <= copc.scale.x,
        "{} vs {}",
        again.scale,
        copc.scale
    );
    assert_eq!(key(&back), key(&flat));
}

/// The parallel reader (chunks decoded and converted on their own, straight into the
/// columns) gives the very cloud the batch reader gives, for LAS, LAZ (point-wise and
/// layered) and COPC files.
#[test]
fn parallel_and_batch_reads_agree() {
    use stipple_io::las_io::{read_las, read_las_batches, LasBatches};
    let Some(dir) = data_dir() else { return };
    // Point format 2 (colours without GPS times), as stipple writes LAS and LAZ.
    let lion = stipple_io::read_cloud(&dir.join("colored/lion_takanawa.copc.laz")).unwrap();
    let tmp = std::env::temp_dir().join(format!("stipple-par-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let (las2, laz2) = (tmp.join("lion.las"), tmp.join("lion.laz"));
    stipple_io::las_io::write_las(&las2, &lion, false).unwrap();
    stipple_io::las_io::write_las(&laz2, &lion, true).unwrap();
    for p in [
        las2.clone(),
        laz2.clone(),
        dir.join("lidar/autzen_trim.las"),
        dir.join("lidar/autzen_trim.laz"),
        dir.join("lidar/lone-star.laz"),
        dir.join("colored/lion_takanawa.copc.laz"),
    ] {
        let f = p.display().to_string();
        let a = read_las(&p).unwrap();
        let b = read_las_batches(&p, LasBatches::open(&p).unwrap()).unwrap();
        assert_eq!(a.origin, b.origin, "{f}");
        assert_eq!(a.positions, b.positions, "{f}");
        assert_eq!(a.intensity, b.intensity, "{f}");
        assert_eq!(a.classification, b.classification, "{f}");
        assert_eq!(a.return_number, b.return_number, "{f}");
        assert_eq!(a.colors, b.colors, "{f}");
        assert_eq!(a.sensor_dirs, b.sensor_dirs, "{f}");
        assert_eq!(a.fields.len(), b.fields.len(), "{f}");
        assert!(a.colors.is_some() || !f.contains("lion"), "{f}");
    }
    let _ = std::fs::remove_dir_all(&tmp);
}
