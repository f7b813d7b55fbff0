//! What the actor-critic learners for actions in a box (TD3 in `td3.rs`, SAC in `sac.rs`) share: the interface a
//! run drives them through (`ActorCriticLearner`; they learn from the replay's batches, [`Batch`]) and what an
//! update measures (`BoxUpdate`); the one learner behind it ([`BoxLearner`]: the shared core and an
//! `Algorithm`'s own part, TD3's or SAC's); the settings both have ([`ActorCriticConfig`]); what both hold
//! (`ActorCritic`: the settings, the box, the actor, the critics, the generator and the per-sample buffers,
//! with the critics' regression towards the clipped double-Q target), the sizes their networks are built to
//! (`Sizes`), the actor with its optimiser and buffers (`Actor`), the box itself (`ActionBox`: the map
//! between a tanh output in (-1, 1) and an action), the critic ensemble with its target and optimiser
//! (`Critics`: K heads on a shared torso, the regression step that returns priorities, the gradient with
//! respect to the action, and the two uncertainties read from its heads), and the behaviour cloning loss with
//! the Q-filter on demonstrated samples (`behaviour_cloning`; Nair et al. 2018).
//!
//! Every buffer is sized once for the largest batch, so an update allocates nothing.

use rand::Rng;
use rand_pcg::Pcg64;

use crate::nn::{Adam, Mlp, MlpWorkspace, OutputActivation};
use crate::replay::Batch;
use crate::state::{Persist, StateDict, StateError};

/// What a run needs of an actor-critic learner of box actions (TD3, SAC): acting, learning from a batch, the
/// critics' disagreement, its generator, its policy network and its state. [`BoxLearner`] is the one
/// implementation, for every [`Algorithm`].
pub(crate) trait ActorCriticLearner: Send {
    /// The behaviour action at `obs` (with the learner's own exploration), into `action`.
    fn act(&mut self, obs: &[f32], action: &mut [f32]);
    /// The test-time actions (no exploration) at the rows of `obs`, into the rows of `actions` (any number of
    /// rows; each row's action is the one a single-row call gives, bit for bit).
    fn test_action(&mut self, obs: &[f32], actions: &mut [f32]);
    /// One update from `batch` (its targets discounted by `gamma` per step, [`Batch::discount`]): what it
    /// measured and the new priority of each sample.
    ///
    /// # Panics
    /// If the batch is larger than the configured maximum or its vectors disagree in length.
    fn learn(&mut self, batch: &Batch<Vec<f32>>, gamma: f32) -> (BoxUpdate, &[f32]);
    /// Turns the cloning loss's Q-filter on or off (pre-training on demonstrations alone clones without it).
    fn set_q_filter(&mut self, on: bool);
    /// The standard deviation of the critic heads at `(obs, action)` (the uncertainty a query rule can read).
    /// Draws no random number.
    fn critic_spread(&mut self, obs: &[f32], action: &[f32]) -> f32;
    /// The critic heads' disagreement about the best action near the test action at `obs`
    /// ([`BoxLearner::disagreement`]; the other uncertainty a query rule can read). Draws no random number.
    fn action_disagreement(&mut self, obs: &[f32]) -> f32;
    /// The learner's generator, for a caller's draws in sequence with the learner's own.
    fn rng(&mut self) -> &mut Pcg64;
    /// The policy network a run keeps (TD3: the tanh actor; SAC: the means and log standard deviations of its
    /// Gaussian).
    fn actor(&self) -> &Mlp;
    /// Writes everything that changes while the learner learns and acts. Buffers are left out: every use
    /// overwrites them.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>);
    /// Reads what [`Self::save_state`] wrote into a learner of the same configuration.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError>;
}

/// The shared core of every actor-critic learner the run drives.
pub(crate) type Core = ActorCritic<Pcg64>;

/// What an actor-critic algorithm (TD3, SAC) adds to the shared [`Core`]: its acting, its update and its state
/// beyond the core. Every method is handed the core it works on.
pub(crate) trait Algorithm: Send {
    /// The behaviour action at `obs` (with the algorithm's own exploration), into `action`.
    fn act(&mut self, core: &mut Core, obs: &[f32], action: &mut [f32]);
    /// The test-time actions (no exploration) at the rows of `obs` as the tanh outputs the box scales, into the
    /// rows of `units`: one batched forward pass of the actor, at most its workspace's batch of rows.
    fn test_units(&self, core: &mut Core, obs: &[f32], units: &mut [f32]);
    /// One update from `batch`: what it measured; the new priorities are left in the core's `priorities`.
    fn learn(&mut self, core: &mut Core, batch: &Batch<Vec<f32>>, gamma: f32) -> BoxUpdate;
    /// Writes what the algorithm holds beyond the core under `prefix`.
    fn save_own<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>);
    /// Reads what [`Self::save_own`] wrote.
    fn load_own(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError>;
}

/// An actor-critic learner of actions in a box: the shared core (the box, the actor, the critics, the generator,
/// the shared settings and buffers) and the algorithm's own part `A` (TD3: [`super::td3::Td3Part`]; SAC:
/// [`super::sac::SacPart`]).
pub struct BoxLearner<A> {
    pub(crate) core: Core,
    pub(crate) algo: A,
    /// The test action's tanh output at one state, the centre of [`Self::disagreement`]'s probes.
    centre: Vec<f32>,
}

impl<A> BoxLearner<A> {
    /// The learner of `core` and `algo`.
    pub(crate) fn from_parts(core: Core, algo: A) -> Self {
        let centre = vec![0.0; core.action_dim()];
        BoxLearner { core, algo, centre }
    }

    /// The critics' disagreement about the best action near the test action at `obs`, in half-widths of the box
    /// (see `Critics::argmax_disagreement`; 0 when every head prefers the same probe). Draws no random number.
    pub(crate) fn disagreement(&mut self, obs: &[f32]) -> f32
    where
        A: Algorithm,
    {
        self.algo.test_units(&mut self.core, obs, &mut self.centre);
        let core = &mut self.core;
        core.critics
            .argmax_disagreement(obs, &self.centre, &core.action_box)
    }
}

impl<A: Algorithm> ActorCriticLearner for BoxLearner<A> {
    fn act(&mut self, obs: &[f32], action: &mut [f32]) {
        self.algo.act(&mut self.core, obs, action);
    }

    fn test_action(&mut self, obs: &[f32], actions: &mut [f32]) {
        let (d, a) = (self.core.obs_dim, self.core.action_dim());
        let rows = self.core.actor.ws.max_batch();
        for (obs, actions) in obs.chunks(rows * d).zip(actions.chunks_mut(rows * a)) {
            self.algo.test_units(&mut self.core, obs, actions);
        }
        self.core.action_box.to_box(actions);
    }

    fn learn(&mut self, batch: &Batch<Vec<f32>>, gamma: f32) -> (BoxUpdate, &[f32]) {
        let stats = self.algo.learn(&mut self.core, batch, gamma);
        (stats, &self.core.priorities[..batch.len()])
    }

    fn set_q_filter(&mut self, on: bool) {
        self.core.config.q_filter = on;
    }

    fn critic_spread(&mut self, obs: &[f32], action: &[f32]) -> f32 {
        self.core.critics.spread(obs, action)
    }

    fn action_disagreement(&mut self, obs: &[f32]) -> f32 {
        self.disagreement(obs)
    }

    fn rng(&mut self) -> &mut Pcg64 {
        &mut self.core.rng
    }

    fn actor(&self) -> &Mlp {
        &self.core.actor.net
    }

    /// The core ([`ActorCritic`]'s state) and the algorithm's own.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.core.save_state(prefix, state);
        self.algo.save_own(prefix, state);
    }

    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.core.load_state(prefix, state)?;
        self.algo.load_own(prefix, state)
    }
}

/// What TD3's and SAC's settings share (each learner's configuration holds one as `common`).
#[derive(Debug, Clone, PartialEq)]
pub struct ActorCriticConfig {
    /// Hidden widths of the actor and of the critics' torso.
    pub hidden: Vec<usize>,
    /// Critic heads on the shared torso (at least 2: the clipped double-Q target takes the first two).
    pub heads: usize,
    /// Polyak averaging rate of the target networks.
    pub tau: f32,
    pub actor_lr: f32,
    pub critic_lr: f32,
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

impl ActorCriticConfig {
    /// The shared defaults with the learning rate `lr` for the actor and the critics: 256-256 networks, two
    /// heads, Polyak rate 0.005, batches of up to 256, no cloning (with the Q-filter when it is turned on) and
    /// no demonstration bonus.
    pub(crate) fn with_learning_rate(lr: f32) -> Self {
        ActorCriticConfig {
            hidden: vec![256, 256],
            heads: 2,
            tau: 0.005,
            actor_lr: lr,
            critic_lr: lr,
            max_batch: 256,
            bc_weight: 0.0,
            q_filter: true,
            demo_priority_bonus: 0.0,
        }
    }

    /// Whether an actor update on `batch` has a cloning term (the weight is positive and the batch holds
    /// demonstrations), and whether that term filters by the critics' values.
    pub(crate) fn cloning(&self, batch: &Batch<Vec<f32>>) -> (bool, bool) {
        let cloning = self.bc_weight > 0.0 && batch.is_demo.contains(&true);
        (cloning, cloning && self.q_filter)
    }
}

/// What one actor-critic update measured.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct BoxUpdate {
    /// Mean over the batch and the heads of the weighted squared TD error.
    pub critic_loss: f32,
    /// The actor's loss without the cloning term, when the actor moved in this update (TD3: `-mean Q` of its
    /// actions; SAC: `mean [alpha log pi - min(Q_1, Q_2)]` of its sampled actions).
    pub actor_loss: Option<f32>,
    /// SAC: `-mean log pi` of the actor's sampled actions, the policy's entropy estimate.
    pub entropy: Option<f32>,
    /// The behaviour cloning term, when the actor moved on a batch with demonstrations and it is on.
    pub bc: Option<BcStats>,
}

/// An action box `[low, high]` and the map from a tanh output `y` in (-1, 1) to an action,
/// `a = low + (y + 1) w` with `w = (high - low) / 2` the half-width.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ActionBox {
    pub low: Vec<f32>,
    pub high: Vec<f32>,
    pub half: Vec<f32>,
}

impl ActionBox {
    /// # Panics
    /// If the box is empty or inverted (callers validate the action space first).
    pub fn new(low: &[f32], high: &[f32]) -> Self {
        assert!(
            !low.is_empty() && low.len() == high.len() && low.iter().zip(high).all(|(l, h)| l < h),
            "an action box needs low < high in every dimension"
        );
        ActionBox {
            low: low.to_vec(),
            high: high.to_vec(),
            half: low.iter().zip(high).map(|(l, h)| 0.5 * (h - l)).collect(),
        }
    }

    /// Action dimension.
    pub fn dim(&self) -> usize {
        self.low.len()
    }

    /// Maps rows of tanh outputs to the box, in place.
    pub(crate) fn to_box(&self, y: &mut [f32]) {
        let dim = self.dim();
        for (i, v) in y.iter_mut().enumerate() {
            let d = i % dim;
            *v = self.low[d] + (*v + 1.0) * self.half[d];
        }
    }

    /// The tanh output of action value `a` in dimension `d` (the inverse of [`Self::to_box`]).
    pub(crate) fn to_unit(&self, a: f32, d: usize) -> f32 {
        (a - self.low[d]) / self.half[d] - 1.0
    }
}

/// What a learner's networks are built to: the observation length, the hidden widths (of the actor and of the
/// critics' torso) and the largest batch their buffers hold.
pub(crate) struct Sizes<'a> {
    pub obs_dim: usize,
    pub hidden: &'a [usize],
    pub max_batch: usize,
}

/// The actor network `obs -> outputs`, its Adam optimiser, its workspace and its parameter gradient.
pub(crate) struct Actor {
    pub net: Mlp,
    pub opt: Adam,
    pub ws: MlpWorkspace,
    pub grads: Vec<f32>,
}

impl Actor {
    /// An actor of `sizes` with `outputs` outputs through `activation`, its weights drawn from `rng`.
    pub fn new(
        sizes: &Sizes<'_>,
        outputs: usize,
        activation: OutputActivation,
        lr: f32,
        rng: &mut impl Rng,
    ) -> Self {
        let mut widths = vec![sizes.obs_dim];
        widths.extend(sizes.hidden);
        widths.push(outputs);
        let net = Mlp::new(&widths, activation, rng);
        Actor {
            opt: Adam::for_parameters(net.parameters().len(), lr),
            ws: MlpWorkspace::new(&net, sizes.max_batch),
            grads: vec![0.0; net.parameters().len()],
            net,
        }
    }

    /// The outputs at `n` rows of `obs`; the pass stays in the workspace for [`Self::backward`].
    pub fn forward(&mut self, obs: &[f32], n: usize) -> &[f32] {
        self.net.forward(obs, n, &mut self.ws)
    }

    /// The parameter gradient of the last [`Self::forward`] given the loss gradient `d_out` at its outputs.
    pub fn backward(&mut self, d_out: &[f32]) {
        self.net
            .backward(&mut self.ws, d_out, &mut self.grads, None);
    }

    /// One optimiser step along the last [`Self::backward`]'s gradient.
    pub fn step(&mut self) {
        self.opt
            .step_parameters(self.net.parameters_mut(), &self.grads);
    }
}

/// Which of the critics' networks to evaluate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Net {
    Online,
    Target,
}

/// The critic ensemble `Q(s, a) -> [Q_1 .. Q_K]` (one network, K linear heads on a shared torso), its Polyak
/// target, its Adam optimiser and its buffers.
pub(crate) struct Critics {
    pub net: Mlp,
    pub target: Mlp,
    opt: Adam,
    ws: MlpWorkspace,
    obs_dim: usize,
    act_dim: usize,
    heads: usize,
    inputs: Vec<f32>,
    d_q: Vec<f32>,
    d_input: Vec<f32>,
    grads: Vec<f32>,
}

impl Persist for Critics {
    /// Writes the critic network, its target and its optimiser (buffers are left out).
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.net.save_state(&format!("{prefix}.net"), state);
        self.target.save_state(&format!("{prefix}.target"), state);
        self.opt.save_state(&format!("{prefix}.adam"), state);
    }

    /// Reads what [`Critics::save_state`] wrote into critics of the same shape.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.net.load_state(&format!("{prefix}.net"), state)?;
        self.target.load_state(&format!("{prefix}.target"), state)?;
        self.opt.load_state(&format!("{prefix}.adam"), state)
    }
}

/// Offset of the probe actions of `Critics::argmax_disagreement` from the centre action, as a fraction of the
/// box's half-width.
pub const PROBE_OFFSET: f32 = 0.5;

impl Critics {
    /// Critics of `sizes` for actions of `act_dim` values, with `heads` heads, initialised from `rng`.
    pub fn new(
        sizes: &Sizes<'_>,
        act_dim: usize,
        heads: usize,
        lr: f32,
        rng: &mut impl Rng,
    ) -> Self {
        let (obs_dim, max_batch) = (sizes.obs_dim, sizes.max_batch);
        let mut widths = vec![obs_dim + act_dim];
        widths.extend(sizes.hidden);
        widths.push(heads);
        let net = Mlp::new(&widths, OutputActivation::Linear, rng);
        // The probes of `argmax_disagreement` are one batch too.
        let rows = max_batch.max(2 * act_dim + 1);
        Critics {
            opt: Adam::for_parameters(net.parameters().len(), lr),
            ws: MlpWorkspace::new(&net, rows),
            inputs: vec![0.0; rows * (obs_dim + act_dim)],
            d_q: vec![0.0; max_batch * heads],
            d_input: vec![0.0; (max_batch * (obs_dim + act_dim)).max(2 * rows * act_dim)],
            grads: vec![0.0; net.parameters().len()],
            target: net.clone(),
            net,
            obs_dim,
            act_dim,
            heads,
        }
    }

    /// The heads' values at `n` rows of `(obs, actions)`, `n * K` values row by row. The online network's pass
    /// stays in the workspace for [`Self::backward_to_actions`].
    pub fn evaluate(&mut self, net: Net, obs: &[f32], actions: &[f32], n: usize) -> &[f32] {
        self.fill_inputs(obs, actions, n);
        let (d, a) = (self.obs_dim, self.act_dim);
        let network = match net {
            Net::Online => &self.net,
            Net::Target => &self.target,
        };
        network.forward(&self.inputs[..n * (d + a)], n, &mut self.ws)
    }

    /// Writes `n` rows of `[obs | action]` into the input buffer.
    fn fill_inputs(&mut self, obs: &[f32], actions: &[f32], n: usize) {
        let (d, a) = (self.obs_dim, self.act_dim);
        for r in 0..n {
            let row = &mut self.inputs[r * (d + a)..(r + 1) * (d + a)];
            row[..d].copy_from_slice(&obs[r * d..(r + 1) * d]);
            row[d..].copy_from_slice(&actions[r * a..(r + 1) * a]);
        }
    }

    /// One regression step of every head on `targets` (`batch`'s weighted squared TD errors, averaged over the
    /// batch): writes each sample's new priority (the first head's absolute TD error, plus `demo_bonus` for a
    /// demonstrated sample) into `priorities` and returns the loss averaged over the batch and the heads.
    pub fn update(
        &mut self,
        batch: &Batch<Vec<f32>>,
        targets: &[f32],
        priorities: &mut [f32],
        demo_bonus: f32,
    ) -> f32 {
        let n = batch.len();
        let k = self.heads;
        self.fill_inputs(&batch.obs, batch.actions.values(), n);
        let width = self.obs_dim + self.act_dim;
        let q = self.net.forward(&self.inputs[..n * width], n, &mut self.ws);
        let mut loss = 0.0f32;
        let d_q = &mut self.d_q[..n * k];
        for r in 0..n {
            for h in 0..k {
                let error = q[r * k + h] - targets[r];
                loss += batch.weights[r] * error * error;
                d_q[r * k + h] = 2.0 * batch.weights[r] * error / n as f32;
            }
            priorities[r] = (q[r * k] - targets[r]).abs();
            if batch.is_demo[r] {
                priorities[r] += demo_bonus;
            }
        }
        self.net.backward(&mut self.ws, d_q, &mut self.grads, None);
        self.opt
            .step_parameters(self.net.parameters_mut(), &self.grads);
        loss / (n * k) as f32
    }

    /// The loss gradient with respect to the heads of the last online [`Self::evaluate`] of `n` rows, to fill
    /// before [`Self::backward_to_actions`].
    pub(crate) fn d_q(&mut self, n: usize) -> &mut [f32] {
        &mut self.d_q[..n * self.heads]
    }

    /// Back-propagates [`Self::d_q`] through the last online evaluation of `n` rows: returns the input gradient,
    /// rows of `obs_dim + act_dim` values whose last `act_dim` are `dL/da` (the critic's own parameter gradients
    /// are not computed: the update that follows changes only the actor).
    pub(crate) fn backward_to_actions(&mut self, n: usize) -> &[f32] {
        let width = self.obs_dim + self.act_dim;
        let d_input = &mut self.d_input[..n * width];
        self.net
            .backward_input(&mut self.ws, &self.d_q[..n * self.heads], d_input);
        d_input
    }

    /// Moves the target towards the online network by Polyak averaging.
    pub(crate) fn soft_update(&mut self, tau: f32) {
        self.target.soft_update(&self.net, tau);
    }

    /// The heads' disagreement at `(obs, action)`: the standard deviation of their values.
    pub fn spread(&mut self, obs: &[f32], action: &[f32]) -> f32 {
        let q = self.evaluate(Net::Online, obs, action, 1);
        let mean = q.iter().sum::<f32>() / q.len() as f32;
        (q.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / q.len() as f32).sqrt()
    }

    /// The heads' disagreement about which action is best near `centre` (a tanh output, one value per
    /// dimension): each head picks the best of `2 dim(A) + 1` probes (the centre, and the centre moved by
    /// `±PROBE_OFFSET` in each dimension, clipped to (-1, 1)); the result is the standard deviation over the heads
    /// of the picked probes, in half-widths, as the root of the mean over dimensions of the variance. 0 when the
    /// heads agree; at most 1. Draws no random number.
    pub fn argmax_disagreement(
        &mut self,
        obs: &[f32],
        centre: &[f32],
        action_box: &ActionBox,
    ) -> f32 {
        let a = self.act_dim;
        let probes = 2 * a + 1;
        // The probes' tanh outputs, then their actions, in `d_input`'s first rows (free outside an update).
        let (units, rest) = self.d_input.split_at_mut(probes * a);
        let actions = &mut rest[..probes * a];
        for p in 0..probes {
            let row = &mut units[p * a..(p + 1) * a];
            row.copy_from_slice(centre);
            if p > 0 {
                let (dim, sign) = ((p - 1) / 2, if p % 2 == 1 { 1.0 } else { -1.0 });
                row[dim] = (row[dim] + sign * PROBE_OFFSET).clamp(-1.0, 1.0);
            }
        }
        actions.copy_from_slice(units);
        action_box.to_box(actions);
        let (d, k) = (self.obs_dim, self.heads);
        for r in 0..probes {
            let row = &mut self.inputs[r * (d + a)..(r + 1) * (d + a)];
            row[..d].copy_from_slice(obs);
            row[d..].copy_from_slice(&actions[r * a..(r + 1) * a]);
        }
        let q = self
            .net
            .forward(&self.inputs[..probes * (d + a)], probes, &mut self.ws);
        let mut variance = 0.0f32;
        for dim in 0..a {
            let picked = |h: usize| {
                let best = (0..probes)
                    .max_by(|&x, &y| q[x * k + h].total_cmp(&q[y * k + h]).then(y.cmp(&x)))
                    .unwrap_or(0);
                units[best * a + dim]
            };
            let mean = (0..k).map(picked).sum::<f32>() / k as f32;
            variance += (0..k).map(|h| (picked(h) - mean).powi(2)).sum::<f32>() / k as f32;
        }
        (variance / a as f32).sqrt()
    }
}

/// What TD3 and SAC both hold: their shared settings, the observation length, the box, the actor, the critics,
/// the generator, the update count, and the per-sample buffers of an update (TD targets, the Q-filter's values,
/// the new priorities).
pub(crate) struct ActorCritic<R> {
    /// The settings TD3 and SAC share.
    pub config: ActorCriticConfig,
    pub obs_dim: usize,
    pub action_box: ActionBox,
    pub actor: Actor,
    pub critics: Critics,
    pub rng: R,
    pub updates: u64,
    pub targets: Vec<f32>,
    /// The critics' values of the demonstrated actions and of the actor's, for the Q-filter.
    pub q_demo: Vec<f32>,
    pub q_pi: Vec<f32>,
    pub priorities: Vec<f32>,
}

impl<R: serde::Serialize + serde::de::DeserializeOwned> Persist for ActorCritic<R> {
    /// Writes the actor and its optimiser, the critics (with their target and optimiser), the generator and
    /// the update count under `prefix` (the learner adds what is its own).
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        self.actor.net.save_state(&format!("{prefix}.actor"), state);
        self.actor
            .opt
            .save_state(&format!("{prefix}.actor_adam"), state);
        self.critics.save_state(&format!("{prefix}.critics"), state);
        state.put_text(&format!("{prefix}.rng"), &self.rng);
        state.put_value(&format!("{prefix}.updates"), &self.updates);
    }

    /// Reads what [`ActorCritic::save_state`] wrote.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.actor
            .net
            .load_state(&format!("{prefix}.actor"), state)?;
        self.actor
            .opt
            .load_state(&format!("{prefix}.actor_adam"), state)?;
        self.critics
            .load_state(&format!("{prefix}.critics"), state)?;
        self.rng = state.text(&format!("{prefix}.rng"))?;
        self.updates = state.value(&format!("{prefix}.updates"))?;
        Ok(())
    }
}

impl<R: Rng> ActorCritic<R> {
    /// The parts of a learner of `config` for observations of `obs_dim` values and actions in the box `[low,
    /// high]`, their weights drawn from `rng`, actor first: `actor` is its outputs per action dimension and their
    /// activation.
    ///
    /// # Panics
    /// If the box is empty or inverted, or the configuration has fewer than two heads or a zero batch (callers
    /// validate configurations first).
    pub fn new(
        config: ActorCriticConfig,
        obs_dim: usize,
        (low, high): (&[f32], &[f32]),
        (per_dim, activation): (usize, OutputActivation),
        mut rng: R,
    ) -> Self {
        let action_box = ActionBox::new(low, high);
        assert!(
            config.heads >= 2 && config.max_batch > 0,
            "an actor-critic learner needs two critic heads and a batch"
        );
        let (a, n) = (action_box.dim(), config.max_batch);
        let sizes = Sizes {
            obs_dim,
            hidden: &config.hidden,
            max_batch: n,
        };
        let actor = Actor::new(&sizes, per_dim * a, activation, config.actor_lr, &mut rng);
        let critics = Critics::new(&sizes, a, config.heads, config.critic_lr, &mut rng);
        ActorCritic {
            config,
            obs_dim,
            action_box,
            actor,
            critics,
            rng,
            updates: 0,
            targets: vec![0.0; n],
            q_demo: vec![0.0; n],
            q_pi: vec![0.0; n],
            priorities: vec![0.0; n],
        }
    }

    /// Action dimension.
    pub fn action_dim(&self) -> usize {
        self.action_box.dim()
    }

    /// Checks `batch` against the learner's shapes (the per-sample buffers hold the largest batch) and returns
    /// its length and the action dimension.
    ///
    /// # Panics
    /// If the batch is empty or larger than the buffers, or its vectors disagree in length (the replay builds
    /// batches; a mismatch is a bug, not an input error).
    pub fn check(&self, batch: &Batch<Vec<f32>>) -> (usize, usize) {
        let (n, d, a) = (batch.len(), self.obs_dim, self.action_dim());
        assert!(n > 0 && n <= self.priorities.len(), "batch of {n} samples");
        assert!(
            batch.obs.len() == n * d
                && batch.bootstrap_obs().len() == n * d
                && batch.actions.values().len() == n * a
                && batch.returns().len() == n
                && batch.terminal.len() == n
                && batch.weights.len() == n
                && batch.is_demo.len() == n,
            "a batch's vectors disagree in length"
        );
        (n, a)
    }

    /// One regression step of the critics ([`Critics::update`]) towards the clipped double-Q target
    /// `r + gamma^n (min(Q'_1, Q'_2)(s', a') - alpha log_probs)` at the next actions `next_actions` (`entropy`
    /// holds `(alpha, log_probs)`; without it the target has no entropy term), with `r`, `s'` and `gamma^n` of
    /// [`Batch::returns`]. Returns the loss; the new priorities are in `priorities`.
    pub(crate) fn critic_step(
        &mut self,
        batch: &Batch<Vec<f32>>,
        gamma: f32,
        next_actions: &[f32],
        entropy: Option<(f32, &[f32])>,
    ) -> f32 {
        let (n, k) = (batch.len(), self.critics.heads);
        let q_next = self
            .critics
            .evaluate(Net::Target, batch.bootstrap_obs(), next_actions, n);
        let returns = batch.returns();
        for r in 0..n {
            let pair = q_next[r * k].min(q_next[r * k + 1]);
            let soft = match entropy {
                Some((alpha, log_probs)) => pair - alpha * log_probs[r],
                None => pair,
            };
            self.targets[r] = returns[r] + batch.discount(r, gamma) * soft;
        }
        self.critics.update(
            batch,
            &self.targets[..n],
            &mut self.priorities[..n],
            self.config.demo_priority_bonus,
        )
    }

    /// The critics' value of each demonstrated action of `batch` (`value` aggregates a row of the heads), into
    /// `q_demo`, for the Q-filter.
    pub(crate) fn value_demonstrations(
        &mut self,
        batch: &Batch<Vec<f32>>,
        value: impl Fn(&[f32]) -> f32,
    ) {
        let (n, k) = (batch.len(), self.critics.heads);
        let q = self
            .critics
            .evaluate(Net::Online, &batch.obs, batch.actions.values(), n);
        for (r, v) in self.q_demo[..n].iter_mut().enumerate() {
            *v = value(&q[r * k..(r + 1) * k]);
        }
    }

    /// [`behaviour_cloning`] of the actor's tanh outputs `y` at `batch`, with the Q-filter of `q_demo` and
    /// `q_pi` when `filtering`.
    pub(crate) fn behaviour_cloning(
        &self,
        weight: f32,
        batch: &Batch<Vec<f32>>,
        filtering: bool,
        y: &[f32],
        d_y: &mut [f32],
    ) -> BcStats {
        let n = batch.len();
        let q_filter = filtering.then_some((&self.q_demo[..n], &self.q_pi[..n]));
        behaviour_cloning(weight, batch, q_filter, y, &self.action_box, d_y)
    }
}

/// What the behaviour cloning term measured in one actor update.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BcStats {
    /// The term's value (already multiplied by its weight).
    pub loss: f32,
    /// Demonstrated samples that passed the Q-filter.
    pub cloned: usize,
    /// Demonstrated samples in the batch.
    pub demos: usize,
}

/// The behaviour cloning loss with the Q-filter (Nair et al. 2018): `weight / n * sum over the demonstrated rows
/// where q_demo > q_pi of |y - y_demo|^2`, with `y` the actor's tanh output and `y_demo` the demonstrated
/// action's (so the distance is in half-widths of the box); adds its gradient with respect to `y` to `d_y`.
/// `q_filter` holds the critic's values (as the actor's loss aggregates the heads) of the demonstrated action and
/// of the actor's, `(q_demo, q_pi)`; without it every demonstrated row counts.
pub(crate) fn behaviour_cloning(
    weight: f32,
    batch: &Batch<Vec<f32>>,
    q_filter: Option<(&[f32], &[f32])>,
    y: &[f32],
    action_box: &ActionBox,
    d_y: &mut [f32],
) -> BcStats {
    let n = batch.len();
    let a = action_box.dim();
    let mut stats = BcStats::default();
    let scale = weight / n as f32;
    let actions = batch.actions.values();
    for r in 0..n {
        if !batch.is_demo[r] {
            continue;
        }
        stats.demos += 1;
        if q_filter.is_some_and(|(q_demo, q_pi)| q_demo[r] <= q_pi[r]) {
            continue;
        }
        stats.cloned += 1;
        for dim in 0..a {
            let diff = y[r * a + dim] - action_box.to_unit(actions[r * a + dim], dim);
            stats.loss += scale * diff * diff;
            d_y[r * a + dim] += 2.0 * scale * diff;
        }
    }
    stats
}

/// What the learners' tests share: a Pendulum-v1 training loop, the evaluation of a greedy policy, and
/// demonstrations of the scripted swing-up.
#[cfg(test)]
pub(crate) mod testing {
    use super::{ActorCriticConfig, ActorCriticLearner, BoxLearner, Core};
    use crate::env::pendulum::swing_up;
    use crate::env::{Env, Outcome, make_continuous};
    use crate::nn::MlpWorkspace;
    use crate::replay::Batch;
    use crate::task::BoxColumn;
    use rand::{Rng, SeedableRng};

    /// The discount of the tests' transitions.
    pub(crate) const GAMMA: f32 = 0.99;

    /// The box of the small learners of the gradient checks, `[-1, 3] x [0, 0.5]` (neither centred nor
    /// symmetric), as `(low, high)`.
    pub(crate) const SMALL_BOX: ([f32; 2], [f32; 2]) = ([-1.0, 0.0], [3.0, 0.5]);

    /// `defaults` with the small networks of the gradient checks (8-8, three heads, batches of up to 8) and the
    /// cloning weight `bc_weight`.
    pub(crate) fn small_config(bc_weight: f32, defaults: ActorCriticConfig) -> ActorCriticConfig {
        ActorCriticConfig {
            hidden: vec![8, 8],
            heads: 3,
            max_batch: 8,
            bc_weight,
            ..defaults
        }
    }

    /// The shared settings of the Pendulum-v1 tests: 64-64 networks, batches of 128, learning rates 1e-3.
    pub(crate) fn pendulum_config() -> ActorCriticConfig {
        ActorCriticConfig {
            hidden: vec![64, 64],
            max_batch: 128,
            ..ActorCriticConfig::with_learning_rate(1e-3)
        }
    }

    /// [`pendulum_config`] for pre-training on demonstrations: cloning with weight 100, without the Q-filter.
    pub(crate) fn pretraining_config() -> ActorCriticConfig {
        ActorCriticConfig {
            bc_weight: 100.0,
            q_filter: false,
            ..pendulum_config()
        }
    }

    /// `n` random one-step samples in [`SMALL_BOX`] with two observations each, flagged by `is_demo` (empty for
    /// none), drawn from `seed` (the observations first, then the actions).
    pub(crate) fn random_batch(n: usize, is_demo: &[bool], seed: u64) -> Batch<Vec<f32>> {
        let mut draw = rand_pcg::Pcg64::seed_from_u64(seed);
        let obs = (0..2 * n).map(|_| draw.random_range(-1.0..1.0)).collect();
        let actions: Vec<f32> = (0..n)
            .flat_map(|_| [draw.random_range(-1.0..3.0), draw.random_range(0.0..0.5)])
            .collect();
        Batch {
            idx: (0..n).collect(),
            obs,
            actions: column(2, &actions),
            rewards: (0..n).map(|_| draw.random_range(-1.0..1.0)).collect(),
            next_obs: (0..2 * n).map(|_| draw.random_range(-1.0..1.0)).collect(),
            terminal: vec![false; n],
            weights: (0..n).map(|_| draw.random_range(0.5..1.0)).collect(),
            is_demo: if is_demo.is_empty() {
                vec![false; n]
            } else {
                is_demo.to_vec()
            },
            ..Batch::default()
        }
    }

    /// The online critic heads' values at `(state, action)`, from a pass of their own.
    pub(crate) fn heads_at(core: &Core, state: &[f32], action: &[f32]) -> Vec<f32> {
        let mut ws = MlpWorkspace::new(&core.critics.net, 1);
        let mut input = state.to_vec();
        input.extend(action);
        core.critics.net.forward(&input, 1, &mut ws).to_vec()
    }

    /// The central difference `(loss(theta_i + h) - loss(theta_i - h)) / 2h` in the actor's parameter `i`; the
    /// parameter is restored.
    pub(crate) fn central_difference<A>(
        learner: &mut BoxLearner<A>,
        i: usize,
        h: f32,
        loss: &mut impl FnMut(&mut BoxLearner<A>) -> f64,
    ) -> f64 {
        let original = learner.core.actor.net.parameters()[i];
        learner.core.actor.net.parameters_mut()[i] = original + h;
        let up = loss(learner);
        learner.core.actor.net.parameters_mut()[i] = original - h;
        let down = loss(learner);
        learner.core.actor.net.parameters_mut()[i] = original;
        (up - down) / (2.0 * f64::from(h))
    }

    /// A column of actions of `width` numbers each, row-major in `values`.
    pub(crate) fn column(width: usize, values: &[f32]) -> BoxColumn {
        let mut column = BoxColumn::default();
        column
            .rows_mut(values.len() / width, width)
            .copy_from_slice(values);
        column
    }

    /// Checks an update's cloning term against the Q-filter computed by the test (`filter`: whether each sample
    /// passes it): with the term on (`bc_weight > 0`), some but not all demonstrated samples pass and the update
    /// counted the same; with it off, the update reports no term.
    pub(crate) fn check_filter_counts(
        bc_weight: f32,
        is_demo: &[bool],
        filter: &[bool],
        bc: Option<super::BcStats>,
    ) {
        if bc_weight > 0.0 {
            let cloned = filter.iter().filter(|&&f| f).count();
            let demos = is_demo.iter().filter(|&&d| d).count();
            assert!(
                cloned > 0 && cloned < demos,
                "the filter passed {cloned} of {demos}"
            );
            let bc = bc.expect("the update reports the cloning term");
            assert_eq!((bc.cloned, bc.demos), (cloned, demos));
        } else {
            assert!(bc.is_none());
        }
    }

    /// One-step transitions, one vector per sample.
    #[derive(Default)]
    pub(crate) struct Transitions {
        pub obs: Vec<Vec<f32>>,
        pub actions: Vec<Vec<f32>>,
        pub rewards: Vec<f32>,
        pub next_obs: Vec<Vec<f32>>,
        pub terminal: Vec<bool>,
    }

    impl Transitions {
        /// Adds the transition from `obs` by `action` to `next_obs` with `out`'s reward and termination.
        fn push(&mut self, obs: Vec<f32>, action: Vec<f32>, out: &Outcome, next_obs: &[f32]) {
            self.obs.push(obs);
            self.actions.push(action);
            self.rewards.push(out.reward as f32);
            self.next_obs.push(next_obs.to_vec());
            self.terminal.push(out.terminated);
        }

        /// Fills `batch` with `size` samples drawn uniformly by `draw`, flagged `demo`.
        pub fn sample(
            &self,
            draw: &mut impl Rng,
            size: usize,
            demo: bool,
            batch: &mut Batch<Vec<f32>>,
        ) {
            *batch = Batch::default();
            let mut actions = Vec::new();
            for _ in 0..size {
                let i = draw.random_range(0..self.rewards.len());
                batch.idx.push(i);
                batch.obs.extend(&self.obs[i]);
                actions.extend(&self.actions[i]);
                batch.rewards.push(self.rewards[i]);
                batch.next_obs.extend(&self.next_obs[i]);
                batch.terminal.push(self.terminal[i]);
                batch.weights.push(1.0);
                batch.is_demo.push(demo);
            }
            batch.actions = column(self.actions[0].len(), &actions);
        }
    }

    /// The mean return of the greedy policy on Pendulum-v1 over the episodes of `seeds`.
    pub(crate) fn evaluate_pendulum(
        agent: &mut impl ActorCriticLearner,
        seeds: std::ops::Range<u64>,
    ) -> f64 {
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

    /// Trains `agent` on Pendulum-v1 for `steps` steps ([`train_pendulum`], batches of 128) and checks that its
    /// greedy policy then holds the task above -200 on ten evaluation seeds it never trained on (1000-1009).
    pub(crate) fn learns_pendulum(agent: &mut impl ActorCriticLearner, steps: usize, name: &str) {
        train_pendulum(agent, steps, 128);
        let score = evaluate_pendulum(agent, 1000..1010);
        eprintln!(
            "{name} on Pendulum-v1 after {steps} steps: mean return {score:.1} on seeds 1000-1009"
        );
        assert!(score > -200.0, "{name} did not learn Pendulum-v1: {score}");
    }

    /// Trains on Pendulum-v1 (seed 0) for `steps` steps, the first 1,000 uniformly random, one update of a
    /// uniform batch of `batch_size` one-step transitions (discounted by [`GAMMA`]) a step after those.
    pub(crate) fn train_pendulum(
        agent: &mut impl ActorCriticLearner,
        steps: usize,
        batch_size: usize,
    ) {
        let mut env = make_continuous("Pendulum-v1").unwrap();
        let mut draw = rand_pcg::Pcg64::seed_from_u64(1);
        let mut replay = Transitions::default();
        let mut obs = vec![0.0; 3];
        let mut action = vec![0.0; 1];
        let mut batch = Batch::default();
        env.reset_into(Some(0), &mut obs);
        for step in 0..steps {
            if step < 1_000 {
                action[0] = draw.random_range(-2.0..2.0);
            } else {
                agent.act(&obs, &mut action);
            }
            let before = obs.clone();
            let out = env.step_into(&action, &mut obs).unwrap();
            replay.push(before, action.clone(), &out, &obs);
            if out.terminated || out.truncated {
                env.reset_into(None, &mut obs);
            }
            if step >= 1_000 {
                replay.sample(&mut draw, batch_size, false, &mut batch);
                agent.learn(&batch, GAMMA);
            }
        }
    }

    /// The scripted swing-up's transitions on Pendulum-v1 over the episodes of `seeds`.
    pub(crate) fn swing_up_demonstrations(seeds: std::ops::Range<u64>) -> Transitions {
        let mut env = make_continuous("Pendulum-v1").unwrap();
        let mut demos = Transitions::default();
        let mut obs = vec![0.0; 3];
        for seed in seeds {
            env.reset_into(Some(seed), &mut obs);
            loop {
                let action = swing_up(&obs).to_vec();
                let before = obs.clone();
                let out = env.step_into(&action, &mut obs).unwrap();
                demos.push(before, action, &out, &obs);
                if out.terminated || out.truncated {
                    break;
                }
            }
        }
        demos
    }

    /// The mean absolute difference between the learner's test action and the demonstrated action over `demos`.
    pub(crate) fn imitation_error(agent: &mut impl ActorCriticLearner, demos: &Transitions) -> f64 {
        let mut action = vec![0.0; 1];
        let mut total = 0.0f64;
        for (obs, expert) in demos.obs.iter().zip(&demos.actions) {
            agent.test_action(obs, &mut action);
            total += f64::from((action[0] - expert[0]).abs());
        }
        total / demos.obs.len() as f64
    }

    /// The mean absolute difference to the best constant action (the median of the demonstrated actions): the
    /// error of a policy that ignores the state.
    pub(crate) fn constant_error(demos: &Transitions) -> f64 {
        let mut actions: Vec<f32> = demos.actions.iter().map(|a| a[0]).collect();
        actions.sort_by(f32::total_cmp);
        let median = actions[actions.len() / 2];
        actions
            .iter()
            .map(|a| f64::from((a - median).abs()))
            .sum::<f64>()
            / actions.len() as f64
    }

    /// Pre-trains `agent` with `updates` updates on batches of 128 demonstrated transitions of the swing-up on
    /// seeds 0-9; returns the mean |pi(s) - a_E| on those states and on seeds 100-102 it never saw, and the
    /// best constant action's on each.
    pub(crate) fn pretrain(
        agent: &mut impl ActorCriticLearner,
        updates: usize,
        name: &str,
    ) -> [f64; 4] {
        let demos = swing_up_demonstrations(0..10);
        let unseen = swing_up_demonstrations(100..103);
        let before = imitation_error(agent, &demos);
        let mut draw = rand_pcg::Pcg64::seed_from_u64(2);
        let mut batch = Batch::default();
        let (mut cloned, mut demos_seen) = (0, 0);
        for _ in 0..updates {
            demos.sample(&mut draw, 128, true, &mut batch);
            if let Some(bc) = agent.learn(&batch, GAMMA).0.bc {
                cloned += bc.cloned;
                demos_seen += bc.demos;
            }
        }
        let (seen, held_out) = (
            imitation_error(agent, &demos),
            imitation_error(agent, &unseen),
        );
        let (constant, constant_unseen) = (constant_error(&demos), constant_error(&unseen));
        eprintln!(
            "{name} pre-trained {updates} updates: mean |pi(s) - a_E| {before:.3} -> {seen:.3} on the \
             demonstrated states ({held_out:.3} on unseen episodes); the best constant action: {constant:.3} \
             ({constant_unseen:.3}); the cloning term covered {cloned} of {demos_seen} demonstrated samples"
        );
        [seen, held_out, constant, constant_unseen]
    }

    /// Pre-trains `agent` ([`pretrain`]) and checks that its test actions then follow the demonstrator, on the
    /// demonstrated states and on unseen episodes, with at most half the error of the best constant action.
    pub(crate) fn pretraining_imitates(
        agent: &mut impl ActorCriticLearner,
        updates: usize,
        name: &str,
    ) {
        let [seen, held_out, constant, constant_unseen] = pretrain(agent, updates, name);
        assert!(
            seen < 0.5 * constant && held_out < 0.5 * constant_unseen,
            "{name} did not imitate the demonstrations: {seen} and {held_out} against {constant} and \
             {constant_unseen}"
        );
    }
}
