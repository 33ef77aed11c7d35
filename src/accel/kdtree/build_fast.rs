//! The O(N log N) kd-tree build of Wald & Havran 2006: the events of all triangles are sorted
//! once per axis; at each node one sweep per axis finds the best plane, the triangles are
//! classified left, right or both (a flag per triangle), and the lists are split in order. Only
//! the triangles that straddle the plane get new events, and only on the split axis: a child's
//! cell is its parent's on the other two axes, so there a straddler's box clipped to either
//! child is the one it already had, and its events go to both lists as they are. On the split
//! axis its start stays left and its end right, and it gets an end at the plane on the left and
//! a start there on the right (all at one position, so sorted by triangle alone).
//!
//! With perfect splits a straddler is clipped to each child instead (`clip.rs`): its old
//! events are dropped on every axis, and its new ones, sorted, are merged into each child's
//! lists (section 4.3 and 5.2 of the paper).
//!
//! The lists live in one arena per axis used as a stack: a node's children's lists are
//! written after everything in use, the left subtree is built, then the right, and the arena
//! is cut back to where the children's lists began. After the root's lists nothing is
//! allocated but the arenas' growth.

use super::clip::split_clipped_boxes;
use super::events::{
    BOTH, Event, Kind, LEFT, RIGHT, Split, choose_split, classify, clip_box, event, kind_of,
    push_events, sort_events, sort_events_by_position, tri_of, write_events,
};
use super::{Built, KdNode, KdParams};
use crate::geom::Aabb;
use glam::Vec3;
use std::ops::Range;

/// Builds the tree over the triangles whose boxes are not empty.
pub(super) fn build(tris: &[[Vec3; 3]], boxes: &[Aabb], bounds: &Aabb, params: &KdParams) -> Built {
    let ids: Vec<u32> = (0..boxes.len() as u32)
        .filter(|&i| !boxes[i as usize].is_empty())
        .collect();
    let mut b = Builder::new(tris, boxes, bounds, params, ids.len());
    if ids.is_empty() {
        return b.finish();
    }
    let mut arena: [Arena; 3] = std::array::from_fn(|axis| {
        // The root's events (at most two a triangle) and room for a few levels of children
        // (straddlers add events), zeroed by the allocator (fresh pages) rather than written,
        // on huge pages where the system gives them: one page fault per 2 MiB touched, not
        // per 4 KiB.
        let mut ev = vec![0; 8 * ids.len()];
        crate::simd::advise_huge_vec(&mut ev);
        let mut top = 0;
        for &i in &ids {
            top += write_events(&mut ev[top..], &boxes[i as usize], axis, i);
        }
        let (root, rest) = ev.split_at_mut(top);
        sort_events_by_position(root, rest);
        Arena { ev, top }
    });
    let ranges = std::array::from_fn(|axis| 0..arena[axis].top);
    let mut scratch = Scratch::default();
    crate::simd::reserve_huge(&mut b.nodes, 4 * ids.len(), 0);
    crate::simd::reserve_huge(&mut b.refs, 2 * ids.len(), 0);
    b.nodes.push(KdNode::leaf(0, 0));
    b.node(&mut arena, &mut scratch, 0, *bounds, ranges, ids.len(), 0);
    b.finish()
}

/// One axis's event lists: `ev[..top]` is in use (the lists of the nodes on the path being
/// built), the rest is room, kept initialised so that it is written without growing.
struct Arena {
    ev: Vec<Event>,
    top: usize,
}

impl Arena {
    /// Makes room for `more` events past `top`.
    fn reserve(&mut self, more: usize) {
        let need = self.top + more;
        if self.ev.len() < need {
            self.ev.resize(need.max(2 * self.ev.len()), 0);
        }
    }
}

/// Per-node buffers, reused: the triangles straddling the plane and their new events on the
/// split axis for each child (with perfect splits, on every axis).
#[derive(Default)]
struct Scratch {
    straddlers: Vec<u32>,
    left: Vec<Event>,
    right: Vec<Event>,
    new_left: [Vec<Event>; 3],
    new_right: [Vec<Event>; 3],
    /// The side of each event of the list being split, read once from the triangles' flags.
    sides: Vec<u8>,
}

/// The state shared by the whole build.
pub(super) struct Builder<'a> {
    pub(super) tris: &'a [[Vec3; 3]],
    pub(super) boxes: &'a [Aabb],
    pub(super) params: &'a KdParams,
    pub(super) nodes: Vec<KdNode>,
    pub(super) refs: Vec<u32>,
    /// Each triangle's side at the node being split ([`BOTH`], [`LEFT`], [`RIGHT`]).
    pub(super) side: Vec<u8>,
    pub(super) root_area: f64,
    /// Sum over nodes of area times (1 for interior nodes, count for leaves).
    pub(super) weighted: f64,
    pub(super) depth: usize,
    pub(super) max_depth: usize,
}

impl<'a> Builder<'a> {
    pub(super) fn new(
        tris: &'a [[Vec3; 3]],
        boxes: &'a [Aabb],
        bounds: &Aabb,
        params: &'a KdParams,
        n: usize,
    ) -> Self {
        Self {
            tris,
            boxes,
            params,
            nodes: Vec::new(),
            refs: Vec::new(),
            side: vec![BOTH; boxes.len()],
            root_area: bounds.half_area_f64(),
            weighted: 0.0,
            depth: 0,
            max_depth: params.depth_limit(n),
        }
    }

    pub(super) fn finish(self) -> Built {
        let sah = if self.root_area > 0.0 {
            self.weighted / self.root_area
        } else {
            self.refs.len() as f64
        };
        Built {
            nodes: self.nodes,
            refs: self.refs,
            sah,
            depth: self.depth,
        }
    }

    /// The split to make at a node of `n` triangles, if any.
    pub(super) fn split_for(
        &self,
        events: [&[Event]; 3],
        n: usize,
        cell: &Aabb,
        depth: usize,
    ) -> Option<Split> {
        // A split costs at least one traversal: when that alone is as dear as testing the
        // triangles, no plane can win (always so for one triangle with the default costs).
        let leaf_cost = f64::from(self.params.intersection_cost) * n as f64;
        if depth >= self.max_depth || n == 0 || f64::from(self.params.traversal_cost) >= leaf_cost {
            return None;
        }
        choose_split(events, n, cell, self.params)
    }

    /// With perfect splits, the boxes of straddler `t` in the two children (empty where it
    /// misses the child); where rounding would drop it from both, its box clipped to each.
    pub(super) fn straddler_boxes(&self, t: u32, cell: &Aabb, s: &Split) -> (Aabb, Aabb) {
        let (tri, bx) = (&self.tris[t as usize], &self.boxes[t as usize]);
        let (l, r) = split_clipped_boxes(tri, bx, cell, s.axis, s.pos);
        if l.is_empty() && r.is_empty() {
            let (mut left, mut right) = (*cell, *cell);
            left.max[s.axis] = s.pos;
            right.min[s.axis] = s.pos;
            (clip_box(bx, &left), clip_box(bx, &right))
        } else {
            (l, r)
        }
    }

    /// Makes node `index` a leaf over `tris`.
    pub(super) fn leaf(&mut self, index: usize, cell: &Aabb, tris: impl Iterator<Item = u32>) {
        let first = self.refs.len();
        self.refs.extend(tris);
        let count = self.refs.len() - first;
        self.nodes[index] = KdNode::leaf(first, count);
        self.weighted += cell.half_area_f64() * count as f64;
    }

    /// Makes node `index` an interior node and returns its first child's index.
    pub(super) fn interior(&mut self, index: usize, cell: &Aabb, s: &Split) -> usize {
        let first = self.nodes.len();
        self.nodes.push(KdNode::leaf(0, 0));
        self.nodes.push(KdNode::leaf(0, 0));
        self.nodes[index] = KdNode::interior(s.axis, s.pos, first);
        self.weighted += cell.half_area_f64();
        first
    }

    /// Builds node `index` over the events `arena[axis][ranges[axis]]` of its `n` triangles.
    #[allow(clippy::too_many_arguments)]
    fn node(
        &mut self,
        arena: &mut [Arena; 3],
        scratch: &mut Scratch,
        index: usize,
        cell: Aabb,
        ranges: [Range<usize>; 3],
        n: usize,
        depth: usize,
    ) {
        self.depth = self.depth.max(depth);
        let mark: [usize; 3] = std::array::from_fn(|a| arena[a].top);
        let lists = std::array::from_fn(|a| &arena[a].ev[ranges[a].clone()]);
        let Some(s) = self.split_for(lists, n, &cell, depth) else {
            let tris = lists[0]
                .iter()
                .filter(|&&e| kind_of(e) != Kind::End as usize);
            self.leaf(index, &cell, tris.map(|&e| tri_of(e)));
            return;
        };
        scratch.straddlers.clear();
        let (mut n_left, mut n_right) =
            classify(lists[s.axis], &s, &mut self.side, &mut scratch.straddlers);
        let (mut left_cell, mut right_cell) = (cell, cell);
        left_cell.max[s.axis] = s.pos;
        right_cell.min[s.axis] = s.pos;

        let (left_ranges, right_ranges) = if scratch.straddlers.is_empty() && n_right == 0 {
            // An empty cut on the right: the left child has the node's lists as they are.
            (ranges.clone(), Default::default())
        } else if scratch.straddlers.is_empty() && n_left == 0 {
            (Default::default(), ranges.clone())
        } else if self.params.perfect_at(n) {
            // Every straddler is clipped to each child and gets new events on every axis there
            // (none where it misses the child); its old events are dropped.
            for a in 0..3 {
                scratch.new_left[a].clear();
                scratch.new_right[a].clear();
            }
            for &t in &scratch.straddlers {
                let (l, r) = self.straddler_boxes(t, &cell, &s);
                n_left -= usize::from(l.is_empty());
                n_right -= usize::from(r.is_empty());
                for a in 0..3 {
                    if !l.is_empty() {
                        push_events(&mut scratch.new_left[a], &l, a, t);
                    }
                    if !r.is_empty() {
                        push_events(&mut scratch.new_right[a], &r, a, t);
                    }
                }
            }
            let mut left_ranges: [Range<usize>; 3] = Default::default();
            let mut right_ranges: [Range<usize>; 3] = Default::default();
            for a in 0..3 {
                sort_events(&mut scratch.new_left[a]);
                sort_events(&mut scratch.new_right[a]);
                let (l, r) = split_perfect(
                    &mut arena[a],
                    ranges[a].clone(),
                    &self.side,
                    &mut scratch.sides,
                    [&scratch.new_left[a], &scratch.new_right[a]],
                );
                left_ranges[a] = l;
                right_ranges[a] = r;
            }
            (left_ranges, right_ranges)
        } else {
            // Triangles in both children: the straddlers' new events on the split axis, at the
            // plane, sorted by triangle.
            scratch.straddlers.sort_unstable();
            scratch.left.clear();
            scratch.right.clear();
            for &t in &scratch.straddlers {
                scratch.left.push(event(s.pos, Kind::End, t));
                scratch.right.push(event(s.pos, Kind::Start, t));
            }
            // On the split axis the lists are sorted by position, so the left child's events
            // (before the plane, ends at it, flat ones at it when they go left) come first.
            let at_plane = if s.planar_left {
                Kind::Start
            } else {
                Kind::Planar
            };
            let first_right = event(s.pos, at_plane, 0);
            let cut = lists[s.axis].partition_point(|&e| e < first_right);
            let mut left_ranges: [Range<usize>; 3] = Default::default();
            let mut right_ranges: [Range<usize>; 3] = Default::default();
            for a in 0..3 {
                let (l, r) = if a == s.axis {
                    split_at_plane(
                        &mut arena[a],
                        ranges[a].clone(),
                        cut,
                        [&scratch.left, &scratch.right],
                    )
                } else {
                    split_by_side(
                        &mut arena[a],
                        ranges[a].clone(),
                        &self.side,
                        &mut scratch.sides,
                    )
                };
                left_ranges[a] = l;
                right_ranges[a] = r;
            }
            (left_ranges, right_ranges)
        };
        let first = self.interior(index, &cell, &s);
        self.node(
            arena,
            scratch,
            first,
            left_cell,
            left_ranges,
            n_left,
            depth + 1,
        );
        // The right child's lists do not depend on the side flags the left subtree rewrote.
        self.node(
            arena,
            scratch,
            first + 1,
            right_cell,
            right_ranges,
            n_right,
            depth + 1,
        );
        for a in 0..3 {
            arena[a].top = mark[a];
        }
    }
}

/// Writes past `arena.top` the events of `arena.ev[src]` (an axis the plane does not cut) of
/// the left child, then those of the right child, and returns their ranges (`top` moved past
/// them). A straddler's events go to both. Each event's side is read from the triangles'
/// flags once (scattered reads) into `sides`; then one pass per child writes every event and
/// advances past those it keeps, without a branch, so that no more memory is written than
/// the lists take.
fn split_by_side(
    arena: &mut Arena,
    src: Range<usize>,
    side: &[u8],
    sides: &mut Vec<u8>,
) -> (Range<usize>, Range<usize>) {
    let len = src.len();
    arena.reserve(2 * len);
    let top = arena.top;
    let (used, room) = arena.ev.split_at_mut(top);
    let used = &used[src];
    sides.clear();
    sides.extend(used.iter().map(|&e| side[tri_of(e) as usize]));
    let nl = keep_events(used, room, sides, |s| s != RIGHT);
    let nr = keep_events(used, &mut room[nl..], sides, |s| s != LEFT);
    arena.top = top + nl + nr;
    (top..top + nl, top + nl..arena.top)
}

/// Writes to the start of `out` the events of `src` whose side (`sides`, one per event)
/// `keep` keeps, in order, and returns how many. Every event is written and only the kept
/// ones advance, so `out` needs room for one more than are kept (or for all of `src`).
#[inline(always)]
fn keep_events(src: &[Event], out: &mut [Event], sides: &[u8], keep: impl Fn(u8) -> bool) -> usize {
    let mut n = 0;
    for (&e, &s) in src.iter().zip(sides) {
        out[n] = e;
        n += usize::from(keep(s));
    }
    n
}

/// With perfect splits: writes past `arena.top` the events of `arena.ev[src]` of the
/// triangles on one side only (left, then right), each side merged with the straddlers' new
/// events `extra` for it (sorted), and returns their ranges (`top` moved past them). The
/// straddlers' old events are dropped. One pass per side, as in [`split_by_side`], with the
/// few new events slipped in as it goes, so that nothing is moved afterwards.
fn split_perfect(
    arena: &mut Arena,
    src: Range<usize>,
    side: &[u8],
    sides: &mut Vec<u8>,
    extra: [&[Event]; 2],
) -> (Range<usize>, Range<usize>) {
    let len = src.len();
    let (kl, kr) = (extra[0].len(), extra[1].len());
    arena.reserve(2 * len + kl + kr);
    let top = arena.top;
    let (used, room) = arena.ev.split_at_mut(top);
    let used = &used[src];
    sides.clear();
    sides.extend(used.iter().map(|&e| side[tri_of(e) as usize]));
    let left = keep_merged(used, room, sides, LEFT, extra[0]);
    let right = keep_merged(used, &mut room[left..], sides, RIGHT, extra[1]);
    arena.top = top + left + right;
    (top..top + left, top + left..arena.top)
}

/// Writes to the start of `out` the events of `src` whose side (`sides`, one per event) is
/// `only`, merged with the sorted `extra` (no key in both), and returns how many. Before each
/// of the new events, the run of `src` below it is found by galloping search and its kept
/// events written as [`keep_events`] does, so no step branches on the keys or the sides.
/// `out` needs room for all of `src` and `extra`.
#[inline(always)]
fn keep_merged(src: &[Event], out: &mut [Event], sides: &[u8], only: u8, extra: &[Event]) -> usize {
    let keep = |s: u8| s == only;
    let (mut n, mut start) = (0, 0);
    for &y in extra {
        let end = start + leading_below(&src[start..], y);
        n += keep_events(&src[start..end], &mut out[n..], &sides[start..end], keep);
        out[n] = y;
        n += 1;
        start = end;
    }
    n + keep_events(&src[start..], &mut out[n..], &sides[start..], keep)
}

/// Writes past `arena.top` the left child's events on the split axis, `arena.ev[src]`'s first
/// `cut` merged with the straddlers' new ends `extra[0]`, then the right child's, the rest
/// merged with their new starts `extra[1]`; returns their ranges (`top` moved past them).
fn split_at_plane(
    arena: &mut Arena,
    src: Range<usize>,
    cut: usize,
    extra: [&[Event]; 2],
) -> (Range<usize>, Range<usize>) {
    let len = src.len();
    arena.reserve(len + extra[0].len() + extra[1].len());
    let top = arena.top;
    let (used, room) = arena.ev.split_at_mut(top);
    let (before, after) = used[src].split_at(cut);
    let left = merge_runs(room, before, extra[0]);
    let right = merge_runs(&mut room[left..], after, extra[1]);
    arena.top = top + left + right;
    (top..top + left, top + left..arena.top)
}

/// How many of the sorted `a`'s first events are below `y`: galloping from the start, then a
/// binary search in the last step, `O(log answer)`.
fn leading_below(a: &[Event], y: Event) -> usize {
    let mut step = 1;
    while step <= a.len() && a[step - 1] < y {
        step *= 2;
    }
    let low = step / 2;
    let high = step.min(a.len());
    low + a[low..high].partition_point(|&x| x < y)
}

/// Writes to `out` the merge of the sorted `a` and the sorted, short `b` (new events; equal
/// keys cannot occur, the triangles differ) and returns its length: before each of `b`'s
/// events, the run of `a` below it is found by galloping search and copied whole.
fn merge_runs(out: &mut [Event], a: &[Event], b: &[Event]) -> usize {
    let (mut rest, mut len) = (a, 0);
    for &y in b {
        let run = leading_below(rest, y);
        out[len..len + run].copy_from_slice(&rest[..run]);
        out[len + run] = y;
        len += run + 1;
        rest = &rest[run..];
    }
    out[len..len + rest.len()].copy_from_slice(rest);
    len + rest.len()
}
