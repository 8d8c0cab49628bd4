//! PLY (Stanford polygon format): ascii, binary little and big endian, optionally gzip
//! compressed.
//!
//! The `vertex` element gives the points: x/y/z (any numeric type), optional nx/ny/nz,
//! red/green/blue (uchar, ushort or float in [0, 1]), alpha (kept as opacity) and intensity.
//! Other vertex properties are skipped. The `face` element's `vertex_indices` lists are kept
//! as triangles (polygons are fanned). Other elements are skipped.

use crate::IoError;
use glam::{DVec3, Vec3};
use std::io::Read;
use std::io::Write;
use std::path::Path;
use stipple_core::PointCloud;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    #[inline]
    fn read(self, b: &[u8], big: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap();
                (if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        }
    }
}

#[derive(Clone, Debug)]
enum Property {
    Scalar {
        name: String,
        ty: Scalar,
    },
    List {
        name: String,
        count: Scalar,
        item: Scalar,
    },
}

impl Property {
    fn name(&self) -> &str {
        match self {
            Property::Scalar { name, .. } | Property::List { name, .. } => name,
        }
    }
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

impl Element {
    /// Smallest number of bytes one binary record can take (lists may be empty).
    fn min_record(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p {
                Property::Scalar { ty, .. } => ty.size(),
                Property::List { count, .. } => count.size(),
            })
            .sum()
    }
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    data_start: usize,
}

const MAX_HEADER: usize = 1 << 20;

fn parse_header(data: &[u8]) -> Result<Header, String> {
    if !(data.starts_with(b"ply\n") || data.starts_with(b"ply\r\n")) {
        return Err("not a PLY file: the first line must be `ply`".into());
    }
    let limit = data.len().min(MAX_HEADER);
    let mut pos = 0;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut line_no = 0;
    loop {
        let rest = &data[pos..limit];
        let Some(nl) = rest.iter().position(|&c| c == b'\n') else {
            return Err(if limit == MAX_HEADER {
                "the header is longer than 1 MiB or has no `end_header`".into()
            } else {
                "the header ends without `end_header` (truncated file?)".into()
            });
        };
        line_no += 1;
        let line = std::str::from_utf8(&rest[..nl])
            .map_err(|_| format!("header line {line_no} is not text"))?
            .trim_end_matches('\r');
        pos += nl + 1;
        let words: Vec<&str> = line.split_ascii_whitespace().collect();
        match words.as_slice() {
            ["ply"] if line_no == 1 => {}
            ["format", f, v] => {
                if *v != "1.0" {
                    return Err(format!("unsupported PLY version {}", crate::shown(v)));
                }
                encoding = Some(match *f {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLittleEndian,
                    "binary_big_endian" => Encoding::BinaryBigEndian,
                    _ => return Err(format!("unknown PLY format `{}`", crate::shown(f))),
                });
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            ["element", name, count] => {
                let count: u64 = count.parse().map_err(|_| {
                    format!(
                        "header line {line_no}: element count `{}` is not a number",
                        crate::shown(count)
                    )
                })?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", "list", c, i, name] => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| format!("header line {line_no}: property before any element"))?;
                let count = Scalar::parse(c).ok_or_else(|| {
                    format!("header line {line_no}: unknown type `{}`", crate::shown(c))
                })?;
                let item = Scalar::parse(i).ok_or_else(|| {
                    format!("header line {line_no}: unknown type `{}`", crate::shown(i))
                })?;
                if matches!(count, Scalar::F32 | Scalar::F64) {
                    return Err(format!(
                        "header line {line_no}: a list count cannot be `{c}`"
                    ));
                }
                el.props.push(Property::List {
                    name: name.to_string(),
                    count,
                    item,
                });
            }
            ["property", t, name] => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| format!("header line {line_no}: property before any element"))?;
                let ty = Scalar::parse(t).ok_or_else(|| {
                    format!("header line {line_no}: unknown type `{}`", crate::shown(t))
                })?;
                el.props.push(Property::Scalar {
                    name: name.to_string(),
                    ty,
                });
            }
            ["end_header"] => break,
            _ => {
                return Err(format!(
                    "header line {line_no} is not understood: `{}`",
                    crate::shown(line)
                ))
            }
        }
    }
    let encoding = encoding.ok_or("the header has no `format` line")?;
    Ok(Header {
        encoding,
        elements,
        data_start: pos,
    })
}

/// Where each attribute lives in a vertex record.
#[derive(Default)]
struct VertexMap {
    xyz: [Option<usize>; 3],
    normal: [Option<usize>; 3],
    rgb: [Option<usize>; 3],
    alpha: Option<usize>,
    intensity: Option<usize>,
    radius: Option<usize>,
    /// Other scalar properties (kept as scalar fields, at most `MAX_FIELDS`).
    other: Vec<usize>,
}

impl VertexMap {
    fn new(el: &Element) -> Result<VertexMap, String> {
        let mut m = VertexMap::default();
        for (k, p) in el.props.iter().enumerate() {
            let slot = match p.name() {
                "x" => &mut m.xyz[0],
                "y" => &mut m.xyz[1],
                "z" => &mut m.xyz[2],
                "nx" | "normal_x" => &mut m.normal[0],
                "ny" | "normal_y" => &mut m.normal[1],
                "nz" | "normal_z" => &mut m.normal[2],
                "red" | "r" | "diffuse_red" => &mut m.rgb[0],
                "green" | "g" | "diffuse_green" => &mut m.rgb[1],
                "blue" | "b" | "diffuse_blue" => &mut m.rgb[2],
                "alpha" | "a" | "diffuse_alpha" => &mut m.alpha,
                "intensity" | "scalar_intensity" => &mut m.intensity,
                "radius" | "scalar_radius" => &mut m.radius,
                _ => {
                    if matches!(p, Property::Scalar { .. })
                        && m.other.len() < stipple_core::cloud::MAX_FIELDS
                    {
                        m.other.push(k);
                    }
                    continue;
                }
            };
            if matches!(p, Property::List { .. }) {
                return Err(format!(
                    "vertex property `{}` is a list, expected a number",
                    p.name()
                ));
            }
            if let Some(first) = *slot {
                return Err(format!(
                    "vertex property `{}` (property {k}) gives the same attribute as `{}` \
                     (property {first}): which one is meant is ambiguous",
                    crate::shown(p.name()),
                    crate::shown(el.props[first].name())
                ));
            }
            *slot = Some(k);
        }
        if m.xyz.iter().any(Option::is_none) {
            return Err("the vertex element lacks x, y or z".into());
        }
        Ok(m)
    }
}

fn scalar_ty(el: &Element, k: usize) -> Scalar {
    match &el.props[k] {
        Property::Scalar { ty, .. } => *ty,
        Property::List { item, .. } => *item,
    }
}

fn to_u8_colour(v: f64, ty: Scalar) -> u8 {
    match ty {
        Scalar::F32 | Scalar::F64 => (v * 255.0).round().clamp(0.0, 255.0) as u8,
        Scalar::U16 | Scalar::I16 => (v / 257.0).round().clamp(0.0, 255.0) as u8,
        _ => v.clamp(0.0, 255.0) as u8,
    }
}

/// Reads the values of one record into `vals` (one f64 per scalar property; lists are
/// skipped unless they are the face index list, which goes to `list`).
trait RecordSource {
    fn record(
        &mut self,
        el: &Element,
        vals: &mut [f64],
        list: Option<(usize, &mut Vec<u32>)>,
    ) -> Result<(), String>;
}

struct Binary<'a> {
    data: &'a [u8],
    pos: usize,
    big: bool,
}

impl Binary<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        if self.data.len() - self.pos < n {
            return Err("the data ends early (truncated file?)".into());
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
}

impl RecordSource for Binary<'_> {
    fn record(
        &mut self,
        el: &Element,
        vals: &mut [f64],
        mut list: Option<(usize, &mut Vec<u32>)>,
    ) -> Result<(), String> {
        let big = self.big;
        for (k, p) in el.props.iter().enumerate() {
            match p {
                Property::Scalar { ty, .. } => vals[k] = ty.read(self.take(ty.size())?, big),
                Property::List { count, item, .. } => {
                    let n = count.read(self.take(count.size())?, big);
                    if n < 0.0 {
                        return Err(format!("list `{}` has a negative length", p.name()));
                    }
                    let n = n as usize;
                    let bytes = self.take(n.checked_mul(item.size()).ok_or("list too long")?)?;
                    if let Some((lk, out)) = list.as_mut() {
                        if *lk == k {
                            out.clear();
                            for c in bytes.chunks_exact(item.size()) {
                                out.push(item.read(c, big) as u32);
                            }
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

/// ASCII records, one per line (as the format defines them): a line with more or fewer
/// values than its element's record is an error naming the line, so one stray value cannot
/// shift every later vertex.
struct Ascii<'a> {
    lines: std::str::Lines<'a>,
    /// 1-based number of the last line read (the header's lines included).
    line_no: usize,
}

impl<'a> Ascii<'a> {
    /// The next line that holds anything.
    fn next_line(&mut self, what: &str) -> Result<&'a str, String> {
        loop {
            let line = self.lines.next().ok_or_else(|| {
                format!("the data ends before all `{what}` records (truncated file?)")
            })?;
            self.line_no += 1;
            if !line.trim().is_empty() {
                return Ok(line);
            }
        }
    }
}

impl RecordSource for Ascii<'_> {
    fn record(
        &mut self,
        el: &Element,
        vals: &mut [f64],
        mut list: Option<(usize, &mut Vec<u32>)>,
    ) -> Result<(), String> {
        let line = self.next_line(&el.name)?;
        let at = self.line_no;
        let mut tokens = line.split_ascii_whitespace();
        let expected = || {
            el.props
                .iter()
                .map(|p| p.name())
                .collect::<Vec<_>>()
                .join(" ")
        };
        let number = |tokens: &mut std::str::SplitAsciiWhitespace| -> Result<f64, String> {
            let t = tokens.next().ok_or_else(|| {
                format!(
                    "line {at}: too few values for a `{}` record ({})",
                    el.name,
                    expected()
                )
            })?;
            t.parse::<f64>().map_err(|_| {
                format!(
                    "line {at}: `{}` in a `{}` record is not a number",
                    crate::shown(t),
                    el.name
                )
            })
        };
        for (k, p) in el.props.iter().enumerate() {
            match p {
                Property::Scalar { .. } => vals[k] = number(&mut tokens)?,
                Property::List { .. } => {
                    let n = number(&mut tokens)?;
                    if !(0.0..=1e6).contains(&n) || n.fract() != 0.0 {
                        return Err(format!(
                            "line {at}: list `{}` has an invalid length `{n}`",
                            p.name()
                        ));
                    }
                    let keep = matches!(list.as_ref(), Some((lk, _)) if *lk == k);
                    if let Some((_, out)) = list.as_mut() {
                        if keep {
                            out.clear();
                        }
                    }
                    for _ in 0..n as usize {
                        let v = number(&mut tokens)?;
                        if keep {
                            if let Some((_, out)) = list.as_mut() {
                                if v < 0.0 || v.fract() != 0.0 || v > u32::MAX as f64 {
                                    return Err(format!(
                                        "line {at}: face index `{v}` is not a valid index"
                                    ));
                                }
                                out.push(v as u32);
                            }
                        }
                    }
                }
            }
        }
        if let Some(t) = tokens.next() {
            return Err(format!(
                "line {at}: more values than a `{}` record has ({}); the first extra one is `{}`",
                el.name,
                expected(),
                crate::shown(t)
            ));
        }
        Ok(())
    }
}

/// At most this many characters per ASCII value (with its separator) are inflated from a
/// `.ply.gz`; the parser needs no more.
const MAX_ASCII_VALUE: u64 = 128;

/// The most bytes the records a header declares can take (ASCII: [`MAX_ASCII_VALUE`] per
/// value; binary lists at their count type's largest length, at most 1e6).
fn max_body_bytes(h: &Header) -> u64 {
    h.elements.iter().fold(0u64, |acc, el| {
        let record: u64 = match h.encoding {
            Encoding::Ascii => (el.props.len() as u64 + 1).saturating_mul(MAX_ASCII_VALUE),
            _ => el
                .props
                .iter()
                .map(|p| match p {
                    Property::Scalar { ty, .. } => ty.size() as u64,
                    Property::List { count, item, .. } => {
                        let longest = match count.size() {
                            1 => 255,
                            2 => 65_535,
                            _ => 1_000_000,
                        };
                        count.size() as u64 + longest * item.size() as u64
                    }
                })
                .sum(),
        };
        acc.saturating_add(el.count.saturating_mul(record))
    })
}

/// A PLY file's bytes; a gzip-compressed one is inflated only as far as its header's
/// records can reach (a small `.ply.gz` that inflates to gigabytes of padding stops there),
/// and refused when even that is more than the memory available.
fn read_ply_bytes(path: &Path) -> Result<Vec<u8>, IoError> {
    let raw = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    if !raw.starts_with(&[0x1f, 0x8b]) {
        return Ok(raw);
    }
    let corrupt = |e: std::io::Error| {
        IoError::invalid(path, format!("gzip data is corrupt or truncated: {e}"))
    };
    let mut dec = flate2::read::MultiGzDecoder::new(&raw[..]);
    let mut out: Vec<u8> = Vec::new();
    let mut limit: Option<u64> = None;
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = dec.read(&mut buf).map_err(corrupt)?;
        if n == 0 {
            break;
        }
        out.extend_from_slice(&buf[..n]);
        if limit.is_none() {
            match parse_header(&out) {
                Ok(h) => {
                    let body = max_body_bytes(&h);
                    if let Some(avail) = stipple_core::sys::available_memory() {
                        if body.min(raw.len() as u64 * 1032) > avail {
                            return Err(IoError::invalid(
                                path,
                                format!(
                                    "the header declares records of up to {} MiB once \
                                     inflated, more than the {} MiB of memory available",
                                    body >> 20,
                                    avail >> 20
                                ),
                            ));
                        }
                    }
                    limit = Some((h.data_start as u64).saturating_add(body));
                }
                // The header is not all there yet; past its maximum size the parser says why.
                Err(_) if out.len() < MAX_HEADER => {}
                Err(_) => limit = Some(out.len() as u64),
            }
        }
        if let Some(l) = limit {
            if out.len() as u64 >= l {
                out.truncate(l as usize);
                break;
            }
        }
    }
    Ok(out)
}

/// Reads a PLY file (gzip-compressed or not).
pub fn read_ply(path: &Path) -> Result<PointCloud, IoError> {
    let data = read_ply_bytes(path)?;
    parse_bytes(&data).map_err(|m| IoError::invalid(path, m))
}

/// Parses PLY bytes.
pub fn parse_ply(data: &[u8]) -> Result<PointCloud, crate::ParseError> {
    parse_bytes(data).map_err(crate::ParseError)
}

fn parse_bytes(data: &[u8]) -> Result<PointCloud, String> {
    let h = parse_header(data)?;
    let body = &data[h.data_start..];
    match h.encoding {
        Encoding::Ascii => {
            let text = std::str::from_utf8(body)
                .map_err(|_| "the ascii data section is not text".to_string())?;
            // Each ascii value takes at least two bytes (a digit and a separator).
            for el in &h.elements {
                let need = el.count.saturating_mul(el.props.len() as u64);
                if need > (body.len() as u64).div_ceil(2) {
                    return Err(format!(
                        "the header declares {} `{}` records but only {} bytes follow it: the file is truncated or the count is wrong",
                        el.count,
                        el.name,
                        body.len()
                    ));
                }
            }
            read_elements(
                &h,
                &mut Ascii {
                    lines: text.lines(),
                    line_no: data[..h.data_start].iter().filter(|&&b| b == b'\n').count(),
                },
                body.len(),
            )
        }
        Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
            let mut need: u64 = 0;
            for el in &h.elements {
                need = need.saturating_add(el.count.saturating_mul(el.min_record() as u64));
            }
            if need > body.len() as u64 {
                let el = &h.elements[0];
                return Err(format!(
                    "the header declares records needing at least {need} bytes (first element: {} `{}`), but only {} bytes follow it: the file is truncated or a count is wrong",
                    el.count,
                    el.name,
                    body.len()
                ));
            }
            let mut src = Binary {
                data: body,
                pos: 0,
                big: h.encoding == Encoding::BinaryBigEndian,
            };
            read_elements(&h, &mut src, body.len())
        }
    }
}

fn read_elements(
    h: &Header,
    src: &mut dyn RecordSource,
    body_len: usize,
) -> Result<PointCloud, String> {
    let mut world: Vec<DVec3> = Vec::new();
    let mut normals: Option<Vec<Vec3>> = None;
    let mut colors: Option<Vec<[u8; 3]>> = None;
    let mut alpha: Option<Vec<f32>> = None;
    let mut radius: Option<Vec<f32>> = None;
    let mut intensity_raw: Option<(Vec<f64>, Scalar)> = None;
    let mut fields: Vec<(usize, stipple_core::cloud::Field)> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    let mut seen_vertex = false;
    for el in &h.elements {
        // Counts were checked against the bytes present; cap again for list-bearing elements.
        let cap = (el.count as usize).min(body_len / el.min_record().max(1));
        let mut vals = vec![0.0f64; el.props.len()];
        if el.name == "vertex" && seen_vertex {
            return Err(
                "the file has a second `vertex` element; stipple reads files with one".into(),
            );
        }
        let is_vertex = el.name == "vertex";
        if el.props.is_empty() && !is_vertex {
            // Records of no bytes: nothing to read, however many the header declares (a
            // count of 4 000 000 000 was a loop of 4e9 empty reads; found by fuzzing).
            continue;
        }
        if is_vertex {
            seen_vertex = true;
            let m = VertexMap::new(el)?;
            stipple_core::sys::try_reserve(&mut world, cap, "the vertices' positions")?;
            if m.normal.iter().all(Option::is_some) {
                normals = Some(Vec::with_capacity(cap));
            }
            if m.rgb.iter().all(Option::is_some) {
                colors = Some(Vec::with_capacity(cap));
            }
            if m.alpha.is_some() {
                alpha = Some(Vec::with_capacity(cap));
            }
            if m.radius.is_some() {
                radius = Some(Vec::with_capacity(cap));
            }
            if let Some(k) = m.intensity {
                intensity_raw = Some((Vec::with_capacity(cap), scalar_ty(el, k)));
            }
            for &k in &m.other {
                fields.push((
                    k,
                    stipple_core::cloud::Field {
                        name: el.props[k].name().to_string(),
                        offset: f64::NAN,
                        values: Vec::with_capacity(cap),
                    },
                ));
            }
            let [x, y, z] = m.xyz.map(Option::unwrap);
            for i in 0..el.count {
                src.record(el, &mut vals, None)
                    .map_err(|e| format!("vertex {i}: {e}"))?;
                let p = DVec3::new(vals[x], vals[y], vals[z]);
                if let Some(problem) = stipple_core::cloud::coordinate_problem(p) {
                    return Err(format!("vertex {i} has {problem}"));
                }
                world.push(p);
                if let Some(n) = normals.as_mut() {
                    let [a, b, c] = m.normal.map(|k| vals[k.unwrap()] as f32);
                    let v = Vec3::new(a, b, c);
                    n.push(v.try_normalize().unwrap_or(Vec3::ZERO));
                }
                if let Some(c) = colors.as_mut() {
                    c.push(m.rgb.map(|k| {
                        let k = k.unwrap();
                        to_u8_colour(vals[k], scalar_ty(el, k))
                    }));
                }
                if let Some(a) = alpha.as_mut() {
                    let k = m.alpha.unwrap();
                    a.push(to_u8_colour(vals[k], scalar_ty(el, k)) as f32 / 255.0);
                }
                if let Some((v, _)) = intensity_raw.as_mut() {
                    v.push(vals[m.intensity.unwrap()]);
                }
                for (k, f) in &mut fields {
                    let v = vals[*k];
                    if f.offset.is_nan() && v.is_finite() {
                        f.offset = v;
                    }
                    f.values.push((v - f.offset) as f32);
                }
                if let Some(r) = radius.as_mut() {
                    let v = vals[m.radius.unwrap()] as f32;
                    if !(v.is_finite() && v > 0.0) {
                        return Err(format!(
                            "vertex {i} has radius {v}; a splat radius must be positive"
                        ));
                    }
                    r.push(v);
                }
            }
        } else if el.name == "face" {
            let lk = el
                .props
                .iter()
                .position(|p| matches!(p, Property::List { name, .. } if name == "vertex_indices" || name == "vertex_index"));
            faces.reserve(cap);
            let mut idx = Vec::new();
            for i in 0..el.count {
                idx.clear();
                src.record(el, &mut vals, lk.map(|k| (k, &mut idx)))
                    .map_err(|e| format!("face {i}: {e}"))?;
                for t in 1..idx.len().saturating_sub(1) {
                    faces.push([idx[0], idx[t], idx[t + 1]]);
                }
            }
        } else {
            for i in 0..el.count {
                src.record(el, &mut vals, None)
                    .map_err(|e| format!("`{}` record {i}: {e}", el.name))?;
            }
        }
    }
    if !seen_vertex {
        return Err("the file has no vertex element".into());
    }
    if world.is_empty() {
        return Err("the cloud has no points (vertex count 0)".into());
    }
    let mut cloud = PointCloud::from_world(&world);
    cloud.normals = normals.filter(|n| n.iter().any(|v| *v != Vec3::ZERO));
    cloud.colors = colors;
    cloud.opacity = alpha;
    cloud.radius = radius;
    cloud.fields = fields
        .into_iter()
        .map(|(_, mut f)| {
            if f.offset.is_nan() {
                f.offset = 0.0;
            }
            f
        })
        .collect();
    cloud.intensity = intensity_raw.map(|(v, ty)| {
        let max = v.iter().cloned().fold(0.0, f64::max);
        let scale = if matches!(ty, Scalar::F32 | Scalar::F64) && max <= 1.0 {
            65535.0
        } else if matches!(ty, Scalar::U8 | Scalar::I8) {
            257.0
        } else {
            1.0
        };
        v.iter()
            .map(|&x| (x * scale).round().clamp(0.0, 65535.0) as u16)
            .collect()
    });
    for (fi, f) in faces.iter().enumerate() {
        if let Some(&v) = f.iter().find(|&&v| v as usize >= world.len()) {
            return Err(format!(
                "face {fi} refers to vertex {v}, but there are {} vertices",
                world.len()
            ));
        }
    }
    cloud.faces = faces;
    Ok(cloud)
}

/// Writes a PLY file. Positions are written as doubles in world coordinates when the cloud's
/// origin is not zero (so LiDAR coordinates keep their precision), else as floats.
pub fn write_ply(path: &Path, cloud: &PointCloud, enc: Encoding) -> Result<(), IoError> {
    let file = std::fs::File::create(path).map_err(|e| IoError::io(path, e))?;
    let mut w = std::io::BufWriter::new(file);
    write_ply_to(&mut w, cloud, enc)
        .and_then(|_| w.flush())
        .map_err(|e| IoError::io(path, e))
}

pub fn write_ply_to(w: &mut impl Write, c: &PointCloud, enc: Encoding) -> std::io::Result<()> {
    let double = c.origin != DVec3::ZERO;
    let pt = if double { "double" } else { "float" };
    writeln!(w, "ply")?;
    writeln!(
        w,
        "format {} 1.0",
        match enc {
            Encoding::Ascii => "ascii",
            Encoding::BinaryLittleEndian => "binary_little_endian",
            Encoding::BinaryBigEndian => "binary_big_endian",
        }
    )?;
    writeln!(w, "comment written by stipple")?;
    writeln!(w, "element vertex {}", c.len())?;
    for a in ["x", "y", "z"] {
        writeln!(w, "property {pt} {a}")?;
    }
    if c.normals.is_some() {
        for a in ["nx", "ny", "nz"] {
            writeln!(w, "property float {a}")?;
        }
    }
    if c.colors.is_some() {
        for a in ["red", "green", "blue"] {
            writeln!(w, "property uchar {a}")?;
        }
    }
    if c.opacity.is_some() {
        writeln!(w, "property uchar alpha")?;
    }
    if c.intensity.is_some() {
        writeln!(w, "property ushort intensity")?;
    }
    if c.radius.is_some() {
        writeln!(w, "property float radius")?;
    }
    // Scalar fields: as doubles where their offset needs the precision (GPS times).
    let wide: Vec<bool> = c.fields.iter().map(|f| f.offset.abs() > 1e4).collect();
    for (f, &wide) in c.fields.iter().zip(&wide) {
        let name: String = f
            .name
            .chars()
            .map(|ch| if ch.is_ascii_graphic() { ch } else { '_' })
            .collect();
        writeln!(
            w,
            "property {} {name}",
            if wide { "double" } else { "float" }
        )?;
    }
    if !c.faces.is_empty() {
        writeln!(w, "element face {}", c.faces.len())?;
        writeln!(w, "property list uchar int vertex_indices")?;
    }
    writeln!(w, "end_header")?;
    let big = enc == Encoding::BinaryBigEndian;
    macro_rules! put {
        ($v:expr) => {
            if big {
                w.write_all(&$v.to_be_bytes())?
            } else {
                w.write_all(&$v.to_le_bytes())?
            }
        };
    }
    for i in 0..c.len() {
        let p = c.world(i);
        let n = c.normals.as_ref().map(|n| n[i]);
        let col = c.colors.as_ref().map(|v| v[i]);
        let a = c
            .opacity
            .as_ref()
            .map(|v| (v[i] * 255.0).round().clamp(0.0, 255.0) as u8);
        let it = c.intensity.as_ref().map(|v| v[i]);
        let rad = c.radius.as_ref().map(|v| v[i]);
        if enc == Encoding::Ascii {
            if double {
                write!(w, "{} {} {}", p.x, p.y, p.z)?;
            } else {
                let q = c.positions[i];
                write!(w, "{} {} {}", q.x, q.y, q.z)?;
            }
            if let Some(n) = n {
                write!(w, " {} {} {}", n.x, n.y, n.z)?;
            }
            if let Some(col) = col {
                write!(w, " {} {} {}", col[0], col[1], col[2])?;
            }
            if let Some(a) = a {
                write!(w, " {a}")?;
            }
            if let Some(it) = it {
                write!(w, " {it}")?;
            }
            if let Some(r) = rad {
                write!(w, " {r}")?;
            }
            for (f, &wide) in c.fields.iter().zip(&wide) {
                if wide {
                    write!(w, " {}", f.value(i))?;
                } else {
                    write!(w, " {}", f.value(i) as f32)?;
                }
            }
            writeln!(w)?;
        } else {
            if double {
                put!(p.x);
                put!(p.y);
                put!(p.z);
            } else {
                let q = c.positions[i];
                put!(q.x);
                put!(q.y);
                put!(q.z);
            }
            if let Some(n) = n {
                put!(n.x);
                put!(n.y);
                put!(n.z);
            }
            if let Some(col) = col {
                w.write_all(&col)?;
            }
            if let Some(a) = a {
                w.write_all(&[a])?;
            }
            if let Some(it) = it {
                put!(it);
            }
            if let Some(r) = rad {
                put!(r);
            }
            for (f, &wide) in c.fields.iter().zip(&wide) {
                if wide {
                    put!(f.value(i));
                } else {
                    put!(f.value(i) as f32);
                }
            }
        }
    }
    for f in &c.faces {
        if enc == Encoding::Ascii {
            writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
        } else {
            w.write_all(&[3u8])?;
            for v in f {
                put!(*v as i32);
            }
        }
    }
    Ok(())
}
