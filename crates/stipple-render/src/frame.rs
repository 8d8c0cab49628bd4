//! A rendered frame and what can be derived from it.

use crate::*;
use stipple_core::Camera;

/// A rendered frame.
#[derive(Clone, Debug)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// sRGB 8-bit RGBA, row 0 at the top.
    pub rgba: Vec<u8>,
    /// View-axis depth of the surface per pixel, +inf on background.
    pub depth: Vec<f32>,
    /// Point shown per pixel ([`BACKGROUND`] where none).
    pub id: Vec<u32>,
    pub stats: Vec<PassStat>,
    /// With depth peeling: how many layers held points, and (with
    /// [`Pipeline::keep_layers`]) each layer's own image, sRGB 8-bit RGBA, front first.
    pub layers: Vec<Vec<u8>>,
    pub layers_peeled: u32,
    /// Per-pixel unit normals where the frame blended them (splat blend mode); otherwise
    /// [`Frame::normal_image`] derives them from the points shown.
    pub normals: Option<Vec<[f32; 3]>>,
    /// Host-side wall time of the frame outside the passes, in ms, by step (GPU backend:
    /// recording, waiting for the device, reading back; empty on the CPU backend, whose
    /// passes are all of its time). `stipple bench` prints them.
    pub host_ms: Vec<(&'static str, f64)>,
}

impl Frame {
    /// World-space unit normals of the visible surface, facing the eye, row 0 at the top,
    /// NaN on background: the blended normal where the frame has one, else the normal of the
    /// point the pixel shows, else (no normals, or a pixel a fill made) the normal of the
    /// depth image's surface from its neighbouring pixels.
    pub fn normal_image(&self, cloud: &PreparedCloud, camera: &Camera) -> Vec<[f32; 3]> {
        use glam::Vec3;
        let v = ViewParams::new(camera, cloud.cloud.origin);
        let (w, h) = (self.width as usize, self.height as usize);
        let (right, up, fwd) = (Vec3::from(v.right), Vec3::from(v.up), Vec3::from(v.forward));
        let view_to_world = |n: Vec3| right * n.x + up * n.y + fwd * n.z;
        let pos = |i: usize, j: usize| -> Option<Vec3> {
            let d = self.depth[j * w + i];
            d.is_finite()
                .then(|| v.view_position(i as u32, j as u32, d))
        };
        let nan = [f32::NAN; 3];
        let mut out = vec![nan; w * h];
        for j in 0..h {
            for i in 0..w {
                let k = j * w + i;
                if !self.depth[k].is_finite() {
                    continue;
                }
                let (_, dir) = v.pixel_ray(i as u32, j as u32);
                let face = |n: Vec3| {
                    let n = n.normalize_or_zero();
                    if n.dot(dir) > 0.0 {
                        -n
                    } else {
                        n
                    }
                };
                if let Some(b) = &self.normals {
                    let n = Vec3::from(b[k]);
                    if n != Vec3::ZERO {
                        out[k] = face(n).to_array();
                        continue;
                    }
                }
                let id = self.id[k];
                if let (true, Some(ns)) = (is_point(id), &cloud.cloud.normals) {
                    let n = ns[id as usize];
                    if n != Vec3::ZERO {
                        out[k] = face(n).to_array();
                        continue;
                    }
                }
                // From the depth image: the smaller one-sided difference on each axis.
                let Some(c) = pos(i, j) else { continue };
                let pick = |a: Option<Vec3>, b: Option<Vec3>| -> Option<Vec3> {
                    match (a.map(|a| c - a), b.map(|b| b - c)) {
                        (Some(x), Some(y)) => Some(if x.length_squared() < y.length_squared() {
                            x
                        } else {
                            y
                        }),
                        (x, y) => x.or(y),
                    }
                };
                let dx = pick(
                    (i > 0).then(|| pos(i - 1, j)).flatten(),
                    (i + 1 < w).then(|| pos(i + 1, j)).flatten(),
                );
                // Rows grow downwards; view y grows upwards.
                let dy = pick(
                    (j + 1 < h).then(|| pos(i, j + 1)).flatten(),
                    (j > 0).then(|| pos(i, j - 1)).flatten(),
                );
                if let (Some(dx), Some(dy)) = (dx, dy) {
                    let n = dx.cross(dy);
                    if n != Vec3::ZERO {
                        out[k] = face(view_to_world(n.normalize())).to_array();
                    }
                }
            }
        }
        out
    }
}
