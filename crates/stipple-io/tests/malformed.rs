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
    // A gzip-compressed file that is not PLY inside is named by its extension.
    ("volume.nii.gz", ".nii files are not supported yet"),
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
    ("tiny.las", "cannot read the LAS header"),
    ("bad_token.xyz", "line 3: `abc` is not a number"),
    ("ragged.xyz", "line 2: 4 values, but earlier lines have 3"),
    ("nan.xyz", "line 2: value 2 is not finite"),
    ("empty.xyz", "no points"),
    ("two_columns.xyz", "expected at least 3 numbers"),
    ("binary.xyz", "not a text file"),
    ("unsupported.pcd", "not supported yet"),
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
