//! TD3 (Fujimoto, van Hoof & Meger 2018, "Addressing Function Approximation Error in Actor-Critic Methods"): the
//! actor-critic learner for actions in a box, with the three devices of the paper: a clipped double-Q target (the
//! smaller of two critics' estimates), delayed policy updates (the actor and the targets move every
//! `policy_delay` critic updates) and target policy smoothing (clipped Gaussian noise on the target action).
//!
//! The critics are `heads` outputs of one network on a shared torso, `Q(s, a) -> [Q_1 .. Q_K]`: with two heads it
//! is TD3's pair, and more heads give the ensemble whose disagreement is an uncertainty signal
//! ([`Td3::critic_spread`]). The target takes the minimum over the first two heads. The actor `pi(s)` is a tanh
//! network scaled to the box. Every parameter lives in an [`Mlp`]; every random draw (initial weights,
//! exploration noise, target smoothing) comes from the generator the learner was built with.
//!
//! A batch ([`BoxBatch`]) carries n-step transitions with their discount `gamma^n` (0 at a terminal state), and
//! per-sample importance weights for a prioritized replay; [`Td3::learn`] returns the new priorities (the
//! absolute TD errors of the first head).

use rand::Rng;
use rand_distr::StandardNormal;

use crate::nn::{Adam, Mlp, MlpWorkspace, OutputActivation};
use crate::state::{Persist, StateDict, StateError};
use serde::{Serialize, de::DeserializeOwned};

/// TD3's settings (the paper's defaults where it has them).
#[derive(Debug, Clone, PartialEq)]
pub struct Td3Config {
    /// Hidden widths of the actor and of the critics' torso.
    pub hidden: Vec<usize>,
    /// Critic heads on the shared torso (at least 2: the clipped double-Q target takes the first two).
    pub heads: usize,
    /// Polyak averaging rate of the target networks.
    pub tau: f32,
    pub actor_lr: f32,
    pub critic_lr: f32,
    /// Critic updates per actor (and target) update.
    pub policy_delay: u64,
    /// Standard deviation of the target smoothing noise and its clip, as fractions of the box's half-width.
    pub target_noise: f32,
    pub noise_clip: f32,
    /// Standard deviation of the exploration noise, as a fraction of the box's half-width.
    pub exploration_noise: f32,
    /// The largest batch [`Td3::learn`] accepts.
    pub max_batch: usize,
}

impl Default for Td3Config {
    fn default() -> Self {
        Td3Config {
            hidden: vec![256, 256],
            heads: 2,
            tau: 0.005,
            actor_lr: 1e-3,
            critic_lr: 1e-3,
            policy_delay: 2,
            target_noise: 0.2,
            noise_clip: 0.5,
            exploration_noise: 0.1,
            max_batch: 256,
        }
    }
}

/// A batch of transitions in a box action space, row-major.
#[derive(Debug, Clone, Default)]
pub struct BoxBatch {
    pub obs: Vec<f32>,
    pub actions: Vec<f32>,
    /// The n-step return of each sample.
    pub rewards: Vec<f32>,
    pub next_obs: Vec<f32>,
    /// `gamma^n` of each sample, 0 where the n-step return reached a terminal state.
    pub discounts: Vec<f32>,
    /// Importance-sampling weights (1 without prioritized replay).
    pub weights: Vec<f32>,
}

impl BoxBatch {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    /// Whether the batch holds no sample.
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }
}

/// What one update measured.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Td3Stats {
    /// Mean over the batch and the heads of the weighted squared TD error.
    pub critic_loss: f32,
    /// `-mean Q` of the actor's actions, when the actor moved in this update.
    pub actor_loss: Option<f32>,
}

/// The TD3 learner: actor, critics, their targets and optimisers, and the buffers of an update.
pub struct Td3<R: Rng> {
    config: Td3Config,
    obs_dim: usize,
    low: Vec<f32>,
    high: Vec<f32>,
    actor: Mlp,
    actor_target: Mlp,
    critic: Mlp,
    critic_target: Mlp,
    actor_opt: Adam,
    critic_opt: Adam,
    rng: R,
    updates: u64,
    // Buffers, sized for `max_batch`.
    actor_ws: MlpWorkspace,
    critic_ws: MlpWorkspace,
    inputs: Vec<f32>,
    targets: Vec<f32>,
    d_out: Vec<f32>,
    d_input: Vec<f32>,
    actor_grads: Vec<f32>,
    critic_grads: Vec<f32>,
    priorities: Vec<f32>,
}

impl<R: Rng> Td3<R> {
    /// A learner for observations of `obs_dim` values and actions in the box `[low, high]`, with its weights
    /// drawn from `rng` (actor first, then critic; the targets start as copies).
    ///
    /// # Panics
    /// If the box is empty or inverted, or the configuration has fewer than two heads or a zero batch (callers
    /// validate configurations first).
    pub fn new(config: Td3Config, obs_dim: usize, low: &[f32], high: &[f32], mut rng: R) -> Self {
        assert!(
            !low.is_empty() && low.len() == high.len() && low.iter().zip(high).all(|(l, h)| l < h),
            "an action box needs low < high in every dimension"
        );
        assert!(
            config.heads >= 2 && config.max_batch > 0,
            "TD3 needs two critic heads and a batch"
        );
        let act_dim = low.len();
        let layers = |input: usize, output: usize| {
            let mut sizes = vec![input];
            sizes.extend(&config.hidden);
            sizes.push(output);
            sizes
        };
        let actor = Mlp::new(&layers(obs_dim, act_dim), OutputActivation::Tanh, &mut rng);
        let critic = Mlp::new(
            &layers(obs_dim + act_dim, config.heads),
            OutputActivation::Linear,
            &mut rng,
        );
        let n = config.max_batch;
        Td3 {
            actor_opt: Adam::for_parameters(actor.parameters().len(), config.actor_lr),
            critic_opt: Adam::for_parameters(critic.parameters().len(), config.critic_lr),
            actor_ws: MlpWorkspace::new(&actor, n),
            critic_ws: MlpWorkspace::new(&critic, n),
            inputs: vec![0.0; n * (obs_dim + act_dim)],
            targets: vec![0.0; n],
            d_out: vec![0.0; n * config.heads.max(act_dim)],
            d_input: vec![0.0; n * (obs_dim + act_dim)],
            actor_grads: vec![0.0; actor.parameters().len()],
            critic_grads: vec![0.0; critic.parameters().len()],
            priorities: vec![0.0; n],
            actor_target: actor.clone(),
            critic_target: critic.clone(),
            actor,
            critic,
            obs_dim,
            low: low.to_vec(),
            high: high.to_vec(),
            rng,
            updates: 0,
            config,
        }
    }

    /// Action dimension.
    pub fn action_dim(&self) -> usize {
        self.low.len()
    }

    /// Number of critic updates so far.
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// The box's half-width of dimension `d`.
    fn half_width(&self, d: usize) -> f32 {
        0.5 * (self.high[d] - self.low[d])
    }

    /// Maps the actor's tanh outputs (in (-1, 1)) to the box, in place.
    fn to_box(&self, y: &mut [f32]) {
        let act_dim = self.action_dim();
        for (i, v) in y.iter_mut().enumerate() {
            let d = i % act_dim;
            *v = self.low[d] + (*v + 1.0) * self.half_width(d);
        }
    }

    /// The test-time action at `obs`: the actor's, without noise.
    pub fn test_action(&mut self, obs: &[f32], action: &mut [f32]) {
        let y = self.actor.forward(obs, 1, &mut self.actor_ws);
        action.copy_from_slice(y);
        self.to_box(action);
    }

    /// The behaviour action at `obs`: the actor's plus Gaussian exploration noise, clipped to the box.
    pub fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        self.test_action(obs, action);
        for (d, a) in action.iter_mut().enumerate() {
            let z: f32 = self.rng.sample(StandardNormal);
            let noisy = *a + z * self.config.exploration_noise * self.half_width(d);
            *a = noisy.clamp(self.low[d], self.high[d]);
        }
    }

    /// The critics' disagreement at `(obs, action)`: the standard deviation of the heads' values (the
    /// uncertainty a query rule can read). Draws no random number.
    pub fn critic_spread(&mut self, obs: &[f32], action: &[f32]) -> f32 {
        let input = &mut self.inputs[..self.obs_dim + action.len()];
        input[..self.obs_dim].copy_from_slice(obs);
        input[self.obs_dim..].copy_from_slice(action);
        let q = self.critic.forward(input, 1, &mut self.critic_ws);
        let mean = q.iter().sum::<f32>() / q.len() as f32;
        (q.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / q.len() as f32).sqrt()
    }

    /// Writes `[obs | action]` rows for the critic into `self.inputs`.
    fn critic_inputs(&mut self, obs: &[f32], actions: &[f32], batch: usize) {
        let (d, a) = (self.obs_dim, self.action_dim());
        for r in 0..batch {
            let row = &mut self.inputs[r * (d + a)..(r + 1) * (d + a)];
            row[..d].copy_from_slice(&obs[r * d..(r + 1) * d]);
            row[d..].copy_from_slice(&actions[r * a..(r + 1) * a]);
        }
    }

    /// One update from `batch`: the critics always, the actor and the targets every `policy_delay` updates.
    /// Returns what it measured and the new priority of each sample.
    ///
    /// # Panics
    /// If the batch is larger than the configured maximum or its vectors disagree in length.
    pub fn learn(&mut self, batch: &BoxBatch) -> (Td3Stats, &[f32]) {
        let n = batch.len();
        let (d, a, k) = (self.obs_dim, self.action_dim(), self.config.heads);
        assert!(n > 0 && n <= self.config.max_batch, "batch of {n} samples");
        assert!(
            batch.obs.len() == n * d
                && batch.next_obs.len() == n * d
                && batch.actions.len() == n * a
                && batch.discounts.len() == n
                && batch.weights.len() == n,
            "a batch's vectors disagree in length"
        );

        // The target: r + gamma^n * min(Q'_1, Q'_2)(s', pi'(s') + clipped noise).
        let mut next_actions = self
            .actor_target
            .forward(&batch.next_obs, n, &mut self.actor_ws)
            .to_vec();
        self.to_box(&mut next_actions);
        for (i, v) in next_actions.iter_mut().enumerate() {
            let dim = i % a;
            let scale = self.half_width(dim);
            let z: f32 = self.rng.sample(StandardNormal);
            let clip = self.config.noise_clip * scale;
            let noise = (z * self.config.target_noise * scale).clamp(-clip, clip);
            *v = (*v + noise).clamp(self.low[dim], self.high[dim]);
        }
        self.critic_inputs(&batch.next_obs, &next_actions, n);
        let q_next =
            self.critic_target
                .forward(&self.inputs[..n * (d + a)], n, &mut self.critic_ws);
        for r in 0..n {
            let pair = q_next[r * k].min(q_next[r * k + 1]);
            self.targets[r] = batch.rewards[r] + batch.discounts[r] * pair;
        }

        // The critics: weighted squared TD error of every head, averaged over the batch.
        self.critic_inputs(&batch.obs, &batch.actions, n);
        let q = self
            .critic
            .forward(&self.inputs[..n * (d + a)], n, &mut self.critic_ws);
        let mut loss = 0.0f32;
        let d_q = &mut self.d_out[..n * k];
        for r in 0..n {
            for h in 0..k {
                let error = q[r * k + h] - self.targets[r];
                loss += batch.weights[r] * error * error;
                d_q[r * k + h] = 2.0 * batch.weights[r] * error / n as f32;
            }
            self.priorities[r] = (q[r * k] - self.targets[r]).abs();
        }
        self.critic
            .backward(&mut self.critic_ws, d_q, &mut self.critic_grads, None);
        self.critic_opt
            .step_parameters(self.critic.parameters_mut(), &self.critic_grads);
        self.updates += 1;
        let mut stats = Td3Stats {
            critic_loss: loss / (n * k) as f32,
            actor_loss: None,
        };

        if self.updates.is_multiple_of(self.config.policy_delay) {
            stats.actor_loss = Some(self.update_actor(batch));
            self.actor_target.soft_update(&self.actor, self.config.tau);
            self.critic_target
                .soft_update(&self.critic, self.config.tau);
        }
        (stats, &self.priorities[..n])
    }

    /// The actor's step: ascend the mean over heads of `Q(s, pi(s))`; returns the loss `-mean Q`.
    fn update_actor(&mut self, batch: &BoxBatch) -> f32 {
        let loss = self.actor_gradient(&batch.obs, batch.len());
        self.actor_opt
            .step_parameters(self.actor.parameters_mut(), &self.actor_grads);
        loss
    }

    /// The loss `-mean over the batch and the heads of Q(s, pi(s))` at the `n` observations `obs`, and its
    /// gradient with respect to the actor's parameters in `self.actor_grads` (through the critic's input
    /// gradient and the box's scaling; the critic's own gradients are computed and dropped).
    fn actor_gradient(&mut self, obs: &[f32], n: usize) -> f32 {
        let (d, a, k) = (self.obs_dim, self.action_dim(), self.config.heads);
        let mut actions = self.actor.forward(obs, n, &mut self.actor_ws).to_vec();
        self.to_box(&mut actions);
        self.critic_inputs(obs, &actions, n);
        let q = self
            .critic
            .forward(&self.inputs[..n * (d + a)], n, &mut self.critic_ws);
        let loss = -q.iter().sum::<f32>() / (n * k) as f32;
        let d_q = &mut self.d_out[..n * k];
        d_q.fill(-1.0 / (n * k) as f32);
        let d_input = &mut self.d_input[..n * (d + a)];
        self.critic.backward(
            &mut self.critic_ws,
            d_q,
            &mut self.critic_grads,
            Some(d_input),
        );
        let half_widths: Vec<f32> = (0..a).map(|dim| self.half_width(dim)).collect();
        let d_y = &mut self.d_out[..n * a];
        for r in 0..n {
            for dim in 0..a {
                d_y[r * a + dim] = self.d_input[r * (d + a) + d + dim] * half_widths[dim];
            }
        }
        self.actor
            .backward(&mut self.actor_ws, d_y, &mut self.actor_grads, None);
        loss
    }
}

impl<R: Rng> Td3<R> {
    /// The learner's generator, for a caller's draws in sequence with the learner's own.
    pub fn rng(&mut self) -> &mut R {
        &mut self.rng
    }

    /// The actor network (the policy).
    pub fn actor(&self) -> &Mlp {
        &self.actor
    }
}

impl<R: Rng + Serialize + DeserializeOwned> Persist for Td3<R> {
    /// Writes everything that changes while TD3 learns and acts: the four networks, both optimisers, the
    /// generator and the update count. Buffers are left out: every use overwrites them.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.actor.save_state(&format!("{prefix}.actor"), state);
        self.actor_target
            .save_state(&format!("{prefix}.actor_target"), state);
        self.critic.save_state(&format!("{prefix}.critic"), state);
        self.critic_target
            .save_state(&format!("{prefix}.critic_target"), state);
        self.actor_opt
            .save_state(&format!("{prefix}.actor_adam"), state);
        self.critic_opt
            .save_state(&format!("{prefix}.critic_adam"), state);
        state.put_text(&format!("{prefix}.rng"), &self.rng);
        state.put_value(&format!("{prefix}.updates"), &self.updates);
    }

    /// Reads what [`Td3::save_state`] wrote into a learner of the same configuration.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.actor.load_state(&format!("{prefix}.actor"), state)?;
        self.actor_target
            .load_state(&format!("{prefix}.actor_target"), state)?;
        self.critic.load_state(&format!("{prefix}.critic"), state)?;
        self.critic_target
            .load_state(&format!("{prefix}.critic_target"), state)?;
        self.actor_opt
            .load_state(&format!("{prefix}.actor_adam"), state)?;
        self.critic_opt
            .load_state(&format!("{prefix}.critic_adam"), state)?;
        self.rng = state.text(&format!("{prefix}.rng"))?;
        self.updates = state.value(&format!("{prefix}.updates"))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::{Env, make_continuous};
    use rand::SeedableRng;

    /// A minimal uniform replay of one-step transitions for the learning test.
    #[derive(Default)]
    struct Replay {
        obs: Vec<Vec<f32>>,
        actions: Vec<Vec<f32>>,
        rewards: Vec<f32>,
        next_obs: Vec<Vec<f32>>,
        discounts: Vec<f32>,
    }

    fn evaluate(agent: &mut Td3<rand_pcg::Pcg64>, seeds: std::ops::Range<u64>) -> f64 {
        let mut env = make_continuous("Pendulum-v1").unwrap();
        let mut obs = vec![0.0; 3];
        let mut action = vec![0.0; 1];
        let episodes = seeds.end - seeds.start;
        let mut total = 0.0;
        for seed in seeds {
            env.reset_into(Some(seed), &mut obs);
            loop {
                agent.test_action(&obs, &mut action);
                let out = env.step_into(&action, &mut obs).unwrap();
                total += out.reward;
                if out.terminated || out.truncated {
                    break;
                }
            }
        }
        total / episodes as f64
    }

    #[test]
    fn td3_learns_pendulum() {
        // 64-64 networks, batch 128, 12,000 steps (the first 1,000 uniformly random), one update a step; the
        // greedy policy must then hold Pendulum-v1 above -200 on ten evaluation seeds it never trained on.
        let config = Td3Config {
            hidden: vec![64, 64],
            max_batch: 128,
            ..Td3Config::default()
        };
        let mut agent = Td3::new(
            config,
            3,
            &[-2.0],
            &[2.0],
            rand_pcg::Pcg64::seed_from_u64(0),
        );
        let mut env = make_continuous("Pendulum-v1").unwrap();
        let mut draw = rand_pcg::Pcg64::seed_from_u64(1);
        let mut replay = Replay::default();
        let mut obs = vec![0.0; 3];
        let mut action = vec![0.0; 1];
        let mut batch = BoxBatch::default();
        env.reset_into(Some(0), &mut obs);
        for step in 0..12_000 {
            if step < 1_000 {
                action[0] = draw.random_range(-2.0..2.0);
            } else {
                agent.act(&obs, &mut action);
            }
            let before = obs.clone();
            let out = env.step_into(&action, &mut obs).unwrap();
            replay.obs.push(before);
            replay.actions.push(action.clone());
            replay.rewards.push(out.reward as f32);
            replay.next_obs.push(obs.clone());
            replay
                .discounts
                .push(if out.terminated { 0.0 } else { 0.99 });
            if out.terminated || out.truncated {
                env.reset_into(None, &mut obs);
            }
            if step >= 1_000 {
                batch = BoxBatch {
                    weights: vec![1.0; 128],
                    ..std::mem::take(&mut batch)
                };
                batch.obs.clear();
                batch.actions.clear();
                batch.rewards.clear();
                batch.next_obs.clear();
                batch.discounts.clear();
                for _ in 0..128 {
                    let i = draw.random_range(0..replay.rewards.len());
                    batch.obs.extend(&replay.obs[i]);
                    batch.actions.extend(&replay.actions[i]);
                    batch.rewards.push(replay.rewards[i]);
                    batch.next_obs.extend(&replay.next_obs[i]);
                    batch.discounts.push(replay.discounts[i]);
                }
                agent.learn(&batch);
            }
        }
        let score = evaluate(&mut agent, 1000..1010);
        eprintln!(
            "TD3 on Pendulum-v1 after 12,000 steps: mean return {score:.1} on seeds 1000-1009"
        );
        assert!(score > -200.0, "TD3 did not learn Pendulum-v1: {score}");
    }

    #[test]
    fn the_actor_gradient_matches_finite_differences_of_the_mean_q() {
        // d(-mean Q(s, pi(s)))/d(theta), from the critic's input gradient through the box's scaling, against
        // central differences of the same loss computed by forward passes alone, in a box that is neither
        // centred nor symmetric.
        let config = Td3Config {
            hidden: vec![8, 8],
            heads: 3,
            max_batch: 4,
            ..Td3Config::default()
        };
        let mut agent = Td3::new(
            config,
            2,
            &[-1.0, 0.0],
            &[3.0, 0.5],
            rand_pcg::Pcg64::seed_from_u64(5),
        );
        let obs: Vec<f32> = vec![0.3, -0.2, 1.0, 0.5, -0.7, 0.1];
        agent.actor_gradient(&obs, 3);
        let grads = agent.actor_grads.clone();
        let loss = |agent: &mut Td3<rand_pcg::Pcg64>| -> f64 {
            let mut total = 0.0f64;
            let mut ws = MlpWorkspace::new(&agent.critic, 1);
            for state in obs.chunks(2) {
                let mut action = vec![0.0; 2];
                agent.test_action(state, &mut action);
                let mut input = state.to_vec();
                input.extend(&action);
                total += agent
                    .critic
                    .forward(&input, 1, &mut ws)
                    .iter()
                    .map(|q| f64::from(*q))
                    .sum::<f64>();
            }
            -total / 9.0
        };
        let h = 1e-2f32;
        for (i, analytic) in grads.iter().enumerate() {
            let original = agent.actor.parameters()[i];
            agent.actor.parameters_mut()[i] = original + h;
            let up = loss(&mut agent);
            agent.actor.parameters_mut()[i] = original - h;
            let down = loss(&mut agent);
            agent.actor.parameters_mut()[i] = original;
            let numeric = (up - down) / (2.0 * f64::from(h));
            assert!(
                (f64::from(*analytic) - numeric).abs() < 2e-3 * numeric.abs().max(0.1),
                "actor parameter {i}: {analytic} vs {numeric}"
            );
        }
    }
}
