//! The two-level grid (Jevans & Wyvill 1989; as built by Kalojanov, Billeter & Slusallek 2011,
//! "Two-Level Grids for Ray Tracing on GPUs"): a coarse uniform grid of about `λ₁ N` cells
//! whose every non-empty cell holds a uniform grid of its own, about `λ₂ n` cells for its `n`
//! triangles. A uniform grid spends its cells evenly over the scene's box, so on an uneven
//! scene (a large backdrop and small detail) the detail shares a few crowded cells; here each
//! top cell is as fine as its own triangles ask. A ray walks the top cells with the 3D-DDA and,
//! in each non-empty one, that cell's grid, with one mailbox for the whole walk, and stops once
//! its best hit lies before the next cell at either level.

use super::Accel;
use super::grid::{Grid, GridParams, Lattice, MAX_REFS_PER_TRIANGLE, resolution};
use super::mailbox::{CellWalk, cell_walk_queries};
use super::triangles::Triangles;
use crate::bvh::{Counters, TraversalStats};
use crate::geom::{Aabb, Hit, Ray, TriMesh};
use glam::Vec3;

/// How a two-level grid is built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid2Params {
    /// Top cells per triangle, `λ₁`.
    pub top_density: f32,
    /// Cells per triangle of a top cell's own grid, `λ₂`.
    pub leaf_density: f32,
    /// Most cells in all, at each level.
    pub max_cells: usize,
}

impl Default for Grid2Params {
    fn default() -> Self {
        Self {
            top_density: 1.0 / 16.0,
            leaf_density: 2.0,
            max_cells: 1 << 25,
        }
    }
}

/// Most cells a side of a top cell's grid.
const MAX_SUB_RES: u32 = 1024;

/// A top cell: where its grid's cells begin in [`Grid2::starts`] and its cells per axis (all
/// zero for an empty top cell).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct TopCell {
    first: u32,
    res: [u16; 3],
}

/// A two-level grid over a mesh's triangles.
#[derive(Clone, Debug, Default)]
pub struct Grid2 {
    bounds: Aabb,
    top: Lattice,
    /// The margin triangles were entered into the top cells with.
    margin: Vec3,
    /// Coordinates' scale, for the margins of the top cells' grids.
    scale: Vec3,
    /// One per top cell.
    cells: Vec<TopCell>,
    /// `refs[starts[k]..starts[k + 1]]`: the triangles of cell `k` of all the top cells' grids,
    /// laid one after the other.
    starts: Vec<u32>,
    refs: Vec<u32>,
    tris: Triangles,
}

impl Grid2 {
    /// Builds a two-level grid over `mesh`'s triangles; triangles without a box are left out.
    ///
    /// # Panics
    /// When a vertex index is out of range.
    #[must_use]
    pub fn build(mesh: &TriMesh, params: &Grid2Params) -> Self {
        let top = Grid::build(
            mesh,
            &GridParams {
                density: params.top_density,
                max_cells: params.max_cells,
            },
        );
        let scale = top.bounds.min.abs().max(top.bounds.max.abs());
        let mut g = Self {
            bounds: top.bounds,
            top: top.lattice,
            margin: top.margin,
            scale,
            ..Self::default()
        };
        if top.starts.is_empty() {
            g.tris = top.tris;
            return g;
        }
        let boxes: Vec<Aabb> = top.tris.tris.iter().map(Aabb::of_triangle).collect();
        let top_cells = top.lattice.cell_count();
        g.cells = vec![TopCell::default(); top_cells];
        let mut starts = Vec::new();
        crate::simd::reserve_huge(&mut starts, top.refs.len() * 2 + 1, 0);
        let mut refs = Vec::new();
        crate::simd::reserve_huge(&mut refs, top.refs.len() * 2, 0);
        let mut ranges: Vec<[u32; 6]> = Vec::new();
        let mut count: Vec<u32> = Vec::new();
        let mut sub_cells = 0usize;
        for (ci, cell) in g.cells.iter_mut().enumerate() {
            let tris = &top.refs[top.starts[ci] as usize..top.starts[ci + 1] as usize];
            if tris.is_empty() {
                continue;
            }
            let idx = top.lattice.position(ci);
            let n = tris.len() as f64;
            let room = params.max_cells.saturating_sub(sub_cells).max(1) as f64;
            let mut target = (f64::from(params.leaf_density.max(1e-6)) * n).clamp(1.0, room);
            let (sub, total) = loop {
                let mut res = resolution(&top.lattice.cell_box(idx), target);
                for r in &mut res {
                    *r = (*r).min(MAX_SUB_RES);
                }
                let sub = top.lattice.sub(idx, res);
                let margin = sub.margin(scale);
                ranges.clear();
                let mut total = 0u64;
                for &t in tris {
                    let r = sub.cell_range(&boxes[t as usize], margin);
                    total += u64::from(r[3] - r[0] + 1)
                        * u64::from(r[4] - r[1] + 1)
                        * u64::from(r[5] - r[2] + 1);
                    ranges.push(r);
                }
                let fits =
                    total <= MAX_REFS_PER_TRIANGLE * tris.len() as u64 + sub.cell_count() as u64;
                if fits || target <= 1.0 {
                    break (sub, total);
                }
                target = (target / 8.0).max(1.0);
            };
            let cells = sub.cell_count();
            *cell = TopCell {
                first: sub_cells as u32,
                res: sub.res.map(|r| r as u16),
            };
            sub_cells += cells;
            // Counting sort of the cell's triangles into its grid's cells.
            count.clear();
            count.resize(cells, 0);
            for r in &ranges {
                for_each_cell(&sub, r, |k| count[k] += 1);
            }
            let base = refs.len() as u32;
            let mut sum = base;
            for c in &mut count {
                starts.push(sum);
                let n = *c;
                *c = sum;
                sum += n;
            }
            refs.resize(refs.len() + total as usize, 0);
            for (&t, r) in tris.iter().zip(&ranges) {
                for_each_cell(&sub, r, |k| {
                    refs[count[k] as usize] = t;
                    count[k] += 1;
                });
            }
        }
        starts.push(refs.len() as u32);
        g.starts = starts;
        g.refs = refs;
        g.tris = top.tris;
        g
    }

    /// Top cell `ci`'s grid and the box a ray is clipped to for it: the cell's, widened by the
    /// margin the triangles were entered into it with.
    #[inline(always)]
    fn sub(&self, idx: [u32; 3], cell: TopCell) -> (Lattice, (Vec3, Vec3)) {
        let sub = self.top.sub(idx, cell.res.map(u32::from));
        let b = self.top.cell_box(idx);
        (sub, (b.min - self.margin, b.max + self.margin))
    }

    /// Top cells per axis.
    #[must_use]
    pub fn resolution(&self) -> [u32; 3] {
        self.top.res
    }

    /// Cells of all the top cells' grids.
    fn sub_cells(&self) -> usize {
        self.starts.len().saturating_sub(1)
    }

    fn check(&self, mesh: &TriMesh) -> Result<(), String> {
        self.tris.check(mesh)?;
        let boxes = self.tris.boxes();
        if self.cells.is_empty() {
            return match boxes.iter().position(|b| !b.is_empty()) {
                Some(i) => Err(format!("no cell but triangle {i} has a box")),
                None => Ok(()),
            };
        }
        if self.cells.len() != self.top.cell_count() {
            return Err(format!(
                "{} top cells for a {:?} lattice",
                self.cells.len(),
                self.top.res
            ));
        }
        if self.starts.windows(2).any(|w| w[0] > w[1])
            || self.starts.last().map(|&s| s as usize) != Some(self.refs.len())
        {
            return Err("cell starts do not cover the references in order".into());
        }
        // Every triangle is in every cell it overlaps at both levels, and no cell holds
        // another.
        let mut want = vec![0u32; self.sub_cells()];
        let mut next = 0u32;
        for (ci, tc) in self.cells.iter().enumerate() {
            if tc.res[0] == 0 {
                continue;
            }
            if tc.first != next {
                return Err(format!(
                    "top cell {ci}'s grid starts at {}, not {next}",
                    tc.first
                ));
            }
            next += tc.res.iter().map(|&r| u32::from(r)).product::<u32>();
        }
        if next as usize != self.sub_cells() {
            return Err(format!(
                "{next} cells in the top cells' grids, {} starts",
                self.sub_cells()
            ));
        }
        for (i, b) in boxes.iter().enumerate().filter(|(_, b)| !b.is_empty()) {
            let r = self.top.cell_range(b, self.margin);
            for z in r[2]..=r[5] {
                for y in r[1]..=r[4] {
                    for x in r[0]..=r[3] {
                        let ci = self.top.cell_index(x, y, z);
                        let tc = self.cells[ci];
                        if tc.res[0] == 0 {
                            return Err(format!(
                                "triangle {i} overlaps empty top cell ({x}, {y}, {z})"
                            ));
                        }
                        let (sub, _) = self.sub([x, y, z], tc);
                        let sr = sub.cell_range(b, sub.margin(self.scale));
                        let mut missing = None;
                        for_each_cell(&sub, &sr, |k| {
                            let k = tc.first as usize + k;
                            let refs =
                                &self.refs[self.starts[k] as usize..self.starts[k + 1] as usize];
                            if refs.contains(&(i as u32)) {
                                want[k] += 1;
                            } else {
                                missing = Some(k);
                            }
                        });
                        if let Some(k) = missing {
                            return Err(format!(
                                "triangle {i} missing from cell {k} of top cell ({x}, {y}, {z})"
                            ));
                        }
                    }
                }
            }
        }
        match (0..self.sub_cells()).find(|&k| self.starts[k + 1] - self.starts[k] != want[k]) {
            Some(k) => Err(format!("cell {k} holds triangles that do not overlap it")),
            None => Ok(()),
        }
    }
}

/// Calls `f` with the table index of each cell of `lattice` in range `r` (`[x0, y0, z0, x1,
/// y1, z1]`, inclusive).
#[inline(always)]
fn for_each_cell(lattice: &Lattice, r: &[u32; 6], mut f: impl FnMut(usize)) {
    for z in r[2]..=r[5] {
        for y in r[1]..=r[4] {
            let row = lattice.cell_index(r[0], y, z);
            for k in row..=row + (r[3] - r[0]) as usize {
                f(k);
            }
        }
    }
}

impl CellWalk for Grid2 {
    fn triangles(&self) -> &Triangles {
        &self.tris
    }

    /// Walks the top cells along the ray and, in each non-empty one, its grid's cells, in
    /// order; `cell` tests one cell's triangles and returns true to stop; `cap()` as in
    /// [`Grid`]'s walk.
    #[inline(always)]
    fn walk<C: Counters>(
        &self,
        ray: &Ray,
        c: &mut C,
        mut cell: impl FnMut(&[u32], &mut C) -> bool,
        cap: impl Fn() -> f32,
    ) {
        if self.cells.is_empty() {
            return;
        }
        self.top.walk(
            ray,
            (self.bounds.min, self.bounds.max),
            c,
            |ci, idx, c| {
                let tc = self.cells[ci];
                if tc.res[0] == 0 {
                    return false;
                }
                let (sub, clip) = self.sub(idx, tc);
                let mut stop = false;
                sub.walk(
                    ray,
                    clip,
                    c,
                    |k, _, c| {
                        let k = tc.first as usize + k;
                        let refs = &self.refs[self.starts[k] as usize..self.starts[k + 1] as usize];
                        stop = !refs.is_empty() && cell(refs, c);
                        stop
                    },
                    &cap,
                );
                stop
            },
            &cap,
        );
    }
}

impl Accel for Grid2 {
    fn name(&self) -> String {
        "grid2".into()
    }

    cell_walk_queries!();

    fn validate(&self, mesh: &TriMesh) -> Result<(), String> {
        self.check(mesh)
    }

    fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.cells.as_slice())
            + std::mem::size_of_val(self.starts.as_slice())
            + std::mem::size_of_val(self.refs.as_slice())
            + self.tris.memory_bytes()
    }

    fn nodes(&self) -> usize {
        self.cells.len() + self.sub_cells()
    }

    fn depth(&self) -> usize {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::triangles::Closest;

    /// A floor of two large triangles and, above one corner of it, a dense cluster of small
    /// ones: the uneven scene a uniform grid handles badly.
    fn floor_and_cluster() -> TriMesh {
        let mut tris = vec![
            [
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(10.0, 0.0, 0.0),
                Vec3::new(10.0, 10.0, 0.0),
            ],
            [
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(10.0, 10.0, 0.0),
                Vec3::new(0.0, 10.0, 0.0),
            ],
        ];
        for i in 0..4000u32 {
            let (x, y, z) = (i % 16, i / 16 % 16, i / 256);
            let p = Vec3::new(1.0, 1.0, 1.0) + Vec3::new(x as f32, y as f32, z as f32) * 0.03;
            tris.push([
                p,
                p + Vec3::new(0.02, 0.0, 0.0),
                p + Vec3::new(0.0, 0.02, 0.01),
            ]);
        }
        TriMesh::from_soup(&tris)
    }

    #[test]
    fn a_crowded_top_cell_gets_a_finer_grid_and_every_hit_is_brute_forces() {
        let mesh = floor_and_cluster();
        let g = Grid2::build(&mesh, &Grid2Params::default());
        g.validate(&mesh).unwrap();
        let cells = |p: Vec3| {
            let idx: [u32; 3] = std::array::from_fn(|a| g.top.cell_of(a, p[a]));
            let tc = g.cells[g.top.cell_index(idx[0], idx[1], idx[2])];
            tc.res.iter().map(|&r| u32::from(r)).product::<u32>()
        };
        let (cluster, floor) = (
            cells(Vec3::new(1.2, 1.2, 1.2)),
            cells(Vec3::new(8.0, 8.0, 0.0)),
        );
        assert!(
            floor >= 1 && cluster > 50 * floor,
            "cluster {cluster}, floor {floor}"
        );
        // Rays down onto the scene and slanted through the cluster, against every triangle.
        let tris = Triangles::of_mesh(&mesh);
        let mut checked = 0;
        for i in 0..400 {
            let (u, v) = ((i % 20) as f32 / 20.0, (i / 20) as f32 / 20.0);
            for ray in [
                Ray::new(
                    Vec3::new(0.5 + u * 9.0, 0.5 + v * 9.0, 5.0),
                    Vec3::new(0.01, 0.02, -1.0),
                ),
                Ray::new(
                    Vec3::new(-1.0, 1.0 + u * 0.5, 1.0 + v * 0.5),
                    Vec3::new(1.0, 0.05, 0.02),
                ),
            ] {
                let mut q = Closest::new(&ray);
                for (p, t) in tris.tris.iter().enumerate() {
                    q.test(t, p as u32, &mut ());
                }
                let want = q.hit;
                assert_eq!(
                    g.closest_hit(&ray).map(|h| (h.t, h.prim)),
                    want.map(|h| (h.t, h.prim))
                );
                assert_eq!(g.any_hit(&ray), want.is_some());
                checked += usize::from(want.is_some());
            }
        }
        assert!(checked > 400, "{checked} rays hit");
    }

    #[test]
    fn lattice_positions_invert_table_indices() {
        let l = Lattice::new(
            &Aabb {
                min: Vec3::ZERO,
                max: Vec3::new(3.0, 5.0, 7.0),
            },
            [3, 5, 7],
        );
        for i in 0..l.cell_count() {
            let [x, y, z] = l.position(i);
            assert_eq!(l.cell_index(x, y, z), i);
        }
    }
}
