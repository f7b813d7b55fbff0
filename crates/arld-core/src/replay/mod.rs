//! Experience replay: proportional prioritized replay with a permanent demonstration part, or
//! plain uniform replay.
//!
//! The memory has two parts (docs/algorithm.md §3, following DQfD):
//! - a **demonstration part** of at most `demo_capacity` transitions, filled in arrival order and
//!   never overwritten (pushing more is a [`ReplayError::DemoCapacityFull`] error);
//! - an **agent part**, a FIFO ring of `capacity` transitions: once full, each new agent transition
//!   replaces the oldest one. Demonstrations do not count against `capacity`.
//!
//! Every stored transition has a *slot*, the handle reported in [`Batch::idx`] and accepted by
//! [`Replay::update_priorities`]: demonstration `d` lives in slot `d`, agent ring position `r`
//! in slot `demo_capacity + r`. A slot names a transition until the ring overwrites it, so
//! priorities should be updated before the next push (as a learner does: sample, learn, update).
//!
//! **Prioritized sampling** (Schaul et al. 2016, proportional variant; docs/algorithm.md §3):
//! - priority `p_i = |δ_i| + ε`, with `ε = eps_demo` for demonstrations and `eps_agent` for agent
//!   transitions (DQfD's demonstration bonus);
//! - `P(i) = p_i^α / Σ_k p_k^α`; the masses `p_i^α` live in one [`SumMinTree`] per part;
//! - a batch of `B` is drawn stratified: the total mass is cut into `B` equal segments and one
//!   point is drawn uniformly in each, so every draw still has marginal law `P(i)`;
//! - importance-sampling weights `w_i = (N P(i))^-β / max_j (N P(j))^-β`, with `N` the number of
//!   stored transitions and `max_j` over the whole memory, not just the batch. The largest weight
//!   belongs to the smallest mass, which the min-tree tracks, so `w_i = (p_i^α / min_j p_j^α)^-β ≤ 1`;
//! - a new transition enters at the **maximum raw priority** `max p` seen so far (over every push and
//!   update, both parts; it starts at 1 and never decreases), i.e. with mass `(max p)^α`. The
//!   maximum is kept in raw priority space; since `p ↦ p^α` is increasing this is the same
//!   transition as the maximum mass.
//!
//! **Uniform sampling** (`prioritized = false`): every stored transition is equally likely and all
//! weights are 1. Raw priorities are still recorded (see [`Replay::priority`]), but the trees are
//! not maintained.
//!
//! `Replay::sample_demo_only` draws from the demonstration part alone (DQfD pre-training,
//! docs/algorithm.md §9), prioritized among demonstrations: `N` and the weight normaliser are then
//! taken over the demonstrations only.
//!
//! **n-step returns** (DQfD's optional n-step loss, off in the paper): with `n_step > 0` the memory computes each
//! transition's n-step return itself (see `nstep`): a pushed transition waits until its return is known, and
//! [`Replay::end_episode`] stores the rest of an episode with shortened horizons.
//!
//! Storage is a set of flat arrays preallocated for `demo_capacity + capacity` slots
//! (observations as `[slot][obs_dim]`), and sampling writes into a reusable [`Batch`], so steady
//! state training allocates nothing here. All randomness comes from the caller's generator.

pub(crate) mod nstep;
pub(crate) mod sum_tree;

pub use sum_tree::SumMinTree;

use nstep::NStepQueue;

use crate::state::{Persist, StateDict, StateError};
use crate::task::{Action, ActionColumn};
use rand::Rng;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Replay settings (defaults: docs/algorithm.md §3 and the CartPole memory size of §9).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReplayConfig {
    /// Size of the agent FIFO ring ("Memory size" in the paper).
    pub capacity: usize,
    /// Maximum number of permanent demonstration transitions (not counted in `capacity`).
    pub demo_capacity: usize,
    /// Proportional prioritized sampling if true, uniform sampling if false.
    pub prioritized: bool,
    /// Priority exponent α in `P(i) ∝ p_i^α` (0.6, Schaul et al.).
    pub alpha: f32,
    /// Priority bonus ε for agent transitions (0.001, DQfD).
    pub eps_agent: f32,
    /// Priority bonus ε for demonstration transitions (1.0, DQfD).
    pub eps_demo: f32,
    /// Horizon n of the n-step return stored with every transition; 0: none (DQfD's optional n-step loss; off
    /// in the paper).
    pub n_step: usize,
    /// Discount γ of the n-step returns (unused when `n_step` is 0).
    pub gamma: f32,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        Self {
            capacity: 10_000,
            demo_capacity: 0,
            prioritized: true,
            alpha: 0.6,
            eps_agent: 0.001,
            eps_demo: 1.0,
            n_step: 0,
            gamma: 0.99,
        }
    }
}

impl ReplayConfig {
    /// Bytes the memory allocates up front for observations of length `obs_dim` (every slot's arrays and
    /// both trees; a tree of `c` leaves has `2 · next_power_of_two(c)` nodes of two `f64`).
    pub(crate) fn memory_bytes(&self, obs_dim: usize) -> f64 {
        let slots = self.capacity as f64 + self.demo_capacity as f64;
        let obs_rows = if self.n_step > 0 { 3.0 } else { 2.0 };
        let per_slot = obs_rows * obs_dim as f64 * 4.0 // obs, next_obs (and the n-step observation)
            + 8.0 + 4.0 + 1.0 + 4.0 // action, reward, terminal, priority
            + if self.n_step > 0 { 8.0 } else { 0.0 }; // n-step reward and discount
        let tree = |c: usize| 2.0 * (c.max(1) as f64).log2().ceil().exp2() * 16.0;
        slots * per_slot + tree(self.capacity) + tree(self.demo_capacity)
    }

    /// Checks the values a user may have put in a configuration file.
    pub fn validate(&self) -> Result<(), ReplayError> {
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(ReplayError::InvalidConfig(format!(
                "alpha must be finite and >= 0, got {}",
                self.alpha
            )));
        }
        for (name, eps) in [("eps_agent", self.eps_agent), ("eps_demo", self.eps_demo)] {
            // A positive ε keeps every transition sampleable (Schaul et al. §3.3).
            if !(eps.is_finite() && eps > 0.0) {
                return Err(ReplayError::InvalidConfig(format!(
                    "{name} must be finite and > 0, got {eps}"
                )));
            }
        }
        if self.capacity == 0 && self.demo_capacity == 0 {
            return Err(ReplayError::InvalidConfig(
                "capacity and demo_capacity are both 0: the memory could hold nothing".into(),
            ));
        }
        Ok(())
    }
}

/// Errors from storing transitions or from a bad configuration.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ReplayError {
    #[error(
        "the demonstration part is full ({demo_capacity} transitions); demonstrations are never evicted"
    )]
    DemoCapacityFull { demo_capacity: usize },
    #[error("the agent part has capacity 0: cannot store an agent transition")]
    NoAgentCapacity,
    #[error("{what} has length {got}, expected the observation size {expected}")]
    ObsDimMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("{what} contains a non-finite value (NaN or infinity)")]
    NonFinite { what: &'static str },
    #[error("invalid replay configuration: {0}")]
    InvalidConfig(String),
}

/// A sampled batch, laid out for the learner; reused across calls so sampling does not allocate.
#[derive(Clone, Debug)]
pub struct Batch<A: Action = usize> {
    /// Slot of each sample, to pass back to [`Replay::update_priorities`].
    pub idx: Vec<usize>,
    /// Importance-sampling weight of each sample (all 1 in uniform mode).
    pub weights: Vec<f32>,
    /// Observations, `[sample][obs_dim]` row-major.
    pub obs: Vec<f32>,
    pub actions: A::Column,
    pub rewards: Vec<f32>,
    /// Next observations, `[sample][obs_dim]` row-major.
    pub next_obs: Vec<f32>,
    /// Bootstrap cut: the target must not bootstrap from `next_obs`.
    pub terminal: Vec<bool>,
    /// The sample is a demonstration (the large-margin loss applies, docs/algorithm.md §4).
    pub is_demo: Vec<bool>,
    /// n-step returns (filled only when the memory stores them): reward sum, the observation n steps
    /// later (`[sample][obs_dim]`), and the discount of its value (0 when the episode ended before).
    pub nstep_rewards: Vec<f32>,
    pub nstep_next_obs: Vec<f32>,
    pub nstep_discounts: Vec<f32>,
}

impl<A: Action> Default for Batch<A> {
    fn default() -> Self {
        Self {
            idx: Vec::new(),
            weights: Vec::new(),
            obs: Vec::new(),
            actions: A::Column::default(),
            rewards: Vec::new(),
            next_obs: Vec::new(),
            terminal: Vec::new(),
            is_demo: Vec::new(),
            nstep_rewards: Vec::new(),
            nstep_next_obs: Vec::new(),
            nstep_discounts: Vec::new(),
        }
    }
}

impl<A: Action> Batch<A> {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.idx.len()
    }

    pub fn is_empty(&self) -> bool {
        self.idx.is_empty()
    }

    /// The return each sample's target adds to its bootstrapped value, for a learner with one target: the
    /// n-step return when the memory keeps them, otherwise the reward.
    pub fn returns(&self) -> &[f32] {
        match self.nstep_rewards.is_empty() {
            true => &self.rewards,
            false => &self.nstep_rewards,
        }
    }

    /// The observations the targets of [`Self::returns`] bootstrap from, `[sample][obs_dim]`.
    pub(crate) fn bootstrap_obs(&self) -> &[f32] {
        match self.nstep_rewards.is_empty() {
            true => &self.next_obs,
            false => &self.nstep_next_obs,
        }
    }

    /// The discount of sample `r`'s bootstrapped value in the target of [`Self::returns`]: `gamma^n` with
    /// n-step returns, otherwise `gamma`; 0 at a bootstrap cut.
    pub(crate) fn discount(&self, r: usize, gamma: f32) -> f32 {
        match (self.nstep_rewards.is_empty(), self.terminal[r]) {
            (false, _) => self.nstep_discounts[r],
            (true, true) => 0.0,
            (true, false) => gamma,
        }
    }

    fn clear(&mut self) {
        self.idx.clear();
        self.weights.clear();
        self.obs.clear();
        self.actions.clear();
        self.rewards.clear();
        self.next_obs.clear();
        self.terminal.clear();
        self.is_demo.clear();
        self.nstep_rewards.clear();
        self.nstep_next_obs.clear();
        self.nstep_discounts.clear();
    }
}

/// One environment transition: what enters the memory ([`Replay::push`]) and what a stored slot holds
/// ([`Replay::transition`]). `terminal` is the bootstrap cut (true termination, or truncation when so
/// configured); `is_demo` marks a demonstration (the expert acted).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transition<'a, A: Action = usize> {
    pub obs: &'a [f32],
    pub action: A::Ref<'a>,
    pub reward: f32,
    pub next_obs: &'a [f32],
    pub terminal: bool,
    pub is_demo: bool,
}

/// The replay memory (see the module docs for layout and sampling rules).
#[derive(Clone, Debug)]
pub struct Replay<A: Action = usize> {
    obs_dim: usize,
    cfg: ReplayConfig,
    // Per-slot storage for `demo_capacity + capacity` slots, demonstrations first.
    obs: Vec<f32>,
    next_obs: Vec<f32>,
    actions: A::Column,
    rewards: Vec<f32>,
    terminal: Vec<bool>,
    /// n-step returns, allocated only when `cfg.n_step > 0`.
    nstep_next_obs: Vec<f32>,
    nstep_rewards: Vec<f32>,
    nstep_discounts: Vec<f32>,
    /// Raw priority `p = |δ| + ε` of each slot.
    priorities: Vec<f32>,
    /// Masses `p^α` of the demonstration slots (leaf `d` = slot `d`).
    demo_tree: SumMinTree,
    /// Masses `p^α` of the agent ring (leaf `r` = slot `demo_capacity + r`).
    agent_tree: SumMinTree,
    n_demo: usize,
    n_agent: usize,
    /// Ring position the next agent transition is written to (the oldest one once full).
    agent_next: usize,
    /// Largest raw priority seen so far; new transitions enter with it.
    max_priority: f32,
    /// Transitions of the current episode waiting for their n-step return (`cfg.n_step > 0`).
    nstep: Option<NStepQueue<A>>,
    /// Reused buffers of the batched tree searches and updates (no allocation per step).
    scratch: Scratch,
}

/// Per-tree buffers of one batched search or update.
#[derive(Clone, Debug, Default)]
struct TreeScratch {
    points: Vec<f64>,
    leaves: Vec<usize>,
    updates: Vec<(usize, f64)>,
}

impl TreeScratch {
    /// Finds the leaf of every point in `tree`.
    fn search(&mut self, tree: &SumMinTree) {
        self.leaves.resize(self.points.len(), 0);
        if !self.points.is_empty() {
            tree.find_prefix_many(&self.points, &mut self.leaves);
        }
    }
}

/// [`TreeScratch`] for both trees, and which tree each point of a batch went to.
#[derive(Clone, Debug, Default)]
struct Scratch {
    demo: TreeScratch,
    agent: TreeScratch,
    in_demo: Vec<bool>,
}

impl Scratch {
    fn clear(&mut self) {
        for tree in [&mut self.demo, &mut self.agent] {
            tree.points.clear();
            tree.leaves.clear();
            tree.updates.clear();
        }
        self.in_demo.clear();
    }
}

impl Replay {
    /// An empty memory for observations of length `obs_dim`.
    ///
    /// # Panics
    /// If `cfg` fails [`ReplayConfig::validate`]; use `Replay::try_new` for configurations that
    /// come from the user.
    pub fn new(obs_dim: usize, cfg: &ReplayConfig) -> Self {
        Self::try_new(obs_dim, cfg).unwrap_or_else(|e| panic!("{e}"))
    }

    /// An empty memory, or the configuration error.
    pub(crate) fn try_new(obs_dim: usize, cfg: &ReplayConfig) -> Result<Self, ReplayError> {
        Self::try_with_action_width(obs_dim, 1, cfg)
    }
}

impl<A: Action> Replay<A> {
    /// An empty memory for observations of `obs_dim` numbers and actions of `action_width` numbers each (the
    /// task's [`crate::task::TaskSpec::action_width`]), or the configuration error.
    pub(crate) fn try_with_action_width(
        obs_dim: usize,
        action_width: usize,
        cfg: &ReplayConfig,
    ) -> Result<Self, ReplayError> {
        cfg.validate()?;
        let slots = cfg.demo_capacity + cfg.capacity;
        let n_step = cfg.n_step > 0;
        Ok(Self {
            obs_dim,
            cfg: cfg.clone(),
            obs: vec![0.0; slots * obs_dim],
            next_obs: vec![0.0; slots * obs_dim],
            actions: A::Column::zeros(slots, action_width),
            rewards: vec![0.0; slots],
            terminal: vec![false; slots],
            nstep_next_obs: vec![0.0; if n_step { slots * obs_dim } else { 0 }],
            nstep_rewards: vec![0.0; if n_step { slots } else { 0 }],
            nstep_discounts: vec![0.0; if n_step { slots } else { 0 }],
            priorities: vec![0.0; slots],
            demo_tree: SumMinTree::new(cfg.demo_capacity),
            agent_tree: SumMinTree::new(cfg.capacity),
            n_demo: 0,
            n_agent: 0,
            agent_next: 0,
            max_priority: 1.0,
            nstep: n_step.then(|| NStepQueue::new(cfg.n_step, cfg.gamma)),
            scratch: Scratch::default(),
        })
    }

    /// Stores one transition. A demonstration goes to the permanent part; an agent transition to the ring,
    /// evicting the oldest agent transition when the ring is full. Either enters with the current maximum
    /// priority. With n-step returns, the transition is checked now but stored once its return is known (at
    /// the latest when its episode ends: a terminal transition, or [`Replay::end_episode`]).
    pub fn push(&mut self, t: Transition<'_, A>) -> Result<(), ReplayError> {
        self.check(&t)?;
        let Some(mut queue) = self.nstep.take() else {
            return self.store(t, None);
        };
        let result = queue.push(t, |t, n| self.store(t, Some(n)));
        self.nstep = Some(queue);
        result
    }

    /// The episode ended (termination or time limit): stores the transitions still waiting for their n-step
    /// return, with shortened horizons. Nothing to do without n-step returns.
    pub fn end_episode(&mut self) -> Result<(), ReplayError> {
        let Some(mut queue) = self.nstep.take() else {
            return Ok(());
        };
        let result = queue.end_episode(|t, n| self.store(t, Some(n)));
        self.nstep = Some(queue);
        result
    }

    /// Rejects a transition that does not fit the memory or holds a non-finite number.
    fn check(&self, t: &Transition<'_, A>) -> Result<(), ReplayError> {
        for (what, o) in [("obs", t.obs), ("next_obs", t.next_obs)] {
            if o.len() != self.obs_dim {
                return Err(ReplayError::ObsDimMismatch {
                    what,
                    expected: self.obs_dim,
                    got: o.len(),
                });
            }
            if !o.iter().all(|x| x.is_finite()) {
                return Err(ReplayError::NonFinite { what });
            }
        }
        if !t.reward.is_finite() {
            return Err(ReplayError::NonFinite { what: "reward" });
        }
        Ok(())
    }

    /// Writes a checked transition (and its n-step return) into its slot.
    fn store(
        &mut self,
        t: Transition<'_, A>,
        n_step: Option<nstep::NStepReturn<'_>>,
    ) -> Result<(), ReplayError> {
        let Transition {
            obs,
            action,
            reward,
            next_obs,
            terminal,
            is_demo,
        } = t;
        let slot = if is_demo {
            if self.n_demo == self.cfg.demo_capacity {
                return Err(ReplayError::DemoCapacityFull {
                    demo_capacity: self.cfg.demo_capacity,
                });
            }
            self.n_demo += 1;
            self.n_demo - 1
        } else {
            if self.cfg.capacity == 0 {
                return Err(ReplayError::NoAgentCapacity);
            }
            let ring_pos = self.agent_next;
            self.agent_next = (self.agent_next + 1) % self.cfg.capacity;
            self.n_agent = (self.n_agent + 1).min(self.cfg.capacity);
            self.cfg.demo_capacity + ring_pos
        };
        let row = slot * self.obs_dim..(slot + 1) * self.obs_dim;
        self.obs[row.clone()].copy_from_slice(obs);
        self.next_obs[row].copy_from_slice(next_obs);
        self.actions.set(slot, action);
        self.rewards[slot] = reward;
        self.terminal[slot] = terminal;
        if let Some(n) = n_step {
            let row = slot * self.obs_dim..(slot + 1) * self.obs_dim;
            self.nstep_next_obs[row].copy_from_slice(n.next_obs);
            self.nstep_rewards[slot] = n.reward;
            self.nstep_discounts[slot] = n.discount;
        }
        self.set_priority(slot, self.max_priority);
        Ok(())
    }

    /// Number of stored transitions (demonstrations plus agent transitions).
    pub fn len(&self) -> usize {
        self.n_demo + self.n_agent
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Number of stored demonstrations.
    pub fn n_demo(&self) -> usize {
        self.n_demo
    }

    /// Number of stored agent transitions.
    pub fn n_agent(&self) -> usize {
        self.n_agent
    }

    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    pub fn config(&self) -> &ReplayConfig {
        &self.cfg
    }

    /// Largest raw priority seen so far (the priority new transitions get).
    pub fn max_priority(&self) -> f32 {
        self.max_priority
    }

    /// Raw priority `p` of a stored slot, `None` if the slot holds nothing.
    pub fn priority(&self, slot: usize) -> Option<f32> {
        self.is_stored(slot).then(|| self.priorities[slot])
    }

    /// The transition in `slot`, `None` if the slot holds nothing.
    pub fn transition(&self, slot: usize) -> Option<Transition<'_, A>> {
        if !self.is_stored(slot) {
            return None;
        }
        let row = slot * self.obs_dim..(slot + 1) * self.obs_dim;
        Some(Transition {
            obs: &self.obs[row.clone()],
            action: self.actions.get(slot),
            reward: self.rewards[slot],
            next_obs: &self.next_obs[row],
            terminal: self.terminal[slot],
            is_demo: self.is_demo_slot(slot),
        })
    }

    /// Slots that currently hold a transition: demonstrations first, then the agent ring in ring
    /// order (not age order).
    pub fn stored_slots(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.n_demo).chain(self.cfg.demo_capacity..self.cfg.demo_capacity + self.n_agent)
    }

    /// Draws `batch_size` transitions (with replacement) into `out`, replacing its contents.
    /// Prioritized: stratified proportional draws with IS weights for exponent `beta`;
    /// uniform: equally likely, weights 1.
    ///
    /// # Panics
    /// If the memory is empty.
    pub fn sample(&mut self, batch_size: usize, beta: f32, rng: &mut impl Rng, out: &mut Batch<A>) {
        assert!(!self.is_empty(), "sample from an empty replay memory");
        out.clear();
        if !self.cfg.prioritized {
            let n = self.len();
            for _ in 0..batch_size {
                let k = rng.random_range(0..n);
                let slot = if k < self.n_demo {
                    k
                } else {
                    self.cfg.demo_capacity + (k - self.n_demo)
                };
                out.idx.push(slot);
                out.weights.push(1.0);
            }
            self.gather(out);
            return;
        }
        let demo_total = self.demo_tree.total();
        let agent_total = self.agent_tree.total();
        let total = demo_total + agent_total;
        let min_mass = self.demo_tree.min().min(self.agent_tree.min());
        let segment = total / batch_size as f64;
        // The demonstration part covers [0, demo_total) of the mass, the ring the rest. The points
        // are drawn in order, then each tree's share is searched in one batched descent.
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        for k in 0..batch_size {
            let u = (k as f64 + rng.random::<f64>()) * segment;
            let demo = agent_total <= 0.0 || (u < demo_total && demo_total > 0.0);
            scratch.in_demo.push(demo);
            if demo {
                scratch.demo.points.push(u);
            } else {
                scratch.agent.points.push(u - demo_total);
            }
        }
        scratch.demo.search(&self.demo_tree);
        scratch.agent.search(&self.agent_tree);
        let (mut demo_leaves, mut agent_leaves) =
            (scratch.demo.leaves.iter(), scratch.agent.leaves.iter());
        for &demo in &scratch.in_demo {
            let slot = match demo {
                true => demo_leaves.next().copied(),
                false => agent_leaves
                    .next()
                    .map(|leaf| self.cfg.demo_capacity + leaf),
            }
            .expect("one leaf per point");
            out.idx.push(slot);
            out.weights.push(is_weight(self.mass(slot), min_mass, beta));
        }
        self.scratch = scratch;
        self.gather(out);
    }

    /// Like [`Replay::sample`], but from the demonstration part only (DQfD pre-training). In
    /// prioritized mode `P(i)` is normalised over the demonstrations and the IS weights use
    /// `N = n_demo` and the smallest demonstration mass.
    ///
    /// # Panics
    /// If no demonstration is stored.
    pub(crate) fn sample_demo_only(
        &mut self,
        batch_size: usize,
        beta: f32,
        rng: &mut impl Rng,
        out: &mut Batch<A>,
    ) {
        assert!(
            self.n_demo > 0,
            "sample_demo_only with no demonstrations stored"
        );
        out.clear();
        if !self.cfg.prioritized {
            for _ in 0..batch_size {
                out.idx.push(rng.random_range(0..self.n_demo));
                out.weights.push(1.0);
            }
            self.gather(out);
            return;
        }
        let segment = self.demo_tree.total() / batch_size as f64;
        let min_mass = self.demo_tree.min();
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        for k in 0..batch_size {
            let u = (k as f64 + rng.random::<f64>()) * segment;
            scratch.demo.points.push(u);
        }
        scratch.demo.search(&self.demo_tree);
        for &slot in &scratch.demo.leaves {
            out.idx.push(slot);
            out.weights.push(is_weight(self.mass(slot), min_mass, beta));
        }
        self.scratch = scratch;
        self.gather(out);
    }

    /// Sets `p = |δ| + ε` for each sampled slot, with ε by the slot's kind, and raises the
    /// maximum priority if exceeded.
    ///
    /// # Panics
    /// If the slices differ in length, a slot holds nothing, or a TD error is not finite
    /// (a diverged learner; continuing would corrupt the sampling distribution).
    pub fn update_priorities(&mut self, idx: &[usize], abs_td: &[f32]) {
        assert_eq!(
            idx.len(),
            abs_td.len(),
            "update_priorities: {} slots but {} TD errors",
            idx.len(),
            abs_td.len()
        );
        for (&slot, &td) in idx.iter().zip(abs_td) {
            assert!(
                self.is_stored(slot),
                "update_priorities: slot {slot} holds no transition"
            );
            assert!(
                td.is_finite(),
                "update_priorities: non-finite TD error {td} for slot {slot}"
            );
            let eps = if self.is_demo_slot(slot) {
                self.cfg.eps_demo
            } else {
                self.cfg.eps_agent
            };
            let p = td.abs() + eps;
            self.max_priority = self.max_priority.max(p);
            self.priorities[slot] = p;
        }
        if !self.cfg.prioritized {
            return;
        }
        // Masses are written per tree in one batched update, in the order of `idx` (a slot sampled
        // twice keeps its last priority, as one `set_priority` per slot would leave it).
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        for &slot in idx {
            let mass = self.mass_of(self.priorities[slot]);
            match self.is_demo_slot(slot) {
                true => scratch.demo.updates.push((slot, mass)),
                false => scratch
                    .agent
                    .updates
                    .push((slot - self.cfg.demo_capacity, mass)),
            }
        }
        self.demo_tree.set_many(&scratch.demo.updates);
        self.agent_tree.set_many(&scratch.agent.updates);
        self.scratch = scratch;
    }

    fn is_demo_slot(&self, slot: usize) -> bool {
        slot < self.cfg.demo_capacity
    }

    fn is_stored(&self, slot: usize) -> bool {
        if self.is_demo_slot(slot) {
            slot < self.n_demo
        } else {
            slot - self.cfg.demo_capacity < self.n_agent
        }
    }

    /// Sampling mass `p^α` of a stored slot.
    fn mass(&self, slot: usize) -> f64 {
        if self.is_demo_slot(slot) {
            self.demo_tree.get(slot)
        } else {
            self.agent_tree.get(slot - self.cfg.demo_capacity)
        }
    }

    fn set_priority(&mut self, slot: usize, p: f32) {
        self.priorities[slot] = p;
        if !self.cfg.prioritized {
            // Uniform sampling never reads the trees; the raw priorities above stay inspectable.
            return;
        }
        let mass = self.mass_of(p);
        if self.is_demo_slot(slot) {
            self.demo_tree.set(slot, mass);
        } else {
            self.agent_tree.set(slot - self.cfg.demo_capacity, mass);
        }
    }

    /// Sampling mass `p^α` of raw priority `p`.
    fn mass_of(&self, p: f32) -> f64 {
        f64::from(p).powf(f64::from(self.cfg.alpha))
    }

    /// Fills every per-sample field of `out` from the slots in `out.idx`, one field at a time: the
    /// slots are random, so nearly every read misses the cache, and a loop over one field keeps many
    /// of those reads in flight at once.
    fn gather(&self, out: &mut Batch<A>) {
        let d = self.obs_dim;
        let rows = |from: &[f32], to: &mut Vec<f32>| gather_rows(from, d, &out.idx, to);
        rows(&self.obs, &mut out.obs);
        rows(&self.next_obs, &mut out.next_obs);
        let idx = &out.idx;
        out.actions.gather(&self.actions, idx);
        out.rewards
            .extend(idx.iter().map(|&slot| self.rewards[slot]));
        out.terminal
            .extend(idx.iter().map(|&slot| self.terminal[slot]));
        out.is_demo
            .extend(idx.iter().map(|&slot| self.is_demo_slot(slot)));
        if self.nstep.is_some() {
            rows(&self.nstep_next_obs, &mut out.nstep_next_obs);
            out.nstep_rewards
                .extend(idx.iter().map(|&slot| self.nstep_rewards[slot]));
            out.nstep_discounts
                .extend(idx.iter().map(|&slot| self.nstep_discounts[slot]));
        }
    }
}

impl<A: Action> Persist for Replay<A> {
    /// Writes the memory's contents into `state` under `prefix`: every slot's arrays, the priorities, the
    /// counters and the n-step queue. The sum/min trees are not written: their inner nodes are recomputed from
    /// the leaves on every change, so rebuilding them from the priorities gives the same trees bit for bit.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        let name = |n: &str| format!("{prefix}.{n}");
        state.put_f32(&name("obs"), &self.obs);
        state.put_f32(&name("next_obs"), &self.next_obs);
        self.actions.save(state, &name("actions"));
        state.put_f32(&name("rewards"), &self.rewards);
        let terminal: Vec<u8> = self.terminal.iter().map(|&t| u8::from(t)).collect();
        state.put_u8(&name("terminal"), terminal);
        state.put_f32(&name("nstep_next_obs"), &self.nstep_next_obs);
        state.put_f32(&name("nstep_rewards"), &self.nstep_rewards);
        state.put_f32(&name("nstep_discounts"), &self.nstep_discounts);
        state.put_f32(&name("priorities"), &self.priorities);
        state.put_value(
            &name("counters"),
            &[self.n_demo, self.n_agent, self.agent_next],
        );
        state.put_value(&name("max_priority"), &self.max_priority);
        if let Some(queue) = &self.nstep {
            state.put_value(&name("nstep_queue"), &queue.pending());
        }
    }

    /// Reads what [`Replay::save_state`] wrote into a memory built with the same configuration.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        use StateError;
        let name = |n: &str| format!("{prefix}.{n}");
        state.f32s_into(&name("obs"), &mut self.obs)?;
        state.f32s_into(&name("next_obs"), &mut self.next_obs)?;
        self.actions.load(state, &name("actions"))?;
        state.f32s_into(&name("rewards"), &mut self.rewards)?;
        let mut terminal = vec![0u8; self.terminal.len()];
        state.u8s_into(&name("terminal"), &mut terminal)?;
        if let Some(slot) = terminal.iter().position(|&t| t > 1) {
            return Err(StateError::Value {
                name: name("terminal"),
                msg: format!(
                    "slot {slot} holds {}, where a flag is 0 or 1",
                    terminal[slot]
                ),
            });
        }
        self.terminal = terminal.iter().map(|&t| t != 0).collect();
        state.f32s_into(&name("nstep_next_obs"), &mut self.nstep_next_obs)?;
        state.f32s_into(&name("nstep_rewards"), &mut self.nstep_rewards)?;
        state.f32s_into(&name("nstep_discounts"), &mut self.nstep_discounts)?;
        let mut priorities = vec![0f32; self.priorities.len()];
        state.f32s_into(&name("priorities"), &mut priorities)?;
        let [n_demo, n_agent, agent_next]: [usize; 3] = state.value(&name("counters"))?;
        if n_demo > self.cfg.demo_capacity
            || n_agent > self.cfg.capacity
            || agent_next >= self.cfg.capacity.max(1)
        {
            return Err(StateError::Value {
                name: name("counters"),
                msg: format!(
                    "{n_demo} demonstrations, {n_agent} agent transitions (next {agent_next}) do not fit \
                     capacities {} and {}",
                    self.cfg.demo_capacity, self.cfg.capacity
                ),
            });
        }
        (self.n_demo, self.n_agent, self.agent_next) = (n_demo, n_agent, agent_next);
        self.max_priority = state.value(&name("max_priority"))?;
        self.demo_tree = SumMinTree::new(self.cfg.demo_capacity);
        self.agent_tree = SumMinTree::new(self.cfg.capacity);
        let stored: Vec<usize> = self.stored_slots().collect();
        for slot in stored {
            let p = priorities[slot];
            if !(p.is_finite() && p >= 0.0) {
                return Err(StateError::Value {
                    name: name("priorities"),
                    msg: format!("slot {slot} has priority {p}"),
                });
            }
            self.set_priority(slot, p);
        }
        self.priorities = priorities;
        if let Some(queue) = &mut self.nstep {
            queue.set_pending(state.value(&name("nstep_queue"))?);
        }
        Ok(())
    }
}

/// Appends row `slot` (`d` values) of `from` to `to` for each slot in `idx`. The tasks' observation sizes
/// are copied as fixed-size arrays: a few moves per row, where a `memcpy` call per row kept fewer of the
/// rows' cache misses in flight at once.
fn gather_rows(from: &[f32], d: usize, idx: &[usize], to: &mut Vec<f32>) {
    fn fixed<const D: usize>(from: &[f32], idx: &[usize], to: &mut [f32]) {
        for (row, &slot) in to.chunks_exact_mut(D).zip(idx) {
            let row: &mut [f32; D] = row.try_into().expect("rows of D values");
            *row = from[slot * D..(slot + 1) * D]
                .try_into()
                .expect("rows of D values");
        }
    }
    let start = to.len();
    to.resize(start + idx.len() * d, 0.0);
    let to = &mut to[start..];
    match d {
        2 => fixed::<2>(from, idx, to),
        4 => fixed::<4>(from, idx, to),
        6 => fixed::<6>(from, idx, to),
        8 => fixed::<8>(from, idx, to),
        _ => {
            for (row, &slot) in to.chunks_exact_mut(d.max(1)).zip(idx) {
                row.copy_from_slice(&from[slot * d..(slot + 1) * d]);
            }
        }
    }
}

/// Normalised IS weight `(N P(i))^-β / max_j (N P(j))^-β`. With `P(i) = m_i / Σ m` the factors
/// `N` and `Σ m` cancel and the maximum belongs to the smallest mass, leaving
/// `(m_i / m_min)^-β` (Schaul et al. 2016, §3.4).
fn is_weight(mass: f64, min_mass: f64, beta: f32) -> f32 {
    (mass / min_mass).powf(-f64::from(beta)) as f32
}

#[cfg(test)]
mod tests;
