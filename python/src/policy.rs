//! Trained policies Python acts with ([`Policy`]): a DQN-family network or a TD3/SAC actor, their weights files,
//! and a run's current network ([`Net`]).

use crate::errors::{runtime_error, value_error};
use arld_core::agent::actor_file::TrainedActor;
use arld_core::nn::QNet;
use arld_core::train::{self, SeedPurpose, TrainConfig, seed_for};
use pyo3::prelude::*;
use rand::SeedableRng;
use rand_pcg::Pcg64;
use std::path::Path;

/// A weights file's metadata (the caller's keys).
pub(crate) type Metadata = std::collections::BTreeMap<String, String>;

/// The two kinds of weights file Python reads and writes: a DQN-family network and a TD3/SAC actor.
pub(crate) trait WeightsFile: Sized {
    fn save_file(&self, path: &Path, meta: &Metadata) -> anyhow::Result<()>;
    fn load_file(path: &Path) -> anyhow::Result<(Self, Metadata)>;
}

impl WeightsFile for QNet {
    fn save_file(&self, path: &Path, meta: &Metadata) -> anyhow::Result<()> {
        self.save(path, meta)
    }
    fn load_file(path: &Path) -> anyhow::Result<(Self, Metadata)> {
        QNet::load(path)
    }
}

impl WeightsFile for TrainedActor {
    fn save_file(&self, path: &Path, meta: &Metadata) -> anyhow::Result<()> {
        self.save(path, meta)
    }
    fn load_file(path: &Path) -> anyhow::Result<(Self, Metadata)> {
        TrainedActor::load(path)
    }
}

/// Writes `weights` to `path` with `meta`; a failure is Python's RuntimeError.
pub(crate) fn save_weights(
    weights: &impl WeightsFile,
    path: &str,
    meta: &Metadata,
) -> PyResult<()> {
    weights
        .save_file(Path::new(path), meta)
        .map_err(|e| runtime_error(format!("{e:#}")))
}

/// Reads the weights at `path`; a file that is not such weights is Python's ValueError, naming it.
pub(crate) fn load_weights<W: WeightsFile>(path: &str) -> PyResult<(W, Metadata)> {
    W::load_file(Path::new(path)).map_err(|e| value_error(format!("cannot load {path}: {e:#}")))
}

/// Refuses an observation of another length than the network's `inputs`.
pub(crate) fn check_obs(obs: &[f32], inputs: usize) -> PyResult<()> {
    if obs.len() != inputs {
        return Err(value_error(format!(
            "the observation has {} values, but the network takes {inputs}",
            obs.len()
        )));
    }
    Ok(())
}

/// A trained policy acting with its test policy (no exploration): a DQN-family network, or a TD3 or SAC actor
/// as the run's test episodes act ([`TrainedActor`]: TD3's action or SAC's `tanh` of its means, mapped into the
/// box). A DQN-family policy that comes from a run also explores as the run does at the step it stands at.
#[pyclass(module = "arld._arld")]
pub(crate) struct Policy {
    pub(crate) kind: PolicyKind,
}

/// The two families of policy, side by side.
pub(crate) enum PolicyKind {
    Q {
        net: Box<QNet>,
        q: Vec<f32>,
        /// The exploring agent (its own generator, so asking it never changes the run) and ε.
        explorer: Option<(Box<arld_core::agent::DqnAgent>, f64)>,
    },
    Actor(TrainedActor),
}

/// An action as Python receives it: an int, or a list of floats for a box.
#[derive(IntoPyObject)]
pub(crate) enum PolicyAction {
    Index(usize),
    Vector(Vec<f32>),
}

impl Policy {
    pub(crate) fn of_net(net: QNet) -> Self {
        let q = vec![0.0; net.heads() * net.n_actions()];
        Self {
            kind: PolicyKind::Q {
                net: Box::new(net),
                q,
                explorer: None,
            },
        }
    }

    /// A policy that also explores as the run `cfg` does at step `step`.
    pub(crate) fn exploring(net: QNet, cfg: &TrainConfig, step: usize) -> Self {
        let rng = Pcg64::seed_from_u64(seed_for(cfg.seed, SeedPurpose::Agent) ^ step as u64);
        let agent =
            arld_core::agent::DqnAgent::from_network(&cfg.dqn_agent_config(), net.clone(), rng);
        let eps = train::epsilon_at(cfg, step);
        let mut policy = Self::of_net(net);
        if let PolicyKind::Q { explorer, .. } = &mut policy.kind {
            *explorer = Some((Box::new(agent), eps));
        }
        policy
    }

    /// The policy of a run's network.
    pub(crate) fn of_run(net: Net, cfg: &TrainConfig, step: usize) -> Self {
        match net {
            Net::Q(net) => Self::exploring(*net, cfg, step),
            Net::Actor(actor) => Self {
                kind: PolicyKind::Actor(*actor),
            },
        }
    }

    /// The observation's length the policy takes, after checking that `obs` has it.
    pub(crate) fn check(&self, obs: &[f32]) -> PyResult<()> {
        check_obs(obs, self.obs_dim())
    }
}

#[pymethods]
impl Policy {
    /// The test policy's action for one observation: an int, or a flat list of floats for a box.
    fn act(&mut self, obs: Vec<f32>) -> PyResult<PolicyAction> {
        self.check(&obs)?;
        Ok(match &mut self.kind {
            PolicyKind::Q { net, q, .. } => {
                PolicyAction::Index(arld_core::agent::test_policy_action(net, q, &obs))
            }
            PolicyKind::Actor(actor) => PolicyAction::Vector(actor.act(&obs)),
        })
    }

    /// The exploration policy's action (ε-greedy with the run's current ε, the episode's bootstrap head, the
    /// noisy layer's sampled noise); `episode_start` begins a new episode (a new head, new noise). An actor acts
    /// as in `act`: TD3's policy is deterministic (its exploration noise belongs to the run), as in
    /// Stable-Baselines3's TD3, whose `predict(deterministic=False)` is the actor's action too.
    fn explore(&mut self, obs: Vec<f32>, episode_start: bool) -> PyResult<PolicyAction> {
        self.check(&obs)?;
        match &mut self.kind {
            PolicyKind::Q { explorer: None, .. } => Err(value_error(
                "this policy has no exploration (loaded weights, not a run): use deterministic=True".into(),
            )),
            PolicyKind::Q {
                explorer: Some((agent, eps)),
                ..
            } => {
                if episode_start {
                    agent.begin_episode();
                }
                Ok(PolicyAction::Index(
                    agent.act(&obs, *eps, arld_core::query::Needs::NOTHING).0,
                ))
            }
            PolicyKind::Actor(actor) => Ok(PolicyAction::Vector(actor.act(&obs))),
        }
    }

    /// The network's kind: "plain", "bootstrap" or "noisy"; or the learner of an actor: "td3" or "sac".
    #[getter]
    fn net(&self) -> &'static str {
        match &self.kind {
            PolicyKind::Q { net, .. } => match net.kind() {
                arld_core::nn::OutputKind::Plain => "plain",
                arld_core::nn::OutputKind::Bootstrap { .. } => "bootstrap",
                _ => "noisy",
            },
            PolicyKind::Actor(actor) => actor.algo().name(),
        }
    }

    /// Saves the weights (safetensors; the run's weights file format, which `checkpoint:PATH` experts read)
    /// with `meta` as metadata.
    fn save(&self, path: &str, meta: Metadata) -> PyResult<()> {
        match &self.kind {
            PolicyKind::Q { net, .. } => save_weights(net.as_ref(), path, &meta),
            PolicyKind::Actor(actor) => save_weights(actor, path, &meta),
        }
    }

    /// Loads weights saved by `save` (or by `arld train`): a DQN-family network or a TD3/SAC actor, whichever
    /// the file holds; returns the policy and the file's metadata.
    #[staticmethod]
    fn load(path: &str) -> PyResult<(Policy, Metadata)> {
        let actor = arld_core::agent::actor_file::holds_an_actor(Path::new(path))
            .map_err(|e| value_error(format!("cannot read {path}: {e:#}")))?;
        if actor {
            let (actor, meta) = load_weights(path)?;
            Ok((
                Policy {
                    kind: PolicyKind::Actor(actor),
                },
                meta,
            ))
        } else {
            let (net, meta) = load_weights(path)?;
            Ok((Policy::of_net(net), meta))
        }
    }

    #[getter]
    fn obs_dim(&self) -> usize {
        match &self.kind {
            PolicyKind::Q { net, .. } => net.obs_dim(),
            PolicyKind::Actor(actor) => actor.obs_dim(),
        }
    }

    /// The number of actions of a DQN-family network; `None` for an actor.
    #[getter]
    fn n_actions(&self) -> Option<usize> {
        match &self.kind {
            PolicyKind::Q { net, .. } => Some(net.n_actions()),
            PolicyKind::Actor(_) => None,
        }
    }

    /// An actor's box: `(low, high)`, flat; `None` for a DQN-family network.
    #[getter]
    fn bounds(&self) -> Option<(Vec<f32>, Vec<f32>)> {
        match &self.kind {
            PolicyKind::Q { .. } => None,
            PolicyKind::Actor(actor) => {
                let (low, high) = actor.bounds();
                Some((low.to_vec(), high.to_vec()))
            }
        }
    }
}

/// A run's current network as Python acts with it: a DQN-family network or a TD3 actor.
#[derive(Clone)]
pub(crate) enum Net {
    Q(Box<QNet>),
    Actor(Box<TrainedActor>),
}
