//! [`Learner`]: what a run asks of an agent, whatever its family. The run loop (`train::run`) calls only this
//! interface; the DQN family ([`super::DqnAgent`]: plain, bootstrapped or noisy output) is its first
//! implementation. An actor-critic family fits the same calls: it acts (with its own exploration), learns from
//! a replay batch, gives a test-time action, the uncertainty signals its critics can give, and its state.

use super::UpdateStats;
use crate::query::{Needs, Signals};
use crate::replay::Batch;
use crate::state::Persist;
use crate::task::Action;
use std::collections::BTreeMap;
use std::path::Path;

/// An agent a run trains. Its whole state (weights, optimiser, generator) is what [`Persist`] saves in a
/// run's snapshot, and every random draw it makes comes from the generator it was built with.
pub trait Learner: Persist {
    /// The kind of the actions it takes: a discrete index (the DQN family) or a box of numbers (the
    /// actor-critic family).
    type Action: Action;

    /// A training episode begins (a bootstrapped agent draws the head it acts with).
    fn begin_episode(&mut self);

    /// The behaviour policy's action at `obs`, exploring at rate `epsilon`, and the uncertainty signals the
    /// query rule (and an expert that shows them) want. Computing a signal draws no random number.
    fn act(&mut self, obs: &[f32], epsilon: f64, want: Needs) -> (Self::Action, Signals);

    /// One update from a replay batch: what it measured, and the new priority of each of the batch's samples.
    fn learn(&mut self, batch: &Batch<Self::Action>) -> (UpdateStats, &[f32]);

    /// Pre-training on demonstrations alone begins (`true`) or ends (`false`). An actor-critic learner then
    /// clones every demonstrated action, its Q-filter off (docs/algorithm.md §17); the DQN family changes
    /// nothing.
    fn set_pretraining(&mut self, _on: bool) {}

    /// The end of a target period (every `target_period` updates, and after pre-training): a DQN copies its
    /// online weights into its target network.
    fn end_target_period(&mut self);

    /// The test-time actions (no exploration) of the observations `obs` (row-major), computed together, into
    /// `actions` (whatever it held before, it then holds one row per observation); each is the action the agent
    /// would take for its observation alone.
    fn test_actions(&mut self, obs: &[f32], actions: &mut <Self::Action as Action>::Column);

    /// Writes the weights a run keeps (its checkpoints and final weights) to `path` with `metadata`.
    fn save_weights(&self, path: &Path, metadata: &BTreeMap<String, String>) -> anyhow::Result<()>;
}
