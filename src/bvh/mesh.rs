//! A BVH over a triangle mesh, with the triangles copied in leaf order so that a leaf's
//! triangles are contiguous in memory for traversal.

use super::refit::LeafRefit;
use super::{BuildParams, BuildWorkspace, Bvh, Counters};
use crate::geom::{Aabb, Hit, Ray, RayTriPrecomp, TriMesh, intersect_triangle};
use glam::{Vec3, Vec3A};
use rayon::prelude::*;

/// Triangles gathered per chunk in parallel when refitting.
const GATHER_CHUNK: usize = 1 << 14;

/// A BVH over the triangles of a [`TriMesh`], ready for ray queries.
#[derive(Debug, Default)]
pub struct MeshBvh {
    pub(super) bvh: Bvh,
    /// `tris[slot]` is the triangle `bvh.prim_indices()[slot]`.
    pub(super) tris: Vec<[Vec3; 3]>,
    /// `leaf_indices[slot]` are that triangle's vertex indices: refit reads them in order
    /// instead of looking each triangle up through the mesh's index buffer.
    pub(super) leaf_indices: Vec<[u32; 3]>,
}

/// `clone_from` reuses the target's buffers (allocating only to grow).
impl Clone for MeshBvh {
    fn clone(&self) -> Self {
        Self {
            bvh: self.bvh.clone(),
            tris: self.tris.clone(),
            leaf_indices: self.leaf_indices.clone(),
        }
    }

    fn clone_from(&mut self, source: &Self) {
        self.bvh.clone_from(&source.bvh);
        self.tris.clone_from(&source.tris);
        self.leaf_indices.clone_from(&source.leaf_indices);
    }
}

impl MeshBvh {
    /// Builds a BVH over `mesh`'s triangles.
    ///
    /// # Panics
    /// When a triangle's vertex index is out of range (see [`TriMesh::check`]).
    #[must_use]
    pub fn build(mesh: &TriMesh, params: &BuildParams) -> Self {
        Self::build_indexed(&mesh.positions, &mesh.indices, params)
    }

    /// [`MeshBvh::build`] from positions and triangle indices held elsewhere (e.g. a pose
    /// buffer).
    ///
    /// # Panics
    /// When a vertex index is out of range.
    #[must_use]
    pub fn build_indexed(positions: &[Vec3], indices: &[[u32; 3]], params: &BuildParams) -> Self {
        let mut m = Self::default();
        m.rebuild_indexed(positions, indices, params, &mut BuildWorkspace::one_shot());
        m
    }

    /// The tree over the triangles alone, with no leaf-ordered copy of them (for a wide tree
    /// that copies them into its own blocks), built in `ws`.
    pub(crate) fn tree_only(
        positions: &[Vec3],
        indices: &[[u32; 3]],
        params: &BuildParams,
        ws: &mut BuildWorkspace,
    ) -> Bvh {
        let mut bvh = Bvh::empty(params.max_leaf_size);
        Indexed { positions, indices }
            .build_tree::<super::build::clip::ClipAware<'_>>(&mut bvh, None, params, ws);
        bvh
    }

    /// Rebuilds the tree for new positions (and possibly other triangles), reusing its storage
    /// and `ws`'s: once they have grown to the mesh's size, a binned or median rebuild allocates
    /// nothing.
    ///
    /// # Panics
    /// When a vertex index is out of range.
    pub fn rebuild_indexed(
        &mut self,
        positions: &[Vec3],
        indices: &[[u32; 3]],
        params: &BuildParams,
        ws: &mut BuildWorkspace,
    ) {
        self.rebuild_split::<super::build::clip::ClipAware<'_>>(
            positions, indices, None, params, ws,
        );
    }

    /// [`MeshBvh::rebuild_indexed`] with `splitter`, when given, in place of `params.method`'s.
    pub(super) fn rebuild_split<S: super::build::Splitter>(
        &mut self,
        positions: &[Vec3],
        indices: &[[u32; 3]],
        splitter: Option<&S>,
        params: &BuildParams,
        ws: &mut BuildWorkspace,
    ) {
        let mesh = Indexed { positions, indices };
        mesh.build_tree(&mut self.bvh, splitter, params, ws);
        // Vertex indices and triangles in leaf order, in one pass (every entry is written, so
        // old contents are kept: only growth initialises memory, and new storage comes zeroed
        // from the system rather than filled, so that a fresh build touches its pages once,
        // from every thread).
        super::build::grow_zeroed(&mut self.leaf_indices, mesh.len());
        super::build::grow_zeroed(&mut self.tris, mesh.len());
        self.leaf_indices.truncate(mesh.len());
        self.tris.truncate(mesh.len());
        let prims = self.bvh.prim_indices();
        let fill = |li: &mut [[u32; 3]], t: &mut [[Vec3; 3]], p: &[u32]| {
            for (li, &p) in li.iter_mut().zip(p) {
                *li = indices[p as usize];
            }
            gather_prefetched(li, positions, t);
        };
        if mesh.len() >= 2 * GATHER_CHUNK {
            self.leaf_indices
                .par_chunks_mut(GATHER_CHUNK)
                .zip(self.tris.par_chunks_mut(GATHER_CHUNK))
                .zip(prims.par_chunks(GATHER_CHUNK))
                .for_each(|((li, t), p)| fill(li, t, p));
        } else {
            fill(&mut self.leaf_indices, &mut self.tris, prims);
        }
    }

    /// Refits for new vertex positions of the same topology (same triangle count and indices).
    /// No allocation.
    ///
    /// # Panics
    /// When `mesh` has another triangle count than the mesh the tree was built for, or a vertex
    /// index is out of range.
    pub fn refit(&mut self, mesh: &TriMesh) {
        self.refit_indexed(&mesh.positions, &mesh.indices);
    }

    /// [`MeshBvh::refit`] from positions and triangle indices held elsewhere. No allocation.
    ///
    /// # Panics
    /// When the triangle count differs from the built one, or a vertex index is out of range.
    pub fn refit_indexed(&mut self, positions: &[Vec3], indices: &[[u32; 3]]) {
        assert_eq!(
            indices.len(),
            self.tris.len(),
            "refit needs the same triangles"
        );
        // The triangles' new vertices are copied into their slots (by subtrees on several
        // threads), then the leaves are bounded from the copies.
        self.bvh.refit_with(
            &mut self.tris,
            &GatherLeaf {
                leaf_indices: &self.leaf_indices,
                positions,
            },
        );
    }

    /// The underlying tree.
    #[must_use]
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// Reserves (without writing) the storage a rebuild over `like`'s triangles needs, with
    /// room for as many nodes as `like` has room for, so that [`MeshBvh::rebuild_indexed`] into
    /// this tree then allocates nothing: for a spare tree that rebuilds go into while another
    /// tree is kept. Returns the bytes reserved.
    pub fn reserve_like(&mut self, like: &MeshBvh) -> usize {
        fn to<T>(v: &mut Vec<T>, cap: usize) -> usize {
            if v.capacity() >= cap {
                return 0;
            }
            let before = v.capacity();
            v.reserve_exact(cap - v.len());
            (v.capacity() - before) * std::mem::size_of::<T>()
        }
        let n = like.tris.len();
        to(&mut self.bvh.nodes, like.bvh.nodes.capacity())
            + to(&mut self.bvh.prim_indices, n)
            + to(&mut self.tris, n)
            + to(&mut self.leaf_indices, n)
    }

    /// Reserves room for the most nodes any tree over its triangles can have (`2 n - 1`), so
    /// that operations that change the node count (a partial rebuild) allocate nothing.
    pub fn reserve_any_shape(&mut self) {
        let want = (2 * self.tris.len()).max(1);
        let nodes = &mut self.bvh.nodes;
        if nodes.capacity() < want {
            nodes.reserve_exact(want - nodes.len());
        }
    }

    /// Bytes held: nodes, primitive indices, and the leaf-ordered triangles and vertex indices.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        self.bvh.memory_bytes()
            + std::mem::size_of_val(self.tris.as_slice())
            + std::mem::size_of_val(self.leaf_indices.as_slice())
    }

    /// [`MeshBvh::memory_bytes`] with the room reserved for rebuilds of another shape.
    #[must_use]
    pub fn storage_bytes(&self) -> usize {
        use crate::bvh::held;
        self.bvh.storage_bytes() + held(&self.tris) + held(&self.leaf_indices)
    }

    /// The closest hit along `ray` in `[ray.tmin, ray.tmax)`.
    #[must_use]
    #[inline]
    pub fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        self.closest_hit_counted(ray, &mut ())
    }

    /// [`MeshBvh::closest_hit`], counting nodes visited and triangles tested.
    #[must_use]
    #[inline]
    pub fn closest_hit_counted<C: Counters>(&self, ray: &Ray, counters: &mut C) -> Option<Hit> {
        let pre = RayTriPrecomp::new(ray.dir);
        let mut uv = (0.0, 0.0);
        let tris = self.tris.as_slice();
        let test = |slot: usize, tmax| {
            let [a, b, c] = tris[slot];
            let (t, u, v) = intersect_triangle(ray, &pre, a, b, c, tmax)?;
            uv = (u, v);
            Some(t)
        };
        let (slot, t) = if C::TRIANGLES {
            let mut with = WithTriangles { counters, tris };
            self.bvh.closest_slot(ray, test, &mut with)
        } else {
            self.bvh.closest_slot(ray, test, counters)
        }?;
        Some(Hit {
            t,
            u: uv.0,
            v: uv.1,
            prim: self.bvh.prim_indices()[slot],
        })
    }

    /// True when anything is hit along `ray` in `[ray.tmin, ray.tmax)`.
    #[must_use]
    #[inline]
    pub fn any_hit(&self, ray: &Ray) -> bool {
        self.any_hit_counted(ray, &mut ())
    }

    /// [`MeshBvh::any_hit`], counting nodes visited and triangles tested.
    #[must_use]
    #[inline]
    pub fn any_hit_counted(&self, ray: &Ray, counters: &mut impl Counters) -> bool {
        let pre = RayTriPrecomp::new(ray.dir);
        let tris = self.tris.as_slice();
        self.bvh
            .any_slot(
                ray,
                |slot, tmax| {
                    let [a, b, c] = tris[slot];
                    intersect_triangle(ray, &pre, a, b, c, tmax).map(|h| h.0)
                },
                counters,
            )
            .is_some()
    }
}

/// Borrowed positions and triangle indices.
pub(super) struct Indexed<'a> {
    pub(super) positions: &'a [Vec3],
    pub(super) indices: &'a [[u32; 3]],
}

impl Indexed<'_> {
    pub(super) fn len(&self) -> usize {
        self.indices.len()
    }

    /// Rebuilds `bvh` over these triangles (with `splitter` when given), each bounded where
    /// the builder makes its reference.
    fn build_tree<S: super::build::Splitter>(
        &self,
        bvh: &mut Bvh,
        splitter: Option<&S>,
        params: &BuildParams,
        ws: &mut BuildWorkspace,
    ) {
        bvh.rebuild_split(
            self.len(),
            |refs, base| super::build::refs_from_corners(refs, base, |i| self.triangle_corners(i)),
            splitter,
            params,
            ws,
        );
    }

    #[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
    #[inline]
    fn triangle(&self, i: usize) -> [Vec3; 3] {
        self.indices[i].map(|v| self.positions[v as usize])
    }

    /// The corners of [`Aabb::of_triangle`] before sanitizing (the builder sanitizes): with
    /// SSE `min`/`max`, which return their second operand when either is NaN, a NaN coordinate
    /// is skipped as `of_triangle` skips it, and an axis with no number at all comes out
    /// `+inf .. -inf` (sanitized as the empty axis `of_triangle` gives). Other targets take
    /// `of_triangle` itself.
    #[inline]
    pub(super) fn triangle_corners(&self, i: usize) -> (Vec3A, Vec3A) {
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        {
            let [a, b, c] = self.indices[i];
            let (a, b, c) = (
                Vec3A::from(self.positions[a as usize]),
                Vec3A::from(self.positions[b as usize]),
                Vec3A::from(self.positions[c as usize]),
            );
            (
                c.min(b.min(a.min(Vec3A::INFINITY))),
                c.max(b.max(a.max(Vec3A::NEG_INFINITY))),
            )
        }
        #[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
        {
            let b = Aabb::of_triangle(&self.triangle(i));
            (b.min.into(), b.max.into())
        }
    }
}

/// Refits by copying the triangles' moved vertices into their slots, then bounding each leaf's.
struct GatherLeaf<'a> {
    leaf_indices: &'a [[u32; 3]],
    positions: &'a [Vec3],
}

impl LeafRefit<[Vec3; 3]> for GatherLeaf<'_> {
    #[inline]
    fn update(&self, tris: &mut [[Vec3; 3]], first: u32) {
        let first = first as usize;
        let idx = &self.leaf_indices[first..first + tris.len()];
        gather_prefetched(idx, self.positions, tris);
    }

    #[inline(always)]
    fn leaf(&self, tris: &[[Vec3; 3]], _: u32, _: u32) -> Aabb {
        bound_tris(tris)
    }
}

/// How many triangles ahead [`gather_prefetched`] asks for vertex positions.
const PREFETCH_TRIS: usize = 128;

/// Copies each triangle into its leaf slot. Its vertices are scattered through `positions`
/// (in leaf order), so the vertices of the triangle [`PREFETCH_TRIS`] slots ahead are asked for
/// at each slot, so that many loads are in flight at once (the build's copy into leaf order
/// uses it too).
fn gather_prefetched(leaf_indices: &[[u32; 3]], positions: &[Vec3], tris: &mut [[Vec3; 3]]) {
    let ask = |idx: &[u32; 3]| {
        for &v in idx {
            if let Some(p) = positions.get(v as usize) {
                crate::simd::prefetch(p);
            }
        }
    };
    leaf_indices.iter().take(PREFETCH_TRIS).for_each(ask);
    for (k, (t, &[a, b, c])) in tris.iter_mut().zip(leaf_indices).enumerate() {
        if let Some(idx) = leaf_indices.get(k + PREFETCH_TRIS) {
            ask(idx);
        }
        *t = [
            positions[a as usize],
            positions[b as usize],
            positions[c as usize],
        ];
    }
}

/// The box of some triangles (at least one), the same box as the union of
/// [`Aabb::of_triangle`] over them.
#[inline(always)]
fn bound_tris(tris: &[[Vec3; 3]]) -> Aabb {
    // SSE `min`/`max` return their second operand when either is NaN, so `v.min(lo)` skips a
    // NaN coordinate exactly as `of_triangle` does; clamping the union to `±f32::MAX` then
    // matches its sanitizing (an axis with no number at all becomes `MAX .. -MAX`). Other
    // targets take the per-triangle path.
    #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
    {
        let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        let mut one = |[a, b, c]: [Vec3; 3]| {
            let (a, b, c) = (Vec3A::from(a), Vec3A::from(b), Vec3A::from(c));
            lo = c.min(b.min(a.min(lo)));
            hi = c.max(b.max(a.max(hi)));
        };
        // Most leaves hold one or two triangles: the first two (the first one twice in a
        // one-triangle leaf, which changes nothing) are done without a loop, whose exit would
        // be mispredicted at about every leaf.
        one(tris[0]);
        one(tris[usize::from(tris.len() > 1)]);
        tris.iter().skip(2).for_each(|&t| one(t));
        let m = Vec3A::splat(f32::MAX);
        Aabb::new(lo.clamp(-m, m).into(), hi.clamp(-m, m).into())
    }
    #[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
    {
        tris.iter()
            .fold(Aabb::EMPTY, |b, t| b.union(Aabb::of_triangle(t)))
    }
}

/// Closest hit by testing every triangle: the reference traversal is checked against.
#[must_use]
pub fn brute_force_closest(mesh: &TriMesh, ray: &Ray) -> Option<Hit> {
    let pre = RayTriPrecomp::new(ray.dir);
    let mut best: Option<Hit> = None;
    for i in 0..mesh.len() {
        let [a, b, c] = mesh.triangle(i);
        let tmax = best.map_or(ray.tmax, |h| h.t);
        if let Some((t, u, v)) = intersect_triangle(ray, &pre, a, b, c, tmax) {
            best = Some(Hit {
                t,
                u,
                v,
                prim: i as u32,
            });
        }
    }
    best
}

/// Any hit by testing every triangle.
#[must_use]
pub fn brute_force_any(mesh: &TriMesh, ray: &Ray) -> bool {
    let pre = RayTriPrecomp::new(ray.dir);
    (0..mesh.len()).any(|i| {
        let [a, b, c] = mesh.triangle(i);
        intersect_triangle(ray, &pre, a, b, c, ray.tmax).is_some()
    })
}

/// Counters that are also told each tested slot's triangle.
struct WithTriangles<'a, C> {
    counters: &'a mut C,
    tris: &'a [[Vec3; 3]],
}

impl<C: Counters> Counters for WithTriangles<'_, C> {
    #[inline(always)]
    fn node(&mut self) {
        self.counters.node();
    }
    #[inline(always)]
    fn prim(&mut self) {
        self.counters.prim();
    }
    #[inline(always)]
    fn slot(&mut self, slot: usize, tmax: f32) {
        self.counters.triangle(self.tris[slot], tmax);
    }
}
