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

#[test]
fn every_covered_data_file_renders() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    if !dir.is_dir() {
        eprintln!("skipped: {} is absent", dir.display());
        return;
    }
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
