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

/// Phong terms of one object's material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Terms {
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    /// Phong exponent (used as an integer: the specular term is a repeated product).
    pub shininess: f32,
}
