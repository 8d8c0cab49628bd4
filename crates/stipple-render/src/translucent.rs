//! # Translucent shadow maps (Gunjee et al. §4.1)
//!
//! Gunjee et al. keep, per light, a table over the directions from the light (rows: polar
//! angle, columns: azimuth) whose cells hold the points seen in that direction as a list
//! sorted by distance. Walking a cell's list from the light, each point's absorbance
//! A = α l c (Eq. 6: absorption coefficient α, splat size l, opacity c) adds up, and the light
//! reaching a point is the incident light times the Beer's-law transmittance of the points
//! in front of it (Eq. 8, Eq. 9); opaque points get α = 100, so nothing passes them.
//!
//! Here the table is the light image that the opaque shadow textures already use (Dobrev §6,
//! see [`crate::shadow`]): one perspective view when the cloud lies within a 60° cone of the
//! light, else the six faces of a cube around it. The cube is the omnidirectional table of the
//! paper with a cheaper parametrisation (no trigonometry per point, square cells of nearly
//! even solid angle, and the same projection code as every other view); it covers lights
//! inside objects as a sphere would. The sorted list of a cell is built by depth peeling the
//! light image, as the camera's transparency does (Dobrev §4–5): layer 1 holds the surface
//! nearest the light at each pixel, layer 2 the next one behind it by more than the light
//! gap, and so on for [`crate::shadow::ShadowSettings::layers`] layers.
//!
//! What accumulates is one absorbance per *surface* crossed, not per point: a surface of
//! opacity α (a scene object's `opacity`, a file's alpha) has optical depth τ = −ln(1 − α),
//! so the light through layers 1 … k − 1 is T = exp(−Σ τ) = Π (1 − α). In the paper's terms
//! l · c · α of a surface is τ. Counting every point of a cell instead (as the paper's list
//! walk does) makes the shadow depend on how many points of one surface fall in a cell, that
//! is on the sampling density and the table's resolution; per surface, a shell of opacity α
//! lets exactly (1 − α)² through its two walls whatever the cloud's density. An opaque surface
//! (α = 1) has τ = ∞: nothing passes, as the paper's α = 100 intends.
//!
//! Per sample of a light (see [`crate::shadow::sample_position`]):
//! 1. `begin_transmit`: T = 1 at every light pixel, no point marked.
//! 2. For each layer k: project (peeling behind layer k − 1 with the light gap), the light
//!    pipeline's fills, then `mark` (mode `Layer`): every point not yet marked that lies within
//!    Δd of layer k's depth at its pixel (the opaque test, Dobrev §6) receives T · 255
//!    (rounded) of this sample's light and is marked; then T ← T · (1 − α) with α the opacity
//!    of the layer's point at the pixel (`blend_layer`, the camera's own front-to-back blend).
//! 3. `mark` (mode `Rest`): points no layer marked (behind the last layer, or peeled by a
//!    layer's plane test but outside its Δd) receive the T left at their pixel.
//!
//! ## Coloured shadows
//!
//! Light through coloured glass takes the glass's colour. When a translucent point has a
//! colour (not grey), the light is tracked per channel: a surface of opacity α and linear
//! colour c has optical depth τ_c = τ · w_c in channel c, with
//! w_c = (1 − c_c + ε) / mean over channels of (1 − c + ε), ε = [`TINT_EPSILON`]: a channel
//! the surface reflects strongly absorbs less and passes more. The weights average to 1, so
//! the geometric mean of the three transmittances is exactly the grey (1 − α), a grey,
//! white or black surface casts the grey shadow, and an opaque point (α = 1) passes nothing
//! in any channel. Light peeling blends τ · w per channel into the accumulator's colour
//! (`transmit_layer`, starting at 0), and a point's channels receive exp(−Σ τ_c) · 255. The
//! texture then holds three sums per light ([`crate::LitTexture::rb`]); shading multiplies
//! each light's diffuse and specular terms per channel, with each channel's m rounded to
//! 8 bits (the GPU packs a pixel's four lights in three words).
//!
//! An opaque cloud takes the single light image of Dobrev §6 as before; its points receive
//! 255 or 0 per sample, so m is unchanged. Shading is unchanged too: m multiplies the diffuse
//! and specular terms of each light (`passes/shade/cpu.rs`), now a fraction for points behind
//! translucent surfaces. Area lights average T over their samples, so a translucent object's
//! shadow is soft as well as partial.

use crate::shadow::ShadowSettings;
use crate::PreparedCloud;

/// ε of the colour weights (see the module notes): keeps a channel a surface reflects in
/// full from passing everything.
pub const TINT_EPSILON: f32 = 0.1;

/// The optical depth of an opaque point (α = 1): nothing passes (exp(−1000 · w) is 0 for
/// every weight [`weights`] gives).
pub const OPAQUE_DEPTH: f32 = 1000.0;

/// The optical depth τ = −ln(1 − α) of a surface of 8-bit opacity `a`.
#[inline]
pub fn optical_depth(a: f32) -> f32 {
    if a >= 1.0 {
        OPAQUE_DEPTH
    } else {
        -(1.0 - a).ln()
    }
}

/// sRGB 8-bit to linear, by the formula (the GPU twin computes the same).
#[inline]
pub fn srgb8_to_linear(v: u8) -> f32 {
    let c = v as f32 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The per-channel weights w_c of a surface's optical depth for its sRGB colour (see the
/// module notes); (1, 1, 1) for grey.
#[inline]
pub fn weights(colour: [u8; 3]) -> [f32; 3] {
    let s = colour.map(|v| 1.0 - srgb8_to_linear(v) + TINT_EPSILON);
    let mean = (s[0] + s[1] + s[2]) * (1.0 / 3.0);
    s.map(|x| x / mean)
}

/// Whether `cloud`'s shadows are coloured: some translucent point has a colour that is not
/// grey (channels more than 2 apart in 8 bits).
pub fn coloured(cloud: &PreparedCloud) -> bool {
    let (Some(alpha), Some(colours)) = (&cloud.alpha, &cloud.cloud.colors) else {
        return false;
    };
    alpha.iter().zip(colours).any(|(&a, c)| {
        let (lo, hi) = (c.iter().min().unwrap(), c.iter().max().unwrap());
        a < 255 && hi - lo > 2
    })
}

/// The light layers a shadow texture of `cloud` peels: `settings.layers` when some point is
/// translucent (opacity below 1 in 8 bits), else 1.
pub fn light_layers(cloud: &PreparedCloud, settings: &ShadowSettings) -> u32 {
    let translucent = cloud
        .alpha
        .as_ref()
        .is_some_and(|a| a.iter().any(|&x| x < 255));
    if translucent {
        settings.layers.max(1)
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_keep_grey_and_the_geometric_mean() {
        for grey in [0u8, 77, 128, 255] {
            for w in weights([grey; 3]) {
                assert!((w - 1.0).abs() < 1e-6, "{grey}: {w}");
            }
        }
        for c in [[230u8, 60, 40], [10, 200, 90], [120, 170, 230]] {
            let w = weights(c);
            assert!(((w[0] + w[1] + w[2]) / 3.0 - 1.0).abs() < 1e-6);
            // The channel the colour is strongest in absorbs least.
            let strongest = (0..3).max_by_key(|&i| c[i]).unwrap();
            assert!((0..3).all(|i| w[strongest] <= w[i]), "{c:?}: {w:?}");
            // The transmittances' geometric mean is the grey (1 − α).
            let tau = optical_depth(0.4);
            let g = w.iter().map(|&w| (-tau * w).exp()).product::<f32>().cbrt();
            assert!((g - 0.6).abs() < 1e-5, "{g}");
        }
        assert!((-OPAQUE_DEPTH * weights([255, 0, 0])[0]).exp() == 0.0);
    }
}
