//! Outputs never clobber inputs or each other (issue "Nothing a user gives is lost or
//! clobbered"; the render command's part of it).

mod common;
use common::{stipple, tempdir, text};

fn small_cloud(dir: &std::path::Path) -> Vec<u8> {
    let mut s = String::new();
    for i in 0..400 {
        let (x, y) = ((i % 20) as f64 * 0.05, (i / 20) as f64 * 0.05);
        s.push_str(&format!("{x} {y} {}\n", 0.1 * (x * 3.0).sin()));
    }
    std::fs::write(dir.join("in.xyz"), &s).unwrap();
    s.into_bytes()
}

#[test]
fn render_outputs_never_clobber_inputs_or_each_other() {
    let dir = tempdir("outputs");
    let before = small_cloud(&dir);
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    let base = ["render", "in.xyz", "--size", "32x32", "--backend", "cpu"];
    let refused = |extra: &[&str], what: &str| {
        let mut a = base.to_vec();
        a.extend_from_slice(extra);
        let o = stipple(&dir, &a);
        assert!(!o.status.success(), "{what}: accepted: {}", text(&o));
        assert!(!text(&o).contains("panicked"), "{}", text(&o));
        assert_eq!(std::fs::read(dir.join("in.xyz")).unwrap(), before, "{what}");
    };
    refused(
        &[
            "-o",
            "a.png",
            "--depth-out",
            "x.npy",
            "--camera-out",
            "x.npy",
        ],
        "depth = camera",
    );
    refused(&["-o", "x.png", "--camera-out", "x.png"], "image = camera");
    refused(
        &["-o", "x.png", "--camera-out", "./sub/../x.png"],
        "same file, other spelling",
    );
    refused(
        &["-o", "a.png", "--camera-out", "in.xyz"],
        "camera over the input",
    );
    // A hard link to the input under another name.
    std::fs::hard_link(dir.join("in.xyz"), dir.join("cam.json")).unwrap();
    refused(
        &["-o", "a.png", "--camera-out", "cam.json"],
        "hard link to the input",
    );
    // A scene's cloud file is an input too.
    std::fs::write(dir.join("s.toml"), "[[cloud]]\nfile = \"in.xyz\"\n").unwrap();
    let o = stipple(
        &dir,
        &[
            "render",
            "s.toml",
            "--size",
            "32x32",
            "--backend",
            "cpu",
            "-o",
            "s.png",
            "--camera-out",
            "in.xyz",
        ],
    );
    assert!(!o.status.success(), "scene input overwritten: {}", text(&o));
    assert_eq!(std::fs::read(dir.join("in.xyz")).unwrap(), before);
    // All or nothing: a failing later output leaves no earlier one behind.
    refused(
        &["-o", "early.png", "--depth-out", "no-such-dir/x.npy"],
        "later output fails",
    );
    assert!(
        !dir.join("early.png").exists(),
        "the image stayed after a failed output"
    );
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().contains("stipple-tmp"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
    // A device is never replaced by a file.
    let full = std::path::Path::new("/dev/full");
    if full.exists() {
        refused(&["-o", "dev.png", "--camera-out", "/dev/full"], "/dev/full");
        assert!(
            !std::fs::metadata(full).unwrap().is_file(),
            "/dev/full was replaced"
        );
        assert!(!dir.join("dev.png").exists());
    }
    // Distinct outputs are fine.
    let o = stipple(
        &dir,
        &[
            "render",
            "in.xyz",
            "--size",
            "32x32",
            "--backend",
            "cpu",
            "-o",
            "a.png",
            "--depth-out",
            "a.npy",
            "--camera-out",
            "a.json",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    std::fs::remove_dir_all(dir).ok();
}

/// An output that another live stipple process is writing (its temporary file is beside
/// the output) is an error; a temporary file left by a dead process is not.
#[test]
fn an_output_another_process_is_writing_is_refused() {
    let dir = tempdir("concurrent");
    // A live process standing in for the other writer.
    let mut other = std::process::Command::new("sleep")
        .arg("60")
        .spawn()
        .unwrap();
    let tmp = dir.join(format!(".x.png.{}.stipple-tmp", other.id()));
    std::fs::write(&tmp, b"half an image").unwrap();
    let args = [
        "render", "--demo", "sphere", "--points", "500", "--size", "32", "-o", "x.png",
    ];
    let o = stipple(&dir, &args);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains(&format!("another stipple process (pid {})", other.id())),
        "{}",
        text(&o)
    );
    assert!(!dir.join("x.png").exists());
    other.kill().unwrap();
    other.wait().unwrap();
    let o = stipple(&dir, &args);
    assert!(o.status.success(), "{}", text(&o));
    assert!(dir.join("x.png").exists());
    std::fs::remove_dir_all(dir).ok();
}
