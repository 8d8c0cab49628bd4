//! LAS and LAZ 1.0–1.4 through the `las` crate (COPC files read as plain LAZ).
//!
//! Scaled integer coordinates become f64 world coordinates, stored relative to an origin at
//! the centre of the header bounds. RGB is 16-bit in the format; files that store 8-bit values
//! in it (maximum ≤ 255) are read as 8-bit, others are shifted down by 8 bits.
//!
//! Extra bytes (LAS 1.4 §2.5.11; the "Extra Bytes" VLR describes them) become scalar fields
//! by their names, scaled and offset as the descriptor says: single numbers of the ten
//! standard types; undocumented bytes and the deprecated two- and three-value types are
//! skipped.

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
        // The header's sizes, counts and offsets are checked against the file first: the
        // `las` crate trusts them (allocating what they claim).
        if let Some(problem) = header_problem(path, file_len) {
            return Err(IoError::invalid(path, problem));
        }
        let reader = las::Reader::from_path(path)
            .map_err(|e| IoError::invalid(path, explain_open_error(path, file_len, &e)))?;
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
        // The LAZ decoder can panic on corrupt chunks (an index out of bounds; found by
        // fuzzing): that is an error like any other corruption.
        let (reader, data) = (&mut self.reader, &mut self.data);
        let got = guarded(|| {
            reader
                .fill_points(n.max(1).min(count - read), data)
                .map_err(|e| e.to_string())
        })
        .map_err(|e| {
            IoError::invalid(
                &self.path,
                format!("point data is corrupt or truncated after {read} of {count} points: {e}"),
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

/// Says what is wrong with a LAS/LAZ file the `las` crate could not open, from the header's
/// own fields where they explain it (truncation, counts and offsets beyond the file).
fn explain_open_error(path: &Path, file_len: u64, e: &las::Error) -> String {
    if let Some(problem) = header_problem(path, file_len) {
        return problem;
    }
    let text = e.to_string();
    let compressed = std::fs::File::open(path)
        .and_then(|mut f| {
            use std::io::{Read, Seek};
            let mut b = [0u8; 1];
            f.seek(std::io::SeekFrom::Start(104))?;
            f.read_exact(&mut b)?;
            Ok(b[0] & 0xC0 != 0)
        })
        .unwrap_or(false);
    if text.contains("fill whole buffer") || text.contains("os error 22") {
        return if compressed {
            format!(
                "the LAZ data cannot be read ({text}): the file ({file_len} bytes) is \
                 truncated or an offset in it is wrong (LAZ keeps its chunk table at the end, \
                 so a cut file loses it)"
            )
        } else {
            format!(
                "the header or its variable-length records reach past the end of the file \
                 ({file_len} bytes): it is truncated or an offset in it is wrong ({text})"
            )
        };
    }
    format!("cannot read the LAS header: {text}")
}

/// A LAS header whose sizes, offsets or counts cannot fit the file, said plainly.
fn header_problem(path: &Path, file_len: u64) -> Option<String> {
    use std::io::{Read, Seek, SeekFrom};
    // Up to the LAS 1.4 header's 375 bytes; 227 are required.
    let mut head = [0u8; 375];
    let Ok(mut file) = std::fs::File::open(path) else {
        return None;
    };
    let mut n = 0;
    while n < head.len() {
        match file.read(&mut head[n..]) {
            Ok(0) | Err(_) => break,
            Ok(k) => n += k,
        }
    }
    if n < 227 {
        return Some(format!(
            "the file ends after {file_len} bytes, inside the LAS header (which takes at \
             least 227): it is truncated"
        ));
    }
    let u16_at = |o: usize| u16::from_le_bytes([head[o], head[o + 1]]) as u64;
    let u32_at = |o: usize| u32::from_le_bytes(head[o..o + 4].try_into().unwrap()) as u64;
    let (header_size, point_offset, nvlr) = (u16_at(94), u32_at(96), u32_at(100));
    if header_size < 227 {
        return Some(format!(
            "the header says it is {header_size} bytes long; a LAS header takes at least 227: \
             the header is corrupt"
        ));
    }
    if header_size > file_len {
        return Some(format!(
            "the header says it is {header_size} bytes long, but the file has only \
             {file_len}: it is truncated"
        ));
    }
    if point_offset > file_len {
        return Some(format!(
            "the header says the points start at byte {point_offset}, but the file has only \
             {file_len} bytes: it is truncated"
        ));
    }
    // A variable-length record takes at least 54 bytes.
    if nvlr.saturating_mul(54) > file_len {
        return Some(format!(
            "the header declares {nvlr} variable-length records, more than the file's \
             {file_len} bytes can hold: the header is corrupt"
        ));
    }
    // The point records' extent must be a number (the `las` crate multiplies count and
    // record length unchecked: an overflow panic in debug builds; found by fuzzing).
    let record_len = u16_at(105);
    let legacy_count = u32_at(107);
    let count = if head[25] >= 4 && n >= 255 {
        u64::from_le_bytes(head[247..255].try_into().unwrap()).max(legacy_count)
    } else {
        legacy_count
    };
    if count
        .checked_mul(record_len)
        .and_then(|b| b.checked_add(point_offset))
        .is_none()
    {
        return Some(format!(
            "the header declares {count} points of {record_len} bytes, more than any file can \
             hold: the header is corrupt"
        ));
    }
    // LAS 1.4 extended VLRs: each one's 64-bit length must stay inside the file (the `las`
    // crate allocates it before reading: a bogus length panicked or exhausted memory; found
    // by fuzzing).
    let minor = head[25];
    if minor >= 4 && n >= 247 {
        let u64_at = |o: usize| u64::from_le_bytes(head[o..o + 8].try_into().unwrap());
        let (mut at, count) = (u64_at(235), u32_at(243));
        if count > 0 && at.saturating_add(count.saturating_mul(60)) > file_len {
            return Some(format!(
                "the header declares {count} extended variable-length records from byte {at}, \
                 beyond the file's {file_len} bytes: it is truncated or the header is corrupt"
            ));
        }
        for k in 0..count {
            let mut len = [0u8; 8];
            if file.seek(SeekFrom::Start(at + 20)).is_err() || file.read_exact(&mut len).is_err() {
                return Some(format!("extended variable-length record {k} is cut short"));
            }
            let len = u64::from_le_bytes(len);
            at = at.saturating_add(60).saturating_add(len);
            if at > file_len {
                return Some(format!(
                    "extended variable-length record {k} claims {len} bytes, beyond the end of \
                     the file ({file_len} bytes): it is truncated or corrupt"
                ));
            }
        }
    }
    if head[104] & 0x80 != 0 {
        return laz_problem(
            &file,
            file_len,
            header_size,
            head[25],
            nvlr,
            point_offset,
            record_len,
        );
    }
    None
}

/// Runs the LAZ decoder with its panics on corrupt data (an index out of bounds; found by
/// fuzzing) turned into errors like any other corruption.
fn guarded<T>(decode: impl FnOnce() -> Result<T, String>) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(decode))
        .unwrap_or_else(|_| Err("the LAZ decoder failed on it".into()))
}

/// Decodes one LAZ chunk (`bytes`) of `points` records into `raw`: a layered chunk's layer
/// table is checked against its size first ([`layered_chunk_problem`]), and the decoder is
/// [`guarded`]. Used by the parallel LAS reader and by COPC nodes.
pub(crate) fn decode_chunk(
    bytes: &[u8],
    raw: &mut [u8],
    vlr: &laz::LazVlr,
    points: u64,
) -> Result<(), String> {
    if let Some(layers) = laz_layers(vlr) {
        let rec = vlr.items_size() as usize;
        if let Some(p) = layered_chunk_problem(bytes, bytes.len() as u64, rec, layers) {
            return Err(p);
        }
    }
    let entry = laz::laszip::ChunkTableEntry {
        point_count: points,
        byte_count: bytes.len() as u64,
    };
    guarded(|| laz::par_decompress(bytes, raw, vlr, &[entry]).map_err(|e| e.to_string()))
}

/// Layers per chunk of a LAS 1.4 ("layered") LAZ record, from its items; None for point-wise
/// compression (LAS 1.0–1.3 formats), whose chunks carry no layer table.
pub(crate) fn laz_layers(vlr: &laz::LazVlr) -> Option<usize> {
    use laz::LazItemType as T;
    let mut layers = None;
    for it in vlr.items() {
        let n = match it.item_type() {
            T::Point14 => 9,
            T::RGB14 | T::WavePacket14 => 1,
            T::RGBNIR14 => 2,
            T::Byte14(n) => n as usize,
            _ => continue,
        };
        layers = Some(layers.unwrap_or(0) + n);
    }
    layers
}

/// What is wrong with a layered LAZ chunk of `chunk_bytes` bytes that starts with `head`
/// (its first point, point count and layer sizes; at least `record_len + 4 + 4 × layers`
/// bytes where the chunk has them): its layers must fit in it. The `laz` crate allocates
/// each layer at the size the chunk gives before reading it (found by fuzzing: a chunk of
/// a few hundred bytes asked for 3.9 GB).
pub(crate) fn layered_chunk_problem(
    head: &[u8],
    chunk_bytes: u64,
    record_len: usize,
    layers: usize,
) -> Option<String> {
    let table = record_len + 4 + 4 * layers;
    if chunk_bytes < table as u64 || head.len() < table {
        return Some(format!(
            "a compressed chunk of {chunk_bytes} bytes is shorter than its own layer table \
             ({table} bytes)"
        ));
    }
    let sizes: u64 = head[record_len + 4..table]
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().unwrap()) as u64)
        .sum();
    (sizes > chunk_bytes - table as u64).then(|| {
        format!(
            "a compressed chunk's layers claim {sizes} bytes, more than the chunk's {} bytes \
             hold",
            chunk_bytes - table as u64
        )
    })
}

/// A LAZ file's chunk table and chunks checked before the `las` crate reads them (it sizes
/// allocations from them): the table inside the file and its chunk count within the bytes
/// the chunks take; for layered (LAS 1.4) compression, every chunk's layers within the chunk.
fn laz_problem(
    file: &std::fs::File,
    file_len: u64,
    header_size: u64,
    version_minor: u8,
    nvlr: u64,
    point_offset: u64,
    record_len: u64,
) -> Option<String> {
    use std::os::unix::fs::FileExt;
    let read = |at: u64, n: usize| -> Option<Vec<u8>> {
        let mut b = vec![0u8; n];
        file.read_exact_at(&mut b, at).ok().map(|_| b)
    };
    let table_at = i64::from_le_bytes(read(point_offset, 8)?.try_into().unwrap());
    if table_at == -1 {
        // Written without a table (streamed): read sequentially by the `las` crate.
        return None;
    }
    let data_end = table_at as u64;
    if table_at < 0 || data_end < point_offset + 8 || data_end.saturating_add(8) > file_len {
        return Some(format!(
            "the LAZ chunk table's offset {table_at} lies outside the file's {file_len} bytes \
             of point data: it is truncated or corrupt"
        ));
    }
    let th = read(data_end, 8)?;
    let chunks = u32::from_le_bytes(th[4..8].try_into().unwrap()) as u64;
    // A chunk starts with its first point uncompressed.
    let room = data_end - point_offset - 8;
    if chunks > room / record_len.max(1) {
        return Some(format!(
            "the LAZ chunk table lists {chunks} chunks, more than the {room} bytes of \
             compressed points can hold: the file is corrupt"
        ));
    }
    // The LAZ VLR (the `las` crate reports a missing or broken one itself). The `las` crate
    // reads a LAS 1.4 header whole whatever size the header gives, so the VLRs are looked
    // for both where the header says and after the version's own header size.
    let own = match version_minor {
        4.. => 375,
        3 => 235,
        _ => 227,
    };
    let find = |start: u64| -> Option<laz::LazVlr> {
        let mut at = start;
        for _ in 0..nvlr {
            let h = read(at, 54)?;
            let len = u16::from_le_bytes([h[20], h[21]]) as u64;
            let uid = &h[2..18];
            let uid = &uid[..uid.iter().position(|&c| c == 0).unwrap_or(16)];
            if uid == b"laszip encoded" && u16::from_le_bytes([h[18], h[19]]) == 22204 {
                return laz::LazVlr::from_buffer(read(at + 54, len as usize)?).ok();
            }
            at = at.saturating_add(54 + len);
            if at > point_offset {
                return None;
            }
        }
        None
    };
    let vlr = find(header_size).or_else(|| find(own))?;
    let mut f = file;
    use std::io::{Seek, SeekFrom};
    f.seek(SeekFrom::Start(point_offset)).ok()?;
    let table = match laz::laszip::ChunkTable::read_from(f, &vlr) {
        Ok(t) => t,
        Err(e) => return Some(format!("the LAZ chunk table cannot be read: {e}")),
    };
    // The `laz` crate allocates the largest chunk's point count in bytes before decoding
    // (a fixed chunk size of 4 × 10⁹ asked for 4 GB; found by fuzzing). LAZ packs at most a
    // few hundred identical points into a byte: 1 024 a byte bounds any real chunk.
    let most = file_len.saturating_mul(1024).max(1 << 22);
    if let Some(big) = table.as_ref().iter().map(|e| e.point_count).max() {
        if big > most {
            return Some(format!(
                "a LAZ chunk claims {big} points, more than the file's {file_len} bytes can \
                 hold: the file is corrupt"
            ));
        }
    }
    let layers = laz_layers(&vlr)?;
    let mut at = point_offset + 8;
    let want = record_len as usize + 4 + 4 * layers;
    for (k, e) in table.as_ref().iter().enumerate() {
        if e.byte_count == 0 {
            continue;
        }
        if at.saturating_add(e.byte_count) > data_end {
            return Some(format!(
                "LAZ chunk {k} ({} bytes at {at}) runs past the chunk table: the file is corrupt",
                e.byte_count
            ));
        }
        let n = (want as u64).min(e.byte_count) as usize;
        let head = read(at, n)?;
        if let Some(p) = layered_chunk_problem(&head, e.byte_count, record_len as usize, layers) {
            return Some(format!("LAZ chunk {k}: {p}"));
        }
        at += e.byte_count;
    }
    None
}

/// Reads a LAS/LAZ file.
pub fn read_las(path: &Path) -> Result<PointCloud, IoError> {
    let batches = LasBatches::open(path)?;
    if let Some(reader) = ChunkReader::open(path, &batches)? {
        return read_las_parallel(path, &batches.header, batches.count, &reader);
    }
    read_las_batches(path, batches)
}

/// [`read_las`] batch by batch through the `las` crate: for files the parallel reader cannot
/// split (extra bytes, a LAZ file without a chunk table).
pub fn read_las_batches(path: &Path, mut batches: LasBatches) -> Result<PointCloud, IoError> {
    let file_len = std::fs::metadata(path)
        .map_err(|e| IoError::io(path, e))?
        .len();
    let header = batches.header.clone();
    let count = batches.count;
    let fmt = header.point_format();
    // The origin of the f32 offsets (see `choose_origin`), from the first batch.
    batches.next_batch(BATCH)?;
    let (flo, fhi) = {
        let pd = &batches.data;
        pd.x()
            .zip(pd.y())
            .zip(pd.z())
            .map(|((x, y), z)| DVec3::new(x, y, z))
            .filter(|p| p.is_finite())
            .fold(
                (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(lo, hi), p| (lo.min(p), hi.max(p)),
            )
    };
    let origin = choose_origin(&header, flo, fhi);
    let cap = count.min(file_len) as usize;
    let mut positions = Vec::new();
    stipple_core::sys::try_reserve(&mut positions, cap, "the points' positions")
        .map_err(|m| IoError::invalid(path, m))?;
    let mut cloud = PointCloud {
        origin,
        positions,
        intensity: Some(Vec::with_capacity(cap)),
        classification: Some(Vec::with_capacity(cap)),
        return_number: Some(Vec::with_capacity(cap)),
        z_up: true,
        ..Default::default()
    };
    let mut rgb16: Option<Vec<[u16; 3]>> = fmt.has_color.then(|| Vec::with_capacity(cap));
    // What places each pulse's sensor (airborne: GPS time, scan angle, flight line), kept
    // while reading to give each point the direction towards the aircraft.
    let mut pulses: Option<(Vec<f64>, Vec<f32>, Vec<u16>)> = fmt.has_gps_time.then(|| {
        (
            Vec::with_capacity(cap),
            Vec::with_capacity(cap),
            Vec::with_capacity(cap),
        )
    });
    let extra = extra_fields(&header, fmt.extra_bytes as usize);
    cloud.fields = extra
        .iter()
        .map(|e| stipple_core::cloud::Field {
            name: e.name.clone(),
            offset: f64::NAN,
            values: Vec::with_capacity(cap),
        })
        .collect();
    let mut read: u64 = 0;
    // The first batch is in `batches.data` already.
    let mut first = true;
    while first || batches.next_batch(BATCH)? > 0 {
        first = false;
        let pd = &batches.data;
        for (k, ((x, y), z)) in pd.x().zip(pd.y()).zip(pd.z()).enumerate() {
            let p = DVec3::new(x, y, z);
            if let Some(problem) = stipple_core::cloud::coordinate_problem(p) {
                return Err(IoError::invalid(
                    path,
                    format!("point {} has {problem}", read + k as u64),
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
        cloud
            .return_number
            .as_mut()
            .unwrap()
            .extend(pd.return_number());
        if let (Some(dst), Some(src)) = (rgb16.as_mut(), pd.rgb()) {
            dst.extend(src.map(|(r, g, b)| [r, g, b]));
        }
        if let (Some((t, a, s)), Some(gps)) = (pulses.as_mut(), pd.gps_time()) {
            t.extend(gps);
            a.extend(pd.scan_angle_degrees());
            s.extend(pd.point_source_id());
        }
        if !extra.is_empty() {
            let rec = pd.record_len();
            let start = rec - fmt.extra_bytes as usize;
            for r in pd.raw_bytes().chunks_exact(rec) {
                for (e, f) in extra.iter().zip(&mut cloud.fields) {
                    let v = e.value(&r[start..]);
                    if f.offset.is_nan() && v.is_finite() {
                        f.offset = v;
                    }
                    f.values.push((v - f.offset) as f32);
                }
            }
        }
        read = batches.read;
    }
    if let Some(rgb) = rgb16 {
        let max = rgb.iter().flatten().copied().max().unwrap_or(0);
        let shift = if max > 255 { 8 } else { 0 };
        cloud.colors = Some(rgb.iter().map(|c| c.map(|v| (v >> shift) as u8)).collect());
    }
    for f in &mut cloud.fields {
        if f.offset.is_nan() {
            f.offset = 0.0;
        }
    }
    if let Some((t, a, s)) = pulses {
        cloud.sensor_dirs =
            stipple_core::normals::airborne_sensor_dirs(&cloud.positions, &t, &a, &s);
    }
    Ok(cloud)
}

/// A run of points that decodes on its own: a LAZ chunk or a block of LAS records.
#[derive(Clone, Copy, Debug)]
pub struct Chunk {
    /// Where its bytes start in the file, and how many.
    pub offset: u64,
    pub bytes: u64,
    /// Its points, and the index of its first.
    pub points: u64,
    pub first: u64,
}

/// A file's runs of points, and the LAZ VLR that decodes them (None: uncompressed LAS).
type Chunks = (Vec<Chunk>, Option<laz::LazVlr>);

/// Points per block of an uncompressed LAS file read in parallel.
const LAS_BLOCK: u64 = 1 << 16;

/// How a file's points split into independent runs for [`read_las_parallel`]: LAZ chunks
/// from the chunk table, or blocks of LAS records. None where the file cannot be read that
/// way (extra bytes, whose fields [`read_las_batches`] handles; a LAZ file written without
/// a chunk table; chunk counts that do not add up to the header's, which the batch reader
/// reports precisely).
fn chunks_of(path: &Path, b: &LasBatches) -> Result<Option<Chunks>, IoError> {
    use std::os::unix::fs::FileExt;
    let fmt = b.header.point_format();
    if fmt.extra_bytes > 0 {
        return Ok(None);
    }
    let file = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| IoError::io(path, e))?.len();
    let mut raw = [0u8; 4];
    file.read_exact_at(&mut raw, 96)
        .map_err(|e| IoError::io(path, e))?;
    let point_offset = u32::from_le_bytes(raw) as u64;
    let rec = fmt.len() as u64;
    let count = b.count;
    if !fmt.is_compressed {
        let chunks = (0..count.div_ceil(LAS_BLOCK))
            .map(|k| {
                let first = k * LAS_BLOCK;
                let points = LAS_BLOCK.min(count - first);
                Chunk {
                    offset: point_offset + first * rec,
                    bytes: points * rec,
                    points,
                    first,
                }
            })
            .collect();
        return Ok(Some((chunks, None)));
    }
    let Some(vlr) = b
        .header
        .vlrs()
        .iter()
        .find(|v| v.user_id.trim_end_matches('\0') == "laszip encoded" && v.record_id == 22204)
        .and_then(|v| laz::LazVlr::from_buffer(&v.data).ok())
    else {
        return Ok(None);
    };
    let mut t = [0u8; 8];
    file.read_exact_at(&mut t, point_offset)
        .map_err(|e| IoError::io(path, e))?;
    if i64::from_le_bytes(t) < 0 {
        return Ok(None);
    }
    // (The table's offset and count were checked against the file when it was opened.)
    let mut f = &file;
    use std::io::{Seek, SeekFrom};
    f.seek(SeekFrom::Start(point_offset))
        .map_err(|e| IoError::io(path, e))?;
    let Ok(table) = laz::laszip::ChunkTable::read_from(f, &vlr) else {
        return Ok(None);
    };
    let mut chunks = Vec::with_capacity(table.len());
    let (mut at, mut first) = (point_offset + 8, 0u64);
    for e in table.as_ref() {
        // Fixed-size tables give every chunk the full size: the last holds what is left.
        let points = e.point_count.min(count.saturating_sub(first));
        if points == 0 {
            break;
        }
        // A chunk beyond the file: the batch reader says where the data ends.
        if at.saturating_add(e.byte_count) > file_len {
            return Ok(None);
        }
        chunks.push(Chunk {
            offset: at,
            bytes: e.byte_count,
            points,
            first,
        });
        at += e.byte_count;
        first += points;
    }
    Ok((first == count).then_some((chunks, Some(vlr))))
}

/// A LAS/LAZ file whose points can be read chunk by chunk, each chunk on its own (LAZ chunks
/// from the chunk table, blocks of LAS records): the reader of [`read_las`], open to callers
/// that stream the points instead of collecting them (`stipple build-lod`).
pub struct ChunkReader {
    path: std::path::PathBuf,
    file: std::fs::File,
    chunks: Vec<Chunk>,
    vlr: Option<laz::LazVlr>,
    lay: Layout,
    scale: DVec3,
    offset: DVec3,
}

/// The fields of one record that a streaming reader uses.
#[derive(Clone, Copy, Debug)]
pub struct LasPoint {
    pub world: DVec3,
    pub intensity: u16,
    /// The record's colour, when its format has one.
    pub rgb: Option<[u16; 3]>,
}

impl ChunkReader {
    /// The reader of an opened file, or None where the file cannot be split (see
    /// `chunks_of`: the batch reader reads those).
    pub fn open(path: &Path, b: &LasBatches) -> Result<Option<ChunkReader>, IoError> {
        let Some((chunks, vlr)) = chunks_of(path, b)? else {
            return Ok(None);
        };
        let file = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
        let t = b.header.transforms();
        Ok(Some(ChunkReader {
            path: path.to_owned(),
            file,
            chunks,
            vlr,
            lay: Layout::of(b.header.point_format()),
            scale: DVec3::new(t.x.scale, t.y.scale, t.z.scale),
            offset: DVec3::new(t.x.offset, t.y.offset, t.z.offset),
        }))
    }

    pub fn chunks(&self) -> &[Chunk] {
        &self.chunks
    }

    /// Whether the records carry RGB.
    pub fn has_rgb(&self) -> bool {
        self.lay.rgb.is_some()
    }

    /// Bytes of one record.
    pub fn record_len(&self) -> usize {
        self.lay.rec
    }

    /// A chunk's records into `raw` (read, or read and decompressed); safe from several
    /// threads at once.
    pub fn records(&self, c: &Chunk, raw: &mut Vec<u8>) -> Result<(), IoError> {
        use std::os::unix::fs::FileExt;
        let path = &self.path;
        let n = c.points as usize * self.lay.rec;
        raw.clear();
        stipple_core::sys::try_reserve(raw, n, "a chunk of points")
            .map_err(|m| IoError::invalid(path, m))?;
        raw.resize(n, 0);
        let corrupt = |e: String| {
            IoError::invalid(
                path,
                format!(
                    "point data is corrupt or truncated in the chunk of points {} to {}: {e}",
                    c.first,
                    c.first + c.points
                ),
            )
        };
        match &self.vlr {
            None => self
                .file
                .read_exact_at(raw, c.offset)
                .map_err(|e| corrupt(e.to_string())),
            Some(vlr) => {
                let mut bytes = vec![0u8; c.bytes as usize];
                self.file
                    .read_exact_at(&mut bytes, c.offset)
                    .map_err(|e| corrupt(e.to_string()))?;
                decode_chunk(&bytes, raw, vlr, c.points).map_err(corrupt)
            }
        }
    }

    /// The world position of a record.
    #[inline]
    pub fn world(&self, r: &[u8]) -> DVec3 {
        let i = |o: usize| i32::from_le_bytes(r[o..o + 4].try_into().unwrap()) as f64;
        DVec3::new(i(0), i(4), i(8)) * self.scale + self.offset
    }

    /// The fields of a record.
    #[inline]
    pub fn point(&self, r: &[u8]) -> LasPoint {
        LasPoint {
            world: self.world(r),
            intensity: u16::from_le_bytes([r[12], r[13]]),
            rgb: self.lay.rgb.map(|at| {
                let v = |o: usize| u16::from_le_bytes([r[at + o], r[at + o + 1]]);
                [v(0), v(2), v(4)]
            }),
        }
    }
}

/// The columns a chunk's points go to (its share of the cloud's arrays).
struct ChunkOut<'a> {
    pos: &'a mut [glam::Vec3],
    intensity: &'a mut [u16],
    class: &'a mut [u8],
    ret: &'a mut [u8],
    rgb: &'a mut [[u16; 3]],
    gps: &'a mut [f64],
    angle: &'a mut [f32],
    source: &'a mut [u16],
}

/// Splits `v` into consecutive slices of `lens` (empty slices where `v` is empty: a column
/// the file does not have).
fn split_by<'a, T>(mut v: &'a mut [T], lens: &[usize]) -> Vec<&'a mut [T]> {
    lens.iter()
        .map(|&n| {
            let n = n.min(v.len());
            let (a, b) = std::mem::take(&mut v).split_at_mut(n);
            v = b;
            a
        })
        .collect()
}

/// Where a record keeps its fields (LAS 1.4 table 7 onwards; extended formats 6–10).
#[derive(Clone, Copy)]
struct Layout {
    rec: usize,
    extended: bool,
    angle: usize,
    source: usize,
    gps: Option<usize>,
    rgb: Option<usize>,
}

impl Layout {
    fn of(f: &las::point::Format) -> Layout {
        if f.is_extended {
            Layout {
                rec: f.len() as usize,
                extended: true,
                angle: 18,
                source: 20,
                gps: Some(22),
                rgb: f.has_color.then_some(30),
            }
        } else {
            Layout {
                rec: f.len() as usize,
                extended: false,
                angle: 16,
                source: 18,
                gps: f.has_gps_time.then_some(20),
                rgb: f.has_color.then_some(20 + 8 * f.has_gps_time as usize),
            }
        }
    }
}

/// [`read_las`] with every chunk decoded and converted on its own, in parallel, straight
/// into the cloud's columns: the same cloud as [`read_las_batches`] (test
/// `parallel_and_batch_reads_agree`).
fn read_las_parallel(
    path: &Path,
    header: &las::Header,
    count: u64,
    reader: &ChunkReader,
) -> Result<PointCloud, IoError> {
    use rayon::prelude::*;
    let fmt = header.point_format();
    let lay = reader.lay;
    let chunks = reader.chunks();
    let world = |r: &[u8]| reader.world(r);
    let records = |c: &Chunk, raw: &mut Vec<u8>| reader.records(c, raw);
    // The origin, as the batch reader chooses it: the header's centre when the header's
    // bounds hold the first chunk's points, else that chunk's centre.
    let mut raw = Vec::new();
    records(&chunks[0], &mut raw)?;
    let (flo, fhi) = raw
        .chunks_exact(lay.rec)
        .map(world)
        .filter(|p| p.is_finite())
        .fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(p), hi.max(p)),
        );
    let origin = choose_origin(header, flo, fhi);
    let n = count as usize;
    let mut positions = Vec::new();
    stipple_core::sys::try_reserve(&mut positions, n, "the points' positions")
        .map_err(|m| IoError::invalid(path, m))?;
    positions.resize(n, glam::Vec3::ZERO);
    let mut intensity = vec![0u16; n];
    let mut class = vec![0u8; n];
    let mut ret = vec![0u8; n];
    let mut rgb = vec![[0u16; 3]; if lay.rgb.is_some() { n } else { 0 }];
    let pulses = lay.gps.is_some() && fmt.has_gps_time;
    let m = if pulses { n } else { 0 };
    let (mut gps, mut angle, mut source) = (vec![0f64; m], vec![0f32; m], vec![0u16; m]);
    let lens: Vec<usize> = chunks.iter().map(|c| c.points as usize).collect();
    let outs: Vec<ChunkOut> = split_by(&mut positions, &lens)
        .into_iter()
        .zip(split_by(&mut intensity, &lens))
        .zip(split_by(&mut class, &lens))
        .zip(split_by(&mut ret, &lens))
        .zip(split_by(&mut rgb, &lens))
        .zip(split_by(&mut gps, &lens))
        .zip(split_by(&mut angle, &lens))
        .zip(split_by(&mut source, &lens))
        .map(
            |(((((((pos, intensity), class), ret), rgb), gps), angle), source)| ChunkOut {
                pos,
                intensity,
                class,
                ret,
                rgb,
                gps,
                angle,
                source,
            },
        )
        .collect();
    outs.into_par_iter()
        .zip(chunks.par_iter())
        .try_for_each_init(Vec::new, |raw, (o, c)| {
            records(c, raw)?;
            for (k, r) in raw.chunks_exact(lay.rec).enumerate() {
                let p = world(r);
                if let Some(problem) = stipple_core::cloud::coordinate_problem(p) {
                    return Err(IoError::invalid(
                        path,
                        format!("point {} has {problem}", c.first + k as u64),
                    ));
                }
                o.pos[k] = (p - origin).as_vec3();
                o.intensity[k] = u16::from_le_bytes([r[12], r[13]]);
                if lay.extended {
                    o.ret[k] = r[14] & 15;
                    o.class[k] = r[16];
                } else {
                    o.ret[k] = r[14] & 7;
                    o.class[k] = r[15] & 0x1f;
                }
                if let Some(at) = lay.rgb {
                    let v = |o: usize| u16::from_le_bytes([r[at + o], r[at + o + 1]]);
                    o.rgb[k] = [v(0), v(2), v(4)];
                }
                if let (true, Some(at)) = (pulses, lay.gps) {
                    o.gps[k] = f64::from_le_bytes(r[at..at + 8].try_into().unwrap());
                    o.angle[k] = if lay.extended {
                        i16::from_le_bytes([r[lay.angle], r[lay.angle + 1]]) as f32 * 0.006
                    } else {
                        r[lay.angle] as i8 as f32
                    };
                    o.source[k] = u16::from_le_bytes([r[lay.source], r[lay.source + 1]]);
                }
            }
            Ok(())
        })?;
    let mut cloud = PointCloud {
        origin,
        positions,
        intensity: Some(intensity),
        classification: Some(class),
        return_number: Some(ret),
        z_up: true,
        ..Default::default()
    };
    if lay.rgb.is_some() {
        let max = rgb
            .par_iter()
            .map(|c| c[0].max(c[1]).max(c[2]))
            .max()
            .unwrap_or(0);
        let shift = if max > 255 { 8 } else { 0 };
        cloud.colors = Some(
            rgb.par_iter()
                .map(|c| c.map(|v| (v >> shift) as u8))
                .collect(),
        );
    }
    if pulses {
        cloud.sensor_dirs =
            stipple_core::normals::airborne_sensor_dirs(&cloud.positions, &gps, &angle, &source);
    }
    Ok(cloud)
}

/// The origin of a LAS file's f32 offsets: the header's centre when the header's bounds
/// hold the first points read (`flo`..`fhi`), else (inverted, far-off or missing bounds,
/// which would quantise the offsets to metres) those points' own centre; rounded.
fn choose_origin(header: &las::Header, flo: DVec3, fhi: DVec3) -> DVec3 {
    let b = header.bounds();
    let (hlo, hhi) = (
        DVec3::new(b.min.x, b.min.y, b.min.z),
        DVec3::new(b.max.x, b.max.y, b.max.z),
    );
    let slack = (hhi - hlo).abs().max_element() * 0.01 + 1.0;
    let header_holds = hlo.is_finite()
        && hhi.is_finite()
        && hlo.cmple(hhi).all()
        && flo.cmpge(hlo - slack).all()
        && fhi.cmple(hhi + slack).all();
    let origin = if header_holds {
        (hlo + hhi) * 0.5
    } else {
        (flo + fhi) * 0.5
    }
    .round();
    if !origin.is_finite() || origin.abs().max_element() > 1e12 {
        DVec3::ZERO
    } else {
        origin
    }
}

/// One extra-bytes value of a record: its name, where it starts in the extra bytes, its
/// type (1–10: u8, i8, u16, i16, u32, i32, u64, i64, f32, f64) and scale and offset.
struct ExtraField {
    name: String,
    at: usize,
    ty: u8,
    scale: f64,
    offset: f64,
}

/// The extra-bytes fields the header describes (at most `MAX_FIELDS`, each within the
/// record's `extra` bytes).
fn extra_fields(header: &las::Header, extra: usize) -> Vec<ExtraField> {
    let Some(vlr) = header
        .all_vlrs()
        .find(|v| v.user_id.trim_end_matches('\0') == "LASF_Spec" && v.record_id == 4)
    else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut at = 0usize;
    for d in vlr.data.chunks_exact(192) {
        let (ty, options) = (d[2], d[3]);
        let base = |t: u8| [1usize, 1, 2, 2, 4, 4, 8, 8, 4, 8][(t as usize - 1) % 10];
        let size = match ty {
            0 => options as usize,
            1..=10 => base(ty),
            11..=20 => 2 * base(ty - 10),
            21..=30 => 3 * base(ty - 20),
            _ => break,
        };
        let f64_at = |o: usize| f64::from_le_bytes(d[o..o + 8].try_into().unwrap());
        if (1..=10).contains(&ty)
            && at + size <= extra
            && out.len() < stipple_core::cloud::MAX_FIELDS
        {
            let name: String = String::from_utf8_lossy(&d[4..36])
                .trim_end_matches('\0')
                .trim()
                .to_string();
            let scale = if options & 8 != 0 { f64_at(112) } else { 1.0 };
            let offset = if options & 16 != 0 { f64_at(136) } else { 0.0 };
            out.push(ExtraField {
                name: if name.is_empty() {
                    format!("extra_{}", out.len())
                } else {
                    name
                },
                at,
                ty,
                scale: if scale.is_finite() && scale != 0.0 {
                    scale
                } else {
                    1.0
                },
                offset: if offset.is_finite() { offset } else { 0.0 },
            });
        }
        at += size;
    }
    out
}

impl ExtraField {
    fn value(&self, b: &[u8]) -> f64 {
        let b = &b[self.at..];
        let raw = match self.ty {
            1 => b[0] as f64,
            2 => b[0] as i8 as f64,
            3 => u16::from_le_bytes([b[0], b[1]]) as f64,
            4 => i16::from_le_bytes([b[0], b[1]]) as f64,
            5 => u32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
            6 => i32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
            7 => u64::from_le_bytes(b[..8].try_into().unwrap()) as f64,
            8 => i64::from_le_bytes(b[..8].try_into().unwrap()) as f64,
            9 => f32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
            _ => f64::from_le_bytes(b[..8].try_into().unwrap()),
        };
        raw * self.scale + self.offset
    }
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
            // Three bits in point format 2.
            return_number: cloud.return_number.as_ref().map_or(1, |v| v[i].min(7)),
            ..Default::default()
        };
        w.write_point(point)
            .map_err(|e| IoError::invalid(path, format!("cannot write point {i}: {e}")))?;
    }
    w.close()
        .map_err(|e| IoError::invalid(path, format!("cannot finish the file: {e}")))?;
    Ok(())
}
