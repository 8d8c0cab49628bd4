//! Shadow texture sidecar files (`.stshadow`): a computed shadow texture saved with the key
//! of what it was computed for (clouds, their placement and the lights, see
//! `scene::relative_key`), reloaded instead of recomputed while the key matches.
//!
//! Layout (little-endian): magic `STSHADOW`, u32 version (2), u32 flags (bit 0: coloured),
//! u64 key, u64 point count, 4 × u32 samples per light, then four u16 lit sums per point
//! (light l's at 2l; 255 per fully lit sample, see `stipple_render::LitTexture`), for a
//! coloured texture followed by eight u16 per point (red and blue of each light, `rb`), then
//! the CRC-32 of everything before it. Version 1 (one byte of sample counts per light) is not read: such a
//! cache is recomputed, and the new one replaces it.

use crate::SceneError;
use std::io::Write;
use std::path::Path;
use stipple_render::LitTexture;

const MAGIC: &[u8; 8] = b"STSHADOW";
const VERSION: u32 = 2;
/// Bytes per point.
const PER_POINT: usize = 8;
/// Bytes per point more for a coloured texture.
const RB_PER_POINT: usize = 16;
const HEADER: usize = 8 + 4 + 4 + 8 + 8 + 16;

/// What a cache file holds.
#[derive(Debug)]
pub struct Cached {
    pub key: u64,
    pub lit: LitTexture,
}

/// Writes a cache file (atomically). Refuses to replace a file that is not a shadow cache.
pub fn write(path: &Path, key: u64, lit: &LitTexture) -> Result<(), SceneError> {
    if let Ok(mut f) = std::fs::File::open(path) {
        let mut magic = [0u8; 8];
        use std::io::Read;
        if f.read_exact(&mut magic).is_err() || &magic != MAGIC {
            return Err(SceneError::Cache {
                path: path.to_path_buf(),
                message: "exists and is not a stipple shadow cache; refusing to overwrite it"
                    .into(),
            });
        }
    }
    let per = PER_POINT + lit.rb.as_ref().map_or(0, |_| RB_PER_POINT);
    let mut buf = Vec::with_capacity(HEADER + per * lit.counts.len() + 4);
    buf.extend_from_slice(MAGIC);
    buf.extend_from_slice(&VERSION.to_le_bytes());
    buf.extend_from_slice(&(lit.rb.is_some() as u32).to_le_bytes());
    buf.extend_from_slice(&key.to_le_bytes());
    buf.extend_from_slice(&(lit.counts.len() as u64).to_le_bytes());
    for s in lit.samples {
        buf.extend_from_slice(&s.to_le_bytes());
    }
    for c in &lit.counts {
        for v in c {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    for c in lit.rb.iter().flatten() {
        for v in c {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    let crc = crc32fast::hash(&buf);
    buf.extend_from_slice(&crc.to_le_bytes());
    stipple_io::write_atomically(path, |tmp| {
        let w = || -> std::io::Result<()> {
            let mut f = std::fs::File::create(tmp)?;
            f.write_all(&buf)?;
            f.sync_all()
        };
        w().map_err(|e| stipple_io::IoError::io(tmp, e))
    })?;
    Ok(())
}

/// Reads a cache file made for a cloud of `points` points. Every inconsistency is an error
/// naming the file; nothing is allocated from an unchecked count.
pub fn read(path: &Path, points: usize) -> Result<Cached, SceneError> {
    let bad = |m: &str| SceneError::Cache {
        path: path.to_path_buf(),
        message: m.to_string(),
    };
    let read_error = |e| SceneError::Read {
        path: path.to_path_buf(),
        source: e,
    };
    let len = std::fs::metadata(path).map_err(read_error)?.len();
    if len < HEADER as u64 {
        return Err(bad("too short to be a shadow cache"));
    }
    // The version and flags first: a version-1 file has another size for the same cloud,
    // and a coloured one more bytes per point.
    let mut coloured = false;
    {
        use std::io::Read;
        let mut head = [0u8; 16];
        let mut f = std::fs::File::open(path).map_err(read_error)?;
        f.read_exact(&mut head).map_err(read_error)?;
        if &head[..8] == MAGIC {
            let v = u32::from_le_bytes(head[8..12].try_into().unwrap());
            if v != VERSION {
                return Err(bad(&format!(
                    "version {v} (this stipple reads {VERSION}; it is recomputed)"
                )));
            }
            let flags = u32::from_le_bytes(head[12..16].try_into().unwrap());
            if flags > 1 {
                return Err(bad(&format!("unknown flags {flags:#x}")));
            }
            coloured = flags == 1;
        }
    }
    let per = PER_POINT + if coloured { RB_PER_POINT } else { 0 };
    let want = (HEADER as u64)
        .saturating_add((per as u64).saturating_mul(points as u64))
        .saturating_add(4);
    if len != want {
        return Err(bad(&format!(
            "has {len} bytes, but a shadow cache for {points} points has {want} (made for \
             another cloud, or cut short)"
        )));
    }
    let buf = std::fs::read(path).map_err(read_error)?;
    if &buf[..8] != MAGIC {
        return Err(bad("not a stipple shadow cache"));
    }
    let u32_at = |o: usize| u32::from_le_bytes(buf[o..o + 4].try_into().unwrap());
    let u64_at = |o: usize| u64::from_le_bytes(buf[o..o + 8].try_into().unwrap());
    if u32_at(8) != VERSION {
        return Err(bad(&format!(
            "version {} (this stipple reads {VERSION})",
            u32_at(8)
        )));
    }
    let n = buf.len() - 4;
    if crc32fast::hash(&buf[..n]) != u32_at(n) {
        return Err(bad("checksum mismatch (the file is damaged)"));
    }
    if u64_at(24) != points as u64 {
        return Err(bad(&format!(
            "made for {} points, the cloud has {points}",
            u64_at(24)
        )));
    }
    let samples = [u32_at(32), u32_at(36), u32_at(40), u32_at(44)];
    if samples
        .iter()
        .any(|&s| s > stipple_render::shadow::MAX_SAMPLES)
    {
        return Err(bad("sample counts out of range"));
    }
    let rb_start = HEADER + PER_POINT * points;
    let counts: Vec<[u16; 4]> = buf[HEADER..rb_start]
        .chunks_exact(PER_POINT)
        .map(|c| std::array::from_fn(|l| u16::from_le_bytes([c[2 * l], c[2 * l + 1]])))
        .collect();
    let most = |l: usize| samples[l] * stipple_render::shadow::FULL as u32;
    if counts.iter().any(|c| (0..4).any(|l| c[l] as u32 > most(l))) {
        return Err(bad("lit sums out of range for the samples taken"));
    }
    let rb: Option<Vec<[u16; 8]>> = coloured.then(|| {
        buf[rb_start..n]
            .chunks_exact(RB_PER_POINT)
            .map(|c| std::array::from_fn(|k| u16::from_le_bytes([c[2 * k], c[2 * k + 1]])))
            .collect()
    });
    if let Some(rb) = &rb {
        if rb.iter().any(|c| (0..8).any(|k| c[k] as u32 > most(k / 2))) {
            return Err(bad("lit sums out of range for the samples taken"));
        }
    }
    Ok(Cached {
        key: u64_at(16),
        lit: LitTexture {
            counts,
            samples,
            rb,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_damage() {
        let dir = std::env::temp_dir().join(format!("stipple-cache-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.stshadow");
        let lit = LitTexture {
            counts: (0..1000u32)
                .map(|i| {
                    let h = i.wrapping_mul(2_654_435_761);
                    [(h % 7651) as u16, (h % 256) as u16, 0, (h % 65026) as u16]
                })
                .collect(),
            samples: [30, 1, 0, 255],
            rb: None,
        };
        write(&p, 42, &lit).unwrap();
        let back = read(&p, 1000).unwrap();
        assert_eq!(back.key, 42);
        assert_eq!(back.lit, lit);
        // Another cloud size, a flipped byte, a cut file: errors naming the file.
        assert!(read(&p, 999)
            .unwrap_err()
            .to_string()
            .contains("a.stshadow"));
        let mut bytes = std::fs::read(&p).unwrap();
        bytes[HEADER + 17] ^= 1;
        std::fs::write(&p, &bytes).unwrap();
        assert!(read(&p, 1000).unwrap_err().to_string().contains("checksum"));
        bytes.truncate(100);
        std::fs::write(&p, &bytes).unwrap();
        assert!(read(&p, 1000).unwrap_err().to_string().contains("bytes"));
        // A file that is not a cache is never overwritten.
        let other = dir.join("notes.stshadow");
        std::fs::write(&other, b"my notes").unwrap();
        assert!(write(&other, 1, &lit)
            .unwrap_err()
            .to_string()
            .contains("refusing"));
        assert_eq!(std::fs::read(&other).unwrap(), b"my notes");
        // A version-1 cache (a byte per light and point) is refused, to be recomputed.
        let mut v1 = MAGIC.to_vec();
        v1.extend_from_slice(&1u32.to_le_bytes());
        v1.resize(HEADER + 4 * 1000 + 4, 0);
        std::fs::write(&p, &v1).unwrap();
        assert!(read(&p, 1000)
            .unwrap_err()
            .to_string()
            .contains("version 1"));
        // A sum larger than the samples allow (light 1 took one sample: at most 255).
        let mut big = lit.clone();
        big.counts[7][1] = 256;
        write(&p, 42, &big).unwrap();
        assert!(read(&p, 1000)
            .unwrap_err()
            .to_string()
            .contains("out of range"));
        // A coloured texture keeps its red and blue sums; one out of range is refused, and
        // unknown flags too.
        let mut coloured = lit.clone();
        coloured.rb = Some(
            (0..1000u16)
                .map(|i| [i % 255, 3, 0, 255, 0, 0, i, 7])
                .collect(),
        );
        write(&p, 43, &coloured).unwrap();
        assert_eq!(read(&p, 1000).unwrap().lit, coloured);
        coloured.rb.as_mut().unwrap()[5][2] = 256;
        write(&p, 43, &coloured).unwrap();
        assert!(read(&p, 1000)
            .unwrap_err()
            .to_string()
            .contains("out of range"));
        let mut bytes = std::fs::read(&p).unwrap();
        bytes[12] = 6;
        std::fs::write(&p, &bytes).unwrap();
        assert!(read(&p, 1000).unwrap_err().to_string().contains("flags"));
        std::fs::remove_dir_all(dir).unwrap();
    }
}
