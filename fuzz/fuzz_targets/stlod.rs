//! A `.stlod` tree: open it (header, node table, checksums) and read every node's payload.
//! Errors are fine, panics, hangs and huge allocations are not.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("stipple-fuzz-{}.stlod", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        if let Ok(tree) = stipple_lod::LodTree::open(&path) {
            for id in 0..tree.nodes.len() as u32 {
                let _ = tree.read_node(id);
            }
        }
        let _ = std::fs::remove_file(&path);
    }
});
