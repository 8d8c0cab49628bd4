//! # Minimal independent grouping (Zhang & Pajarola §4.1)
//!
//! Deferred blending renders every group of splats into its own image with a plain depth
//! test and blends the groups per pixel afterwards (§3.2), so splats that overlap must land
//! in different groups: a graph colouring. Nodes are the points; an edge joins i and j when
//! their splats overlap, |pᵢ − pⱼ| < c·(rᵢ + rⱼ) (Eq. 5 with relaxation 3: c = 1 is the
//! exact overlap, the paper uses c = 0.4), except (relaxation 1) virtually co-planar pairs,
//! which shade alike, and (relaxation 2) pairs whose normals point opposite ways
//! (nᵢ·nⱼ < 0: different surface layers). Colours come from the Largest-First algorithm:
//! nodes in order of non-increasing degree (ties: the smaller index) take the smallest
//! colour none of their coloured neighbours has.
//!
//! Beyond the paper: at most [`MAX_GROUPS`] colours (a frame keeps one image per group); a
//! node whose neighbours use them all takes the colour the fewest of them use, and the
//! number of such conflicts is reported. Neighbours come from the k-nearest search of
//! `normals` with k sized to c (see [`grouping`]).

use crate::normals::{neighbours, NormalError};
use glam::Vec3;
use rayon::prelude::*;

/// The paper's relaxation parameter c (Table 2: 22.6 fps on the Dragon at c = 0.4).
pub const DEFAULT_C: f32 = 0.4;
/// Largest number of groups.
pub const MAX_GROUPS: usize = 32;
/// Co-planar (relaxation 1): normals within this cosine (2°) and each point within this
/// share of the summed radii off the other's tangent plane.
const COPLANAR_COS: f32 = 0.9994;
const COPLANAR_OFF: f32 = 0.02;

/// The groups of a cloud's splats.
#[derive(Clone, Debug, PartialEq)]
pub struct Grouping {
    /// Group per point.
    pub group: Vec<u8>,
    /// Number of groups K.
    pub groups: usize,
    /// Largest and mean degree of the overlap graph (the paper's Table 1 columns).
    pub max_degree: usize,
    pub mean_degree: f32,
    /// Points that had to share a group with an overlapping neighbour (all colours taken).
    pub conflicts: usize,
    /// The relaxation parameter used.
    pub c: f32,
}

/// Groups a cloud's splats (positions, unit normals if any, radii) with relaxation `c` in
/// (0, 1]. Errors as `normals::neighbours` does (fewer than 3 points, non-finite
/// coordinates) and for c outside (0, 1].
pub fn grouping(
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    radii: &[f32],
    c: f32,
) -> Result<Grouping, NormalError> {
    if !(c > 0.0 && c <= 1.0) {
        return Err(NormalError::BadC(c));
    }
    let n = positions.len();
    if n < 3 {
        // Nothing overlaps enough to matter: one group per point is fine too, but one
        // group is simplest.
        return Ok(Grouping {
            group: vec![0; n],
            groups: 1,
            max_degree: 0,
            mean_degree: 0.0,
            conflicts: 0,
            c,
        });
    }
    // Radii are about 0.6 × the 16th-neighbour distance, so overlaps reach about
    // 1.2·c·d₁₆: the neighbours within hold about 16·(1.2c)² points; take 1.5 × that.
    let k = ((16.0 * (1.2 * c) * (1.2 * c) * 1.5).ceil() as usize).clamp(8, 64);
    let nb = neighbours(positions, k)?;
    let overlaps = |i: usize, j: usize| -> bool {
        let d = positions[j] - positions[i];
        let reach = c * (radii[i] + radii[j]);
        if d.length_squared() >= reach * reach {
            return false;
        }
        if let Some(nm) = normals {
            let (a, b) = (nm[i], nm[j]);
            let cos = a.dot(b);
            if cos < 0.0 {
                return false;
            }
            let tol = COPLANAR_OFF * (radii[i] + radii[j]);
            if cos > COPLANAR_COS && d.dot(a).abs() < tol && d.dot(b).abs() < tol {
                return false;
            }
        }
        true
    };
    // Symmetric adjacency (CSR) of the overlap graph.
    let fwd: Vec<Vec<u32>> = (0..n)
        .into_par_iter()
        .map(|i| {
            nb.of(i)
                .iter()
                .copied()
                .filter(|&j| j as usize != i && overlaps(i, j as usize))
                .collect()
        })
        .collect();
    let mut deg = vec![0u32; n];
    for (i, js) in fwd.iter().enumerate() {
        for &j in js {
            deg[i] += 1;
            deg[j as usize] += 1;
        }
    }
    let mut start = vec![0usize; n + 1];
    for i in 0..n {
        start[i + 1] = start[i] + deg[i] as usize;
    }
    let mut fill = start.clone();
    let mut adj = vec![0u32; start[n]];
    for (i, js) in fwd.iter().enumerate() {
        for &j in js {
            adj[fill[i]] = j;
            fill[i] += 1;
            adj[fill[j as usize]] = i as u32;
            fill[j as usize] += 1;
        }
    }
    drop(fwd);
    drop(fill);
    // Largest First (duplicate edges, found from both ends, only repeat a colour).
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.par_sort_unstable_by(|&a, &b| deg[b as usize].cmp(&deg[a as usize]).then(a.cmp(&b)));
    const NONE: u8 = u8::MAX;
    let mut group = vec![NONE; n];
    let mut conflicts = 0;
    let mut used = 0usize;
    for &v in &order {
        let v = v as usize;
        let mut taken = [0u32; MAX_GROUPS];
        let mut mask = 0u64;
        for &u in &adj[start[v]..start[v + 1]] {
            let g = group[u as usize];
            if g != NONE {
                mask |= 1 << g;
                taken[g as usize] += 1;
            }
        }
        let g = (!mask).trailing_zeros() as usize;
        let g = if g < MAX_GROUPS {
            g
        } else {
            conflicts += 1;
            (0..MAX_GROUPS).min_by_key(|&g| (taken[g], g)).unwrap_or(0)
        };
        group[v] = g as u8;
        used = used.max(g + 1);
    }
    let max_degree = deg.iter().copied().max().unwrap_or(0) as usize;
    let mean_degree = deg.iter().map(|&d| d as f64).sum::<f64>() as f32 / n as f32;
    Ok(Grouping {
        group,
        groups: used.max(1),
        max_degree,
        mean_degree,
        conflicts,
        c,
    })
}

/// Share of a splat's radius within which it counts as covering a sample (the rest is
/// margin for the surface between samples).
pub const COVER_REACH: f32 = 0.5;
/// Groups of transparent splats: the paper's choice (§6.2, "sufficient to set K = 4").
pub const TRANSPARENT_GROUPS: usize = 4;

/// Memberships of transparent splats (Zhang & Pajarola §4.2.2, method 1: splats of other
/// groups duplicated into a group until it covers the surface): bit k of a point's mask is
/// set when it is drawn in group k. The colouring's groups are folded into at most
/// [`TRANSPARENT_GROUPS`] (group g into g mod 4: the paper's K = 4, §6.2; folded groups
/// overlap a little, which transparent splats' culling absorbs, and need far fewer
/// duplicates). A point belongs to its own group; then, per group, the
/// samples of the cloud are visited in index order and a sample that no splat of the group
/// reaches (within half the splat's radius: transparent splats are drawn 1.2× their
/// radius, which leaves the rest for the surface between samples; 0.6 left holes on random
/// spheres with points 2 px apart) joins it, reaching in turn its neighbours.
/// Each group thus ends as a maximal set whose splats reach every sample: the paper's
/// priority queue on clipped areas, made greedy over the neighbour graph. Returns the masks
/// and the number of duplicates (memberships beyond the first).
pub fn coverage_masks(
    positions: &[Vec3],
    radii: &[f32],
    g: &Grouping,
) -> Result<(Vec<u32>, usize), NormalError> {
    let n = positions.len();
    let k_groups = g.groups.clamp(1, TRANSPARENT_GROUPS);
    let own: Vec<u32> = g
        .group
        .iter()
        .map(|&k| 1u32 << (k as usize % k_groups))
        .collect();
    if n < 3 || k_groups == 1 {
        return Ok((own, 0));
    }
    let nb = neighbours(positions, 16.min(n - 1))?;
    let reaches = |i: usize, j: usize| {
        let r = COVER_REACH * radii[i];
        (positions[j] - positions[i]).length_squared() <= r * r
    };
    let added: Vec<Vec<u32>> = (0..k_groups)
        .into_par_iter()
        .map(|k| {
            let mut covered = vec![false; n];
            let cover = |i: usize, covered: &mut [bool]| {
                covered[i] = true;
                for &j in nb.of(i) {
                    if reaches(i, j as usize) {
                        covered[j as usize] = true;
                    }
                }
            };
            for i in 0..n {
                if g.group[i] as usize % k_groups == k {
                    cover(i, &mut covered);
                }
            }
            let mut extra = Vec::new();
            for i in 0..n {
                if !covered[i] {
                    cover(i, &mut covered);
                    extra.push(i as u32);
                }
            }
            extra
        })
        .collect();
    let mut masks = own;
    let mut dup = 0;
    for (k, extra) in added.iter().enumerate() {
        for &i in extra {
            masks[i as usize] |= 1 << k;
            dup += 1;
        }
    }
    Ok((masks, dup))
}

/// The most a splat's radius is enlarged by [`coverage_by_radii`].
pub const MAX_ENLARGE: f32 = 8.0;

/// Memberships and radius factors of transparent splats by the paper's method (2) of
/// §4.2.2: each point is in one of K = [`TRANSPARENT_GROUPS`] groups, and its splat is
/// enlarged until its group's splats reach every sample of the cloud.
///
/// The groups are not the colouring's: Largest-First with relaxation leaves a few tiny
/// groups beside one holding nearly every point (a sphere at c = 0.4: 19 989 and 11
/// points), which no radius makes cover the surface. Instead each point, in index order,
/// takes the group least present among its neighbours already placed (ties: the lowest),
/// so every neighbourhood holds every group about equally and each group's splats lie
/// about twice as far apart as the cloud's.
///
/// For every sample and every other group, the group's splat nearest the sample among its
/// 16 neighbours must reach it (within [`COVER_REACH`] of the enlarged radius, as method (1)
/// counts); a splat's factor is the largest such need over the samples it serves, at least
/// 1 and at most [`MAX_ENLARGE`]. A sample with no neighbour of a group joins that group
/// itself, as in method (1). Returns the masks, the number of such duplicates and the
/// factor per point.
pub fn coverage_by_radii(
    positions: &[Vec3],
    radii: &[f32],
) -> Result<(Vec<u32>, usize, Vec<f32>), NormalError> {
    use std::sync::atomic::{AtomicU32, Ordering};
    let n = positions.len();
    let k_groups = TRANSPARENT_GROUPS;
    if n < 3 {
        return Ok((vec![1; n], 0, vec![1.0; n]));
    }
    let nb = neighbours(positions, 16.min(n - 1))?;
    const NONE: u8 = u8::MAX;
    let mut group = vec![NONE; n];
    for i in 0..n {
        let mut count = [0u32; TRANSPARENT_GROUPS];
        for &p in nb.of(i) {
            if let Some(c) = count.get_mut(group[p as usize] as usize) {
                *c += 1;
            }
        }
        let least = (0..k_groups).min_by_key(|&k| count[k]).unwrap_or(0);
        group[i] = least as u8;
    }
    let folded = |i: usize| group[i] as usize;
    let mut masks: Vec<u32> = (0..n).map(|i| 1u32 << folded(i)).collect();
    // The distance each splat must reach (non-negative floats order as their bits).
    let need: Vec<AtomicU32> = (0..n).map(|_| AtomicU32::new(0)).collect();
    let alone: Vec<u32> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut nearest = [(f32::INFINITY, u32::MAX); TRANSPARENT_GROUPS];
            for &p in nb.of(j) {
                let d = (positions[p as usize] - positions[j]).length();
                let k = folded(p as usize);
                if d < nearest[k].0 {
                    nearest[k] = (d, p);
                }
            }
            let mut missing = 0u32;
            for (k, &(d, p)) in nearest.iter().enumerate().take(k_groups) {
                if k == folded(j) {
                    continue;
                }
                if p == u32::MAX {
                    missing |= 1 << k;
                } else {
                    need[p as usize].fetch_max(d.to_bits(), Ordering::Relaxed);
                }
            }
            missing
        })
        .collect();
    let mut dup = 0;
    for (m, a) in masks.iter_mut().zip(&alone) {
        *m |= a;
        dup += a.count_ones() as usize;
    }
    let factor = need
        .iter()
        .zip(radii)
        .map(|(d, &r)| {
            let d = f32::from_bits(d.load(Ordering::Relaxed));
            if r > 0.0 && d > 0.0 {
                (d / (COVER_REACH * r)).clamp(1.0, MAX_ENLARGE)
            } else {
                1.0
            }
        })
        .collect();
    Ok((masks, dup, factor))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::normals::random_sphere as sphere;

    /// No two overlapping splats (by the relaxed rule) share a group unless reported as a
    /// conflict; smaller c gives fewer groups (the trend of the paper's Table 1).
    #[test]
    fn groups_are_independent_and_shrink_with_c() {
        let pts = sphere(20_000, 3);
        let radii = crate::normals::splat_radii(&neighbours(&pts, 16).unwrap(), 1.0);
        let mut last = usize::MAX;
        for c in [1.0, 0.8, 0.6, 0.4] {
            let g = grouping(&pts, Some(&pts), &radii, c).unwrap();
            assert_eq!(g.conflicts, 0, "c = {c}: {g:?}");
            assert!(
                g.groups <= last,
                "c = {c}: {} groups after {last}",
                g.groups
            );
            last = g.groups;
            // Brute force over a sample: overlapping pairs differ in group.
            for i in (0..pts.len()).step_by(97) {
                for j in 0..pts.len() {
                    if i == j {
                        continue;
                    }
                    let d = (pts[i] - pts[j]).length();
                    let cos = pts[i].dot(pts[j]);
                    if d < c * (radii[i] + radii[j]) && cos <= COPLANAR_COS {
                        assert_ne!(g.group[i], g.group[j], "c = {c}: {i} and {j}");
                    }
                }
            }
        }
        assert!(last <= 8, "c = 0.4 gives few groups: {last}");
    }

    /// With its duplicates, every group's splats reach every sample of the cloud; a point
    /// stays in its own group.
    #[test]
    fn coverage_masks_let_each_group_reach_every_sample() {
        let pts = sphere(20_000, 5);
        let radii = crate::normals::splat_radii(&neighbours(&pts, 16).unwrap(), 1.0);
        let g = grouping(&pts, Some(&pts), &radii, 0.4).unwrap();
        assert!(g.groups > 1);
        let (masks, dup) = coverage_masks(&pts, &radii, &g).unwrap();
        let total: usize = masks.iter().map(|m| m.count_ones() as usize).sum();
        assert_eq!(total, pts.len() + dup);
        let kt = g.groups.min(TRANSPARENT_GROUPS);
        for (i, m) in masks.iter().enumerate() {
            assert!(m >> kt == 0, "point {i} in a group past {kt}");
            assert!(
                m & (1 << (g.group[i] as usize % kt)) != 0,
                "point {i} left its group"
            );
        }
        each_group_covers(&pts, &masks, kt, |j| radii[j]);
        // Far fewer duplicates than a copy of the cloud per group.
        assert!(dup < pts.len() * kt, "{dup} duplicates over {kt} groups");
    }

    /// Method (2): every point stays in its own group alone but for rare duplicates, and
    /// each group's enlarged splats reach (within COVER_REACH of their radius) every
    /// sample; some splats grow, none shrinks or grows past MAX_ENLARGE.
    #[test]
    fn enlarged_radii_let_each_group_reach_every_sample() {
        let pts = sphere(20_000, 6);
        let radii = crate::normals::splat_radii(&neighbours(&pts, 16).unwrap(), 1.0);
        let (masks, dup, factor) = coverage_by_radii(&pts, &radii).unwrap();
        let kt = TRANSPARENT_GROUPS;
        let total: usize = masks.iter().map(|m| m.count_ones() as usize).sum();
        assert_eq!(total, pts.len() + dup);
        // The groups are about equal.
        for k in 0..kt {
            let own = masks
                .iter()
                .filter(|&&m| m.trailing_zeros() as usize == k)
                .count();
            assert!(own * kt * 10 > pts.len() * 9, "group {k}: {own} points");
        }
        assert!(
            dup * 50 < pts.len(),
            "{dup} duplicates: the radii should do the work"
        );
        assert!(factor.iter().all(|&f| (1.0..=MAX_ENLARGE).contains(&f)));
        assert!(factor.iter().any(|&f| f > 1.5), "no splat grew");
        each_group_covers(&pts, &masks, kt, |j| {
            COVER_REACH * radii[j] * factor[j] * 1.0001
        });
    }

    /// Every one of `kt` groups (bit k of `masks`) has a member j within `reach(j)` of
    /// every 37th sample.
    fn each_group_covers(pts: &[Vec3], masks: &[u32], kt: usize, reach: impl Fn(usize) -> f32) {
        for k in 0..kt {
            let members: Vec<usize> = (0..pts.len())
                .filter(|&i| masks[i] & (1 << k) != 0)
                .collect();
            for i in (0..pts.len()).step_by(37) {
                assert!(
                    members
                        .iter()
                        .any(|&j| (pts[i] - pts[j]).length() <= reach(j)),
                    "group {k} leaves sample {i} uncovered"
                );
            }
        }
    }

    #[test]
    fn bad_c_and_tiny_clouds() {
        let pts = sphere(100, 4);
        let r = vec![0.1; 100];
        assert!(grouping(&pts, None, &r, 0.0).is_err());
        assert!(grouping(&pts, None, &r, 1.5).is_err());
        assert!(grouping(&pts, None, &r, f32::NAN).is_err());
        let g = grouping(&pts[..2], None, &r[..2], 0.4).unwrap();
        assert_eq!(g.groups, 1);
    }
}
