//! The SAH-optimal collapse of a binary tree into a wide one, by dynamic programming (Ylitie,
//! Karras & Laine 2017, "Efficient incoherent ray traversal on GPUs through compressed wide
//! BVHs", sections 3.1 and 3.2).
//!
//! For every binary node `n` and `j` in `1 ..= K`, `cost(n, j)` is the least SAH cost of
//! representing `n`'s subtree as a forest of at most `j` roots, each root a wide leaf (a subtree
//! of at most [`MAX_WIDE_LEAF`] triangles) or a wide node whose lanes are again such a forest
//! of at most `K` roots. Costs come bottom-up (children first, by recursion, so only one path's
//! costs live at a time); each node keeps its choices (leaf, wide node, or how many roots go to
//! the left child) in one word, from which the wide tree is written top-down, depth first, as
//! the greedy collapse writes it. Leaf sizes are chosen here, not by the binary builder.

use super::{Collapse, Item, MAX_WIDE_LEAF, WideNode, encode_leaf};

/// Costs of the wide SAH that [`super::CollapseMethod::Sah`] minimises: each is paid by a ray
/// that enters a box, weighted by the box's surface area.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WideCost {
    /// Testing a ray against one wide node's child boxes.
    pub node: f32,
    /// Entering a leaf lane.
    pub leaf: f32,
    /// Testing one block of four triangles (a leaf of `n` triangles has `ceil(n / 4)`).
    pub block: f32,
    /// Each triangle of a leaf.
    pub tri: f32,
}

impl WideCost {
    /// The costs [`super::CollapseMethod::SAH`] uses.
    pub const DEFAULT: Self = Self {
        node: 1.0,
        leaf: 0.0,
        block: 1.0,
        tri: 0.0,
    };

    /// Cost of a leaf lane of `count` triangles, per unit of its box's area.
    #[must_use]
    pub fn leaf_cost(&self, count: u32) -> f32 {
        self.leaf + self.block * count.div_ceil(4) as f32 + self.tri * count as f32
    }
}

/// Choice of a `(node, j)` entry: one wide leaf lane (for a binary leaf larger than a wide
/// leaf: as many lanes as it needs).
const LEAF: u64 = 0;
/// Choice of a `(node, j)` entry: one wide node. Values `1 .. K` are a distribution, that many
/// roots to the left child and the rest to the right.
const WIDE: u64 = 15;
/// Bits of the choice word below the wide node's own split of `K` roots.
const SPLIT_SHIFT: u32 = 32;

/// A lane of a wide node being written.
#[derive(Clone, Copy)]
enum Lane {
    Leaf(u32, u32),
    Wide(u32),
}

/// The dynamic program over one binary tree.
pub(super) struct Dp<'a, 'b> {
    pub(super) c: &'a Collapse<'b>,
    pub(super) cost: WideCost,
    /// Per binary node: the choice of `(node, j)` in bits `4 (j - 1) ..`, and the split of the
    /// node's `K` roots when it becomes a wide node at bit [`SPLIT_SHIFT`].
    pub(super) choice: &'a mut [u64],
    /// One over the root's area: costs are relative to it, so that they stay finite.
    pub(super) inv_root: f64,
}

impl Dp<'_, '_> {
    /// Fills the choices of binary node `i`'s subtree and returns `cost(i, j)` for
    /// `j = 1 ..= K` (relative to the root's area).
    pub(super) fn solve<const K: usize>(&mut self, i: u32) -> [f32; K] {
        let n = *self.c.binary(i);
        let a = (n.bounds().half_area_f64() * self.inv_root) as f32;
        let count = self.c.ranges[i as usize].1;
        if n.is_leaf() {
            if count <= MAX_WIDE_LEAF {
                self.choice[i as usize] = LEAF;
                return [a * self.cost.leaf_cost(count); K];
            }
            // Too large for one lane: several lanes of this area (an upper bound) if there is
            // room for them, else a wide node of them (written by the greedy collapse).
            let pieces = count.div_ceil(MAX_WIDE_LEAF);
            let lanes = a * self.pieces_cost(count, pieces);
            let mut out = [a * self.cost.node + lanes; K];
            let mut ch = 0;
            for (j, o) in out.iter_mut().enumerate() {
                if j + 1 >= pieces as usize {
                    *o = lanes;
                } else {
                    ch |= WIDE << (4 * j);
                }
            }
            self.choice[i as usize] = ch;
            return out;
        }
        let l = self.solve::<K>(n.first);
        let r = self.solve::<K>(n.first + 1);
        // dist[j - 1]: at most j roots shared between the children, each child at least one;
        // split[j - 1]: how many of them go to the left child (the fewest among equal costs).
        // The inner loop runs over j, branch free, so that it vectorises.
        let mut dist = [f32::INFINITY; K];
        let mut split = [1u32; K];
        for k in 1..K {
            for j in k + 1..=K {
                let c = l[k - 1] + r[j - k - 1];
                let better = c < dist[j - 1];
                dist[j - 1] = if better { c } else { dist[j - 1] };
                split[j - 1] = if better { k as u32 } else { split[j - 1] };
            }
        }
        let wide = a * self.cost.node + dist[K - 1];
        let mut out = [0f32; K];
        let mut prev = WIDE;
        out[0] = wide;
        if count <= MAX_WIDE_LEAF {
            let leaf = a * self.cost.leaf_cost(count);
            if leaf <= wide {
                out[0] = leaf;
                prev = LEAF;
            }
        }
        // More roots allowed: the best distribution, unless fewer roots cost no more. Masks
        // rather than branches: which way this goes is data dependent.
        let mut ch = prev;
        for j in 2..=K {
            let take = u64::from(dist[j - 1] < out[j - 2]).wrapping_neg();
            out[j - 1] = dist[j - 1].min(out[j - 2]);
            prev = (u64::from(split[j - 1]) & take) | (prev & !take);
            ch |= prev << (4 * (j - 1));
        }
        self.choice[i as usize] = ch | u64::from(split[K - 1]) << SPLIT_SHIFT;
        out
    }

    /// Cost per unit area of a binary leaf of `count` triangles as `pieces` leaf lanes.
    fn pieces_cost(&self, count: u32, pieces: u32) -> f32 {
        (0..pieces)
            .map(|p| self.cost.leaf_cost(piece(0, count, pieces, p).1))
            .sum()
    }

    /// Writes binary node `i` (whose choice was a wide node) as a wide node and its subtree,
    /// depth first; returns its index.
    pub(super) fn write<const K: usize>(&self, i: u32, out: &mut Vec<WideNode<K>>) -> u32 {
        let n = *self.c.binary(i);
        if n.is_leaf() {
            // A binary leaf of more than K wide leaves' triangles.
            return self.c.node(&self.c.open(Item::Node(i)), out);
        }
        let mut lanes = [Lane::Wide(0); K];
        let mut len = 0;
        let k = (self.choice[i as usize] >> SPLIT_SHIFT) as usize;
        self.lanes(n.first, k, &mut lanes, &mut len);
        self.lanes(n.first + 1, K - k, &mut lanes, &mut len);
        let idx = out.len();
        out.push(WideNode::EMPTY);
        for (k, lane) in lanes[..len].iter().enumerate() {
            out[idx].child[k] = match *lane {
                Lane::Leaf(first, count) => encode_leaf(first, count),
                Lane::Wide(c) => self.write(c, out),
            };
        }
        idx as u32
    }

    /// Appends the at most `j` roots that represent binary node `i`'s subtree.
    fn lanes<const K: usize>(&self, i: u32, j: usize, lanes: &mut [Lane; K], len: &mut usize) {
        match (self.choice[i as usize] >> (4 * (j - 1))) & 15 {
            LEAF => {
                let (first, count) = self.c.ranges[i as usize];
                let pieces = count.div_ceil(MAX_WIDE_LEAF);
                for p in 0..pieces {
                    let (f, n) = piece(first, count, pieces, p);
                    lanes[*len] = Lane::Leaf(f, n);
                    *len += 1;
                }
            }
            WIDE => {
                lanes[*len] = Lane::Wide(i);
                *len += 1;
            }
            k => {
                let n = self.c.binary(i);
                let k = k as usize;
                self.lanes(n.first, k, lanes, len);
                self.lanes(n.first + 1, j - k, lanes, len);
            }
        }
    }
}

/// Piece `p` of `pieces` nearly equal pieces of the slots `first .. first + count`.
fn piece(first: u32, count: u32, pieces: u32, p: u32) -> (u32, u32) {
    let (a, b) = (
        (u64::from(count) * u64::from(p) / u64::from(pieces)) as u32,
        (u64::from(count) * u64::from(p + 1) / u64::from(pieces)) as u32,
    );
    (first + a, b - a)
}

#[cfg(test)]
mod tests {
    use super::super::{CollapseMethod, MERGE, WideBvh};
    use super::*;
    use crate::bvh::{BuildParams, MeshBvh, brute_force_any, brute_force_closest};
    use crate::geom::{Ray, TriMesh, shapes};
    use glam::Vec3;

    /// A small deterministic generator (xorshift), to avoid a dependency in unit tests.
    fn next(s: &mut u64) -> f32 {
        *s ^= *s << 13;
        *s ^= *s >> 7;
        *s ^= *s << 17;
        (*s >> 40) as f32 / (1u64 << 24) as f32
    }

    fn soup(n: usize, s: &mut u64) -> TriMesh {
        let tris: Vec<[Vec3; 3]> = (0..n)
            .map(|_| {
                let mut r = || next(s);
                let c = Vec3::new(r(), r(), r()) * 10.0;
                let e = 0.05 + r();
                [
                    c,
                    c + Vec3::new(e, r() * e, 0.0),
                    c + Vec3::new(0.0, e, r() * e),
                ]
            })
            .collect();
        TriMesh::from_soup(&tris)
    }

    fn costs() -> [WideCost; 3] {
        [
            WideCost::DEFAULT,
            WideCost {
                node: 1.0,
                leaf: 0.0,
                block: 0.0,
                tri: 0.3,
            },
            WideCost {
                node: 1.0,
                leaf: 0.5,
                block: 0.7,
                tri: 0.1,
            },
        ]
    }

    /// The SAH collapse's tree costs what the dynamic program says (so it is written as
    /// chosen), no more than the greedy collapse's (whose trees it could have chosen: binary
    /// leaves here hold at most 8 triangles), and answers rays as brute force does.
    fn check<const K: usize>(mesh: &TriMesh, params: &BuildParams, s: &mut u64) {
        let bin = MeshBvh::build(mesh, params);
        let bvh = bin.bvh();
        assert!(bvh.nodes().len() > 1);
        for cost in costs() {
            let greedy = WideBvh::<K>::from_mesh_bvh_with(&bin, CollapseMethod::Greedy);
            let dp = WideBvh::<K>::from_mesh_bvh_with(&bin, CollapseMethod::Sah(cost));
            dp.validate(mesh).unwrap();
            let (g, d) = (greedy.sah_cost(cost), dp.sah_cost(cost));
            assert!(d <= g * (1.0 + 1e-5), "BVH{K} {cost:?}: dp {d} greedy {g}");
            let mut ranges = Vec::new();
            let c = Collapse::new(
                bvh,
                super::super::TriSlots::Copied {
                    tris: &bin.tris,
                    indices: &bin.leaf_indices,
                    prims: bvh.prim_indices(),
                },
                MERGE,
                &mut ranges,
            );
            let mut choice = vec![0; bvh.nodes().len()];
            let a = bvh.nodes()[0].bounds().half_area_f64();
            let mut dp_run = Dp {
                c: &c,
                cost,
                choice: &mut choice,
                inv_root: 1.0 / a,
            };
            let optimum = f64::from(dp_run.solve::<K>(0)[0]);
            assert!(
                (optimum - d).abs() <= 1e-4 * d,
                "BVH{K} {cost:?}: dp says {optimum}, tree costs {d}"
            );
            let b = mesh.bounds();
            for _ in 0..300 {
                let mut r = || next(s);
                let o = b.center() + Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5) * 3.0 * b.extent();
                let t = b.min + Vec3::new(r(), r(), r()) * b.extent();
                let ray = Ray::new(o, t - o);
                let want = brute_force_closest(mesh, &ray).map(|h| h.t);
                assert_eq!(dp.closest_hit(&ray).map(|h| h.t), want, "{ray:?}");
                assert_eq!(dp.any_hit(&ray), brute_force_any(mesh, &ray), "{ray:?}");
            }
        }
    }

    #[test]
    fn sah_collapse_is_optimal_and_exact() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let meshes = [
            shapes::icosphere(3),
            shapes::bumpy_sphere(3000),
            soup(2000, &mut s),
            soup(40, &mut s),
        ];
        for mesh in &meshes {
            for params in [
                BuildParams::BINNED,
                BuildParams::SWEEP,
                BuildParams::MEDIAN,
                BuildParams {
                    max_leaf_size: 1,
                    ..BuildParams::BINNED
                },
            ] {
                check::<8>(mesh, &params, &mut s);
                check::<4>(mesh, &params, &mut s);
            }
        }
    }
}
