//! Gymnasium-exact tasks whose action is a vector of float32 in a box (`Pendulum-v1`, `MountainCarContinuous-v0`
//! and `LunarLanderContinuous-v3`, found by id in [`super::make_continuous`]): their registered facts, the interface of
//! their physics, and the environment that adds the reset generator and the time limit.
//!
//! They share with the discrete tasks the reset generator ([`EnvRng`]: NumPy's `PCG64(SeedSequence(seed))`),
//! Gymnasium's `TimeLimit` (truncated on the limit step) and the outcome of a step ([`Outcome`]); an action is a
//! slice of `f32` of the task's action dimension, as Gymnasium passes a float32 array. Each task's arithmetic
//! follows NumPy's types step for step, float32 where NumPy computes in float32 (see each task's docs), so the
//! conformance traces recorded from Gymnasium 1.4.0 are reproduced bit for bit (`tests/continuous_conformance.rs`).

use super::{BoxSpec, Env, EnvError, EnvRng, EpisodeClock, Outcome};
use crate::rng::NumpyRng;

/// Every continuous-action task, in the order `known_continuous_ids` lists them.
pub static CONTINUOUS_SPECS: [BoxSpec; 3] = [
    BoxSpec {
        id: "Pendulum-v1",
        obs_dim: 3,
        action_low: &[-2.0],
        action_high: &[2.0],
        max_episode_steps: 200,
        // Gymnasium registers none; -200 is ours (a mean test return above -200 swings up and holds from
        // almost every start: the swing-up controller scores -184).
        solve_threshold: Some(-200.0),
    },
    BoxSpec {
        id: "MountainCarContinuous-v0",
        obs_dim: 2,
        action_low: &[-1.0],
        action_high: &[1.0],
        max_episode_steps: 999,
        solve_threshold: Some(90.0),
    },
    BoxSpec {
        id: "LunarLanderContinuous-v3",
        obs_dim: 8,
        action_low: &[-1.0, -1.0],
        action_high: &[1.0, 1.0],
        max_episode_steps: 1000,
        solve_threshold: Some(200.0),
    },
];

/// The ids of the continuous-action tasks.
pub fn known_continuous_ids() -> Vec<&'static str> {
    CONTINUOUS_SPECS.iter().map(|s| s.id).collect()
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
}

/// An episodic task with a box of float32 actions: a task's physics, its reset generator and its time limit.
pub struct ContinuousEnv {
    spec: &'static BoxSpec,
    rng: EnvRng,
    physics: Box<dyn ContinuousDynamics>,
    clock: EpisodeClock,
}

impl ContinuousEnv {
    /// The task `spec` with `physics` (the registry, [`super::make_continuous`], pairs them).
    pub fn new(spec: &'static BoxSpec, physics: Box<dyn ContinuousDynamics>) -> Self {
        ContinuousEnv {
            spec,
            rng: EnvRng::default(),
            physics,
            clock: EpisodeClock::new(spec.id, spec.max_episode_steps),
        }
    }
}

impl Env<Vec<f32>> for ContinuousEnv {
    /// Starts an episode and writes its first observation into `obs` (`reset(seed=seed)` in Gymnasium; `None`
    /// continues the current generator).
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut [f32]) {
        self.physics.reset(self.rng.reseed(seed));
        self.clock.start();
        self.physics.observe(obs);
    }

    /// Advances one step with `action` and writes the observation after it into `obs`. An action of another
    /// length or with a value that is not finite is an error naming it, and so is a step outside an episode.
    fn step_into(&mut self, action: &[f32], obs: &mut [f32]) -> Result<Outcome, EnvError> {
        let env = self.spec.id;
        self.clock.check_running()?;
        <Vec<f32> as super::Action>::check(action, self.spec)
            .map_err(|msg| EnvError::BadState { env, msg })?;
        let Some(rng) = self.rng.current() else {
            return Err(EnvError::NeedsReset { env });
        };
        let (reward, terminated) = self.physics.step(action, rng);
        let outcome = self.clock.finish_step(reward, terminated);
        self.physics.observe(obs);
        Ok(outcome)
    }

    fn spec(&self) -> &'static BoxSpec {
        self.spec
    }

    fn generator(&self) -> Option<NumpyRng> {
        self.rng.get()
    }

    fn set_generator(&mut self, rng: Option<NumpyRng>) {
        self.rng.set(rng);
    }

    /// Overwrites the internal float64 state (a new episode starts at it) and returns its observation.
    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f32>, EnvError> {
        self.physics
            .set_state(state)
            .map_err(|msg| EnvError::BadState {
                env: self.spec.id,
                msg,
            })?;
        self.clock.start();
        let mut obs = vec![0.0; self.spec.obs_dim];
        self.physics.observe(&mut obs);
        Ok(obs)
    }
}

/// Checks the length of a state given to [`ContinuousDynamics::set_state`].
pub(super) fn state_of_len<const N: usize>(state: &[f64]) -> Result<[f64; N], String> {
    state
        .try_into()
        .map_err(|_| format!("a state has {N} values, not {}", state.len()))
}
