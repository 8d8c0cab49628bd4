//! Mesh readers: Wavefront OBJ and STL (binary and ASCII). A mesh is read as a point cloud
//! of its vertices with its triangles in [`PointCloud::faces`] (polygons fanned into
//! triangles), so that `render` draws the vertices and `convert` samples the faces
//! (`stipple_core::mesh`).
//!
//! OBJ: `v x y z [r g b]` (colours in 0..1, a common extension), `vn`, and `f` with
//! `v`, `v/vt`, `v//vn` or `v/vt/vn` references, negative ones counting back from the last
//! vertex; vertex normals are kept when every vertex gets one from the faces. Other
//! statements (`vt`, `o`, `g`, `s`, `usemtl`, `mtllib`, `l`, `p`) are ignored.
//! STL: binary (an 80-byte header, a triangle count and 50 bytes a triangle, checked against
//! the file's size before anything is allocated) or ASCII (`solid … facet … vertex x y z …`);
//! every triangle has its own three vertices (STL shares none).

use crate::IoError;
use glam::{DVec3, Vec3};
use std::path::Path;
use stipple_core::PointCloud;

/// Reads a Wavefront OBJ file.
pub fn read_obj(path: &Path) -> Result<PointCloud, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    let text = String::from_utf8_lossy(&bytes);
    parse_obj(&text).map_err(|e| IoError::invalid(path, e))
}

/// Quotes at most 40 characters of a token for an error message.
fn quoted(s: &str) -> String {
    let t: String = s.chars().take(40).flat_map(char::escape_default).collect();
    if s.chars().count() > 40 {
        format!("`{t}…`")
    } else {
        format!("`{t}`")
    }
}

/// Parses OBJ text (see the module documentation).
pub fn parse_obj(text: &str) -> Result<PointCloud, String> {
    let mut world: Vec<DVec3> = Vec::new();
    let mut colours: Vec<[u8; 3]> = Vec::new();
    let mut vn: Vec<Vec3> = Vec::new();
    let mut normal_of: Vec<Option<Vec3>> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let ln = ln + 1;
        let line = line.split('#').next().unwrap_or("");
        let mut it = line.split_whitespace();
        let Some(kw) = it.next() else { continue };
        let num = |t: Option<&str>| -> Result<f64, String> {
            let t = t.ok_or_else(|| format!("line {ln}: `{kw}` has too few values"))?;
            let v: f64 = t
                .parse()
                .map_err(|_| format!("line {ln}: {} is not a number", quoted(t)))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(format!("line {ln}: {} is not finite", quoted(t)))
            }
        };
        match kw {
            "v" => {
                let p = DVec3::new(num(it.next())?, num(it.next())?, num(it.next())?);
                let rest: Vec<&str> = it.collect();
                if rest.len() >= 3 {
                    let c: Result<Vec<f64>, String> =
                        rest[..3].iter().map(|t| num(Some(t))).collect();
                    let c = c?;
                    colours.push(std::array::from_fn(|i| {
                        (c[i].clamp(0.0, 1.0) * 255.0).round() as u8
                    }));
                } else if !colours.is_empty() {
                    return Err(format!(
                        "line {ln}: a vertex without a colour after vertices with colours"
                    ));
                }
                if !colours.is_empty() && colours.len() != world.len() + 1 {
                    return Err(format!(
                        "line {ln}: a vertex with a colour after vertices without colours"
                    ));
                }
                world.push(p);
                normal_of.push(None);
            }
            "vn" => {
                let n = DVec3::new(num(it.next())?, num(it.next())?, num(it.next())?);
                vn.push(n.as_vec3());
            }
            "f" => {
                let mut idx: Vec<u32> = Vec::new();
                for t in it {
                    let mut parts = t.split('/');
                    let v = parts.next().unwrap_or("");
                    let n = parts.nth(1);
                    let resolve = |s: &str, len: usize, what: &str| -> Result<usize, String> {
                        let k: i64 = s.parse().map_err(|_| {
                            format!("line {ln}: {} is not a {what} index", quoted(t))
                        })?;
                        let i = if k > 0 {
                            k - 1
                        } else if k < 0 {
                            len as i64 + k
                        } else {
                            -1
                        };
                        if i < 0 || i as usize >= len {
                            return Err(format!(
                                "line {ln}: {what} {k} does not exist ({len} so far)"
                            ));
                        }
                        Ok(i as usize)
                    };
                    let vi = resolve(v, world.len(), "vertex")?;
                    if let Some(n) = n.filter(|n| !n.is_empty()) {
                        let ni = resolve(n, vn.len(), "normal")?;
                        normal_of[vi] = Some(vn[ni]);
                    }
                    idx.push(vi as u32);
                }
                if idx.len() < 3 {
                    return Err(format!("line {ln}: a face needs at least 3 vertices"));
                }
                for k in 1..idx.len() - 1 {
                    faces.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if world.is_empty() {
        return Err("no vertices (`v` lines)".into());
    }
    let mut cloud = PointCloud::from_world(&world);
    if !colours.is_empty() {
        cloud.colors = Some(colours);
    }
    if normal_of.iter().all(Option::is_some) && !vn.is_empty() {
        cloud.normals = Some(
            normal_of
                .into_iter()
                .map(|n| n.expect("checked").normalize_or_zero())
                .collect(),
        );
    }
    cloud.faces = faces;
    Ok(cloud)
}

/// Reads a binary or ASCII STL file.
pub fn read_stl(path: &Path) -> Result<PointCloud, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    parse_stl(&bytes).map_err(|e| IoError::invalid(path, e))
}

/// Parses STL bytes: binary when the triangle count after the 80-byte header matches the
/// size, else ASCII when the file starts with `solid`.
pub fn parse_stl(bytes: &[u8]) -> Result<PointCloud, String> {
    let binary_count = (bytes.len() >= 84)
        .then(|| u32::from_le_bytes(bytes[80..84].try_into().expect("4 bytes")) as u64);
    let ascii = bytes.trim_ascii_start().starts_with(b"solid");
    let world: Vec<DVec3> = match binary_count {
        Some(n) if 84 + 50 * n == bytes.len() as u64 => {
            let mut w = Vec::with_capacity(3 * n as usize);
            for t in bytes[84..].chunks_exact(50) {
                for v in 0..3 {
                    let f = |k: usize| {
                        let at = 12 + 12 * v + 4 * k;
                        f32::from_le_bytes(t[at..at + 4].try_into().expect("4 bytes")) as f64
                    };
                    let p = DVec3::new(f(0), f(1), f(2));
                    if !p.is_finite() {
                        return Err(format!("triangle {}: a vertex is not finite", w.len() / 3));
                    }
                    w.push(p);
                }
            }
            w
        }
        _ if ascii => parse_stl_ascii(&String::from_utf8_lossy(bytes))?,
        Some(n) => {
            return Err(format!(
                "binary STL header says {n} triangles ({} bytes), but the file has {} bytes \
                 (truncated or not an STL file)",
                84 + 50 * n,
                bytes.len()
            ))
        }
        None => return Err("too short for an STL file".into()),
    };
    if world.is_empty() {
        return Err("no triangles".into());
    }
    let mut cloud = PointCloud::from_world(&world);
    cloud.faces = (0..world.len() as u32 / 3)
        .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
        .collect();
    Ok(cloud)
}

fn parse_stl_ascii(text: &str) -> Result<Vec<DVec3>, String> {
    let mut w = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        if it.next() != Some("vertex") {
            continue;
        }
        let mut c = [0.0; 3];
        for x in &mut c {
            let t = it
                .next()
                .ok_or_else(|| format!("line {}: a vertex needs x y z", ln + 1))?;
            *x = t
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("line {}: {} is not a finite number", ln + 1, quoted(t)))?;
        }
        w.push(DVec3::from(c));
    }
    if w.len() % 3 != 0 {
        return Err(format!(
            "{} vertices: not a whole number of triangles",
            w.len()
        ));
    }
    Ok(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obj_faces_normals_colours_and_negative_indices() {
        let c = parse_obj(
            "# a quad and a triangle\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 1 1 1\n\
             vn 0 0 2\nf 1//1 2//1 3//1 4//1\nf -4/7/1 -2/3/1 -1//1\ng ignored\nusemtl x\n",
        )
        .unwrap();
        assert_eq!(c.len(), 4);
        assert_eq!(c.faces, vec![[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
        assert_eq!(c.colors.as_ref().unwrap()[1], [0, 255, 0]);
        assert!(c.normals.as_ref().unwrap().iter().all(|n| *n == Vec3::Z));
        assert!((c.world(2) - DVec3::new(1.0, 1.0, 0.0)).length() < 1e-9);
    }

    #[test]
    fn bad_obj_is_an_error_naming_the_line() {
        for (text, want) in [
            (
                "v 0 0 0\nv 1 0 0\nf 1 2 3\n",
                "line 3: vertex 3 does not exist",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n",
                "vertex 0 does not exist",
            ),
            ("v 0 0 nan\n", "line 1: `nan` is not finite"),
            ("v 0 0\n", "too few values"),
            ("v 0 0 0\nf 1 1\n", "at least 3 vertices"),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//4 2 3\n",
                "normal 4 does not exist",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 x 3\n",
                "`x` is not a vertex index",
            ),
            ("# nothing\n", "no vertices"),
        ] {
            let e = parse_obj(text).err().unwrap_or_default();
            assert!(e.contains(want), "{text:?}: {e}");
        }
    }

    fn binary_stl(tris: &[[[f32; 3]; 3]], claimed: u32) -> Vec<u8> {
        let mut b = vec![0u8; 80];
        b.extend_from_slice(&claimed.to_le_bytes());
        for t in tris {
            b.extend_from_slice(&[0u8; 12]);
            for v in t {
                for x in v {
                    b.extend_from_slice(&x.to_le_bytes());
                }
            }
            b.extend_from_slice(&[0u8; 2]);
        }
        b
    }

    #[test]
    fn stl_binary_and_ascii() {
        let t = [[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]; 2];
        let c = parse_stl(&binary_stl(&t, 2)).unwrap();
        assert_eq!((c.len(), c.faces.len()), (6, 2));
        assert_eq!(c.faces[1], [3, 4, 5]);
        // A binary file whose header starts with "solid" is still binary.
        let mut b = binary_stl(&t, 2);
        b[..5].copy_from_slice(b"solid");
        assert_eq!(parse_stl(&b).unwrap().faces.len(), 2);
        let a = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n\
                 vertex 0 1 0\nendloop\nendfacet\nendsolid x\n";
        let c = parse_stl(a.as_bytes()).unwrap();
        assert_eq!((c.len(), c.faces.len()), (3, 1));
    }

    #[test]
    fn bad_stl_is_an_error_without_allocating_what_the_header_claims() {
        let t = [[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]];
        // The header claims 4 billion triangles: refused from the file's size.
        let e = parse_stl(&binary_stl(&t, u32::MAX)).err().unwrap();
        assert!(e.contains("truncated"), "{e}");
        let e = parse_stl(b"solid\nvertex 0 0 0\nvertex 1 0\n")
            .err()
            .unwrap();
        assert!(e.contains("line 3"), "{e}");
        let e = parse_stl(b"solid\nvertex 0 0 0\nvertex 1 0 0\n")
            .err()
            .unwrap();
        assert!(e.contains("whole number of triangles"), "{e}");
        let nan = [[[f32::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]];
        assert!(parse_stl(&binary_stl(&nan, 1)).is_err());
        assert!(parse_stl(b"abc").is_err());
        assert!(parse_stl(&binary_stl(&[], 0)).is_err());
    }
}
