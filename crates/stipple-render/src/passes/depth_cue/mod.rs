//! # Depth cueing (a pixel pass)
//!
//! Covered pixels fade towards a colour (the background, by default) in proportion to their
//! depth between the near and far planes: t = s · clamp((d − near) / (far − near), 0, 1),
//! c' = c + (fog − c) · t. The camera's planes are fitted to the cloud, so the nearest points
//! keep their colour and the farthest take a fraction s of the fog colour; on LiDAR seen
//! from above this separates ground from canopy at a glance. Background pixels are kept.
//!
//! This pass is the worked example of `docs/architecture.md` ("how to add a pass"): all of
//! it is this folder, its variant [`crate::ColourPass::DepthCue`], one registration line
//! in `ColourPass::kernel` and the CLI flag `--depth-cue`.

use super::pixel::{PixelImages, PixelPass};
use crate::device::shaders::{ShaderModule, PIXEL_PASS};
use crate::params::ViewParams;
use rayon::prelude::*;

/// Depth cueing with strength `strength` (0: off, 1: the farthest points take the colour).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthCue {
    pub strength: f32,
    /// Linear RGB the pixels fade to.
    pub colour: [f32; 3],
}

const MODULE: ShaderModule =
    ShaderModule::new("depth_cue", &[PIXEL_PASS, include_str!("depth_cue.wgsl")]);

/// The uniform block of `depth_cue.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Block {
    colour: [f32; 3],
    strength: f32,
}

impl PixelPass for DepthCue {
    fn id(&self) -> crate::stats::PassId {
        crate::stats::PassId::DepthCue
    }

    fn cpu(&self, v: &ViewParams, input: &PixelImages<'_>, dst: &mut [[f32; 3]]) -> u64 {
        dst.par_iter_mut()
            .zip(input.depth.par_iter().zip(input.colour.par_iter()))
            .for_each(|(o, (&d, c))| {
                if !d.is_finite() {
                    *o = *c;
                    return;
                }
                // Term by term as the WGSL evaluates it.
                let t = ((d - v.near) / (v.far - v.near)).clamp(0.0, 1.0) * self.strength;
                *o = std::array::from_fn(|i| c[i] + (self.colour[i] - c[i]) * t);
            });
        0
    }

    fn module(&self) -> &'static ShaderModule {
        &MODULE
    }

    fn block(&self, _v: &ViewParams) -> Vec<u8> {
        bytemuck::bytes_of(&Block {
            colour: self.colour,
            strength: self.strength,
        })
        .to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use stipple_core::{Camera, Projection};

    fn view() -> ViewParams {
        let cam = Camera {
            eye: glam::DVec3::new(0.0, 0.0, 5.0),
            target: glam::DVec3::ZERO,
            up: glam::DVec3::Y,
            projection: Projection::Perspective { fov_deg: 40.0 },
            width: 3,
            height: 1,
            near: 1.0,
            far: 9.0,
        };
        ViewParams::new(&cam, glam::DVec3::ZERO)
    }

    #[test]
    fn far_pixels_fade_near_ones_keep_their_colour_background_stays() {
        let v = view();
        let cue = DepthCue {
            strength: 0.5,
            colour: [0.0, 0.0, 1.0],
        };
        let input = PixelImages {
            id: &[0, 1, u32::MAX],
            depth: &[v.near, v.far, f32::INFINITY],
            colour: &[[1.0, 0.0, 0.0]; 3],
        };
        let mut out = [[0.0; 3]; 3];
        cue.cpu(&v, &input, &mut out);
        assert_eq!(out[0], [1.0, 0.0, 0.0], "at the near plane");
        assert_eq!(
            out[1],
            [0.5, 0.0, 0.5],
            "at the far plane, half way to the fog"
        );
        assert_eq!(out[2], [1.0, 0.0, 0.0], "background");
    }

    /// The WGSL compiles, and its block is the size of the Rust one.
    #[test]
    fn the_shader_validates_and_its_block_matches() {
        let m = naga::front::wgsl::parse_str(&MODULE.source()).expect("depth_cue.wgsl parses");
        naga::valid::Validator::new(Default::default(), naga::valid::Capabilities::empty())
            .validate(&m)
            .expect("depth_cue.wgsl validates");
        let block = m
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some("DepthCue"))
            .map(|(_, t)| t.inner.size(m.to_ctx()))
            .expect("struct DepthCue");
        assert_eq!(block as usize, std::mem::size_of::<Block>());
    }
}
