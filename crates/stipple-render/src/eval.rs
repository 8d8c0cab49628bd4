//! # Surface reconstruction error against a mesh (Pintus Fig. 4)
//!
//! How it works: the mesh is rasterized on the CPU into a reference depth image with the same
//! camera and pixel centres as the point renderer (view-axis depth, perspective-correct:
//! 1/z is interpolated in screen space), and a rendered depth image is compared with it pixel
//! by pixel. Errors are measured against the reference's depth range over covered pixels.

use crate::params::ViewParams;
use glam::Vec3;

/// The reference depth of a triangle mesh (positions in the cloud's local frame): view-axis
/// depth per pixel, +inf where no triangle is. Triangles reaching behind the near plane are
/// skipped (the evaluation frames the whole mesh, so none do).
pub fn mesh_depth(v: &ViewParams, positions: &[Vec3], faces: &[[u32; 3]]) -> Vec<f32> {
    let (w, h) = (v.width as usize, v.height as usize);
    let mut depth = vec![f32::INFINITY; w * h];
    let (eye, r, u, f) = (
        Vec3::from(v.eye),
        Vec3::from(v.right),
        Vec3::from(v.up),
        Vec3::from(v.forward),
    );
    let persp = v.perspective == 1;
    // Screen position in pixels (x right, y down) and view depth.
    let screen = |p: Vec3| -> (f64, f64, f64) {
        let d = p - eye;
        let (x, y, z) = (d.dot(r) as f64, d.dot(u) as f64, d.dot(f) as f64);
        let s = if persp { z } else { 1.0 };
        let nx = x * v.sx as f64 / s;
        let ny = y * v.sy as f64 / s;
        ((nx + 1.0) * 0.5 * w as f64, (1.0 - ny) * 0.5 * h as f64, z)
    };
    for tri in faces {
        let Some(p) = tri
            .iter()
            .map(|&i| positions.get(i as usize).copied())
            .collect::<Option<Vec<Vec3>>>()
        else {
            continue;
        };
        let s = [screen(p[0]), screen(p[1]), screen(p[2])];
        if s.iter().any(|q| q.2 <= v.near as f64) {
            continue;
        }
        let area = (s[1].0 - s[0].0) * (s[2].1 - s[0].1) - (s[2].0 - s[0].0) * (s[1].1 - s[0].1);
        if area.abs() < 1e-12 {
            continue;
        }
        let x0 = s
            .iter()
            .map(|q| q.0)
            .fold(f64::INFINITY, f64::min)
            .floor()
            .max(0.0) as usize;
        let x1 = (s
            .iter()
            .map(|q| q.0)
            .fold(f64::NEG_INFINITY, f64::max)
            .ceil() as i64)
            .clamp(0, w as i64) as usize;
        let y0 = s
            .iter()
            .map(|q| q.1)
            .fold(f64::INFINITY, f64::min)
            .floor()
            .max(0.0) as usize;
        let y1 = (s
            .iter()
            .map(|q| q.1)
            .fold(f64::NEG_INFINITY, f64::max)
            .ceil() as i64)
            .clamp(0, h as i64) as usize;
        for j in y0..y1 {
            let py = j as f64 + 0.5;
            for i in x0..x1 {
                let px = i as f64 + 0.5;
                let e = |a: usize, b: usize| {
                    (s[b].0 - s[a].0) * (py - s[a].1) - (s[b].1 - s[a].1) * (px - s[a].0)
                };
                let (b0, b1, b2) = (e(1, 2) / area, e(2, 0) / area, e(0, 1) / area);
                if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                    continue;
                }
                let z = if persp {
                    1.0 / (b0 / s[0].2 + b1 / s[1].2 + b2 / s[2].2)
                } else {
                    b0 * s[0].2 + b1 * s[1].2 + b2 * s[2].2
                };
                let k = j * w + i;
                if (z as f32) < depth[k] {
                    depth[k] = z as f32;
                }
            }
        }
    }
    depth
}

/// A rendered depth image against the reference.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthError {
    /// Pixels the reference covers.
    pub inside: usize,
    /// Of those, pixels left as background.
    pub holes: usize,
    /// Of those, pixels within `tolerance` of the reference.
    pub within: usize,
    /// Of those, pixels more than `behind_margin` behind the reference: a hidden surface
    /// showing through.
    pub behind: usize,
    /// Pixels the reference leaves empty but the render covers (grown silhouettes).
    pub leaks: usize,
    /// Reference depth range over covered pixels.
    pub range: f32,
    pub tolerance: f32,
    pub behind_margin: f32,
}

impl DepthError {
    pub fn within_share(&self) -> f64 {
        self.within as f64 / self.inside.max(1) as f64
    }
    pub fn behind_share(&self) -> f64 {
        self.behind as f64 / self.inside.max(1) as f64
    }
    pub fn leak_share(&self) -> f64 {
        self.leaks as f64 / self.inside.max(1) as f64
    }
    /// The share of covered pixels whose error exceeds the tolerance (Fig. 4's white pixels).
    pub fn above_share(&self) -> f64 {
        1.0 - self.within_share()
    }
}

/// The paper's tolerance: 0.5% of the depth range.
pub const TOLERANCE: f32 = 0.005;
/// "Behind the true surface": more than 2% of the depth range behind it.
pub const BEHIND: f32 = 0.02;

/// Compares a rendered depth image (`width` pixels wide) with the reference. `band` > 0
/// leaves out the contours, as Pintus Fig. 4 discusses them ("the error is concentrated along
/// object contours"): a pixel counts as inside only when no contour pixel of the reference
/// lies within `band` pixels (Chebyshev distance), and as a leak only when no covered one
/// does. A contour pixel is a covered pixel with a 4-neighbour that is empty or more than
/// [`BEHIND`] of the depth range away (a silhouette or a depth discontinuity).
pub fn compare(rendered: &[f32], reference: &[f32], width: usize, band: usize) -> DepthError {
    let (lo, hi) = reference
        .iter()
        .filter(|d| d.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &d| {
            (a.min(d), b.max(d))
        });
    let range = (hi - lo).max(f32::MIN_POSITIVE);
    let (tol, margin) = (TOLERANCE * range, BEHIND * range);
    let mut e = DepthError {
        inside: 0,
        holes: 0,
        within: 0,
        behind: 0,
        leaks: 0,
        range,
        tolerance: tol,
        behind_margin: margin,
    };
    let height = reference.len() / width.max(1);
    let (w, h) = (width as i64, height as i64);
    let at = |x: i64, y: i64| -> f32 {
        if x < 0 || y < 0 || x >= w || y >= h {
            f32::INFINITY
        } else {
            reference[(y * w + x) as usize]
        }
    };
    let contour: Vec<bool> = (0..reference.len())
        .map(|k| {
            let (x, y) = ((k % width) as i64, (k / width) as i64);
            let t = reference[k];
            t.is_finite()
                && [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|&(dx, dy)| {
                    let n = at(x + dx, y + dy);
                    !n.is_finite() || (n - t).abs() > margin
                })
        })
        .collect();
    // Whether any pixel within `band` satisfies `f`.
    let near = |k: usize, f: &dyn Fn(usize) -> bool| {
        let (x, y) = ((k % width) as i64, (k / width) as i64);
        let b = band as i64;
        (-b..=b).any(|dy| {
            (-b..=b).any(|dx| {
                let (nx, ny) = (x + dx, y + dy);
                nx >= 0 && ny >= 0 && nx < w && ny < h && f((ny * w + nx) as usize)
            })
        })
    };
    let all = |k: usize, covered: bool| {
        if covered {
            !near(k, &|n| contour[n])
        } else {
            !near(k, &|n| reference[n].is_finite())
        }
    };
    for (k, (&d, &t)) in rendered.iter().zip(reference).enumerate() {
        match (d.is_finite(), t.is_finite()) {
            (_, true) if band == 0 || all(k, true) => {
                e.inside += 1;
                if !d.is_finite() {
                    e.holes += 1;
                } else if (d - t).abs() <= tol {
                    e.within += 1;
                } else if d - t > margin {
                    e.behind += 1;
                }
            }
            (true, false) if band == 0 || all(k, false) => e.leaks += 1,
            _ => {}
        }
    }
    e
}

/// Fig. 4(e): |depth − reference| as grey, black = 0, white = at or above the tolerance;
/// holes inside the reference red, leaks outside it blue, background black. RGBA 8-bit.
pub fn error_image(rendered: &[f32], reference: &[f32], tolerance: f32) -> Vec<u8> {
    let mut out = Vec::with_capacity(rendered.len() * 4);
    for (&d, &t) in rendered.iter().zip(reference) {
        let px = match (d.is_finite(), t.is_finite()) {
            (true, true) => {
                let g = ((d - t).abs() / tolerance).min(1.0);
                let g = (g * 255.0 + 0.5) as u8;
                [g, g, g]
            }
            (false, true) => [220, 40, 40],
            (true, false) => [40, 90, 220],
            (false, false) => [0, 0, 0],
        };
        out.extend_from_slice(&[px[0], px[1], px[2], 255]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tilted_quad_rasterizes_to_its_plane() {
        // The plane z = 5 + 0.5 y over a quad covering the view.
        let v = ViewParams::axis_aligned(32, 32, true, 1.0);
        let p = |x: f32, y: f32| Vec3::new(x, y, 5.0 + 0.5 * y);
        let pos = vec![p(-9.0, -3.0), p(9.0, -3.0), p(9.0, 3.0), p(-9.0, 3.0)];
        let d = mesh_depth(&v, &pos, &[[0, 1, 2], [0, 2, 3]]);
        for j in 0..32 {
            for i in 0..32 {
                let (o, dir) = v.pixel_ray(i, j);
                // Ray o + t dir meets z = 5 + 0.5 y: t = 5 / (1 − 0.5 dir.y).
                let t = (5.0 + 0.5 * o.y - o.z) / (dir.z - 0.5 * dir.y);
                let got = d[(j * 32 + i) as usize];
                if got.is_finite() {
                    assert!((got - t).abs() < 1e-4 * t, "({i},{j}) {got} vs {t}");
                }
            }
        }
        assert!(d.iter().filter(|x| x.is_finite()).count() > 32 * 20);
    }

    #[test]
    fn compare_counts_each_kind_of_error() {
        let reference = [1.0, 2.0, 3.0, f32::INFINITY, 1.0];
        let rendered = [1.0, 2.001, 2.5, 4.0, f32::INFINITY];
        let e = compare(&rendered, &reference, 5, 0);
        assert_eq!((e.inside, e.within, e.holes, e.leaks), (4, 2, 1, 1));
        assert_eq!(e.behind, 0);
        let e = compare(&[1.0, 2.0, 3.5, f32::INFINITY, 1.0], &reference, 5, 0);
        assert_eq!(e.behind, 1);
        // A 5×5 patch: the image border is a contour, so with a band of 1 only the centre
        // is inside; an empty corner pixel covered by the render is a leak only at band 0.
        let mut t = vec![1.0f32; 25];
        t[0] = f32::INFINITY;
        let mut r = t.clone();
        r[0] = 1.0;
        let e = compare(&r, &t, 5, 1);
        assert_eq!((e.inside, e.within, e.leaks), (1, 1, 0));
        let e = compare(&r, &t, 5, 0);
        assert_eq!((e.inside, e.within, e.leaks), (24, 24, 1));
    }
}
