//! Replays the `.stlod` fuzzing corpus (`fuzz/corpus/stlod`, and failures kept in
//! `fuzz/regressions/stlod`) as `fuzz/fuzz_targets/stlod.rs` does: open the tree and read
//! every node; errors are fine, panics are not.

use std::path::Path;

#[test]
fn stlod_corpus_replays_without_panics() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let mut files = Vec::new();
    for dir in ["corpus", "regressions"] {
        if let Ok(rd) = std::fs::read_dir(root.join(dir).join("stlod")) {
            files.extend(rd.filter_map(|e| e.ok()).map(|e| e.path()));
        }
    }
    assert!(!files.is_empty(), "no stlod corpus under fuzz/");
    for f in files {
        if let Ok(tree) = stipple_lod::LodTree::open(&f) {
            for id in 0..tree.nodes.len() as u32 {
                let _ = tree.read_node(id);
            }
        }
    }
}
