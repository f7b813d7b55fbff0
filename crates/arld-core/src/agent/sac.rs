//! SAC (Haarnoja et al. 2018, "Soft Actor-Critic Algorithms and Applications"): the maximum-entropy actor-critic
//! learner for actions in a box, with a tanh-squashed Gaussian policy, a clipped double-Q soft target and an
//! entropy temperature tuned towards a target entropy.
//!
//! The actor maps a state to the mean `mu` and log standard deviation `log sigma` (clipped to [-20, 2]) of a
//! Gaussian per action dimension; an action is `u = mu + sigma eps` with `eps ~ N(0, 1)`, squashed to
//! `y = tanh(u)` and scaled to the box. Its log-probability (of `y`, in the squashed space (-1, 1)^dim(A), as
//! SB3 and the authors' code define it) is `sum_d [log N(u_d; mu_d, sigma_d) - log(1 - tanh(u_d)^2)]`, the second
//! term computed as `2 (u + softplus(-2u) - log 2)` so that it stays finite where `tanh(u)` rounds to ±1.
//!
//! The critics are the ensemble of `actor_critic.rs` (K heads on a shared torso; the soft target takes the first
//! two, and their spread is an uncertainty). One update (`learn`), in the order of the paper's algorithm:
//! - critics: regress every head on `y = r + gamma^n (min(Q'_1, Q'_2)(s', a') - alpha log pi(a'|s'))`, `a' ~
//!   pi(s')`, weighted by the replay's importance weights; the priority is the first head's absolute TD error
//!   (plus the demonstration bonus on demonstrated samples);
//! - actor: descend `mean_b [alpha log pi(a_b|s_b) - min(Q_1, Q_2)(s_b, a_b)]` with `a_b` reparameterised (plus
//!   the behaviour cloning term with the Q-filter on demonstrated samples, comparing `tanh(mu)`, the test action);
//! - temperature: descend `-log alpha (mean_b log pi(a_b|s_b) + target entropy)` in `log alpha`;
//! - targets: Polyak averaging of the critics.
//!
//! Every random draw (initial weights, the policy's noise when acting and learning) comes from the generator the
//! learner was built with; an update allocates nothing.

use rand::Rng;
use rand_distr::StandardNormal;

pub use super::actor_critic::BcStats;
use super::actor_critic::{
    ActionBox, ActorCritic, ActorCriticConfig, Algorithm, BoxLearner, BoxUpdate, Core, Net,
};
use crate::nn::{Adam, OutputActivation};
use crate::replay::Batch;
use crate::state::{Persist, StateDict, StateError};
use rand_pcg::Pcg64;

/// SAC's settings (the paper's defaults where it has them).
#[derive(Debug, Clone, PartialEq)]
pub struct SacConfig {
    /// What SAC shares with TD3 (networks, heads, learning rates: 3e-4 by default, Polyak rate, batch, cloning).
    pub common: ActorCriticConfig,
    /// Learning rate of `log alpha`.
    pub alpha_lr: f32,
    /// The temperature before the first update.
    pub initial_alpha: f32,
    /// The entropy the temperature steers towards; `None` for the paper's `-dim(A)`.
    pub target_entropy: Option<f32>,
}

impl Default for SacConfig {
    fn default() -> Self {
        SacConfig {
            common: ActorCriticConfig::with_learning_rate(3e-4),
            alpha_lr: 3e-4,
            initial_alpha: 1.0,
            target_entropy: None,
        }
    }
}

/// SAC's own part of the learner: the temperature, its optimiser and the buffers of an update.
pub struct SacPart {
    target_entropy: f32,
    log_alpha: f32,
    alpha_opt: Adam,
    // Buffers, sized for `max_batch`.
    /// The actor's outputs, rows `[mu | log sigma]`, and their loss gradient, `max_batch * 2 dim(A)`.
    out: Vec<f32>,
    d_out: Vec<f32>,
    /// The policy's noise `eps`, squashed samples `tanh(u)` and their actions, `max_batch * dim(A)`.
    noise: Vec<f32>,
    y: Vec<f32>,
    actions: Vec<f32>,
    /// `tanh(mu)` (the test action) and the cloning term's gradient with respect to it.
    y_mean: Vec<f32>,
    d_y_mean: Vec<f32>,
    log_probs: Vec<f32>,
    /// The head (0 or 1) with the smaller value at each sampled action.
    min_head: Vec<usize>,
}

/// The SAC learner: the shared core (actor, critics with their target, optimisers, generator) and SAC's part.
pub type Sac = BoxLearner<SacPart>;

/// The clip of the actor's log standard deviation (the authors' code).
pub(crate) const LOG_STD_MIN: f32 = -20.0;
pub(crate) const LOG_STD_MAX: f32 = 2.0;

/// `log(2 pi) / 2`.
const HALF_LOG_TWO_PI: f32 = 0.918_938_5;

/// `log(1 - tanh(u)^2)`, as `2 (log 2 - u - softplus(-2u))` (finite for every finite `u`).
fn log_one_minus_tanh_squared(u: f32) -> f32 {
    let x = -2.0 * u;
    let softplus = x.max(0.0) + (-x.abs()).exp().ln_1p();
    2.0 * (std::f32::consts::LN_2 - u - softplus)
}

/// Samples the squashed Gaussian policy for `noise.len() / dim` rows: from the actor's outputs `out` (rows
/// `[mu | log sigma]`) and standard normal `noise`, writes `y = tanh(mu + sigma eps)`, the actions (`y` scaled to
/// the box) and each row's log-probability.
fn squash(
    out: &[f32],
    noise: &[f32],
    action_box: &ActionBox,
    y: &mut [f32],
    actions: &mut [f32],
    log_probs: &mut [f32],
) {
    let a = action_box.dim();
    for (r, log_prob) in log_probs.iter_mut().enumerate() {
        let mut total = 0.0f32;
        for d in 0..a {
            let mu = out[r * 2 * a + d];
            let log_std = out[r * 2 * a + a + d].clamp(LOG_STD_MIN, LOG_STD_MAX);
            let eps = noise[r * a + d];
            let u = mu + log_std.exp() * eps;
            y[r * a + d] = u.tanh();
            total += -0.5 * eps * eps - log_std - HALF_LOG_TWO_PI - log_one_minus_tanh_squared(u);
        }
        *log_prob = total;
    }
    actions.copy_from_slice(y);
    action_box.to_box(actions);
}

impl Sac {
    /// A learner for observations of `obs_dim` values and actions in the box `[low, high]`, with its weights
    /// drawn from `rng` (actor first, then critic; the target starts as a copy).
    ///
    /// # Panics
    /// If the box is empty or inverted, or the configuration has fewer than two heads, a zero batch or a
    /// non-positive initial temperature (callers validate configurations first).
    pub fn new(config: SacConfig, obs_dim: usize, low: &[f32], high: &[f32], rng: Pcg64) -> Self {
        assert!(
            config.initial_alpha > 0.0,
            "SAC needs a positive temperature"
        );
        let core = ActorCritic::new(config.common, obs_dim, (low, high), SacPart::ACTOR, rng);
        let (a, n) = (core.action_dim(), core.config.max_batch);
        let algo = SacPart {
            target_entropy: config.target_entropy.unwrap_or(-(a as f32)),
            log_alpha: config.initial_alpha.ln(),
            alpha_opt: Adam::for_parameters(1, config.alpha_lr),
            out: vec![0.0; n * 2 * a],
            d_out: vec![0.0; n * 2 * a],
            noise: vec![0.0; n * a],
            y: vec![0.0; n * a],
            actions: vec![0.0; n * a],
            y_mean: vec![0.0; n * a],
            d_y_mean: vec![0.0; n * a],
            log_probs: vec![0.0; n],
            min_head: vec![0; n],
        };
        BoxLearner::from_parts(core, algo)
    }
}

impl SacPart {
    /// The actor's outputs per dimension of the action and their activation: the mean and the log standard
    /// deviation of the Gaussian, unbounded.
    pub(crate) const ACTOR: (usize, OutputActivation) = (2, OutputActivation::Linear);

    /// The test-time actions' tanh outputs from the actor's outputs `out` (rows of `2 * a`): `tanh(mu)`.
    pub(crate) fn units_of(out: &[f32], a: usize, units: &mut [f32]) {
        for (unit, out) in units.chunks_exact_mut(a).zip(out.chunks_exact(2 * a)) {
            for (v, mu) in unit.iter_mut().zip(&out[..a]) {
                *v = mu.tanh();
            }
        }
    }

    /// The entropy temperature `alpha`.
    pub fn alpha(&self) -> f32 {
        self.log_alpha.exp()
    }

    /// Fills the first `count` noise values from the generator.
    fn draw_noise(&mut self, core: &mut Core, count: usize) {
        for eps in &mut self.noise[..count] {
            *eps = core.rng.sample(StandardNormal);
        }
    }

    /// The actor's outputs at `n` rows of `obs`, into `self.out` (the pass stays in the actor's workspace).
    fn actor_outputs(&mut self, core: &mut Core, obs: &[f32], n: usize) {
        let a = core.action_dim();
        let out = core.actor.forward(obs, n);
        self.out[..2 * n * a].copy_from_slice(out);
    }

    /// Samples the policy ([`squash`]) at the first `n` rows of `self.out` with the noise in `self.noise`, into
    /// `self.y`, `self.actions` and `self.log_probs`.
    fn sample_policy(&mut self, core: &Core, n: usize) {
        let a = core.action_dim();
        squash(
            &self.out[..2 * n * a],
            &self.noise[..n * a],
            &core.action_box,
            &mut self.y[..n * a],
            &mut self.actions[..n * a],
            &mut self.log_probs[..n],
        );
    }

    /// The entropy estimate `-mean log pi` of the last actor step's `n` samples and the temperature loss's
    /// gradient `d/d(log alpha) of -log alpha (mean log pi + target entropy)`.
    fn temperature_gradient(&self, n: usize) -> (f32, f32) {
        let mean = self.log_probs[..n].iter().sum::<f32>() / n as f32;
        (-mean, -(mean + self.target_entropy))
    }

    /// The actor's loss at the batch's states with the noise in `self.noise` and temperature `alpha`:
    /// `mean_b [alpha log pi(a_b|s_b) - min(Q_1, Q_2)(s_b, a_b)]` plus the behaviour cloning term with the
    /// Q-filter (the demonstrated action against `tanh(mu)`, each valued by `min(Q_1, Q_2)`), and its gradient
    /// with respect to the actor's parameters in `core.actor.grads`. Returns the first part and the cloning
    /// term's measures; leaves the samples' log-probabilities in `self.log_probs`.
    fn actor_gradient(
        &mut self,
        core: &mut Core,
        batch: &Batch<Vec<f32>>,
        alpha: f32,
    ) -> (f32, Option<BcStats>) {
        let n = batch.len();
        let (d, a, k) = (core.obs_dim, core.action_dim(), core.config.heads);
        let pair_min = |q: &[f32], r: usize| q[r * k].min(q[r * k + 1]);
        let (cloning, filtering) = core.config.cloning(batch);
        if filtering {
            core.value_demonstrations(batch, |q| q[0].min(q[1]));
        }
        self.actor_outputs(core, &batch.obs, n);
        if cloning {
            for r in 0..n {
                for dim in 0..a {
                    self.y_mean[r * a + dim] = self.out[r * 2 * a + dim].tanh();
                }
            }
        }
        if filtering {
            let actions = &mut self.actions[..n * a];
            actions.copy_from_slice(&self.y_mean[..n * a]);
            core.action_box.to_box(actions);
            let q = core.critics.evaluate(Net::Online, &batch.obs, actions, n);
            for r in 0..n {
                core.q_pi[r] = pair_min(q, r);
            }
        }
        self.sample_policy(core, n);
        let q = core
            .critics
            .evaluate(Net::Online, &batch.obs, &self.actions[..n * a], n);
        let mut loss = 0.0f32;
        for r in 0..n {
            loss += alpha * self.log_probs[r] - pair_min(q, r);
            self.min_head[r] = usize::from(q[r * k + 1] < q[r * k]);
        }
        let d_q = core.critics.d_q(n);
        d_q.fill(0.0);
        for r in 0..n {
            d_q[r * k + self.min_head[r]] = -1.0 / n as f32;
        }
        let d_input = core.critics.backward_to_actions(n);
        let inv_n = 1.0 / n as f32;
        for r in 0..n {
            for dim in 0..a {
                let y = self.y[r * a + dim];
                let eps = self.noise[r * a + dim];
                let raw_log_std = self.out[r * 2 * a + a + dim];
                let d_action = d_input[r * (d + a) + d + dim];
                // dL/du: the entropy term's (d/du of -log(1 - tanh(u)^2) is 2 tanh(u)) and the critic's.
                let d_u =
                    alpha * 2.0 * y * inv_n + d_action * core.action_box.half[dim] * (1.0 - y * y);
                self.d_out[r * 2 * a + dim] = d_u;
                // u = mu + exp(log sigma) eps, and log N contributes -log sigma; the clip passes no gradient.
                self.d_out[r * 2 * a + a + dim] =
                    if raw_log_std > LOG_STD_MIN && raw_log_std < LOG_STD_MAX {
                        -alpha * inv_n + d_u * raw_log_std.exp() * eps
                    } else {
                        0.0
                    };
            }
        }
        let bc = if cloning {
            let d_y = &mut self.d_y_mean[..n * a];
            d_y.fill(0.0);
            let y = &self.y_mean[..n * a];
            let stats = core.behaviour_cloning(core.config.bc_weight, batch, filtering, y, d_y);
            for r in 0..n {
                for dim in 0..a {
                    let y = self.y_mean[r * a + dim];
                    self.d_out[r * 2 * a + dim] += d_y[r * a + dim] * (1.0 - y * y);
                }
            }
            Some(stats)
        } else {
            None
        };
        core.actor.backward(&self.d_out[..2 * n * a]);
        (loss * inv_n, bc)
    }
}

impl Algorithm for SacPart {
    /// The behaviour action at `obs`: a sample of the policy.
    fn act(&mut self, core: &mut Core, obs: &[f32], action: &mut [f32]) {
        let a = core.action_dim();
        self.actor_outputs(core, obs, 1);
        self.draw_noise(core, a);
        self.sample_policy(core, 1);
        action.copy_from_slice(&self.actions[..a]);
    }

    /// The test-time actions at the rows of `obs`: `tanh(mu)`.
    fn test_units(&self, core: &mut Core, obs: &[f32], units: &mut [f32]) {
        let a = core.action_dim();
        Self::units_of(core.actor.forward(obs, units.len() / a), a, units);
    }

    /// One update from `batch`: critics, actor, temperature, target.
    fn learn(&mut self, core: &mut Core, batch: &Batch<Vec<f32>>, gamma: f32) -> BoxUpdate {
        let (n, a) = core.check(batch);
        let alpha = self.alpha();

        // The soft target: r + gamma^n (min(Q'_1, Q'_2)(s', a') - alpha log pi(a'|s')), a' ~ pi(s').
        self.actor_outputs(core, batch.bootstrap_obs(), n);
        self.draw_noise(core, n * a);
        self.sample_policy(core, n);
        let entropy = Some((alpha, &self.log_probs[..n]));
        let critic_loss = core.critic_step(batch, gamma, &self.actions[..n * a], entropy);

        // The actor, on fresh samples at the batch's states.
        self.draw_noise(core, n * a);
        let (actor_loss, bc) = self.actor_gradient(core, batch, alpha);
        core.actor.step();

        // The temperature, from the same samples' log-probabilities.
        let (entropy, d_log_alpha) = self.temperature_gradient(n);
        self.alpha_opt
            .step_parameters(std::slice::from_mut(&mut self.log_alpha), &[d_log_alpha]);

        core.critics.soft_update(core.config.tau);
        core.updates += 1;
        BoxUpdate {
            critic_loss,
            actor_loss: Some(actor_loss),
            entropy: Some(entropy),
            bc,
        }
    }

    /// Writes the temperature and its optimiser (the core holds the rest).
    fn save_own<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        state.put_value(&format!("{prefix}.log_alpha"), &self.log_alpha);
        self.alpha_opt
            .save_state(&format!("{prefix}.alpha_adam"), state);
    }

    fn load_own(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.log_alpha = state.value(&format!("{prefix}.log_alpha"))?;
        self.alpha_opt
            .load_state(&format!("{prefix}.alpha_adam"), state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::actor_critic::ActorCriticLearner;
    use crate::agent::actor_critic::testing::*;
    use crate::nn::MlpWorkspace;
    use rand::SeedableRng;

    type Pcg = rand_pcg::Pcg64;

    /// A learner of the gradient checks in [`SMALL_BOX`] with two observations, temperature 0.3, from `seed`.
    fn small(bc_weight: f32, seed: u64) -> Sac {
        let config = SacConfig {
            common: small_config(bc_weight, SacConfig::default().common),
            initial_alpha: 0.3,
            ..SacConfig::default()
        };
        let (low, high) = SMALL_BOX;
        Sac::new(config, 2, &low, &high, Pcg::seed_from_u64(seed))
    }

    /// The first two heads' minimum at `(state, action)`, in float64.
    fn pair_min(agent: &Sac, state: &[f32], action: &[f32]) -> f64 {
        let q = heads_at(&agent.core, state, action);
        f64::from(q[0].min(q[1]))
    }

    /// One sample of the policy at `state` for the noise `eps`, in float64 with the textbook formulas: the
    /// action (in the box) and `log N(u; mu, sigma) - log(1 - tanh(u)^2)` summed over the dimensions.
    fn sample(agent: &Sac, state: &[f32], eps: &[f32]) -> (Vec<f32>, f64, Vec<f64>) {
        let mut ws = MlpWorkspace::new(&agent.core.actor.net, 1);
        let out = agent.core.actor.net.forward(state, 1, &mut ws).to_vec();
        let a = eps.len();
        let (low, high) = (&agent.core.action_box.low, &agent.core.action_box.high);
        let mut action = vec![0.0; a];
        let mut means = vec![0.0; a];
        let mut log_prob = 0.0f64;
        for d in 0..a {
            let mu = f64::from(out[d]);
            let log_std = f64::from(out[a + d]).clamp(-20.0, 2.0);
            let sigma = log_std.exp();
            let u = mu + sigma * f64::from(eps[d]);
            let y = u.tanh();
            let density = (-0.5 * ((u - mu) / sigma).powi(2)).exp()
                / (sigma * (2.0 * std::f64::consts::PI).sqrt());
            log_prob += density.ln() - (1.0 - y * y).ln();
            let half = 0.5 * f64::from(high[d] - low[d]);
            action[d] = (f64::from(low[d]) + (y + 1.0) * half) as f32;
            means[d] = mu.tanh();
        }
        (action, log_prob, means)
    }

    /// Checks `actor_gradient` against central differences of the loss computed here with forward passes alone.
    fn check_actor_gradient(bc_weight: f32, is_demo: &[bool]) {
        let mut agent = small(bc_weight, 5);
        let n = is_demo.len().max(3);
        let batch = random_batch(n, is_demo, 6);
        let mut draw = Pcg::seed_from_u64(7);
        let noise: Vec<f32> = (0..2 * n).map(|_| draw.sample(StandardNormal)).collect();
        agent.algo.noise[..2 * n].copy_from_slice(&noise);
        let alpha = 0.3f32;
        let (_, bc) = agent.algo.actor_gradient(&mut agent.core, &batch, alpha);
        let grads = agent.core.actor.grads.clone();
        // The Q-filter's outcome at the unperturbed parameters (a selection, not differentiated).
        let filter: Vec<bool> = (0..n)
            .map(|r| {
                let state = &batch.obs[2 * r..2 * r + 2];
                let mut test = vec![0.0; 2];
                agent.test_action(state, &mut test);
                batch.is_demo[r]
                    && pair_min(&agent, state, &batch.actions.values()[2 * r..2 * r + 2])
                        > pair_min(&agent, state, &test)
            })
            .collect();
        check_filter_counts(bc_weight, is_demo, &filter, bc);
        let half = [2.0f64, 0.25];
        let low = [-1.0f64, 0.0];
        let mut loss = |agent: &mut Sac| -> f64 {
            let mut total = 0.0f64;
            for r in 0..n {
                let state = &batch.obs[2 * r..2 * r + 2];
                let (action, log_prob, means) = sample(agent, state, &noise[2 * r..2 * r + 2]);
                total += f64::from(alpha) * log_prob - pair_min(agent, state, &action);
                if filter[r] {
                    for d in 0..2 {
                        let y_demo =
                            (f64::from(batch.actions.values()[2 * r + d]) - low[d]) / half[d] - 1.0;
                        total += f64::from(bc_weight) * (means[d] - y_demo).powi(2);
                    }
                }
            }
            total / n as f64
        };
        // Central differences at two steps; where a step crosses a kink (a ReLU, the heads' minimum) the two
        // disagree and the point is skipped; with eight rows through 16 ReLUs there are a few, at most one in ten.
        let mut skipped = 0;
        for (i, analytic) in grads.iter().enumerate() {
            let coarse = central_difference(&mut agent, i, 1e-2, &mut loss);
            let numeric = central_difference(&mut agent, i, 5e-3, &mut loss);
            let tolerance = 5e-3 * numeric.abs().max(0.1);
            if (coarse - numeric).abs() > tolerance {
                skipped += 1;
                continue;
            }
            assert!(
                (f64::from(*analytic) - numeric).abs() < tolerance,
                "actor parameter {i}: {analytic} vs {numeric}"
            );
        }
        eprintln!("{skipped} of {} parameters at a kink", grads.len());
        assert!(
            skipped * 10 <= grads.len(),
            "{skipped} of {} at a kink",
            grads.len()
        );
    }

    #[test]
    fn the_actor_gradient_with_the_tanh_correction_matches_finite_differences() {
        // d/d(theta) of mean [alpha log pi(a|s) - min(Q_1, Q_2)(s, a)] for fixed noise, against the float64
        // textbook density of the squashed Gaussian, in a box neither centred nor symmetric, three heads.
        check_actor_gradient(0.0, &[]);
    }

    #[test]
    fn the_behaviour_cloning_gradient_with_the_q_filter_matches_finite_differences() {
        check_actor_gradient(0.7, &[true, true, false, true, true, true, false, true]);
    }

    #[test]
    fn the_actor_gradient_on_eight_rows_matches_finite_differences() {
        check_actor_gradient(0.0, &[false; 8]);
    }

    #[test]
    fn the_temperature_gradient_and_log_probabilities_match_an_independent_computation() {
        // The learner's log-probabilities (stable form of the tanh correction) against the float64 textbook
        // density, and d/d(log alpha) of -log alpha (mean log pi + target entropy) against central differences
        // of that loss.
        let mut agent = small(0.0, 11);
        let n = 8;
        let batch = random_batch(n, &[], 12);
        let mut draw = Pcg::seed_from_u64(13);
        let noise: Vec<f32> = (0..2 * n).map(|_| draw.sample(StandardNormal)).collect();
        agent.algo.noise[..2 * n].copy_from_slice(&noise);
        agent.algo.actor_gradient(&mut agent.core, &batch, 0.5);
        let mut mean = 0.0f64;
        for r in 0..n {
            let (_, log_prob, _) = sample(
                &agent,
                &batch.obs[2 * r..2 * r + 2],
                &noise[2 * r..2 * r + 2],
            );
            let ours = f64::from(agent.algo.log_probs[r]);
            assert!(
                (ours - log_prob).abs() < 1e-4 * log_prob.abs().max(1.0),
                "row {r}: {ours} vs {log_prob}"
            );
            mean += log_prob / n as f64;
        }
        assert_eq!(agent.algo.target_entropy, -2.0);
        let loss = |log_alpha: f64| -log_alpha * (mean + f64::from(agent.algo.target_entropy));
        let log_alpha = f64::from(agent.algo.log_alpha);
        let numeric = (loss(log_alpha + 1e-3) - loss(log_alpha - 1e-3)) / 2e-3;
        let (entropy, analytic) = agent.algo.temperature_gradient(n);
        assert!(
            (f64::from(analytic) - numeric).abs() < 1e-4 * numeric.abs().max(1.0),
            "{analytic} vs {numeric}"
        );
        assert!((f64::from(entropy) + mean).abs() < 1e-4 * mean.abs().max(1.0));
        // Far in the tails, where tanh(u) rounds to ±1 in float32, the log-probability stays finite.
        assert!(
            log_one_minus_tanh_squared(30.0).is_finite()
                && log_one_minus_tanh_squared(-30.0).is_finite()
        );
        assert!(
            (f64::from(log_one_minus_tanh_squared(30.0)) - (-60.0 + 2.0 * std::f64::consts::LN_2))
                .abs()
                < 1e-3
        );
    }

    #[test]
    fn the_same_seed_gives_the_same_bytes() {
        // Two learners from seed 21 fed the same batches (with demonstrations and the cloning term) act and learn
        // identically, bit for bit; a third from seed 22 does not.
        let run = |seed: u64| {
            let mut agent = small(0.5, seed);
            let mut trace = Vec::new();
            let mut action = [0.0f32; 2];
            for step in 0..6 {
                let batch = random_batch(
                    8,
                    &[true, false, true, false, false, true, true, false],
                    step,
                );
                let alpha = agent.algo.alpha();
                let (stats, priorities) = agent.learn(&batch, GAMMA);
                trace.extend(priorities.iter().map(|p| p.to_bits()));
                trace.push(stats.critic_loss.to_bits());
                trace.push(alpha.to_bits());
                agent.act(&[0.1, -0.2], &mut action);
                trace.extend(action.map(f32::to_bits));
                trace.push(agent.critic_spread(&[0.1, -0.2], &action).to_bits());
                trace.push(agent.action_disagreement(&[0.1, -0.2]).to_bits());
            }
            trace.extend(
                agent
                    .core
                    .actor
                    .net
                    .parameters()
                    .iter()
                    .map(|p| p.to_bits()),
            );
            trace.extend(
                agent
                    .core
                    .critics
                    .net
                    .parameters()
                    .iter()
                    .map(|p| p.to_bits()),
            );
            trace
        };
        let (first, second, other) = (run(21), run(21), run(22));
        assert_eq!(first, second);
        assert_ne!(first, other);
    }

    #[test]
    fn the_action_disagreement_matches_each_heads_argmax_computed_here() {
        // Each head's best of the probes around tanh(mu), found by evaluating the critic one probe at a time; the
        // disagreement is their standard deviation over heads, in half-widths.
        let mut agent = small(0.0, 31);
        let batch = random_batch(8, &[], 32);
        for _ in 0..20 {
            agent.learn(&batch, GAMMA);
        }
        let mut nonzero = 0;
        for r in 0..8 {
            let state = &batch.obs[2 * r..2 * r + 2];
            let (_, _, means) = sample(&agent, state, &[0.0, 0.0]);
            let mut probes = vec![means.iter().map(|m| *m as f32).collect::<Vec<f32>>()];
            for d in 0..2 {
                for sign in [1.0f32, -1.0] {
                    let mut p = probes[0].clone();
                    p[d] =
                        (p[d] + sign * crate::agent::actor_critic::PROBE_OFFSET).clamp(-1.0, 1.0);
                    probes.push(p);
                }
            }
            let mut ws = MlpWorkspace::new(&agent.core.critics.net, 1);
            let values: Vec<Vec<f32>> = probes
                .iter()
                .map(|p| {
                    let mut input = state.to_vec();
                    input.extend([-1.0 + (p[0] + 1.0) * 2.0, (p[1] + 1.0) * 0.25]);
                    agent.core.critics.net.forward(&input, 1, &mut ws).to_vec()
                })
                .collect();
            let picks: Vec<&Vec<f32>> = (0..3)
                .map(|h| {
                    let mut best = 0;
                    for (i, v) in values.iter().enumerate() {
                        if v[h] > values[best][h] {
                            best = i;
                        }
                    }
                    &probes[best]
                })
                .collect();
            let mut variance = 0.0f64;
            for d in 0..2 {
                let mean = picks.iter().map(|p| f64::from(p[d])).sum::<f64>() / 3.0;
                variance += picks
                    .iter()
                    .map(|p| (f64::from(p[d]) - mean).powi(2))
                    .sum::<f64>()
                    / 3.0;
            }
            let expected = (variance / 2.0).sqrt();
            let ours = agent.action_disagreement(state);
            assert!(
                (f64::from(ours) - expected).abs() < 1e-5,
                "state {r}: {ours} vs {expected}"
            );
            nonzero += usize::from(expected > 0.0);
        }
        eprintln!("the heads disagreed on {nonzero} of 8 states");
    }

    /// SAC with the shared settings `common` and its learning rate of the temperature 1e-3.
    fn pendulum_agent(common: ActorCriticConfig, seed: u64) -> Sac {
        let config = SacConfig {
            common,
            alpha_lr: 1e-3,
            ..SacConfig::default()
        };
        Sac::new(config, 3, &[-2.0], &[2.0], Pcg::seed_from_u64(seed))
    }

    #[test]
    fn sac_learns_pendulum() {
        // 64-64 networks, batch 128, 10,000 steps (the first 1,000 uniformly random), one update a step; the
        // policy's mean action must then hold Pendulum-v1 above -200 on ten evaluation seeds it never trained on.
        let mut agent = pendulum_agent(pendulum_config(), 0);
        learns_pendulum(&mut agent, 10_000, "SAC");
        eprintln!(
            "SAC's temperature after training: {:.4}",
            agent.algo.alpha()
        );
    }

    #[test]
    fn pretraining_on_demonstrations_imitates_the_swing_up() {
        pretraining_imitates(&mut pendulum_agent(pretraining_config(), 3), 2_000, "SAC");
    }
}
