//! Write → read round trips for every writable format, and encoding variants of PLY.

use glam::{DVec3, Vec3};
use std::path::PathBuf;
use stipple_core::demo::{generate, DemoScene};
use stipple_core::PointCloud;
use stipple_io::ply::{parse_ply, write_ply_to, Encoding};

fn tempdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("stipple-rt-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn cloud() -> PointCloud {
    let mut c = generate(DemoScene::Torus, 500, 11);
    c.intensity = Some((0..500).map(|i| (i * 97 % 65536) as u16).collect());
    c.opacity = Some((0..500).map(|i| (i % 256) as f32 / 255.0).collect());
    c.faces = vec![[0, 1, 2], [3, 4, 5]];
    c.fields = vec![
        stipple_core::cloud::Field::new(
            "curvature",
            &(0..500).map(|i| i as f64 * 0.01).collect::<Vec<_>>(),
        ),
        // GPS times: large values a quarter-second apart must survive.
        stipple_core::cloud::Field::new(
            "gps_time",
            &(0..500)
                .map(|i| 4.0e8 + i as f64 * 0.25)
                .collect::<Vec<_>>(),
        ),
    ];
    c
}

fn assert_close(a: &PointCloud, b: &PointCloud, tol: f64) {
    assert_eq!(a.len(), b.len());
    for i in 0..a.len() {
        assert!(
            (a.world(i) - b.world(i)).abs().max_element() <= tol,
            "point {i}"
        );
    }
}

#[test]
fn ply_round_trips_in_every_encoding() {
    let c = cloud();
    for enc in [
        Encoding::Ascii,
        Encoding::BinaryLittleEndian,
        Encoding::BinaryBigEndian,
    ] {
        let mut bytes = Vec::new();
        write_ply_to(&mut bytes, &c, enc).unwrap();
        let r = parse_ply(&bytes).unwrap();
        assert_close(&c, &r, 1e-6);
        assert_eq!(r.colors, c.colors, "{enc:?}");
        assert_eq!(r.intensity, c.intensity, "{enc:?}");
        assert_eq!(r.faces, c.faces, "{enc:?}");
        assert_eq!(r.fields.len(), 2, "{enc:?}");
        for (f, g) in c.fields.iter().zip(&r.fields) {
            assert_eq!(f.name, g.name);
            for i in 0..c.len() {
                assert!((f.value(i) - g.value(i)).abs() < 1e-6, "{} {i}", f.name);
            }
        }
        let (n0, n1) = (c.normals.as_ref().unwrap(), r.normals.as_ref().unwrap());
        assert!(n0.iter().zip(n1).all(|(a, b)| (*a - *b).length() < 1e-5));
        let (a0, a1) = (c.opacity.as_ref().unwrap(), r.opacity.as_ref().unwrap());
        assert!(a0.iter().zip(a1).all(|(a, b)| (a - b).abs() < 1.0 / 255.0));
    }
}

#[test]
fn gzip_ply_and_lidar_coordinates_round_trip() {
    let dir = tempdir("gz");
    let world: Vec<DVec3> = (0..100)
        .map(|i| DVec3::new(637_000.0 + i as f64 * 0.001, 850_000.5, 10.0 + i as f64))
        .collect();
    let c = PointCloud::from_world(&world);
    let mut raw = Vec::new();
    write_ply_to(&mut raw, &c, Encoding::BinaryLittleEndian).unwrap();
    let path = dir.join("c.ply.gz");
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut enc, &raw).unwrap();
    std::fs::write(&path, enc.finish().unwrap()).unwrap();
    let r = stipple_io::read_cloud(&path).unwrap();
    assert_close(&c, &r, 1e-4);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn las_laz_and_xyz_round_trip() {
    let dir = tempdir("las");
    let mut c = cloud();
    c.faces.clear();
    c.opacity = None;
    c.classification = Some((0..500).map(|i| (i % 10) as u8).collect());
    for ext in ["las", "laz", "xyz"] {
        let path = dir.join(format!("c.{ext}"));
        stipple_io::write_cloud(&path, &c).unwrap();
        let r = stipple_io::read_cloud(&path).unwrap();
        assert_close(&c, &r, if ext == "xyz" { 1e-6 } else { 1e-4 });
        assert_eq!(r.colors, c.colors, "{ext}");
        if ext != "xyz" {
            assert_eq!(r.intensity, c.intensity, "{ext}");
            assert_eq!(r.classification, c.classification, "{ext}");
        } else {
            assert!(r.normals.is_some());
        }
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn xyz_layouts_are_understood() {
    let c = stipple_io::xyz::parse_xyz("X,Y,Z,Red,Green,Blue\n1,2,3,255,0,10\n4,5,6,0,128,0\n")
        .unwrap();
    assert_eq!(c.colors.unwrap(), vec![[255, 0, 10], [0, 128, 0]]);
    let c = stipple_io::xyz::parse_xyz("1 2 3 0 0 1\n4 5 6 1 0 0\n").unwrap();
    assert_eq!(c.normals.unwrap(), vec![Vec3::Z, Vec3::X]);
    let c = stipple_io::xyz::parse_xyz("1 2 3 0.5 0.5 0.5\n4 5 6 1 0 0\n").unwrap();
    assert!(c.normals.is_none());
    assert_eq!(c.colors.unwrap()[0], [128, 128, 128]);
    let c = stipple_io::xyz::parse_xyz("2\n1 2 3 7 10 20 30\n4 5 6 8 1 2 3\n").unwrap();
    assert_eq!(c.len(), 2);
    assert_eq!(c.intensity.unwrap(), vec![7, 8]);
}

#[test]
fn outputs_round_trip() {
    let dir = tempdir("img");
    let d: Vec<f32> = (0..12)
        .map(|i| {
            if i == 5 {
                f32::INFINITY
            } else {
                i as f32 * 0.5
            }
        })
        .collect();
    let p = dir.join("d.npy");
    stipple_io::image::write_npy(&p, 4, 3, &d).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!((bytes.len() - 48) % 4, 0);
    assert_eq!(bytes.len(), 128 + 12 * 4, "header padded to 64 bytes");
    let (w, h, back) = stipple_io::image::read_npy(&p).unwrap();
    assert_eq!((w, h), (4, 3));
    assert_eq!(back, d);
    let rgba: Vec<u8> = (0..4 * 3 * 4).map(|i| (i * 7) as u8).collect();
    let q = dir.join("i.png");
    stipple_io::image::write_png(&q, 4, 3, &rgba).unwrap();
    assert_eq!(stipple_io::image::read_png(&q).unwrap(), (4, 3, rgba));
    std::fs::remove_dir_all(dir).ok();
}
