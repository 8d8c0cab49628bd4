//! Radiance HDR (`.hdr`, RGBE) images: high-dynamic-range environments for transparent
//! splats (`--env FILE.hdr`). Reads the standard orientation (`-Y H +X W`) with flat or
//! run-length-encoded scanlines (the "new" encoding every writer uses); the old-style
//! repeat markers are refused with a message.

use crate::IoError;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// The most pixels an HDR read may hold (67 M: 768 MiB of linear RGB): a header claiming
/// more is an error before anything is allocated.
pub const MAX_HDR_PIXELS: u64 = 1 << 26;

/// The longest header line read (a hostile file is not read whole into one line).
const MAX_LINE: u64 = 4096;

/// One RGBE pixel as linear RGB (Radiance's `colr_color`: the mantissa's middle).
#[inline]
pub fn rgbe_to_linear([r, g, b, e]: [u8; 4]) -> [f32; 3] {
    if e == 0 {
        return [0.0; 3];
    }
    let f = 2f32.powi(e as i32 - 136);
    [
        (r as f32 + 0.5) * f,
        (g as f32 + 0.5) * f,
        (b as f32 + 0.5) * f,
    ]
}

/// Reads a Radiance HDR image into (width, height, linear RGB, rows top to bottom).
pub fn read_hdr(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>), IoError> {
    let f = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
    read_hdr_from(BufReader::new(f)).map_err(|m| match m {
        HdrError::Io(e) => IoError::io(path, e),
        HdrError::Invalid(m) => IoError::invalid(path, format!("HDR: {m}")),
    })
}

enum HdrError {
    Io(std::io::Error),
    Invalid(String),
}

impl From<std::io::Error> for HdrError {
    fn from(e: std::io::Error) -> Self {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            HdrError::Invalid("the file ends before its pixels do".into())
        } else {
            HdrError::Io(e)
        }
    }
}

fn bad<T>(m: impl Into<String>) -> Result<T, HdrError> {
    Err(HdrError::Invalid(m.into()))
}

/// A header line without its newline (at most MAX_LINE bytes).
fn line(r: &mut impl BufRead) -> Result<String, HdrError> {
    let mut buf = Vec::new();
    r.take(MAX_LINE).read_until(b'\n', &mut buf)?;
    if buf.last() != Some(&b'\n') {
        return bad(if buf.len() as u64 >= MAX_LINE {
            "a header line is too long"
        } else {
            "the file ends in its header"
        });
    }
    buf.pop();
    Ok(String::from_utf8_lossy(&buf)
        .trim_end_matches('\r')
        .to_string())
}

fn read_hdr_from(mut r: impl BufRead) -> Result<(u32, u32, Vec<[f32; 3]>), HdrError> {
    let magic = line(&mut r)?;
    if !(magic.starts_with("#?RADIANCE") || magic.starts_with("#?RGBE")) {
        return bad("not a Radiance HDR file (no #?RADIANCE line)");
    }
    let mut lines = 0;
    loop {
        let l = line(&mut r)?;
        if l.is_empty() {
            break;
        }
        if let Some(fmt) = l.strip_prefix("FORMAT=") {
            if fmt.trim() != "32-bit_rle_rgbe" {
                return bad(format!("format {fmt}: only 32-bit_rle_rgbe is read"));
            }
        }
        lines += 1;
        if lines > 1024 {
            return bad("the header has no end");
        }
    }
    let res = line(&mut r)?;
    let parts: Vec<&str> = res.split_whitespace().collect();
    let (h, w) = match parts[..] {
        ["-Y", h, "+X", w] => match (h.parse::<u32>(), w.parse::<u32>()) {
            (Ok(h), Ok(w)) if h > 0 && w > 0 => (h, w),
            _ => return bad(format!("bad size line {res:?}")),
        },
        _ => {
            return bad(format!(
                "size line {res:?}: only the standard orientation \"-Y H +X W\" is read"
            ))
        }
    };
    if w as u64 * h as u64 > MAX_HDR_PIXELS {
        return bad(format!(
            "{w}×{h} pixels is more than stipple reads (at most {MAX_HDR_PIXELS})"
        ));
    }
    // Row by row, so a short file fails before a large image is allocated.
    let mut out = Vec::new();
    let mut row = vec![[0u8; 4]; w as usize];
    for _ in 0..h {
        read_scanline(&mut r, &mut row)?;
        out.extend(row.iter().map(|&p| rgbe_to_linear(p)));
    }
    Ok((w, h, out))
}

fn read_scanline(r: &mut impl Read, row: &mut [[u8; 4]]) -> Result<(), HdrError> {
    let w = row.len();
    let mut head = [0u8; 4];
    r.read_exact(&mut head)?;
    let rle = (8..=0x7fff).contains(&w) && head[0] == 2 && head[1] == 2 && head[2] & 0x80 == 0;
    if !rle {
        // Flat pixels.
        row[0] = head;
        for p in row.iter_mut().skip(1) {
            r.read_exact(p)?;
            if p[0] == 1 && p[1] == 1 && p[2] == 1 {
                return bad("old-style run-length encoding is not read");
            }
        }
        return Ok(());
    }
    if ((head[2] as usize) << 8 | head[3] as usize) != w {
        return bad("a scanline's length differs from the image's width");
    }
    // Each channel in turn: runs (count > 128: count − 128 copies of a byte) and literals.
    for ch in 0..4 {
        let mut x = 0;
        while x < w {
            let mut c = [0u8; 1];
            r.read_exact(&mut c)?;
            let (run, n) = if c[0] > 128 {
                (true, (c[0] - 128) as usize)
            } else {
                (false, c[0] as usize)
            };
            if n == 0 || x + n > w {
                return bad("a run overflows its scanline");
            }
            if run {
                let mut v = [0u8; 1];
                r.read_exact(&mut v)?;
                for p in &mut row[x..x + n] {
                    p[ch] = v[0];
                }
            } else {
                for p in &mut row[x..x + n] {
                    let mut v = [0u8; 1];
                    r.read_exact(&mut v)?;
                    p[ch] = v[0];
                }
            }
            x += n;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(w: u32, h: u32) -> Vec<u8> {
        format!(
            "#?RADIANCE\n# made by a test\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1.0\n\n-Y {h} +X {w}\n"
        )
        .into_bytes()
    }

    /// The RGBE of a linear value (exact for these: powers of two times small integers).
    fn rgbe(v: [f32; 3]) -> [u8; 4] {
        let m = v.iter().cloned().fold(0.0f32, f32::max);
        if m <= 0.0 {
            return [0; 4];
        }
        let e = m.log2().floor() as i32 + 1;
        let f = 2f32.powi(8 - e);
        [
            (v[0] * f) as u8,
            (v[1] * f) as u8,
            (v[2] * f) as u8,
            (e + 128) as u8,
        ]
    }

    #[test]
    fn flat_and_run_length_scanlines_read_as_linear_rgb() {
        // Flat: 3 × 2.
        let px = [
            [4.0, 0.5, 0.0],
            [1.0, 1.0, 1.0],
            [0.0; 3],
            [0.25, 2.0, 8.0],
            [3.0, 0.0, 0.0],
            [0.5; 3],
        ];
        let mut f = header(3, 2);
        for p in px {
            f.extend(rgbe(p));
        }
        let (w, h, got) = read_hdr_from(&f[..]).ok().unwrap();
        assert_eq!((w, h), (3, 2));
        for (g, p) in got.iter().zip(px) {
            let e = rgbe_to_linear(rgbe(p));
            assert_eq!(*g, e);
            // Within half a step of the shared exponent's mantissa.
            let step = p.iter().cloned().fold(0.0f32, f32::max) / 128.0;
            for c in 0..3 {
                assert!((g[c] - p[c]).abs() <= step + 1e-6, "{g:?} vs {p:?}");
            }
        }
        // Run-length encoded: 10 × 1, a sky of 2.0 then 0.25, channel by channel.
        let mut f = header(10, 1);
        f.extend([2, 2, 0, 10]);
        let a = rgbe([2.0, 2.0, 2.0]);
        let b = rgbe([0.25, 0.25, 0.25]);
        for ch in 0..4 {
            // 6 copies of a (a run), then 4 literals of b.
            f.extend([128 + 6, a[ch], 4, b[ch], b[ch], b[ch], b[ch]]);
        }
        let (w, h, got) = read_hdr_from(&f[..]).ok().unwrap();
        assert_eq!((w, h), (10, 1));
        assert!(
            got[..6].iter().all(|p| (p[0] - 2.0).abs() < 0.02),
            "{got:?}"
        );
        assert!(
            got[6..].iter().all(|p| (p[1] - 0.25).abs() < 0.002),
            "{got:?}"
        );
    }

    #[test]
    fn hostile_files_are_clear_errors() {
        let msg = |b: &[u8]| match read_hdr_from(b) {
            Err(HdrError::Invalid(m)) => m,
            Err(HdrError::Io(e)) => format!("io {e}"),
            Ok(_) => "read".into(),
        };
        assert!(msg(b"P6\n").contains("not a Radiance"));
        assert!(msg(b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n").contains("xyze"));
        assert!(msg(b"#?RADIANCE\n\n+X 4 -Y 4\n").contains("orientation"));
        assert!(msg(b"#?RADIANCE\n\n-Y 100000 +X 100000\n").contains("more than"));
        assert!(msg(b"#?RADIANCE\n\n-Y 0 +X 5\n").contains("bad size"));
        // Claims 4096 × 4096 and stops: an error, not a 200 MB allocation.
        assert!(msg(b"#?RADIANCE\n\n-Y 4096 +X 4096\n\x02\x02").contains("ends before"));
        assert!(msg(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe").contains("ends in its header"));
        let long = [b"#?RADIANCE\n".to_vec(), vec![b'x'; 10_000]].concat();
        assert!(msg(&long).contains("too long"));
        // A run past the scanline's end.
        let mut f = header(10, 1);
        f.extend([2, 2, 0, 10, 128 + 20, 7]);
        assert!(msg(&f).contains("overflows"));
        // The old repeat markers.
        let mut f = header(3, 1);
        f.extend([10, 10, 10, 130, 1, 1, 1, 2, 0, 0, 0, 0]);
        assert!(msg(&f).contains("old-style"));
    }
}
