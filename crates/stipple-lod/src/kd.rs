//! The kd-tree of Pintus §7, built in memory for one chunk of the input.
//!
//! A node with fewer than M points is a leaf. Otherwise its points go to two children by
//! bisecting its box at the midpoint of the longest axis (a point on the plane goes right),
//! and the node's samples are taken out of its children's payloads on a grid
//! ([`crate::sample`]): every point is stored once, in the highest node that took it.
//! The two halves are built in parallel (rayon) while they are large.
//!
//! The split rule is a function of the box alone, so the out-of-core builder can predict the
//! top of the tree from a grid of counts ([`crate::build`](mod@crate::build)) and hand each chunk's box here.

use crate::record::Record;
use crate::sample;
use glam::Vec3;
use stipple_core::Bounds;

/// Boxes stop splitting this deep (only reached by ≥ M points at one spot).
pub const MAX_DEPTH: u16 = 60;
/// Below this many points the halves are built on one thread.
const PARALLEL_MIN: usize = 1 << 16;

/// The longest axis of a box; ties go to the lower axis (x, then y, then z).
pub fn longest_axis(b: &Bounds) -> usize {
    let e = b.extent();
    if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    }
}

/// The split plane of a box: its longest axis and that axis's midpoint, or `None` when the
/// midpoint is not strictly inside (the box is as thin as f32 allows).
pub fn split_plane(b: &Bounds) -> Option<(usize, f32)> {
    let a = longest_axis(b);
    let mid = (b.min[a] + b.max[a]) * 0.5;
    (mid > b.min[a] && mid < b.max[a]).then_some((a, mid))
}

/// The two halves of a box at its split plane.
pub fn halves(b: &Bounds, axis: usize, mid: f32) -> (Bounds, Bounds) {
    let mut l = *b;
    let mut r = *b;
    l.max[axis] = mid;
    r.min[axis] = mid;
    (l, r)
}

/// A leaf's spacing: its points spread over the box's two largest extents.
pub fn leaf_spacing(b: &Bounds, n: usize) -> f32 {
    let mut e = b.extent().to_array();
    e.sort_by(f32::total_cmp);
    if n == 0 {
        return 0.0;
    }
    (e[2] * e[1].max(e[2] * 1e-3) / n as f32).sqrt()
}

/// What a node's payload is.
#[derive(Debug)]
pub enum Payload {
    /// A leaf: a range of the chunk's (partitioned) records.
    Range(usize, usize),
    /// An inner node's samples (taken out of its children's payloads).
    Owned(Vec<Record>),
}

/// A node of an in-core subtree; children index the same (preorder) vector.
#[derive(Debug)]
pub struct LocalNode {
    pub bounds: Bounds,
    pub subtree_points: u64,
    pub children: Option<[usize; 2]>,
    pub spacing: f32,
    pub depth: u16,
    pub payload: Payload,
}

impl LocalNode {
    pub fn samples<'a>(&'a self, recs: &'a [Record]) -> &'a [Record] {
        self.samples_at(recs, 0)
    }

    /// [`LocalNode::samples`] where `recs` starts at record `base` of the chunk.
    fn samples_at<'a>(&'a self, recs: &'a [Record], base: usize) -> &'a [Record] {
        match &self.payload {
            Payload::Range(s, n) => &recs[*s - base..*s - base + *n],
            Payload::Owned(v) => v,
        }
    }

    /// Removes the payload's records marked in `taken` (a parent took them), keeping the
    /// others in order. A leaf's range shrinks: its kept records move to its front.
    fn give_up(&mut self, taken: &[bool], recs: &mut [Record], base: usize) {
        match &mut self.payload {
            Payload::Range(s, n) => {
                let r = &mut recs[*s - base..*s - base + *n];
                let mut w = 0;
                for i in 0..r.len() {
                    if !taken[i] {
                        r[w] = r[i];
                        w += 1;
                    }
                }
                *n = w;
            }
            Payload::Owned(v) => {
                let mut i = 0;
                v.retain(|_| {
                    i += 1;
                    !taken[i - 1]
                });
            }
        }
    }
}

/// Builds the subtree of `recs` (all inside `bounds`), partitioning `recs` in place so that
/// every leaf is a contiguous range. Returns the nodes in preorder (the root first).
pub fn build(recs: &mut [Record], bounds: Bounds, depth: u16, m: usize) -> Vec<LocalNode> {
    build_at(recs, 0, bounds, depth, m)
}

fn build_at(
    recs: &mut [Record],
    base: usize,
    bounds: Bounds,
    depth: u16,
    m: usize,
) -> Vec<LocalNode> {
    let n = recs.len();
    let plane = split_plane(&bounds);
    let (axis, mid) = match plane {
        Some(p) if n >= m && depth < MAX_DEPTH => p,
        _ => {
            return vec![LocalNode {
                bounds,
                subtree_points: n as u64,
                children: None,
                spacing: leaf_spacing(&bounds, n),
                depth,
                payload: Payload::Range(base, n),
            }]
        }
    };
    let k = partition(recs, |r| r.pos[axis] < mid);
    let (lb, rb) = halves(&bounds, axis, mid);
    let (l, r) = recs.split_at_mut(k);
    let (mut ln, mut rn) = if n >= PARALLEL_MIN {
        rayon::join(
            || build_at(l, base, lb, depth + 1, m),
            || build_at(r, base + k, rb, depth + 1, m),
        )
    } else {
        (
            build_at(l, base, lb, depth + 1, m),
            build_at(r, base + k, rb, depth + 1, m),
        )
    };
    // The node's samples are taken out of its children's payloads.
    let t = sample::take(
        ln[0].samples_at(recs, base),
        rn[0].samples_at(recs, base),
        &bounds,
        m,
        ln[0].spacing.max(rn[0].spacing),
    );
    ln[0].give_up(&t.left, recs, base);
    rn[0].give_up(&t.right, recs, base);
    let (samples, spacing) = (t.samples, t.spacing);
    let mut out = Vec::with_capacity(1 + ln.len() + rn.len());
    out.push(LocalNode {
        bounds,
        subtree_points: n as u64,
        children: Some([1, 1 + ln.len()]),
        spacing,
        depth,
        payload: Payload::Owned(samples),
    });
    let shift = |mut v: Vec<LocalNode>, by: usize, out: &mut Vec<LocalNode>| {
        for node in &mut v {
            if let Some(c) = &mut node.children {
                c[0] += by;
                c[1] += by;
            }
        }
        out.extend(v);
    };
    let off = 1 + ln.len();
    shift(ln, 1, &mut out);
    shift(rn, off, &mut out);
    out
}

/// Moves the records satisfying `left` to the front (order within each side is not kept, but
/// is the same for the same input); returns how many there are.
pub fn partition(recs: &mut [Record], left: impl Fn(&Record) -> bool) -> usize {
    let (mut i, mut j) = (0, recs.len());
    loop {
        while i < j && left(&recs[i]) {
            i += 1;
        }
        while i < j && !left(&recs[j - 1]) {
            j -= 1;
        }
        if i >= j {
            return i;
        }
        recs.swap(i, j - 1);
        i += 1;
        j -= 1;
    }
}

/// Whether `p` lies in the closed box.
pub fn contains(b: &Bounds, p: Vec3) -> bool {
    p.cmpge(b.min).all() && p.cmple(b.max).all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partition_splits_by_the_predicate() {
        let mut v: Vec<Record> = (0..1000)
            .map(|i| Record::new(Vec3::splat(((i * 7919) % 1000) as f32), [0; 3]))
            .collect();
        let k = partition(&mut v, |r| r.pos[0] < 300.0);
        assert_eq!(k, 300);
        assert!(v[..k].iter().all(|r| r.pos[0] < 300.0));
        assert!(v[k..].iter().all(|r| r.pos[0] >= 300.0));
    }

    #[test]
    fn split_plane_halves_the_longest_axis() {
        let b = Bounds {
            min: Vec3::new(0.0, 0.0, 0.0),
            max: Vec3::new(1.0, 4.0, 2.0),
        };
        assert_eq!(split_plane(&b), Some((1, 2.0)));
        let (l, r) = halves(&b, 1, 2.0);
        assert_eq!(l.max.y, 2.0);
        assert_eq!(r.min.y, 2.0);
        let flat = Bounds {
            min: Vec3::splat(1.0),
            max: Vec3::splat(1.0),
        };
        assert_eq!(split_plane(&flat), None);
    }
}
