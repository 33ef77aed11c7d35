//! The uniform grid: the scene's box cut into `nx · ny · nz` equal cells, about `λ N` of them
//! (`λ N^(1/3)` per side for a cube: the rule of Cleary & Wyvill 1988 and of Amanatides & Woo),
//! each cell listing the triangles whose boxes overlap it. A ray walks the cells it crosses in
//! order with the 3D-DDA of Amanatides & Woo 1987 ("A Fast Voxel Traversal Algorithm"), with
//! mailboxing, and stops once its best hit lies before the next cell. Triangles are entered
//! into cells with a small margin, so a ray whose computed cell walk goes past a cell corner on
//! the other side of the exact one still meets every triangle near it.

use super::Accel;
use super::interval::{box_interval, lower};
use super::mailbox::{CellWalk, cell_walk_queries};
use super::triangles::Triangles;
use crate::bvh::{Counters, TraversalStats};
use crate::geom::{Aabb, Hit, Ray, TriMesh};
use glam::Vec3;

/// How a grid is built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridParams {
    /// Cells per triangle, `λ`.
    pub density: f32,
    /// Most cells in all (also bounds the memory of the cell table).
    pub max_cells: usize,
}

impl GridParams {
    /// The default `λ` (see `docs/accel.md` for the measurement).
    pub const DEFAULT_DENSITY: f32 = 2.0;
    /// Smallest `λ` accepted by name.
    pub const MIN_DENSITY: f32 = 0.01;
    /// Largest `λ` accepted by name.
    pub const MAX_DENSITY: f32 = 64.0;
}

impl Default for GridParams {
    fn default() -> Self {
        Self {
            density: Self::DEFAULT_DENSITY,
            max_cells: 1 << 25,
        }
    }
}

/// Cell references allowed per triangle before the grid is made coarser (a few huge triangles
/// in a fine grid would otherwise fill it).
pub(super) const MAX_REFS_PER_TRIANGLE: u64 = 64;

/// Cells up to which the build enters triangles in the mesh's order whatever it is: the
/// counts (4 bytes a cell) and lists of such a grid stay in the cache (see `count_refs`).
const CACHED_CELLS: usize = 1 << 19;

/// A triangle entered into the grid: its index and its cells, `[x0, y0, z0, x1, y1, z1]`
/// inclusive (16 bits suffice: [`resolution`] keeps at most 4096 cells a side).
type Entry = (u32, [u16; 6]);

/// A uniform grid over a mesh's triangles.
#[derive(Clone, Debug, Default)]
pub struct Grid {
    pub(super) bounds: Aabb,
    /// The cells.
    pub(super) lattice: Lattice,
    /// `refs[starts[c]..starts[c + 1]]`: the triangles of cell `c` (`x + nx (y + ny z)`).
    pub(super) starts: Vec<u32>,
    pub(super) refs: Vec<u32>,
    pub(super) tris: Triangles,
    /// The margin triangles were entered with, per axis.
    pub(super) margin: Vec3,
}

impl Grid {
    /// Builds a grid over `mesh`'s triangles; triangles without a box are left out.
    ///
    /// # Panics
    /// When a vertex index is out of range.
    #[must_use]
    pub fn build(mesh: &TriMesh, params: &GridParams) -> Self {
        let (tris, bounds, n) = Triangles::of_mesh_bounded(mesh);
        if n == 0 {
            return Self {
                tris,
                bounds,
                ..Self::default()
            };
        }
        let mut target = (f64::from(params.density.max(1e-6)) * n as f64)
            .min(params.max_cells.max(1) as f64)
            .max(1.0);
        loop {
            let mut g = Self::with_resolution(bounds, resolution(&bounds, target));
            let (sorted, count, total) = g.count_refs(&tris.tris);
            if total <= MAX_REFS_PER_TRIANGLE * n as u64 + count.len() as u64 || target <= 1.0 {
                g.fill(&sorted, count);
                g.tris = tris;
                return g;
            }
            target = (target / 8.0).max(1.0);
        }
    }

    fn with_resolution(bounds: Aabb, res: [u32; 3]) -> Self {
        let lattice = Lattice::new(&bounds, res);
        let scale = bounds.min.abs().max(bounds.max.abs());
        Self {
            bounds,
            lattice,
            margin: lattice.margin(scale),
            ..Self::default()
        }
    }

    /// The cells a triangle's box (with the margin) overlaps: `[x0, y0, z0, x1, y1, z1]`,
    /// inclusive.
    #[inline(always)]
    fn cell_range(&self, b: &Aabb) -> [u32; 6] {
        self.lattice.cell_range(b, self.margin)
    }

    fn cell_index(&self, x: u32, y: u32, z: u32) -> usize {
        self.lattice.cell_index(x, y, z)
    }

    fn cell_count(&self) -> usize {
        self.lattice.cell_count()
    }

    /// Each triangle with a box and its cell range (`[x0, y0, z0, x1, y1, z1]`, inclusive),
    /// the references per cell and their total (`u64::MAX` past `u32::MAX`); each triangle is
    /// located once, in one pass, so the fill does not locate it again.
    ///
    /// The fill takes the triangles sorted by the row (`y`, `z`) of their first cell (two
    /// counting sorts: by `y`, then stably by `z`; one sort over all rows at once scatters its
    /// own writes over too many places), so that the lists written for consecutive triangles
    /// lie in a few rows of the table, which stay in cache: in a mesh stored in no spatial
    /// order (a soup) entering them by index scatters every write over the whole table, a
    /// cache miss each. Triangles mostly in that order already (as a mesh's are), and all of
    /// them when the grid is small enough for its table to stay in the cache, are taken as they
    /// are, and counted in the same pass when the first of them show that order.
    fn count_refs(&self, tris: &[[Vec3; 3]]) -> (Vec<Entry>, Vec<u32>, u64) {
        const PROBE: usize = 4096;
        let boxes = || {
            tris.iter()
                .enumerate()
                .map(|(i, t)| (i, Aabb::of_triangle(t)))
                .filter(|(_, b)| !b.is_empty())
        };
        let near_rows =
            |a: &[u32; 6], b: &[u32; 6]| a[1].abs_diff(b[1]) <= 1 && a[2].abs_diff(b[2]) <= 1;
        let mostly = |near: usize, m: usize| near >= m - m / 8;
        // A table that fits in the cache is written fast in any order; a larger one when the
        // first triangles are in spatial order: then counting as they come writes near the
        // last count, and the count needs no pass of its own.
        let cached = self.cell_count() <= CACHED_CELLS;
        let count_now = cached || {
            let probe: Vec<[u32; 6]> = boxes()
                .take(PROBE)
                .map(|(_, b)| self.cell_range(&b))
                .collect();
            let near = probe.windows(2).filter(|w| near_rows(&w[0], &w[1])).count();
            mostly(near + 1, probe.len())
        };
        let mut count = huge_vec(self.cell_count(), 0u32);
        let mut entries = Vec::new();
        crate::simd::reserve_huge(&mut entries, tris.len(), 0);
        let mut total = 0u64;
        let res = self.lattice.res;
        let mut ys = vec![0u32; res[1] as usize + 1];
        let mut zs = vec![0u32; res[2] as usize + 1];
        // Consecutive triangles whose first cells lie in neighbouring rows.
        let (mut near, mut last) = (0usize, [u32::MAX; 6]);
        for (i, b) in boxes() {
            let r = self.cell_range(&b);
            total += u64::from(r[3] - r[0] + 1)
                * u64::from(r[4] - r[1] + 1)
                * u64::from(r[5] - r[2] + 1);
            ys[r[1] as usize + 1] += 1;
            zs[r[2] as usize + 1] += 1;
            near += usize::from(near_rows(&r, &last));
            last = r;
            let e = (i as u32, r.map(|x| x as u16));
            if count_now {
                self.add_counts(&mut count, &e);
            }
            entries.push(e);
        }
        if total > u64::from(u32::MAX) {
            return (Vec::new(), Vec::new(), u64::MAX);
        }
        let m = entries.len();
        let in_order = cached || mostly(near, m);
        if !in_order {
            for k in 1..ys.len() {
                ys[k] += ys[k - 1];
            }
            for k in 1..zs.len() {
                zs[k] += zs[k - 1];
            }
            let mut by_row = huge_vec(m, (0, [0; 6]));
            for &e in &entries {
                let slot = &mut ys[e.1[1] as usize];
                by_row[*slot as usize] = e;
                *slot += 1;
            }
            for &e in &by_row {
                let slot = &mut zs[e.1[2] as usize];
                entries[*slot as usize] = e;
                *slot += 1;
            }
        }
        if !count_now {
            for e in &entries {
                self.add_counts(&mut count, e);
            }
        }
        (entries, count, total)
    }

    /// Adds one to the count of each cell of entry `e`.
    #[inline(always)]
    fn add_counts(&self, count: &mut [u32], e: &Entry) {
        self.for_each_row(&e.1, |row| {
            for c in &mut count[row] {
                *c += 1;
            }
        });
    }

    /// Calls `f` with the table indices of each row of cells in range `r` (`[x0, y0, z0, x1,
    /// y1, z1]`, inclusive): consecutive cells along `x`.
    #[inline(always)]
    fn for_each_row(&self, r: &[u16; 6], mut f: impl FnMut(std::ops::Range<usize>)) {
        let res = self.lattice.res;
        let (nx, nxy) = (res[0] as usize, res[0] as usize * res[1] as usize);
        for z in r[2] as usize..=r[5] as usize {
            for y in r[1] as usize..=r[4] as usize {
                let row = z * nxy + y * nx;
                f(row + r[0] as usize..row + r[3] as usize + 1);
            }
        }
    }

    fn fill(&mut self, sorted: &[Entry], count: Vec<u32>) {
        let mut starts = Vec::new();
        crate::simd::reserve_huge(&mut starts, count.len() + 1, 0);
        let mut sum = 0u32;
        starts.push(0);
        for c in &count {
            sum += c;
            starts.push(sum);
        }
        // `count` becomes each cell's next free slot.
        let mut next = count;
        let cells = next.len();
        next.copy_from_slice(&starts[..cells]);
        let mut refs = huge_vec(sum as usize, 0u32);
        for (i, r) in sorted {
            self.for_each_row(r, |row| {
                for c in &mut next[row] {
                    refs[*c as usize] = *i;
                    *c += 1;
                }
            });
        }
        self.starts = starts;
        self.refs = refs;
    }

    /// Cells per axis.
    #[must_use]
    pub fn resolution(&self) -> [u32; 3] {
        self.lattice.res
    }

    fn check(&self, mesh: &TriMesh) -> Result<(), String> {
        self.tris.check(mesh)?;
        let boxes = self.tris.boxes();
        if self.starts.is_empty() {
            return match boxes.iter().position(|b| !b.is_empty()) {
                Some(i) => Err(format!("no cell but triangle {i} has a box")),
                None => Ok(()),
            };
        }
        let cells = self.cell_count();
        if self.starts.len() != cells + 1 || self.starts[cells] as usize != self.refs.len() {
            return Err(format!(
                "{} cell starts for {cells} cells",
                self.starts.len()
            ));
        }
        if self.starts.windows(2).any(|w| w[0] > w[1]) {
            return Err("cell starts decrease".into());
        }
        let mut want = vec![0u32; cells];
        for (i, b) in boxes.iter().enumerate().filter(|(_, b)| !b.is_empty()) {
            let r = self.cell_range(b);
            for z in r[2]..=r[5] {
                for y in r[1]..=r[4] {
                    for x in r[0]..=r[3] {
                        let c = self.cell_index(x, y, z);
                        let refs = &self.refs[self.starts[c] as usize..self.starts[c + 1] as usize];
                        if !refs.contains(&(i as u32)) {
                            return Err(format!("triangle {i} missing from cell ({x}, {y}, {z})"));
                        }
                        want[c] += 1;
                    }
                }
            }
        }
        match (0..cells).find(|&c| self.starts[c + 1] - self.starts[c] != want[c]) {
            Some(c) => Err(format!("cell {c} holds triangles that do not overlap it")),
            None => Ok(()),
        }
    }
}

/// Equal cells over a box: `res` per axis from `min`, each `cell_size` wide. The uniform grid
/// is one; the two-level grid has one on top and one in each of its top cells.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Lattice {
    pub min: Vec3,
    /// Cells per axis (at least 1).
    pub res: [u32; 3],
    pub cell_size: Vec3,
    /// `res / extent` per axis, 0 on a flat or unbounded side.
    pub inv_cell_size: Vec3,
}

impl Lattice {
    /// `res` cells over `bounds`.
    pub fn new(bounds: &Aabb, res: [u32; 3]) -> Self {
        let e = bounds.extent();
        let r = Vec3::new(res[0] as f32, res[1] as f32, res[2] as f32);
        let inv = |n: f32, e: f32| if e > 0.0 && e.is_finite() { n / e } else { 0.0 };
        Self {
            min: bounds.min,
            res,
            cell_size: e / r,
            inv_cell_size: Vec3::new(inv(r.x, e.x), inv(r.y, e.y), inv(r.z, e.z)),
        }
    }

    /// The margin triangles are entered with: a small share of a cell, and at least a few
    /// units in the last place of coordinates as large as `scale`.
    pub fn margin(&self, scale: Vec3) -> Vec3 {
        let margin = (self.cell_size * (1.0 / 1024.0)).max(scale * (1.0 / (1 << 18) as f32));
        Vec3::select(margin.is_finite_mask(), margin, Vec3::ZERO)
    }

    /// The cell index along `axis` of coordinate `x`, clamped to the lattice.
    #[inline(always)]
    pub fn cell_of(&self, axis: usize, x: f32) -> u32 {
        let f = ((x - self.min[axis]) * self.inv_cell_size[axis]).floor();
        if f >= 0.0 {
            (f as u32).min(self.res[axis] - 1)
        } else {
            0
        }
    }

    /// The cells box `b` widened by `margin` overlaps: `[x0, y0, z0, x1, y1, z1]`, inclusive.
    #[inline(always)]
    pub fn cell_range(&self, b: &Aabb, margin: Vec3) -> [u32; 6] {
        let lo: [u32; 3] = std::array::from_fn(|a| self.cell_of(a, b.min[a] - margin[a]));
        let hi: [u32; 3] = std::array::from_fn(|a| self.cell_of(a, b.max[a] + margin[a]));
        [lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]]
    }

    /// The table index of cell `(x, y, z)`.
    #[inline(always)]
    pub fn cell_index(&self, x: u32, y: u32, z: u32) -> usize {
        x as usize + self.res[0] as usize * (y as usize + self.res[1] as usize * z as usize)
    }

    /// Cells in all.
    pub fn cell_count(&self) -> usize {
        self.res.iter().map(|&r| r as usize).product()
    }

    /// The position of the cell of table index `i`.
    pub fn position(&self, i: usize) -> [u32; 3] {
        let (nx, ny) = (self.res[0] as usize, self.res[1] as usize);
        [
            (i % nx) as u32,
            (i / nx % ny) as u32,
            (i / (nx * ny)) as u32,
        ]
    }

    /// The box of the cell at `idx`, its faces where the walk puts them.
    #[inline(always)]
    pub fn cell_box(&self, idx: [u32; 3]) -> Aabb {
        let face = |a: usize, i: u32| self.min[a] + i as f32 * self.cell_size[a];
        Aabb {
            min: Vec3::new(face(0, idx[0]), face(1, idx[1]), face(2, idx[2])),
            max: Vec3::new(
                face(0, idx[0] + 1),
                face(1, idx[1] + 1),
                face(2, idx[2] + 1),
            ),
        }
    }

    /// `res` cells over the cell at `idx` (its sizes from this lattice's, without a division
    /// by the box's extent: the walk makes one for every cell it enters).
    #[inline(always)]
    pub fn sub(&self, idx: [u32; 3], res: [u32; 3]) -> Self {
        let r = Vec3::new(res[0] as f32, res[1] as f32, res[2] as f32);
        Self {
            min: self.cell_box(idx).min,
            res,
            cell_size: self.cell_size / r,
            inv_cell_size: self.inv_cell_size * r,
        }
    }

    /// The 3D-DDA: calls `cell` with the table index and position of each cell the ray crosses inside the
    /// box `(lo, hi)`, in order, until `cell` returns true, the walk leaves the lattice, or the
    /// next cell starts beyond `cap()`.
    #[inline(always)]
    pub fn walk<C: Counters>(
        &self,
        ray: &Ray,
        (lo, hi): (Vec3, Vec3),
        c: &mut C,
        mut cell: impl FnMut(usize, [u32; 3], &mut C) -> bool,
        cap: impl Fn() -> f32,
    ) {
        let Some((tn, _)) = box_interval(ray, lo, hi, ray.tmax) else {
            return;
        };
        // The entry point. Where the direction is infinite on an axis and the distance zero,
        // their product is NaN and the point's coordinate is the origin's.
        let t0 = tn.max(ray.tmin);
        let p: [f32; 3] = std::array::from_fn(|a| {
            let s = ray.dir[a] * t0;
            if s.is_nan() {
                ray.origin[a]
            } else {
                ray.origin[a] + s
            }
        });
        let mut idx = [0u32; 3];
        let mut step = [0i32; 3];
        for a in 0..3 {
            idx[a] = self.cell_of(a, p[a]);
            step[a] = if ray.dir[a] > 0.0 {
                1
            } else if ray.dir[a] < 0.0 {
                -1
            } else {
                0
            };
        }
        // Distance along the ray to the next cell boundary on each axis.
        let exit = |a: usize, i: u32, s: i32| -> f32 {
            if s == 0 {
                return f32::INFINITY;
            }
            let face = if s > 0 { i + 1 } else { i };
            let x = self.min[a] + face as f32 * self.cell_size[a];
            (x - ray.origin[a]) * ray.inv_dir[a]
        };
        let mut t_next = [
            exit(0, idx[0], step[0]),
            exit(1, idx[1], step[1]),
            exit(2, idx[2], step[2]),
        ];
        loop {
            c.node();
            if cell(self.cell_index(idx[0], idx[1], idx[2]), idx, c) {
                return;
            }
            let a = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                0
            } else if t_next[1] <= t_next[2] {
                1
            } else {
                2
            };
            let t_exit = t_next[a];
            // The walk ends once the next cell starts beyond the best hit, or the ray does not
            // move at all.
            let next_may_help = lower(t_exit) <= cap();
            if !next_may_help || step[a] == 0 {
                return;
            }
            if step[a] > 0 {
                if idx[a] + 1 >= self.res[a] {
                    return;
                }
                idx[a] += 1;
            } else {
                if idx[a] == 0 {
                    return;
                }
                idx[a] -= 1;
            }
            t_next[a] = exit(a, idx[a], step[a]);
        }
    }
}

/// `n` copies of `x` in storage asked to be backed by huge pages
/// ([`crate::simd::reserve_huge`]): the build's tables are large and written in scattered
/// order, and rays read the cell lists in random order; with 4 KiB pages most of the build's
/// time went to page faults and the walk's to TLB misses.
fn huge_vec<T: Clone>(n: usize, x: T) -> Vec<T> {
    let mut v = Vec::new();
    crate::simd::reserve_huge(&mut v, n, 0);
    v.resize(n, x);
    v
}

/// Cells per axis for about `target` cells over `bounds`, proportional to its sides (flat or
/// unbounded sides get one cell).
pub(super) fn resolution(bounds: &Aabb, target: f64) -> [u32; 3] {
    let e = bounds.extent();
    let sides: Vec<f64> = (0..3)
        .map(|a| f64::from(e[a]))
        .filter(|&x| x > 0.0 && x.is_finite())
        .collect();
    if sides.is_empty() {
        return [1, 1, 1];
    }
    let volume: f64 = sides.iter().product();
    let k = (target / volume).powf(1.0 / sides.len() as f64);
    let mut res: [u32; 3] = std::array::from_fn(|a| {
        let x = f64::from(e[a]);
        if x > 0.0 && x.is_finite() {
            (x * k).round().clamp(1.0, 4096.0) as u32
        } else {
            1
        }
    });
    // Sides rounded up to one cell leave the others finer than the target allows.
    while res.iter().map(|&r| r as f64).product::<f64>() > 2.0 * target.max(1.0) {
        let a = (0..3).max_by_key(|&a| res[a]).unwrap_or(0);
        res[a] = res[a].div_ceil(2);
    }
    res
}

impl CellWalk for Grid {
    fn triangles(&self) -> &Triangles {
        &self.tris
    }

    /// Walks the cells along the ray in order; `cell` tests one cell's triangles and returns
    /// true to stop; `cap()` is the distance beyond which no cell can help (the best hit so far,
    /// widened: `beyond` of it, set when the best changes).
    #[inline(always)]
    fn walk<C: Counters>(
        &self,
        ray: &Ray,
        c: &mut C,
        mut cell: impl FnMut(&[u32], &mut C) -> bool,
        cap: impl Fn() -> f32,
    ) {
        if self.starts.is_empty() {
            return;
        }
        self.lattice.walk(
            ray,
            (self.bounds.min, self.bounds.max),
            c,
            |ci, _, c| {
                let refs = &self.refs[self.starts[ci] as usize..self.starts[ci + 1] as usize];
                !refs.is_empty() && cell(refs, c)
            },
            cap,
        );
    }
}

impl Accel for Grid {
    fn name(&self) -> String {
        "grid".into()
    }

    cell_walk_queries!();

    fn validate(&self, mesh: &TriMesh) -> Result<(), String> {
        self.check(mesh)
    }

    fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.starts.as_slice())
            + std::mem::size_of_val(self.refs.as_slice())
            + self.tris.memory_bytes()
    }

    fn nodes(&self) -> usize {
        self.cell_count()
    }

    fn depth(&self) -> usize {
        0
    }
}
