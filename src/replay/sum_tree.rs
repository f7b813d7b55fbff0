//! A sum-tree paired with a min-tree over a fixed number of non-negative leaf values.
//!
//! Proportional prioritized replay (Schaul et al. 2016, docs/algorithm.md §3) needs three things
//! of the sampling masses `p_i^α`, each in O(log n): the total mass (to normalise), the leaf in
//! which a point `u ∈ [0, total)` of the cumulative mass falls (to sample), and the smallest mass
//! over the stored transitions (for the largest importance-sampling weight). [`SumMinTree`] keeps
//! a complete binary tree with both reductions per node in one flat array with the usual heap layout: node `n`
//! has children `2n` and `2n + 1`, the root is node 1 and leaf `i` is node `size + i`, where
//! `size` is the leaf count rounded up to a power of two.
//!
//! Inner nodes are always recomputed from their two children (never adjusted by a difference), so
//! rounding errors cannot accumulate over millions of updates. Masses are kept in `f64`: with
//! 100k leaves a running `f32` total would lose about five significant digits.
//!
//! An unused leaf holds mass 0 in the sum-tree and `+∞` in the min-tree, so it is never sampled
//! and never the minimum.

/// Sum-tree and min-tree over `capacity` leaves (see the module docs).
#[derive(Clone, Debug)]
pub struct SumMinTree {
    capacity: usize,
    /// Leaf count rounded up to a power of two; leaf `i` is node `size + i`.
    size: usize,
    /// Node `n` holds the total and the minimum of the leaves below it (index 0 unused). Keeping
    /// both in one element means an update touches one cache line per level, not two.
    nodes: Vec<Node>,
}

#[derive(Clone, Copy, Debug)]
struct Node {
    sum: f64,
    min: f64,
}

impl Node {
    const EMPTY: Node = Node {
        sum: 0.0,
        min: f64::INFINITY,
    };
}

impl SumMinTree {
    /// A tree of `capacity` unused leaves.
    pub fn new(capacity: usize) -> Self {
        let size = capacity.max(1).next_power_of_two();
        Self {
            capacity,
            size,
            nodes: vec![Node::EMPTY; 2 * size],
        }
    }

    /// Number of leaves.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Sets leaf `leaf` to `value` (finite and non-negative) and refreshes its ancestors.
    ///
    /// # Panics
    /// If `leaf >= capacity` or `value` is negative or not finite (caller bugs).
    pub fn set(&mut self, leaf: usize, value: f64) {
        assert!(
            leaf < self.capacity,
            "leaf {leaf} out of range 0..{}",
            self.capacity
        );
        assert!(
            value.is_finite() && value >= 0.0,
            "leaf value must be finite and non-negative, got {value}"
        );
        let mut node = self.size + leaf;
        self.nodes[node] = Node {
            sum: value,
            min: value,
        };
        while node > 1 {
            node /= 2;
            let (left, right) = (self.nodes[2 * node], self.nodes[2 * node + 1]);
            self.nodes[node] = Node {
                sum: left.sum + right.sum,
                min: left.min.min(right.min),
            };
        }
    }

    /// Value of leaf `leaf` (0 if never set).
    pub fn get(&self, leaf: usize) -> f64 {
        assert!(
            leaf < self.capacity,
            "leaf {leaf} out of range 0..{}",
            self.capacity
        );
        self.nodes[self.size + leaf].sum
    }

    /// Sum of all leaves.
    pub fn total(&self) -> f64 {
        self.nodes[1].sum
    }

    /// Smallest value over the leaves that were set, `+∞` if none was.
    pub fn min(&self) -> f64 {
        self.nodes[1].min
    }

    /// The leaf `i` whose cumulative interval `[c_{i-1}, c_i)` contains `u`, where
    /// `c_i = leaf_0 + … + leaf_i`; that is, the first leaf with `c_i > u`. Drawing `u` uniformly
    /// from `[0, total)` therefore picks leaf `i` with probability `leaf_i / total`.
    ///
    /// The returned leaf always has a positive value: a `u` at or beyond the total (which rounding
    /// in the caller can produce) lands on the last positive leaf rather than on an empty one.
    ///
    /// # Panics
    /// If the total is not positive (nothing to sample from).
    pub fn find_prefix(&self, u: f64) -> usize {
        assert!(
            self.total() > 0.0,
            "find_prefix on a tree with zero total mass"
        );
        let mut u = u.max(0.0);
        let mut node = 1;
        // Invariant: the sum at `node` is > 0. Going left when `u < left` keeps it because
        // u >= 0; going right is only done into a positive subtree; otherwise left holds all
        // the mass.
        // Branch-free: which child is taken is a coin flip weighted by the masses, so a branch would be
        // mispredicted about every other level.
        while node < self.size {
            let left = self.nodes[2 * node].sum;
            let right = self.nodes[2 * node + 1].sum;
            let go_right = !(u < left || right <= 0.0);
            u = if go_right { u - left } else { u };
            node = 2 * node + usize::from(go_right);
        }
        node - self.size
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Oracle: the first leaf whose running (left-to-right) sum exceeds `u`, else the last
    /// positive leaf.
    fn linear_find(values: &[f64], u: f64) -> usize {
        let mut cumulative = 0.0;
        for (i, &v) in values.iter().enumerate() {
            cumulative += v;
            if cumulative > u {
                return i;
            }
        }
        values.iter().rposition(|&v| v > 0.0).unwrap()
    }

    fn build(values: &[f64]) -> SumMinTree {
        let mut tree = SumMinTree::new(values.len());
        for (i, &v) in values.iter().enumerate() {
            tree.set(i, v);
        }
        tree
    }

    #[test]
    fn small_tree_matches_hand_computed_intervals() {
        // Intervals: leaf 0 -> [0,1), leaf 1 empty, leaf 2 -> [1,3), leaf 3 -> [3,6).
        let tree = build(&[1.0, 0.0, 2.0, 3.0]);
        assert_eq!(tree.total(), 6.0);
        assert_eq!(tree.min(), 0.0);
        let expect = [
            (0.0, 0),
            (0.999, 0),
            (1.0, 2),
            (2.5, 2),
            (3.0, 3),
            (5.99, 3),
            (6.0, 3),
            (1e9, 3),
        ];
        for (u, leaf) in expect {
            assert_eq!(tree.find_prefix(u), leaf, "u = {u}");
        }
    }

    #[test]
    fn unset_leaves_are_never_found_and_never_the_minimum() {
        // 5 leaves round up to 8: leaves 5..8 are padding, leaf 4 is unused.
        let mut tree = SumMinTree::new(5);
        tree.set(0, 0.5);
        tree.set(2, 0.25);
        assert_eq!(tree.min(), 0.25);
        assert_eq!(tree.find_prefix(0.75), 2);
        assert_eq!(tree.find_prefix(100.0), 2);
        tree.set(2, 0.0);
        assert_eq!(tree.find_prefix(0.6), 0);
    }

    proptest! {
        /// Integer masses make every partial sum exact, so the tree and the linear scan must agree
        /// for every `u`, including points exactly on interval boundaries.
        #[test]
        fn find_prefix_matches_linear_scan(
            values in prop::collection::vec(0u32..20, 1..70),
            fractions in prop::collection::vec(0.0f64..1.0, 1..20),
            boundary in 0usize..70,
        ) {
            let values: Vec<f64> = values.into_iter().map(f64::from).collect();
            prop_assume!(values.iter().any(|&v| v > 0.0));
            let tree = build(&values);
            let total: f64 = values.iter().sum();
            prop_assert_eq!(tree.total(), total);
            let mut points: Vec<f64> = fractions.iter().map(|f| (f * total).floor()).collect();
            points.extend(fractions.iter().map(|f| f * total));
            points.push(values[..boundary.min(values.len())].iter().sum());
            points.push(total);
            for u in points {
                prop_assert_eq!(tree.find_prefix(u), linear_find(&values, u), "u = {}", u);
            }
        }

        /// Arbitrary masses after a sequence of overwrites: totals and minima agree with direct
        /// computation, and search agrees with the scan away from rounding-sized boundary gaps.
        #[test]
        fn updates_keep_sum_min_and_search_consistent(
            initial in prop::collection::vec(0.0f64..10.0, 1..50),
            updates in prop::collection::vec((0usize..50, 0.0f64..10.0), 0..100),
            fractions in prop::collection::vec(0.0f64..1.0, 1..20),
        ) {
            let mut values = initial;
            let mut tree = build(&values);
            for (leaf, v) in updates {
                let leaf = leaf % values.len();
                values[leaf] = v;
                tree.set(leaf, v);
            }
            let total: f64 = values.iter().sum();
            prop_assert!((tree.total() - total).abs() <= 1e-9 * total.max(1.0));
            let min = values.iter().copied().fold(f64::INFINITY, f64::min);
            prop_assert_eq!(tree.min(), min);
            prop_assume!(total > 0.0);
            let mut cumulative = Vec::with_capacity(values.len());
            let mut running = 0.0;
            for &v in &values {
                running += v;
                cumulative.push(running);
            }
            for f in fractions {
                let u = f * total;
                // Skip points within rounding distance of an interval boundary.
                if cumulative.iter().any(|&c| (c - u).abs() < 1e-9) {
                    continue;
                }
                let leaf = tree.find_prefix(u);
                prop_assert_eq!(leaf, linear_find(&values, u));
                prop_assert!(values[leaf] > 0.0);
            }
        }
    }
}
