//! Replays the fuzzing corpora (`fuzz/corpus/{ply,xyz,cloud_file,mesh,copc}`, minimised by
//! `fuzz/run.sh`) and the inputs that once failed (`fuzz/regressions/<target>/`) through the
//! same entry points as the fuzz targets: every input must come back as a value or an error,
//! never a panic. CI runs this on stable; the fuzzing itself needs nightly (fuzz/run.sh).

use std::path::{Path, PathBuf};

fn inputs(target: &str) -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let mut out = Vec::new();
    for dir in ["corpus", "regressions"] {
        if let Ok(rd) = std::fs::read_dir(root.join(dir).join(target)) {
            out.extend(rd.filter_map(|e| e.ok()).map(|e| e.path()));
        }
    }
    out.sort();
    out
}

#[test]
fn ply_corpus_replays_without_panics() {
    let files = inputs("ply");
    assert!(!files.is_empty(), "no ply corpus under fuzz/");
    for f in files {
        let data = std::fs::read(&f).unwrap();
        let _ = stipple_io::ply::parse_ply(&data);
    }
}

#[test]
fn xyz_corpus_replays_without_panics() {
    let files = inputs("xyz");
    assert!(!files.is_empty(), "no xyz corpus under fuzz/");
    for f in files {
        let data = std::fs::read(&f).unwrap();
        if let Ok(text) = std::str::from_utf8(&data) {
            let _ = stipple_io::xyz::parse_xyz(text);
        }
    }
}

/// As `fuzz/fuzz_targets/cloud_file.rs`: the first byte picks the extension.
#[test]
fn cloud_file_corpus_replays_without_panics() {
    let files = inputs("cloud_file");
    assert!(!files.is_empty(), "no cloud_file corpus under fuzz/");
    let dir = std::env::temp_dir().join(format!("stipple-fuzz-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (k, f) in files.iter().enumerate() {
        let data = std::fs::read(f).unwrap();
        let Some((&pick, body)) = data.split_first() else {
            continue;
        };
        let ext = ["las", "laz", "ply", "ply.gz", "xyz", "copc.laz"][pick as usize % 6];
        let path = dir.join(format!("{k}.{ext}"));
        std::fs::write(&path, body).unwrap();
        let _ = stipple_io::read_cloud(&path);
        let _ = std::fs::remove_file(&path);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// As `fuzz/fuzz_targets/mesh.rs`: OBJ, STL, PCD, E57 and the volume parsers on every input.
#[test]
fn mesh_corpus_replays_without_panics() {
    let files = inputs("mesh");
    assert!(!files.is_empty(), "no mesh corpus under fuzz/");
    for f in files {
        let data = std::fs::read(&f).unwrap();
        let _ = stipple_io::mesh_io::parse_stl(&data);
        let _ = stipple_io::mesh_io::parse_obj(&String::from_utf8_lossy(&data));
        let _ = stipple_io::pcd::parse_pcd(&data);
        let _ = stipple_io::e57_io::parse_e57(std::io::Cursor::new(&data[..]), data.len() as u64);
        let _ = stipple_io::volume_io::parse_nrrd(&data);
        let _ = stipple_io::volume_io::parse_nifti(&data);
        let _ = stipple_io::volume_io::parse_raw("v_4x4x4_uint16.raw", &data);
    }
}

/// As `fuzz/fuzz_targets/copc.rs`: opened, and decoded when it opens with a modest count.
#[test]
fn copc_corpus_replays_without_panics() {
    let files = inputs("copc");
    assert!(!files.is_empty(), "no copc corpus under fuzz/");
    let dir = std::env::temp_dir().join(format!("stipple-copc-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (k, f) in files.iter().enumerate() {
        let path = dir.join(format!("{k}.copc.laz"));
        std::fs::write(&path, std::fs::read(f).unwrap()).unwrap();
        if let Ok(c) = stipple_io::copc::Copc::open(&path) {
            if c.point_count <= 1 << 16 {
                let all: Vec<usize> = (0..c.nodes.len()).collect();
                let _ = c.read_nodes(&all, Default::default());
            }
        }
        let _ = std::fs::remove_file(&path);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
