//! Scripted experts: hand-written controllers where a good one is known, one per task of the registry
//! ([`crate::env::registry`], which pairs each task with its controller).
//!
//! LunarLander uses Gymnasium's heuristic controller; CartPole a linear state-feedback rule; MountainCar pushes
//! in the direction of motion (pumping energy); Acrobot applies elbow torque against the first link's swing;
//! Pendulum an energy-based swing-up; MountainCarContinuous a momentum controller. They are deterministic, fast
//! and good, which makes them handy as "perfect" experts in tests.

use super::Expert;
use crate::env::registry::{self, Body};
use anyhow::{Result, bail};

/// A hand-written controller for one task, of its kind of action (`usize`, or `Vec<f32>` for a box).
pub struct Scripted<A> {
    env: &'static str,
    policy: fn(&[f32]) -> A,
}

/// The scripted controller of a task with discrete actions.
pub type ScriptedExpert = Scripted<usize>;

/// The scripted controller of a task with actions in a box: Gymnasium's heuristic for the continuous lander, an
/// energy-based swing-up for Pendulum, a momentum controller for MountainCarContinuous.
pub type ScriptedBoxExpert = Scripted<Vec<f32>>;

/// A kind of action a scripted controller acts in, and where the registry keeps a task's controller of it.
pub trait ScriptedKind: crate::task::Action {
    /// The kind in words, for the error of a task of the other kind.
    const KIND: &'static str;
    /// The task's controller, if its actions are of this kind.
    fn controller(body: &Body) -> Option<fn(&[f32]) -> Self>;
}

impl ScriptedKind for usize {
    const KIND: &'static str = "discrete actions";
    fn controller(body: &Body) -> Option<fn(&[f32]) -> usize> {
        match body {
            Body::Discrete { scripted, .. } => Some(*scripted),
            Body::Box { .. } => None,
        }
    }
}

impl ScriptedKind for Vec<f32> {
    const KIND: &'static str = "actions in a box";
    fn controller(body: &Body) -> Option<fn(&[f32]) -> Vec<f32>> {
        if let Body::Box { scripted, .. } = body {
            return Some(*scripted);
        }
        None
    }
}

impl<A: ScriptedKind> Scripted<A> {
    /// The scripted controller of the task `env_id`, whose actions are of the kind `A`.
    pub fn new(env_id: &str) -> Result<Self> {
        let found = registry::task(env_id).ok();
        match found.and_then(|task| A::controller(&task.body).map(|policy| (task.id, policy))) {
            Some((env, policy)) => Ok(Scripted { env, policy }),
            None => bail!(
                "no scripted expert for '{env_id}' (a task with {})",
                A::KIND
            ),
        }
    }
}

impl<A: ScriptedKind> Expert<A> for Scripted<A> {
    fn act(&mut self, obs: &[f32]) -> Result<A> {
        Ok((self.policy)(obs))
    }
    fn describe(&self) -> String {
        format!("scripted({})", self.env)
    }
}
