//! Batches of rays through the wide tree, one thread, incoherent batches reordered first
//! ([`RayOrder`]) so that rays that travel close together are traced one after the other.

use super::WideBvh;
use crate::bvh::ray_order::RayOrder;
use crate::geom::{Hit, Ray};

/// Rays ahead in the planned order whose data is asked for before their turn.
const AHEAD: usize = 8;

impl<const K: usize> WideBvh<K> {
    /// The closest hit of each ray, `out[i]` for `rays[i]`, exactly as
    /// [`WideBvh::closest_hit`] gives it; a large incoherent batch is traced in the order
    /// `order` plans (its scratch is reused between calls).
    ///
    /// # Panics
    /// When `out` and `rays` differ in length.
    pub fn closest_hit_batch(&self, rays: &[Ray], out: &mut [Option<Hit>], order: &mut RayOrder) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        match order.plan(rays, &self.bounds()) {
            Some(plan) => {
                for (j, &i) in plan.iter().enumerate() {
                    // The ray and its answer's slot a few rays ahead, scattered in memory.
                    if let Some(&a) = plan.get(j + AHEAD) {
                        crate::simd::prefetch_all(&rays[a as usize]);
                        crate::simd::prefetch(&out[a as usize]);
                    }
                    out[i as usize] = self.closest_hit(&rays[i as usize]);
                }
            }
            None => {
                for (o, r) in out.iter_mut().zip(rays) {
                    *o = self.closest_hit(r);
                }
            }
        }
    }

    /// Whether each ray hits anything, `out[i]` for `rays[i]`, as [`WideBvh::any_hit`] gives
    /// it, in the order `order` plans (see [`WideBvh::closest_hit_batch`]).
    ///
    /// # Panics
    /// When `out` and `rays` differ in length.
    pub fn any_hit_batch(&self, rays: &[Ray], out: &mut [bool], order: &mut RayOrder) {
        assert_eq!(rays.len(), out.len(), "one output per ray");
        match order.plan(rays, &self.bounds()) {
            Some(plan) => {
                for (j, &i) in plan.iter().enumerate() {
                    // The ray and its answer's slot a few rays ahead, scattered in memory.
                    if let Some(&a) = plan.get(j + AHEAD) {
                        crate::simd::prefetch_all(&rays[a as usize]);
                        crate::simd::prefetch(&out[a as usize]);
                    }
                    out[i as usize] = self.any_hit(&rays[i as usize]);
                }
            }
            None => {
                for (o, r) in out.iter_mut().zip(rays) {
                    *o = self.any_hit(r);
                }
            }
        }
    }
}
