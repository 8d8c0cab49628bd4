//! E57 (ASTM E2807) through the `e57` crate: every scan of the file, placed by its pose,
//! Cartesian or spherical (converted), with colours and intensity where the scans have them;
//! invalid points are dropped. A file whose scans disagree (one coloured, one not) keeps an
//! attribute only if every scan has it.

use glam::DVec3;
use stipple_core::PointCloud;

/// The most points read from an E57 file.
const MAX_POINTS: u64 = 1 << 31;

/// Reads an E57 file.
pub fn read_e57(path: &std::path::Path) -> Result<PointCloud, crate::IoError> {
    let f = std::fs::File::open(path).map_err(|e| crate::IoError::io(path, e))?;
    let size = f.metadata().map_err(|e| crate::IoError::io(path, e))?.len();
    parse_e57(std::io::BufReader::new(f), size).map_err(|e| crate::IoError::invalid(path, e))
}

/// Reads E57 data of `size` bytes.
pub fn parse_e57<R: std::io::Read + std::io::Seek>(
    reader: R,
    size: u64,
) -> Result<PointCloud, String> {
    let mut r = e57::E57Reader::new(reader).map_err(|e| format!("E57: {e}"))?;
    let scans = r.pointclouds();
    if scans.is_empty() {
        return Err("the E57 file holds no point clouds".into());
    }
    // Declared counts checked against the file: a record takes at least a bit or so, so
    // more records than 8 × the file's bytes cannot be real.
    let declared: u64 = scans.iter().map(|s| s.records).sum();
    if declared > MAX_POINTS || declared > size.saturating_mul(8) {
        return Err(format!(
            "the E57 scans declare {declared} points, more than a {size}-byte file can hold"
        ));
    }
    let colour = scans.iter().all(|s| s.has_color());
    let intensity = scans.iter().all(|s| s.has_intensity());
    let mut world = Vec::with_capacity(declared as usize);
    let mut colours = Vec::new();
    let mut intensities = Vec::new();
    for pc in &scans {
        let mut it = r
            .pointcloud_simple(pc)
            .map_err(|e| format!("E57 scan: {e}"))?;
        it.intensity_to_color(false);
        for p in it {
            let p = p.map_err(|e| format!("E57 point: {e}"))?;
            let e57::CartesianCoordinate::Valid { x, y, z } = p.cartesian else {
                continue;
            };
            let q = DVec3::new(x, y, z);
            if !q.is_finite() {
                continue;
            }
            if let Some(why) = stipple_core::cloud::coordinate_problem(q) {
                return Err(why);
            }
            world.push(q);
            if colour {
                let c = p.color.map_or([0.0; 3], |c| [c.red, c.green, c.blue]);
                colours.push(c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8));
            }
            if intensity {
                let i = p.intensity.unwrap_or(0.0).clamp(0.0, 1.0);
                intensities.push((i * 65535.0).round() as u16);
            }
        }
    }
    if world.is_empty() {
        return Err("the E57 scans hold no valid points".into());
    }
    let mut cloud = PointCloud::from_world(&world);
    cloud.colors = colour.then_some(colours);
    cloud.intensity = intensity.then_some(intensities);
    Ok(cloud)
}
