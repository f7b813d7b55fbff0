//! `arld._arld`: the Python bindings of the `arld` library. This crate only converts between Python objects and
//! the library's types and calls the library; the Python package `arld` (in `arld/__init__.py`) gives it the
//! interface a Stable-Baselines3 user expects.
//!
//! The training loop is the library's ([`arld::train::RunBuilder`]). Python is called back only to step an
//! environment ([`PyEnv`]: any object with `reset(seed) -> list[float]` and `step(action) -> (obs, reward,
//! terminated, truncated)`) and to ask an expert ([`PyExpert`]: a callable `obs -> action`). Both are generic over
//! the kind of action ([`PyAction`]): a discrete index (the DQN family learns) or a list of floats in a box (TD3
//! learns, [`BoxAgent`]); a run's kind follows from its task's registration (`register_env` or
//! `register_box_env`). An exception raised
//! there is kept in an [`ErrorSlot`]. An exception from an expert or a callback pauses the run whole (the
//! expert's question stays open and is asked again when the run goes on); `advance` then raises the original
//! exception with a note saying where the run paused. An exception from the environment ends the run (its state
//! in the middle of a step is unknown) and is raised with the loop's context as a note. Ctrl-C is noticed at
//! every environment step (`check_signals`), so it interrupts training as a `KeyboardInterrupt`.
//!
//! A callback runs on the run's thread after a step; while it runs, the live agent and log are lent to it
//! ([`Lent`]), so `Run.live_actions`, `Run.live_policy` and the evaluations and queries it reads are those of that
//! step, without a copy per step. A `save` inside a callback is written at a pause right after the callback
//! returns (the run's replay and generators are reachable only there); the run then goes on by itself.

use arld::agent::actor_file::{ActorKind, TrainedActor};
use arld::agent::box_agent::BoxAgent;
use arld::agent::{Agent, Learner};
use arld::env::{self, Action, Env, EnvError, Outcome, TaskSpec};
use arld::expert::Expert;
use arld::expert::demos::{DemoAction, DemoColumns, Demonstrations};
use arld::interrupt::Interrupted;
use arld::nn::QNet;
use arld::rng::NumpyRng;
use arld::train::{
    self, Checkpointer, ConfigInput, Control, Driver, EvalPoint, PausedRun, QueryEvent, RunBuilder,
    RunLog, SeedPurpose, StepView, Summary, TrainConfig, seed_for,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rand::SeedableRng;
use rand_pcg::Pcg64;
use std::cell::Cell;
use std::path::Path;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
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

    /// The kept exception with `note` added (Python 3.11 on), if one is kept.
    fn take_with_note(&self, py: Python<'_>, note: &str) -> Option<PyErr> {
        let original = self.0.lock().unwrap_or_else(|e| e.into_inner()).take()?;
        let _ = original.value(py).call_method1("add_note", (note,));
        Some(original)
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

/// A kind of action as it crosses to Python and back, and what a run of that kind needs besides (its built-in
/// environments, its experts from a spec, its demonstrations).
trait PyAction: DemoAction {
    /// The action as the Python environment's `step` is given it: an int, or a list of floats (the Python side
    /// shapes it as its space).
    fn to_py<'py>(py: Python<'py>, action: Self::Ref<'_>) -> PyResult<Bound<'py, PyAny>>;
    /// An expert's answer (made a Python int, or a flat list of floats, by the Python side), checked against
    /// `spec`; the error says what is wrong.
    fn answer(obj: &Bound<'_, PyAny>, spec: &Self::Spec) -> Result<Self, String>;
    /// The built-in task `id` of this kind.
    fn builtin(id: &str) -> anyhow::Result<Box<dyn Env<Self>>>;
    /// The expert of the configuration's spec (`cfg.expert`), for a run without a Python expert.
    fn spec_expert(cfg: &TrainConfig) -> anyhow::Result<Box<dyn Expert<Self>>>;
    /// The queries of a run of this kind, kept for Python.
    fn records(events: &[QueryEvent<Self>]) -> Records;
    /// The registered facts of the task `id` of this kind.
    fn spec_of(id: &str) -> Result<&'static Self::Spec, EnvError>;
    /// The actions of demonstrations given in Python, as actions of this kind; the error says why they are not.
    fn demo_actions(actions: DemoActions) -> anyhow::Result<Vec<Self>>;
}

impl PyAction for usize {
    fn to_py<'py>(py: Python<'py>, action: usize) -> PyResult<Bound<'py, PyAny>> {
        Ok(action.into_pyobject(py)?.into_any())
    }

    fn answer(obj: &Bound<'_, PyAny>, spec: &env::EnvSpec) -> Result<usize, String> {
        let answer = obj.extract::<i64>().map_err(|e| e.to_string())?;
        if !(0..spec.n_actions as i64).contains(&answer) {
            return Err(format!(
                "it answered action {answer}, but the environment has {} actions (0 to {})",
                spec.n_actions,
                spec.n_actions.saturating_sub(1)
            ));
        }
        Ok(answer as usize)
    }

    fn builtin(id: &str) -> anyhow::Result<Box<dyn Env>> {
        Ok(env::make(id)?)
    }

    fn spec_expert(cfg: &TrainConfig) -> anyhow::Result<Box<dyn Expert>> {
        arld_web::from_spec(
            &cfg.expert,
            &cfg.env,
            seed_for(cfg.seed, SeedPurpose::Expert),
            cfg.expert_timeout,
        )
    }

    fn records(events: &[QueryEvent]) -> Records {
        Records::Discrete(events.to_vec())
    }

    fn spec_of(id: &str) -> Result<&'static env::EnvSpec, EnvError> {
        env::spec(id)
    }

    fn demo_actions(actions: DemoActions) -> anyhow::Result<Vec<usize>> {
        match actions {
            DemoActions::Indices(actions) => Ok(actions),
            DemoActions::Vectors(_) => anyhow::bail!(
                "the demonstrations' actions are vectors, but the environment's actions are discrete: give one \
                 integer action per transition"
            ),
        }
    }
}

impl PyAction for Vec<f32> {
    fn to_py<'py>(py: Python<'py>, action: &[f32]) -> PyResult<Bound<'py, PyAny>> {
        Ok(action.into_pyobject(py)?.into_any())
    }

    fn answer(obj: &Bound<'_, PyAny>, spec: &env::BoxSpec) -> Result<Vec<f32>, String> {
        let answer = obj.extract::<Vec<f32>>().map_err(|e| e.to_string())?;
        Vec::<f32>::check(&answer, spec).map_err(|m| format!("it answered {answer:?}: {m}"))?;
        Ok(answer)
    }

    fn builtin(id: &str) -> anyhow::Result<Box<dyn Env<Vec<f32>>>> {
        Ok(env::make_box(id)?)
    }

    fn spec_expert(cfg: &TrainConfig) -> anyhow::Result<Box<dyn Expert<Vec<f32>>>> {
        arld::expert::boxed::from_spec(
            &cfg.expert,
            env::box_spec(&cfg.env)?,
            seed_for(cfg.seed, SeedPurpose::Expert),
            cfg.expert_timeout,
        )
    }

    fn records(events: &[QueryEvent<Vec<f32>>]) -> Records {
        Records::Box(events.to_vec())
    }

    fn spec_of(id: &str) -> Result<&'static env::BoxSpec, EnvError> {
        env::box_spec(id)
    }

    fn demo_actions(actions: DemoActions) -> anyhow::Result<Vec<Vec<f32>>> {
        match actions {
            DemoActions::Vectors(actions) => Ok(actions),
            // No transitions at all extract as the first kind.
            DemoActions::Indices(actions) if actions.is_empty() => Ok(Vec::new()),
            DemoActions::Indices(_) => anyhow::bail!(
                "the demonstrations' actions are single numbers, but the environment's actions are in a box: \
                 give one row of numbers per transition"
            ),
        }
    }
}

/// A run's queries as Python reads them, of either kind of action.
#[derive(Clone)]
enum Records {
    Discrete(Vec<QueryEvent>),
    Box(Vec<QueryEvent<Vec<f32>>>),
}

impl Records {
    /// Appends every query to `list` as a dict.
    fn fill(&self, py: Python<'_>, list: &Bound<'_, PyList>) -> PyResult<()> {
        match self {
            Records::Discrete(events) => events
                .iter()
                .try_for_each(|q| list.append(query_dict(py, q)?)),
            Records::Box(events) => events
                .iter()
                .try_for_each(|q| list.append(query_dict(py, q)?)),
        }
    }
}

/// A Python environment behind the library's [`Env`] trait, for actions of the kind `A`.
struct PyEnv<A: PyAction> {
    obj: Py<PyAny>,
    spec: &'static A::Spec,
    errors: ErrorSlot,
    /// Why the last `reset` failed: the loop takes it after an episode's reset (and pauses when the environment
    /// raised); otherwise the next step reports it (the trait's `reset` cannot fail).
    reset_failed: Option<EnvError>,
}

impl<A: PyAction> PyEnv<A> {
    fn error(&self, msg: String) -> EnvError {
        EnvError::External {
            env: self.spec.id().to_string(),
            msg,
        }
    }

    fn checked_obs(&self, obs: Vec<f32>) -> Result<Vec<f32>, String> {
        if obs.len() != self.spec.obs_dim() {
            return Err(format!(
                "the observation has {} values, but the environment declared {}",
                obs.len(),
                self.spec.obs_dim()
            ));
        }
        Ok(obs)
    }
}

impl<A: PyAction> Env<A> for PyEnv<A> {
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut [f32]) {
        let result = Python::attach(|py| {
            self.obj
                .call_method1(py, "reset", (seed,))
                .and_then(|o| o.extract::<Vec<f32>>(py))
                .map_err(|e| EnvError::Raised {
                    env: self.spec.id().to_string(),
                    msg: format!("reset failed: {}", self.errors.keep(e)),
                })
        })
        .and_then(|obs| {
            self.checked_obs(obs)
                .map_err(|m| self.error(format!("reset failed: {m}")))
        });
        match result {
            Ok(first) => {
                self.reset_failed = None;
                obs.copy_from_slice(&first);
            }
            Err(err) => {
                self.reset_failed = Some(err);
                obs.fill(0.0);
            }
        }
    }

    fn take_reset_error(&mut self) -> Option<EnvError> {
        self.reset_failed.take()
    }

    fn step_into(&mut self, action: A::Ref<'_>, obs: &mut [f32]) -> Result<Outcome, EnvError> {
        // A failed reset that the loop did not take (the first one, or one while an episode is replayed) ends
        // the run.
        if let Some(err) = &self.reset_failed {
            return Err(self.error(format!("the last reset failed ({err})")));
        }
        let result = Python::attach(|py| {
            py.check_signals()?;
            let out = self
                .obj
                .call_method1(py, "step", (A::to_py(py, action)?,))?;
            out.extract::<(Vec<f32>, f64, bool, bool)>(py)
        });
        // An exception (the environment's own, or a value of the wrong type) pauses the run whole.
        let (next, reward, terminated, truncated) = result.map_err(|e| EnvError::Raised {
            env: self.spec.id().to_string(),
            msg: self.errors.keep(e),
        })?;
        let next = self.checked_obs(next).map_err(|m| self.error(m))?;
        obs.copy_from_slice(&next);
        Ok(Outcome {
            reward,
            terminated,
            truncated,
        })
    }

    fn spec(&self) -> &'static A::Spec {
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

/// A Python callable `obs -> action` as an [`Expert`] of actions of the kind `A`.
struct PyExpert<A: PyAction> {
    call: Py<PyAny>,
    name: String,
    spec: &'static A::Spec,
    errors: ErrorSlot,
}

impl<A: PyAction> Expert<A> for PyExpert<A> {
    fn act(&mut self, obs: &[f32]) -> anyhow::Result<A> {
        // An exception pauses the run whole with the question open (a stop, for the loop), so that the next
        // `learn` asks the same question again; `advance` raises the exception. A bad answer is raised as a
        // ValueError from `learn` (a bad value from the caller's code); the run pauses too.
        let answer = Python::attach(|py| {
            let answer = self.call.call1(py, (obs.to_vec(),)).map_err(|e| {
                let note = format!("arld: raised by the expert python:{}", self.name);
                let _ = e.value(py).call_method1("add_note", (note,));
                Interrupted(format!("the expert raised {}", self.errors.keep(e)))
            })?;
            A::answer(answer.bind(py), self.spec).map_err(|msg| {
                self.errors.keep(PyValueError::new_err(msg.clone()));
                Interrupted(msg)
            })
        })?;
        Ok(answer)
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

/// Registers the facts of a Python environment with actions in a box (`low`, `high`: the flattened bounds) so
/// configurations can name it; returns nothing, fails on a clash or bad bounds.
#[pyfunction]
#[pyo3(signature = (id, obs_dim, low, high, max_episode_steps, reward_threshold=None))]
fn register_box_env(
    id: &str,
    obs_dim: usize,
    low: Vec<f32>,
    high: Vec<f32>,
    max_episode_steps: usize,
    reward_threshold: Option<f64>,
) -> PyResult<()> {
    env::register_box(
        id,
        obs_dim,
        &low,
        &high,
        max_episode_steps,
        reward_threshold,
    )
    .map(|_| ())
    .map_err(|e| value_error(e.to_string()))
}

/// Whether `id` names a task with actions in a box (built in or registered).
#[pyfunction]
fn is_box_env(id: &str) -> bool {
    env::box_spec(id).is_ok()
}

/// The bounds `(low, high)` of the actions of a task with actions in a box (built in or registered); `None` for
/// a task arld does not know with actions in a box.
#[pyfunction]
fn box_bounds(id: &str) -> Option<(Vec<f32>, Vec<f32>)> {
    env::box_spec(id)
        .ok()
        .map(|spec| (spec.action_low.to_vec(), spec.action_high.to_vec()))
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
/// `preset_of`: the built-in task whose preset a wrapped or re-limited copy of it (`env`) takes; the values are
/// resolved as for that task, then the run is named `env`. `person`: the options of an `arld.WebExpert` as its spec
/// (`.spec`): in real time a question's segment lasts its seconds of play unless `segment_len` is given
/// ([`ConfigInput::real_time_segment`]).
#[pyfunction]
#[pyo3(signature = (env, method, net, seed, values, preset_of=None, person=None))]
fn resolve_config(
    env: &str,
    method: &str,
    net: &str,
    seed: u64,
    values: Vec<(String, String)>,
    preset_of: Option<&str>,
    person: Option<&str>,
) -> PyResult<String> {
    let cfg = resolve(env, method, net, seed, &values, preset_of, person)
        .map_err(|e| value_error(format!("{e:#}")))?;
    Ok(cfg.to_json())
}

fn resolve(
    env: &str,
    method: &str,
    net: &str,
    seed: u64,
    values: &[(String, String)],
    preset_of: Option<&str>,
    person: Option<&str>,
) -> anyhow::Result<TrainConfig> {
    let mut input = ConfigInput::new(
        preset_of.unwrap_or(env),
        method.parse()?,
        net.parse()?,
        seed,
    );
    for (key, json) in values {
        let value: serde_json::Value = serde_json::from_str(json)?;
        input.set(key, toml_value(key, value)?)?;
    }
    if let Some(steps) = person.and_then(|spec| input.real_time_segment(spec)) {
        input.set("segment_len", steps as i64)?;
    }
    let mut cfg = input.resolve()?;
    if preset_of.is_some() {
        cfg.env = env.to_string();
        cfg.validate()?;
    }
    Ok(cfg)
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

/// A weights file's metadata (the caller's keys).
type Metadata = std::collections::BTreeMap<String, String>;

/// The two kinds of weights file Python reads and writes: a DQN-family network and a TD3/SAC actor.
trait WeightsFile: Sized {
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
fn save_weights(weights: &impl WeightsFile, path: &str, meta: &Metadata) -> PyResult<()> {
    weights
        .save_file(Path::new(path), meta)
        .map_err(|e| runtime_error(format!("{e:#}")))
}

/// Reads the weights at `path`; a file that is not such weights is Python's ValueError, naming it.
fn load_weights<W: WeightsFile>(path: &str) -> PyResult<(W, Metadata)> {
    W::load_file(Path::new(path)).map_err(|e| value_error(format!("cannot load {path}: {e:#}")))
}

/// Refuses an observation of another length than the network's `inputs`.
fn check_obs(obs: &[f32], inputs: usize) -> PyResult<()> {
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
struct Policy {
    kind: PolicyKind,
}

/// The two families of policy, side by side.
enum PolicyKind {
    Q {
        net: Box<QNet>,
        q: Vec<f32>,
        /// The exploring agent (its own generator, so asking it never changes the run) and ε.
        explorer: Option<(Box<arld::agent::Agent>, f64)>,
    },
    Actor(TrainedActor),
}

/// An action as Python receives it: an int, or a list of floats for a box.
#[derive(IntoPyObject)]
enum PolicyAction {
    Index(usize),
    Vector(Vec<f32>),
}

impl Policy {
    fn of_net(net: QNet) -> Self {
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
    fn exploring(net: QNet, cfg: &TrainConfig, step: usize) -> Self {
        let rng = Pcg64::seed_from_u64(seed_for(cfg.seed, SeedPurpose::Agent) ^ step as u64);
        let agent = arld::agent::Agent::from_network(&cfg.agent_config(), net.clone(), rng);
        let eps = train::epsilon_at(cfg, step);
        let mut policy = Self::of_net(net);
        if let PolicyKind::Q { explorer, .. } = &mut policy.kind {
            *explorer = Some((Box::new(agent), eps));
        }
        policy
    }

    /// The policy of a run's network.
    fn of_run(net: Net, cfg: &TrainConfig, step: usize) -> Self {
        match net {
            Net::Q(net) => Self::exploring(*net, cfg, step),
            Net::Actor(actor) => Self {
                kind: PolicyKind::Actor(*actor),
            },
        }
    }

    /// The observation's length the policy takes, after checking that `obs` has it.
    fn check(&self, obs: &[f32]) -> PyResult<()> {
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
                PolicyAction::Index(arld::agent::test_policy_action(net, q, &obs))
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
                    agent.act(&obs, *eps, arld::query::Needs::NOTHING).0,
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
                arld::nn::OutputKind::Plain => "plain",
                arld::nn::OutputKind::Bootstrap { .. } => "bootstrap",
                _ => "noisy",
            },
            PolicyKind::Actor(actor) => actor.kind().learner(),
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
        let actor = arld::agent::actor_file::holds_an_actor(Path::new(path))
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
enum Net {
    Q(Box<QNet>),
    Actor(Box<TrainedActor>),
}

/// A built-in environment (`arld.make`), stepped from Python (also from a run's thread, when wrapped).
#[pyclass(module = "arld._arld")]
struct BuiltinEnv {
    /// In a mutex only to be shared between threads (Python's and a run's); the methods take `&mut self`.
    env: Mutex<Box<dyn Env>>,
}

impl BuiltinEnv {
    fn env_mut(&mut self) -> &mut dyn Env {
        self.env
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .as_mut()
    }
}

#[pymethods]
impl BuiltinEnv {
    #[new]
    fn new(id: &str) -> PyResult<Self> {
        let env = env::make(id).map_err(|e| value_error(e.to_string()))?;
        Ok(Self {
            env: Mutex::new(env),
        })
    }
    #[pyo3(signature = (seed=None))]
    fn reset(&mut self, seed: Option<u64>) -> Vec<f32> {
        self.env_mut().reset(seed)
    }
    fn step(&mut self, action: usize) -> PyResult<(Vec<f32>, f64, bool, bool)> {
        let s = self
            .env_mut()
            .step(action)
            .map_err(|e| value_error(e.to_string()))?;
        Ok((s.obs, s.reward, s.terminated, s.truncated))
    }
    /// (id, obs_dim, n_actions, max_episode_steps, reward_threshold)
    #[getter]
    fn spec(&self) -> (&'static str, usize, usize, usize, f64) {
        let s = self.env.lock().unwrap_or_else(|e| e.into_inner()).spec();
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
    /// Write the run's snapshot into this file.
    Snapshot(PathBuf),
    /// End the run.
    Stop,
}

/// Where a paused (or finished) run stands, sent to Python.
struct Pause {
    net: Net,
    curve: Vec<EvalPoint>,
    queries: Records,
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

/// What `Run::wait` saw: a pause at a step, or a snapshot written (or why not).
enum Waited {
    Paused(usize),
    Saved(Result<(), String>),
}

/// The live agent and log of a run, lent to a callback while it runs on the run's thread.
#[derive(Clone, Copy)]
enum LentParts {
    Discrete(*const Agent, *const RunLog),
    Box(*const BoxAgent, *const RunLog<Vec<f32>>),
}

/// The live agent and log of a run, borrowed for the length of a call from its callback.
enum LentRef<'a> {
    Discrete(&'a Agent, &'a RunLog),
    Box(&'a BoxAgent, &'a RunLog<Vec<f32>>),
}

impl LentRef<'_> {
    fn curve(&self) -> &[EvalPoint] {
        match self {
            LentRef::Discrete(_, log) => log.curve(),
            LentRef::Box(_, log) => log.curve(),
        }
    }
}

/// The live run lent to a callback while it runs on the run's thread: which run, its agent and its log.
type LentRun = (u64, LentParts);

thread_local! {
    /// Set only by [`Lent`], for the length of one callback call on the run's thread.
    static LENT: Cell<Option<LentRun>> = const { Cell::new(None) };
}

/// Lends a step's agent and log to the callback called while it lives (on this thread only).
struct Lent;

impl Lent {
    fn new(run: u64, parts: LentParts) -> Self {
        LENT.with(|l| l.set(Some((run, parts))));
        Lent
    }
}

impl Drop for Lent {
    fn drop(&mut self) {
        LENT.with(|l| l.set(None));
    }
}

/// `f` of the live agent and log of run `run`, when called from inside that run's callback; `None` otherwise.
fn with_lent<R>(run: u64, f: impl FnOnce(LentRef<'_>) -> R) -> Option<R> {
    let (id, parts) = LENT.with(|l| l.get())?;
    if id != run {
        return None;
    }
    // SAFETY: the pointers are set by `Lent` from the `StepView` of the callback call that is running on this
    // thread (thread-local, so no other thread sees them) and cleared when it returns; the loop holds only shared
    // borrows of the agent and the log meanwhile, so both are alive and unchanged while `f` reads them.
    Some(unsafe {
        match parts {
            LentParts::Discrete(agent, log) => f(LentRef::Discrete(&*agent, &*log)),
            LentParts::Box(agent, log) => f(LentRef::Box(&*agent, &*log)),
        }
    })
}

/// Whether this thread is inside a callback of any run (a run's thread, waiting for it).
fn in_callback() -> bool {
    LENT.with(|l| l.get()).is_some()
}

/// A learner that Python runs drive: how its run starts, how it is lent to a callback, and what Python keeps
/// of it at a pause.
trait PyLearner: Learner<Action: PyAction> + Sized + 'static {
    /// A run of `cfg` with this learner.
    fn builder(cfg: &TrainConfig) -> RunBuilder<'_, Self>;
    /// The agent and log as a callback borrows them.
    fn lend(agent: &Self, log: &RunLog<Self::Action>) -> LentParts;
    /// The network Python acts with, for the task `id`.
    fn net(&self, id: &str) -> Net;
    /// A learner of `cfg`'s shape, to load a snapshot's state into.
    fn for_snapshot(cfg: &TrainConfig) -> anyhow::Result<Self>;
}

impl PyLearner for Agent {
    fn builder(cfg: &TrainConfig) -> RunBuilder<'_, Self> {
        RunBuilder::new(cfg)
    }
    fn lend(agent: &Self, log: &RunLog) -> LentParts {
        LentParts::Discrete(agent as *const Agent, log as *const RunLog)
    }
    fn net(&self, _id: &str) -> Net {
        Net::Q(Box::new(self.network().clone()))
    }
    fn for_snapshot(cfg: &TrainConfig) -> anyhow::Result<Self> {
        let spec = env::spec(&cfg.env)?;
        Ok(Agent::new(
            &cfg.agent_config(),
            spec.obs_dim,
            spec.n_actions,
            0,
        ))
    }
}

impl PyLearner for BoxAgent {
    fn builder(cfg: &TrainConfig) -> RunBuilder<'_, Self> {
        RunBuilder::for_box(cfg)
    }
    fn lend(agent: &Self, log: &RunLog<Vec<f32>>) -> LentParts {
        LentParts::Box(agent as *const BoxAgent, log as *const RunLog<Vec<f32>>)
    }
    fn net(&self, id: &str) -> Net {
        let spec = env::box_spec(id).expect("a box run's task is registered");
        let kind = ActorKind::of_learner(self.learner_name())
            .expect("a box agent's learner is TD3 or SAC");
        Net::Actor(Box::new(TrainedActor::new(
            kind,
            self.actor().clone(),
            spec.action_low,
            spec.action_high,
        )))
    }
    fn for_snapshot(cfg: &TrainConfig) -> anyhow::Result<Self> {
        Ok(train::run::box_agent(cfg, env::box_spec(&cfg.env)?))
    }
}

/// Writes a paused run's snapshot into the file `path` (through a directory of its own, the snapshot's format).
fn write_snapshot<L: Learner>(run: &mut PausedRun<'_, L>, path: &Path) -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    run.snapshot(dir.path())?;
    std::fs::copy(dir.path().join(train::snapshot::SNAPSHOT_FILE), path)
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
    Ok(())
}

/// The driver of a run in its own thread: trains until the step Python asked for, then pauses and waits there
/// (the whole run alive) for the next command.
struct Remote {
    /// Which run (the key of what is lent to its callbacks).
    id: u64,
    until: usize,
    callback: Option<Py<PyAny>>,
    commands: Receiver<Command>,
    reports: Sender<Report>,
    interrupt: Arc<AtomicBool>,
    step: Arc<AtomicUsize>,
    errors: ErrorSlot,
    /// Files a callback asked the run's snapshot to be written to (`save` inside a callback).
    saves: Arc<Mutex<Vec<PathBuf>>>,
    /// The pause under way only writes `saves`: the run goes on by itself afterwards.
    only_saving: bool,
    /// The run's task.
    env_id: String,
}

impl Remote {
    /// Python's callback after a step, with the live run lent to it: anything but `False` goes on. An exception
    /// is kept (with a note of the step) and pauses the run.
    fn call_back<L: PyLearner>(&self, at: &StepView<'_, L>) -> bool {
        let Some(cb) = &self.callback else {
            return true;
        };
        let last_eval = at.log.curve().last().map(|p| (p.step, p.mean));
        let _lent = Lent::new(self.id, L::lend(at.agent, at.log));
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
            );
            match answer {
                Ok(answer) => !answer
                    .bind(py)
                    .is(pyo3::types::PyBool::new(py, false).to_owned()),
                Err(e) => {
                    let note = format!("arld: raised by a callback after step {}", at.step);
                    let _ = e.value(py).call_method1("add_note", (note,));
                    self.errors.keep(e);
                    false
                }
            }
        })
    }

    fn pending_saves(&self) -> Vec<PathBuf> {
        std::mem::take(&mut *self.saves.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

impl<L: PyLearner> Driver<L> for Remote {
    fn after_step(&mut self, at: &StepView<'_, L>) -> anyhow::Result<Control> {
        self.step.store(at.step, Ordering::Relaxed);
        let pause =
            !self.call_back(at) || self.interrupt.load(Ordering::Relaxed) || at.step >= self.until;
        if !pause
            && !self
                .saves
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .is_empty()
        {
            self.only_saving = true;
            return Ok(Control::Pause);
        }
        Ok(if pause {
            Control::Pause
        } else {
            Control::Continue
        })
    }

    fn paused(&mut self, run: &mut PausedRun<'_, L>) -> anyhow::Result<Control> {
        let mut failed = false;
        for path in self.pending_saves() {
            if let Err(e) = write_snapshot(run, &path) {
                let msg = format!("save() in a callback: {e:#}");
                Python::attach(|_| self.errors.keep(runtime_error(msg)));
                failed = true;
            }
        }
        if std::mem::take(&mut self.only_saving) && !failed {
            return Ok(Control::Continue);
        }
        // A person's page shows that the program has the run back, and why.
        let step = run.summary.train_steps;
        let note = if self.interrupt.load(Ordering::Relaxed) {
            format!(
                "The program stopped the run at step {step} (Ctrl-C or SIGTERM). Your answers are saved; if it \
                 goes on, an open question is asked again."
            )
        } else if step >= self.until {
            format!(
                "Training returned at step {step}: the program has the run back (it may train on)."
            )
        } else {
            format!("The program paused the run at step {step}.")
        };
        run.hand_over(&note);
        let pause = Pause {
            net: run.agent.net(&self.env_id),
            curve: run.log.curve().to_vec(),
            queries: L::Action::records(run.log.query_events()),
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
                Ok(Command::Snapshot(path)) => {
                    let saved = write_snapshot(run, &path).map_err(|e| format!("{e:#}"));
                    if self.reports.send(Report::Saved(saved)).is_err() {
                        return Ok(Control::Stop);
                    }
                }
                Ok(Command::Stop) | Err(_) => return Ok(Control::Stop),
            }
        }
    }
}

/// The next run's key.
static NEXT_RUN: AtomicU64 = AtomicU64::new(1);

/// One training run, alive in its own thread between `learn` calls: `advance` trains it to a step and returns
/// where it stands; the run goes on from there at the next `advance`, exactly as if it had not paused. Every
/// method takes `&self`, so a callback may call them while `advance` waits.
#[pyclass(module = "arld._arld")]
struct Run {
    id: u64,
    commands: Sender<Command>,
    reports: Mutex<Receiver<Report>>,
    interrupt: Arc<AtomicBool>,
    step: Arc<AtomicUsize>,
    errors: ErrorSlot,
    saves: Arc<Mutex<Vec<PathBuf>>>,
    cfg: TrainConfig,
    last: Mutex<Option<Box<Pause>>>,
    started: AtomicBool,
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
}

impl Drop for Run {
    fn drop(&mut self) {
        let _ = self.commands.send(Command::Stop);
    }
}

impl Run {
    /// Waits for the thread's next report, with the GIL released; Ctrl-C pauses the run and is raised once it
    /// has paused, as is an exception an expert or a callback raised. `progress(step)` is called every tenth of
    /// a second.
    fn wait(&self, py: Python<'_>, progress: Option<&Py<PyAny>>) -> PyResult<Waited> {
        let mut interrupted: Option<PyErr> = None;
        loop {
            let got = py.detach(|| {
                let reports = self.reports.lock().unwrap_or_else(|e| e.into_inner());
                reports.recv_timeout(std::time::Duration::from_millis(100))
            });
            match got {
                Ok(Report::Failed(e)) => {
                    if let Some(p) = self.last().as_mut() {
                        p.finished = true;
                    }
                    return Err(self.errors.raise(py, e, runtime_error));
                }
                Ok(Report::Paused(p)) => {
                    let step = p.summary.train_steps;
                    *self.last() = Some(p);
                    let note = format!(
                        "arld: the run paused whole after step {step} (network, replay, queries and budget kept; \
                         an open question is asked again): learn(..., reset_num_timesteps=False) goes on from there"
                    );
                    if let Some(e) = self.errors.take_with_note(py, &note) {
                        return Err(e);
                    }
                    return match interrupted {
                        Some(e) => Err(e),
                        None => Ok(Waited::Paused(step)),
                    };
                }
                Ok(Report::Saved(saved)) => {
                    return match interrupted {
                        Some(e) => Err(e),
                        None => Ok(Waited::Saved(saved)),
                    };
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

    fn last(&self) -> std::sync::MutexGuard<'_, Option<Box<Pause>>> {
        self.last.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// `f` of the last pause, or the error that the run has not trained yet.
    fn with_last<R>(&self, f: impl FnOnce(&Pause) -> R) -> PyResult<R> {
        self.last()
            .as_deref()
            .map(f)
            .ok_or_else(|| runtime_error("the run has not trained yet: call learn() first".into()))
    }

    fn refuse_in_callback(&self, what: &str) -> PyResult<()> {
        if in_callback() {
            return Err(runtime_error(format!(
                "{what} cannot be called from inside a callback (the run is waiting for it to return); return \
                 False to stop training there"
            )));
        }
        Ok(())
    }
}

fn eval_dict<'py>(py: Python<'py>, p: &EvalPoint) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("step", p.step)?;
    d.set_item("mean", p.mean)?;
    d.set_item("std", p.std)?;
    d.set_item("min", p.min)?;
    d.set_item("max", p.max)?;
    Ok(d)
}

fn query_dict<'py, A>(py: Python<'py>, q: &QueryEvent<A>) -> PyResult<Bound<'py, PyDict>>
where
    A: Action + for<'a> IntoPyObject<'a>,
{
    let d = PyDict::new(py);
    d.set_item("step", q.step)?;
    d.set_item("episode", q.episode)?;
    d.set_item("uncertainty", q.uncertainty)?;
    d.set_item("threshold", q.threshold)?;
    d.set_item("expert_action", q.expert_action.clone())?;
    d.set_item("agent_action", q.agent_action.clone())?;
    Ok(d)
}

#[pymethods]
impl Run {
    /// Trains until environment step `until` (at least one step), calling `callback(step, episode, budget_used,
    /// queries, last_eval)` after every step (`False` pauses the run there) and `progress(step)` every tenth of
    /// a second. Returns the steps done.
    #[pyo3(signature = (until, callback=None, progress=None))]
    fn advance(
        &self,
        py: Python<'_>,
        until: usize,
        callback: Option<Py<PyAny>>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<usize> {
        self.refuse_in_callback("learn()")?;
        if self.last().as_ref().is_some_and(|p| p.finished) {
            return Err(runtime_error(
                "this run has ended (an error stopped it); start a new one with learn(...)".into(),
            ));
        }
        self.interrupt.store(false, Ordering::Relaxed);
        self.commands
            .send(Command::Advance { until, callback })
            .map_err(|_| runtime_error("the run's thread has ended".into()))?;
        self.started.store(true, Ordering::Relaxed);
        match self.wait(py, progress.as_ref())? {
            Waited::Paused(step) => Ok(step),
            Waited::Saved(_) => Err(runtime_error("unexpected report from the run".into())),
        }
    }

    /// Writes the run's full snapshot (network, optimiser, replay, query state, generators) to the file `path`;
    /// inside a callback, at a pause right after the callback returns.
    fn save(&self, py: Python<'_>, path: &str) -> PyResult<()> {
        if with_lent(self.id, |_| ()).is_some() {
            self.saves
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(path.into());
            return Ok(());
        }
        self.refuse_in_callback("save() of another run")?;
        if !self.started.load(Ordering::Relaxed) {
            return Err(runtime_error(
                "the run has not started: call learn() first".into(),
            ));
        }
        self.commands
            .send(Command::Snapshot(path.into()))
            .map_err(|_| runtime_error("the run's thread has ended".into()))?;
        match self.wait(py, None)? {
            Waited::Saved(r) => r.map_err(runtime_error),
            Waited::Paused(_) => Err(runtime_error("unexpected report from the run".into())),
        }
    }

    /// Ends the run (its thread finishes the log) and waits for the thread.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        self.refuse_in_callback("a learn() that starts a new run")?;
        let _ = self.commands.send(Command::Stop);
        let thread = self.thread.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(t) = thread {
            py.detach(|| {
                let _ = t.join();
            });
        }
        Ok(())
    }

    /// The current policy (a copy of the network, with the exploration of training at its step): the live one
    /// inside a callback, the last pause's otherwise.
    fn policy(&self) -> PyResult<Policy> {
        if let Some(p) = self.live_policy() {
            return Ok(p);
        }
        let (net, step) = self.with_last(|p| (p.net.clone(), p.summary.train_steps))?;
        Ok(Policy::of_run(net, &self.cfg, step))
    }

    /// The live network as a policy, inside this run's callback; `None` elsewhere.
    fn live_policy(&self) -> Option<Policy> {
        let step = self.step.load(Ordering::Relaxed);
        with_lent(self.id, |lent| {
            let net = match lent {
                LentRef::Discrete(agent, _) => Net::Q(Box::new(agent.network().clone())),
                LentRef::Box(agent, _) => agent.net(&self.cfg.env),
            };
            Policy::of_run(net, &self.cfg, step)
        })
    }

    /// The live target network (as a policy), inside this run's callback of a DQN-family run; `None` elsewhere
    /// (TD3's targets follow by Polyak averaging and are not shown). It changes only at a target copy.
    fn live_target_policy(&self) -> Option<Policy> {
        let step = self.step.load(Ordering::Relaxed);
        with_lent(self.id, |lent| match lent {
            LentRef::Discrete(agent, _) => Some(Policy::exploring(
                agent.target_network().clone(),
                &self.cfg,
                step,
            )),
            LentRef::Box(..) => None,
        })
        .flatten()
    }

    /// The live network's test-policy actions for rows of observations (ints, or lists of floats for actions
    /// in a box), inside this run's callback; `None` elsewhere.
    fn live_actions(&self, py: Python<'_>, rows: Vec<Vec<f32>>) -> PyResult<Option<Py<PyAny>>> {
        let check = |obs: &[f32], dim: usize| {
            if obs.len() != dim {
                return Err(value_error(format!(
                    "the observation has {} values, but the network takes {dim}",
                    obs.len()
                )));
            }
            Ok(())
        };
        with_lent(self.id, |lent| match lent {
            LentRef::Discrete(agent, _) => {
                let net = agent.network();
                let mut q = vec![0.0; net.heads() * net.n_actions()];
                let actions = rows
                    .iter()
                    .map(|obs| {
                        check(obs, net.obs_dim())?;
                        Ok(arld::agent::test_policy_action(net, &mut q, obs))
                    })
                    .collect::<PyResult<Vec<usize>>>()?;
                Ok(actions.into_pyobject(py)?.into_any().unbind())
            }
            LentRef::Box(agent, _) => {
                let Net::Actor(mut actor) = agent.net(&self.cfg.env) else {
                    unreachable!("a box agent's network is an actor")
                };
                let actions = rows
                    .iter()
                    .map(|obs| {
                        check(obs, actor.obs_dim())?;
                        Ok(actor.act(obs))
                    })
                    .collect::<PyResult<Vec<Vec<f32>>>>()?;
                Ok(actions.into_pyobject(py)?.into_any().unbind())
            }
        })
        .transpose()
    }

    /// The evaluations so far (live inside a callback): dicts of step, mean, std, min, max.
    fn evaluations(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        let list = PyList::empty(py);
        let fill = |curve: &[EvalPoint]| {
            curve
                .iter()
                .try_for_each(|p| list.append(eval_dict(py, p)?))
        };
        match with_lent(self.id, |lent| fill(lent.curve())) {
            Some(filled) => filled?,
            None => self.with_last(|last| fill(&last.curve))??,
        }
        Ok(list.unbind())
    }

    /// The queries so far (live inside a callback): dicts of step, episode, uncertainty, threshold,
    /// expert_action, agent_action (ints, or lists of floats for actions in a box).
    fn queries(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        let list = PyList::empty(py);
        let live = with_lent(self.id, |lent| match lent {
            LentRef::Discrete(_, log) => usize::records(log.query_events()),
            LentRef::Box(_, log) => Vec::<f32>::records(log.query_events()),
        });
        match live {
            Some(records) => records.fill(py, &list)?,
            None => self.with_last(|last| last.queries.fill(py, &list))??,
        }
        Ok(list.unbind())
    }

    /// The summary at the last pause, as JSON text.
    fn summary(&self) -> PyResult<String> {
        self.with_last(|p| serde_json::to_string(&p.summary))?
            .map_err(|e| runtime_error(e.to_string()))
    }

    /// Environment steps done.
    #[getter]
    fn num_timesteps(&self) -> usize {
        self.step.load(Ordering::Relaxed)
    }

    /// ε of the run's exploration at its current step.
    #[getter]
    fn exploration_rate(&self) -> f64 {
        train::epsilon_at(&self.cfg, self.step.load(Ordering::Relaxed))
    }

    /// Whether this run's callback is running on this thread (the live run is lent to it).
    #[getter]
    fn in_callback(&self) -> bool {
        with_lent(self.id, |_| ()).is_some()
    }
}

/// Takes the lock of the run directory `dir` (created if missing), as `arld train` does: one process, and in it
/// one run, at a time. Refused naming the holder (and, when it is this process, how to end its run).
fn lock_run_dir(dir: &Path) -> anyhow::Result<arld::dir_lock::DirLock> {
    use arld::dir_lock::{DirLock, Holder};
    anyhow::ensure!(
        !dir.exists() || dir.is_dir(),
        "the run directory {} exists and is not a directory",
        dir.display()
    );
    std::fs::create_dir_all(dir)
        .map_err(|e| anyhow::anyhow!("cannot create the run directory {}: {e}", dir.display()))?;
    DirLock::acquire(dir, train::run_dir::LOCK_FILE).map_err(|e| {
        let holder = std::fs::read_to_string(dir.join(train::run_dir::LOCK_FILE))
            .ok()
            .and_then(|text| serde_json::from_str::<Holder>(&text).ok());
        match holder {
            Some(h) if h.pid == std::process::id() => e.context(
                "another Agent of this Python process runs in it; its close() ends that run",
            ),
            _ => e,
        }
    })
}

/// Starts a training run in its own thread (it waits for `Run.advance`): the configuration as JSON text (from
/// `resolve_config`) and what Python gives the run ([`RunRequest`]).
#[pyfunction]
fn start_run(py: Python<'_>, config: &str, request: RunRequest) -> PyResult<Run> {
    let errors = ErrorSlot::default();
    let cfg: TrainConfig = serde_json::from_str(config).map_err(|e| value_error(e.to_string()))?;
    let (commands_tx, commands_rx) = channel();
    let (reports_tx, reports_rx) = channel();
    let interrupt = Arc::new(AtomicBool::new(false));
    let step = Arc::new(AtomicUsize::new(0));
    let saves = Arc::new(Mutex::new(Vec::new()));
    let id = NEXT_RUN.fetch_add(1, Ordering::Relaxed);
    let mut remote = Remote {
        id,
        saves: saves.clone(),
        only_saving: false,
        until: 0,
        callback: None,
        commands: commands_rx,
        reports: reports_tx.clone(),
        interrupt: interrupt.clone(),
        step: step.clone(),
        errors: errors.clone(),
        env_id: cfg.env.clone(),
    };
    // A person's page is built here, where Python can be asked about the environment (its frames, its keys),
    // and the run waits for the page to open before its thread starts.
    let boxed = env::box_spec(&cfg.env).is_ok();
    let keep = {
        let errors = errors.clone();
        move |e| errors.keep(e)
    };
    let gym = request.env.as_ref().map(|e| e.bind(py));
    let (web_discrete, web_box) = match &request.expert {
        Some(call) if boxed => {
            let web =
                web::expert::<Vec<f32>>(call.bind(py), gym, &cfg.env, keep, interrupt.clone());
            (None, web.map_err(|e| errors.raise(py, e, runtime_error))?)
        }
        Some(call) => {
            let web = web::expert::<usize>(call.bind(py), gym, &cfg.env, keep, interrupt.clone());
            (web.map_err(|e| errors.raise(py, e, runtime_error))?, None)
        }
        None => (None, None),
    };
    // One process per run directory, as `arld train`: the lock is taken here (a second run is refused before
    // anything starts, naming the holder) and held by the run's thread until it ends.
    let lock = match &request.log_dir {
        Some(dir) => {
            Some(lock_run_dir(Path::new(dir)).map_err(|e| errors.raise(py, e, runtime_error))?)
        }
        None => None,
    };
    let inputs = RunInputs {
        cfg: cfg.clone(),
        request,
        errors: errors.clone(),
    };
    let body = move || -> anyhow::Result<()> {
        let _lock = lock;
        // Wait for the first command: the run starts on the first `advance`.
        match remote.commands.recv() {
            Ok(Command::Advance { until, callback }) => {
                (remote.until, remote.callback) = (until, callback)
            }
            _ => return Ok(()),
        }
        if boxed {
            train_in_thread::<BoxAgent>(inputs, &mut remote, web_box)
        } else {
            train_in_thread::<Agent>(inputs, &mut remote, web_discrete)
        }
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
        id,
        commands: commands_tx,
        reports: Mutex::new(reports_rx),
        interrupt,
        step,
        errors,
        saves,
        cfg,
        last: Mutex::new(None),
        started: AtomicBool::new(false),
        thread: Mutex::new(Some(thread)),
    })
}

/// What Python gives a run to train with (`start_run`'s second argument, a dict with every key): the
/// environments (Python objects, or `None` for the built-in one of the configuration's id; `test_envs` one per
/// test episode, stepped in lockstep), the expert (a Python callable, or `None` to build the configuration's
/// expert spec) and its name, demonstrations as arrays of rows (or `None` to collect them from the expert on
/// `demo_env`, or on the built-in environment), a run directory, and a snapshot file to continue from.
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
struct RunRequest {
    env: Option<Py<PyAny>>,
    test_envs: Option<Vec<Py<PyAny>>>,
    expert: Option<Py<PyAny>>,
    expert_name: String,
    demos: Option<DemoArrays>,
    log_dir: Option<String>,
    resume: Option<String>,
    demo_env: Option<Py<PyAny>>,
}

/// What a run's thread is given to train with (see [`start_run`]).
struct RunInputs {
    cfg: TrainConfig,
    request: RunRequest,
    errors: ErrorSlot,
}

/// Trains the run of `inputs` with the learner `L`, driven by `remote`, on the run's thread (after its first
/// command). `web_expert`: a person's page already built, which takes the place of the Python expert.
fn train_in_thread<L: PyLearner>(
    inputs: RunInputs,
    remote: &mut Remote,
    web_expert: Option<Box<dyn Expert<L::Action>>>,
) -> anyhow::Result<()> {
    let RunInputs {
        cfg,
        request,
        errors,
    } = inputs;
    let RunRequest {
        env,
        test_envs,
        expert,
        expert_name,
        demos,
        log_dir,
        resume,
        demo_env,
    } = request;
    let spec = L::Action::spec_of(&cfg.env)?;
    let make = |obj: Option<Py<PyAny>>| -> anyhow::Result<Box<dyn Env<L::Action>>> {
        Ok(match obj {
            Some(obj) => Box::new(PyEnv::<L::Action> {
                obj,
                spec,
                errors: errors.clone(),
                reset_failed: None,
            }),
            None => L::Action::builtin(&cfg.env)?,
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
    let mut expert: Option<Box<dyn Expert<L::Action>>> = match (web_expert, expert) {
        (Some(web), _) => Some(web),
        (None, Some(call)) => Some(Box::new(PyExpert::<L::Action> {
            call,
            name: expert_name,
            spec,
            errors: errors.clone(),
        })),
        (None, None) if cfg.expert_used().is_some() => Some(L::Action::spec_expert(&cfg)?),
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
    // Demonstrations given as rows, else the run's own (its demo_file, or collected from the expert on
    // `demo_env`): `train::run_demonstrations`, as for the command line.
    let demos = match demos {
        _ if resume_state.is_some() => None,
        Some(given) if cfg.method.pretrains() => {
            Some(given.into_demonstrations::<L::Action>(&cfg)?)
        }
        _ => train::run_demonstrations(
            &cfg,
            expert
                .as_mut()
                .map(|e| &mut **e as &mut dyn Expert<L::Action>),
            || make(demo_env),
        )?,
    };
    let mut log = train::open_log(
        log_dir.as_deref().map(Path::new),
        &cfg,
        resume_state.as_ref(),
        false,
    )?;
    L::builder(&cfg)
        .env(env)
        .test_envs(test_envs)
        .expert(
            expert
                .as_mut()
                .map(|e| &mut **e as &mut dyn Expert<L::Action>),
        )
        .demos(demos.as_ref())
        .driver(remote)
        .resume_from(resume_state.as_ref())
        .train(&mut log)?;
    Ok(())
}

/// What `snapshot_policy` returns: the policy, the configuration (JSON), the step, the evaluations (JSON), the
/// queries.
type SnapshotPolicy = (Policy, String, usize, String, Py<PyList>);

/// The network of a run's snapshot file, acting (and exploring) as the run did at its step; returns the policy,
/// the configuration as JSON text, the step and the run's evaluations so far (JSON text: step, mean, std, min,
/// max of each) and its queries so far (as [`Run::queries`]; none from a snapshot of an arld that did not keep
/// them).
#[pyfunction]
fn snapshot_policy(py: Python<'_>, path: &str) -> PyResult<SnapshotPolicy> {
    let read = || -> anyhow::Result<(Net, TrainConfig, usize, String, Records)> {
        let text = train::snapshot::recorded_config(Path::new(path))?;
        let cfg: TrainConfig = toml::from_str(&text)?;
        let dir = tempfile::tempdir()?;
        std::fs::copy(path, dir.path().join(train::snapshot::SNAPSHOT_FILE))?;
        let state = Checkpointer::new(dir.path(), &cfg)
            .load()?
            .ok_or_else(|| anyhow::anyhow!("no snapshot"))?;
        let st: serde_json::Value = state.value("loop")?;
        let step = st["step"].as_u64().unwrap_or(0) as usize;
        let (net, curve, queries) = if env::box_spec(&cfg.env).is_ok() {
            snapshot_parts::<BoxAgent>(&cfg, &state)?
        } else {
            snapshot_parts::<Agent>(&cfg, &state)?
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

/// The network, the evaluations (JSON text) and the queries of a run's snapshot `state`, for the learner `L`.
fn snapshot_parts<L: PyLearner>(
    cfg: &TrainConfig,
    state: &arld::state::StateDict<'_>,
) -> anyhow::Result<(Net, String, Records)> {
    let mut agent = L::for_snapshot(cfg)?;
    agent.load_state("agent", state)?;
    let position = train::resume_position::<L::Action>(state)?;
    Ok((
        agent.net(&cfg.env),
        serde_json::to_string(&position.curve)?,
        L::Action::records(&position.query_events),
    ))
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
            Ok(Some(cfg.to_json()))
        }
    }
}

/// Demonstrations given as rows: (obs, action, reward, next_obs, terminated) per transition, in episode order.
#[derive(FromPyObject)]
struct DemoArrays {
    obs: Vec<Vec<f32>>,
    actions: DemoActions,
    rewards: Vec<f32>,
    next_obs: Vec<Vec<f32>>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
}

/// The actions of demonstrations given in Python: one integer per transition, or one row of numbers (a box).
#[derive(FromPyObject)]
enum DemoActions {
    Indices(Vec<usize>),
    Vectors(Vec<Vec<f32>>),
}

impl DemoArrays {
    /// The library's [`DemoColumns`] of actions of the kind `A`, checked and read into demonstrations there.
    fn into_demonstrations<A: PyAction>(
        self,
        cfg: &TrainConfig,
    ) -> anyhow::Result<Demonstrations<A>> {
        let columns = DemoColumns {
            obs: self.obs,
            actions: A::demo_actions(self.actions)?,
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
    m.add_function(wrap_pyfunction!(register_box_env, m)?)?;
    m.add_function(wrap_pyfunction!(is_box_env, m)?)?;
    m.add_function(wrap_pyfunction!(box_bounds, m)?)?;
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
