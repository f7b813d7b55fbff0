//! Experiments: running one configured run end to end ([`run_one`]: expert, demonstrations, training, in the run
//! directory that [`arld_core::train::session`] opens), sweeps over grids of runs ([`sweep`]) and their submission to Slurm as job arrays ([`slurm`]),
//! the paper's experiment grids ([`protocol`]), statistics over seeds ([`stats`]), and reports with the paper's
//! table and figures ([`report`]; which figures and what they show in [`figures`], how one is drawn in
//! [`plot`]; hand-written documents that quote its tables in [`quote`]). Sweeps and reports read runs through
//! [`arld_core::train::run_dir`], the owner of the run directory's format.
//!
//! A sweep directory is locked with the core's [`dir_lock`] (re-exported here), the lock of a run directory.
//!
//! Within this layer imports go one way: `stats`, `sweep` <- `protocol`;
//! `protocol`, `plot` <- `figures`; `protocol`, `plot`, `stats`, `verdict` <- `effort`; `effort`, `figures`, `plot`,
//! `quote`, `pack` <- `report`; `pack` <- `sweep`; `slurm` <- the CLI.

pub use arld_core::dir_lock;
pub mod effort;
pub mod figures;
pub mod pack;
pub mod plot;
pub mod protocol;
pub mod quote;
pub mod reference;
pub mod report;
pub mod slurm;
pub mod stats;
pub mod sweep;
pub mod verdict;

use anyhow::Result;
use arld_core::agent::DqnAgent;
use arld_core::agent::box_agent::BoxAgent;
use arld_core::env;
use arld_core::expert::{
    self,
    demos::{DemoAction, Demonstrations},
};
use arld_core::train::{self, OwnRun, SeedPurpose, Summary, TrainConfig, seed_for, session};
use std::path::Path;

/// Builds the expert and the demonstrations a configuration needs, trains, and writes the run directory
/// (or keeps everything in memory when `out_dir` is `None`). A run directory holding a snapshot of an
/// interrupted run of `cfg` is continued from it; while the run goes on it snapshots itself every
/// `cfg.snapshot_every` steps and when asked to stop ([`arld_core::interrupt`]).
///
/// A run that ends with an error leaves `failed.json` in its directory when it has one (training records the
/// step it failed at; an error before training, such as an expert that cannot be started, is recorded as the
/// `setup` phase: [`session::record_setup_failure`]); the summary of a later attempt that finishes the run
/// removes it.
pub fn run_one(cfg: &TrainConfig, out_dir: Option<&Path>, progress: bool) -> Result<Summary> {
    let expert_seed = seed_for(cfg.seed, SeedPurpose::Expert);
    if let Ok(spec) = env::box_spec(&cfg.env) {
        let (expert, demos) = setup(cfg, || {
            expert::boxed::from_spec_with(
                &cfg.expert,
                spec,
                expert_seed,
                cfg.expert_timeout,
                arld_web::start_box,
            )
        })
        .map_err(|err| session::record_setup_failure(out_dir, err))?;
        return run_in::<BoxAgent>(expert, demos, cfg, out_dir, progress);
    }
    let (expert, demos) = setup(cfg, || {
        arld_web::from_spec(&cfg.expert, &cfg.env, expert_seed, cfg.expert_timeout)
    })
    .map_err(|err| session::record_setup_failure(out_dir, err))?;
    run_in::<DqnAgent>(expert, demos, cfg, out_dir, progress)
}

/// Trains the run of `cfg` learned by `L` with its expert and demonstrations, into `out_dir` or in memory (see
/// [`run_one`]; the directory is opened by [`session::open`]), whatever the kind of its actions.
fn run_in<L: OwnRun>(
    mut expert: Option<Box<dyn expert::Expert<L::Action>>>,
    demos: Option<Demonstrations<L::Action>>,
    cfg: &TrainConfig,
    out_dir: Option<&Path>,
    progress: bool,
) -> Result<Summary> {
    let mut opened = session::open::<L::Action>(out_dir, cfg, progress)?;
    let session::Opened {
        log,
        snapshot,
        checkpointer,
    } = &mut opened;
    let expert = expert
        .as_mut()
        .map(|e| &mut **e as &mut dyn expert::Expert<L::Action>);
    let mut run = L::builder(cfg)
        .expert(expert)
        .demos(demos.as_ref())
        .resume_from(snapshot.as_ref());
    if let Some(checkpointer) = checkpointer {
        run = run.snapshots(checkpointer);
    }
    let (summary, _agent) = run.train(log)?;
    Ok(summary)
}

/// What a run is given before training: its expert and its pre-training demonstrations, each if it needs them.
type Setup<A> = (
    Option<Box<dyn expert::Expert<A>>>,
    Option<Demonstrations<A>>,
);

/// The expert (built by `build_expert`, when `cfg` asks one) and the demonstrations (when its method
/// pre-trains: [`train::run_demonstrations`]) a run of `cfg` needs, for either kind of action.
fn setup<A: DemoAction>(
    cfg: &TrainConfig,
    build_expert: impl FnOnce() -> Result<Box<dyn expert::Expert<A>>>,
) -> Result<Setup<A>> {
    let mut expert = match cfg.expert_used() {
        Some(_) => Some(build_expert()?),
        None => None,
    };
    let demos = train::run_demonstrations(
        cfg,
        expert
            .as_mut()
            .map(|e| &mut **e as &mut dyn expert::Expert<A>),
        || A::make_env(&cfg.env),
    )?;
    Ok((expert, demos))
}

/// Runs `cfg` into `dir`, or reuses the finished run there when it was run with exactly `cfg` (returns `None`
/// then). A finished run of another configuration is refused, naming the keys that differ; an interrupted run
/// with a snapshot continues; any other leftovers of a run are cleared first, so that no earlier run's files
/// (checkpoints) mix into this one.
pub fn run_or_reuse(cfg: &TrainConfig, dir: &Path, progress: bool) -> Result<Option<Summary>> {
    if session::reuse_or_clear(cfg, dir)? {
        return Ok(None);
    }
    run_one(cfg, Some(dir), progress).map(Some)
}

/// Runs one grid point of a sweep into `dir` (its configuration: [`sweep::RunSpec::config`]).
pub fn run_spec(spec: &sweep::RunSpec, dir: &Path) -> Result<()> {
    run_one(&spec.config()?, Some(dir), false)?;
    Ok(())
}
