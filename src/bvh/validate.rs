//! The invariant checker that tests run after every build and refit.

use super::{Bvh, MAX_DEPTH, MeshBvh, Node};
use crate::geom::{Aabb, TriMesh};
use glam::Vec3;

impl Bvh {
    /// Checks every invariant of the module docs; the message names the first broken one.
    pub fn validate(&self) -> Result<(), String> {
        self.validate_with(|_| None)
    }

    /// [`Bvh::validate`], and also that every leaf's box holds `prim_bounds(id)` of each of its
    /// primitives (when it returns `Some`).
    pub fn validate_with(&self, prim_bounds: impl Fn(u32) -> Option<Aabb>) -> Result<(), String> {
        let n = self.prim_indices.len();
        if self.nodes.is_empty() {
            return if n == 0 {
                Ok(())
            } else {
                Err(format!("no nodes but {n} primitives"))
            };
        }
        let mut seen = vec![false; n];
        for &p in &self.prim_indices {
            let s = seen
                .get_mut(p as usize)
                .ok_or_else(|| format!("primitive index {p} out of range (n = {n})"))?;
            if *s {
                return Err(format!("primitive {p} appears twice"));
            }
            *s = true;
        }
        let mut w = Walk {
            bvh: self,
            next_slot: 0,
            visited: 0,
            prim_bounds: &prim_bounds,
        };
        let root = self.nodes[0];
        if root.is_leaf() {
            w.leaf(0, &root)?;
        } else {
            let end = w.interior(0, &root, 0)?;
            if end != self.nodes.len() {
                return Err(format!(
                    "descendants of the root end at {end}, not at the node count {}",
                    self.nodes.len()
                ));
            }
        }
        if w.next_slot as usize != n {
            return Err(format!("leaves cover {} of {n} slots", w.next_slot));
        }
        if w.visited + 1 != self.nodes.len() {
            return Err(format!(
                "{} of {} nodes reachable from the root",
                w.visited + 1,
                self.nodes.len()
            ));
        }
        Ok(())
    }
}

struct Walk<'a, F> {
    bvh: &'a Bvh,
    next_slot: u32,
    visited: usize,
    prim_bounds: &'a F,
}

impl<F: Fn(u32) -> Option<Aabb>> Walk<'_, F> {
    fn leaf(&mut self, i: usize, node: &Node) -> Result<(), String> {
        if node.count > self.bvh.max_leaf_size {
            return Err(format!(
                "leaf {i} holds {} primitives, more than {}",
                node.count, self.bvh.max_leaf_size
            ));
        }
        if node.first != self.next_slot {
            return Err(format!(
                "leaf {i} starts at slot {}, expected {} (leaves must cover slots in order)",
                node.first, self.next_slot
            ));
        }
        let end = node.first as usize + node.count as usize;
        if end > self.bvh.prim_indices.len() {
            return Err(format!("leaf {i} ends at slot {end}, past the last slot"));
        }
        let b = node.bounds();
        for &p in &self.bvh.prim_indices[node.first as usize..end] {
            if let Some(pb) = (self.prim_bounds)(p).map(Aabb::sanitized)
                && !b.contains(&pb)
            {
                return Err(format!(
                    "leaf {i} box {b:?} does not hold primitive {p} box {pb:?}"
                ));
            }
        }
        self.next_slot = end as u32;
        Ok(())
    }

    /// Checks the subtree of interior node `i` and returns one past its last descendant.
    fn interior(&mut self, i: usize, node: &Node, depth: usize) -> Result<usize, String> {
        if depth + 1 > MAX_DEPTH {
            return Err(format!("node {i} is deeper than {MAX_DEPTH}"));
        }
        let c = node.first as usize;
        if c <= i || c + 1 >= self.bvh.nodes.len() {
            return Err(format!(
                "node {i} has children at {c}, not after it and in range"
            ));
        }
        self.visited += 2;
        let b = node.bounds();
        let mut end = c + 2;
        for k in [c, c + 1] {
            let child = self.bvh.nodes[k];
            if !b.contains(&child.bounds()) {
                return Err(format!(
                    "child {k} box {:?} is not inside parent {i} box {b:?}",
                    child.bounds()
                ));
            }
            if child.is_leaf() {
                self.leaf(k, &child)?;
            } else {
                if child.first as usize != end {
                    return Err(format!(
                        "node {k}'s children are at {}, expected {end} (subtrees must be contiguous)",
                        child.first
                    ));
                }
                end = self.interior(k, &child, depth + 1)?;
            }
        }
        Ok(end)
    }
}

impl MeshBvh {
    /// [`Bvh::validate`], plus: leaf boxes hold their triangles, and the leaf-ordered copy
    /// equals `mesh`'s triangles bit for bit.
    pub fn validate(&self, mesh: &TriMesh) -> Result<(), String> {
        mesh.check()?;
        if mesh.len() != self.bvh.prim_count() {
            return Err(format!(
                "tree has {} triangles, mesh has {}",
                self.bvh.prim_count(),
                mesh.len()
            ));
        }
        self.bvh
            .validate_with(|p| Some(mesh.triangle_bounds(p as usize)))?;
        // Bit for bit: a NaN coordinate is copied as it is.
        let bits = |t: [Vec3; 3]| t.map(|v| v.to_array().map(f32::to_bits));
        for (slot, &p) in self.bvh.prim_indices().iter().enumerate() {
            if bits(self.tris[slot]) != bits(mesh.triangle(p as usize)) {
                return Err(format!("slot {slot} holds a stale copy of triangle {p}"));
            }
        }
        Ok(())
    }
}
