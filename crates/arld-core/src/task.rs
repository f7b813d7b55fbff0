//! What a task is, whatever its actions: its registered facts ([`EnvSpec`] for a task with discrete actions,
//! [`BoxSpec`] for one with a box of float32 actions, both read through [`TaskSpec`]), and the kind of its
//! actions ([`Action`]): a discrete index (`usize`) or a vector of `f32` in a box (`Vec<f32>`).
//!
//! Everything that carries actions (environments, the replay, learners) is generic over the [`Action`] kind,
//! with `usize` as the default, so the discrete path is the code it always was. An action kind brings the facts
//! of its tasks ([`Action::Spec`]), how it is checked against them, and how many of them are stored side by
//! side ([`Action::Column`]: a replay's actions, a batch's actions).

use crate::state::{StateDict, StateError};
use serde::Serialize;
use serde::de::DeserializeOwned;
use std::fmt::Debug;

/// Static facts about a registered task with discrete actions.
#[derive(Debug, Clone, Copy)]
pub struct EnvSpec {
    pub id: &'static str,
    pub obs_dim: usize,
    pub n_actions: usize,
    pub max_episode_steps: usize,
    pub solve_threshold: f64,
}

/// The registered facts of a task with a box of float32 actions.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxSpec {
    /// Gymnasium id.
    pub id: &'static str,
    /// Length of the observation vector.
    pub obs_dim: usize,
    /// The action box's lower bounds, one per action dimension.
    pub action_low: &'static [f32],
    /// The action box's upper bounds.
    pub action_high: &'static [f32],
    /// Gymnasium's `max_episode_steps`.
    pub max_episode_steps: usize,
    /// The mean test return that counts as solving the task: Gymnasium's `reward_threshold`, or ours where it
    /// has none (Pendulum-v1: -200).
    pub solve_threshold: Option<f64>,
    /// How a transition says the task reached its goal (the success a risk critic predicts).
    pub goal: Goal,
}

/// How a task with actions in a box says that a transition reached its goal: the binary success that a risk
/// critic learns to predict (ThriftyDAgger's `Q_R`, docs/algorithm.md §20).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Goal {
    /// The task has no goal a transition can show; the reason says why (it ends a sentence naming the task).
    Absent(&'static str),
    /// Reached by a transition that ends the episode (a termination, not a time limit) with a reward of at least
    /// `min_reward`: the goal's bonus, which no other transition of the task earns.
    TerminalReward { min_reward: f32 },
}

impl Goal {
    /// Whether a transition with `reward` that ends the episode when `terminal` reached the goal.
    pub fn reached(self, reward: f32, terminal: bool) -> bool {
        match self {
            Goal::Absent(_) => false,
            Goal::TerminalReward { min_reward } => terminal && reward >= min_reward,
        }
    }

    /// Whether task `id` has a goal; the error says why not.
    pub fn check(self, id: &str) -> Result<(), String> {
        match self {
            Goal::Absent(why) => Err(format!("{id} {why}")),
            Goal::TerminalReward { .. } => Ok(()),
        }
    }
}

impl BoxSpec {
    /// Number of action dimensions.
    pub fn action_dim(&self) -> usize {
        self.action_low.len()
    }
}

/// The facts every task has, whatever its actions.
pub trait TaskSpec: Debug + Send + Sync + 'static {
    /// Gymnasium id, e.g. `CartPole-v0`.
    fn id(&self) -> &'static str;
    /// Length of the observation vector.
    fn obs_dim(&self) -> usize;
    /// Gymnasium's `max_episode_steps`.
    fn max_episode_steps(&self) -> usize;
    /// Gymnasium's `reward_threshold`: the mean test return that counts as solving the task (infinite for a
    /// task without one: no run solves it).
    fn solve_threshold(&self) -> f64;
    /// How many numbers one action is: 1 for a discrete index, the box's dimension for a box.
    fn action_width(&self) -> usize;
}

impl TaskSpec for EnvSpec {
    fn id(&self) -> &'static str {
        self.id
    }
    fn obs_dim(&self) -> usize {
        self.obs_dim
    }
    fn max_episode_steps(&self) -> usize {
        self.max_episode_steps
    }
    fn solve_threshold(&self) -> f64 {
        self.solve_threshold
    }
    fn action_width(&self) -> usize {
        1
    }
}

impl TaskSpec for BoxSpec {
    fn id(&self) -> &'static str {
        self.id
    }
    fn obs_dim(&self) -> usize {
        self.obs_dim
    }
    fn max_episode_steps(&self) -> usize {
        self.max_episode_steps
    }
    fn solve_threshold(&self) -> f64 {
        self.solve_threshold.unwrap_or(f64::INFINITY)
    }
    fn action_width(&self) -> usize {
        self.action_dim()
    }
}

/// A kind of action: a discrete index (`usize`) or a vector of `f32` in a box (`Vec<f32>`).
///
/// An action travels borrowed ([`Action::Ref`]: the index itself, or a slice of the box's numbers), so stepping
/// an environment or storing a transition allocates nothing.
pub trait Action:
    Clone + PartialEq + Debug + Send + Sync + Serialize + DeserializeOwned + 'static
{
    /// The registered facts of the tasks with actions of this kind.
    type Spec: TaskSpec;
    /// An action of this kind, borrowed.
    type Ref<'a>: Copy + PartialEq + Debug;
    /// Many actions of this kind side by side (a replay's, a batch's).
    type Column: ActionColumn<Self>;
    /// The action, borrowed.
    fn borrow(&self) -> Self::Ref<'_>;
    /// A borrowed action, owned.
    fn owned(action: Self::Ref<'_>) -> Self;
    /// Checks that `action` is one the task `spec` accepts; the error says why not.
    fn check(action: Self::Ref<'_>, spec: &Self::Spec) -> Result<(), String>;
    /// The index of a discrete action (`None` for a box): what rules that compare the agent's action with an
    /// oracle's read.
    fn index(action: Self::Ref<'_>) -> Option<usize>;
    /// The action as one field of a CSV file (`queries.csv`): the index, or the box's numbers separated by
    /// spaces.
    fn to_field(action: Self::Ref<'_>) -> String;
}

impl Action for usize {
    type Spec = EnvSpec;
    type Ref<'a> = usize;
    type Column = Vec<usize>;

    fn borrow(&self) -> usize {
        *self
    }

    fn owned(action: usize) -> usize {
        action
    }

    fn index(action: usize) -> Option<usize> {
        Some(action)
    }

    fn to_field(action: usize) -> String {
        action.to_string()
    }

    fn check(action: usize, spec: &EnvSpec) -> Result<(), String> {
        if action < spec.n_actions {
            Ok(())
        } else {
            Err(format!(
                "{} has {} actions (0 to {})",
                spec.id,
                spec.n_actions,
                spec.n_actions.saturating_sub(1)
            ))
        }
    }
}

impl Action for Vec<f32> {
    type Spec = BoxSpec;
    type Ref<'a> = &'a [f32];
    type Column = BoxColumn;

    fn borrow(&self) -> &[f32] {
        self
    }

    fn owned(action: &[f32]) -> Vec<f32> {
        action.to_vec()
    }

    fn index(_: &[f32]) -> Option<usize> {
        None
    }

    fn to_field(action: &[f32]) -> String {
        action
            .iter()
            .map(f32::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    }

    fn check(action: &[f32], spec: &BoxSpec) -> Result<(), String> {
        if action.len() != spec.action_dim() {
            return Err(format!(
                "an action has {} values, not {} ({}'s action dimension)",
                action.len(),
                spec.action_dim(),
                spec.id
            ));
        }
        match action.iter().find(|a| !a.is_finite()) {
            Some(bad) => Err(format!(
                "an action holds {bad}, which is not a finite number"
            )),
            None => Ok(()),
        }
    }
}

/// Actions stored side by side, one row each, `width` numbers per action (the task's
/// [`TaskSpec::action_width`]).
pub trait ActionColumn<A: Action>: Clone + Debug + Default + Send + Sync {
    /// `rows` actions, all zero.
    fn zeros(rows: usize, width: usize) -> Self;
    /// Overwrites row `row`.
    fn set(&mut self, row: usize, action: A::Ref<'_>);
    /// The action of row `row`.
    fn get(&self, row: usize) -> A::Ref<'_>;
    /// Appends the rows `rows` of `other`, in order.
    fn gather(&mut self, other: &Self, rows: &[usize]);
    /// Removes every row.
    fn clear(&mut self);
    /// Saves the column as the array `name` of `state`.
    fn save<'a>(&'a self, state: &mut StateDict<'a>, name: &str);
    /// Loads the column saved as `name` into `self` (which has the right shape).
    fn load(&mut self, state: &StateDict<'_>, name: &str) -> Result<(), StateError>;
}

impl ActionColumn<usize> for Vec<usize> {
    fn zeros(rows: usize, _width: usize) -> Self {
        vec![0; rows]
    }
    fn set(&mut self, row: usize, action: usize) {
        self[row] = action;
    }
    fn get(&self, row: usize) -> usize {
        self[row]
    }
    fn gather(&mut self, other: &Self, rows: &[usize]) {
        self.extend(rows.iter().map(|&row| other[row]));
    }
    fn clear(&mut self) {
        Vec::clear(self);
    }
    fn save<'a>(&'a self, state: &mut StateDict<'a>, name: &str) {
        let actions: Vec<u64> = self.iter().map(|&a| a as u64).collect();
        state.put_u64(name, actions);
    }
    fn load(&mut self, state: &StateDict<'_>, name: &str) -> Result<(), StateError> {
        let mut actions = vec![0u64; self.len()];
        state.u64s_into(name, &mut actions)?;
        for (slot, &a) in self.iter_mut().zip(&actions) {
            *slot = a as usize;
        }
        Ok(())
    }
}

/// Box actions side by side: `width` float32 numbers per row, rows one after another.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BoxColumn {
    width: usize,
    values: Vec<f32>,
}

impl BoxColumn {
    /// Numbers per action.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Every row's numbers, row-major.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// Makes the column `rows` actions of `width` numbers (their values left as they were or zero) and
    /// returns every row's numbers to fill.
    pub fn rows_mut(&mut self, rows: usize, width: usize) -> &mut [f32] {
        self.width = width;
        self.values.resize(rows * width, 0.0);
        &mut self.values
    }
}

impl ActionColumn<Vec<f32>> for BoxColumn {
    fn zeros(rows: usize, width: usize) -> Self {
        BoxColumn {
            width,
            values: vec![0.0; rows * width],
        }
    }
    fn set(&mut self, row: usize, action: &[f32]) {
        self.values[row * self.width..(row + 1) * self.width].copy_from_slice(action);
    }
    fn get(&self, row: usize) -> &[f32] {
        &self.values[row * self.width..(row + 1) * self.width]
    }
    fn gather(&mut self, other: &Self, rows: &[usize]) {
        self.width = other.width;
        for &row in rows {
            self.values.extend_from_slice(other.get(row));
        }
    }
    fn clear(&mut self) {
        self.values.clear();
    }
    fn save<'a>(&'a self, state: &mut StateDict<'a>, name: &str) {
        state.put_f32(name, &self.values);
    }
    fn load(&mut self, state: &StateDict<'_>, name: &str) -> Result<(), StateError> {
        state.f32s_into(name, &mut self.values)
    }
}
