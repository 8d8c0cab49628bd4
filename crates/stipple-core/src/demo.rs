//! Built-in demo scenes: points sampled uniformly by area on analytic surfaces, with normals
//! and colours, reproducible from a seed.

use crate::cloud::PointCloud;
use crate::rng::Rng;
use glam::Vec3;
use std::f32::consts::TAU;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DemoScene {
    /// Unit sphere at the origin.
    Sphere,
    /// Torus around the Y axis, major radius 1, minor radius 0.35.
    Torus,
    /// Dobrev Fig. 17: three tori sharing a centre line, tube radii 0.2, 0.3, 0.4;
    /// opaque brown inside, green α = 0.5, blue α = 0.3 outside.
    NestedTori,
    /// A 4 × 4 ground plane (y = 0) with a sphere, a standing torus and a box on it.
    PlaneObjects,
}

impl DemoScene {
    pub const ALL: [DemoScene; 4] = [
        DemoScene::Sphere,
        DemoScene::Torus,
        DemoScene::NestedTori,
        DemoScene::PlaneObjects,
    ];

    pub fn name(self) -> &'static str {
        match self {
            DemoScene::Sphere => "sphere",
            DemoScene::Torus => "torus",
            DemoScene::NestedTori => "nested-tori",
            DemoScene::PlaneObjects => "plane-objects",
        }
    }

    pub fn from_name(s: &str) -> Option<DemoScene> {
        DemoScene::ALL.into_iter().find(|d| d.name() == s)
    }

    /// Default point count when none is given.
    pub fn default_points(self) -> usize {
        match self {
            DemoScene::NestedTori => 1_500_000,
            _ => 1_000_000,
        }
    }
}

/// Accumulates sampled parts into one cloud.
#[derive(Default)]
struct Builder {
    p: Vec<Vec3>,
    n: Vec<Vec3>,
    c: Vec<[u8; 3]>,
    a: Vec<f32>,
}

impl Builder {
    fn push(&mut self, p: Vec3, n: Vec3, c: [u8; 3], a: f32) {
        self.p.push(p);
        self.n.push(n);
        self.c.push(c);
        self.a.push(a);
    }

    /// The cloud with its points in Morton (Z-curve) order of position, as a scanner or a
    /// tiling tool writes them: neighbours in the file are neighbours in space.
    fn finish(self, with_opacity: bool) -> PointCloud {
        let order = morton_order(&self.p);
        let pick = |v: &[f32]| order.iter().map(|&i| v[i]).collect::<Vec<_>>();
        PointCloud {
            positions: order.iter().map(|&i| self.p[i]).collect(),
            normals: Some(order.iter().map(|&i| self.n[i]).collect()),
            colors: Some(order.iter().map(|&i| self.c[i]).collect()),
            opacity: with_opacity.then(|| pick(&self.a)),
            ..Default::default()
        }
    }
}

/// Indices of `p` sorted by the Morton code of their position in a 2^10 grid over the bounds.
pub fn morton_order(p: &[Vec3]) -> Vec<usize> {
    let b = crate::Bounds::from_points(p);
    let scale = 1023.0 / b.extent().max_element().max(f32::MIN_POSITIVE);
    let mut keyed: Vec<(u32, usize)> = p
        .iter()
        .enumerate()
        .map(|(i, &q)| {
            let c = ((q - b.min) * scale)
                .to_array()
                .map(|v| v.clamp(0.0, 1023.0) as u32);
            (crate::cloud::morton3(c), i)
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// A point uniformly distributed on the unit sphere.
pub fn sphere_point(rng: &mut Rng) -> Vec3 {
    let z = 2.0 * rng.f32() - 1.0;
    let phi = TAU * rng.f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// A point uniformly distributed (by area) on a torus around the Y axis; returns the point
/// and its normal.
pub fn torus_point(rng: &mut Rng, major: f32, minor: f32) -> (Vec3, Vec3) {
    loop {
        let theta = TAU * rng.f32();
        // Area element ∝ (R + r cos θ): rejection sampling on θ.
        if rng.f32() * (major + minor) > major + minor * theta.cos() {
            continue;
        }
        let phi = TAU * rng.f32();
        let n = Vec3::new(
            theta.cos() * phi.cos(),
            theta.sin(),
            theta.cos() * phi.sin(),
        );
        let ring = Vec3::new(phi.cos(), 0.0, phi.sin()) * major;
        return (ring + n * minor, n);
    }
}

fn shade(base: [u8; 3], rng: &mut Rng, amount: f32) -> [u8; 3] {
    let k = 1.0 + amount * (rng.f32() - 0.5);
    base.map(|v| (v as f32 * k).clamp(0.0, 255.0) as u8)
}

/// A torus around the Y axis (major radius 1, tube radius `tube`) of one colour.
pub fn torus(n: usize, tube: f32, colour: [u8; 3], seed: u64) -> PointCloud {
    let mut rng = Rng::new(seed);
    let mut b = Builder::default();
    for _ in 0..n {
        let (p, nn) = torus_point(&mut rng, 1.0, tube);
        b.push(p, nn, colour, 1.0);
    }
    b.finish(false)
}

/// A unit square in the XZ plane centred at the origin, facing +Y, of one colour.
pub fn plane(n: usize, colour: [u8; 3], seed: u64) -> PointCloud {
    let mut rng = Rng::new(seed);
    let mut b = Builder::default();
    for _ in 0..n {
        let p = Vec3::new(rng.f32() - 0.5, 0.0, rng.f32() - 0.5);
        b.push(p, Vec3::Y, colour, 1.0);
    }
    b.finish(false)
}

/// Generates `scene` with (about) `n` points; the same seed gives the same cloud.
pub fn generate(scene: DemoScene, n: usize, seed: u64) -> PointCloud {
    let mut rng = Rng::new(seed);
    let mut b = Builder::default();
    match scene {
        DemoScene::Sphere => {
            for _ in 0..n {
                let p = sphere_point(&mut rng);
                // Colour by latitude so the shading of the sphere is easy to read.
                let t = (p.y + 1.0) * 0.5;
                let c = [(200.0 - 120.0 * t) as u8, (90.0 + 110.0 * t) as u8, 170];
                b.push(p, p, c, 1.0);
            }
            b.finish(false)
        }
        DemoScene::Torus => {
            for _ in 0..n {
                let (p, nn) = torus_point(&mut rng, 1.0, 0.35);
                b.push(p, nn, shade([214, 170, 60], &mut rng, 0.1), 1.0);
            }
            b.finish(false)
        }
        DemoScene::NestedTori => {
            let parts = [
                (0.2, [120u8, 72, 40], 1.0f32),
                (0.3, [60, 170, 70], 0.5),
                (0.4, [60, 100, 210], 0.3),
            ];
            // Split by area (∝ minor radius) so every torus has the same density.
            let total: f32 = parts.iter().map(|p| p.0).sum();
            for (k, &(r, col, alpha)) in parts.iter().enumerate() {
                let m = if k == parts.len() - 1 {
                    n - b.p.len()
                } else {
                    (n as f32 * r / total) as usize
                };
                for _ in 0..m {
                    let (p, nn) = torus_point(&mut rng, 1.0, r);
                    b.push(p, nn, col, alpha);
                }
            }
            b.finish(true)
        }
        DemoScene::PlaneObjects => {
            // Areas: plane 16, sphere (r 0.6) 4.52, torus (1.0 x 0.25 ... scaled 0.6) ~5.9,
            // box 0.8^3 → 3.84. Points split by area.
            let sphere_r = 0.6f32;
            let (tor_r, tor_t) = (0.6f32, 0.18f32);
            let areas = [
                16.0,
                4.0 * std::f32::consts::PI * sphere_r * sphere_r,
                4.0 * std::f32::consts::PI * std::f32::consts::PI * tor_r * tor_t,
                6.0 * 0.8 * 0.8,
            ];
            let total: f32 = areas.iter().sum();
            let counts: Vec<usize> = areas
                .iter()
                .map(|a| (n as f32 * a / total) as usize)
                .collect();
            for _ in 0..counts[0] {
                let p = Vec3::new(4.0 * rng.f32() - 2.0, 0.0, 4.0 * rng.f32() - 2.0);
                let checker = ((p.x.floor() + p.z.floor()) as i32).rem_euclid(2) == 0;
                let col = if checker {
                    [200, 200, 190]
                } else {
                    [150, 150, 140]
                };
                b.push(p, Vec3::Y, col, 1.0);
            }
            for _ in 0..counts[1] {
                let d = sphere_point(&mut rng);
                b.push(
                    Vec3::new(-0.9, sphere_r, -0.5) + d * sphere_r,
                    d,
                    [200, 60, 50],
                    1.0,
                );
            }
            for _ in 0..counts[2] {
                // A torus standing on its rim: rotate the Y-axis torus about X by 90°.
                let (p, nn) = torus_point(&mut rng, tor_r, tor_t);
                let rot = |v: Vec3| Vec3::new(v.x, -v.z, v.y);
                b.push(
                    rot(p) + Vec3::new(0.8, tor_r + tor_t, 0.6),
                    rot(nn),
                    [214, 170, 60],
                    1.0,
                );
            }
            let rest = n.saturating_sub(b.p.len());
            for _ in 0..rest {
                // Box of side 0.8 standing on the plane at (0.6, 0, -0.9): its five faces
                // that can be seen, as a scan takes them. (A bottom face would lie in the
                // plane facing down, and the plane's points beside it face up: neighbours
                // whose normals disagree, which render reports as inconsistent given normals.)
                let face: usize = [0, 1, 2, 4, 5][rng.below(5) as usize];
                let (u, v) = (rng.f32() - 0.5, rng.f32() - 0.5);
                let axis = face / 2;
                let sign = if face.is_multiple_of(2) { 0.5 } else { -0.5 };
                let mut q = [0.0f32; 3];
                q[axis] = sign;
                q[(axis + 1) % 3] = u;
                q[(axis + 2) % 3] = v;
                let mut nn = [0.0f32; 3];
                nn[axis] = sign * 2.0;
                let p = Vec3::from(q) * 0.8 + Vec3::new(0.6, 0.4, -0.9);
                b.push(p, Vec3::from(nn), [70, 130, 190], 1.0);
            }
            b.finish(false)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scenes_are_valid_reproducible_and_sized() {
        for s in DemoScene::ALL {
            let a = generate(s, 5000, 7);
            a.validate().unwrap();
            assert_eq!(a.len(), 5000, "{}", s.name());
            let b = generate(s, 5000, 7);
            assert_eq!(a.positions, b.positions);
            let c = generate(s, 5000, 8);
            assert_ne!(a.positions, c.positions);
            for nn in a.normals.as_ref().unwrap() {
                assert!((nn.length() - 1.0).abs() < 1e-4);
            }
            assert_eq!(DemoScene::from_name(s.name()), Some(s));
        }
    }

    /// The demo scenes' normals are consistent as given: `render` would otherwise report
    /// them inconsistent and turn some round (a box's bottom face lying in the plane did).
    #[test]
    fn demo_normals_are_consistent() {
        use crate::normals::{inconsistency, neighbours, DEFAULT_K, INCONSISTENT};
        for s in DemoScene::ALL {
            let c = generate(s, 200_000, 1);
            let nb = neighbours(&c.positions, DEFAULT_K).unwrap();
            let bad = inconsistency(&c.positions, c.normals.as_ref().unwrap(), &nb);
            assert!(bad < INCONSISTENT / 4.0, "{}: {bad}", s.name());
        }
    }

    #[test]
    fn samples_lie_on_their_surfaces() {
        let s = generate(DemoScene::Sphere, 1000, 1);
        assert!(s.positions.iter().all(|p| (p.length() - 1.0).abs() < 1e-5));
        let t = generate(DemoScene::Torus, 1000, 1);
        for p in &t.positions {
            let ring = (p.x * p.x + p.z * p.z).sqrt();
            let d = ((ring - 1.0).powi(2) + p.y * p.y).sqrt();
            assert!((d - 0.35).abs() < 1e-5);
        }
        let nt = generate(DemoScene::NestedTori, 3000, 1);
        let op = nt.opacity.as_ref().unwrap();
        assert!(op.contains(&1.0) && op.contains(&0.5) && op.contains(&0.3));
    }
}
