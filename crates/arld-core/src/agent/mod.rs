//! The agent: acting (ε-greedy over one bootstrapped head or a noise sample), learning (double-DQN TD loss plus
//! the large-margin loss on demonstrations, Adam) and the test-time policy (majority vote or mean weights).
//!
//! One [`DqnAgent`] owns the online and target networks, the optimiser, and every buffer an update needs, so a
//! steady-state step allocates nothing. Losses follow docs/algorithm.md §2–§5:
//! `L = Σ_k mean_b w_b [ℓ(δ_kb) + λ·demo_b·L_E,kb]` with
//! `δ_kb = Q_k(s_b, a_b) − (r_b + γ(1 − d_b) Q⁻_k(s'_b, argmax_a Q_k(s'_b, a)))` and
//! `L_E = max_a [Q(s, a) + M·1(a ≠ a_E)] − Q(s, a_E)`.

pub mod actor_critic;
pub mod actor_file;
pub mod algo;
pub mod box_agent;
mod learner;
pub mod risk;
pub mod sac;
pub mod td3;

pub use algo::Algo;
pub use learner::Learner;

use crate::nn::{
    Adam, Grads, HiddenLayers, NoiseSample, OutputKind, QNet, Workspace, argmax, clip_grad_norm,
};
use crate::query::{Needs, Signals, head_variance, js_divergence, noisy_variance, q_gap};
use crate::replay::Batch;
use crate::state::{Persist, StateDict, StateError};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde::{Deserialize, Serialize};

/// The TD loss (docs/algorithm.md §2: squared error by default, Huber as an option).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TdLoss {
    Mse,
    Huber,
}

/// Everything an [`DqnAgent`] needs to know: its network's output stage and its learning settings. A run builds
/// it from its configuration (`TrainConfig::dqn_agent_config`); an agent can be built and tested without one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DqnAgentConfig {
    /// Plain, K bootstrapped heads, or noisy output.
    pub output: OutputKind,
    /// Widths of the hidden layers, 1 to [`crate::nn::MAX_DEPTH`] of them (the paper's: 64 and 64).
    pub hidden: HiddenLayers,
    /// Minibatch size the update buffers are sized for.
    pub batch_size: usize,
    /// Adam learning rate.
    pub lr: f32,
    /// Discount factor γ.
    pub gamma: f32,
    pub loss: TdLoss,
    /// Double DQN's target (online argmax, target value); false: the target network's maximum.
    pub double_q: bool,
    /// Global gradient-norm clip.
    pub grad_clip: f32,
    /// Large-margin loss margin M and its weight λ.
    pub margin: f32,
    pub lambda: f32,
    /// Weight of DQfD's n-step TD loss (0: off).
    pub lambda_n: f32,
    /// L2 regularisation weight.
    pub l2: f32,
    /// Exact factorised-noise variance instead of the paper's formula.
    pub exact_factorised_var: bool,
}

/// What one gradient update measured (means over the batch, summed over heads).
#[derive(Clone, Copy, Debug, Default)]
pub struct UpdateStats {
    pub td_loss: f32,
    pub margin_loss: f32,
    pub nstep_loss: f32,
    pub grad_norm: f32,
}

/// A DQN-family agent with a plain, bootstrapped or noisy output stage.
pub struct DqnAgent {
    online: QNet,
    target: QNet,
    adam: Adam,
    grads: Grads,
    q_act: Vec<f32>,
    /// The features `phi(s)` of the last acting pass (the last hidden layer's width).
    phi: Vec<f32>,
    ws_batch: Workspace,
    ws_next_online: Workspace,
    ws_next_target: Workspace,
    /// Workspaces of the n-step targets (used only when `lambda_n > 0`).
    ws_nstep_online: Workspace,
    ws_nstep_target: Workspace,
    /// The workspace of the batched test-time forward, grown to the largest batch of observations asked.
    ws_test: Workspace,
    /// Independent noise samples for acting, the online Q(s, ·), the double-Q argmax and the target (§5).
    noise_act: NoiseSample,
    noise_online: NoiseSample,
    noise_argmax: NoiseSample,
    noise_target: NoiseSample,
    active_head: usize,
    rng: Pcg64,
    dq: Vec<f32>,
    abs_td: Vec<f32>,
    gamma: f32,
    loss: TdLoss,
    double_q: bool,
    grad_clip: f32,
    margin: f32,
    lambda: f32,
    exact_factorised_var: bool,
    l2: f32,
    lambda_n: f32,
}

impl DqnAgent {
    /// A freshly initialised agent for an environment with `obs_dim` inputs and `n_actions` actions.
    pub fn new(cfg: &DqnAgentConfig, obs_dim: usize, n_actions: usize, seed: u64) -> Self {
        let mut rng = Pcg64::seed_from_u64(seed);
        let online = QNet::with_hidden(obs_dim, n_actions, cfg.output, &cfg.hidden, &mut rng);
        Self::from_network(cfg, online, rng)
    }

    /// An agent that starts from given online weights (for example a loaded checkpoint).
    pub fn from_network(cfg: &DqnAgentConfig, online: QNet, mut rng: Pcg64) -> Self {
        let target = online.clone();
        let n_actions = online.n_actions();
        let features = online.features_len();
        let batch = cfg.batch_size;
        let mut noise = || {
            let mut n = NoiseSample::with_inputs(features, n_actions);
            n.resample(&mut rng);
            n
        };
        let (noise_act, noise_online, noise_argmax, noise_target) =
            (noise(), noise(), noise(), noise());
        let heads = online.heads();
        Self {
            adam: Adam::new(&online, cfg.lr),
            grads: Grads::new(&online),
            q_act: vec![0.0; heads * n_actions],
            phi: vec![0.0; features],
            ws_batch: Workspace::new(&online, batch),
            ws_next_online: Workspace::new(&online, batch),
            ws_next_target: Workspace::new(&online, batch),
            ws_nstep_online: Workspace::new(&online, if cfg.lambda_n > 0.0 { batch } else { 1 }),
            ws_nstep_target: Workspace::new(&online, if cfg.lambda_n > 0.0 { batch } else { 1 }),
            ws_test: Workspace::new(&online, 0),
            noise_act,
            noise_online,
            noise_argmax,
            noise_target,
            active_head: 0,
            dq: vec![0.0; heads * batch * n_actions],
            abs_td: vec![0.0; batch],
            gamma: cfg.gamma,
            loss: cfg.loss,
            double_q: cfg.double_q,
            grad_clip: cfg.grad_clip,
            margin: cfg.margin,
            lambda: cfg.lambda,
            exact_factorised_var: cfg.exact_factorised_var,
            l2: cfg.l2,
            lambda_n: cfg.lambda_n,
            online,
            target,
            rng,
        }
    }

    /// The online network.
    pub fn network(&self) -> &QNet {
        &self.online
    }

    /// The target network (a copy of the online one at its last target copy).
    pub fn target_network(&self) -> &QNet {
        &self.target
    }

    /// Bootstrapped acting samples one head uniformly at the start of every episode [BS].
    pub fn begin_episode(&mut self) {
        if self.online.heads() > 1 {
            self.active_head = self.rng.random_range(0..self.online.heads());
        }
    }

    /// The behaviour policy: greedy under the active head (or the current noise sample), ε-greedy on top.
    /// Also returns the signals `want` asks for (§7 and docs/algorithm.md section 14): the uncertainty (the
    /// Jensen–Shannon divergence of the heads' softmax policies, or the predictive variance of the noisy layer
    /// for the greedy action), the variance of the heads' Q-values, and the active head's Q-gap. None of them
    /// draws a random number: what is computed does not change the run.
    pub fn act(&mut self, obs: &[f32], epsilon: f64, want: Needs) -> (usize, Signals) {
        let a = self.online.n_actions();
        let heads = self.online.heads();
        let noise = matches!(self.online.kind(), OutputKind::Noisy).then_some(&self.noise_act);
        self.online
            .q_values_single_with_features(obs, noise, &mut self.q_act, &mut self.phi);
        let q = &self.q_act;
        let active = &q[self.active_head * a..(self.active_head + 1) * a];
        let greedy = argmax(active);
        let uncertainty = if want.uncertainty {
            match self.online.kind() {
                OutputKind::Bootstrap { .. } => Some(js_divergence(q, heads, a)),
                OutputKind::Noisy => {
                    let (sigma_w, sigma_b) = self
                        .online
                        .noisy_sigmas()
                        .expect("noisy network has sigmas");
                    Some(noisy_variance(
                        &self.phi,
                        &sigma_w[greedy * self.phi.len()..(greedy + 1) * self.phi.len()],
                        sigma_b[greedy],
                        self.exact_factorised_var,
                    ))
                }
                OutputKind::Plain => None,
            }
        } else {
            None
        };
        let signals = Signals {
            uncertainty,
            head_variance: (want.head_variance && heads > 1).then(|| head_variance(q, heads, a)),
            q_gap: want.q_gap.then(|| q_gap(active)),
            risk: None,
            greedy,
        };
        let action = if epsilon > 0.0 && self.rng.random::<f64>() < epsilon {
            self.rng.random_range(0..a)
        } else {
            greedy
        };
        (action, signals)
    }

    /// The test-time policy, without exploration (§5): see [`test_policy_action`].
    pub fn act_greedy(&mut self, obs: &[f32]) -> usize {
        test_policy_action(&self.online, &mut self.q_act, obs)
    }

    /// One gradient step on a minibatch; returns its statistics and the new priorities of the batch's samples
    /// (|δ| per sample, mean over heads), to hand to [`crate::replay::Replay::update_priorities`].
    pub fn update(&mut self, batch: &Batch) -> (UpdateStats, &[f32]) {
        let b = batch.actions.len();
        let a = self.online.n_actions();
        let heads = self.online.heads();
        let noisy = matches!(self.online.kind(), OutputKind::Noisy);
        let q = self.online.forward(
            &batch.obs,
            b,
            noisy.then_some(&self.noise_online),
            &mut self.ws_batch,
        );
        let next_noise = noisy.then_some((&self.noise_argmax, &self.noise_target));
        let (qn_online, qn_target) = next_state_q(
            self.double_q,
            [&self.online, &self.target],
            &batch.next_obs,
            b,
            next_noise,
            [&mut self.ws_next_online, &mut self.ws_next_target],
        );
        let nstep = (self.lambda_n > 0.0).then(|| {
            next_state_q(
                self.double_q,
                [&self.online, &self.target],
                &batch.nstep_next_obs,
                b,
                next_noise,
                [&mut self.ws_nstep_online, &mut self.ws_nstep_target],
            )
        });
        let losses = LossParams {
            gamma: self.gamma,
            loss: self.loss,
            margin: self.margin,
            lambda: self.lambda,
            lambda_n: self.lambda_n,
        };
        let (td_loss, margin_loss, nstep_loss) = double_dqn_loss(
            &losses,
            batch,
            Heads {
                q,
                qn_online,
                qn_target,
                nstep,
                heads,
                n_actions: a,
            },
            &mut self.dq[..heads * b * a],
            &mut self.abs_td[..b],
        );
        self.online.backward(
            &mut self.ws_batch,
            &self.dq[..heads * b * a],
            &mut self.grads,
        );
        if self.l2 > 0.0 {
            add_l2_gradient(self.online.parameters(), &mut self.grads.data, self.l2);
        }
        let grad_norm = clip_grad_norm(&mut self.grads, self.grad_clip);
        self.adam.step(&mut self.online, &self.grads);
        if noisy {
            // New noise after every optimisation step, independent for each use (§5, [NN]).
            for n in [
                &mut self.noise_act,
                &mut self.noise_online,
                &mut self.noise_argmax,
                &mut self.noise_target,
            ] {
                n.resample(&mut self.rng);
            }
        }
        let stats = UpdateStats {
            td_loss,
            margin_loss,
            nstep_loss,
            grad_norm,
        };
        (stats, &self.abs_td[..b])
    }

    /// Hard copy of the online weights into the target network.
    pub(crate) fn sync_target(&mut self) {
        self.target.copy_from(&self.online);
    }

    /// The agent's own generator (ε draws, head sampling, noise), for callers that need a draw in sequence.
    pub fn rng(&mut self) -> &mut Pcg64 {
        &mut self.rng
    }
}

/// The DQN family as a [`Learner`]: the methods above, and the batched test-time policy
/// (`test_policy_actions`).
impl Learner for DqnAgent {
    type Action = usize;

    fn begin_episode(&mut self) {
        DqnAgent::begin_episode(self);
    }

    fn act(&mut self, obs: &[f32], epsilon: f64, want: Needs) -> (usize, Signals) {
        DqnAgent::act(self, obs, epsilon, want)
    }

    fn learn(&mut self, batch: &Batch) -> (UpdateStats, &[f32]) {
        self.update(batch)
    }

    fn end_target_period(&mut self) {
        self.sync_target();
    }

    fn test_actions(&mut self, obs: &[f32], actions: &mut Vec<usize>) {
        actions.resize(obs.len() / self.online.obs_dim(), 0);
        if self.ws_test.max_batch() < actions.len() {
            self.ws_test = Workspace::new(&self.online, actions.len());
        }
        test_policy_actions(&self.online, &mut self.ws_test, obs, actions);
    }

    fn save_weights(
        &self,
        path: &std::path::Path,
        metadata: &std::collections::BTreeMap<String, String>,
    ) -> anyhow::Result<()> {
        self.online.save(path, metadata)
    }
}

impl Persist for DqnAgent {
    /// Writes everything that changes while the agent learns and acts (online and target weights, Adam's
    /// moments and step, the generator, the active head, the noise samples) into `state` under `prefix`.
    /// Scratch buffers are left out: every use overwrites them.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.online.save_state(&format!("{prefix}.online"), state);
        self.target.save_state(&format!("{prefix}.target"), state);
        self.adam.save_state(&format!("{prefix}.adam"), state);
        state.put_text(&format!("{prefix}.rng"), &self.rng);
        state.put_value(&format!("{prefix}.active_head"), &self.active_head);
        for (name, noise) in [
            ("act", &self.noise_act),
            ("online", &self.noise_online),
            ("argmax", &self.noise_argmax),
            ("target", &self.noise_target),
        ] {
            noise.save_state(&format!("{prefix}.noise_{name}"), state);
        }
    }

    /// Reads what [`DqnAgent::save_state`] wrote into an agent built with the same configuration.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.online.load_state(&format!("{prefix}.online"), state)?;
        self.target.load_state(&format!("{prefix}.target"), state)?;
        self.adam.load_state(&format!("{prefix}.adam"), state)?;
        self.rng = state.text(&format!("{prefix}.rng"))?;
        let active_head: usize = state.value(&format!("{prefix}.active_head"))?;
        if active_head >= self.online.heads() {
            return Err(StateError::Value {
                name: format!("{prefix}.active_head"),
                msg: format!(
                    "head {active_head}, but the network has {} heads",
                    self.online.heads()
                ),
            });
        }
        self.active_head = active_head;
        for (name, noise) in [
            ("act", &mut self.noise_act),
            ("online", &mut self.noise_online),
            ("argmax", &mut self.noise_argmax),
            ("target", &mut self.noise_target),
        ] {
            noise.load_state(&format!("{prefix}.noise_{name}"), state)?;
        }
        Ok(())
    }
}

/// The forward passes over next states (`b` rows of `obs`) that the TD target needs: the Q-values that pick the
/// action and those that value it, each network with its own noise sample when noisy, each into its own
/// workspace. Double DQN (`double`): the online network picks, the target network values. Otherwise the target
/// network does both (its maximum), and the online pass is skipped.
fn next_state_q<'w>(
    double: bool,
    [online, target]: [&QNet; 2],
    obs: &[f32],
    b: usize,
    noise: Option<(&NoiseSample, &NoiseSample)>,
    [ws_online, ws_target]: [&'w mut Workspace; 2],
) -> (&'w [f32], &'w [f32]) {
    let (online_noise, target_noise) = noise.unzip();
    let values = target.forward(obs, b, target_noise, ws_target);
    if !double {
        return (values, values);
    }
    (online.forward(obs, b, online_noise, ws_online), values)
}

/// The test-time policy of a network, without exploration (docs/algorithm.md §5): a majority vote over the
/// bootstrapped heads with ties broken by the mean Q-value, the noise-free mean weights of a noisy layer, or
/// plain argmax. Also the policy of a checkpoint expert.
/// `q` is a buffer of `heads * n_actions` values.
pub fn test_policy_action(net: &QNet, q: &mut [f32], obs: &[f32]) -> usize {
    let a = net.n_actions();
    net.q_values_single(obs, None, q);
    vote(net.heads(), |k| &q[k * a..(k + 1) * a])
}

/// [`test_policy_action`] for `actions.len()` states at once (`obs` row-major), with one batched forward in
/// `ws` (built for `net`, for at least that many rows). The forward computes every row exactly as the single
/// state's forward does, so the actions are the same as [`test_policy_action`]'s one by one.
pub(crate) fn test_policy_actions(
    net: &QNet,
    ws: &mut Workspace,
    obs: &[f32],
    actions: &mut [usize],
) {
    let (n, a) = (actions.len(), net.n_actions());
    let q = net.forward(obs, n, None, ws);
    for (row, action) in actions.iter_mut().enumerate() {
        *action = vote(net.heads(), |k| {
            &q[(k * n + row) * a..(k * n + row + 1) * a]
        });
    }
}

/// The majority vote of [`test_policy_action`] over `heads` rows of Q-values (`head(k)` is head k's row).
fn vote<'q>(heads: usize, head: impl Fn(usize) -> &'q [f32]) -> usize {
    if heads == 1 {
        return argmax(head(0));
    }
    let a = head(0).len();
    const MAX_ACTIONS: usize = 32;
    assert!(
        a <= MAX_ACTIONS,
        "at most {MAX_ACTIONS} actions are supported"
    );
    let mut votes = [0u32; MAX_ACTIONS];
    let mut mean = [0f32; MAX_ACTIONS];
    for k in 0..heads {
        let row = head(k);
        votes[argmax(row)] += 1;
        for (m, v) in mean.iter_mut().zip(row) {
            *m += v;
        }
    }
    let top = votes[..a].iter().copied().max().unwrap_or(0);
    let mut best = 0;
    let mut best_q = f32::NEG_INFINITY;
    for i in 0..a {
        if votes[i] == top && mean[i] > best_q {
            best = i;
            best_q = mean[i];
        }
    }
    best
}

/// Adds the gradient of the L2 regulariser `l2 · ‖θ‖²` (DQfD's λ3 term; 0 in the paper) to `grads`.
pub(crate) fn add_l2_gradient(params: &[f32], grads: &mut [f32], l2: f32) {
    for (g, &p) in grads.iter_mut().zip(params) {
        *g += 2.0 * l2 * p;
    }
}

/// The constants of the loss.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LossParams {
    pub gamma: f32,
    pub loss: TdLoss,
    pub margin: f32,
    pub lambda: f32,
    /// Weight of the n-step TD loss (DQfD's λ1; 0 in the paper).
    pub lambda_n: f32,
}

/// Network outputs for a batch, each laid out `[head][batch][action]`: Q(s, ·) under the online network,
/// Q(s', ·) under the online network (for the double-Q argmax) and under the target network.
pub(crate) struct Heads<'a> {
    pub q: &'a [f32],
    pub qn_online: &'a [f32],
    pub qn_target: &'a [f32],
    /// Q(s_{t+n}, ·) under the online and the target network, when the n-step loss is on.
    pub nstep: Option<(&'a [f32], &'a [f32])>,
    pub heads: usize,
    pub n_actions: usize,
}

/// The loss of one minibatch and its gradient with respect to Q(s, ·) (docs/algorithm.md §2, §4):
/// `L = Σ_k (1/B) Σ_b w_b [ℓ(δ_kb) + λ·demo_b·L_E,kb]`, with double-DQN targets
/// `y_kb = r_b + γ(1 − d_b) Q⁻_k(s'_b, argmax_a Q_k(s'_b, a))` held constant. Writes `dL/dQ` into `dq` and the
/// new priorities `mean_k |δ_kb|` into `abs_td`; returns the TD, margin and n-step parts of `L` (the n-step
/// part, `λ1·ℓ(Q(s, a) − R_n − γ^n Q⁻(s_n, argmax Q(s_n)))`, only when `h.nstep` is given).
pub(crate) fn double_dqn_loss(
    p: &LossParams,
    batch: &Batch,
    h: Heads<'_>,
    dq: &mut [f32],
    abs_td: &mut [f32],
) -> (f32, f32, f32) {
    let b = batch.actions.len();
    let a = h.n_actions;
    dq.iter_mut().for_each(|g| *g = 0.0);
    abs_td.iter_mut().for_each(|x| *x = 0.0);
    let mut td_loss = 0.0f32;
    let mut margin_loss = 0.0f32;
    let mut nstep_loss = 0.0f32;
    let inv_b = 1.0 / b as f32;
    let td = |delta: f32| match p.loss {
        TdLoss::Mse => (delta * delta, 2.0 * delta),
        TdLoss::Huber if delta.abs() <= 1.0 => (0.5 * delta * delta, delta),
        TdLoss::Huber => (delta.abs() - 0.5, delta.signum()),
    };
    for k in 0..h.heads {
        for (i, abs_td_i) in abs_td.iter_mut().enumerate().take(b) {
            let row = (k * b + i) * a;
            let qs = &h.q[row..row + a];
            let next_a = argmax(&h.qn_online[row..row + a]);
            let not_done = if batch.terminal[i] { 0.0 } else { 1.0 };
            let y = batch.rewards[i] + p.gamma * not_done * h.qn_target[row + next_a];
            let act = batch.actions[i];
            let delta = qs[act] - y;
            let w = batch.weights[i] * inv_b;
            let (l, g) = td(delta);
            td_loss += w * l;
            dq[row + act] += w * g;
            if let Some((qo, qt)) = h.nstep {
                let na = argmax(&qo[row..row + a]);
                let y_n = batch.nstep_rewards[i] + batch.nstep_discounts[i] * qt[row + na];
                let (l, g) = td(qs[act] - y_n);
                nstep_loss += w * l;
                dq[row + act] += p.lambda_n * w * g;
            }
            *abs_td_i += delta.abs() / h.heads as f32;
            if batch.is_demo[i] && p.lambda > 0.0 {
                // Large-margin loss (§4): the expert's action must beat every other action by M.
                let (m, a_max) = margin_term(qs, act, p.margin);
                margin_loss += w * m;
                dq[row + a_max] += p.lambda * w;
                dq[row + act] -= p.lambda * w;
            }
        }
    }
    (td_loss, margin_loss, nstep_loss)
}

/// `max_a [q(a) + M·1(a ≠ a_E)] − q(a_E)` and the maximising action.
pub(crate) fn margin_term(q: &[f32], expert_action: usize, margin: f32) -> (f32, usize) {
    let mut best = f32::NEG_INFINITY;
    let mut best_a = expert_action;
    for (i, &v) in q.iter().enumerate() {
        let v = if i == expert_action { v } else { v + margin };
        if v > best {
            best = v;
            best_a = i;
        }
    }
    (best - q[expert_action], best_a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn margin_loss_matches_hand_computation() {
        // Q = (1.0, 0.5, 0.9), expert action 0, M = 0.8:
        // max(1.0, 0.5 + 0.8, 0.9 + 0.8) - 1.0 = 1.7 - 1.0 = 0.7, attained at action 2.
        let (m, a) = margin_term(&[1.0, 0.5, 0.9], 0, 0.8);
        assert!((m - 0.7).abs() < 1e-6);
        assert_eq!(a, 2);
        // When the expert's action already wins by the margin the loss is zero and the gradient cancels.
        let (m, a) = margin_term(&[3.0, 0.5, 0.9], 0, 0.8);
        assert_eq!((m, a), (0.0, 0));
    }

    fn batch_of(
        actions: Vec<usize>,
        rewards: Vec<f32>,
        terminal: Vec<bool>,
        is_demo: Vec<bool>,
    ) -> Batch {
        let n = actions.len();
        Batch {
            idx: (0..n).collect(),
            weights: (0..n).map(|i| 1.0 - 0.1 * i as f32).collect(),
            actions,
            rewards,
            terminal,
            is_demo,
            ..Batch::default()
        }
    }

    /// The analytic dL/dQ of the whole minibatch loss agrees with central finite differences, for both losses,
    /// several heads, terminal and demonstration samples, with and without the n-step term.
    #[test]
    fn loss_gradient_matches_finite_differences() {
        let (heads, b, a) = (3, 4, 3);
        let mut batch = batch_of(
            vec![0, 2, 1, 2],
            vec![1.0, -0.5, 0.0, 2.0],
            vec![false, true, false, false],
            vec![true, false, true, false],
        );
        batch.nstep_rewards = vec![2.5, -0.5, 1.0, 3.0];
        batch.nstep_discounts = vec![0.7, 0.0, 0.5, 0.9];
        // Q-values spread over a few levels: ((i * step) mod levels - shift) * scale.
        let pattern = |step: usize, levels: usize, shift: f32, scale: f32| -> Vec<f32> {
            (0..heads * b * a)
                .map(|i| ((i * step % levels) as f32 - shift) * scale)
                .collect()
        };
        let q = pattern(37, 11, 5.0, 0.3);
        let qn_online = pattern(17, 7, 3.0, 0.5);
        let qn_target = pattern(13, 5, 2.0, 0.7);
        let qn_online_n = pattern(7, 9, 4.0, 0.4);
        let qn_target_n = pattern(11, 13, 6.0, 0.2);
        for (loss, lambda_n) in [
            (TdLoss::Mse, 0.0),
            (TdLoss::Huber, 0.0),
            (TdLoss::Mse, 0.7),
            (TdLoss::Huber, 1.0),
        ] {
            let nstep = (lambda_n > 0.0).then_some((&qn_online_n[..], &qn_target_n[..]));
            let p = LossParams {
                gamma: 0.9,
                loss,
                margin: 0.8,
                lambda: 0.5,
                lambda_n,
            };
            let total = |q: &[f32]| -> f64 {
                let mut dq = vec![0.0; q.len()];
                let mut abs_td = vec![0.0; b];
                let h = Heads {
                    q,
                    qn_online: &qn_online,
                    qn_target: &qn_target,
                    nstep,
                    heads,
                    n_actions: a,
                };
                let (td, m, n) = double_dqn_loss(&p, &batch, h, &mut dq, &mut abs_td);
                td as f64 + p.lambda as f64 * m as f64 + p.lambda_n as f64 * n as f64
            };
            let mut dq = vec![0.0; q.len()];
            let mut abs_td = vec![0.0; b];
            let h = Heads {
                q: &q,
                qn_online: &qn_online,
                qn_target: &qn_target,
                nstep,
                heads,
                n_actions: a,
            };
            double_dqn_loss(&p, &batch, h, &mut dq, &mut abs_td);
            for i in 0..q.len() {
                let eps = 1e-3;
                let (mut plus, mut minus) = (q.clone(), q.clone());
                plus[i] += eps;
                minus[i] -= eps;
                let fd = (total(&plus) - total(&minus)) / (2.0 * eps as f64);
                assert!(
                    (fd - dq[i] as f64).abs() < 2e-3,
                    "{loss:?} lambda_n {lambda_n} dq[{i}]: analytic {} vs numeric {fd}",
                    dq[i]
                );
            }
        }
    }

    #[test]
    fn l2_gradient_matches_finite_differences() {
        let params = [0.5f32, -1.25, 2.0, 0.0];
        let l2 = 1e-2;
        let mut grads = [0.1f32, 0.0, -0.2, 0.3];
        add_l2_gradient(&params, &mut grads, l2);
        let reg = |p: &[f32]| l2 as f64 * p.iter().map(|&x| (x as f64).powi(2)).sum::<f64>();
        for i in 0..params.len() {
            let (mut plus, mut minus) = (params, params);
            plus[i] += 1e-3;
            minus[i] -= 1e-3;
            let fd = (reg(&plus) - reg(&minus)) / 2e-3;
            let base = [0.1f32, 0.0, -0.2, 0.3][i] as f64;
            assert!((grads[i] as f64 - base - fd).abs() < 1e-5, "param {i}");
        }
    }

    #[test]
    fn td_target_uses_online_argmax_and_target_value() {
        // One head, one sample: online next-state Q picks action 1, target Q of action 1 is 2.0.
        let batch = batch_of(vec![0], vec![1.0], vec![false], vec![false]);
        let p = LossParams {
            gamma: 0.5,
            loss: TdLoss::Mse,
            margin: 0.8,
            lambda: 0.0,
            lambda_n: 0.0,
        };
        let (q, qn_online, qn_target) = ([3.0f32, 0.0], [0.0f32, 1.0], [10.0f32, 2.0]);
        let (mut dq, mut abs_td) = ([0.0f32; 2], [0.0f32; 1]);
        let h = Heads {
            q: &q,
            qn_online: &qn_online,
            qn_target: &qn_target,
            nstep: None,
            heads: 1,
            n_actions: 2,
        };
        let (td, _, _) = double_dqn_loss(&p, &batch, h, &mut dq, &mut abs_td);
        // y = 1 + 0.5 * 2 = 2; delta = 3 - 2 = 1.
        assert!((td - 1.0).abs() < 1e-6 && (abs_td[0] - 1.0).abs() < 1e-6);
        assert!((dq[0] - 2.0).abs() < 1e-6 && dq[1] == 0.0);
    }
    /// The TD error of an update against an independent recomputation from single-state Q-values: with
    /// `double_q` the online network picks the next action and the target network values it; without, the target
    /// network's maximum.
    #[test]
    fn the_td_target_follows_double_q() {
        let (d, a, b, gamma) = (3, 4, 4, 0.9f32);
        let obs: Vec<f32> = (0..b * d).map(|i| (i as f32 * 0.37).sin()).collect();
        let next_obs: Vec<f32> = (0..b * d).map(|i| (i as f32 * 0.53).cos() * 2.0).collect();
        let mut differ = false;
        for double_q in [false, true] {
            let cfg = DqnAgentConfig {
                output: OutputKind::Plain,
                hidden: HiddenLayers::new(&[crate::nn::HIDDEN; 2]).unwrap(),
                batch_size: b,
                lr: 1e-3,
                gamma,
                loss: TdLoss::Mse,
                double_q,
                grad_clip: 10.0,
                margin: 0.8,
                lambda: 0.0,
                lambda_n: 0.0,
                l2: 0.0,
                exact_factorised_var: false,
            };
            let mut agent = DqnAgent::new(&cfg, d, a, 7);
            agent.target = QNet::new(d, a, OutputKind::Plain, &mut Pcg64::seed_from_u64(99));
            let mut batch = batch_of(
                vec![0, 1, 2, 3],
                vec![1.0, -0.5, 0.25, 2.0],
                vec![false; b],
                vec![false; b],
            );
            batch.obs = obs.clone();
            batch.next_obs = next_obs.clone();
            let mut expected = Vec::new();
            for i in 0..b {
                let (mut q, mut q_online, mut q_target) = ([0.0f32; 4], [0.0f32; 4], [0.0f32; 4]);
                let rows = i * d..(i + 1) * d;
                agent
                    .online
                    .q_values_single(&obs[rows.clone()], None, &mut q);
                agent
                    .online
                    .q_values_single(&next_obs[rows.clone()], None, &mut q_online);
                agent
                    .target
                    .q_values_single(&next_obs[rows], None, &mut q_target);
                let picked = q_target[argmax(&q_online)];
                let maximum = q_target.iter().copied().fold(f32::MIN, f32::max);
                differ |= picked != maximum;
                let next = if double_q { picked } else { maximum };
                expected.push((q[batch.actions[i]] - (batch.rewards[i] + gamma * next)).abs());
            }
            let (_, abs_td) = agent.update(&batch);
            for (got, want) in abs_td.iter().zip(&expected) {
                assert!(
                    (got - want).abs() < 1e-5,
                    "double_q = {double_q}: |delta| {got} vs {want}"
                );
            }
        }
        assert!(differ, "the case must tell the two targets apart");
    }
}
