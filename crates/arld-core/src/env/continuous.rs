//! Gymnasium-exact tasks whose action is a vector of float32 in a box (`Pendulum-v1`, `MountainCarContinuous-v0`
//! and `LunarLanderContinuous-v3`, found by id in [`super::make_continuous`]): their registered facts, the interface of
//! their physics, and the environment of it ([`ContinuousEnv`], the [`Simulated`] that adds the reset generator and
//! the time limit, as for the discrete tasks).
//!
//! They share with the discrete tasks the reset generator ([`EnvRng`]: NumPy's `PCG64(SeedSequence(seed))`),
//! Gymnasium's `TimeLimit` (truncated on the limit step) and the outcome of a step ([`super::Outcome`]); an action is a
//! slice of `f32` of the task's action dimension, as Gymnasium passes a float32 array. Each task's arithmetic
//! follows NumPy's types step for step, float32 where NumPy computes in float32 (see each task's docs), so the
//! conformance traces recorded from Gymnasium 1.4.0 are reproduced bit for bit (`tests/continuous_conformance.rs`).

use super::{BoxSpec, EnvError, EnvRng, Geometry, Physics, Simulated};
use crate::rng::NumpyRng;
use crate::task::{Action, Goal};

/// The registered facts of every continuous-action task (each one's entry in the task registry points here).
pub(crate) static CONTINUOUS_SPECS: [BoxSpec; 3] = [
    BoxSpec {
        id: "Pendulum-v1",
        obs_dim: 3,
        action_low: &[-2.0],
        action_high: &[2.0],
        max_episode_steps: 200,
        // Gymnasium registers none; -200 is ours (a mean test return above -200 swings up and holds from
        // almost every start: the swing-up controller scores -184).
        solve_threshold: Some(-200.0),
        goal: Goal::Absent(
            "has no goal: it never ends before its time limit, so no transition says it succeeded",
        ),
    },
    BoxSpec {
        id: "MountainCarContinuous-v0",
        obs_dim: 2,
        action_low: &[-1.0],
        action_high: &[1.0],
        max_episode_steps: 999,
        solve_threshold: Some(90.0),
        // Reaching the flag ends the episode with +100 less the action's cost (0.1 a^2, at most 0.1 in the box);
        // every other step earns at most 0.
        goal: Goal::TerminalReward { min_reward: 50.0 },
    },
    BoxSpec {
        id: "LunarLanderContinuous-v3",
        obs_dim: 8,
        action_low: &[-1.0, -1.0],
        action_high: &[1.0, 1.0],
        max_episode_steps: 1000,
        solve_threshold: Some(200.0),
        // Landed and at rest ends the episode with exactly +100; a crash or flying out of view with -100.
        goal: Goal::TerminalReward { min_reward: 100.0 },
    },
];

/// The ids of the built-in continuous-action tasks, in the registry's order.
pub fn known_continuous_ids() -> Vec<&'static str> {
    CONTINUOUS_SPECS.iter().map(|spec| spec.id).collect()
}

/// The physics of one continuous-action task.
pub trait ContinuousDynamics: Send {
    /// Draws the initial state from the reset's generator.
    fn reset(&mut self, rng: &mut NumpyRng);
    /// One step with a finite action of the task's dimension (not yet clipped to the box: each task clips as
    /// Gymnasium does), drawing what the step draws (the lander's engine dispersion) from the episode's
    /// generator; returns the reward and whether the task terminated.
    fn step(&mut self, action: &[f32], rng: &mut NumpyRng) -> (f64, bool);
    /// Writes the observation of the current state into `obs`.
    fn observe(&self, obs: &mut [f32]);
    /// Overwrites the internal float64 state as Gymnasium's `env.unwrapped.state = ...` does.
    fn set_state(&mut self, state: &[f64]) -> Result<(), String>;
    /// See [`super::Env::geometry`].
    fn geometry(&self) -> Option<Geometry> {
        None
    }
}

/// An episodic task with a box of float32 actions: a task's physics, its reset generator and its time limit
/// (`Simulated::with_spec` of the task's spec and physics; the registry, [`super::make_continuous`], pairs them).
pub type ContinuousEnv = Simulated<Box<dyn ContinuousDynamics>>;

impl Physics for Box<dyn ContinuousDynamics> {
    type Action = Vec<f32>;

    fn reset(&mut self, rng: &mut NumpyRng) {
        self.as_mut().reset(rng);
    }

    /// A finite action of the task's dimension, in an episode the generator has started.
    fn step(
        &mut self,
        spec: &'static BoxSpec,
        action: &[f32],
        rng: &mut EnvRng,
    ) -> Result<(f64, bool), EnvError> {
        let env = spec.id;
        <Vec<f32> as Action>::check(action, spec).map_err(|msg| EnvError::BadState { env, msg })?;
        let Some(rng) = rng.current() else {
            return Err(EnvError::NeedsReset { env });
        };
        Ok(self.as_mut().step(action, rng))
    }

    fn observe(&self, obs: &mut [f32]) {
        self.as_ref().observe(obs);
    }

    fn set_state(&mut self, env: &'static str, state: &[f64]) -> Result<(), EnvError> {
        self.as_mut()
            .set_state(state)
            .map_err(|msg| EnvError::BadState { env, msg })
    }

    fn geometry(&self) -> Option<Geometry> {
        self.as_ref().geometry()
    }
}

/// Checks the length of a state given to [`ContinuousDynamics::set_state`].
pub(super) fn state_of_len<const N: usize>(state: &[f64]) -> Result<[f64; N], String> {
    state
        .try_into()
        .map_err(|_| format!("a state has {N} values, not {}", state.len()))
}
