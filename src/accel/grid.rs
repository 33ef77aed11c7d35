//! The uniform grid: the scene's box cut into `nx · ny · nz` equal cells, about `λ N` of them
//! (`λ N^(1/3)` per side for a cube: the rule of Cleary & Wyvill 1988 and of Amanatides & Woo),
//! each cell listing the triangles whose boxes overlap it. A ray walks the cells it crosses in
//! order with the 3D-DDA of Amanatides & Woo 1987 ("A Fast Voxel Traversal Algorithm"), with
//! mailboxing, and stops once its best hit lies before the next cell. Triangles are entered
//! into cells with a small margin, so a ray whose computed cell walk goes past a cell corner on
//! the other side of the exact one still meets every triangle near it.

use super::Accel;
use super::interval::{beyond, box_interval, lower};
use super::mailbox::Mailbox;
use super::triangles::{AnyHit, Closest, Triangles, bounds_of};
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
const MAX_REFS_PER_TRIANGLE: u64 = 64;

/// A uniform grid over a mesh's triangles.
#[derive(Clone, Debug, Default)]
pub struct Grid {
    bounds: Aabb,
    /// Cells per axis.
    res: [u32; 3],
    cell_size: Vec3,
    inv_cell_size: Vec3,
    /// `refs[starts[c]..starts[c + 1]]`: the triangles of cell `c` (`x + nx (y + ny z)`).
    starts: Vec<u32>,
    refs: Vec<u32>,
    tris: Triangles,
    /// The margin triangles were entered with, per axis.
    margin: Vec3,
}

impl Grid {
    /// Builds a grid over `mesh`'s triangles; triangles without a box are left out.
    ///
    /// # Panics
    /// When a vertex index is out of range.
    #[must_use]
    pub fn build(mesh: &TriMesh, params: &GridParams) -> Self {
        let tris = Triangles::of_mesh(mesh);
        let boxes = tris.boxes();
        let bounds = bounds_of(&boxes);
        let n = boxes.iter().filter(|b| !b.is_empty()).count();
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
            let (ranges, count, total) = g.count_refs(&boxes);
            if total <= MAX_REFS_PER_TRIANGLE * n as u64 + count.len() as u64 || target <= 1.0 {
                g.fill(&ranges, count);
                g.tris = tris;
                return g;
            }
            target = (target / 8.0).max(1.0);
        }
    }

    fn with_resolution(bounds: Aabb, res: [u32; 3]) -> Self {
        let e = bounds.extent();
        let r = Vec3::new(res[0] as f32, res[1] as f32, res[2] as f32);
        let cell_size = e / r;
        let inv = |n: f32, e: f32| if e > 0.0 && e.is_finite() { n / e } else { 0.0 };
        let inv_cell_size = Vec3::new(inv(r.x, e.x), inv(r.y, e.y), inv(r.z, e.z));
        let scale = bounds.min.abs().max(bounds.max.abs());
        let margin = (cell_size * (1.0 / 1024.0)).max(scale * (1.0 / (1 << 18) as f32));
        Self {
            bounds,
            res,
            cell_size,
            inv_cell_size,
            margin: Vec3::select(margin.is_finite_mask(), margin, Vec3::ZERO),
            ..Self::default()
        }
    }

    /// The cell index along `axis` of coordinate `x`, clamped to the grid.
    #[inline(always)]
    fn cell_of(&self, axis: usize, x: f32) -> u32 {
        let f = ((x - self.bounds.min[axis]) * self.inv_cell_size[axis]).floor();
        if f >= 0.0 {
            (f as u32).min(self.res[axis] - 1)
        } else {
            0
        }
    }

    /// The cells a triangle's box (with the margin) overlaps, as index ranges per axis.
    fn cell_range(&self, b: &Aabb) -> [std::ops::RangeInclusive<u32>; 3] {
        std::array::from_fn(|a| {
            self.cell_of(a, b.min[a] - self.margin[a])..=self.cell_of(a, b.max[a] + self.margin[a])
        })
    }

    fn cell_index(&self, x: u32, y: u32, z: u32) -> usize {
        x as usize + self.res[0] as usize * (y as usize + self.res[1] as usize * z as usize)
    }

    fn cell_count(&self) -> usize {
        self.res.iter().map(|&r| r as usize).product()
    }

    /// Each triangle's cell range (`[x0, y0, z0, x1, y1, z1]`, inclusive; `None` without a
    /// box), the references per cell, and their total; computed once, so the fill does not
    /// locate the triangles in the grid again.
    fn count_refs(&self, boxes: &[Aabb]) -> (Vec<Option<[u32; 6]>>, Vec<u32>, u64) {
        let mut count = vec![0u32; self.cell_count()];
        let mut total = 0u64;
        let (nx, nxy) = (
            self.res[0] as usize,
            self.res[0] as usize * self.res[1] as usize,
        );
        let mut ranges = Vec::with_capacity(boxes.len());
        for b in boxes {
            if b.is_empty() {
                ranges.push(None);
                continue;
            }
            let [rx, ry, rz] = self.cell_range(b);
            let r = [
                *rx.start(),
                *ry.start(),
                *rz.start(),
                *rx.end(),
                *ry.end(),
                *rz.end(),
            ];
            ranges.push(Some(r));
            total += u64::from(r[3] - r[0] + 1)
                * u64::from(r[4] - r[1] + 1)
                * u64::from(r[5] - r[2] + 1);
            if total > u64::from(u32::MAX) {
                return (ranges, count, u64::MAX);
            }
            for z in r[2] as usize..=r[5] as usize {
                for y in r[1] as usize..=r[4] as usize {
                    let row = z * nxy + y * nx;
                    for c in &mut count[row + r[0] as usize..=row + r[3] as usize] {
                        *c += 1;
                    }
                }
            }
        }
        (ranges, count, total)
    }

    fn fill(&mut self, ranges: &[Option<[u32; 6]>], count: Vec<u32>) {
        let mut starts = Vec::with_capacity(count.len() + 1);
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
        let mut refs = vec![0u32; sum as usize];
        let (nx, nxy) = (
            self.res[0] as usize,
            self.res[0] as usize * self.res[1] as usize,
        );
        for (i, r) in ranges.iter().enumerate() {
            let Some(r) = r else { continue };
            for z in r[2] as usize..=r[5] as usize {
                for y in r[1] as usize..=r[4] as usize {
                    let row = z * nxy + y * nx;
                    for c in &mut next[row + r[0] as usize..=row + r[3] as usize] {
                        refs[*c as usize] = i as u32;
                        *c += 1;
                    }
                }
            }
        }
        self.starts = starts;
        self.refs = refs;
    }

    /// Walks the cells along the ray in order; `cell` tests one cell's triangles and returns
    /// true to stop; `best` is the distance beyond which no cell can help.
    #[inline(always)]
    fn walk<C: Counters>(
        &self,
        ray: &Ray,
        c: &mut C,
        mut cell: impl FnMut(&[u32], &mut C) -> bool,
        best: impl Fn() -> f32,
    ) {
        if self.starts.is_empty() {
            return;
        }
        let Some((tn, _)) = box_interval(ray, self.bounds.min, self.bounds.max, ray.tmax) else {
            return;
        };
        let p = ray.at(tn.max(ray.tmin));
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
            let x = self.bounds.min[a] + face as f32 * self.cell_size[a];
            (x - ray.origin[a]) * ray.inv_dir[a]
        };
        let mut t_next = [
            exit(0, idx[0], step[0]),
            exit(1, idx[1], step[1]),
            exit(2, idx[2], step[2]),
        ];
        loop {
            c.node();
            let ci = self.cell_index(idx[0], idx[1], idx[2]);
            let refs = &self.refs[self.starts[ci] as usize..self.starts[ci + 1] as usize];
            if !refs.is_empty() && cell(refs, c) {
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
            let next_may_help = lower(t_exit) <= beyond(best());
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

    fn closest<C: Counters>(&self, ray: &Ray, c: &mut C) -> Option<Hit> {
        let q = std::cell::RefCell::new(Closest::new(ray));
        let mut mailbox = Mailbox::new();
        self.walk(
            ray,
            c,
            |refs, c| {
                let mut q = q.borrow_mut();
                for &p in refs {
                    if !mailbox.seen(p) {
                        q.test(&self.tris.tris[p as usize], p, c);
                    }
                }
                false
            },
            || q.borrow().tmax,
        );
        q.into_inner().hit
    }

    fn any<C: Counters>(&self, ray: &Ray, c: &mut C) -> bool {
        let q = AnyHit::new(ray);
        let mut mailbox = Mailbox::new();
        let mut found = false;
        self.walk(
            ray,
            c,
            |refs, c| {
                found = refs
                    .iter()
                    .any(|&p| !mailbox.seen(p) && q.test(&self.tris.tris[p as usize], c));
                found
            },
            || ray.tmax,
        );
        found
    }

    /// Cells per axis.
    #[must_use]
    pub fn resolution(&self) -> [u32; 3] {
        self.res
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
            let [rx, ry, rz] = self.cell_range(b);
            for z in rz {
                for y in ry.clone() {
                    for x in rx.clone() {
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

/// Cells per axis for about `target` cells over `bounds`, proportional to its sides (flat or
/// unbounded sides get one cell).
fn resolution(bounds: &Aabb, target: f64) -> [u32; 3] {
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

impl Accel for Grid {
    fn name(&self) -> String {
        "grid".into()
    }

    fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        self.closest(ray, &mut ())
    }

    fn any_hit(&self, ray: &Ray) -> bool {
        self.any(ray, &mut ())
    }

    fn closest_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> Option<Hit> {
        self.closest(ray, stats)
    }

    fn any_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> bool {
        self.any(ray, stats)
    }

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
