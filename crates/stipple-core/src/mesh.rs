//! Meshes to points (Gunjee et al. §3: polygon models converted to points so that one
//! renderer draws meshes, scans and volumes alike).
//!
//! Sampling is by area and stratified per triangle: a triangle of area A at a target density
//! ρ = 1 / s² (s: the spacing asked for) gets ⌊Aρ + u⌋ points, u uniform in [0, 1) drawn per
//! triangle, so every triangle's expected count is exactly Aρ and no triangle of area at least
//! s² is left empty; within a triangle the points are uniform (barycentric coordinates from
//! √r₁ and r₂). Each point takes its triangle's vertex normals and colours interpolated
//! barycentrically (normals renormalised), or, without vertex normals, the face normal of
//! the vertices' winding. Degenerate triangles (zero area) get no points.

use crate::rng::Rng;
use crate::PointCloud;
use glam::{DVec3, Vec3};

/// Why a mesh cannot be sampled.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MeshError {
    #[error("the file has no faces: it is a point cloud, not a mesh")]
    NoFaces,
    #[error("face {face} refers to vertex {vertex}, but there are {vertices} vertices")]
    Index {
        face: usize,
        vertex: u32,
        vertices: usize,
    },
    #[error("spacing {0}: it must be a positive distance")]
    Spacing(f64),
    #[error(
        "sampling at spacing {spacing} would make {points:.3e} points (more than {limit}); \
         choose a larger spacing"
    )]
    TooMany {
        spacing: f64,
        points: f64,
        limit: usize,
    },
    #[error("the mesh has no area (every face is degenerate)")]
    NoArea,
}

/// A sampled mesh: the points (with normals, and colours where the vertices had them) and
/// the face each point lies on.
pub struct Sampled {
    pub cloud: PointCloud,
    pub face: Vec<u32>,
}

/// The total area of a mesh's faces (world units²).
pub fn area(mesh: &PointCloud) -> f64 {
    mesh.faces
        .iter()
        .map(|f| triangle(mesh, f).map_or(0.0, |t| tri_area(&t)))
        .sum()
}

/// The spacing that gives about `points` points over the mesh's area.
pub fn spacing_for(mesh: &PointCloud, points: usize) -> f64 {
    (area(mesh) / points.max(1) as f64).sqrt()
}

fn triangle(mesh: &PointCloud, f: &[u32; 3]) -> Option<[DVec3; 3]> {
    let n = mesh.positions.len();
    if f.iter().any(|&v| v as usize >= n) {
        return None;
    }
    Some(f.map(|v| mesh.world(v as usize)))
}

fn tri_area(t: &[DVec3; 3]) -> f64 {
    0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()
}

/// Samples the mesh's faces at `spacing` (world units; density 1 / spacing²), with at most
/// `limit` points, reproducibly from `seed`.
pub fn sample(
    mesh: &PointCloud,
    spacing: f64,
    limit: usize,
    seed: u64,
) -> Result<Sampled, MeshError> {
    if mesh.faces.is_empty() {
        return Err(MeshError::NoFaces);
    }
    if !(spacing > 0.0 && spacing.is_finite()) {
        return Err(MeshError::Spacing(spacing));
    }
    let nv = mesh.positions.len();
    for (face, f) in mesh.faces.iter().enumerate() {
        if let Some(&vertex) = f.iter().find(|&&v| v as usize >= nv) {
            return Err(MeshError::Index {
                face,
                vertex,
                vertices: nv,
            });
        }
    }
    let density = 1.0 / (spacing * spacing);
    let total = area(mesh);
    if total <= 0.0 {
        return Err(MeshError::NoArea);
    }
    let expected = total * density;
    if expected > limit as f64 {
        return Err(MeshError::TooMany {
            spacing,
            points: expected,
            limit,
        });
    }
    let mut rng = Rng::new(seed);
    let mut world = Vec::with_capacity(expected as usize + mesh.faces.len() / 8 + 16);
    let mut normals = Vec::with_capacity(world.capacity());
    let mut colours = mesh
        .colors
        .as_ref()
        .map(|_| Vec::with_capacity(world.capacity()));
    let mut face = Vec::with_capacity(world.capacity());
    for (fi, f) in mesh.faces.iter().enumerate() {
        let t = triangle(mesh, f).expect("indices checked");
        let a = tri_area(&t);
        if a.is_nan() || a <= 0.0 {
            continue;
        }
        let count = (a * density + rng.f64()).floor() as usize;
        if world.len() + count > limit {
            return Err(MeshError::TooMany {
                spacing,
                points: expected,
                limit,
            });
        }
        let face_n = (t[1] - t[0]).cross(t[2] - t[0]).normalize().as_vec3();
        for _ in 0..count {
            let (r1, r2) = (rng.f64().sqrt(), rng.f64());
            let b = [1.0 - r1, r1 * (1.0 - r2), r1 * r2];
            world.push(t[0] * b[0] + t[1] * b[1] + t[2] * b[2]);
            let n = match &mesh.normals {
                Some(vn) => {
                    let m = f
                        .iter()
                        .zip(b)
                        .map(|(&v, w)| vn[v as usize] * w as f32)
                        .sum::<Vec3>();
                    m.try_normalize().unwrap_or(face_n)
                }
                None => face_n,
            };
            normals.push(n);
            if let (Some(out), Some(vc)) = (colours.as_mut(), mesh.colors.as_ref()) {
                let c: [f64; 3] = std::array::from_fn(|i| {
                    f.iter()
                        .zip(b)
                        .map(|(&v, w)| vc[v as usize][i] as f64 * w)
                        .sum()
                });
                out.push(c.map(|x| x.round().clamp(0.0, 255.0) as u8));
            }
            face.push(fi as u32);
        }
    }
    let mut cloud = PointCloud::from_world(&world);
    cloud.normals = Some(normals);
    cloud.colors = colours;
    cloud.z_up = mesh.z_up;
    Ok(Sampled { cloud, face })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube's 12 triangles (outward winding), with its 8 corners.
    fn cube() -> PointCloud {
        let corners: Vec<DVec3> = (0..8)
            .map(|k| DVec3::new((k & 1) as f64, (k >> 1 & 1) as f64, (k >> 2 & 1) as f64))
            .collect();
        let mut c = PointCloud::from_world(&corners);
        let quad = |a: u32, b: u32, cc: u32, d: u32| [[a, b, cc], [a, cc, d]];
        c.faces = [
            quad(0, 2, 3, 1), // z = 0, normal −z
            quad(4, 5, 7, 6), // z = 1, +z
            quad(0, 1, 5, 4), // y = 0, −y
            quad(2, 6, 7, 3), // y = 1, +y
            quad(0, 4, 6, 2), // x = 0, −x
            quad(1, 3, 7, 5), // x = 1, +x
        ]
        .concat();
        c
    }

    #[test]
    fn points_lie_on_their_faces_spread_by_area_with_outward_normals() {
        let c = cube();
        assert!((area(&c) - 6.0).abs() < 1e-12);
        let s = sample(&c, 0.02, 1 << 20, 1).unwrap();
        let n = s.cloud.len();
        // 6 / 0.02² = 15 000 expected; the per-face rounding is unbiased.
        assert!((n as f64 - 15_000.0).abs() < 300.0, "{n}");
        let normals = s.cloud.normals.as_ref().unwrap();
        let mut per_face = [0usize; 12];
        for i in 0..n {
            let p = s.cloud.world(i);
            let f = s.face[i] as usize;
            per_face[f] += 1;
            // On its face's plane, inside the cube's square.
            let t = triangle(&c, &c.faces[f]).unwrap();
            let m = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
            assert!((p - t[0]).dot(m).abs() < 1e-6, "point {i} off its face");
            assert!(p.min_element() > -1e-9 && p.max_element() < 1.0 + 1e-9);
            // Outward: along the face normal, away from the centre.
            let out = normals[i].as_dvec3().dot(p - DVec3::splat(0.5));
            assert!(out > 0.0 && (normals[i].length() - 1.0).abs() < 1e-5);
        }
        // Equal areas, even counts: each triangle near 1 250.
        for (f, &k) in per_face.iter().enumerate() {
            assert!((k as f64 - 1250.0).abs() < 150.0, "face {f}: {k}");
        }
        // Reproducible from the seed.
        let again = sample(&c, 0.02, 1 << 20, 1).unwrap();
        assert_eq!(again.cloud.positions, s.cloud.positions);
    }

    #[test]
    fn small_triangles_are_not_left_empty_and_colours_interpolate() {
        // Many triangles each of area exactly s²: every one gets at least one point.
        let mut pts = Vec::new();
        let mut faces = Vec::new();
        for k in 0..200u32 {
            let x = k as f64 * 3.0;
            pts.extend([
                DVec3::new(x, 0.0, 0.0),
                DVec3::new(x + 0.2, 0.0, 0.0),
                DVec3::new(x, 0.1, 0.0),
            ]);
            faces.push([3 * k, 3 * k + 1, 3 * k + 2]);
        }
        let mut c = PointCloud::from_world(&pts);
        c.faces = faces;
        c.colors = Some(
            (0..600)
                .map(|i| {
                    if i % 3 == 0 {
                        [0, 0, 0]
                    } else {
                        [200, 100, 50]
                    }
                })
                .collect(),
        );
        let s = sample(&c, 0.1, 1 << 20, 5).unwrap();
        let mut hit = [false; 200];
        for &f in &s.face {
            hit[f as usize] = true;
        }
        assert!(hit.iter().all(|&h| h), "an empty triangle");
        let col = s.cloud.colors.as_ref().unwrap();
        assert!(col
            .iter()
            .all(|c| c[0] <= 200 && c[1] <= 100 && c[0] >= c[1]));
    }

    #[test]
    fn bad_meshes_are_errors() {
        let mut c = cube();
        assert!(matches!(
            sample(&c, 0.0, 100, 1),
            Err(MeshError::Spacing(_))
        ));
        assert!(matches!(
            sample(&c, f64::NAN, 100, 1),
            Err(MeshError::Spacing(_))
        ));
        assert!(matches!(
            sample(&c, 0.001, 1000, 1),
            Err(MeshError::TooMany { .. })
        ));
        c.faces.push([0, 1, 99]);
        assert_eq!(
            sample(&c, 0.1, 1000, 1).err(),
            Some(MeshError::Index {
                face: 12,
                vertex: 99,
                vertices: 8
            })
        );
        c.faces.clear();
        assert_eq!(sample(&c, 0.1, 1000, 1).err(), Some(MeshError::NoFaces));
        c.faces = vec![[0, 0, 1]];
        assert_eq!(sample(&c, 0.1, 1000, 1).err(), Some(MeshError::NoArea));
    }
}
