//! An order-statistics multiset of `f32`: the balanced search tree "B" of the paper's Algorithm 1.
//!
//! The adaptive query rule (docs/algorithm.md section 8) needs, at every agent decision, the k-th largest of the
//! last N_r uncertainties, then one insertion and one deletion. The paper keeps them in a balanced binary search
//! tree for O(log N_r) per step; [`OrderStatistics`] is such a tree:
//!
//! - a treap (binary search tree on the keys, max-heap on random priorities, so its expected depth is
//!   O(log n) whatever the insertion order);
//! - every node stores one distinct key with its multiplicity and the total multiplicity of its subtree, which
//!   turns "k-th largest" into one walk from the root;
//! - nodes live in an arena (`Vec`) linked by `u32` indices, and freed slots are recycled, so a window that
//!   inserts one value and removes one value per step stops allocating once it has reached its size.
//!
//! Keys are ordered by [`f32::total_cmp`] (so `-0.0 < +0.0` and NaNs have a place), which makes the multiset
//! well defined for every bit pattern. Priorities come from an internal SplitMix64 generator with a fixed or
//! caller-given seed: the tree's shape never affects any answer, only its speed, and runs stay reproducible.

use std::cmp::Ordering;

/// Marks a missing child.
const NIL: u32 = u32::MAX;
/// Index into [`Node::children`] of the subtree with the lower keys.
const SMALLER: usize = 0;
/// Index into [`Node::children`] of the subtree with the higher keys.
const LARGER: usize = 1;

/// The side of a node on which `key` belongs, or `None` if it is the node's own key.
#[inline(always)]
fn side(key: f32, node_key: f32) -> Option<usize> {
    match key.total_cmp(&node_key) {
        Ordering::Equal => None,
        // Computed, not branched on: the comparison result is hard to predict.
        ordering => Some(if ordering.is_gt() { LARGER } else { SMALLER }),
    }
}

#[derive(Clone, Debug)]
struct Node {
    key: f32,
    /// Heap priority: a parent's priority is at least its children's.
    priority: u32,
    /// Children by side: `[SMALLER]` holds the lower keys, `[LARGER]` the higher ones.
    children: [u32; 2],
    /// How many copies of `key` the multiset holds.
    count: u32,
    /// Total multiplicity of the subtree rooted here (this node's `count` included).
    size: u32,
}

/// A multiset of `f32` with insert, remove and k-th largest in expected O(log n).
#[derive(Clone, Debug)]
pub struct OrderStatistics {
    nodes: Vec<Node>,
    free_slots: Vec<u32>,
    root: u32,
    priority_state: u64,
}

impl Default for OrderStatistics {
    fn default() -> Self {
        Self::new()
    }
}

impl OrderStatistics {
    /// Seed of the priority generator used by [`OrderStatistics::new`].
    pub(crate) const DEFAULT_SEED: u64 = 0x5EED_0F0B_5EED_0F0B;

    /// An empty multiset with the default priority seed.
    pub fn new() -> Self {
        Self::with_seed(Self::DEFAULT_SEED)
    }

    /// An empty multiset whose treap priorities come from `seed` (the shape changes, the answers do not).
    pub(crate) fn with_seed(seed: u64) -> Self {
        Self {
            nodes: Vec::new(),
            free_slots: Vec::new(),
            root: NIL,
            priority_state: seed,
        }
    }

    /// An empty multiset with room for `capacity` distinct keys before the arena reallocates.
    pub fn with_capacity(capacity: usize) -> Self {
        let mut multiset = Self::new();
        multiset.nodes.reserve(capacity);
        multiset.free_slots.reserve(capacity);
        multiset
    }

    /// Number of stored values, duplicates counted.
    pub fn len(&self) -> usize {
        self.size_of(self.root) as usize
    }

    /// Whether the multiset holds no value.
    pub fn is_empty(&self) -> bool {
        self.root == NIL
    }

    /// Removes every value, keeping the arena's memory.
    pub fn clear(&mut self) {
        self.nodes.clear();
        self.free_slots.clear();
        self.root = NIL;
    }

    /// Adds one occurrence of `value`.
    ///
    /// # Panics
    /// If the multiset already holds `u32::MAX - 1` values (far beyond any query window).
    pub fn insert(&mut self, value: f32) {
        assert!(self.len() < (NIL - 1) as usize, "OrderStatistics is full");
        self.root = self.insert_under(self.root, value);
    }

    /// Removes one occurrence of `value` (compared with `total_cmp`); returns whether one was present.
    pub fn remove(&mut self, value: f32) -> bool {
        let mut removed = false;
        self.root = self.remove_under(self.root, value, &mut removed);
        removed
    }

    /// The `k`-th largest value, 0-based (`kth_largest(0)` is the maximum), or `None` if `k >= len()`.
    pub fn kth_largest(&self, k: usize) -> Option<f32> {
        if k >= self.len() {
            return None;
        }
        // k < len <= u32::MAX, so the conversion is exact.
        let mut remaining = k as u32;
        let mut current = self.root;
        // Walk down from the root: larger keys are on the right, so skip the right subtree first.
        while current != NIL {
            let node = &self.nodes[current as usize];
            let larger = self.size_of(node.children[LARGER]);
            if remaining < larger {
                current = node.children[LARGER];
            } else if remaining < larger + node.count {
                return Some(node.key);
            } else {
                remaining -= larger + node.count;
                current = node.children[SMALLER];
            }
        }
        unreachable!("subtree sizes are inconsistent")
    }

    /// How many stored values are strictly below `value` (compared with `total_cmp`), duplicates counted.
    pub(crate) fn count_below(&self, value: f32) -> usize {
        let mut below = 0u32;
        let mut current = self.root;
        while current != NIL {
            let node = &self.nodes[current as usize];
            if node.key.total_cmp(&value).is_lt() {
                below += self.size_of(node.children[SMALLER]) + node.count;
                current = node.children[LARGER];
            } else {
                current = node.children[SMALLER];
            }
        }
        below as usize
    }

    /// The `k`-th smallest value, 0-based, or `None` if `k >= len()`.
    pub(crate) fn kth_smallest(&self, k: usize) -> Option<f32> {
        let len = self.len();
        if k >= len {
            None
        } else {
            self.kth_largest(len - 1 - k)
        }
    }

    fn size_of(&self, index: u32) -> u32 {
        if index == NIL {
            0
        } else {
            self.nodes[index as usize].size
        }
    }

    /// Recomputes a node's subtree size from its children.
    fn update_size(&mut self, index: u32) {
        let node = &self.nodes[index as usize];
        let [smaller, larger] = node.children;
        let size = self.size_of(smaller) + self.size_of(larger) + node.count;
        self.nodes[index as usize].size = size;
    }

    /// SplitMix64 step, truncated to 32 bits: cheap, seedable, and good enough for treap priorities.
    fn next_priority(&mut self) -> u32 {
        self.priority_state = self.priority_state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.priority_state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 32) as u32
    }

    fn allocate(&mut self, key: f32) -> u32 {
        let node = Node {
            key,
            priority: self.next_priority(),
            children: [NIL; 2],
            count: 1,
            size: 1,
        };
        match self.free_slots.pop() {
            Some(slot) => {
                self.nodes[slot as usize] = node;
                slot
            }
            None => {
                self.nodes.push(node);
                (self.nodes.len() - 1) as u32
            }
        }
    }

    /// Rotates the child on `side` up into `index`'s place; returns the new subtree root.
    fn rotate_up(&mut self, index: u32, side: usize) -> u32 {
        // Both sides are 0 or 1; the mask lets the compiler drop the bounds checks.
        let (side, other) = (side & 1, (side ^ 1) & 1);
        let child = self.nodes[index as usize].children[side];
        self.nodes[index as usize].children[side] = self.nodes[child as usize].children[other];
        self.nodes[child as usize].children[other] = index;
        self.update_size(index);
        self.update_size(child);
        child
    }

    /// Inserts into the subtree at `index`; returns the subtree's new root. Recursion depth is the tree depth.
    fn insert_under(&mut self, index: u32, key: f32) -> u32 {
        if index == NIL {
            return self.allocate(key);
        }
        let i = index as usize;
        let Some(side) = side(key, self.nodes[i].key) else {
            self.nodes[i].count += 1;
            self.nodes[i].size += 1;
            return index;
        };
        let child = self.insert_under(self.nodes[i].children[side], key);
        self.nodes[i].children[side] = child;
        if self.nodes[child as usize].priority > self.nodes[i].priority {
            self.rotate_up(index, side)
        } else {
            self.update_size(index);
            index
        }
    }

    /// Removes one occurrence of `key` from the subtree at `index`; returns the subtree's new root.
    fn remove_under(&mut self, index: u32, key: f32, removed: &mut bool) -> u32 {
        if index == NIL {
            return NIL;
        }
        let i = index as usize;
        let Some(side) = side(key, self.nodes[i].key) else {
            *removed = true;
            if self.nodes[i].count > 1 {
                self.nodes[i].count -= 1;
                self.nodes[i].size -= 1;
                return index;
            }
            let [smaller, larger] = self.nodes[i].children;
            let merged = self.merge(smaller, larger);
            self.free_slots.push(index);
            return merged;
        };
        let child = self.remove_under(self.nodes[i].children[side], key, removed);
        self.nodes[i].children[side] = child;
        if *removed {
            self.update_size(index);
        }
        index
    }

    /// Joins two treaps where every key of `low` is below every key of `high`.
    fn merge(&mut self, low: u32, high: u32) -> u32 {
        if low == NIL {
            return high;
        }
        if high == NIL {
            return low;
        }
        if self.nodes[low as usize].priority > self.nodes[high as usize].priority {
            let joined = self.merge(self.nodes[low as usize].children[LARGER], high);
            self.nodes[low as usize].children[LARGER] = joined;
            self.update_size(low);
            low
        } else {
            let joined = self.merge(low, self.nodes[high as usize].children[SMALLER]);
            self.nodes[high as usize].children[SMALLER] = joined;
            self.update_size(high);
            high
        }
    }

    /// Checks every structural invariant; used by the tests.
    #[cfg(test)]
    fn check_invariants(&self) {
        fn walk(
            tree: &OrderStatistics,
            index: u32,
            low: Option<f32>,
            high: Option<f32>,
        ) -> (u32, usize) {
            if index == NIL {
                return (0, 0);
            }
            let node = &tree.nodes[index as usize];
            assert!(node.count > 0);
            if let Some(low) = low {
                assert_eq!(
                    low.total_cmp(&node.key),
                    Ordering::Less,
                    "search order violated"
                );
            }
            if let Some(high) = high {
                assert_eq!(
                    node.key.total_cmp(&high),
                    Ordering::Less,
                    "search order violated"
                );
            }
            for child in node.children {
                if child != NIL {
                    assert!(
                        tree.nodes[child as usize].priority <= node.priority,
                        "heap order violated"
                    );
                }
            }
            let (left_size, left_nodes) = walk(tree, node.children[SMALLER], low, Some(node.key));
            let (right_size, right_nodes) = walk(tree, node.children[LARGER], Some(node.key), high);
            assert_eq!(
                node.size,
                left_size + right_size + node.count,
                "subtree size wrong"
            );
            (node.size, left_nodes + right_nodes + 1)
        }
        let (_, live_nodes) = walk(self, self.root, None, None);
        assert_eq!(
            live_nodes + self.free_slots.len(),
            self.nodes.len(),
            "arena slots leaked"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[derive(Clone, Debug)]
    enum Operation {
        Insert(f32),
        /// Remove the value at this position (modulo length) of the oracle, so removals usually hit.
        RemovePresent(usize),
        /// Remove an arbitrary value, usually absent.
        RemoveAny(f32),
        KthLargest(usize),
    }

    fn operation() -> impl Strategy<Value = Operation> {
        // A small value pool makes duplicates common; the full range exercises arbitrary bit patterns.
        let value = prop_oneof![(-5i32..5).prop_map(|v| v as f32 * 0.5), any::<f32>()];
        prop_oneof![
            4 => value.clone().prop_map(Operation::Insert),
            2 => any::<usize>().prop_map(Operation::RemovePresent),
            1 => value.prop_map(Operation::RemoveAny),
            2 => any::<usize>().prop_map(Operation::KthLargest),
        ]
    }

    fn position(sorted: &[f32], value: f32) -> Result<usize, usize> {
        sorted.binary_search_by(|probe| probe.total_cmp(&value))
    }

    proptest! {
        #[test]
        fn agrees_with_sorted_vec_oracle(
            operations in proptest::collection::vec(operation(), 0..400), seed in any::<u64>(),
        ) {
            let mut tree = OrderStatistics::with_seed(seed);
            // Oracle: ascending by total_cmp.
            let mut oracle: Vec<f32> = Vec::new();
            for operation in operations {
                match operation {
                    Operation::Insert(value) => {
                        tree.insert(value);
                        let at = position(&oracle, value).unwrap_or_else(|at| at);
                        oracle.insert(at, value);
                    }
                    Operation::RemovePresent(index) => {
                        if !oracle.is_empty() {
                            let value = oracle[index % oracle.len()];
                            prop_assert!(tree.remove(value));
                            let at = position(&oracle, value).unwrap();
                            oracle.remove(at);
                        }
                    }
                    Operation::RemoveAny(value) => {
                        let expected = match position(&oracle, value) {
                            Ok(at) => {
                                oracle.remove(at);
                                true
                            }
                            Err(_) => false,
                        };
                        prop_assert_eq!(tree.remove(value), expected);
                    }
                    Operation::KthLargest(k) => {
                        let k = if oracle.is_empty() { k % 3 } else { k % (oracle.len() + 2) };
                        let expected = if k < oracle.len() { Some(oracle[oracle.len() - 1 - k]) } else { None };
                        prop_assert_eq!(tree.kth_largest(k).map(f32::to_bits), expected.map(f32::to_bits));
                        let expected_small = oracle.get(k).copied();
                        prop_assert_eq!(tree.kth_smallest(k).map(f32::to_bits), expected_small.map(f32::to_bits));
                    }
                }
                prop_assert_eq!(tree.len(), oracle.len());
                prop_assert_eq!(tree.is_empty(), oracle.is_empty());
                if let Some(&probe) = oracle.get(oracle.len() / 2) {
                    let below = oracle.iter().filter(|v| v.total_cmp(&probe).is_lt()).count();
                    prop_assert_eq!(tree.count_below(probe), below);
                    prop_assert_eq!(tree.count_below(f32::INFINITY), oracle.iter().filter(|v| v.total_cmp(&f32::INFINITY).is_lt()).count());
                }
                tree.check_invariants();
            }
        }
    }

    #[test]
    fn sliding_window_stops_allocating() {
        // Steady state of the query window: one insert and one removal per step.
        let window = 1000;
        let mut tree = OrderStatistics::new();
        let mut recent = std::collections::VecDeque::new();
        let mut state = 1u64;
        let mut next_value = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32
        };
        for _ in 0..window {
            let value = next_value();
            tree.insert(value);
            recent.push_back(value);
        }
        let mut arena_capacity = tree.nodes.capacity();
        let mut free_capacity = tree.free_slots.capacity();
        let mut reallocations = 0;
        for _ in 0..20 * window {
            let value = next_value();
            tree.insert(value);
            recent.push_back(value);
            assert!(tree.remove(recent.pop_front().unwrap()));
            if tree.nodes.capacity() != arena_capacity
                || tree.free_slots.capacity() != free_capacity
            {
                reallocations += 1;
                arena_capacity = tree.nodes.capacity();
                free_capacity = tree.free_slots.capacity();
            }
        }
        tree.check_invariants();
        assert_eq!(tree.len(), window);
        // The arena never grows past window + 1 live slots; after the first growths it is stable.
        assert!(tree.nodes.len() <= window + 1);
        assert!(
            reallocations <= 2,
            "{reallocations} reallocations in steady state"
        );
    }

    #[test]
    fn degenerate_insertion_order_stays_shallow() {
        // Sorted insertion would make a plain search tree a list; the treap's depth must stay logarithmic.
        let mut tree = OrderStatistics::new();
        for i in 0..10_000 {
            tree.insert(i as f32);
        }
        fn depth(tree: &OrderStatistics, index: u32) -> usize {
            if index == NIL {
                0
            } else {
                let node = &tree.nodes[index as usize];
                let [smaller, larger] = node.children;
                1 + depth(tree, smaller).max(depth(tree, larger))
            }
        }
        let measured = depth(&tree, tree.root);
        assert!(measured < 60, "depth {measured} for 10000 sorted inserts");
        assert_eq!(tree.kth_largest(0), Some(9999.0));
        assert_eq!(tree.kth_largest(9999), Some(0.0));
    }
}
