//! Every file in `../shared/data/` that the readers cover renders without error on the CPU,
//! framed by the default camera, and shows the cloud (not an empty frame). Skipped with a
//! printed reason when the folder is absent.

use std::path::Path;
use stipple_core::Camera;
use stipple_render::{render, Backend, Pipeline, PreparedCloud, BACKGROUND};

const FILES: &[&str] = &[
    "stanford/bunny/bun_zipper.ply",
    "stanford/bunny/bun_zipper_res2.ply",
    "stanford/bunny/bun_zipper_res3.ply",
    "stanford/bunny/bun_zipper_res4.ply",
    "stanford/bunny/data/bun000.ply",
    "stanford/bunny/data/top2.ply",
    "stanford/dragon/dragon_vrip.ply.gz",
    "stanford/dragon/dragon_vrip_res2.ply.gz",
    "stanford/dragon/dragon_vrip_res3.ply.gz",
    "stanford/dragon/dragon_vrip_res4.ply.gz",
    "stanford/armadillo/Armadillo_38k_normals.ply",
    "stanford/buddha/happy_rawscan_78k.xyz",
    "stanford/lucy/Lucy100k.ply",
    "lidar/autzen_trim.las",
    "lidar/autzen_trim.laz",
    "lidar/ign_lidarhd_extrabytes_698k.laz",
    "lidar/lone-star.laz",
    "lidar/autzen_full_10.6M_rgb.laz",
    "colored/lion_takanawa.copc.laz",
    "colored/milk_color.pcd",
    "colored/office1.pcd",
    "colored/region_growing_rgb_tutorial.pcd",
    "stanford/bunny_e57/bunnyDouble.e57",
    "volume/stent.nrrd",
    "volume/ch2.nii.gz",
    "volume/tooth_103x94x161_uint8.raw",
];

/// `../shared/data`, or None (the reason printed) where it is absent.
fn data_dir() -> Option<std::path::PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("skipped: {} is absent", dir.display());
        None
    }
}

/// Runs `stipple` with `args`, asserting that it succeeds; returns its stderr and stdout.
fn stipple<S: AsRef<std::ffi::OsStr>>(args: impl IntoIterator<Item = S>) -> String {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_stipple"))
        .args(args)
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&o.stderr).into_owned() + &String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{text}");
    text
}

#[test]
fn every_covered_data_file_renders() {
    let Some(dir) = data_dir() else {
        return;
    };
    // Every cloud, mesh and volume file in the data folder is in the list.
    let mut found = Vec::new();
    let mut stack = vec![dir.clone()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if matches!(
                stipple_io::extension(&p).as_str(),
                "ply"
                    | "las"
                    | "laz"
                    | "xyz"
                    | "pcd"
                    | "e57"
                    | "obj"
                    | "stl"
                    | "nrrd"
                    | "nii"
                    | "raw"
            ) {
                found.push(p.strip_prefix(&dir).unwrap().to_string_lossy().into_owned());
            }
        }
    }
    for f in &found {
        let listed = FILES.contains(&f.as_str()) || f.starts_with("stanford/bunny/data/");
        assert!(
            listed,
            "{f} is readable by stipple but not rendered by this test"
        );
    }
    let mut names: Vec<String> = FILES.iter().map(|s| s.to_string()).collect();
    names.extend(
        found
            .into_iter()
            .filter(|f| f.starts_with("stanford/bunny/data/")),
    );
    names.sort();
    names.dedup();
    for name in names {
        let t0 = std::time::Instant::now();
        let cloud = stipple_io::read_cloud(&dir.join(&name)).unwrap_or_else(|e| panic!("{e}"));
        let (lo, hi) = cloud.world_bounds();
        let cam = Camera::framing_up(lo, hi, 160, 120, 45.0, cloud.z_up);
        let prepared = PreparedCloud::new(cloud);
        let f = render(&prepared, &cam, &Pipeline::default(), Backend::Cpu).unwrap();
        let covered = f.id.iter().filter(|&&i| i != BACKGROUND).count();
        assert!(
            covered > 160 * 120 / 50,
            "{name}: only {covered} pixels covered"
        );
        eprintln!(
            "{name}: {} points, {covered} px, {:.2} s",
            prepared.cloud.len(),
            t0.elapsed().as_secs_f64()
        );
    }
}

/// `--colour-by return` on a real LiDAR tile: first returns (most of the ground) take the
/// first colour, and some pixels (canopy) show later returns.
#[test]
fn lidar_colours_by_return_number() {
    let Some(data) = data_dir() else {
        return;
    };
    let laz = data.join("lidar/autzen_trim.laz");
    let out = std::env::temp_dir().join(format!("stipple-returns-{}.png", std::process::id()));
    let text = stipple([
        "render",
        laz.to_str().unwrap(),
        "--colour-by",
        "return",
        "--no-lighting",
        "--pipeline",
        "dobrev",
        "--size",
        "256x192",
        "--backend",
        "cpu",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(text.contains("colouring by return number"), "{text}");
    let (_, _, rgba) = stipple_io::image::read_png(&out).unwrap();
    std::fs::remove_file(&out).ok();
    let (mut first, mut later) = (0, 0);
    for p in rgba.chunks(4) {
        let [r, g, b] = [p[0] as i32, p[1] as i32, p[2] as i32];
        // Light grey (first returns) against amber, orange and red (later ones).
        if (r - b).abs() < 25 && (r - g).abs() < 25 && r > 120 {
            first += 1;
        } else if r > 150 && b < 110 {
            later += 1;
        }
    }
    assert!(
        first > 5 * later && later >= 5,
        "first {first}, later {later}"
    );
}

/// The default framing looks at a scanned object's front: the Stanford Lucy and Armadillo
/// face −Z (the eye comes out on −Z of the target), the bunny, the Dragon and the Happy
/// Buddha face +Z; `--view` still names the side.
#[test]
fn the_default_framing_finds_the_front() {
    let Some(data) = data_dir() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("stipple-front-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let side = |name: &str, extra: &[&str]| {
        let cam = dir.join("c.json");
        let (file, cam_s, png) = (data.join(name), cam.to_str().unwrap(), dir.join("x.png"));
        let mut args = vec!["render", file.to_str().unwrap(), "--size", "48"];
        args.extend(["--backend", "cpu", "--pipeline", "dobrev"]);
        args.extend(["--camera-out", cam_s, "-o", png.to_str().unwrap()]);
        args.extend(extra);
        stipple(args);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&cam).unwrap()).unwrap();
        let z = |k: &str| v[k][2].as_f64().unwrap();
        (z("eye") - z("target")).signum()
    };
    for (name, want) in [
        ("stanford/lucy/Lucy100k.ply", -1.0),
        ("stanford/armadillo/Armadillo_38k_normals.ply", -1.0),
        ("stanford/bunny/bun_zipper.ply", 1.0),
        ("stanford/dragon/dragon_vrip_res2.ply.gz", 1.0),
        ("stanford/buddha/happy_rawscan_78k.xyz", 1.0),
    ] {
        assert_eq!(side(name, &[]), want, "{name}");
    }
    assert_eq!(
        side("stanford/lucy/Lucy100k.ply", &["--view", "three-quarter"]),
        1.0
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A decimated scan (the Dragon at a quarter of its points, 2 px apart at 768²) rendered
/// with estimated normals shows the normals of the full scan at the same camera: the
/// quadric fits that bend its splats follow the surface's own curvature where it changes
/// within a neighbourhood (`stipple_core::normals`, the local fit). Median angle between
/// the two images' normals over the pixels both cover: 1.5° with the broad fit alone.
#[test]
fn a_decimated_scan_shows_the_full_scans_normals() {
    let Some(data) = data_dir() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("stipple-decimated-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cam = dir.join("c.json");
    let normals = |name: &str, camera: &[&str]| -> Vec<f32> {
        let (file, out, png) = (data.join(name), dir.join("n.npy"), dir.join("x.png"));
        let mut args = vec!["render", file.to_str().unwrap(), "--size", "768"];
        args.extend(["--backend", "cpu"]);
        args.extend(camera);
        args.extend([
            "--normal-out",
            out.to_str().unwrap(),
            "-o",
            png.to_str().unwrap(),
        ]);
        stipple(args);
        let (shape, n) = stipple_io::image::read_npy_shaped(&out).unwrap();
        std::fs::remove_file(&out).unwrap();
        assert_eq!(shape, [768, 768, 3], "{name}");
        n
    };
    let full = normals(
        "stanford/dragon/dragon_vrip.ply.gz",
        &["--camera-out", cam.to_str().unwrap()],
    );
    let part = normals(
        "stanford/dragon/dragon_vrip_res2.ply.gz",
        &["--camera", cam.to_str().unwrap()],
    );
    assert_eq!(full.len(), part.len());
    let mut off: Vec<f32> = full
        .chunks_exact(3)
        .zip(part.chunks_exact(3))
        .filter(|(a, b)| !a[0].is_nan() && !b[0].is_nan())
        .map(|(a, b)| {
            let d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            d.clamp(-1.0, 1.0).acos().to_degrees()
        })
        .collect();
    off.sort_by(f32::total_cmp);
    let (med, p90) = (off[off.len() / 2], off[off.len() * 9 / 10]);
    eprintln!(
        "Dragon res2 against the full scan: normals {med:.2}° apart (median), {p90:.2}° (90th), \
         over {} pixels",
        off.len()
    );
    assert!(off.len() > 100_000, "{} pixels", off.len());
    assert!(med <= 1.2 && p90 <= 4.5, "{med} {p90}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A placeholder intensity is not shown: the Stanford bunny's zipper reconstruction writes
/// intensity 0.5 for 79% of its points and lower values at scattered others, and
/// showing it as grey speckled the bunny white and grey. Its default frame is the frame of
/// the same points without intensity (the material's colour). A LiDAR scan's intensity
/// (lone-star, no RGB) still shows as grey.
#[test]
fn a_placeholder_intensity_is_not_shown() {
    let Some(data) = data_dir() else {
        return;
    };
    let frames = |name: &str| {
        let cloud = stipple_io::read_cloud(&data.join(name)).unwrap();
        assert!(
            cloud.intensity.is_some() && cloud.colors.is_none(),
            "{name}"
        );
        let (lo, hi) = cloud.world_bounds();
        let cam = Camera::framing_up(lo, hi, 160, 120, 45.0, cloud.z_up);
        let mut plain = cloud.clone();
        plain.intensity = None;
        let [with, without] = [cloud, plain].map(|c| {
            let p = PreparedCloud::new(c);
            let shown = p.intensity_scale.is_some();
            let f = render(&p, &cam, &Pipeline::default(), Backend::Cpu).unwrap();
            (shown, f.rgba)
        });
        (with, without)
    };
    let ((shown, with), (_, without)) = frames("stanford/bunny/bun_zipper.ply");
    assert!(!shown);
    assert!(
        with == without,
        "the bunny's placeholder intensity changed its frame"
    );
    let ((shown, with), (_, without)) = frames("lidar/lone-star.laz");
    assert!(shown);
    let differ = with.iter().zip(&without).filter(|(a, b)| a != b).count();
    assert!(
        differ > with.len() / 10,
        "lone-star: {differ} pixels differ"
    );
    // The command line says which intensity it does not show, and how to show it.
    let out = std::env::temp_dir().join(format!("stipple-placeholder-{}.png", std::process::id()));
    let said = |name: &str| {
        let file = data.join(name);
        let args = [
            "render",
            file.to_str().unwrap(),
            "--size",
            "64",
            "--backend",
            "cpu",
        ];
        let text =
            stipple(
                args.into_iter()
                    .chain(["--pipeline", "raw", "-o", out.to_str().unwrap()]),
            );
        text.contains("the intensity is one value for 79% of the points (a placeholder)")
            && text.contains("--colour-by intensity shows it")
    };
    assert!(said("stanford/bunny/bun_zipper.ply"));
    assert!(!said("lidar/lone-star.laz"));
    std::fs::remove_file(&out).ok();
}

/// A depth camera quantises depth in steps far wider than its points' spacing (the PCL
/// office, a Kinect capture: 7 cm steps at 5 m, points 1 cm apart). Points alone on their
/// step, or in a row along a step's edge, had normals tilted by up to 90° towards the next
/// step (their splats stood edge-on across the back wall: dark streaks); they now take the
/// steps' normal (`stipple_core::normals::robust_normals`, detached points). Measured on the
/// walls facing the camera, against PCA over 64 neighbours (which spans the steps): 539
/// normals over 45° off with PCA over 16, 421 after the re-fit before, 19 now.
#[test]
fn a_depth_cameras_steps_leave_no_edge_on_splats() {
    use stipple_core::normals as nm;
    let Some(data) = data_dir() else {
        return;
    };
    let c = stipple_io::read_cloud(&data.join("colored/office1.pcd")).unwrap();
    let pos = &c.positions;
    let truth = nm::pca_normals(pos, &nm::neighbours(pos, 64).unwrap());
    let walls: Vec<usize> = (0..pos.len())
        .filter(|&i| truth[i].z.abs() > 0.97)
        .collect();
    let off = |n: &[glam::Vec3]| {
        walls
            .iter()
            .filter(|&&i| n[i].normalize_or_zero().dot(truth[i]).abs() < 0.7)
            .count()
    };
    let pca = off(&nm::pca_normals(pos, &nm::neighbours(pos, 16).unwrap()));
    let est = nm::estimate_from(pos, None, 16, 1.0, nm::Towards::Unknown).unwrap();
    let now = off(&est.normals);
    eprintln!(
        "office walls: {} points, over 45° off: PCA {pca}, estimate {now}",
        walls.len()
    );
    assert!(walls.len() > 50_000 && pca > 200, "{} {pca}", walls.len());
    assert!(now * 10 <= pca, "{now} of PCA's {pca}");
}

/// A depth camera's quantised depths (the Kinect office: 125 distinct depths, steps of 1 to
/// 8 cm, points 2 to 9 mm apart): every neighbourhood lay on one terrace, so oblique walls
/// and the floor had normals facing the camera with steeply tilted ones along each step's
/// edge. Render's preparation smooths the depths across the steps first
/// (`stipple_core::normals::quantised`) and says so; the normals then agree with their
/// neighbours' where they disagreed along every step.
#[test]
fn a_depth_cameras_quantised_depths_are_smoothed_before_estimating() {
    use stipple_core::normals as nm;
    let Some(data) = data_dir() else {
        return;
    };
    let file = data.join("colored/office1.pcd");
    let c = stipple_io::read_cloud(&file).unwrap();
    // Points whose normal is over 30° from most of their 16 neighbours'.
    let rough = |pos: &[glam::Vec3], n: &[glam::Vec3]| {
        let nb = nm::neighbours(pos, 16).unwrap();
        (0..pos.len())
            .filter(|&i| {
                let ids = nb.of(i);
                let off = ids
                    .iter()
                    .filter(|&&j| n[i].dot(n[j as usize]).abs() < 0.866);
                2 * off.count() > ids.len()
            })
            .count()
    };
    let stored = nm::estimate_from(&c.positions, None, 16, 1.0, nm::Towards::Unknown).unwrap();
    let before = rough(&c.positions, &stored.normals);
    let mut p = stipple_render::PreparedCloud::new(c);
    let at = p.cloud.sensor.map(|s| s.position);
    let r = p.prepare_surface_from(16, true, at).unwrap();
    let (levels, _) = r.dequantised.expect("the office's depths are quantised");
    let after = rough(&p.cloud.positions, p.cloud.normals.as_ref().unwrap());
    eprintln!("office: {levels} depths; normals off most neighbours' {before} -> {after}");
    assert!(levels < 200, "{levels}");
    assert!(before > 5_000 && after * 5 <= before, "{before} -> {after}");
    // The command line says what it did.
    let out = std::env::temp_dir().join(format!("stipple-office-{}.png", std::process::id()));
    let text = stipple([
        "render".as_ref(),
        file.as_os_str(),
        "--size".as_ref(),
        "64x48".as_ref(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    std::fs::remove_file(&out).ok();
    assert!(text.contains("a depth camera's"), "{text}");
}
