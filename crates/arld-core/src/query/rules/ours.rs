//! Query rules of arld's own, designed on the effort benchmark's design seeds (docs/algorithm.md section 14).
//!
//! - [`RankedPacedRule`] (`ranked`): chance paced over the first `horizon` of the run, tilted toward the
//!   states the agent is most uncertain about. At each decision with p the paced probability
//!   (`super::QueryContext::paced_probability`) and r the fraction of the last `n_r` uncertainties below the
//!   current one, it asks with probability `min(1, 2 r p)`: the expected spend stays the paced one (r is about
//!   uniform on [0, 1]), but a question lands where the agent is unsure relative to its recent states, and no
//!   question is asked before `start` of the run (say, before the network has learned anything).

use rand::RngCore;

use super::paper::AdaptiveQuantileRule;
use super::{Needs, QueryContext, QueryRule, RuleInfo, Verdict};
use crate::state::{StateDict, StateError};

/// Paced chance tilted by the uncertainty's rank in the recent window.
#[derive(Clone, Debug)]
pub struct RankedPacedRule {
    pub horizon: f64,
    pub start: f64,
    window: AdaptiveQuantileRule,
}

impl QueryRule for RankedPacedRule {
    fn info(&self) -> &'static RuleInfo {
        &RANKED
    }
    fn decide(&mut self, ctx: &QueryContext<'_>, rng: &mut dyn RngCore) -> Verdict {
        let u = ctx.uncertainty(self.name());
        let rank = self.window.rank(u);
        self.window.push(u);
        if (ctx.step as f64) < self.start * ctx.train_steps as f64 || u.is_nan() {
            return Verdict {
                score: Some(u),
                ..Verdict::NO
            };
        }
        let p = (2.0 * rank * ctx.paced_probability(self.horizon)).min(1.0);
        Verdict {
            score: Some(u),
            ..Verdict::chance(p, rng)
        }
    }
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.window.save_window(prefix, state);
    }
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.window.load_window(prefix, state)
    }
}

pub(super) const RANKED: RuleInfo = RuleInfo {
    name: "ranked",
    source: "ours: paced chance tilted toward uncertain states",
    params: &[("horizon", "1"), ("start", "0"), ("n_r", "n_r (1000)")],
    needs: Needs::UNCERTAINTY,
    build: |params, d| {
        let horizon = params.fraction("horizon", 1.0)?;
        let start = params.get("start", 0.0, "in [0, 1)", |v| (0.0..1.0).contains(&v))?;
        let n_r = params.count("n_r", d.n_r)?;
        // The window's t_query is unused: this rule reads ranks, not the threshold.
        Ok(Box::new(RankedPacedRule {
            horizon,
            start,
            window: AdaptiveQuantileRule::new(n_r, 0.0)?,
        }))
    },
};

#[cfg(test)]
mod tests {
    use super::super::tests_support::{Recorded, SEGMENT_LEN, replay};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    #[test]
    fn ranked_draws_twice_the_rank_times_the_paced_probability() {
        let r = Recorded::new(21, 900);
        let (n_r, horizon, start) = (60, 0.5, 0.1);
        let t = r.len() as f64;
        let mut rng = Pcg64::seed_from_u64(r.rng_seed);
        let (budget, uncertainty) = (r.budget(), r.column(|s| s.uncertainty));
        let mut spent = 0;
        let expected: Vec<bool> = (0..r.len())
            .map(|i| {
                if spent >= budget {
                    return false;
                }
                let u = uncertainty[i];
                let window = &uncertainty[i.saturating_sub(n_r)..i];
                let rank = if window.is_empty() {
                    0.0
                } else {
                    window.iter().filter(|v| **v < u).count() as f64 / window.len() as f64
                };
                if (i as f64) < start * t {
                    return false;
                }
                let until = (horizon * t).ceil();
                let end = if (i as f64) < until { until } else { t };
                let paced = ((budget - spent) as f64
                    / (SEGMENT_LEN as f64 * (end - i as f64).max(1.0)))
                .min(1.0);
                let q = rng.random_bool((2.0 * rank * paced).min(1.0));
                if q {
                    spent = (spent + SEGMENT_LEN).min(budget);
                }
                q
            })
            .collect();
        let got = replay(
            &format!("ranked(n_r={n_r},horizon={horizon},start={start})"),
            &r,
        );
        assert_eq!(got, expected);
        assert!(got[..90].iter().all(|q| !q) && got.iter().any(|q| *q));
    }
}
