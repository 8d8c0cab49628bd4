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
//! An opaque cloud takes the single light image of Dobrev §6 as before; its points receive
//! 255 or 0 per sample, so m is unchanged. Shading is unchanged too: m multiplies the diffuse
//! and specular terms of each light (`passes/shade/cpu.rs`), now a fraction for points behind
//! translucent surfaces. Area lights average T over their samples, so a translucent object's
//! shadow is soft as well as partial.

use crate::shadow::ShadowSettings;
use crate::PreparedCloud;

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
