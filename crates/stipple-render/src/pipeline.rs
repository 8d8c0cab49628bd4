//! The frame described as data: which passes run, in which order, with which parameters.
//! The CLI, the benchmarks and the tests all build a [`Pipeline`] and hand it to a backend.
//!
//! A frame has two fixed stages and two ordered lists around them:
//! `project` → geometry passes (on depth + point id) → `shade` → colour passes.

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
    pub fn parse(s: &str) -> Result<Iterations, String> {
        if s == "auto" {
            return Ok(Iterations::UntilStable { max: 64 });
        }
        s.parse::<u32>()
            .map(Iterations::Fixed)
            .map_err(|_| format!("`{s}` is not an iteration count (a number or `auto`)"))
    }
}

/// Low-pass kernels of Dobrev Table 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// 1/9 everywhere.
    Box,
    /// 1 2 1 / 2 4 2 / 1 2 1, over 16.
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

    pub fn parse(s: &str) -> Result<Kernel, String> {
        match s {
            "box" => Ok(Kernel::Box),
            "gauss" | "gaussian" => Ok(Kernel::Gauss),
            "alleviated" => Ok(Kernel::Alleviated),
            _ => Err(format!("unknown kernel `{s}` (box, gauss, alleviated)")),
        }
    }
}

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
}

/// Passes that work on the shaded colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ColourPass {
    /// Dobrev §3.4.
    Smooth { kernel: Kernel, iterations: u32 },
    /// Dobrev §3.5: Laplace on depth/z_far; pixels above `threshold` are blended with their
    /// Gaussian-weighted neighbourhood by `strength`.
    Antialias { threshold: f32, strength: f32 },
}

/// Where the light is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// At the eye (the default).
    Headlight,
    /// Coming from a world direction (pointing from the scene towards the light).
    Directional([f64; 3]),
    /// At a world position.
    Point([f64; 3]),
}

/// Phong material (Dobrev §3.1: ambient, diffuse, specular).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub shininess: f32,
    /// Linear RGB albedo for clouds without colours.
    pub base_colour: [f32; 3],
}

impl Default for Material {
    fn default() -> Self {
        Material {
            ambient: 0.2,
            diffuse: 0.75,
            specular: 0.25,
            shininess: 32.0,
            base_colour: [0.62, 0.62, 0.60],
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Pipeline {
    /// Discard points whose normal faces away from the eye (only where normals exist).
    pub backface_culling: bool,
    pub geometry: Vec<GeometryPass>,
    pub colour: Vec<ColourPass>,
    pub light: Light,
    pub material: Material,
    /// Whether to light with normals at all (clouds without normals are never lit).
    pub lighting: bool,
    /// Background colour, sRGB 8-bit.
    pub background: [u8; 3],
}

impl Default for Pipeline {
    /// The paper's pipeline with one iteration of each step (Dobrev §7).
    fn default() -> Self {
        Pipeline {
            backface_culling: true,
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
            light: Light::Headlight,
            material: Material::default(),
            lighting: true,
            background: [24, 26, 31],
        }
    }
}

impl Pipeline {
    /// Only projection and shading: the raw points (Dobrev Fig. 1).
    pub fn points_only() -> Pipeline {
        Pipeline {
            geometry: vec![],
            colour: vec![],
            ..Pipeline::default()
        }
    }
}

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

impl GeometryPass {
    pub fn name(&self) -> &'static str {
        match self {
            GeometryPass::FillBackground { .. } => "fill_background",
            GeometryPass::FillOccluded { .. } => "fill_occluded",
        }
    }
}

impl ColourPass {
    pub fn name(&self) -> &'static str {
        match self {
            ColourPass::Smooth { .. } => "smooth",
            ColourPass::Antialias { .. } => "antialias",
        }
    }
}
