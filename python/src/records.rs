//! A run's records as Python reads them: its queries ([`Records`], of either kind of action) and evaluations, as
//! dicts.

use arld_core::env::Action;
use arld_core::train::{EvalPoint, QueryEvent};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// A run's queries as Python reads them, of either kind of action.
#[derive(Clone)]
pub(crate) enum Records {
    Discrete(Vec<QueryEvent>),
    Box(Vec<QueryEvent<Vec<f32>>>),
}

impl Records {
    /// Appends every query to `list` as a dict.
    pub(crate) fn fill(&self, py: Python<'_>, list: &Bound<'_, PyList>) -> PyResult<()> {
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

pub(crate) fn eval_dict<'py>(py: Python<'py>, p: &EvalPoint) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("step", p.step)?;
    d.set_item("mean", p.mean)?;
    d.set_item("std", p.std)?;
    d.set_item("min", p.min)?;
    d.set_item("max", p.max)?;
    Ok(d)
}

pub(crate) fn query_dict<'py, A>(py: Python<'py>, q: &QueryEvent<A>) -> PyResult<Bound<'py, PyDict>>
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
