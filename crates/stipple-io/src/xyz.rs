//! Plain-text points: one point per line, values separated by spaces, tabs, commas or
//! semicolons. Lines starting with `#` or `//` are comments.
//!
//! Columns: `x y z`, then optionally `r g b` and `nx ny nz`. A first line with words names the
//! columns (x, y, z, r/red, g/green, b/blue, nx, ny, nz, intensity/i); without one:
//! * 3 columns: x y z
//! * 4 columns: x y z intensity
//! * 6 columns: x y z r g b, or x y z nx ny nz when every triple has unit length
//! * 7 columns: x y z intensity r g b (the PTS layout)
//! * 9 columns: x y z r g b nx ny nz
//!
//! Colours are 0–255, or 0–1 when no value exceeds 1. A lone integer on the first line (the
//! PTS point count) is skipped.

use crate::IoError;
use glam::{DVec3, Vec3};
use std::io::Write;
use std::path::Path;
use stipple_core::PointCloud;

#[derive(Clone, Copy, PartialEq, Debug)]
enum Col {
    X,
    Y,
    Z,
    R,
    G,
    B,
    Nx,
    Ny,
    Nz,
    Intensity,
    Skip,
}

fn column_from_name(s: &str) -> Col {
    match s.to_ascii_lowercase().trim_matches('"') {
        "x" | "//x" => Col::X,
        "y" => Col::Y,
        "z" => Col::Z,
        "r" | "red" => Col::R,
        "g" | "green" => Col::G,
        "b" | "blue" => Col::B,
        "nx" | "normal_x" => Col::Nx,
        "ny" | "normal_y" => Col::Ny,
        "nz" | "normal_z" => Col::Nz,
        "i" | "intensity" => Col::Intensity,
        _ => Col::Skip,
    }
}

fn split(line: &str) -> impl Iterator<Item = &str> {
    line.split(|c: char| c == ',' || c == ';' || c.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// Reads a text point file.
pub fn read_xyz(path: &Path) -> Result<PointCloud, IoError> {
    let data = crate::read_maybe_gz(path)?;
    let text = std::str::from_utf8(&data).map_err(|e| {
        IoError::invalid(
            path,
            format!(
                "not a text file (invalid UTF-8 at byte {})",
                e.valid_up_to()
            ),
        )
    })?;
    parse_text(text).map_err(|m| IoError::invalid(path, m))
}

/// The longest line a text point file may have (a point with dozens of attributes takes a
/// few hundred bytes); longer lines are refused before they are split into tokens.
pub const MAX_LINE: usize = 64 << 10;

/// Parses the text of a point file (see [`read_xyz`] for the layouts understood).
pub fn parse_xyz(text: &str) -> Result<PointCloud, crate::ParseError> {
    parse_text(text).map_err(crate::ParseError)
}

fn parse_text(text: &str) -> Result<PointCloud, String> {
    let mut names: Option<Vec<Col>> = None;
    let mut ncols = 0usize;
    let mut rows: Vec<f64> = Vec::new();
    let mut first_content = true;
    for (ln, line) in text.lines().enumerate() {
        let line_no = ln + 1;
        if line.len() > MAX_LINE {
            return Err(format!(
                "line {line_no} is {} bytes long, more than a point's line can be ({MAX_LINE}): \
                 this is not a text point file",
                line.len()
            ));
        }
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') || t.starts_with("//") && !t.starts_with("//x") {
            continue;
        }
        let toks: Vec<&str> = split(t).collect();
        let nums: Result<Vec<f64>, _> = toks.iter().map(|s| s.parse::<f64>()).collect();
        match nums {
            Ok(v) => {
                if first_content && v.len() == 1 {
                    // PTS point count.
                    first_content = false;
                    continue;
                }
                first_content = false;
                if ncols == 0 {
                    if v.len() < 3 {
                        return Err(format!(
                            "line {line_no}: expected at least 3 numbers (x y z), found {}",
                            v.len()
                        ));
                    }
                    ncols = v.len();
                    if let Some(n) = &names {
                        if n.len() != ncols {
                            return Err(format!(
                                "line {line_no}: {ncols} values, but the header names {} columns",
                                n.len()
                            ));
                        }
                    }
                } else if v.len() != ncols {
                    return Err(format!(
                        "line {line_no}: {} values, but earlier lines have {ncols}",
                        v.len()
                    ));
                }
                if let Some(bad) = v.iter().position(|x| !x.is_finite()) {
                    return Err(format!(
                        "line {line_no}: value {} is not finite (`{}`)",
                        bad + 1,
                        crate::shown(toks[bad])
                    ));
                }
                rows.extend_from_slice(&v);
            }
            Err(_) => {
                if first_content && names.is_none() {
                    first_content = false;
                    let cols: Vec<Col> = toks.iter().map(|s| column_from_name(s)).collect();
                    if ![Col::X, Col::Y, Col::Z].iter().all(|c| cols.contains(c)) {
                        return Err(format!(
                            "line {line_no}: the header line does not name x, y and z columns"
                        ));
                    }
                    names = Some(cols);
                    continue;
                }
                let bad = toks.iter().find(|s| s.parse::<f64>().is_err()).unwrap();
                return Err(format!(
                    "line {line_no}: `{}` is not a number",
                    crate::shown(bad)
                ));
            }
        }
    }
    if ncols == 0 {
        return Err("the cloud has no points (no data lines)".into());
    }
    let n = rows.len() / ncols;
    let at = |i: usize, c: usize| rows[i * ncols + c];
    let cols: Vec<Col> = match names {
        Some(n) => n,
        None => {
            use Col::*;
            match ncols {
                3 => vec![X, Y, Z],
                4 => vec![X, Y, Z, Intensity],
                6 => {
                    let unit = (0..n).all(|i| {
                        let l = (at(i, 3).powi(2) + at(i, 4).powi(2) + at(i, 5).powi(2)).sqrt();
                        (l - 1.0).abs() < 1e-2
                    });
                    if unit {
                        vec![X, Y, Z, Nx, Ny, Nz]
                    } else {
                        vec![X, Y, Z, R, G, B]
                    }
                }
                7 => vec![X, Y, Z, Intensity, R, G, B],
                9 => vec![X, Y, Z, R, G, B, Nx, Ny, Nz],
                k => {
                    return Err(format!(
                        "{k} columns without a header line: expected 3 (x y z), 4 (+ intensity), 6 (+ r g b or normals), 7 (PTS) or 9 (+ r g b + normals); add a header line naming the columns"
                    ))
                }
            }
        }
    };
    let find = |c: Col| cols.iter().position(|&x| x == c);
    let (x, y, z) = (
        find(Col::X).unwrap(),
        find(Col::Y).unwrap(),
        find(Col::Z).unwrap(),
    );
    let world: Vec<DVec3> = (0..n)
        .map(|i| DVec3::new(at(i, x), at(i, y), at(i, z)))
        .collect();
    if let Some((i, problem)) = world
        .iter()
        .enumerate()
        .find_map(|(i, &p)| stipple_core::cloud::coordinate_problem(p).map(|m| (i, m)))
    {
        return Err(format!("point {i} has {problem}"));
    }
    let mut cloud = PointCloud::from_world(&world);
    if let (Some(r), Some(g), Some(b)) = (find(Col::R), find(Col::G), find(Col::B)) {
        let max = (0..n)
            .map(|i| at(i, r).max(at(i, g)).max(at(i, b)))
            .fold(0.0, f64::max);
        let scale = if max <= 1.0 { 255.0 } else { 1.0 };
        cloud.colors = Some(
            (0..n)
                .map(|i| [r, g, b].map(|c| (at(i, c) * scale).round().clamp(0.0, 255.0) as u8))
                .collect(),
        );
    }
    if let (Some(a), Some(b), Some(c)) = (find(Col::Nx), find(Col::Ny), find(Col::Nz)) {
        cloud.normals = Some(
            (0..n)
                .map(|i| {
                    Vec3::new(at(i, a) as f32, at(i, b) as f32, at(i, c) as f32)
                        .try_normalize()
                        .unwrap_or(Vec3::ZERO)
                })
                .collect(),
        );
    }
    if let Some(k) = find(Col::Intensity) {
        cloud.intensity = Some(
            (0..n)
                .map(|i| at(i, k).round().clamp(0.0, 65535.0) as u16)
                .collect(),
        );
    }
    Ok(cloud)
}

/// Writes `x y z [r g b] [nx ny nz]` with a header line naming the columns.
pub fn write_xyz(path: &Path, c: &PointCloud) -> Result<(), IoError> {
    let f = std::fs::File::create(path).map_err(|e| IoError::io(path, e))?;
    let mut w = std::io::BufWriter::new(f);
    let res = (|| -> std::io::Result<()> {
        write!(w, "x y z")?;
        if c.colors.is_some() {
            write!(w, " r g b")?;
        }
        if c.normals.is_some() {
            write!(w, " nx ny nz")?;
        }
        writeln!(w)?;
        for i in 0..c.len() {
            let p = c.world(i);
            write!(w, "{} {} {}", p.x, p.y, p.z)?;
            if let Some(col) = &c.colors {
                write!(w, " {} {} {}", col[i][0], col[i][1], col[i][2])?;
            }
            if let Some(n) = &c.normals {
                write!(w, " {} {} {}", n[i].x, n[i].y, n[i].z)?;
            }
            writeln!(w)?;
        }
        w.flush()
    })();
    res.map_err(|e| IoError::io(path, e))
}
