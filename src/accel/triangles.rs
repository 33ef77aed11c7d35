//! The triangles a structure tests, copied out of the mesh, with the closest- and any-hit tests
//! the structures share (the watertight test of `geom::triangle`).

use crate::bvh::Counters;
use crate::geom::{Aabb, Hit, Ray, RayTriPrecomp, TriMesh, intersect_triangle};
use glam::Vec3;

/// Triangles by index, and the per-ray closest-hit state.
#[derive(Clone, Debug, Default)]
pub(super) struct Triangles {
    pub(super) tris: Vec<[Vec3; 3]>,
}

impl Triangles {
    /// The mesh's triangles in its order, on huge pages where the system gives them
    /// ([`crate::simd::reserve_huge`]: rays read them in random order).
    pub(super) fn of_mesh(mesh: &TriMesh) -> Self {
        let mut tris = Vec::new();
        crate::simd::reserve_huge(&mut tris, mesh.len(), 0);
        tris.extend((0..mesh.len()).map(|i| mesh.triangle(i)));
        Self { tris }
    }

    /// [`Triangles::of_mesh`], with the union of the triangles' boxes and how many have one,
    /// found in the same pass.
    pub(super) fn of_mesh_bounded(mesh: &TriMesh) -> (Self, Aabb, usize) {
        let mut tris = Vec::new();
        crate::simd::reserve_huge(&mut tris, mesh.len(), 0);
        let (mut bounds, mut n) = (Aabb::EMPTY, 0usize);
        tris.extend((0..mesh.len()).map(|i| {
            let t = mesh.triangle(i);
            let b = Aabb::of_triangle(&t);
            if !b.is_empty() {
                bounds = bounds.union(b);
                n += 1;
            }
            t
        }));
        (Self { tris }, bounds, n)
    }

    /// Each triangle's box as trees store it ([`Aabb::of_triangle`]).
    pub(super) fn boxes(&self) -> Vec<Aabb> {
        self.tris.iter().map(Aabb::of_triangle).collect()
    }

    /// Bytes held.
    pub(super) fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.tris.as_slice())
    }

    /// Checks that these are the mesh's triangles.
    pub(super) fn check(&self, mesh: &TriMesh) -> Result<(), String> {
        if self.tris.len() != mesh.len() {
            return Err(format!(
                "{} triangles stored, the mesh has {}",
                self.tris.len(),
                mesh.len()
            ));
        }
        match (0..mesh.len()).find(|&i| !same_triangle(&self.tris[i], &mesh.triangle(i))) {
            Some(i) => Err(format!("triangle {i} differs from the mesh's")),
            None => Ok(()),
        }
    }
}

/// Bitwise equality (so that NaN corners compare equal to themselves).
pub(super) fn same_triangle(a: &[Vec3; 3], b: &[Vec3; 3]) -> bool {
    a.iter()
        .zip(b)
        .all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits))
}

/// A ray's search for its closest hit.
pub(super) struct Closest<'r> {
    pub(super) ray: &'r Ray,
    pre: RayTriPrecomp,
    /// The best distance so far (`ray.tmax` before any hit).
    pub(super) tmax: f32,
    pub(super) hit: Option<Hit>,
}

impl<'r> Closest<'r> {
    #[inline(always)]
    pub(super) fn new(ray: &'r Ray) -> Self {
        Self {
            ray,
            pre: RayTriPrecomp::new(ray.dir),
            tmax: ray.tmax,
            hit: None,
        }
    }

    /// Tests triangle `prim` (whose corners are `tri`); keeps it when it is the closest yet.
    #[inline(always)]
    pub(super) fn test(&mut self, tri: &[Vec3; 3], prim: u32, c: &mut impl Counters) {
        c.prim();
        if let Some((t, u, v)) =
            intersect_triangle(self.ray, &self.pre, tri[0], tri[1], tri[2], self.tmax)
        {
            self.tmax = t;
            self.hit = Some(Hit { t, u, v, prim });
        }
    }
}

/// A ray's search for any hit.
pub(super) struct AnyHit<'r> {
    ray: &'r Ray,
    pre: RayTriPrecomp,
}

impl<'r> AnyHit<'r> {
    #[inline(always)]
    pub(super) fn new(ray: &'r Ray) -> Self {
        Self {
            ray,
            pre: RayTriPrecomp::new(ray.dir),
        }
    }

    /// True when the triangle is hit within the ray's range.
    #[inline(always)]
    pub(super) fn test(&self, tri: &[Vec3; 3], c: &mut impl Counters) -> bool {
        c.prim();
        intersect_triangle(self.ray, &self.pre, tri[0], tri[1], tri[2], self.ray.tmax).is_some()
    }
}

/// The box of all the boxes that hold a point (an empty box when none does).
pub(super) fn bounds_of(boxes: &[Aabb]) -> Aabb {
    boxes
        .iter()
        .filter(|b| !b.is_empty())
        .fold(Aabb::EMPTY, |a, b| a.union(*b))
}
