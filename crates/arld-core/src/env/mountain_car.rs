//! MountainCar-v0, as Gymnasium 1.x computes it.
//!
//! An underpowered car in a valley must rock back and forth to reach the flag at position 0.5. Actions:
//! 0 accelerate left, 1 coast, 2 accelerate right. One step (float64, Gymnasium's order):
//! `velocity += (a - 1) * 0.001 + cos(3 * position) * (-0.0025)`, clipped to +-0.07; `position += velocity`,
//! clipped to [-1.2, 0.6]; at the left wall a negative velocity becomes 0. Terminal when position >= 0.5
//! and velocity >= 0; reward -1 per step; limit 200 steps. The initial position is one draw of
//! `uniform(-0.6, -0.4)`, the initial velocity 0 (docs/environments.md, "Classic control").

use super::Simulated;
use super::classic::{Classic, ClassicTask, SingleId};
use crate::rng::NumpyRng;

pub(super) const MIN_POSITION: f64 = -1.2;
pub(super) const MAX_POSITION: f64 = 0.6;
pub(super) const MAX_SPEED: f64 = 0.07;
const GOAL_POSITION: f64 = 0.5;
pub(super) const GOAL_VELOCITY: f64 = 0.0;
const FORCE: f64 = 0.001;
const GRAVITY: f64 = 0.0025;

/// Height of the hill at `x` as Gymnasium draws it (the dynamics' gravity term is its slope).
fn hill_height(x: f64) -> f64 {
    (3.0 * x).sin() * 0.45 + 0.55
}

/// MountainCar-v0 with its 200-step limit.
pub type MountainCar = Simulated<Classic<MountainCarPhysics, 2>>;

/// The car's dynamics, on the float64 state `[position, velocity]`.
#[derive(Debug, Clone)]
pub struct MountainCarPhysics;

impl SingleId for MountainCarPhysics {
    const ID: &'static str = "MountainCar-v0";
}

impl ClassicTask<2> for MountainCarPhysics {
    fn reset(state: &mut [f64; 2], rng: &mut NumpyRng) {
        *state = [rng.uniform(-0.6, -0.4), 0.0];
    }

    fn step(state: &mut [f64; 2], action: usize) -> (f64, bool) {
        let [position, velocity] = *state;
        let push = (action as f64 - 1.0) * FORCE;
        let mut velocity = velocity + (push + (3.0 * position).cos() * (-GRAVITY));
        velocity = velocity.clamp(-MAX_SPEED, MAX_SPEED);
        let position = (position + velocity).clamp(MIN_POSITION, MAX_POSITION);
        // Inelastic collision with the left wall.
        if position == MIN_POSITION && velocity < 0.0 {
            velocity = 0.0;
        }
        *state = [position, velocity];
        let terminated = position >= GOAL_POSITION && velocity >= GOAL_VELOCITY;
        (-1.0, terminated)
    }

    fn observe(state: &[f64; 2], obs: &mut [f32]) {
        let [position, velocity] = *state;
        obs.copy_from_slice(&[position as f32, velocity as f32]);
    }

    fn geometry(state: &[f64; 2]) -> super::Geometry {
        geometry(state[0], GOAL_POSITION, None)
    }
}

/// The drawing of a car at `position` on the valley's hill with the flag at `goal`, and the force of its last
/// step where the task has one (continuous actions).
pub(super) fn geometry(position: f64, goal: f64, force: Option<f64>) -> super::Geometry {
    let hill = (0..=60)
        .map(|i| {
            let x = MIN_POSITION + (MAX_POSITION - MIN_POSITION) * f64::from(i) / 60.0;
            [x, hill_height(x)]
        })
        .collect();
    super::Geometry::MountainCar {
        position,
        height: hill_height(position),
        // The slope of the hill under the car: d/dx of 0.45 sin(3x).
        angle: (1.35 * (3.0 * position).cos()).atan(),
        goal,
        hill,
        force,
    }
}

/// Accelerate in the direction of motion. Observation: [position, velocity]; actions: 0 left, 1 none, 2 right.
pub(crate) fn push_with_motion(obs: &[f32]) -> usize {
    if obs[1] >= 0.0 { 2 } else { 0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::{Env, EnvError};

    #[test]
    fn left_wall_stops_the_car() {
        let mut env = MountainCar::new();
        env.set_state(&[-1.19, -0.05]).unwrap();
        let step = env.step(0).unwrap();
        assert_eq!(env.state(), [MIN_POSITION, 0.0]);
        assert_eq!(step.reward, -1.0);
        assert!(!step.terminated);
    }

    #[test]
    fn reaching_the_flag_terminates() {
        let mut env = MountainCar::new();
        env.set_state(&[0.49, 0.07]).unwrap();
        let step = env.step(2).unwrap();
        assert!(step.terminated && !step.truncated);
        assert!(matches!(env.step(1), Err(EnvError::NeedsReset { .. })));
    }
}
