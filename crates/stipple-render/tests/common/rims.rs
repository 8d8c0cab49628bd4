//! The analytic reference of a transparent surface over the background, shared by the test
//! `peeled_layers_stay_closed_where_rays_graze_a_transparent_torus` and
//! `examples/peel_rims.rs` (which includes this file by path).

use glam::DVec3;
use stipple_core::{Camera, Projection};

/// The oblique view of `examples/nested-tori.toml` (eye (0, 2.2, 3) looking at the origin,
/// 40°), `size` pixels square: rays graze the tori's tubes near their silhouettes.
pub fn oblique(size: u32) -> Camera {
    Camera {
        eye: DVec3::new(0.0, 2.2, 3.0),
        target: DVec3::ZERO,
        up: DVec3::Y,
        projection: Projection::Perspective { fov_deg: 40.0 },
        width: size,
        height: size,
        near: 0.5,
        far: 10.0,
    }
}

/// Signed distance to a torus around the Y axis (major radius `major`, tube `tube`).
pub fn torus_sdf(major: f64, tube: f64) -> impl Fn(DVec3) -> f64 {
    move |q| (((q.x * q.x + q.z * q.z).sqrt() - major).powi(2) + q.y * q.y).sqrt() - tube
}

/// How many times the centre ray of each pixel of `cam` (perspective) crosses the surface
/// whose signed distance is `sdf`.
pub fn crossings(cam: &Camera, sdf: &dyn Fn(DVec3) -> f64) -> Vec<u8> {
    crossing_lists(cam, sdf)
        .iter()
        .map(|l| l.len() as u8)
        .collect()
}

/// Per pixel of `cam` (perspective), the distances along its centre ray at which it crosses
/// the surface whose signed distance is `sdf` (sphere tracing with a floor on the step).
pub fn crossing_lists(cam: &Camera, sdf: &dyn Fn(DVec3) -> f64) -> Vec<Vec<f64>> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let fwd = (cam.target - cam.eye).normalize();
    let right = fwd.cross(cam.up).normalize();
    let up = right.cross(fwd);
    let Projection::Perspective { fov_deg } = cam.projection else {
        panic!("perspective only")
    };
    let th = (fov_deg.to_radians() / 2.0).tan();
    let mut out = vec![Vec::new(); w * h];
    for j in 0..h {
        for i in 0..w {
            let x = ((i as f64 + 0.5) / w as f64 * 2.0 - 1.0) * th * w as f64 / h as f64;
            let y = (1.0 - (j as f64 + 0.5) / h as f64 * 2.0) * th;
            let d = (fwd + right * x + up * y).normalize();
            let (mut t, mut prev) = (cam.near, sdf(cam.eye + d * cam.near));
            while t < cam.far {
                t += prev.abs().max(0.0005);
                let v = sdf(cam.eye + d * t);
                if (v < 0.0) != (prev < 0.0) {
                    out[j * w + i].push(t);
                }
                prev = v;
            }
        }
    }
    out
}

/// How an image (`rgba`, `w` × `w`) compares with the analytic composite of a surface of
/// colour `colour` and opacity 0.5 over `background`: (1 − 0.5ⁿ) s + 0.5ⁿ b for a pixel's
/// n crossings (`counts`), pixels within 2 px of a change of n left out.
pub struct RimScore {
    /// Mean absolute error, 8-bit levels.
    pub error: f64,
    /// Share of pixels off by more than 12 levels.
    pub bad: f64,
    pub pixels: usize,
    /// The largest standard deviation of linear luminance over the pixels of one n.
    pub worst_sd: f64,
    /// Per pixel: true where it was scored and off by more than 12 levels.
    pub bad_map: Vec<bool>,
}

pub fn score(
    rgba: &[u8],
    w: usize,
    counts: &[u8],
    colour: [u8; 3],
    background: [u8; 3],
) -> RimScore {
    let lut = stipple_render::srgb::srgb_to_linear_table();
    let lin = |c: [u8; 3]| c.map(|v| lut[v as usize]);
    let (s, b) = (lin(colour), lin(background));
    let (mut err, mut total, mut bad) = (0.0, 0usize, 0usize);
    let mut lum: [Vec<f64>; 5] = Default::default();
    let mut bad_map = vec![false; w * w];
    for j in 2..w - 2 {
        for i in 2..w - 2 {
            let n = counts[j * w + i];
            let uniform = (j - 2..=j + 2).all(|y| (i - 2..=i + 2).all(|x| counts[y * w + x] == n));
            if !uniform || n == 0 {
                continue;
            }
            let t = 0.5f32.powi(n as i32);
            let want = std::array::from_fn::<f32, 3, _>(|ch| (1.0 - t) * s[ch] + t * b[ch])
                .map(stipple_render::srgb::linear_to_srgb8);
            let k = (j * w + i) * 4;
            let e = (0..3)
                .map(|ch| (rgba[k + ch] as f64 - want[ch] as f64).abs())
                .sum::<f64>()
                / 3.0;
            err += e;
            total += 1;
            if e > 12.0 {
                bad += 1;
                bad_map[j * w + i] = true;
            }
            let l: f32 = (0..3)
                .map(|ch| lut[rgba[k + ch] as usize] * [0.2126, 0.7152, 0.0722][ch])
                .sum();
            lum[n.min(4) as usize].push(l as f64);
        }
    }
    let worst_sd = lum
        .iter()
        .filter(|l| l.len() > 100)
        .map(|l| {
            let m = l.iter().sum::<f64>() / l.len() as f64;
            (l.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / l.len() as f64).sqrt()
        })
        .fold(0.0, f64::max);
    RimScore {
        error: err / total.max(1) as f64,
        bad: bad as f64 / total.max(1) as f64,
        pixels: total,
        worst_sd,
        bad_map,
    }
}

/// A surface for [`composite`]: its signed distance, colour and opacity.
pub type Surface<'a> = (&'a dyn Fn(DVec3) -> f64, [u8; 3], f32);

/// The analytic composite of several transparent surfaces (`surfaces`: signed distance,
/// colour, opacity) over `background`, per pixel of `cam`: the surfaces its centre ray
/// crosses, blended front to back. Returns, per pixel, the sequence of surfaces crossed
/// (base-4 digits, 1 + the surface's index; at most 3 surfaces) and the composite's 8-bit sRGB colour.
pub fn composite(
    cam: &Camera,
    surfaces: &[Surface<'_>],
    background: [u8; 3],
) -> (Vec<u64>, Vec<[u8; 3]>) {
    assert!(surfaces.len() <= 3);
    let lut = stipple_render::srgb::srgb_to_linear_table();
    let lin = |c: [u8; 3]| c.map(|v| lut[v as usize]);
    let lists: Vec<Vec<Vec<f64>>> = surfaces.iter().map(|s| crossing_lists(cam, s.0)).collect();
    let n = cam.width as usize * cam.height as usize;
    let (mut seq, mut want) = (vec![0u64; n], vec![[0u8; 3]; n]);
    for p in 0..n {
        let mut hits: Vec<(f64, usize)> = (0..surfaces.len())
            .flat_map(|k| lists[k][p].iter().map(move |&d| (d, k)))
            .collect();
        hits.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut acc, mut t) = ([0.0f32; 3], 1.0f32);
        for &(_, k) in &hits {
            seq[p] = seq[p] * 4 + k as u64 + 1;
            let (c, a) = (lin(surfaces[k].1), surfaces[k].2);
            for ch in 0..3 {
                acc[ch] += t * a * c[ch];
            }
            t *= 1.0 - a;
        }
        let b = lin(background);
        want[p] =
            std::array::from_fn(|ch| stipple_render::srgb::linear_to_srgb8(acc[ch] + t * b[ch]));
    }
    (seq, want)
}

/// How an image (`rgba`, `w` × `w`) compares with an analytic composite (`seq`, `want` from
/// [`composite`]), over the pixels whose 5×5 neighbourhood crosses the same surfaces (pixels
/// within 2 px of a silhouette, and the background, left out).
pub fn score_composite(rgba: &[u8], w: usize, seq: &[u64], want: &[[u8; 3]]) -> RimScore {
    let (mut err, mut total, mut bad) = (0.0, 0usize, 0usize);
    let mut bad_map = vec![false; w * w];
    for j in 2..w - 2 {
        for i in 2..w - 2 {
            let p = j * w + i;
            let s = seq[p];
            if s == 0 || !(j - 2..=j + 2).all(|y| (i - 2..=i + 2).all(|x| seq[y * w + x] == s)) {
                continue;
            }
            let e = (0..3)
                .map(|ch| (rgba[p * 4 + ch] as f64 - want[p][ch] as f64).abs())
                .sum::<f64>()
                / 3.0;
            err += e;
            total += 1;
            if e > 12.0 {
                bad += 1;
                bad_map[p] = true;
            }
        }
    }
    RimScore {
        error: err / total.max(1) as f64,
        bad: bad as f64 / total.max(1) as f64,
        pixels: total,
        worst_sd: 0.0,
        bad_map,
    }
}
