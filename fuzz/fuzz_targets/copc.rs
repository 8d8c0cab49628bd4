//! A file through `stipple_io::copc`: opened (header, VLRs, every hierarchy page checked),
//! then, when it opens with a modest count, every node decoded. Errors are fine, panics,
//! hangs and huge allocations are not.
//!
//! Panics inside the LAZ decoder are let through to the reader, which catches them
//! (`laz_panics.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "laz_panics.rs"]
mod laz_panics;

fuzz_target!(|data: &[u8]| {
    laz_panics::let_laz_panics_through();
    let path = std::env::temp_dir().join(format!("stipple-fuzz-{}.copc.laz", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        if let Ok(c) = stipple_io::copc::Copc::open(&path) {
            if c.point_count <= 1 << 16 {
                let all: Vec<usize> = (0..c.nodes.len()).collect();
                let _ = c.read_nodes(&all, Default::default());
            }
        }
        let _ = std::fs::remove_file(&path);
    }
});
