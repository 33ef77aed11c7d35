//! Closest-hit and any-hit traversal of the wide tree: each node's children are tested in one
//! SIMD slab test; for closest hit the hit children are visited nearest first (the others go on
//! the stack, farthest at the bottom, with their entry distances, and are skipped when popped
//! beyond the closest hit so far). Leaf triangles use the crate's watertight test, so the tree
//! reports exactly the binary tree's and brute force's distance.

use super::lanes::{BlockHit, RayLanes, TriLanes, intersect4, slab, slab_fma};
use super::{LEAF_BIT, NO_PRIM, WideBvh, leaf_range};
use crate::bvh::Counters;
use crate::geom::{FAR_SCALE, Hit, Ray, intersect_triangle};

/// Stack entries of the traversal for trees whose bound fits (nearly all); deeper trees use
/// [`BIG_STACK`].
pub(super) const SMALL_STACK: usize = 64;
/// Enough for any tree: the binary depth is at most `MAX_DEPTH`, splitting binary leaves too
/// large for one lane adds at most 27 levels, and each level leaves at most 7 siblings pending.
pub(super) const BIG_STACK: usize = (crate::bvh::MAX_DEPTH + 32) * 8;

/// Whether the children pushed on the stack are prefetched.
const PREFETCH: bool = true;

/// Switches of the closest-hit and any-hit walk (bits of its `X` parameter), so that variants
/// can be timed against each other pass by pass in one process
/// ([`WideBvh::bench_closest_hit`]).
pub(super) mod x {
    /// Zero the stack's storage for every ray (as a `[T; N]` array would be).
    pub const ZERO_STACK: u32 = 1;
    /// Two hit children: compare and push the farther one, no insertion loop.
    pub const SORT2: u32 = 2;
}
/// The switches of the queries.
pub(super) const X_DEFAULT: u32 = x::SORT2;

/// The closest hit so far: block lane (`4 * block + lane`), distance, barycentrics.
pub(super) type Best = Option<(usize, f32, f32, f32)>;

impl<const K: usize> WideBvh<K> {
    /// The closest hit along `ray` in `[ray.tmin, ray.tmax)`.
    #[must_use]
    #[inline]
    pub fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        self.closest_hit_counted(ray, &mut ())
    }

    /// [`WideBvh::closest_hit`], counting nodes visited (interior and leaf) and triangles tested.
    #[must_use]
    #[inline]
    pub fn closest_hit_counted(&self, ray: &Ray, counters: &mut impl Counters) -> Option<Hit> {
        let best = if self.stack_need < SMALL_STACK {
            self.traverse::<false, SMALL_STACK, X_DEFAULT>(0, ray, ray.tmax, counters)
        } else {
            self.traverse::<false, BIG_STACK, X_DEFAULT>(0, ray, ray.tmax, counters)
        };
        best.map(|(slot, t, u, v)| Hit {
            t,
            u,
            v,
            prim: self.blocks[slot / 4].prims[slot % 4],
        })
    }

    /// For benchmarks: [`WideBvh::closest_hit`] with the walk's switches `variant` (bits of
    /// `traverse::x`; only the combinations listed here are compiled).
    #[doc(hidden)]
    #[must_use]
    pub fn bench_closest_hit(&self, ray: &Ray, variant: u32) -> Option<Hit> {
        use x::{SORT2, ZERO_STACK};
        assert!(self.stack_need < SMALL_STACK, "a deep tree");
        let best = match variant {
            0 => self.traverse::<false, SMALL_STACK, 0>(0, ray, ray.tmax, &mut ()),
            ZERO_STACK => {
                self.traverse::<false, SMALL_STACK, ZERO_STACK>(0, ray, ray.tmax, &mut ())
            }
            SORT2 => self.traverse::<false, SMALL_STACK, SORT2>(0, ray, ray.tmax, &mut ()),
            _ => panic!("variant {variant} not compiled"),
        };
        best.map(|(slot, t, u, v)| Hit {
            t,
            u,
            v,
            prim: self.blocks[slot / 4].prims[slot % 4],
        })
    }

    /// True when anything is hit along `ray` in `[ray.tmin, ray.tmax)`.
    #[must_use]
    #[inline]
    pub fn any_hit(&self, ray: &Ray) -> bool {
        self.any_hit_counted(ray, &mut ())
    }

    /// [`WideBvh::any_hit`], counting nodes visited and triangles tested.
    #[must_use]
    #[inline]
    pub fn any_hit_counted(&self, ray: &Ray, counters: &mut impl Counters) -> bool {
        if self.stack_need < SMALL_STACK {
            self.traverse::<true, SMALL_STACK, X_DEFAULT>(0, ray, ray.tmax, counters)
        } else {
            self.traverse::<true, BIG_STACK, X_DEFAULT>(0, ray, ray.tmax, counters)
        }
        .is_some()
    }

    /// Asks for the cache lines of a child that is likely visited soon: the whole node, or a
    /// leaf's first block (asking for every block of a leaf traced no faster).
    #[inline(always)]
    pub(super) fn prefetch(&self, c: u32) {
        if c & LEAF_BIT != 0 {
            let (first, _) = leaf_range(c);
            if let Some(b) = self.blocks.get(first as usize) {
                crate::simd::prefetch_all(b);
            }
        } else if let Some(n) = self.nodes.get(c as usize) {
            crate::simd::prefetch_all(n);
        }
    }

    /// The traversal both queries share, from the child reference `start` (0: the root; an
    /// interior node's box is not tested, its children's are) with hits closer than `tmax`.
    /// `ANY` returns at the first hit and visits children in lane order; otherwise hit children
    /// are visited nearest first.
    #[inline(always)]
    pub(super) fn traverse<const ANY: bool, const N: usize, const X: u32>(
        &self,
        start: u32,
        ray: &Ray,
        tmax: f32,
        counters: &mut impl Counters,
    ) -> Best {
        let lanes = RayLanes::new(ray);
        // One fused multiply-add a plane for the rays it is safe for (nearly all), else the
        // exact test.
        if lanes.fma_ok(self.coord_max) {
            self.walk::<ANY, N, true, X, _>(start, ray, &lanes, tmax, counters)
        } else {
            self.walk::<ANY, N, false, X, _>(start, ray, &lanes, tmax, counters)
        }
    }

    /// The closest hit (`ANY`: the first) closer than `tmax` among the triangles of the leaf
    /// `leaf`, a block of four at a time.
    #[inline(always)]
    pub(super) fn leaf<const ANY: bool, C: Counters>(
        &self,
        leaf: u32,
        ray: &Ray,
        tri_lanes: &TriLanes,
        mut tmax: f32,
        counters: &mut C,
    ) -> Best {
        let (first, count) = leaf_range(leaf);
        let first = first as usize;
        let mut best: Best = None;
        for (b, block) in (first..).zip(&self.blocks[first..first + count as usize]) {
            for l in 0..4 {
                if block.prims[l] != NO_PRIM {
                    counters.prim();
                    if C::TRIANGLES {
                        counters.triangle(block.get(l), tmax);
                    }
                }
            }
            let hit = match intersect4(block, tri_lanes, tmax) {
                BlockHit::None => continue,
                BlockHit::Hit(l, t, u, v) => Some((b * 4 + l, t, u, v)),
                BlockHit::Scalar => {
                    // Lane by lane, nearest first hit kept, as the scalar loop does.
                    let pre = tri_lanes.precomp();
                    let mut found = None;
                    for l in 0..4 {
                        let [p, q, r] = block.get(l);
                        if let Some((t, u, v)) = intersect_triangle(
                            ray,
                            &pre,
                            p,
                            q,
                            r,
                            found.map_or(tmax, |f: (usize, f32, f32, f32)| f.1),
                        ) {
                            found = Some((b * 4 + l, t, u, v));
                        }
                    }
                    found
                }
            };
            if let Some(h) = hit {
                if ANY {
                    return Some(h);
                }
                tmax = h.1;
                best = Some(h);
            }
        }
        best
    }

    /// [`WideBvh::traverse`] with the node test [`slab_fma`] (`FMA`) or [`slab`].
    #[inline(always)]
    fn walk<const ANY: bool, const N: usize, const FMA: bool, const X: u32, C: Counters>(
        &self,
        start: u32,
        ray: &Ray,
        lanes: &RayLanes,
        mut tmax: f32,
        counters: &mut C,
    ) -> Best {
        let nodes = self.nodes.as_slice();
        if nodes.is_empty() {
            return None;
        }
        let lanes = *lanes;
        let tri_lanes = TriLanes::new(ray);
        let mut best: Best = None;
        let mut stack = crate::simd::Stack::<(u32, f32), N>::default();
        if X & x::ZERO_STACK != 0 {
            stack.zero();
        }
        let mut dist = [0f32; K];
        let mut cur = start;
        loop {
            counters.node();
            if cur & LEAF_BIT != 0 {
                if let Some(h) = self.leaf::<ANY, C>(cur, ray, &tri_lanes, tmax, counters) {
                    if ANY {
                        return Some(h);
                    }
                    tmax = h.1;
                    best = Some(h);
                }
            } else {
                let node = &nodes[cur as usize];
                let mut mask = if FMA {
                    slab_fma(&node.bounds, &lanes, tmax, &mut dist)
                } else {
                    slab(&node.bounds, &lanes, tmax, &mut dist)
                };
                if lanes.nonfinite {
                    mask &= node.occupied();
                }
                if mask != 0 {
                    let hits = mask.count_ones();
                    if hits == 1 {
                        cur = node.child[mask.trailing_zeros() as usize];
                        continue;
                    }
                    if ANY {
                        // Lane order; the first hit lane is visited now.
                        let first = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        while mask != 0 {
                            let k = mask.trailing_zeros() as usize;
                            mask &= mask - 1;
                            if PREFETCH {
                                self.prefetch(node.child[k]);
                            }
                            stack.push((node.child[k], dist[k]));
                        }
                        cur = node.child[first];
                        continue;
                    }
                    if X & x::SORT2 != 0 && hits == 2 {
                        // Two hits, the commonest case after one: the farther one onto the
                        // stack without the insertion loop, ties ordered as it orders them.
                        let k0 = mask.trailing_zeros() as usize;
                        let k1 = (mask & (mask - 1)).trailing_zeros() as usize;
                        let a = (node.child[k0], dist[k0]);
                        let b = (node.child[k1], dist[k1]);
                        let (near, far) = if a.1 < b.1 { (a, b) } else { (b, a) };
                        if PREFETCH {
                            self.prefetch(far.0);
                        }
                        stack.push(far);
                        cur = near.0;
                        continue;
                    }
                    // Sort the hit lanes by entry distance, farthest first, onto the stack.
                    let base = stack.len();
                    while mask != 0 {
                        let k = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let e = (node.child[k], dist[k]);
                        if PREFETCH {
                            self.prefetch(e.0);
                        }
                        stack.insert_by(base, e, |e, s| s.1 < e.1);
                    }
                    // The nearest is on top: visit it now.
                    cur = stack.pop().expect("pushed").0;
                    continue;
                }
            }
            // Pop the next subtree that may still hold a closer hit.
            loop {
                let Some((c, tnear)) = stack.pop() else {
                    return best;
                };
                if tnear <= tmax * FAR_SCALE {
                    cur = c;
                    break;
                }
            }
        }
    }
}
