//! Columnar (structure-of-arrays) point clouds.
//!
//! Positions are stored as `f32` relative to an `f64` origin: LiDAR coordinates such as
//! (637 000, 850 000) keep sub-millimetre precision while hot loops read 12 bytes per point.
//! Optional attributes are separate columns of the same length; the schema is the set of
//! columns that are present ([`PointCloud::attributes`]).

use glam::{DVec3, Vec3};

/// The Morton code of a cell's coordinates (10 bits each): their bits interleaved, x
/// lowest.
pub(crate) fn morton3(c: [u32; 3]) -> u32 {
    let spread = |v: u32| {
        let mut x = v & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    };
    spread(c[0]) | spread(c[1]) << 1 | spread(c[2]) << 2
}

/// The box outside which a point strays from the bulk of `points`: the 1st–99th
/// percentile box (per axis, on a sample of at most 2^16 points) grown on every side by
/// twice its largest side. None for fewer than three points or a bulk without extent.
fn bulk_box<P>(points: &[P], at: impl Fn(&P) -> DVec3) -> Option<(DVec3, DVec3)> {
    let n = points.len();
    if n < 3 {
        return None;
    }
    let step = n.div_ceil(1 << 16);
    let (mut lo, mut hi) = (DVec3::ZERO, DVec3::ZERO);
    let mut v: Vec<f64> = Vec::with_capacity(n / step + 1);
    for a in 0..3 {
        v.clear();
        v.extend(points.iter().step_by(step).map(|p| at(p)[a]));
        let m = v.len();
        lo[a] = *v.select_nth_unstable_by(m / 100, f64::total_cmp).1;
        hi[a] = *v.select_nth_unstable_by(m - 1 - m / 100, f64::total_cmp).1;
    }
    let side = (hi - lo).max_element();
    (side > 0.0 && side.is_finite()).then(|| (lo - 2.0 * side, hi + 2.0 * side))
}

/// An axis-aligned box in the cloud's local (origin-relative) frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub min: Vec3,
    pub max: Vec3,
}

impl Bounds {
    pub const EMPTY: Bounds = Bounds {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn from_points(points: &[Vec3]) -> Bounds {
        points.iter().fold(Bounds::EMPTY, |b, &p| b.including(p))
    }

    pub fn including(self, p: Vec3) -> Bounds {
        Bounds {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    pub fn union(self, o: Bounds) -> Bounds {
        Bounds {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x
    }

    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    pub fn extent(&self) -> Vec3 {
        (self.max - self.min).max(Vec3::ZERO)
    }

    pub fn diagonal(&self) -> f32 {
        self.extent().length()
    }

    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }
}

/// The largest coordinate magnitude a reader accepts: positions are kept as 32-bit offsets
/// from the cloud's centre, and beyond this no geodetic or scientific use remains (a finite
/// 1e300 would become an infinite offset).
pub const MAX_COORDINATE: f64 = 1e15;

/// Why a finite world position cannot be kept (see [`MAX_COORDINATE`]), if it cannot.
/// Inlined: readers call it for every point, and nearly every point is fine.
#[inline]
pub fn coordinate_problem(p: glam::DVec3) -> Option<String> {
    if p.is_finite() && p.abs().max_element() <= MAX_COORDINATE {
        return None;
    }
    describe_coordinate_problem(p)
}

#[cold]
fn describe_coordinate_problem(p: glam::DVec3) -> Option<String> {
    if !p.is_finite() {
        return Some(format!(
            "a non-finite coordinate ({}, {}, {})",
            p.x, p.y, p.z
        ));
    }
    (p.abs().max_element() > MAX_COORDINATE).then(|| {
        format!(
            "a coordinate out of range ({:e}, {:e}, {:e}): positions are kept as 32-bit \
             offsets from the cloud's centre and may be at most {MAX_COORDINATE:e} in magnitude",
            p.x, p.y, p.z
        )
    })
}

/// A problem with the contents of a cloud (not with the file it came from: readers wrap this
/// with the path).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CloudError {
    #[error("the cloud has no points")]
    Empty,
    #[error("point {index} has a non-finite coordinate ({x}, {y}, {z})")]
    NonFinite {
        index: usize,
        x: f64,
        y: f64,
        z: f64,
    },
    #[error("attribute `{name}` has {len} values for {points} points")]
    LengthMismatch {
        name: &'static str,
        len: usize,
        points: usize,
    },
    #[error("face {face} refers to vertex {vertex}, but the cloud has {points} points")]
    BadFace {
        face: usize,
        vertex: u32,
        points: usize,
    },
}

/// A point cloud in columnar storage.
#[derive(Clone, Debug, Default)]
pub struct PointCloud {
    /// World position of the local frame's origin.
    pub origin: DVec3,
    /// Positions relative to `origin`.
    pub positions: Vec<Vec3>,
    /// Unit normals, if the source had them.
    pub normals: Option<Vec<Vec3>>,
    /// sRGB 8-bit colours.
    pub colors: Option<Vec<[u8; 3]>>,
    /// LiDAR intensity (16-bit, as in LAS).
    pub intensity: Option<Vec<u16>>,
    /// LiDAR classification codes.
    pub classification: Option<Vec<u8>>,
    /// LiDAR return number of each pulse's echo (1 = first), as LAS files give it.
    pub return_number: Option<Vec<u8>>,
    /// Per-point opacity in [0, 1].
    pub opacity: Option<Vec<f32>>,
    /// Splat radius per point, world units (PLY `radius`; see [`crate::normals`]).
    pub radius: Option<Vec<f32>>,
    /// The file's other per-point values by name (scalar fields: a PLY or PCD property such
    /// as `curvature`, `confidence` or a material id), at most [`MAX_FIELDS`], for colouring
    /// by and lookup tables (see [`crate::colour_map`], [`crate::lookup`]).
    pub fields: Vec<Field>,
    /// Triangles from the source file (kept for ground-truth rendering and later conversions).
    pub faces: Vec<[u32; 3]>,
    /// The source says +Z is up (LAS/LAZ/COPC: georeferenced, Z is elevation); the default
    /// framing then looks at the cloud Z-up. Other sources are framed Y-up unless flat in Z.
    pub z_up: bool,
    /// Where the sensor stood and how it looked, when the file says (a PCD's `VIEWPOINT`):
    /// the default camera then sees the cloud as captured, and estimated normals face the
    /// sensor.
    pub sensor: Option<Sensor>,
    /// The normals' signs are known to be right (a volume's iso-surface: from the gradient),
    /// so renders keep them as they are instead of checking their consistency over a
    /// neighbour graph (which can turn whole nested surfaces round where they touch).
    pub normals_trusted: bool,
    /// Per point, the direction from the point towards the sensor that measured it, a unit
    /// vector times 127 (`[0, 0, 0]`: not known); estimated normals face it. Airborne LiDAR
    /// with GPS times and scan angles gives it (see stipple_io's LAS reader).
    pub sensor_dirs: Option<Vec<[i8; 3]>>,
}

/// A unit direction quantised for [`PointCloud::sensor_dirs`] (zero or non-finite: unknown).
pub fn quantise_dir(d: DVec3) -> [i8; 3] {
    match d.try_normalize() {
        Some(u) => [u.x, u.y, u.z].map(|c| (c * 127.0).round() as i8),
        None => [0; 3],
    }
}

/// Scalar fields a cloud keeps from its file (further ones are skipped): a file with
/// thousands of properties must not multiply its memory by thousands.
pub const MAX_FIELDS: usize = 32;

/// One scalar field: a value per point, stored as `f32` offsets from `offset` so that large
/// values with a small spread (GPS times, ids in the millions) keep their precision.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Field {
    /// The name the file gave it.
    pub name: String,
    pub offset: f64,
    /// `value(i) = offset + values[i]`; NaN where a point has no value (a merged cloud's
    /// points from a file without this field).
    pub values: Vec<f32>,
}

impl Field {
    /// A field from values in f64 (the offset: the first finite value).
    pub fn new(name: impl Into<String>, values: &[f64]) -> Field {
        let offset = values
            .iter()
            .copied()
            .find(|v| v.is_finite())
            .unwrap_or(0.0);
        Field {
            name: name.into(),
            offset,
            values: values.iter().map(|&v| (v - offset) as f32).collect(),
        }
    }

    /// Point `i`'s value.
    #[inline]
    pub fn value(&self, i: usize) -> f64 {
        self.offset + self.values[i] as f64
    }

    /// Whether `name` names this field: equal ignoring ASCII case, and ignoring the
    /// `scalar_` prefix CloudCompare writes (`scalar_Curvature` is `curvature`).
    pub fn is_named(&self, name: &str) -> bool {
        fn strip(s: &str) -> &str {
            match s.get(..7) {
                Some(p) if p.eq_ignore_ascii_case("scalar_") && s.len() > 7 => &s[7..],
                _ => s,
            }
        }
        strip(&self.name).eq_ignore_ascii_case(strip(name))
    }
}

/// A sensor's pose in world coordinates: its position, viewing direction and image up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensor {
    pub position: DVec3,
    pub forward: DVec3,
    pub up: DVec3,
}

impl PointCloud {
    /// Turns the sensor (if any) to face the points. Writers disagree on whether a pose
    /// turns the sensor or the cloud (PCL's Kinect frames carry a half turn about x with the
    /// points still in front along +z): the sensor's view becomes the one of ±forward (with
    /// up turned alike) that has most points in front. Readers call it once, so that the
    /// camera and the normal estimation can take `forward` as it is.
    pub fn face_sensor_to_points(&mut self) {
        let Some(s) = self.sensor else {
            return;
        };
        let step = (self.len() / 20_000).max(1);
        let ahead = (0..self.len())
            .step_by(step)
            .filter(|&i| (self.world(i) - s.position).dot(s.forward) > 0.0)
            .count();
        if 2 * ahead < self.len().div_ceil(step) {
            self.sensor = Some(Sensor {
                forward: -s.forward,
                up: -s.up,
                ..s
            });
        }
    }

    /// Builds a cloud from world positions, choosing the origin at the centre of their bounds
    /// so that `f32` offsets keep the most precision.
    pub fn from_world(points: &[DVec3]) -> PointCloud {
        let (lo, hi) = points.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        );
        let origin = if points.is_empty() || !lo.is_finite() || !hi.is_finite() {
            DVec3::ZERO
        } else {
            // The centre of the bulk where a few points stray far from it (see
            // `framing_bounds`), so that the bulk keeps its precision as 32-bit offsets.
            let (lo, hi) = match bulk_box(points, |p: &DVec3| *p) {
                Some((a, b)) if points.iter().any(|p| p.cmplt(a).any() || p.cmpgt(b).any()) => {
                    points
                        .iter()
                        .filter(|p| p.cmpge(a).all() && p.cmple(b).all())
                        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), &p| {
                            (l.min(p), h.max(p))
                        })
                }
                _ => (lo, hi),
            };
            ((lo + hi) * 0.5).round()
        };
        PointCloud {
            origin,
            positions: points.iter().map(|&p| (p - origin).as_vec3()).collect(),
            ..Default::default()
        }
    }

    /// Builds a cloud from local positions with a zero origin.
    pub fn from_positions(positions: Vec<Vec3>) -> PointCloud {
        PointCloud {
            positions,
            ..Default::default()
        }
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// World position of point `i`.
    pub fn world(&self, i: usize) -> DVec3 {
        self.origin + self.positions[i].as_dvec3()
    }

    /// Checks the invariants every renderer relies on: at least one point, finite
    /// coordinates, attribute columns as long as the position column, faces in range.
    pub fn validate(&self) -> Result<(), CloudError> {
        let n = self.len();
        if n == 0 {
            return Err(CloudError::Empty);
        }
        if let Some(index) = self.positions.iter().position(|p| !p.is_finite()) {
            let w = self.world(index);
            return Err(CloudError::NonFinite {
                index,
                x: w.x,
                y: w.y,
                z: w.z,
            });
        }
        let check = |name: &'static str, len: Option<usize>| match len {
            Some(len) if len != n => Err(CloudError::LengthMismatch {
                name,
                len,
                points: n,
            }),
            _ => Ok(()),
        };
        check("normals", self.normals.as_ref().map(Vec::len))?;
        check("colors", self.colors.as_ref().map(Vec::len))?;
        check("intensity", self.intensity.as_ref().map(Vec::len))?;
        check("classification", self.classification.as_ref().map(Vec::len))?;
        check("return_number", self.return_number.as_ref().map(Vec::len))?;
        check("opacity", self.opacity.as_ref().map(Vec::len))?;
        check("radius", self.radius.as_ref().map(Vec::len))?;
        check("sensor_dirs", self.sensor_dirs.as_ref().map(Vec::len))?;
        for f in &self.fields {
            check("a scalar field", Some(f.values.len()))?;
        }
        for (face, tri) in self.faces.iter().enumerate() {
            if let Some(&vertex) = tri.iter().find(|&&v| v as usize >= n) {
                return Err(CloudError::BadFace {
                    face,
                    vertex,
                    points: n,
                });
            }
        }
        Ok(())
    }

    /// Names of the columns present, positions first, scalar fields last.
    pub fn attributes(&self) -> Vec<String> {
        let mut a = vec!["position"];
        if self.normals.is_some() {
            a.push("normal");
        }
        if self.colors.is_some() {
            a.push("color");
        }
        if self.intensity.is_some() {
            a.push("intensity");
        }
        if self.classification.is_some() {
            a.push("classification");
        }
        if self.return_number.is_some() {
            a.push("return number");
        }
        if self.opacity.is_some() {
            a.push("opacity");
        }
        if self.radius.is_some() {
            a.push("radius");
        }
        if self.sensor_dirs.is_some() {
            a.push("sensor direction");
        }
        let mut a: Vec<String> = a.into_iter().map(String::from).collect();
        a.extend(self.fields.iter().map(|f| f.name.clone()));
        a
    }

    /// The scalar field named `name` (see [`Field::is_named`]).
    pub fn field(&self, name: &str) -> Option<&Field> {
        self.fields.iter().find(|f| f.is_named(name))
    }

    /// Bounds in the local frame.
    pub fn bounds(&self) -> Bounds {
        use rayon::prelude::*;
        self.positions
            .par_chunks(1 << 16)
            .map(Bounds::from_points)
            .reduce(|| Bounds::EMPTY, Bounds::union)
    }

    /// Bounds in world coordinates (min, max).
    pub fn world_bounds(&self) -> (DVec3, DVec3) {
        let b = self.bounds();
        (
            self.origin + b.min.as_dvec3(),
            self.origin + b.max.as_dvec3(),
        )
    }

    /// Bounds in world coordinates of the cloud's bulk, for framing a view, and how many
    /// stray points lie outside them. A stray point lies farther outside the 1st–99th
    /// percentile box (per axis, on a sample of at most 2^16 points) than twice that box's
    /// largest side: a point at 1e9 or at the origin of a georeferenced tile (an invalid
    /// return), which would otherwise shrink the cloud to a dot. A cloud with no such point
    /// gets exactly [`Self::world_bounds`]; one whose bulk has no extent keeps all its
    /// points.
    pub fn framing_bounds(&self) -> (DVec3, DVec3, usize) {
        use rayon::prelude::*;
        let Some((lo, hi)) = bulk_box(&self.positions, |p: &Vec3| p.as_dvec3()) else {
            let (lo, hi) = self.world_bounds();
            return (lo, hi, 0);
        };
        // In the local frame (the box's f32 rounding moves its sides by far less than the
        // two sides' margin); one pass gives the bulk's bounds and, without strays, the
        // whole cloud's.
        let (lo, hi) = (lo.as_vec3(), hi.as_vec3());
        let keep = |p: &Vec3| p.cmpge(lo).all() && p.cmple(hi).all();
        let (b, strays) = self
            .positions
            .par_chunks(1 << 16)
            .map(|c| {
                let mut b = Bounds::EMPTY;
                let mut s = 0usize;
                for p in c {
                    if keep(p) {
                        b = b.including(*p);
                    } else {
                        s += 1;
                    }
                }
                (b, s)
            })
            .reduce(|| (Bounds::EMPTY, 0), |x, y| (x.0.union(y.0), x.1 + y.1));
        (
            self.origin + b.min.as_dvec3(),
            self.origin + b.max.as_dvec3(),
            strays,
        )
    }

    /// Keeps the points whose flag in `keep` is set (one flag per point), in order, with every
    /// column; faces through a point left out go, the others are re-indexed.
    pub fn retain(&mut self, keep: &[bool]) {
        use crate::lookup::retain;
        let n = self.len();
        assert_eq!(keep.len(), n, "one flag per point");
        retain(&mut self.positions, keep);
        if let Some(c) = self.normals.as_mut() {
            retain(c, keep);
        }
        if let Some(c) = self.colors.as_mut() {
            retain(c, keep);
        }
        if let Some(c) = self.intensity.as_mut() {
            retain(c, keep);
        }
        if let Some(c) = self.classification.as_mut() {
            retain(c, keep);
        }
        if let Some(c) = self.return_number.as_mut() {
            retain(c, keep);
        }
        if let Some(c) = self.opacity.as_mut() {
            retain(c, keep);
        }
        if let Some(c) = self.radius.as_mut() {
            retain(c, keep);
        }
        if let Some(c) = self.sensor_dirs.as_mut() {
            retain(c, keep);
        }
        for f in &mut self.fields {
            retain(&mut f.values, keep);
        }
        if !self.faces.is_empty() {
            let mut new = vec![u32::MAX; n];
            let mut k = 0u32;
            for (i, &kp) in keep.iter().enumerate() {
                if kp {
                    new[i] = k;
                    k += 1;
                }
            }
            self.faces = self
                .faces
                .iter()
                .filter_map(|f| {
                    let g = f.map(|v| new.get(v as usize).copied().unwrap_or(u32::MAX));
                    g.iter().all(|&v| v != u32::MAX).then_some(g)
                })
                .collect();
        }
    }

    /// Appends another cloud, re-expressing its positions relative to this cloud's origin.
    /// Attribute columns present in only one of the two are filled with neutral values.
    pub fn append(&mut self, other: &PointCloud) {
        let n0 = self.len();
        let n1 = other.len();
        let shift = (other.origin - self.origin).as_vec3();
        fn merge<T: Clone>(a: &mut Option<Vec<T>>, b: &Option<Vec<T>>, n0: usize, n1: usize, d: T) {
            match (a.as_mut(), b) {
                (None, None) => {}
                (Some(a), Some(b)) => a.extend_from_slice(b),
                (Some(a), None) => a.extend(std::iter::repeat_n(d, n1)),
                (None, Some(b)) => {
                    let mut v = vec![d; n0];
                    v.extend_from_slice(b);
                    *a = Some(v);
                }
            }
        }
        self.positions
            .extend(other.positions.iter().map(|&p| p + shift));
        merge(&mut self.normals, &other.normals, n0, n1, Vec3::Z);
        merge(&mut self.colors, &other.colors, n0, n1, [255, 255, 255]);
        merge(&mut self.intensity, &other.intensity, n0, n1, 0);
        merge(&mut self.classification, &other.classification, n0, n1, 0);
        merge(&mut self.return_number, &other.return_number, n0, n1, 1);
        merge(&mut self.opacity, &other.opacity, n0, n1, 1.0);
        merge(&mut self.sensor_dirs, &other.sensor_dirs, n0, n1, [0; 3]);
        // Radii are only meaningful where every point has one.
        match (self.radius.as_mut(), &other.radius) {
            (Some(a), Some(b)) => a.extend_from_slice(b),
            _ => self.radius = None,
        }
        // Scalar fields by name; points without one get NaN (no value).
        for f in &mut self.fields {
            match other.fields.iter().find(|g| g.name == f.name) {
                Some(g) => {
                    let d = (g.offset - f.offset) as f32;
                    f.values.extend(g.values.iter().map(|&v| v + d));
                }
                None => f.values.extend(std::iter::repeat_n(f32::NAN, n1)),
            }
        }
        for g in &other.fields {
            if self.fields.len() < MAX_FIELDS && !self.fields.iter().any(|f| f.name == g.name) {
                let mut values = vec![f32::NAN; n0];
                values.extend_from_slice(&g.values);
                self.fields.push(Field {
                    name: g.name.clone(),
                    offset: g.offset,
                    values,
                });
            }
        }
        self.faces
            .extend(other.faces.iter().map(|f| f.map(|v| v + n0 as u32)));
        // Trusted only where every point's normal is.
        self.normals_trusted = (self.normals_trusted || n0 == 0) && other.normals_trusted;
    }

    /// Estimates the typical distance between neighbouring points (the median nearest-neighbour
    /// distance), used for defaults such as the layer gap d̃.
    ///
    /// How: the points are hashed into a uniform grid whose cell is twice the spacing expected
    /// for a surface of the bounds' size; 4096 query points find their nearest neighbour in the
    /// 27 surrounding cells. Clouds over 4 M points are estimated on 8 contiguous windows of
    /// 512 K points (files store points in scan or tile order, so a window keeps the local
    /// density, where a subsample would not) and the median over windows is returned.
    /// Exact duplicates are ignored. Deterministic.
    pub fn estimate_spacing(&self) -> f32 {
        const EXACT_MAX: usize = 4 << 20;
        const WINDOWS: usize = 8;
        const WINDOW: usize = 512 << 10;
        let n = self.len();
        if n <= EXACT_MAX {
            return spacing_of(&self.positions);
        }
        let step = (n - WINDOW) / (WINDOWS - 1);
        let mut est: Vec<f32> = (0..WINDOWS)
            .map(|w| spacing_of(&self.positions[w * step..w * step + WINDOW]))
            .filter(|&s| s > 0.0)
            .collect();
        if est.is_empty() {
            return 0.0;
        }
        est.sort_unstable_by(f32::total_cmp);
        est[est.len() / 2]
    }
}

fn spacing_of(pts: &[Vec3]) -> f32 {
    const QUERIES: usize = 4096;
    let m = pts.len();
    if m < 2 {
        return 0.0;
    }
    let b = Bounds::from_points(pts);
    let e = b.extent();
    if e == Vec3::ZERO {
        // Every point at one position: no spacing.
        return 0.0;
    }
    let area = e.x * e.y + e.y * e.z + e.z * e.x;
    let mut cell = 2.0 * (area / m as f32).sqrt();
    if !(cell > 0.0 && cell.is_finite()) {
        cell = (b.diagonal() / m as f32).max(f32::MIN_POSITIVE);
    }
    if !(cell > 0.0 && cell.is_finite()) {
        return 0.0;
    }
    let qstride = m.div_ceil(QUERIES).max(1);
    for _attempt in 0..8 {
        if let Some(d) = median_nn(pts, b.min, cell, qstride) {
            return d;
        }
        cell *= 4.0;
    }
    0.0
}

fn median_nn(pts: &[Vec3], min: Vec3, cell: f32, qstride: usize) -> Option<f32> {
    use rayon::prelude::*;
    const PER_CELL: usize = 256;
    const LIM: i64 = 1 << 20;
    let key_of =
        |c: [i64; 3]| -> u64 { ((c[0] as u64) << 42) | ((c[1] as u64) << 21) | (c[2] as u64) };
    let cell_of = |p: Vec3| -> [i64; 3] {
        let c = ((p - min) / cell).floor();
        [
            (c.x as i64).clamp(0, LIM - 1),
            (c.y as i64).clamp(0, LIM - 1),
            (c.z as i64).clamp(0, LIM - 1),
        ]
    };
    let mut keyed: Vec<(u64, u32)> = pts
        .par_iter()
        .enumerate()
        .map(|(i, &p)| (key_of(cell_of(p)), i as u32))
        .collect();
    keyed.par_sort_unstable();
    let queries: Vec<usize> = (0..pts.len()).step_by(qstride).collect();
    let found: Vec<f32> = queries
        .par_iter()
        .filter_map(|&qi| {
            let q = pts[qi];
            let c = cell_of(q);
            let mut best = f32::INFINITY;
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let cc = [c[0] + dx, c[1] + dy, c[2] + dz];
                        if cc.iter().any(|&v| !(0..LIM).contains(&v)) {
                            continue;
                        }
                        let k = key_of(cc);
                        let s = keyed.partition_point(|e| e.0 < k);
                        // At most PER_CELL points of a cell: cells are sized for a few points
                        // each, and only duplicates pile up (440 000 coinciding points made
                        // this quadratic: 51 s).
                        for &(kk, j) in keyed[s..].iter().take(PER_CELL) {
                            if kk != k {
                                break;
                            }
                            let d2 = (pts[j as usize] - q).length_squared();
                            if d2 > 0.0 && d2 < best {
                                best = d2;
                            }
                        }
                    }
                }
            }
            (best <= cell * cell).then(|| best.sqrt())
        })
        .collect();
    // Trust the estimate only when most queries found a neighbour within one cell.
    if found.len() * 2 < queries.len() {
        return None;
    }
    let mut found = found;
    found.sort_unstable_by(f32::total_cmp);
    Some(found[found.len() / 2])
}

#[cfg(test)]
mod tests {
    /// A sensor whose pose looks away from its points (PCL's Kinect frames) is turned round
    /// with its up; one that faces them, or no sensor, is left as it is.
    #[test]
    fn a_sensor_is_turned_to_face_its_points() {
        use super::*;
        let pts: Vec<DVec3> = (0..100)
            .map(|i| DVec3::new(i as f64 * 0.01, 0.0, 2.0 + (i % 7) as f64 * 0.1))
            .collect();
        let looking = |z: f64| Sensor {
            position: DVec3::ZERO,
            forward: DVec3::new(0.0, 0.0, z),
            up: DVec3::new(0.0, -z, 0.0),
        };
        let mut c = PointCloud::from_world(&pts);
        c.sensor = Some(looking(-1.0));
        c.face_sensor_to_points();
        assert_eq!(c.sensor, Some(looking(1.0)));
        c.face_sensor_to_points();
        assert_eq!(c.sensor, Some(looking(1.0)));
        c.sensor = None;
        c.face_sensor_to_points();
        assert_eq!(c.sensor, None);
    }

    use super::*;

    /// Framing leaves out only points far outside the bulk: a georeferenced tile's stray
    /// points at the origin and at 1e9 go, a second cluster as large as the first stays, and
    /// a cloud without strays (or with all but a few points coinciding) keeps its bounds.
    #[test]
    fn framing_leaves_out_only_far_strays() {
        let mut pts: Vec<DVec3> = (0..20_000)
            .map(|i| {
                let (u, v) = ((i % 200) as f64, (i / 200) as f64);
                DVec3::new(
                    500_000.0 + u,
                    4_000_000.0 + v,
                    100.0 + (u * 0.1).sin() * 5.0,
                )
            })
            .collect();
        let c = PointCloud::from_world(&pts);
        let (lo, hi, strays) = c.framing_bounds();
        assert_eq!(strays, 0);
        assert_eq!((lo, hi), c.world_bounds());
        pts.push(DVec3::ZERO);
        pts.push(DVec3::ZERO);
        pts.push(DVec3::splat(1e9));
        let c = PointCloud::from_world(&pts);
        let (lo, hi, strays) = c.framing_bounds();
        assert_eq!(strays, 3);
        // The origin is the bulk's centre, so that the bulk keeps its precision.
        assert!((c.origin - DVec3::new(500_100.0, 4_000_050.0, 100.0)).length() < 1.0);
        assert!(
            (lo - DVec3::new(500_000.0, 4_000_000.0, 95.0))
                .abs()
                .max_element()
                < 0.01
        );
        assert!(
            (hi - DVec3::new(500_199.0, 4_000_099.0, 105.0))
                .abs()
                .max_element()
                < 0.01
        );
        // Two clusters of equal size, far apart: both are the bulk.
        let two: Vec<Vec3> = (0..2000)
            .map(|i| {
                Vec3::new(
                    (i % 1000) as f32 * 1e-3 + (i / 1000) as f32 * 100.0,
                    0.0,
                    0.0,
                )
            })
            .collect();
        let c = PointCloud::from_positions(two);
        assert_eq!(c.framing_bounds().2, 0);
        // All but a few points coincide: the bulk has no extent, nothing is left out.
        let mut same = vec![Vec3::ONE; 1000];
        same.push(Vec3::splat(50.0));
        let c = PointCloud::from_positions(same);
        assert_eq!(
            c.framing_bounds(),
            (c.world_bounds().0, c.world_bounds().1, 0)
        );
    }

    /// Coinciding points: all at one position (no spacing), and a grid with a pile of
    /// duplicates on one of its points (the grid's spacing). Both used to scan every
    /// duplicate for every query (51 s for 440 000 coinciding points; now milliseconds).
    #[test]
    fn spacing_of_degenerate_clouds() {
        let same = PointCloud::from_positions(vec![Vec3::new(1.0, 2.0, 3.0); 300_000]);
        assert_eq!(same.estimate_spacing(), 0.0);
        let mut pts = vec![Vec3::new(0.5, 0.5, 0.0); 300_000];
        for i in 0..100 {
            for j in 0..100 {
                pts.push(Vec3::new(i as f32 * 0.01, j as f32 * 0.01, 0.0));
            }
        }
        let s = PointCloud::from_positions(pts).estimate_spacing();
        assert!(s > 0.0 && s <= 0.0101, "spacing {s}");
    }

    #[test]
    fn spacing_of_a_regular_grid() {
        let mut pts = Vec::new();
        for i in 0..200 {
            for j in 0..200 {
                pts.push(Vec3::new(i as f32 * 0.01, j as f32 * 0.01, 0.0));
            }
        }
        let s = PointCloud::from_positions(pts).estimate_spacing();
        assert!((s - 0.01).abs() < 1e-4, "spacing {s}");
    }

    #[test]
    fn spacing_of_a_large_grid_from_windows() {
        // 2100 x 2100 = 4.4 M points: the estimate comes from windows of the cloud.
        let mut pts = Vec::with_capacity(2100 * 2100);
        for i in 0..2100 {
            for j in 0..2100 {
                pts.push(Vec3::new(i as f32 * 0.002, j as f32 * 0.002, 0.0));
            }
        }
        let s = PointCloud::from_positions(pts).estimate_spacing();
        assert!((s - 0.002).abs() < 2e-5, "spacing {s}");
    }

    #[test]
    fn world_precision_is_kept_for_lidar_coordinates() {
        let w = [
            DVec3::new(637_000.123, 850_000.456, 12.789),
            DVec3::new(638_000.001, 851_000.002, 100.003),
        ];
        let c = PointCloud::from_world(&w);
        for (i, p) in w.iter().enumerate() {
            assert!((c.world(i) - *p).abs().max_element() < 1e-3);
        }
    }

    #[test]
    fn validate_reports_problems() {
        assert_eq!(PointCloud::default().validate(), Err(CloudError::Empty));
        let mut c = PointCloud::from_positions(vec![Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0)]);
        assert!(matches!(
            c.validate(),
            Err(CloudError::NonFinite { index: 1, .. })
        ));
        c.positions[1] = Vec3::ONE;
        c.colors = Some(vec![[0; 3]]);
        assert!(matches!(
            c.validate(),
            Err(CloudError::LengthMismatch { name: "colors", .. })
        ));
        c.colors = None;
        c.faces.push([0, 1, 2]);
        assert!(matches!(
            c.validate(),
            Err(CloudError::BadFace { vertex: 2, .. })
        ));
    }

    #[test]
    fn append_merges_columns_and_origins() {
        let mut a = PointCloud::from_world(&[DVec3::new(10.0, 0.0, 0.0)]);
        let mut b = PointCloud::from_world(&[DVec3::new(20.0, 0.0, 0.0)]);
        b.colors = Some(vec![[1, 2, 3]]);
        a.append(&b);
        assert_eq!(a.len(), 2);
        assert!((a.world(1).x - 20.0).abs() < 1e-6);
        assert_eq!(
            a.colors.as_ref().unwrap(),
            &vec![[255, 255, 255], [1, 2, 3]]
        );
        a.validate().unwrap();
        b.append(&a.clone());
        assert_eq!(b.len(), 3);
    }
}
