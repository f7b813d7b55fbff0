//! Saved runs read from Python: a snapshot's configuration and network, its evaluations and queries, and a network of
//! a configuration's shape for weights to be set into.

use crate::actions::PyAction;
use crate::errors::value_error;
use crate::learners::PyLearner;
use crate::policy::{Net, Policy};
use crate::records::Records;
use arld_core::agent::DqnAgent;
use arld_core::agent::box_agent::BoxAgent;
use arld_core::env::{self};
use arld_core::train::{self, Checkpointer, TrainConfig};
use pyo3::prelude::*;
use pyo3::types::PyList;
use std::path::Path;

/// What `snapshot_policy` returns: the policy, the configuration (JSON), the step, the evaluations (JSON), the
/// queries.
pub(crate) type SnapshotPolicy = (Policy, String, usize, String, Py<PyList>);

/// The network of a run's snapshot file, acting (and exploring) as the run did at its step; returns the policy,
/// the configuration as JSON text, the step and the run's evaluations so far (JSON text: step, mean, std, min,
/// max of each) and its queries so far (as [`Run::queries`]; none from a snapshot of an arld that did not keep
/// them).
#[pyfunction]
pub(crate) fn snapshot_policy(py: Python<'_>, path: &str) -> PyResult<SnapshotPolicy> {
    let read = || -> anyhow::Result<(Net, TrainConfig, usize, String, Records)> {
        let (cfg, state) = read_snapshot_file(path)?;
        let st: serde_json::Value = state.value("loop")?;
        let step = st["step"].as_u64().unwrap_or(0) as usize;
        let (net, curve, queries) = if env::box_spec(&cfg.env).is_ok() {
            snapshot_parts::<BoxAgent>(&cfg, &state)?
        } else {
            snapshot_parts::<DqnAgent>(&cfg, &state)?
        };
        Ok((net, cfg, step, curve, queries))
    };
    let (net, cfg, step, curve, queries) =
        read().map_err(|e| value_error(format!("cannot load {path}: {e:#}")))?;
    let list = PyList::empty(py);
    queries.fill(py, &list)?;
    let policy = Policy::of_run(net, &cfg, step);
    Ok((policy, cfg.to_json(), step, curve, list.unbind()))
}

/// The snapshot file `path` (a saved run) with the configuration it recorded.
pub(crate) fn read_snapshot_file(
    path: &str,
) -> anyhow::Result<(TrainConfig, arld_core::state::StateDict<'static>)> {
    let text = train::snapshot::recorded_config(Path::new(path))?;
    let cfg: TrainConfig = toml::from_str(&text)?;
    // The snapshot machinery reads `snapshot.safetensors` in a directory: a private copy there.
    let dir = tempfile::tempdir()?;
    std::fs::copy(path, dir.path().join(train::snapshot::SNAPSHOT_FILE))?;
    let state = Checkpointer::new(dir.path(), &cfg)
        .load()?
        .ok_or_else(|| anyhow::anyhow!("no snapshot"))?;
    Ok((cfg, state))
}

/// The network, the evaluations (JSON text) and the queries of a run's snapshot `state`, for the learner `L`.
pub(crate) fn snapshot_parts<L: PyLearner>(
    cfg: &TrainConfig,
    state: &arld_core::state::StateDict<'_>,
) -> anyhow::Result<(Net, String, Records)> {
    let mut agent = L::for_snapshot(cfg)?;
    agent.load_state(train::run::AGENT_STATE, state)?;
    let position = train::session::resume_position::<L::Action>(state)?;
    Ok((
        agent.net(&cfg.env),
        serde_json::to_string(&position.curve)?,
        L::Action::records(&position.query_events),
    ))
}

/// A network of the shape a run of `config` (JSON text, from `resolve_config`) trains, for weights to be set into
/// (`Agent.set_parameters` before any run).
#[pyfunction]
pub(crate) fn fresh_policy(config: &str) -> PyResult<Policy> {
    let cfg: TrainConfig = serde_json::from_str(config).map_err(|e| value_error(e.to_string()))?;
    let net = if env::box_spec(&cfg.env).is_ok() {
        <BoxAgent as PyLearner>::for_snapshot(&cfg).map(|a| a.net(&cfg.env))
    } else {
        <DqnAgent as PyLearner>::for_snapshot(&cfg).map(|a| a.net(&cfg.env))
    }
    .map_err(|e| value_error(format!("{e:#}")))?;
    Ok(Policy::of_run(net, &cfg, 0))
}

/// The configuration a snapshot file recorded, as JSON text (`None` when the file is plain weights).
#[pyfunction]
pub(crate) fn snapshot_config(path: &str) -> PyResult<Option<String>> {
    match train::snapshot::recorded_config(Path::new(path)) {
        Err(_) => Ok(None),
        Ok(text) => {
            let cfg: TrainConfig = toml::from_str(&text).map_err(|e| {
                value_error(format!("{path}: its configuration cannot be read: {e}"))
            })?;
            Ok(Some(cfg.to_json()))
        }
    }
}
