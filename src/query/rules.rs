//! Query rules and the controller that turns their decisions into expert control under a budget.
//!
//! - [`AdaptiveQuantileRule`]: the paper's Algorithm 1 (docs/algorithm.md sections 8 and 13). It keeps the last N_r
//!   uncertainties in a deque (for eviction order) and an [`OrderStatistics`] tree (for ranks), and queries when
//!   the current uncertainty exceeds the `floor(|D| * t_query)`-th largest recent one, so that about a fraction
//!   `t_query` of agent decisions trigger a query whatever the scale of the uncertainty.
//! - [`QueryRule`]: the four strategies compared in the paper (section 5.1; docs/algorithm.md section 9): never
//!   (DQN, DQfD), greedy (GDQN), Bernoulli (BDQN) and adaptive (ADQN, ADQNP).
//! - [`QueryController`]: owns a rule, the budget and the current segment. The budget counts demonstrated
//!   *transitions* (or, as an ablation, queries: [`BudgetUnit`]) and is never exceeded; one query hands the expert control for `segment_len` consecutive steps
//!   (the paper's "five consecutive expert demonstrations"), cut short by the end of the episode or of the budget.
//!   The rule is only consulted when the agent is about to act, never during expert control.
//!
//! One step of the training loop, in terms of this module:
//!
//! ```
//! # use arld::query::{QueryController, QueryRule};
//! # use rand::SeedableRng;
//! # let mut rng = rand_pcg::Pcg64::seed_from_u64(0);
//! # let mut controller = QueryController::new(QueryRule::adaptive(1000, 0.3).unwrap(), 100, 5).unwrap();
//! # let compute_uncertainty = || 0.5f32;
//! let expert_acts = controller.expert_in_control() || {
//!     let uncertainty = controller.uncertainty_wanted_now().then(compute_uncertainty);
//!     controller.decide(uncertainty, &mut rng).query
//! };
//! if expert_acts {
//!     // ... the expert picks the action; the transition is stored as a demonstration ...
//!     controller.record_expert_step();
//! }
//! // ... on episode end: controller.end_episode();
//! ```

use std::collections::VecDeque;

use rand::Rng;

use super::order_stats::OrderStatistics;
use crate::state::{Persist, StateDict, StateError};

/// Invalid query configuration.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum QueryError {
    #[error("t_query must lie in [0, 1] (it is the fraction of recent steps to query), got {0}")]
    TQueryOutOfRange(f64),
    #[error("the Bernoulli query probability must lie in [0, 1], got {0}")]
    ProbabilityOutOfRange(f64),
    #[error("the adaptive rule's window N_r must hold at least one uncertainty, got N_r = 0")]
    EmptyWindow,
    #[error("segment_len must be at least 1: a query hands the expert at least one step")]
    EmptySegment,
    #[error(
        "the {rule} query rule ranks uncertainties, but the network has no uncertainty measure; \
         use a bootstrapped (JS divergence) or noisy (predictive variance) network, or a rule that needs none"
    )]
    NoUncertaintySource { rule: &'static str },
}

/// Outcome of one query decision.
#[derive(Clone, Copy, Debug, PartialEq)]
#[must_use]
pub struct Decision {
    /// Whether the expert takes over from this step on.
    pub query: bool,
    /// The adaptive rule's threshold at this decision (for the query log); `None` for other rules, for an
    /// empty window, or when the budget is spent.
    pub threshold: Option<f32>,
    /// How many expert steps the query grants (0 without a query): `segment_len`, truncated to the budget left.
    pub expert_steps: usize,
}

impl Decision {
    const NO_QUERY: Decision = Decision {
        query: false,
        threshold: None,
        expert_steps: 0,
    };
}

/// The paper's adaptive query rule (Algorithm 1; docs/algorithm.md sections 8 and 13).
///
/// With D the last `n_r` uncertainties, at each agent decision:
/// 1. if D is non-empty, `thr = (floor(|D| * t_query))-th largest of D` (0-based, index clamped to `|D| - 1`),
///    i.e. the `(1 - t_query)`-quantile read in descending order; with D empty there is no query;
/// 2. query iff `U > thr`;
/// 3. push U, evicting the oldest value once D holds more than `n_r`.
///
/// NaN uncertainties never query and are not pushed (a NaN in the window would block every later query).
#[derive(Clone, Debug)]
pub struct AdaptiveQuantileRule {
    n_r: usize,
    t_query: f64,
    recent: VecDeque<f32>,
    ranked: OrderStatistics,
}

impl AdaptiveQuantileRule {
    /// Default window N_r; the paper does not give it (docs/algorithm.md section 8, ours).
    pub const DEFAULT_N_R: usize = 1000;

    /// A rule over the last `n_r` uncertainties querying about a fraction `t_query` of decisions.
    pub fn new(n_r: usize, t_query: f64) -> Result<Self, QueryError> {
        if n_r == 0 {
            return Err(QueryError::EmptyWindow);
        }
        if !(0.0..=1.0).contains(&t_query) {
            return Err(QueryError::TQueryOutOfRange(t_query));
        }
        Ok(Self {
            n_r,
            t_query,
            recent: VecDeque::with_capacity(n_r + 1),
            ranked: OrderStatistics::with_capacity(n_r + 1),
        })
    }

    /// A rule with the default window [`Self::DEFAULT_N_R`].
    pub fn with_default_window(t_query: f64) -> Result<Self, QueryError> {
        Self::new(Self::DEFAULT_N_R, t_query)
    }

    /// Window size N_r.
    pub fn n_r(&self) -> usize {
        self.n_r
    }

    /// Quantile position read from the top of the window: about a fraction `t_query` of decisions query.
    pub fn t_query(&self) -> f64 {
        self.t_query
    }

    /// Number of uncertainties currently in the window, at most `n_r`.
    pub fn window_len(&self) -> usize {
        self.recent.len()
    }

    /// The threshold the next decision would use, or `None` while the window is empty.
    pub fn threshold(&self) -> Option<f32> {
        let len = self.recent.len();
        if len == 0 {
            return None;
        }
        // floor(|D| * t_query), clamped: t_query = 1 would otherwise index one past the smallest value.
        let index = ((len as f64 * self.t_query).floor() as usize).min(len - 1);
        self.ranked.kth_largest(index)
    }

    /// Decides whether to query at this uncertainty, then adds it to the window. `expert_steps` is left at 0:
    /// segments are the controller's business.
    pub fn decide(&mut self, uncertainty: f32) -> Decision {
        if uncertainty.is_nan() {
            return Decision {
                threshold: self.threshold(),
                ..Decision::NO_QUERY
            };
        }
        let threshold = self.threshold();
        let query = threshold.is_some_and(|threshold| uncertainty > threshold);
        self.recent.push_back(uncertainty);
        self.ranked.insert(uncertainty);
        if self.recent.len() > self.n_r {
            let oldest = self.recent.pop_front().expect("window is non-empty");
            let removed = self.ranked.remove(oldest);
            debug_assert!(removed, "deque and tree out of sync");
        }
        Decision {
            query,
            threshold,
            expert_steps: 0,
        }
    }
}

/// Query with a fixed probability at each agent decision (BDQN); built only with a probability in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BernoulliRule {
    p: f64,
}

impl BernoulliRule {
    pub fn new(p: f64) -> Result<Self, QueryError> {
        if !(0.0..=1.0).contains(&p) {
            return Err(QueryError::ProbabilityOutOfRange(p));
        }
        Ok(Self { p })
    }

    /// The query probability.
    pub fn p(&self) -> f64 {
        self.p
    }
}

/// When the agent asks the expert (paper section 5.1; docs/algorithm.md section 9).
#[derive(Clone, Debug)]
pub enum QueryRule {
    /// Never query (DQN, DQfD).
    Never,
    /// Query at every decision until the budget is spent (GDQN): the expert drives the first `budget` steps.
    Greedy,
    /// Query with fixed probability `p` at each agent decision (BDQN).
    Bernoulli(BernoulliRule),
    /// Uncertainty-ranked adaptive rule (ADQN, ADQNP).
    Adaptive(AdaptiveQuantileRule),
}

impl QueryRule {
    /// A validated Bernoulli rule.
    pub fn bernoulli(p: f64) -> Result<Self, QueryError> {
        Ok(QueryRule::Bernoulli(BernoulliRule::new(p)?))
    }

    /// A validated adaptive rule.
    pub fn adaptive(n_r: usize, t_query: f64) -> Result<Self, QueryError> {
        Ok(QueryRule::Adaptive(AdaptiveQuantileRule::new(
            n_r, t_query,
        )?))
    }

    /// Short lowercase name, as used in configs and logs.
    pub fn name(&self) -> &'static str {
        match self {
            QueryRule::Never => "never",
            QueryRule::Greedy => "greedy",
            QueryRule::Bernoulli(_) => "bernoulli",
            QueryRule::Adaptive(_) => "adaptive",
        }
    }

    /// Whether decisions need an uncertainty value (only the adaptive rule ranks them).
    pub fn needs_uncertainty(&self) -> bool {
        matches!(self, QueryRule::Adaptive(_))
    }

    /// Rejects, up front, a rule that needs an uncertainty when the network provides none (plain output stage).
    pub fn check_uncertainty_source(
        &self,
        network_has_uncertainty: bool,
    ) -> Result<(), QueryError> {
        if self.needs_uncertainty() && !network_has_uncertainty {
            return Err(QueryError::NoUncertaintySource { rule: self.name() });
        }
        Ok(())
    }
}

/// What the budget counts. The paper's budget is in demonstrated transitions; counting queries (each one a whole
/// segment of up to `segment_len` transitions, however few of them the episode leaves) is an ablation of that
/// reading (docs/algorithm.md sections 8 and 13).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum BudgetUnit {
    /// One unit per demonstrated transition; the last segment is cut at the budget.
    #[default]
    Transitions,
    /// One unit per query, however many transitions its segment demonstrates.
    Queries,
}

impl BudgetUnit {
    /// The most demonstrated transitions a budget of `budget` units can bring, with `segment_len` steps per query.
    pub fn max_transitions(self, budget: usize, segment_len: usize) -> usize {
        match self {
            BudgetUnit::Transitions => budget,
            BudgetUnit::Queries => budget.saturating_mul(segment_len),
        }
    }
}

/// A query rule with its budget and expert-control segments (docs/algorithm.md sections 8-9).
///
/// Invariants: `budget_spent() <= budget()`; every query grants between 1 and `segment_len` expert steps;
/// the rule sees only the steps where the agent is about to act.
#[derive(Clone, Debug)]
pub struct QueryController {
    rule: QueryRule,
    budget: usize,
    unit: BudgetUnit,
    budget_used: usize,
    segment_len: usize,
    /// Expert steps left in the current segment; the expert is in control while this is positive.
    segment_left: usize,
    queries: usize,
}

impl QueryController {
    /// Default expert steps per query: the paper's "five consecutive expert demonstrations" (section 5.1).
    pub const DEFAULT_SEGMENT_LEN: usize = 5;

    /// A controller spending at most `budget` demonstrated transitions, `segment_len` steps per query.
    /// The rule's own parameters were checked when it was built.
    pub fn new(rule: QueryRule, budget: usize, segment_len: usize) -> Result<Self, QueryError> {
        if segment_len == 0 {
            return Err(QueryError::EmptySegment);
        }
        Ok(Self {
            rule,
            budget,
            unit: BudgetUnit::Transitions,
            budget_used: 0,
            segment_len,
            segment_left: 0,
            queries: 0,
        })
    }

    /// The same controller with its budget counted in `unit` (the default counts transitions).
    pub fn counting(self, unit: BudgetUnit) -> Self {
        Self { unit, ..self }
    }

    /// The rule, e.g. to read the adaptive window.
    pub fn rule(&self) -> &QueryRule {
        &self.rule
    }

    /// Whether the rule ranks uncertainties (see [`QueryRule::needs_uncertainty`]).
    pub fn needs_uncertainty(&self) -> bool {
        self.rule.needs_uncertainty()
    }

    /// Whether the next [`decide`](Self::decide) will read an uncertainty: the rule needs one, the agent is
    /// about to act, and budget is left. Otherwise the caller may skip computing it.
    pub fn uncertainty_wanted_now(&self) -> bool {
        self.needs_uncertainty() && !self.expert_in_control() && self.budget_left() > 0
    }

    /// Whether the expert acts at this step (a segment is running).
    pub fn expert_in_control(&self) -> bool {
        self.segment_left > 0
    }

    /// Decides, as the agent is about to act, whether to query; a query opens a segment of expert control of
    /// `min(segment_len, budget_left)` steps, starting with this one.
    ///
    /// Once the budget is spent the rule is no longer consulted: no uncertainty is read, no random number drawn.
    ///
    /// # Panics
    /// Programming errors in the caller: calling this while [`expert_in_control`](Self::expert_in_control), or
    /// passing `None` to a rule that [`needs_uncertainty`](Self::needs_uncertainty) while budget is left (reject
    /// that configuration up front with [`QueryRule::check_uncertainty_source`]).
    pub fn decide<R: Rng + ?Sized>(&mut self, uncertainty: Option<f32>, rng: &mut R) -> Decision {
        assert!(
            !self.expert_in_control(),
            "decide called during expert control; call record_expert_step instead"
        );
        if self.budget_left() == 0 {
            return Decision::NO_QUERY;
        }
        let rule_decision = match &mut self.rule {
            QueryRule::Never => Decision::NO_QUERY,
            QueryRule::Greedy => Decision {
                query: true,
                ..Decision::NO_QUERY
            },
            QueryRule::Bernoulli(rule) => Decision {
                query: rng.random_bool(rule.p),
                ..Decision::NO_QUERY
            },
            QueryRule::Adaptive(rule) => {
                let uncertainty = uncertainty
                    .expect("the adaptive query rule needs an uncertainty at every decision");
                rule.decide(uncertainty)
            }
        };
        if !rule_decision.query {
            return rule_decision;
        }
        self.queries += 1;
        self.segment_left = match self.unit {
            BudgetUnit::Transitions => self.segment_len.min(self.budget_left()),
            BudgetUnit::Queries => self.segment_len,
        };
        Decision {
            expert_steps: self.segment_left,
            ..rule_decision
        }
    }

    /// Records one demonstrated transition: spends one unit of budget and advances the segment.
    ///
    /// # Panics
    /// If the expert is not in control (a caller bug: the budget would be spent outside a query).
    pub fn record_expert_step(&mut self) {
        assert!(
            self.expert_in_control(),
            "record_expert_step called while the agent is in control"
        );
        self.segment_left -= 1;
        self.budget_used += 1;
    }

    /// Ends the current segment, if any: expert control never crosses an episode boundary.
    pub fn end_episode(&mut self) {
        self.segment_left = 0;
    }

    /// The expert gave the query back (nobody answered): the segment ends here and the step the expert did not
    /// answer spends no budget. The query still counts in [`queries`](Self::queries): it was asked.
    pub fn withdraw(&mut self) {
        self.segment_left = 0;
    }

    /// Expert steps left in the running segment (0 while the agent is in control).
    pub fn segment_left(&self) -> usize {
        self.segment_left
    }

    /// Total budget, in its unit ([`BudgetUnit`]).
    pub fn budget(&self) -> usize {
        self.budget
    }

    /// What the budget counts.
    pub fn unit(&self) -> BudgetUnit {
        self.unit
    }

    /// Demonstrated transitions so far.
    pub fn budget_used(&self) -> usize {
        self.budget_used
    }

    /// Budget spent, in its unit: demonstrated transitions, or queries asked (a query nobody answered included).
    pub fn budget_spent(&self) -> usize {
        match self.unit {
            BudgetUnit::Transitions => self.budget_used,
            BudgetUnit::Queries => self.queries,
        }
    }

    /// Budget not yet spent, in its unit (counting transitions, the remaining steps of a running segment are
    /// included).
    pub fn budget_left(&self) -> usize {
        self.budget - self.budget_spent()
    }

    /// Number of queries made so far.
    pub fn queries(&self) -> usize {
        self.queries
    }

    /// Steps per query.
    pub fn segment_len(&self) -> usize {
        self.segment_len
    }
}

impl Persist for QueryController {
    /// Writes the controller's position into `state` under `prefix`: budget used, segment in progress,
    /// queries, and the adaptive rule's window. The rule's ranking tree is not written: its answers depend only
    /// on the values in the window, so it is rebuilt from them.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        state.put_value(
            &format!("{prefix}.counters"),
            &[self.budget_used, self.segment_left, self.queries],
        );
        if let QueryRule::Adaptive(rule) = &self.rule {
            let window: Vec<f32> = rule.recent.iter().copied().collect();
            state.put_f32(&format!("{prefix}.window"), window);
        }
    }

    /// Reads what [`QueryController::save_state`] wrote into a controller built with the same rule.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        let [budget_used, segment_left, queries]: [usize; 3] =
            state.value(&format!("{prefix}.counters"))?;
        (self.budget_used, self.segment_left, self.queries) = (budget_used, segment_left, queries);
        if let QueryRule::Adaptive(rule) = &mut self.rule {
            let window = state.f32s(&format!("{prefix}.window"))?;
            rule.recent.clear();
            rule.ranked.clear();
            for &u in window {
                rule.recent.push_back(u);
                rule.ranked.insert(u);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    #[test]
    fn invalid_parameters_are_rejected_with_errors() {
        assert_eq!(
            AdaptiveQuantileRule::new(10, 1.5).unwrap_err(),
            QueryError::TQueryOutOfRange(1.5)
        );
        assert_eq!(
            AdaptiveQuantileRule::new(10, -0.1).unwrap_err(),
            QueryError::TQueryOutOfRange(-0.1)
        );
        assert!(matches!(
            AdaptiveQuantileRule::new(10, f64::NAN),
            Err(QueryError::TQueryOutOfRange(_))
        ));
        assert_eq!(
            AdaptiveQuantileRule::new(0, 0.3).unwrap_err(),
            QueryError::EmptyWindow
        );
        assert_eq!(
            QueryRule::bernoulli(1.01).unwrap_err(),
            QueryError::ProbabilityOutOfRange(1.01)
        );
        assert_eq!(
            QueryRule::bernoulli(-0.5).unwrap_err(),
            QueryError::ProbabilityOutOfRange(-0.5)
        );
        assert_eq!(
            QueryController::new(QueryRule::Greedy, 10, 0).unwrap_err(),
            QueryError::EmptySegment
        );
        let adaptive = QueryRule::adaptive(100, 0.3).unwrap();
        assert_eq!(
            adaptive.check_uncertainty_source(false).unwrap_err(),
            QueryError::NoUncertaintySource { rule: "adaptive" }
        );
        assert!(adaptive.check_uncertainty_source(true).is_ok());
        assert!(QueryRule::Greedy.check_uncertainty_source(false).is_ok());
        // Boundary values are valid.
        assert!(
            AdaptiveQuantileRule::new(1, 0.0).is_ok() && AdaptiveQuantileRule::new(1, 1.0).is_ok()
        );
        assert!(QueryRule::bernoulli(0.0).is_ok() && QueryRule::bernoulli(1.0).is_ok());
    }

    proptest! {
        #[test]
        fn adaptive_rule_matches_sorted_window_oracle(
            n_r in 1usize..20,
            t_query in 0.0f64..=1.0,
            // Few distinct values so ties (U equal to the threshold: no query) are frequent.
            stream in proptest::collection::vec(0u8..12, 0..200),
        ) {
            let mut rule = AdaptiveQuantileRule::new(n_r, t_query).unwrap();
            let mut window: VecDeque<f32> = VecDeque::new();
            for value in stream {
                let uncertainty = value as f32 * 0.25;
                let mut descending: Vec<f32> = window.iter().copied().collect();
                descending.sort_by(|a, b| b.total_cmp(a));
                let expected_threshold = if descending.is_empty() {
                    None
                } else {
                    let index = ((descending.len() as f64 * t_query).floor() as usize).min(descending.len() - 1);
                    Some(descending[index])
                };
                let expected_query = expected_threshold.is_some_and(|t| uncertainty > t);
                let decision = rule.decide(uncertainty);
                prop_assert_eq!(decision.threshold, expected_threshold);
                prop_assert_eq!(decision.query, expected_query);
                window.push_back(uncertainty);
                if window.len() > n_r {
                    window.pop_front();
                }
                prop_assert_eq!(rule.window_len(), window.len());
            }
        }
    }

    #[test]
    fn adaptive_rule_queries_a_fraction_t_query_of_a_stationary_stream() {
        for (case, t_query) in [0.05, 0.1, 0.3, 0.5].into_iter().enumerate() {
            let mut rng = Pcg64::seed_from_u64(100 + case as u64);
            let mut rule = AdaptiveQuantileRule::with_default_window(t_query).unwrap();
            let steps = 100_000;
            // Exponential-looking values: the rule must not care about the distribution's scale or shape.
            let queries = (0..steps)
                .filter(|_| {
                    let uniform: f32 = rng.random();
                    rule.decide(-(1.0 - uniform).ln() * 3.7).query
                })
                .count();
            let fraction = queries as f64 / steps as f64;
            assert!(
                (fraction - t_query).abs() <= 0.02,
                "t_query {t_query}: queried {fraction}"
            );
        }
    }

    #[test]
    fn nan_uncertainty_never_queries_and_is_not_kept() {
        let mut rule = AdaptiveQuantileRule::new(10, 0.5).unwrap();
        for value in [1.0, 2.0, 3.0] {
            let _ = rule.decide(value);
        }
        assert!(!rule.decide(f32::NAN).query);
        assert_eq!(rule.window_len(), 3);
        assert!(rule.decide(3.5).query);
    }

    /// Who acted at one environment step of a simulated run.
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Actor {
        Agent,
        /// The expert, with the index of the query that handed it control.
        Expert {
            query: usize,
        },
    }

    /// Drives a controller through episodes of the given lengths, as the training loop would, and returns who
    /// acted at every step of every episode.
    fn simulate(
        controller: &mut QueryController,
        episode_lengths: &[usize],
        rng: &mut Pcg64,
    ) -> Vec<Vec<Actor>> {
        let mut query_index = 0;
        let mut current_query = None;
        episode_lengths
            .iter()
            .map(|&length| {
                let actors = (0..length)
                    .map(|_| {
                        let in_control = controller.expert_in_control();
                        let expert_acts = in_control || {
                            let uncertainty = controller
                                .uncertainty_wanted_now()
                                .then(|| rng.random::<f32>());
                            let decision = controller.decide(uncertainty, rng);
                            if decision.query {
                                assert!(decision.expert_steps >= 1);
                                current_query = Some(query_index);
                                query_index += 1;
                            }
                            decision.query
                        };
                        if expert_acts {
                            controller.record_expert_step();
                            Actor::Expert {
                                query: current_query.unwrap(),
                            }
                        } else {
                            Actor::Agent
                        }
                    })
                    .collect();
                controller.end_episode();
                assert!(!controller.expert_in_control());
                actors
            })
            .collect()
    }

    fn rule_strategy() -> impl Strategy<Value = QueryRule> {
        prop_oneof![
            Just(QueryRule::Never),
            Just(QueryRule::Greedy),
            (0.0f64..=1.0).prop_map(|p| QueryRule::bernoulli(p).unwrap()),
            (1usize..50, 0.0f64..=1.0).prop_map(|(n_r, t)| QueryRule::adaptive(n_r, t).unwrap()),
        ]
    }

    proptest! {
        #[test]
        fn budget_is_never_exceeded_and_segments_are_bounded(
            rule in rule_strategy(),
            budget in 0usize..60,
            segment_len in 1usize..8,
            episode_lengths in proptest::collection::vec(0usize..40, 0..12),
            seed in any::<u64>(),
        ) {
            let is_never = matches!(rule, QueryRule::Never);
            let is_greedy = matches!(rule, QueryRule::Greedy);
            let mut controller = QueryController::new(rule, budget, segment_len).unwrap();
            let mut rng = Pcg64::seed_from_u64(seed);
            let episodes = simulate(&mut controller, &episode_lengths, &mut rng);

            let expert_steps = episodes.iter().flatten().filter(|a| **a != Actor::Agent).count();
            prop_assert!(controller.budget_used() <= budget);
            prop_assert_eq!(controller.budget_used(), expert_steps);
            prop_assert_eq!(controller.budget_left(), budget - expert_steps);

            // Per query: at most segment_len steps, consecutive, within one episode, and a full segment unless
            // the episode or the budget ran out.
            let mut steps_per_query = vec![0usize; controller.queries()];
            for episode in &episodes {
                let mut previous: Option<usize> = None;
                for (step, actor) in episode.iter().enumerate() {
                    if let Actor::Expert { query } = *actor {
                        steps_per_query[query] += 1;
                        if steps_per_query[query] > 1 {
                            prop_assert_eq!(previous, Some(query), "segment not contiguous at step {}", step);
                        }
                        previous = Some(query);
                    } else {
                        previous = None;
                    }
                }
            }
            let total_steps: usize = episode_lengths.iter().sum();
            for (query, &steps) in steps_per_query.iter().enumerate() {
                prop_assert!((1..=segment_len).contains(&steps), "query {} got {} steps", query, steps);
            }
            // A segment shorter than segment_len was cut by the end of its episode or of the budget.
            let mut cut_by_episode_end = vec![false; controller.queries()];
            for episode in &episodes {
                if let Some(Actor::Expert { query }) = episode.last() {
                    cut_by_episode_end[*query] = true;
                }
            }
            for (query, &steps) in steps_per_query.iter().enumerate() {
                let full = steps == segment_len;
                prop_assert!(full || cut_by_episode_end[query] || controller.budget_left() == 0);
            }
            if is_never {
                prop_assert_eq!(expert_steps, 0);
            }
            if is_greedy {
                prop_assert_eq!(expert_steps, budget.min(total_steps));
            }
        }
    }

    #[test]
    fn a_withdrawn_query_spends_no_budget() {
        let mut rng = Pcg64::seed_from_u64(0);
        let mut controller = QueryController::new(QueryRule::Greedy, 10, 5).unwrap();
        assert!(controller.decide(None, &mut rng).query);
        assert_eq!(controller.segment_left(), 5);
        controller.withdraw();
        assert!(!controller.expert_in_control());
        assert_eq!((controller.budget_used(), controller.queries()), (0, 1));
        // Withdrawn mid-segment: the steps already taken stay charged.
        assert!(controller.decide(None, &mut rng).query);
        controller.record_expert_step();
        controller.record_expert_step();
        controller.withdraw();
        assert_eq!((controller.budget_used(), controller.budget_left()), (2, 8));
    }

    #[test]
    fn greedy_spends_the_budget_on_the_first_steps() {
        let budget = 23;
        let mut controller = QueryController::new(QueryRule::Greedy, budget, 5).unwrap();
        let mut rng = Pcg64::seed_from_u64(1);
        let episodes = simulate(&mut controller, &[7, 3, 9, 30, 12], &mut rng);
        let actors: Vec<Actor> = episodes.into_iter().flatten().collect();
        assert!(actors[..budget].iter().all(|a| *a != Actor::Agent));
        assert!(actors[budget..].iter().all(|a| *a == Actor::Agent));
        assert_eq!(controller.budget_used(), budget);
    }

    #[test]
    fn last_segment_is_truncated_to_the_budget_left() {
        let mut controller = QueryController::new(QueryRule::Greedy, 7, 5).unwrap();
        let mut rng = Pcg64::seed_from_u64(2);
        let first = controller.decide(None, &mut rng);
        assert_eq!((first.query, first.expert_steps), (true, 5));
        (0..5).for_each(|_| controller.record_expert_step());
        let second = controller.decide(None, &mut rng);
        assert_eq!((second.query, second.expert_steps), (true, 2));
        (0..2).for_each(|_| controller.record_expert_step());
        assert!(!controller.expert_in_control());
        assert!(!controller.decide(None, &mut rng).query);
        assert_eq!(controller.queries(), 2);
    }

    #[test]
    fn a_budget_in_queries_grants_whole_segments_and_counts_queries_cut_short() {
        // Greedy with a budget of 3 queries of 5 steps over episodes of 7, 2 and 30 steps.
        let mut controller = QueryController::new(QueryRule::Greedy, 3, 5)
            .unwrap()
            .counting(BudgetUnit::Queries);
        let mut rng = Pcg64::seed_from_u64(4);
        let episodes = simulate(&mut controller, &[7, 2, 30], &mut rng);
        let expert_steps: Vec<usize> = episodes
            .iter()
            .map(|e| e.iter().filter(|a| **a != Actor::Agent).count())
            .collect();
        // Episode 0: query 1 (steps 0-4), query 2 (steps 5-6, cut by the end); episode 1: query 3 (both steps);
        // then the budget of 3 queries is spent and the 30-step episode is the agent's.
        assert_eq!(expert_steps, vec![7, 2, 0]);
        assert_eq!(controller.queries(), 3);
        assert_eq!(
            (controller.budget_spent(), controller.budget_left()),
            (3, 0)
        );
        assert_eq!(controller.budget_used(), 9);
        assert!(
            controller.budget_used() <= BudgetUnit::Queries.max_transitions(3, 5),
            "the replay's demonstration part is sized by max_transitions"
        );
        // Counting transitions, the same budget of 3 would have given 3 transitions only.
        let mut by_transitions = QueryController::new(QueryRule::Greedy, 3, 5).unwrap();
        simulate(&mut by_transitions, &[7, 2, 30], &mut rng);
        assert_eq!(
            (by_transitions.budget_used(), by_transitions.queries()),
            (3, 1)
        );
    }

    #[test]
    fn adaptive_rule_is_not_evaluated_during_expert_control() {
        // Every uncertainty pushed is an agent decision: window length = agent decisions made (below N_r).
        let mut controller =
            QueryController::new(QueryRule::adaptive(10_000, 0.5).unwrap(), 10_000, 5).unwrap();
        let mut rng = Pcg64::seed_from_u64(3);
        let episodes = simulate(&mut controller, &[200, 150, 300], &mut rng);
        let agent_steps = episodes
            .iter()
            .flatten()
            .filter(|a| **a == Actor::Agent)
            .count();
        let decisions = agent_steps + controller.queries();
        let QueryRule::Adaptive(rule) = controller.rule() else {
            unreachable!()
        };
        assert!(controller.queries() > 0);
        assert_eq!(rule.window_len(), decisions);
    }

    #[test]
    fn bernoulli_rule_queries_at_its_probability() {
        let p = 0.2;
        let mut controller =
            QueryController::new(QueryRule::bernoulli(p).unwrap(), usize::MAX, 1).unwrap();
        let mut rng = Pcg64::seed_from_u64(4);
        let decisions = 50_000;
        let mut queries = 0;
        for _ in 0..decisions {
            if controller.decide(None, &mut rng).query {
                queries += 1;
                controller.record_expert_step();
            }
        }
        let fraction = queries as f64 / decisions as f64;
        assert!((fraction - p).abs() < 0.01, "queried {fraction}");
    }

    #[test]
    #[should_panic(expected = "needs an uncertainty")]
    fn adaptive_rule_without_uncertainty_is_a_programming_error() {
        let mut controller =
            QueryController::new(QueryRule::adaptive(10, 0.3).unwrap(), 10, 5).unwrap();
        let _ = controller.decide(None, &mut Pcg64::seed_from_u64(5));
    }
}
