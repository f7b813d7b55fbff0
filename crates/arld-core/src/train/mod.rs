//! Training: one run of any method in the paper, from its configuration ([`TrainConfig`], every
//! hyperparameter) to its summary and run directory. [`RunBuilder`] (in [`run`]) is the one entry point and the
//! loop itself; [`eval`] runs the test episodes; the pieces the loop shares with pre-training and tests
//! (the ε schedule, DQfD pre-training, a checked update) are here. [`session`] alone opens a run directory (lock,
//! overwrite, resume or restart, the run's log, the failure record) for the command line, the laboratory and Python.

pub mod config;
pub mod eval;
pub mod log;
pub mod run;
pub mod run_dir;
pub mod seeds;
pub mod session;
pub mod snapshot;

pub use config::{Algo, BoxUncertainty, ConfigInput, Method, NetKind, TdLoss, TrainConfig};
pub use eval::Evaluator;
pub use log::{LogPosition, RunLog};
pub use run::{Control, Driver, LastStep, OwnRun, PausedRun, RunBuilder, StepView};
pub use run_dir::{EvalPoint, QueryEvent, Summary, steps_to_solve};
pub use seeds::{SeedPurpose, seed_for};
pub use session::Session;
pub use snapshot::Checkpointer;

use crate::agent::Learner;
use crate::env::Env;
use crate::expert::Expert;
use crate::expert::demos::{DemoAction, Demonstrations};
use crate::replay::{Batch, Replay};
use anyhow::{Result, ensure};
use rand_pcg::Pcg64;

/// ε-greedy schedule: linear from `eps_start` to `eps_end` over `eps_fraction` of training (§5).
pub fn epsilon_at(cfg: &TrainConfig, step: usize) -> f64 {
    if !cfg.eps_greedy_on_top && cfg.net != NetKind::Plain {
        return 0.0;
    }
    let horizon = (cfg.eps_fraction * cfg.train_steps as f64).max(1.0);
    let frac = (step as f64 / horizon).min(1.0);
    cfg.eps_start + frac * (cfg.eps_end - cfg.eps_start)
}

/// DQfD pre-training (§9): the demonstrations enter replay permanently, then `pretrain_steps` updates sample
/// from them alone (TD plus margin loss, prioritized among demonstrations), with the usual target copies.
pub fn pretrain<L: Learner>(
    cfg: &TrainConfig,
    agent: &mut L,
    replay: &mut Replay<L::Action>,
    demos: &Demonstrations<L::Action>,
    rng: &mut Pcg64,
    batch: &mut Batch<L::Action>,
) -> Result<()> {
    push_demos(cfg, replay, demos)?;
    agent.set_pretraining(true);
    for update in 1..=cfg.pretrain_steps {
        pretrain_update(cfg, agent, replay, rng, batch, update)?;
    }
    agent.set_pretraining(false);
    agent.end_target_period();
    Ok(())
}

/// The demonstrations a run of `cfg` pre-trains on, whatever the kind of its actions: none for a method that
/// does not pre-train; else those of `demo_file`, a demonstration file or a Minari dataset
/// ([`crate::expert::minari`]; its first `n_demo` transitions when `n_demo` is positive),
/// else `n_demo` transitions collected from `expert` in the environment `make_env` makes (episode i reset with
/// the run's demonstration seed plus i). The command line, sweeps and Python (unless given `demos=`) all take a
/// run's demonstrations here.
pub fn run_demonstrations<A: DemoAction>(
    cfg: &TrainConfig,
    expert: Option<&mut dyn Expert<A>>,
    make_env: impl FnOnce() -> Result<Box<dyn Env<A>>>,
) -> Result<Option<Demonstrations<A>>> {
    if !cfg.method.pretrains() {
        return Ok(None);
    }
    if let Some(path) = cfg.demo_path()? {
        let keep = if cfg.n_demo > 0 {
            cfg.n_demo
        } else {
            usize::MAX
        };
        let demos = match crate::expert::minari::dataset_dir(path)? {
            Some(dataset) => crate::expert::minari::load(&dataset, &cfg.env)?,
            None => Demonstrations::load(path, Some(&cfg.env))?,
        };
        return Ok(Some(demos.truncated_to(keep)));
    }
    let expert = expert.ok_or_else(|| {
        anyhow::anyhow!(
            "{} pre-trains on demonstrations collected from an expert, but none was given",
            cfg.method
        )
    })?;
    let mut env = make_env()?;
    Ok(Some(Demonstrations::collect_in(
        env.as_mut(),
        expert,
        cfg.n_demo,
        seed_for(cfg.seed, SeedPurpose::Demonstrations),
    )?))
}

/// The demonstrations enter replay permanently, episode by episode.
pub(super) fn push_demos<A: crate::task::Action>(
    cfg: &TrainConfig,
    replay: &mut Replay<A>,
    demos: &Demonstrations<A>,
) -> Result<()> {
    ensure!(
        demos.env == cfg.env,
        "the demonstrations are for {}, not {}",
        demos.env,
        cfg.env
    );
    for (i, t) in demos.transitions.iter().enumerate() {
        replay.push(t.transition())?;
        if demos
            .transitions
            .get(i + 1)
            .is_none_or(|next| next.episode != t.episode)
        {
            replay.end_episode()?;
        }
    }
    Ok(())
}

/// Pre-training update number `update` (from 1): demonstrations only, prioritized among them.
pub(super) fn pretrain_update<L: Learner>(
    cfg: &TrainConfig,
    agent: &mut L,
    replay: &mut Replay<L::Action>,
    rng: &mut Pcg64,
    batch: &mut Batch<L::Action>,
    update: usize,
) -> Result<()> {
    replay.sample_demo_only(cfg.batch_size, cfg.beta0 as f32, rng, batch);
    update_checked(cfg, agent, replay, batch, || {
        format!("pre-training update {update}")
    })?;
    if update.is_multiple_of(cfg.target_period) {
        agent.end_target_period();
    }
    Ok(())
}

/// A run whose learning blew up: a loss or the gradient is no longer a finite number.
#[derive(Debug, thiserror::Error)]
#[error(
    "diverged at {at}: the {what} is {value}; the learning rate may be too high for this task: try a lower \
     `lr` (now {lr}, e.g. --set lr={lower})",
    lower = .lr / 10.0
)]
pub(crate) struct Diverged {
    pub at: String,
    pub what: &'static str,
    pub value: f32,
    pub lr: f64,
}

/// One prioritized update on `batch` and the new priorities of its transitions. A loss or gradient that is not
/// finite ends the run with [`Diverged`] (`at` says where), before any priority is taken from it; the weights
/// the update spoiled are never saved, since the run ends there.
pub(super) fn update_checked<L: Learner>(
    cfg: &TrainConfig,
    agent: &mut L,
    replay: &mut Replay<L::Action>,
    batch: &Batch<L::Action>,
    at: impl FnOnce() -> String,
) -> Result<crate::agent::UpdateStats> {
    let (stats, priorities) = agent.learn(batch);
    let checked = [
        ("TD loss", stats.td_loss),
        ("margin loss", stats.margin_loss),
        ("n-step loss", stats.nstep_loss),
        ("gradient norm", stats.grad_norm),
    ];
    if let Some(&(what, value)) = checked.iter().find(|(_, v)| !v.is_finite()) {
        return Err(Diverged {
            at: at(),
            what,
            value,
            lr: cfg.lr,
        }
        .into());
    }
    replay.update_priorities(&batch.idx, priorities);
    Ok(stats)
}
