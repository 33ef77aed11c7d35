//! Masks and filters, and what a hit tells besides its distance. Each instance has a 32-bit
//! visibility mask; a query sees an instance when its own mask shares a bit with it (as in
//! Embree's `rtcSetGeometryMask` and OptiX's visibility masks), and may name one instance to
//! pass through (the sensor's own body, a viewer's own car). The check is made at the
//! top-level leaf, before the ray enters the instance's tree, so a filtered-out instance costs
//! one test.

use super::{Engine, InstanceId, MeshId, SceneHit};
use crate::engine::ray_work::Query;
use crate::geom::Ray;
use glam::Vec3;
use std::time::Instant;

/// Which instances a query sees: those whose mask shares a bit with `mask`, except `exclude`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueryFilter {
    /// ANDed with each instance's mask ([`Engine::set_instance_mask`]); zero sees nothing.
    pub mask: u32,
    /// One instance the query passes through.
    pub exclude: Option<InstanceId>,
}

impl QueryFilter {
    /// Every instance (whatever its mask, unless the mask is zero).
    pub const ALL: Self = Self {
        mask: u32::MAX,
        exclude: None,
    };

    /// The instances whose mask shares a bit with `mask`.
    #[must_use]
    pub const fn mask(mask: u32) -> Self {
        Self {
            mask,
            exclude: None,
        }
    }

    /// This filter, passing through `instance` too.
    #[must_use]
    pub const fn excluding(self, instance: InstanceId) -> Self {
        Self {
            exclude: Some(instance),
            ..self
        }
    }

    /// True when the instance with index `k` and mask `mask` is seen.
    #[inline(always)]
    pub(crate) fn admits(&self, k: u32, mask: u32) -> bool {
        mask & self.mask != 0 && self.exclude != Some(InstanceId(k))
    }
}

impl Default for QueryFilter {
    fn default() -> Self {
        Self::ALL
    }
}

/// A hit with its surface: world-space position and geometric normal, and which mesh,
/// instance and triangle it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitDetail {
    /// Distance along the ray, in units of its direction.
    pub t: f32,
    /// The hit point in world space (the triangle's world vertices weighted by the
    /// barycentrics).
    pub position: Vec3,
    /// The triangle's unit normal in world space, `(b - a) x (c - a)` of its world vertices (by
    /// its winding, not turned towards the ray); zero for a degenerate triangle.
    pub normal: Vec3,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
    /// Triangle index within the mesh.
    pub prim: u32,
    /// The mesh hit.
    pub mesh: MeshId,
    /// The instance hit.
    pub instance: InstanceId,
}

impl Engine {
    /// Sets the visibility mask of an instance (all bits set when it is added): queries whose
    /// [`QueryFilter::mask`] shares no bit with it pass through it.
    pub fn set_instance_mask(&mut self, i: InstanceId, mask: u32) {
        self.instances[i.0 as usize].mask = mask;
    }

    /// The visibility mask of an instance.
    #[must_use]
    pub fn instance_mask(&self, i: InstanceId) -> u32 {
        self.instances[i.0 as usize].mask
    }

    /// [`Engine::closest_hit`] among the instances `filter` admits.
    #[must_use]
    #[inline]
    pub fn closest_hit_filtered(&self, ray: &Ray, filter: &QueryFilter) -> Option<SceneHit> {
        self.closest_impl(ray, filter, &mut (), &mut ())
    }

    /// [`Engine::any_hit`] among the instances `filter` admits.
    #[must_use]
    #[inline]
    pub fn any_hit_filtered(&self, ray: &Ray, filter: &QueryFilter) -> bool {
        self.any_impl(ray, filter, &mut (), &mut ())
    }

    /// Any-hit answers of `queries` (each a ray and its own filter), in parallel, recorded as
    /// this frame's trace as [`Engine::trace_any`] records (the ray-work sample traces the rays
    /// unfiltered). Returns the trace time in ms.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn trace_any_filtered(&mut self, queries: &[(Ray, QueryFilter)], out: &mut [bool]) -> f64 {
        assert_eq!(queries.len(), out.len(), "one output per query");
        let t = Instant::now();
        crate::parallel::map(queries, out, super::RAY_CHUNK, |(r, f)| {
            self.any_hit_filtered(r, f)
        });
        let ms = super::ms_since(t);
        self.record_trace(ms, queries.len() as u64);
        if !self.sample_scratch_is_needed() {
            return ms;
        }
        // Sampled in pieces of the rays alone, so that no buffer of rays is needed.
        let mut rays = [Ray::new(Vec3::ZERO, Vec3::X); 64];
        for chunk in queries.chunks(rays.len()) {
            for (r, (q, _)) in rays.iter_mut().zip(chunk) {
                *r = *q;
            }
            self.sample_timed(&rays[..chunk.len()], Query::Any);
        }
        ms
    }

    /// The surface of a hit of [`Engine::closest_hit`] (or of any query returning a
    /// [`SceneHit`]) on this engine as last updated.
    #[must_use]
    pub fn hit_detail(&self, hit: &SceneHit) -> HitDetail {
        let inst = &self.instances[hit.instance.0 as usize];
        let m = &self.meshes[inst.mesh as usize];
        let [a, b, c] = m.indices[hit.prim as usize].map(|i| {
            let p = m.positions[i as usize];
            if inst.identity {
                p
            } else {
                inst.transform.transform_point3(p)
            }
        });
        let position = a * (1.0 - hit.u - hit.v) + b * hit.u + c * hit.v;
        let normal = (b - a).cross(c - a).normalize_or_zero();
        HitDetail {
            t: hit.t,
            position,
            normal,
            u: hit.u,
            v: hit.v,
            prim: hit.prim,
            mesh: MeshId(inst.mesh),
            instance: hit.instance,
        }
    }

    /// False when the ray-work sample would take nothing this frame (no mesh moved).
    fn sample_scratch_is_needed(&self) -> bool {
        self.meshes.iter().any(|m| m.moved)
    }
}
