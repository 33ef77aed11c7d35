//! SAH cost of a tree: the expected cost of a random ray that hits the root,
//! `sum over interior n of Ct A(n)/A(root) + sum over leaves l of Ci N(l) A(l)/A(root)`.

use super::Bvh;

/// Cost of visiting an interior node in reported SAH figures (as in peer comparisons).
pub const TRAVERSAL_COST: f32 = 1.0;
/// Cost of one primitive test in reported SAH figures.
pub const INTERSECTION_COST: f32 = 1.0;

/// The two constants of an SAH cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SahCost {
    /// Cost of visiting an interior node (the root counts as one).
    pub traversal: f32,
    /// Cost of intersecting one primitive.
    pub intersection: f32,
}

impl Default for SahCost {
    fn default() -> Self {
        Self {
            traversal: TRAVERSAL_COST,
            intersection: INTERSECTION_COST,
        }
    }
}

impl Bvh {
    /// SAH cost with both constants 1, normalised by the root's area: the figure reported
    /// everywhere (0 for the empty tree).
    #[must_use]
    pub fn sah_cost(&self) -> f32 {
        self.sah_cost_with(SahCost::default())
    }

    /// SAH cost with the given constants, normalised by the root's area.
    #[must_use]
    pub fn sah_cost_with(&self, c: SahCost) -> f32 {
        let Some(root) = self.nodes.first() else {
            return 0.0;
        };
        // Millions of terms: accumulate in f64 so the sum does not drift.
        let sum: f64 = self
            .nodes
            .iter()
            .map(|n| {
                let a = n.bounds().half_area_f64();
                if n.is_leaf() {
                    c.intersection as f64 * n.count as f64 * a
                } else {
                    c.traversal as f64 * a
                }
            })
            .sum();
        normalise(sum, root.bounds().half_area_f64(), root.count, c)
    }

    /// SAH cost of every subtree, each normalised by its own root's area, written to `out`
    /// (resized to the node count): where a refitted tree has degraded, these grow.
    pub fn subtree_sah(&self, c: SahCost, out: &mut Vec<f32>) {
        out.clear();
        out.resize(self.nodes.len(), 0.0);
        // Unnormalised sums bottom-up (children after parents), normalised in a second pass.
        for (i, n) in self.nodes.iter().enumerate().rev() {
            let a = n.bounds().half_area();
            out[i] = if n.is_leaf() {
                c.intersection * n.count as f32 * a
            } else {
                c.traversal * a + out[n.first as usize] + out[n.first as usize + 1]
            };
        }
        for (cost, n) in out.iter_mut().zip(&self.nodes) {
            *cost = normalise(f64::from(*cost), n.bounds().half_area_f64(), n.count, c);
        }
    }
}

/// Divides by the area (in `f64`: a root box with extents past about 1e19 has an area beyond
/// `f32`); a tree whose root has no area (all primitives in one point) costs what its
/// primitives cost.
fn normalise(sum: f64, area: f64, root_count: u32, c: SahCost) -> f32 {
    if area > 0.0 && area.is_finite() {
        (sum / area) as f32
    } else if root_count > 0 {
        c.intersection * root_count as f32
    } else {
        c.traversal
    }
}
