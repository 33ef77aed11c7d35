//! The nearest surface point on the wide tree: the binary tree's best-first branch and bound
//! ([`crate::bvh::Bvh::nearest_slot`]) with a node's `K` child box distances computed in one
//! SIMD pass ([`box_distance_lanes`]); leaf triangles take the scalar
//! [`closest_point_on_triangle`], so the distance is exactly brute force's. A mesh placed by
//! an affine map is searched in its own space: a world distance is at least the smallest
//! singular value of the map times the mesh-space one, so mesh-space box distances bound
//! world ones once scaled and widened by the rounding of the placed vertices ([`Placed`]).

use super::lanes::{DistanceLanes, box_distance_lanes};
use super::traverse::{BIG_STACK, SMALL_STACK};
use super::{LEAF_BIT, NO_PRIM, WideBvh, leaf_range};
use crate::bvh::PointHit;
use crate::bvh::closest_point::{PENDING, Pending, key, squared_bound};
use crate::geom::{Aabb, closest_point_on_triangle};
use glam::{Affine3A, DVec3, Vec3};

/// The nearest triangle so far: block lane (`4 * block + lane`), its closest point and squared
/// distance (the bound when none).
struct Nearest {
    slot: Option<usize>,
    point: Vec3,
    d2: f32,
}

impl<const K: usize> WideBvh<K> {
    /// The point of the mesh nearest to `p` among those within `max_dist` of it (inclusive;
    /// `f32::INFINITY` for no limit), its distance and triangle; `None` when no triangle is
    /// that close (or `max_dist` is NaN or negative). Exactly
    /// [`MeshBvh::closest_point`](crate::bvh::MeshBvh::closest_point)'s distance (the minimum
    /// of [`closest_point_on_triangle`] over the triangles); of two triangles at the same
    /// distance either may be returned.
    #[must_use]
    pub fn closest_point(&self, p: Vec3, max_dist: f32) -> Option<PointHit> {
        let (point, d2, prim) = self.closest_point_below(p, squared_bound(max_dist))?;
        Some(PointHit {
            point,
            distance: d2.sqrt(),
            prim,
        })
    }

    /// [`WideBvh::closest_point`] below the squared distance `bound`: `(point, squared
    /// distance, triangle)`.
    pub(crate) fn closest_point_below(&self, p: Vec3, bound: f32) -> Option<(Vec3, f32, u32)> {
        self.closest_point_pending(p, bound, PENDING, &InPlace)
    }

    /// [`WideBvh::closest_point_below`] of the mesh placed in the world by `place` (its
    /// vertices transformed as `transform_point3` rounds them; `p` and the result in world
    /// space).
    pub(crate) fn closest_point_placed(
        &self,
        p: Vec3,
        bound: f32,
        place: &Placed,
    ) -> Option<(Vec3, f32, u32)> {
        self.closest_point_pending(p, bound, PENDING, place)
    }

    /// [`WideBvh::closest_point_placed`] for a map that [`Placed`] does not take (not finite,
    /// or near singular): each lane's box is carried into the world
    /// ([`Aabb::transformed`], conservative) and its world distance bounds the triangles'; the
    /// lanes are taken depth first in lane order (such maps are rare, this search is not
    /// tuned).
    pub(crate) fn closest_point_transformed(
        &self,
        p: Vec3,
        bound: f32,
        m: &Affine3A,
    ) -> Option<(Vec3, f32, u32)> {
        if bound.is_nan() || bound <= 0.0 || !p.is_finite() {
            return None;
        }
        let best = std::cell::Cell::new(bound);
        let mut found = None;
        self.for_each_lane_in(
            |node| {
                super::overlap::placed_lanes(node, |b| {
                    crate::geom::box_distance_squared(p, b.transformed(m)) < best.get()
                })
            },
            |tri, prim| {
                let [a, b, c] = tri.map(|v| m.transform_point3(v));
                let q = closest_point_on_triangle(p, a, b, c);
                let d2 = q.distance_squared(p);
                if d2 < best.get() {
                    best.set(d2);
                    found = Some((q, d2, prim));
                }
            },
        );
        found
    }

    /// [`WideBvh::closest_point_below`] keeping at most `limit` subtrees pending, the mesh
    /// where `frame` puts it.
    fn closest_point_pending<F: Frame>(
        &self,
        p: Vec3,
        bound: f32,
        limit: usize,
        frame: &F,
    ) -> Option<(Vec3, f32, u32)> {
        // A non-finite point is at no finite distance from anything (brute force finds
        // nothing either).
        if self.nodes.is_empty() || bound.is_nan() || bound <= 0.0 || !p.is_finite() {
            return None;
        }
        let lanes = frame.lanes(p, &self.bounds())?;
        let walk = Walk { p, frame, lanes };
        let mut best = Nearest {
            slot: None,
            point: Vec3::ZERO,
            d2: bound,
        };
        let mut pending = Pending::new(limit);
        let mut dist = [0f32; K];
        // The root node is entered without a box test (its children's boxes are tested).
        let mut cur = 0u32;
        loop {
            if cur & LEAF_BIT != 0 {
                self.leaf_nearest(cur, &walk, &mut best);
            } else {
                let node = &self.nodes[cur as usize];
                let reach = walk.frame.reach(best.d2);
                let mut mask = box_distance_lanes(&node.bounds, &walk.lanes, reach, &mut dist);
                // The nearest lane is entered now when no pending subtree is nearer; the
                // others wait.
                let mut enter = None;
                let mut nearest = u64::MAX;
                while mask != 0 {
                    let k = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let key = key(dist[k], node.child[k]);
                    if key < nearest {
                        if let Some(prev) = enter.replace(key) {
                            self.wait(&mut pending, prev, &walk, &mut best);
                        }
                        nearest = key;
                    } else {
                        self.wait(&mut pending, key, &walk, &mut best);
                    }
                }
                if let Some(k) = enter {
                    if k <= pending.nearest
                        && f32::from_bits((k >> 32) as u32) < frame.reach(best.d2)
                    {
                        cur = k as u32;
                        continue;
                    }
                    self.wait(&mut pending, k, &walk, &mut best);
                }
            }
            match pending.pop(frame.reach(best.d2)) {
                Some(next) => cur = next,
                None => {
                    let slot = best.slot?;
                    return Some((best.point, best.d2, self.blocks[slot / 4].prims[slot % 4]));
                }
            }
        }
    }

    /// Puts a child (its key) among the pending ones and asks for its memory, or searches it
    /// depth first now when they are full.
    #[inline(always)]
    fn wait<F: Frame>(&self, pending: &mut Pending, key: u64, walk: &Walk<F>, best: &mut Nearest) {
        if pending.push(key) {
            self.prefetch(key as u32);
        } else if self.stack_need < SMALL_STACK {
            self.nearest_depth_first::<SMALL_STACK, F>(key as u32, walk, best);
        } else {
            self.nearest_depth_first::<BIG_STACK, F>(key as u32, walk, best);
        }
    }

    /// The search below `best` within the child `start`, depth first, nearest lane first, on a
    /// stack of `N` entries (enough for the tree: [`WideBvh::stack_need`]).
    fn nearest_depth_first<const N: usize, F: Frame>(
        &self,
        start: u32,
        walk: &Walk<F>,
        best: &mut Nearest,
    ) {
        let mut stack = [(0u32, 0f32); N];
        let mut sp = 0usize;
        let mut dist = [0f32; K];
        let mut cur = start;
        loop {
            if cur & LEAF_BIT != 0 {
                self.leaf_nearest(cur, walk, best);
            } else {
                let node = &self.nodes[cur as usize];
                let reach = walk.frame.reach(best.d2);
                let mut mask = box_distance_lanes(&node.bounds, &walk.lanes, reach, &mut dist);
                // Farthest first onto the stack, so the nearest is on top.
                let base = sp;
                while mask != 0 {
                    let k = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let e = (node.child[k], dist[k]);
                    let mut j = sp;
                    while j > base && stack[j - 1].1 < e.1 {
                        stack[j] = stack[j - 1];
                        j -= 1;
                    }
                    stack[j] = e;
                    sp += 1;
                }
            }
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let (c, d) = stack[sp];
                if d < walk.frame.reach(best.d2) {
                    cur = c;
                    break;
                }
            }
        }
    }

    /// Tests a leaf child's triangles below `best`, keeping the nearest.
    #[inline(always)]
    fn leaf_nearest<F: Frame>(&self, leaf: u32, walk: &Walk<F>, best: &mut Nearest) {
        let p = walk.p;
        let (first, count) = leaf_range(leaf);
        let first = first as usize;
        for (b, block) in (first..).zip(&self.blocks[first..first + count as usize]) {
            for l in 0..4 {
                if block.prims[l] == NO_PRIM {
                    continue;
                }
                let [a, v, c] = block.get(l).map(|x| walk.frame.place(x));
                let q = closest_point_on_triangle(p, a, v, c);
                let d2 = q.distance_squared(p);
                if d2 < best.d2 {
                    *best = Nearest {
                        slot: Some(b * 4 + l),
                        point: q,
                        d2,
                    };
                }
            }
        }
    }
}

/// One search's query: the point in world space, where its frame puts the mesh, and the
/// point's lanes in mesh space.
struct Walk<'a, F> {
    p: Vec3,
    frame: &'a F,
    lanes: DistanceLanes,
}

/// Where a search sees the mesh: the box distances' query lanes in mesh space, the
/// mesh-space squared box distance a subtree must stay below to hold a triangle nearer than
/// a world squared distance, and a vertex in world space.
trait Frame {
    fn lanes(&self, p: Vec3, root: &Aabb) -> Option<DistanceLanes>;
    fn reach(&self, best: f32) -> f32;
    fn place(&self, v: Vec3) -> Vec3;
}

/// The mesh where it is (world and mesh space agree).
struct InPlace;

impl Frame for InPlace {
    #[inline(always)]
    fn lanes(&self, p: Vec3, root: &Aabb) -> Option<DistanceLanes> {
        Some(DistanceLanes::new(p, root, 0.0))
    }
    #[inline(always)]
    fn reach(&self, best: f32) -> f32 {
        best
    }
    #[inline(always)]
    fn place(&self, v: Vec3) -> Vec3 {
        v
    }
}

/// A mesh placed by an affine map `M = (A, t)`. For mesh-space points `x`, `q`:
/// `|A (x - q)| >= σ |x - q|` with `σ` the smallest singular value of `A`, so a mesh-space box
/// distance times `σ` bounds the world distance of the exact placed triangles; the placed
/// vertices as `transform_point3` rounds them, the closest-point arithmetic in world space
/// and the mapping of the query point into mesh space each move that by a little, which a
/// margin added to every box distance (in mesh units) covers.
pub(crate) struct Placed {
    m: Affine3A,
    inverse: glam::DAffine3,
    /// `1 / σ²`, rounded up with room for the squared distances' rounding.
    inv_s2: f32,
    /// Per component: `Σ_j |A_ij|` and `|t_i|`, for the placed vertices' rounding.
    rows: DVec3,
    shift: DVec3,
    sigma: f64,
    /// The largest singular value over the smallest is above [`UNEVEN`].
    uneven: bool,
}

/// Above this ratio of the map's singular values a placed query also tests each lane's box
/// carried into the world ([`super::lanes::PlacedLanes`]): the preimage's box and the
/// smallest singular value then leave much of a lane's search loose, where under a rotation
/// and an even scale (ratio 1) the world test costs more than it prunes (`docs/library.md`).
const UNEVEN: f64 = 1.5;

impl Placed {
    /// `None` when the map is not finite or so near singular (`σ` below 1e-4 of the largest
    /// singular value) that the bound would prune nothing: search the binary tree then.
    pub(crate) fn new(m: &Affine3A) -> Option<Self> {
        let d = glam::DAffine3::from_cols(
            m.matrix3.x_axis.as_dvec3(),
            m.matrix3.y_axis.as_dvec3(),
            m.matrix3.z_axis.as_dvec3(),
            DVec3::from(Vec3::from(m.translation)),
        );
        if !d.is_finite() {
            return None;
        }
        let g = d.matrix3.transpose() * d.matrix3;
        let (low, high) = symmetric_extremes(&g);
        // The closed form's smallest eigenvalue can be off by far more than its rounding
        // suggests: lower it until `AᵀA - low I` is positive definite (a Cholesky factoring
        // with every pivot clear of its rounding), which proves `low` a lower bound.
        let mut low = low * (1.0 - 1e-6);
        while low > 1e-8 * high && !positive_definite(&g, low, 1e-12 * high) {
            low *= 0.5;
        }
        if low.is_nan() || low <= 1e-8 * high {
            return None;
        }
        let inv_s2 = ((1.0 / low) * (1.0 + 1e-5)) as f32;
        let inverse = d.inverse();
        let a = d.matrix3.transpose();
        Some(Self {
            m: *m,
            inverse,
            inv_s2: inv_s2.next_up(),
            rows: DVec3::new(
                a.x_axis.abs().element_sum(),
                a.y_axis.abs().element_sum(),
                a.z_axis.abs().element_sum(),
            ),
            shift: d.translation.abs(),
            sigma: low.sqrt(),
            uneven: high > UNEVEN * UNEVEN * low,
        })
    }
}

impl Placed {
    /// The lanes that carry boxes into the world, where the map scales unevenly (see
    /// [`UNEVEN`]).
    pub(super) fn world_lanes(&self) -> Option<super::lanes::PlacedLanes> {
        self.uneven.then(|| super::lanes::PlacedLanes::new(&self.m))
    }

    /// The margin (in mesh units) that covers the rounding of the placed vertices of a mesh
    /// inside `root` and of world-space arithmetic on coordinates up to `near` in magnitude.
    fn margin(&self, root: &Aabb, near: f32) -> f64 {
        let eps = f64::from(f32::EPSILON);
        let reach = f64::from(root.min.abs().max(root.max.abs()).max_element());
        // Each placed coordinate is rounded at most 4 times; the world-space closest point
        // and its distance round relative to the world coordinates involved (8 ε as the
        // in-place walk allows); twice each, in world units, then in mesh units over σ.
        let vertex = (self.rows * reach + self.shift) * (4.0 * eps);
        let world = self.rows.max_element() * reach + self.shift.max_element();
        let world = f64::from(near) + world;
        2.0 * (vertex.length() + 8.0 * eps * world) / self.sigma
    }

    /// For the sphere overlap: the mesh-space lanes of the centre `p` and the reach under
    /// which a lane's box distance keeps it (every lane holding a placed triangle within
    /// `r2`, inclusive, stays).
    pub(super) fn sphere_lanes(
        &self,
        p: Vec3,
        r2: f32,
        root: &Aabb,
    ) -> Option<(DistanceLanes, f32)> {
        Some((self.lanes(p, root)?, self.reach(r2).next_up()))
    }

    /// For the box overlap: a mesh-space box holding every point of a triangle of the mesh
    /// (inside `root`) whose placed triangle touches `world` (the preimage's box, widened by
    /// the margin of the placed vertices' rounding); `None` when `world` is not finite.
    pub(super) fn mesh_box(&self, world: &Aabb, root: &Aabb) -> Option<Aabb> {
        if !world.is_finite() {
            return None;
        }
        let (lo, hi) = (world.min.as_dvec3(), world.max.as_dvec3());
        let (mut min, mut max) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for k in 0..8 {
            let c = DVec3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            let q = self.inverse.transform_point3(c);
            min = min.min(q);
            max = max.max(q);
        }
        let near = world.min.abs().max(world.max.abs()).max_element();
        let margin = DVec3::splat(self.margin(root, near));
        let (min, max) = ((min - margin).as_vec3(), (max + margin).as_vec3());
        let (min, max) = (
            Vec3::from(min.to_array().map(f32::next_down)),
            Vec3::from(max.to_array().map(f32::next_up)),
        );
        (min.is_finite() && max.is_finite()).then(|| Aabb::new(min, max))
    }
}

impl Frame for Placed {
    fn lanes(&self, p: Vec3, root: &Aabb) -> Option<DistanceLanes> {
        let q = self.inverse.transform_point3(p.as_dvec3()).as_vec3();
        if !q.is_finite() {
            return None;
        }
        let margin = self.margin(root, p.abs().max_element());
        Some(DistanceLanes::new(q, root, margin as f32))
    }
    #[inline(always)]
    fn reach(&self, best: f32) -> f32 {
        best * self.inv_s2
    }
    #[inline(always)]
    fn place(&self, v: Vec3) -> Vec3 {
        self.m.transform_point3(v)
    }
}

/// Whether `g - shift I` (symmetric) factors as `L D Lᵀ` with every pivot of `D` above `floor`.
fn positive_definite(g: &glam::DMat3, shift: f64, floor: f64) -> bool {
    let m = |r: usize, c: usize| g.col(c)[r] - if r == c { shift } else { 0.0 };
    let d1 = m(0, 0);
    if d1.is_nan() || d1 <= floor {
        return false;
    }
    let (l10, l20) = (m(1, 0) / d1, m(2, 0) / d1);
    let d2 = m(1, 1) - l10 * l10 * d1;
    if d2.is_nan() || d2 <= floor {
        return false;
    }
    let l21 = (m(2, 1) - l20 * l10 * d1) / d2;
    m(2, 2) - l20 * l20 * d1 - l21 * l21 * d2 > floor
}

/// The smallest (at least 0) and largest eigenvalues of the symmetric `g` (for `g = AᵀA`, the
/// squared extreme singular values of `A`), by the closed form for symmetric 3×3 matrices
/// (Smith, "Eigenvalues of a symmetric 3 × 3 matrix", 1961).
fn symmetric_extremes(g: &glam::DMat3) -> (f64, f64) {
    let g = *g;
    let off = g.y_axis.x.powi(2) + g.z_axis.x.powi(2) + g.z_axis.y.powi(2);
    let q = (g.x_axis.x + g.y_axis.y + g.z_axis.z) / 3.0;
    let p2 =
        (g.x_axis.x - q).powi(2) + (g.y_axis.y - q).powi(2) + (g.z_axis.z - q).powi(2) + 2.0 * off;
    if p2 <= 0.0 {
        return (q, q);
    }
    let p = (p2 / 6.0).sqrt();
    let b = (g - glam::DMat3::from_diagonal(DVec3::splat(q))) * (1.0 / p);
    let phi = (b.determinant() / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    let high = q + 2.0 * p * phi.cos();
    let low = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    (low.max(0.0), high)
}

#[cfg(test)]
mod tests {
    use crate::bvh::{BuildParams, MeshBvh4, MeshBvh8, brute_force_closest_point};
    use crate::geom::shapes;
    use glam::{Affine3A, Quat, Vec3};

    /// The squared singular values of a turned, unevenly scaled map; none for a singular one.
    #[test]
    fn singular_values_of_placements() {
        let a = Affine3A::from_scale_rotation_translation(
            Vec3::new(2.0, 0.3, 1.0),
            Quat::from_rotation_y(0.8) * Quat::from_rotation_x(-0.3),
            Vec3::new(4.0, 5.0, 6.0),
        );
        let d = glam::DAffine3::from_mat4(glam::Mat4::from(a).as_dmat4());
        let (low, high) = super::symmetric_extremes(&(d.matrix3.transpose() * d.matrix3));
        assert!(
            (low - 0.09).abs() < 1e-6 && (high - 4.0).abs() < 1e-5,
            "{low} {high}"
        );
        let p = super::Placed::new(&a).unwrap();
        let s = f64::from(0.3f32);
        assert!(p.sigma <= s && p.sigma > s * (1.0 - 1e-5), "{}", p.sigma);
        let flat = Affine3A::from_scale(Vec3::new(1.0, 1.0, 0.0));
        assert!(super::Placed::new(&flat).is_none());
        assert!(super::Placed::new(&Affine3A::from_scale(Vec3::splat(f32::NAN))).is_none());
    }

    /// With room for one or two pending subtrees nearly every subtree is searched depth first
    /// on the spot: the answers stay brute force's, on fresh and refitted 8-wide trees and a
    /// 4-wide one.
    #[test]
    fn depth_first_fallback_is_exact() {
        let mut mesh = shapes::icosphere(3);
        let rest = mesh.positions.clone();
        let mut refitted = MeshBvh8::build(&mesh, &BuildParams::BINNED);
        shapes::sine_deform(&rest, &mut mesh.positions, 0.05, 0.3);
        refitted.refit(&mesh);
        let fresh = MeshBvh8::build(&mesh, &BuildParams::BINNED);
        let fresh4 = MeshBvh4::build(&mesh, &BuildParams::BINNED);
        let mut seed = 1u32;
        let mut f = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 * 3.0 - 1.5
        };
        for _ in 0..200 {
            let p = Vec3::new(f(), f(), f());
            let want = brute_force_closest_point(&mesh, p, f32::INFINITY).map(|h| h.distance);
            for limit in [1, 2, super::PENDING] {
                for tree in [&fresh, &refitted] {
                    let got = tree
                        .closest_point_pending(p, f32::INFINITY, limit, &super::InPlace)
                        .map(|(_, d2, _)| d2.sqrt());
                    assert_eq!(got, want, "{p} with {limit} pending");
                }
                let got = fresh4
                    .closest_point_pending(p, f32::INFINITY, limit, &super::InPlace)
                    .map(|(_, d2, _)| d2.sqrt());
                assert_eq!(got, want, "{p} with {limit} pending, 4 wide");
            }
        }
    }
}
