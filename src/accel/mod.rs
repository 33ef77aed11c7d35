//! The course's other acceleration structures, side by side with the BVH: the kd-tree (SAH,
//! built in O(N log N) by Wald & Havran 2006, and naively), the bounding interval hierarchy
//! (Wächter & Keller 2006), the uniform grid (3D-DDA, Amanatides & Woo 1987), the two-level grid
//! (a uniform grid of uniform grids, Jevans & Wyvill 1989) and the octree.
//!
//! Every structure offers the same [`Accel`] interface (closest hit, any hit, counted variants,
//! `validate`, memory), so benchmarks and tests treat them alike and a new structure is one
//! file plus its tests. All of them test triangles with the crate's watertight test and return
//! exactly what brute force returns: the hit of smallest `t`, which may be found in a cell
//! that is not the first one the ray crosses (space partitions hold a triangle in every cell
//! it overlaps), so a traversal stops only once the best hit lies before every cell still to
//! visit (see `interval.rs`).

mod bih;
mod bvh;
mod grid;
mod grid2;
mod interval;
mod kdtree;
mod kind;
mod mailbox;
mod octree;
mod triangles;

pub use bih::{Bih, BihParams};
pub use grid::{Grid, GridParams};
pub use grid2::{Grid2, Grid2Params};
pub use kdtree::{KdBuild, KdParams, KdTree, MAX_KD_DEPTH};
pub use kind::AccelKind;
pub use octree::{MAX_OCTREE_DEPTH, Octree, OctreeParams};

use crate::bvh::TraversalStats;
use crate::geom::{Hit, Ray, TriMesh};

/// What every acceleration structure offers. Queries cover `[ray.tmin, ray.tmax)`.
pub trait Accel: Send + Sync {
    /// The structure's short name (`kdtree`, `bih`, ...).
    fn name(&self) -> String;

    /// The closest hit along `ray`.
    fn closest_hit(&self, ray: &Ray) -> Option<Hit>;

    /// True when anything is hit along `ray`.
    fn any_hit(&self, ray: &Ray) -> bool;

    /// [`Accel::closest_hit`], adding the nodes (or cells) visited and triangles tested.
    fn closest_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> Option<Hit>;

    /// [`Accel::any_hit`], adding the nodes (or cells) visited and triangles tested.
    fn any_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> bool;

    /// Checks the structure's invariants against the mesh it was built (or refitted) for; the
    /// message names the first broken one.
    fn validate(&self, mesh: &TriMesh) -> Result<(), String>;

    /// Bytes held by the structure (nodes or cells, references, triangles).
    fn memory_bytes(&self) -> usize;

    /// Nodes (tree structures) or cells (grids).
    fn nodes(&self) -> usize;

    /// Depth of the deepest leaf (0 for a grid).
    fn depth(&self) -> usize;

    /// SAH cost with both constants 1, normalised by the root's area, where it is defined.
    fn sah(&self) -> Option<f32> {
        None
    }

    /// Updates the structure for new vertex positions of the same triangles without changing
    /// its topology; returns false when the structure cannot be refitted (it must be rebuilt).
    fn refit(&mut self, _mesh: &TriMesh) -> bool {
        false
    }
}
