//! Payload codecs of the `.stlod` format ([`crate::format::Header::codec`]).
//!
//! [`CODEC_LZ4`]: the records are split into byte planes (byte k of every record, then byte
//! k + 1, …: the high bytes of nearby positions repeat, and a colour channel often does), and
//! the planes are compressed as one LZ4 block. LZ4 was chosen over zstd for decoding speed:
//! a frame waits on payloads while it streams (figures in `BENCHMARKS.md`).

use crate::format::{CODEC_LZ4, CODEC_RAW};
use crate::record::Record;

/// No codec decodes more than this many bytes per stored byte (LZ4's bound is about 255), so
/// a node's count can be checked against its stored size before anything is allocated.
pub const MAX_RATIO: u64 = 256;

/// The stored form of `recs`.
pub fn encode(codec: u32, recs: &[Record]) -> Vec<u8> {
    let bytes: &[u8] = bytemuck::cast_slice(recs);
    match codec {
        CODEC_LZ4 => lz4_flex::block::compress(&planes(bytes)),
        _ => bytes.to_vec(),
    }
}

/// Decodes `stored` into `out` (sized to the node's count); an error says what is wrong.
pub fn decode(codec: u32, stored: &[u8], out: &mut [Record]) -> Result<(), String> {
    let dst: &mut [u8] = bytemuck::cast_slice_mut(out);
    match codec {
        CODEC_RAW if stored.len() == dst.len() => {
            dst.copy_from_slice(stored);
            Ok(())
        }
        CODEC_LZ4 => {
            let mut p = vec![0u8; dst.len()];
            let n = lz4_flex::block::decompress_into(stored, &mut p)
                .map_err(|e| format!("do not decompress ({e})"))?;
            if n != dst.len() {
                return Err(format!("decompress to {n} bytes instead of {}", dst.len()));
            }
            unplanes(&p, dst);
            Ok(())
        }
        c => Err(format!("are stored with unknown codec {c}")),
    }
}

/// Records (16 bytes each) to byte planes.
fn planes(b: &[u8]) -> Vec<u8> {
    let n = b.len() / Record::SIZE;
    let mut p = vec![0u8; b.len()];
    for (i, r) in b.chunks_exact(Record::SIZE).enumerate() {
        for (k, &v) in r.iter().enumerate() {
            p[k * n + i] = v;
        }
    }
    p
}

/// Byte planes back to records.
fn unplanes(p: &[u8], b: &mut [u8]) {
    let n = b.len() / Record::SIZE;
    for (i, r) in b.chunks_exact_mut(Record::SIZE).enumerate() {
        for (k, v) in r.iter_mut().enumerate() {
            *v = p[k * n + i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn payloads_round_trip_and_damage_is_an_error() {
        let recs: Vec<Record> = (0..5000)
            .map(|i| {
                let t = i as f32 * 0.01;
                Record::new(
                    Vec3::new(t.sin() * 10.0, t, t.cos()),
                    [(i % 7) as u8, 200, (i / 50) as u8],
                )
            })
            .collect();
        for codec in [CODEC_RAW, CODEC_LZ4] {
            let s = encode(codec, &recs);
            let mut back = vec![Record::zeroed(); recs.len()];
            decode(codec, &s, &mut back).unwrap();
            assert_eq!(back, recs, "codec {codec}");
            // Cut short: an error, never a panic.
            let e = decode(codec, &s[..s.len() / 2], &mut back);
            assert!(e.is_err(), "codec {codec}");
        }
        let s = encode(CODEC_LZ4, &recs);
        assert!(
            s.len() < recs.len() * Record::SIZE * 3 / 4,
            "{} bytes",
            s.len()
        );
        // A stored payload that decodes to fewer records than the node says.
        let short = encode(CODEC_LZ4, &recs[..10]);
        let mut back = vec![Record::zeroed(); 11];
        assert!(decode(CODEC_LZ4, &short, &mut back).is_err());
        assert!(decode(9, &short, &mut back).is_err());
    }
}
