//! The naive kd-tree build, for comparison with the sorted one: at every node each triangle's
//! box is clipped to the cell and its events made and sorted again, O(N log² N) in all. It
//! makes the same splits as `build_fast` (same events, same sweep).

use super::build_fast::Builder;
use super::events::{Event, LEFT, RIGHT, classify, clip_box, push_events, sort_events};
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
    b.nodes.push(KdNode::leaf(0, 0));
    node(&mut b, 0, *bounds, ids, 0);
    b.finish()
}

fn node(b: &mut Builder, index: usize, cell: Aabb, tris: Vec<u32>, depth: usize) {
    b.depth = b.depth.max(depth);
    let events: [Vec<Event>; 3] = std::array::from_fn(|axis| {
        let mut ev = Vec::with_capacity(2 * tris.len());
        for &t in &tris {
            push_events(&mut ev, &clip_box(&b.boxes[t as usize], &cell), axis, t);
        }
        sort_events(&mut ev);
        ev
    });
    let split = b.split_for(
        [&events[0], &events[1], &events[2]],
        tris.len(),
        &cell,
        depth,
    );
    let Some(s) = split else {
        b.leaf(index, &cell, tris.into_iter());
        return;
    };
    classify(&events[s.axis], &s, &mut b.side, &mut Vec::new());
    let (mut left_cell, mut right_cell) = (cell, cell);
    left_cell.max[s.axis] = s.pos;
    right_cell.min[s.axis] = s.pos;
    let left: Vec<u32> = tris
        .iter()
        .copied()
        .filter(|&t| b.side[t as usize] != RIGHT)
        .collect();
    let right: Vec<u32> = tris
        .iter()
        .copied()
        .filter(|&t| b.side[t as usize] != LEFT)
        .collect();
    drop((events, tris));
    let first = b.interior(index, &cell, &s);
    node(b, first, left_cell, left, depth + 1);
    node(b, first + 1, right_cell, right, depth + 1);
}
