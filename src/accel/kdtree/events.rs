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

/// Sorts `events` in place as [`sort_events`] does, by a least-significant-digit radix sort of
/// the position and kind bits, with `tmp` (at least as long) as the other buffer: for events
/// written in the order of their triangles (as the root's are), which a stable sort keeps
/// among equal positions and kinds, so the order is that of the whole keys.
pub(super) fn sort_events_by_position(events: &mut [Event], tmp: &mut [Event]) {
    /// The digits' bit ranges, from the kind's lowest bit to the top; an even count, so the
    /// result ends where it began.
    const DIGITS: [(u32, u32); 4] = [(KIND_SHIFT, 9), (KIND_SHIFT + 9, 9), (48, 8), (56, 8)];
    let tmp = &mut tmp[..events.len()];
    let (mut src, mut dst) = (events, tmp);
    for (shift, bits) in DIGITS {
        let mask = (1u64 << bits) - 1;
        let digit = |e: Event| ((e >> shift) & mask) as usize;
        let mut start = [0usize; 512];
        for &e in src.iter() {
            start[digit(e)] += 1;
        }
        let mut sum = 0;
        for s in &mut start {
            (*s, sum) = (sum, sum + *s);
        }
        for &e in src.iter() {
            let d = digit(e);
            dst[start[d]] = e;
            start[d] += 1;
        }
        std::mem::swap(&mut src, &mut dst);
    }
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

/// Writes the events of triangle `tri`'s box on `axis` at the start of `out`; returns how
/// many (1 or 2), as [`push_events`] appends them.
#[inline(always)]
pub(super) fn write_events(out: &mut [Event], b: &Aabb, axis: usize, tri: u32) -> usize {
    let (lo, hi) = (b.min[axis], b.max[axis]);
    if lo == hi {
        out[0] = event(lo, Kind::Planar, tri);
        1
    } else {
        out[0] = event(lo, Kind::Start, tri);
        out[1] = event(hi, Kind::End, tri);
        2
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

/// The SAH cost of the planes across one axis of one cell.
struct PlaneCost {
    axis: usize,
    lo: f32,
    hi: f32,
    /// The cell's face across the axis and that face's perimeter, over the cell's area: a
    /// child's area over the cell's is `face + perim * length` (linear in its length).
    face: f64,
    perim: f64,
    traversal: f64,
    intersection: f64,
    /// What an empty child leaves of the children's intersection cost.
    empty_factor: f64,
}

impl PlaneCost {
    /// `None` when the cell has no area (or an infinite one).
    fn new(cell: &Aabb, axis: usize, params: &KdParams) -> Option<Self> {
        let area = cell.half_area_f64();
        if area <= 0.0 || !area.is_finite() {
            return None;
        }
        let e = cell.extent();
        let (eu, ev) = (f64::from(e[(axis + 1) % 3]), f64::from(e[(axis + 2) % 3]));
        Some(Self {
            axis,
            lo: cell.min[axis],
            hi: cell.max[axis],
            face: eu * ev / area,
            perim: (eu + ev) / area,
            traversal: f64::from(params.traversal_cost),
            intersection: f64::from(params.intersection_cost),
            empty_factor: 1.0 - f64::from(params.empty_bonus),
        })
    }

    /// The split at `pos` with `nl` triangles before the plane, `nr` after it and `planar` in
    /// it (put on the cheaper side, left on ties); `None` unless the plane is strictly inside
    /// the cell.
    #[inline(always)]
    fn at(&self, pos: f32, nl: usize, nr: usize, planar: usize) -> Option<Split> {
        if !(self.lo < pos && pos < self.hi) {
            return None;
        }
        let pl = self.face + self.perim * f64::from(pos - self.lo);
        let pr = self.face + self.perim * f64::from(self.hi - pos);
        // The bonus discounts the children's intersection cost only (as in pbrt), not the
        // traversal: cutting empty space off a cell pays only where it saves triangle tests,
        // so a leaf of one triangle is never cut down further.
        let cost = |nl: usize, nr: usize| {
            // Counts below 2^30 (the triangle ids' bits): converted from `u32`, one
            // instruction where a `usize` takes several.
            let c = self.intersection * (pl * f64::from(nl as u32) + pr * f64::from(nr as u32));
            self.traversal
                + if nl == 0 || nr == 0 {
                    self.empty_factor * c
                } else {
                    c
                }
        };
        let cost_left = cost(nl + planar, nr);
        let (cost, planar_left) = if planar == 0 {
            (cost_left, true)
        } else {
            let cost_right = cost(nl, nr + planar);
            if cost_left <= cost_right {
                (cost_left, true)
            } else {
                (cost_right, false)
            }
        };
        Some(Split {
            axis: self.axis,
            pos,
            planar_left,
            cost,
        })
    }

    /// A lower bound on the cost of every split that leaves triangles on both sides: each of
    /// the `n` triangles goes to at least one child and each child holds at least one, so
    /// `pl nl + pr nr >= face n + (1 - face)`. Kept below what [`PlaneCost::at`] computes,
    /// whatever its rounding.
    fn both_sides_bound(&self, n: usize) -> f64 {
        let n = n as f64;
        (self.traversal + self.intersection * (self.face * n + 1.0 - self.face)) * (1.0 - 1e-9)
    }

    /// The cheapest split among the planes of `events` (sorted) for `n` triangles, the first
    /// position on ties; `None` when no plane is strictly inside the cell.
    fn sweep(&self, events: &[Event], n: usize) -> Option<Split> {
        let mut best: Option<Split> = None;
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
            if let Some(s) = self.at(pos_of(events[i - 1]), nl, nr, planar)
                && best.is_none_or(|b| s.cost < b.cost)
            {
                best = Some(s);
            }
            nl += starts + planar;
        }
        best
    }

    /// The cheaper of the planes at the first and at the last position of `events` (sorted),
    /// the only planes that can leave a child empty, with the counts [`PlaneCost::sweep`] has
    /// there: nothing ends at the first position (an end follows its triangle's start) and
    /// nothing starts at the last, so only the triangles flat in those planes need counting.
    fn end_planes(&self, events: &[Event], n: usize) -> Option<Split> {
        let (&first, &last) = (events.first()?, events.last()?);
        let flat_at = |key: u32, e: &&Event| pos_key(**e) == key && kind_of(**e) == 1;
        let first_flat = events
            .iter()
            .take_while(|e| flat_at(pos_key(first), e))
            .count();
        let last_flat = events
            .iter()
            .rev()
            .take_while(|e| flat_at(pos_key(last), e))
            .count();
        let low = self.at(pos_of(first), 0, n - first_flat, first_flat);
        let high = self.at(pos_of(last), n - last_flat, 0, last_flat);
        match (low, high) {
            (Some(l), Some(h)) => Some(if h.cost < l.cost { h } else { l }),
            (l, h) => l.or(h),
        }
    }
}

/// With [`KdParams::longest_axis_only`], the smallest node whose other axes are swept when its
/// longest offers no split: in smaller nodes the retries cost many sweeps for splits that
/// barely lower the tree's cost (figures in `docs/accel.md`).
pub(super) const RETRY_ABOVE: usize = 16;

/// The cheapest split over the three axes' sorted events (the lowest axis on ties, then the
/// lowest position), if it beats making a leaf of the `n` triangles.
///
/// The planes that leave a child empty (at each axis's first and last event) are costed
/// first; then the axes are swept (with [`KdParams::longest_axis_only`], the cell's longest
/// axis alone unless no split so far beats the leaf and the node holds more than
/// [`RETRY_ABOVE`] triangles) in the order of a lower bound on their other splits' cost
/// ([`PlaneCost::both_sides_bound`]), and an axis whose bound is not below the best split so
/// far (or the leaf) is not swept, since none of its other planes can win or tie.
pub(super) fn choose_split(
    events: [&[Event]; 3],
    n: usize,
    cell: &Aabb,
    params: &KdParams,
) -> Option<Split> {
    let leaf_cost = f64::from(params.intersection_cost) * n as f64;
    let planes: [PlaneCost; 3] = [
        PlaneCost::new(cell, 0, params)?,
        PlaneCost::new(cell, 1, params)?,
        PlaneCost::new(cell, 2, params)?,
    ];
    let mut per_axis: [Option<Split>; 3] =
        std::array::from_fn(|axis| planes[axis].end_planes(events[axis], n));
    let best = |per_axis: &[Option<Split>; 3]| {
        per_axis
            .iter()
            .flatten()
            .fold(None, |best: Option<Split>, &s| match best {
                Some(b) if b.cost <= s.cost => Some(b),
                _ => Some(s),
            })
    };
    let bounds = planes.each_ref().map(|p| p.both_sides_bound(n));
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| bounds[a].total_cmp(&bounds[b]));
    if params.longest_axis_only {
        // As in pbrt: the cell's longest axis first (the lowest on ties); the others only
        // when it offers no split that beats the leaf, and not in small nodes.
        let longest = cell.largest_axis();
        order.sort_by_key(|&a| a != longest);
    }
    for (k, axis) in order.into_iter().enumerate() {
        let limit = best(&per_axis).map_or(leaf_cost, |b| b.cost.min(leaf_cost));
        if params.longest_axis_only && k > 0 && (limit < leaf_cost || n <= RETRY_ABOVE) {
            break;
        }
        if bounds[axis] < limit {
            per_axis[axis] = planes[axis].sweep(events[axis], n);
        }
    }
    best(&per_axis).filter(|s| s.cost < leaf_cost)
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
    fn radix_sort_of_events_in_triangle_order_sorts_whole_keys() {
        let mut seed = 0x9e37_79b9_u64;
        let mut next = move || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (seed >> 33) as u32
        };
        // Few distinct positions (many ties), negative and positive, flat boxes among them.
        let mut ev = Vec::new();
        for t in 0..5000u32 {
            let lo = (next() % 64) as f32 - 32.0;
            let hi = if next() % 4 == 0 {
                lo
            } else {
                lo + (next() % 8) as f32
            };
            push_events(&mut ev, &Aabb::new(Vec3::splat(lo), Vec3::splat(hi)), 0, t);
        }
        ev.push(event(-0.0, Kind::Start, 5000));
        ev.push(event(f32::INFINITY, Kind::End, 5000));
        let mut expected = ev.clone();
        sort_events(&mut expected);
        let mut tmp = vec![0; ev.len()];
        sort_events_by_position(&mut ev, &mut tmp);
        assert_eq!(ev, expected);
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
        let params = KdParams {
            intersection_cost: 1.0,
            ..KdParams::default()
        };
        let s = PlaneCost::new(&cell, 0, &params)
            .unwrap()
            .sweep(&ev, 3)
            .unwrap();
        assert_eq!(choose_split([&ev, &[], &[]], 3, &cell, &params), Some(s));
        assert!(s.pos == 1.0 || s.pos == 2.0, "{s:?}");
        let mut side = vec![BOTH; 3];
        let mut straddlers = Vec::new();
        assert_eq!(classify(&ev, &s, &mut side, &mut straddlers), (2, 1));
        assert!(straddlers.is_empty());
        assert_eq!(side[0], LEFT);
        assert_eq!(side[1], RIGHT);
    }
}
