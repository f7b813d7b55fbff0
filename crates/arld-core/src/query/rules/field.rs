//! Query rules from the literature on asking for help, each on arld's signals (docs/algorithm.md section 14 has
//! the sources, in our words):
//!
//! - [`PacedRule`] (`paced`): chance without front-loading: Bernoulli with the probability that spends the
//!   budget left evenly over the steps left (until `horizon` of the run);
//! - [`RcmpRule`] (`rcmp`; Da Silva et al., AAAI 2020): ask when the variance of the heads' Q-values, averaged
//!   over actions, exceeds a threshold;
//! - [`QGapRule`] (`qgap`; student-initiated advising, Amir et al. 2016): ask when the gap between the best and
//!   worst Q-value is below its `percentile` of all past gaps;
//! - [`CalibratedRule`] (`calibrated`; ThriftyDAgger, Hoque et al. 2021): the threshold is the `(1 - alpha)`
//!   quantile of every uncertainty seen so far, recomputed after each episode, `alpha` set so that the budget is
//!   spread over the run;
//! - [`BudgetPacedRule`] (`budget_paced`; stream-based active learning's budget managers, Zliobaite et al. 2014):
//!   the paper's windowed test, and the spend so far below the pro-rata share of the budget;
//!   [`VariableThresholdRule`] (`variable`): the same budget manager with a threshold raised after each question
//!   and lowered after each decision that asks nothing;
//! - [`ImportanceRule`] (`importance`, `mistake`; Torrey and Taylor 2013), oracle references: ask where the
//!   expert's best and worst Q-values are far apart, and (mistake correcting) the agent is about to act otherwise
//!   than the expert would;
//! - [`ThriftyRule`] (`risk`, `thrifty`; ThriftyDAgger, Hoque et al. 2021): ask when the risk of the agent's
//!   action (`1 - Q_R`) is above the `(1 - alpha)` quantile of every risk so far, calibrated as `calibrated`
//!   is; `thrifty` also asks when the uncertainty (ThriftyDAgger's novelty) is above its own such quantile.

use rand::RngCore;

use super::paper::{AdaptiveQuantileRule, window};
use super::{Needs, QueryContext, QueryError, QueryRule, RuleInfo, Verdict};
use crate::query::OrderStatistics;
use crate::state::{StateDict, StateError};

/// Bernoulli with the paced probability `QueryContext::paced_probability`.
#[derive(Clone, Copy, Debug)]
pub struct PacedRule {
    pub horizon: f64,
}

impl QueryRule for PacedRule {
    fn info(&self) -> &'static RuleInfo {
        &PACED
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, rng: &mut dyn RngCore) -> Verdict {
        Verdict::chance(ctx.paced_probability(self.horizon), rng)
    }
}

/// Ask when the heads' Q-value variance exceeds a fixed threshold.
#[derive(Clone, Copy, Debug)]
pub struct RcmpRule {
    pub threshold: f32,
}

impl QueryRule for RcmpRule {
    fn info(&self) -> &'static RuleInfo {
        &RCMP
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, _rng: &mut dyn RngCore) -> Verdict {
        let variance = ctx
            .signals
            .head_variance
            .expect("rcmp reads the head variance");
        Verdict {
            query: variance > self.threshold,
            threshold: Some(self.threshold),
            score: Some(variance),
        }
    }
    fn threshold(&self) -> Option<f32> {
        Some(self.threshold)
    }
}

/// Every value seen so far, ranked; kept in arrival order too for the snapshot.
#[derive(Clone, Debug, Default)]
struct History {
    values: Vec<f32>,
    ranked: OrderStatistics,
}

impl History {
    fn push(&mut self, value: f32) {
        if !value.is_nan() {
            self.values.push(value);
            self.ranked.insert(value);
        }
    }

    /// The value at ascending position `floor(len * fraction)`, clamped to the last one.
    fn ascending_quantile(&self, fraction: f64) -> Option<f32> {
        let len = self.values.len();
        (len > 0).then(|| {
            let k = ((len as f64 * fraction).floor() as usize).min(len - 1);
            self.ranked.kth_smallest(k).expect("k < len")
        })
    }

    /// The value at descending position `floor(len * fraction)`, clamped to the last one.
    fn descending_quantile(&self, fraction: f64) -> Option<f32> {
        let len = self.values.len();
        (len > 0).then(|| {
            let k = ((len as f64 * fraction).floor() as usize).min(len - 1);
            self.ranked.kth_largest(k).expect("k < len")
        })
    }

    fn save<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        state.put_f32(&format!("{prefix}.history"), self.values.as_slice());
    }

    fn load(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        *self = History::default();
        for &v in state.f32s(&format!("{prefix}.history"))? {
            self.push(v);
        }
        Ok(())
    }
}

/// Ask when the Q-gap is below its `percentile` of every past gap.
#[derive(Clone, Debug)]
pub struct QGapRule {
    pub percentile: f64,
    history: History,
}

impl QueryRule for QGapRule {
    fn info(&self) -> &'static RuleInfo {
        &QGAP
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, _rng: &mut dyn RngCore) -> Verdict {
        let gap = ctx.signals.q_gap.expect("qgap reads the Q-gap");
        let threshold = self.history.ascending_quantile(self.percentile);
        self.history.push(gap);
        Verdict {
            query: threshold.is_some_and(|t| gap < t),
            threshold,
            score: Some(gap),
        }
    }
    fn threshold(&self) -> Option<f32> {
        self.history.ascending_quantile(self.percentile)
    }
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.history.save(prefix, state);
    }
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.history.load(prefix, state)
    }
}

/// ThriftyDAgger's calibration: the `(1 - alpha)` quantile of all uncertainties so far, set after each episode.
#[derive(Clone, Debug)]
pub struct CalibratedRule {
    pub alpha: f64,
    history: History,
    threshold: Option<f32>,
}

impl QueryRule for CalibratedRule {
    fn info(&self) -> &'static RuleInfo {
        &CALIBRATED
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, _rng: &mut dyn RngCore) -> Verdict {
        self.observe(ctx.uncertainty(self.name()))
    }
    fn end_episode(&mut self) {
        self.threshold = self.history.descending_quantile(self.alpha);
    }
    fn threshold(&self) -> Option<f32> {
        self.threshold
    }
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.history.save(prefix, state);
        state.put_value(&format!("{prefix}.threshold"), &self.threshold);
    }
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.history.load(prefix, state)?;
        self.threshold = state.value(&format!("{prefix}.threshold"))?;
        Ok(())
    }
}

impl CalibratedRule {
    /// A calibration at the `(1 - alpha)` quantile, with nothing seen yet.
    fn new(alpha: f64) -> Self {
        CalibratedRule {
            alpha,
            history: History::default(),
            threshold: None,
        }
    }

    /// Records `value` and compares it with the threshold of the last episode's end.
    fn observe(&mut self, value: f32) -> Verdict {
        self.history.push(value);
        Verdict {
            query: self.threshold.is_some_and(|t| value > t),
            threshold: self.threshold,
            score: Some(value),
        }
    }
}

/// ThriftyDAgger's gate: the risk of the agent's action above the `(1 - alpha)` quantile of every risk so far,
/// or (with `novelty`) the uncertainty above the `(1 - alpha)` quantile of every uncertainty so far; both
/// thresholds recomputed after each episode. Logged: the risk and its threshold (a question whose risk is at
/// most its threshold was asked for novelty).
#[derive(Clone, Debug)]
pub struct ThriftyRule {
    risk: CalibratedRule,
    novelty: Option<CalibratedRule>,
}

impl QueryRule for ThriftyRule {
    fn info(&self) -> &'static RuleInfo {
        if self.novelty.is_some() {
            &THRIFTY
        } else {
            &RISK
        }
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, _rng: &mut dyn RngCore) -> Verdict {
        let name = self.name();
        let risky = self.risk.observe(ctx.risk(name));
        let novel = match &mut self.novelty {
            Some(novelty) => novelty.observe(ctx.uncertainty(name)).query,
            None => false,
        };
        Verdict {
            query: risky.query || novel,
            ..risky
        }
    }
    fn end_episode(&mut self) {
        self.risk.end_episode();
        if let Some(novelty) = &mut self.novelty {
            novelty.end_episode();
        }
    }
    fn threshold(&self) -> Option<f32> {
        self.risk.threshold
    }
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.risk.save_state(&format!("{prefix}.risk"), state);
        if let Some(novelty) = &self.novelty {
            novelty.save_state(&format!("{prefix}.novelty"), state);
        }
    }
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.risk.load_state(&format!("{prefix}.risk"), state)?;
        match &mut self.novelty {
            Some(novelty) => novelty.load_state(&format!("{prefix}.novelty"), state),
            None => Ok(()),
        }
    }
}

/// The paper's windowed test, asked only while the spend is below the pro-rata share of the budget.
#[derive(Clone, Debug)]
pub struct BudgetPacedRule {
    pub horizon: f64,
    window: AdaptiveQuantileRule,
}

impl QueryRule for BudgetPacedRule {
    fn info(&self) -> &'static RuleInfo {
        &BUDGET_PACED
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, _rng: &mut dyn RngCore) -> Verdict {
        let u = ctx.uncertainty(self.name());
        let verdict = self.window.observe(u);
        Verdict {
            query: verdict.query && (ctx.budget_spent as f64) < ctx.pro_rata(self.horizon),
            ..verdict
        }
    }
    fn threshold(&self) -> Option<f32> {
        self.window.threshold()
    }
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.window.save_window(prefix, state);
    }
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.window.load_window(prefix, state)
    }
}

/// Zliobaite et al.'s variable threshold under the pro-rata budget: starts at the first uncertainty; while
/// the spend is below the pro-rata share, asks when the uncertainty exceeds it, then multiplies it by
/// `1 + step` after a question and by `1 - step` otherwise.
#[derive(Clone, Copy, Debug)]
pub struct VariableThresholdRule {
    pub step: f64,
    pub horizon: f64,
    threshold: Option<f32>,
}

impl QueryRule for VariableThresholdRule {
    fn info(&self) -> &'static RuleInfo {
        &VARIABLE
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, _rng: &mut dyn RngCore) -> Verdict {
        let u = ctx.uncertainty(self.name());
        let Some(threshold) = self.threshold.filter(|_| !u.is_nan()) else {
            if !u.is_nan() {
                self.threshold = Some(u);
            }
            return Verdict {
                score: Some(u),
                ..Verdict::NO
            };
        };
        if (ctx.budget_spent as f64) >= ctx.pro_rata(self.horizon) {
            return Verdict {
                threshold: Some(threshold),
                score: Some(u),
                ..Verdict::NO
            };
        }
        let query = u > threshold;
        let factor = if query {
            1.0 + self.step
        } else {
            1.0 - self.step
        };
        self.threshold = Some((threshold as f64 * factor) as f32);
        Verdict {
            query,
            threshold: Some(threshold),
            score: Some(u),
        }
    }
    fn threshold(&self) -> Option<f32> {
        self.threshold
    }
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        state.put_value(&format!("{prefix}.threshold"), &self.threshold);
    }
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.threshold = state.value(&format!("{prefix}.threshold"))?;
        Ok(())
    }
}

/// Teacher-side advising: importance = the expert's best minus worst Q-value. With a fixed `threshold`, ask when
/// importance is at least that; without one, when it exceeds the paper's windowed quantile of recent
/// importances (so the rule needs no scale per task). `mistake` also requires the agent's action to differ from
/// the expert's.
#[derive(Clone, Debug)]
pub struct ImportanceRule {
    pub threshold: Option<f32>,
    pub mistake: bool,
    window: AdaptiveQuantileRule,
}

impl QueryRule for ImportanceRule {
    fn info(&self) -> &'static RuleInfo {
        if self.mistake { &MISTAKE } else { &IMPORTANCE }
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, _rng: &mut dyn RngCore) -> Verdict {
        let oracle = ctx.oracle.expect("an oracle rule sees the expert");
        let importance = importance(&oracle.q_values);
        let verdict = match self.threshold {
            Some(t) => Verdict {
                query: importance >= t,
                threshold: Some(t),
                score: Some(importance),
            },
            None => self.window.observe(importance),
        };
        Verdict {
            query: verdict.query && (!self.mistake || ctx.agent_action != Some(oracle.action)),
            ..verdict
        }
    }
    fn threshold(&self) -> Option<f32> {
        self.threshold.or_else(|| self.window.threshold())
    }
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.window.save_window(prefix, state);
    }
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.window.load_window(prefix, state)
    }
}

/// The expert's best minus worst Q-value.
fn importance(q: &[f32]) -> f32 {
    let max = q.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let min = q.iter().copied().fold(f32::INFINITY, f32::min);
    max - min
}

fn horizon(params: &mut super::Params) -> Result<f64, QueryError> {
    params.fraction("horizon", 1.0)
}

pub(super) const PACED: RuleInfo = RuleInfo {
    name: "paced",
    source: "chance without front-loading (ours, after the issue's probe)",
    params: &[("horizon", "1: spread over the whole run")],
    needs: Needs::NOTHING,
    build: |params, _| {
        Ok(Box::new(PacedRule {
            horizon: horizon(params)?,
        }))
    },
};

pub(super) const RCMP: RuleInfo = RuleInfo {
    name: "rcmp",
    source: "Da Silva, Hernandez-Leal, Kartal, Taylor (AAAI 2020)",
    params: &[(
        "threshold",
        "0.03: about the upper decile of the head variances on design seed 0",
    )],
    needs: Needs {
        head_variance: true,
        ..Needs::NOTHING
    },
    build: |params, _| {
        let threshold = params.get("threshold", 0.03, "at least 0", |v| v >= 0.0)?;
        Ok(Box::new(RcmpRule {
            threshold: threshold as f32,
        }))
    },
};

pub(super) const QGAP: RuleInfo = RuleInfo {
    name: "qgap",
    source: "student-initiated advising, Amir, Kamar, Kolobov, Grosz (IJCAI 2016)",
    params: &[("percentile", "the task's t_query")],
    needs: Needs {
        q_gap: true,
        ..Needs::NOTHING
    },
    build: |params, d| {
        let percentile = params.fraction("percentile", d.t_query)?;
        Ok(Box::new(QGapRule {
            percentile,
            history: History::default(),
        }))
    },
};

pub(super) const CALIBRATED: RuleInfo = RuleInfo {
    name: "calibrated",
    source: "ThriftyDAgger, Hoque, Balakrishna, Novoseller, Wilcox, Brown, Goldberg (CoRL 2021)",
    params: &[(
        "alpha",
        "budget / (units per query x train_steps): the budget spread over the run",
    )],
    needs: Needs::UNCERTAINTY,
    build: |params, d| Ok(Box::new(CalibratedRule::new(target_alpha(params, d)?))),
};

/// The `alpha` parameter of a calibrated rule: by default the rate that spreads the budget over the run.
fn target_alpha(params: &mut super::Params, d: &super::RuleDefaults) -> Result<f64, QueryError> {
    params.fraction("alpha", d.target_rate().max(f64::MIN_POSITIVE))
}

pub(super) const RISK: RuleInfo = RuleInfo {
    name: "risk",
    source: "ThriftyDAgger's risk gate, Hoque et al. (CoRL 2021)",
    params: CALIBRATED.params,
    needs: Needs {
        risk: true,
        ..Needs::NOTHING
    },
    build: |params, d| {
        Ok(Box::new(ThriftyRule {
            risk: CalibratedRule::new(target_alpha(params, d)?),
            novelty: None,
        }))
    },
};

pub(super) const THRIFTY: RuleInfo = RuleInfo {
    name: "thrifty",
    source: "ThriftyDAgger's novelty-or-risk gate, Hoque et al. (CoRL 2021)",
    params: CALIBRATED.params,
    needs: Needs {
        risk: true,
        uncertainty: true,
        ..Needs::NOTHING
    },
    build: |params, d| {
        let alpha = target_alpha(params, d)?;
        Ok(Box::new(ThriftyRule {
            risk: CalibratedRule::new(alpha),
            novelty: Some(CalibratedRule::new(alpha)),
        }))
    },
};

pub(super) const BUDGET_PACED: RuleInfo = RuleInfo {
    name: "budget_paced",
    source: "budget managers of stream-based active learning, Zliobaite, Bifet, Pfahringer, Holmes (2014)",
    params: &[
        ("t_query", "the task's t_query"),
        ("n_r", "n_r (1000)"),
        ("horizon", "1"),
    ],
    needs: Needs::UNCERTAINTY,
    build: |params, d| {
        let window = window(params, d)?;
        Ok(Box::new(BudgetPacedRule {
            horizon: horizon(params)?,
            window,
        }))
    },
};

pub(super) const VARIABLE: RuleInfo = RuleInfo {
    name: "variable",
    source: "variable-threshold budget manager, Zliobaite et al. (2014)",
    params: &[("step", "0.01"), ("horizon", "1")],
    needs: Needs::UNCERTAINTY,
    build: |params, _| {
        let step = params.get("step", 0.01, "in (0, 1)", |v| v > 0.0 && v < 1.0)?;
        Ok(Box::new(VariableThresholdRule {
            step,
            horizon: horizon(params)?,
            threshold: None,
        }))
    },
};

fn importance_rule(
    params: &mut super::Params,
    d: &super::RuleDefaults,
    mistake: bool,
) -> Result<Box<dyn QueryRule>, QueryError> {
    let threshold = params.get("threshold", -1.0, "at least 0 (or -1: adaptive)", |v| {
        v >= 0.0 || v == -1.0
    })?;
    Ok(Box::new(ImportanceRule {
        threshold: (threshold >= 0.0).then_some(threshold as f32),
        mistake,
        window: window(params, d)?,
    }))
}

pub(super) const IMPORTANCE: RuleInfo = RuleInfo {
    name: "importance",
    source: "importance advising, Torrey and Taylor (AAMAS 2013); oracle",
    params: &[
        ("threshold", "-1: the windowed quantile of importances"),
        ("t_query", "the task's t_query"),
        ("n_r", "n_r (1000)"),
    ],
    needs: Needs::ORACLE,
    build: |params, d| importance_rule(params, d, false),
};

pub(super) const MISTAKE: RuleInfo = RuleInfo {
    name: "mistake",
    source: "mistake correcting, Torrey and Taylor (AAMAS 2013); oracle",
    params: IMPORTANCE.params,
    needs: Needs::ORACLE,
    build: |params, d| importance_rule(params, d, true),
};

#[cfg(test)]
mod tests {
    use super::super::tests_support::{EPISODE_LEN, Recorded, SEGMENT_LEN, replay};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// Decisions written directly from each rule's definition, with the spend accounting of `replay`.
    fn by_definition(
        recorded: &Recorded,
        mut rule: impl FnMut(usize, usize, &mut Pcg64) -> bool,
        mut end_episode: impl FnMut(usize),
    ) -> Vec<bool> {
        let mut rng = Pcg64::seed_from_u64(recorded.rng_seed);
        let mut spent = 0;
        (0..recorded.len())
            .map(|i| {
                if i > 0 && i % EPISODE_LEN == 0 {
                    end_episode(i);
                }
                if spent >= recorded.budget() {
                    return false;
                }
                let q = rule(i, spent, &mut rng);
                if q {
                    spent = (spent + SEGMENT_LEN).min(recorded.budget());
                }
                q
            })
            .collect()
    }

    fn nth_desc(values: &[f32], fraction: f64) -> Option<f32> {
        let mut v = values.to_vec();
        v.sort_by(|a, b| b.total_cmp(a));
        (!v.is_empty()).then(|| v[((v.len() as f64 * fraction).floor() as usize).min(v.len() - 1)])
    }

    fn nth_asc(values: &[f32], fraction: f64) -> Option<f32> {
        let mut v = values.to_vec();
        v.sort_by(|a, b| a.total_cmp(b));
        (!v.is_empty()).then(|| v[((v.len() as f64 * fraction).floor() as usize).min(v.len() - 1)])
    }

    #[test]
    fn paced_draws_the_probability_that_spreads_the_budget_left() {
        let r = Recorded::new(11, 600);
        let t = r.len() as f64;
        for horizon in [1.0, 0.25] {
            let expected = by_definition(
                &r,
                |i, spent, rng| {
                    let end = if (i as f64) < (horizon * t).ceil() {
                        (horizon * t).ceil()
                    } else {
                        t
                    };
                    let p =
                        ((r.budget() - spent) as f64 / (5.0 * (end - i as f64).max(1.0))).min(1.0);
                    rng.random_bool(p)
                },
                |_| {},
            );
            let got = replay(&format!("paced(horizon={horizon})"), &r);
            assert_eq!(got, expected, "horizon {horizon}");
            assert!(got.iter().any(|q| *q));
        }
    }

    #[test]
    fn rcmp_asks_above_its_variance_threshold() {
        let r = Recorded::new(12, 500);
        let variance = r.column(|s| s.head_variance);
        let expected = by_definition(&r, |i, _, _| variance[i] > 0.5, |_| {});
        assert_eq!(replay("rcmp(threshold=0.5)", &r), expected);
    }

    #[test]
    fn qgap_asks_below_its_percentile_of_past_gaps() {
        let r = Recorded::new(13, 500);
        let gap = r.column(|s| s.q_gap);
        let expected = by_definition(
            &r,
            |i, _, _| nth_asc(&gap[..i], 0.2).is_some_and(|t| gap[i] < t),
            |_| {},
        );
        let got = replay("qgap(percentile=0.2)", &r);
        assert_eq!(got, expected);
        assert!(got.iter().any(|q| *q));
    }

    #[test]
    fn calibrated_recomputes_its_quantile_after_each_episode() {
        let r = Recorded::new(14, 700);
        let alpha = 0.05;
        let threshold = std::cell::Cell::new(None);
        let u = r.column(|s| s.uncertainty);
        let expected = by_definition(
            &r,
            |i, _, _| threshold.get().is_some_and(|t: f32| u[i] > t),
            |i| threshold.set(nth_desc(&u[..i], alpha)),
        );
        assert_eq!(replay("calibrated(alpha=0.05)", &r), expected);
    }

    #[test]
    fn risk_and_thrifty_recompute_their_quantiles_after_each_episode() {
        // `risk`: the risk above the (1 - alpha) quantile of every risk before the last episode's end;
        // `thrifty`: that, or the uncertainty above its own such quantile. Thresholds recomputed here by sorting.
        let mut r = Recorded::new(18, 900);
        // Uncertainties that grow as the run goes on, so that novelty asks too.
        let mut u = r.column(|s| s.uncertainty);
        u.reverse();
        for (s, u) in r.signals.iter_mut().zip(&u) {
            s.uncertainty = Some(*u);
        }
        let risk = r.column(|s| s.risk);
        let alpha = 0.04;
        let (risk_t, novelty_t) = (std::cell::Cell::new(None), std::cell::Cell::new(None));
        let recalibrate = |i: usize| {
            risk_t.set(nth_desc(&risk[..i], alpha));
            novelty_t.set(nth_desc(&u[..i], alpha));
        };
        let above = |t: &std::cell::Cell<Option<f32>>, v: f32| t.get().is_some_and(|t| v > t);
        let risky = by_definition(&r, |i, _, _| above(&risk_t, risk[i]), recalibrate);
        let got = replay(&format!("risk(alpha={alpha})"), &r);
        assert_eq!(got, risky);
        risk_t.set(None);
        novelty_t.set(None);
        let either = by_definition(
            &r,
            |i, _, _| above(&risk_t, risk[i]) || above(&novelty_t, u[i]),
            recalibrate,
        );
        let got_thrifty = replay(&format!("thrifty(alpha={alpha})"), &r);
        assert_eq!(got_thrifty, either);
        // Questions happen, and the novelty changes which.
        assert!(got.iter().any(|q| *q));
        assert_ne!(got, got_thrifty);
    }

    #[test]
    fn budget_paced_is_the_windowed_test_under_the_pro_rata_share() {
        let r = Recorded::new(15, 800);
        let (n_r, t, horizon) = (40, 0.3, 0.5);
        let u = r.column(|s| s.uncertainty);
        let expected = by_definition(
            &r,
            |i, spent, _| {
                let window = &u[i.saturating_sub(n_r)..i];
                let pro_rata =
                    r.budget() as f64 * ((i + 1) as f64 / (horizon * r.len() as f64)).min(1.0);
                nth_desc(window, t).is_some_and(|thr| u[i] > thr) && (spent as f64) < pro_rata
            },
            |_| {},
        );
        assert_eq!(
            replay(
                &format!("budget_paced(n_r={n_r},t_query={t},horizon={horizon})"),
                &r
            ),
            expected
        );
    }

    #[test]
    fn variable_moves_its_threshold_after_each_decision() {
        let r = Recorded::new(16, 800);
        let step = 0.05;
        let theta = std::cell::Cell::new(None::<f32>);
        let expected = by_definition(
            &r,
            |i, spent, _| {
                let u = r.signals[i].uncertainty.unwrap();
                let Some(th) = theta.get() else {
                    theta.set(Some(u));
                    return false;
                };
                if spent as f64 >= r.budget() as f64 * ((i + 1) as f64 / r.len() as f64) {
                    return false;
                }
                let q = u > th;
                theta.set(Some(
                    (th as f64 * if q { 1.0 + step } else { 1.0 - step }) as f32,
                ));
                q
            },
            |_| {},
        );
        assert_eq!(replay(&format!("variable(step={step})"), &r), expected);
    }

    #[test]
    fn oracle_rules_read_the_experts_q_values() {
        let r = Recorded::new(17, 600);
        let importance = |i: usize| {
            let q = &r.oracle[i].q_values;
            q.iter().cloned().fold(f32::MIN, f32::max) - q.iter().cloned().fold(f32::MAX, f32::min)
        };
        let expected = by_definition(&r, |i, _, _| importance(i) >= 6.0, |_| {});
        assert_eq!(replay("importance(threshold=6)", &r), expected);
        let expected = by_definition(
            &r,
            |i, _, _| importance(i) >= 6.0 && r.signals[i].greedy != r.oracle[i].action,
            |_| {},
        );
        assert_eq!(replay("mistake(threshold=6)", &r), expected);
        // Without a threshold: the windowed quantile of recent importances.
        let all: Vec<f32> = (0..r.len()).map(importance).collect();
        let expected = by_definition(
            &r,
            |i, _, _| nth_desc(&all[i.saturating_sub(100)..i], 0.1).is_some_and(|t| all[i] > t),
            |_| {},
        );
        assert_eq!(replay("importance(n_r=100,t_query=0.1)", &r), expected);
    }
}
