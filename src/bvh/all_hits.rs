//! Every hit along a ray, not only the closest: for inside/outside tests and occupancy (count
//! the crossings), transparency and multi-return sensors (the first few surfaces in order).
//! A bounded query walks as the closest hit does, with a distance limit that only shrinks once
//! `max` hits are held (the farthest of them), so `all_hits(ray, 1)` costs about a closest hit.
//! An unbounded one and a hit count can prune nothing: they visit every leaf the ray's box test
//! reaches, in any order ([`Bvh::leaves_hit`](super::Bvh::leaves_hit)).

use super::MeshBvh;
use crate::geom::{Hit, Ray, RayTriPrecomp, TriMesh, intersect_triangle};

impl MeshBvh {
    /// The first `max` hits along `ray` in `[ray.tmin, ray.tmax)`, sorted by `t` (then by
    /// triangle), into `out` (cleared first). With `max` at least the number of hits, exactly
    /// [`brute_force_all_hits`]; a ray through a shared edge or vertex hits every triangle
    /// there (the watertight test reports each). Of hits at the same `t` as the `max`-th, which
    /// are kept is unspecified.
    pub fn all_hits(&self, ray: &Ray, max: usize, out: &mut Vec<Hit>) {
        out.clear();
        if max == 0 {
            return;
        }
        if max == usize::MAX {
            self.hits_any_order(ray, ray.tmax, |h| out.push(h));
        } else {
            self.all_hits_within(ray, ray.tmax, max, out);
        }
        out.sort_unstable_by(|a, b| a.t.total_cmp(&b.t).then(a.prim.cmp(&b.prim)));
        out.truncate(max);
    }

    /// Hits along `ray` in `[ray.tmin, tmax)` appended to `out` (unsorted); once `out` holds
    /// `max` of them or more, only hits nearer than the farthest of the nearest `max` are
    /// searched for.
    fn all_hits_within(&self, ray: &Ray, tmax: f32, max: usize, out: &mut Vec<Hit>) {
        let start = out.len();
        self.for_each_hit(ray, tmax, |h| {
            out.push(h);
            keep_nearest(out, start, max, |h| h.t)
        });
    }

    /// Calls `on_hit` with every hit along `ray` in `[ray.tmin, limit)`, `limit` starting at
    /// `tmax` and replaced by what `on_hit` returns when that is nearer (the rest of the walk
    /// then looks only nearer than it).
    pub(crate) fn for_each_hit(&self, ray: &Ray, tmax: f32, mut on_hit: impl FnMut(Hit) -> f32) {
        let pre = RayTriPrecomp::new(ray.dir);
        let tris = self.tris.as_slice();
        let prims = self.bvh.prim_indices();
        let mut ray = *ray;
        ray.tmax = tmax;
        let mut limit = tmax;
        self.bvh.closest_slot(
            &ray,
            |slot, _| {
                let [a, b, c] = tris[slot];
                let (t, u, v) = intersect_triangle(&ray, &pre, a, b, c, limit)?;
                let next = on_hit(Hit {
                    t,
                    u,
                    v,
                    prim: prims[slot],
                });
                if next < limit {
                    limit = next;
                    return Some(limit);
                }
                None
            },
            &mut (),
        );
    }

    /// Calls `on_hit` with every hit along `ray` in `[ray.tmin, tmax)`, in no particular order.
    #[inline]
    pub(crate) fn hits_any_order(&self, ray: &Ray, tmax: f32, mut on_hit: impl FnMut(Hit)) {
        let pre = RayTriPrecomp::new(ray.dir);
        let tris = self.tris.as_slice();
        let prims = self.bvh.prim_indices();
        self.bvh.leaves_hit(ray, tmax, |first, count| {
            let slots = first..first + count;
            for (&[a, b, c], &prim) in tris[slots.clone()].iter().zip(&prims[slots]) {
                if let Some((t, u, v)) = intersect_triangle(ray, &pre, a, b, c, tmax) {
                    on_hit(Hit { t, u, v, prim });
                }
            }
        });
    }

    /// How many triangles `ray` hits in `[ray.tmin, ray.tmax)`, each triangle once (a ray
    /// through a shared edge counts every triangle there). Exactly the length of
    /// [`brute_force_all_hits`].
    #[must_use]
    pub fn count_hits(&self, ray: &Ray) -> u32 {
        let mut n = 0;
        self.hits_any_order(ray, ray.tmax, |_| n += 1);
        n
    }
}

/// Keeps the nearest `max` entries of `v[start..]` (by `t`) once there are `max` or more, and
/// returns the limit the search may shrink to: the `t` of the farthest kept, else `+inf`.
pub(crate) fn keep_nearest<T>(
    v: &mut Vec<T>,
    start: usize,
    max: usize,
    t: impl Fn(&T) -> f32,
) -> f32 {
    let held = v.len() - start;
    if max == 0 || held < max {
        return f32::INFINITY;
    }
    let mine = &mut v[start..];
    mine.select_nth_unstable_by(max - 1, |a, b| t(a).total_cmp(&t(b)));
    let limit = t(&mine[max - 1]);
    v.truncate(start + max);
    limit
}

/// The reference for [`MeshBvh::all_hits`]: every triangle tested, every hit in
/// `[ray.tmin, ray.tmax)` sorted by `t`, then triangle.
#[must_use]
pub fn brute_force_all_hits(mesh: &TriMesh, ray: &Ray) -> Vec<Hit> {
    let pre = RayTriPrecomp::new(ray.dir);
    let mut hits: Vec<Hit> = mesh
        .indices
        .iter()
        .enumerate()
        .filter_map(|(k, t)| {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            let (t, u, v) = intersect_triangle(ray, &pre, a, b, c, ray.tmax)?;
            Some(Hit {
                t,
                u,
                v,
                prim: k as u32,
            })
        })
        .collect();
    hits.sort_unstable_by(|a, b| a.t.total_cmp(&b.t).then(a.prim.cmp(&b.prim)));
    hits
}

#[cfg(test)]
mod tests {
    use super::brute_force_all_hits;
    use crate::bvh::{BuildParams, MeshBvh};
    use crate::geom::{Hit, Ray, shapes};
    use glam::Vec3;

    /// The unordered walk (unbounded, counts) and the pruned one (bounded) against brute force
    /// on rays aimed at a closed mesh's vertices and edge midpoints, where the watertight test
    /// leaves no gap (every ray hits), from outside, from the centre, as segments ending
    /// inside and along the axes (inside box faces' planes).
    #[test]
    fn unbounded_and_bounded_hits_through_shared_edges_and_vertices() {
        let mut mesh = shapes::icosphere(2);
        let rest = mesh.positions.clone();
        let mut refitted = MeshBvh::build(&mesh, &BuildParams::BINNED);
        shapes::sine_deform(&rest, &mut mesh.positions, 0.05, 0.3);
        refitted.refit(&mesh);
        let fresh = MeshBvh::build(&mesh, &BuildParams::BINNED);
        let mut targets: Vec<Vec3> = mesh.positions.clone();
        for t in &mesh.indices {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            targets.extend([(a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5]);
        }
        let mut rays = Vec::new();
        for (k, &p) in targets.iter().enumerate() {
            let from = Vec3::new(2.5, 1.5 - (k % 7) as f32 * 0.5, -2.0 + (k % 5) as f32);
            rays.push(Ray::new(from, p - from));
            rays.push(Ray::new(Vec3::ZERO, p));
            rays.push(Ray::segment(from, p * 0.5));
            // Along an axis through a vertex: the ray runs inside the planes of the faces of
            // the boxes that vertex bounds.
            let axis = [Vec3::X, Vec3::Y, Vec3::Z][k % 3];
            rays.push(Ray::new(p + axis * 3.0, -axis));
        }
        let mut hits: Vec<Hit> = Vec::new();
        for (k, ray) in rays.iter().enumerate() {
            let want = brute_force_all_hits(&mesh, ray);
            // From the centre and into the inside, a ray crosses the closed surface: no gap at
            // an edge or a vertex lets it through (from outside it may graze the silhouette).
            assert!(
                k % 4 == 0 || k % 4 == 3 || !want.is_empty(),
                "{ray:?} slips through"
            );
            for bvh in [&fresh, &refitted] {
                bvh.all_hits(ray, usize::MAX, &mut hits);
                assert_eq!(hits, want, "every hit of {ray:?}");
                assert_eq!(bvh.count_hits(ray) as usize, want.len(), "count of {ray:?}");
                for max in [1, 2, 3] {
                    bvh.all_hits(ray, max, &mut hits);
                    let got: Vec<f32> = hits.iter().map(|h| h.t).collect();
                    let expect: Vec<f32> = want.iter().take(max).map(|h| h.t).collect();
                    assert_eq!(got, expect, "{max} hits of {ray:?}");
                }
            }
        }
    }
}
