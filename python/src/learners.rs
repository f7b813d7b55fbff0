//! The learners Python runs drive ([`PyLearner`]: the DQN family and TD3/SAC): how a run of each starts, is lent to a
//! callback, begins from a snapshot or from weights, and writes its snapshot.

use crate::actions::PyAction;
use crate::lent::LentParts;
use crate::policy::Net;
use crate::policy::WeightsFile;
use arld_core::agent::actor_file::TrainedActor;
use arld_core::agent::box_agent::BoxAgent;
use arld_core::agent::{DqnAgent, Learner};
use arld_core::env;
use arld_core::nn::QNet;
use arld_core::train::{self, OwnRun, PausedRun, RunLog, SeedPurpose, TrainConfig, seed_for};
use rand::SeedableRng;
use rand_pcg::Pcg64;
use std::path::Path;

/// A learner that Python runs drive (its run starts at [`OwnRun::builder`]): how it is lent to a callback, and what Python keeps
/// of it at a pause.
pub(crate) trait PyLearner: OwnRun<Action: PyAction> + 'static {
    /// The agent and log as a callback borrows them.
    fn lend(agent: &Self, log: &RunLog<Self::Action>) -> LentParts;
    /// The network Python acts with, for the task `id`.
    fn net(&self, id: &str) -> Net;
    /// A learner of `cfg`'s shape, to load a snapshot's state into.
    fn for_snapshot(cfg: &TrainConfig) -> anyhow::Result<Self>;
    /// A learner of `cfg` that begins with the weights file `path` (`set_parameters` before a new run).
    fn from_weights(cfg: &TrainConfig, path: &Path) -> anyhow::Result<Self>;
}

impl PyLearner for DqnAgent {
    fn lend(agent: &Self, log: &RunLog) -> LentParts {
        LentParts::Discrete(agent as *const DqnAgent, log as *const RunLog)
    }
    fn net(&self, _id: &str) -> Net {
        Net::Q(Box::new(self.network().clone()))
    }
    fn for_snapshot(cfg: &TrainConfig) -> anyhow::Result<Self> {
        let spec = env::spec(&cfg.env)?;
        Ok(DqnAgent::new(
            &cfg.dqn_agent_config(),
            spec.obs_dim,
            spec.n_actions,
            0,
        ))
    }
    fn from_weights(cfg: &TrainConfig, path: &Path) -> anyhow::Result<Self> {
        let (net, _meta) = QNet::load_file(path)?;
        let rng = Pcg64::seed_from_u64(seed_for(cfg.seed, SeedPurpose::Agent));
        Ok(DqnAgent::from_network(&cfg.dqn_agent_config(), net, rng))
    }
}

impl PyLearner for BoxAgent {
    fn lend(agent: &Self, log: &RunLog<Vec<f32>>) -> LentParts {
        LentParts::Box(agent as *const BoxAgent, log as *const RunLog<Vec<f32>>)
    }
    fn net(&self, id: &str) -> Net {
        let spec = env::box_spec(id).expect("a box run's task is registered");
        Net::Actor(Box::new(TrainedActor::new(
            self.algo(),
            self.actor().clone(),
            spec.action_low,
            spec.action_high,
        )))
    }
    fn for_snapshot(cfg: &TrainConfig) -> anyhow::Result<Self> {
        Ok(train::run::box_agent(cfg, env::box_spec(&cfg.env)?))
    }
    fn from_weights(_cfg: &TrainConfig, _path: &Path) -> anyhow::Result<Self> {
        anyhow::bail!(
            "a TD3 or SAC run cannot begin from an actor's weights alone (its critics are not in them)"
        )
    }
}

/// Writes a paused run's snapshot into the file `path` (through a directory of its own, the snapshot's format).
pub(crate) fn write_snapshot<L: Learner>(
    run: &mut PausedRun<'_, L>,
    path: &Path,
) -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    run.snapshot(dir.path())?;
    std::fs::copy(dir.path().join(train::snapshot::SNAPSHOT_FILE), path)
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
    Ok(())
}
