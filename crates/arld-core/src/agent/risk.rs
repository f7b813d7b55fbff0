//! ThriftyDAgger's risk critic (Hoque, Balakrishna, Novoseller, Wilcox, Brown, Goldberg, CoRL 2021): `Q_R(s, a)`,
//! the chance that the agent's policy reaches the task's goal after taking `a` in `s`, discounted by how long it
//! takes, learned by temporal differences next to the critics of a learner of box actions. The risk a query rule
//! reads is `1 - Q_R(s, a)` (docs/algorithm.md §20). [`super::box_agent::BoxAgent`] holds one only when the run's
//! query rule reads the risk, so a run without it computes and stores nothing more.
//!
//! - Network: `[obs | action] -> 1` with the critics' hidden widths and ReLU, and a sigmoid output (as the
//!   authors' code), computed as `Q_R = (1 + tanh(z)) / 2`, so `Q_R` lies in (0, 1). It has its own Adam, a
//!   Polyak target, and initial weights from a generator of its own (seeded from the run's seed).
//! - Target of a transition `(s, a, r, s')`: 1 when it reached the goal ([`Goal::reached`]), 0 when it ended the
//!   episode otherwise, and `gamma Q_R'(s', pi(s'))` when the episode goes on (through a time limit too), with
//!   `pi(s')` the policy's test action and `Q_R'` the target network.
//! - Loss: `(1/n) sum_b w_b (Q_R(s_b, a_b) - y_b)^2`, `w_b` the replay's importance weights.
//!
//! Every buffer is sized once for the largest batch, so an update allocates nothing.

use rand::SeedableRng;
use rand_pcg::Pcg64;

use crate::nn::{Adam, Mlp, MlpWorkspace, OutputActivation};
use crate::replay::Batch;
use crate::state::{Persist, StateDict, StateError};
use crate::task::Goal;

/// A risk critic's settings.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RiskConfig {
    /// Hidden widths (the critics').
    pub hidden: Vec<usize>,
    pub lr: f32,
    /// The discount of the chance of reaching the goal.
    pub gamma: f32,
    /// Polyak averaging rate of the target network.
    pub tau: f32,
    /// The largest batch an update accepts.
    pub max_batch: usize,
    /// What reaching the task's goal looks like in a transition.
    pub goal: Goal,
}

/// The risk critic: its network, target, optimiser and the buffers of an update.
pub(crate) struct RiskCritic {
    config: RiskConfig,
    net: Mlp,
    target: Mlp,
    opt: Adam,
    ws: MlpWorkspace,
    obs_dim: usize,
    act_dim: usize,
    // Buffers, sized for `max_batch`.
    inputs: Vec<f32>,
    next_actions: Vec<f32>,
    targets: Vec<f32>,
    d_out: Vec<f32>,
    grads: Vec<f32>,
}

/// `Q_R` of the network's tanh output.
fn probability(y: f32) -> f32 {
    0.5 * (1.0 + y)
}

impl RiskCritic {
    /// A critic for observations of `obs_dim` values and actions of `act_dim`, its weights drawn from a generator
    /// seeded with `seed`.
    ///
    /// # Panics
    /// If the batch size is zero (callers validate configurations first).
    pub fn new(config: RiskConfig, obs_dim: usize, act_dim: usize, seed: u64) -> Self {
        assert!(config.max_batch > 0, "a risk critic needs a batch");
        let mut widths = vec![obs_dim + act_dim];
        widths.extend(&config.hidden);
        widths.push(1);
        let net = Mlp::new(
            &widths,
            OutputActivation::Tanh,
            &mut Pcg64::seed_from_u64(seed),
        );
        let n = config.max_batch;
        RiskCritic {
            opt: Adam::for_parameters(net.parameters().len(), config.lr),
            ws: MlpWorkspace::new(&net, n),
            inputs: vec![0.0; n * (obs_dim + act_dim)],
            next_actions: vec![0.0; n * act_dim],
            targets: vec![0.0; n],
            d_out: vec![0.0; n],
            grads: vec![0.0; net.parameters().len()],
            target: net.clone(),
            net,
            obs_dim,
            act_dim,
            config,
        }
    }

    /// `Q_R(obs, action)` of the online network: the (discounted) chance of reaching the goal.
    pub fn value(&mut self, obs: &[f32], action: &[f32]) -> f32 {
        let y = forward(
            &self.net,
            &mut self.ws,
            &mut self.inputs,
            (obs, action, self.obs_dim),
            1,
        );
        probability(y[0])
    }

    /// The risk of `action` at `obs`: `1 - Q_R(obs, action)`.
    pub fn risk(&mut self, obs: &[f32], action: &[f32]) -> f32 {
        1.0 - self.value(obs, action)
    }

    /// The TD target of each sample of `batch` (see the module docs), with `policy` writing the policy's test
    /// actions at the rows of the batch's next observations into the rows of its second argument (one batched
    /// pass of the policy, not one per sample).
    ///
    /// # Panics
    /// If the batch is larger than the configured maximum or its vectors disagree in length.
    pub fn targets(
        &mut self,
        batch: &Batch<Vec<f32>>,
        policy: &mut dyn FnMut(&[f32], &mut [f32]),
    ) -> &[f32] {
        let (n, d, a) = self.check(batch);
        policy(&batch.next_obs[..n * d], &mut self.next_actions[..n * a]);
        let y = forward(
            &self.target,
            &mut self.ws,
            &mut self.inputs,
            (&batch.next_obs, &self.next_actions[..n * a], d),
            n,
        );
        for (r, &next) in y.iter().enumerate() {
            let (reward, terminal) = (batch.rewards[r], batch.terminal[r]);
            self.targets[r] = if self.config.goal.reached(reward, terminal) {
                1.0
            } else if terminal {
                0.0
            } else {
                self.config.gamma * probability(next)
            };
        }
        &self.targets[..n]
    }

    /// The loss at `batch` towards the last [`Self::targets`], and its gradient in the parameters (kept for
    /// [`Self::update`]).
    fn loss_and_gradient(&mut self, batch: &Batch<Vec<f32>>) -> f32 {
        let n = batch.len();
        let y = forward(
            &self.net,
            &mut self.ws,
            &mut self.inputs,
            (&batch.obs, batch.actions.values(), self.obs_dim),
            n,
        );
        let mut loss = 0.0f32;
        for (r, &out) in y.iter().enumerate() {
            let error = probability(out) - self.targets[r];
            loss += batch.weights[r] * error * error;
            // dL/dQ = 2 w (Q - y) / n, and dQ/d(tanh) = 1/2.
            self.d_out[r] = batch.weights[r] * error / n as f32;
        }
        self.net
            .backward(&mut self.ws, &self.d_out[..n], &mut self.grads, None);
        loss / n as f32
    }

    /// One TD step on `batch` (`policy` as in [`Self::targets`]), then the target's Polyak step; returns the
    /// loss before the step.
    pub fn update(
        &mut self,
        batch: &Batch<Vec<f32>>,
        policy: &mut dyn FnMut(&[f32], &mut [f32]),
    ) -> f32 {
        self.targets(batch, policy);
        let loss = self.loss_and_gradient(batch);
        self.opt
            .step_parameters(self.net.parameters_mut(), &self.grads);
        self.target.soft_update(&self.net, self.config.tau);
        loss
    }

    /// Checks `batch` against the critic's shapes; returns its length and the observation and action widths.
    fn check(&self, batch: &Batch<Vec<f32>>) -> (usize, usize, usize) {
        let (n, d, a) = (batch.len(), self.obs_dim, self.act_dim);
        assert!(n > 0 && n <= self.config.max_batch, "batch of {n} samples");
        assert!(
            batch.obs.len() == n * d
                && batch.next_obs.len() == n * d
                && batch.actions.values().len() == n * a
                && batch.rewards.len() == n
                && batch.terminal.len() == n
                && batch.weights.len() == n,
            "a batch's vectors disagree in length"
        );
        (n, d, a)
    }
}

/// The tanh outputs of `net` at `n` rows of `[obs | action]` (`rows` = observations, actions, observation width),
/// assembled in `inputs`.
fn forward<'w>(
    net: &Mlp,
    ws: &'w mut MlpWorkspace,
    inputs: &mut [f32],
    (obs, actions, d): (&[f32], &[f32], usize),
    n: usize,
) -> &'w [f32] {
    let a = actions.len() / n;
    for r in 0..n {
        let row = &mut inputs[r * (d + a)..(r + 1) * (d + a)];
        row[..d].copy_from_slice(&obs[r * d..(r + 1) * d]);
        row[d..].copy_from_slice(&actions[r * a..(r + 1) * a]);
    }
    net.forward(&inputs[..n * (d + a)], n, ws)
}

impl Persist for RiskCritic {
    /// Writes the network, its target and its optimiser (buffers are left out).
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        for (part, net) in [("net", &self.net), ("target", &self.target)] {
            net.save_state(&format!("{prefix}.{part}"), state);
        }
        self.opt.save_state(&format!("{prefix}.adam"), state);
    }

    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        for (part, net) in [("net", &mut self.net), ("target", &mut self.target)] {
            net.load_state(&format!("{prefix}.{part}"), state)?;
        }
        self.opt.load_state(&format!("{prefix}.adam"), state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::actor_critic::testing::column;
    use rand::Rng;

    const GOAL: Goal = Goal::TerminalReward { min_reward: 50.0 };

    fn critic(hidden: &[usize], lr: f32, gamma: f32, tau: f32, max_batch: usize) -> RiskCritic {
        let config = RiskConfig {
            hidden: hidden.to_vec(),
            lr,
            gamma,
            tau,
            max_batch,
            goal: GOAL,
        };
        RiskCritic::new(config, 2, 1, 11)
    }

    /// A policy that depends on the state: `tanh(s_0 - s_1)`, at every row of two observations.
    fn policy(obs: &[f32], actions: &mut [f32]) {
        for (obs, action) in obs.chunks_exact(2).zip(actions) {
            *action = (obs[0] - obs[1]).tanh();
        }
    }

    /// `Q_R` of `net` at one row, from a forward pass of its own.
    fn q_of(net: &Mlp, obs: &[f32], action: &[f32]) -> f64 {
        let mut ws = MlpWorkspace::new(net, 1);
        let mut input = obs.to_vec();
        input.extend(action);
        0.5 * (1.0 + f64::from(net.forward(&input, 1, &mut ws)[0]))
    }

    /// Six transitions: the goal reached, the goal's reward without an end (not reached), a failed end, a time
    /// limit (not terminal: bootstraps) and two ordinary steps; importance weights not all 1.
    fn batch() -> Batch<Vec<f32>> {
        let mut draw = Pcg64::seed_from_u64(3);
        let n = 6;
        let mut values =
            |k: usize| -> Vec<f32> { (0..k).map(|_| draw.random_range(-1.0..1.0)).collect() };
        Batch {
            idx: (0..n).collect(),
            obs: values(2 * n),
            actions: column(1, &values(n)),
            rewards: vec![100.0, 100.0, -100.0, -0.1, 0.0, 3.0],
            next_obs: values(2 * n),
            terminal: vec![true, false, true, false, false, false],
            weights: vec![1.0, 0.5, 2.0, 1.0, 0.7, 1.0],
            is_demo: vec![false; n],
            ..Batch::default()
        }
    }

    #[test]
    fn the_target_is_one_at_the_goal_zero_at_another_end_and_the_discounted_value_of_the_policy_otherwise()
     {
        let mut risk = critic(&[8, 8], 1e-2, 0.9, 0.3, 8);
        let b = batch();
        // One update first, so that the online network and its target differ.
        risk.update(&b, &mut policy);
        assert_ne!(risk.net.parameters(), risk.target.parameters());
        let targets = risk.targets(&b, &mut policy).to_vec();
        assert_eq!(targets.len(), b.len());
        for (r, target) in targets.iter().enumerate() {
            let next = &b.next_obs[2 * r..2 * r + 2];
            let mut action = [0.0];
            policy(next, &mut action);
            let expected = match r {
                0 => 1.0,
                2 => 0.0,
                _ => 0.9 * q_of(&risk.target, next, &action),
            };
            assert!(
                (f64::from(*target) - expected).abs() < 1e-6,
                "sample {r}: {target} vs {expected}"
            );
        }
    }

    #[test]
    fn the_gradient_matches_central_differences_of_the_loss() {
        let mut risk = critic(&[6, 5], 1e-3, 0.95, 0.005, 8);
        let b = batch();
        let targets: Vec<f64> = risk
            .targets(&b, &mut policy)
            .iter()
            .map(|&t| f64::from(t))
            .collect();
        risk.loss_and_gradient(&b);
        let grads = risk.grads.clone();
        let loss = |net: &Mlp| -> f64 {
            let n = b.len();
            (0..n)
                .map(|r| {
                    let q = q_of(net, &b.obs[2 * r..2 * r + 2], &b.actions.values()[r..r + 1]);
                    f64::from(b.weights[r]) * (q - targets[r]).powi(2)
                })
                .sum::<f64>()
                / n as f64
        };
        // Central differences, one parameter at a time, of the loss computed by forward passes alone.
        let h = 1e-3f32;
        let numeric: Vec<f64> = (0..grads.len())
            .map(|i| {
                let at = |delta: f32| {
                    let mut net = risk.net.clone();
                    net.parameters_mut()[i] += delta;
                    loss(&net)
                };
                (at(h) - at(-h)) / (2.0 * f64::from(h))
            })
            .collect();
        for (i, (analytic, numeric)) in grads.iter().zip(&numeric).enumerate() {
            let error = (f64::from(*analytic) - numeric).abs();
            assert!(
                error < 2e-3 * numeric.abs().max(0.1),
                "parameter {i}: {analytic} vs {numeric}"
            );
        }
    }

    #[test]
    fn trained_on_a_chain_it_learns_the_chance_of_reaching_the_goal_found_by_value_iteration() {
        // A chain of states 1-5 (observation [s / 5, 0]). Action +1 moves right with probability 0.8 and left
        // with 0.2; action -1 moves left. Entering 6 reaches the goal (reward 100, terminal); entering 0 fails
        // (reward -100, terminal). The policy always takes +1. The fixed set holds each (state, action) with its
        // outcomes in proportion to their probabilities (+1: four right, one left; -1: one left).
        let gamma = 0.9f32;
        let obs = |s: usize| [s as f32 / 5.0, 0.0];
        let mut set: Vec<(usize, f32, usize)> = Vec::new();
        for s in 1..=5 {
            set.extend(std::iter::repeat_n((s, 1.0, s + 1), 4));
            set.push((s, 1.0, s - 1));
            set.push((s, -1.0, s - 1));
        }
        // Value iteration for V(s) = Q(s, +1) under the policy.
        let outcome = |v: &[f64; 7], next: usize| match next {
            6 => 1.0,
            0 => 0.0,
            _ => f64::from(gamma) * v[next],
        };
        let mut v = [0.0f64; 7];
        for _ in 0..500 {
            let old = v;
            for (s, value) in v.iter_mut().enumerate().take(6).skip(1) {
                *value = 0.8 * outcome(&old, s + 1) + 0.2 * outcome(&old, s - 1);
            }
        }
        let expected = |s: usize, a: f32| if a > 0.0 { v[s] } else { outcome(&v, s - 1) };

        let mut risk = critic(&[32, 32], 3e-3, gamma, 0.05, 64);
        let mut always_right = |_: &[f32], actions: &mut [f32]| actions.fill(1.0);
        let mut draw = Pcg64::seed_from_u64(4);
        for _ in 0..4000 {
            let mut b = Batch::default();
            let mut actions = Vec::new();
            for i in 0..64 {
                let (s, a, next) = set[draw.random_range(0..set.len())];
                b.idx.push(i);
                b.obs.extend(obs(s));
                actions.push(a);
                b.next_obs.extend(obs(next.clamp(1, 5)));
                b.rewards.push(match next {
                    6 => 100.0,
                    0 => -100.0,
                    _ => 0.0,
                });
                b.terminal.push(next == 0 || next == 6);
                b.weights.push(1.0);
                b.is_demo.push(false);
            }
            b.actions = column(1, &actions);
            risk.update(&b, &mut always_right);
        }
        for s in 1..=5 {
            for a in [1.0f32, -1.0] {
                let learned = risk.value(&obs(s), &[a]);
                let truth = expected(s, a);
                assert!(
                    (f64::from(learned) - truth).abs() < 0.03,
                    "Q_R({s}, {a}) = {learned}, value iteration {truth:.4}"
                );
                assert!((risk.risk(&obs(s), &[a]) - (1.0 - learned)).abs() < 1e-7);
            }
        }
    }
}
