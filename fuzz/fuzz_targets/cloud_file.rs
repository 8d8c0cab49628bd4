//! A file through `read_cloud` (format detection, gzip, LAS/LAZ, PLY, XYZ): the first byte
//! picks the file name's extension, the rest is the file. Errors are fine, panics are not.
#![no_main]
use libfuzzer_sys::fuzz_target;

static HOOK: std::sync::Once = std::sync::Once::new();

fuzz_target!(|data: &[u8]| {
    // Panics inside the LAZ decoder (the `laz` crate, on some corrupt chunks) are caught by
    // the LAS reader and become errors: let them through to it (libFuzzer's hook would abort
    // first). Any other panic aborts as usual.
    HOOK.call_once(|| {
        let abort = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !info.location().is_some_and(|l| l.file().contains("/laz-")) {
                abort(info);
            }
        }));
    });
    let Some((&pick, body)) = data.split_first() else {
        return;
    };
    let ext = ["las", "laz", "ply", "ply.gz", "xyz", "copc.laz"][pick as usize % 6];
    let path = std::env::temp_dir().join(format!("stipple-fuzz-{}.{ext}", std::process::id()));
    if std::fs::write(&path, body).is_ok() {
        let _ = stipple_io::read_cloud(&path);
        let _ = std::fs::remove_file(&path);
    }
});
