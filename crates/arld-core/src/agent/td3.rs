//! TD3 (Fujimoto, van Hoof & Meger 2018, "Addressing Function Approximation Error in Actor-Critic Methods"): the
//! actor-critic learner for actions in a box, with the three devices of the paper: a clipped double-Q target (the
//! smaller of two critics' estimates), delayed policy updates (the actor and the targets move every
//! `policy_delay` critic updates) and target policy smoothing (clipped Gaussian noise on the target action).
//!
//! The critics are `heads` outputs of one network on a shared torso, `Q(s, a) -> [Q_1 .. Q_K]`: with two heads it
//! is TD3's pair, and more heads give the ensemble whose disagreement is an uncertainty signal
//! (`critic_spread`). The target takes the minimum over the first two heads. The actor `pi(s)` is a tanh
//! network scaled to the box. Every parameter lives in an [`Mlp`]; every random draw (initial weights,
//! exploration noise, target smoothing) comes from the generator the learner was built with.
//!
//! A batch (the replay's [`Batch`]) carries n-step transitions with their discount `gamma^n` (0 at a terminal
//! state), and per-sample importance weights for a prioritized replay; `learn` returns the new priorities (the
//! absolute TD errors of the first head, plus `demo_priority_bonus` on demonstrated samples). On demonstrated
//! samples the actor's loss gains the behaviour cloning term of Nair et al. 2018, with or without their Q-filter
//! (`bc_weight`, `q_filter`; docs/algorithm.md §17). The critics, the batch and the box map are shared with SAC
//! (`actor_critic.rs`).

use rand::Rng;
use rand_distr::StandardNormal;
use rand_pcg::Pcg64;

pub use super::actor_critic::BcStats;
use super::actor_critic::{
    ActorCritic, ActorCriticConfig, Algorithm, BoxLearner, BoxUpdate, Core, Net,
};
use crate::nn::{Mlp, OutputActivation};
use crate::replay::Batch;
use crate::state::{Persist, StateDict, StateError};

/// TD3's settings (the paper's defaults where it has them).
#[derive(Debug, Clone, PartialEq)]
pub struct Td3Config {
    /// What TD3 shares with SAC (networks, heads, learning rates: 1e-3 by default, Polyak rate, batch, cloning).
    pub common: ActorCriticConfig,
    /// Critic updates per actor (and target) update.
    pub policy_delay: u64,
    /// Standard deviation of the target smoothing noise and its clip, as fractions of the box's half-width.
    pub target_noise: f32,
    pub noise_clip: f32,
    /// Standard deviation of the exploration noise, as a fraction of the box's half-width.
    pub exploration_noise: f32,
}

impl Default for Td3Config {
    fn default() -> Self {
        Td3Config {
            common: ActorCriticConfig::with_learning_rate(1e-3),
            policy_delay: 2,
            target_noise: 0.2,
            noise_clip: 0.5,
            exploration_noise: 0.1,
        }
    }
}

/// TD3's own part of the learner: its settings beyond the shared ones, the actor's target and the buffers of an
/// update.
pub struct Td3Part {
    policy_delay: u64,
    target_noise: f32,
    noise_clip: f32,
    exploration_noise: f32,
    actor_target: Mlp,
    // Buffers, sized for `max_batch`.
    /// Actions (in the box), the actor's tanh outputs and their loss gradient, `max_batch * dim(A)`.
    actions: Vec<f32>,
    y: Vec<f32>,
    d_y: Vec<f32>,
}

/// The TD3 learner: the shared core (actor, critics with their target, optimisers, generator) and TD3's part.
pub type Td3 = BoxLearner<Td3Part>;

impl Td3Part {
    /// The actor's outputs per dimension of the action and their activation: the tanh action itself.
    pub(crate) const ACTOR: (usize, OutputActivation) = (1, OutputActivation::Tanh);

    /// The test-time actions' tanh outputs from the actor's outputs `out`: the outputs themselves.
    pub(crate) fn units_of(out: &[f32], _a: usize, units: &mut [f32]) {
        units.copy_from_slice(&out[..units.len()]);
    }
}

impl Td3 {
    /// A learner for observations of `obs_dim` values and actions in the box `[low, high]`, with its weights
    /// drawn from `rng` (actor first, then critic; the targets start as copies).
    ///
    /// # Panics
    /// If the box is empty or inverted, or the configuration has fewer than two heads or a zero batch (callers
    /// validate configurations first).
    pub fn new(config: Td3Config, obs_dim: usize, low: &[f32], high: &[f32], rng: Pcg64) -> Self {
        let core = ActorCritic::new(config.common, obs_dim, (low, high), Td3Part::ACTOR, rng);
        let len = core.config.max_batch * core.action_dim();
        let algo = Td3Part {
            policy_delay: config.policy_delay,
            target_noise: config.target_noise,
            noise_clip: config.noise_clip,
            exploration_noise: config.exploration_noise,
            actor_target: core.actor.net.clone(),
            actions: vec![0.0; len],
            y: vec![0.0; len],
            d_y: vec![0.0; len],
        };
        BoxLearner::from_parts(core, algo)
    }
}

impl Td3Part {
    /// The actor's loss at the batch's observations, `-mean over the batch and the heads of Q(s, pi(s))` plus the
    /// behaviour cloning term with the Q-filter on its demonstrated samples (the heads' mean compares the
    /// demonstrated action with the actor's), and its gradient with respect to the actor's parameters in
    /// `core.actor.grads` (through the critic's input gradient and the box's scaling). Returns the Q part of the
    /// loss and the cloning term's measures.
    fn actor_gradient(
        &mut self,
        core: &mut Core,
        batch: &Batch<Vec<f32>>,
    ) -> (f32, Option<BcStats>) {
        let n = batch.len();
        let (d, a, k) = (core.obs_dim, core.action_dim(), core.config.heads);
        let (cloning, filtering) = core.config.cloning(batch);
        if filtering {
            core.value_demonstrations(batch, |q| q.iter().sum::<f32>() / k as f32);
        }
        let y = core.actor.forward(&batch.obs, n);
        self.y[..n * a].copy_from_slice(y);
        let actions = &mut self.actions[..n * a];
        actions.copy_from_slice(y);
        core.action_box.to_box(actions);
        let q = core.critics.evaluate(Net::Online, &batch.obs, actions, n);
        let loss = -q.iter().sum::<f32>() / (n * k) as f32;
        if filtering {
            for r in 0..n {
                core.q_pi[r] = q[r * k..(r + 1) * k].iter().sum::<f32>() / k as f32;
            }
        }
        core.critics.d_q(n).fill(-1.0 / (n * k) as f32);
        let d_input = core.critics.backward_to_actions(n);
        let d_y = &mut self.d_y[..n * a];
        for r in 0..n {
            for dim in 0..a {
                d_y[r * a + dim] = d_input[r * (d + a) + d + dim] * core.action_box.half[dim];
            }
        }
        let bc = if cloning {
            let y = &self.y[..n * a];
            Some(core.behaviour_cloning(core.config.bc_weight, batch, filtering, y, d_y))
        } else {
            None
        };
        core.actor.backward(d_y);
        (loss, bc)
    }
}

impl Algorithm for Td3Part {
    /// The behaviour action at `obs`: the actor's plus Gaussian exploration noise, clipped to the box.
    fn act(&mut self, core: &mut Core, obs: &[f32], action: &mut [f32]) {
        self.test_units(core, obs, action);
        let b = &core.action_box;
        b.to_box(action);
        for (d, a) in action.iter_mut().enumerate() {
            let z: f32 = core.rng.sample(StandardNormal);
            let noisy = *a + z * self.exploration_noise * b.half[d];
            *a = noisy.clamp(b.low[d], b.high[d]);
        }
    }

    /// The test-time actions at the rows of `obs`: the actor's, without noise.
    fn test_units(&self, core: &mut Core, obs: &[f32], units: &mut [f32]) {
        let a = core.action_dim();
        Self::units_of(core.actor.forward(obs, units.len() / a), a, units);
    }

    /// One update from `batch`: the critics always, the actor and the targets every `policy_delay` updates.
    fn learn(&mut self, core: &mut Core, batch: &Batch<Vec<f32>>, gamma: f32) -> BoxUpdate {
        let (n, a) = core.check(batch);

        // The target: r + gamma^n * min(Q'_1, Q'_2)(s', pi'(s') + clipped noise).
        let y = self
            .actor_target
            .forward(batch.bootstrap_obs(), n, &mut core.actor.ws);
        let next_actions = &mut self.actions[..n * a];
        next_actions.copy_from_slice(y);
        core.action_box.to_box(next_actions);
        let b = &core.action_box;
        for (i, v) in next_actions.iter_mut().enumerate() {
            let dim = i % a;
            let scale = b.half[dim];
            let z: f32 = core.rng.sample(StandardNormal);
            let clip = self.noise_clip * scale;
            let noise = (z * self.target_noise * scale).clamp(-clip, clip);
            *v = (*v + noise).clamp(b.low[dim], b.high[dim]);
        }
        // The critics: weighted squared TD error of every head, averaged over the batch.
        let critic_loss = core.critic_step(batch, gamma, next_actions, None);
        core.updates += 1;
        let mut stats = BoxUpdate {
            critic_loss,
            actor_loss: None,
            entropy: None,
            bc: None,
        };

        if core.updates.is_multiple_of(self.policy_delay) {
            let (actor_loss, bc) = self.actor_gradient(core, batch);
            core.actor.step();
            stats.actor_loss = Some(actor_loss);
            stats.bc = bc;
            let tau = core.config.tau;
            self.actor_target.soft_update(&core.actor.net, tau);
            core.critics.soft_update(tau);
        }
        stats
    }

    /// Writes the actor's target (the core holds the rest).
    fn save_own<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.actor_target
            .save_state(&format!("{prefix}.actor_target"), state);
    }

    fn load_own(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.actor_target
            .load_state(&format!("{prefix}.actor_target"), state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::actor_critic::ActorCriticLearner;
    use crate::agent::actor_critic::testing::*;
    use rand::SeedableRng;

    /// A learner for Pendulum-v1 (3 observations, one action in [-2, 2]) with the shared settings `common` and
    /// TD3's defaults, from `seed`.
    fn pendulum_agent(common: ActorCriticConfig, seed: u64) -> Td3 {
        let config = Td3Config {
            common,
            ..Td3Config::default()
        };
        Td3::new(config, 3, &[-2.0], &[2.0], Pcg64::seed_from_u64(seed))
    }

    #[test]
    fn td3_learns_pendulum() {
        // 64-64 networks, batch 128, 12,000 steps (the first 1,000 uniformly random), one update a step; the
        // greedy policy must then hold Pendulum-v1 above -200 on ten evaluation seeds it never trained on.
        learns_pendulum(&mut pendulum_agent(pendulum_config(), 0), 12_000, "TD3");
    }

    #[test]
    fn pretraining_on_demonstrations_imitates_the_swing_up() {
        pretraining_imitates(&mut pendulum_agent(pretraining_config(), 3), 2_000, "TD3");
    }

    #[test]
    fn the_actor_gradient_matches_finite_differences_of_the_mean_q() {
        // d(-mean Q(s, pi(s)))/d(theta), from the critic's input gradient through the box's scaling, against
        // central differences of the same loss computed by forward passes alone, in a box that is neither
        // centred nor symmetric.
        check_actor_gradient(0.0, &[]);
    }

    /// Checks `actor_gradient` against central differences with the cloning weight `bc_weight` and the
    /// demonstration flags `is_demo` (one per row; empty for none).
    fn check_actor_gradient(bc_weight: f32, is_demo: &[bool]) {
        let config = Td3Config {
            common: small_config(bc_weight, Td3Config::default().common),
            ..Td3Config::default()
        };
        let (low, high) = SMALL_BOX;
        let mut agent = Td3::new(config, 2, &low, &high, Pcg64::seed_from_u64(5));
        let n = is_demo.len().max(3);
        let batch = random_batch(n, is_demo, 6);
        let actions = batch.actions.values();
        let (_, bc) = agent.algo.actor_gradient(&mut agent.core, &batch);
        let grads = agent.core.actor.grads.clone();
        // The sum and the mean of the heads; the Q-filter's outcome at the unperturbed parameters (a selection,
        // not differentiated).
        let heads_mean = |agent: &Td3, state: &[f32], action: &[f32]| -> (f64, f64) {
            let q = heads_at(&agent.core, state, action);
            let sum = q.iter().map(|v| f64::from(*v)).sum::<f64>();
            (sum, sum / q.len() as f64)
        };
        let filter: Vec<bool> = (0..n)
            .map(|r| {
                let state = &batch.obs[2 * r..2 * r + 2];
                let mut action = vec![0.0; 2];
                agent.test_action(state, &mut action);
                let demo = &actions[2 * r..2 * r + 2];
                batch.is_demo[r]
                    && heads_mean(&agent, state, demo).1 > heads_mean(&agent, state, &action).1
            })
            .collect();
        check_filter_counts(bc_weight, is_demo, &filter, bc);
        let mut loss = |agent: &mut Td3| -> f64 {
            let mut q_total = 0.0f64;
            let mut cloning = 0.0f64;
            for (r, &cloned) in filter.iter().enumerate() {
                let state = &batch.obs[2 * r..2 * r + 2];
                let mut action = vec![0.0; 2];
                agent.test_action(state, &mut action);
                q_total += heads_mean(agent, state, &action).0;
                if cloned {
                    for d in 0..2 {
                        let half = 0.5 * f64::from(high[d] - low[d]);
                        let y = (f64::from(action[d]) - f64::from(low[d])) / half;
                        let y_demo = (f64::from(actions[2 * r + d]) - f64::from(low[d])) / half;
                        cloning += (y - y_demo).powi(2);
                    }
                }
            }
            -q_total / (3 * n) as f64 + f64::from(bc_weight) / n as f64 * cloning
        };
        for (i, analytic) in grads.iter().enumerate() {
            let numeric = central_difference(&mut agent, i, 1e-2, &mut loss);
            assert!(
                (f64::from(*analytic) - numeric).abs() < 2e-3 * numeric.abs().max(0.1),
                "actor parameter {i}: {analytic} vs {numeric}"
            );
        }
    }

    #[test]
    fn the_behaviour_cloning_gradient_with_the_q_filter_matches_finite_differences() {
        // The actor loss plus 0.7 / n * sum over demonstrated rows whose demonstrated action the critics value
        // above the actor's of |y - y_demo|^2: the Q-filter computed independently here, and both of its
        // outcomes present among the demonstrated rows.
        check_actor_gradient(0.7, &[true, true, false, true, true, true, false, true]);
    }

    #[test]
    fn demonstrated_samples_get_the_priority_bonus_and_nothing_else_changes() {
        // Two learners from one seed, one with a bonus of 0.5: on a batch with demonstrations the priorities
        // differ by exactly the bonus on the demonstrated samples, and the updates are the same.
        let mut agents = [0.0, 0.5].map(|bonus| {
            let common = ActorCriticConfig {
                hidden: vec![8],
                max_batch: 4,
                demo_priority_bonus: bonus,
                ..Td3Config::default().common
            };
            let config = Td3Config {
                common,
                ..Td3Config::default()
            };
            Td3::new(config, 1, &[-2.0], &[2.0], Pcg64::seed_from_u64(9))
        });
        let batch = Batch {
            idx: (0..4).collect(),
            obs: vec![0.1, -0.4, 0.9, 0.3],
            actions: column(1, &[1.0, -1.5, 0.2, 0.0]),
            rewards: vec![1.0, 0.0, -1.0, 0.5],
            next_obs: vec![0.2, -0.3, 0.8, 0.2],
            terminal: vec![false, true, false, false],
            weights: vec![1.0; 4],
            is_demo: vec![true, false, false, true],
            ..Batch::default()
        };
        let plain = agents[0].learn(&batch, GAMMA).1.to_vec();
        let bonus = agents[1].learn(&batch, GAMMA).1.to_vec();
        for r in 0..4 {
            let expected = plain[r] + if batch.is_demo[r] { 0.5 } else { 0.0 };
            assert_eq!(bonus[r], expected, "sample {r}");
        }
        assert_eq!(
            agents[0].core.critics.net.parameters(),
            agents[1].core.critics.net.parameters()
        );
    }
}
