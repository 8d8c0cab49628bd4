//! Volumes to points (Gunjee et al. §3: volume data converted to points so that one renderer
//! draws meshes, scans and volumes alike): the iso-surface at a value as points where the
//! volume crosses it along voxel edges, each placed by linear interpolation between the two
//! samples, with its normal from the central-difference gradient interpolated the same way
//! (pointing from high values to low: the outside of a dense object in CT). Without a value
//! given, the iso-value is Otsu's threshold of the volume's histogram (the value that best
//! splits it into two classes: air and tissue, background and object).

use crate::PointCloud;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// A scalar volume on a regular grid: `dims` samples along x, y, z (x fastest), `spacing`
/// between samples and the world position of sample (0, 0, 0).
#[derive(Clone, Debug)]
pub struct Volume {
    pub dims: [usize; 3],
    pub spacing: [f64; 3],
    pub origin: [f64; 3],
    pub data: Vec<f32>,
}

/// Why a volume cannot be turned into points.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VolumeError {
    #[error("iso-value {0}: it must be finite")]
    Iso(f64),
    #[error("no sample crosses the iso-value {iso} (the volume's values lie in {lo}..{hi})")]
    Empty { iso: f64, lo: f64, hi: f64 },
    #[error("the volume is {0:?} samples: at least 2 along each axis are needed")]
    TooSmall([usize; 3]),
    #[error("the iso-surface would have more than {0} points: choose another value")]
    TooMany(usize),
    #[error("no sample has an opacity above 0 under the transfer function (the volume's values lie in {lo}..{hi})")]
    Transparent { lo: f64, hi: f64 },
    #[error(
        "the transfer function gives {count} samples an opacity above 0, more than {limit} points"
    )]
    TooManySamples { count: usize, limit: usize },
}

/// A transfer function: control points (value, sRGB colour, opacity), linearly interpolated
/// between them and held at the ends. Written one point a line, `value r g b opacity` (colour
/// 0–255, opacity 0–1; `#` starts a comment), or inline with `;` between the points.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunction {
    /// Sorted by value, at least one.
    pub points: Vec<(f64, [f32; 3], f32)>,
}

/// Why a transfer function cannot be read.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("transfer function, point {point} (`{text}`): {message}")]
pub struct TransferError {
    pub point: usize,
    pub text: String,
    pub message: String,
}

impl TransferFunction {
    /// Parses the text form (see the type's documentation): points on lines or between `;`.
    pub fn parse(text: &str) -> Result<TransferFunction, TransferError> {
        let mut points = Vec::new();
        let items = text
            .split(['\n', ';'])
            .map(|l| l.split('#').next().unwrap_or("").trim())
            .enumerate()
            .filter(|(_, l)| !l.is_empty());
        for (i, item) in items {
            let bad = |message: &str| TransferError {
                point: i + 1,
                text: item.chars().take(60).collect(),
                message: message.into(),
            };
            let f: Vec<&str> = item
                .split(|c: char| c.is_whitespace() || c == ',' || c == ':')
                .filter(|s| !s.is_empty())
                .collect();
            if f.len() != 5 {
                return Err(bad("expected `value r g b opacity` (five numbers)"));
            }
            let num = |s: &str| s.parse::<f64>().ok().filter(|x| x.is_finite());
            let value = num(f[0]).ok_or_else(|| bad("the value is not a finite number"))?;
            let mut rgb = [0f32; 3];
            for (c, s) in rgb.iter_mut().zip(&f[1..4]) {
                *c = num(s)
                    .filter(|x| (0.0..=255.0).contains(x))
                    .ok_or_else(|| bad("colours are 0 to 255"))? as f32;
            }
            let a = num(f[4])
                .filter(|x| (0.0..=1.0).contains(x))
                .ok_or_else(|| bad("the opacity is 0 to 1"))? as f32;
            if points.len() >= 4096 {
                return Err(bad("at most 4096 points"));
            }
            points.push((value, rgb, a));
        }
        if points.is_empty() {
            return Err(TransferError {
                point: 0,
                text: String::new(),
                message: "no control points".into(),
            });
        }
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(TransferFunction { points })
    }

    /// Colour (sRGB, 0–255) and opacity at `v`.
    pub fn eval(&self, v: f64) -> ([f32; 3], f32) {
        let p = &self.points;
        let i = p.partition_point(|q| q.0 <= v);
        if i == 0 {
            return (p[0].1, p[0].2);
        }
        if i == p.len() {
            let l = p[p.len() - 1];
            return (l.1, l.2);
        }
        let (a, b) = (p[i - 1], p[i]);
        let t = ((v - a.0) / (b.0 - a.0)).clamp(0.0, 1.0) as f32;
        let mix = |x: f32, y: f32| x + (y - x) * t;
        (
            [
                mix(a.1[0], b.1[0]),
                mix(a.1[1], b.1[1]),
                mix(a.1[2], b.1[2]),
            ],
            mix(a.2, b.2),
        )
    }
}

/// Every sample of `v` whose opacity under `tf` is above zero, as a point at the sample with
/// the function's colour and opacity and the normal of the gradient (see the module
/// documentation); at most `limit` points, counted before anything is allocated.
pub fn transfer_points(
    v: &Volume,
    tf: &TransferFunction,
    limit: usize,
) -> Result<PointCloud, VolumeError> {
    let [nx, ny, nz] = v.dims;
    if nx < 2 || ny < 2 || nz < 2 {
        return Err(VolumeError::TooSmall(v.dims));
    }
    let shown = |x: f32| x.is_finite() && tf.eval(x as f64).1 > 0.0;
    let count: usize = v.data.par_iter().filter(|&&x| shown(x)).count();
    if count == 0 {
        let (lo, hi) = v.range();
        return Err(VolumeError::Transparent { lo, hi });
    }
    if count > limit {
        return Err(VolumeError::TooManySamples { count, limit });
    }
    type Slab = (Vec<DVec3>, Vec<Vec3>, Vec<[u8; 3]>, Vec<f32>);
    let slabs: Vec<Slab> = (0..nz)
        .into_par_iter()
        .map(|z| {
            let mut s: Slab = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
            for y in 0..ny {
                for x in 0..nx {
                    let val = v.at(x, y, z);
                    if !shown(val) {
                        continue;
                    }
                    let (rgb, a) = tf.eval(val as f64);
                    s.0.push(v.position(x as f64, y as f64, z as f64));
                    // Inside a uniform region the gradient vanishes: such a point faces +z.
                    let g = -v.gradient(x, y, z);
                    s.1.push(if g.length() > 0.0 {
                        g.normalize().as_vec3()
                    } else {
                        Vec3::Z
                    });
                    s.2.push(rgb.map(|c| (c + 0.5) as u8));
                    s.3.push(a);
                }
            }
            s
        })
        .collect();
    let mut world = Vec::with_capacity(count);
    let (mut normals, mut colours, mut opacity) = (
        Vec::with_capacity(count),
        Vec::with_capacity(count),
        Vec::with_capacity(count),
    );
    for (p, n, c, a) in slabs {
        world.extend(p);
        normals.extend(n);
        colours.extend(c);
        opacity.extend(a);
    }
    let mut cloud = PointCloud::from_world(&world);
    cloud.normals = Some(normals);
    cloud.normals_trusted = true;
    cloud.colors = Some(colours);
    cloud.opacity = Some(opacity);
    Ok(cloud)
}

impl Volume {
    fn at(&self, x: usize, y: usize, z: usize) -> f32 {
        self.data[(z * self.dims[1] + y) * self.dims[0] + x]
    }

    /// The central-difference gradient at a sample (one-sided at the border), per world unit.
    fn gradient(&self, x: usize, y: usize, z: usize) -> DVec3 {
        let d = |i: usize, n: usize, f: &dyn Fn(usize) -> f32, h: f64| -> f64 {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            (f(b) as f64 - f(a) as f64) / ((b - a).max(1) as f64 * h)
        };
        let [nx, ny, nz] = self.dims;
        DVec3::new(
            d(x, nx, &|i| self.at(i, y, z), self.spacing[0]),
            d(y, ny, &|i| self.at(x, i, z), self.spacing[1]),
            d(z, nz, &|i| self.at(x, y, i), self.spacing[2]),
        )
    }

    fn position(&self, x: f64, y: f64, z: f64) -> DVec3 {
        DVec3::new(
            self.origin[0] + x * self.spacing[0],
            self.origin[1] + y * self.spacing[1],
            self.origin[2] + z * self.spacing[2],
        )
    }

    /// The smallest and largest finite values.
    pub fn range(&self) -> (f64, f64) {
        self.data
            .par_iter()
            .filter(|v| v.is_finite())
            .fold(
                || (f64::INFINITY, f64::NEG_INFINITY),
                |(lo, hi), &v| (lo.min(v as f64), hi.max(v as f64)),
            )
            .reduce(
                || (f64::INFINITY, f64::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            )
    }
}

/// Otsu's threshold over a 256-bin histogram of the finite values.
pub fn otsu(v: &Volume) -> f64 {
    let (lo, hi) = v.range();
    if hi.is_nan() || lo.is_nan() || hi <= lo {
        return lo;
    }
    const BINS: usize = 256;
    let scale = (BINS - 1) as f64 / (hi - lo);
    let hist = v
        .data
        .par_iter()
        .filter(|x| x.is_finite())
        .fold(
            || vec![0u64; BINS],
            |mut h, &x| {
                h[((x as f64 - lo) * scale) as usize] += 1;
                h
            },
        )
        .reduce(
            || vec![0u64; BINS],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    *x += y;
                }
                a
            },
        );
    let total: u64 = hist.iter().sum();
    let sum: f64 = hist
        .iter()
        .enumerate()
        .map(|(i, &c)| i as f64 * c as f64)
        .sum();
    let (mut w0, mut s0, mut best, mut at) = (0u64, 0.0, -1.0, 0);
    for (i, &c) in hist.iter().enumerate() {
        w0 += c;
        s0 += i as f64 * c as f64;
        let w1 = total - w0;
        if w0 == 0 || w1 == 0 {
            continue;
        }
        let (m0, m1) = (s0 / w0 as f64, (sum - s0) / w1 as f64);
        let between = w0 as f64 * w1 as f64 * (m0 - m1) * (m0 - m1);
        if between > best {
            best = between;
            at = i;
        }
    }
    lo + (at as f64 + 1.0) / scale
}

/// The iso-surface of `v` at `iso` as points with normals (see the module documentation);
/// at most `limit` points.
pub fn iso_points(v: &Volume, iso: f64, limit: usize) -> Result<PointCloud, VolumeError> {
    if !iso.is_finite() {
        return Err(VolumeError::Iso(iso));
    }
    let [nx, ny, nz] = v.dims;
    if nx < 2 || ny < 2 || nz < 2 {
        return Err(VolumeError::TooSmall(v.dims));
    }
    let iso32 = iso as f32;
    // Slab by slab in parallel: the crossings of the edges leaving each sample in +x, +y, +z.
    let slabs: Vec<(Vec<DVec3>, Vec<Vec3>)> = (0..nz)
        .into_par_iter()
        .map(|z| {
            let (mut pts, mut nrm) = (Vec::new(), Vec::new());
            for y in 0..ny {
                for x in 0..nx {
                    let a = v.at(x, y, z);
                    for (dx, dy, dz) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                        let (bx, by, bz) = (x + dx, y + dy, z + dz);
                        if bx >= nx || by >= ny || bz >= nz {
                            continue;
                        }
                        let b = v.at(bx, by, bz);
                        if !(a.is_finite() && b.is_finite()) || (a >= iso32) == (b >= iso32) {
                            continue;
                        }
                        let t = ((iso - a as f64) / (b as f64 - a as f64)).clamp(0.0, 1.0);
                        pts.push(v.position(
                            x as f64 + t * dx as f64,
                            y as f64 + t * dy as f64,
                            z as f64 + t * dz as f64,
                        ));
                        let g = v.gradient(x, y, z) * (1.0 - t) + v.gradient(bx, by, bz) * t;
                        nrm.push((-g).normalize_or_zero().as_vec3());
                    }
                }
            }
            (pts, nrm)
        })
        .collect();
    let n: usize = slabs.iter().map(|s| s.0.len()).sum();
    if n == 0 {
        let (lo, hi) = v.range();
        return Err(VolumeError::Empty { iso, lo, hi });
    }
    if n > limit {
        return Err(VolumeError::TooMany(limit));
    }
    let mut world = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(n);
    for (p, q) in slabs {
        world.extend(p);
        normals.extend(q);
    }
    let mut cloud = PointCloud::from_world(&world);
    cloud.normals = Some(normals);
    // The gradient's direction: outward from the object's side, consistent by construction.
    cloud.normals_trusted = true;
    Ok(cloud)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ball of radius r (values: distance below r, positive inside) sampled at `h`.
    fn ball(n: usize, r: f64, h: f64) -> Volume {
        let c = (n - 1) as f64 * h / 2.0;
        let mut data = Vec::with_capacity(n * n * n);
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let p = DVec3::new(x as f64, y as f64, z as f64) * h - DVec3::splat(c);
                    data.push((100.0 * (r - p.length())) as f32);
                }
            }
        }
        Volume {
            dims: [n; 3],
            spacing: [h; 3],
            origin: [-c; 3],
            data,
        }
    }

    #[test]
    fn a_ball_gives_points_on_its_sphere_with_outward_normals() {
        let h = 0.05;
        let v = ball(48, 0.8, h);
        let c = iso_points(&v, 0.0, 1 << 24).unwrap();
        assert!(c.len() > 1000);
        let n = c.normals.as_ref().unwrap();
        let mut errs = Vec::new();
        for i in 0..c.len() {
            let p = c.world(i);
            assert!(
                (p.length() - 0.8).abs() < 0.5 * h,
                "point {i} at radius {}",
                p.length()
            );
            errs.push(n[i].as_dvec3().angle_between(p).to_degrees());
        }
        errs.sort_by(f64::total_cmp);
        assert!(
            errs[errs.len() / 2] < 5.0,
            "median normal error {}",
            errs[errs.len() / 2]
        );
        assert!(errs.iter().all(|&e| e < 90.0), "every normal outward");
    }

    #[test]
    fn a_transfer_function_keeps_the_samples_it_shows_with_its_colour_and_opacity() {
        let h = 0.05;
        let v = ball(40, 0.6, h);
        // Values are 100 × (0.6 − distance): transparent outside, α 0.2 at the surface rising
        // to 0.6 at 30 (0.3 inside), red to white.
        let tf = TransferFunction::parse(
            "# value r g b opacity\n-0.001 0 0 0 0\n0 255 0 0 0.2\n30: 255, 255, 255, 0.6",
        )
        .unwrap();
        let c = transfer_points(&v, &tf, 1 << 24).unwrap();
        let inside = v.data.iter().filter(|&&x| x >= 0.0).count();
        assert_eq!(c.len(), inside);
        let (col, a) = (c.colors.as_ref().unwrap(), c.opacity.as_ref().unwrap());
        for i in 0..c.len() {
            let d = c.world(i).length();
            assert!(d <= 0.6 + 1e-6, "a point outside the ball at {d}");
            let val = 100.0 * (0.6 - d);
            let want = if val >= 30.0 {
                0.6
            } else {
                0.2 + 0.4 * val / 30.0
            };
            assert!(
                (a[i] as f64 - want).abs() < 2e-3,
                "opacity {} at value {val}",
                a[i]
            );
            assert_eq!(col[i][0], 255);
            let g = (255.0 * (val / 30.0).min(1.0) + 0.5) as i32;
            assert!(
                (col[i][1] as i32 - g).abs() <= 1,
                "green {} at value {val}",
                col[i][1]
            );
        }
        // Inline form, sorted; errors name the point.
        let tf = TransferFunction::parse("10 0 0 0 1; 5 255 255 255 0").unwrap();
        assert_eq!(tf.eval(7.5), ([127.5; 3], 0.5));
        assert_eq!(tf.eval(-1.0).1, 0.0);
        assert_eq!(tf.eval(99.0).1, 1.0);
        for (bad, says) in [
            ("", "no control points"),
            ("1 2 3", "five numbers"),
            ("0 0 0 0 0; x 1 1 1 1", "point 2"),
            ("0 300 0 0 1", "0 to 255"),
            ("0 0 0 0 1.5", "0 to 1"),
            ("inf 0 0 0 1", "finite"),
        ] {
            let e = TransferFunction::parse(bad).unwrap_err().to_string();
            assert!(e.contains(says), "{bad:?}: {e}");
        }
        // Nothing shown, or too many: errors before any allocation.
        let none = TransferFunction::parse("0 0 0 0 0").unwrap();
        assert!(matches!(
            transfer_points(&v, &none, 10),
            Err(VolumeError::Transparent { .. })
        ));
        assert!(matches!(
            transfer_points(&v, &tf, 10),
            Err(VolumeError::TooManySamples { .. })
        ));
    }

    #[test]
    fn otsu_splits_two_populations() {
        let mut v = ball(20, 0.3, 0.05);
        // Two values only: 0 outside, 1000 inside.
        for x in &mut v.data {
            *x = if *x > 0.0 { 1000.0 } else { 0.0 };
        }
        let t = otsu(&v);
        assert!(t > 0.0 && t < 1000.0, "{t}");
    }

    #[test]
    fn bad_volumes_are_errors() {
        let v = ball(10, 0.2, 0.1);
        assert!(matches!(
            iso_points(&v, f64::NAN, 100),
            Err(VolumeError::Iso(_))
        ));
        assert!(matches!(
            iso_points(&v, 1e9, 100),
            Err(VolumeError::Empty { .. })
        ));
        assert!(matches!(
            iso_points(&v, 0.0, 3),
            Err(VolumeError::TooMany(3))
        ));
        let flat = Volume {
            dims: [1, 4, 4],
            spacing: [1.0; 3],
            origin: [0.0; 3],
            data: vec![0.0; 16],
        };
        assert!(matches!(
            iso_points(&flat, 0.0, 100),
            Err(VolumeError::TooSmall(_))
        ));
    }
}
