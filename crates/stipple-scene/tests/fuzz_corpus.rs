//! Replays the scene and shadow-cache fuzzing corpora (`fuzz/corpus/{scene,stshadow}`, the
//! seeds and the failures kept in `fuzz/regressions/`) as the fuzz targets do: errors are
//! fine, panics are not.

use std::path::{Path, PathBuf};

fn corpus(target: &str) -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let mut files = Vec::new();
    for dir in ["corpus", "regressions", "seeds"] {
        if let Ok(rd) = std::fs::read_dir(root.join(dir).join(target)) {
            files.extend(rd.filter_map(|e| e.ok()).map(|e| e.path()));
        }
    }
    assert!(!files.is_empty(), "no {target} corpus under fuzz/");
    files
}

#[test]
fn scene_corpus_replays_without_panics() {
    for f in corpus("scene") {
        stipple_scene::fuzzing::scene_text(&std::fs::read(&f).unwrap());
    }
}

#[test]
fn stshadow_corpus_replays_without_panics() {
    let scratch =
        std::env::temp_dir().join(format!("stipple-fuzz-{}.stshadow", std::process::id()));
    for f in corpus("stshadow") {
        stipple_scene::fuzzing::stshadow_bytes(&std::fs::read(&f).unwrap(), &scratch);
    }
    let _ = std::fs::remove_file(scratch);
}
