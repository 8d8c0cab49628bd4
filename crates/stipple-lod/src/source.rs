//! Build inputs, read as a stream of [`Record`] batches.
//!
//! LAS and LAZ (the formats of large scans and national LiDAR) are streamed: only a batch is
//! in memory at a time, so inputs may be far larger than RAM. Other formats (PLY, XYZ text)
//! are read whole by `stipple-io` and refused when the file alone exceeds the memory budget;
//! the error says to convert them to LAS/LAZ.
//!
//! Colour: RGB where the file has it (16-bit LAS colours are shifted to 8 bits, decided on
//! the file's first batch), else grey from intensity as the renderer shows it (scaled by the
//! first batch's 99th percentile; `stipple_core::colour_map::intensity_scale`), else a
//! neutral grey (also where the intensity is a placeholder, one value for most points).

use crate::record::Record;
use crate::LodError;
use glam::DVec3;
use std::path::{Path, PathBuf};
use stipple_core::PointCloud;

/// Grey for points without colour or intensity.
pub const NEUTRAL: [u8; 3] = [200, 200, 200];

pub struct Input {
    pub path: PathBuf,
    pub count: u64,
    /// World bounds, from the header (LAS) or the points (others).
    pub lo: DVec3,
    pub hi: DVec3,
    /// The points carry colour or intensity.
    pub coloured: bool,
    kind: Kind,
}

enum Kind {
    Las,
    Loaded(Box<PointCloud>),
}

/// Opens every input and reads what the build needs to plan: counts and bounds.
pub fn open_inputs(paths: &[PathBuf], memory: u64) -> Result<Vec<Input>, LodError> {
    if paths.is_empty() {
        return Err(LodError::Invalid("no input files".into()));
    }
    paths.iter().map(|p| open_input(p, memory)).collect()
}

fn open_input(path: &Path, memory: u64) -> Result<Input, LodError> {
    let mut head = [0u8; 4];
    {
        use std::io::Read;
        let mut f = std::fs::File::open(path).map_err(|e| LodError::io(path, e))?;
        let _ = f.read(&mut head).map_err(|e| LodError::io(path, e))?;
    }
    let file_len = std::fs::metadata(path)
        .map_err(|e| LodError::io(path, e))?
        .len();
    if &head == b"LASF" {
        // Opening checks the header's count against the file's size.
        let las = stipple_io::las_io::LasBatches::open(path)?;
        let (h, count) = (&las.header, las.count);
        let b = h.bounds();
        let lo = DVec3::new(b.min.x, b.min.y, b.min.z);
        let hi = DVec3::new(b.max.x, b.max.y, b.max.z);
        if !lo.is_finite() || !hi.is_finite() || lo.cmpgt(hi).any() {
            return Err(LodError::Input(stipple_io::IoError::invalid(
                path,
                "the header's bounds are not finite or are inverted",
            )));
        }
        return Ok(Input {
            path: path.to_owned(),
            count,
            lo,
            hi,
            coloured: true,
            kind: Kind::Las,
        });
    }
    if file_len > memory / 2 {
        return Err(LodError::Budget(format!(
            "{}: {} MiB of {} does not fit in half the memory budget ({} MiB); only LAS/LAZ inputs \
             are streamed: convert it (`stipple` reads it, e.g. with PDAL or las2las) or raise --memory",
            path.display(),
            file_len >> 20,
            stipple_io::extension(path),
            memory >> 21
        )));
    }
    let cloud = stipple_io::read_cloud(path)?;
    let (lo, hi) = cloud.world_bounds();
    Ok(Input {
        path: path.to_owned(),
        count: cloud.len() as u64,
        lo,
        hi,
        coloured: cloud.colors.is_some() || cloud.intensity.is_some(),
        kind: Kind::Loaded(Box::new(cloud)),
    })
}

fn bad(path: &Path, e: impl std::fmt::Display) -> LodError {
    LodError::Input(stipple_io::IoError::invalid(path, e.to_string()))
}

/// How a file's colour becomes 8-bit RGB.
#[derive(Clone, Copy)]
enum ColourMode {
    Rgb { shift: u32 },
    Intensity { scale: f32 },
    Neutral,
}

/// Grey from intensity under [`stipple_core::colour_map::intensity_scale`] (the renderer's
/// rule: 1 / the 99th percentile), or neutral where the intensity shows nothing.
fn intensity_mode(v: &[u16]) -> ColourMode {
    match stipple_core::colour_map::intensity_scale(v) {
        Some(scale) => ColourMode::Intensity { scale },
        None => ColourMode::Neutral,
    }
}

fn grey(i: u16, scale: f32) -> [u8; 3] {
    [stipple_core::colour_map::intensity_grey(i, scale); 3]
}

impl Input {
    /// Streams the points as records relative to `origin`, `batch` at a time. A point that
    /// is not finite is an error naming the file.
    pub fn read(
        &self,
        origin: DVec3,
        batch: usize,
        f: &mut dyn FnMut(&[Record]) -> Result<(), LodError>,
    ) -> Result<(), LodError> {
        let batch = batch.max(1);
        let path = &self.path;
        let mut out: Vec<Record> = Vec::with_capacity(batch.min(self.count as usize));
        match &self.kind {
            Kind::Loaded(c) => {
                let mode = match (&c.colors, &c.intensity) {
                    (Some(_), _) => ColourMode::Rgb { shift: 0 },
                    (None, Some(i)) => intensity_mode(i),
                    _ => ColourMode::Neutral,
                };
                for start in (0..c.len()).step_by(batch) {
                    out.clear();
                    for i in start..(start + batch).min(c.len()) {
                        let rgb = match mode {
                            ColourMode::Rgb { .. } => c.colors.as_ref().unwrap()[i],
                            ColourMode::Intensity { scale } => {
                                grey(c.intensity.as_ref().unwrap()[i], scale)
                            }
                            ColourMode::Neutral => NEUTRAL,
                        };
                        let p = if c.origin == origin {
                            c.positions[i]
                        } else {
                            (c.world(i) - origin).as_vec3()
                        };
                        out.push(Record::new(p, rgb));
                    }
                    f(&out)?;
                }
                Ok(())
            }
            Kind::Las => {
                let las = stipple_io::las_io::LasBatches::open(path)?;
                if let Some(r) = stipple_io::las_io::ChunkReader::open(path, &las)? {
                    return read_chunks(path, &r, origin, batch, f);
                }
                read_batches(path, las, origin, batch, f)
            }
        }
    }
}

/// A LAS/LAZ file read a group of chunks at a time (at least `batch` points), the chunks of a
/// group decoded and converted to records on all cores, straight into the batch; the batch
/// reader's colours (the mode chosen from the first batch's points) and errors.
fn read_chunks(
    path: &Path,
    r: &stipple_io::las_io::ChunkReader,
    origin: DVec3,
    batch: usize,
    f: &mut dyn FnMut(&[Record]) -> Result<(), LodError>,
) -> Result<(), LodError> {
    use rayon::prelude::*;
    let chunks = r.chunks();
    let rec = r.record_len();
    let mut mode: Option<ColourMode> = None;
    let mut out: Vec<Record> = Vec::new();
    let mut raws: Vec<Vec<u8>> = Vec::new();
    let mut start = 0;
    while start < chunks.len() {
        let mut end = start;
        let mut points = 0usize;
        while end < chunks.len() && (points < batch || end == start) {
            points += chunks[end].points as usize;
            end += 1;
        }
        let group = &chunks[start..end];
        raws.resize_with(group.len(), Vec::new);
        group
            .par_iter()
            .zip(raws.par_iter_mut())
            .try_for_each(|(c, raw)| r.records(c, raw))?;
        let mode = *mode.get_or_insert_with(|| {
            // The first `batch` points, as the batch reader sees its first batch.
            let all = || {
                raws.iter()
                    .flat_map(|b| b.chunks_exact(rec))
                    .take(batch)
                    .map(|b| r.point(b))
            };
            if r.has_rgb() {
                let max = all()
                    .map(|p| p.rgb.map_or(0, |[a, b, c]| a.max(b).max(c)))
                    .max()
                    .unwrap_or(0);
                ColourMode::Rgb {
                    shift: if max > 255 { 8 } else { 0 },
                }
            } else {
                intensity_mode(&all().map(|p| p.intensity).collect::<Vec<_>>())
            }
        });
        out.clear();
        out.resize(points, Record::zeroed());
        let mut parts = Vec::with_capacity(group.len());
        let mut rest = out.as_mut_slice();
        for c in group {
            let (a, b) = std::mem::take(&mut rest).split_at_mut(c.points as usize);
            parts.push(a);
            rest = b;
        }
        parts
            .into_par_iter()
            .zip(group.par_iter().zip(raws.par_iter()))
            .try_for_each(|(part, (c, raw))| {
                for (k, (o, b)) in part.iter_mut().zip(raw.chunks_exact(rec)).enumerate() {
                    let p = r.point(b);
                    if let Some(problem) = stipple_core::cloud::coordinate_problem(p.world) {
                        return Err(bad(
                            path,
                            format!("point {} has {problem}", c.first + k as u64),
                        ));
                    }
                    let rgb = match (mode, p.rgb) {
                        (ColourMode::Rgb { shift }, Some(c)) => {
                            c.map(|v| (v >> shift).min(255) as u8)
                        }
                        (ColourMode::Intensity { scale }, _) => grey(p.intensity, scale),
                        _ => NEUTRAL,
                    };
                    *o = Record::new((p.world - origin).as_vec3(), rgb);
                }
                Ok(())
            })?;
        f(&out)?;
        start = end;
    }
    Ok(())
}

/// A LAS/LAZ file read batch by batch through the `las` crate: files [`read_chunks`] cannot
/// split (extra bytes, a LAZ file without a chunk table).
fn read_batches(
    path: &Path,
    mut las: stipple_io::las_io::LasBatches,
    origin: DVec3,
    batch: usize,
    f: &mut dyn FnMut(&[Record]) -> Result<(), LodError>,
) -> Result<(), LodError> {
    let mut out: Vec<Record> = Vec::new();
    let mut mode: Option<ColourMode> = None;
    loop {
        let read = las.read;
        if las.next_batch(batch as u64)? == 0 {
            break;
        }
        let pd = &las.data;
        let mode = *mode.get_or_insert_with(|| match pd.rgb() {
            Some(rgb) => {
                let max = rgb.map(|(r, g, b)| r.max(g).max(b)).max().unwrap_or(0);
                ColourMode::Rgb {
                    shift: if max > 255 { 8 } else { 0 },
                }
            }
            None => intensity_mode(&pd.intensity().collect::<Vec<_>>()),
        });
        out.clear();
        for (k, ((x, y), z)) in pd.x().zip(pd.y()).zip(pd.z()).enumerate() {
            let w = DVec3::new(x, y, z);
            if let Some(problem) = stipple_core::cloud::coordinate_problem(w) {
                return Err(bad(
                    path,
                    format!("point {} has {problem}", read + k as u64),
                ));
            }
            out.push(Record::new((w - origin).as_vec3(), NEUTRAL));
        }
        match mode {
            ColourMode::Rgb { shift } => {
                if let Some(rgb) = pd.rgb() {
                    for (r, (cr, cg, cb)) in out.iter_mut().zip(rgb) {
                        r.rgb = [cr, cg, cb].map(|v| (v >> shift).min(255) as u8);
                    }
                }
            }
            ColourMode::Intensity { scale } => {
                for (r, i) in out.iter_mut().zip(pd.intensity()) {
                    r.rgb = grey(i, scale);
                }
            }
            ColourMode::Neutral => {}
        }
        f(&out)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(path: &Path, n: usize, format: u8, compress: bool) {
        let mut b = las::Builder::from((1, 2));
        let mut f = las::point::Format::new(format).unwrap();
        f.is_compressed = compress;
        b.point_format = f;
        let t = |offset: f64| las::Transform {
            scale: 0.001,
            offset,
        };
        b.transforms = las::Vector {
            x: t(637_000.0),
            y: t(850_000.0),
            z: t(100.0),
        };
        let mut w = las::Writer::from_path(path, b.into_header().unwrap()).unwrap();
        let mut rng = stipple_core::rng::Rng::new(7);
        for _ in 0..n {
            let v = |rng: &mut stipple_core::rng::Rng| (rng.f64() * 65535.0) as u16;
            w.write_point(las::Point {
                x: 637_000.0 + rng.f64() * 500.0,
                y: 850_000.0 + rng.f64() * 300.0,
                z: 100.0 + rng.f64() * 20.0,
                intensity: v(&mut rng),
                color: (format == 2).then(|| las::Color::new(v(&mut rng), v(&mut rng), 9)),
                ..Default::default()
            })
            .unwrap();
        }
        w.close().unwrap();
    }

    /// The parallel chunk reader gives the batch reader's records, colours included, in the
    /// same order: RGB (16-bit, shifted) and intensity files, LAS and LAZ, several groups.
    #[test]
    fn chunked_and_batch_reads_agree() {
        let dir = std::env::temp_dir().join(format!("stipple-src-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let origin = DVec3::new(637_250.0, 850_150.0, 110.0);
        for (format, compress) in [(2, false), (2, true), (0, false), (0, true)] {
            let p = dir.join(if compress { "a.laz" } else { "a.las" });
            write(&p, 150_000, format, compress);
            let collect = |chunked: bool| {
                let (mut all, mut batches) = (Vec::new(), 0);
                let mut f = |b: &[Record]| {
                    all.extend_from_slice(b);
                    batches += 1;
                    Ok(())
                };
                let las = stipple_io::las_io::LasBatches::open(&p).unwrap();
                if chunked {
                    let r = stipple_io::las_io::ChunkReader::open(&p, &las)
                        .unwrap()
                        .expect("the file splits into chunks");
                    read_chunks(&p, &r, origin, 40_000, &mut f).unwrap();
                } else {
                    read_batches(&p, las, origin, 40_000, &mut f).unwrap();
                }
                (all, batches)
            };
            let (a, na) = collect(true);
            let (b, nb) = collect(false);
            assert_eq!(a.len(), 150_000);
            assert!(na > 1 && nb > 1, "{na} and {nb} batches");
            assert!(a == b, "format {format}, compressed {compress}");
            // The colours are the file's, not the neutral grey.
            assert!(a.iter().any(|r| r.rgb != NEUTRAL && r.rgb[0] != r.rgb[2]) || format == 0);
            assert!(a.iter().any(|r| r.rgb != NEUTRAL));
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
