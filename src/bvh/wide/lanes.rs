//! The SIMD kernels of the wide tree: the slab test of one ray against all `K` child boxes of a
//! node at once, the distance of a point to all of them, and the union of a node's child boxes. Written with the `wide` crate (AVX or
//! SSE when the target has them, plain arrays otherwise), so there is no `unsafe` here.

use crate::geom::{Aabb, FAR_SCALE, Ray, RayTriPrecomp};
use glam::Vec3;
use wide::{f32x4, f32x8};

/// Per-ray constants of the slab test: which of a node's six bound rows is the near and the far
/// plane on each axis (by the sign of the reciprocal direction), the origin subtracted from each
/// (`Ray::slab_lo` from a min plane, `Ray::slab_hi` from a max plane) and the reciprocal.
#[derive(Clone, Copy, Debug)]
pub(super) struct RayLanes {
    /// Origin subtracted from bound row `i` (rows min x, y, z, max x, y, z).
    origin: [f32; 6],
    inv: [f32; 3],
    tmin: f32,
    near: [usize; 3],
    far: [usize; 3],
    /// The slab distances may be NaN (a NaN or infinite origin or direction, a NaN range):
    /// an empty lane's infinite bounds can then pass the test, so the traversal masks the
    /// test's answer with the occupied lanes.
    pub(super) nonfinite: bool,
    /// `-(origin * inv)` of each bound row's axis, moved away from the box by a few ulps
    /// (down for the near rows, up for the far ones): the offsets of [`slab_fma`].
    neg_c: [f32; 6],
    /// Largest `|origin * inv|` over the axes, for [`RayLanes::fma_ok`].
    c_max: f32,
}

/// The pad of [`RayLanes`]'s `neg_c`: `4u` relative (u = 2^-24, the unit roundoff).
const C_PAD: f32 = 1.0 / 4_194_304.0;

impl RayLanes {
    #[inline(always)]
    pub(super) fn new(ray: &Ray) -> Self {
        // Arrays, not `Vec3` indexing (a match per access in the per-ray setup).
        let inv = ray.inv_dir.to_array();
        let origin = ray.origin.to_array();
        let mut near = [0, 1, 2];
        let mut far = [3, 4, 5];
        for a in 0..3 {
            // A negative reciprocal enters through the max plane (a zero component's is `+inf`:
            // min plane first). For a box with min <= max this gives exactly the distances of
            // `Ray::hit_box` (which takes min/max of the two); an inverted (empty) box misses.
            if inv[a].is_sign_negative() {
                near[a] = 3 + a;
                far[a] = a;
            }
        }
        // Each plane distance (b - o) / d is computed as fma(b, inv, -c) with c = o * inv
        // rounded: beside the relative rounding of `inv` and of the fma (which the far
        // distance's `FAR_SCALE` covers, as for the exact test), the rounding of `c` adds an
        // absolute error of at most u |c|, and (without a fused multiply-add) the product's
        // another u (|t| + |c|). Moving c by 4u |c| (and at least the smallest normal, against
        // underflow) towards the outside of every slab keeps the test conservative.
        let mut neg_c = [0f32; 6];
        let mut c_max = 0f32;
        for a in 0..3 {
            let c = origin[a] * inv[a];
            let pad = (c.abs() * C_PAD).max(f32::MIN_POSITIVE);
            // A larger c gives a smaller distance: the near row gets the larger.
            neg_c[near[a]] = -(c + pad);
            neg_c[far[a]] = -(c - pad);
            c_max = c_max.max(c.abs());
        }
        Self {
            neg_c,
            c_max,
            origin: [
                ray.slab_lo.x,
                ray.slab_lo.y,
                ray.slab_lo.z,
                ray.slab_hi.x,
                ray.slab_hi.y,
                ray.slab_hi.z,
            ],
            inv,
            tmin: ray.tmin,
            near,
            far,
            nonfinite: !ray.origin.is_finite()
                || !ray.dir.is_finite()
                || ray.tmin.is_nan()
                || ray.tmax.is_nan(),
        }
    }
}

impl RayLanes {
    /// True when [`slab_fma`] may be used for boxes whose coordinates are at most `coord_max`
    /// in magnitude: the ray moves along every axis (no infinite reciprocal), is finite, and no
    /// product `b * inv` or offset comes near overflow (a NaN `coord_max` answers false).
    #[inline(always)]
    pub(super) fn fma_ok(&self, coord_max: f32) -> bool {
        const LIMIT: f32 = f32::MAX / 8.0;
        let inv_max = self.inv[0]
            .abs()
            .max(self.inv[1].abs())
            .max(self.inv[2].abs());
        !self.nonfinite && self.c_max < LIMIT && coord_max * inv_max < LIMIT
    }
}

/// The slab test over one vector of `$k` lanes (`$v`), the plane distance of bound row `plane`
/// (a vector `row`) on axis `a` given by `$t`: [`slab`] and [`slab_fma`] differ only in it.
macro_rules! slab_lanes {
    ($v:ident, $k:literal, $bounds:ident, $r:ident, $tmax:ident, $dist:ident,
     |$row:ident, $a:ident, $plane:ident| $t:expr) => {{
        let t = |$a: usize, $plane: usize| {
            let a: &[f32; $k] = $bounds[$plane].as_slice().try_into().expect("K lanes");
            let $row = $v::from(*a);
            $t
        };
        let tn = t(0, $r.near[0])
            .fast_max(t(1, $r.near[1]))
            .fast_max(t(2, $r.near[2]).fast_max($v::splat($r.tmin)));
        let tf = t(0, $r.far[0])
            .fast_min(t(1, $r.far[1]))
            .fast_min(t(2, $r.far[2]).fast_min($v::splat($tmax)))
            * $v::splat(FAR_SCALE);
        $dist.as_mut_slice().copy_from_slice(&tn.to_array());
        tn.simd_le(tf).to_bitmask()
    }};
}

/// [`slab`] with each plane distance one fused multiply-add, `b * inv - c` (half the
/// arithmetic of `(b - o) * inv`), for rays that pass [`RayLanes::fma_ok`]: conservative by the
/// padded offsets (see [`RayLanes::new`]); the far distance gets the same `FAR_SCALE`. The
/// entry distances it writes may be a few ulps of `|o / d|` below [`slab`]'s.
#[inline(always)]
pub(super) fn slab_fma<const K: usize>(
    bounds: &[[f32; K]; 6],
    r: &RayLanes,
    tmax: f32,
    dist: &mut [f32; K],
) -> u32 {
    if K == 8 {
        slab_lanes!(f32x8, 8, bounds, r, tmax, dist, |row, a, plane| row
            .mul_add(f32x8::splat(r.inv[a]), f32x8::splat(r.neg_c[plane])))
    } else if K == 4 {
        slab_lanes!(f32x4, 4, bounds, r, tmax, dist, |row, a, plane| row
            .mul_add(f32x4::splat(r.inv[a]), f32x4::splat(r.neg_c[plane])))
    } else {
        slab(bounds, r, tmax, dist)
    }
}

/// Tests the ray against the `K` boxes `bounds` (rows min x, y, z, max x, y, z; one lane per
/// child) from `tmin` to `tmax`, closed. Returns the mask of hit lanes (bit `i` for lane `i`)
/// and writes every lane's entry distance into `dist`. Lane by lane the same arithmetic as
/// [`Ray::hit_box`], so just as conservative.
#[inline(always)]
pub(super) fn slab<const K: usize>(
    bounds: &[[f32; K]; 6],
    r: &RayLanes,
    tmax: f32,
    dist: &mut [f32; K],
) -> u32 {
    if K == 8 {
        slab_lanes!(f32x8, 8, bounds, r, tmax, dist, |row, a, plane| (row
            - f32x8::splat(r.origin[plane]))
            * f32x8::splat(r.inv[a]))
    } else if K == 4 {
        slab_lanes!(f32x4, 4, bounds, r, tmax, dist, |row, a, plane| (row
            - f32x4::splat(r.origin[plane]))
            * f32x4::splat(r.inv[a]))
    } else {
        let mut mask = 0;
        for i in 0..K {
            let t = |a: usize, plane: usize| (bounds[plane][i] - r.origin[plane]) * r.inv[a];
            let tn = fmax(
                fmax(t(0, r.near[0]), t(1, r.near[1])),
                fmax(t(2, r.near[2]), r.tmin),
            );
            let tf = fmin(
                fmin(t(0, r.far[0]), t(1, r.far[1])),
                fmin(t(2, r.far[2]), tmax),
            ) * FAR_SCALE;
            dist[i] = tn;
            mask |= u32::from(tn <= tf) << i;
        }
        mask
    }
}

#[inline(always)]
fn fmax(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

#[inline(always)]
fn fmin(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// Per-query constants of the box distance of [`box_distance_lanes`]: the query point moved
/// up (`above`) and down (`below`) by the margin of
/// [`box_distance_squared`](crate::geom::box_distance_squared) taken with the root box's
/// coordinates, which bound every node's, so one margin serves the whole tree.
#[derive(Clone, Copy, Debug)]
pub(super) struct DistanceLanes {
    above: [f32; 3],
    below: [f32; 3],
}

impl DistanceLanes {
    #[inline(always)]
    /// The point `p`'s lanes for boxes inside `root`, every box distance lowered by the
    /// rounding of the arithmetic and by `margin` more (per axis).
    pub(super) fn new(p: Vec3, root: &Aabb, margin: f32) -> Self {
        let pad = (root.min.abs().max(root.max.abs()) + p.abs()) * (8.0 * f32::EPSILON) + margin;
        Self {
            above: (p + pad).into(),
            below: (p - pad).into(),
        }
    }
}

/// The squared distances from the query point of `d` to the `K` boxes `bounds` (rows min x,
/// y, z, max x, y, z), each a lower bound of the distance of a triangle inside, into `dist`;
/// returns the mask of lanes nearer than `best`. An empty lane is infinitely far. The query
/// point must be finite.
#[inline(always)]
pub(super) fn box_distance_lanes<const K: usize>(
    bounds: &[[f32; K]; 6],
    d: &DistanceLanes,
    best: f32,
    dist: &mut [f32; K],
) -> u32 {
    if K == 8 {
        let row = |i: usize| -> f32x8 {
            let a: &[f32; 8] = bounds[i].as_slice().try_into().expect("K == 8");
            f32x8::from(*a)
        };
        let gap = |a: usize| {
            let lo = row(a) - f32x8::splat(d.above[a]);
            let hi = f32x8::splat(d.below[a]) - row(a + 3);
            lo.fast_max(hi).fast_max(f32x8::ZERO)
        };
        let (x, y, z) = (gap(0), gap(1), gap(2));
        let d2 = x * x + y * y + z * z;
        dist.as_mut_slice().copy_from_slice(&d2.to_array());
        d2.simd_lt(f32x8::splat(best)).to_bitmask()
    } else if K == 4 {
        let row = |i: usize| -> f32x4 {
            let a: &[f32; 4] = bounds[i].as_slice().try_into().expect("K == 4");
            f32x4::from(*a)
        };
        let gap = |a: usize| {
            let lo = row(a) - f32x4::splat(d.above[a]);
            let hi = f32x4::splat(d.below[a]) - row(a + 3);
            lo.fast_max(hi).fast_max(f32x4::ZERO)
        };
        let (x, y, z) = (gap(0), gap(1), gap(2));
        let d2 = x * x + y * y + z * z;
        dist.as_mut_slice().copy_from_slice(&d2.to_array());
        d2.simd_lt(f32x4::splat(best)).to_bitmask()
    } else {
        let mut mask = 0;
        for i in 0..K {
            let gap = |a: usize| {
                fmax(
                    fmax(bounds[a][i] - d.above[a], d.below[a] - bounds[a + 3][i]),
                    0.0,
                )
            };
            let (x, y, z) = (gap(0), gap(1), gap(2));
            dist[i] = x * x + y * y + z * z;
            mask |= u32::from(dist[i] < best) << i;
        }
        mask
    }
}

/// The mask of the `K` boxes `bounds` (rows min x, y, z, max x, y, z) that share a point with
/// `query`, faces included: lane by lane [`boxes_touch`](crate::bvh::boxes_touch) (a NaN on
/// either side touches nothing; an empty lane touches nothing).
#[inline(always)]
pub(super) fn box_touch_lanes<const K: usize>(bounds: &[[f32; K]; 6], query: &Aabb) -> u32 {
    let (lo, hi) = (query.min.to_array(), query.max.to_array());
    if K == 8 {
        let row = |i: usize| -> f32x8 {
            let a: &[f32; 8] = bounds[i].as_slice().try_into().expect("K == 8");
            f32x8::from(*a)
        };
        let axis = |a: usize| {
            row(a).simd_le(f32x8::splat(hi[a])) & row(a + 3).simd_ge(f32x8::splat(lo[a]))
        };
        (axis(0) & axis(1) & axis(2)).to_bitmask()
    } else if K == 4 {
        let row = |i: usize| -> f32x4 {
            let a: &[f32; 4] = bounds[i].as_slice().try_into().expect("K == 4");
            f32x4::from(*a)
        };
        let axis = |a: usize| {
            row(a).simd_le(f32x4::splat(hi[a])) & row(a + 3).simd_ge(f32x4::splat(lo[a]))
        };
        (axis(0) & axis(1) & axis(2)).to_bitmask()
    } else {
        (0..K).fold(0, |mask, i| {
            let touch = (0..3).all(|a| bounds[a][i] <= hi[a] && bounds[a + 3][i] >= lo[a]);
            mask | u32::from(touch) << i
        })
    }
}

/// A placed mesh's map for carrying its lanes' boxes into the world: the image of a box with
/// centre `c` and half extent `h` under `x ↦ A x + t` lies in the box of centre `A c + t` and
/// half extent `|A| h` (Arvo, "Transforming axis-aligned bounding boxes", Graphics Gems 1990):
/// a sphere's distance to it bounds the placed triangles' where the map's smallest singular
/// value bounds them loosely.
#[derive(Clone, Copy, Debug)]
pub(super) struct PlacedLanes {
    /// `A` by rows, `|A|`, and `t`.
    a: [[f32; 3]; 3],
    abs: [[f32; 3]; 3],
    t: [f32; 3],
}

/// Relative slack of a lane's world box: `2^-18` (64 ulps) of the magnitudes it comes from,
/// several times the rounding of its centre, its extent and the placed vertices (about 10
/// ulps of the same magnitudes together).
const PLACED_SLACK: f32 = 1.0 / 262_144.0;

impl PlacedLanes {
    pub(super) fn new(m: &glam::Affine3A) -> Self {
        let rows = m.matrix3.transpose();
        let row = |i: usize| Vec3::from(rows.col(i)).to_array();
        let a = [row(0), row(1), row(2)];
        Self {
            a,
            abs: a.map(|r| r.map(f32::abs)),
            t: Vec3::from(m.translation).to_array(),
        }
    }

    /// The mask of the lanes whose placed triangles may have a point within `r2` (squared,
    /// inclusive) of `p` as the triangles' closest points compute it: `p`'s distance to each
    /// lane's world box is within `r2`, with `2^-16` of it to spare, once the box is widened
    /// to hold every placed vertex (as `Affine3A::transform_point3` rounds it) of a triangle
    /// inside the lane's mesh-space box and by the rounding of those closest points (8 ulps
    /// of the coordinates involved, twice). An axis whose arithmetic overflows (or an empty
    /// lane's) adds nothing to the distance.
    #[inline(always)]
    pub(super) fn near<const K: usize>(&self, bounds: &[[f32; K]; 6], p: Vec3, r2: f32) -> u32 {
        let p = p.to_array();
        let mut c = [[0f32; K]; 3];
        let mut h = [[0f32; K]; 3];
        for j in 0..3 {
            for k in 0..K {
                c[j][k] = (bounds[j][k] + bounds[j + 3][k]) * 0.5;
                h[j][k] = (bounds[j + 3][k] - bounds[j][k]) * 0.5;
            }
        }
        let mut d2 = [0f32; K];
        for (i, &pi) in p.iter().enumerate() {
            let (a, abs, t) = (self.a[i], self.abs[i], self.t[i]);
            for k in 0..K {
                let centre = t + a[0] * c[0][k] + a[1] * c[1][k] + a[2] * c[2][k];
                let half = abs[0] * h[0][k] + abs[1] * h[1][k] + abs[2] * h[2][k];
                let size = t.abs()
                    + abs[0] * c[0][k].abs()
                    + abs[1] * c[1][k].abs()
                    + abs[2] * c[2][k].abs();
                let reach = half + PLACED_SLACK * (size + half) + f32::MIN_POSITIVE;
                let reach = reach + (pi.abs() + centre.abs() + reach) * (16.0 * f32::EPSILON);
                let gap = ((centre - pi).abs() - reach).max(0.0);
                if gap.is_finite() && reach.is_finite() {
                    d2[k] += gap * gap;
                }
            }
        }
        let reach = r2 * (1.0 + 1.0 / 65_536.0) + f32::MIN_POSITIVE;
        // A sum that overflowed keeps the lane: its true value may still be within `r2`.
        (0..K).fold(0, |mask, k| {
            mask | u32::from(d2[k] <= reach || d2[k] == f32::INFINITY) << k
        })
    }
}

/// The union of a node's `K` child boxes (empty lanes hold the empty box).
#[inline(always)]
pub(super) fn union_lanes<const K: usize>(bounds: &[[f32; K]; 6]) -> Aabb {
    let lo = |i: usize| bounds[i].iter().fold(f32::INFINITY, |m, &v| fmin(m, v));
    let hi = |i: usize| bounds[i].iter().fold(f32::NEG_INFINITY, |m, &v| fmax(m, v));
    Aabb::new(
        Vec3::new(lo(0), lo(1), lo(2)),
        Vec3::new(hi(3), hi(4), hi(5)),
    )
}

/// Four triangles as structure of arrays: rows `v0.x, v0.y, v0.z, v1.x, .., v2.z`, one lane
/// per triangle, and each lane's triangle index. Unused lanes hold NaN, which the triangle test
/// never hits, and the index [`NO_PRIM`](super::NO_PRIM).
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Zeroable)]
pub struct TriBlock {
    /// The nine coordinate rows.
    pub rows: [[f32; 4]; 9],
    /// The triangle index of each lane (in the mesh's order).
    pub prims: [u32; 4],
}

impl TriBlock {
    /// A block of four unused lanes.
    pub const EMPTY: Self = Self {
        rows: [[f32::NAN; 4]; 9],
        prims: [super::NO_PRIM; 4],
    };

    /// The triangle in lane `l`.
    #[must_use]
    #[inline(always)]
    pub fn get(&self, l: usize) -> [Vec3; 3] {
        let r = &self.rows;
        let v = |j: usize| Vec3::new(r[j][l], r[j + 1][l], r[j + 2][l]);
        [v(0), v(3), v(6)]
    }

    /// Puts a triangle into lane `l`.
    #[inline(always)]
    pub fn set(&mut self, l: usize, t: &[Vec3; 3]) {
        for (j, v) in t.iter().enumerate() {
            self.rows[3 * j][l] = v.x;
            self.rows[3 * j + 1][l] = v.y;
            self.rows[3 * j + 2][l] = v.z;
        }
    }
}

/// Per-ray constants of the four-wide watertight triangle test: the rows holding each vertex's
/// permuted coordinates, and the shear of [`RayTriPrecomp`].
#[derive(Clone, Copy, Debug)]
pub(super) struct TriLanes {
    k: [usize; 3],
    origin: [f32; 3],
    shear: [f32; 3],
    tmin: f32,
}

impl TriLanes {
    #[inline(always)]
    pub(super) fn new(ray: &Ray) -> Self {
        // The same permutation and shear as `RayTriPrecomp::new`, on arrays (see
        // `RayLanes::new`).
        let d = ray.dir.to_array();
        let o = ray.origin.to_array();
        let a = ray.dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = 1.0 / d[kz];
        Self {
            k: [kx, ky, kz],
            origin: [o[kx], o[ky], o[kz]],
            shear: [d[kx] * sz, d[ky] * sz, sz],
            tmin: ray.tmin,
        }
    }

    /// The scalar test's constants for the same ray (its rare fallback), from these.
    #[inline(always)]
    pub(super) fn precomp(&self) -> RayTriPrecomp {
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.shear;
        RayTriPrecomp {
            kx,
            ky,
            kz,
            sx,
            sy,
            sz,
        }
    }
}

/// The outcome of testing a block.
pub(super) enum BlockHit {
    /// No lane is hit closer than `tmax`.
    None,
    /// Lane `.0` is hit at `t = .1` with barycentrics `.2`, `.3`: the nearest, and the first
    /// lane among equally near ones.
    Hit(usize, f32, f32, f32),
    /// Some edge function is exactly zero, or a scaled distance overflows: the caller must use
    /// the scalar test (which redoes such edges and distances in f64) on every lane, in order.
    Scalar,
}

/// Every lane of a block hit closer than `tmax`.
pub(super) enum BlockHits {
    /// No lane is hit closer than `tmax`.
    None,
    /// The lanes in `mask` (bit `l` for lane `l`) are hit, lane `l` at `t[l]` with
    /// barycentrics `u[l]`, `v[l]`.
    Lanes {
        mask: u32,
        t: [f32; 4],
        u: [f32; 4],
        v: [f32; 4],
    },
    /// Some edge function is exactly zero: as [`BlockHit::Scalar`].
    Scalar,
}

/// The watertight test of [`intersect_triangle`](crate::geom::intersect_triangle) on four
/// triangles at once, lane by lane the same operations in the same order, so every distance and
/// barycentric is bit for bit the scalar test's: every lane hit closer than `tmax`.
#[inline(always)]
pub(super) fn intersect4_all(b: &TriBlock, r: &TriLanes, tmax: f32) -> BlockHits {
    let row = |i: usize| f32x4::from(b.rows[i]);
    let o = |a: usize| f32x4::splat(r.origin[a]);
    let [kx, ky, kz] = r.k;
    let (sx, sy, sz) = (
        f32x4::splat(r.shear[0]),
        f32x4::splat(r.shear[1]),
        f32x4::splat(r.shear[2]),
    );
    // Vertex j translated to the ray origin, then sheared: (x, y) and the unsheared z.
    let vert = |j: usize| {
        let px = row(3 * j + kx) - o(0);
        let py = row(3 * j + ky) - o(1);
        let pz = row(3 * j + kz) - o(2);
        (px - sx * pz, py - sy * pz, pz)
    };
    let (ax, ay, az) = vert(0);
    let (bx, by, bz) = vert(1);
    let (cx, cy, cz) = vert(2);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    let zero = f32x4::ZERO;
    if (u.simd_eq(zero) | v.simd_eq(zero) | w.simd_eq(zero)).to_bitmask() != 0 {
        return BlockHits::Scalar;
    }
    // No edge function is zero here, so the scalar test's "some negative and some positive"
    // is "the sign bits differ" (a lane with a NaN one has a NaN determinant, rejected below).
    let mixed = ((u ^ v) | (u ^ w)).to_bitmask();
    let det = u + v + w;
    let bad_det = (det.simd_eq(zero) | !det.is_finite()).to_bitmask();
    // No lane inside its triangle: nothing below could be kept (the division is skipped).
    if !(mixed | bad_det) & 0xF == 0 {
        return BlockHits::None;
    }
    let t_scaled = u * (sz * az) + v * (sz * bz) + w * (sz * cz);
    let rcp = f32x4::splat(1.0) / det;
    let t = t_scaled * rcp;
    let in_range = (t.simd_ge(f32x4::splat(r.tmin)) & t.simd_lt(f32x4::splat(tmax))).to_bitmask();
    // A scaled distance that is not a normal f32 (overflowed or underflowed) is redone in f64
    // by the scalar test, as `scaled_t_in_range` decides.
    let a = t_scaled.abs();
    let normal =
        a.simd_ge(f32x4::splat(f32::MIN_POSITIVE)) & a.simd_lt(f32x4::splat(f32::INFINITY));
    if (!normal).to_bitmask() & !mixed & !bad_det != 0 {
        return BlockHits::Scalar;
    }
    let mask = in_range & !mixed & !bad_det;
    if mask == 0 {
        return BlockHits::None;
    }
    BlockHits::Lanes {
        mask,
        t: t.to_array(),
        u: (v * rcp).to_array(),
        v: (w * rcp).to_array(),
    }
}

/// The nearest lane of a block hit closer than `tmax` ([`intersect4_all`]'s nearest, the
/// first lane among equally near ones).
#[inline(always)]
pub(super) fn intersect4(b: &TriBlock, r: &TriLanes, tmax: f32) -> BlockHit {
    match intersect4_all(b, r, tmax) {
        BlockHits::None => BlockHit::None,
        BlockHits::Scalar => BlockHit::Scalar,
        BlockHits::Lanes { mut mask, t, u, v } => {
            let mut best = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            while mask != 0 {
                let l = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if t[l] < t[best] {
                    best = l;
                }
            }
            BlockHit::Hit(best, t[best], u[best], v[best])
        }
    }
}

/// The box of the triangles in `blocks`, skipping NaN coordinates (`if p < lo { p } else { lo }`
/// never keeps a NaN `p`). Unused lanes are all NaN and so add nothing.
#[inline(always)]
pub(super) fn bound_lanes(blocks: &[TriBlock]) -> Aabb {
    let mut lo = [f32x4::splat(f32::INFINITY); 3];
    let mut hi = [f32x4::splat(f32::NEG_INFINITY); 3];
    for b in blocks {
        for j in 0..3 {
            for a in 0..3 {
                let p = f32x4::from(b.rows[3 * j + a]);
                lo[a] = p.simd_lt(lo[a]).select(p, lo[a]);
                hi[a] = p.simd_gt(hi[a]).select(p, hi[a]);
            }
        }
    }
    let lo = lo.map(|v| v.to_array().into_iter().fold(f32::INFINITY, fmin));
    let hi = hi.map(|v| v.to_array().into_iter().fold(f32::NEG_INFINITY, fmax));
    Aabb::new(Vec3::from(lo), Vec3::from(hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (xorshift), to avoid a dependency in unit tests.
    fn next(s: &mut u64) -> f32 {
        *s ^= *s << 13;
        *s ^= *s >> 7;
        *s ^= *s << 17;
        (*s >> 40) as f32 / (1u64 << 24) as f32
    }

    /// The scalar fallback's constants taken from the lanes are those the scalar test computes
    /// itself, for directions of every sign, with ties and zero components.
    #[test]
    fn precomp_from_the_lanes_is_the_scalar_tests() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut dirs = vec![
            Vec3::X,
            -Vec3::Y,
            Vec3::Z,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(0.0, -0.0, 2.0),
        ];
        for _ in 0..1000 {
            let mut r = || next(&mut s) * 2.0 - 1.0;
            dirs.push(Vec3::new(r(), r(), r()));
        }
        let key = |p: RayTriPrecomp| (p.kx, p.ky, p.kz, [p.sx, p.sy, p.sz].map(f32::to_bits));
        for d in dirs {
            let ray = Ray::new(Vec3::new(0.5, -2.0, 3.0), d);
            let a = TriLanes::new(&ray).precomp();
            assert_eq!(key(a), key(RayTriPrecomp::new(d)), "{d}");
        }
    }

    /// The four-lane watertight test answers lane by lane as the scalar test does, bit for bit,
    /// whenever it does not hand the block to the scalar test: triangles around the ray, on
    /// it, through its origin, and with NaN, infinite, huge and tiny corners.
    #[test]
    fn intersect4_all_is_the_scalar_test_lane_by_lane() {
        use crate::geom::intersect_triangle;
        let mut s = 0x2f0d_8b31_c4a7_e965u64;
        let odd = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            1e30,
            -1e-30,
            3e12,
        ];
        let (mut hits, mut blocks) = (0, 0);
        for i in 0..40_000 {
            let mut r = || next(&mut s) * 2.0 - 1.0;
            let mut d = Vec3::new(r(), r(), r());
            if i % 9 == 0 {
                d.z = 0.0;
            }
            let mut ray = Ray::new(Vec3::new(r(), r(), r()), d);
            ray.tmin = if i % 3 == 0 { 0.0 } else { r().abs() * 0.3 };
            let tmax = if i % 4 == 0 {
                f32::INFINITY
            } else {
                r().abs() * 3.0
            };
            let mut b = TriBlock::EMPTY;
            for l in 0..4 {
                if i % 13 == l {
                    continue;
                }
                let on = ray.origin + ray.dir * (r() * 3.0);
                let mut t = [0; 3].map(|_| on + Vec3::new(r(), r(), r()) * 0.5);
                if i % 7 == l {
                    let k = ((r() + 1.0) * 4.5) as usize % 9;
                    t[k / 3][k % 3] = odd[((r() + 1.0) * 3.5) as usize % 7];
                }
                b.set(l, &t);
                b.prims[l] = l as u32;
            }
            let lanes = TriLanes::new(&ray);
            let pre = lanes.precomp();
            let (mask, t, u, v) = match intersect4_all(&b, &lanes, tmax) {
                BlockHits::Scalar => continue,
                BlockHits::None => (0, [0.0; 4], [0.0; 4], [0.0; 4]),
                BlockHits::Lanes { mask, t, u, v } => (mask, t, u, v),
            };
            blocks += 1;
            for l in 0..4 {
                let [p, q, c] = b.get(l);
                let want = intersect_triangle(&ray, &pre, p, q, c, tmax);
                assert_eq!(mask >> l & 1 == 1, want.is_some(), "ray {i} lane {l}");
                if let Some((wt, wu, wv)) = want {
                    let bits = |x: [f32; 3]| x.map(f32::to_bits);
                    assert_eq!(
                        bits([t[l], u[l], v[l]]),
                        bits([wt, wu, wv]),
                        "ray {i} lane {l}"
                    );
                    hits += 1;
                }
            }
        }
        assert!(blocks > 30_000 && hits > 5_000, "{blocks} {hits}");
    }

    /// A lane whose placed triangle has its computed closest point within a sphere is kept by
    /// the world-space lane test, with the centre on a triangle's very corner or beside it and
    /// the radius that very distance, under maps that turn, shear, mirror and scale unevenly,
    /// at scales from 1e-20 to 1e20; and the test does prune.
    #[test]
    fn placed_lanes_keep_every_lane_whose_placed_triangle_is_near() {
        use crate::geom::closest_point_on_triangle;
        const K: usize = 8;
        let mut s = 0x7f4a_7c15_9e37_79b9u64;
        let mut pruned = 0;
        for round in 0..3000 {
            let scale = [1e-20f32, 1e-3, 1.0, 1e3, 1e20][round % 5];
            let r = |s: &mut u64| next(s) * 2.0 - 1.0;
            let col = |s: &mut u64| Vec3::new(r(s), r(s), r(s)) * 2.0;
            let m = glam::Affine3A::from_cols(
                col(&mut s).into(),
                col(&mut s).into(),
                col(&mut s).into(),
                (col(&mut s) * scale * 4.0).into(),
            );
            let tris: Vec<[Vec3; 3]> = (0..K)
                .map(|_| {
                    let c = col(&mut s) * scale;
                    let size = scale * next(&mut s).powi(3);
                    [(); 3].map(|()| c + col(&mut s) * size)
                })
                .collect();
            let mut bounds = [[0f32; K]; 6];
            for (k, t) in tris.iter().enumerate() {
                let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
                for a in 0..3 {
                    bounds[a][k] = lo[a];
                    bounds[a + 3][k] = hi[a];
                }
            }
            let lanes = PlacedLanes::new(&m);
            let placed: Vec<[Vec3; 3]> = tris
                .iter()
                .map(|t| t.map(|v| m.transform_point3(v)))
                .collect();
            // The query at one placed triangle's corner, or a point beside it.
            let k = (next(&mut s) * K as f32) as usize % K;
            let corner = placed[k][(next(&mut s) * 3.0) as usize % 3];
            let p = if round % 2 == 0 {
                corner
            } else {
                corner + col(&mut s) * scale * 0.1
            };
            let r2 = closest_point_on_triangle(p, placed[k][0], placed[k][1], placed[k][2])
                .distance_squared(p);
            let near = lanes.near(&bounds, p, r2);
            for (l, t) in placed.iter().enumerate() {
                if closest_point_on_triangle(p, t[0], t[1], t[2]).distance_squared(p) <= r2 {
                    assert!(near & 1 << l != 0, "round {round}: lane {l} dropped");
                }
            }
            pruned += (!near & 0xff).count_ones();
        }
        assert!(pruned > 5_000, "the lane test prunes little: {pruned}");
    }

    /// The lanes' box test is the scalar `boxes_touch` lane by lane, on 4 and 8 lanes and the
    /// generic loop: boxes that overlap, touch at a face or corner (coordinates on a coarse
    /// grid, so faces meet exactly), miss, are empty, infinite or NaN.
    #[test]
    fn box_touch_lanes_is_the_scalar_test_lane_by_lane() {
        fn check<const K: usize>(s: &mut u64) {
            let coord = |s: &mut u64| match (next(s) * 16.0) as u32 {
                0 => f32::NAN,
                1 => f32::INFINITY,
                2 => f32::NEG_INFINITY,
                _ => (next(s) * 8.0).floor(),
            };
            let boxed = |s: &mut u64| {
                let (a, b) = (
                    Vec3::new(coord(s), coord(s), coord(s)),
                    Vec3::new(coord(s), coord(s), coord(s)),
                );
                // Mostly ordered corners, sometimes inverted (empty).
                if next(s) < 0.8 {
                    Aabb::new(a.min(b), a.max(b))
                } else {
                    Aabb::new(a, b)
                }
            };
            let mut touched = 0;
            for _ in 0..2000 {
                let query = boxed(s);
                let lanes: Vec<Aabb> = (0..K).map(|_| boxed(s)).collect();
                let mut bounds = [[0f32; K]; 6];
                for (k, b) in lanes.iter().enumerate() {
                    for a in 0..3 {
                        bounds[a][k] = b.min[a];
                        bounds[a + 3][k] = b.max[a];
                    }
                }
                let want = lanes.iter().enumerate().fold(0, |m, (k, b)| {
                    m | u32::from(crate::bvh::boxes_touch(b, &query)) << k
                });
                assert_eq!(
                    box_touch_lanes(&bounds, &query),
                    want,
                    "{lanes:?} {query:?}"
                );
                touched += want.count_ones();
            }
            assert!(touched > 100, "too few boxes touch: {touched}");
        }
        let mut s = 0x51a3_07c2_9e44_b16du64;
        check::<8>(&mut s);
        check::<4>(&mut s);
        check::<2>(&mut s);
    }

    /// `slab_fma` accepts every box the plain test accepts, for rays from far and near origins
    /// aimed at box corners, edges and faces (where rounding decides), at every scale.
    #[test]
    fn fma_slab_accepts_what_the_plain_test_accepts() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut checked = 0;
        for scale in [1e-20f32, 1e-3, 1.0, 1e3, 1e12] {
            for _ in 0..20_000 {
                let mut r = || next(&mut s) * 2.0 - 1.0;
                let c = Vec3::new(r(), r(), r()) * scale;
                let h = Vec3::new(r().abs(), r().abs(), r().abs()) * scale * 0.1;
                let b = Aabb::new(c - h, c + h);
                // A point on the box's surface (a corner, an edge or a face) as the target.
                let pick = |v: f32, lo: f32, hi: f32| {
                    if v < -0.3 {
                        lo
                    } else if v > 0.3 {
                        hi
                    } else {
                        lo + (hi - lo) * (v + 0.5)
                    }
                };
                let target = Vec3::new(
                    pick(r(), b.min.x, b.max.x),
                    pick(r(), b.min.y, b.max.y),
                    pick(r(), b.min.z, b.max.z),
                );
                let o = c + Vec3::new(r(), r(), r()) * scale * (1.0 + 1e4 * r().abs());
                let ray = Ray::new(o, target - o);
                let lanes = RayLanes::new(&ray);
                if !lanes.fma_ok(scale * 4.0) {
                    continue;
                }
                let mut bounds = [[f32::INFINITY; 8]; 6];
                for (i, v) in [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z]
                    .into_iter()
                    .enumerate()
                {
                    bounds[i][3] = v;
                }
                for row in bounds.iter_mut().skip(3) {
                    for (k, v) in row.iter_mut().enumerate() {
                        if k != 3 {
                            *v = f32::NEG_INFINITY;
                        }
                    }
                }
                let mut d = [0f32; 8];
                let plain = slab(&bounds, &lanes, ray.tmax, &mut d);
                let fma = slab_fma(&bounds, &lanes, ray.tmax, &mut d);
                assert_eq!(plain & !0b1000, 0);
                assert_eq!(fma & !0b1000, 0, "an empty lane passed");
                if ray.hit_box(b.min, b.max, ray.tmax).is_some() {
                    assert_eq!(fma, 0b1000, "missed {b:?} from {o:?} to {target:?}");
                    checked += 1;
                }
            }
        }
        assert!(checked > 50_000, "{checked}");
    }
}
