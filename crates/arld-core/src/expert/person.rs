//! The hooks of an expert who is a person: [`Person`], beside [`Expert`](super::Expert).
//!
//! A program answers the agent's queries and nothing else. A person (the web expert) also follows the run as it
//! goes (every step, its evaluations, a resume, a hand-over to a Python program, the end), may take over unasked,
//! is shown what the agent would do, spends time the run records, and may retry a segment. The training loop
//! asks an expert for these hooks ([`super::Expert::person`]) and calls them only when it has them, so that an
//! expert that only answers implements only what it needs.

use super::{Progress, RunEnd, RunHistory};
use crate::env::Action;

/// What a person does besides answering (see the module's documentation). Every hook has a default that does
/// nothing, so that a person implements the ones it uses.
pub trait Person<A: Action = usize> {
    /// Called by the training loop after every step, so that the person sees the run as it goes. It must be
    /// cheap and must not change anything the run depends on.
    fn observe(&mut self, _progress: &Progress<'_, A>) {}
    /// Polled once per step where the agent is about to act and budget is left: whether the person takes over
    /// unasked from this state (they pressed "Take over" on the page; human-gated control as in HG-DAgger and
    /// HIL-SERL). When it says yes, the run opens a segment charged like a question's (the query rule does not
    /// see it) and asks [`super::Expert::answer`] at once, with the agent's proposal, until the expert hands back
    /// ([`super::Answer::Unanswered`]), the episode ends or the budget is spent. It must be cheap and draw
    /// nothing.
    fn wants_control(&mut self) -> bool {
        false
    }
    /// Called once when a resumed run goes on, before anything else is shown: what the run kept of its course
    /// before the stop (a person's page draws its charts from it).
    fn resumed_history(&mut self, _history: &RunHistory) {}
    /// Whether the person is shown the agent's uncertainty at every step: the agent then computes it even where
    /// no query rule reads it (a segment aside), so that it goes on after the budget is spent.
    fn shows_uncertainty(&self) -> bool {
        false
    }
    /// Whether the person is shown the agent's proposal at every step of a segment ([`super::Query::propose`]):
    /// the loop then lets the expert ask the agent's test-time action (no exploration, no random draw) at any
    /// observation while a question is open.
    fn shows_proposals(&self) -> bool {
        false
    }
    /// Seconds the person spent answering (recorded in the run's summary), when they are counted.
    fn person_seconds(&self) -> Option<f64> {
        None
    }
    /// Called right after the person answered the question that opens a segment: the steps of the attempts at
    /// it that they chose to retry (played on a copy of the environment, never given to the run, but given by
    /// the person: the run charges them to the budget). 0 when they kept their first attempt.
    fn retried_steps(&mut self) -> usize {
        0
    }
    /// Called once when the run has finished, with its outcome (the person's page shows it).
    fn finish(&mut self, _end: &RunEnd) {}
    /// Called when a driven run (a Python program's `learn`) is handed back to its program between two steps:
    /// `end` says where it stands, `note` why (training returned, or a stop). The run may go on later; the page
    /// shows the note until the next step or question.
    fn handed_over(&mut self, _end: &RunEnd, _note: &str) {}
}
