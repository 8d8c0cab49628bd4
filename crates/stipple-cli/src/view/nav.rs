//! Navigation of `stipple view`: how mouse and keys move the camera. Pure camera arithmetic
//! (no window), so it is tested on its own.
//!
//! - **Orbit** (left drag): the eye turns about the target, about the world's up axis (Z for
//!   LiDAR, Y for scanned objects: the up the default camera uses) and the camera's right
//!   axis; the view never tips over the pole (the angle to the up axis stays within 2°–178°).
//! - **Pan** (right or middle drag, or shift + left drag): eye and target move together in
//!   the image plane, so the point under the cursor stays under it at the target's depth.
//! - **Zoom** (wheel): the eye moves towards the target (15% of the distance a notch); an
//!   orthographic view scales its height instead.
//! - **Fly** (W A S D, Q E for down and up): eye and target move together at a speed tied to
//!   the cloud's size (a quarter of its bounding diagonal a second; shift: four times).
//! - **Frame all** (F): back to the camera the view opened with.
//! - **Centre** (double click): the target moves to the picked surface point; the eye stays.
//!
//! After every move near and far are fitted to the cloud's bounds again
//! ([`Camera::fit_clip`]), as `stipple render` does, so the CLI renders a saved camera the
//! same.

use glam::DVec3;
use stipple_core::camera::Projection;
use stipple_core::Camera;

/// Degrees of orbit per pixel of drag.
pub const ORBIT_DEG_PER_PX: f64 = 0.3;
/// The distance to the target kept after a notch of zoom.
pub const ZOOM_STEP: f64 = 0.85;

/// The camera and what moves it.
#[derive(Clone, Debug)]
pub struct Nav {
    pub camera: Camera,
    /// The camera the view opened with (F returns to it).
    pub home: Camera,
    /// The world's up axis for orbits.
    pub up: DVec3,
    /// The cloud's world bounds (near and far are fitted to them).
    pub lo: DVec3,
    pub hi: DVec3,
}

impl Nav {
    pub fn new(camera: Camera, z_up: bool, lo: DVec3, hi: DVec3) -> Nav {
        Nav {
            home: camera.clone(),
            camera,
            up: if z_up { DVec3::Z } else { DVec3::Y },
            lo,
            hi,
        }
    }

    /// The cloud's bounding diagonal (at least a tiny positive length).
    pub fn size(&self) -> f64 {
        (self.hi - self.lo).length().max(1e-9)
    }

    fn refit(&mut self) {
        let f = (self.camera.target - self.camera.eye).normalize_or_zero();
        // Keep the image's up off the viewing direction.
        if f.cross(self.camera.up).length_squared() < 1e-12 {
            self.camera.up = if f.cross(self.up).length_squared() > 1e-12 {
                self.up
            } else {
                f.any_orthonormal_vector()
            };
        }
        self.camera.fit_clip(self.lo, self.hi);
    }

    /// Turns the eye about the target by a drag of (dx, dy) pixels.
    pub fn orbit(&mut self, dx: f64, dy: f64) {
        let c = &mut self.camera;
        let offset = c.eye - c.target;
        let yaw = (-dx * ORBIT_DEG_PER_PX).to_radians();
        let mut o = glam::DQuat::from_axis_angle(self.up, yaw) * offset;
        // Pitch about the right axis, the angle to the up axis kept within 2°–178°.
        let right = self.up.cross(o).normalize_or_zero();
        if right != DVec3::ZERO {
            let angle = o
                .normalize()
                .dot(self.up)
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees();
            let pitch = (dy * ORBIT_DEG_PER_PX).clamp(angle - 178.0, angle - 2.0);
            // About right = up × o a positive angle turns o away from up: a drag down
            // (dy > 0) raises the eye.
            o = glam::DQuat::from_axis_angle(right, -pitch.to_radians()) * o;
        }
        c.eye = c.target + o;
        c.up = self.up;
        self.refit();
    }

    /// World units per pixel at the target's depth.
    pub fn pixel_size(&self) -> f64 {
        let c = &self.camera;
        match c.projection {
            Projection::Perspective { fov_deg } => {
                let d = (c.target - c.eye).length();
                2.0 * d * (fov_deg.to_radians() * 0.5).tan() / c.height as f64
            }
            Projection::Orthographic { height } => height / c.height as f64,
        }
    }

    /// Moves eye and target in the image plane by a drag of (dx, dy) pixels (the content
    /// follows the cursor).
    pub fn pan(&mut self, dx: f64, dy: f64) {
        let s = self.pixel_size();
        let b = self.camera.basis();
        let shift = b.right * (-dx * s) + b.up * (dy * s);
        self.camera.eye += shift;
        self.camera.target += shift;
        self.refit();
    }

    /// Zooms by `notches` (positive: closer).
    pub fn zoom(&mut self, notches: f64) {
        let k = ZOOM_STEP.powf(notches.clamp(-20.0, 20.0));
        let least = self.size() * 1e-6;
        let c = &mut self.camera;
        match &mut c.projection {
            Projection::Perspective { .. } => {
                let o = c.eye - c.target;
                let d = (o.length() * k).max(least);
                c.eye = c.target + o.normalize() * d;
            }
            Projection::Orthographic { height } => *height = (*height * k).max(1e-9),
        }
        self.refit();
    }

    /// Flies for `dt` seconds along the view (forward, right, up in −1..1), `fast` four times
    /// quicker.
    pub fn fly(&mut self, forward: f64, right: f64, up: f64, dt: f64, fast: bool) {
        let speed = 0.25 * self.size() * if fast { 4.0 } else { 1.0 };
        let b = self.camera.basis();
        let shift = (b.forward * forward + b.right * right + self.up * up) * (speed * dt);
        self.camera.eye += shift;
        self.camera.target += shift;
        self.refit();
    }

    /// Back to the opening camera, at the window's current size.
    pub fn frame_all(&mut self) {
        let (w, h) = (self.camera.width, self.camera.height);
        self.camera = self.home.clone();
        self.resize(w, h);
    }

    /// The target moves to `p`; the eye stays.
    pub fn centre_on(&mut self, p: DVec3) {
        if (p - self.camera.eye).length() > self.size() * 1e-9 {
            self.camera.target = p;
            self.refit();
        }
    }

    /// Switches the orbit's up axis between Z (LiDAR) and Y (scanned objects); the image's
    /// up follows it.
    pub fn toggle_up(&mut self) {
        self.up = if self.up == DVec3::Z {
            DVec3::Y
        } else {
            DVec3::Z
        };
        self.camera.up = self.up;
        self.refit();
    }

    /// The window's new size in pixels.
    pub fn resize(&mut self, w: u32, h: u32) {
        self.camera.width = w.clamp(1, stipple_core::camera::MAX_SIDE);
        self.camera.height = h.clamp(1, stipple_core::camera::MAX_SIDE);
        self.refit();
    }
}

/// Reads a camera path: a JSON list of cameras as `--camera-out` writes them (keyframes).
pub fn read_path(text: &str) -> Result<Vec<Camera>, String> {
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    let list = v
        .as_array()
        .ok_or("a camera path is a JSON list of cameras (as --camera-out writes them)")?;
    if list.is_empty() || list.len() > 100_000 {
        return Err(format!("{} cameras: 1 to 100000", list.len()));
    }
    list.iter()
        .enumerate()
        .map(|(k, c)| {
            Camera::from_json(&c.to_string()).map_err(|e| format!("camera {}: {e}", k + 1))
        })
        .collect()
}

/// Frame `k` of `frames` along the keyframes: eye, target and up interpolated linearly
/// between neighbouring keys (the field of view too, between perspective keys), the first
/// frame at the first key and the last at the last.
pub fn path_camera(keys: &[Camera], k: usize, frames: usize) -> Camera {
    let n = keys.len();
    if n == 1 || frames <= 1 {
        return keys[0].clone();
    }
    let t = (k.min(frames - 1) as f64 / (frames - 1) as f64) * (n - 1) as f64;
    let i = (t.floor() as usize).min(n - 2);
    let f = t - i as f64;
    let (a, b) = (&keys[i], &keys[i + 1]);
    let mut c = a.clone();
    c.eye = a.eye.lerp(b.eye, f);
    c.target = a.target.lerp(b.target, f);
    c.up = a.up.lerp(b.up, f).normalize_or(a.up);
    if let (Projection::Perspective { fov_deg: x }, Projection::Perspective { fov_deg: y }) =
        (a.projection, b.projection)
    {
        c.projection = Projection::Perspective {
            fov_deg: x + (y - x) * f,
        };
    }
    c
}

/// The point budget of a tree's next cut while the view moves: a frame of `points` that
/// took `ms` against a target of `target` ms scales it down (to 90% of what fits), a frame
/// well under the target lets it grow by a quarter; within `range` (one node … the full
/// budget).
pub fn next_budget(points: u64, ms: f64, target: f64, current: u64, range: (u64, u64)) -> u64 {
    let next = if ms > target {
        points as f64 * target / ms * 0.9
    } else if ms < 0.5 * target {
        current as f64 * 1.25
    } else {
        current as f64
    };
    (next as u64).clamp(range.0, range.1.max(range.0))
}

/// A point's own position (world, in the file's units with its f64 origin) and attributes,
/// for a pick's report: "" when `id` is not a point of `cloud`.
pub fn describe_point(cloud: &stipple_core::PointCloud, id: u32) -> String {
    let i = id as usize;
    if i >= cloud.len() {
        return String::new();
    }
    let w = cloud.world(i);
    let mut parts = vec![format!("point {i} at {:.4} {:.4} {:.4}", w.x, w.y, w.z)];
    if let Some(c) = &cloud.colors {
        parts.push(format!("colour {} {} {}", c[i][0], c[i][1], c[i][2]));
    }
    if let Some(v) = &cloud.intensity {
        parts.push(format!("intensity {}", v[i]));
    }
    if let Some(v) = &cloud.classification {
        parts.push(format!("class {}", v[i]));
    }
    if let Some(v) = &cloud.return_number {
        parts.push(format!("return {}", v[i]));
    }
    if let Some(v) = &cloud.opacity {
        parts.push(format!("opacity {:.3}", v[i]));
    }
    for f in &cloud.fields {
        parts.push(format!("{} {}", f.name, f.value(i)));
    }
    format!(" ({})", parts.join(", "))
}

/// The world point a pixel shows, from the frame's view-axis depth there (None on background).
pub fn pick(camera: &Camera, depth: &[f32], i: u32, j: u32) -> Option<DVec3> {
    if i >= camera.width || j >= camera.height {
        return None;
    }
    let d = *depth.get((j * camera.width + i) as usize)? as f64;
    if !d.is_finite() {
        return None;
    }
    let (o, dir) = camera.pixel_ray(i, j);
    let along = dir.dot(camera.basis().forward);
    if along <= 0.0 {
        return None;
    }
    let t = match camera.projection {
        Projection::Perspective { .. } => d / along,
        Projection::Orthographic { .. } => d - (o - camera.eye).dot(camera.basis().forward),
    };
    Some(o + dir * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nav() -> Nav {
        let cam = Camera {
            eye: DVec3::new(0.0, 0.0, 5.0),
            target: DVec3::ZERO,
            up: DVec3::Y,
            projection: Projection::Perspective { fov_deg: 40.0 },
            width: 200,
            height: 100,
            near: 0.1,
            far: 10.0,
        };
        Nav::new(cam, false, DVec3::splat(-1.0), DVec3::splat(1.0))
    }

    #[test]
    fn orbit_keeps_the_distance_and_stops_at_the_pole() {
        let mut n = nav();
        n.orbit(300.0, 0.0);
        let c = &n.camera;
        assert!(((c.eye - c.target).length() - 5.0).abs() < 1e-9);
        // 300 px × 0.3° = 90° about +Y: from +Z to −X (a drag to the right turns the eye left).
        assert!(
            (c.eye - DVec3::new(-5.0, 0.0, 0.0)).length() < 1e-9,
            "{:?}",
            c.eye
        );
        // Dragging far down stops 2° short of the pole.
        n.orbit(0.0, 10_000.0);
        let a = (n.camera.eye - n.camera.target)
            .normalize()
            .dot(DVec3::Y)
            .acos()
            .to_degrees();
        assert!((a - 2.0).abs() < 1e-6 || (a - 178.0).abs() < 1e-6, "{a}");
        assert!(n.camera.validate().is_ok());
        // Near and far still hold the bounds: every corner's depth lies between them.
        let f = n.camera.basis().forward;
        for k in 0..8 {
            let c = DVec3::new(
                if k & 1 == 0 { -1.0 } else { 1.0 },
                if k & 2 == 0 { -1.0 } else { 1.0 },
                if k & 4 == 0 { -1.0 } else { 1.0 },
            );
            let d = (c - n.camera.eye).dot(f);
            assert!(n.camera.near <= d && d <= n.camera.far, "corner {c:?}: {d}");
        }
    }

    #[test]
    fn pan_moves_the_target_by_the_drag_in_world_units() {
        let mut n = nav();
        let s = n.pixel_size();
        assert!((s - 2.0 * 5.0 * 20f64.to_radians().tan() / 100.0).abs() < 1e-12);
        n.pan(10.0, 0.0);
        // Content follows the cursor: dragging right moves the camera left.
        assert!((n.camera.target - DVec3::new(-10.0 * s, 0.0, 0.0)).length() < 1e-12);
        assert!((n.camera.eye - DVec3::new(-10.0 * s, 0.0, 5.0)).length() < 1e-12);
        // The point under the cursor stays under it: the target, projected, moved 10 px right.
        let mut m = nav();
        m.pan(10.0, -4.0);
        let (x, y, _) = m.camera.project(DVec3::ZERO).unwrap();
        assert!(
            (x - 110.0).abs() < 1e-6 && (y - 46.0).abs() < 1e-6,
            "{x} {y}"
        );
    }

    #[test]
    fn zoom_fly_frame_and_pick() {
        let mut n = nav();
        n.zoom(1.0);
        assert!(((n.camera.eye - n.camera.target).length() - 5.0 * ZOOM_STEP).abs() < 1e-9);
        n.zoom(-1.0);
        assert!(((n.camera.eye - n.camera.target).length() - 5.0).abs() < 1e-9);
        n.fly(1.0, 0.0, 0.0, 1.0, false);
        let step = 0.25 * 12f64.sqrt();
        assert!((n.camera.eye.z - (5.0 - step)).abs() < 1e-9);
        n.resize(64, 48);
        n.frame_all();
        assert_eq!(n.camera.eye, DVec3::new(0.0, 0.0, 5.0));
        assert_eq!((n.camera.width, n.camera.height), (64, 48));
        // A pixel whose depth is 5 (the plane z = 0) picks a point on that plane, on the ray.
        let depth = vec![5.0f32; 64 * 48];
        let p = pick(&n.camera, &depth, 10, 7).unwrap();
        assert!(p.z.abs() < 1e-5, "{p:?}");
        let (o, d) = n.camera.pixel_ray(10, 7);
        assert!(((p - o).normalize() - d).length() < 1e-9);
        assert_eq!(pick(&n.camera, &vec![f32::INFINITY; 64 * 48], 1, 1), None);
        n.centre_on(p);
        assert_eq!(n.camera.target, p);
        n.toggle_up();
        assert_eq!((n.up, n.camera.up), (DVec3::Z, DVec3::Z));
        assert!(n.camera.validate().is_ok());
    }

    #[test]
    fn camera_paths_interpolate_between_keyframes() {
        let n = nav();
        let mut b = n.camera.clone();
        b.eye = DVec3::new(5.0, 0.0, 5.0);
        b.projection = Projection::Perspective { fov_deg: 60.0 };
        let keys = vec![n.camera.clone(), b.clone()];
        assert_eq!(path_camera(&keys, 0, 5).eye, n.camera.eye);
        assert_eq!(path_camera(&keys, 4, 5).eye, b.eye);
        let mid = path_camera(&keys, 2, 5);
        assert!((mid.eye - DVec3::new(2.5, 0.0, 5.0)).length() < 1e-12);
        assert_eq!(mid.projection, Projection::Perspective { fov_deg: 50.0 });
        // As --camera-out writes them, and errors that say which camera.
        let json = format!("[{}, {}]", n.camera.to_json(), b.to_json());
        let back = read_path(&json).unwrap();
        assert_eq!(back.len(), 2);
        assert!((back[1].eye - b.eye).length() < 1e-12);
        assert!(read_path("{}").unwrap_err().contains("list"));
        assert!(read_path("[]").unwrap_err().contains("0 cameras"));
        assert!(read_path("[{\"eye\": 1}]")
            .unwrap_err()
            .contains("camera 1"));
    }

    #[test]
    fn the_moving_budget_follows_the_frame_time() {
        // 2 M points took 40 ms against 16: the next cut holds 0.72 M.
        assert_eq!(
            next_budget(2_000_000, 40.0, 16.0, 2_000_000, (1000, 5_000_000)),
            720_000
        );
        // Fast frames grow it by a quarter, up to the full budget.
        assert_eq!(
            next_budget(100_000, 2.0, 16.0, 100_000, (1000, 5_000_000)),
            125_000
        );
        assert_eq!(
            next_budget(100, 1.0, 16.0, 4_900_000, (1000, 5_000_000)),
            5_000_000
        );
        // Never below one node, however slow.
        assert_eq!(next_budget(10, 1e6, 16.0, 10, (1000, 5_000_000)), 1000);
        // Within the target: unchanged.
        assert_eq!(
            next_budget(300, 12.0, 16.0, 300_000, (1000, 5_000_000)),
            300_000
        );
    }

    #[test]
    fn a_pick_reports_the_point_and_its_attributes() {
        let mut c = stipple_core::PointCloud::from_world(&[
            DVec3::new(637_000.25, 850_000.5, 10.0),
            DVec3::new(637_001.0, 850_000.0, 11.0),
        ]);
        c.classification = Some(vec![2, 6]);
        c.fields
            .push(stipple_core::cloud::Field::new("Deviation", &[3.0, 7.0]));
        let d = describe_point(&c, 1);
        assert!(
            d.contains("point 1 at 637001.0000 850000.0000 11.0000"),
            "{d}"
        );
        assert!(d.contains("class 6") && d.contains("Deviation 7"), "{d}");
        assert_eq!(describe_point(&c, 2), "");
        assert_eq!(describe_point(&c, u32::MAX), "");
    }
}
