//! dynbvh: ray tracing animated scenes.
//!
//! Each frame of an animated glTF scene dynbvh poses the meshes, refits their bounding volume
//! hierarchies, measures how far each tree's SAH cost has degraded, and rebuilds with binned SAH
//! when refitting no longer pays.
//!
//! ```
//! use dynbvh::bvh::{BuildParams, MeshBvh};
//! use dynbvh::geom::{Ray, TriMesh};
//! use glam::Vec3;
//!
//! // Two triangles of a unit quad in the z = 0 plane.
//! let mesh = TriMesh::new(
//!     vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
//!     vec![[0, 1, 2], [0, 2, 3]],
//! );
//! let mut bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
//! bvh.validate(&mesh).unwrap();
//! let ray = Ray::new(Vec3::new(0.25, 0.75, 1.0), -Vec3::Z);
//! let hit = bvh.closest_hit(&ray).unwrap();
//! assert_eq!((hit.t, hit.prim), (1.0, 1));
//!
//! // Move the quad and refit: same topology, new boxes.
//! let moved = TriMesh::new(mesh.positions.iter().map(|p| *p + Vec3::Z).collect(), mesh.indices.clone());
//! bvh.refit(&moved);
//! bvh.validate(&moved).unwrap();
//! assert_eq!(bvh.closest_hit(&ray).unwrap().t, 0.0);
//! ```

/// The README's library example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctest;

pub mod anim;
pub mod bvh;
pub mod cputime;
pub mod engine;
pub mod error;
pub mod geom;
pub mod io;
pub mod render;
pub mod report;
mod simd;

pub use error::{Error, Result};
