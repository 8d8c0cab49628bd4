//! sRGB encoding and decoding, shared by both backends (the GPU uploads these tables, so the
//! two encode identically).

pub use stipple_core::colour_map::intensity_grey;

/// sRGB 8-bit → linear, by level.
pub fn srgb_to_linear_table() -> [f32; 256] {
    let mut t = [0.0; 256];
    for (i, v) in t.iter_mut().enumerate() {
        let c = i as f32 / 255.0;
        *v = if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        };
    }
    t
}

/// Linear → sRGB 8-bit through a 16384-entry table (error under 0.5 of an 8-bit level
/// beyond rounding).
pub struct SrgbEncoder(Vec<u8>);

impl SrgbEncoder {
    const N: usize = 16384;

    pub fn new() -> SrgbEncoder {
        SrgbEncoder(
            (0..Self::N)
                .map(|i| linear_to_srgb8(i as f32 / (Self::N - 1) as f32))
                .collect(),
        )
    }

    /// The table itself: entry i encodes the linear value i / (N − 1) (the GPU output pass
    /// uploads it, so both backends encode identically).
    pub fn table(&self) -> &[u8] {
        &self.0
    }

    #[inline]
    pub fn encode(&self, c: f32) -> u8 {
        let i = (c.clamp(0.0, 1.0) * (Self::N - 1) as f32 + 0.5) as usize;
        self.0[i]
    }
}

impl Default for SrgbEncoder {
    fn default() -> Self {
        Self::new()
    }
}

/// Linear → sRGB 8-bit (exact).
pub fn linear_to_srgb8(c: f32) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}
