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

/// A hand-written controller for one environment.
pub struct ScriptedExpert {
    env: &'static str,
    policy: fn(&[f32]) -> usize,
}

impl ScriptedExpert {
    /// The scripted controller of `env_id`.
    pub fn new(env_id: &str) -> Result<Self> {
        match registry::task(env_id).map(|task| (task.id, &task.body)) {
            Ok((env, Body::Discrete { scripted, .. })) => Ok(Self {
                env,
                policy: *scripted,
            }),
            _ => bail!("no scripted expert for '{env_id}' (a task with discrete actions)"),
        }
    }
}

impl Expert for ScriptedExpert {
    fn act(&mut self, obs: &[f32]) -> Result<usize> {
        Ok((self.policy)(obs))
    }
    fn describe(&self) -> String {
        format!("scripted({})", self.env)
    }
}

/// A controller of box actions: the action for an observation.
type BoxPolicy = fn(&[f32]) -> Vec<f32>;

/// A hand-written controller for a task with actions in a box: Gymnasium's heuristic for the continuous
/// lander, an energy-based swing-up for Pendulum, a momentum controller for MountainCarContinuous.
pub struct ScriptedBoxExpert {
    env: &'static str,
    policy: BoxPolicy,
}

impl ScriptedBoxExpert {
    /// The scripted controller of the continuous task `env_id`.
    pub fn new(env_id: &str) -> Result<Self> {
        match registry::task(env_id).map(|task| (task.id, &task.body)) {
            Ok((env, Body::Box { scripted, .. })) => Ok(Self {
                env,
                policy: *scripted,
            }),
            _ => bail!("no scripted expert for '{env_id}' (a task with actions in a box)"),
        }
    }
}

impl Expert<Vec<f32>> for ScriptedBoxExpert {
    fn act(&mut self, obs: &[f32]) -> Result<Vec<f32>> {
        Ok((self.policy)(obs))
    }
    fn describe(&self) -> String {
        format!("scripted({})", self.env)
    }
}
