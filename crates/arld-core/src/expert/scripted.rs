//! Scripted experts: hand-written controllers where a good one is known.
//!
//! LunarLander uses Gymnasium's heuristic controller; CartPole a linear state-feedback rule; MountainCar pushes
//! in the direction of motion (pumping energy); Acrobot applies elbow torque against the first link's swing. They are deterministic, fast and good, which makes them handy as "perfect" experts in tests.

use super::Expert;
use crate::env::{lunar_lander, mountain_car_continuous, pendulum};
use anyhow::{Result, bail};

/// A hand-written controller for one environment.
pub struct ScriptedExpert {
    env: &'static str,
    policy: fn(&[f32]) -> usize,
}

impl ScriptedExpert {
    /// The scripted controller of `env_id`.
    pub fn new(env_id: &str) -> Result<Self> {
        let (env, policy): (&'static str, fn(&[f32]) -> usize) = match env_id {
            "CartPole-v0" => ("CartPole-v0", cartpole),
            "CartPole-v1" => ("CartPole-v1", cartpole),
            "MountainCar-v0" => ("MountainCar-v0", mountain_car),
            "Acrobot-v1" => ("Acrobot-v1", acrobot),
            "LunarLander-v2" => ("LunarLander-v2", crate::env::lunar_lander::heuristic_action),
            "LunarLander-v3" => ("LunarLander-v3", crate::env::lunar_lander::heuristic_action),
            other => bail!("no scripted expert for '{other}'"),
        };
        Ok(Self { env, policy })
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
        let (env, policy): (&'static str, BoxPolicy) = match env_id {
            "Pendulum-v1" => ("Pendulum-v1", |obs| pendulum::swing_up(obs).to_vec()),
            "MountainCarContinuous-v0" => ("MountainCarContinuous-v0", |obs| {
                mountain_car_continuous::momentum(obs, 0.6).to_vec()
            }),
            "LunarLanderContinuous-v3" => ("LunarLanderContinuous-v3", |obs| {
                lunar_lander::heuristic_throttle(obs).to_vec()
            }),
            other => bail!("no scripted expert for '{other}'"),
        };
        Ok(Self { env, policy })
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

/// Push the cart towards where the pole is falling, with a little position and velocity feedback to keep the
/// cart near the centre. Observation: [x, x_dot, theta, theta_dot].
pub fn cartpole(obs: &[f32]) -> usize {
    let u = 0.1 * obs[0] + 0.5 * obs[1] + 10.0 * obs[2] + 2.0 * obs[3];
    usize::from(u > 0.0)
}

/// Accelerate in the direction of motion. Observation: [position, velocity]; actions: 0 left, 1 none, 2 right.
pub fn mountain_car(obs: &[f32]) -> usize {
    if obs[1] >= 0.0 { 2 } else { 0 }
}

/// Torque on the elbow against the first link's angular velocity: the second link then swings the other way,
/// which pumps energy into the first link's swing until the tip clears the bar (about 75 steps).
/// Observation: [cos th1, sin th1, cos th2, sin th2, dth1, dth2]; actions: torque -1, 0, +1.
pub fn acrobot(obs: &[f32]) -> usize {
    if obs[4] > 0.0 { 0 } else { 2 }
}
