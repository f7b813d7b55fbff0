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

pub use super::actor_critic::BcStats;
use super::actor_critic::{ActionBox, ActorCritic, ActorCriticLearner, BoxUpdate, Net, Sizes};
use crate::nn::{Mlp, OutputActivation};
use crate::replay::Batch;
use crate::state::{Persist, StateDict, StateError};
use rand_pcg::Pcg64;

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
    /// The largest batch an update (`learn`) accepts.
    pub max_batch: usize,
    /// Weight of the behaviour cloning loss on demonstrated samples (with the Q-filter; 0 turns it off).
    pub bc_weight: f32,
    /// Whether the cloning loss keeps only the demonstrated samples whose action the critics value above the
    /// actor's (the Q-filter); without it every demonstrated sample counts (pre-training on demonstrations
    /// alone needs that: there the critics overvalue the actor's unseen actions).
    pub q_filter: bool,
    /// Added to the priority of a demonstrated sample (DDPGfD's `eps_D`).
    pub demo_priority_bonus: f32,
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
            bc_weight: 0.0,
            q_filter: true,
            demo_priority_bonus: 0.0,
        }
    }
}

/// The TD3 learner: actor, critics, their targets and optimisers, and the buffers of an update.
pub struct Td3<R: Rng> {
    config: Td3Config,
    /// The box, the actor, the critics (with their target), the generator and the per-sample buffers.
    ac: ActorCritic<R>,
    actor_target: Mlp,
    // Buffers, sized for `max_batch`.
    /// Actions (in the box), the actor's tanh outputs and their loss gradient, `max_batch * dim(A)`.
    actions: Vec<f32>,
    y: Vec<f32>,
    d_y: Vec<f32>,
}

impl<R: Rng> Td3<R> {
    /// A learner for observations of `obs_dim` values and actions in the box `[low, high]`, with its weights
    /// drawn from `rng` (actor first, then critic; the targets start as copies).
    ///
    /// # Panics
    /// If the box is empty or inverted, or the configuration has fewer than two heads or a zero batch (callers
    /// validate configurations first).
    pub fn new(config: Td3Config, obs_dim: usize, low: &[f32], high: &[f32], rng: R) -> Self {
        let action_box = ActionBox::new(low, high);
        assert!(
            config.heads >= 2 && config.max_batch > 0,
            "TD3 needs two critic heads and a batch"
        );
        let (act_dim, n) = (low.len(), config.max_batch);
        let sizes = Sizes {
            obs_dim,
            hidden: &config.hidden,
            max_batch: n,
        };
        let actor = (1, OutputActivation::Tanh, config.actor_lr);
        let critics = (config.heads, config.critic_lr);
        let ac = ActorCritic::new(&sizes, action_box, actor, critics, rng);
        Td3 {
            actions: vec![0.0; n * act_dim],
            y: vec![0.0; n * act_dim],
            d_y: vec![0.0; n * act_dim],
            actor_target: ac.actor.net.clone(),
            ac,
            config,
        }
    }

    /// The critics' disagreement about the best action near the actor's at `obs`, in half-widths of the box
    /// (see `Critics::argmax_disagreement`; 0 when every head prefers the same probe). Draws no random number.
    pub fn action_disagreement(&mut self, obs: &[f32]) -> f32 {
        let a = self.ac.action_dim();
        let y = self.ac.actor.forward(obs, 1);
        self.y[..a].copy_from_slice(y);
        self.ac
            .critics
            .argmax_disagreement(obs, &self.y[..a], &self.ac.action_box)
    }

    /// The actor's loss at the batch's observations, `-mean over the batch and the heads of Q(s, pi(s))` plus the
    /// behaviour cloning term with the Q-filter on its demonstrated samples (the heads' mean compares the
    /// demonstrated action with the actor's), and its gradient with respect to the actor's parameters in
    /// `self.ac.actor.grads` (through the critic's input gradient and the box's scaling). Returns the Q part of
    /// the loss and the cloning term's measures.
    fn actor_gradient(&mut self, batch: &Batch<Vec<f32>>) -> (f32, Option<BcStats>) {
        let n = batch.len();
        let (d, a, k) = (self.ac.obs_dim, self.ac.action_dim(), self.config.heads);
        let cloning = self.config.bc_weight > 0.0 && batch.is_demo.contains(&true);
        let filtering = cloning && self.config.q_filter;
        if filtering {
            self.ac
                .value_demonstrations(batch, |q| q.iter().sum::<f32>() / k as f32);
        }
        let y = self.ac.actor.forward(&batch.obs, n);
        self.y[..n * a].copy_from_slice(y);
        let actions = &mut self.actions[..n * a];
        actions.copy_from_slice(y);
        self.ac.action_box.to_box(actions);
        let q = self
            .ac
            .critics
            .evaluate(Net::Online, &batch.obs, actions, n);
        let loss = -q.iter().sum::<f32>() / (n * k) as f32;
        if filtering {
            for r in 0..n {
                self.ac.q_pi[r] = q[r * k..(r + 1) * k].iter().sum::<f32>() / k as f32;
            }
        }
        self.ac.critics.d_q(n).fill(-1.0 / (n * k) as f32);
        let d_input = self.ac.critics.backward_to_actions(n);
        let d_y = &mut self.d_y[..n * a];
        for r in 0..n {
            for dim in 0..a {
                d_y[r * a + dim] = d_input[r * (d + a) + d + dim] * self.ac.action_box.half[dim];
            }
        }
        let bc = if cloning {
            let y = &self.y[..n * a];
            Some(
                self.ac
                    .behaviour_cloning(self.config.bc_weight, batch, filtering, y, d_y),
            )
        } else {
            None
        };
        self.ac.actor.backward(d_y);
        (loss, bc)
    }
}

impl ActorCriticLearner for Td3<Pcg64> {
    fn name(&self) -> &'static str {
        "td3"
    }

    /// The behaviour action at `obs`: the actor's plus Gaussian exploration noise, clipped to the box.
    fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        self.test_action(obs, action);
        let b = &self.ac.action_box;
        for (d, a) in action.iter_mut().enumerate() {
            let z: f32 = self.ac.rng.sample(StandardNormal);
            let noisy = *a + z * self.config.exploration_noise * b.half[d];
            *a = noisy.clamp(b.low[d], b.high[d]);
        }
    }

    /// The test-time action at `obs`: the actor's, without noise.
    fn test_action(&mut self, obs: &[f32], action: &mut [f32]) {
        let y = self.ac.actor.forward(obs, 1);
        action.copy_from_slice(y);
        self.ac.action_box.to_box(action);
    }

    /// One update from `batch`: the critics always, the actor and the targets every `policy_delay` updates.
    fn learn(&mut self, batch: &Batch<Vec<f32>>, gamma: f32) -> (BoxUpdate, &[f32]) {
        let (n, a) = self.ac.check(batch);

        // The target: r + gamma^n * min(Q'_1, Q'_2)(s', pi'(s') + clipped noise).
        let y = self
            .actor_target
            .forward(batch.bootstrap_obs(), n, &mut self.ac.actor.ws);
        let next_actions = &mut self.actions[..n * a];
        next_actions.copy_from_slice(y);
        self.ac.action_box.to_box(next_actions);
        let b = &self.ac.action_box;
        for (i, v) in next_actions.iter_mut().enumerate() {
            let dim = i % a;
            let scale = b.half[dim];
            let z: f32 = self.ac.rng.sample(StandardNormal);
            let clip = self.config.noise_clip * scale;
            let noise = (z * self.config.target_noise * scale).clamp(-clip, clip);
            *v = (*v + noise).clamp(b.low[dim], b.high[dim]);
        }
        // The critics: weighted squared TD error of every head, averaged over the batch.
        let bonus = self.config.demo_priority_bonus;
        let critic_loss = self.ac.critic_step(batch, gamma, next_actions, None, bonus);
        self.ac.updates += 1;
        let mut stats = BoxUpdate {
            critic_loss,
            actor_loss: None,
            entropy: None,
            bc: None,
        };

        if self.ac.updates.is_multiple_of(self.config.policy_delay) {
            let (actor_loss, bc) = self.actor_gradient(batch);
            self.ac.actor.step();
            stats.actor_loss = Some(actor_loss);
            stats.bc = bc;
            self.actor_target
                .soft_update(&self.ac.actor.net, self.config.tau);
            self.ac.critics.soft_update(self.config.tau);
        }
        (stats, &self.ac.priorities[..n])
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

    fn core(&self) -> &ActorCritic<Pcg64> {
        &self.ac
    }

    fn core_mut(&mut self) -> &mut ActorCritic<Pcg64> {
        &mut self.ac
    }

    fn set_q_filter(&mut self, on: bool) {
        self.config.q_filter = on;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::actor_critic::testing::{
        GAMMA, check_filter_counts, column, evaluate_pendulum, pretraining_imitates, train_pendulum,
    };
    use crate::nn::MlpWorkspace;
    use rand::SeedableRng;

    /// A learner for Pendulum-v1 (3 observations, one action in [-2, 2]) from `seed`.
    fn pendulum_agent(config: Td3Config, seed: u64) -> Td3<rand_pcg::Pcg64> {
        Td3::new(
            config,
            3,
            &[-2.0],
            &[2.0],
            rand_pcg::Pcg64::seed_from_u64(seed),
        )
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
        let mut agent = pendulum_agent(config, 0);
        train_pendulum(&mut agent, 12_000, 128);
        let score = evaluate_pendulum(&mut agent, 1000..1010);
        eprintln!(
            "TD3 on Pendulum-v1 after 12,000 steps: mean return {score:.1} on seeds 1000-1009"
        );
        assert!(score > -200.0, "TD3 did not learn Pendulum-v1: {score}");
    }

    #[test]
    fn pretraining_on_demonstrations_imitates_the_swing_up() {
        let config = Td3Config {
            hidden: vec![64, 64],
            max_batch: 128,
            bc_weight: 100.0,
            q_filter: false,
            ..Td3Config::default()
        };
        let mut agent = pendulum_agent(config, 3);
        pretraining_imitates(&mut agent, 2_000, "TD3");
    }

    #[test]
    fn the_actor_gradient_matches_finite_differences_of_the_mean_q() {
        // d(-mean Q(s, pi(s)))/d(theta), from the critic's input gradient through the box's scaling, against
        // central differences of the same loss computed by forward passes alone, in a box that is neither
        // centred nor symmetric.
        check_actor_gradient(0.0, &[]);
    }

    #[test]
    fn the_behaviour_cloning_gradient_with_the_q_filter_matches_finite_differences() {
        // The actor loss plus 0.7 / n * sum over demonstrated rows whose demonstrated action the critics value
        // above the actor's of |y - y_demo|^2: the Q-filter computed independently here, and both of its
        // outcomes present among the demonstrated rows.
        check_actor_gradient(0.7, &[true, true, false, true, true, true, false, true]);
    }

    /// Checks `actor_gradient` against central differences with the cloning weight `bc_weight` and the
    /// demonstration flags `is_demo` (one per row; empty for none).
    fn check_actor_gradient(bc_weight: f32, is_demo: &[bool]) {
        let config = Td3Config {
            hidden: vec![8, 8],
            heads: 3,
            max_batch: 8,
            bc_weight,
            ..Td3Config::default()
        };
        let (low, high) = ([-1.0f32, 0.0], [3.0f32, 0.5]);
        let mut agent = Td3::new(config, 2, &low, &high, rand_pcg::Pcg64::seed_from_u64(5));
        let mut draw = rand_pcg::Pcg64::seed_from_u64(6);
        let n = is_demo.len().max(3);
        let obs = (0..2 * n).map(|_| draw.random_range(-1.0..1.0)).collect();
        let actions: Vec<f32> = (0..n)
            .flat_map(|_| [draw.random_range(-1.0..3.0), draw.random_range(0.0..0.5)])
            .collect();
        let batch = Batch {
            idx: (0..n).collect(),
            obs,
            actions: column(2, &actions),
            rewards: vec![0.0; n],
            next_obs: vec![0.0; 2 * n],
            terminal: vec![false; n],
            weights: vec![1.0; n],
            is_demo: if is_demo.is_empty() {
                vec![false; n]
            } else {
                is_demo.to_vec()
            },
            ..Batch::default()
        };
        let (_, bc) = agent.actor_gradient(&batch);
        let grads = agent.ac.actor.grads.clone();
        // The Q-filter's outcome at the unperturbed parameters (a selection, not differentiated).
        let heads_mean =
            |agent: &Td3<rand_pcg::Pcg64>, state: &[f32], action: &[f32]| -> (f64, f64) {
                let mut ws = MlpWorkspace::new(&agent.ac.critics.net, 1);
                let mut input = state.to_vec();
                input.extend(action);
                let q = agent.ac.critics.net.forward(&input, 1, &mut ws);
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
        let loss = |agent: &mut Td3<rand_pcg::Pcg64>| -> f64 {
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
        let h = 1e-2f32;
        for (i, analytic) in grads.iter().enumerate() {
            let original = agent.ac.actor.net.parameters()[i];
            agent.ac.actor.net.parameters_mut()[i] = original + h;
            let up = loss(&mut agent);
            agent.ac.actor.net.parameters_mut()[i] = original - h;
            let down = loss(&mut agent);
            agent.ac.actor.net.parameters_mut()[i] = original;
            let numeric = (up - down) / (2.0 * f64::from(h));
            assert!(
                (f64::from(*analytic) - numeric).abs() < 2e-3 * numeric.abs().max(0.1),
                "actor parameter {i}: {analytic} vs {numeric}"
            );
        }
    }

    #[test]
    fn demonstrated_samples_get_the_priority_bonus_and_nothing_else_changes() {
        // Two learners from one seed, one with a bonus of 0.5: on a batch with demonstrations the priorities
        // differ by exactly the bonus on the demonstrated samples, and the updates are the same.
        let mut agents = [0.0, 0.5].map(|bonus| {
            Td3::new(
                Td3Config {
                    hidden: vec![8],
                    max_batch: 4,
                    demo_priority_bonus: bonus,
                    ..Td3Config::default()
                },
                1,
                &[-2.0],
                &[2.0],
                rand_pcg::Pcg64::seed_from_u64(9),
            )
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
            agents[0].ac.critics.net.parameters(),
            agents[1].ac.critics.net.parameters()
        );
    }
}
