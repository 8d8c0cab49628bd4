//! OBJ text, STL, PCD, E57, NRRD, NIfTI and raw volume bytes through their parsers: errors are fine, panics and
//! allocations beyond the input's size are not.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = stipple_io::mesh_io::parse_stl(data);
    let _ = stipple_io::pcd::parse_pcd(data);
    let _ = stipple_io::e57_io::parse_e57(std::io::Cursor::new(data), data.len() as u64);
    let _ = stipple_io::volume_io::parse_nrrd(data);
    let _ = stipple_io::volume_io::parse_nifti(data);
    let _ = stipple_io::volume_io::parse_raw("v_4x4x4_uint16.raw", data);
    let _ = stipple_io::mesh_io::parse_obj(&String::from_utf8_lossy(data));
});
