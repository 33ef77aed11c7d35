//! The naive kd-tree build, for comparison with the sorted one: at every node each triangle's
//! events are made from its box in the cell and sorted again, O(N log² N) in all. It makes the
//! same splits as `build_fast` (same boxes, same events, same sweep): a triangle's box is
//! carried down and only changed where a plane cuts it (clipped to the child's cell, or with
//! perfect splits the triangle clipped to it).

use super::build_fast::Builder;
use super::events::{Event, LEFT, RIGHT, classify, clip_box, push_events, sort_events};
use super::{Built, KdNode, KdParams};
use crate::geom::Aabb;
use glam::Vec3;

/// Builds the tree over the triangles whose boxes are not empty.
pub(super) fn build(tris: &[[Vec3; 3]], boxes: &[Aabb], bounds: &Aabb, params: &KdParams) -> Built {
    let items: Vec<(u32, Aabb)> = (0..boxes.len() as u32)
        .filter(|&i| !boxes[i as usize].is_empty())
        .map(|i| (i, boxes[i as usize]))
        .collect();
    let mut b = Builder::new(tris, boxes, bounds, params, items.len());
    if items.is_empty() {
        return b.finish();
    }
    b.nodes.push(KdNode::leaf(0, 0));
    node(&mut b, 0, *bounds, items, 0);
    b.finish()
}

/// Builds node `index` over `items`: each triangle with its box in `cell`.
fn node(b: &mut Builder, index: usize, cell: Aabb, items: Vec<(u32, Aabb)>, depth: usize) {
    b.depth = b.depth.max(depth);
    let events: [Vec<Event>; 3] = std::array::from_fn(|axis| {
        let mut ev = Vec::with_capacity(2 * items.len());
        for &(t, bx) in &items {
            push_events(&mut ev, &bx, axis, t);
        }
        sort_events(&mut ev);
        ev
    });
    let split = b.split_for(
        [&events[0], &events[1], &events[2]],
        items.len(),
        &cell,
        depth,
    );
    let Some(s) = split else {
        b.leaf(index, &cell, items.into_iter().map(|(t, _)| t));
        return;
    };
    classify(&events[s.axis], &s, &mut b.side, &mut Vec::new());
    let (mut left_cell, mut right_cell) = (cell, cell);
    left_cell.max[s.axis] = s.pos;
    right_cell.min[s.axis] = s.pos;
    let (mut left, mut right) = (Vec::new(), Vec::new());
    for &(t, bx) in &items {
        match b.side[t as usize] {
            LEFT => left.push((t, bx)),
            RIGHT => right.push((t, bx)),
            _ => {
                let (l, r) = if b.params.perfect_at(items.len()) {
                    b.straddler_boxes(t, &cell, &s)
                } else {
                    (clip_box(&bx, &left_cell), clip_box(&bx, &right_cell))
                };
                if !l.is_empty() {
                    left.push((t, l));
                }
                if !r.is_empty() {
                    right.push((t, r));
                }
            }
        }
    }
    drop((events, items));
    let first = b.interior(index, &cell, &s);
    node(b, first, left_cell, left, depth + 1);
    node(b, first + 1, right_cell, right, depth + 1);
}
