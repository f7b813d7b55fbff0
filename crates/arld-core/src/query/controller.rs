//! The query controller: turns a rule's decisions into expert control under a budget.
//!
//! [`QueryController`] owns a [`QueryRule`], the budget and the current segment. The budget counts demonstrated
//! *transitions* (or, as an ablation, queries: [`BudgetUnit`]) and is never exceeded; one query hands the expert
//! control for `segment_len` consecutive steps (the paper's "five consecutive expert demonstrations"), cut short
//! by the end of the episode or of the budget. The rule is only consulted when the agent is about to act, never
//! during expert control, and not once the budget is spent. A person may also take over unasked
//! (`QueryController::open_segment_by_person`): that segment is charged exactly like a query's, but the rule
//! does not see it (no decision, no statistics) and it lasts until the person hands back, the episode ends or
//! the budget is spent.
//!
//! One step of the training loop, in terms of this module:
//!
//! ```
//! # use arld_core::query::{QueryController, RuleSpec, RuleDefaults, BudgetUnit, Signals, DecisionInput};
//! # use rand::SeedableRng;
//! # let mut rng = rand_pcg::Pcg64::seed_from_u64(0);
//! # let defaults = RuleDefaults { t_query: 0.3, n_r: 1000, budget: 100, segment_len: 5, train_steps: 1000, unit: BudgetUnit::Transitions };
//! # let rule = "adaptive".parse::<RuleSpec>().unwrap().build(&defaults).unwrap();
//! # let mut controller = QueryController::new(rule, 100, 5).unwrap();
//! # let signals_of = |_needs| Signals { uncertainty: Some(0.5), ..Signals::default() };
//! let expert_acts = controller.expert_in_control() || {
//!     let signals = signals_of(controller.signals_wanted_now());
//!     let input = DecisionInput { step: 0, train_steps: 1000, agent_action: Some(0), signals: &signals, oracle: None };
//!     controller.decide(&input, &mut rng).query
//! };
//! if expert_acts {
//!     // ... the expert picks the action; the transition is stored as a demonstration ...
//!     controller.record_expert_step();
//! }
//! // ... on episode end: controller.end_episode();
//! ```

use rand::RngCore;

pub use super::rules::BudgetUnit;
use super::rules::{Needs, OracleView, QueryContext, QueryError, QueryRule, Signals};
use crate::state::{Persist, StateDict, StateError};

/// Outcome of one query decision.
#[derive(Clone, Copy, Debug, PartialEq)]
#[must_use]
pub struct Decision {
    /// Whether the expert takes over from this step on.
    pub query: bool,
    /// The rule's threshold at this decision (for the query log), if it has one.
    pub threshold: Option<f32>,
    /// The value the rule compared (logged as the query's uncertainty), if any.
    pub score: Option<f32>,
    /// How many expert steps the query grants (0 without a query): `segment_len`, truncated to the budget left.
    pub expert_steps: usize,
}

impl Decision {
    const NO_QUERY: Decision = Decision {
        query: false,
        threshold: None,
        score: None,
        expert_steps: 0,
    };
}

/// What the training loop knows at an agent decision, beyond the controller's own budget and segments.
#[derive(Clone, Copy, Debug)]
pub struct DecisionInput<'a> {
    pub step: usize,
    pub train_steps: usize,
    /// The index of the action the agent is about to take (`None` for a box action).
    pub agent_action: Option<usize>,
    pub signals: &'a Signals,
    /// The expert's view, given only to oracle rules.
    pub oracle: Option<&'a OracleView>,
}

/// A query rule with its budget and expert-control segments (docs/algorithm.md sections 8-9).
///
/// Invariants: `budget_spent() <= budget()`; every query grants between 1 and `segment_len` expert steps;
/// the rule sees only the steps where the agent is about to act.
#[derive(Debug)]
pub struct QueryController {
    rule: Box<dyn QueryRule>,
    budget: usize,
    unit: BudgetUnit,
    transitions_used: usize,
    segment_len: usize,
    /// Expert steps left in the current segment; the expert is in control while this is positive.
    segment_left: usize,
    queries: usize,
    /// Segments a person opened unasked ([`Self::open_segment_by_person`]); not queries of the rule.
    takeovers: usize,
    /// Steps a person gave in attempts they retried, and the attempts ([`Self::charge_retried`]).
    retried_steps: usize,
    retries: usize,
}

impl QueryController {
    /// Default expert steps per query: the paper's "five consecutive expert demonstrations" (section 5.1).
    pub const DEFAULT_SEGMENT_LEN: usize = 5;

    /// A controller spending at most `budget` demonstrated transitions, `segment_len` steps per query.
    /// The rule's own parameters were checked when it was built.
    pub fn new(
        rule: Box<dyn QueryRule>,
        budget: usize,
        segment_len: usize,
    ) -> Result<Self, QueryError> {
        if segment_len == 0 {
            return Err(QueryError::EmptySegment);
        }
        Ok(Self {
            rule,
            budget,
            unit: BudgetUnit::Transitions,
            transitions_used: 0,
            segment_len,
            segment_left: 0,
            queries: 0,
            takeovers: 0,
            retried_steps: 0,
            retries: 0,
        })
    }

    /// The same controller with its budget counted in `unit` (the default counts transitions).
    pub fn counting(self, unit: BudgetUnit) -> Self {
        Self { unit, ..self }
    }

    /// The rule, e.g. to read its threshold.
    pub fn rule(&self) -> &dyn QueryRule {
        &*self.rule
    }

    /// The signals the rule reads (see [`QueryRule::needs`]).
    pub fn needs(&self) -> Needs {
        self.rule.needs()
    }

    /// The signals the next [`decide`](Self::decide) will read: the rule's, while the agent is about to act and
    /// budget is left; nothing otherwise, so the caller may skip computing them.
    pub fn signals_wanted_now(&self) -> Needs {
        if !self.expert_in_control() && self.budget_left() > 0 {
            self.needs()
        } else {
            Needs::NOTHING
        }
    }

    /// Whether the expert acts at this step (a segment is running).
    pub fn expert_in_control(&self) -> bool {
        self.segment_left > 0
    }

    /// Decides, as the agent is about to act, whether to query; a query opens a segment of expert control of
    /// `min(segment_len, budget_left)` steps, starting with this one.
    ///
    /// Once the budget is spent the rule is no longer consulted: no signal is read, no random number drawn.
    ///
    /// # Panics
    /// Programming errors in the caller: calling this while [`expert_in_control`](Self::expert_in_control), or
    /// without a signal the rule [`needs`](Self::needs) while budget is left (reject that configuration up
    /// front with [`super::check_signals`]).
    pub fn decide(&mut self, input: &DecisionInput<'_>, rng: &mut dyn RngCore) -> Decision {
        assert!(
            !self.expert_in_control(),
            "decide called during expert control; call record_expert_step instead"
        );
        if self.budget_left() == 0 {
            return Decision::NO_QUERY;
        }
        let ctx = QueryContext {
            step: input.step,
            train_steps: input.train_steps,
            budget: self.budget,
            budget_spent: self.budget_spent(),
            unit: self.unit,
            segment_len: self.segment_len,
            queries: self.queries,
            agent_action: input.agent_action,
            signals: input.signals,
            oracle: input.oracle,
        };
        let verdict = self.rule.decide(&ctx, rng);
        let decision = Decision {
            query: verdict.query,
            threshold: verdict.threshold,
            score: verdict.score,
            expert_steps: 0,
        };
        if !decision.query {
            return decision;
        }
        self.queries += 1;
        self.segment_left = match self.unit {
            BudgetUnit::Transitions => self.segment_len.min(self.budget_left()),
            BudgetUnit::Queries => self.segment_len,
        };
        Decision {
            expert_steps: self.segment_left,
            ..decision
        }
    }

    /// A person takes over unasked, as the agent is about to act (human-gated control: HG-DAgger, HIL-SERL): a
    /// segment opens as a query's would and is charged the same way (one unit per demonstrated transition, or one
    /// query), but the rule is not consulted and does not see it. Counting transitions, it may last the whole
    /// budget left (the person hands back when done, [`withdraw`](Self::withdraw)); counting queries, it costs
    /// one query and lasts `segment_len` steps, as a query's segment does (the replay holds that many
    /// demonstrations per query). Returns the steps granted.
    ///
    /// # Panics
    /// Programming errors in the caller: calling this during expert control or with no budget left.
    pub(crate) fn open_segment_by_person(&mut self) -> usize {
        assert!(
            !self.expert_in_control(),
            "open_segment_by_person called during expert control"
        );
        assert!(
            self.budget_left() > 0,
            "open_segment_by_person called with no budget left"
        );
        self.takeovers += 1;
        self.segment_left = match self.unit {
            BudgetUnit::Transitions => self.budget_left(),
            BudgetUnit::Queries => self.segment_len,
        };
        self.segment_left
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
        self.transitions_used += 1;
    }

    /// A person answered the question that opened the running segment after retrying it: the `steps` of the
    /// attempts they dropped were given too, so they are charged (a retry costs a query, counting queries), and
    /// the segment is cut to the budget left.
    pub fn charge_retried(&mut self, steps: usize) {
        self.retried_steps += steps;
        self.retries += 1;
        let left = self.budget_left();
        if self.unit == BudgetUnit::Transitions {
            self.segment_left = self.segment_left.min(left);
        }
    }

    /// Steps a person gave in attempts they retried (charged to the budget, never stored).
    pub fn retried_steps(&self) -> usize {
        self.retried_steps
    }

    /// Ends the current segment, if any (expert control never crosses an episode boundary), and tells the rule.
    pub fn end_episode(&mut self) {
        self.segment_left = 0;
        self.rule.end_episode();
    }

    /// The expert gave the query back (nobody answered): the segment ends here and the step the expert did not
    /// answer spends no budget. The query still counts in [`queries`](Self::queries): it was asked.
    pub fn withdraw(&mut self) {
        self.segment_left = 0;
    }

    /// Expert steps left in the running segment (0 while the agent is in control).
    pub(crate) fn segment_left(&self) -> usize {
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

    /// Demonstrated transitions the expert gave so far, whatever the budget's unit ([`Self::budget_spent`]: in
    /// its unit).
    pub fn transitions_used(&self) -> usize {
        self.transitions_used
    }

    /// Budget spent, in its unit: demonstrated transitions, or queries asked (a query nobody answered included)
    /// and takeovers.
    pub fn budget_spent(&self) -> usize {
        match self.unit {
            BudgetUnit::Transitions => self.transitions_used + self.retried_steps,
            BudgetUnit::Queries => self.queries + self.takeovers + self.retries,
        }
    }

    /// Budget not yet spent, in its unit (counting transitions, the remaining steps of a running segment are
    /// included).
    pub fn budget_left(&self) -> usize {
        self.budget.saturating_sub(self.budget_spent())
    }

    /// Number of queries made so far (by the rule; takeovers are counted apart).
    pub fn queries(&self) -> usize {
        self.queries
    }

    /// Number of segments a person opened unasked (`Self::open_segment_by_person`).
    pub fn takeovers(&self) -> usize {
        self.takeovers
    }

    /// Steps per query.
    pub fn segment_len(&self) -> usize {
        self.segment_len
    }
}

impl Persist for QueryController {
    /// Writes the controller's position into `state` under `prefix`: budget used, segment in progress,
    /// queries (and takeovers, once there were any: a run without them writes what it always did), and the
    /// rule's own state (the adaptive rule's window, under `{prefix}.window` as before rules were an interface).
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        let mut counters = vec![self.transitions_used, self.segment_left, self.queries];
        if self.takeovers > 0 || self.retries > 0 {
            counters.push(self.takeovers);
        }
        if self.retries > 0 {
            counters.extend([self.retried_steps, self.retries]);
        }
        state.put_value(&format!("{prefix}.counters"), &counters);
        self.rule.save_state(prefix, state);
    }

    /// Reads what [`QueryController::save_state`] wrote into a controller built with the same rule.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        let name = format!("{prefix}.counters");
        let counters: Vec<usize> = state.value(&name)?;
        let (transitions_used, segment_left, queries, takeovers, retried) = match counters[..] {
            [b, s, q] => (b, s, q, 0, (0, 0)),
            [b, s, q, t] => (b, s, q, t, (0, 0)),
            [b, s, q, t, rs, r] => (b, s, q, t, (rs, r)),
            _ => {
                return Err(StateError::Value {
                    name,
                    msg: format!("{} counters, expected 3, 4 or 6", counters.len()),
                });
            }
        };
        (
            self.transitions_used,
            self.segment_left,
            self.queries,
            self.takeovers,
            (self.retried_steps, self.retries),
        ) = (transitions_used, segment_left, queries, takeovers, retried);
        self.rule.load_state(prefix, state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::query::rules::{AdaptiveQuantileRule, RuleDefaults, RuleSpec, check_signals};
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// A rule from its spec, with defaults that leave nothing to chance: t_query 0.3, N_r 1000.
    fn rule(spec: &str) -> Box<dyn QueryRule> {
        spec.parse::<RuleSpec>().unwrap().build(&DEFAULTS).unwrap()
    }

    /// Defaults that leave nothing to chance: t_query 0.3, N_r 1000, a budget of 100 transitions.
    const DEFAULTS: RuleDefaults = RuleDefaults {
        t_query: 0.3,
        n_r: 1000,
        budget: 100,
        segment_len: 5,
        train_steps: 1000,
        unit: BudgetUnit::Transitions,
    };

    /// One decision with `uncertainty` as the only signal.
    fn decide_with(
        controller: &mut QueryController,
        uncertainty: Option<f32>,
        rng: &mut Pcg64,
    ) -> Decision {
        let signals = Signals {
            uncertainty,
            ..Signals::default()
        };
        let input = DecisionInput {
            step: 0,
            train_steps: 1000,
            agent_action: Some(0),
            signals: &signals,
            oracle: None,
        };
        controller.decide(&input, rng)
    }

    #[test]
    fn invalid_parameters_are_rejected_with_errors() {
        let build = |spec: &str| spec.parse::<RuleSpec>().unwrap().build(&DEFAULTS);
        assert_eq!(
            AdaptiveQuantileRule::new(10, 1.5).unwrap_err(),
            QueryError::TQueryOutOfRange(1.5)
        );
        assert!(matches!(
            AdaptiveQuantileRule::new(10, f64::NAN),
            Err(QueryError::TQueryOutOfRange(_))
        ));
        assert_eq!(
            AdaptiveQuantileRule::new(0, 0.3).unwrap_err(),
            QueryError::EmptyWindow
        );
        assert!(build("bernoulli(p=1.01)").is_err());
        assert!(build("bernoulli(p=-0.5)").is_err());
        assert_eq!(
            QueryController::new(rule("greedy"), 10, 0).unwrap_err(),
            QueryError::EmptySegment
        );
        let adaptive = rule("adaptive");
        assert_eq!(
            check_signals(&*adaptive, false, false, Ok(())).unwrap_err(),
            QueryError::NoUncertaintySource { rule: "adaptive" }
        );
        assert!(check_signals(&*adaptive, true, false, Ok(())).is_ok());
        assert!(check_signals(&*rule("greedy"), false, false, Ok(())).is_ok());
        assert_eq!(
            check_signals(&*rule("rcmp"), true, false, Ok(())).unwrap_err(),
            QueryError::NoHeads { rule: "rcmp" }
        );
        // A rule that reads the risk is refused, with the reason, where no risk critic can be trained; a rule
        // that does not read it is not.
        let no_goal = || Err("Pendulum-v1 has no goal".to_string());
        for name in ["risk", "thrifty"] {
            let err = check_signals(&*rule(name), true, true, no_goal()).unwrap_err();
            assert!(err.to_string().contains("Pendulum-v1 has no goal"), "{err}");
            assert!(check_signals(&*rule(name), true, true, Ok(())).is_ok());
        }
        assert!(check_signals(&*adaptive, true, true, no_goal()).is_ok());
        // Boundary values are valid.
        assert!(
            AdaptiveQuantileRule::new(1, 0.0).is_ok() && AdaptiveQuantileRule::new(1, 1.0).is_ok()
        );
        assert!(build("bernoulli(p=0)").is_ok() && build("bernoulli(p=1)").is_ok());
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
                                .signals_wanted_now()
                                .uncertainty
                                .then(|| rng.random::<f32>());
                            let decision = decide_with(controller, uncertainty, rng);
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

    fn rule_strategy() -> impl Strategy<Value = String> {
        prop_oneof![
            Just("never".to_string()),
            Just("greedy".to_string()),
            (0.0f64..=1.0).prop_map(|p| format!("bernoulli(p={p})")),
            (1usize..50, 0.0f64..=1.0)
                .prop_map(|(n_r, t)| format!("adaptive(n_r={n_r},t_query={t})")),
            (0.01f64..=1.0).prop_map(|h| format!("paced(horizon={h})")),
            (0.01f64..=1.0).prop_map(|h| format!("ranked(horizon={h})")),
            (0.01f64..=1.0).prop_map(|h| format!("budget_paced(horizon={h})")),
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
            let is_never = rule == "never";
            let is_greedy = rule == "greedy";
            let mut controller = QueryController::new(self::rule(&rule), budget, segment_len).unwrap();
            let mut rng = Pcg64::seed_from_u64(seed);
            let episodes = simulate(&mut controller, &episode_lengths, &mut rng);

            let expert_steps = episodes.iter().flatten().filter(|a| **a != Actor::Agent).count();
            prop_assert!(controller.transitions_used() <= budget);
            prop_assert_eq!(controller.transitions_used(), expert_steps);
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
        let mut controller = QueryController::new(rule("greedy"), 10, 5).unwrap();
        assert!(decide_with(&mut controller, None, &mut rng).query);
        assert_eq!(controller.segment_left(), 5);
        controller.withdraw();
        assert!(!controller.expert_in_control());
        assert_eq!(
            (controller.transitions_used(), controller.queries()),
            (0, 1)
        );
        // Withdrawn mid-segment: the steps already taken stay charged.
        assert!(decide_with(&mut controller, None, &mut rng).query);
        controller.record_expert_step();
        controller.record_expert_step();
        controller.withdraw();
        assert_eq!(
            (controller.transitions_used(), controller.budget_left()),
            (2, 8)
        );
    }

    /// A person's retried attempts are charged (steps counting transitions, one query counting queries), never
    /// stored, cut the segment to the budget left, and survive a snapshot.
    #[test]
    fn retried_steps_are_charged_and_cut_the_segment_to_the_budget() {
        let mut rng = Pcg64::seed_from_u64(0);
        let mut controller = QueryController::new(rule("greedy"), 12, 5).unwrap();
        assert!(decide_with(&mut controller, None, &mut rng).query);
        // Two attempts of 5 and 4 steps dropped: 9 charged, 3 left, so the kept attempt has 3 steps at most.
        controller.charge_retried(5);
        controller.charge_retried(4);
        assert_eq!(
            (controller.budget_left(), controller.segment_left()),
            (3, 3)
        );
        (0..3).for_each(|_| controller.record_expert_step());
        assert_eq!(
            (controller.transitions_used(), controller.retried_steps()),
            (3, 9)
        );
        assert_eq!(
            (controller.budget_spent(), controller.budget_left()),
            (12, 0)
        );
        let mut state = StateDict::default();
        controller.save_state("q", &mut state);
        let mut back = QueryController::new(rule("greedy"), 12, 5).unwrap();
        back.load_state("q", &state).unwrap();
        assert_eq!(
            (
                back.transitions_used(),
                back.retried_steps(),
                back.budget_left()
            ),
            (3, 9, 0)
        );
        // Counting queries, a retry costs one query.
        let mut queries = QueryController::new(rule("greedy"), 3, 5)
            .unwrap()
            .counting(BudgetUnit::Queries);
        assert!(decide_with(&mut queries, None, &mut rng).query);
        queries.charge_retried(5);
        assert_eq!((queries.budget_spent(), queries.segment_left()), (2, 5));
    }

    #[test]
    fn a_takeover_is_charged_like_a_query_and_unseen_by_the_rule() {
        let mut rng = Pcg64::seed_from_u64(5);
        let mut controller =
            QueryController::new(rule("adaptive(n_r=10000,t_query=0.5)"), 12, 5).unwrap();
        // Three agent decisions the rule sees (low uncertainty: no query), then a person takes over.
        for _ in 0..3 {
            assert!(!decide_with(&mut controller, Some(0.0), &mut rng).query);
        }
        assert_eq!(controller.open_segment_by_person(), 12);
        assert!(controller.expert_in_control());
        (0..4).for_each(|_| controller.record_expert_step());
        controller.withdraw();
        // Four transitions charged (12 - 4 left), no query of the rule, one takeover.
        assert_eq!(
            (
                controller.transitions_used(),
                controller.budget_left(),
                controller.queries(),
                controller.takeovers()
            ),
            (4, 8, 0, 1)
        );
        // The rule's window holds its three decisions only.
        let mut state = StateDict::default();
        controller.save_state("q", &mut state);
        assert_eq!(state.f32s("q.window").unwrap().len(), 3);
        // The takeover survives a snapshot; a snapshot without takeovers keeps its three counters.
        let mut back =
            QueryController::new(rule("adaptive(n_r=10000,t_query=0.5)"), 12, 5).unwrap();
        back.load_state("q", &state).unwrap();
        assert_eq!((back.transitions_used(), back.takeovers()), (4, 1));
        let fresh = QueryController::new(rule("greedy"), 12, 5).unwrap();
        let mut plain = StateDict::default();
        fresh.save_state("q", &mut plain);
        assert_eq!(plain.value::<Vec<usize>>("q.counters").unwrap().len(), 3);
        // Counting queries, a takeover costs one query and lasts a segment.
        let mut queries = QueryController::new(rule("greedy"), 2, 5)
            .unwrap()
            .counting(BudgetUnit::Queries);
        assert_eq!(queries.open_segment_by_person(), 5);
        assert_eq!((queries.budget_spent(), queries.queries()), (1, 0));
        queries.end_episode();
        assert!(decide_with(&mut queries, None, &mut rng).query);
        assert_eq!(queries.budget_left(), 0);
    }

    #[test]
    fn greedy_spends_the_budget_on_the_first_steps() {
        let budget = 23;
        let mut controller = QueryController::new(rule("greedy"), budget, 5).unwrap();
        let mut rng = Pcg64::seed_from_u64(1);
        let episodes = simulate(&mut controller, &[7, 3, 9, 30, 12], &mut rng);
        let actors: Vec<Actor> = episodes.into_iter().flatten().collect();
        assert!(actors[..budget].iter().all(|a| *a != Actor::Agent));
        assert!(actors[budget..].iter().all(|a| *a == Actor::Agent));
        assert_eq!(controller.transitions_used(), budget);
    }

    #[test]
    fn last_segment_is_truncated_to_the_budget_left() {
        let mut controller = QueryController::new(rule("greedy"), 7, 5).unwrap();
        let mut rng = Pcg64::seed_from_u64(2);
        let first = decide_with(&mut controller, None, &mut rng);
        assert_eq!((first.query, first.expert_steps), (true, 5));
        (0..5).for_each(|_| controller.record_expert_step());
        let second = decide_with(&mut controller, None, &mut rng);
        assert_eq!((second.query, second.expert_steps), (true, 2));
        (0..2).for_each(|_| controller.record_expert_step());
        assert!(!controller.expert_in_control());
        assert!(!decide_with(&mut controller, None, &mut rng).query);
        assert_eq!(controller.queries(), 2);
    }

    #[test]
    fn a_budget_in_queries_grants_whole_segments_and_counts_queries_cut_short() {
        // Greedy with a budget of 3 queries of 5 steps over episodes of 7, 2 and 30 steps.
        let mut controller = QueryController::new(rule("greedy"), 3, 5)
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
        assert_eq!(controller.transitions_used(), 9);
        assert!(
            controller.transitions_used() <= BudgetUnit::Queries.max_transitions(3, 5),
            "the replay's demonstration part is sized by max_transitions"
        );
        // Counting transitions, the same budget of 3 would have given 3 transitions only.
        let mut by_transitions = QueryController::new(rule("greedy"), 3, 5).unwrap();
        simulate(&mut by_transitions, &[7, 2, 30], &mut rng);
        assert_eq!(
            (by_transitions.transitions_used(), by_transitions.queries()),
            (3, 1)
        );
    }

    #[test]
    fn adaptive_rule_is_not_evaluated_during_expert_control() {
        // Every uncertainty pushed is an agent decision: window length = agent decisions made (below N_r).
        let mut controller =
            QueryController::new(rule("adaptive(n_r=10000,t_query=0.5)"), 10_000, 5).unwrap();
        let mut rng = Pcg64::seed_from_u64(3);
        let episodes = simulate(&mut controller, &[200, 150, 300], &mut rng);
        let agent_steps = episodes
            .iter()
            .flatten()
            .filter(|a| **a == Actor::Agent)
            .count();
        let decisions = agent_steps + controller.queries();
        assert!(controller.queries() > 0);
        let mut state = StateDict::default();
        controller.save_state("q", &mut state);
        assert_eq!(state.f32s("q.window").unwrap().len(), decisions);
    }

    #[test]
    fn bernoulli_rule_queries_at_its_probability() {
        let p = 0.2;
        let mut controller = QueryController::new(rule("bernoulli(p=0.2)"), usize::MAX, 1).unwrap();
        let mut rng = Pcg64::seed_from_u64(4);
        let decisions = 50_000;
        let mut queries = 0;
        for _ in 0..decisions {
            if decide_with(&mut controller, None, &mut rng).query {
                queries += 1;
                controller.record_expert_step();
            }
        }
        let fraction = queries as f64 / decisions as f64;
        assert!((fraction - p).abs() < 0.01, "queried {fraction}");
    }

    #[test]
    #[should_panic(expected = "the adaptive rule reads the uncertainty")]
    fn adaptive_rule_without_uncertainty_is_a_programming_error() {
        let mut controller = QueryController::new(rule("adaptive(n_r=10)"), 10, 5).unwrap();
        let _ = decide_with(&mut controller, None, &mut Pcg64::seed_from_u64(5));
    }
}
