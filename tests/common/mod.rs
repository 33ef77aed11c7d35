//! Helpers shared by integration tests: brute-force comparison and test meshes.
#![allow(dead_code)]

use dynbvh::bvh::{MeshBvh, brute_force_any, brute_force_closest};
use dynbvh::geom::{Ray, RayTriPrecomp, TriMesh, intersect_triangle};
use glam::Vec3;

/// Compares one ray's closest and any hit through the tree with brute force. Ties (two
/// triangles at the same distance) may resolve to either triangle, but the distance must be
/// identical and the reported triangle must really be hit there.
pub fn check_ray(mesh: &TriMesh, bvh: &MeshBvh, ray: &Ray) -> Result<(), String> {
    let want = brute_force_closest(mesh, ray);
    let got = bvh.closest_hit(ray);
    match (want, got) {
        (None, None) => {}
        (Some(w), Some(g)) => {
            if w.t != g.t {
                return Err(format!(
                    "ray {ray:?}: brute force t {} prim {}, tree t {} prim {}",
                    w.t, w.prim, g.t, g.prim
                ));
            }
            if w.prim != g.prim {
                let [a, b, c] = mesh.triangle(g.prim as usize);
                let pre = RayTriPrecomp::new(ray.dir);
                let t = intersect_triangle(ray, &pre, a, b, c, f32::INFINITY).map(|h| h.0);
                if t != Some(g.t) {
                    return Err(format!(
                        "ray {ray:?}: tree reports prim {} at {} but it is hit at {t:?}",
                        g.prim, g.t
                    ));
                }
            }
        }
        (w, g) => return Err(format!("ray {ray:?}: brute force {w:?}, tree {g:?}")),
    }
    let (wa, ga) = (brute_force_any(mesh, ray), bvh.any_hit(ray));
    if wa != ga {
        return Err(format!("ray {ray:?}: any hit brute force {wa}, tree {ga}"));
    }
    Ok(())
}

/// A closed icosphere: the icosahedron with each face split `subdiv` times (shared vertices).
pub fn icosphere(subdiv: u32) -> TriMesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut pos: Vec<Vec3> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| Vec3::from(*p).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdiv {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::with_capacity(faces.len() * 4);
        let mut midpoint = |a: u32, b: u32, pos: &mut Vec<Vec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                pos.push(((pos[a as usize] + pos[b as usize]) * 0.5).normalize());
                pos.len() as u32 - 1
            })
        };
        for [a, b, c] in faces {
            let ab = midpoint(a, b, &mut pos);
            let bc = midpoint(b, c, &mut pos);
            let ca = midpoint(c, a, &mut pos);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    TriMesh::new(pos, faces)
}

/// Deterministic pseudo-random numbers (splitmix64) for non-proptest tests.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn f(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
    pub fn unit_vector(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f32::consts::TAU);
        let s = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(s * phi.cos(), s * phi.sin(), z)
    }
}
