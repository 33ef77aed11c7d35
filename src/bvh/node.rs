use crate::geom::Aabb;
use glam::Vec3;

/// One BVH node in 32 bytes: its box, and either its children (interior) or its primitives (leaf).
///
/// Interior nodes (`count == 0`) keep their two children adjacent at `first` and `first + 1`,
/// always after the node itself. Leaves (`count > 0`) own the slots
/// `first .. first + count` of the BVH's primitive index array.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Zeroable)]
pub struct Node {
    /// Lower corner of the box.
    pub min: [f32; 3],
    /// Interior: index of the left child. Leaf: first primitive slot.
    pub first: u32,
    /// Upper corner of the box.
    pub max: [f32; 3],
    /// Number of primitives; 0 for interior nodes.
    pub count: u32,
}

const _: () = assert!(std::mem::size_of::<Node>() == 32);
const _: () = assert!(std::mem::align_of::<Node>() == 4);

impl Node {
    /// A leaf over primitive slots `first .. first + count` (`count > 0`).
    #[must_use]
    #[inline]
    pub fn leaf(bounds: Aabb, first: u32, count: u32) -> Self {
        debug_assert!(count > 0);
        Self {
            min: bounds.min.into(),
            first,
            max: bounds.max.into(),
            count,
        }
    }

    /// An interior node whose children are at `left` and `left + 1`.
    #[must_use]
    #[inline]
    pub fn interior(bounds: Aabb, left: u32) -> Self {
        Self {
            min: bounds.min.into(),
            first: left,
            max: bounds.max.into(),
            count: 0,
        }
    }

    /// True for a leaf.
    #[must_use]
    #[inline(always)]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }

    /// The node's box.
    #[must_use]
    #[inline(always)]
    pub fn bounds(&self) -> Aabb {
        Aabb::new(Vec3::from(self.min), Vec3::from(self.max))
    }

    /// Replaces the node's box.
    #[inline(always)]
    pub fn set_bounds(&mut self, b: Aabb) {
        self.min = b.min.into();
        self.max = b.max.into();
    }
}

/// One past the last descendant of interior node `n` (in the builders' layout a node's
/// descendants follow one another: its children, the left one's descendants, the right's).
pub(crate) fn descendants_end(nodes: &[Node], mut n: usize) -> usize {
    loop {
        let c = nodes[n].first as usize;
        if !nodes[c + 1].is_leaf() {
            n = c + 1;
        } else if !nodes[c].is_leaf() {
            n = c;
        } else {
            return c + 2;
        }
    }
}
