//! Packet traversal of the wide tree: up to [`MAX_PACKET`](crate::bvh::MAX_PACKET) coherent
//! rays walk a [`WideBvh`] together, as they walk the binary tree in `crate::bvh::packet`.
//!
//! - An interior node is expanded once for the packet: one interval-arithmetic test of the
//!   packet's ray bounds against all `K` child boxes culls the children no ray can reach; the
//!   others go on the stack ordered by the packet's mean direction.
//! - A stack entry is a child lane with the index of the first ray that may still need it
//!   (first-active-ray traversal); when popped, its box is tested against the rays from that
//!   one on (16 rays per SIMD test) with their current `tmax`.
//! - A leaf's triangle blocks are tested against the rays whose slab test touches its box,
//!   with the watertight 16-ray kernel (bit for bit the single-ray test's distances), or by
//!   each of those rays alone with the 4-triangle kernel when they are few (on fine meshes,
//!   most leaves: a triangle covers a few rays of a packet at most).
//! - A subtree that at most [`SINGLE_BELOW`] rays still need is walked by each of them alone;
//!   packets that are not coherent are traced ray by ray.

use super::lanes::TriLanes;
use super::traverse::{BIG_STACK, SMALL_STACK};
use super::{EMPTY_CHILD, LEAF_BIT, NO_PRIM, WideBvh, leaf_range};
use crate::bvh::packet::{
    Mask, PacketMode, RayPacket, packets_any, packets_closest, row8, trace_tiles,
};
use crate::geom::{Hit, Ray};
use crate::simd::packet::LANES;
use wide::f32x8;

/// A subtree, or a leaf, that at most this many rays of a packet still need is walked ray by
/// ray.
const SINGLE_BELOW: u32 = 4;

/// A pending child: its reference, its parent node, its lane there, and the first ray that may
/// need it.
type Entry = (u32, u32, u8, u8);

impl<const K: usize> WideBvh<K> {
    /// Closest hits of `rays` (`hits[i]` for `rays[i]`), traced as packets of up to
    /// [`MAX_PACKET`](crate::bvh::MAX_PACKET) consecutive rays: give coherent rays next to each other (e.g. a 16x8 tile
    /// of a camera image; [`WideBvh::trace_image_closest`] does the tiling). Exactly the hits of
    /// [`WideBvh::closest_hit`]; packets that are not coherent are traced ray by ray.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn closest_hit_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        self.closest_hit_packet_mode(rays, hits, PacketMode::Auto);
    }

    /// [`WideBvh::closest_hit_packet`], choosing when to trace packets by `mode`.
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
            |slot| self.slot_prim(slot),
            |r| self.closest_hit(r),
        );
    }

    /// Any-hit answers of `rays` (`out[i]` for `rays[i]`), as packets of up to [`MAX_PACKET`](crate::bvh::MAX_PACKET)
    /// consecutive rays; exactly the answers of [`WideBvh::any_hit`].
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn any_hit_packet(&self, rays: &[Ray], out: &mut [bool]) {
        self.any_hit_packet_mode(rays, out, PacketMode::Auto);
    }

    /// [`WideBvh::any_hit_packet`], choosing when to trace packets by `mode`.
    ///
    /// # Panics
    /// When the lengths differ.
    pub fn any_hit_packet_mode(&self, rays: &[Ray], out: &mut [bool], mode: PacketMode) {
        packets_any(rays, out, mode, |p| self.any_packet(p), |r| self.any_hit(r));
    }

    /// Closest hits of a camera image's rays given row by row (`width` rays a row), traced as
    /// packets of [`TILE_W`](crate::bvh::TILE_W) x [`TILE_H`](crate::bvh::TILE_H) pixels
    /// ([`image_tiles`](crate::bvh::image_tiles)). `hits[i]` answers `rays[i]`.
    ///
    /// # Panics
    /// When the lengths differ, or `rays` is not a whole number of rows of `width`.
    pub fn trace_image_closest(&self, rays: &[Ray], width: usize, hits: &mut [Option<Hit>]) {
        trace_tiles(rays, width, hits, |r, h| self.closest_hit_packet(r, h));
    }

    /// Any-hit answers of an image's rays given row by row, as packets of
    /// [`TILE_W`](crate::bvh::TILE_W) x [`TILE_H`](crate::bvh::TILE_H) pixels.
    ///
    /// # Panics
    /// When the lengths differ, or `rays` is not a whole number of rows of `width`.
    pub fn trace_image_any(&self, rays: &[Ray], width: usize, out: &mut [bool]) {
        trace_tiles(rays, width, out, |r, o| self.any_hit_packet(r, o));
    }

    /// The triangle index of a packet hit's slot (`4 * block + lane`).
    #[inline]
    pub(crate) fn slot_prim(&self, slot: u32) -> u32 {
        self.blocks[slot as usize / 4].prims[slot as usize % 4]
    }

    /// Packet closest-hit traversal of the loaded rays, each from its current `tmax`; hits are
    /// recorded in the packet (slot `4 * block + lane`).
    pub(crate) fn closest_packet(&self, p: &mut RayPacket) {
        if self.stack_need < SMALL_STACK - 1 {
            self.traverse_packet::<false, SMALL_STACK>(p);
        } else {
            self.traverse_packet::<false, BIG_STACK>(p);
        }
    }

    /// Packet any-hit traversal: retires every ray that hits something.
    pub(crate) fn any_packet(&self, p: &mut RayPacket) {
        if self.stack_need < SMALL_STACK - 1 {
            self.traverse_packet::<true, SMALL_STACK>(p);
        } else {
            self.traverse_packet::<true, BIG_STACK>(p);
        }
    }

    /// Pushes the children of node `ni` that some ray from `first` on may reach (the interval
    /// test), the one furthest along the packet's direction first (so the nearest is on top),
    /// and prefetches them.
    #[inline(always)]
    fn expand(&self, p: &RayPacket, ni: u32, first: u8, stack: &mut [Entry], sp: &mut usize) {
        let node = &self.nodes[ni as usize];
        let mut mask = p.may_hit_lanes(&node.bounds);
        for k in 0..K {
            if node.child[k] == EMPTY_CHILD {
                mask &= !(1 << k);
            }
        }
        // Twice each box centre, along the packet's direction.
        let d = p.dir();
        let b = &node.bounds;
        let c = |a: usize| row8(&b[a]) + row8(&b[3 + a]);
        let key = (c(0) * f32x8::splat(d.x) + c(1) * f32x8::splat(d.y) + c(2) * f32x8::splat(d.z))
            .to_array();
        let base = *sp;
        while mask != 0 {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let e = (node.child[k], ni, k as u8, first);
            self.prefetch(e.0);
            // Insertion by key, largest at the bottom.
            let mut j = *sp;
            while j > base && key[stack[j - 1].2 as usize] < key[k] {
                stack[j] = stack[j - 1];
                j -= 1;
            }
            stack[j] = e;
            *sp += 1;
        }
    }

    /// Walks the tree with the packet's active rays; closest hit (`ANY == false`) records each
    /// ray's nearest hit in the packet, any hit retires the rays that hit something.
    fn traverse_packet<const ANY: bool, const N: usize>(&self, p: &mut RayPacket) {
        let nodes = self.nodes.as_slice();
        if nodes.is_empty() || p.active() == 0 {
            return;
        }
        let mut stack: [Entry; N] = [(0, 0, 0, 0); N];
        let mut sp = 0;
        // Hits lower the packet's largest `tmax`, which only the interval tests of interior
        // nodes read: it is brought up to date there, not after every leaf.
        let mut stale = false;
        self.expand(p, 0, 0, &mut stack, &mut sp);
        while sp > 0 {
            sp -= 1;
            let (c, parent, lane, first) = stack[sp];
            let live = p.active() & (Mask::MAX << first);
            if live == 0 {
                continue;
            }
            let pb = &nodes[parent as usize].bounds;
            let k = lane as usize;
            let (bmin, bmax) = (
                [pb[0][k], pb[1][k], pb[2][k]],
                [pb[3][k], pb[4][k], pb[5][k]],
            );
            if c & LEAF_BIT != 0 {
                let rays = p.hit_mask_box(bmin, bmax, live);
                if rays == 0 {
                    continue;
                }
                // Few rays: each tests the blocks alone, which costs less than the packet
                // kernel's lanes left idle.
                let changed = if rays.count_ones() <= SINGLE_BELOW {
                    self.each_alone::<ANY, N>(p, rays, c)
                } else {
                    self.leaf_packet::<ANY>(p, rays, c)
                };
                if settle::<ANY>(p, changed, &mut stale) {
                    return;
                }
            } else {
                if stale {
                    p.update_tmax_hi();
                    stale = false;
                }
                if live.count_ones() <= SINGLE_BELOW {
                    // Too few rays left for the packet to pay: each goes on alone.
                    let changed = self.each_alone::<ANY, N>(p, live, c);
                    if settle::<ANY>(p, changed, &mut stale) {
                        return;
                    }
                    continue;
                }
                let Some(f) = p.first_hit_box(bmin, bmax, live, true) else {
                    continue;
                };
                self.expand(p, c, f, &mut stack, &mut sp);
            }
        }
    }

    /// Tests the triangles of leaf `c` against the packet's rays of `rays` (the 16-ray kernel,
    /// one triangle at a time). Returns true when some ray found a (closer) hit.
    fn leaf_packet<const ANY: bool>(&self, p: &mut RayPacket, rays: Mask, c: u32) -> bool {
        let (fb, count) = leaf_range(c);
        let run = fb as usize..(fb + count) as usize;
        let mut changed = false;
        for (b, block) in run.clone().zip(&self.blocks[run]) {
            for l in 0..4 {
                // Unused lanes come last in a block.
                if block.prims[l] == NO_PRIM {
                    break;
                }
                let rays = rays & p.active();
                if rays == 0 {
                    return changed;
                }
                changed |= p.test_triangle::<ANY>(&block.get(l), (b * 4 + l) as u32, rays);
            }
        }
        changed
    }

    /// Each ray of `rays` alone from the child reference `c`: a leaf's blocks (the single-ray
    /// walk's leaf test), or a subtree's single-ray walk, from the ray's current `tmax`; what
    /// a ray finds is recorded in the packet. Returns true when some ray found a (closer) hit.
    fn each_alone<const ANY: bool, const N: usize>(
        &self,
        p: &mut RayPacket,
        rays: Mask,
        c: u32,
    ) -> bool {
        let mut changed = false;
        let mut bits = rays;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let ray = *p.ray(i);
            let found = if c & LEAF_BIT != 0 {
                self.leaf::<ANY, ()>(c, &ray, &TriLanes::new(&ray), p.tmax(i), &mut ())
            } else {
                self.traverse::<ANY, N, { super::traverse::X_DEFAULT }>(c, &ray, p.tmax(i), &mut ())
            };
            let Some((slot, t, u, v)) = found else {
                continue;
            };
            changed = true;
            if ANY {
                p.retire((1 as Mask) << i);
            } else {
                p.record(i / LANES, i % LANES, slot as u32, (t, u, v));
            }
        }
        changed
    }
}

/// After rays found hits: any hit answers whether every ray is done (the walk may stop);
/// closest hit marks the packet's largest `tmax` stale when some ray was shortened.
#[inline(always)]
fn settle<const ANY: bool>(p: &RayPacket, changed: bool, stale: &mut bool) -> bool {
    if ANY {
        p.active() == 0
    } else {
        *stale |= changed;
        false
    }
}
