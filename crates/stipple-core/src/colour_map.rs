//! Colour by attribute (Gunjee et al. §3, rendering-oriented attributes; and what LiDAR
//! tools call "colour by"): a per-point value (elevation, intensity, a coordinate) mapped
//! through a named colour map over a range, or a classification code through the ASPRS
//! class palette. The result is an sRGB colour per point, which every pipeline and backend
//! then shades like a file's own colours.
//!
//! Colour maps are piecewise linear between key colours in sRGB (each key is the map's
//! published colour at that fraction): `viridis` (perceptually uniform, colour-blind safe;
//! the default), `turbo` (a rainbow with a smooth lightness profile, for detail), `grey`
//! (black to white) and `inferno` (black through red to yellow). Values below or above the
//! range take the end colours.

use crate::PointCloud;

/// A per-point quantity to colour by.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Attribute {
    /// Height: world Z for Z-up sources (LAS/LAZ/COPC, clouds flat in Z), else world Y.
    Elevation,
    /// LiDAR return intensity.
    Intensity,
    /// LiDAR classification code, through the ASPRS class palette (the colour map is not
    /// used).
    Classification,
    /// World X.
    X,
    /// World Y.
    Y,
    /// World Z.
    Z,
    /// LiDAR return number (1 = first echo of a pulse), through its own palette (the colour
    /// map is not used): first returns light grey, second amber, third orange, fourth red,
    /// later ones purple, so that canopy and what lies under it stand out from open ground.
    #[cfg_attr(feature = "clap", value(name = "return", alias = "return-number"))]
    Return,
}

/// The scale (1 / the 99th percentile) under which a cloud without colours shows its
/// intensity as grey ([`intensity_grey`]) by default, or None where the intensity shows
/// nothing ([`intensity_scale_or_why`]).
pub fn intensity_scale(v: &[u16]) -> Option<f32> {
    intensity_scale_or_why(v).ok()
}

/// Why a cloud's intensity is not shown by default ([`intensity_scale_or_why`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum IntensityHidden {
    /// No points, or 99% of them (or one value held by half of them) zero.
    Zero,
    /// One value held by this share (at least half) of the points.
    Placeholder { value: u16, share: f64 },
}

/// [`intensity_scale`], or why there is none: all (or 99% of it) zero, or a placeholder, one
/// value held by at least half the points. The Stanford bunny's zipper reconstruction writes
/// 0.5 for 79% of its points and lower values at scattered others; shown, they
/// speckled a uniform surface white and grey. A LiDAR return's intensity varies from point
/// to point (Autzen's most common value holds 1% of its points). `--colour-by intensity`
/// shows any intensity.
pub fn intensity_scale_or_why(v: &[u16]) -> Result<f32, IntensityHidden> {
    let mut hist = vec![0u64; 65536];
    for &i in v {
        hist[i as usize] += 1;
    }
    let n = v.len() as u64;
    if n == 0 {
        return Err(IntensityHidden::Zero);
    }
    let (value, &most) = hist
        .iter()
        .enumerate()
        .max_by_key(|&(i, c)| (*c, std::cmp::Reverse(i)))
        .expect("65536 bins");
    if 2 * most >= n {
        return Err(if value == 0 {
            IntensityHidden::Zero
        } else {
            IntensityHidden::Placeholder {
                value: value as u16,
                share: most as f64 / n as f64,
            }
        });
    }
    let target = (n as f64 * 0.99) as u64;
    let mut acc = 0;
    let p99 = hist
        .iter()
        .position(|&c| {
            acc += c;
            acc >= target
        })
        .unwrap_or(0);
    if p99 == 0 {
        return Err(IntensityHidden::Zero);
    }
    Ok(1.0 / p99 as f32)
}

/// The sRGB 8-bit grey level that shows intensity `t` under `scale` ([`intensity_scale`]).
#[inline]
pub fn intensity_grey(t: u16, scale: f32) -> u8 {
    ((t as f32 * scale).min(1.0) * 255.0) as u8
}

/// A named colour map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ColourMap {
    #[default]
    Viridis,
    Turbo,
    #[cfg_attr(feature = "clap", value(alias = "gray"))]
    Grey,
    Inferno,
}

/// Why a cloud cannot be coloured as asked.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ColourError {
    #[error("the cloud has no {0} values to colour by")]
    Missing(&'static str),
    #[error("the cloud has no attribute or scalar field `{name}` to colour by (it has: {have})")]
    NoField { name: String, have: String },
    #[error("colour range {0}..{1}: it must be finite with the low end below the high end")]
    Range(f64, f64),
    #[error("the cloud has no points")]
    Empty,
}

const VIRIDIS: &[u32] = &[
    0x440154, 0x482878, 0x3e4989, 0x31688e, 0x26828e, 0x1f9e89, 0x35b779, 0x6ece58, 0xb5de2b,
    0xfde725,
];
const TURBO: &[u32] = &[
    0x30123b, 0x4145ab, 0x4675ed, 0x39a2fc, 0x1bcfd4, 0x24eca6, 0x61fc6c, 0xa4fc3b, 0xd1e834,
    0xf3c63a, 0xfe9b2d, 0xf36315, 0xd93806, 0xb11901, 0x7a0402,
];
const INFERNO: &[u32] = &[
    0x000004, 0x1b0c41, 0x4a0c6b, 0x781c6d, 0xa52c60, 0xcf4446, 0xed6925, 0xfb9b06, 0xf7d13d,
    0xfcffa4,
];
const GREY: &[u32] = &[0x000000, 0xffffff];

impl ColourMap {
    fn keys(self) -> &'static [u32] {
        match self {
            ColourMap::Viridis => VIRIDIS,
            ColourMap::Turbo => TURBO,
            ColourMap::Grey => GREY,
            ColourMap::Inferno => INFERNO,
        }
    }

    /// The sRGB colour at fraction `t` of the map (clamped to [0, 1]; NaN: the low end).
    pub fn at(self, t: f32) -> [u8; 3] {
        let keys = self.keys();
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let x = t * (keys.len() - 1) as f32;
        let k = (x.floor() as usize).min(keys.len() - 2);
        let f = x - k as f32;
        let rgb = |c: u32| [(c >> 16) as u8, (c >> 8) as u8, c as u8];
        let (a, b) = (rgb(keys[k]), rgb(keys[k + 1]));
        std::array::from_fn(|i| (a[i] as f32 + (b[i] as f32 - a[i] as f32) * f).round() as u8)
    }
}

/// The colour of an ASPRS classification code (LAS 1.4 table 17 names; colours as LiDAR
/// viewers commonly draw them): 0–1 unclassified grey, 2 ground brown, 3–5 low, medium and
/// high vegetation in lighter to darker greens, 6 building orange, 7 low noise magenta,
/// 8 model key point, 9 water blue, 10 rail, 11 road surface dark grey, 12 overlap, 13–14
/// wires yellow, 15 transmission tower, 16 wire connector, 17 bridge deck, 18 high noise
/// magenta; other codes a colour of their own from a fixed hash.
pub fn class_colour(code: u8) -> [u8; 3] {
    match code {
        0 | 1 => [170, 170, 170],
        2 => [150, 105, 60],
        3 => [170, 220, 110],
        4 => [80, 180, 60],
        5 => [30, 110, 40],
        6 => [235, 120, 50],
        7 | 18 => [230, 40, 200],
        8 => [255, 255, 255],
        9 => [40, 110, 230],
        10 => [120, 80, 140],
        11 => [90, 90, 95],
        12 => [200, 200, 120],
        13 | 14 => [250, 220, 40],
        15 => [200, 60, 60],
        16 => [250, 160, 40],
        17 => [160, 160, 200],
        c => {
            let h = (c as u32).wrapping_mul(0x9E37_79B9);
            [
                (h >> 24) as u8 | 64,
                (h >> 16) as u8 | 64,
                (h >> 8) as u8 | 64,
            ]
        }
    }
}

/// The attribute's value per point (world units for coordinates), or why there is none.
pub fn values(cloud: &PointCloud, attr: Attribute) -> Result<Vec<f64>, ColourError> {
    if cloud.positions.is_empty() {
        return Err(ColourError::Empty);
    }
    let axis = |a: usize| -> Vec<f64> {
        let o = cloud.origin.to_array()[a];
        cloud
            .positions
            .iter()
            .map(|p| o + p.to_array()[a] as f64)
            .collect()
    };
    Ok(match attr {
        Attribute::Elevation => axis(if elevation_is_z(cloud) { 2 } else { 1 }),
        Attribute::X => axis(0),
        Attribute::Y => axis(1),
        Attribute::Z => axis(2),
        Attribute::Intensity => match &cloud.intensity {
            Some(v) => v.iter().map(|&v| v as f64).collect(),
            None => field_values(cloud, "intensity").ok_or(ColourError::Missing("intensity"))?,
        },
        Attribute::Classification => match &cloud.classification {
            Some(v) => v.iter().map(|&v| v as f64).collect(),
            None => field_values(cloud, "classification")
                .ok_or(ColourError::Missing("classification"))?,
        },
        Attribute::Return => match &cloud.return_number {
            Some(v) => v.iter().map(|&v| v as f64).collect(),
            None => {
                field_values(cloud, "return_number").ok_or(ColourError::Missing("return-number"))?
            }
        },
    })
}

/// The values of the scalar field `name` (see [`crate::cloud::Field::is_named`]).
fn field_values(cloud: &PointCloud, name: &str) -> Option<Vec<f64>> {
    let f = cloud.field(name)?;
    Some((0..cloud.len()).map(|i| f.value(i)).collect())
}

/// What to colour by: a built-in attribute or a scalar field of the file, by name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ColourBy {
    Attribute(Attribute),
    /// A scalar field (a PLY or PCD property stipple has no column for).
    Field(String),
}

impl ColourBy {
    /// The name as the user gave it, for messages.
    pub fn name(&self) -> String {
        match self {
            ColourBy::Attribute(a) => format!("{a:?}").to_lowercase(),
            ColourBy::Field(f) => f.clone(),
        }
    }
}

/// Colours every point by `by` (see [`colour_by`]); a field takes a colour map like a
/// built-in value.
pub fn colour_by_any(
    cloud: &PointCloud,
    by: &ColourBy,
    map: ColourMap,
    range: Option<(f64, f64)>,
) -> Result<Coloured, ColourError> {
    match by {
        ColourBy::Attribute(a) => colour_by(cloud, *a, map, range),
        ColourBy::Field(name) => {
            if cloud.positions.is_empty() {
                return Err(ColourError::Empty);
            }
            let v = field_values(cloud, name).ok_or_else(|| ColourError::NoField {
                name: name.clone(),
                have: cloud.attributes().join(", "),
            })?;
            map_values(&v, map, range)
        }
    }
}

/// Whether "elevation" is world Z for this cloud: the source says Z is up, or the cloud is
/// flat in Z (a tile seen from above), as the default framing decides.
pub fn elevation_is_z(cloud: &PointCloud) -> bool {
    let e = crate::Bounds::from_points(&cloud.positions).extent();
    cloud.z_up || e.z < 0.35 * e.x.min(e.y)
}

/// The range a colour map spans by default: the 2nd to the 98th percentile of the values
/// (a few outliers, such as birds and low points in LiDAR, do not squash the rest into one
/// colour); the whole range when that is empty.
pub fn robust_range(values: &[f64]) -> (f64, f64) {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (0.0, 1.0);
    }
    v.sort_unstable_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = (at(0.02), at(0.98));
    if hi > lo {
        (lo, hi)
    } else if v[v.len() - 1] > v[0] {
        (v[0], v[v.len() - 1])
    } else {
        (v[0] - 0.5, v[0] + 0.5)
    }
}

/// sRGB colours per point, and the value range the colour map spans.
pub type Coloured = (Vec<[u8; 3]>, (f64, f64));

/// sRGB colours of every point by `attr` through `map` over `range` (None: [`robust_range`]),
/// and the range used.
pub fn colour_by(
    cloud: &PointCloud,
    attr: Attribute,
    map: ColourMap,
    range: Option<(f64, f64)>,
) -> Result<Coloured, ColourError> {
    let v = values(cloud, attr)?;
    if attr == Attribute::Classification {
        let range = range.unwrap_or((0.0, 255.0));
        return Ok((v.iter().map(|&c| class_colour(c as u8)).collect(), range));
    }
    if attr == Attribute::Return {
        const PALETTE: [[u8; 3]; 5] = [
            [205, 205, 200],
            [250, 195, 60],
            [240, 110, 40],
            [200, 40, 40],
            [150, 50, 160],
        ];
        let colour = |r: f64| PALETTE[(r.max(1.0) as usize - 1).min(PALETTE.len() - 1)];
        return Ok((v.iter().map(|&r| colour(r)).collect(), (1.0, 5.0)));
    }
    map_values(&v, map, range)
}

/// Values through `map` over `range` (None: [`robust_range`]).
fn map_values(
    v: &[f64],
    map: ColourMap,
    range: Option<(f64, f64)>,
) -> Result<Coloured, ColourError> {
    let (lo, hi) = match range {
        Some((lo, hi)) if lo.is_finite() && hi.is_finite() && lo < hi => (lo, hi),
        Some((lo, hi)) => return Err(ColourError::Range(lo, hi)),
        None => robust_range(v),
    };
    let inv = 1.0 / (hi - lo);
    Ok((
        v.iter().map(|&x| map.at(((x - lo) * inv) as f32)).collect(),
        (lo, hi),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn return_numbers_have_a_colour_each() {
        let mut c = PointCloud::from_world(&[DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z]);
        assert!(colour_by(&c, Attribute::Return, ColourMap::Viridis, None).is_err());
        c.return_number = Some(vec![1, 1, 2, 9]);
        let (col, _) = colour_by(&c, Attribute::Return, ColourMap::Viridis, None).unwrap();
        assert_eq!(col[0], col[1]);
        assert!(col[0] != col[2] && col[2] != col[3], "{col:?}");
    }

    #[test]
    fn maps_start_and_end_at_their_key_colours_and_clamp() {
        assert_eq!(ColourMap::Viridis.at(0.0), [0x44, 0x01, 0x54]);
        assert_eq!(ColourMap::Viridis.at(1.0), [0xfd, 0xe7, 0x25]);
        assert_eq!(ColourMap::Viridis.at(-3.0), ColourMap::Viridis.at(0.0));
        assert_eq!(ColourMap::Viridis.at(7.0), ColourMap::Viridis.at(1.0));
        assert_eq!(ColourMap::Grey.at(0.5), [128, 128, 128]);
        assert_eq!(ColourMap::Turbo.at(f32::NAN), ColourMap::Turbo.at(0.0));
        // Viridis and grey grow lighter along the map.
        for map in [ColourMap::Viridis, ColourMap::Grey, ColourMap::Inferno] {
            let luma = |c: [u8; 3]| 0.3 * c[0] as f32 + 0.59 * c[1] as f32 + 0.11 * c[2] as f32;
            let l: Vec<f32> = (0..=20).map(|k| luma(map.at(k as f32 / 20.0))).collect();
            assert!(l.windows(2).all(|w| w[1] >= w[0] - 1.0), "{map:?}: {l:?}");
        }
    }

    #[test]
    fn elevation_follows_the_up_axis_and_the_range_ignores_outliers() {
        // A tile from a LAS file (Z up) with one bird far above it.
        let mut pts: Vec<DVec3> = (0..1000)
            .map(|i| {
                DVec3::new(
                    (i % 40) as f64,
                    (i / 40) as f64,
                    100.0 + 0.01 * (i % 40) as f64,
                )
            })
            .collect();
        pts.push(DVec3::new(5.0, 5.0, 500.0));
        let mut c = PointCloud::from_world(&pts);
        assert!(!elevation_is_z(&c), "the bird makes it tall");
        c.z_up = true;
        assert!(elevation_is_z(&c));
        let (colours, (lo, hi)) =
            colour_by(&c, Attribute::Elevation, ColourMap::Viridis, None).unwrap();
        assert!(
            (lo - 100.0).abs() < 0.02 && (hi - 100.39).abs() < 0.02,
            "{lo} {hi}"
        );
        assert_eq!(colours[0], ColourMap::Viridis.at(0.0));
        assert_eq!(colours[39], ColourMap::Viridis.at(1.0));
        assert_eq!(colours[1000], ColourMap::Viridis.at(1.0), "the bird clamps");
        // A given range is used as is; a bad one is an error.
        let (_, r) = colour_by(&c, Attribute::X, ColourMap::Grey, Some((0.0, 39.0))).unwrap();
        assert_eq!(r, (0.0, 39.0));
        for bad in [(1.0, 1.0), (2.0, 1.0), (f64::NAN, 1.0)] {
            assert!(matches!(
                colour_by(&c, Attribute::X, ColourMap::Grey, Some(bad)),
                Err(ColourError::Range(..))
            ));
        }
    }

    #[test]
    fn classification_uses_the_class_palette_and_missing_attributes_are_errors() {
        let mut c = PointCloud::from_world(&[DVec3::ZERO, DVec3::X, DVec3::Y]);
        assert_eq!(
            colour_by(&c, Attribute::Classification, ColourMap::Viridis, None).err(),
            Some(ColourError::Missing("classification"))
        );
        assert_eq!(
            colour_by(&c, Attribute::Intensity, ColourMap::Viridis, None).err(),
            Some(ColourError::Missing("intensity"))
        );
        c.classification = Some(vec![2, 6, 200]);
        let (col, _) = colour_by(&c, Attribute::Classification, ColourMap::Turbo, None).unwrap();
        assert_eq!(col[0], class_colour(2));
        assert_eq!(col[1], class_colour(6));
        assert_ne!(col[0], col[1]);
        assert_eq!(col[2], class_colour(200));
        // Every code has a colour, and the common classes differ from each other.
        let common: Vec<[u8; 3]> = [1, 2, 3, 4, 5, 6, 7, 9, 11].map(class_colour).to_vec();
        for (i, a) in common.iter().enumerate() {
            for b in &common[i + 1..] {
                assert_ne!(a, b);
            }
        }
        assert_eq!(
            colour_by(&PointCloud::default(), Attribute::X, ColourMap::Grey, None).err(),
            Some(ColourError::Empty)
        );
    }

    #[test]
    fn scalar_fields_colour_by_name_and_stand_in_for_missing_columns() {
        use crate::cloud::Field;
        let mut c = PointCloud::from_world(&[DVec3::ZERO, DVec3::X, DVec3::Y]);
        c.fields
            .push(Field::new("scalar_Curvature", &[0.0, 0.5, 1.0]));
        c.fields
            .push(Field::new("Classification", &[2.0, 6.0, 2.0]));
        let by = ColourBy::Field("curvature".into());
        let (col, r) = colour_by_any(&c, &by, ColourMap::Grey, Some((0.0, 1.0))).unwrap();
        assert_eq!(r, (0.0, 1.0));
        assert_eq!(col, vec![[0, 0, 0], [128, 128, 128], [255, 255, 255]]);
        // A PLY's classification property colours by class like a LAS file's.
        let (col, _) = colour_by(&c, Attribute::Classification, ColourMap::Grey, None).unwrap();
        assert_eq!(col[1], class_colour(6));
        let e = colour_by_any(&c, &ColourBy::Field("gps".into()), ColourMap::Grey, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("`gps`") && e.contains("scalar_Curvature"), "{e}");
        // Large values with a small spread keep their precision (GPS times).
        let f = Field::new("t", &[4.0e8, 4.0e8 + 0.25]);
        assert_eq!(f.value(1) - f.value(0), 0.25);
    }

    /// Intensity shows as grey under 1 / its 99th percentile where it varies, and not at all
    /// where one value holds half the points or more (a placeholder) or where it is zero.
    #[test]
    fn intensity_shows_where_it_varies() {
        // Varying: 0..1000, each value once; 99% of them are at most 989.
        let v: Vec<u16> = (0..1000).collect();
        let s = intensity_scale(&v).unwrap();
        assert_eq!(s, 1.0 / 989.0);
        assert_eq!(intensity_grey(495, s), 127);
        assert_eq!(intensity_grey(999, s), 255);
        // A placeholder: one value for half the points, whatever the others hold.
        for share in [500, 750, 1000] {
            let mut v: Vec<u16> = (0..1000).map(|i| (i * 37 % 3000) as u16).collect();
            v[..share].fill(32768);
            assert_eq!(intensity_scale(&v), None, "{share}");
        }
        // Just under half on one value still varies.
        let mut v: Vec<u16> = (0..1000).map(|i| 1 + i as u16).collect();
        v[..499].fill(7);
        assert!(intensity_scale(&v).is_some());
        let mut v: Vec<u16> = (0..1000).map(|i| i as u16).collect();
        v[..750].fill(32768);
        assert_eq!(
            intensity_scale_or_why(&v),
            Err(IntensityHidden::Placeholder {
                value: 32768,
                share: 0.75
            })
        );
        // Nothing to show: no points, all zero, or 99% zero.
        assert_eq!(intensity_scale_or_why(&[0; 10]), Err(IntensityHidden::Zero));
        assert_eq!(intensity_scale(&[]), None);
        assert_eq!(intensity_scale(&[0; 10]), None);
        let mut v = vec![0u16; 1000];
        for (i, x) in v.iter_mut().enumerate().take(9) {
            *x = 100 + i as u16;
        }
        assert_eq!(intensity_scale(&v), None);
    }
}
