//! Packet traversal: up to [`MAX_PACKET`] coherent rays walk the binary tree together.
//!
//! - **First active ray** (Wald, Boulos & Shirley 2007): each node on the stack carries the
//!   index of the first ray that may still need it; a node is entered when some ray from that
//!   one on hits its box (16 rays per SIMD test), and its children inherit that index.
//! - **Interval arithmetic**: the packet's origins and reciprocal directions are bounded per
//!   axis; a node that no ray's slab interval can overlap (or that lies beyond every ray's
//!   `tmax`) is skipped with one test. Rounding is monotone, so the bounds hold for every ray.
//! - The triangle test is [`crate::geom::intersect_triangle`]'s watertight one, 16 rays at once
//!   ([`crate::simd::packet`]): a packet's hits are exactly the single-ray (and brute-force) hits.
//! - Rays that are not coherent (directions spread wider than [`COHERENT_COS`], or fewer than
//!   [`MIN_PACKET`] rays) are traced one by one, which is faster for them.

use super::{Bvh, MAX_DEPTH, MeshBvh, Node};
use crate::geom::{FAR_SCALE, Hit, Ray, RayTriPrecomp, intersect_triangle};
use crate::simd::packet::{LANES, RayLanes};
use crate::simd::prefetch;
use glam::{Vec3, Vec3A};
use wide::f32x16 as F;

/// Most rays in one packet (one bit each in a [`Mask`]).
pub const MAX_PACKET: usize = 128;
/// A bit per ray of a packet.
pub type Mask = u128;
/// Fewer rays than this are traced one by one.
pub const MIN_PACKET: usize = 4;
/// A packet whose unit directions are not all within this cosine of their mean direction
/// (about 25 degrees) is traced one ray at a time.
pub const COHERENT_COS: f32 = 0.9;
/// Width of the image tiles [`MeshBvh::trace_image_closest`] makes packets of.
pub const TILE_W: usize = 16;
/// Height of the image tiles [`MeshBvh::trace_image_closest`] makes packets of.
pub const TILE_H: usize = 8;

/// The first `K` (at most 8) values of a row of a wide node, padded with NaN.
#[inline(always)]
pub(crate) fn row8<const K: usize>(r: &[f32; K]) -> wide::f32x8 {
    let mut a = [f32::NAN; 8];
    a[..K].copy_from_slice(r);
    wide::f32x8::from(a)
}

/// Calls `f` with the pixel indices of each tile of a `width` x `height` image (row-major
/// pixels), tile by tile ([`TILE_W`] x [`TILE_H`], smaller at the right and bottom edges), each
/// tile's pixels in 4x4 blocks so that every 16-ray SIMD group of a packet is a compact square.
pub fn image_tiles(width: usize, height: usize, mut f: impl FnMut(&[usize])) {
    let mut idx = Vec::with_capacity(TILE_W * TILE_H);
    for ty in (0..height).step_by(TILE_H) {
        for tx in (0..width).step_by(TILE_W) {
            idx.clear();
            let (ye, xe) = ((ty + TILE_H).min(height), (tx + TILE_W).min(width));
            for by in (ty..ye).step_by(4) {
                for bx in (tx..xe).step_by(4) {
                    for y in by..(by + 4).min(ye) {
                        for x in bx..(bx + 4).min(xe) {
                            idx.push(y * width + x);
                        }
                    }
                }
            }
            f(&idx);
        }
    }
}

const GROUPS: usize = MAX_PACKET / LANES;
/// What an inactive lane holds.
const IDLE: Ray = Ray {
    origin: Vec3::ZERO,
    dir: Vec3::X,
    inv_dir: Vec3::ONE,
    slab_lo: Vec3::ZERO,
    slab_hi: Vec3::ZERO,
    tmin: 0.0,
    tmax: f32::NEG_INFINITY,
};
/// All bits set: a true lane of a vector mask.
const TRUE_BITS: f32 = f32::from_bits(u32::MAX);
const LEAF_IA: bool = false;
/// A subtree that at most this many rays of a packet still need is walked ray by ray.
const SINGLE_BELOW: u32 = 4;

/// Whether the packet queries trace a group of rays as a packet.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PacketMode {
    /// As a packet when it is coherent ([`RayPacket::is_coherent`]), else ray by ray.
    #[default]
    Auto,
    /// Always as a packet, coherent or not (for tests and measurements).
    Always,
}

impl PacketMode {
    /// Whether the rays just loaded into `p` go as a packet.
    #[inline]
    pub(crate) fn use_packet(self, p: &RayPacket) -> bool {
        match self {
            PacketMode::Auto => p.is_coherent(),
            PacketMode::Always => !p.is_empty(),
        }
    }
}

/// True when `rays` are worth tracing as a packet: at least [`MIN_PACKET`] of them, all unit
/// directions within [`COHERENT_COS`] of their mean. Cheap next to tracing them.
#[must_use]
pub fn is_coherent(rays: &[Ray]) -> bool {
    if rays.len() < MIN_PACKET {
        return false;
    }
    let mean = rays
        .iter()
        .map(|r| r.dir.normalize_or_zero())
        .sum::<Vec3>()
        .normalize_or_zero();
    mean != Vec3::ZERO
        && rays
            .iter()
            .all(|r| r.dir.normalize_or_zero().dot(mean) >= COHERENT_COS)
}

/// Up to [`MAX_PACKET`] rays in SIMD form, with what traversal learns about them.
#[derive(Clone, Debug)]
pub struct RayPacket {
    n: usize,
    lanes: [RayLanes; GROUPS],
    rays: [Ray; MAX_PACKET],
    /// Rays still traversing (any hit clears a ray's bit at its first hit).
    active: Mask,
    /// The `(kx, ky, kz)` of the watertight test when every ray shares it.
    uniform: Option<[usize; 3]>,
    /// Per-axis bounds of the origins and reciprocal directions of the rays. With a zero
    /// direction component among them (an infinite reciprocal) the
    /// interval test is skipped: its corner products could be `0 * inf`.
    o_lo: Vec3A,
    o_hi: Vec3A,
    i_lo: Vec3A,
    i_hi: Vec3A,
    tmin_lo: f32,
    /// Largest `tmax` of an active ray.
    tmax_hi: f32,
    /// Sum of the unit directions: orders children near to far.
    dir: Vec3,
    /// Rays whose closest hit has been found so far, with its slot and barycentrics.
    found: Mask,
    /// What [`RayPacket::is_coherent`] answers for the loaded rays.
    coherent: bool,
    /// Per group: the slot (as the bits of an f32), and the barycentrics.
    slot: [F; GROUPS],
    u: [F; GROUPS],
    v: [F; GROUPS],
}

impl Default for RayPacket {
    fn default() -> Self {
        Self::new()
    }
}

impl RayPacket {
    /// An empty packet (load rays with [`RayPacket::load`]).
    #[must_use]
    pub fn new() -> Self {
        Self {
            n: 0,
            lanes: [RayLanes::default(); GROUPS],
            rays: [Ray::new(Vec3::ZERO, Vec3::X); MAX_PACKET],
            active: 0,
            uniform: None,
            o_lo: Vec3A::ZERO,
            o_hi: Vec3A::ZERO,
            i_lo: Vec3A::ZERO,
            i_hi: Vec3A::ZERO,
            tmin_lo: 0.0,
            tmax_hi: 0.0,
            dir: Vec3::ZERO,
            found: 0,
            coherent: false,
            slot: [F::splat(0.0); GROUPS],
            u: [F::splat(0.0); GROUPS],
            v: [F::splat(0.0); GROUPS],
        }
    }

    /// Number of rays loaded.
    #[must_use]
    pub fn len(&self) -> usize {
        self.n
    }

    /// True when no ray is loaded.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Loads `rays` (at most [`MAX_PACKET`]); every ray becomes active with no hit.
    ///
    /// # Panics
    /// When there are more than [`MAX_PACKET`] rays.
    pub fn load(&mut self, rays: &[Ray]) {
        assert!(
            rays.len() <= MAX_PACKET,
            "at most {MAX_PACKET} rays a packet"
        );
        let n = rays.len();
        let all = if n == MAX_PACKET {
            Mask::MAX
        } else {
            ((1 as Mask) << n) - 1
        };
        self.load_with(n, all, |i| rays[i]);
    }

    /// Loads the rays of the mask `which` among `n` lanes, ray `i` being `ray(i)`; the other
    /// lanes are left inactive.
    ///
    /// Sixteen rays at a time: each group's rays are copied in and read back as rows, and the
    /// watertight test's per-ray constants (the same operations as [`RayTriPrecomp::new`], so
    /// the same bits), the packet's bounds, its direction and its coherence are computed on
    /// whole vectors.
    // The loops index the packet's rays, the lane masks and the unit directions together.
    #[allow(clippy::needless_range_loop)]
    pub(crate) fn load_with(&mut self, n: usize, which: Mask, mut ray: impl FnMut(usize) -> Ray) {
        debug_assert!(n <= MAX_PACKET);
        self.n = n;
        self.active = which;
        self.found = 0;
        let inf = F::splat(f32::INFINITY);
        let ninf = F::splat(f32::NEG_INFINITY);
        let zero = F::splat(0.0);
        let (mut o_lo, mut o_hi) = ([inf; 3], [ninf; 3]);
        let (mut i_lo, mut i_hi) = ([inf; 3], [ninf; 3]);
        let (mut tmin_lo, mut tmax_hi) = (inf, ninf);
        let mut dir_sum = [zero; 3];
        let mut units = [[zero; 3]; GROUPS];
        // Per row of `RayLanes::k`: some active lane has it set, some has it clear.
        let (mut k_set, mut k_clear) = ([false; 6], [false; 6]);
        let groups = n.div_ceil(LANES);
        for g in 0..groups {
            let bits = (which >> (g * LANES)) as u32 & 0xFFFF;
            // The group's rays (an idle ray in inactive lanes) and the mask of active lanes.
            let mut on = [0f32; LANES];
            for l in 0..LANES {
                let i = g * LANES + l;
                if bits >> l & 1 == 0 {
                    self.rays[i] = IDLE;
                } else {
                    self.rays[i] = ray(i);
                    on[l] = TRUE_BITS;
                }
            }
            // Then the rows, one field of the group's 16 rays each (built in registers: cheaper
            // than storing each ray's fields lane by lane into rows).
            let rays: &[Ray; LANES] = self.rays[g * LANES..(g + 1) * LANES]
                .try_into()
                .expect("a group");
            let col = |f: &dyn Fn(&Ray) -> f32| F::from(std::array::from_fn(|l| f(&rays[l])));
            let on = F::from(on);
            let o = [
                col(&|r| r.origin.x),
                col(&|r| r.origin.y),
                col(&|r| r.origin.z),
            ];
            let d = [col(&|r| r.dir.x), col(&|r| r.dir.y), col(&|r| r.dir.z)];
            // The slab test's origins are the origin's own except on an axis the ray does not
            // move along (`Ray::derive`), and the reciprocal is `1 / d` (`+inf` for a zero `d`),
            // the same bits as the rays hold, computed here rather than gathered; an idle lane
            // keeps `IDLE`'s.
            let still = (d[0].simd_eq(zero) | d[1].simd_eq(zero) | d[2].simd_eq(zero)) & on;
            let (slab_lo, slab_hi) = if still.any() {
                (
                    [
                        col(&|r| r.slab_lo.x),
                        col(&|r| r.slab_lo.y),
                        col(&|r| r.slab_lo.z),
                    ],
                    [
                        col(&|r| r.slab_hi.x),
                        col(&|r| r.slab_hi.y),
                        col(&|r| r.slab_hi.z),
                    ],
                )
            } else {
                (o, o)
            };
            let one = F::splat(1.0);
            let inv = d.map(|c| on.select(c.simd_eq(zero).select(inf, one / c), one));
            let tmin_row = col(&|r| r.tmin);
            let tmax_row = col(&|r| r.tmax);
            // The watertight test's axes (`RayTriPrecomp::new`): kz the largest |d| (the first
            // on ties), kx and ky the next ones, swapped when d[kz] is negative.
            let (ax, ay, az) = (d[0].abs(), d[1].abs(), d[2].abs());
            let kz0 = ax.simd_ge(ay) & ax.simd_ge(az);
            let kz1 = !kz0 & ay.simd_ge(az);
            let kz2 = !(kz0 | kz1);
            let pick = |is0: F, is1: F, v: &[F; 3]| is0.select(v[0], is1.select(v[1], v[2]));
            let dkz = pick(kz0, kz1, &d);
            let neg = dkz.simd_lt(zero);
            let kx0 = (kz2 & !neg) | (kz1 & neg);
            let kx1 = (kz0 & !neg) | (kz2 & neg);
            let ky0 = (kz1 & !neg) | (kz2 & neg);
            let ky1 = (kz2 & !neg) | (kz0 & neg);
            let sz = F::splat(1.0) / dkz;
            let lanes = &mut self.lanes[g];
            lanes.slab_lo = slab_lo;
            lanes.slab_hi = slab_hi;
            lanes.inv = inv;
            lanes.tmin = tmin_row;
            lanes.tmax = tmax_row;
            lanes.ok = [pick(kx0, kx1, &o), pick(ky0, ky1, &o), pick(kz0, kz1, &o)];
            lanes.s = [pick(kx0, kx1, &d) * sz, pick(ky0, ky1, &d) * sz, sz];
            lanes.k = [kx0, kx1, ky0, ky1, kz0, kz1];
            for (j, k) in lanes.k.iter().enumerate() {
                let m = k.to_bitmask() & bits;
                k_set[j] |= m != 0;
                k_clear[j] |= m != bits;
            }
            // Bounds over the active lanes.
            for a in 0..3 {
                o_lo[a] = o_lo[a].fast_min(on.select(o[a], inf));
                o_hi[a] = o_hi[a].fast_max(on.select(o[a], ninf));
                i_lo[a] = i_lo[a].fast_min(on.select(inv[a], inf));
                i_hi[a] = i_hi[a].fast_max(on.select(inv[a], ninf));
            }
            tmin_lo = tmin_lo.fast_min(on.select(lanes.tmin, inf));
            tmax_hi = tmax_hi.fast_max(on.select(lanes.tmax, ninf));
            // Unit directions (zero for a zero or non-finite length).
            let rcp = F::splat(1.0) / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let ok = on & rcp.is_finite() & rcp.simd_gt(zero);
            let u = d.map(|c| ok.select(c * rcp, zero));
            for a in 0..3 {
                dir_sum[a] += u[a];
            }
            units[g] = u;
        }
        let lo = |v: F| v.to_array().into_iter().fold(f32::INFINITY, f32::min);
        let hi = |v: F| v.to_array().into_iter().fold(f32::NEG_INFINITY, f32::max);
        self.o_lo = Vec3A::from(o_lo.map(lo));
        self.o_hi = Vec3A::from(o_hi.map(hi));
        self.i_lo = Vec3A::from(i_lo.map(lo));
        self.i_hi = Vec3A::from(i_hi.map(hi));
        self.tmin_lo = lo(tmin_lo);
        self.tmax_hi = hi(tmax_hi);
        let dir = Vec3::from(dir_sum.map(F::reduce_add));
        self.dir = dir;
        self.uniform = (which != 0 && (0..6).all(|j| !(k_set[j] && k_clear[j]))).then(|| {
            let axis = |j: usize| {
                if k_set[2 * j] {
                    0
                } else if k_set[2 * j + 1] {
                    1
                } else {
                    2
                }
            };
            [axis(0), axis(1), axis(2)]
        });
        // Coherent: enough rays, all unit directions within `COHERENT_COS` of their mean.
        let mean = dir.normalize_or_zero();
        self.coherent = which.count_ones() as usize >= MIN_PACKET && mean != Vec3::ZERO && {
            let (mx, my, mz) = (F::splat(mean.x), F::splat(mean.y), F::splat(mean.z));
            let cos = F::splat(COHERENT_COS);
            (0..groups).all(|g| {
                let [ux, uy, uz] = units[g];
                let bits = (which >> (g * LANES)) as u32 & 0xFFFF;
                let dot = ux * mx + uy * my + uz * mz;
                dot.simd_ge(cos).to_bitmask() & bits == bits
            })
        };
    }

    /// True when the loaded rays are worth tracing as a packet: at least [`MIN_PACKET`] of
    /// them, all unit directions within [`COHERENT_COS`] of their mean (the test of
    /// [`is_coherent`], computed on vectors when the rays are loaded).
    #[must_use]
    pub fn is_coherent(&self) -> bool {
        self.coherent
    }

    /// The current `tmax` of ray `i`: its closest hit so far, or its own `tmax`.
    #[inline]
    pub(crate) fn tmax(&self, i: usize) -> f32 {
        self.lanes[i / LANES].tmax.as_array()[i % LANES]
    }

    pub(crate) fn update_tmax_hi(&mut self) {
        let mut hi = wide::f32x16::splat(f32::NEG_INFINITY);
        for l in &self.lanes[..self.n.div_ceil(LANES)] {
            hi = hi.fast_max(l.tmax);
        }
        // Lanes past `n` hold stale values: they only make the bound looser.
        self.tmax_hi = hi
            .as_array()
            .iter()
            .fold(f32::NEG_INFINITY, |a, &b| a.max(b));
    }

    /// Interval-arithmetic test: false when no ray of the packet can touch the box.
    #[inline(always)]
    fn may_hit(&self, n: &Node) -> bool {
        self.may_hit_box(n.min, n.max)
    }

    /// [`RayPacket::may_hit`] of the box `[bmin, bmax]`.
    #[inline(always)]
    fn may_hit_box(&self, bmin: [f32; 3], bmax: [f32; 3]) -> bool {
        if !self.interval_ok() {
            return true;
        }
        let bmin = Vec3A::from(bmin);
        let bmax = Vec3A::from(bmax);
        let corners = |d_lo: Vec3A, d_hi: Vec3A| {
            let a = d_lo * self.i_lo;
            let b = d_lo * self.i_hi;
            let c = d_hi * self.i_lo;
            let d = d_hi * self.i_hi;
            (a.min(b).min(c.min(d)), a.max(b).max(c.max(d)))
        };
        let (t0_lo, t0_hi) = corners(bmin - self.o_hi, bmin - self.o_lo);
        let (t1_lo, t1_hi) = corners(bmax - self.o_hi, bmax - self.o_lo);
        let near = t0_lo.min(t1_lo).max_element().max(self.tmin_lo);
        let far = t0_hi.max(t1_hi).min_element().min(self.tmax_hi) * FAR_SCALE;
        near <= far
    }

    /// The interval test of [`RayPacket::may_hit`] on `K` boxes at once (rows min x, y, z, max
    /// x, y, z; one lane per box): bit `k` is clear when no ray of the packet can touch box `k`.
    /// All `K` bits are set when the test cannot be used ([`RayPacket::interval_ok`]). An empty box
    /// (min `+inf`, max `-inf`) may keep its bit: callers mask empty lanes themselves.
    #[inline(always)]
    pub(crate) fn may_hit_lanes<const K: usize>(&self, b: &[[f32; K]; 6]) -> u32 {
        use wide::f32x8;
        if !self.interval_ok() {
            return (1 << K) - 1;
        }
        let (o_lo, o_hi) = (self.o_lo.to_array(), self.o_hi.to_array());
        let (i_lo, i_hi) = (self.i_lo.to_array(), self.i_hi.to_array());
        let mut near = f32x8::splat(self.tmin_lo);
        let mut far = f32x8::splat(self.tmax_hi);
        for a in 0..3 {
            let (ol, oh) = (f32x8::splat(o_lo[a]), f32x8::splat(o_hi[a]));
            let (il, ih) = (f32x8::splat(i_lo[a]), f32x8::splat(i_hi[a]));
            // Corner products of (plane - origin) and the reciprocal, both as intervals. The
            // minima and maxima keep the second operand on NaN, as `if a < b { a } else { b }`.
            let span = |p: f32x8| {
                let (d_lo, d_hi) = (p - oh, p - ol);
                let (w, x) = (d_lo * il, d_lo * ih);
                let (y, z) = (d_hi * il, d_hi * ih);
                (
                    w.fast_min(x).fast_min(y.fast_min(z)),
                    w.fast_max(x).fast_max(y.fast_max(z)),
                )
            };
            let (t0_lo, t0_hi) = span(row8(&b[a]));
            let (t1_lo, t1_hi) = span(row8(&b[3 + a]));
            near = near.fast_max(t0_lo.fast_min(t1_lo));
            far = far.fast_min(t0_hi.fast_max(t1_hi));
        }
        // A NaN keeps the box.
        let culled = near.simd_gt(far * f32x8::splat(FAR_SCALE)).to_bitmask();
        !culled & ((1 << K) - 1)
    }

    /// Sum of the rays' unit directions.
    #[inline(always)]
    pub(crate) fn dir(&self) -> Vec3 {
        self.dir
    }

    /// True when the interval test may be used: every reciprocal direction is finite.
    #[inline(always)]
    pub(crate) fn interval_ok(&self) -> bool {
        self.i_lo.is_finite() && self.i_hi.is_finite()
    }

    /// Index of the first ray of `live` whose slab test touches the box.
    #[inline(always)]
    fn first_hit(&self, n: &Node, live: Mask) -> Option<u8> {
        self.first_hit_box(n.min, n.max, live, true)
    }

    /// Index of the first ray of `live` whose slab test touches the box `[bmin, bmax]`; with
    /// `cull`, the interval test may reject the box after the first live ray's group missed.
    #[inline(always)]
    pub(crate) fn first_hit_box(
        &self,
        bmin: [f32; 3],
        bmax: [f32; 3],
        live: Mask,
        cull: bool,
    ) -> Option<u8> {
        let mut g = live.trailing_zeros() as usize / LANES;
        // The group of the first live ray usually hits: test it before anything else.
        let bits = (live >> (g * LANES)) as u32 & 0xFFFF;
        let m = self.lanes[g].hit_box(bmin, bmax) & bits;
        if m != 0 {
            return Some((g * LANES) as u8 + m.trailing_zeros() as u8);
        }
        // Then cull the node for the whole packet before testing the other groups.
        if cull && !self.may_hit_box(bmin, bmax) {
            return None;
        }
        g += 1;
        while g < GROUPS {
            let rest = live >> (g * LANES);
            if rest == 0 {
                break;
            }
            let bits = rest as u32 & 0xFFFF;
            if bits != 0 {
                let m = self.lanes[g].hit_box(bmin, bmax) & bits;
                if m != 0 {
                    return Some((g * LANES) as u8 + m.trailing_zeros() as u8);
                }
            }
            g += 1;
        }
        None
    }

    /// Every ray of `live` whose slab test touches the box.
    #[inline(always)]
    fn hit_mask(&self, n: &Node, live: Mask) -> Mask {
        self.hit_mask_box(n.min, n.max, live)
    }

    /// Every ray of `live` whose slab test touches the box `[bmin, bmax]`.
    #[inline(always)]
    pub(crate) fn hit_mask_box(&self, bmin: [f32; 3], bmax: [f32; 3], live: Mask) -> Mask {
        let mut mask: Mask = 0;
        let mut g = live.trailing_zeros() as usize / LANES;
        while g < GROUPS && live >> (g * LANES) != 0 {
            let bits = (live >> (g * LANES)) as u32 & 0xFFFF;
            if bits != 0 {
                mask |= Mask::from(self.lanes[g].hit_box(bmin, bmax) & bits) << (g * LANES);
            }
            g += 1;
        }
        mask
    }

    /// Tests triangle `tri` (in leaf slot `slot`) against the rays of `rays`. Closest hit
    /// (`ANY == false`): shortens each ray that hits it and records the hit; returns true when
    /// some ray was shortened. Any hit: retires the rays that hit it.
    #[inline(always)]
    pub(crate) fn test_triangle<const ANY: bool>(
        &mut self,
        tri: &[Vec3; 3],
        slot: u32,
        rays: Mask,
    ) -> bool {
        let uniform = self.uniform.map(|k| RayLanes::permute_uniform(tri, k));
        let mut changed = false;
        for g in 0..GROUPS {
            let bits = (rays >> (g * LANES)) as u32 & 0xFFFF;
            if bits == 0 {
                if rays >> (g * LANES) == 0 {
                    break;
                }
                continue;
            }
            let lanes = &mut self.lanes[g];
            let perm = match &uniform {
                Some(p) => *p,
                None => lanes.permute(tri),
            };
            let h = lanes.hit_triangle(&perm, bits);
            if h.hit != 0 {
                changed = true;
                if ANY {
                    self.active &= !(Mask::from(h.hit) << (g * LANES));
                } else if h.exact {
                    lanes.tmax = h.mask.select(h.t, lanes.tmax);
                    self.u[g] = h.mask.select(h.u, self.u[g]);
                    self.v[g] = h.mask.select(h.v, self.v[g]);
                    let s = F::splat(f32::from_bits(slot));
                    self.slot[g] = h.mask.select(s, self.slot[g]);
                    self.found |= Mask::from(h.hit) << (g * LANES);
                } else {
                    let mut hit = h.hit;
                    while hit != 0 {
                        let l = hit.trailing_zeros() as usize;
                        hit &= hit - 1;
                        self.record(
                            g,
                            l,
                            slot,
                            (h.t.as_array()[l], h.u.as_array()[l], h.v.as_array()[l]),
                        );
                    }
                }
            }
            let mut redo = h.redo;
            while redo != 0 {
                let l = redo.trailing_zeros() as usize;
                redo &= redo - 1;
                let i = g * LANES + l;
                let r = &self.rays[i];
                let pre = RayTriPrecomp::new(r.dir);
                let tmax = self.lanes[g].tmax.as_array()[l];
                if let Some((t, u, v)) = intersect_triangle(r, &pre, tri[0], tri[1], tri[2], tmax) {
                    if ANY {
                        self.active &= !((1 as Mask) << i);
                    } else {
                        self.record(g, l, slot, (t, u, v));
                    }
                    changed = true;
                }
            }
        }
        changed
    }
}

impl RayPacket {
    /// Records a closest hit `(t, u, v)` in `slot` for lane `l` of group `g`.
    #[inline]
    pub(crate) fn record(&mut self, g: usize, l: usize, slot: u32, (t, u, v): (f32, f32, f32)) {
        self.lanes[g].tmax.as_mut_array()[l] = t;
        self.found |= (1 as Mask) << (g * LANES + l);
        self.slot[g].as_mut_array()[l] = f32::from_bits(slot);
        self.u[g].as_mut_array()[l] = u;
        self.v[g].as_mut_array()[l] = v;
    }

    /// What a packet's closest-hit traversal found for ray `i`: `(t, u, v, slot)`.
    #[inline]
    pub(crate) fn closest(&self, i: usize) -> Option<(f32, f32, f32, u32)> {
        let (g, l) = (i / LANES, i % LANES);
        (self.found >> i & 1 != 0).then(|| {
            (
                self.tmax(i),
                self.u[g].as_array()[l],
                self.v[g].as_array()[l],
                self.slot[g].as_array()[l].to_bits(),
            )
        })
    }

    /// True when ray `i` found a hit (any-hit traversal).
    #[inline]
    pub(crate) fn occluded(&self, i: usize) -> bool {
        i < self.n && self.active >> i & 1 == 0
    }

    /// Sets the `tmax` of ray `i` (e.g. to the best hit found in another tree); the traversal
    /// refreshes its bounds when the leaf callback that did this returns true.
    #[inline]
    pub(crate) fn set_tmax(&mut self, i: usize, t: f32) {
        self.lanes[i / LANES].tmax.as_mut_array()[i % LANES] = t;
    }

    /// Rays that found a closest hit.
    #[inline]
    pub(crate) fn found(&self) -> Mask {
        self.found
    }

    /// Marks every ray of `done` as finished (any-hit).
    #[inline]
    pub(crate) fn retire(&mut self, done: Mask) {
        self.active &= !done;
    }

    /// Rays still active.
    #[inline]
    pub(crate) fn active(&self) -> Mask {
        self.active
    }

    /// Ray `i` as loaded.
    #[inline]
    pub(crate) fn ray(&self, i: usize) -> &Ray {
        &self.rays[i]
    }
}

impl Bvh {
    /// Walks the tree with the packet's active rays. `leaf(packet, slot, rays)` tests the
    /// primitive in `slot` for the rays of the mask `rays` (all hit the leaf's box); closest hit
    /// (`ANY == false`): it shortens rays' `tmax` and returns true when it did; any hit: it
    /// retires rays ([`RayPacket::retire`]), and traversal stops once every ray is retired.
    pub(crate) fn traverse_packet<const ANY: bool>(
        &self,
        p: &mut RayPacket,
        prefetch_leaf: impl Fn(usize),
        mut leaf: impl FnMut(&mut RayPacket, usize, Mask) -> bool,
    ) {
        let nodes = self.nodes.as_slice();
        if nodes.is_empty() || p.active == 0 {
            return;
        }
        let mut stack = [(0u32, 0u8); MAX_DEPTH + 2];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let (ni, first) = stack[sp];
            let live = p.active & (Mask::MAX << first);
            if live == 0 {
                continue;
            }
            let node = &nodes[ni as usize];
            if node.is_leaf() {
                if LEAF_IA && !p.may_hit(node) {
                    continue;
                }
                let rays = p.hit_mask(node, live);
                if rays == 0 {
                    continue;
                }
                let mut changed = false;
                for slot in node.first as usize..(node.first + node.count) as usize {
                    let rays = rays & p.active;
                    if rays == 0 {
                        break;
                    }
                    changed |= leaf(p, slot, rays);
                }
                if ANY {
                    if p.active == 0 {
                        return;
                    }
                } else if changed {
                    p.update_tmax_hi();
                }
            } else {
                if live.count_ones() <= SINGLE_BELOW {
                    // Too few rays left for the packet to pay: each goes on alone.
                    let mut changed = false;
                    let mut bits = live;
                    while bits != 0 {
                        let i = bits.trailing_zeros() as usize;
                        bits &= bits - 1;
                        changed |= self.walk_single::<ANY>(p, i, ni, &mut leaf);
                    }
                    if ANY {
                        if p.active == 0 {
                            return;
                        }
                    } else if changed {
                        p.update_tmax_hi();
                    }
                    continue;
                }
                let Some(f) = p.first_hit(node, live) else {
                    continue;
                };
                let l = &nodes[node.first as usize];
                let r = &nodes[node.first as usize + 1];
                // Start loading the grandchildren (and the leaves' primitives) now: the walk is
                // bound by memory latency on large trees.
                // A pair of 32-byte nodes may straddle two cache lines: fetch both halves.
                for c in [l, r] {
                    if c.is_leaf() {
                        prefetch_leaf(c.first as usize);
                        prefetch_leaf((c.first + c.count - 1) as usize);
                    } else if let Some(n) = nodes.get(c.first as usize..c.first as usize + 2) {
                        prefetch(&n[0]);
                        prefetch(&n[1]);
                    }
                }
                // The child whose centre lies further along the packet's direction is the far one.
                let cl = Vec3::from(l.min) + Vec3::from(l.max);
                let cr = Vec3::from(r.min) + Vec3::from(r.max);
                let (near, far) = if (cr - cl).dot(p.dir) >= 0.0 {
                    (node.first, node.first + 1)
                } else {
                    (node.first + 1, node.first)
                };
                stack[sp] = (far, f);
                stack[sp + 1] = (near, f);
                sp += 2;
            }
        }
    }
}

impl Bvh {
    /// Walks the subtree at `root` with ray `i` of the packet alone, as a single ray walks the
    /// tree (both children tested, the nearer first, the farther skipped when it starts beyond
    /// the ray's closest hit); leaves go to `leaf` with that ray's bit. Returns true when `leaf`
    /// did.
    fn walk_single<const ANY: bool>(
        &self,
        p: &mut RayPacket,
        i: usize,
        root: u32,
        leaf: &mut impl FnMut(&mut RayPacket, usize, Mask) -> bool,
    ) -> bool {
        let bit = (1 as Mask) << i;
        let ray = p.rays[i];
        let tmax = p.tmax(i);
        let mut changed = false;
        // `leaf` keeps the lane's closest hit (and its `tmax`) in the packet; the walk only
        // needs to hear that it moved, or for any-hit that the lane is done.
        self.traverse_from::<ANY>(
            root as usize,
            &ray,
            tmax,
            |slot, _| {
                let c = leaf(p, slot, bit);
                changed |= c;
                if ANY {
                    (p.active & bit == 0).then_some(0.0)
                } else {
                    c.then(|| p.tmax(i))
                }
            },
            &mut (),
        );
        changed
    }
}

thread_local! {
    /// Packets kept per thread between calls of the packet queries.
    static SPARE: std::cell::RefCell<Vec<Box<RayPacket>>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// Runs `f` with one of this thread's spare packets (a new one when none is spare: the first
/// time, and the first time calls nest one level deeper, as the engine's world and instance
/// packets do): setting up the 20 KiB of a packet costs about 2% of tracing 128 rays.
pub(crate) fn with_packet<R>(f: impl FnOnce(&mut RayPacket) -> R) -> R {
    let mut p = SPARE
        .with(|s| s.borrow_mut().pop())
        .unwrap_or_else(|| Box::new(RayPacket::new()));
    let r = f(&mut p);
    SPARE.with(|s| s.borrow_mut().push(p));
    r
}

/// The loop every tree's packet closest-hit query shares: `rays` in packets of up to
/// [`MAX_PACKET`], each traced by `packet` when `mode` says so (its hits' slots turned into
/// triangle indices by `prim`), else ray by ray by `single`.
pub(crate) fn packets_closest(
    rays: &[Ray],
    hits: &mut [Option<Hit>],
    mode: PacketMode,
    packet: impl Fn(&mut RayPacket),
    prim: impl Fn(u32) -> u32,
    single: impl Fn(&Ray) -> Option<Hit>,
) {
    assert_eq!(rays.len(), hits.len(), "one output per ray");
    with_packet(|p| {
        for (r, h) in rays.chunks(MAX_PACKET).zip(hits.chunks_mut(MAX_PACKET)) {
            p.load(r);
            if mode.use_packet(p) {
                packet(p);
                for (i, h) in h.iter_mut().enumerate() {
                    *h = p.closest(i).map(|(t, u, v, slot)| Hit {
                        t,
                        u,
                        v,
                        prim: prim(slot),
                    });
                }
            } else {
                for (r, h) in r.iter().zip(h) {
                    *h = single(r);
                }
            }
        }
    });
}

/// The any-hit twin of [`packets_closest`].
pub(crate) fn packets_any(
    rays: &[Ray],
    out: &mut [bool],
    mode: PacketMode,
    packet: impl Fn(&mut RayPacket),
    single: impl Fn(&Ray) -> bool,
) {
    assert_eq!(rays.len(), out.len(), "one output per ray");
    with_packet(|p| {
        for (r, o) in rays.chunks(MAX_PACKET).zip(out.chunks_mut(MAX_PACKET)) {
            p.load(r);
            if mode.use_packet(p) {
                packet(p);
                for (i, o) in o.iter_mut().enumerate() {
                    *o = p.occluded(i);
                }
            } else {
                for (r, o) in r.iter().zip(o) {
                    *o = single(r);
                }
            }
        }
    });
}

/// The rays of an image given row by row (`width` rays a row) in tiles ([`image_tiles`]), each
/// tile's rays gathered and answered by `trace`; `out[i]` answers `rays[i]`.
///
/// # Panics
/// When the lengths differ, or `rays` is not a whole number of rows of `width`.
pub(crate) fn trace_tiles<T: Copy + Default>(
    rays: &[Ray],
    width: usize,
    out: &mut [T],
    mut trace: impl FnMut(&[Ray], &mut [T]),
) {
    assert_eq!(rays.len(), out.len(), "one output per ray");
    if rays.is_empty() {
        return;
    }
    assert!(
        width > 0 && rays.len().is_multiple_of(width),
        "rows of {width} rays"
    );
    let mut buf = Vec::with_capacity(MAX_PACKET);
    let mut res = vec![T::default(); MAX_PACKET];
    image_tiles(width, rays.len() / width, |idx| {
        buf.clear();
        buf.extend(idx.iter().map(|&i| rays[i]));
        trace(&buf, &mut res[..buf.len()]);
        for (&i, r) in idx.iter().zip(&res) {
            out[i] = *r;
        }
    });
}

impl MeshBvh {
    /// Closest hits of `rays` (`hits[i]` for `rays[i]`), traced as packets of up to
    /// [`MAX_PACKET`] consecutive rays: give coherent rays next to each other (e.g. a 16x8 tile
    /// of a camera image; [`MeshBvh::trace_image_closest`] does the tiling). Exactly the hits of
    /// [`MeshBvh::closest_hit`]; packets that are not coherent are traced ray by ray.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn closest_hit_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.closest_hit_packet_mode(rays, hits, PacketMode::Auto);
    }

    /// [`MeshBvh::closest_hit_packet`], choosing when to trace packets by `mode`.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn closest_hit_packet_mode(
        &self,
        rays: &[Ray],
        hits: &mut [Option<Hit>],
        mode: PacketMode,
    ) {
        packets_closest(
            rays,
            hits,
            mode,
            |p| self.closest_packet(p),
            |slot| self.bvh.prim_indices()[slot as usize],
            |r| self.closest_hit(r),
        );
    }

    /// Any-hit answers of `rays` (`out[i]` for `rays[i]`), as packets of up to [`MAX_PACKET`]
    /// consecutive rays; exactly the answers of [`MeshBvh::any_hit`].
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn any_hit_packet(&self, rays: &[Ray], out: &mut [bool]) {
        self.any_hit_packet_mode(rays, out, PacketMode::Auto);
    }

    /// [`MeshBvh::any_hit_packet`], choosing when to trace packets by `mode`.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn any_hit_packet_mode(&self, rays: &[Ray], out: &mut [bool], mode: PacketMode) {
        packets_any(rays, out, mode, |p| self.any_packet(p), |r| self.any_hit(r));
    }

    /// Closest hits of a camera image's rays given row by row (`width` rays a row), traced as
    /// packets of [`TILE_W`] x [`TILE_H`] pixels ([`image_tiles`]). `hits[i]` answers `rays[i]`.
    ///
    /// # Panics
    /// When the lengths differ, or `rays` is not a whole number of rows of `width`.
    pub fn trace_image_closest(&self, rays: &[Ray], width: usize, hits: &mut [Option<Hit>]) {
        trace_tiles(rays, width, hits, |r, h| self.closest_hit_packet(r, h));
    }

    /// Any-hit answers of an image's rays given row by row, as packets of [`TILE_W`] x
    /// [`TILE_H`] pixels (e.g. shadow rays from the points the camera rays hit).
    ///
    /// # Panics
    /// When the lengths differ, or `rays` is not a whole number of rows of `width`.
    pub fn trace_image_any(&self, rays: &[Ray], width: usize, out: &mut [bool]) {
        trace_tiles(rays, width, out, |r, o| self.any_hit_packet(r, o));
    }

    /// Packet closest-hit traversal of the loaded rays, each from its current `tmax`; hits are
    /// recorded in the packet (slots of this tree).
    pub(crate) fn closest_packet(&self, p: &mut RayPacket) {
        let tris = self.tris.as_slice();
        let pf = |slot: usize| {
            if let Some(t) = tris.get(slot) {
                prefetch(t);
            }
        };
        self.bvh.traverse_packet::<false>(p, pf, |p, slot, rays| {
            p.test_triangle::<false>(&tris[slot], slot as u32, rays)
        });
    }

    /// Packet any-hit traversal: retires every ray that hits something.
    pub(crate) fn any_packet(&self, p: &mut RayPacket) {
        let tris = self.tris.as_slice();
        let pf = |slot: usize| {
            if let Some(t) = tris.get(slot) {
                prefetch(t);
            }
        };
        self.bvh.traverse_packet::<true>(p, pf, |p, slot, rays| {
            p.test_triangle::<true>(&tris[slot], slot as u32, rays)
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rows a packet computes from its rays' directions (the reciprocal, the slab test's
    /// origins) are bit for bit the fields each ray holds, for every kind of component, and an
    /// idle lane of a loaded group holds `IDLE`'s.
    #[test]
    fn loaded_rows_are_the_rays_fields() {
        let comps = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            3.0e-39,
            -1.0e-45,
            1.0e30,
            -7.5,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.3,
        ];
        let origins = [-2.5, 0.0, 1.0e-40, 17.0, f32::NAN];
        let mut rays = Vec::new();
        for (i, &x) in comps.iter().enumerate() {
            for (j, &y) in comps.iter().enumerate() {
                let z = comps[(i + 2 * j) % comps.len()];
                let o = Vec3::new(origins[i % 5], origins[j % 5], origins[(i + j) % 5]);
                rays.push(Ray::with_range(o, Vec3::new(x, y, z), 0.25, 9.0));
            }
        }
        let mut p = RayPacket::new();
        for chunk in rays.chunks(100) {
            p.load(chunk);
            // Groups past the last loaded ray are not touched.
            for i in 0..chunk.len().div_ceil(LANES) * LANES {
                let want = chunk.get(i).unwrap_or(&IDLE);
                let lanes = &p.lanes[i / LANES];
                let l = i % LANES;
                let bits = |v: &F| v.as_array()[l].to_bits();
                for a in 0..3 {
                    assert_eq!(bits(&lanes.inv[a]), want.inv_dir[a].to_bits(), "{want:?}");
                    assert_eq!(
                        bits(&lanes.slab_lo[a]),
                        want.slab_lo[a].to_bits(),
                        "{want:?}"
                    );
                    assert_eq!(
                        bits(&lanes.slab_hi[a]),
                        want.slab_hi[a].to_bits(),
                        "{want:?}"
                    );
                }
                assert_eq!(bits(&lanes.tmin), want.tmin.to_bits());
                assert_eq!(bits(&lanes.tmax), want.tmax.to_bits());
            }
        }
    }
}
