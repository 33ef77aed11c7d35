//! Split events and the SAH sweep over them (Wald & Havran, "On building fast kd-Trees for Ray
//! Tracing, and on doing that in O(N log N)", 2006): each triangle's box, clipped to the node's
//! cell, gives a start and an end event on every axis (one planar event where it is flat);
//! sorted by position and kind, one sweep counts the triangles left of, right of and in each
//! candidate plane.

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

/// One event on one axis.
#[derive(Clone, Copy, Debug)]
pub(super) struct Event {
    pub(super) pos: f32,
    pub(super) tri: u32,
    pub(super) kind: Kind,
}

impl Event {
    /// The sort order: by position, then end before planar before start.
    #[inline]
    pub(super) fn precedes(&self, o: &Event) -> bool {
        (self.pos, self.kind as u8) < (o.pos, o.kind as u8)
    }
}

/// Sorts events in place by [`Event::precedes`].
pub(super) fn sort_events(events: &mut [Event]) {
    events.sort_unstable_by(|a, b| {
        a.pos
            .total_cmp(&b.pos)
            .then((a.kind as u8).cmp(&(b.kind as u8)))
    });
}

/// Appends the events of triangle `tri`'s (clipped) box on `axis`.
#[inline]
pub(super) fn push_events(out: &mut Vec<Event>, b: &Aabb, axis: usize, tri: u32) {
    let (lo, hi) = (b.min[axis], b.max[axis]);
    if lo == hi {
        out.push(Event {
            pos: lo,
            tri,
            kind: Kind::Planar,
        });
    } else {
        out.push(Event {
            pos: lo,
            tri,
            kind: Kind::Start,
        });
        out.push(Event {
            pos: hi,
            tri,
            kind: Kind::End,
        });
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

/// The SAH cost of a split with `pl`, `pr` the children's area over the node's and `nl`, `nr`
/// their triangle counts; an empty child earns the empty-space bonus.
#[inline]
pub(super) fn split_cost(params: &KdParams, pl: f64, pr: f64, nl: usize, nr: usize) -> f64 {
    let bonus = if nl == 0 || nr == 0 {
        1.0 - f64::from(params.empty_bonus)
    } else {
        1.0
    };
    bonus
        * (f64::from(params.traversal_cost)
            + f64::from(params.intersection_cost) * (pl * nl as f64 + pr * nr as f64))
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
    let mut best: Option<Split> = None;
    let (mut nl, mut nr) = (0usize, n);
    let mut i = 0;
    while i < events.len() {
        let pos = events[i].pos;
        let mut count = [0usize; 3];
        while i < events.len() && events[i].pos == pos {
            count[events[i].kind as usize] += 1;
            i += 1;
        }
        let [ends, planar, starts] = count;
        nr -= planar + ends;
        if lo < pos && pos < hi {
            let (mut left, mut right) = (*cell, *cell);
            left.max[axis] = pos;
            right.min[axis] = pos;
            let (pl, pr) = (left.half_area_f64() / area, right.half_area_f64() / area);
            let cost_left = split_cost(params, pl, pr, nl + planar, nr);
            let cost_right = split_cost(params, pl, pr, nl, nr + planar);
            let (cost, planar_left) = if cost_left <= cost_right {
                (cost_left, true)
            } else {
                (cost_right, false)
            };
            if best.is_none_or(|b| cost < b.cost) {
                best = Some(Split {
                    axis,
                    pos,
                    planar_left,
                    cost,
                });
            }
        }
        nl += starts + planar;
    }
    best
}

/// The cheapest split over the three axes' sorted events (the lowest axis on ties), if it
/// beats making a leaf of the `n` triangles.
pub(super) fn choose_split(
    events: [&[Event]; 3],
    n: usize,
    cell: &Aabb,
    params: &KdParams,
) -> Option<Split> {
    let leaf_cost = f64::from(params.intersection_cost) * n as f64;
    (0..3)
        .filter_map(|axis| best_split_on_axis(events[axis], axis, n, cell, params))
        .fold(None, |best: Option<Split>, s| match best {
            Some(b) if b.cost <= s.cost => Some(b),
            _ => Some(s),
        })
        .filter(|s| s.cost < leaf_cost)
}

/// `b` clipped to `cell` (the box the triangle has in that cell when splits are not perfect).
#[inline]
pub(super) fn clip_box(b: &Aabb, cell: &Aabb) -> Aabb {
    Aabb::new(b.min.max(cell.min), b.max.min(cell.max))
}

/// Which children a triangle goes to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(super) enum Side {
    Both = 0,
    Left = 1,
    Right = 2,
}

/// Marks every triangle of the node's events on the split axis with its side (`side` is indexed
/// by triangle id; only the node's triangles are written).
pub(super) fn classify(events: &[Event], split: &Split, side: &mut [Side]) {
    for e in events {
        side[e.tri as usize] = Side::Both;
    }
    for e in events {
        let s = &mut side[e.tri as usize];
        match e.kind {
            Kind::End if e.pos <= split.pos => *s = Side::Left,
            Kind::Start if e.pos >= split.pos => *s = Side::Right,
            Kind::Planar => {
                *s = if e.pos < split.pos || (e.pos == split.pos && split.planar_left) {
                    Side::Left
                } else {
                    Side::Right
                }
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

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
        let mut side = vec![Side::Both; 3];
        classify(&ev, &s, &mut side);
        assert_eq!(side[0], Side::Left);
        assert_eq!(side[1], Side::Right);
    }
}
