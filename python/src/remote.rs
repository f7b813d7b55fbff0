//! The driver of a run in its own thread ([`Remote`]): it trains until the step Python asked for, calls Python's
//! callback after every step, and at a pause waits for the next command ([`Command`]), reporting where it stands.

use crate::actions::PyAction;
use crate::errors::{ErrorSlot, runtime_error};
use crate::learners::{PyLearner, write_snapshot};
use crate::lent::Lent;
use crate::policy::Net;
use crate::records::Records;
use arld_core::env::Action;
use arld_core::train::{Control, Driver, EvalPoint, PausedRun, StepView, Summary};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::{Arc, Mutex};

/// A command from Python to a run's thread.
pub(crate) enum Command {
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
pub(crate) struct Pause {
    pub(crate) net: Net,
    pub(crate) curve: Vec<EvalPoint>,
    pub(crate) queries: Records,
    pub(crate) summary: Summary,
    /// The run ended (by error, or stopped): it cannot go on.
    pub(crate) finished: bool,
}

/// A report from a run's thread.
pub(crate) enum Report {
    Paused(Box<Pause>),
    Saved(Result<(), String>),
    Failed(anyhow::Error),
}

/// What `Run::wait` saw: a pause at a step, or a snapshot written (or why not).
pub(crate) enum Waited {
    Paused(usize),
    Saved(Result<(), String>),
}

/// The driver of a run in its own thread: trains until the step Python asked for, then pauses and waits there
/// (the whole run alive) for the next command.
pub(crate) struct Remote {
    /// Which run (the key of what is lent to its callbacks).
    pub(crate) id: u64,
    pub(crate) until: usize,
    pub(crate) callback: Option<Py<PyAny>>,
    pub(crate) commands: Receiver<Command>,
    pub(crate) reports: Sender<Report>,
    pub(crate) interrupt: Arc<AtomicBool>,
    pub(crate) step: Arc<AtomicUsize>,
    pub(crate) errors: ErrorSlot,
    /// Files a callback asked the run's snapshot to be written to (`save` inside a callback).
    pub(crate) saves: Arc<Mutex<Vec<PathBuf>>>,
    /// The pause under way only writes `saves`: the run goes on by itself afterwards.
    pub(crate) only_saving: bool,
    /// The run's task.
    pub(crate) env_id: String,
}

impl Remote {
    /// Python's callback after a step, with the live run lent to it: anything but `False` goes on. An exception
    /// is kept (with a note of the step) and pauses the run.
    pub(crate) fn call_back<L: PyLearner>(&self, at: &StepView<'_, L>) -> bool {
        let Some(cb) = &self.callback else {
            return true;
        };
        let last_eval = at.log.curve().last().map(|p| (p.step, p.mean));
        let _lent = Lent::new(self.id, L::lend(at.agent, at.log));
        Python::attach(|py| {
            let last = at.last;
            // What the step did, as SB3's callbacks see it: the action, the reward, the episode's end (and its
            // return and length), the next observation.
            let action = last
                .action
                .as_ref()
                .and_then(|a| L::Action::to_py(py, a.borrow()).ok());
            let taken = (
                action,
                last.reward,
                last.terminated,
                last.truncated,
                last.ended,
                at.obs,
            );
            let answer = cb.call1(
                py,
                (
                    at.step,
                    at.episode,
                    at.transitions_used,
                    at.log.query_events().len(),
                    last_eval,
                    taken,
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

    pub(crate) fn pending_saves(&self) -> Vec<PathBuf> {
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
