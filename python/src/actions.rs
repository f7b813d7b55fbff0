//! The two kinds of action as they cross to Python and back ([`PyAction`]): a discrete index, or a list of floats
//! in a box; what a run of each kind needs besides (its built-in tasks, its experts from a spec, its demonstrations).

use crate::records::Records;
use arld_core::env::{self, Env, EnvError};
use arld_core::expert::Expert;
use arld_core::expert::demos::DemoAction;
use arld_core::expert::process::WireAction;
use arld_core::train::{QueryEvent, SeedPurpose, TrainConfig, seed_for};
use pyo3::prelude::*;

/// The actions of demonstrations given in Python: one integer per transition, or one row of numbers (a box).
#[derive(FromPyObject)]
pub(crate) enum DemoActions {
    Indices(Vec<usize>),
    Vectors(Vec<Vec<f32>>),
}

/// A kind of action as it crosses to Python and back, and what a run of that kind needs besides (its built-in
/// environments, its experts from a spec, its demonstrations).
pub(crate) trait PyAction: DemoAction {
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
        // The check a process expert's answer passes (in the box's bounds): one rule for every expert.
        <Vec<f32> as WireAction>::check_answer(&answer, spec)
            .map_err(|m| format!("it answered {answer:?}: {m}"))?;
        Ok(answer)
    }

    fn builtin(id: &str) -> anyhow::Result<Box<dyn Env<Vec<f32>>>> {
        Ok(env::make_box(id)?)
    }

    fn spec_expert(cfg: &TrainConfig) -> anyhow::Result<Box<dyn Expert<Vec<f32>>>> {
        arld_core::expert::boxed::from_spec(
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
