//! Query rules: when the learning agent asks the expert. One interface, [`QueryRule`], and its implementations
//! side by side (docs/algorithm.md section 14 gives each rule's source and defaults):
//!
//! - [`paper`]: the four strategies the paper compares: never (DQN, DQfD), greedy (GDQN), Bernoulli (BDQN) and the
//!   adaptive windowed quantile of Algorithm 1 (ADQN, ADQNP);
//! - [`field`]: rules from the literature on asking for help, on the same signals: paced random, RCMP's head
//!   variance, the Q-gap percentile of student-initiated advising, ThriftyDAgger's target-rate calibration, the
//!   budget managers of stream-based active learning, the oracle references of teacher advising
//!   (importance advising and mistake correcting), which read the expert's own Q-values, and ThriftyDAgger's
//!   risk, alone or with its novelty (box tasks with a goal: the risk critic of `agent::risk`);
//! - [`ours`]: rules designed on the effort benchmark's design seeds.
//!
//! A rule is chosen by a spec, `name` or `name(key=value, ...)` (the `query_rule` key of a run's configuration,
//! the same keyword in Python), looked up in [`RULES`]. At each agent decision while budget is left the rule sees a
//! [`QueryContext`]: the network's uncertainty signals ([`Signals`]: only those it asked for in
//! [`QueryRule::needs`] are computed), the agent's action, the step and the run's length, the budget spent and
//! left, the questions asked so far, and for oracle rules only the expert's action and Q-values ([`OracleView`]).
//! The [`super::QueryController`] owns the budget and the segments; a rule only says yes or no.

pub mod field;
pub mod ours;
pub mod paper;

use std::collections::BTreeMap;

use rand::{Rng, RngCore};

use crate::state::{StateDict, StateError};

pub use field::{
    BudgetPacedRule, CalibratedRule, ImportanceRule, PacedRule, QGapRule, RcmpRule, ThriftyRule,
    VariableThresholdRule,
};
pub use ours::RankedPacedRule;
pub use paper::{AdaptiveQuantileRule, BernoulliRule, FixedRule};

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
    pub(crate) fn max_transitions(self, budget: usize, segment_len: usize) -> usize {
        match self {
            BudgetUnit::Transitions => budget,
            BudgetUnit::Queries => budget.saturating_mul(segment_len),
        }
    }
}

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
    #[error(
        "the {rule} query rule reads the variance of the bootstrapped heads' Q-values; use a bootstrapped network"
    )]
    NoHeads { rule: &'static str },
    #[error(
        "the {rule} query rule reads the risk of the agent's action, 1 - Q_R(s, a), with Q_R a critic of the chance \
         of reaching the task's goal (docs/algorithm.md section 20), but {reason}"
    )]
    NoRisk { rule: &'static str, reason: String },
    #[error("unknown query rule '{0}'; the rules are: {list}", list = rule_names().join(", "))]
    UnknownRule(String),
    #[error(
        "query rule spec '{spec}': {reason} (write NAME or NAME(key=value, ...), e.g. paced(horizon=0.1))"
    )]
    BadSpec { spec: String, reason: String },
    #[error("the {rule} query rule has no parameter '{key}'; its parameters are: {known}")]
    UnknownParameter {
        rule: &'static str,
        key: String,
        known: String,
    },
    #[error("the {rule} query rule's {key} must be {expected}, got {value}")]
    BadParameter {
        rule: &'static str,
        key: &'static str,
        expected: &'static str,
        value: f64,
    },
}

/// The network's signals at one agent decision. Each is `None` when the rule did not ask for it
/// ([`Needs`]) or the network cannot give it (a plain network has no uncertainty, only bootstrapped heads have a
/// head variance).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Signals {
    /// The paper's uncertainty: the heads' JS divergence (bootstrapped) or the predictive variance of the greedy
    /// action's noisy output (noisy).
    pub uncertainty: Option<f32>,
    /// The variance over heads of each action's Q-value, averaged over actions (RCMP).
    pub head_variance: Option<f32>,
    /// The active head's best minus worst Q-value (student-initiated advising).
    pub q_gap: Option<f32>,
    /// ThriftyDAgger's risk at the agent's action: `1 - Q_R(s, a)`, with `Q_R` the risk critic's estimate of the
    /// (discounted) chance of reaching the task's goal (box tasks with a goal only).
    pub risk: Option<f32>,
    /// The agent's greedy action (its active head's argmax).
    pub greedy: usize,
}

/// What the expert would do here: for oracle rules only (checkpoint experts give Q-values).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OracleView {
    pub action: usize,
    pub q_values: Vec<f32>,
}

/// Which signals a rule reads; the training loop computes only these.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    pub uncertainty: bool,
    pub head_variance: bool,
    pub q_gap: bool,
    /// The risk of the agent's action ([`Signals::risk`]): the agent then trains a risk critic.
    pub risk: bool,
    /// The expert's action and Q-values at every decision ([`OracleView`]): an upper-bound reference, not a
    /// rule an agent could run against a real expert.
    pub oracle: bool,
}

impl Needs {
    /// Nothing: the rule decides from the step, the budget or chance.
    pub const NOTHING: Needs = Needs {
        uncertainty: false,
        head_variance: false,
        q_gap: false,
        risk: false,
        oracle: false,
    };
    /// The paper's uncertainty only.
    pub(crate) const UNCERTAINTY: Needs = Needs {
        uncertainty: true,
        ..Needs::NOTHING
    };
    /// The expert's view only ([`OracleView`]).
    pub(crate) const ORACLE: Needs = Needs {
        oracle: true,
        ..Needs::NOTHING
    };
}

/// Everything a rule may read at one agent decision.
#[derive(Clone, Copy, Debug)]
pub struct QueryContext<'a> {
    /// 0-based environment step of this decision.
    pub step: usize,
    /// The run's length in environment steps.
    pub train_steps: usize,
    /// The budget, in its unit.
    pub budget: usize,
    /// Budget spent so far, in its unit.
    pub budget_spent: usize,
    /// What the budget counts.
    pub unit: BudgetUnit,
    /// Expert steps per query.
    pub segment_len: usize,
    /// Queries asked so far.
    pub queries: usize,
    /// The index of the action the agent is about to take (after exploration); `None` for a box action.
    pub agent_action: Option<usize>,
    pub signals: &'a Signals,
    /// The expert's view, for oracle rules only.
    pub oracle: Option<&'a OracleView>,
}

impl QueryContext<'_> {
    /// The uncertainty signal, for a rule whose `needs` asked for it (the agent computes every declared
    /// signal; its absence is a bug in the rule's `needs`, named by `rule`).
    pub fn uncertainty(&self, rule: &str) -> f32 {
        self.signals.uncertainty.unwrap_or_else(|| {
            panic!("the {rule} rule reads the uncertainty: its needs must declare it")
        })
    }

    /// The risk signal, for a rule whose `needs` asked for it (as [`Self::uncertainty`]).
    pub fn risk(&self, rule: &str) -> f32 {
        self.signals
            .risk
            .unwrap_or_else(|| panic!("the {rule} rule reads the risk: its needs must declare it"))
    }

    /// Budget left, in its unit.
    pub fn budget_left(&self) -> usize {
        self.budget - self.budget_spent
    }

    /// Budget units one query spends when its segment runs whole: `segment_len` transitions, or one query.
    pub(crate) fn units_per_query(&self) -> f64 {
        match self.unit {
            BudgetUnit::Transitions => self.segment_len as f64,
            BudgetUnit::Queries => 1.0,
        }
    }

    /// The share of the budget a rule paced over the first `horizon` of the run (a fraction, 0 < horizon <= 1)
    /// may have spent after this decision: `budget * min(1, (step + 1) / (horizon * train_steps))`.
    pub(crate) fn pro_rata(&self, horizon: f64) -> f64 {
        let until = (horizon * self.train_steps as f64).max(1.0);
        self.budget as f64 * ((self.step + 1) as f64 / until).min(1.0)
    }

    /// The query probability that spends the budget left evenly over the decisions left until `horizon` of the
    /// run (after it, until the run's end): `left / (units_per_query * steps_left)`, at most 1.
    pub(crate) fn paced_probability(&self, horizon: f64) -> f64 {
        let until = (horizon * self.train_steps as f64).ceil() as usize;
        let end = if self.step < until {
            until
        } else {
            self.train_steps
        };
        let steps_left = end.saturating_sub(self.step).max(1) as f64;
        (self.budget_left() as f64 / (self.units_per_query() * steps_left)).min(1.0)
    }
}

/// A rule's answer at one decision.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[must_use]
pub struct Verdict {
    /// Whether to ask the expert now.
    pub query: bool,
    /// The threshold the rule compared against, if it has one (logged with each query).
    pub threshold: Option<f32>,
    /// The value the rule compared (logged as the query's uncertainty); rules that rank nothing give `None`.
    pub score: Option<f32>,
}

impl Verdict {
    /// No query, nothing compared.
    pub(crate) const NO: Verdict = Verdict {
        query: false,
        threshold: None,
        score: None,
    };
    /// A query with probability `p` (a draw from `rng`), nothing compared.
    pub fn chance(p: f64, rng: &mut dyn RngCore) -> Verdict {
        Verdict {
            query: rng.random_bool(p),
            ..Verdict::NO
        }
    }
}

/// When the agent asks the expert: one decision per agent step while budget is left.
///
/// Rules are deterministic given the context and `rng` (the run's query generator): the same seed gives the
/// same questions. A rule's state (windows, thresholds) goes into the run's snapshot through
/// [`QueryRule::save_state`] so that a resumed run decides exactly as an uninterrupted one.
pub trait QueryRule: std::fmt::Debug + Send {
    /// The rule's entry in [`RULES`], which names it and says what it reads.
    fn info(&self) -> &'static RuleInfo;
    /// The rule's name, as in specs and logs.
    fn name(&self) -> &'static str {
        self.info().name
    }
    /// The signals the rule reads.
    fn needs(&self) -> Needs {
        self.info().needs
    }
    /// Decides whether to ask now. Called only while the agent is about to act and budget is left.
    fn decide(&mut self, ctx: &QueryContext<'_>, rng: &mut dyn RngCore) -> Verdict;
    /// An episode ended (rules that recalibrate per episode do it here).
    fn end_episode(&mut self) {}
    /// The current threshold, for logs and the web page, if the rule has one.
    fn threshold(&self) -> Option<f32> {
        None
    }
    /// Writes the rule's state under `prefix` (nothing for stateless rules).
    fn save_state<'a>(&'a self, _prefix: &str, _state: &mut StateDict<'a>) {}
    /// Reads what [`QueryRule::save_state`] wrote into a rule built from the same spec.
    fn load_state(&mut self, _prefix: &str, _state: &StateDict<'_>) -> Result<(), StateError> {
        Ok(())
    }
}

/// What a rule's parameters default to when its spec leaves them out: the run's own settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RuleDefaults {
    /// The task's t_query (the paper's query fraction, BDQN's probability).
    pub t_query: f64,
    /// ADQN's window N_r.
    pub n_r: usize,
    pub budget: usize,
    pub segment_len: usize,
    pub train_steps: usize,
    pub unit: BudgetUnit,
}

impl RuleDefaults {
    /// The fraction of agent decisions that would spend the budget evenly over the run.
    pub(crate) fn target_rate(&self) -> f64 {
        let per_query = match self.unit {
            BudgetUnit::Transitions => self.segment_len as f64,
            BudgetUnit::Queries => 1.0,
        };
        (self.budget as f64 / (per_query * self.train_steps.max(1) as f64)).min(1.0)
    }
}

/// A rule spec's parameters, each read once by the rule's builder; leftovers are an error.
#[derive(Debug)]
pub(crate) struct Params {
    rule: &'static str,
    values: BTreeMap<String, f64>,
}

impl Params {
    /// The value of `key` checked by `valid` (described by `expected`), or `default`.
    pub fn get(
        &mut self,
        key: &'static str,
        default: f64,
        expected: &'static str,
        valid: impl Fn(f64) -> bool,
    ) -> Result<f64, QueryError> {
        let value = self.values.remove(key).unwrap_or(default);
        if !valid(value) {
            return Err(QueryError::BadParameter {
                rule: self.rule,
                key,
                expected,
                value,
            });
        }
        Ok(value)
    }

    /// A fraction in (0, 1].
    pub fn fraction(&mut self, key: &'static str, default: f64) -> Result<f64, QueryError> {
        self.get(key, default, "in (0, 1]", |v| v > 0.0 && v <= 1.0)
    }

    /// A count of at least 1.
    pub fn count(&mut self, key: &'static str, default: usize) -> Result<usize, QueryError> {
        self.get(key, default as f64, "a whole number of at least 1", |v| {
            v >= 1.0 && v.fract() == 0.0 && v <= 1e9
        })
        .map(|v| v as usize)
    }

    fn finish(self, known: &[&str]) -> Result<(), QueryError> {
        match self.values.into_keys().next() {
            None => Ok(()),
            Some(key) => Err(QueryError::UnknownParameter {
                rule: self.rule,
                key,
                known: if known.is_empty() {
                    "none".into()
                } else {
                    known.join(", ")
                },
            }),
        }
    }
}

type Build = fn(&mut Params, &RuleDefaults) -> Result<Box<dyn QueryRule>, QueryError>;

/// One entry of the rule registry.
pub struct RuleInfo {
    pub name: &'static str,
    /// Where the rule comes from.
    pub source: &'static str,
    /// Its parameters and their defaults, in words.
    pub params: &'static [(&'static str, &'static str)],
    /// The signals the rule reads; an oracle rule ([`Needs::oracle`]) reads the expert's Q-values: a reference,
    /// not a rule for a real expert.
    pub needs: Needs,
    build: Build,
}

/// Every rule arld knows, in the order of docs/algorithm.md section 14.
pub const RULES: &[RuleInfo] = &[
    paper::NEVER,
    paper::GREEDY,
    paper::BERNOULLI,
    paper::ADAPTIVE,
    field::PACED,
    field::RCMP,
    field::QGAP,
    field::CALIBRATED,
    field::BUDGET_PACED,
    field::VARIABLE,
    field::IMPORTANCE,
    field::MISTAKE,
    field::RISK,
    field::THRIFTY,
    ours::RANKED,
];

/// The names of every rule.
pub(crate) fn rule_names() -> Vec<&'static str> {
    RULES.iter().map(|r| r.name).collect()
}

/// A parsed rule spec: `name` or `name(key=value, ...)`.
#[derive(Clone, Debug, PartialEq)]
pub struct RuleSpec {
    pub name: String,
    pub params: BTreeMap<String, f64>,
}

impl std::str::FromStr for RuleSpec {
    type Err = QueryError;

    fn from_str(spec: &str) -> Result<Self, QueryError> {
        let bad = |reason: &str| QueryError::BadSpec {
            spec: spec.to_string(),
            reason: reason.to_string(),
        };
        let spec_trim = spec.trim();
        let (name, rest) = match spec_trim.find('(') {
            None => (spec_trim, None),
            Some(open) => {
                let inner = spec_trim[open + 1..]
                    .strip_suffix(')')
                    .ok_or_else(|| bad("the parameter list does not end with ')'"))?;
                (spec_trim[..open].trim(), Some(inner))
            }
        };
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        {
            return Err(bad("the name must be lowercase letters, digits and '_'"));
        }
        let mut params = BTreeMap::new();
        for pair in rest.into_iter().flat_map(|r| r.split(',')) {
            let pair = pair.trim();
            if pair.is_empty() {
                continue;
            }
            let (key, value) = pair
                .split_once('=')
                .ok_or_else(|| bad(&format!("'{pair}' is not key=value")))?;
            let value: f64 = value
                .trim()
                .parse()
                .map_err(|_| bad(&format!("'{}' is not a number", value.trim())))?;
            if !value.is_finite() {
                return Err(bad(&format!("{} must be finite", key.trim())));
            }
            if params.insert(key.trim().to_string(), value).is_some() {
                return Err(bad(&format!("'{}' is given twice", key.trim())));
            }
        }
        Ok(RuleSpec {
            name: name.to_string(),
            params,
        })
    }
}

impl std::fmt::Display for RuleSpec {
    /// The canonical form: parameters in key order, numbers as Rust prints them.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name)?;
        if !self.params.is_empty() {
            let list: Vec<String> = self
                .params
                .iter()
                .map(|(k, v)| format!("{k}={v}"))
                .collect();
            write!(f, "({})", list.join(","))?;
        }
        Ok(())
    }
}

impl RuleSpec {
    /// The registry entry of this spec's rule.
    pub fn info(&self) -> Result<&'static RuleInfo, QueryError> {
        RULES
            .iter()
            .find(|r| r.name == self.name)
            .ok_or_else(|| QueryError::UnknownRule(self.name.clone()))
    }

    /// Builds the rule; parameters left out take their defaults from `defaults`.
    pub fn build(&self, defaults: &RuleDefaults) -> Result<Box<dyn QueryRule>, QueryError> {
        let info = self.info()?;
        let mut params = Params {
            rule: info.name,
            values: self.params.clone(),
        };
        let rule = (info.build)(&mut params, defaults)?;
        let known: Vec<&str> = info.params.iter().map(|(k, _)| *k).collect();
        params.finish(&known)?;
        Ok(rule)
    }
}

/// Rejects, up front, a rule whose signals the network cannot give. `risk` says whether the run can train a risk
/// critic (a box task with a goal), or why not.
pub fn check_signals(
    rule: &dyn QueryRule,
    has_uncertainty: bool,
    has_heads: bool,
    risk: Result<(), String>,
) -> Result<(), QueryError> {
    let needs = rule.needs();
    if let (true, Err(reason)) = (needs.risk, risk) {
        return Err(QueryError::NoRisk {
            rule: rule.name(),
            reason,
        });
    }
    if needs.uncertainty && !has_uncertainty {
        return Err(QueryError::NoUncertaintySource { rule: rule.name() });
    }
    if needs.head_variance && !has_heads {
        return Err(QueryError::NoHeads { rule: rule.name() });
    }
    Ok(())
}

/// A recorded sequence of signals and a driver that feeds it to a rule, for the rules' tests.
#[cfg(test)]
pub(crate) mod tests_support {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// Decisions per episode: `replay` ends an episode every so many.
    pub const EPISODE_LEN: usize = 37;
    /// Transitions one question spends.
    pub const SEGMENT_LEN: usize = 5;

    /// Signals of `len` decisions: uncertainties that shrink as training goes on, with noise; episodes of
    /// [`EPISODE_LEN`] decisions; an expert with 3 actions; a budget of a quarter of the decisions' transitions.
    pub struct Recorded {
        /// What the agent's network signals at each decision (its greedy action is the agent's action).
        pub signals: Vec<Signals>,
        /// What the expert would do at each decision.
        pub oracle: Vec<OracleView>,
        /// The seed of the query generator `replay` gives the rule.
        pub rng_seed: u64,
    }

    impl Recorded {
        pub fn new(seed: u64, len: usize) -> Self {
            let mut rng = Pcg64::seed_from_u64(seed);
            let mut noise = move |scale: f32| rng.random::<f32>() * scale;
            let mut risk_draws = Pcg64::seed_from_u64(seed ^ 0x5249_534b);
            let mut r = Recorded {
                signals: Vec::with_capacity(len),
                oracle: Vec::with_capacity(len),
                rng_seed: seed + 1000,
            };
            for i in 0..len {
                let decay = 1.0 / (1.0 + i as f32 / 100.0);
                let uncertainty = Some(decay * noise(1.0));
                let head_variance = Some(decay * noise(4.0));
                let q_gap = Some(noise(2.0) + i as f32 / 200.0);
                r.signals.push(Signals {
                    uncertainty,
                    head_variance,
                    q_gap,
                    // From a stream of its own, so that the other signals stay what they were.
                    risk: Some(risk_draws.random::<f32>() * (1.0 - decay) + 0.5 * decay),
                    greedy: (noise(3.0) as usize).min(2),
                });
                let q: Vec<f32> = (0..3).map(|_| noise(10.0)).collect();
                let action = (0..3).max_by(|&a, &b| q[a].total_cmp(&q[b])).unwrap();
                r.oracle.push(OracleView {
                    action,
                    q_values: q,
                });
            }
            r
        }

        pub fn len(&self) -> usize {
            self.signals.len()
        }

        /// The budget, in transitions.
        pub fn budget(&self) -> usize {
            self.len() / 4
        }

        /// One signal at every decision, in order (`|s| s.uncertainty`, ...).
        pub fn column(&self, signal: impl Fn(&Signals) -> Option<f32>) -> Vec<f32> {
            self.signals
                .iter()
                .map(|s| signal(s).expect("every signal is recorded"))
                .collect()
        }
    }

    /// Feeds `recorded` to the rule built from `spec`, as the controller would: one decision per step, every
    /// query spending a whole segment, no decision once the budget is spent, `end_episode` every
    /// [`EPISODE_LEN`] decisions. Returns the decisions.
    pub fn replay(spec: &str, recorded: &Recorded) -> Vec<bool> {
        let defaults = RuleDefaults {
            t_query: 0.1,
            n_r: 1000,
            budget: recorded.budget(),
            segment_len: SEGMENT_LEN,
            train_steps: recorded.len(),
            unit: BudgetUnit::Transitions,
        };
        let mut rule = spec.parse::<RuleSpec>().unwrap().build(&defaults).unwrap();
        let mut rng = Pcg64::seed_from_u64(recorded.rng_seed);
        let (mut spent, mut queries) = (0, 0);
        let mut out = Vec::with_capacity(recorded.len());
        for i in 0..recorded.len() {
            if i > 0 && i % EPISODE_LEN == 0 {
                rule.end_episode();
            }
            if spent >= recorded.budget() {
                out.push(false);
                continue;
            }
            let ctx = QueryContext {
                step: i,
                train_steps: recorded.len(),
                budget: recorded.budget(),
                budget_spent: spent,
                unit: BudgetUnit::Transitions,
                segment_len: SEGMENT_LEN,
                queries,
                agent_action: Some(recorded.signals[i].greedy),
                signals: &recorded.signals[i],
                oracle: Some(&recorded.oracle[i]),
            };
            let query = rule.decide(&ctx, &mut rng).query;
            if query {
                queries += 1;
                spent = (spent + SEGMENT_LEN).min(recorded.budget());
            }
            out.push(query);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_print_and_refuse_what_they_should() {
        let spec: RuleSpec = "paced( horizon = 0.25 )".parse().unwrap();
        assert_eq!(spec.name, "paced");
        assert_eq!(spec.params["horizon"], 0.25);
        assert_eq!(spec.to_string(), "paced(horizon=0.25)");
        assert_eq!(
            "adaptive".parse::<RuleSpec>().unwrap().to_string(),
            "adaptive"
        );
        for (bad, says) in [
            ("paced(horizon=0.25", "does not end"),
            ("paced(horizon)", "not key=value"),
            ("paced(horizon=x)", "not a number"),
            ("paced(horizon=1,horizon=2)", "twice"),
            ("Paced", "lowercase"),
            ("paced(horizon=inf)", "finite"),
        ] {
            let err = bad.parse::<RuleSpec>().unwrap_err().to_string();
            assert!(err.contains(says), "{bad}: {err}");
        }
        let defaults = RuleDefaults {
            t_query: 0.3,
            n_r: 1000,
            budget: 100,
            segment_len: 5,
            train_steps: 20_000,
            unit: BudgetUnit::Transitions,
        };
        for (spec, named) in [
            ("nope", "rcmp"),
            ("paced(speed=2)", "horizon"),
            ("paced(horizon=2)", "(0, 1]"),
        ] {
            let err = spec.parse::<RuleSpec>().unwrap().build(&defaults);
            let err = err.unwrap_err().to_string();
            assert!(err.contains(named), "{spec}: {err}");
        }
        // Every registered rule builds with its defaults, under its own name.
        for info in RULES {
            let rule = info
                .name
                .parse::<RuleSpec>()
                .unwrap()
                .build(&defaults)
                .unwrap();
            assert_eq!((rule.name(), rule.needs()), (info.name, info.needs));
        }
    }

    #[test]
    fn pacing_helpers_spread_the_budget() {
        let signals = Signals::default();
        let ctx = |step: usize, spent: usize| QueryContext {
            step,
            train_steps: 1000,
            budget: 100,
            budget_spent: spent,
            unit: BudgetUnit::Transitions,
            segment_len: 5,
            queries: 0,
            agent_action: Some(0),
            signals: &signals,
            oracle: None,
        };
        // 100 transitions over 1000 steps in segments of 5: p = 100 / (5 * 1000).
        assert_eq!(ctx(0, 0).paced_probability(1.0), 100.0 / 5000.0);
        // Half the run left, 30 left: 30 / (5 * 500).
        assert_eq!(ctx(500, 70).paced_probability(1.0), 30.0 / 2500.0);
        // A horizon of 0.1: 100 over the first 100 steps; after it, the rest of the run.
        assert_eq!(ctx(0, 0).paced_probability(0.1), 100.0 / 500.0);
        assert_eq!(ctx(200, 90).paced_probability(0.1), 10.0 / (5.0 * 800.0));
        assert_eq!(ctx(99, 0).pro_rata(0.1), 100.0);
        assert_eq!(ctx(49, 0).pro_rata(0.1), 50.0);
        assert_eq!(ctx(499, 0).pro_rata(1.0), 50.0);
    }
}
