//! The structures by name, as `build-bench --methods` and the tests know them.

use super::{
    Accel, Bih, BihParams, Grid, Grid2, Grid2Params, GridParams, KdParams, KdTree, Octree,
    OctreeParams,
};
use crate::geom::TriMesh;
use std::fmt;
use std::str::FromStr;

/// One of the structures of this module, with its build settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AccelKind {
    /// kd-tree, O(N log N) SAH build (`kdtree`).
    KdTree,
    /// kd-tree, naive O(N log² N) SAH build (`kdtree-naive`).
    KdTreeNaive,
    /// Bounding interval hierarchy (`bih`).
    Bih,
    /// Uniform grid with `λ N` cells (`grid`, or `gridL` for another `λ`, e.g. `grid4`).
    Grid(f32),
    /// Two-level grid (`grid2`).
    Grid2,
    /// Octree (`octree`).
    Octree,
}

impl AccelKind {
    /// Every structure with its default settings.
    pub const ALL: [AccelKind; 6] = [
        AccelKind::KdTree,
        AccelKind::KdTreeNaive,
        AccelKind::Bih,
        AccelKind::Grid(GridParams::DEFAULT_DENSITY),
        AccelKind::Grid2,
        AccelKind::Octree,
    ];

    /// Builds this structure over `mesh`.
    ///
    /// # Panics
    /// When a vertex index is out of range (see [`TriMesh::check`]).
    #[must_use]
    pub fn build(self, mesh: &TriMesh) -> Box<dyn Accel> {
        match self {
            AccelKind::KdTree => Box::new(KdTree::build(mesh, &KdParams::default())),
            AccelKind::KdTreeNaive => Box::new(KdTree::build(mesh, &KdParams::NAIVE)),
            AccelKind::Bih => Box::new(Bih::build(mesh, &BihParams::default())),
            AccelKind::Grid(density) => Box::new(Grid::build(
                mesh,
                &GridParams {
                    density,
                    ..GridParams::default()
                },
            )),
            AccelKind::Grid2 => Box::new(Grid2::build(mesh, &Grid2Params::default())),
            AccelKind::Octree => Box::new(Octree::build(mesh, &OctreeParams::default())),
        }
    }

    /// True for the structures refitted rather than rebuilt when the vertices move.
    #[must_use]
    pub fn refits(self) -> bool {
        self == AccelKind::Bih
    }
}

impl fmt::Display for AccelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AccelKind::KdTree => f.write_str("kdtree"),
            AccelKind::KdTreeNaive => f.write_str("kdtree-naive"),
            AccelKind::Bih => f.write_str("bih"),
            AccelKind::Grid(d) if *d == GridParams::DEFAULT_DENSITY => f.write_str("grid"),
            AccelKind::Grid(d) => write!(f, "grid{d}"),
            AccelKind::Grid2 => f.write_str("grid2"),
            AccelKind::Octree => f.write_str("octree"),
        }
    }
}

impl FromStr for AccelKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s {
            "kdtree" => AccelKind::KdTree,
            "kdtree-naive" => AccelKind::KdTreeNaive,
            "bih" => AccelKind::Bih,
            "grid" => AccelKind::Grid(GridParams::DEFAULT_DENSITY),
            "grid2" => AccelKind::Grid2,
            "octree" => AccelKind::Octree,
            _ => {
                let density = s
                    .strip_prefix("grid")
                    .and_then(|d| d.parse::<f32>().ok())
                    .filter(|d| (GridParams::MIN_DENSITY..=GridParams::MAX_DENSITY).contains(d))
                    .ok_or_else(|| {
                        format!(
                            "unknown structure {s:?}: kdtree, kdtree-naive, bih, grid, gridL \
                             (L from {} to {} cells per triangle), grid2, octree",
                            GridParams::MIN_DENSITY,
                            GridParams::MAX_DENSITY
                        )
                    })?;
                AccelKind::Grid(density)
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for k in AccelKind::ALL.into_iter().chain([AccelKind::Grid(4.0)]) {
            assert_eq!(k.to_string().parse::<AccelKind>(), Ok(k));
        }
        assert!("grid0".parse::<AccelKind>().is_err());
        assert!("gridnan".parse::<AccelKind>().is_err());
        assert!("bvh".parse::<AccelKind>().is_err());
    }
}
