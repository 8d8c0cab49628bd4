//! PLY bytes (every encoding) through the parser: errors are fine, panics are not.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = stipple_io::ply::parse_ply(data);
});
