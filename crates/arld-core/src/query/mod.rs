//! Query machinery of Active DQN: when the learning agent hands control to the expert.
//!
//! This is the paper's contribution (Chen et al., section 4 and Algorithm 1; docs/algorithm.md sections 7-9).
//! At every step where the agent is about to act, the training loop
//!
//! 1. asks the [`QueryController`] which signals the rule reads now (`QueryController::signals_wanted_now`);
//! 2. computes those from the network output: [`js_divergence`] (bootstrapped heads) or [`noisy_variance`]
//!    (noisy output layer), [`head_variance`], the Q-gap;
//! 3. calls [`QueryController::decide`], which consults the [`QueryRule`] (the paper's never, greedy,
//!    Bernoulli and adaptive rules, or any rule of [`rules`]) and, on a query, opens a segment of expert control;
//! 4. while [`QueryController::expert_in_control`] holds, lets the expert act and reports every demonstrated
//!    transition with `QueryController::record_expert_step`, which spends the budget.
//!
//! The parts:
//! - [`uncertainty`]: the two uncertainty measures, allocation-free, one call per agent decision.
//! - `order_stats`: [`OrderStatistics`], a size-augmented treap over `f32`, the balanced search tree that lets
//!   the adaptive rule read a quantile of the recent uncertainties in O(log N_r).
//! - [`rules`]: the [`QueryRule`] interface, its implementations side by side, and rule specs ([`RuleSpec`]).
//! - [`controller`]: [`QueryController`] with the budget (counted in demonstrated transitions) and the segment
//!   logic (one query = up to `segment_len` expert steps).

pub mod controller;
pub(crate) mod order_stats;
pub mod rules;
pub mod uncertainty;

pub use controller::{BudgetUnit, Decision, DecisionInput, QueryController};
pub use order_stats::OrderStatistics;
pub use rules::{
    AdaptiveQuantileRule, Needs, OracleView, QueryError, QueryRule, RULES, RuleDefaults, RuleSpec,
    Signals, check_signals,
};
pub use uncertainty::{head_variance, js_divergence, noisy_variance, q_gap};
