//! Every hit along a ray on the wide tree: the closest-hit traversal (children nearest first,
//! one SIMD slab test per node) with a limit that only shrinks once `max` hits are held, and a
//! block test that reports every lane it hits ([`intersect4_all`]), bit for bit the scalar
//! test's distances, so the hits are exactly the binary tree's and brute force's.

use super::lanes::{BlockHits, RayLanes, TriLanes, intersect4_all, slab};
use super::traverse::{BIG_STACK, SMALL_STACK};
use super::{LEAF_BIT, WideBvh, leaf_range};
use crate::bvh::keep_nearest;
use crate::geom::{FAR_SCALE, Hit, Ray, RayTriPrecomp, intersect_triangle};

impl<const K: usize> WideBvh<K> {
    /// The first `max` hits along `ray` in `[ray.tmin, ray.tmax)`, sorted by `t` (then by
    /// triangle), into `out` (cleared first): exactly
    /// [`MeshBvh::all_hits`](crate::bvh::MeshBvh::all_hits).
    pub fn all_hits(&self, ray: &Ray, max: usize, out: &mut Vec<Hit>) {
        out.clear();
        if max == 0 {
            return;
        }
        let walk = |on_hit| {
            // Nothing shortens an unbounded walk: it may take the children in any order.
            if max == usize::MAX {
                self.hits_any_order(ray, ray.tmax, on_hit);
            } else {
                self.for_each_hit(ray, ray.tmax, on_hit);
            }
        };
        walk(&mut |h| {
            out.push(h);
            keep_nearest(out, 0, max, |h| h.t)
        });
        out.sort_unstable_by(|a, b| a.t.total_cmp(&b.t).then(a.prim.cmp(&b.prim)));
        out.truncate(max);
    }

    /// How many triangles `ray` hits in `[ray.tmin, ray.tmax)`, each triangle once: exactly
    /// [`MeshBvh::count_hits`](crate::bvh::MeshBvh::count_hits).
    #[must_use]
    pub fn count_hits(&self, ray: &Ray) -> u32 {
        let mut n = 0;
        self.hits_any_order(ray, ray.tmax, |_| {
            n += 1;
            ray.tmax
        });
        n
    }

    /// Calls `on_hit` with every hit along `ray` in `[ray.tmin, limit)`, `limit` starting at
    /// `tmax` and replaced by what `on_hit` returns when that is nearer (the rest of the walk
    /// then looks only nearer than it).
    pub(crate) fn for_each_hit(&self, ray: &Ray, tmax: f32, on_hit: impl FnMut(Hit) -> f32) {
        if self.stack_need < SMALL_STACK {
            self.hits_walk::<true, SMALL_STACK>(ray, tmax, on_hit);
        } else {
            self.hits_walk::<true, BIG_STACK>(ray, tmax, on_hit);
        }
    }

    /// [`WideBvh::for_each_hit`] for callers that never shorten the walk: the children are
    /// taken in lane order, unsorted.
    pub(crate) fn hits_any_order(&self, ray: &Ray, tmax: f32, on_hit: impl FnMut(Hit) -> f32) {
        if self.stack_need < SMALL_STACK {
            self.hits_walk::<false, SMALL_STACK>(ray, tmax, on_hit);
        } else {
            self.hits_walk::<false, BIG_STACK>(ray, tmax, on_hit);
        }
    }

    /// [`WideBvh::for_each_hit`] on a stack of `N` entries; `ORDERED` visits the hit children
    /// nearest first.
    #[inline(always)]
    fn hits_walk<const ORDERED: bool, const N: usize>(
        &self,
        ray: &Ray,
        tmax: f32,
        mut on_hit: impl FnMut(Hit) -> f32,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let lanes = RayLanes::new(ray);
        let tri_lanes = TriLanes::new(ray);
        let pre = RayTriPrecomp::new(ray.dir);
        let mut limit = tmax;
        let mut stack = [(0u32, 0f32); N];
        let mut sp = 0usize;
        let mut dist = [0f32; K];
        let mut cur = 0u32;
        loop {
            if cur & LEAF_BIT != 0 {
                let (first, count) = leaf_range(cur);
                let first = first as usize;
                for block in &self.blocks[first..first + count as usize] {
                    match intersect4_all(block, &tri_lanes, limit) {
                        BlockHits::None => {}
                        BlockHits::Lanes { mut mask, t, u, v } => {
                            while mask != 0 {
                                let l = mask.trailing_zeros() as usize;
                                mask &= mask - 1;
                                // A lane beyond a limit an earlier lane set is left out, as
                                // the binary tree's test with that limit would.
                                if t[l] < limit {
                                    let h = Hit {
                                        t: t[l],
                                        u: u[l],
                                        v: v[l],
                                        prim: block.prims[l],
                                    };
                                    limit = limit.min(on_hit(h));
                                }
                            }
                        }
                        BlockHits::Scalar => {
                            for l in 0..4 {
                                let [p, q, r] = block.get(l);
                                if let Some((t, u, v)) =
                                    intersect_triangle(ray, &pre, p, q, r, limit)
                                {
                                    let prim = block.prims[l];
                                    limit = limit.min(on_hit(Hit { t, u, v, prim }));
                                }
                            }
                        }
                    }
                }
            } else {
                let node = &self.nodes[cur as usize];
                let mut mask = slab(&node.bounds, &lanes, limit, &mut dist);
                if lanes.nonfinite {
                    mask &= node.occupied();
                }
                // Hit lanes onto the stack (sorted by entry distance, farthest first, when
                // ordered), each asked for from memory.
                let base = sp;
                while mask != 0 {
                    let k = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let e = (node.child[k], dist[k]);
                    self.prefetch(e.0);
                    let mut j = sp;
                    while ORDERED && j > base && stack[j - 1].1 < e.1 {
                        stack[j] = stack[j - 1];
                        j -= 1;
                    }
                    stack[j] = e;
                    sp += 1;
                }
            }
            // Pop the next subtree that may still hold a hit below the limit.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let (c, tnear) = stack[sp];
                if tnear <= limit * FAR_SCALE {
                    cur = c;
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::bvh::{BuildParams, MeshBvh4, MeshBvh8, brute_force_all_hits};
    use crate::geom::{Ray, shapes};
    use glam::Vec3;

    /// Both widths, fresh and refitted, every hit and the first two against brute force on
    /// rays through a deformed sphere (two hits or more each when they hit).
    #[test]
    fn all_hits_match_brute_force_at_both_widths() {
        let mut mesh = shapes::icosphere(3);
        let rest = mesh.positions.clone();
        let mut refit4 = MeshBvh4::build(&mesh, &BuildParams::BINNED);
        let mut refit8 = MeshBvh8::build(&mesh, &BuildParams::BINNED);
        shapes::sine_deform(&rest, &mut mesh.positions, 0.05, 0.3);
        refit4.refit(&mesh);
        refit8.refit(&mesh);
        let fresh4 = MeshBvh4::build(&mesh, &BuildParams::BINNED);
        let fresh8 = MeshBvh8::build(&mesh, &BuildParams::BINNED);
        let mut seed = 7u32;
        let mut f = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
        };
        let mut hits = Vec::new();
        let mut hitting = 0;
        for _ in 0..300 {
            let o = Vec3::new(f(), f(), f()) * 3.0;
            let ray = Ray::new(o, Vec3::new(f(), f(), f()) * 0.8 - o);
            let want = brute_force_all_hits(&mesh, &ray);
            hitting += usize::from(!want.is_empty());
            for max in [usize::MAX, 1, 2] {
                let expect: Vec<f32> = want.iter().take(max).map(|h| h.t).collect();
                let check = |hits: &Vec<crate::geom::Hit>, what: &str| {
                    assert_eq!(
                        hits.iter().map(|h| h.t).collect::<Vec<_>>(),
                        expect,
                        "{what}, {max} hits of {ray:?}"
                    );
                };
                fresh4.all_hits(&ray, max, &mut hits);
                check(&hits, "4 wide");
                refit4.all_hits(&ray, max, &mut hits);
                check(&hits, "4 wide refitted");
                fresh8.all_hits(&ray, max, &mut hits);
                check(&hits, "8 wide");
                refit8.all_hits(&ray, max, &mut hits);
                check(&hits, "8 wide refitted");
            }
            assert_eq!(fresh4.count_hits(&ray) as usize, want.len());
            assert_eq!(refit8.count_hits(&ray) as usize, want.len());
        }
        assert!(hitting > 100, "most rays aim at the sphere");
    }
}
