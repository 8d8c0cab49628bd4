//! Scene files (TOML and JSON) parsed and built with no file access and a bounded point
//! budget (`stipple_scene::fuzzing`): errors are fine, panics are not.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    stipple_scene::fuzzing::scene_text(data);
});
