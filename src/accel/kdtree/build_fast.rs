//! The O(N log N) kd-tree build of Wald & Havran 2006: the events of all triangles are sorted
//! once per axis; at each node one sweep per axis finds the best plane, the triangles are
//! classified left, right or both (a flag per triangle), and the lists are split in order. Only
//! the triangles that straddle the plane get new events (their boxes clipped to each child),
//! which are sorted and merged into the children's lists.
//!
//! The lists live in one arena per axis used as a stack: a node's children's lists are
//! appended after everything in use, the left subtree is built, then the right, and the arena
//! is cut back to where the children's lists began. After the root's lists nothing is
//! allocated but the arenas' growth.

use super::events::{
    BOTH, Event, Kind, LEFT, RIGHT, Split, choose_split, classify, clip_box, kind_of, push_events,
    sort_events, tri_of,
};
use super::{Built, KdNode, KdParams};
use crate::geom::Aabb;
use std::ops::Range;

/// Builds the tree over the triangles whose boxes are not empty.
pub(super) fn build(boxes: &[Aabb], bounds: &Aabb, params: &KdParams) -> Built {
    let ids: Vec<u32> = (0..boxes.len() as u32)
        .filter(|&i| !boxes[i as usize].is_empty())
        .collect();
    let mut b = Builder::new(boxes, bounds, params, ids.len());
    if ids.is_empty() {
        return b.finish();
    }
    let mut arena: [Vec<Event>; 3] = std::array::from_fn(|axis| {
        // Room for the root's lists and a few levels of children (straddlers add events).
        let mut ev = Vec::with_capacity(8 * ids.len());
        for &i in &ids {
            push_events(&mut ev, &boxes[i as usize], axis, i);
        }
        sort_events(&mut ev);
        ev
    });
    let ranges = std::array::from_fn(|axis| 0..arena[axis].len());
    let mut scratch = Scratch::default();
    b.nodes.reserve(4 * ids.len());
    b.refs.reserve(2 * ids.len());
    b.nodes.push(KdNode::leaf(0, 0));
    b.node(&mut arena, &mut scratch, 0, *bounds, ranges, ids.len(), 0);
    b.finish()
}

/// Per-node buffers, reused: the triangles straddling the plane, their new events for each
/// child, and the node's events sorted by side.
#[derive(Default)]
struct Scratch {
    straddlers: Vec<u32>,
    left: [Vec<Event>; 3],
    right: [Vec<Event>; 3],
    tmp: Vec<Event>,
}

/// The state shared by the whole build.
pub(super) struct Builder<'a> {
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
    pub(super) fn new(boxes: &'a [Aabb], bounds: &Aabb, params: &'a KdParams, n: usize) -> Self {
        Self {
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
        arena: &mut [Vec<Event>; 3],
        scratch: &mut Scratch,
        index: usize,
        cell: Aabb,
        ranges: [Range<usize>; 3],
        n: usize,
        depth: usize,
    ) {
        self.depth = self.depth.max(depth);
        let mark: [usize; 3] = std::array::from_fn(|a| arena[a].len());
        let lists = std::array::from_fn(|a| &arena[a][ranges[a].clone()]);
        let Some(s) = self.split_for(lists, n, &cell, depth) else {
            let tris = lists[0]
                .iter()
                .filter(|&&e| kind_of(e) != Kind::End as usize);
            self.leaf(index, &cell, tris.map(|&e| tri_of(e)));
            return;
        };
        scratch.straddlers.clear();
        let (n_left, n_right) =
            classify(lists[s.axis], &s, &mut self.side, &mut scratch.straddlers);
        let (mut left_cell, mut right_cell) = (cell, cell);
        left_cell.max[s.axis] = s.pos;
        right_cell.min[s.axis] = s.pos;

        let (left_ranges, right_ranges) = if scratch.straddlers.is_empty() && n_right == 0 {
            // An empty cut on the right: the left child has the node's lists as they are.
            (ranges.clone(), Default::default())
        } else if scratch.straddlers.is_empty() && n_left == 0 {
            (Default::default(), ranges.clone())
        } else {
            // Triangles in both children: new events from their boxes clipped to each child.
            for a in 0..3 {
                scratch.left[a].clear();
                scratch.right[a].clear();
            }
            for &t in &scratch.straddlers {
                let b = &self.boxes[t as usize];
                let (bl, br) = (clip_box(b, &left_cell), clip_box(b, &right_cell));
                for a in 0..3 {
                    push_events(&mut scratch.left[a], &bl, a, t);
                    push_events(&mut scratch.right[a], &br, a, t);
                }
            }
            let mut left_ranges: [Range<usize>; 3] = Default::default();
            let mut right_ranges: [Range<usize>; 3] = Default::default();
            for a in 0..3 {
                sort_events(&mut scratch.left[a]);
                sort_events(&mut scratch.right[a]);
                let (l, r) = split_list(
                    &mut arena[a],
                    ranges[a].clone(),
                    &self.side,
                    [&scratch.left[a], &scratch.right[a]],
                    &mut scratch.tmp,
                );
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
            arena[a].truncate(mark[a]);
        }
    }
}

/// Appends to `list` the events of `list[src]` of the left child, then those of the right
/// child (each merged in order with the sorted new events `extra` of its side); returns their
/// ranges. One branch-free pass sorts the node's events into the two halves of `tmp`.
fn split_list(
    list: &mut Vec<Event>,
    src: Range<usize>,
    side: &[u8],
    extra: [&[Event]; 2],
    tmp: &mut Vec<Event>,
) -> (Range<usize>, Range<usize>) {
    let len = src.len();
    // Grown, never cleared: only the slots written below are read.
    if tmp.len() < 2 * len {
        tmp.resize(2 * len, 0);
    }
    let (tl, tr) = tmp[..2 * len].split_at_mut(len);
    let (mut nl, mut nr) = (0, 0);
    for &e in &list[src] {
        let s = side[tri_of(e) as usize];
        tl[nl] = e;
        tr[nr] = e;
        nl += usize::from(s == LEFT);
        nr += usize::from(s == RIGHT);
    }
    let start = list.len();
    list.reserve(nl + nr + extra[0].len() + extra[1].len());
    merge_into(list, &tl[..nl], extra[0]);
    let mid = list.len();
    merge_into(list, &tr[..nr], extra[1]);
    (start..mid, mid..list.len())
}

/// Appends the merge of the sorted `a` and `b` to `out`. Room is made first, and each step
/// takes the smaller head without a branch on which it is (the two lists interleave
/// unpredictably).
fn merge_into(out: &mut Vec<Event>, a: &[Event], b: &[Event]) {
    out.reserve(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        let (x, y) = (a[i], b[j]);
        let take_b = y < x;
        out.push(if take_b { y } else { x });
        j += usize::from(take_b);
        i += usize::from(!take_b);
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
}
