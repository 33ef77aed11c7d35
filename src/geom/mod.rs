//! Geometry: boxes, rays, triangles and indexed triangle meshes.

mod aabb;
mod framing;
mod mesh;
mod proximity;
mod ray;
pub mod shapes;
mod triangle;

pub use aabb::Aabb;
pub use framing::framing_bounds;
pub use mesh::TriMesh;
pub use proximity::{box_distance_squared, closest_point_on_triangle, triangle_overlaps_box};
pub(crate) use ray::FAR_SCALE;
pub use ray::{Hit, Ray};
pub use triangle::{RayTriPrecomp, intersect_triangle};
