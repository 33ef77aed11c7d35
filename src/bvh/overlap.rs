//! Overlap queries: the triangles of a mesh that a box or a sphere touches. A subtree is
//! entered when its box meets the query (exactly for boxes: a triangle that touches the query
//! box has its own box touching it, and every node's box holds its triangles' boxes; for
//! spheres through the conservative [`box_distance_squared`]), and each triangle of a leaf
//! reached is tested exactly ([`triangle_overlaps_box`], or its closest point to the centre).

use super::{Bvh, MAX_DEPTH, MeshBvh, Node};
use crate::geom::{
    Aabb, TriMesh, box_distance_squared, closest_point_on_triangle, triangle_overlaps_box,
};
use glam::{Affine3A, Vec3};

impl Bvh {
    /// Calls `visit(slot)` for every primitive slot of every leaf reached through nodes that
    /// `enter` accepts (the root included).
    pub fn for_each_slot_in(&self, enter: impl Fn(&Node) -> bool, mut visit: impl FnMut(usize)) {
        let nodes = self.nodes.as_slice();
        let Some(root) = nodes.first() else {
            return;
        };
        if !enter(root) {
            return;
        }
        let mut stack = [0u32; MAX_DEPTH];
        let mut sp = 0;
        let mut node = root;
        loop {
            if node.is_leaf() {
                for slot in node.first as usize..(node.first + node.count) as usize {
                    visit(slot);
                }
            } else {
                let (l, r) = (node.first as usize, node.first as usize + 1);
                let (el, er) = (enter(&nodes[l]), enter(&nodes[r]));
                if el || er {
                    if el && er {
                        stack[sp] = r as u32;
                        sp += 1;
                    }
                    node = &nodes[if el { l } else { r }];
                    continue;
                }
            }
            if sp == 0 {
                return;
            }
            sp -= 1;
            node = &nodes[stack[sp] as usize];
        }
    }
}

/// True when two boxes share a point (faces included).
#[inline(always)]
pub(crate) fn boxes_touch(a: &Aabb, b: &Aabb) -> bool {
    a.min.cmple(b.max).all() && b.min.cmple(a.max).all()
}

impl MeshBvh {
    /// The triangles (indices in the mesh's input order) that share a point with `query`,
    /// faces and edges included, into `out` (cleared first), ascending. Exactly
    /// [`brute_force_overlap_box`].
    pub fn overlap_box(&self, query: Aabb, out: &mut Vec<u32>) {
        out.clear();
        self.overlap_box_placed(query, None, |p| out.push(p));
        out.sort_unstable();
    }

    /// The triangles within `radius` of `centre` (their closest point at most `radius` away),
    /// into `out` (cleared first), ascending. Exactly [`brute_force_overlap_sphere`].
    pub fn overlap_sphere(&self, centre: Vec3, radius: f32, out: &mut Vec<u32>) {
        out.clear();
        self.overlap_sphere_placed(centre, radius, None, |p| out.push(p));
        out.sort_unstable();
    }

    /// [`MeshBvh::overlap_box`] of the mesh placed by `place`, each triangle found given to
    /// `found` (in tree order).
    pub(crate) fn overlap_box_placed(
        &self,
        query: Aabb,
        place: Option<&Affine3A>,
        mut found: impl FnMut(u32),
    ) {
        let tris = self.tris.as_slice();
        let prims = self.bvh.prim_indices();
        match place {
            None => self.bvh.for_each_slot_in(
                |n| boxes_touch(&n.bounds(), &query),
                |slot| {
                    let [a, b, c] = tris[slot];
                    if triangle_overlaps_box(a, b, c, query) {
                        found(prims[slot]);
                    }
                },
            ),
            Some(m) => self.bvh.for_each_slot_in(
                |n| boxes_touch(&n.bounds().transformed(m), &query),
                |slot| {
                    let [a, b, c] = tris[slot].map(|v| m.transform_point3(v));
                    if triangle_overlaps_box(a, b, c, query) {
                        found(prims[slot]);
                    }
                },
            ),
        }
    }

    /// [`MeshBvh::overlap_sphere`] of the mesh placed by `place`, each triangle found given to
    /// `found` (in tree order).
    pub(crate) fn overlap_sphere_placed(
        &self,
        centre: Vec3,
        radius: f32,
        place: Option<&Affine3A>,
        mut found: impl FnMut(u32),
    ) {
        if radius.is_nan() || radius < 0.0 {
            return;
        }
        let r2 = radius * radius;
        let tris = self.tris.as_slice();
        let prims = self.bvh.prim_indices();
        let within = |[a, b, c]: [Vec3; 3]| {
            closest_point_on_triangle(centre, a, b, c).distance_squared(centre) <= r2
        };
        match place {
            None => self.bvh.for_each_slot_in(
                |n| box_distance_squared(centre, n.bounds()) <= r2,
                |slot| {
                    if within(tris[slot]) {
                        found(prims[slot]);
                    }
                },
            ),
            Some(m) => self.bvh.for_each_slot_in(
                |n| box_distance_squared(centre, n.bounds().transformed(m)) <= r2,
                |slot| {
                    if within(tris[slot].map(|v| m.transform_point3(v))) {
                        found(prims[slot]);
                    }
                },
            ),
        }
    }
}

/// The reference for [`MeshBvh::overlap_box`]: every triangle tested, ascending.
#[must_use]
pub fn brute_force_overlap_box(mesh: &TriMesh, query: Aabb) -> Vec<u32> {
    (0..mesh.indices.len() as u32)
        .filter(|&k| {
            let [a, b, c] = mesh.indices[k as usize].map(|i| mesh.positions[i as usize]);
            triangle_overlaps_box(a, b, c, query)
        })
        .collect()
}

/// The reference for [`MeshBvh::overlap_sphere`]: every triangle tested, ascending.
#[must_use]
pub fn brute_force_overlap_sphere(mesh: &TriMesh, centre: Vec3, radius: f32) -> Vec<u32> {
    let r2 = radius * radius;
    if radius.is_nan() || radius < 0.0 {
        return Vec::new();
    }
    (0..mesh.indices.len() as u32)
        .filter(|&k| {
            let [a, b, c] = mesh.indices[k as usize].map(|i| mesh.positions[i as usize]);
            closest_point_on_triangle(centre, a, b, c).distance_squared(centre) <= r2
        })
        .collect()
}
