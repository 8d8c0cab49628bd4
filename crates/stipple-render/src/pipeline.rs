//! The frame described as data: which passes run, in which order, with which parameters.
//! The CLI, the benchmarks and the tests all build a [`Pipeline`] and hand it to a backend.
//!
//! A frame has two fixed stages and two ordered lists around them:
//! `project` → geometry passes (on depth + point id) → `shade` → colour passes.

use crate::lights::{Light, LightError};
pub use crate::material::{Material, Terms};

/// How many times an iterative pass runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Iterations {
    /// Exactly this many iterations (0 = off).
    Fixed(u32),
    /// Until an iteration changes no pixel, at most `max` iterations.
    UntilStable { max: u32 },
}

impl Iterations {
    pub fn max(self) -> u32 {
        match self {
            Iterations::Fixed(n) => n,
            Iterations::UntilStable { max } => max,
        }
    }

    /// Parses `N` or `auto` (until stable, at most 64 iterations).
    pub fn parse(s: &str) -> Result<Iterations, IterationsError> {
        if s == "auto" {
            return Ok(Iterations::UntilStable { max: 64 });
        }
        s.parse::<u32>()
            .map(Iterations::Fixed)
            .map_err(|_| IterationsError(s.to_string()))
    }
}

/// Text that is not an iteration count.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not an iteration count (a number or `auto`)")]
pub struct IterationsError(pub String);

/// Low-pass kernels of Dobrev Table 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Kernel {
    /// 1/9 everywhere.
    Box,
    /// 1 2 1 / 2 4 2 / 1 2 1, over 16.
    #[cfg_attr(feature = "clap", value(alias = "gaussian"))]
    Gauss,
    /// The Gaussian with the centre weighted 16 (of 28): less blur (the paper's choice).
    Alleviated,
}

impl Kernel {
    /// Weights in row order (9 values).
    pub fn weights(self) -> [f32; 9] {
        match self {
            Kernel::Box => [1.0; 9],
            Kernel::Gauss => [1.0, 2.0, 1.0, 2.0, 4.0, 2.0, 1.0, 2.0, 1.0],
            Kernel::Alleviated => [1.0, 2.0, 1.0, 2.0, 16.0, 2.0, 1.0, 2.0, 1.0],
        }
    }
}

/// The visibility kernel sizes accepted (k of a k×k neighbourhood).
pub const VISIBILITY_KERNELS: std::ops::RangeInclusive<u32> = 3..=15;

/// Passes that work on the visibility G-buffer (depth + point id), before shading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GeometryPass {
    /// Dobrev §3.2: fill background pixels inside the silhouette. `radius` 1 = the paper's
    /// 3×3 masks; 2 = the same half-plane rule on 5×5 (see `masks.rs`).
    FillBackground { iterations: Iterations, radius: u32 },
    /// Dobrev §3.3: replace pixels showing an occluded surface; `layer_gap` = d̃ in world
    /// units (None: derived from the point spacing, see [`default_layer_gap`]).
    FillOccluded {
        iterations: Iterations,
        layer_gap: Option<f32>,
        radius: u32,
    },
    /// Pintus §4: screen-space visibility. Each pixel's free solid angle towards the eye,
    /// estimated over the disc of diameter `kernel` pixels in 8 sectors, as a fraction of the
    /// hemisphere; pixels below `threshold` become [`crate::gbuffer::HOLE`] (empty and
    /// mutable), points and background above it stay (immutable). `kernel` 0 = automatic
    /// (see [`auto_kernel`]), resolved per frame.
    Visibility { kernel: u32, threshold: f32 },
}

/// Passes that work on the shaded colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ColourPass {
    /// Dobrev §3.4.
    Smooth { kernel: Kernel, iterations: u32 },
    /// Dobrev §3.5: Laplace on depth/z_far; pixels above `threshold` are blended with their
    /// Gaussian-weighted neighbourhood by `strength`.
    Antialias { threshold: f32, strength: f32 },
    /// Pintus §5: fill the pixels visibility emptied (3×3, Jacobi iterations). An empty pixel
    /// first takes the median depth of its valid neighbours (and that neighbour's colour);
    /// later iterations average depth and colour with Eq. 1's weights. `delta` is δ in
    /// pixel footprints at the pixel's depth (so the same value works at any distance).
    /// `iterations` 0 = twice the visibility kernel (§5), resolved per frame.
    /// `all_empty`: every empty pixel is mutable, background included (the raw preset with
    /// visibility off, Pintus Fig. 9a); otherwise only [`crate::gbuffer::HOLE`] pixels.
    FillAnisotropic {
        iterations: u32,
        delta: f32,
        all_empty: bool,
    },
    /// Pintus §6: multi-level shape depiction on the filled depth (Eq. 2 per level, levels
    /// merged by Eq. 3 with `xi`, normalised so a flat facing surface shades to 1). `levels`
    /// = 1 is the single-level mode. `epsilon` is Eq. 2's ε in pixel footprints.
    Depiction { levels: u32, xi: f32, epsilon: f32 },
    /// Eye-dome lighting (as in Potree and CloudCompare): darkens pixels by how much nearer
    /// their neighbours at `radius` pixels are, in log2 depth; background neighbours outline.
    Edl { strength: f32, radius: f32 },
    /// Depth cueing: covered pixels fade towards `colour` (linear RGB; None: the pipeline's
    /// background, filled in by [`Pipeline::resolved`]) by `strength` × their depth between
    /// the near and far planes (see [`crate::passes::depth_cue`]).
    DepthCue {
        strength: f32,
        colour: Option<[f32; 3]>,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Pipeline {
    /// Discard points whose normal faces away from the eye (only where normals exist), as
    /// Dobrev §3.1 does. Off by default (a deviation from the paper): where a randomly
    /// sampled surface lands about one point per pixel, culling leaves clusters of empty
    /// pixels that one iteration of the 3×3 background fill cannot close (the demo sphere of
    /// 1 M points at 1024²: thousands of dark specks), while the hidden side's points fill
    /// them and the occluded fill (§3.3) then replaces them with the front's points (one
    /// speck left). A patch of normals oriented wrongly is not cut out either.
    pub backface_culling: bool,
    pub geometry: Vec<GeometryPass>,
    pub colour: Vec<ColourPass>,
    /// The lights (1 to [`crate::lights::MAX_LIGHTS`]; the Phong terms add up).
    pub lights: Vec<Light>,
    /// Distance attenuation of point and area lights (Gunjee §4.1): None, none (every light
    /// shines at full strength wherever it reaches); Some(d₀), the inverse-square law with
    /// full strength at distance d₀ from the light: strength (d₀ / d)², more than 1 nearer
    /// than d₀. Every light then has the same power. Headlights and directional lights do
    /// not fall off.
    pub falloff: Option<f32>,
    /// The material of a plain cloud (a scene's objects carry their own, see
    /// [`crate::ObjectTable`]).
    pub material: Material,
    /// Whether to light with normals at all (clouds without normals are never lit).
    pub lighting: bool,
    /// Background colour, sRGB 8-bit.
    pub background: [u8; 3],
    /// Depth peeling (Dobrev §4–5): how many layers to peel and blend front to back with each
    /// point's opacity; 1 = the nearest surface only. Peeling stops early at an empty layer.
    /// With more than one layer back faces are kept (a closed surface has a back layer).
    pub layers: u32,
    /// Keep every layer's own image in the frame ([`crate::Frame::layers`]).
    pub keep_layers: bool,
    /// Draw the points as surface splats (Zhang & Pajarola, see [`crate::passes::splat`])
    /// instead of projecting them to one pixel each.
    pub splat: Option<crate::SplatSettings>,
    /// An environment behind transparent splats, reflected by them with an index of
    /// refraction ([`crate::env`]); other pipelines draw the plain background.
    pub environment: Option<crate::env::EnvSettings>,
}

impl Default for Pipeline {
    /// The paper's pipeline with one iteration of each step (Dobrev §7).
    fn default() -> Self {
        Pipeline {
            backface_culling: false,
            geometry: vec![
                GeometryPass::FillBackground {
                    iterations: Iterations::Fixed(1),
                    radius: 1,
                },
                GeometryPass::FillOccluded {
                    iterations: Iterations::Fixed(1),
                    layer_gap: None,
                    radius: 1,
                },
            ],
            colour: vec![
                ColourPass::Smooth {
                    kernel: Kernel::Alleviated,
                    iterations: 1,
                },
                ColourPass::Antialias {
                    threshold: 0.02,
                    strength: 0.6,
                },
            ],
            lights: vec![Light::Headlight],
            falloff: None,
            material: Material::default(),
            lighting: true,
            background: [24, 26, 31],
            layers: 1,
            keep_layers: false,
            splat: None,
            environment: None,
        }
    }
}

/// Shading of the raw preset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RawShading {
    /// Pintus §6 with this many levels (1 = single-level).
    Depiction(u32),
    Edl,
    /// The filled colour only.
    None,
}

/// Settings of the raw preset (Pintus §3–6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawSettings {
    /// Visibility kernel size k (the k×k neighbourhood; 4 to 9 in the paper); 0 = automatic
    /// from the point spacing on screen ([`auto_kernel`]).
    pub kernel: u32,
    /// Run the visibility operator (off: every empty pixel is filled, nothing is removed).
    pub visibility: bool,
    /// Free fraction of the hemisphere above which a pixel is visible.
    pub threshold: f32,
    /// Fill iterations (default: twice the kernel size, as §5 advises).
    pub fill_iterations: Option<u32>,
    /// δ of Eq. 1, in pixel footprints.
    pub delta: f32,
    pub shading: RawShading,
    /// ξ of Eq. 3.
    pub xi: f32,
    /// ε of Eq. 2, in pixel footprints.
    pub epsilon: f32,
    /// Eye-dome lighting strength and neighbour radius in pixels (with `RawShading::Edl`).
    pub edl_strength: f32,
    pub edl_radius: f32,
}

impl Default for RawSettings {
    fn default() -> Self {
        RawSettings {
            kernel: 0,
            visibility: true,
            threshold: 0.4,
            fill_iterations: None,
            delta: 8.0,
            shading: RawShading::Depiction(6),
            xi: 1.5,
            epsilon: 2.0,
            edl_strength: 1.0,
            edl_radius: 1.4,
        }
    }
}

impl Pipeline {
    /// The raw-cloud preset (Pintus §3): visibility → anisotropic filling → shape depiction,
    /// ignoring normals (no culling, no lighting).
    pub fn raw(s: RawSettings) -> Pipeline {
        // No fill at all when asked for zero iterations (0 inside the pass means "twice the
        // kernel, once the automatic kernel is known").
        let mut colour = match s.fill_iterations {
            Some(0) => vec![],
            n => vec![ColourPass::FillAnisotropic {
                iterations: n.unwrap_or(2 * s.kernel),
                delta: s.delta,
                all_empty: !s.visibility,
            }],
        };
        match s.shading {
            RawShading::Depiction(levels) => colour.push(ColourPass::Depiction {
                levels,
                xi: s.xi,
                epsilon: s.epsilon,
            }),
            RawShading::Edl => colour.push(ColourPass::Edl {
                strength: s.edl_strength,
                radius: s.edl_radius,
            }),
            RawShading::None => {}
        }
        Pipeline {
            backface_culling: false,
            geometry: if s.visibility {
                vec![GeometryPass::Visibility {
                    kernel: s.kernel,
                    threshold: s.threshold,
                }]
            } else {
                vec![]
            },
            colour,
            lighting: false,
            ..Pipeline::default()
        }
    }

    /// Surface splats (Zhang & Pajarola §3–5): splat → shade → smooth → antialias. The
    /// image-space fills are not needed (splats leave no holes) and nothing is culled (the
    /// ε-z test hides what is behind, whatever the normals' signs).
    pub fn splats(s: crate::SplatSettings) -> Pipeline {
        Pipeline {
            backface_culling: false,
            geometry: vec![],
            splat: Some(s),
            ..Pipeline::default()
        }
    }

    /// Only projection and shading: the raw points (Dobrev Fig. 1).
    pub fn points_only() -> Pipeline {
        Pipeline {
            geometry: vec![],
            colour: vec![],
            ..Pipeline::default()
        }
    }
}

/// The visibility kernel for points `spacing_px` pixels apart on screen (median spacing):
/// 8 × the spacing + 4, from 4 to 15. Why: a pixel behind a surface must find nearer points
/// in most of its 8 sectors, so the radius must span several gaps, and real clouds are not
/// uniform (the median understates the gaps in sparse regions). Calibrated with
/// `stipple eval` against the meshes of the bunny (2 px spacing at 512²: 15) and the Dragon
/// (0.9 px at 1024²: 12), where smaller kernels leave hidden surfaces showing through.
/// Beyond 15 (points over 1.4 px apart) the cost grows with the square of the kernel; the CLI
/// suggests a smaller image instead.
pub fn auto_kernel(spacing_px: f32) -> u32 {
    if !spacing_px.is_finite() {
        return 9;
    }
    ((8.0 * spacing_px).ceil() as u32 + 4).clamp(4, *VISIBILITY_KERNELS.end())
}

impl Pipeline {
    /// Resolves the automatic settings (kernel 0, fill iterations 0) for a cloud of median
    /// point spacing `spacing` whose centre is at view depth `depth`; peeled layers size
    /// their fills at view depth `front` (nearer than the centre: see
    /// [`peel_fill_iterations`]).
    pub fn resolved(
        &self,
        v: &crate::ViewParams,
        spacing: f32,
        depth: f32,
        front: f32,
    ) -> Pipeline {
        let mut p = self.clone();
        let px = if depth > v.near {
            spacing / v.footprint(depth)
        } else {
            f32::NAN
        };
        let mut kernel = 7;
        for g in &mut p.geometry {
            if let GeometryPass::Visibility { kernel: k, .. } = g {
                if *k == 0 {
                    *k = auto_kernel(px);
                }
                kernel = *k;
            }
        }
        let lut = crate::srgb::srgb_to_linear_table();
        let background = p.background.map(|c| lut[c as usize]);
        for c in &mut p.colour {
            match c {
                ColourPass::FillAnisotropic { iterations, .. } if *iterations == 0 => {
                    *iterations = 2 * kernel;
                }
                ColourPass::DepthCue { colour, .. } if colour.is_none() => {
                    *colour = Some(background);
                }
                _ => {}
            }
        }
        if p.layers > 1 {
            // Peeled layers: the fills follow the spacing (see `peel_fill_iterations`).
            let px = if front > v.near {
                spacing / v.footprint(front)
            } else {
                px
            };
            let want = peel_fill_iterations(px);
            let wide = px >= PEEL_WIDE_FILL_SPACING;
            for g in &mut p.geometry {
                if let GeometryPass::FillBackground { iterations, radius }
                | GeometryPass::FillOccluded {
                    iterations, radius, ..
                } = g
                {
                    if wide {
                        *radius = (*radius).max(2);
                    }
                    if let Iterations::Fixed(n) = iterations {
                        *n = (*n).max(want);
                    }
                }
            }
        }
        p
    }
}

/// Fill iterations of each peeled layer for points `spacing_px` pixels apart on screen (the
/// median distance to the nearest neighbour, taken at the view depth halfway between the
/// cloud's nearest bound and its centre; a pipeline asking for fewer gets these): 1 below
/// 0.4 px, 2 below 1.2 px, then 3. From [`PEEL_WIDE_FILL_SPACING`] on, the fills of peeled
/// layers also use the 5×5 masks (radius 2).
///
/// Why: a layer's holes grow with the spacing; an unfilled hole of a front layer lets the
/// surface behind win that pixel, which then shows once too often in the composite (the
/// blotches of a transparent sphere, the specks of `examples/nested-tori.toml` at 512²,
/// where holes three pixels across in the outer torus let the inner ones through), while
/// more iterations than the holes need smear a layer's edge. Where points land a pixel or
/// more apart, gaps two pixels wide see a clear half-plane of the 3×3 masks and never close
/// (see `passes::fill_background`), and the spacing is not uniform over the image (nearer
/// parts of a surface are sparser than the median), so the wider masks close what more
/// iterations cannot. Measured with `examples/peel_quality.rs` (a sphere of opacity 0.5
/// over a plane, interior) and `examples/peel_rims.rs` (a tilted torus of opacity 0.5,
/// every pixel but 2 px around silhouettes), errors to the analytic composite in 8-bit
/// levels: with 3×3 masks the torus errs by 9.4 levels at 0.99 px and 19 at 1.32 px
/// (27–39% of its pixels off by more than 12) and the sphere by 4.5 at 1.56 px; with these
/// rules the sphere errs by at most 0.01 from 0.56 to 1.11 px (median neighbour) and the
/// torus by 0.91 (0.33 px: at its silhouettes, where one iteration gave 0.35), 0.43
/// (0.50 px), 0.50 (0.66 px), 0.41 (0.83 px), 0.58 (0.99 px) and 0.80 (1.32 px).
pub fn peel_fill_iterations(spacing_px: f32) -> u32 {
    if !spacing_px.is_finite() || spacing_px < 0.4 {
        1
    } else if spacing_px < 1.2 {
        2
    } else {
        3
    }
}

/// The screen spacing (pixels) from which peeled layers fill with the 5×5 masks (see
/// [`peel_fill_iterations`]); below it holes are rare and the 3×3 masks keep edges sharper.
pub const PEEL_WIDE_FILL_SPACING: f32 = 0.8;

/// The default layer gap d̃ for a cloud: 2.5 × its estimated point spacing.
///
/// Why: within one surface layer, neighbouring pixels come from points at most about one
/// spacing apart, so their depths differ by less than d̃ unless the surface is nearly edge-on
/// (where the mask test still finds a white half-plane); two front-facing layers closer than
/// 2.5 spacings are not resolvable by the points anyway. Override with `--layer-gap`.
pub fn default_layer_gap(spacing: f32) -> f32 {
    2.5 * spacing
}

/// The layer gap d̃ a pipeline uses: its own, else derived from the cloud's point spacing.
pub fn layer_gap(pipe: &Pipeline, spacing: f32) -> f32 {
    pipe.geometry
        .iter()
        .find_map(|p| match p {
            GeometryPass::FillOccluded { layer_gap, .. } => *layer_gap,
            _ => None,
        })
        .unwrap_or_else(|| default_layer_gap(spacing))
}

impl Pipeline {
    /// Checks what a frame cannot run with: the lights (see [`crate::lights::validate`])
    /// and the layer count (1 to [`MAX_LAYERS`]).
    pub fn validate(&self) -> Result<(), PipelineError> {
        crate::lights::validate(&self.lights)?;
        if let Some(s) = &self.splat {
            if self.layers > 1 {
                return Err(PipelineError::PeeledSplats);
            }
            if !(s.scale.is_finite() && s.scale > 0.0) {
                return Err(PipelineError::SplatScale(s.scale));
            }
            if let Some(e) = s.epsilon {
                if !(e.is_finite() && e >= 0.0) {
                    return Err(PipelineError::SplatEpsilon(e));
                }
            }
            if !(s.c > 0.0 && s.c <= 1.0) {
                return Err(PipelineError::SplatOverlap(s.c));
            }
        }
        if !(1..=MAX_LAYERS).contains(&self.layers) {
            return Err(PipelineError::Layers(self.layers));
        }
        Ok(())
    }
}

/// What a frame cannot run with (see [`Pipeline::validate`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Lights(#[from] LightError),
    #[error(
        "depth peeling of splats (transparent splats) is not implemented yet: use --layers 1 \
         with the splat pipeline"
    )]
    PeeledSplats,
    #[error("splat scale {0}: it must be positive")]
    SplatScale(f32),
    #[error("splat epsilon {0}: it must be 0 or more")]
    SplatEpsilon(f32),
    #[error("splat grouping c = {0}: the overlap relaxation must lie in (0, 1]")]
    SplatOverlap(f32),
    #[error("{0} layers: depth peeling takes 1 to {MAX_LAYERS}")]
    Layers(u32),
}

/// The most layers a frame peels.
pub const MAX_LAYERS: u32 = 64;

#[cfg(test)]
mod tests {
    use super::*;
    use stipple_core::{Camera, Projection};

    /// Depth cueing without a colour fades into the pipeline's background once resolved;
    /// a given colour is kept.
    #[test]
    fn depth_cue_defaults_to_the_background_when_resolved() {
        let cam = Camera {
            eye: glam::DVec3::new(0.0, 0.0, 5.0),
            target: glam::DVec3::ZERO,
            up: glam::DVec3::Y,
            projection: Projection::Perspective { fov_deg: 40.0 },
            width: 8,
            height: 8,
            near: 1.0,
            far: 9.0,
        };
        let v = crate::ViewParams::new(&cam, glam::DVec3::ZERO);
        let mut p = Pipeline {
            background: [255, 0, 0],
            ..Pipeline::points_only()
        };
        p.colour.push(ColourPass::DepthCue {
            strength: 0.5,
            colour: None,
        });
        p.colour.push(ColourPass::DepthCue {
            strength: 0.5,
            colour: Some([0.0, 0.0, 1.0]),
        });
        let r = p.resolved(&v, 0.01, 5.0, 5.0);
        let colours: Vec<_> = r
            .colour
            .iter()
            .map(|c| match c {
                ColourPass::DepthCue { colour, .. } => *colour,
                _ => None,
            })
            .collect();
        assert_eq!(colours, [Some([1.0, 0.0, 0.0]), Some([0.0, 0.0, 1.0])]);
    }
}
