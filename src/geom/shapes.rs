//! Procedural test meshes: a bumpy geodesic sphere of any size and its smooth deformation.

use super::TriMesh;
use glam::Vec3;

const ICO_VERTS: [[f32; 3]; 12] = {
    const T: f32 = 1.618_034;
    [
        [-1.0, T, 0.0],
        [1.0, T, 0.0],
        [-1.0, -T, 0.0],
        [1.0, -T, 0.0],
        [0.0, -1.0, T],
        [0.0, 1.0, T],
        [0.0, -1.0, -T],
        [0.0, 1.0, -T],
        [T, 0.0, -1.0],
        [T, 0.0, 1.0],
        [-T, 0.0, -1.0],
        [-T, 0.0, 1.0],
    ]
};

const ICO_FACES: [[usize; 3]; 20] = [
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

/// Radius of the bumpy sphere in direction `d`: smooth bumps plus finer ripples (about ±10%).
fn bump(d: Vec3) -> f32 {
    1.0 + 0.08 * (6.0 * d.x).sin() * (5.0 * d.y + 1.0).sin() * (7.0 * d.z + 2.0).sin()
        + 0.02 * (17.0 * d.x + 11.0 * d.y + 0.5).sin() * (13.0 * d.z - 7.0 * d.x).sin()
}

/// A geodesic sphere of about `triangles` triangles (`20 f²` for the nearest frequency `f`),
/// radius about 1, displaced by bumps. Vertices are shared between neighbouring triangles
/// within each of the 20 icosahedron faces.
#[must_use]
pub fn bumpy_sphere(triangles: usize) -> TriMesh {
    let f = ((triangles as f64 / 20.0).sqrt().round() as usize).max(1);
    let mut positions = Vec::new();
    let mut indices = Vec::with_capacity(20 * f * f);
    for face in ICO_FACES {
        let [a, b, c] = face.map(|i| Vec3::from(ICO_VERTS[i]));
        let base = positions.len() as u32;
        // Row i has f + 1 - i vertices.
        let index = |i: usize, j: usize| base + (i * (2 * f + 3 - i) / 2 + j) as u32;
        for i in 0..=f {
            for j in 0..=f - i {
                let q = a + (b - a) * (i as f32 / f as f32) + (c - a) * (j as f32 / f as f32);
                let d = q.normalize();
                positions.push(d * bump(d));
            }
        }
        for i in 0..f {
            for j in 0..f - i {
                indices.push([index(i, j), index(i + 1, j), index(i, j + 1)]);
                if i + j + 1 < f {
                    indices.push([index(i + 1, j), index(i + 1, j + 1), index(i, j + 1)]);
                }
            }
        }
    }
    TriMesh::new(positions, indices)
}

/// A closed unit icosphere: the icosahedron with each face split into four `subdiv` times,
/// vertices shared and projected onto the sphere. Every edge is shared by exactly two triangles.
#[must_use]
pub fn icosphere(subdiv: u32) -> TriMesh {
    let mut positions: Vec<Vec3> = ICO_VERTS
        .iter()
        .map(|p| Vec3::from(*p).normalize())
        .collect();
    let mut faces: Vec<[u32; 3]> = ICO_FACES.iter().map(|f| f.map(|i| i as u32)).collect();
    for _ in 0..subdiv {
        let mut mid = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, pos: &mut Vec<Vec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                pos.push(((pos[a as usize] + pos[b as usize]) * 0.5).normalize());
                pos.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = midpoint(a, b, &mut positions);
            let bc = midpoint(b, c, &mut positions);
            let ca = midpoint(c, a, &mut positions);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    TriMesh::new(positions, faces)
}

/// Moves every vertex by a smooth sine wave of amplitude `amplitude` times the largest extent
/// of the mesh's box, `phase` shifting the wave (animate it to deform over time).
pub fn sine_deform(rest: &[Vec3], out: &mut [Vec3], amplitude: f32, phase: f32) {
    let b = super::Aabb::from_points(rest);
    let ext = b.extent().max_element().max(f32::MIN_POSITIVE);
    let a = amplitude * ext;
    let w = std::f32::consts::TAU / ext;
    for (o, p) in out.iter_mut().zip(rest) {
        *o = *p
            + a * Vec3::new(
                (w * p.y + 0.3 + phase).sin(),
                (w * p.z + 1.1 + phase).sin(),
                (w * p.x + 2.0 + phase).sin(),
            );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_is_closed() {
        let m = icosphere(2);
        assert_eq!(m.len(), 20 * 16);
        let mut edges = std::collections::HashMap::new();
        for t in &m.indices {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        assert!(edges.values().all(|&n| n == 2));
    }

    #[test]
    fn sphere_has_the_asked_size_and_valid_indices() {
        let m = bumpy_sphere(20 * 10 * 10);
        assert_eq!(m.len(), 2000);
        m.check().unwrap();
        let r = m.positions.iter().map(|p| p.length());
        assert!(r.clone().all(|r| (0.85..1.15).contains(&r)));
    }
}
