use super::Aabb;
use glam::Vec3;

/// An indexed triangle mesh: shared vertex positions and one `[u32; 3]` per triangle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Vertex indices, three per triangle.
    pub indices: Vec<[u32; 3]>,
}

impl TriMesh {
    /// A mesh from positions and indices. Indices must be in range (see [`TriMesh::check`]).
    #[must_use]
    pub fn new(positions: Vec<Vec3>, indices: Vec<[u32; 3]>) -> Self {
        Self { positions, indices }
    }

    /// A mesh with three unshared vertices per triangle.
    #[must_use]
    pub fn from_soup(tris: &[[Vec3; 3]]) -> Self {
        let positions = tris.iter().flatten().copied().collect();
        let indices = (0..tris.len() as u32)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect();
        Self { positions, indices }
    }

    /// Number of triangles.
    #[must_use]
    pub fn len(&self) -> usize {
        self.indices.len()
    }

    /// True when there is no triangle.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.indices.is_empty()
    }

    /// The three corners of triangle `i`.
    ///
    /// # Panics
    /// When `i` or one of its vertex indices is out of range.
    #[must_use]
    #[inline]
    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.indices[i];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// The bounding box of triangle `i`, as trees store it ([`Aabb::of_triangle`]).
    #[must_use]
    #[inline]
    pub fn triangle_bounds(&self, i: usize) -> Aabb {
        Aabb::of_triangle(&self.triangle(i))
    }

    /// The bounding box of all vertices that triangles use.
    #[must_use]
    pub fn bounds(&self) -> Aabb {
        (0..self.len()).fold(Aabb::EMPTY, |b, i| b.union(self.triangle_bounds(i)))
    }

    /// Checks that every index is in range; the message names the first bad triangle.
    pub fn check(&self) -> Result<(), String> {
        let n = self.positions.len();
        match self
            .indices
            .iter()
            .position(|t| t.iter().any(|&i| i as usize >= n))
        {
            Some(i) => Err(format!(
                "triangle {i} has indices {:?} but there are {n} vertices",
                self.indices[i]
            )),
            None => Ok(()),
        }
    }
}
