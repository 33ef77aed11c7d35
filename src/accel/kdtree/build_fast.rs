//! The O(N log N) kd-tree build of Wald & Havran 2006: the events of all triangles are sorted
//! once per axis; at each node one sweep per axis finds the best plane, the triangles are
//! classified left, right or both, and the lists are split in order. Only the triangles that
//! straddle the plane get new events (their boxes clipped to each child), which are sorted and
//! merged into the children's lists.

use super::events::{
    Event, Side, Split, choose_split, classify, clip_box, push_events, sort_events,
};
use super::{Built, KdNode, KdParams};
use crate::geom::Aabb;

/// Builds the tree over the triangles whose boxes are not empty.
pub(super) fn build(boxes: &[Aabb], bounds: &Aabb, params: &KdParams) -> Built {
    let ids: Vec<u32> = (0..boxes.len() as u32)
        .filter(|&i| !boxes[i as usize].is_empty())
        .collect();
    let mut b = Builder::new(boxes, bounds, params, ids.len());
    if ids.is_empty() {
        return b.finish();
    }
    let events = std::array::from_fn(|axis| {
        let mut ev = Vec::with_capacity(2 * ids.len());
        for &i in &ids {
            push_events(&mut ev, &boxes[i as usize], axis, i);
        }
        sort_events(&mut ev);
        ev
    });
    b.nodes.push(KdNode::leaf(0, 0));
    b.node(0, *bounds, events, ids.len(), 0);
    b.finish()
}

/// The state shared by the whole build.
pub(super) struct Builder<'a> {
    pub(super) boxes: &'a [Aabb],
    pub(super) params: &'a KdParams,
    pub(super) nodes: Vec<KdNode>,
    pub(super) refs: Vec<u32>,
    /// Each triangle's side at the node being split.
    pub(super) side: Vec<Side>,
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
            side: vec![Side::Both; boxes.len()],
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
        if depth >= self.max_depth || n == 0 {
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

    fn node(&mut self, index: usize, cell: Aabb, events: [Vec<Event>; 3], n: usize, depth: usize) {
        self.depth = self.depth.max(depth);
        let split = self.split_for([&events[0], &events[1], &events[2]], n, &cell, depth);
        let Some(s) = split else {
            let tris = events[0]
                .iter()
                .filter(|e| e.kind != super::events::Kind::End);
            self.leaf(index, &cell, tris.map(|e| e.tri));
            return;
        };
        classify(&events[s.axis], &s, &mut self.side);
        let (mut left_cell, mut right_cell) = (cell, cell);
        left_cell.max[s.axis] = s.pos;
        right_cell.min[s.axis] = s.pos;

        // Triangles in both children: new events from their boxes clipped to each child.
        let mut straddle_left: [Vec<Event>; 3] = Default::default();
        let mut straddle_right: [Vec<Event>; 3] = Default::default();
        let (mut n_left, mut n_right) = (0, 0);
        for e in &events[s.axis] {
            if e.kind == super::events::Kind::End {
                continue;
            }
            match self.side[e.tri as usize] {
                Side::Left => n_left += 1,
                Side::Right => n_right += 1,
                Side::Both => {
                    n_left += 1;
                    n_right += 1;
                    let b = &self.boxes[e.tri as usize];
                    let (bl, br) = (clip_box(b, &left_cell), clip_box(b, &right_cell));
                    for axis in 0..3 {
                        push_events(&mut straddle_left[axis], &bl, axis, e.tri);
                        push_events(&mut straddle_right[axis], &br, axis, e.tri);
                    }
                }
            }
        }
        let mut left: [Vec<Event>; 3] = Default::default();
        let mut right: [Vec<Event>; 3] = Default::default();
        for axis in 0..3 {
            sort_events(&mut straddle_left[axis]);
            sort_events(&mut straddle_right[axis]);
            let side = &self.side;
            let only = |want: Side| {
                events[axis]
                    .iter()
                    .filter(move |e| side[e.tri as usize] == want)
                    .copied()
            };
            left[axis] = merge(only(Side::Left), &straddle_left[axis]);
            right[axis] = merge(only(Side::Right), &straddle_right[axis]);
        }
        drop(events);
        let first = self.interior(index, &cell, &s);
        self.node(first, left_cell, left, n_left, depth + 1);
        self.node(first + 1, right_cell, right, n_right, depth + 1);
    }
}

/// Merges two sorted event sequences into one sorted list.
fn merge(a: impl Iterator<Item = Event>, b: &[Event]) -> Vec<Event> {
    if b.is_empty() {
        return a.collect();
    }
    let mut out = Vec::with_capacity(b.len() + a.size_hint().1.unwrap_or(0));
    let mut j = 0;
    for e in a {
        while j < b.len() && b[j].precedes(&e) {
            out.push(b[j]);
            j += 1;
        }
        out.push(e);
    }
    out.extend_from_slice(&b[j..]);
    out
}
