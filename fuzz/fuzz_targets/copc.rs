//! A file through `stipple_io::copc`: opened (header, VLRs, every hierarchy page checked),
//! then, when it opens with a modest count, every node decoded. Errors are fine, panics,
//! hangs and huge allocations are not.
//!
//! The LAZ decoder (the `laz` crate) panics on some corrupt chunks; the reader catches those
//! panics and returns an error, so they are let through to it here (libFuzzer's hook would
//! abort on them before the reader could catch them). Any other panic aborts as usual.
#![no_main]
use libfuzzer_sys::fuzz_target;

static HOOK: std::sync::Once = std::sync::Once::new();

fuzz_target!(|data: &[u8]| {
    HOOK.call_once(|| {
        let abort = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !info.location().is_some_and(|l| l.file().contains("/laz-")) {
                abort(info);
            }
        }));
    });
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
