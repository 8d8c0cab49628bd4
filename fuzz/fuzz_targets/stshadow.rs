//! `.stshadow` shadow caches read back (`stipple_scene::fuzzing`): errors are fine, panics
//! and allocations from unchecked counts are not.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let scratch = std::env::temp_dir().join(format!("stipple-fuzz-{}.stshadow", std::process::id()));
    stipple_scene::fuzzing::stshadow_bytes(data, &scratch);
});
