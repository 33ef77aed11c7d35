//! Median split: along the longest axis of the centroid bounds, cut at the median centroid.

use super::{PrimRef, RangeBounds, Split, Splitter};

/// The median splitter; its field is the largest leaf size.
pub(crate) struct Median(pub usize);

impl Splitter for Median {
    type Scratch = ();

    fn scratch(&self) {}

    fn split(&self, refs: &mut [PrimRef], rb: &RangeBounds, _: &mut ()) -> Option<Split> {
        // When all centroids coincide the caller halves the range, which is the same cut.
        if refs.len() <= self.0 {
            return None;
        }
        let ext = rb.cbounds.max - rb.cbounds.min;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        if ext[axis].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let mid = refs.len() / 2;
        select_median(refs, mid, axis);
        Some(Split {
            mid,
            left: RangeBounds::of(&refs[..mid], usize::MAX),
            right: RangeBounds::of(&refs[mid..], usize::MAX),
        })
    }
}

/// Puts the reference with the `mid`-th smallest centroid on `axis` at `mid`, the smaller ones
/// before it. Kept out of line: inlined into `split`, the selection runs slower.
#[inline(never)]
fn select_median(refs: &mut [PrimRef], mid: usize, axis: usize) {
    refs.select_nth_unstable_by(mid, |a, b| a.c2()[axis].total_cmp(&b.c2()[axis]));
}
