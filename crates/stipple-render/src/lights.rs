//! Lights: where they are, how an area light is sampled for soft shadows (Dobrev §6), and
//! the one place they are validated.

use glam::DVec3;

/// The most lights a frame shades with (one byte each of a shadow texture's u32 counts).
pub const MAX_LIGHTS: usize = 4;
/// The most shadow samples a light takes (a count must fit one byte).
pub const MAX_SAMPLES: u32 = 255;

/// Where a light is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// At the eye (the default).
    Headlight,
    /// Coming from a world direction (pointing from the scene towards the light).
    Directional([f64; 3]),
    /// At a world position.
    Point([f64; 3]),
    /// An area light (Dobrev §6): shaded as a point light at its centre; its shadow texture
    /// averages `samples` point lights spread over its area.
    Area(AreaLight),
}

/// A flat light: a rectangle or a disc centred at `centre`, facing `facing`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaLight {
    pub centre: [f64; 3],
    /// The direction the emitting face looks (need not be unit length).
    pub facing: [f64; 3],
    pub shape: AreaShape,
    /// Monte Carlo samples for the shadow texture (1 to [`MAX_SAMPLES`]).
    pub samples: u32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AreaShape {
    Rectangle { width: f64, height: f64 },
    Disc { radius: f64 },
}

impl Light {
    /// The position shading uses (the centre of an area light), if the light has one.
    pub fn position(&self) -> Option<[f64; 3]> {
        match self {
            Light::Point(p) => Some(*p),
            Light::Area(a) => Some(a.centre),
            Light::Headlight | Light::Directional(_) => None,
        }
    }
}

/// How many shadow samples a light takes (0: it casts no shadows: headlights and
/// directional lights).
pub fn light_samples(light: &Light) -> u32 {
    match light {
        Light::Point(_) => 1,
        Light::Area(a) => a.samples,
        Light::Headlight | Light::Directional(_) => 0,
    }
}

/// The R2 low-discrepancy sequence (Roberts 2018), shifted so that sample 0 is (0.5, 0.5).
fn r2(k: u32) -> (f64, f64) {
    const A1: f64 = 0.754_877_666_246_692_8;
    const A2: f64 = 0.569_840_290_998_053_3;
    ((0.5 + A1 * k as f64).fract(), (0.5 + A2 * k as f64).fract())
}

/// Two unit vectors spanning the plane perpendicular to `n`.
fn plane_basis(n: DVec3) -> (DVec3, DVec3) {
    let n = n.normalize_or_zero();
    let helper = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let u = n.cross(helper).normalize();
    (u, n.cross(u))
}

/// World position of sample `k` of a light (its position for a point light; sample 0 of an
/// area light is its centre). None for lights without a position.
pub fn sample_position(light: &Light, k: u32) -> Option<DVec3> {
    match light {
        Light::Point(p) => Some(DVec3::from(*p)),
        Light::Area(a) => {
            let (s, t) = r2(k);
            let (u, w) = plane_basis(DVec3::from(a.facing));
            let c = DVec3::from(a.centre);
            Some(match a.shape {
                AreaShape::Rectangle { width, height } => {
                    c + u * ((s - 0.5) * width) + w * ((t - 0.5) * height)
                }
                AreaShape::Disc { radius } => {
                    // Shirley–Chiu concentric map of the square onto the disc.
                    let (x, y) = (2.0 * s - 1.0, 2.0 * t - 1.0);
                    let (r, phi) = if x == 0.0 && y == 0.0 {
                        (0.0, 0.0)
                    } else if x.abs() > y.abs() {
                        (x, std::f64::consts::FRAC_PI_4 * (y / x))
                    } else {
                        (
                            y,
                            std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (x / y),
                        )
                    };
                    c + (u * phi.cos() + w * phi.sin()) * (r * radius)
                }
            })
        }
        Light::Headlight | Light::Directional(_) => None,
    }
}

/// What makes a light unusable.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LightError {
    #[error("{0} lights: 1 to {MAX_LIGHTS} are supported")]
    Count(usize),
    #[error("light {0}: position is not finite")]
    Position(usize),
    #[error("light {0}: direction must be non-zero")]
    Direction(usize),
    #[error("light {light}: {samples} samples (1 to {MAX_SAMPLES})")]
    Samples { light: usize, samples: u32 },
    #[error("light {0}: centre and facing direction must be finite and non-zero")]
    Placement(usize),
    #[error("light {0}: its size must be positive")]
    Size(usize),
}

/// Checks a pipeline's lights: 1 to [`MAX_LIGHTS`], finite, area lights with 1 to
/// [`MAX_SAMPLES`] samples and a positive size. Lights are counted from 1 in the errors.
pub fn validate(lights: &[Light]) -> Result<(), LightError> {
    if lights.is_empty() || lights.len() > MAX_LIGHTS {
        return Err(LightError::Count(lights.len()));
    }
    for (i, l) in lights.iter().enumerate() {
        let n = i + 1;
        let finite = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        match l {
            Light::Point(p) if !finite(p) => return Err(LightError::Position(n)),
            Light::Directional(d) if !finite(d) || DVec3::from(*d).length() == 0.0 => {
                return Err(LightError::Direction(n))
            }
            Light::Area(a) => {
                if !(1..=MAX_SAMPLES).contains(&a.samples) {
                    return Err(LightError::Samples {
                        light: n,
                        samples: a.samples,
                    });
                }
                if !finite(&a.centre) || !finite(&a.facing) || DVec3::from(a.facing).length() == 0.0
                {
                    return Err(LightError::Placement(n));
                }
                let ok = match a.shape {
                    AreaShape::Rectangle { width, height } => width > 0.0 && height > 0.0,
                    AreaShape::Disc { radius } => radius > 0.0,
                };
                if !ok {
                    return Err(LightError::Size(n));
                }
            }
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn area_samples_start_at_the_centre_and_stay_on_the_light() {
        for shape in [
            AreaShape::Rectangle {
                width: 2.0,
                height: 1.0,
            },
            AreaShape::Disc { radius: 0.5 },
        ] {
            let l = Light::Area(AreaLight {
                centre: [1.0, 5.0, 2.0],
                facing: [0.0, -1.0, 0.0],
                shape,
                samples: 30,
            });
            assert_eq!(sample_position(&l, 0), Some(DVec3::new(1.0, 5.0, 2.0)));
            let mut xs = Vec::new();
            for k in 0..30 {
                let p = sample_position(&l, k).unwrap() - DVec3::new(1.0, 5.0, 2.0);
                assert!(p.y.abs() < 1e-12, "in the light's plane");
                match shape {
                    AreaShape::Rectangle { .. } => {
                        assert!(p.x.abs() <= 1.0 + 1e-12 && p.z.abs() <= 1.0 + 1e-12)
                    }
                    AreaShape::Disc { radius } => assert!(p.length() <= radius + 1e-12),
                }
                xs.push(p);
            }
            // Spread: the samples are distinct and cover both sides of the centre.
            assert!(xs.iter().any(|p| p.x > 0.2) && xs.iter().any(|p| p.x < -0.2));
        }
    }
}
