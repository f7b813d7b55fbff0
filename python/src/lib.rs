//! `arld._arld`: the Python bindings of the `arld` library. This crate only converts between Python objects and
//! the library's types and calls the library; the Python package `arld` (in `arld/__init__.py`) gives it the
//! interface a Stable-Baselines3 user expects.
//!
//! The training loop is the library's ([`arld_core::train::RunBuilder`]). Python is called back only to step an
//! environment ([`envs::PyEnv`]: any object with `reset(seed) -> list[float]` and `step(action) -> (obs, reward,
//! terminated, truncated)`) and to ask an expert ([`experts::PyExpert`]: a callable `obs -> action`). Both are
//! generic over the kind of action ([`actions::PyAction`]): a discrete index (the DQN family learns) or a list of
//! floats in a box (TD3 or SAC learns); a run's kind follows from its task's registration (`register_env` or
//! `register_box_env`). An exception raised there is kept in an [`errors::ErrorSlot`]. An exception from an expert
//! or a callback pauses the run whole (the expert's question stays open and is asked again when the run goes on);
//! `advance` then raises the original exception with a note saying where the run paused. An exception from the
//! environment ends the run (its state in the middle of a step is unknown) and is raised with the loop's context
//! as a note. Ctrl-C is noticed at every environment step (`check_signals`), so it interrupts training as a
//! `KeyboardInterrupt`.
//!
//! A callback runs on the run's thread after a step; while it runs, the live agent and log are lent to it
//! ([`lent::Lent`]), so `Run.live_actions`, `Run.live_policy` and the evaluations and queries it reads are those of
//! that step, without a copy per step. A `save` inside a callback is written at a pause right after the callback
//! returns (the run's replay and generators are reachable only there); the run then goes on by itself.
//!
//! The modules, by concern: conversion ([`errors`], [`actions`], [`records`], [`demos`]), environments
//! ([`envs`]), experts ([`experts`], and [`web`] for a person), configuration ([`config`]), policies ([`policy`],
//! [`snapshots`]), and the run ([`run`]: its Python class and start; [`remote`]: its thread's driver; [`lent`]:
//! what a callback borrows; [`learners`]: the learners it drives). This file only declares them and the Python
//! module.

mod actions;
mod config;
mod demos;
mod envs;
mod errors;
mod experts;
mod learners;
mod lent;
mod policy;
mod records;
mod remote;
mod run;
mod snapshots;
mod web;

use crate::config::{config_keys, resolve_config};
use crate::envs::{
    BuiltinEnv, box_bounds, builtin_env_ids, is_box_env, register_box_env, register_env,
};
use crate::policy::Policy;
use crate::run::{Run, start_run};
use crate::snapshots::{fresh_policy, snapshot_config, snapshot_policy};
use pyo3::prelude::*;

#[pymodule]
pub(crate) fn _arld(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // The library's version and the git commit it was built from (`arld.__version__`, `_arld.git_commit`).
    m.add("__version__", arld_core::VERSION)?;
    m.add("git_commit", arld_core::GIT_COMMIT)?;
    m.add_function(wrap_pyfunction!(register_env, m)?)?;
    m.add_function(wrap_pyfunction!(register_box_env, m)?)?;
    m.add_function(wrap_pyfunction!(is_box_env, m)?)?;
    m.add_function(wrap_pyfunction!(box_bounds, m)?)?;
    m.add_function(wrap_pyfunction!(builtin_env_ids, m)?)?;
    m.add_function(wrap_pyfunction!(fresh_policy, m)?)?;
    m.add_function(wrap_pyfunction!(config_keys, m)?)?;
    m.add_function(wrap_pyfunction!(resolve_config, m)?)?;
    m.add_function(wrap_pyfunction!(start_run, m)?)?;
    m.add_function(wrap_pyfunction!(snapshot_config, m)?)?;
    m.add_function(wrap_pyfunction!(snapshot_policy, m)?)?;
    m.add_class::<Run>()?;
    m.add_class::<Policy>()?;
    m.add_class::<BuiltinEnv>()?;
    m.add_class::<web::PyWebExpert>()?;
    Ok(())
}
