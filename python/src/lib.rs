//! `arld._arld`: the Python bindings of the `arld` library. This crate only converts between Python objects and
//! the library's types and calls the library; the Python package `arld` (in `arld/__init__.py`) gives it the
//! interface a Stable-Baselines3 user expects.
//!
//! The training loop is the library's ([`arld::train::train_in`]). Python is called back only to step an
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
use arld::train::{self, ConfigInput, RunLog, SeedPurpose, TrainConfig, seed_for};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::Path;
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
        let context = format!("{err:#}");
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

    /// A Python environment keeps its generator to itself: runs from Python take no snapshots.
    fn generator(&self) -> Option<NumpyRng> {
        None
    }

    fn set_generator(&mut self, _rng: Option<NumpyRng>) {}
}

/// A built-in environment that lets Ctrl-C through at every step.
struct Interruptible {
    inner: Box<dyn Env>,
    errors: ErrorSlot,
}

impl Env for Interruptible {
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut [f32]) {
        self.inner.reset_into(seed, obs)
    }
    fn step_into(&mut self, action: usize, obs: &mut [f32]) -> Result<Outcome, EnvError> {
        if let Err(e) = Python::attach(|py| py.check_signals()) {
            return Err(EnvError::External {
                env: self.inner.id().to_string(),
                msg: self.errors.keep(e),
            });
        }
        self.inner.step_into(action, obs)
    }
    fn spec(&self) -> &'static EnvSpec {
        self.inner.spec()
    }
    fn generator(&self) -> Option<NumpyRng> {
        self.inner.generator()
    }
    fn set_generator(&mut self, rng: Option<NumpyRng>) {
        self.inner.set_generator(rng)
    }
    fn geometry(&self) -> Option<env::Geometry> {
        self.inner.geometry()
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
                "it answered action {answer}, but the environment has {} actions (0..{})",
                self.n_actions, self.n_actions
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
        let value = match value {
            serde_json::Value::Bool(b) => toml::Value::Boolean(b),
            serde_json::Value::String(s) => toml::Value::String(s),
            serde_json::Value::Number(n) if n.is_i64() => {
                toml::Value::Integer(n.as_i64().expect("checked"))
            }
            serde_json::Value::Number(n) => toml::Value::Float(n.as_f64().unwrap_or(f64::NAN)),
            other => anyhow::bail!("`{key}`: a number, boolean or string is needed, got {other}"),
        };
        input.set(key, value)?;
    }
    input.resolve()
}

/// A trained network acting with the test policy (no exploration).
#[pyclass(module = "arld._arld")]
struct Policy {
    net: QNet,
    q: Vec<f32>,
}

impl Policy {
    fn new(net: QNet) -> Self {
        let q = vec![0.0; net.heads() * net.n_actions()];
        Self { net, q }
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

/// One training run: the configuration as JSON text (from `resolve_config`), the environments (Python objects,
/// or `None` for the built-in one of the configuration's id; `test_envs` one per test episode, stepped in
/// lockstep), the expert (a Python callable, or `None` to build
/// the configuration's expert spec), demonstrations as arrays of rows (or `None` to collect them from the
/// expert). Returns the trained policy, the evaluations, the queries and the summary as JSON text.
#[pyfunction(name = "train")]
#[pyo3(signature = (config, env=None, test_envs=None, expert=None, expert_name=String::new(), demos=None, log_dir=None, progress=false))]
#[allow(clippy::too_many_arguments)]
fn train_run(
    py: Python<'_>,
    config: &str,
    env: Option<Py<PyAny>>,
    test_envs: Option<Vec<Py<PyAny>>>,
    expert: Option<Py<PyAny>>,
    expert_name: String,
    demos: Option<DemoArrays>,
    log_dir: Option<String>,
    progress: bool,
) -> PyResult<(Policy, Py<PyList>, Py<PyList>, String)> {
    let errors = ErrorSlot::default();
    let run = || -> anyhow::Result<_> {
        let cfg: TrainConfig = serde_json::from_str(config)?;
        cfg.validate()?;
        let spec = env::spec(&cfg.env)?;
        let make = |obj: Option<Py<PyAny>>| -> anyhow::Result<Box<dyn Env>> {
            Ok(match obj {
                Some(obj) => Box::new(PyEnv {
                    obj,
                    spec,
                    errors: errors.clone(),
                    reset_failed: None,
                }),
                None => Box::new(Interruptible {
                    inner: env::make(&cfg.env)?,
                    errors: errors.clone(),
                }),
            })
        };
        let web_env = env.as_ref().map(|e| e.clone_ref(py));
        let mut env = make(env)?;
        let test_envs = match test_envs {
            Some(objs) => objs
                .into_iter()
                .map(|obj| make(Some(obj)))
                .collect::<anyhow::Result<Vec<_>>>()?,
            None => (0..cfg.eval_episodes)
                .map(|_| make(None))
                .collect::<anyhow::Result<Vec<_>>>()?,
        };
        let keep = {
            let errors = errors.clone();
            move |e| errors.keep(e)
        };
        let mut expert: Option<Box<dyn Expert>> = match expert {
            Some(call) => match web::expert(
                call.bind(py),
                web_env.as_ref().map(|e| e.bind(py)),
                spec,
                keep,
            )? {
                Some(web) => Some(web),
                None => Some(Box::new(PyExpert {
                    call,
                    name: expert_name,
                    n_actions: spec.n_actions,
                    errors: errors.clone(),
                })),
            },
            None if cfg.method.needs_expert() => Some(expert::from_spec(
                &cfg.expert,
                &cfg.env,
                seed_for(cfg.seed, SeedPurpose::Expert),
                cfg.expert_timeout,
            )?),
            None => None,
        };
        let demos = match (cfg.method.pretrains(), demos) {
            (false, _) => None,
            (true, Some(d)) => Some(d.into_demonstrations(&cfg)?),
            (true, None) => {
                let e = expert
                    .as_deref_mut()
                    .expect("methods that pre-train need an expert");
                let mut demo_env = make(None).or_else(|_| {
                    anyhow::bail!(
                        "{} pre-trains on demonstrations: give them as `demos=` (a Python environment cannot \
                         be copied to collect them)",
                        cfg.method
                    )
                })?;
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
                progress,
            )?,
            None => RunLog::in_memory_with_progress(cfg.train_steps as u64, progress),
        };
        let (summary, agent) = train::train_in(
            &cfg,
            env.as_mut(),
            test_envs,
            expert.as_mut().map(|e| &mut **e as &mut dyn Expert),
            demos.as_ref(),
            &mut log,
        )?;
        Ok((summary, agent, log))
    };
    let (summary, agent, log) = run().map_err(|e| errors.raise(py, e, runtime_error))?;
    let evaluations = PyList::empty(py);
    for p in log.curve() {
        let d = PyDict::new(py);
        d.set_item("step", p.step)?;
        d.set_item("mean", p.mean)?;
        d.set_item("std", p.std)?;
        d.set_item("min", p.min)?;
        d.set_item("max", p.max)?;
        evaluations.append(d)?;
    }
    let queries = PyList::empty(py);
    for q in log.query_events() {
        let d = PyDict::new(py);
        d.set_item("step", q.step)?;
        d.set_item("episode", q.episode)?;
        d.set_item("uncertainty", q.uncertainty)?;
        d.set_item("threshold", q.threshold)?;
        d.set_item("expert_action", q.expert_action)?;
        d.set_item("agent_action", q.agent_action)?;
        queries.append(d)?;
    }
    let summary = serde_json::to_string(&summary).map_err(|e| runtime_error(e.to_string()))?;
    Ok((
        Policy::new(agent.network().clone()),
        evaluations.unbind(),
        queries.unbind(),
        summary,
    ))
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
    m.add_function(wrap_pyfunction!(train_run, m)?)?;
    m.add_class::<Policy>()?;
    m.add_class::<BuiltinEnv>()?;
    m.add_class::<web::PyWebExpert>()?;
    Ok(())
}
