//! The camera convention shared by every backend (see `DESIGN.md`, "Conventions").
//!
//! * World right-handed; view space looks down −Z; aspect = W/H; `fov` is vertical, in degrees.
//! * Pixel (i, j): column i from the left, row j from the top; its centre ray passes through
//!   NDC x = 2(i+0.5)/W − 1, y = 1 − 2(j+0.5)/H.
//! * Depth = view-axis depth dot(p − eye, forward), positive in front.

use crate::cloud::Bounds;
use glam::{DMat4, DVec3, DVec4};
use serde::Serialize;

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "lowercase", tag = "kind")]
pub enum Projection {
    /// Vertical field of view in degrees.
    Perspective { fov_deg: f64 },
    /// Height of the view volume in world units.
    Orthographic { height: f64 },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub eye: DVec3,
    pub target: DVec3,
    pub up: DVec3,
    pub projection: Projection,
    pub width: u32,
    pub height: u32,
    pub near: f64,
    pub far: f64,
}

/// Orthonormal camera basis: `forward` points from the eye towards the target.
/// Where the default framing looks from, relative to the cloud's up axis: +Y up (scanned
/// objects, whose front conventionally faces +Z; the command line frames one that faces −Z
/// from behind, see [`faces_negative_z`]) or +Z up (LiDAR, with north along +Y).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum View {
    /// A three-quarter view from the front, a little from the right and above (Y up); a
    /// LiDAR tile from the south, raised about 40°.
    #[default]
    ThreeQuarter,
    /// The same from behind (a model that faces −Z, such as the Stanford Lucy).
    ThreeQuarterBack,
    /// Straight from the front: from +Z (Y up), from the south (Z up).
    Front,
    /// Straight from behind.
    Back,
    /// From the left (−X).
    Left,
    /// From the right (+X).
    Right,
    /// From above: a plan (Z up: a map, north up; Y up: the front at the bottom).
    Top,
    /// From below.
    Bottom,
}

impl View {
    /// The up vector and the unit direction from the target towards the eye.
    pub fn direction(self, z_up: bool) -> (DVec3, DVec3) {
        // (right, up, front) axes of the cloud.
        let (r, u, f) = if z_up {
            (DVec3::X, DVec3::Z, DVec3::NEG_Y)
        } else {
            (DVec3::X, DVec3::Y, DVec3::Z)
        };
        let d = match self {
            View::ThreeQuarter if z_up => f + 0.8 * u,
            View::ThreeQuarter => 0.45 * r + 0.35 * u + f,
            View::ThreeQuarterBack if z_up => -f + 0.8 * u,
            View::ThreeQuarterBack => -0.45 * r + 0.35 * u - f,
            View::Front => f,
            View::Back => -f,
            View::Left => -r,
            View::Right => r,
            View::Top => u,
            View::Bottom => -u,
        };
        // Looking along the up axis, the image's up is the cloud's back (a map: north).
        let up = match self {
            View::Top => -f,
            View::Bottom => f,
            _ => u,
        };
        (up, d.normalize())
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Basis {
    pub right: DVec3,
    pub up: DVec3,
    pub forward: DVec3,
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CameraError {
    #[error("image size {0}x{1} is invalid: both sides must be between 1 and 16384")]
    BadSize(u32, u32),
    #[error("eye and target coincide")]
    EyeIsTarget,
    #[error("the up vector is parallel to the viewing direction")]
    UpParallel,
    #[error("field of view {0}° must lie strictly between 0 and 180")]
    BadFov(f64),
    #[error("orthographic height {0} must be positive")]
    BadOrtho(f64),
    #[error("the camera's {0} is not finite (NaN or infinite)")]
    NonFinite(&'static str),
}

pub const MAX_SIDE: u32 = 16384;

impl Camera {
    pub fn aspect(&self) -> f64 {
        self.width as f64 / self.height as f64
    }

    pub fn validate(&self) -> Result<(), CameraError> {
        if self.width == 0 || self.height == 0 || self.width > MAX_SIDE || self.height > MAX_SIDE {
            return Err(CameraError::BadSize(self.width, self.height));
        }
        // The projection first: a bad field of view makes a framed eye infinite, and the
        // error should name the cause.
        match self.projection {
            Projection::Perspective { fov_deg } if !(fov_deg > 0.0 && fov_deg < 180.0) => {
                return Err(CameraError::BadFov(fov_deg))
            }
            Projection::Orthographic { height } if !(height > 0.0 && height.is_finite()) => {
                return Err(CameraError::BadOrtho(height))
            }
            _ => {}
        }
        for (what, v) in [
            ("eye", self.eye),
            ("target", self.target),
            ("up vector", self.up),
        ] {
            if !v.is_finite() {
                return Err(CameraError::NonFinite(what));
            }
        }
        if (self.target - self.eye).length() <= 1e-12 * (1.0 + self.eye.length()) {
            return Err(CameraError::EyeIsTarget);
        }
        let f = (self.target - self.eye).normalize();
        if self.up.length() == 0.0 || f.cross(self.up.normalize()).length() < 1e-9 {
            return Err(CameraError::UpParallel);
        }
        Ok(())
    }

    pub fn basis(&self) -> Basis {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        Basis { right, up, forward }
    }

    /// A camera that frames world bounds `[lo, hi]`: it looks at their centre from a fixed
    /// direction (Y-up: a three-quarter view from +Z; Z-up: from −Y, raised about 40°, so a
    /// rectangular tile faces the image squarely and fills it), as close as the eight
    /// corners of the box allow (they fill 95% of the frame). The up axis is +Y, or +Z when the bounds are flat in Z (LiDAR
    /// tiles); [`Camera::framing_up`] takes the source's word for it.
    pub fn framing(lo: DVec3, hi: DVec3, width: u32, height: u32, fov_deg: f64) -> Camera {
        Camera::framing_up(lo, hi, width, height, fov_deg, false)
    }

    /// [`Camera::framing`] with `z_up` when the source says +Z is up (LAS/LAZ/COPC).
    pub fn framing_up(
        lo: DVec3,
        hi: DVec3,
        width: u32,
        height: u32,
        fov_deg: f64,
        z_up: bool,
    ) -> Camera {
        Camera::framing_view(lo, hi, width, height, fov_deg, z_up, View::default())
    }

    /// Whether the default framing takes +Z as up for bounds `lo`..`hi`: the source says so
    /// (`z_up`: LAS/LAZ/COPC), or the bounds are flat in Z (a LiDAR tile in another format).
    pub fn frames_z_up(lo: DVec3, hi: DVec3, z_up: bool) -> bool {
        let e = hi - lo;
        z_up || e.z < 0.35 * e.x.min(e.y)
    }

    /// [`Camera::framing_up`] from a named direction ([`View`]).
    pub fn framing_view(
        lo: DVec3,
        hi: DVec3,
        width: u32,
        height: u32,
        fov_deg: f64,
        z_up: bool,
        view: View,
    ) -> Camera {
        let c = (lo + hi) * 0.5;
        let e = hi - lo;
        let z_up = Camera::frames_z_up(lo, hi, z_up);
        let (up, dir) = view.direction(z_up);
        let r = (e.length() * 0.5).max(1e-6);
        let aspect = width as f64 / height.max(1) as f64;
        let half_v = (fov_deg.to_radians() * 0.5).min(1.5);
        let half_h = (half_v.tan() * aspect).atan();
        let dist = r / half_v.min(half_h).sin() * 1.02;
        let mut cam = Camera {
            eye: c + dir * dist,
            target: c,
            up,
            projection: Projection::Perspective { fov_deg },
            width,
            height,
            near: 0.0,
            far: 0.0,
        };
        // The bounding sphere always fits; move closer while the eight box corners still
        // project inside 95% of the frame (bisection on the distance).
        let fits = |d: f64| {
            let cam = Camera {
                eye: c + dir * d,
                ..cam.clone()
            };
            (0..8).all(|k| {
                let p = DVec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                );
                match cam.project(p) {
                    Some((x, y, z)) => {
                        let (w, h) = (width as f64, height as f64);
                        z > 0.0
                            && (x - w / 2.0).abs() <= 0.475 * w
                            && (y - h / 2.0).abs() <= 0.475 * h
                    }
                    None => false,
                }
            })
        };
        let (mut near_d, mut far_d) = (r * 1e-3, dist);
        for _ in 0..8 {
            if fits(far_d) {
                break;
            }
            far_d *= 1.5;
        }
        if fits(far_d) {
            for _ in 0..40 {
                let mid = 0.5 * (near_d + far_d);
                if fits(mid) {
                    far_d = mid;
                } else {
                    near_d = mid;
                }
            }
            cam.eye = c + dir * far_d;
        }
        cam.fit_clip(lo, hi);
        cam
    }

    /// Sets near and far from the world bounds so that every point in them is inside the
    /// view volume's depth range: far = the farthest corner (+1%); near = the nearest corner
    /// (−1%), never below far·1e-5 (the camera may sit inside the bounds).
    pub fn fit_clip(&mut self, lo: DVec3, hi: DVec3) {
        let f = self.basis().forward;
        let b = Bounds {
            min: glam::Vec3::ZERO,
            max: (hi - lo).as_vec3(),
        };
        let (mut dmin, mut dmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for corner in b.corners() {
            let d = (lo + corner.as_dvec3() - self.eye).dot(f);
            dmin = dmin.min(d);
            dmax = dmax.max(d);
        }
        let far = (dmax * 1.01).max(1e-6);
        let near = match self.projection {
            // An orthographic camera can see behind the eye plane; keep it simple and start
            // at the nearest corner.
            Projection::Orthographic { .. } => dmin - 0.01 * (dmax - dmin).abs() - 1e-6,
            Projection::Perspective { .. } => (dmin * 0.99).max(far * 1e-5),
        };
        self.near = near;
        self.far = far.max(near + 1e-6);
    }

    /// World → view matrix (right-handed, looking down −Z).
    pub fn view_matrix(&self) -> DMat4 {
        let b = self.basis();
        let e = self.eye;
        DMat4::from_cols(
            DVec4::new(b.right.x, b.up.x, -b.forward.x, 0.0),
            DVec4::new(b.right.y, b.up.y, -b.forward.y, 0.0),
            DVec4::new(b.right.z, b.up.z, -b.forward.z, 0.0),
            DVec4::new(-b.right.dot(e), -b.up.dot(e), b.forward.dot(e), 1.0),
        )
    }

    /// View → clip matrix, depth mapped to [0, 1] (the wgpu convention).
    pub fn projection_matrix(&self) -> DMat4 {
        let (sx, sy) = self.ndc_scale();
        let (n, f) = (self.near, self.far);
        match self.projection {
            Projection::Perspective { .. } => DMat4::from_cols(
                DVec4::new(sx, 0.0, 0.0, 0.0),
                DVec4::new(0.0, sy, 0.0, 0.0),
                DVec4::new(0.0, 0.0, f / (n - f), -1.0),
                DVec4::new(0.0, 0.0, n * f / (n - f), 0.0),
            ),
            Projection::Orthographic { .. } => DMat4::from_cols(
                DVec4::new(sx, 0.0, 0.0, 0.0),
                DVec4::new(0.0, sy, 0.0, 0.0),
                DVec4::new(0.0, 0.0, 1.0 / (n - f), 0.0),
                DVec4::new(0.0, 0.0, n / (n - f), 1.0),
            ),
        }
    }

    /// NDC scale factors: ndc = (x·sx, y·sy) / z for perspective (z = view depth),
    /// (x·sx, y·sy) for orthographic.
    pub fn ndc_scale(&self) -> (f64, f64) {
        match self.projection {
            Projection::Perspective { fov_deg } => {
                let t = (fov_deg.to_radians() * 0.5).tan();
                (1.0 / (t * self.aspect()), 1.0 / t)
            }
            Projection::Orthographic { height } => (2.0 / (height * self.aspect()), 2.0 / height),
        }
    }

    /// Projects a world point: `(column, row, depth)` in continuous pixel units, or `None`
    /// behind the eye plane (perspective).
    pub fn project(&self, p: DVec3) -> Option<(f64, f64, f64)> {
        let b = self.basis();
        let v = p - self.eye;
        let z = v.dot(b.forward);
        let (sx, sy) = self.ndc_scale();
        let (nx, ny) = match self.projection {
            Projection::Perspective { .. } => {
                if z <= 0.0 {
                    return None;
                }
                (v.dot(b.right) * sx / z, v.dot(b.up) * sy / z)
            }
            Projection::Orthographic { .. } => (v.dot(b.right) * sx, v.dot(b.up) * sy),
        };
        Some((
            (nx + 1.0) * 0.5 * self.width as f64,
            (1.0 - ny) * 0.5 * self.height as f64,
            z,
        ))
    }

    /// The ray through the centre of pixel (i, j): origin and unit direction (world).
    pub fn pixel_ray(&self, i: u32, j: u32) -> (DVec3, DVec3) {
        let b = self.basis();
        let (sx, sy) = self.ndc_scale();
        let nx = 2.0 * (i as f64 + 0.5) / self.width as f64 - 1.0;
        let ny = 1.0 - 2.0 * (j as f64 + 0.5) / self.height as f64;
        match self.projection {
            Projection::Perspective { .. } => {
                let d = b.forward + b.right * (nx / sx) + b.up * (ny / sy);
                (self.eye, d.normalize())
            }
            Projection::Orthographic { .. } => {
                (self.eye + b.right * (nx / sx) + b.up * (ny / sy), b.forward)
            }
        }
    }

    /// The camera as JSON (DESIGN.md): eye, target, up, fov, size, near, far, and the view
    /// and projection matrices as row-major 4×4 arrays.
    pub fn to_json(&self) -> String {
        fn rows(m: DMat4) -> [[f64; 4]; 4] {
            let t = m.transpose();
            let r = |v: DVec4| v.to_array();
            [r(t.x_axis), r(t.y_axis), r(t.z_axis), r(t.w_axis)]
        }
        let (fov, ortho) = match self.projection {
            Projection::Perspective { fov_deg } => (Some(fov_deg), None),
            Projection::Orthographic { height } => (None, Some(height)),
        };
        let v = serde_json::json!({
            "eye": self.eye.to_array(),
            "target": self.target.to_array(),
            "up": self.up.to_array(),
            "fov": fov,
            "ortho_height": ortho,
            "projection_kind": if ortho.is_some() { "orthographic" } else { "perspective" },
            "size": [self.width, self.height],
            "near": self.near,
            "far": self.far,
            "view": rows(self.view_matrix()),
            "projection": rows(self.projection_matrix()),
            "depth": "view-axis distance dot(p - eye, forward); background +inf",
        });
        serde_json::to_string_pretty(&v).expect("camera JSON is always serialisable")
    }
}

/// Whether a scanned object (Y up) faces −Z rather than +Z, the convention the default
/// framing assumes: the side from which more of its samples are in view is its front. A
/// scan is densest where the scanner looked most, and a simplified mesh keeps most vertices
/// where the detail is (a face, hands, folds), so the front shows more samples than the
/// back, whose silhouette is the same. The samples (up to 200 000, evenly strided) are
/// binned on a grid over X–Y of about 1.5 samples a cell; from +Z a sample is in view when
/// it lies within two cells of the largest z in its cell, from −Z of the smallest. −Z wins
/// only by more than 5%: the Stanford Lucy 9.8% and Armadillo 10.7% (both face −Z), the
/// bunny −4%, the Dragon −0.9%, the Happy Buddha 0% (all three face +Z); a symmetric
/// object keeps +Z.
pub fn faces_negative_z(positions: &[glam::Vec3]) -> bool {
    let n = positions.len();
    if n < 16 {
        return false;
    }
    let step = n / 200_000 + 1;
    let pts = || positions.iter().step_by(step).filter(|p| p.is_finite());
    let (mut lo, mut hi) = (glam::Vec3::splat(f32::MAX), glam::Vec3::splat(f32::MIN));
    let mut m = 0usize;
    for p in pts() {
        lo = lo.min(*p);
        hi = hi.max(*p);
        m += 1;
    }
    let e = (hi.x - lo.x).max(hi.y - lo.y);
    if m < 16 || e <= 0.0 || !e.is_finite() {
        return false;
    }
    let res = ((m as f64 / 1.5).sqrt() as usize).clamp(32, 512);
    let cell = e / res as f32;
    let at = |p: &glam::Vec3| {
        let i = (((p.x - lo.x) / cell) as usize).min(res - 1);
        let j = (((p.y - lo.y) / cell) as usize).min(res - 1);
        j * res + i
    };
    let mut top = vec![f32::MIN; res * res];
    let mut bottom = vec![f32::MAX; res * res];
    for p in pts() {
        let k = at(p);
        top[k] = top[k].max(p.z);
        bottom[k] = bottom[k].min(p.z);
    }
    let (mut plus, mut minus) = (0usize, 0usize);
    for p in pts() {
        let k = at(p);
        plus += (p.z >= top[k] - 2.0 * cell) as usize;
        minus += (p.z <= bottom[k] + 2.0 * cell) as usize;
    }
    minus as f64 > 1.05 * plus as f64
}

impl Camera {
    /// Reads the camera JSON that [`Camera::to_json`] writes (`stipple render --camera-out`):
    /// eye, target, up, size, `fov` or `ortho_height`, near and far (the matrices are
    /// derived, so they are not read). The camera is validated.
    pub fn from_json(text: &str) -> Result<Camera, String> {
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
        let num = |k: &str| -> Result<Option<f64>, String> {
            match v.get(k) {
                None | Some(serde_json::Value::Null) => Ok(None),
                Some(x) => x
                    .as_f64()
                    .map(Some)
                    .ok_or_else(|| format!("`{k}` must be a number")),
            }
        };
        let vec3 = |k: &str| -> Result<DVec3, String> {
            let a = v
                .get(k)
                .and_then(|x| x.as_array())
                .filter(|a| a.len() == 3)
                .ok_or_else(|| format!("`{k}` must be an array of three numbers"))?;
            let c: Option<Vec<f64>> = a.iter().map(|x| x.as_f64()).collect();
            let c = c.ok_or_else(|| format!("`{k}` must be an array of three numbers"))?;
            Ok(DVec3::new(c[0], c[1], c[2]))
        };
        let size = v
            .get("size")
            .and_then(|x| x.as_array())
            .filter(|a| a.len() == 2)
            .and_then(|a| Some((a[0].as_u64()?, a[1].as_u64()?)))
            .ok_or("`size` must be [width, height] in pixels")?;
        let side = |x: u64| u32::try_from(x).unwrap_or(u32::MAX);
        let projection = match (num("fov")?, num("ortho_height")?) {
            (Some(f), None) => Projection::Perspective { fov_deg: f },
            (None, Some(h)) => Projection::Orthographic { height: h },
            _ => return Err("give exactly one of `fov` and `ortho_height`".into()),
        };
        let cam = Camera {
            eye: vec3("eye")?,
            target: vec3("target")?,
            up: vec3("up")?,
            projection,
            width: side(size.0),
            height: side(size.1),
            near: num("near")?.ok_or("`near` is missing")?,
            far: num("far")?.ok_or("`far` is missing")?,
        };
        cam.validate().map_err(|e| e.to_string())?;
        if !(cam.near.is_finite() && cam.far.is_finite() && cam.far > cam.near) {
            return Err(format!(
                "near {} and far {} must be finite with far > near",
                cam.near, cam.far
            ));
        }
        Ok(cam)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sphere sampled `dense` times as densely on its −Z half as on its +Z half faces −Z
    /// when `dense` is well above 1; evenly sampled, or denser on +Z, it keeps +Z.
    #[test]
    fn the_front_is_the_side_showing_more_samples() {
        let sphere = |dense: f64, flip: bool| {
            let mut r = 0x2545_f491_4f6c_dd1du64;
            let mut u = || {
                r ^= r << 13;
                r ^= r >> 7;
                r ^= r << 17;
                (r >> 11) as f64 / (1u64 << 53) as f64
            };
            let mut p = Vec::new();
            while p.len() < 60_000 {
                let z = 2.0 * u() - 1.0;
                let a = std::f64::consts::TAU * u();
                // Keep a +Z sample with probability 1/dense.
                if z > 0.0 && u() * dense > 1.0 {
                    continue;
                }
                let s = (1.0 - z * z).sqrt();
                let z = if flip { -z } else { z };
                p.push(glam::Vec3::new(
                    (s * a.cos()) as f32,
                    (s * a.sin()) as f32,
                    z as f32,
                ));
            }
            p
        };
        assert!(faces_negative_z(&sphere(1.5, false)));
        assert!(!faces_negative_z(&sphere(1.5, true)));
        assert!(!faces_negative_z(&sphere(1.0, false)));
        assert!(!faces_negative_z(&sphere(1.0, true)));
        assert!(!faces_negative_z(&[]));
        assert!(!faces_negative_z(&[glam::Vec3::ONE; 100]));
    }

    #[test]
    fn json_round_trips_and_bad_json_is_refused() {
        for c in [
            cam(),
            Camera {
                projection: Projection::Orthographic { height: 3.0 },
                ..cam()
            },
        ] {
            assert_eq!(Camera::from_json(&c.to_json()).unwrap(), c);
        }
        assert!(Camera::from_json("{").is_err());
        let no_size = cam().to_json().replace("\"size\"", "\"sighs\"");
        assert!(Camera::from_json(&no_size).unwrap_err().contains("size"));
        let bad = cam().to_json().replace("\"far\": 10.0", "\"far\": 0.01");
        assert!(Camera::from_json(&bad).unwrap_err().contains("far"));
    }

    fn cam() -> Camera {
        Camera {
            eye: DVec3::new(0.0, 0.0, 5.0),
            target: DVec3::ZERO,
            up: DVec3::Y,
            projection: Projection::Perspective { fov_deg: 60.0 },
            width: 200,
            height: 100,
            near: 0.1,
            far: 10.0,
        }
    }

    #[test]
    fn pixel_centre_rays_project_back_to_pixel_centres() {
        for c in [
            cam(),
            Camera {
                projection: Projection::Orthographic { height: 3.0 },
                ..cam()
            },
        ] {
            for (i, j) in [(0, 0), (17, 93), (199, 99), (100, 50)] {
                let (o, d) = c.pixel_ray(i, j);
                let (x, y, z) = c.project(o + d * 4.0).unwrap();
                assert!((x - (i as f64 + 0.5)).abs() < 1e-9 && (y - (j as f64 + 0.5)).abs() < 1e-9);
                assert!(z > 0.0);
            }
        }
    }

    #[test]
    fn matrices_agree_with_project() {
        let c = cam();
        let p = DVec3::new(0.7, -0.3, 1.2);
        let clip = c.projection_matrix() * c.view_matrix() * p.extend(1.0);
        let ndc = clip.truncate() / clip.w;
        let (x, y, z) = c.project(p).unwrap();
        assert!(((ndc.x + 1.0) * 0.5 * 200.0 - x).abs() < 1e-9);
        assert!(((1.0 - ndc.y) * 0.5 * 100.0 - y).abs() < 1e-9);
        assert!((z - 3.8).abs() < 1e-12);
    }

    #[test]
    fn framing_sees_every_corner() {
        let lo = DVec3::new(637_000.0, 850_000.0, 10.0);
        let hi = DVec3::new(637_800.0, 850_500.0, 60.0);
        let c = Camera::framing(lo, hi, 640, 480, 45.0);
        c.validate().unwrap();
        assert_eq!(c.up, DVec3::Z);
        for k in 0..8 {
            let p = DVec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            let (x, y, z) = c.project(p).unwrap();
            assert!(
                (0.0..640.0).contains(&x) && (0.0..480.0).contains(&y),
                "{x} {y}"
            );
            assert!(z >= c.near && z <= c.far);
        }
    }

    /// Every named view frames every corner, looks from its side (a plan from above, north
    /// up, for a LiDAR tile; the front from +Z for a Y-up model), and the default is the
    /// three-quarter view.
    #[test]
    fn every_view_frames_from_its_side() {
        let corners = |lo: DVec3, hi: DVec3| {
            (0..8).map(move |k| {
                DVec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                )
            })
        };
        let views = [
            View::ThreeQuarter,
            View::ThreeQuarterBack,
            View::Front,
            View::Back,
            View::Left,
            View::Right,
            View::Top,
            View::Bottom,
        ];
        for (lo, hi, z_up) in [
            (
                DVec3::new(-1.0, -2.0, -0.5),
                DVec3::new(1.0, 2.0, 0.5),
                false,
            ),
            (
                DVec3::new(500.0, 800.0, 10.0),
                DVec3::new(900.0, 1300.0, 60.0),
                true,
            ),
        ] {
            for view in views {
                let c = Camera::framing_view(lo, hi, 320, 240, 45.0, z_up, view);
                c.validate().unwrap();
                for p in corners(lo, hi) {
                    let (x, y, _) = c.project(p).unwrap();
                    assert!(
                        (0.0..320.0).contains(&x) && (0.0..240.0).contains(&y),
                        "{view:?}: {x} {y}"
                    );
                }
                let d = (c.eye - c.target).normalize();
                let (up, front) = if z_up {
                    (DVec3::Z, DVec3::NEG_Y)
                } else {
                    (DVec3::Y, DVec3::Z)
                };
                let want = match view {
                    View::Front => front,
                    View::Back => -front,
                    View::Left => DVec3::NEG_X,
                    View::Right => DVec3::X,
                    View::Top => up,
                    View::Bottom => -up,
                    View::ThreeQuarter => {
                        assert!(d.dot(front) > 0.5 && d.dot(up) > 0.2, "{view:?} {d}");
                        continue;
                    }
                    View::ThreeQuarterBack => {
                        assert!(d.dot(front) < -0.5 && d.dot(up) > 0.2, "{view:?} {d}");
                        continue;
                    }
                };
                assert!((d - want).length() < 1e-12, "{view:?}: {d}");
                if view == View::Top && z_up {
                    // A map: north (+y) at the top of the image.
                    assert_eq!(c.up, DVec3::Y);
                }
            }
        }
        let a = Camera::framing(DVec3::ZERO, DVec3::ONE, 64, 64, 45.0);
        let b = Camera::framing_view(
            DVec3::ZERO,
            DVec3::ONE,
            64,
            64,
            45.0,
            false,
            View::default(),
        );
        assert_eq!(a, b);
    }

    #[test]
    fn validation_rejects_bad_cameras() {
        assert!(matches!(
            Camera { width: 0, ..cam() }.validate(),
            Err(CameraError::BadSize(..))
        ));
        assert_eq!(
            Camera {
                target: cam().eye,
                ..cam()
            }
            .validate(),
            Err(CameraError::EyeIsTarget)
        );
        assert_eq!(
            Camera {
                up: DVec3::Z,
                ..cam()
            }
            .validate(),
            Err(CameraError::UpParallel)
        );
        assert!(matches!(
            Camera {
                projection: Projection::Perspective { fov_deg: 180.0 },
                ..cam()
            }
            .validate(),
            Err(CameraError::BadFov(_))
        ));
    }

    #[test]
    fn json_has_the_fixed_fields() {
        let v: serde_json::Value = serde_json::from_str(&cam().to_json()).unwrap();
        for k in [
            "eye",
            "target",
            "up",
            "fov",
            "size",
            "near",
            "far",
            "view",
            "projection",
        ] {
            assert!(v.get(k).is_some(), "missing {k}");
        }
        assert_eq!(v["view"].as_array().unwrap().len(), 4);
        // Row-major: the translation sits in the last column of the rows.
        assert!((v["view"][2][3].as_f64().unwrap() + 5.0).abs() < 1e-12);
    }
}
