//! Nearest-surface queries: the point of a mesh closest to a query point, within a distance.
//! Depth-first, nearer child first, pruning a subtree when a lower bound of its distance (the
//! box distance, [`box_distance_squared`]) is no smaller than the best so far; the same
//! best-first branch-and-bound as the ray queries, with the box distance for the entry
//! distance.

use super::{Bvh, MAX_DEPTH, MeshBvh, Node};
use crate::geom::{TriMesh, box_distance_squared, closest_point_on_triangle};
use glam::{Affine3A, Vec3};

/// The surface point nearest to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointHit {
    /// The nearest point of the surface.
    pub point: Vec3,
    /// Its distance to the query point.
    pub distance: f32,
    /// The triangle it lies on (index in the mesh's input order).
    pub prim: u32,
}

impl Bvh {
    /// The slot whose primitive is nearest, by squared distances below `bound`: `lower(node)`
    /// is a lower bound of the squared distance of every primitive under `node`, and
    /// `test(slot, best)` the primitive's squared distance when it is below `best`. Returns the
    /// slot and squared distance found, `None` when nothing is below `bound`.
    pub fn nearest_slot(
        &self,
        lower: impl Fn(&Node) -> f32,
        bound: f32,
        mut test: impl FnMut(usize, f32) -> Option<f32>,
    ) -> Option<(usize, f32)> {
        let nodes = self.nodes.as_slice();
        let root = nodes.first()?;
        let mut best_d2 = bound;
        let d = lower(root);
        if d.partial_cmp(&best_d2) != Some(std::cmp::Ordering::Less) {
            return None;
        }
        let mut best = None;
        let mut stack = [(0u32, 0f32); MAX_DEPTH];
        let mut sp = 0;
        let mut node = root;
        loop {
            if node.is_leaf() {
                for slot in node.first as usize..(node.first + node.count) as usize {
                    if let Some(d2) = test(slot, best_d2) {
                        best_d2 = d2;
                        best = Some((slot, d2));
                    }
                }
            } else {
                let (l, r) = (node.first, node.first + 1);
                let dl = lower(&nodes[l as usize]);
                let dr = lower(&nodes[r as usize]);
                let (near, dn, far, df) = if dl <= dr {
                    (l, dl, r, dr)
                } else {
                    (r, dr, l, dl)
                };
                if dn < best_d2 {
                    if df < best_d2 {
                        stack[sp] = (far, df);
                        sp += 1;
                    }
                    node = &nodes[near as usize];
                    continue;
                }
            }
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                let (i, d) = stack[sp];
                if d < best_d2 {
                    node = &nodes[i as usize];
                    break;
                }
            }
        }
    }
}

impl MeshBvh {
    /// The point of the mesh nearest to `p` among those within `max_dist` of it (inclusive;
    /// `f32::INFINITY` for no limit), its distance and triangle; `None` when no triangle is
    /// that close (or `max_dist` is NaN or negative). Exactly the minimum of
    /// [`closest_point_on_triangle`] over the triangles ([`brute_force_closest_point`]); of
    /// two triangles at the same distance either may be returned.
    #[must_use]
    pub fn closest_point(&self, p: Vec3, max_dist: f32) -> Option<PointHit> {
        let (point, d2, prim) = self.closest_point_placed(p, squared_bound(max_dist), None)?;
        Some(PointHit {
            point,
            distance: d2.sqrt(),
            prim,
        })
    }

    /// [`MeshBvh::closest_point`] of the mesh placed in the world by `place` (its vertices
    /// transformed by it, as `transform_point3` rounds them), below the squared distance
    /// `bound`: `(point, squared distance, triangle)`.
    pub(crate) fn closest_point_placed(
        &self,
        p: Vec3,
        bound: f32,
        place: Option<&Affine3A>,
    ) -> Option<(Vec3, f32, u32)> {
        let tris = self.tris.as_slice();
        let mut point = Vec3::ZERO;
        let (slot, d2) = match place {
            None => {
                // One margin for every node (they all lie inside the root): the same lower
                // bound as `box_distance_squared` with the root's coordinates, which are at
                // least every node's.
                let r = self.bvh.bounds();
                let pad = (r.min.abs().max(r.max.abs()) + p.abs()) * (8.0 * f32::EPSILON);
                let (above, below) = (p + pad, p - pad);
                self.bvh.nearest_slot(
                    |n| {
                        let lo = Vec3::from(n.min) - above;
                        let hi = below - Vec3::from(n.max);
                        lo.max(hi).max(Vec3::ZERO).length_squared()
                    },
                    bound,
                    |slot, best| {
                        let [a, b, c] = tris[slot];
                        let q = closest_point_on_triangle(p, a, b, c);
                        let d2 = q.distance_squared(p);
                        (d2 < best).then(|| {
                            point = q;
                            d2
                        })
                    },
                )
            }
            Some(m) => self.bvh.nearest_slot(
                |n| box_distance_squared(p, n.bounds().transformed(m)),
                bound,
                |slot, best| {
                    let [a, b, c] = tris[slot].map(|v| m.transform_point3(v));
                    let q = closest_point_on_triangle(p, a, b, c);
                    let d2 = q.distance_squared(p);
                    (d2 < best).then(|| {
                        point = q;
                        d2
                    })
                },
            ),
        }?;
        Some((point, d2, self.bvh.prim_indices()[slot]))
    }
}

/// The strict squared bound that keeps distances up to `max_dist` (inclusive); `0` (nothing)
/// for NaN or negative distances.
pub(crate) fn squared_bound(max_dist: f32) -> f32 {
    if max_dist >= 0.0 {
        (max_dist * max_dist).next_up()
    } else {
        0.0
    }
}

/// The reference for [`MeshBvh::closest_point`]: every triangle tested, the first nearest in
/// input order kept.
#[must_use]
pub fn brute_force_closest_point(mesh: &TriMesh, p: Vec3, max_dist: f32) -> Option<PointHit> {
    let mut best = squared_bound(max_dist);
    let mut hit = None;
    for (k, t) in mesh.indices.iter().enumerate() {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        let q = closest_point_on_triangle(p, a, b, c);
        let d2 = q.distance_squared(p);
        if d2 < best {
            best = d2;
            hit = Some(PointHit {
                point: q,
                distance: d2.sqrt(),
                prim: k as u32,
            });
        }
    }
    hit
}
