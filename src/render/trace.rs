//! What the renderer asks of a scene: the closest surface along a ray (with its normals) and
//! whether anything blocks a ray. Two answers: the engine's two-level trees, and brute force
//! over a flat triangle list (the reference the engine's pictures are checked against).

use crate::bvh::{MAX_PACKET, TraversalStats};
use crate::engine::{Engine, MeshId, SceneHit};
use crate::geom::{Ray, RayTriPrecomp, TriMesh, intersect_triangle};
use glam::{Mat3A, Vec3, Vec3A};
use std::ops::Range;

/// A ray's closest surface, as shading needs it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Distance along the ray.
    pub t: f32,
    /// Geometric normal in world space (not normalised; either side).
    pub geometric: Vec3,
    /// Shading normal in world space: interpolated vertex normals, or the geometric normal
    /// (not normalised; either side).
    pub shading: Vec3,
    /// Instance hit (picks the material colour).
    pub instance: u32,
}

/// A scene rays can be cast into.
pub trait Tracer: Sync {
    /// The closest surface along `ray` in `[ray.tmin, ray.tmax)`; with `work`, adds the nodes
    /// visited and triangles tested.
    fn closest(
        &self,
        ray: &Ray,
        smooth: bool,
        work: Option<&mut TraversalStats>,
    ) -> Option<Surface>;
    /// True when something lies along `ray` in `[ray.tmin, ray.tmax)`.
    fn occluded(&self, ray: &Ray, work: Option<&mut TraversalStats>) -> bool;

    /// [`Tracer::closest`] of many rays (`out[i]` for `rays[i]`), coherent ones next to each
    /// other: a tracer may trace them as packets. The same answers as one by one.
    fn closest_batch(&self, rays: &[Ray], smooth: bool, out: &mut [Option<Surface>]) {
        for (r, o) in rays.iter().zip(out) {
            *o = self.closest(r, smooth, None);
        }
    }

    /// [`Tracer::occluded`] of many rays, as [`Tracer::closest_batch`].
    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        for (r, o) in rays.iter().zip(out) {
            *o = self.occluded(r, None);
        }
    }
}

/// Area-weighted vertex normals of the triangles, unit length (zero for vertices of no
/// non-degenerate triangle), written into `out` (resized; no allocation once it is large
/// enough).
pub fn vertex_normals(positions: &[Vec3], indices: &[[u32; 3]], out: &mut Vec<Vec3>) {
    out.clear();
    out.resize(positions.len(), Vec3::ZERO);
    for t in indices {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        // The cross product's length is twice the area: the weighting comes for free.
        let n = (b - a).cross(c - a);
        if n.is_finite() {
            for &i in t {
                out[i as usize] += n;
            }
        }
    }
    for n in out.iter_mut() {
        *n = unit_or_zero(*n);
    }
}

/// `v` scaled to unit length, or zero when it is zero or not finite. Divided by its largest
/// component first, so that the squared length neither overflows (a cross product of edges
/// 1e15 long is 1e30) nor underflows (edges 1e-10 long give 1e-20).
#[must_use]
#[inline]
pub fn unit_or_zero(v: Vec3) -> Vec3 {
    let m = v.abs().max_element();
    if m > 0.0 && m.is_finite() {
        (v / m).normalize_or_zero()
    } else {
        Vec3::ZERO
    }
}

/// Geometric and shading normals of triangle `tri` at barycentrics `(u, v)` in its own space.
#[inline]
fn local_normals(
    positions: &[Vec3],
    normals: &[Vec3],
    tri: [u32; 3],
    u: f32,
    v: f32,
    smooth: bool,
) -> (Vec3, Vec3) {
    let [i0, i1, i2] = tri.map(|i| i as usize);
    let (p0, p1, p2) = (positions[i0], positions[i1], positions[i2]);
    let ng = (p1 - p0).cross(p2 - p0);
    let ns = if smooth {
        let n = normals[i0] * (1.0 - u - v) + normals[i1] * u + normals[i2] * v;
        if n.length_squared() > 0.0 { n } else { ng }
    } else {
        ng
    };
    (ng, ns)
}

/// Per-mesh vertex normals and per-instance normal matrices of an [`Engine`], kept up to date
/// frame by frame in reused buffers.
#[derive(Default)]
pub struct EngineShading {
    normals: Vec<Vec<Vec3>>,
    /// Inverse transpose of each instance's linear part; `None` for the identity.
    normal_mats: Vec<Option<Mat3A>>,
}

impl EngineShading {
    /// Nothing computed yet; call [`EngineShading::refresh_all`].
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Recomputes the normals of every mesh (after a build) and the instance matrices.
    pub fn refresh_all(&mut self, engine: &Engine) {
        self.normals.resize_with(engine.mesh_count(), Vec::new);
        for m in 0..engine.mesh_count() {
            let id = MeshId(m as u32);
            vertex_normals(
                engine.positions(id),
                engine.indices(id),
                &mut self.normals[m],
            );
        }
        self.refresh_instances(engine);
    }

    /// Recomputes the normals of `meshes` (the ones written this frame) and the instance
    /// matrices.
    pub fn refresh(&mut self, engine: &Engine, meshes: &[MeshId]) {
        if self.normals.len() != engine.mesh_count() {
            self.refresh_all(engine);
            return;
        }
        for &id in meshes {
            vertex_normals(
                engine.positions(id),
                engine.indices(id),
                &mut self.normals[id.0 as usize],
            );
        }
        self.refresh_instances(engine);
    }

    fn refresh_instances(&mut self, engine: &Engine) {
        self.normal_mats.clear();
        for i in 0..engine.instance_count() {
            let m = engine
                .transform(crate::engine::InstanceId(i as u32))
                .matrix3;
            self.normal_mats.push(if m == Mat3A::IDENTITY {
                None
            } else {
                // Only the normals' directions matter: the matrix divided by its largest entry
                // has the same inverse transpose up to a factor, and a determinant that does
                // not overflow or underflow at scales of 1e15 or 1e-10.
                let big = m.abs().to_cols_array().into_iter().fold(0.0f32, f32::max);
                let m = if big > 0.0 && big.is_finite() {
                    m * (1.0 / big)
                } else {
                    m
                };
                let det = m.determinant();
                (det != 0.0 && det.is_finite()).then(|| m.inverse().transpose())
            });
        }
    }

    /// A tracer over `engine` with these normals (refreshed for the engine's current pose).
    #[must_use]
    pub fn tracer<'a>(&'a self, engine: &'a Engine) -> EngineTracer<'a> {
        EngineTracer {
            engine,
            shading: self,
            packets: PacketUse::DEFAULT,
        }
    }
}

/// [`Tracer`] over an [`Engine`]'s two-level trees.
pub struct EngineTracer<'a> {
    engine: &'a Engine,
    shading: &'a EngineShading,
    packets: PacketUse,
}

impl Tracer for EngineTracer<'_> {
    #[inline]
    fn closest(
        &self,
        ray: &Ray,
        smooth: bool,
        work: Option<&mut TraversalStats>,
    ) -> Option<Surface> {
        let h = match work {
            Some(w) => self.engine.closest_hit_counted(ray, w),
            None => self.engine.closest_hit(ray),
        }?;
        Some(self.surface(&h, smooth))
    }

    #[inline]
    fn occluded(&self, ray: &Ray, work: Option<&mut TraversalStats>) -> bool {
        match work {
            Some(w) => self.engine.any_hit_counted(ray, w),
            None => self.engine.any_hit(ray),
        }
    }

    fn closest_batch(&self, rays: &[Ray], smooth: bool, out: &mut [Option<Surface>]) {
        if !self.packets.primary {
            for (r, o) in rays.iter().zip(out) {
                *o = self.closest(r, smooth, None);
            }
            return;
        }
        let mut hits = [None; MAX_PACKET];
        for (r, o) in rays.chunks(MAX_PACKET).zip(out.chunks_mut(MAX_PACKET)) {
            let hits = &mut hits[..r.len()];
            self.engine.closest_hit_packet(r, hits);
            for (h, o) in hits.iter().zip(o) {
                *o = h.map(|h| self.surface(&h, smooth));
            }
        }
    }

    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        if self.packets.shadow {
            self.engine.any_hit_packet(rays, out);
        } else {
            for (r, o) in rays.iter().zip(out) {
                *o = self.engine.any_hit(r);
            }
        }
    }
}

impl EngineTracer<'_> {
    /// Which rays this tracer traces as packets in [`Tracer::closest_batch`] and
    /// [`Tracer::occluded_batch`] (default: [`PacketUse::DEFAULT`]).
    #[must_use]
    pub fn with_packets(mut self, packets: PacketUse) -> Self {
        self.packets = packets;
        self
    }

    /// The surface of a scene hit: normals from the hit triangle, moved to world space.
    #[inline]
    fn surface(&self, h: &SceneHit, smooth: bool) -> Surface {
        let e = self.engine;
        let mesh = e.instance_mesh(h.instance);
        let tri = e.indices(mesh)[h.prim as usize];
        let (ng, ns) = local_normals(
            e.positions(mesh),
            &self.shading.normals[mesh.0 as usize],
            tri,
            h.u,
            h.v,
            smooth,
        );
        let (geometric, shading) = match self
            .shading
            .normal_mats
            .get(h.instance.0 as usize)
            .copied()
            .flatten()
        {
            Some(m) => (
                Vec3::from(m * Vec3A::from(ng)),
                Vec3::from(m * Vec3A::from(ns)),
            ),
            None => (ng, ns),
        };
        Surface {
            t: h.t,
            geometric,
            shading,
            instance: h.instance.0,
        }
    }
}

/// Which rays an [`EngineTracer`] traces as packets (the rest one by one; the answers are the
/// same either way).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PacketUse {
    /// Camera rays.
    pub primary: bool,
    /// Shadow rays toward the key light.
    pub shadow: bool,
}

impl PacketUse {
    /// Packets for both, the faster choice (compare with `dynbvh render --bench`).
    pub const DEFAULT: PacketUse = PacketUse {
        primary: true,
        shadow: true,
    };
    /// Every ray one by one.
    pub const NONE: PacketUse = PacketUse {
        primary: false,
        shadow: false,
    };
}

impl Default for PacketUse {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl std::str::FromStr for PacketUse {
    type Err = String;

    /// `both`, `primary`, `shadow` or `none`: the rays traced as packets.
    fn from_str(s: &str) -> Result<Self, String> {
        let (primary, shadow) = match s.trim().to_ascii_lowercase().as_str() {
            "both" => (true, true),
            "primary" => (true, false),
            "shadow" => (false, true),
            "none" => (false, false),
            _ => return Err(format!("{s:?}: expected both, primary, shadow or none")),
        };
        Ok(PacketUse { primary, shadow })
    }
}

impl std::fmt::Display for PacketUse {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match (self.primary, self.shadow) {
            (true, true) => "both",
            (true, false) => "primary",
            (false, true) => "shadow",
            (false, false) => "none",
        })
    }
}

/// [`Tracer`] testing every triangle of a flat world-space mesh: slow, obviously right.
pub struct BruteForce<'a> {
    mesh: &'a TriMesh,
    normals: Vec<Vec3>,
    /// First triangle of each instance, ascending.
    instance_starts: Vec<usize>,
}

impl<'a> BruteForce<'a> {
    /// Over `mesh`, whose instances own the triangle ranges `instances` (as
    /// [`crate::anim::Scene::instance_triangle_ranges`] gives; empty: one instance).
    #[must_use]
    pub fn new(mesh: &'a TriMesh, instances: &[Range<usize>]) -> Self {
        let mut normals = Vec::new();
        vertex_normals(&mesh.positions, &mesh.indices, &mut normals);
        Self {
            mesh,
            normals,
            instance_starts: instances.iter().map(|r| r.start).collect(),
        }
    }
}

impl Tracer for BruteForce<'_> {
    fn closest(
        &self,
        ray: &Ray,
        smooth: bool,
        mut work: Option<&mut TraversalStats>,
    ) -> Option<Surface> {
        let pre = RayTriPrecomp::new(ray.dir);
        let mut best: Option<(f32, f32, f32, usize)> = None;
        for (i, t) in self.mesh.indices.iter().enumerate() {
            let [a, b, c] = t.map(|k| self.mesh.positions[k as usize]);
            let tmax = best.map_or(ray.tmax, |h| h.0);
            if let Some(w) = work.as_deref_mut() {
                w.prims += 1;
            }
            if let Some((t, u, v)) = intersect_triangle(ray, &pre, a, b, c, tmax) {
                best = Some((t, u, v, i));
            }
        }
        let (t, u, v, i) = best?;
        let (geometric, shading) = local_normals(
            &self.mesh.positions,
            &self.normals,
            self.mesh.indices[i],
            u,
            v,
            smooth,
        );
        let instance = self
            .instance_starts
            .partition_point(|&s| s <= i)
            .saturating_sub(1) as u32;
        Some(Surface {
            t,
            geometric,
            shading,
            instance,
        })
    }

    fn occluded(&self, ray: &Ray, work: Option<&mut TraversalStats>) -> bool {
        let pre = RayTriPrecomp::new(ray.dir);
        let mut tested = 0u64;
        let hit = self.mesh.indices.iter().any(|t| {
            tested += 1;
            let [a, b, c] = t.map(|k| self.mesh.positions[k as usize]);
            intersect_triangle(ray, &pre, a, b, c, ray.tmax).is_some()
        });
        if let Some(w) = work {
            w.prims += tested;
        }
        hit
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packet_use_names_round_trip() {
        for name in ["both", "primary", "shadow", "none"] {
            let p: PacketUse = name.parse().unwrap();
            assert_eq!(p.to_string(), name);
        }
        assert_eq!("both".parse::<PacketUse>(), Ok(PacketUse::DEFAULT));
        assert!("all".parse::<PacketUse>().is_err());
    }

    #[test]
    fn normals_of_a_tent_are_area_weighted() {
        // Two triangles sharing the edge 0-1; the bigger one dominates the shared vertices.
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(0.0, 3.0, 0.0),
        ];
        let idx = vec![[0, 1, 2], [0, 1, 3]];
        let mut n = Vec::new();
        vertex_normals(&p, &idx, &mut n);
        // Triangle 0: normal +y with twice-area 1; triangle 1: normal +z with twice-area 3.
        let expect = Vec3::new(0.0, 1.0, 3.0).normalize();
        assert!((n[0] - expect).length() < 1e-6);
        assert!((n[2] - Vec3::Y).length() < 1e-6);
        assert!((n[3] - Vec3::Z).length() < 1e-6);
    }
}
