//! Split events and the SAH sweep over them (Wald & Havran, "On building fast kd-Trees for Ray
//! Tracing, and on doing that in O(N log N)", 2006): each triangle's box, clipped to the node's
//! cell, gives a start and an end event on every axis (one planar event where it is flat);
//! sorted by position and kind, one sweep counts the triangles left of, right of and in each
//! candidate plane.
//!
//! An event is one `u64` key, `position (32 bits, order-preserving) | kind (2) | triangle (30)`,
//! so that sorting the keys as integers sorts the events by position, then kind, and merging two
//! sorted lists compares plain integers.

use super::KdParams;
use crate::geom::Aabb;

/// What happens to a triangle at an event's plane; the order is the sort order at one position.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u8)]
pub(super) enum Kind {
    /// The triangle's box ends here.
    End = 0,
    /// The triangle's box is flat and lies in this plane.
    Planar = 1,
    /// The triangle's box starts here.
    Start = 2,
}

/// One event on one axis, packed (see the module's documentation).
pub(super) type Event = u64;

/// Bits of an event key below the position.
const POS_SHIFT: u32 = 32;
/// Bits of an event key below the kind.
const KIND_SHIFT: u32 = 30;
const TRI_MASK: u64 = (1 << KIND_SHIFT) - 1;

/// The event of `tri` at `pos`. `-0.0` becomes `+0.0`, so that equal positions get equal keys.
#[inline(always)]
pub(super) fn event(pos: f32, kind: Kind, tri: u32) -> Event {
    let bits = (pos + 0.0).to_bits();
    // Order-preserving map of the float's bits: negatives flipped, positives above them.
    let ord = if bits >> 31 == 1 {
        !bits
    } else {
        bits | 0x8000_0000
    };
    (u64::from(ord) << POS_SHIFT) | (u64::from(kind as u8) << KIND_SHIFT) | u64::from(tri)
}

/// The key bits naming an event's position (equal for events at the same position).
#[inline(always)]
pub(super) fn pos_key(e: Event) -> u32 {
    (e >> POS_SHIFT) as u32
}

/// An event's position.
#[inline(always)]
pub(super) fn pos_of(e: Event) -> f32 {
    let ord = pos_key(e);
    f32::from_bits(if ord >> 31 == 1 {
        ord & 0x7fff_ffff
    } else {
        !ord
    })
}

/// An event's kind, as its `Kind` number.
#[inline(always)]
pub(super) fn kind_of(e: Event) -> usize {
    ((e >> KIND_SHIFT) & 3) as usize
}

/// An event's triangle.
#[inline(always)]
pub(super) fn tri_of(e: Event) -> u32 {
    (e & TRI_MASK) as u32
}

/// Sorts events in place by position, then kind.
pub(super) fn sort_events(events: &mut [Event]) {
    events.sort_unstable();
}

/// Appends the events of triangle `tri`'s (clipped) box on `axis`.
#[inline(always)]
pub(super) fn push_events(out: &mut Vec<Event>, b: &Aabb, axis: usize, tri: u32) {
    let (lo, hi) = (b.min[axis], b.max[axis]);
    if lo == hi {
        out.push(event(lo, Kind::Planar, tri));
    } else {
        out.push(event(lo, Kind::Start, tri));
        out.push(event(hi, Kind::End, tri));
    }
}

/// A chosen split plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Split {
    pub(super) axis: usize,
    pub(super) pos: f32,
    /// Triangles lying in the plane go left (else right).
    pub(super) planar_left: bool,
    /// Expected cost of splitting here, in the units of [`KdParams`].
    pub(super) cost: f64,
}

/// The cheapest split of `cell` among the planes of `events` (sorted, on `axis`) strictly inside
/// the cell, for `n` triangles; `None` when the cell has no such plane.
pub(super) fn best_split_on_axis(
    events: &[Event],
    axis: usize,
    n: usize,
    cell: &Aabb,
    params: &KdParams,
) -> Option<Split> {
    let area = cell.half_area_f64();
    if area <= 0.0 || !area.is_finite() {
        return None;
    }
    let (lo, hi) = (cell.min[axis], cell.max[axis]);
    // A child's half area is linear in its length along `axis`: the face across the axis plus
    // the perimeter of that face times the length.
    let e = cell.extent();
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let (eu, ev) = (f64::from(e[u]), f64::from(e[v]));
    let (face, perim) = (eu * ev / area, (eu + ev) / area);
    let (kt, ki) = (
        f64::from(params.traversal_cost),
        f64::from(params.intersection_cost),
    );
    let bonus = 1.0 - f64::from(params.empty_bonus);
    // The bonus discounts the children's intersection cost only (as in pbrt), not the
    // traversal: cutting empty space off a cell pays only where it saves triangle tests, so a
    // leaf of one triangle is never cut down further.
    let cost = |pl: f64, pr: f64, nl: usize, nr: usize| {
        let c = ki * (pl * nl as f64 + pr * nr as f64);
        kt + if nl == 0 || nr == 0 { bonus * c } else { c }
    };
    let (mut best_cost, mut best_pos, mut best_planar_left) = (f64::INFINITY, 0.0, true);
    let (mut nl, mut nr) = (0usize, n);
    let mut i = 0;
    while i < events.len() {
        let key = pos_key(events[i]);
        // Events at one position, counted by kind without branching on the kind.
        let (mut ends, mut planar, mut starts) = (0usize, 0usize, 0usize);
        while let Some(&e) = events.get(i) {
            if pos_key(e) != key {
                break;
            }
            let k = kind_of(e);
            ends += usize::from(k == 0);
            planar += usize::from(k == 1);
            starts += usize::from(k == 2);
            i += 1;
        }
        nr -= planar + ends;
        let pos = pos_of(events[i - 1]);
        if lo < pos && pos < hi {
            let pl = face + perim * f64::from(pos - lo);
            let pr = face + perim * f64::from(hi - pos);
            let cost_left = cost(pl, pr, nl + planar, nr);
            let (c, planar_left) = if planar == 0 {
                (cost_left, true)
            } else {
                let cost_right = cost(pl, pr, nl, nr + planar);
                if cost_left <= cost_right {
                    (cost_left, true)
                } else {
                    (cost_right, false)
                }
            };
            if c < best_cost {
                (best_cost, best_pos, best_planar_left) = (c, pos, planar_left);
            }
        }
        nl += starts + planar;
    }
    best_cost.is_finite().then_some(Split {
        axis,
        pos: best_pos,
        planar_left: best_planar_left,
        cost: best_cost,
    })
}

/// The cheapest split over the three axes' sorted events (the lowest axis on ties), if it
/// beats making a leaf of the `n` triangles.
///
/// Axes are swept in the order of a lower bound on their splits' cost, and an axis whose bound
/// is already above the best split found (or the leaf) is not swept: every triangle goes to
/// at least one child, and a child's area is at least the cell's face across the axis, so a
/// split costs at least `kt + ki min(λ f n, f n + 1 - f)` (`f` that face over the cell's area,
/// `λ` the empty cut's factor; the second term when both children hold triangles).
pub(super) fn choose_split(
    events: [&[Event]; 3],
    n: usize,
    cell: &Aabb,
    params: &KdParams,
) -> Option<Split> {
    let (kt, ki) = (
        f64::from(params.traversal_cost),
        f64::from(params.intersection_cost),
    );
    let leaf_cost = ki * n as f64;
    let area = cell.half_area_f64();
    let e = cell.extent();
    let empty_factor = (1.0 - f64::from(params.empty_bonus)).max(0.0);
    let bound = |axis: usize| {
        let f = f64::from(e[(axis + 1) % 3]) * f64::from(e[(axis + 2) % 3]) / area;
        let n = n as f64;
        // Kept below the costs the sweep computes, whatever their rounding.
        (kt + ki * (empty_factor * f * n).min(f * n + 1.0 - f)) * (1.0 - 1e-9)
    };
    let bounds = [bound(0), bound(1), bound(2)];
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| bounds[a].total_cmp(&bounds[b]));
    let mut best: Option<Split> = None;
    for axis in order {
        if bounds[axis] >= best.map_or(leaf_cost, |b| b.cost) {
            continue;
        }
        if let Some(s) = best_split_on_axis(events[axis], axis, n, cell, params) {
            if best.is_none_or(|b| s.cost < b.cost || (s.cost == b.cost && s.axis < b.axis)) {
                best = Some(s);
            }
        }
    }
    best.filter(|s| s.cost < leaf_cost)
}

/// `b` clipped to `cell` (the box the triangle has in that cell when splits are not perfect).
#[inline(always)]
pub(super) fn clip_box(b: &Aabb, cell: &Aabb) -> Aabb {
    Aabb::new(b.min.max(cell.min), b.max.min(cell.max))
}

/// Which children a triangle goes to (a flag per triangle, indexed by its id).
pub(super) const BOTH: u8 = 0;
pub(super) const LEFT: u8 = 1;
pub(super) const RIGHT: u8 = 2;

/// Marks every triangle of the node's events on the split axis with its side (`side` is indexed
/// by triangle id; only the node's triangles are written), in one pass: a triangle's start
/// event precedes its end event, so the start marks it right (at or past the plane) or both,
/// and an end at or before the plane makes it left. The triangles left in both (they straddle
/// the plane) are appended to `straddlers`; returns the triangle counts of the two children.
pub(super) fn classify(
    events: &[Event],
    split: &Split,
    side: &mut [u8],
    straddlers: &mut Vec<u32>,
) -> (usize, usize) {
    let plane = pos_key(event(split.pos, Kind::End, 0));
    // The events are sorted: those before the plane, at it, and past it are three runs, and in
    // the first and last the kind alone decides, without a branch.
    let below = events.partition_point(|&e| pos_key(e) < plane);
    let above = below + events[below..].partition_point(|&e| pos_key(e) == plane);
    let (mut left, mut right) = (0, 0);
    let first = straddlers.len();
    // Before the plane: an end or a planar event puts its triangle left; a start marks it both
    // until its end is seen.
    for &e in &events[..below] {
        let starts = kind_of(e) == Kind::Start as usize;
        side[tri_of(e) as usize] = if starts { BOTH } else { LEFT };
        left += usize::from(!starts);
    }
    for &e in &events[below..above] {
        let t = tri_of(e) as usize;
        match kind_of(e) {
            0 => {
                side[t] = LEFT;
                left += 1;
            }
            1 if split.planar_left => {
                side[t] = LEFT;
                left += 1;
            }
            _ => {
                side[t] = RIGHT;
                right += 1;
            }
        }
    }
    // Past the plane: a start or a planar event puts its triangle right; the end of one still
    // marked both (it started before the plane) names a straddler.
    for &e in &events[above..] {
        let t = tri_of(e) as usize;
        let ends = kind_of(e) == Kind::End as usize;
        if ends && side[t] == BOTH {
            straddlers.push(t as u32);
        }
        side[t] = if ends { side[t] } else { RIGHT };
        right += usize::from(!ends);
    }
    let both = straddlers.len() - first;
    (left + both, right + both)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn keys_sort_by_position_then_kind() {
        let xs = [
            -3.5f32,
            -0.0,
            0.0,
            1e-30,
            2.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ];
        for &a in &xs {
            assert_eq!(pos_of(event(a, Kind::Start, 7)), a + 0.0);
            for &b in &xs {
                let (ka, kb) = (event(a, Kind::End, 9), event(b, Kind::Start, 1));
                assert_eq!(a < b, pos_key(ka) < pos_key(kb), "{a} {b}");
                if a == b {
                    assert!(ka < kb, "end before start at one position");
                }
            }
        }
        let e = event(1.0, Kind::Planar, (1 << 30) - 1);
        assert_eq!(
            (kind_of(e), tri_of(e)),
            (Kind::Planar as usize, (1 << 30) - 1)
        );
    }

    #[test]
    fn sweep_counts_left_right_and_planar() {
        // Two unit boxes side by side on x, and one flat box at x = 1.
        let boxes = [
            Aabb::new(Vec3::ZERO, Vec3::ONE),
            Aabb::new(Vec3::new(2.0, 0.0, 0.0), Vec3::new(3.0, 1.0, 1.0)),
            Aabb::new(Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 1.0)),
        ];
        let mut ev = Vec::new();
        for (i, b) in boxes.iter().enumerate() {
            push_events(&mut ev, b, 0, i as u32);
        }
        sort_events(&mut ev);
        let cell = Aabb::new(Vec3::ZERO, Vec3::new(3.0, 1.0, 1.0));
        let params = KdParams::default();
        let s = best_split_on_axis(&ev, 0, 3, &cell, &params).unwrap();
        assert!(s.pos == 1.0 || s.pos == 2.0, "{s:?}");
        let mut side = vec![BOTH; 3];
        let mut straddlers = Vec::new();
        assert_eq!(classify(&ev, &s, &mut side, &mut straddlers), (2, 1));
        assert!(straddlers.is_empty());
        assert_eq!(side[0], LEFT);
        assert_eq!(side[1], RIGHT);
    }
}
