//! How a frame runs, written once for both backends.
//!
//! ```text
//! frame:       [begin_peel]
//!              for each layer (1, or Pipeline::layers with peeling):
//!                  project | splat  (peeling behind the previous layer's surface + d̃)
//!                  geometry passes  (on depth + point id; none with splats)
//!                  shade
//!                  colour passes
//!                  [keep_front]     (layer 0: the frame's depth and id outputs)
//!                  [blend_layer, keep_layer, peel_behind]
//!              [compose] output
//! light view:  project → the light pipeline's geometry passes → mark   (shadow textures)
//! translucent: begin_transmit
//! light view   for each light layer (ShadowSettings::layers):
//!                  project (peeling) → geometry passes → mark (layer)
//!                  light_surface → blend_layer (transmittance) → peel_behind
//!              mark (rest)
//! ```
//!
//! A backend implements [`PassExec`]: the CPU runs each step when it is called, the GPU
//! records it into the frame's command buffer. The loops over layers and over light views,
//! and the rules around them (culling only without peeling, stopping at an empty layer,
//! which layer's depth is the frame's), live here and nowhere else.

use crate::passes::shadow_texture::cpu::{MarkMode, MarkParams};
use crate::pipeline::{ColourPass, GeometryPass, Pipeline};
use crate::SplatSettings;

/// One backend's steps of a frame, in the order [`frame`] and [`light_view`] call them.
pub trait PassExec {
    type Error;

    /// Projects the points into the G-buffer (depth + point id), or draws them as splats.
    /// `peel` = the layer gap d̃ for a layer after the first: only points farther than the
    /// previous layer's surface plus d̃ at their pixel are kept. `cull`: drop points whose
    /// normal faces away. Returns the points kept when the backend knows it before the frame
    /// ends (the CPU), `None` when it does not (the GPU counts on the device).
    fn project(
        &mut self,
        splat: Option<&SplatSettings>,
        peel: Option<f32>,
        cull: bool,
    ) -> Result<Option<u64>, Self::Error>;

    /// One geometry pass; `gap` is d̃ for passes that do not set their own.
    fn geometry(&mut self, pass: &GeometryPass, gap: f32) -> Result<(), Self::Error>;

    /// Lights the G-buffer's points: linear colour and surface depth per pixel.
    fn shade(&mut self) -> Result<(), Self::Error>;

    /// One colour pass.
    fn colour(&mut self, pass: &ColourPass) -> Result<(), Self::Error>;

    /// Keeps the current layer's surface depth and point ids as the frame's outputs.
    fn keep_front(&mut self) -> Result<(), Self::Error>;

    /// Clears the accumulator of the front-to-back blend (depth peeling).
    fn begin_peel(&mut self) -> Result<(), Self::Error>;

    /// Blends the current layer under what the accumulator holds.
    fn blend_layer(&mut self) -> Result<(), Self::Error>;
    /// A light view's layer for coloured translucent shadows: the accumulator's colour
    /// gathers each channel's optical depth (see [`crate::translucent`]).
    fn transmit_layer(&mut self) -> Result<(), Self::Error>;

    /// Keeps the current layer's own image (layer `k`, counted from 0).
    fn keep_layer(&mut self, k: u32) -> Result<(), Self::Error>;

    /// The current layer's surface depth becomes the reference the next layer peels behind
    /// (see `passes::project::cpu::peel_reference`; `gap` is d̃).
    fn peel_behind(&mut self, gap: f32) -> Result<(), Self::Error>;

    /// Composes the accumulator over the background into the colour image.
    fn compose(&mut self) -> Result<(), Self::Error>;

    /// Encodes the colour image to 8-bit sRGB.
    fn output(&mut self) -> Result<(), Self::Error>;

    /// Marks the points the light sees in this light image (Dobrev §6), or with a
    /// translucent mode the points of this light layer (see `passes::shadow_texture::cpu`).
    fn mark(&mut self, params: &MarkParams) -> Result<(), Self::Error>;

    /// A translucent light view begins: every light pixel lets all light through (the
    /// blend accumulator's transmittance is 1) and no point is marked yet.
    fn begin_transmit(&mut self) -> Result<(), Self::Error>;

    /// A light layer's surface for the steps after it: the per-pixel surface depth (the
    /// layer's depth, as shade leaves it for points) and each pixel's point attributes
    /// (opacity, position and normal), which `blend_layer` and `peel_behind` read.
    fn light_surface(&mut self) -> Result<(), Self::Error>;
}

/// Runs (or records) one frame of `pipe`; `gap` is the layer gap d̃ for the cloud (see
/// [`crate::pipeline::layer_gap`]). Returns how many layers were peeled as far as the
/// backend knows while it runs: a backend that counts on the device (`project` returns
/// `None`) gets every layer asked for and works the true count out of its statistics.
pub fn frame<X: PassExec>(x: &mut X, pipe: &Pipeline, gap: f32) -> Result<u32, X::Error> {
    let layers = pipe.layers.max(1);
    if layers == 1 {
        layer(x, pipe, None, pipe.backface_culling, gap)?;
        x.keep_front()?;
        x.output()?;
        return Ok(1);
    }
    // Back faces are kept: the back of a closed surface is a layer of its own.
    x.begin_peel()?;
    let mut peeled = 0;
    for k in 0..layers {
        let peel = (k > 0).then_some(gap);
        if layer(x, pipe, peel, false, gap)? == Some(0) {
            // Nothing behind the last layer: every later layer would be empty too.
            break;
        }
        peeled += 1;
        if k == 0 {
            x.keep_front()?;
        }
        x.blend_layer()?;
        if pipe.keep_layers {
            x.keep_layer(k)?;
        }
        if k + 1 < layers {
            x.peel_behind(gap)?;
        }
    }
    x.compose()?;
    x.output()?;
    Ok(peeled)
}

/// One layer: project (or splat), the geometry passes, shade and the colour passes.
fn layer<X: PassExec>(
    x: &mut X,
    pipe: &Pipeline,
    peel: Option<f32>,
    cull: bool,
    gap: f32,
) -> Result<Option<u64>, X::Error> {
    let kept = x.project(pipe.splat.as_ref(), peel, cull)?;
    // Splats leave no holes to fill: the geometry passes work on one-pixel points.
    if pipe.splat.is_none() {
        for pass in &pipe.geometry {
            x.geometry(pass, gap)?;
        }
    }
    // Sorted splats are shaded per point and blended as they are drawn.
    if !pipe.splat.is_some_and(|s| s.mode.is_ordered()) {
        x.shade()?;
    }
    for pass in &pipe.colour {
        x.colour(pass)?;
    }
    Ok(kept)
}

/// One light image of a shadow texture: project from the light (nothing culled), close the
/// holes with `light_pipe`'s geometry passes and mark the points the light sees (see
/// [`crate::shadow`]). With `layers` > 1 (a translucent cloud, see [`crate::translucent`])
/// the light image is peeled into up to `layers` layers, each marking its points with the
/// light the layers in front of it let through.
pub fn light_view<X: PassExec>(
    x: &mut X,
    light_pipe: &Pipeline,
    params: &MarkParams,
    layers: u32,
) -> Result<(), X::Error> {
    if layers <= 1 {
        x.project(None, None, false)?;
        for pass in &light_pipe.geometry {
            x.geometry(pass, params.fill_gap)?;
        }
        return x.mark(&MarkParams {
            mode: MarkMode::Opaque,
            ..*params
        });
    }
    x.begin_transmit()?;
    for k in 0..layers {
        let peel = (k > 0).then_some(params.fill_gap);
        if x.project(None, peel, false)? == Some(0) {
            break;
        }
        for pass in &light_pipe.geometry {
            x.geometry(pass, params.fill_gap)?;
        }
        x.mark(&MarkParams {
            mode: MarkMode::Layer,
            ..*params
        })?;
        x.light_surface()?;
        if params.coloured {
            x.transmit_layer()?;
        } else {
            x.blend_layer()?;
        }
        if k + 1 < layers {
            x.peel_behind(params.fill_gap)?;
        }
    }
    x.mark(&MarkParams {
        mode: MarkMode::Rest,
        ..*params
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::Iterations;

    /// Records the steps a schedule calls, and plays a backend that finds `empty_from`'s
    /// layer and all later ones empty.
    struct Log {
        steps: Vec<String>,
        empty_from: u32,
        layer: u32,
        knows_counts: bool,
    }

    impl PassExec for Log {
        type Error = ();
        fn project(
            &mut self,
            splat: Option<&SplatSettings>,
            peel: Option<f32>,
            cull: bool,
        ) -> Result<Option<u64>, ()> {
            self.steps.push(format!(
                "{}(peel {peel:?}, cull {cull})",
                if splat.is_some() { "splat" } else { "project" }
            ));
            let kept = if self.layer >= self.empty_from {
                0
            } else {
                100
            };
            self.layer += 1;
            Ok(self.knows_counts.then_some(kept))
        }
        fn geometry(&mut self, pass: &GeometryPass, gap: f32) -> Result<(), ()> {
            self.steps.push(format!("{}({gap})", pass.name()));
            Ok(())
        }
        fn shade(&mut self) -> Result<(), ()> {
            self.steps.push("shade".into());
            Ok(())
        }
        fn colour(&mut self, pass: &ColourPass) -> Result<(), ()> {
            self.steps.push(pass.name().into());
            Ok(())
        }
        fn keep_front(&mut self) -> Result<(), ()> {
            self.steps.push("keep_front".into());
            Ok(())
        }
        fn begin_peel(&mut self) -> Result<(), ()> {
            self.steps.push("begin_peel".into());
            Ok(())
        }
        fn blend_layer(&mut self) -> Result<(), ()> {
            self.steps.push("blend".into());
            Ok(())
        }
        fn transmit_layer(&mut self) -> Result<(), ()> {
            self.steps.push("transmit".into());
            Ok(())
        }
        fn keep_layer(&mut self, k: u32) -> Result<(), ()> {
            self.steps.push(format!("keep_layer({k})"));
            Ok(())
        }
        fn peel_behind(&mut self, _gap: f32) -> Result<(), ()> {
            self.steps.push("peel_behind".into());
            Ok(())
        }
        fn compose(&mut self) -> Result<(), ()> {
            self.steps.push("compose".into());
            Ok(())
        }
        fn output(&mut self) -> Result<(), ()> {
            self.steps.push("output".into());
            Ok(())
        }
        fn mark(&mut self, p: &MarkParams) -> Result<(), ()> {
            self.steps
                .push(format!("mark(light {}, {:?})", p.light, p.mode));
            Ok(())
        }
        fn begin_transmit(&mut self) -> Result<(), ()> {
            self.steps.push("begin_transmit".into());
            Ok(())
        }
        fn light_surface(&mut self) -> Result<(), ()> {
            self.steps.push("light_surface".into());
            Ok(())
        }
    }

    fn log(empty_from: u32, knows_counts: bool) -> Log {
        Log {
            steps: vec![],
            empty_from,
            layer: 0,
            knows_counts,
        }
    }

    #[test]
    fn one_layer_culls_as_asked_and_runs_every_pass_in_order() {
        let mut x = log(99, true);
        let culled = Pipeline {
            backface_culling: true,
            ..Pipeline::default()
        };
        assert_eq!(frame(&mut x, &culled, 0.5), Ok(1));
        assert_eq!(
            x.steps,
            [
                "project(peel None, cull true)",
                "fill_background(0.5)",
                "fill_occluded(0.5)",
                "shade",
                "smooth",
                "antialias",
                "keep_front",
                "output"
            ]
        );
    }

    #[test]
    fn peeling_keeps_back_faces_and_stops_at_the_first_empty_layer() {
        let pipe = Pipeline {
            layers: 4,
            keep_layers: true,
            ..Pipeline::points_only()
        };
        let mut x = log(2, true);
        assert_eq!(frame(&mut x, &pipe, 0.25), Ok(2));
        assert_eq!(
            x.steps,
            [
                "begin_peel",
                "project(peel None, cull false)",
                "shade",
                "keep_front",
                "blend",
                "keep_layer(0)",
                "peel_behind",
                "project(peel Some(0.25), cull false)",
                "shade",
                "blend",
                "keep_layer(1)",
                "peel_behind",
                "project(peel Some(0.25), cull false)",
                "shade",
                "compose",
                "output"
            ]
        );
        // A backend that counts on the device records every layer.
        let mut x = log(2, false);
        assert_eq!(frame(&mut x, &pipe, 0.25), Ok(4));
        assert_eq!(x.steps.iter().filter(|s| *s == "blend").count(), 4);
        assert_eq!(x.steps.iter().filter(|s| *s == "peel_behind").count(), 3);
    }

    #[test]
    fn splats_skip_the_geometry_passes_and_light_views_fill_with_the_light_gap() {
        let pipe = Pipeline {
            geometry: Pipeline::default().geometry,
            ..Pipeline::splats(SplatSettings::default())
        };
        let mut x = log(99, true);
        frame(&mut x, &pipe, 1.0).unwrap();
        assert_eq!(x.steps[0], "splat(peel None, cull false)");
        assert!(!x.steps.iter().any(|s| s.starts_with("fill")));

        let light = Pipeline {
            geometry: vec![GeometryPass::FillBackground {
                iterations: Iterations::Fixed(1),
                radius: 1,
            }],
            ..Pipeline::default()
        };
        let mut x = log(99, true);
        let params = MarkParams {
            gap: 1.0,
            fill_gap: 0.125,
            slope_cap: 16.0,
            face: 0,
            light: 2,
            mode: MarkMode::Rest,
            coloured: false,
        };
        light_view(&mut x, &light, &params, 1).unwrap();
        assert_eq!(
            x.steps,
            [
                "project(peel None, cull false)",
                "fill_background(0.125)",
                "mark(light 2, Opaque)"
            ]
        );

        // Translucent: layers peel behind each other with the light gap until one is empty,
        // then the points no layer marked take what is left.
        let mut x = log(2, true);
        light_view(&mut x, &light, &params, 4).unwrap();
        assert_eq!(
            x.steps,
            [
                "begin_transmit",
                "project(peel None, cull false)",
                "fill_background(0.125)",
                "mark(light 2, Layer)",
                "light_surface",
                "blend",
                "peel_behind",
                "project(peel Some(0.125), cull false)",
                "fill_background(0.125)",
                "mark(light 2, Layer)",
                "light_surface",
                "blend",
                "peel_behind",
                "project(peel Some(0.125), cull false)",
                "mark(light 2, Rest)"
            ]
        );
        let mut x = log(9, false);
        light_view(&mut x, &light, &params, 3).unwrap();
        assert_eq!(x.steps.iter().filter(|s| *s == "peel_behind").count(), 2);
        assert_eq!(x.steps.iter().filter(|s| *s == "blend").count(), 3);
        assert_eq!(x.steps.last().unwrap(), "mark(light 2, Rest)");
    }
}
