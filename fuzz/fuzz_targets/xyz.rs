//! XYZ/TXT/CSV text through the parser: errors are fine, panics are not.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = stipple_io::xyz::parse_xyz(text);
    }
});
