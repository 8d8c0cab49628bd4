//! Renderer outputs: 8-bit sRGB PNG and NumPy `.npy` (v1.0, little-endian float32, shape
//! (H, W), row 0 = top).

use crate::{write_atomically, IoError};
use std::io::Write;
use std::path::Path;

/// Writes an RGBA8 image as PNG.
pub fn write_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<(), IoError> {
    assert_eq!(rgba.len(), width as usize * height as usize * 4);
    write_atomically(path, |tmp| {
        let f = std::fs::File::create(tmp).map_err(|e| IoError::io(tmp, e))?;
        let mut enc = png::Encoder::new(std::io::BufWriter::new(f), width, height);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut w = enc
            .write_header()
            .map_err(|e| IoError::invalid(tmp, format!("PNG: {e}")))?;
        w.write_image_data(rgba)
            .map_err(|e| IoError::invalid(tmp, format!("PNG: {e}")))?;
        w.finish()
            .map_err(|e| IoError::invalid(tmp, format!("PNG: {e}")))
    })
}

/// The most pixels a PNG read may hold (1 GiB of RGBA): a header claiming more is an error
/// before anything is allocated.
pub const MAX_PNG_PIXELS: u64 = 1 << 28;

/// Reads a PNG into (width, height, RGBA8).
pub fn read_png(path: &Path) -> Result<(u32, u32, Vec<u8>), IoError> {
    let f = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
    let mut dec = png::Decoder::new(std::io::BufReader::new(f));
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut r = dec
        .read_info()
        .map_err(|e| IoError::invalid(path, format!("PNG: {e}")))?;
    // The header's size is checked before its pixels are allocated.
    let (hw, hh) = (r.info().width as u64, r.info().height as u64);
    if hw * hh > MAX_PNG_PIXELS {
        return Err(IoError::invalid(
            path,
            format!("PNG: {hw}×{hh} pixels is more than stipple reads (at most {MAX_PNG_PIXELS})"),
        ));
    }
    let size = r
        .output_buffer_size()
        .ok_or_else(|| IoError::invalid(path, "PNG: image too large"))?;
    let mut buf = vec![0; size];
    let info = r
        .next_frame(&mut buf)
        .map_err(|e| IoError::invalid(path, format!("PNG: {e}")))?;
    buf.truncate(info.buffer_size());
    let (w, h) = (info.width, info.height);
    let px = (w * h) as usize;
    let rgba = match info.color_type {
        png::ColorType::Rgba => buf,
        png::ColorType::Rgb => buf
            .chunks_exact(3)
            .flat_map(|c| [c[0], c[1], c[2], 255])
            .collect(),
        png::ColorType::GrayscaleAlpha => buf
            .chunks_exact(2)
            .flat_map(|c| [c[0], c[0], c[0], c[1]])
            .collect(),
        png::ColorType::Grayscale => buf.iter().flat_map(|&g| [g, g, g, 255]).collect(),
        png::ColorType::Indexed => return Err(IoError::invalid(path, "PNG: unexpanded palette")),
    };
    debug_assert_eq!(rgba.len(), px * 4);
    Ok((w, h, rgba))
}

/// Encodes a float32 (H, W) array in the NumPy .npy v1.0 format.
pub fn npy_bytes(width: u32, height: u32, data: &[f32]) -> Vec<u8> {
    npy_bytes_shaped(&[height as usize, width as usize], data)
}

/// Encodes a float32 C-order array of any shape in the NumPy .npy v1.0 format.
pub fn npy_bytes_shaped(shape: &[usize], data: &[f32]) -> Vec<u8> {
    assert_eq!(data.len(), shape.iter().product::<usize>());
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let dims = if dims.len() == 1 {
        format!("{},", dims[0])
    } else {
        dims.join(", ")
    };
    let dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({dims}), }}");
    // Magic (6) + version (2) + header length (2) + dict + padding + '\n', multiple of 64.
    let unpadded = 10 + dict.len() + 1;
    let pad = (64 - unpadded % 64) % 64;
    let header_len = dict.len() + pad + 1;
    let mut out = Vec::with_capacity(10 + header_len + data.len() * 4);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header_len as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.extend(std::iter::repeat_n(b' ', pad));
    out.push(b'\n');
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Writes a float32 (H, W) .npy file.
pub fn write_npy(path: &Path, width: u32, height: u32, data: &[f32]) -> Result<(), IoError> {
    let bytes = npy_bytes(width, height, data);
    write_atomically(path, |tmp| {
        let mut f = std::fs::File::create(tmp).map_err(|e| IoError::io(tmp, e))?;
        f.write_all(&bytes).map_err(|e| IoError::io(tmp, e))
    })
}

/// Writes a float32 (H, W, 3) .npy file (per-pixel vectors such as normals).
pub fn write_npy3(path: &Path, width: u32, height: u32, data: &[[f32; 3]]) -> Result<(), IoError> {
    let flat: Vec<f32> = data.iter().flatten().copied().collect();
    let bytes = npy_bytes_shaped(&[height as usize, width as usize, 3], &flat);
    write_atomically(path, |tmp| {
        let mut f = std::fs::File::create(tmp).map_err(|e| IoError::io(tmp, e))?;
        f.write_all(&bytes).map_err(|e| IoError::io(tmp, e))
    })
}

/// Reads a float32 (H, W) .npy file written by [`write_npy`] (or NumPy): (width, height, data).
pub fn read_npy(path: &Path) -> Result<(u32, u32, Vec<f32>), IoError> {
    let (dims, data) = read_npy_shaped(path)?;
    let [h, w] = dims[..] else {
        return Err(IoError::invalid(path, "npy: expected a 2-D array"));
    };
    Ok((w as u32, h as u32, data))
}

/// Reads a little-endian float32 C-order .npy file of any shape: (shape, data).
pub fn read_npy_shaped(path: &Path) -> Result<(Vec<usize>, Vec<f32>), IoError> {
    let b = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    let bad = |m: &str| IoError::invalid(path, format!("npy: {m}"));
    if b.len() < 10 || &b[..6] != b"\x93NUMPY" {
        return Err(bad("wrong magic"));
    }
    let hl = u16::from_le_bytes([b[8], b[9]]) as usize;
    let header = std::str::from_utf8(b.get(10..10 + hl).ok_or_else(|| bad("truncated header"))?)
        .map_err(|_| bad("header is not text"))?;
    if !header.contains("'<f4'") || header.contains("'fortran_order': True") {
        return Err(bad(
            "only little-endian float32 C-order arrays are supported",
        ));
    }
    let shape = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| bad("no shape"))?;
    let dims: Vec<usize> = shape
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().map_err(|_| bad("bad shape")))
        .collect::<Result<_, _>>()?;
    let body = &b[10 + hl..];
    let n = dims
        .iter()
        .try_fold(4usize, |a, &d| a.checked_mul(d))
        .ok_or_else(|| bad("shape too large"))?;
    if body.len() != n {
        return Err(bad("data length does not match the shape"));
    }
    let data = body
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    Ok((dims, data))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A PNG whose header claims 100 000 × 100 000 pixels (and holds none) is refused from
    /// its header, not by a 40 GB allocation.
    #[test]
    fn a_huge_png_header_is_refused_before_allocating() {
        fn crc(bytes: &[u8]) -> u32 {
            let mut c = 0xFFFF_FFFFu32;
            for &b in bytes {
                c ^= b as u32;
                for _ in 0..8 {
                    c = if c & 1 == 1 {
                        0xEDB8_8320 ^ (c >> 1)
                    } else {
                        c >> 1
                    };
                }
            }
            !c
        }
        let mut ihdr = b"IHDR".to_vec();
        ihdr.extend_from_slice(&100_000u32.to_be_bytes());
        ihdr.extend_from_slice(&100_000u32.to_be_bytes());
        ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        png.extend_from_slice(&13u32.to_be_bytes());
        png.extend_from_slice(&ihdr);
        png.extend_from_slice(&crc(&ihdr).to_be_bytes());
        // An empty IDAT: the decoder reads the header up to the image data.
        png.extend_from_slice(&0u32.to_be_bytes());
        png.extend_from_slice(b"IDAT");
        png.extend_from_slice(&crc(b"IDAT").to_be_bytes());
        let mut iend = b"IEND".to_vec();
        png.extend_from_slice(&0u32.to_be_bytes());
        png.extend_from_slice(&iend);
        iend = crc(&iend).to_be_bytes().to_vec();
        png.extend_from_slice(&iend);
        let p = std::env::temp_dir().join(format!("stipple-huge-{}.png", std::process::id()));
        std::fs::write(&p, &png).unwrap();
        let e = read_png(&p).unwrap_err().to_string();
        let _ = std::fs::remove_file(&p);
        assert!(e.contains("100000×100000"), "{e}");
    }
}
