//! `arld._arld`: the Python bindings of the `arld` library. This crate only converts between Python objects and
//! the library's types and calls the library; the Python package `arld` (in `arld/__init__.py`) gives it the
//! interface a Stable-Baselines3 user expects.
//!
//! The training loop is the library's ([`arld::train::RunBuilder`]). Python is called back only to step an
//! environment ([`PyEnv`]: any object with `reset(seed) -> list[float]` and `step(action) -> (obs, reward,
//! terminated, truncated)`) and to ask an expert ([`PyExpert`]: a callable `obs -> int`). An exception raised
//! there is kept in an [`ErrorSlot`] while the error travels up through the loop as a Rust error with its
//! context; `train` then raises the original exception with that context added as a note. Ctrl-C is noticed at
//! every environment step (`check_signals`), so it interrupts training as a `KeyboardInterrupt`.

use arld::env::{self, Env, EnvError, EnvSpec, Outcome};
use arld::expert::demos::{DemoColumns, Demonstrations};
use arld::expert::{self, Expert};
use arld::nn::QNet;
use arld::rng::NumpyRng;
use arld::state::Persist;
use arld::train::{
    self, Checkpointer, ConfigInput, Control, Driver, EvalPoint, PausedRun, QueryEvent, RunBuilder,
    RunLog, SeedPurpose, StepView, Summary, TrainConfig, seed_for,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rand::SeedableRng;
use rand_pcg::Pcg64;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::sync::{Arc, Mutex};

mod web;

/// The first Python exception raised during a call into the library, kept until the call returns.
#[derive(Clone, Default)]
struct ErrorSlot(Arc<Mutex<Option<PyErr>>>);

impl ErrorSlot {
    /// Keeps `err` (the first one wins) and returns its text for the Rust error.
    fn keep(&self, err: PyErr) -> String {
        let text = err.to_string();
        let mut slot = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if slot.is_none() {
            *slot = Some(err);
        }
        text
    }

    /// The Python exception to raise for a library error: the kept exception with the Rust context as a note,
    /// or `fallback` carrying the context.
    fn raise(&self, py: Python<'_>, err: anyhow::Error, fallback: fn(String) -> PyErr) -> PyErr {
        let context = arld::errors::error_line(&err);
        match self.0.lock().unwrap_or_else(|e| e.into_inner()).take() {
            Some(original) => {
                let note = format!("arld: {context}");
                // add_note exists from Python 3.11 on; older versions still get the original exception.
                let _ = original.value(py).call_method1("add_note", (note,));
                original
            }
            None => fallback(context),
        }
    }
}

fn value_error(msg: String) -> PyErr {
    PyValueError::new_err(msg)
}

fn runtime_error(msg: String) -> PyErr {
    PyRuntimeError::new_err(msg)
}

/// A Python environment behind the library's [`Env`] trait.
struct PyEnv {
    obj: Py<PyAny>,
    spec: &'static EnvSpec,
    errors: ErrorSlot,
    /// The last `reset` raised: the next step reports it (the trait's `reset` cannot fail).
    reset_failed: Option<String>,
}

impl PyEnv {
    fn error(&self, msg: String) -> EnvError {
        EnvError::External {
            env: self.spec.id.to_string(),
            msg,
        }
    }

    fn checked_obs(&self, obs: Vec<f32>) -> Result<Vec<f32>, String> {
        if obs.len() != self.spec.obs_dim {
            return Err(format!(
                "the observation has {} values, but the environment declared {}",
                obs.len(),
                self.spec.obs_dim
            ));
        }
        Ok(obs)
    }
}

impl Env for PyEnv {
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut [f32]) {
        let result = Python::attach(|py| {
            self.obj
                .call_method1(py, "reset", (seed,))
                .and_then(|o| o.extract::<Vec<f32>>(py))
                .map_err(|e| self.errors.keep(e))
        })
        .and_then(|obs| self.checked_obs(obs));
        match result {
            Ok(first) => {
                self.reset_failed = None;
                obs.copy_from_slice(&first);
            }
            Err(msg) => {
                self.reset_failed = Some(format!("reset failed: {msg}"));
                obs.fill(0.0);
            }
        }
    }

    fn step_into(&mut self, action: usize, obs: &mut [f32]) -> Result<Outcome, EnvError> {
        if let Some(msg) = &self.reset_failed {
            return Err(self.error(msg.clone()));
        }
        let result = Python::attach(|py| {
            py.check_signals()?;
            let out = self.obj.call_method1(py, "step", (action,))?;
            out.extract::<(Vec<f32>, f64, bool, bool)>(py)
        });
        let (next, reward, terminated, truncated) =
            result.map_err(|e| self.error(self.errors.keep(e)))?;
        let next = self.checked_obs(next).map_err(|m| self.error(m))?;
        obs.copy_from_slice(&next);
        Ok(Outcome {
            reward,
            terminated,
            truncated,
        })
    }

    fn spec(&self) -> &'static EnvSpec {
        self.spec
    }

    /// The generator of a Gymnasium environment (`np_random`, NumPy's PCG64), through the bridge's
    /// `generator()`; `None` when it has none or another kind.
    fn generator(&self) -> Option<NumpyRng> {
        Python::attach(|py| {
            self.obj
                .call_method0(py, "generator")
                .and_then(|w| w.extract::<Option<[u64; 6]>>(py))
                .ok()
                .flatten()
                .map(NumpyRng::from_words)
        })
    }

    fn set_generator(&mut self, rng: Option<NumpyRng>) {
        if let Some(rng) = rng {
            Python::attach(|py| {
                if let Err(e) = self
                    .obj
                    .call_method1(py, "set_generator", (rng.to_words(),))
                {
                    self.errors.keep(e);
                }
            });
        }
    }
}

/// A Python callable `obs -> int` as an [`Expert`].
struct PyExpert {
    call: Py<PyAny>,
    name: String,
    n_actions: usize,
    errors: ErrorSlot,
}

impl Expert for PyExpert {
    fn act(&mut self, obs: &[f32]) -> anyhow::Result<usize> {
        let answer = Python::attach(|py| {
            self.call
                .call1(py, (obs.to_vec(),))
                .and_then(|a| a.extract::<i64>(py))
                .map_err(|e| self.errors.keep(e))
        })
        .map_err(|msg| anyhow::anyhow!("it raised {msg}"))?;
        if !(0..self.n_actions as i64).contains(&answer) {
            let msg = format!(
                "it answered action {answer}, but the environment has {} actions (0 to {})",
                self.n_actions,
                self.n_actions.saturating_sub(1)
            );
            // Raised as a ValueError from `learn` (a bad value from the caller's code).
            self.errors.keep(PyValueError::new_err(msg.clone()));
            anyhow::bail!(msg);
        }
        Ok(answer as usize)
    }
    fn describe(&self) -> String {
        format!("python:{}", self.name)
    }
}

/// Registers a Python environment's facts so configurations can name it; returns nothing, fails on a clash.
#[pyfunction]
#[pyo3(signature = (id, obs_dim, n_actions, max_episode_steps, reward_threshold=None))]
fn register_env(
    id: &str,
    obs_dim: usize,
    n_actions: usize,
    max_episode_steps: usize,
    reward_threshold: Option<f64>,
) -> PyResult<()> {
    env::register(id, obs_dim, n_actions, max_episode_steps, reward_threshold)
        .map(|_| ())
        .map_err(|e| value_error(e.to_string()))
}

/// The ids of the built-in environments.
#[pyfunction]
fn builtin_env_ids() -> Vec<&'static str> {
    env::known_ids()
}

/// Every configuration key (the CLI's `--set` keys), in order.
#[pyfunction]
fn config_keys() -> Vec<String> {
    TrainConfig::valid_keys()
}

/// Resolves a configuration (the paper's preset, then `values` as JSON texts) and returns it as JSON text.
#[pyfunction]
fn resolve_config(
    env: &str,
    method: &str,
    net: &str,
    seed: u64,
    values: Vec<(String, String)>,
) -> PyResult<String> {
    let cfg =
        resolve(env, method, net, seed, &values).map_err(|e| value_error(format!("{e:#}")))?;
    serde_json::to_string(&cfg).map_err(|e| runtime_error(e.to_string()))
}

fn resolve(
    env: &str,
    method: &str,
    net: &str,
    seed: u64,
    values: &[(String, String)],
) -> anyhow::Result<TrainConfig> {
    let mut input = ConfigInput::new(env, method.parse()?, net.parse()?, seed);
    for (key, json) in values {
        let value: serde_json::Value = serde_json::from_str(json)?;
        input.set(key, toml_value(key, value)?)?;
    }
    input.resolve()
}

/// A Python value (as JSON) as the configuration's TOML value: a number, boolean, string, or a list of them.
fn toml_value(key: &str, value: serde_json::Value) -> anyhow::Result<toml::Value> {
    Ok(match value {
        serde_json::Value::Bool(b) => toml::Value::Boolean(b),
        serde_json::Value::String(s) => toml::Value::String(s),
        serde_json::Value::Number(n) if n.is_i64() => {
            toml::Value::Integer(n.as_i64().expect("checked"))
        }
        serde_json::Value::Number(n) => toml::Value::Float(n.as_f64().unwrap_or(f64::NAN)),
        serde_json::Value::Array(items) => toml::Value::Array(
            items
                .into_iter()
                .map(|v| toml_value(key, v))
                .collect::<anyhow::Result<_>>()?,
        ),
        other => {
            anyhow::bail!("`{key}`: a number, boolean, string or list is needed, got {other}")
        }
    })
}

/// A trained network acting with the test policy (no exploration), or, when it comes from a run, also with
/// the run's exploration policy at the step it stands at.
#[pyclass(module = "arld._arld")]
struct Policy {
    net: QNet,
    q: Vec<f32>,
    /// The exploring agent (its own generator, so asking it never changes the run) and ε.
    explorer: Option<(Box<arld::agent::Agent>, f64)>,
}

impl Policy {
    fn new(net: QNet) -> Self {
        let q = vec![0.0; net.heads() * net.n_actions()];
        Self {
            net,
            q,
            explorer: None,
        }
    }

    /// A policy that also explores as the run `cfg` does at step `step`.
    fn exploring(net: QNet, cfg: &TrainConfig, step: usize) -> Self {
        let rng = Pcg64::seed_from_u64(seed_for(cfg.seed, SeedPurpose::Agent) ^ step as u64);
        let agent = arld::agent::Agent::from_network(&cfg.agent_config(), net.clone(), rng);
        let eps = train::epsilon_at(cfg, step);
        Self {
            explorer: Some((Box::new(agent), eps)),
            ..Self::new(net)
        }
    }
}

#[pymethods]
impl Policy {
    /// The test policy's action for one observation.
    fn act(&mut self, obs: Vec<f32>) -> PyResult<usize> {
        if obs.len() != self.net.obs_dim() {
            return Err(value_error(format!(
                "the observation has {} values, but the network takes {}",
                obs.len(),
                self.net.obs_dim()
            )));
        }
        Ok(arld::agent::test_policy_action(
            &self.net,
            &mut self.q,
            &obs,
        ))
    }

    /// The exploration policy's action (ε-greedy with the run's current ε, the episode's bootstrap head, the
    /// noisy layer's sampled noise); `episode_start` begins a new episode (a new head, new noise).
    fn explore(&mut self, obs: Vec<f32>, episode_start: bool) -> PyResult<usize> {
        if obs.len() != self.net.obs_dim() {
            return Err(value_error(format!(
                "the observation has {} values, but the network takes {}",
                obs.len(),
                self.net.obs_dim()
            )));
        }
        match &mut self.explorer {
            None => Err(value_error(
                "this policy has no exploration (loaded weights, not a run): use deterministic=True".into(),
            )),
            Some((agent, eps)) => {
                if episode_start {
                    agent.begin_episode();
                }
                Ok(agent.act(&obs, *eps, arld::query::Needs::NOTHING).0)
            }
        }
    }

    /// The network's kind: "plain", "bootstrap" or "noisy".
    #[getter]
    fn net(&self) -> &'static str {
        match self.net.kind() {
            arld::nn::OutputKind::Plain => "plain",
            arld::nn::OutputKind::Bootstrap { .. } => "bootstrap",
            _ => "noisy",
        }
    }

    /// Saves the weights (safetensors) with `meta` as metadata.
    fn save(&self, path: &str, meta: std::collections::BTreeMap<String, String>) -> PyResult<()> {
        self.net
            .save(Path::new(path), &meta)
            .map_err(|e| runtime_error(format!("{e:#}")))
    }

    /// Loads weights saved by `save` (or by `arld train`); returns the policy and the file's metadata.
    #[staticmethod]
    fn load(path: &str) -> PyResult<(Policy, std::collections::BTreeMap<String, String>)> {
        let (net, meta) = QNet::load(Path::new(path))
            .map_err(|e| value_error(format!("cannot load {path}: {e:#}")))?;
        Ok((Policy::new(net), meta.into_iter().collect()))
    }

    #[getter]
    fn obs_dim(&self) -> usize {
        self.net.obs_dim()
    }

    #[getter]
    fn n_actions(&self) -> usize {
        self.net.n_actions()
    }
}

/// A built-in environment (`arld.make`), stepped from Python.
#[pyclass(module = "arld._arld", unsendable)]
struct BuiltinEnv {
    env: Box<dyn Env>,
}

#[pymethods]
impl BuiltinEnv {
    #[new]
    fn new(id: &str) -> PyResult<Self> {
        let env = env::make(id).map_err(|e| value_error(e.to_string()))?;
        Ok(Self { env })
    }
    #[pyo3(signature = (seed=None))]
    fn reset(&mut self, seed: Option<u64>) -> Vec<f32> {
        self.env.reset(seed)
    }
    fn step(&mut self, action: usize) -> PyResult<(Vec<f32>, f64, bool, bool)> {
        let s = self
            .env
            .step(action)
            .map_err(|e| value_error(e.to_string()))?;
        Ok((s.obs, s.reward, s.terminated, s.truncated))
    }
    /// (id, obs_dim, n_actions, max_episode_steps, reward_threshold)
    #[getter]
    fn spec(&self) -> (&'static str, usize, usize, usize, f64) {
        let s = self.env.spec();
        (
            s.id,
            s.obs_dim,
            s.n_actions,
            s.max_episode_steps,
            s.solve_threshold,
        )
    }
}

/// A command from Python to a run's thread.
enum Command {
    /// Train until step `until`, calling `callback` after every step.
    Advance {
        until: usize,
        callback: Option<Py<PyAny>>,
    },
    /// Write the run's snapshot into this directory.
    Snapshot(std::path::PathBuf),
    /// End the run.
    Stop,
}

/// Where a paused (or finished) run stands, sent to Python.
struct Pause {
    net: QNet,
    curve: Vec<EvalPoint>,
    queries: Vec<QueryEvent>,
    summary: Summary,
    /// The run ended (by error, or stopped): it cannot go on.
    finished: bool,
}

/// A report from a run's thread.
enum Report {
    Paused(Box<Pause>),
    Saved(Result<(), String>),
    Failed(anyhow::Error),
}

/// The driver of a run in its own thread: trains until the step Python asked for, then pauses and waits there
/// (the whole run alive) for the next command.
struct Remote {
    until: usize,
    callback: Option<Py<PyAny>>,
    commands: Receiver<Command>,
    reports: Sender<Report>,
    interrupt: Arc<AtomicBool>,
    step: Arc<AtomicUsize>,
    errors: ErrorSlot,
}

impl Remote {
    /// Python's callback after a step: anything but `False` goes on.
    fn call_back(&self, at: &StepView<'_>) -> anyhow::Result<bool> {
        let Some(cb) = &self.callback else {
            return Ok(true);
        };
        let last_eval = at.log.curve().last().map(|p| (p.step, p.mean));
        Python::attach(|py| {
            let answer = cb.call1(
                py,
                (
                    at.step,
                    at.episode,
                    at.budget_used,
                    at.log.query_events().len(),
                    last_eval,
                ),
            )?;
            let stop = answer
                .bind(py)
                .is(pyo3::types::PyBool::new(py, false).to_owned());
            Ok(!stop)
        })
        .map_err(|e: PyErr| anyhow::anyhow!("the callback raised {}", self.errors.keep(e)))
    }
}

impl Driver for Remote {
    fn after_step(&mut self, at: &StepView<'_>) -> anyhow::Result<Control> {
        self.step.store(at.step, Ordering::Relaxed);
        if !self.call_back(at)? || self.interrupt.load(Ordering::Relaxed) || at.step >= self.until {
            return Ok(Control::Pause);
        }
        Ok(Control::Continue)
    }

    fn paused(&mut self, run: &mut PausedRun<'_>) -> anyhow::Result<Control> {
        let pause = Pause {
            net: run.agent.network().clone(),
            curve: run.log.curve().to_vec(),
            queries: run.log.query_events().to_vec(),
            summary: run.summary.clone(),
            finished: false,
        };
        if self.reports.send(Report::Paused(Box::new(pause))).is_err() {
            return Ok(Control::Stop);
        }
        loop {
            match self.commands.recv() {
                Ok(Command::Advance { until, callback }) => {
                    (self.until, self.callback) = (until, callback);
                    return Ok(Control::Continue);
                }
                Ok(Command::Snapshot(dir)) => {
                    let saved = run.snapshot(&dir).map_err(|e| format!("{e:#}"));
                    if self.reports.send(Report::Saved(saved)).is_err() {
                        return Ok(Control::Stop);
                    }
                }
                Ok(Command::Stop) | Err(_) => return Ok(Control::Stop),
            }
        }
    }
}

/// One training run, alive in its own thread between `learn` calls: `advance` trains it to a step and returns
/// where it stands; the run goes on from there at the next `advance`, exactly as if it had not paused.
#[pyclass(module = "arld._arld")]
struct Run {
    commands: Sender<Command>,
    reports: Mutex<Receiver<Report>>,
    interrupt: Arc<AtomicBool>,
    step: Arc<AtomicUsize>,
    errors: ErrorSlot,
    cfg: TrainConfig,
    last: Option<Box<Pause>>,
    started: bool,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Run {
    fn drop(&mut self) {
        let _ = self.commands.send(Command::Stop);
    }
}

impl Run {
    /// Waits for the thread's next report, with the GIL released; Ctrl-C pauses the run and is raised once it
    /// has paused. `progress(step)` is called every tenth of a second.
    fn wait(&mut self, py: Python<'_>, progress: Option<&Py<PyAny>>) -> PyResult<Report> {
        let mut interrupted: Option<PyErr> = None;
        loop {
            let got = py.detach(|| {
                let reports = self.reports.lock().unwrap_or_else(|e| e.into_inner());
                reports.recv_timeout(std::time::Duration::from_millis(100))
            });
            match got {
                Ok(Report::Failed(e)) => {
                    if let Some(p) = self.last.as_mut() {
                        p.finished = true;
                    }
                    return Err(self.errors.raise(py, e, runtime_error));
                }
                Ok(report) => {
                    if let Some(e) = interrupted {
                        if let Report::Paused(p) = report {
                            self.last = Some(p);
                        }
                        return Err(e);
                    }
                    return Ok(report);
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(runtime_error("the run's thread ended unexpectedly".into()));
                }
                Err(RecvTimeoutError::Timeout) => {
                    if let Err(e) = py.check_signals() {
                        self.interrupt.store(true, Ordering::Relaxed);
                        interrupted.get_or_insert(e);
                    }
                    if let Some(p) = progress {
                        p.call1(py, (self.step.load(Ordering::Relaxed),))?;
                    }
                }
            }
        }
    }
}

#[pymethods]
impl Run {
    /// Trains until environment step `until` (at least one step), calling `callback(step, episode, budget_used,
    /// queries, last_eval)` after every step (`False` pauses the run there) and `progress(step)` every tenth of
    /// a second. Returns `(steps_done, paused_by_callback)`.
    #[pyo3(signature = (until, callback=None, progress=None))]
    fn advance(
        &mut self,
        py: Python<'_>,
        until: usize,
        callback: Option<Py<PyAny>>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<usize> {
        if self.last.as_ref().is_some_and(|p| p.finished) {
            return Err(runtime_error(
                "this run has ended (an error stopped it); start a new one with learn(...)".into(),
            ));
        }
        self.interrupt.store(false, Ordering::Relaxed);
        self.commands
            .send(Command::Advance { until, callback })
            .map_err(|_| runtime_error("the run's thread has ended".into()))?;
        self.started = true;
        match self.wait(py, progress.as_ref())? {
            Report::Paused(p) => {
                let steps = p.summary.train_steps;
                self.last = Some(p);
                Ok(steps)
            }
            _ => Err(runtime_error("unexpected report from the run".into())),
        }
    }

    /// Writes the run's full snapshot (network, optimiser, replay, query state, generators) into `dir`.
    fn snapshot(&mut self, py: Python<'_>, dir: &str) -> PyResult<()> {
        if !self.started {
            return Err(runtime_error(
                "the run has not started: call learn() first".into(),
            ));
        }
        self.commands
            .send(Command::Snapshot(dir.into()))
            .map_err(|_| runtime_error("the run's thread has ended".into()))?;
        match self.wait(py, None)? {
            Report::Saved(r) => r.map_err(runtime_error),
            _ => Err(runtime_error("unexpected report from the run".into())),
        }
    }

    /// Ends the run (its thread finishes the log) and waits for the thread.
    fn close(&mut self, py: Python<'_>) {
        let _ = self.commands.send(Command::Stop);
        if let Some(t) = self.thread.take() {
            py.detach(|| {
                let _ = t.join();
            });
        }
    }

    /// The current policy (a copy of the network, with the exploration of training at step `step`).
    fn policy(&self) -> PyResult<Policy> {
        let p = self.require()?;
        Ok(Policy::exploring(
            p.net.clone(),
            &self.cfg,
            p.summary.train_steps,
        ))
    }

    /// The evaluations so far: dicts of step, mean, std, min, max.
    fn evaluations(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        let list = PyList::empty(py);
        for p in &self.require()?.curve {
            let d = PyDict::new(py);
            d.set_item("step", p.step)?;
            d.set_item("mean", p.mean)?;
            d.set_item("std", p.std)?;
            d.set_item("min", p.min)?;
            d.set_item("max", p.max)?;
            list.append(d)?;
        }
        Ok(list.unbind())
    }

    /// The queries so far: dicts of step, episode, uncertainty, threshold, expert_action, agent_action.
    fn queries(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        let list = PyList::empty(py);
        for q in &self.require()?.queries {
            let d = PyDict::new(py);
            d.set_item("step", q.step)?;
            d.set_item("episode", q.episode)?;
            d.set_item("uncertainty", q.uncertainty)?;
            d.set_item("threshold", q.threshold)?;
            d.set_item("expert_action", q.expert_action)?;
            d.set_item("agent_action", q.agent_action)?;
            list.append(d)?;
        }
        Ok(list.unbind())
    }

    /// The summary so far, as JSON text.
    fn summary(&self) -> PyResult<String> {
        serde_json::to_string(&self.require()?.summary).map_err(|e| runtime_error(e.to_string()))
    }

    /// Environment steps done.
    #[getter]
    fn num_timesteps(&self) -> usize {
        self.step.load(Ordering::Relaxed)
    }
}

impl Run {
    fn require(&self) -> PyResult<&Pause> {
        self.last
            .as_deref()
            .ok_or_else(|| runtime_error("the run has not trained yet: call learn() first".into()))
    }
}

/// Starts a training run in its own thread (it waits for `Run.advance`): the configuration as JSON text (from
/// `resolve_config`), the environments (Python objects, or `None` for the built-in one of the configuration's
/// id; `test_envs` one per test episode, stepped in lockstep), the expert (a Python callable, or `None` to
/// build the configuration's expert spec), demonstrations as arrays of rows (or `None` to collect them from the
/// expert on `demo_env`, or on the built-in environment), a run directory, and a snapshot file to continue from.
#[pyfunction]
#[pyo3(signature = (config, env=None, test_envs=None, expert=None, expert_name=String::new(), demos=None, log_dir=None, resume=None, demo_env=None))]
#[allow(clippy::too_many_arguments)]
fn start_run(
    py: Python<'_>,
    config: &str,
    env: Option<Py<PyAny>>,
    test_envs: Option<Vec<Py<PyAny>>>,
    expert: Option<Py<PyAny>>,
    expert_name: String,
    demos: Option<DemoArrays>,
    log_dir: Option<String>,
    resume: Option<String>,
    demo_env: Option<Py<PyAny>>,
) -> PyResult<Run> {
    let errors = ErrorSlot::default();
    let cfg: TrainConfig = serde_json::from_str(config).map_err(|e| value_error(e.to_string()))?;
    let (commands_tx, commands_rx) = channel();
    let (reports_tx, reports_rx) = channel();
    let interrupt = Arc::new(AtomicBool::new(false));
    let step = Arc::new(AtomicUsize::new(0));
    let mut remote = Remote {
        until: 0,
        callback: None,
        commands: commands_rx,
        reports: reports_tx.clone(),
        interrupt: interrupt.clone(),
        step: step.clone(),
        errors: errors.clone(),
    };
    // A person's page is built here, where Python can be asked about the environment (its frames, its keys),
    // and the run waits for the page to open before its thread starts.
    let spec = env::spec(&cfg.env).map_err(|e| value_error(e.to_string()))?;
    let web_expert = match &expert {
        Some(call) => {
            let keep = {
                let errors = errors.clone();
                move |e| errors.keep(e)
            };
            web::expert(
                call.bind(py),
                env.as_ref().map(|e| e.bind(py)),
                spec,
                keep,
                interrupt.clone(),
            )
            .map_err(|e| errors.raise(py, e, runtime_error))?
        }
        None => None,
    };
    let thread_cfg = cfg.clone();
    let thread_errors = errors.clone();
    let body = move || -> anyhow::Result<()> {
        let cfg = thread_cfg;
        let errors = thread_errors;
        // Wait for the first command: the run starts on the first `advance`.
        match remote.commands.recv() {
            Ok(Command::Advance { until, callback }) => {
                (remote.until, remote.callback) = (until, callback)
            }
            _ => return Ok(()),
        }
        let make = |obj: Option<Py<PyAny>>| -> anyhow::Result<Box<dyn Env>> {
            Ok(match obj {
                Some(obj) => Box::new(PyEnv {
                    obj,
                    spec,
                    errors: errors.clone(),
                    reset_failed: None,
                }),
                None => env::make(&cfg.env)?,
            })
        };
        let env = make(env)?;
        let test_envs = match test_envs {
            Some(objs) => objs
                .into_iter()
                .map(|obj| make(Some(obj)))
                .collect::<anyhow::Result<Vec<_>>>()?,
            None => (0..cfg.eval_episodes)
                .map(|_| make(None))
                .collect::<anyhow::Result<Vec<_>>>()?,
        };
        let mut expert: Option<Box<dyn Expert>> = match (web_expert, expert) {
            (Some(web), _) => Some(web),
            (None, Some(call)) => Some(Box::new(PyExpert {
                call,
                name: expert_name,
                n_actions: spec.n_actions,
                errors: errors.clone(),
            })),
            (None, None) if cfg.expert_used().is_some() => Some(expert::from_spec(
                &cfg.expert,
                &cfg.env,
                seed_for(cfg.seed, SeedPurpose::Expert),
                cfg.expert_timeout,
            )?),
            (None, None) => None,
        };
        let resume_state = match &resume {
            None => None,
            Some(path) => {
                // The snapshot machinery reads `snapshot.safetensors` in a directory: a private copy there.
                let dir = tempfile::tempdir()?;
                std::fs::copy(path, dir.path().join(train::snapshot::SNAPSHOT_FILE))?;
                let mut ck = Checkpointer::new(dir.path(), &cfg);
                ck.load()?
            }
        };
        let demos = match (cfg.method.pretrains(), demos) {
            (false, _) => None,
            (true, _) if resume_state.is_some() => None,
            (true, Some(d)) => Some(d.into_demonstrations(&cfg)?),
            (true, None) => {
                let e = expert
                    .as_deref_mut()
                    .expect("methods that pre-train need an expert");
                let mut demo_env = make(demo_env)?;
                Some(Demonstrations::collect_in(
                    demo_env.as_mut(),
                    e,
                    cfg.n_demo,
                    seed_for(cfg.seed, SeedPurpose::Demonstrations),
                )?)
            }
        };
        let mut log = match &log_dir {
            Some(dir) => RunLog::create(
                Path::new(dir),
                &cfg.to_toml(),
                cfg.train_steps as u64,
                false,
            )?,
            None => RunLog::in_memory(),
        };
        RunBuilder::new(&cfg)
            .env(env)
            .test_envs(test_envs)
            .expert(expert.as_mut().map(|e| &mut **e as &mut dyn Expert))
            .demos(demos.as_ref())
            .driver(&mut remote)
            .resume_from(resume_state.as_ref())
            .train(&mut log)?;
        Ok(())
    };
    let thread = std::thread::Builder::new()
        .name("arld-run".into())
        .spawn(move || {
            if let Err(e) = body() {
                let _ = reports_tx.send(Report::Failed(e));
            }
        })
        .map_err(|e| runtime_error(e.to_string()))?;
    Ok(Run {
        commands: commands_tx,
        reports: Mutex::new(reports_rx),
        interrupt,
        step,
        errors,
        cfg,
        last: None,
        started: false,
        thread: Some(thread),
    })
}

/// The network of a run's snapshot file, acting (and exploring) as the run did at its step; returns the policy,
/// the configuration as JSON text and the step.
#[pyfunction]
fn snapshot_policy(path: &str) -> PyResult<(Policy, String, usize)> {
    let read = || -> anyhow::Result<(Policy, String, usize)> {
        let text = train::snapshot::recorded_config(Path::new(path))?;
        let cfg: TrainConfig = toml::from_str(&text)?;
        let spec = env::spec(&cfg.env)?;
        let dir = tempfile::tempdir()?;
        std::fs::copy(path, dir.path().join(train::snapshot::SNAPSHOT_FILE))?;
        let state = Checkpointer::new(dir.path(), &cfg)
            .load()?
            .ok_or_else(|| anyhow::anyhow!("no snapshot"))?;
        let mut agent =
            arld::agent::Agent::new(&cfg.agent_config(), spec.obs_dim, spec.n_actions, 0);
        agent.load_state("agent", &state)?;
        let st: serde_json::Value = state.value("loop")?;
        let step = st["step"].as_u64().unwrap_or(0) as usize;
        let policy = Policy::exploring(agent.network().clone(), &cfg, step);
        Ok((policy, serde_json::to_string(&cfg)?, step))
    };
    read().map_err(|e| value_error(format!("cannot load {path}: {e:#}")))
}

/// The configuration a snapshot file recorded, as JSON text (`None` when the file is plain weights).
#[pyfunction]
fn snapshot_config(path: &str) -> PyResult<Option<String>> {
    match train::snapshot::recorded_config(Path::new(path)) {
        Err(_) => Ok(None),
        Ok(text) => {
            let cfg: TrainConfig = toml::from_str(&text).map_err(|e| {
                value_error(format!("{path}: its configuration cannot be read: {e}"))
            })?;
            serde_json::to_string(&cfg)
                .map(Some)
                .map_err(|e| runtime_error(e.to_string()))
        }
    }
}

/// Demonstrations given as rows: (obs, action, reward, next_obs, terminated) per transition, in episode order.
#[derive(FromPyObject)]
struct DemoArrays {
    obs: Vec<Vec<f32>>,
    actions: Vec<usize>,
    rewards: Vec<f32>,
    next_obs: Vec<Vec<f32>>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
}

impl DemoArrays {
    /// The library's [`DemoColumns`], checked and read into demonstrations there.
    fn into_demonstrations(self, cfg: &TrainConfig) -> anyhow::Result<Demonstrations> {
        let columns = DemoColumns {
            obs: self.obs,
            actions: self.actions,
            rewards: self.rewards,
            next_obs: self.next_obs,
            terminated: self.terminated,
            truncated: self.truncated,
        };
        Demonstrations::from_columns(&cfg.env, columns)
    }
}

#[pymodule]
fn _arld(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // The library's version and the git commit it was built from (`arld.__version__`, `_arld.git_commit`).
    m.add("__version__", arld::VERSION)?;
    m.add("git_commit", arld::GIT_COMMIT)?;
    m.add_function(wrap_pyfunction!(register_env, m)?)?;
    m.add_function(wrap_pyfunction!(builtin_env_ids, m)?)?;
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
