//! proptest strategies shared by the property tests: meshes (triangle soups and connected
//! height fields) and rays (random, axis-parallel, starting inside the mesh's box, with
//! shortened ranges).

use dynbvh::geom::{Ray, TriMesh};
use glam::Vec3;
use proptest::collection::SizeRange;
use proptest::prelude::*;

pub fn coord() -> impl Strategy<Value = f32> {
    -10.0f32..10.0
}

pub fn vec3() -> impl Strategy<Value = Vec3> {
    (coord(), coord(), coord()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// A triangle soup of 1 to `max_tris - 1` triangles: unshared vertices anywhere in the cube.
pub fn soup(max_tris: usize) -> impl Strategy<Value = TriMesh> {
    prop::collection::vec([vec3(), vec3(), vec3()], 1..max_tris)
        .prop_map(|t| TriMesh::from_soup(&t))
}

/// A connected height-field mesh on a grid of 2 to `max_side - 1` vertices a side (shared
/// vertices and edges).
pub fn grid(max_side: usize) -> impl Strategy<Value = TriMesh> {
    (2usize..max_side, 2usize..max_side)
        .prop_flat_map(|(w, h)| (Just((w, h)), prop::collection::vec(-3.0f32..3.0, w * h)))
        .prop_map(|((w, h), heights)| {
            let positions = (0..w * h)
                .map(|i| Vec3::new((i % w) as f32, heights[i], (i / w) as f32))
                .collect();
            let mut indices = Vec::new();
            for y in 0..h - 1 {
                for x in 0..w - 1 {
                    let i = (y * w + x) as u32;
                    let (r, d) = (i + 1, i + w as u32);
                    indices.push([i, r, d + 1]);
                    indices.push([i, d + 1, d]);
                }
            }
            TriMesh::new(positions, indices)
        })
}

/// A soup or a grid.
pub fn mesh(max_tris: usize, max_side: usize) -> impl Strategy<Value = TriMesh> {
    prop_oneof![soup(max_tris), grid(max_side)]
}

/// A direction: random, or with one or two zero components (axis-parallel rays).
pub fn direction() -> impl Strategy<Value = Vec3> {
    prop_oneof![
        vec3().prop_filter("non-zero", |d| d.length() > 1e-3),
        (0usize..3, any::<bool>()).prop_map(|(a, neg)| {
            let mut d = Vec3::ZERO;
            d[a] = if neg { -1.0 } else { 1.0 };
            d
        }),
        (0usize..3, coord(), coord()).prop_filter_map("non-zero", |(a, u, v)| {
            let mut d = Vec3::new(u, v, u - v);
            d[a] = 0.0;
            (d.length() > 1e-3).then_some(d)
        }),
    ]
}

/// `len` rays: origins anywhere (inside the mesh's box too), mixed signs, axis-parallel
/// directions, some ending early, some starting late.
pub fn rays(len: impl Into<SizeRange>) -> impl Strategy<Value = Vec<Ray>> {
    prop::collection::vec(
        (
            vec3(),
            direction(),
            prop_oneof![Just(f32::INFINITY), 0.5f32..20.0],
            prop_oneof![Just(0.0f32), 0.0f32..2.0],
        ),
        len,
    )
    .prop_map(|v| {
        v.into_iter()
            .map(|(o, d, tmax, tmin)| Ray::with_range(o, d, tmin, tmax))
            .collect()
    })
}

/// A coherent packet: a pinhole camera's tile (common origin, directions in a narrow cone), or
/// parallel rays from a patch of origins (shadow rays toward a distant light); the camera
/// may sit inside the mesh's box. Some packets aim exactly along an axis.
pub fn coherent() -> impl Strategy<Value = Vec<Ray>> {
    (
        vec3(),
        direction(),
        0.0f32..0.3,
        1usize..=8,
        1usize..=8,
        any::<bool>(),
        prop_oneof![Just(f32::INFINITY), 2.0f32..30.0],
    )
        .prop_map(|(eye, fwd, spread, w, h, parallel, tmax)| {
            let fwd = fwd.normalize();
            let helper = if fwd.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
            let right = fwd.cross(helper).normalize();
            let up = right.cross(fwd);
            let mut rays = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    let sx = (x as f32 / w as f32 - 0.5) * spread;
                    let sy = (y as f32 / h as f32 - 0.5) * spread;
                    rays.push(if parallel {
                        // Origins on a patch 4 units wide, one direction.
                        let o = eye + (right * sx + up * sy) * (4.0 / spread.max(1e-3));
                        Ray::with_range(o, fwd, 0.0, tmax)
                    } else {
                        Ray::with_range(eye, fwd + right * sx + up * sy, 0.0, tmax)
                    });
                }
            }
            rays
        })
}
