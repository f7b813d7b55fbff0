//! A sum-tree paired with a min-tree over a fixed number of non-negative leaf values.
//!
//! Proportional prioritized replay (Schaul et al. 2016, docs/algorithm.md §3) needs three things
//! of the sampling masses `p_i^α`, each in O(log n): the total mass (to normalise), the leaf in
//! which a point `u ∈ [0, total)` of the cumulative mass falls (to sample), and the smallest mass
//! over the stored transitions (for the largest importance-sampling weight). [`SumMinTree`] keeps
//! a complete binary tree, its sums and its minima in two flat arrays with the usual heap layout: node `n`
//! has children `2n` and `2n + 1`, the root is node 1 and leaf `i` is node `size + i`, where
//! `size` is the leaf count rounded up to a power of two.
//!
//! Inner nodes are always recomputed from their two children (never adjusted by a difference), so
//! rounding errors cannot accumulate over millions of updates, and the tree is a function of its
//! leaves alone. Searches and updates come in batches (a replay batch at a time) that walk the
//! levels together, so their cache misses overlap. Masses are kept in `f64`: with
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
    /// Node `n` holds the total of the leaves below it (index 0 unused). The sums and the minima
    /// are separate arrays because the search, the hot part, reads only the sums: half the memory
    /// it would touch otherwise.
    sums: Vec<f64>,
    /// Node `n` holds the minimum of the leaves below it (index 0 unused).
    mins: Vec<f64>,
}

impl SumMinTree {
    /// A tree of `capacity` unused leaves.
    pub fn new(capacity: usize) -> Self {
        let size = capacity.max(1).next_power_of_two();
        Self {
            capacity,
            size,
            sums: vec![0.0; 2 * size],
            mins: vec![f64::INFINITY; 2 * size],
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
        self.set_many(&[(leaf, value)]);
    }

    /// Value of leaf `leaf` (0 if never set).
    pub fn get(&self, leaf: usize) -> f64 {
        assert!(
            leaf < self.capacity,
            "leaf {leaf} out of range 0..{}",
            self.capacity
        );
        self.sums[self.size + leaf]
    }

    /// Sum of all leaves.
    pub fn total(&self) -> f64 {
        self.sums[1]
    }

    /// Smallest value over the leaves that were set, `+∞` if none was.
    pub fn min(&self) -> f64 {
        self.mins[1]
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
        let mut leaf = [0];
        self.find_prefix_many(&[u], &mut leaf);
        leaf[0]
    }

    /// [`SumMinTree::find_prefix`] for many points at once: `leaves[j]` receives the leaf of `us[j]`.
    ///
    /// The walks descend together, one level at a time, so the memory reads of up to [`CHUNK`] walks are
    /// in flight at once instead of one after another: below the first few levels every read misses the
    /// cache.
    ///
    /// # Panics
    /// If the slices differ in length or the total is not positive.
    pub(crate) fn find_prefix_many(&self, us: &[f64], leaves: &mut [usize]) {
        assert_eq!(
            us.len(),
            leaves.len(),
            "find_prefix_many: slice lengths differ"
        );
        assert!(
            self.total() > 0.0,
            "find_prefix on a tree with zero total mass"
        );
        for (us, leaves) in us.chunks(CHUNK).zip(leaves.chunks_mut(CHUNK)) {
            let n = us.len();
            let mut u = [0.0f64; CHUNK];
            for (u, &point) in u.iter_mut().zip(us) {
                *u = point.max(0.0);
            }
            let mut node = [1usize; CHUNK];
            let mut width = 1;
            while width < self.size {
                for (node, u) in node[..n].iter_mut().zip(&mut u[..n]) {
                    // Invariant: the sum at `node` is > 0. Going left when `u < left` keeps it
                    // because u >= 0; going right is only done into a positive subtree; otherwise
                    // left holds all the mass.
                    let left = self.sums[2 * *node];
                    let right = self.sums[2 * *node + 1];
                    let go_right;
                    (go_right, *u) = descend(*u, left, right);
                    *node = 2 * *node + usize::from(go_right);
                    // The next node's grandchildren (4 sums, one cache line) are read two levels on:
                    // asking for them now overlaps their cache miss with this level's other walks.
                    prefetch(&self.sums, 4 * *node);
                }
                width *= 2;
            }
            for (leaf, &node) in leaves.iter_mut().zip(&node[..n]) {
                *leaf = node - self.size;
            }
        }
    }

    /// [`SumMinTree::set`] for many leaves: each `(leaf, value)` in order, so a leaf listed twice keeps
    /// its last value.
    ///
    /// The leaves are written first, then their ancestors are recomputed one level at a time, each
    /// shared ancestor once, from its two children. Every inner node is therefore its children's sum
    /// and minimum computed from their final values: the tree depends only on the leaf values, bit for
    /// bit, not on how the updates were grouped.
    ///
    /// # Panics
    /// As [`SumMinTree::set`].
    pub(crate) fn set_many(&mut self, updates: &[(usize, f64)]) {
        for updates in updates.chunks(CHUNK) {
            let mut nodes = [0usize; CHUNK];
            for (node, &(leaf, value)) in nodes.iter_mut().zip(updates) {
                assert!(
                    leaf < self.capacity,
                    "leaf {leaf} out of range 0..{}",
                    self.capacity
                );
                assert!(
                    value.is_finite() && value >= 0.0,
                    "leaf value must be finite and non-negative, got {value}"
                );
                *node = self.size + leaf;
                self.sums[*node] = value;
                self.mins[*node] = value;
            }
            let nodes = &mut nodes[..updates.len()];
            nodes.sort_unstable();
            let mut n = nodes.len();
            let mut width = 1;
            while width < self.size {
                // Parents of a sorted list are sorted: duplicates are neighbours.
                let mut kept = 0;
                for j in 0..n {
                    let parent = nodes[j] / 2;
                    if kept == 0 || nodes[kept - 1] != parent {
                        nodes[kept] = parent;
                        kept += 1;
                    }
                }
                n = kept;
                for &node in &nodes[..n] {
                    self.sums[node] = self.sums[2 * node] + self.sums[2 * node + 1];
                    self.mins[node] = self.mins[2 * node].min(self.mins[2 * node + 1]);
                }
                width *= 2;
            }
        }
    }
}

/// One step of the search from a node with child sums `left` and `right`: whether it goes right, which is
/// `!(u < left || right <= 0)`, and the point within the child, `u - left` going right and `u` otherwise.
///
/// Branch-free: which child is taken is a coin flip weighted by the masses, so a branch is mispredicted about
/// every other level. On x86-64 it is written with SSE2 masks, because LLVM compiles the plain `if` and even a
/// bit-mask formulation back into a branch.
#[inline(always)]
fn descend(u: f64, left: f64, right: f64) -> (bool, f64) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of the x86-64 baseline.
        unsafe {
            let (u, l) = (_mm_set_sd(u), _mm_set_sd(left));
            let go = _mm_and_pd(
                _mm_cmpnlt_sd(u, l),
                _mm_cmpnle_sd(_mm_set_sd(right), _mm_setzero_pd()),
            );
            // `u - 0` is `u` exactly.
            let within = _mm_sub_sd(u, _mm_and_pd(l, go));
            (_mm_movemask_pd(go) & 1 == 1, _mm_cvtsd_f64(within))
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let go = !(u < left || right <= 0.0);
        (go, if go { u - left } else { u })
    }
}

/// Asks the CPU to bring `values[index]` into the cache (nothing if `index` is out of range).
#[inline(always)]
fn prefetch(values: &[f64], index: usize) {
    #[cfg(target_arch = "x86_64")]
    if index < values.len() {
        // SAFETY: a prefetch of an address inside the slice; it reads nothing and writes nothing.
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                values.as_ptr().add(index).cast(),
            )
        };
    }
}

/// How many walks [`SumMinTree::find_prefix_many`] and [`SumMinTree::set_many`] run together (a
/// replay batch; larger inputs are taken in chunks of this size).
const CHUNK: usize = 64;

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
        /// Batched updates (duplicates in one batch, batches longer than a chunk) against a bottom-up
        /// rebuild from the final leaf values, node for node and bit for bit; batched searches against
        /// a recursive descent over that rebuild.
        #[test]
        fn batched_operations_match_a_rebuild(
            initial in prop::collection::vec(0.0f64..10.0, 1..300),
            updates in prop::collection::vec((0usize..300, 0.0f64..10.0), 0..150),
            fractions in prop::collection::vec(0.0f64..1.1, 1..150),
        ) {
            let mut tree = SumMinTree::new(initial.len());
            let all: Vec<(usize, f64)> = initial.iter().copied().enumerate().collect();
            tree.set_many(&all);
            let updates: Vec<(usize, f64)> =
                updates.into_iter().map(|(leaf, v)| (leaf % initial.len(), v)).collect();
            tree.set_many(&updates);
            let mut leaves = initial.clone();
            for &(leaf, v) in &updates {
                leaves[leaf] = v;
            }
            let size = tree.size;
            let mut sums = vec![0.0; 2 * size];
            let mut mins = vec![f64::INFINITY; 2 * size];
            for (i, &v) in leaves.iter().enumerate() {
                (sums[size + i], mins[size + i]) = (v, v);
            }
            for n in (1..size).rev() {
                sums[n] = sums[2 * n] + sums[2 * n + 1];
                mins[n] = mins[2 * n].min(mins[2 * n + 1]);
            }
            for n in 1..2 * size {
                prop_assert_eq!(tree.sums[n].to_bits(), sums[n].to_bits(), "sum of node {}", n);
                prop_assert_eq!(tree.mins[n].to_bits(), mins[n].to_bits(), "min of node {}", n);
            }
            prop_assume!(sums[1] > 0.0);
            fn descend(sums: &[f64], size: usize, node: usize, u: f64) -> usize {
                if node >= size {
                    return node - size;
                }
                let (left, right) = (sums[2 * node], sums[2 * node + 1]);
                if u < left || right <= 0.0 {
                    descend(sums, size, 2 * node, u)
                } else {
                    descend(sums, size, 2 * node + 1, u - left)
                }
            }
            let us: Vec<f64> = fractions.iter().map(|f| f * sums[1]).collect();
            let mut found = vec![usize::MAX; us.len()];
            tree.find_prefix_many(&us, &mut found);
            for (&u, &leaf) in us.iter().zip(&found) {
                prop_assert_eq!(leaf, descend(&sums, size, 1, u.max(0.0)), "u = {}", u);
            }
        }

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
