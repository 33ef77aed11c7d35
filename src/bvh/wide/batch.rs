//! Batches of rays through the wide tree, in parallel, incoherent batches reordered first
//! ([`RayBatch`]) so that rays that travel close together are traced one after the other.

use super::WideBvh;
use crate::bvh::ray_order::RayBatch;
use crate::geom::{Hit, Ray};

impl<const K: usize> WideBvh<K> {
    /// The closest hit of each ray, `out[i]` for `rays[i]`, exactly as
    /// [`WideBvh::closest_hit`] gives it, on the current rayon pool's threads; a large
    /// incoherent batch is traced in the order `batch` plans (its scratch is reused between
    /// calls).
    ///
    /// # Panics
    /// When `out` and `rays` differ in length.
    pub fn closest_hit_batch(&self, rays: &[Ray], out: &mut [Option<Hit>], batch: &mut RayBatch) {
        batch.run(rays, &self.bounds(), out, |r| self.closest_hit(r));
    }

    /// Whether each ray hits anything, `out[i]` for `rays[i]`, as [`WideBvh::any_hit`] gives
    /// it (see [`WideBvh::closest_hit_batch`]).
    ///
    /// # Panics
    /// When `out` and `rays` differ in length.
    pub fn any_hit_batch(&self, rays: &[Ray], out: &mut [bool], batch: &mut RayBatch) {
        batch.run(rays, &self.bounds(), out, |r| self.any_hit(r));
    }
}
