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
//! The public types are built on [`glam`], re-exported as `dynbvh::glam` so that a dependent
//! need not match its version. The two-level scene is [`engine::Engine`]; a glTF file is loaded
//! by [`anim::Scene::load`] and posed into an engine by [`engine::gltf::GltfSource`] (see that
//! module's quick start). A simulator's frame: pose, update, query.
//!
//! ```
//! use dynbvh::engine::{Engine, EngineConfig, QueryFilter};
//! use dynbvh::geom::{Aabb, Ray, shapes};
//! use dynbvh::glam::{Affine3A, Vec3};
//!
//! let mut engine = Engine::new(EngineConfig::default());
//! let ball = shapes::icosphere(3);
//! let cloth = engine.add_mesh(ball.positions.clone(), ball.indices.clone()); // deforms
//! let rock = engine.add_mesh(ball.positions.clone(), ball.indices.clone()); // rigid
//! let me = engine.add_instance(rock, Affine3A::from_translation(Vec3::new(0.0, 0.0, 5.0)));
//! engine.add_instance(cloth, Affine3A::IDENTITY);
//! let rays: Vec<Ray> = (0..64)
//!     .map(|k| Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::new(k as f32 * 0.01 - 0.3, 0.1, -1.0)))
//!     .collect();
//! let mut hits = vec![None; rays.len()];
//! for frame in 0..3 {
//!     for p in engine.positions_mut(cloth) {
//!         *p *= 1.0 + 0.05 * frame as f32; // inflate the cloth
//!     }
//!     engine.set_transform(me, Affine3A::from_translation(Vec3::new(0.0, 0.1 * frame as f32, 5.0)));
//!     engine.update(); // refit or rebuild, as the policy decides
//!     engine.trace_closest(&rays, &mut hits); // a batch, timed for the policy
//! }
//! // From inside the rock, looking past it: exclude it.
//! let ray = Ray::new(Vec3::new(0.0, 0.1, 5.0), -Vec3::Z);
//! let hit = engine.closest_hit_filtered(&ray, &QueryFilter::ALL.excluding(me)).unwrap();
//! let detail = engine.hit_detail(&hit);
//! assert!(detail.position.z > 0.9 && detail.normal.z.abs() > 0.5);
//! let near = engine.closest_point(Vec3::new(0.0, 3.0, 0.0), f32::INFINITY).unwrap();
//! assert!(near.distance < 2.0);
//! let mut touched = Vec::new();
//! engine.overlap_box(Aabb::new(Vec3::splat(-0.2), Vec3::splat(0.2) + Vec3::Z * 2.0), &mut touched);
//! assert!(!touched.is_empty());
//! assert_eq!(engine.count_hits(&Ray::new(Vec3::new(0.0, 0.05, 0.0), Vec3::X)), 1); // inside
//! ```
//!
//! **SIMD width.** The packet and wide-tree kernels take their vector width from the target
//! features dynbvh is compiled with, and a dependent's build does not read this repository's
//! `-C target-cpu=native`: set it in the dependent's own `.cargo/config.toml` or `RUSTFLAGS`
//! (`docs/library.md`, "SIMD width"). Results are the same at every width; only speed differs.

pub use glam;

/// The README's library example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctest;

pub mod accel;
pub mod anim;
pub mod bvh;
pub mod cputime;
pub mod engine;
pub mod error;
pub mod geom;
pub mod io;
pub mod parallel;
pub mod render;
pub mod report;
mod simd;

pub use error::{Error, Result};
