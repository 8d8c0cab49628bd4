//! The analytic reference of a transparent surface over the background, shared by the test
//! `peeled_layers_stay_closed_where_rays_graze_a_transparent_torus` and
//! `examples/peel_rims.rs` (which includes this file by path).

use glam::DVec3;
use stipple_core::{Camera, Projection};

/// Signed distance to a torus around the Y axis (major radius `major`, tube `tube`).
pub fn torus_sdf(major: f64, tube: f64) -> impl Fn(DVec3) -> f64 {
    move |q| (((q.x * q.x + q.z * q.z).sqrt() - major).powi(2) + q.y * q.y).sqrt() - tube
}

/// How many times the centre ray of each pixel of `cam` (perspective) crosses the surface
/// whose signed distance is `sdf` (sphere tracing with a floor on the step).
pub fn crossings(cam: &Camera, sdf: &dyn Fn(DVec3) -> f64) -> Vec<u8> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let fwd = (cam.target - cam.eye).normalize();
    let right = fwd.cross(cam.up).normalize();
    let up = right.cross(fwd);
    let Projection::Perspective { fov_deg } = cam.projection else {
        panic!("perspective only")
    };
    let th = (fov_deg.to_radians() / 2.0).tan();
    let mut out = vec![0u8; w * h];
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
                    out[j * w + i] += 1;
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
