//! The malformed corpus (`tests/corpus/`): every file is rejected with an error that names the
//! file and says what is wrong; none panics, none allocates from an unchecked header count.

use std::path::{Path, PathBuf};
use stipple_io::read_cloud;

fn corpus(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/corpus")
        .join(name)
}

/// (file, a phrase the message must contain)
const CASES: &[(&str, &str)] = &[
    ("bad_magic.ply", "not a PLY file"),
    ("truncated_binary.ply", "truncated"),
    ("huge_count_binary.ply", "count is wrong"),
    ("huge_count_ascii.ply", "count is wrong"),
    ("nan_ascii.ply", "vertex 1 has a non-finite coordinate"),
    ("inf_binary_be.ply", "vertex 1 has a non-finite coordinate"),
    ("empty_cloud.ply", "no points"),
    ("no_end_header.ply", "end_header"),
    (
        "bad_number.ply",
        "`abc` in a `vertex` record is not a number",
    ),
    // One value too many or too few on a line is an error there, not a shift of every
    // later vertex.
    (
        "extra_value.ply",
        "line 9: more values than a `vertex` record has (x y z)",
    ),
    (
        "missing_value.ply",
        "line 9: too few values for a `vertex` record (x y z)",
    ),
    // A gzip-compressed file that is not PLY inside is read by its extension.
    ("volume.nii.gz", "shorter than a NIfTI-1 header"),
    // An offending token is shown escaped and cut at 32 characters.
    (
        "long_token.xyz",
        "line 2: `77777777777777777777777777777777…` is not a number",
    ),
    ("truncated_ascii.ply", "truncated"),
    ("bad_face_index.ply", "face 0 refers to vertex 10"),
    ("no_xyz.ply", "lacks x, y or z"),
    ("corrupt.ply.gz", "gzip data is corrupt"),
    ("truncated.ply.gz", "gzip data is corrupt or truncated"),
    ("empty_file.ply", "not a PLY file"),
    ("bad_magic.las", "not a LAS/LAZ file"),
    ("tiny.las", "inside the LAS header"),
    ("bad_token.xyz", "line 3: `abc` is not a number"),
    ("ragged.xyz", "line 2: 4 values, but earlier lines have 3"),
    ("nan.xyz", "line 2: value 2 is not finite"),
    ("empty.xyz", "no points"),
    ("two_columns.xyz", "expected at least 3 numbers"),
    ("binary.xyz", "not a text file"),
    ("no_data_line.pcd", "the header ends without a DATA line"),
    (
        "truncated_binary.pcd",
        "POINTS 1000 × 12 bytes is more than the 100 bytes",
    ),
    ("huge_compressed.pcd", "cannot hold 1200000000 bytes"),
    ("bad_index.obj", "line 4: vertex 4 does not exist"),
    ("truncated.stl", "binary STL header says 1000 triangles"),
    ("huge_sizes.nrrd", "more than the file can hold (64)"),
    ("truncated.e57", "E57"),
    ("garbage.e57", "E57"),
    ("short_2x2x2_uint16.raw", "more than the file can hold (10)"),
    // A finite 1e300 is out of range, not "non-finite".
    (
        "huge_coordinate.ply",
        "vertex 1 has a coordinate out of range (1e300",
    ),
    (
        "huge_coordinate.xyz",
        "point 2 has a coordinate out of range",
    ),
    // Ambiguous files are errors, not a silent choice.
    (
        "duplicate_x.ply",
        "vertex property `x` (property 3) gives the same attribute as `x`",
    ),
    ("two_vertex_elements.ply", "a second `vertex` element"),
    // A line longer than any point's is refused before it is split into tokens.
    ("long_line.xyz", "line 2 is 66000 bytes long"),
    // Found by fuzzing: LAS 1.4 extended VLRs beyond the file made the `las` crate
    // allocate what they claimed (a panic, or memory exhausted).
    (
        "bogus_evlr_count.las",
        "256 extended variable-length records from byte 116",
    ),
    (
        "huge_evlr.las",
        "extended variable-length record 0 claims 1152921504606846976 bytes",
    ),
    (
        "header_size_zero.copc.laz",
        "a LAS header takes at least 227",
    ),
    // Found by fuzzing: an element of 4e9 records without properties looped 4e9 times.
    ("fuzz_empty_element.ply", "no vertex element"),
];

#[test]
fn corpus_is_rejected_with_the_right_message() {
    for &(name, phrase) in CASES {
        let path = corpus(name);
        let err = match read_cloud(&path) {
            Ok(c) => panic!("{name}: accepted ({} points)", c.len()),
            Err(e) => e.to_string(),
        };
        assert!(
            err.contains(name),
            "{name}: message does not name the file: {err}"
        );
        assert!(
            err.contains(phrase),
            "{name}: expected `{phrase}` in: {err}"
        );
    }
    // Every corpus file is covered by a case.
    let n = std::fs::read_dir(corpus("")).unwrap().count();
    assert_eq!(n, CASES.len(), "corpus files without a case");
}

#[test]
fn missing_file_names_the_path() {
    let e = read_cloud(Path::new("/nonexistent/cloud.ply"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("/nonexistent/cloud.ply"), "{e}");
}

fn las_fixture(dir: &Path, n: usize) -> PathBuf {
    let mut c = stipple_core::demo::generate(stipple_core::demo::DemoScene::Sphere, n, 3);
    c.normals = None;
    let path = dir.join(format!("fixture{n}.las"));
    stipple_io::write_cloud(&path, &c).unwrap();
    path
}

fn tempdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("stipple-io-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn truncated_and_inflated_las_are_rejected() {
    let dir = tempdir("las");
    let path = las_fixture(&dir, 1000);
    let bytes = std::fs::read(&path).unwrap();
    // Cut in the middle of the point records.
    let cut = dir.join("cut.las");
    std::fs::write(&cut, &bytes[..bytes.len() - 5000]).unwrap();
    let e = read_cloud(&cut).unwrap_err().to_string();
    assert!(e.contains("cut.las") && e.contains("truncated"), "{e}");
    // Legacy point count (LAS 1.2 header offset 107) claims 4 billion points.
    let mut inflated = bytes.clone();
    inflated[107..111].copy_from_slice(&4_000_000_000u32.to_le_bytes());
    let big = dir.join("inflated.las");
    std::fs::write(&big, &inflated).unwrap();
    let e = read_cloud(&big).unwrap_err().to_string();
    assert!(
        e.contains("inflated.las") && e.contains("count is wrong"),
        "{e}"
    );
    // Zero points.
    let mut empty = bytes.clone();
    empty[107..111].copy_from_slice(&0u32.to_le_bytes());
    let z = dir.join("zero.las");
    std::fs::write(&z, &empty).unwrap();
    let e = read_cloud(&z).unwrap_err().to_string();
    assert!(e.contains("zero.las") && e.contains("no points"), "{e}");
    std::fs::remove_dir_all(dir).ok();
}

/// LAS header bounds that disagree with the points (far off, or inverted) do not quantise
/// the points: the origin then comes from the data.
#[test]
fn wrong_las_header_bounds_keep_the_points_precise() {
    let dir = tempdir("las-bounds");
    let path = las_fixture(&dir, 2000);
    let truth = read_cloud(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    // LAS 1.2 header: max x, min x, max y, min y, max z, min z as f64 from offset 179.
    let put =
        |b: &mut Vec<u8>, off: usize, v: f64| b[off..off + 8].copy_from_slice(&v.to_le_bytes());
    for (tag, vals) in [
        ("far", [1e9 + 1.0, 1e9, 1e9 + 1.0, 1e9, 1e9 + 1.0, 1e9]),
        ("inverted", [-5.0, 5.0, -5.0, 5.0, -5.0, 5.0]),
    ] {
        let mut b = bytes.clone();
        for (k, v) in vals.into_iter().enumerate() {
            put(&mut b, 179 + 8 * k, v);
        }
        let p = dir.join(format!("{tag}.las"));
        std::fs::write(&p, &b).unwrap();
        let c = read_cloud(&p).unwrap();
        assert_eq!(c.len(), truth.len());
        for (a, t) in c.positions.iter().zip(&truth.positions) {
            let (a, t) = (c.origin + a.as_dvec3(), truth.origin + t.as_dvec3());
            assert!((a - t).length() < 1e-3, "{tag}: {a} vs {t}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Truncated and corrupt LAS/LAZ headers say what is wrong and where, from the header's own
/// fields (the `las` crate alone said "failed to fill whole buffer").
#[test]
fn truncated_las_and_laz_say_where() {
    let dir = tempdir("las-truncated");
    let mut c = stipple_core::demo::generate(stipple_core::demo::DemoScene::Torus, 3000, 5);
    c.normals = None;
    let laz = dir.join("f.laz");
    stipple_io::write_cloud(&laz, &c).unwrap();
    let bytes = std::fs::read(&laz).unwrap();
    let mut offset = bytes.clone();
    offset[96..100].copy_from_slice(&(bytes.len() as u32 + 100).to_le_bytes());
    let mut nvlr = bytes.clone();
    nvlr[100..104].copy_from_slice(&u32::MAX.to_le_bytes());
    for (name, data, want) in [
        ("head.laz", bytes[..100].to_vec(), "inside the LAS header"),
        ("offset.laz", offset, "the points start at byte"),
        (
            "data.laz",
            bytes[..bytes.len() * 2 / 3].to_vec(),
            "truncated",
        ),
        ("nvlr.laz", nvlr, "4294967295 variable-length records"),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, &data).unwrap();
        let e = read_cloud(&p).unwrap_err().to_string();
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Devices, directories and pipes are not read (a symbolic link to /dev/zero named `.xyz`
/// used to be read until memory ran out).
#[test]
fn non_regular_inputs_are_refused() {
    let dir = tempdir("special");
    let link = dir.join("zero.xyz");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
    for p in [link.as_path(), dir.as_path()] {
        let e = read_cloud(p).unwrap_err().to_string();
        assert!(e.contains("not a regular file"), "{e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
