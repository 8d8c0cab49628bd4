//! LAS and LAZ 1.0–1.4 through the `las` crate (COPC files read as plain LAZ).
//!
//! Scaled integer coordinates become f64 world coordinates, stored relative to an origin at
//! the centre of the header bounds. RGB is 16-bit in the format; files that store 8-bit values
//! in it (maximum ≤ 255) are read as 8-bit, others are shifted down by 8 bits.

use crate::IoError;
use glam::DVec3;
use std::path::Path;
use stipple_core::PointCloud;

const BATCH: u64 = 1 << 20;

/// A LAS/LAZ file read in batches, its header's count checked against the file's size before
/// anything is allocated from it. Used by [`read_las`] and by the streaming LOD build.
pub struct LasBatches {
    path: std::path::PathBuf,
    reader: las::Reader,
    pub header: las::Header,
    /// Points the header declares (never 0).
    pub count: u64,
    /// Points read so far.
    pub read: u64,
    /// The latest batch.
    pub data: las::PointData,
}

impl LasBatches {
    pub fn open(path: &Path) -> Result<LasBatches, IoError> {
        let file_len = std::fs::metadata(path)
            .map_err(|e| IoError::io(path, e))?
            .len();
        let reader = las::Reader::from_path(path)
            .map_err(|e| IoError::invalid(path, format!("cannot read the LAS header: {e}")))?;
        let header = reader.header().clone();
        let count = header.number_of_points();
        if count == 0 {
            return Err(IoError::invalid(
                path,
                "the cloud has no points (header count 0)",
            ));
        }
        let fmt = header.point_format();
        let record = fmt.len() as u64;
        // An uncompressed file must hold every record; a compressed one at least a byte each.
        let min_bytes = if fmt.is_compressed {
            count
        } else {
            count.saturating_mul(record)
        };
        if min_bytes > file_len {
            return Err(IoError::invalid(
                path,
                format!(
                    "the header declares {count} points of {record} bytes, but the file has only {file_len} bytes: it is truncated or the count is wrong"
                ),
            ));
        }
        let data = las::PointDataBuilder::new().for_header(&header).build();
        Ok(LasBatches {
            path: path.to_owned(),
            reader,
            header,
            count,
            read: 0,
            data,
        })
    }

    /// Reads the next batch of at most `n` points into `data`; 0 once every declared point
    /// was read. A file that ends early or is corrupt is an error naming it.
    pub fn next_batch(&mut self, n: u64) -> Result<u64, IoError> {
        let (read, count) = (self.read, self.count);
        if read >= count {
            return Ok(0);
        }
        let got = self
            .reader
            .fill_points(n.max(1).min(count - read), &mut self.data)
            .map_err(|e| {
                IoError::invalid(
                    &self.path,
                    format!(
                        "point data is corrupt or truncated after {read} of {count} points: {e}"
                    ),
                )
            })?;
        if got == 0 {
            return Err(IoError::invalid(
                &self.path,
                format!("the file ends after {read} of the {count} points its header declares"),
            ));
        }
        self.read += got;
        Ok(got)
    }
}

/// Reads a LAS/LAZ file.
pub fn read_las(path: &Path) -> Result<PointCloud, IoError> {
    let file_len = std::fs::metadata(path)
        .map_err(|e| IoError::io(path, e))?
        .len();
    let mut batches = LasBatches::open(path)?;
    let header = batches.header.clone();
    let count = batches.count;
    let fmt = header.point_format();
    let b = header.bounds();
    let mut origin = DVec3::new(
        (b.min.x + b.max.x) * 0.5,
        (b.min.y + b.max.y) * 0.5,
        (b.min.z + b.max.z) * 0.5,
    )
    .round();
    if !origin.is_finite() || origin.abs().max_element() > 1e12 {
        origin = DVec3::ZERO;
    }
    let cap = count.min(file_len) as usize;
    let mut cloud = PointCloud {
        origin,
        positions: Vec::with_capacity(cap),
        intensity: Some(Vec::with_capacity(cap)),
        classification: Some(Vec::with_capacity(cap)),
        z_up: true,
        ..Default::default()
    };
    let mut rgb16: Option<Vec<[u16; 3]>> = fmt.has_color.then(|| Vec::with_capacity(cap));
    let mut read: u64 = 0;
    while batches.next_batch(BATCH)? > 0 {
        let pd = &batches.data;
        for (k, ((x, y), z)) in pd.x().zip(pd.y()).zip(pd.z()).enumerate() {
            let p = DVec3::new(x, y, z);
            if !p.is_finite() {
                return Err(IoError::invalid(
                    path,
                    format!("point {} has a non-finite coordinate", read + k as u64),
                ));
            }
            cloud.positions.push((p - origin).as_vec3());
        }
        cloud.intensity.as_mut().unwrap().extend(pd.intensity());
        cloud
            .classification
            .as_mut()
            .unwrap()
            .extend(pd.classification());
        if let (Some(dst), Some(src)) = (rgb16.as_mut(), pd.rgb()) {
            dst.extend(src.map(|(r, g, b)| [r, g, b]));
        }
        read = batches.read;
    }
    if let Some(rgb) = rgb16 {
        let max = rgb.iter().flatten().copied().max().unwrap_or(0);
        let shift = if max > 255 { 8 } else { 0 };
        cloud.colors = Some(rgb.iter().map(|c| c.map(|v| (v >> shift) as u8)).collect());
    }
    Ok(cloud)
}

/// Writes a LAS (or, with `compress`, LAZ) 1.2 file with point format 2 (RGB), 0.1 mm scale.
pub fn write_las(path: &Path, cloud: &PointCloud, compress: bool) -> Result<(), IoError> {
    let mut builder = las::Builder::from((1, 2));
    let mut format = las::point::Format::new(2).expect("format 2 exists");
    format.is_compressed = compress;
    builder.point_format = format;
    let (lo, _) = cloud.world_bounds();
    let scale = 1e-4;
    builder.transforms = las::Vector {
        x: las::Transform {
            scale,
            offset: lo.x.floor(),
        },
        y: las::Transform {
            scale,
            offset: lo.y.floor(),
        },
        z: las::Transform {
            scale,
            offset: lo.z.floor(),
        },
    };
    let header = builder
        .into_header()
        .map_err(|e| IoError::invalid(path, format!("cannot build a LAS header: {e}")))?;
    let mut w = las::Writer::from_path(path, header)
        .map_err(|e| IoError::invalid(path, format!("cannot write: {e}")))?;
    for i in 0..cloud.len() {
        let p = cloud.world(i);
        let color = cloud.colors.as_ref().map(|c| {
            let [r, g, b] = c[i].map(|v| v as u16 * 257);
            las::Color::new(r, g, b)
        });
        let point = las::Point {
            x: p.x,
            y: p.y,
            z: p.z,
            intensity: cloud.intensity.as_ref().map_or(0, |v| v[i]),
            classification: las::point::Classification::new(
                cloud.classification.as_ref().map_or(0, |v| v[i]).min(31),
            )
            .unwrap_or(las::point::Classification::CreatedNeverClassified),
            color: Some(color.unwrap_or(las::Color::new(65535, 65535, 65535))),
            ..Default::default()
        };
        w.write_point(point)
            .map_err(|e| IoError::invalid(path, format!("cannot write point {i}: {e}")))?;
    }
    w.close()
        .map_err(|e| IoError::invalid(path, format!("cannot finish the file: {e}")))?;
    Ok(())
}
