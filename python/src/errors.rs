//! Python's exceptions on the way through the library: the first one a call raised, kept until the call returns
//! ([`ErrorSlot`]), and the two kinds arld raises itself.

use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::sync::{Arc, Mutex};

/// The first Python exception raised during a call into the library, kept until the call returns.
#[derive(Clone, Default)]
pub(crate) struct ErrorSlot(Arc<Mutex<Option<PyErr>>>);

impl ErrorSlot {
    /// Keeps `err` (the first one wins) and returns its text for the Rust error.
    pub(crate) fn keep(&self, err: PyErr) -> String {
        let text = err.to_string();
        let mut slot = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if slot.is_none() {
            *slot = Some(err);
        }
        text
    }

    /// The kept exception with `note` added (Python 3.11 on), if one is kept.
    pub(crate) fn take_with_note(&self, py: Python<'_>, note: &str) -> Option<PyErr> {
        let original = self.0.lock().unwrap_or_else(|e| e.into_inner()).take()?;
        let _ = original.value(py).call_method1("add_note", (note,));
        Some(original)
    }

    /// The Python exception to raise for a library error: the kept exception with the Rust context as a note,
    /// or `fallback` carrying the context.
    pub(crate) fn raise(
        &self,
        py: Python<'_>,
        err: anyhow::Error,
        fallback: fn(String) -> PyErr,
    ) -> PyErr {
        let context = arld_core::errors::error_line(&err);
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

pub(crate) fn value_error(msg: String) -> PyErr {
    PyValueError::new_err(msg)
}

pub(crate) fn runtime_error(msg: String) -> PyErr {
    PyRuntimeError::new_err(msg)
}
