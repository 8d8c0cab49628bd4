//! Depth quantised in steps wider than the points' spacing (a depth camera's), smoothed
//! across the steps before normals are estimated.
//!
//! A structured-light or stereo depth camera measures disparity in whole (or sub-) pixels,
//! so its depths take few values: the PCL office capture (`office1.pcd`, a Kinect) has 125
//! distinct depths for 254 456 points, 1 cm apart at 1 m and 7.5 cm at 5 m, where its points
//! lie 2 mm and 9 mm apart. A surface seen at an angle becomes a staircase of flat terraces
//! facing the camera. Every k-nearest neighbourhood lies on one terrace (the next one is
//! a step away, further than the sixteenth neighbour on its own), so its normal faces the
//! camera, and along each step's edge the plane through two terraces stands steeply
//! tilted: oblique walls and floors were lit as if they faced the camera, crossed by dark
//! streaks.
//!
//! [`dequantise`] finds such depths (few distinct values, in a ladder of steps that grow
//! smoothly with depth, each step wider than the points' spacing) and moves each point
//! along its ray onto a smooth surface. Neighbours are taken on the image plane (the rays'
//! directions), where a terrace's neighbours include the next terraces' points; a neighbour
//! whose depth is several steps from the point's lies on another surface (an object before
//! a wall) and is left out. A plane (depth as a linear function on the image plane) is
//! fitted to each point's neighbours by least squares and the point moved to it; a few
//! rounds, each on the depths the last left, widen the window over several terraces. A
//! staircase relaxes into the slope it was sampled from, and a flat wall facing the camera
//! stays where it was. Measured on the office: its oblique walls show their cupboards'
//! doors and handles instead of streaks, and its floor is even (`BENCHMARKS.md`).

use super::{neighbours, NormalError};
use glam::Vec3;
use rayon::prelude::*;

/// Depths are quantised when they take at most one distinct value per this many points.
pub const POINTS_PER_LEVEL: usize = 64;
/// ... and a point's step is wider than this many times its distance to its nearest
/// neighbour across the image (the median over points).
pub const STEP_OVER_SPACING: f32 = 1.5;
/// At least this many distinct depths ...
pub const MIN_LEVELS: usize = 16;
/// ... whose steps follow a ladder (`Ladder`): this share of the gaps between neighbouring
/// depths lie within [`EVEN_STEPS`] of it (a depth camera's grow with the square of the
/// depth; a few surfaces facing the camera at chosen depths are no ladder).
const EVEN_SHARE: f32 = 0.75;
/// Gaps within this factor of the ladder's step follow it.
const EVEN_STEPS: f32 = 1.25;
/// Neighbours on the image plane (the search's most): 256 bytes a point, so above
/// [`LARGE`] points (a depth camera's frame holds at most a few million) ...
const PLANE_K: usize = 64;
/// ... this many.
const PLANE_K_LARGE: usize = 24;
/// See [`PLANE_K`].
const LARGE: usize = 2_000_000;
/// Rounds of fitting: each fits a plane to the depths the last one left, so the window
/// widens with every round (the office's walls, seen at 45°, step every 6 points). At 8 the
/// office's back wall kept waves of the camera's noise, lit as ripples; 16 smooths them
/// (its estimate 0.82 → 1.00 s).
pub const ROUNDS: usize = 16;
/// A neighbour whose stored depth differs from the point's by more than this many of the
/// point's steps lies on another surface (an object before a wall). At 1.5 a floor seen
/// at a grazing angle, whose rows of points lie two steps apart, kept bright lines.
const SAME_SURFACE: f32 = 3.0;
/// No point moves further along its ray than this many of its steps. Clamped within its
/// own step (half a step, where the rounding put the true depth), the noise of a depth
/// camera, as wide as its steps, pinned points off the smoothed surface: specks.
pub const MAX_MOVE: f32 = 3.0;

/// Where a cloud's depths were quantised, and the smoothed positions.
#[derive(Clone, Debug)]
pub struct Dequantised {
    /// Each point moved along its ray to the smoothed depth.
    pub positions: Vec<Vec3>,
    /// How many distinct depths the cloud had.
    pub levels: usize,
    /// The steps at the nearest and the farthest point (the ladder's, see the module
    /// documentation).
    pub steps: (f32, f32),
}

/// A depth camera's steps as a function of depth: c · d^p, p = 0 (depth in fixed steps,
/// as a time-of-flight camera's millimetres), 1, or 2 (disparity in fixed steps, as a
/// structured-light or stereo camera's).
#[derive(Clone, Copy, Debug)]
struct Ladder {
    c: f32,
    p: i32,
}

impl Ladder {
    /// The ladder most gaps between neighbouring `levels` follow within [`EVEN_STEPS`],
    /// if [`EVEN_SHARE`] of them do. (Depths no surface lies at leave a wider gap: the
    /// levels' own gaps overstate an isolated surface's step.)
    fn of(levels: &[f32]) -> Option<Ladder> {
        let gaps: Vec<(f32, f32)> = levels
            .windows(2)
            .map(|w| (0.5 * (w[0] + w[1]), w[1] - w[0]))
            .collect();
        let mut best: Option<(usize, Ladder)> = None;
        for p in 0..=2 {
            let mut r: Vec<f32> = gaps.iter().map(|&(d, g)| g / d.powi(p)).collect();
            let mid = r.len() / 2;
            let c = *r.select_nth_unstable_by(mid, f32::total_cmp).1;
            let even = r
                .iter()
                .filter(|&&x| x <= EVEN_STEPS * c && c <= EVEN_STEPS * x)
                .count();
            if best.is_none_or(|(e, _)| even > e) {
                best = Some((even, Ladder { c, p }));
            }
        }
        let (even, ladder) = best?;
        (even as f32 >= EVEN_SHARE * gaps.len() as f32 && ladder.c > 0.0).then_some(ladder)
    }

    fn step(self, d: f32) -> f32 {
        self.c * d.powi(self.p)
    }
}

/// The distinct values of sorted `d` (values within rounding of each other are one).
fn levels_of(sorted: &[f32]) -> Vec<f32> {
    let mut out: Vec<f32> = Vec::new();
    for &x in sorted {
        match out.last() {
            Some(&l) if x - l <= 1e-5 * l.abs() + 1e-7 => {}
            _ => out.push(x),
        }
    }
    out
}

/// Smooths depths quantised along the `forward` axis of a sensor at `eye` (positions and
/// eye in the cloud's frame; forward towards the points, as readers leave a sensor:
/// `PointCloud::face_sensor_to_points`); None where they are not quantised in steps wider than the
/// points' spacing (see the module documentation). Errors only where the neighbour search
/// does (non-finite positions).
pub fn dequantise(
    positions: &[Vec3],
    eye: Vec3,
    forward: Vec3,
) -> Result<Option<Dequantised>, NormalError> {
    let n = positions.len();
    let Some(f) = forward.try_normalize() else {
        return Ok(None);
    };
    if n < 4 * POINTS_PER_LEVEL {
        return Ok(None);
    }
    let depth: Vec<f32> = positions.par_iter().map(|p| (*p - eye).dot(f)).collect();
    // A depth camera sees everything in front of it.
    if depth.iter().any(|d| d.is_nan() || *d <= 0.0) {
        return Ok(None);
    }
    let mut sorted = depth.clone();
    sorted.par_sort_unstable_by(f32::total_cmp);
    let levels = levels_of(&sorted);
    if levels.len() < MIN_LEVELS || levels.len() * POINTS_PER_LEVEL > n {
        return Ok(None);
    }
    let Some(ladder) = Ladder::of(&levels) else {
        return Ok(None);
    };
    let step: Vec<f32> = depth.par_iter().map(|&d| ladder.step(d)).collect();
    // The image plane: each point's ray direction, as (x/d, y/d) in a frame about forward.
    let (a, b) = super::tangent_frame(f);
    let plane: Vec<Vec3> = positions
        .par_iter()
        .zip(&depth)
        .map(|(p, &d)| {
            let r = *p - eye;
            Vec3::new(r.dot(a) / d, r.dot(b) / d, 0.0)
        })
        .collect();
    let nb = neighbours(&plane, if n <= LARGE { PLANE_K } else { PLANE_K_LARGE })?;
    // Steps against the spacing across the image (the nearest neighbour's, at the depth).
    let mut ratio: Vec<f32> = (0..n)
        .into_par_iter()
        .filter_map(|i| {
            let j = *nb.of(i).first()? as usize;
            let gap = (plane[j] - plane[i]).length() * depth[i];
            (gap > 0.0 && step[i] > 0.0).then(|| step[i] / gap)
        })
        .collect();
    if ratio.len() < n / 2 {
        return Ok(None);
    }
    let mid = ratio.len() / 2;
    let (_, &mut median, _) = ratio.select_nth_unstable_by(mid, f32::total_cmp);
    if median < STEP_OVER_SPACING {
        return Ok(None);
    }
    let (lo, hi) = (sorted[0], sorted[n - 1]);
    let mut cur = depth.clone();
    for _ in 0..ROUNDS {
        cur = (0..n)
            .into_par_iter()
            .map(|i| {
                let (d, s) = (depth[i], step[i]);
                // Least squares d = a + b u + c v over the same-surface neighbours on the
                // image plane, about the point.
                let mut m = [[0.0f64; 3]; 3];
                let mut r = [0.0f64; 3];
                let mut add = |du: f64, dv: f64, z: f64| {
                    let x = [1.0, du, dv];
                    for a in 0..3 {
                        for b in 0..3 {
                            m[a][b] += x[a] * x[b];
                        }
                        r[a] += x[a] * z;
                    }
                };
                add(0.0, 0.0, cur[i] as f64);
                let mut count = 1;
                for &j in nb.of(i) {
                    let j = j as usize;
                    if (depth[j] - d).abs() <= SAME_SURFACE * s {
                        let q = plane[j] - plane[i];
                        add(q.x as f64, q.y as f64, cur[j] as f64);
                        count += 1;
                    }
                }
                if count < 6 {
                    return cur[i];
                }
                let a = solve3(m, r)
                    .filter(|a| a.is_finite())
                    .unwrap_or(cur[i] as f64);
                // Never beyond the stored depths' range either: the camera's near and far
                // planes were fitted to the stored points.
                let reach = MAX_MOVE * s;
                (a as f32).clamp((d - reach).max(lo), (d + reach).min(hi))
            })
            .collect();
    }
    let moved: Vec<Vec3> = positions
        .par_iter()
        .zip(depth.par_iter().zip(&cur))
        .map(|(p, (&d, &e))| {
            let r = (*p - eye).as_dvec3();
            (eye.as_dvec3() + r * (e as f64 / d as f64)).as_vec3()
        })
        .collect();
    let used = step.iter().filter(|s| **s > 0.0);
    let steps = used.fold((f32::INFINITY, 0.0f32), |(lo, hi), &s| {
        (lo.min(s), hi.max(s))
    });
    Ok(Some(Dequantised {
        positions: moved,
        levels: levels.len(),
        steps,
    }))
}

/// The first unknown of m x = r (Cramer's rule), None where m is singular. (glam's
/// `DMat3::inverse` computes all nine cofactors: the office's estimate 1.00 → 1.19 s.)
fn solve3(m: [[f64; 3]; 3], r: [f64; 3]) -> Option<f64> {
    let det = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(m);
    if d.abs() < 1e-18 * (m[0][0] * m[1][1] * m[2][2]).abs().max(1e-300) {
        return None;
    }
    let mut a = m;
    for k in 0..3 {
        a[k][0] = r[k];
    }
    Some(det(a) / d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::normals::{neighbours, pca_normals};

    const K: f32 = 100.0;

    /// A pinhole camera at the origin looking along +z, 240 × 180 pixels at 200 px focal
    /// length: the points where its rays first meet `hit` (a depth along +z), each depth
    /// rounded as a disparity camera rounds it when `quantise`: 1 / z in steps of 1 / K,
    /// so steps of 9 cm at 3 m where the points lie 1.5 cm apart (a Kinect's, 6 to 1).
    fn capture(hit: impl Fn(Vec3) -> Option<f32>, quantise: bool) -> Vec<Vec3> {
        let mut out = Vec::new();
        for j in 0..180 {
            for i in 0..240 {
                let ray = Vec3::new((i as f32 - 119.5) / 200.0, (j as f32 - 89.5) / 200.0, 1.0);
                if let Some(z) = hit(ray) {
                    let z = if quantise { K / (K / z).round() } else { z };
                    out.push(ray * z);
                }
            }
        }
        out
    }

    /// A plane through (0, 0, 3) whose normal is `n`: the depth along each ray.
    fn plane(n: Vec3) -> impl Fn(Vec3) -> Option<f32> {
        move |ray: Vec3| {
            let t = n.dot(Vec3::new(0.0, 0.0, 3.0)) / n.dot(ray);
            (t > 0.0 && t < 8.0).then_some(t)
        }
    }

    fn median_error(positions: &[Vec3], n: Vec3) -> f32 {
        let nb = neighbours(positions, 16).unwrap();
        let mut e: Vec<f32> = pca_normals(positions, &nb)
            .iter()
            .map(|m| m.dot(n).abs().min(1.0).acos().to_degrees())
            .collect();
        e.sort_by(f32::total_cmp);
        e[e.len() / 2]
    }

    #[test]
    fn a_depth_cameras_steps_are_smoothed_into_their_slope() {
        // Seen at 50° and at 70° (a floor at a grazing angle).
        for deg in [50.0f32, 70.0] {
            let a = deg.to_radians();
            let n = Vec3::new(0.0, a.sin(), -a.cos());
            let stepped = capture(plane(n), true);
            let before = median_error(&stepped, n);
            let d = dequantise(&stepped, Vec3::ZERO, Vec3::Z).unwrap().unwrap();
            assert!(d.levels >= MIN_LEVELS, "{deg}°: {} levels", d.levels);
            let after = median_error(&d.positions, n);
            eprintln!("{deg}°: median normal error {before:.1}° → {after:.1}°");
            assert!(before > 20.0, "{deg}°: the steps tilt normals ({before}°)");
            assert!(after < 3.0, "{deg}°: {after}° after smoothing");
            // Each point moved along its own ray, by at most MAX_MOVE of its step.
            for (p, q) in stepped.iter().zip(&d.positions) {
                assert!(p.normalize().dot(q.normalize()) > 1.0 - 1e-6);
                let step = p.z * p.z / K;
                assert!((q.z - p.z).abs() <= MAX_MOVE * step * 1.2 + 1e-4);
            }
        }
    }

    #[test]
    fn a_surface_before_another_keeps_its_depth() {
        // A square facing the camera at 1.5, before a wall at 50° through (0, 0, 3).
        let a = 50f32.to_radians();
        let wall = plane(Vec3::new(0.0, a.sin(), -a.cos()));
        let scene = |ray: Vec3| {
            let p = ray * 1.5;
            if p.x.abs() < 0.3 && p.y.abs() < 0.3 {
                Some(1.5)
            } else {
                wall(ray)
            }
        };
        let stepped = capture(scene, true);
        let d = dequantise(&stepped, Vec3::ZERO, Vec3::Z).unwrap().unwrap();
        let mut square = 0;
        for (p, q) in stepped.iter().zip(&d.positions) {
            if (p.z - 1.5).abs() < 0.02 {
                square += 1;
                assert!((q.z - p.z).abs() < 1e-4, "{p} moved to {q}");
            }
        }
        assert!(square > 1000, "{square}");
    }

    #[test]
    fn depths_that_are_not_a_cameras_steps_are_left_alone() {
        let a = 50f32.to_radians();
        let n = Vec3::new(0.0, a.sin(), -a.cos());
        // Not rounded.
        let smooth = capture(plane(n), false);
        assert!(dequantise(&smooth, Vec3::ZERO, Vec3::Z).unwrap().is_none());
        // Surfaces facing the camera at a few chosen depths: few, uneven levels.
        for bands in [6usize, 40] {
            let depths: Vec<f32> = (0..bands)
                .map(|b| 1.0 + b as f32 * 0.05 + if b % 3 == 0 { 0.03 } else { 0.0 })
                .collect();
            let stack = capture(
                |ray| {
                    let b = (((ray.x + 0.6) / 1.2 * bands as f32) as usize).min(bands - 1);
                    Some(depths[b])
                },
                false,
            );
            assert!(
                dequantise(&stack, Vec3::ZERO, Vec3::Z).unwrap().is_none(),
                "{bands} bands"
            );
        }
        // Points behind the sensor (its axis the other way round) are no depth camera's.
        let stepped = capture(plane(n), true);
        assert!(dequantise(&stepped, Vec3::ZERO, -Vec3::Z)
            .unwrap()
            .is_none());
    }
}
