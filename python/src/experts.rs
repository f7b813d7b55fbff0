//! A Python callable `obs -> action` as the library's expert ([`PyExpert`]).

use crate::actions::PyAction;
use crate::errors::ErrorSlot;
use arld_core::expert::Expert;
use arld_core::interrupt::Interrupted;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// A Python callable `obs -> action` as an [`Expert`] of actions of the kind `A`.
pub(crate) struct PyExpert<A: PyAction> {
    pub(crate) call: Py<PyAny>,
    pub(crate) name: String,
    pub(crate) spec: &'static A::Spec,
    pub(crate) errors: ErrorSlot,
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
