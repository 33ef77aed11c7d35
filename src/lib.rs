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
//!
//! # Using dynbvh from another crate
//!
//! The crate's public types are built on [`glam`] (vectors, affine transforms); it is re-exported
//! as `dynbvh::glam`, so a dependent uses that one instead of matching its version by hand:
//! `use dynbvh::glam::{Affine3A, Vec3};`. The two-level scene is [`engine::Engine`]; a glTF
//! file is loaded by [`anim::Scene::load`] and posed into an engine by
//! [`engine::gltf::GltfSource`] (see that module's quick start).
//!
//! **SIMD width.** The packet and wide-tree kernels use the `wide` crate, which picks AVX-512,
//! AVX2 or SSE vectors *at compile time* from the enabled target features. This repository's
//! `.cargo/config.toml` sets `-C target-cpu=native`, but Cargo reads configuration only from the
//! directory it is run in (and its parents, and `~/.cargo`), never from a dependency: a
//! dependent builds dynbvh for the baseline x86-64 target (SSE2) unless it asks for more. To get
//! the machine's width, put the same in the dependent's own `.cargo/config.toml`:
//!
//! ```toml
//! [build]
//! rustflags = ["-C", "target-cpu=native"]
//! ```
//!
//! or build with `RUSTFLAGS="-C target-cpu=native" cargo build --release` (for binaries shipped
//! to other machines, name a target instead, e.g. `-C target-cpu=x86-64-v3` for AVX2). Results
//! are the same at every width; only the speed differs.

pub use glam;

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
