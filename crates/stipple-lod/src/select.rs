//! View-dependent cuts: which nodes to draw for a camera.
//!
//! The hierarchy is additive: every point is stored once, and a node's points add detail to
//! its ancestors' (Potree's scheme). A cut is therefore a subtree: the root and, wherever more
//! detail is wanted, a node's visible children drawn together with it. Starting from the
//! root, the drawn node with the largest screen-space error that has children not yet drawn
//! adds them, as long as the point budget allows, until every error is below the target. The
//! error of a node is its sample spacing (the spacing of it and its ancestors together)
//! projected at the nearest point of its box, in pixels: large and near nodes come first.
//! Nodes outside the view frustum are dropped. Ties are broken by node id, so the same tree
//! and camera always give the same cut.

use crate::format::{LodTree, Node};
use glam::DVec3;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use stipple_core::{Camera, Projection};

#[derive(Clone, Copy, Debug)]
pub struct SelectOptions {
    /// At most this many points in the cut (the root is always allowed).
    pub point_budget: u64,
    /// Refine until the projected sample spacing is at most this many pixels.
    pub max_error_px: f32,
}

impl Default for SelectOptions {
    fn default() -> Self {
        SelectOptions {
            point_budget: 5_000_000,
            max_error_px: 1.0,
        }
    }
}

/// A cut: the nodes to draw (each with all its ancestors), in the order they should be loaded
/// (largest error first, so the root comes first).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Selection {
    pub nodes: Vec<u32>,
    /// Projected sample spacing (px) of each node of `nodes`.
    pub errors: Vec<f32>,
    pub points: u64,
    /// Refinements skipped because the budget would have been exceeded.
    pub budget_limited: bool,
}

/// What selection needs of a camera, in the tree's local frame.
struct View {
    eye: DVec3,
    right: DVec3,
    up: DVec3,
    forward: DVec3,
    sx: f64,
    sy: f64,
    /// Pixels per world unit at depth 1 (perspective) or everywhere (orthographic).
    px_per_unit: f64,
    perspective: bool,
    near: f64,
}

impl View {
    fn new(c: &Camera, origin: DVec3) -> View {
        let b = c.basis();
        let (sx, sy) = c.ndc_scale();
        View {
            eye: c.eye - origin,
            right: b.right,
            up: b.up,
            forward: b.forward,
            sx,
            sy,
            px_per_unit: sy * 0.5 * c.height as f64,
            perspective: matches!(c.projection, Projection::Perspective { .. }),
            near: c.near.max(1e-9),
        }
    }

    /// Conservative: false only when all corners are outside one side of the frustum.
    fn visible(&self, n: &Node) -> bool {
        let mut out = [true; 5];
        for p in n.bounds.corners() {
            let v = p.as_dvec3() - self.eye;
            let (x, y, z) = (v.dot(self.right), v.dot(self.up), v.dot(self.forward));
            let w = if self.perspective { z } else { 1.0 };
            let tests = [
                x * self.sx <= w,
                -x * self.sx <= w,
                y * self.sy <= w,
                -y * self.sy <= w,
                !self.perspective || z > 0.0,
            ];
            for (o, t) in out.iter_mut().zip(tests) {
                *o &= !t;
            }
        }
        !out.iter().any(|&o| o)
    }

    /// Projected spacing in pixels at the nearest point of the node's box.
    fn error(&self, n: &Node) -> f32 {
        let s = n.spacing as f64;
        if !self.perspective {
            return (s * self.px_per_unit) as f32;
        }
        let near = self
            .eye
            .clamp(n.bounds.min.as_dvec3(), n.bounds.max.as_dvec3());
        let d = (near - self.eye).length().max(self.near);
        (s * self.px_per_unit / d) as f32
    }
}

#[derive(PartialEq)]
struct Candidate {
    error: f32,
    id: u32,
}

impl Eq for Candidate {}

impl Ord for Candidate {
    fn cmp(&self, o: &Self) -> Ordering {
        self.error
            .total_cmp(&o.error)
            .then_with(|| o.id.cmp(&self.id))
    }
}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// The cut of `tree` for `camera`.
pub fn select(tree: &LodTree, camera: &Camera, o: &SelectOptions) -> Selection {
    select_nodes(&tree.nodes, tree.header.origin, camera, o)
}

/// [`select`] on a node table (tests build tables by hand).
pub fn select_nodes(
    nodes: &[Node],
    origin: DVec3,
    camera: &Camera,
    o: &SelectOptions,
) -> Selection {
    let view = View::new(camera, origin);
    let mut sel = Selection::default();
    let root = &nodes[0];
    if !view.visible(root) || root.subtree_points == 0 {
        return sel;
    }
    let mut in_cut = vec![false; nodes.len()];
    let mut error = vec![0f32; nodes.len()];
    in_cut[0] = true;
    error[0] = view.error(root);
    let mut points = root.sample_count as u64;
    let mut heap = BinaryHeap::new();
    heap.push(Candidate {
        error: error[0],
        id: 0,
    });
    while let Some(Candidate { error: e, id }) = heap.pop() {
        if e <= o.max_error_px {
            break;
        }
        let n = &nodes[id as usize];
        let kids: Vec<u32> = n
            .children
            .iter()
            .copied()
            .filter(|&c| {
                let c = &nodes[c as usize];
                c.subtree_points > 0 && view.visible(c)
            })
            .collect();
        let add: u64 = kids
            .iter()
            .map(|&c| nodes[c as usize].sample_count as u64)
            .sum();
        if points + add > o.point_budget {
            sel.budget_limited = true;
            continue;
        }
        points += add;
        for c in kids {
            in_cut[c as usize] = true;
            let ce = view.error(&nodes[c as usize]);
            error[c as usize] = ce;
            if !nodes[c as usize].is_leaf() {
                heap.push(Candidate { error: ce, id: c });
            }
        }
    }
    let mut cut: Vec<u32> = (0..nodes.len() as u32)
        .filter(|&i| in_cut[i as usize])
        .collect();
    cut.sort_by(|&a, &b| {
        error[b as usize]
            .total_cmp(&error[a as usize])
            .then(a.cmp(&b))
    });
    sel.errors = cut.iter().map(|&i| error[i as usize]).collect();
    sel.nodes = cut;
    sel.points = points;
    sel
}
