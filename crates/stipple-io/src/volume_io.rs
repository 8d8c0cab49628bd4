//! Volume readers: NRRD (attached data, `raw` or `gzip` encoding), NIfTI-1 (`.nii`,
//! `.nii.gz`) and headerless raw volumes whose shape and sample type are in the file name
//! (`NAME_WxHxD_TYPE.raw`, e.g. `tooth_103x94x161_uint8.raw`). Samples become f32 (NIfTI's
//! `scl_slope`/`scl_inter` applied); spacing comes from NRRD `space directions`/`spacings`
//! or NIfTI `pixdim` (axis-aligned: rotations of the grid are not applied), the origin from
//! NRRD `space origin` or NIfTI `qoffset`. The sample count the header declares is checked
//! against the bytes present (and decompression stops there) before anything is allocated.

use std::io::Read;
use stipple_core::volume::Volume;

/// A sample type and its byte size.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Sample {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    F32,
    F64,
}

impl Sample {
    fn size(self) -> usize {
        match self {
            Sample::U8 | Sample::I8 => 1,
            Sample::U16 | Sample::I16 => 2,
            Sample::U32 | Sample::I32 | Sample::F32 => 4,
            Sample::F64 => 8,
        }
    }

    fn from_name(s: &str) -> Option<Sample> {
        Some(match s {
            "uchar" | "unsigned char" | "uint8" | "uint8_t" => Sample::U8,
            "signed char" | "int8" | "int8_t" => Sample::I8,
            "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => {
                Sample::U16
            }
            "short" | "short int" | "signed short" | "int16" | "int16_t" => Sample::I16,
            "uint" | "unsigned int" | "uint32" | "uint32_t" => Sample::U32,
            "int" | "signed int" | "int32" | "int32_t" => Sample::I32,
            "float" | "float32" => Sample::F32,
            "double" | "float64" => Sample::F64,
            _ => return None,
        })
    }

    fn decode(self, b: &[u8], big: bool) -> f32 {
        let mut a = [0u8; 8];
        let n = self.size();
        a[..n].copy_from_slice(&b[..n]);
        if big {
            a[..n].reverse();
        }
        let u = u64::from_le_bytes(a);
        match self {
            Sample::U8 => u as u8 as f32,
            Sample::I8 => u as u8 as i8 as f32,
            Sample::U16 => u as u16 as f32,
            Sample::I16 => u as u16 as i16 as f32,
            Sample::U32 => u as u32 as f32,
            Sample::I32 => u as u32 as i32 as f32,
            Sample::F32 => f32::from_bits(u as u32),
            Sample::F64 => f64::from_bits(u) as f32,
        }
    }
}

/// The sample count of `dims`, refused beyond `max` (a header cannot make us allocate more
/// than its file can hold).
fn count(dims: [usize; 3], sample: Sample, max_bytes: u64) -> Result<usize, String> {
    let n = dims
        .iter()
        .try_fold(1u64, |a, &d| a.checked_mul(d as u64))
        .filter(|&n| n > 0)
        .ok_or_else(|| format!("sizes {dims:?} are empty or overflow"))?;
    let bytes = n.saturating_mul(sample.size() as u64);
    if bytes > max_bytes {
        return Err(format!(
            "sizes {dims:?} of {sample:?} need {bytes} bytes of data, more than the file can \
             hold ({max_bytes})"
        ));
    }
    Ok(n as usize)
}

/// Decodes `n` samples from `bytes`.
fn samples(bytes: &[u8], n: usize, sample: Sample, big: bool) -> Result<Vec<f32>, String> {
    let need = n * sample.size();
    if bytes.len() < need {
        return Err(format!(
            "{n} samples need {need} bytes of data, the file has {} (truncated?)",
            bytes.len()
        ));
    }
    Ok(bytes[..need]
        .chunks_exact(sample.size())
        .map(|c| sample.decode(c, big))
        .collect())
}

/// Decompresses gzip data, stopping after `max` bytes.
fn gunzip(data: &[u8], max: u64) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    flate2::read::MultiGzDecoder::new(data)
        .take(max)
        .read_to_end(&mut out)
        .map_err(|e| format!("gzip data is corrupt or truncated: {e}"))?;
    Ok(out)
}

/// Parses an NRRD file with its data attached.
pub fn parse_nrrd(bytes: &[u8]) -> Result<Volume, String> {
    if !bytes.starts_with(b"NRRD000") {
        return Err("not an NRRD file: the magic `NRRD000x` is missing".into());
    }
    // After the magic line.
    let mut at = bytes
        .iter()
        .position(|&b| b == b'\n')
        .map_or(bytes.len(), |e| e + 1);
    let mut fields: Vec<(String, String)> = Vec::new();
    loop {
        let end = bytes[at..]
            .iter()
            .position(|&b| b == b'\n')
            .map(|e| at + e)
            .ok_or("the header does not end (no blank line before the data)")?;
        let line = String::from_utf8_lossy(&bytes[at..end])
            .trim_end_matches('\r')
            .to_string();
        at = end + 1;
        if line.is_empty() {
            break;
        }
        if line.starts_with('#') {
            continue;
        }
        if let Some((k, v)) = line.split_once(": ").or_else(|| line.split_once(":=")) {
            fields.push((k.trim().to_ascii_lowercase(), v.trim().to_string()));
        }
        if fields.len() > 256 {
            return Err("more than 256 header fields: not an NRRD file".into());
        }
    }
    let get = |k: &str| fields.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str());
    if get("data file").or(get("datafile")).is_some() {
        return Err(
            "the data is in a separate file (`data file:`): give an NRRD with the data attached"
                .into(),
        );
    }
    let sample = get("type").and_then(Sample::from_name).ok_or_else(|| {
        format!(
            "type `{}` (an integer or float sample type)",
            get("type").unwrap_or("")
        )
    })?;
    let dim: usize = get("dimension")
        .and_then(|s| s.parse().ok())
        .ok_or("no dimension")?;
    if dim != 3 {
        return Err(format!("dimension {dim}: a 3-D volume is needed"));
    }
    let sizes: Vec<usize> = get("sizes")
        .ok_or("no sizes")?
        .split_whitespace()
        .map(|s| {
            s.parse()
                .map_err(|_| format!("sizes: `{s}` is not a count"))
        })
        .collect::<Result<_, _>>()?;
    let dims: [usize; 3] = sizes
        .try_into()
        .map_err(|_| "sizes: three counts are needed".to_string())?;
    let big = get("endian") == Some("big");
    let vectors = |s: &str| -> Vec<[f64; 3]> {
        s.split(')')
            .filter_map(|v| {
                let v = v.trim().trim_start_matches('(');
                let c: Vec<f64> = v.split(',').filter_map(|x| x.trim().parse().ok()).collect();
                (c.len() == 3).then(|| [c[0], c[1], c[2]])
            })
            .collect()
    };
    let mut spacing = [1.0; 3];
    if let Some(d) = get("space directions") {
        let v = vectors(d);
        if v.len() == 3 {
            for k in 0..3 {
                spacing[k] = (v[k][0] * v[k][0] + v[k][1] * v[k][1] + v[k][2] * v[k][2]).sqrt();
            }
        }
    } else if let Some(s) = get("spacings") {
        for (k, x) in s.split_whitespace().take(3).enumerate() {
            spacing[k] = x.parse().unwrap_or(1.0);
        }
    }
    if spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(format!("spacing {spacing:?}: it must be positive"));
    }
    let origin = get("space origin")
        .map(vectors)
        .and_then(|v| v.first().copied())
        .unwrap_or([0.0; 3]);
    let data = &bytes[at..];
    let raw;
    let body: &[u8] = match get("encoding").unwrap_or("raw") {
        "raw" => data,
        "gzip" | "gz" => {
            let n = count(dims, sample, inflate_limit())?;
            raw = gunzip(data, (n * sample.size()) as u64)?;
            &raw
        }
        e => return Err(format!("encoding `{e}` (raw or gzip)")),
    };
    let n = count(dims, sample, body.len() as u64)?;
    Ok(Volume {
        dims,
        spacing,
        origin,
        data: samples(body, n, sample, big)?,
    })
}

/// The most bytes a compressed volume may expand to (4 GiB).
pub const MAX_VOLUME_BYTES: u64 = 4 << 30;

/// What a compressed volume may expand to here: [`MAX_VOLUME_BYTES`], or less where less
/// memory is available.
fn inflate_limit() -> u64 {
    stipple_core::sys::available_memory().map_or(MAX_VOLUME_BYTES, |m| m.min(MAX_VOLUME_BYTES))
}

/// Parses a NIfTI-1 file (`.nii`; gzip-compressed `.nii.gz` decompressed first).
pub fn parse_nifti(bytes: &[u8]) -> Result<Volume, String> {
    if bytes.starts_with(&[0x1f, 0x8b]) {
        // The header first, then exactly the bytes it declares (a small file cannot make us
        // inflate gigabytes).
        let head = gunzip(bytes, 348)?;
        let need = nifti_size(&head)?;
        if need > MAX_VOLUME_BYTES {
            return Err(format!(
                "the header declares {need} bytes, more than {MAX_VOLUME_BYTES}"
            ));
        }
        return parse_nifti_plain(&gunzip(bytes, need)?);
    }
    parse_nifti_plain(bytes)
}

/// The bytes a NIfTI-1 file needs (header, offset and samples), from its header.
fn nifti_size(h: &[u8]) -> Result<u64, String> {
    if h.len() < 348 {
        return Err("shorter than a NIfTI-1 header (348 bytes)".into());
    }
    let le = i32::from_le_bytes(h[0..4].try_into().expect("4 bytes")) == 348;
    let i16_at = |o: usize| {
        let b: [u8; 2] = h[o..o + 2].try_into().expect("2 bytes");
        if le {
            i16::from_le_bytes(b)
        } else {
            i16::from_be_bytes(b)
        }
    };
    let f32_at = |o: usize| {
        let b: [u8; 4] = h[o..o + 4].try_into().expect("4 bytes");
        if le {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let n = [42, 44, 46]
        .iter()
        .map(|&o| i16_at(o).max(0) as u64)
        .product::<u64>();
    let bits = i16_at(72).max(0) as u64;
    let off = f32_at(108);
    let off = if off.is_finite() && off >= 0.0 {
        off as u64
    } else {
        352
    };
    Ok(off.saturating_add(n.saturating_mul(bits.max(8) / 8)))
}

fn parse_nifti_plain(bytes: &[u8]) -> Result<Volume, String> {
    if bytes.len() < 348 {
        return Err("shorter than a NIfTI-1 header (348 bytes)".into());
    }
    let le = i32::from_le_bytes(bytes[0..4].try_into().expect("4 bytes")) == 348;
    let be = i32::from_be_bytes(bytes[0..4].try_into().expect("4 bytes")) == 348;
    if !(le || be) || !(&bytes[344..347] == b"n+1" || &bytes[344..347] == b"ni1") {
        return Err("not a NIfTI-1 file (sizeof_hdr 348 and magic `n+1`)".into());
    }
    let i16_at = |o: usize| {
        let b: [u8; 2] = bytes[o..o + 2].try_into().expect("2 bytes");
        if le {
            i16::from_le_bytes(b)
        } else {
            i16::from_be_bytes(b)
        }
    };
    let f32_at = |o: usize| {
        let b: [u8; 4] = bytes[o..o + 4].try_into().expect("4 bytes");
        if le {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let ndim = i16_at(40);
    if !(3..=7).contains(&ndim) {
        return Err(format!("dim[0] = {ndim}: a 3-D volume is needed"));
    }
    let d = [i16_at(42), i16_at(44), i16_at(46)];
    if d.iter().any(|&x| x < 1) || (4..=ndim).any(|k| i16_at(40 + 2 * k as usize) > 1) {
        return Err(format!("dims {d:?} (and no 4th dimension) are needed"));
    }
    let dims = d.map(|x| x as usize);
    let sample = match i16_at(70) {
        2 => Sample::U8,
        4 => Sample::I16,
        8 => Sample::I32,
        16 => Sample::F32,
        64 => Sample::F64,
        256 => Sample::I8,
        512 => Sample::U16,
        768 => Sample::U32,
        t => return Err(format!("datatype {t} is not a real scalar sample type")),
    };
    let pix = [f32_at(80), f32_at(84), f32_at(88)].map(|x| x.abs() as f64);
    let spacing = pix.map(|x| if x.is_finite() && x > 0.0 { x } else { 1.0 });
    let offset = f32_at(108);
    if !(offset.is_finite() && offset >= 348.0) || offset as usize > bytes.len() {
        return Err(format!("vox_offset {offset} lies outside the file"));
    }
    let body = &bytes[offset as usize..];
    let n = count(dims, sample, body.len() as u64)?;
    let mut data = samples(body, n, sample, !le)?;
    let (slope, inter) = (f32_at(112), f32_at(116));
    if slope.is_finite() && slope != 0.0 && (slope != 1.0 || inter != 0.0) {
        let inter = if inter.is_finite() { inter } else { 0.0 };
        data.iter_mut().for_each(|x| *x = *x * slope + inter);
    }
    let q = [f32_at(268), f32_at(272), f32_at(276)];
    let origin = if q.iter().all(|x| x.is_finite()) {
        q.map(|x| x as f64)
    } else {
        [0.0; 3]
    };
    Ok(Volume {
        dims,
        spacing,
        origin,
        data,
    })
}

/// Parses a raw volume whose file name carries its shape and type (`…_WxHxD_TYPE.raw`).
pub fn parse_raw(name: &str, bytes: &[u8]) -> Result<Volume, String> {
    let stem = name.trim_end_matches(".raw");
    let parts: Vec<&str> = stem.rsplit('_').take(2).collect();
    let help = "a raw volume's name must give its shape and sample type, \
                NAME_WxHxD_TYPE.raw (e.g. tooth_103x94x161_uint8.raw)";
    let (ty, shape) = match parts.as_slice() {
        [ty, shape] => (*ty, *shape),
        _ => return Err(help.into()),
    };
    let sample = Sample::from_name(ty).ok_or(help)?;
    let dims: Vec<usize> = shape
        .split('x')
        .map(|s| s.parse().map_err(|_| help.to_string()))
        .collect::<Result<_, _>>()?;
    let dims: [usize; 3] = dims.try_into().map_err(|_| help.to_string())?;
    let n = count(dims, sample, bytes.len() as u64)?;
    Ok(Volume {
        dims,
        spacing: [1.0; 3],
        origin: [0.0; 3],
        data: samples(bytes, n, sample, false)?,
    })
}

/// Reads a volume by its extension (`.nrrd`, `.nii`, `.nii.gz`, `.raw`).
pub fn read_volume(path: &std::path::Path) -> Result<Volume, crate::IoError> {
    let bytes = std::fs::read(path).map_err(|e| crate::IoError::io(path, e))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    let r = if name.ends_with(".nrrd") {
        parse_nrrd(&bytes)
    } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        parse_nifti(&bytes)
    } else if name.ends_with(".raw") {
        parse_raw(&name, &bytes)
    } else {
        Err("not a volume file (.nrrd, .nii, .nii.gz, .raw)".into())
    };
    r.map_err(|e| crate::IoError::invalid(path, e))
}

/// Whether the path names a volume file.
pub fn is_volume(path: &std::path::Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    [".nrrd", ".nii", ".nii.gz", ".raw"]
        .iter()
        .any(|e| name.ends_with(e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nrrd_raw_and_gzip_with_spacing_and_origin() {
        let mut b = b"NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\
            endian: little\nspace directions: (0.5,0,0) (0,2,0) (0,0,1)\nspace origin: (1,2,3)\n\n"
            .to_vec();
        for k in 0..8i16 {
            b.extend_from_slice(&(k * 10 - 30).to_le_bytes());
        }
        let v = parse_nrrd(&b).unwrap();
        assert_eq!(v.dims, [2, 2, 2]);
        assert_eq!(v.spacing, [0.5, 2.0, 1.0]);
        assert_eq!(v.origin, [1.0, 2.0, 3.0]);
        assert_eq!(v.data[7], 40.0);
        assert_eq!(v.data[0], -30.0);
        let e = parse_nrrd(&b[..b.len() - 3]).err().unwrap();
        assert!(e.contains("more than the file can hold"), "{e}");
        let huge =
            b"NRRD0004\ntype: float\ndimension: 3\nsizes: 100000 100000 100000\nencoding: gzip\n\n";
        let e = parse_nrrd(huge).err().unwrap();
        assert!(
            e.contains("more than the file can hold") || e.contains("gzip"),
            "{e}"
        );
    }

    #[test]
    fn raw_shape_from_the_name() {
        let v = parse_raw("x_2x3x4_uint8.raw", &[7u8; 24]).unwrap();
        assert_eq!((v.dims, v.data[23]), ([2, 3, 4], 7.0));
        assert!(parse_raw("x_2x3x4_uint8.raw", &[7u8; 23]).is_err());
        assert!(parse_raw("tooth.raw", &[0u8; 8])
            .err()
            .unwrap()
            .contains("NAME_WxHxD_TYPE"));
        assert!(parse_raw("x_2x3_uint8.raw", &[0u8; 8]).is_err());
    }

    #[test]
    fn nifti_header_checks() {
        let mut h = vec![0u8; 352 + 8];
        h[0..4].copy_from_slice(&348i32.to_le_bytes());
        for (o, v) in [(40, 3i16), (42, 2), (44, 2), (46, 2), (70, 2)] {
            h[o..o + 2].copy_from_slice(&v.to_le_bytes());
        }
        h[108..112].copy_from_slice(&352f32.to_le_bytes());
        h[344..348].copy_from_slice(b"n+1\0");
        for (k, x) in h[352..].iter_mut().enumerate() {
            *x = k as u8;
        }
        let v = parse_nifti(&h).unwrap();
        assert_eq!((v.dims, v.data[7]), ([2, 2, 2], 7.0));
        let mut bad = h.clone();
        bad[42..44].copy_from_slice(&30000i16.to_le_bytes());
        assert!(parse_nifti(&bad)
            .err()
            .unwrap()
            .contains("more than the file can hold"));
        assert!(parse_nifti(&h[..300]).is_err());
        let mut bad = h.clone();
        bad[108..112].copy_from_slice(&1e9f32.to_le_bytes());
        assert!(parse_nifti(&bad).err().unwrap().contains("vox_offset"));
    }
}
