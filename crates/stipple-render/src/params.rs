//! Parameter blocks handed to the passes. They are `#[repr(C)]`, 16-byte aligned rows of
//! f32/u32 so the GPU twins can upload them unchanged (keep in sync with the WGSL structs).

use glam::{DVec3, Vec3};
use stipple_core::{Camera, Projection};

/// The camera in the cloud's local frame (eye relative to the cloud origin), in f32.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct ViewParams {
    pub eye: [f32; 3],
    pub near: f32,
    pub right: [f32; 3],
    pub far: f32,
    pub up: [f32; 3],
    /// NDC x = x_view · sx (/ z for perspective).
    pub sx: f32,
    pub forward: [f32; 3],
    pub sy: f32,
    pub width: u32,
    pub height: u32,
    /// 1 for perspective, 0 for orthographic.
    pub perspective: u32,
    pub _pad: u32,
}

const _: () = assert!(std::mem::size_of::<ViewParams>() == 80);

impl ViewParams {
    pub fn new(camera: &Camera, origin: DVec3) -> ViewParams {
        let b = camera.basis();
        let (sx, sy) = camera.ndc_scale();
        let f = |v: DVec3| v.as_vec3().to_array();
        ViewParams {
            eye: f(camera.eye - origin),
            near: camera.near as f32,
            right: f(b.right),
            far: camera.far as f32,
            up: f(b.up),
            sx: sx as f32,
            forward: f(b.forward),
            sy: sy as f32,
            width: camera.width,
            height: camera.height,
            perspective: matches!(camera.projection, Projection::Perspective { .. }) as u32,
            _pad: 0,
        }
    }

    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The ray through pixel (i, j) in the local frame: origin and a direction whose view
    /// depth is 1 per unit (so `origin + dir · t` has view depth t, relative to the eye plane).
    #[inline]
    pub fn pixel_ray(&self, i: u32, j: u32) -> (Vec3, Vec3) {
        let nx = 2.0 * (i as f32 + 0.5) / self.width as f32 - 1.0;
        let ny = 1.0 - 2.0 * (j as f32 + 0.5) / self.height as f32;
        let (r, u, f) = (
            Vec3::from(self.right),
            Vec3::from(self.up),
            Vec3::from(self.forward),
        );
        let off = r * (nx / self.sx) + u * (ny / self.sy);
        if self.perspective == 1 {
            (Vec3::from(self.eye), f + off)
        } else {
            (Vec3::from(self.eye) + off, f)
        }
    }

    /// A camera at the origin looking along +z (x right, y up) with NDC scale `scale` on both
    /// axes, near 0.1 and far 100: the view of hand-made test images, where world, local and
    /// view coordinates coincide.
    pub fn axis_aligned(width: u32, height: u32, perspective: bool, scale: f32) -> ViewParams {
        ViewParams {
            eye: [0.0; 3],
            near: 0.1,
            right: [1.0, 0.0, 0.0],
            far: 100.0,
            up: [0.0, 1.0, 0.0],
            sx: scale,
            forward: [0.0, 0.0, 1.0],
            sy: scale,
            width,
            height,
            perspective: perspective as u32,
            _pad: 0,
        }
    }

    /// The view-space position (camera at the origin, +z forward, x right, y up) of the point
    /// at view depth `z` on pixel (i, j)'s centre ray. Written as the WGSL twin computes it.
    #[inline]
    pub fn view_position(&self, i: u32, j: u32, z: f32) -> Vec3 {
        let nx = 2.0 * (i as f32 + 0.5) / self.width as f32 - 1.0;
        let ny = 1.0 - 2.0 * (j as f32 + 0.5) / self.height as f32;
        let s = if self.perspective == 1 { z } else { 1.0 };
        Vec3::new(nx / self.sx * s, ny / self.sy * s, z)
    }

    /// The world size of one pixel (vertically) at view depth `z`.
    #[inline]
    pub fn footprint(&self, z: f32) -> f32 {
        let s = if self.perspective == 1 { z } else { 1.0 };
        2.0 / (self.height as f32 * self.sy) * s
    }
}
