//! Materials: the Phong terms a cloud or a scene object is lit with (Dobrev §3.1).

/// Phong material (Dobrev §3.1: ambient, diffuse, specular).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub shininess: f32,
    /// Linear RGB albedo for clouds without colours.
    pub base_colour: [f32; 3],
    /// How the object's transparent surface treats its surroundings (transparent splats).
    pub optics: Optics,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            ambient: 0.2,
            diffuse: 0.75,
            specular: 0.25,
            shininess: 32.0,
            base_colour: [0.62, 0.62, 0.60],
            optics: Optics::default(),
        }
    }
}

/// How an object's transparent surface reflects, refracts and absorbs what lies around and
/// behind it (Zhang & Pajarola §5.2.3; transparent splats, `crate::env`): per object in a
/// scene (`[cloud.material]`), the frame's `--ior` and `--dispersion` where not given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Optics {
    /// Refractive index (None: the frame's).
    pub ior: Option<f32>,
    /// Chromatic dispersion δ (None: the frame's).
    pub dispersion: Option<f32>,
    /// Multiplies the Fresnel reflectance (1: a clean dielectric; 0: no reflection).
    pub reflectivity: f32,
    /// The share of each linear RGB channel of what lies behind that each layer absorbs
    /// besides its opacity: what the layers let through is multiplied by (1 − a)^l (tinted
    /// glass).
    pub absorption: [f32; 3],
    /// Whether the object's nearest layer is smoothly interpolated where it is the nearest
    /// at a pixel: Zhang & Pajarola's Algorithm 3 (true) or Algorithm 2 (false); None: the
    /// frame's choice (`SplatSettings::smooth_nearest`).
    pub smooth_nearest: Option<bool>,
}

impl Default for Optics {
    fn default() -> Self {
        Optics {
            ior: None,
            dispersion: None,
            reflectivity: 1.0,
            absorption: [0.0; 3],
            smooth_nearest: None,
        }
    }
}

impl Optics {
    /// This object's surface in a frame whose environment settings are `frame`.
    pub fn resolve(&self, frame: &crate::env::EnvSettings) -> crate::env::Surface {
        crate::env::Surface {
            eta: self.ior.or(frame.ior),
            dispersion: self.dispersion.unwrap_or(frame.dispersion),
            reflectivity: self.reflectivity,
            absorption: self.absorption,
        }
    }
}

/// Phong terms of one object's material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Terms {
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    /// Phong exponent (used as an integer: the specular term is a repeated product).
    pub shininess: f32,
}
