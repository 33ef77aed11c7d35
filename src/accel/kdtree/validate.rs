//! The kd-tree's invariants: children stored after their parent, planes strictly inside their
//! cells, every reference overlapping its leaf's cell, and every triangle reachable from the
//! root wherever its box lies (on both sides of a plane it straddles, on one side of a plane
//! it lies in); with perfect splits, wherever the triangle clipped to the cell lies.

use super::clip::clipped_box_exact;
use super::events::clip_box;
use super::{KdNode, KdTree, MAX_KD_DEPTH};
use crate::accel::triangles::same_triangle;
use crate::geom::{Aabb, TriMesh};

impl KdTree {
    pub(super) fn check(&self, mesh: &TriMesh) -> Result<(), String> {
        self.tris.check(mesh)?;
        if self.leaf_tris.iter().any(|t| {
            !self
                .tris
                .tris
                .get(t.id as usize)
                .is_some_and(|u| same_triangle(u, &t.corners))
        }) {
            return Err("leaf-order triangle copies differ from the triangles".into());
        }
        let boxes = self.tris.boxes();
        let with_box = boxes.iter().filter(|b| !b.is_empty()).count();
        if self.nodes.is_empty() {
            return if with_box == 0 {
                Ok(())
            } else {
                Err(format!("no node but {with_box} triangles with a box"))
            };
        }
        if self.depth > MAX_KD_DEPTH {
            return Err(format!("depth {} over {MAX_KD_DEPTH}", self.depth));
        }
        self.check_node(0, self.bounds, &boxes, 0)?;
        for (i, b) in boxes.iter().enumerate() {
            if !b.is_empty() && !self.reaches(0, self.bounds, b, i as u32) {
                return Err(format!(
                    "triangle {i} is missing from a leaf its box overlaps"
                ));
            }
        }
        Ok(())
    }

    fn check_node(&self, i: usize, cell: Aabb, boxes: &[Aabb], depth: usize) -> Result<(), String> {
        if depth > self.depth {
            return Err(format!(
                "node {i} at depth {depth}, over the recorded depth"
            ));
        }
        let n: KdNode = self.nodes[i];
        if n.is_leaf() {
            let range = n.index()..n.index() + n.count();
            let refs = self
                .leaf_tris
                .get(range.clone())
                .ok_or_else(|| format!("leaf {i}: references {range:?} out of range"))?;
            for t in refs.iter().map(|t| t.id) {
                let b = boxes
                    .get(t as usize)
                    .ok_or_else(|| format!("leaf {i}: triangle {t} out of range"))?;
                if clip_box(b, &cell).is_empty() {
                    return Err(format!("leaf {i}: triangle {t} lies outside the cell"));
                }
            }
            return Ok(());
        }
        let (axis, pos, first) = (n.axis(), n.split(), n.index());
        if first <= i || first + 1 >= self.nodes.len() {
            return Err(format!(
                "node {i}: children at {first} (of {})",
                self.nodes.len()
            ));
        }
        if !(cell.min[axis] < pos && pos < cell.max[axis]) {
            return Err(format!(
                "node {i}: plane {pos} on axis {axis} outside {cell:?}"
            ));
        }
        let (mut left, mut right) = (cell, cell);
        left.max[axis] = pos;
        right.min[axis] = pos;
        self.check_node(first, left, boxes, depth + 1)?;
        self.check_node(first + 1, right, boxes, depth + 1)
    }

    /// True when triangle `t` (box `b`) is in every leaf below `i` that it must be in.
    fn reaches(&self, i: usize, cell: Aabb, b: &Aabb, t: u32) -> bool {
        let n = self.nodes[i];
        if n.is_leaf() {
            return self.leaf_tris[n.index()..n.index() + n.count()]
                .iter()
                .any(|l| l.id == t);
        }
        let (axis, pos, first) = (n.axis(), n.split(), n.index());
        let (mut left, mut right) = (cell, cell);
        left.max[axis] = pos;
        right.min[axis] = pos;
        let c = if self.params.perfect_splits_above < usize::MAX {
            clipped_box_exact(&self.tris.tris[t as usize], b, &cell)
        } else {
            clip_box(b, &cell)
        };
        if c.is_empty() {
            return true;
        }
        let (lo, hi) = (c.min[axis], c.max[axis]);
        if lo == pos && hi == pos {
            return self.reaches(first, left, b, t) || self.reaches(first + 1, right, b, t);
        }
        (lo >= pos || self.reaches(first, left, b, t))
            && (hi <= pos || self.reaches(first + 1, right, b, t))
    }
}
