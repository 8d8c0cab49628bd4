//! A file through `read_cloud` (format detection, gzip, LAS/LAZ, PLY, XYZ): the first byte
//! picks the file name's extension, the rest is the file. Errors are fine, panics are not.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "laz_panics.rs"]
mod laz_panics;

fuzz_target!(|data: &[u8]| {
    laz_panics::let_laz_panics_through();
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
