//! The paper's four query strategies (section 5.1; docs/algorithm.md sections 8, 9 and 14): never (DQN, DQfD),
//! greedy (GDQN), Bernoulli (BDQN) and the adaptive windowed quantile of Algorithm 1 (ADQN, ADQNP).

use std::collections::VecDeque;

use rand::RngCore;

use super::{Needs, Params, QueryContext, QueryError, QueryRule, RuleDefaults, RuleInfo, Verdict};
use crate::query::OrderStatistics;
use crate::state::{StateDict, StateError};

/// The same answer at every decision: never ask (`never`: DQN, DQfD), or ask at every decision until the budget
/// is spent (`greedy`: GDQN, whose expert drives the first `budget` steps).
#[derive(Clone, Copy, Debug)]
pub struct FixedRule {
    pub ask: bool,
}

impl QueryRule for FixedRule {
    fn info(&self) -> &'static RuleInfo {
        if self.ask { &GREEDY } else { &NEVER }
    }
    fn decide(&mut self, _ctx: &QueryContext<'_>, _rng: &mut dyn RngCore) -> Verdict {
        Verdict {
            query: self.ask,
            ..Verdict::NO
        }
    }
}

/// Ask with a fixed probability at each agent decision (BDQN); built only with a probability in [0, 1].
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

impl QueryRule for BernoulliRule {
    fn info(&self) -> &'static RuleInfo {
        &BERNOULLI
    }
    fn decide(&mut self, _ctx: &QueryContext<'_>, rng: &mut dyn RngCore) -> Verdict {
        Verdict::chance(self.p, rng)
    }
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
/// Other rules reuse this windowed test on other signals ([`AdaptiveQuantileRule::observe`]).
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

    /// Number of values currently in the window, at most `n_r`.
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

    /// The fraction of the window strictly below `value` (0 for an empty window).
    pub fn rank(&self, value: f32) -> f64 {
        if self.recent.is_empty() {
            return 0.0;
        }
        self.ranked.count_below(value) as f64 / self.recent.len() as f64
    }

    /// Whether `value` exceeds the current threshold, then adds it to the window.
    pub fn observe(&mut self, value: f32) -> Verdict {
        let threshold = self.threshold();
        if value.is_nan() {
            return Verdict {
                threshold,
                ..Verdict::NO
            };
        }
        let query = threshold.is_some_and(|threshold| value > threshold);
        self.push(value);
        Verdict {
            query,
            threshold,
            score: Some(value),
        }
    }

    /// Adds `value` to the window without deciding.
    pub fn push(&mut self, value: f32) {
        if value.is_nan() {
            return;
        }
        self.recent.push_back(value);
        self.ranked.insert(value);
        if self.recent.len() > self.n_r {
            let oldest = self.recent.pop_front().expect("window is non-empty");
            let removed = self.ranked.remove(oldest);
            debug_assert!(removed, "deque and tree out of sync");
        }
    }

    /// Writes the window (oldest first) under `prefix`. The ranking tree is not written: its answers depend only
    /// on the values in the window, so it is rebuilt from them.
    pub(crate) fn save_window<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        let window: Vec<f32> = self.recent.iter().copied().collect();
        state.put_f32(&format!("{prefix}.window"), window);
    }

    /// Reads what [`Self::save_window`] wrote.
    pub(crate) fn load_window(
        &mut self,
        prefix: &str,
        state: &StateDict<'_>,
    ) -> Result<(), StateError> {
        let window = state.f32s(&format!("{prefix}.window"))?;
        self.recent.clear();
        self.ranked.clear();
        for &u in window {
            self.recent.push_back(u);
            self.ranked.insert(u);
        }
        Ok(())
    }
}

impl QueryRule for AdaptiveQuantileRule {
    fn info(&self) -> &'static RuleInfo {
        &ADAPTIVE
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, _rng: &mut dyn RngCore) -> Verdict {
        let uncertainty = ctx.uncertainty(self.name());
        self.observe(uncertainty)
    }
    fn threshold(&self) -> Option<f32> {
        AdaptiveQuantileRule::threshold(self)
    }
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.save_window(prefix, state);
    }
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.load_window(prefix, state)
    }
}

/// The paper's windowed test of the parameters `t_query` (its fraction in [0, 1]) and `n_r` (the window's
/// length), the task's and the run's unless given.
pub(super) fn window(
    params: &mut Params,
    d: &RuleDefaults,
) -> Result<AdaptiveQuantileRule, QueryError> {
    let t = params.get("t_query", d.t_query, "in [0, 1]", |v| {
        (0.0..=1.0).contains(&v)
    })?;
    let n_r = params.count("n_r", d.n_r)?;
    AdaptiveQuantileRule::new(n_r, t)
}

/// The registry entry of a [`FixedRule`] answering `ASK`: no parameters, no signals.
const fn fixed<const ASK: bool>(name: &'static str, source: &'static str) -> RuleInfo {
    RuleInfo {
        name,
        source,
        params: &[],
        needs: Needs::NOTHING,
        build: |_, _| Ok(Box::new(FixedRule { ask: ASK })),
    }
}

pub(super) const NEVER: RuleInfo = fixed::<false>("never", "the paper (DQN, DQfD)");

pub(super) const GREEDY: RuleInfo = fixed::<true>("greedy", "the paper (GDQN): the first B steps");

pub(super) const BERNOULLI: RuleInfo = RuleInfo {
    name: "bernoulli",
    source: "the paper (BDQN)",
    params: &[("p", "the task's t_query")],
    needs: Needs::NOTHING,
    build: |params, d| {
        let p = params.get("p", d.t_query, "in [0, 1]", |v| (0.0..=1.0).contains(&v))?;
        Ok(Box::new(BernoulliRule::new(p)?))
    },
};

pub(super) const ADAPTIVE: RuleInfo = RuleInfo {
    name: "adaptive",
    source: "the paper (ADQN, ADQNP; Algorithm 1)",
    params: &[("t_query", "the task's t_query"), ("n_r", "n_r (1000)")],
    needs: Needs::UNCERTAINTY,
    build: |params, d| Ok(Box::new(window(params, d)?)),
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::query::rules::tests_support::{Recorded, SEGMENT_LEN, replay};
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

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
                let below = window.iter().filter(|v| **v < uncertainty).count();
                let expected_rank = if window.is_empty() { 0.0 } else { below as f64 / window.len() as f64 };
                prop_assert_eq!(rule.rank(uncertainty), expected_rank);
                let decision = rule.observe(uncertainty);
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
                    rule.observe(-(1.0 - uniform).ln() * 3.7).query
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
            let _ = rule.observe(value);
        }
        assert!(!rule.observe(f32::NAN).query);
        assert_eq!(rule.window_len(), 3);
        assert!(rule.observe(3.5).query);
    }

    #[test]
    fn the_paper_rules_on_a_recorded_sequence() {
        let recorded = Recorded::new(7, 400);
        // Every question spends a whole segment: the rule is asked until this many questions.
        let questions = recorded.budget() / SEGMENT_LEN;
        // Never: no question; greedy: a question at every decision until the budget is spent.
        assert!(replay("never", &recorded).iter().all(|q| !q));
        let greedy = replay("greedy", &recorded);
        assert!(greedy[..questions].iter().all(|q| *q) && greedy[questions..].iter().all(|q| !q));
        // Bernoulli(p): one draw of the query generator per decision, `random_bool(p)`, until the budget is spent.
        let mut rng = Pcg64::seed_from_u64(recorded.rng_seed);
        let mut asked = 0;
        let expected: Vec<bool> = (0..recorded.len())
            .map(|_| {
                let q = asked < questions && rng.random_bool(0.2);
                asked += usize::from(q);
                q
            })
            .collect();
        assert_eq!(replay("bernoulli(p=0.2)", &recorded), expected);
        // Adaptive: the uncertainty exceeds the floor(|D| t)-th largest of the last n_r values.
        let (n_r, t) = (50, 0.1);
        let u = recorded.column(|s| s.uncertainty);
        let expected: Vec<bool> = (0..recorded.len())
            .map(|i| {
                let window = &u[i.saturating_sub(n_r)..i];
                if window.is_empty() {
                    return false;
                }
                let mut sorted = window.to_vec();
                sorted.sort_by(|a, b| b.total_cmp(a));
                let k = ((sorted.len() as f64 * t).floor() as usize).min(sorted.len() - 1);
                u[i] > sorted[k]
            })
            .scan(0, |asked, q| {
                let q = q && *asked < questions;
                *asked += usize::from(q);
                Some(q)
            })
            .collect();
        assert!(expected.iter().any(|q| *q));
        assert_eq!(replay("adaptive(n_r=50,t_query=0.1)", &recorded), expected);
    }
}
