//! Proximity, overlap and multi-hit queries through the two-level scene. The top-level tree
//! prunes instances by their world boxes. Inside an instance, with [`super::Traversal::Wide`],
//! every query walks the mesh's 8-wide tree: all hits and hit counts carry the ray into
//! instance space, as the ray queries do, so `t` keeps its meaning; the closest point and the
//! box and sphere overlaps search the mesh in its own space, box distances and the query
//! box's preimage widened to bound world ones ([`crate::bvh::wide`]'s `Placed`), or, under a
//! near-singular placement, with each box carried into the world. With the binary traversal
//! the mesh's binary tree (kept in every [`super::Traversal`], refitted or rebuilt by every
//! update) is walked, its node boxes carried into world space
//! ([`crate::geom::Aabb::transformed`], conservative). The triangles' vertices are transformed
//! as `transform_point3` rounds them, so distances and overlaps are world-space ones even under
//! scaled instances. Removed and hidden instances are skipped.

use super::{Engine, InstanceEntry, InstanceId, MeshId, SceneHit, local_ray};
use crate::bvh::wide::Placed;
use crate::bvh::{MeshBvh, keep_nearest};
use crate::geom::{Aabb, Hit, Ray, box_distance_squared};
use glam::{Affine3A, Vec3};

/// The scene's surface point nearest to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScenePoint {
    /// The nearest point, in world space.
    pub point: Vec3,
    /// Its distance to the query point.
    pub distance: f32,
    /// The triangle it lies on, within the instance's mesh.
    pub prim: u32,
    /// The instance.
    pub instance: InstanceId,
    /// The instance's mesh.
    pub mesh: MeshId,
}

/// The instance's transform when it is not the identity (the mesh is then walked in place).
fn placement(inst: &InstanceEntry) -> Option<&Affine3A> {
    (!inst.identity).then_some(&inst.transform)
}

impl Engine {
    /// The live instance behind a top-level slot, if queries see it.
    #[inline]
    fn slot_instance(&self, slot: usize) -> Option<(u32, &InstanceEntry, &MeshBvh)> {
        let k = self.tlas_instances[self.tlas.prim_indices()[slot] as usize];
        let inst = &self.instances[k as usize];
        (inst.visible && !inst.removed).then(|| (k, inst, &self.meshes[inst.mesh as usize].bvh))
    }

    /// The surface point nearest to `p` within `max_dist` (inclusive; `f32::INFINITY` for no
    /// limit), over every instance, as of the last update; `None` when nothing is that close.
    /// Exactly the minimum over all world-space triangles of
    /// [`crate::geom::closest_point_on_triangle`]; of two at the same distance either may come.
    #[must_use]
    pub fn closest_point(&self, p: Vec3, max_dist: f32) -> Option<ScenePoint> {
        let mut found = None;
        self.tlas.nearest_slot(
            |n| box_distance_squared(p, n.bounds()),
            crate::bvh::squared_bound(max_dist),
            |slot, best| {
                let (k, inst, bvh) = self.slot_instance(slot)?;
                let wide = self.meshes[inst.mesh as usize].wide.as_ref();
                let place = placement(inst);
                let (point, d2, prim) = match (place, wide) {
                    (None, Some(w)) => w.closest_point_below(p, best)?,
                    (Some(m), Some(w)) => match Placed::new(m) {
                        Some(placed) => w.closest_point_placed(p, best, &placed)?,
                        None => w.closest_point_transformed(p, best, m)?,
                    },
                    (place, None) => bvh.closest_point_placed(p, best, place)?,
                };
                found = Some(ScenePoint {
                    point,
                    distance: d2.sqrt(),
                    prim,
                    instance: InstanceId(k),
                    mesh: MeshId(inst.mesh),
                });
                Some(d2)
            },
        );
        found
    }

    /// The triangles (instance, triangle within its mesh) that share a point with `query`,
    /// faces and edges included, into `out` (cleared first), sorted. Exactly the world-space
    /// triangles [`crate::geom::triangle_overlaps_box`] accepts.
    pub fn overlap_box(&self, query: Aabb, out: &mut Vec<(InstanceId, u32)>) {
        out.clear();
        self.tlas.for_each_slot_in(
            |n| crate::bvh::boxes_touch(&n.bounds(), &query),
            |slot| {
                if let Some((k, inst, bvh)) = self.slot_instance(slot) {
                    let found = |t| out.push((InstanceId(k), t));
                    match &self.meshes[inst.mesh as usize].wide {
                        Some(w) => w.overlap_box_placed(query, placement(inst), found),
                        None => bvh.overlap_box_placed(query, placement(inst), found),
                    }
                }
            },
        );
        out.sort_unstable();
    }

    /// The triangles (instance, triangle) within `radius` of `centre`, into `out` (cleared
    /// first), sorted.
    pub fn overlap_sphere(&self, centre: Vec3, radius: f32, out: &mut Vec<(InstanceId, u32)>) {
        out.clear();
        if radius.is_nan() || radius < 0.0 {
            return;
        }
        let r2 = radius * radius;
        self.tlas.for_each_slot_in(
            |n| box_distance_squared(centre, n.bounds()) <= r2,
            |slot| {
                if let Some((k, inst, bvh)) = self.slot_instance(slot) {
                    let found = |t| out.push((InstanceId(k), t));
                    let place = placement(inst);
                    match &self.meshes[inst.mesh as usize].wide {
                        Some(w) => w.overlap_sphere_placed(centre, radius, place, found),
                        None => bvh.overlap_sphere_placed(centre, radius, place, found),
                    }
                }
            },
        );
        out.sort_unstable();
    }

    /// The instances a box touches (some triangle of theirs does), sorted, into `out`.
    pub fn overlap_box_instances(&self, query: Aabb, out: &mut Vec<InstanceId>) {
        let mut tris = Vec::new();
        self.overlap_box(query, &mut tris);
        out.clear();
        out.extend(tris.iter().map(|&(i, _)| i));
        out.dedup();
    }

    /// The first `max` hits along `ray` in `[ray.tmin, ray.tmax)` over every instance, sorted
    /// by `t` (then instance, then triangle), into `out` (cleared first). With `max` at least
    /// the number of hits, every hit of every instance; of hits at the same `t` as the
    /// `max`-th, which are kept is unspecified.
    pub fn all_hits(&self, ray: &Ray, max: usize, out: &mut Vec<SceneHit>) {
        out.clear();
        if max == 0 {
            return;
        }
        let mut limit = ray.tmax;
        self.tlas.closest_slot(
            ray,
            |slot, _| {
                let (k, inst, bvh) = self.slot_instance(slot)?;
                let local = local_ray(inst, ray, limit);
                let below = limit;
                let mut on_hit = |h: Hit| {
                    out.push(SceneHit {
                        t: h.t,
                        u: h.u,
                        v: h.v,
                        prim: h.prim,
                        instance: InstanceId(k),
                    });
                    let l = keep_nearest(out, 0, max, |h| h.t);
                    limit = limit.min(l);
                    limit
                };
                match &self.meshes[inst.mesh as usize].wide {
                    // Nothing shortens an unbounded walk: any order will do.
                    Some(w) if max == usize::MAX => w.hits_any_order(&local, below, on_hit),
                    Some(w) => w.for_each_hit(&local, below, on_hit),
                    None if max == usize::MAX => bvh.hits_any_order(&local, below, |h| {
                        on_hit(h);
                    }),
                    None => bvh.for_each_hit(&local, below, on_hit),
                }
                (limit < ray.tmax).then_some(limit)
            },
            &mut (),
        );
        out.sort_unstable_by(|a, b| {
            a.t.total_cmp(&b.t)
                .then(a.instance.cmp(&b.instance))
                .then(a.prim.cmp(&b.prim))
        });
        out.truncate(max);
    }

    /// How many triangles `ray` hits in `[ray.tmin, ray.tmax)` over every instance (each
    /// triangle once; a ray through a shared edge counts every triangle there): with a closed
    /// surface, an odd count from a point means inside.
    #[must_use]
    pub fn count_hits(&self, ray: &Ray) -> u32 {
        let mut n = 0;
        self.tlas.closest_slot(
            ray,
            |slot, _| {
                let (_, inst, bvh) = self.slot_instance(slot)?;
                let local = local_ray(inst, ray, ray.tmax);
                match &self.meshes[inst.mesh as usize].wide {
                    Some(w) => w.hits_any_order(&local, ray.tmax, |_| {
                        n += 1;
                        ray.tmax
                    }),
                    None => bvh.hits_any_order(&local, ray.tmax, |_| n += 1),
                }
                None
            },
            &mut (),
        );
        n
    }
}
