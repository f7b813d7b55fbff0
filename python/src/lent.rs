//! The live agent and log of a run, lent to a callback while it runs on the run's thread ([`Lent`]), so that what
//! the callback reads is that step's, without a copy per step.

use arld_core::agent::DqnAgent;
use arld_core::agent::box_agent::BoxAgent;
use arld_core::train::{EvalPoint, RunLog};
use std::cell::Cell;

/// The live agent and log of a run, lent to a callback while it runs on the run's thread.
#[derive(Clone, Copy)]
pub(crate) enum LentParts {
    Discrete(*const DqnAgent, *const RunLog),
    Box(*const BoxAgent, *const RunLog<Vec<f32>>),
}

/// The live agent and log of a run, borrowed for the length of a call from its callback.
pub(crate) enum LentRef<'a> {
    Discrete(&'a DqnAgent, &'a RunLog),
    Box(&'a BoxAgent, &'a RunLog<Vec<f32>>),
}

impl LentRef<'_> {
    pub(crate) fn curve(&self) -> &[EvalPoint] {
        match self {
            LentRef::Discrete(_, log) => log.curve(),
            LentRef::Box(_, log) => log.curve(),
        }
    }
}

/// The live run lent to a callback while it runs on the run's thread: which run, its agent and its log.
pub(crate) type LentRun = (u64, LentParts);

thread_local! {
    /// Set only by [`Lent`], for the length of one callback call on the run's thread.
    static LENT: Cell<Option<LentRun>> = const { Cell::new(None) };
}

/// Lends a step's agent and log to the callback called while it lives (on this thread only).
pub(crate) struct Lent;

impl Lent {
    pub(crate) fn new(run: u64, parts: LentParts) -> Self {
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
pub(crate) fn with_lent<R>(run: u64, f: impl FnOnce(LentRef<'_>) -> R) -> Option<R> {
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
pub(crate) fn in_callback() -> bool {
    LENT.with(|l| l.get()).is_some()
}
