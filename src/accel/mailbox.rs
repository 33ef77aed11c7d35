//! Mailboxing (Amanatides & Woo 1987): a space partition holds a triangle in every cell it
//! overlaps, so a ray meets it again in the next cells; a few recently tested triangle ids,
//! kept per ray, skip those repeats. A skipped test could not have changed the answer: it ran
//! with a `tmax` no smaller than today's.

use super::interval::beyond;
use super::triangles::{AnyHit, Closest, Triangles};
use crate::bvh::Counters;
use crate::geom::{Hit, Ray};

/// The last [`Mailbox::SIZE`] triangles a ray tested, as a ring.
pub(super) struct Mailbox {
    ids: [u32; Mailbox::SIZE],
    next: usize,
}

impl Mailbox {
    /// Ids remembered.
    pub(super) const SIZE: usize = 8;

    /// An empty mailbox.
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            ids: [u32::MAX; Self::SIZE],
            next: 0,
        }
    }

    /// True when `id` was tested recently; otherwise remembers it and returns false.
    #[inline(always)]
    pub(super) fn seen(&mut self, id: u32) -> bool {
        if self.ids.contains(&id) {
            return true;
        }
        self.ids[self.next] = id;
        self.next = (self.next + 1) % Self::SIZE;
        false
    }
}

/// A space partition that holds a triangle in every cell (or leaf) it overlaps, and walks the
/// cells a ray crosses in order: the grids and the octree. Closest and any hit over such a walk
/// are the same for all of them: each triangle tested once per ray (the mailbox), and the walk
/// told after each cell how far a cell can still help (the best hit, widened by `beyond`).
pub(super) trait CellWalk {
    /// The triangles the cells' ids index.
    fn triangles(&self) -> &Triangles;

    /// Walks the cells along `ray` in order; `cell` tests one cell's triangle ids and returns
    /// true to stop; `cap()` is the distance beyond which no cell can help.
    fn walk<C: Counters>(
        &self,
        ray: &Ray,
        c: &mut C,
        cell: impl FnMut(&[u32], &mut C) -> bool,
        cap: impl Fn() -> f32,
    );

    /// The closest hit along `ray`, counting the work.
    #[inline(always)]
    fn closest_in_cells<C: Counters>(&self, ray: &Ray, c: &mut C) -> Option<Hit> {
        let tris = &self.triangles().tris;
        let mut q = Closest::new(ray);
        let cap = std::cell::Cell::new(beyond(q.tmax));
        let mut mailbox = Mailbox::new();
        self.walk(
            ray,
            c,
            |refs, c| {
                for &p in refs {
                    if !mailbox.seen(p) {
                        q.test(&tris[p as usize], p, c);
                    }
                }
                cap.set(beyond(q.tmax));
                false
            },
            || cap.get(),
        );
        q.hit
    }

    /// True when anything is hit along `ray`, counting the work.
    #[inline(always)]
    fn any_in_cells<C: Counters>(&self, ray: &Ray, c: &mut C) -> bool {
        let tris = &self.triangles().tris;
        let q = AnyHit::new(ray);
        let cap = beyond(ray.tmax);
        let mut mailbox = Mailbox::new();
        let mut found = false;
        self.walk(
            ray,
            c,
            |refs, c| {
                found = refs
                    .iter()
                    .any(|&p| !mailbox.seen(p) && q.test(&tris[p as usize], c));
                found
            },
            || cap,
        );
        found
    }
}

/// The ray queries of [`Accel`](super::Accel) (closest and any hit, plain and counted) for a
/// [`CellWalk`], written inside its `impl Accel`.
macro_rules! cell_walk_queries {
    () => {
        fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
            self.closest_in_cells(ray, &mut ())
        }

        fn any_hit(&self, ray: &Ray) -> bool {
            self.any_in_cells(ray, &mut ())
        }

        fn closest_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> Option<Hit> {
            self.closest_in_cells(ray, stats)
        }

        fn any_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> bool {
            self.any_in_cells(ray, stats)
        }
    };
}
pub(super) use cell_walk_queries;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remembers_the_last_ids() {
        let mut m = Mailbox::new();
        assert!(!m.seen(3));
        assert!(m.seen(3));
        for i in 10..10 + Mailbox::SIZE as u32 {
            assert!(!m.seen(i));
        }
        assert!(!m.seen(3), "evicted after SIZE others");
    }
}
