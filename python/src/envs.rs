//! Environments: a Python (Gymnasium) environment behind the library's `Env` trait ([`PyEnv`]), the registration of
//! a Python task's facts, and the built-in tasks stepped from Python ([`BuiltinEnv`], `arld.make`).

use crate::actions::PyAction;
use crate::errors::{ErrorSlot, value_error};
use arld_core::env::{self, Env, EnvError, Outcome, TaskSpec};
use arld_core::rng::NumpyRng;
use pyo3::prelude::*;
use std::sync::Mutex;

/// A Python environment behind the library's [`Env`] trait, for actions of the kind `A`.
pub(crate) struct PyEnv<A: PyAction> {
    pub(crate) obj: Py<PyAny>,
    pub(crate) spec: &'static A::Spec,
    pub(crate) errors: ErrorSlot,
    /// Why the last `reset` failed: the loop takes it after an episode's reset (and pauses when the environment
    /// raised); otherwise the next step reports it (the trait's `reset` cannot fail).
    pub(crate) reset_failed: Option<EnvError>,
}

impl<A: PyAction> PyEnv<A> {
    pub(crate) fn error(&self, msg: String) -> EnvError {
        EnvError::External {
            env: self.spec.id().to_string(),
            msg,
        }
    }

    pub(crate) fn checked_obs(&self, obs: Vec<f32>) -> Result<Vec<f32>, String> {
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

/// Registers a Python environment's facts so configurations can name it; returns nothing, fails on a clash.
#[pyfunction]
#[pyo3(signature = (id, obs_dim, n_actions, max_episode_steps, reward_threshold=None))]
pub(crate) fn register_env(
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
pub(crate) fn register_box_env(
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
pub(crate) fn is_box_env(id: &str) -> bool {
    env::box_spec(id).is_ok()
}

/// The bounds `(low, high)` of the actions of a task with actions in a box (built in or registered); `None` for
/// a task arld does not know with actions in a box.
#[pyfunction]
pub(crate) fn box_bounds(id: &str) -> Option<(Vec<f32>, Vec<f32>)> {
    env::box_spec(id)
        .ok()
        .map(|spec| (spec.action_low.to_vec(), spec.action_high.to_vec()))
}

/// The ids of the built-in environments: the tasks of discrete actions, then those with actions in a box.
#[pyfunction]
pub(crate) fn builtin_env_ids() -> Vec<&'static str> {
    let mut ids = env::known_ids();
    ids.extend(env::continuous::known_continuous_ids());
    ids
}

/// A built-in environment (`arld.make`), stepped from Python (also from a run's thread, when wrapped): a task of
/// discrete actions or one with actions in a box.
#[pyclass(module = "arld._arld")]
pub(crate) struct BuiltinEnv {
    /// In a mutex only to be shared between threads (Python's and a run's); the methods take `&mut self`.
    pub(crate) env: Mutex<BuiltinKind>,
}

/// The two kinds of built-in task, side by side.
pub(crate) enum BuiltinKind {
    Discrete(Box<dyn Env>),
    Box(Box<dyn Env<Vec<f32>>>),
}

/// A built-in task's actions as Python sees them: their number, or the box's bounds.
#[derive(IntoPyObject)]
pub(crate) enum BuiltinActions {
    Count(usize),
    Bounds(Vec<f32>, Vec<f32>),
}

impl BuiltinEnv {
    pub(crate) fn env_mut(&mut self) -> &mut BuiltinKind {
        self.env.get_mut().unwrap_or_else(|e| e.into_inner())
    }
}

#[pymethods]
impl BuiltinEnv {
    #[new]
    fn new(id: &str) -> PyResult<Self> {
        let kind = match env::make(id) {
            Ok(env) => BuiltinKind::Discrete(env),
            Err(discrete) => match env::make_box(id) {
                Ok(env) => BuiltinKind::Box(env),
                Err(_) => return Err(value_error(discrete.to_string())),
            },
        };
        Ok(Self {
            env: Mutex::new(kind),
        })
    }
    #[pyo3(signature = (seed=None))]
    fn reset(&mut self, seed: Option<u64>) -> Vec<f32> {
        match self.env_mut() {
            BuiltinKind::Discrete(env) => env.reset(seed),
            BuiltinKind::Box(env) => env.reset(seed),
        }
    }
    /// One step with `action`: an int, or a list of floats in the box (Gymnasium clips an action outside it).
    fn step(&mut self, action: &Bound<'_, PyAny>) -> PyResult<(Vec<f32>, f64, bool, bool)> {
        let s = match self.env_mut() {
            BuiltinKind::Discrete(env) => env.step(action.extract::<usize>()?),
            BuiltinKind::Box(env) => env.step(&action.extract::<Vec<f32>>()?),
        }
        .map_err(|e| value_error(e.to_string()))?;
        Ok((s.obs, s.reward, s.terminated, s.truncated))
    }
    /// (id, obs_dim, actions: their number or the box's (low, high), max_episode_steps, reward_threshold)
    #[getter]
    fn spec(&self) -> (&'static str, usize, BuiltinActions, usize, Option<f64>) {
        match &*self.env.lock().unwrap_or_else(|e| e.into_inner()) {
            BuiltinKind::Discrete(env) => {
                let s = env.spec();
                (
                    s.id,
                    s.obs_dim,
                    BuiltinActions::Count(s.n_actions),
                    s.max_episode_steps,
                    Some(s.solve_threshold),
                )
            }
            BuiltinKind::Box(env) => {
                let s = env.spec();
                (
                    s.id,
                    s.obs_dim,
                    BuiltinActions::Bounds(s.action_low.to_vec(), s.action_high.to_vec()),
                    s.max_episode_steps,
                    s.solve_threshold,
                )
            }
        }
    }
}
