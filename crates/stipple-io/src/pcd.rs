//! PCD (the Point Cloud Library's format, v0.6/v0.7): `DATA ascii`, `binary` (one record
//! per point) and `binary_compressed` (LZF-compressed, each field's values stored together).
//! Fields read: `x y z` (required), `normal_x normal_y normal_z`, `rgb` (a float whose bits
//! are 0x00RRGGBB, as PCL writes it) or `rgba` (a 32-bit integer), and `intensity`; other
//! single-valued fields (`curvature`, `label`, …) are kept as scalar fields (at most
//! `MAX_FIELDS`), fields of several values (histograms) are skipped. Points with a non-finite coordinate (the invalid pixels of an organised cloud,
//! e.g. a Kinect frame) are dropped, as PCL's own tools do.
//!
//! Sizes are checked before anything is allocated: the header's point count against the
//! file's length for `binary`, and the compressed block's declared sizes against the file
//! and against LZF's largest expansion for `binary_compressed`.

use glam::{DVec3, Vec3};
use stipple_core::PointCloud;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    I,
    U,
    F,
}

#[derive(Clone, Debug)]
struct Field {
    name: String,
    size: usize,
    kind: Kind,
    count: usize,
}

impl Field {
    fn bytes(&self) -> usize {
        self.size * self.count
    }

    /// The first value of this field in `b` (its bytes, little endian).
    fn value(&self, b: &[u8]) -> f64 {
        let le = |n: usize| {
            let mut a = [0u8; 8];
            a[..n].copy_from_slice(&b[..n]);
            u64::from_le_bytes(a)
        };
        match (self.kind, self.size) {
            (Kind::F, 4) => f32::from_bits(le(4) as u32) as f64,
            (Kind::F, 8) => f64::from_bits(le(8)),
            (Kind::U, n) => le(n) as f64,
            (Kind::I, n) => {
                let shift = 64 - 8 * n as u32;
                ((le(n) << shift) as i64 >> shift) as f64
            }
            (Kind::F, _) => f64::NAN,
        }
    }

    /// The first value's raw bits (for packed colours).
    fn bits(&self, b: &[u8]) -> u32 {
        let mut a = [0u8; 4];
        let n = self.size.min(4);
        a[..n].copy_from_slice(&b[..n]);
        u32::from_le_bytes(a)
    }
}

/// Reads a PCD file.
pub fn read_pcd(path: &std::path::Path) -> Result<PointCloud, crate::IoError> {
    let bytes = std::fs::read(path).map_err(|e| crate::IoError::io(path, e))?;
    parse_pcd(&bytes).map_err(|e| crate::IoError::invalid(path, e))
}

/// Parses PCD bytes.
pub fn parse_pcd(bytes: &[u8]) -> Result<PointCloud, String> {
    // The header: text lines up to and including DATA.
    let mut at = 0;
    let mut fields: Vec<String> = Vec::new();
    let (mut sizes, mut types, mut counts) = (Vec::new(), Vec::new(), Vec::new());
    let (mut width, mut height, mut points) = (None::<u64>, None::<u64>, None::<u64>);
    let mut viewpoint: Option<Vec<f64>> = None;
    let data;
    loop {
        if at >= bytes.len() {
            return Err("the header ends without a DATA line".into());
        }
        let end = bytes[at..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |e| at + e);
        if end - at > 4096 {
            return Err("a header line longer than 4096 bytes: not a PCD file".into());
        }
        let line = std::str::from_utf8(&bytes[at..end])
            .map_err(|_| "the header is not text: not a PCD file".to_string())?
            .trim();
        at = (end + 1).min(bytes.len());
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut it = line.split_whitespace();
        let key = it.next().unwrap_or("").to_ascii_uppercase();
        let rest: Vec<&str> = it.collect();
        let num = |s: &str| -> Result<u64, String> {
            s.parse().map_err(|_| {
                format!(
                    "{key}: `{}` is not a count",
                    s.chars().take(20).collect::<String>()
                )
            })
        };
        match key.as_str() {
            "VERSION" => {}
            "VIEWPOINT" => {
                let v: Vec<f64> = rest.iter().filter_map(|s| s.parse().ok()).collect();
                if v.len() != 7 || v.iter().any(|x| !x.is_finite()) {
                    return Err("VIEWPOINT: expected tx ty tz qw qx qy qz".into());
                }
                viewpoint = Some(v);
            }
            "FIELDS" | "COLUMNS" => fields = rest.iter().map(|s| s.to_string()).collect(),
            "SIZE" => sizes = rest.iter().map(|s| num(s)).collect::<Result<_, _>>()?,
            "TYPE" => {
                types = rest
                    .iter()
                    .map(|s| match *s {
                        "I" => Ok(Kind::I),
                        "U" => Ok(Kind::U),
                        "F" => Ok(Kind::F),
                        o => Err(format!(
                            "TYPE: `{}` (I, U or F)",
                            o.chars().take(8).collect::<String>()
                        )),
                    })
                    .collect::<Result<_, _>>()?
            }
            "COUNT" => counts = rest.iter().map(|s| num(s)).collect::<Result<_, _>>()?,
            "WIDTH" => width = Some(num(rest.first().copied().unwrap_or(""))?),
            "HEIGHT" => height = Some(num(rest.first().copied().unwrap_or(""))?),
            "POINTS" => points = Some(num(rest.first().copied().unwrap_or(""))?),
            "DATA" => {
                data = rest
                    .first()
                    .map(|s| s.to_ascii_lowercase())
                    .unwrap_or_default();
                break;
            }
            _ => {
                return Err(format!(
                    "unknown header line `{}`: not a PCD file",
                    key.chars().take(20).collect::<String>()
                ))
            }
        }
    }
    if fields.is_empty() {
        return Err("no FIELDS line".into());
    }
    if counts.is_empty() {
        counts = vec![1; fields.len()];
    }
    if sizes.len() != fields.len() || types.len() != fields.len() || counts.len() != fields.len() {
        return Err(format!(
            "{} FIELDS but {} SIZE, {} TYPE and {} COUNT entries",
            fields.len(),
            sizes.len(),
            types.len(),
            counts.len()
        ));
    }
    let fields: Vec<Field> = (0..fields.len())
        .map(|i| {
            let (size, kind, count) = (sizes[i] as usize, types[i], counts[i] as usize);
            let ok = match kind {
                Kind::F => matches!(size, 4 | 8),
                _ => matches!(size, 1 | 2 | 4 | 8),
            };
            if !ok || count == 0 || count > 1 << 16 {
                return Err(format!(
                    "field `{}`: SIZE {size}, TYPE {kind:?}, COUNT {count} is not a PCD field",
                    fields[i]
                ));
            }
            Ok(Field {
                name: fields[i].clone(),
                size,
                kind,
                count,
            })
        })
        .collect::<Result<_, _>>()?;
    let n = match (points, width, height) {
        (Some(p), _, _) => p,
        (None, Some(w), Some(h)) => w.saturating_mul(h),
        _ => return Err("no POINTS (or WIDTH and HEIGHT) line".into()),
    };
    let record: usize = fields.iter().map(Field::bytes).sum();
    let find = |name: &str| fields.iter().position(|f| f.name == name);
    let (ix, iy, iz) = match (find("x"), find("y"), find("z")) {
        (Some(x), Some(y), Some(z)) => (x, y, z),
        _ => return Err("FIELDS has no x y z".into()),
    };
    let body = &bytes[at..];
    // Every point's record, as bytes per field: (field index) → slice for point i.
    let table: Vec<u8>;
    let aos: bool;
    match data.as_str() {
        "ascii" => {
            let mut c = parse_ascii(body, &fields, n, [ix, iy, iz])?;
            c.sensor = sensor(viewpoint.as_deref());
            c.face_sensor_to_points();
            return Ok(c);
        }
        "binary" => {
            let need = n
                .checked_mul(record as u64)
                .filter(|&b| b <= body.len() as u64);
            let Some(need) = need else {
                return Err(format!(
                    "POINTS {n} × {record} bytes is more than the {} bytes of data in the file \
                     (truncated?)",
                    body.len()
                ));
            };
            table = body[..need as usize].to_vec();
            aos = true;
        }
        "binary_compressed" => {
            if body.len() < 8 {
                return Err("the compressed block's sizes are missing (truncated?)".into());
            }
            let csize = u32::from_le_bytes(body[0..4].try_into().expect("4 bytes")) as usize;
            let usize_ = u32::from_le_bytes(body[4..8].try_into().expect("4 bytes")) as u64;
            if csize > body.len() - 8 {
                return Err(format!(
                    "the compressed block claims {csize} bytes, the file holds {} (truncated?)",
                    body.len() - 8
                ));
            }
            if n.checked_mul(record as u64) != Some(usize_) {
                return Err(format!(
                    "the compressed block holds {usize_} bytes, but POINTS {n} × {record} bytes \
                     were declared"
                ));
            }
            // LZF expands at most about 132 × (a 3-byte reference copies up to 264 bytes).
            if usize_ > 132 * csize as u64 + 264 {
                return Err(format!(
                    "the compressed block of {csize} bytes cannot hold {usize_} bytes"
                ));
            }
            table = lzf_decompress(&body[8..8 + csize], usize_ as usize)?;
            aos = false;
        }
        other => {
            return Err(format!(
                "DATA `{}` (ascii, binary or binary_compressed)",
                other.chars().take(20).collect::<String>()
            ))
        }
    }
    let n = n as usize;
    // Where field f of point i starts in `table`.
    let mut offset = Vec::with_capacity(fields.len());
    let mut o = 0;
    for f in &fields {
        offset.push(o);
        o += if aos { f.bytes() } else { f.bytes() * n };
    }
    let slot = |f: usize, i: usize| -> &[u8] {
        let start = if aos {
            i * record + offset[f]
        } else {
            offset[f] + i * fields[f].bytes()
        };
        &table[start..start + fields[f].bytes()]
    };
    let value = |f: usize, i: usize| fields[f].value(slot(f, i));
    let mut c = collect(n, &fields, [ix, iy, iz], value, |f, i| {
        fields[f].bits(slot(f, i))
    })?;
    c.sensor = sensor(viewpoint.as_deref());
    c.face_sensor_to_points();
    Ok(c)
}

/// The sensor of a `VIEWPOINT tx ty tz qw qx qy qz` (PCL's default, `0 0 0 1 0 0 0`, is a
/// sensor at the origin): it looks along its +Z with image up along its −Y (the camera
/// convention of depth sensors such as the Kinect). Absent: none.
fn sensor(v: Option<&[f64]>) -> Option<stipple_core::cloud::Sensor> {
    let v = v?;
    let q = glam::DQuat::from_xyzw(v[4], v[5], v[6], v[3]);
    let q = if q.length() > 0.0 {
        q.normalize()
    } else {
        glam::DQuat::IDENTITY
    };
    Some(stipple_core::cloud::Sensor {
        position: DVec3::new(v[0], v[1], v[2]),
        forward: q * DVec3::Z,
        up: q * -DVec3::Y,
    })
}

/// Builds the cloud from per-point field values (`value`) and raw bits (`bits`, colours).
fn collect(
    n: usize,
    fields: &[Field],
    [ix, iy, iz]: [usize; 3],
    value: impl Fn(usize, usize) -> f64,
    bits: impl Fn(usize, usize) -> u32,
) -> Result<PointCloud, String> {
    let find = |name: &str| fields.iter().position(|f| f.name == name);
    let normal = match (find("normal_x"), find("normal_y"), find("normal_z")) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    let colour = find("rgb").or_else(|| find("rgba"));
    let intensity = find("intensity");
    let keep: Vec<usize> = (0..n)
        .filter(|&i| [ix, iy, iz].iter().all(|&f| value(f, i).is_finite()))
        .collect();
    if keep.is_empty() {
        return Err(format!("none of the {n} points has finite coordinates"));
    }
    let world: Vec<DVec3> = keep
        .iter()
        .map(|&i| DVec3::new(value(ix, i), value(iy, i), value(iz, i)))
        .collect();
    for p in &world {
        if let Some(why) = stipple_core::cloud::coordinate_problem(*p) {
            return Err(why);
        }
    }
    let mut cloud = PointCloud::from_world(&world);
    if let Some([a, b, c]) = normal {
        let nr: Vec<Vec3> = keep
            .iter()
            .map(|&i| DVec3::new(value(a, i), value(b, i), value(c, i)).as_vec3())
            .collect();
        if nr.iter().all(|v| v.is_finite()) {
            cloud.normals = Some(nr);
        }
    }
    if let Some(f) = colour {
        cloud.colors = Some(
            keep.iter()
                .map(|&i| {
                    let v = bits(f, i);
                    [(v >> 16) as u8, (v >> 8) as u8, v as u8]
                })
                .collect(),
        );
    }
    let used = |f: usize| {
        [Some(ix), Some(iy), Some(iz), colour, intensity].contains(&Some(f))
            || normal.is_some_and(|n| n.contains(&f))
    };
    for (f, field) in fields.iter().enumerate() {
        if used(f)
            || field.count != 1
            || field.name.starts_with('_')
            || cloud.fields.len() >= stipple_core::cloud::MAX_FIELDS
        {
            continue;
        }
        let v: Vec<f64> = keep.iter().map(|&i| value(f, i)).collect();
        cloud
            .fields
            .push(stipple_core::cloud::Field::new(field.name.clone(), &v));
    }
    if let Some(f) = intensity {
        let v: Vec<f64> = keep.iter().map(|&i| value(f, i)).collect();
        let max = v
            .iter()
            .copied()
            .filter(|x| x.is_finite())
            .fold(0.0, f64::max);
        // Intensities in 0..1 (PCL's float convention) scale to the 16-bit range LAS uses.
        let scale = if max <= 1.0 { 65535.0 } else { 1.0 };
        cloud.intensity = Some(
            v.iter()
                .map(|x| {
                    if x.is_finite() {
                        (x * scale).round().clamp(0.0, 65535.0) as u16
                    } else {
                        0
                    }
                })
                .collect(),
        );
    }
    Ok(cloud)
}

fn parse_ascii(
    body: &[u8],
    fields: &[Field],
    n: u64,
    xyz: [usize; 3],
) -> Result<PointCloud, String> {
    let text = String::from_utf8_lossy(body);
    let per: usize = fields.iter().map(|f| f.count).sum();
    // Each field's first value per point.
    let mut first = Vec::with_capacity(fields.len());
    let mut k = 0;
    for f in fields {
        first.push(k);
        k += f.count;
    }
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let v: Vec<f64> = line
            .split_whitespace()
            .map(|t| {
                // "nan" and "inf" parse; such points are dropped later.
                t.parse::<f64>().map_err(|_| {
                    format!(
                        "data line {}: `{}` is not a number",
                        ln + 1,
                        t.chars().take(20).collect::<String>()
                    )
                })
            })
            .collect::<Result<_, _>>()?;
        if v.len() != per {
            return Err(format!(
                "data line {}: {} values, {per} expected from FIELDS and COUNT",
                ln + 1,
                v.len()
            ));
        }
        rows.push(v);
    }
    if rows.len() as u64 != n {
        return Err(format!("{} data lines, but POINTS {n}", rows.len()));
    }
    collect(
        rows.len(),
        fields,
        xyz,
        |f, i| rows[i][first[f]],
        |f, i| {
            let x = rows[i][first[f]];
            // A packed float colour as written in text is its float value.
            if fields[f].kind == Kind::F {
                (x as f32).to_bits()
            } else {
                x as u32
            }
        },
    )
}

/// LZF decompression (the format PCL's binary_compressed uses) into exactly `size` bytes.
pub fn lzf_decompress(input: &[u8], size: usize) -> Result<Vec<u8>, String> {
    let bad = || "the compressed data is corrupt".to_string();
    let mut out: Vec<u8> = Vec::with_capacity(size);
    let mut ip = 0;
    while ip < input.len() {
        let ctrl = input[ip] as usize;
        ip += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            if ip + len > input.len() || out.len() + len > size {
                return Err(bad());
            }
            out.extend_from_slice(&input[ip..ip + len]);
            ip += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += *input.get(ip).ok_or_else(bad)? as usize;
                ip += 1;
            }
            len += 2;
            let low = *input.get(ip).ok_or_else(bad)? as usize;
            ip += 1;
            let back = ((ctrl & 0x1f) << 8) + low + 1;
            if back > out.len() || out.len() + len > size {
                return Err(bad());
            }
            let from = out.len() - back;
            for k in 0..len {
                let b = out[from + k];
                out.push(b);
            }
        }
    }
    if out.len() != size {
        return Err(format!(
            "the compressed data gives {} bytes, {size} were declared",
            out.len()
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(fields: &str, size: &str, ty: &str, n: usize, data: &str) -> String {
        format!(
            "# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {ty}\nCOUNT {}\n\
             WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n",
            vec!["1"; fields.split(' ').count()].join(" ")
        )
    }

    #[test]
    fn ascii_with_colours_normals_and_invalid_points() {
        let rgb = f32::from_bits(0x00ff8010);
        let mut s = header(
            "x y z normal_x normal_y normal_z rgb",
            "4 4 4 4 4 4 4",
            "F F F F F F F",
            3,
            "ascii",
        );
        s.push_str(&format!(
            "0 0 0 0 0 1 {rgb:e}\n1 2 3 0 1 0 {rgb:e}\nnan nan nan 0 0 1 0\n"
        ));
        let c = parse_pcd(s.as_bytes()).unwrap();
        assert_eq!(c.len(), 2, "the invalid point is dropped");
        assert_eq!(c.colors.as_ref().unwrap()[1], [0xff, 0x80, 0x10]);
        assert_eq!(c.normals.as_ref().unwrap()[1], Vec3::Y);
        assert!((c.world(1) - DVec3::new(1.0, 2.0, 3.0)).length() < 1e-6);
    }

    #[test]
    fn single_valued_extra_fields_are_kept_by_name() {
        let mut s = header(
            "x y z curvature label _ fpfh",
            "4 4 4 4 4 1 4",
            "F F F F U U F",
            2,
            "ascii",
        );
        // `fpfh` has 3 values per point (COUNT 1 1 1 1 1 1 3), `_` is padding.
        s = s.replace("COUNT 1 1 1 1 1 1 1", "COUNT 1 1 1 1 1 1 3");
        s.push_str("0 0 0 0.5 7 0 1 2 3\n1 1 1 0.25 9 0 4 5 6\n");
        let c = parse_pcd(s.as_bytes()).unwrap();
        let names: Vec<&str> = c.fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["curvature", "label"]);
        assert_eq!(c.field("label").unwrap().value(1), 9.0);
        assert_eq!(c.field("curvature").unwrap().value(1), 0.25);
    }

    /// A compressor for tests: literal runs only (valid LZF).
    fn lzf_literal(data: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        for chunk in data.chunks(32) {
            out.push(chunk.len() as u8 - 1);
            out.extend_from_slice(chunk);
        }
        out
    }

    #[test]
    fn binary_and_compressed_agree() {
        let pts = [[0.5f32, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.5]];
        let colours = [0x010203u32, 0x102030, 0xa0b0c0];
        let mut aos = Vec::new();
        for (p, c) in pts.iter().zip(colours) {
            for x in p {
                aos.extend_from_slice(&x.to_le_bytes());
            }
            aos.extend_from_slice(&c.to_le_bytes());
        }
        let mut bin = header("x y z rgba", "4 4 4 4", "F F F U", 3, "binary").into_bytes();
        bin.extend_from_slice(&aos);
        let a = parse_pcd(&bin).unwrap();
        let mut soa = Vec::new();
        for f in 0..4 {
            for k in 0..3 {
                soa.extend_from_slice(&aos[16 * k + 4 * f..16 * k + 4 * f + 4]);
            }
        }
        let z = lzf_literal(&soa);
        let mut comp =
            header("x y z rgba", "4 4 4 4", "F F F U", 3, "binary_compressed").into_bytes();
        comp.extend_from_slice(&(z.len() as u32).to_le_bytes());
        comp.extend_from_slice(&(soa.len() as u32).to_le_bytes());
        comp.extend_from_slice(&z);
        let b = parse_pcd(&comp).unwrap();
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.colors, b.colors);
        assert_eq!(a.colors.as_ref().unwrap()[2], [0xa0, 0xb0, 0xc0]);
    }

    #[test]
    fn lzf_back_references_repeat_bytes() {
        // "abc" then a reference of length 6 at distance 3: "abcabcabc".
        let z = [2, b'a', b'b', b'c', (4 << 5) as u8, 2];
        assert_eq!(lzf_decompress(&z, 9).unwrap(), b"abcabcabc");
        assert!(lzf_decompress(&z, 8).is_err(), "longer than declared");
        assert!(
            lzf_decompress(&[(1 << 5) as u8, 9], 3).is_err(),
            "reference before the start"
        );
        assert!(
            lzf_decompress(&[5, b'a'], 6).is_err(),
            "literal past the end"
        );
    }

    #[test]
    fn bad_files_are_errors_before_allocating() {
        let big = header("x y z", "4 4 4", "F F F", 4_000_000_000, "binary");
        let e = parse_pcd(big.as_bytes()).err().unwrap();
        assert!(e.contains("more than the 0 bytes"), "{e}");
        let mut c = header("x y z", "4 4 4", "F F F", 1_000_000, "binary_compressed").into_bytes();
        c.extend_from_slice(&4u32.to_le_bytes());
        c.extend_from_slice(&12_000_000u32.to_le_bytes());
        c.extend_from_slice(&[0, 0, 0, 0]);
        let e = parse_pcd(&c).err().unwrap();
        assert!(e.contains("cannot hold"), "{e}");
        for (text, want) in [
            (
                "VERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nPOINTS 1\nDATA ascii\n1 2\n",
                "no x y z",
            ),
            (
                "VERSION 0.7\nFIELDS x y z\nSIZE 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 2 3\n",
                "SIZE",
            ),
            (
                "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 2\nDATA ascii\n1 2 3\n",
                "POINTS 2",
            ),
            (
                "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 2\n",
                "2 values",
            ),
            (
                "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA zip\n",
                "DATA `zip`",
            ),
            (
                "VERSION 0.7\nFIELDS x y z\nSIZE 3 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 2 3\n",
                "SIZE 3",
            ),
            ("hello\n", "unknown header line"),
            ("VERSION 0.7\nFIELDS x y z\n", "without a DATA line"),
        ] {
            let e = parse_pcd(text.as_bytes()).err().unwrap_or_default();
            assert!(e.contains(want), "{text:?}: {e}");
        }
    }
}
