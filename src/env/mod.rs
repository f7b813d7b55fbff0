//! Environments: the [`Env`] trait and Gymnasium-exact implementations, found by Gymnasium id in [`make`].
//!
//! Every environment reproduces Gymnasium 1.x step for step and seed for seed: the physics are ported
//! line by line (float64 for classic control, Box2D 2.3 in float32 for LunarLander), and every random draw
//! comes from [`crate::rng::NumpyRng`], a bit-exact port of NumPy's `PCG64(SeedSequence(seed))`.
//! `../conformance` traces recorded from Gymnasium are the test (see [`conformance`]).

pub mod lunar_lander;

use thiserror::Error;

/// What one environment step returns (Gymnasium's 5-tuple without `info`).
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Observation after the step (float32, as Gymnasium returns it).
    pub obs: Vec<f32>,
    /// Reward of the step (float64 as Gymnasium computes it).
    pub reward: f64,
    /// The episode reached a terminal state of the task.
    pub terminated: bool,
    /// The episode was cut by the time limit (and did not terminate).
    pub truncated: bool,
}

/// Errors from environments: bad ids, bad actions, bad states.
#[derive(Debug, Error)]
pub enum EnvError {
    #[error("unknown environment id '{id}'; known ids: {}", known_ids().join(", "))]
    UnknownId { id: String },
    #[error(
        "action {action} is out of range for {env}: it has {n_actions} actions (0..{n_actions})"
    )]
    ActionOutOfRange {
        env: &'static str,
        action: usize,
        n_actions: usize,
    },
    #[error("step() called on {env} before reset() or after the episode ended; call reset() first")]
    NeedsReset { env: &'static str },
    #[error("{env}: {msg}")]
    BadState { env: &'static str, msg: String },
}

/// A Gymnasium-style episodic environment with a discrete action space.
///
/// The time limit is part of the environment (as Gymnasium's `TimeLimit` wrapper is part of `gym.make`):
/// `step` sets `truncated` when the limit is reached without termination.
pub trait Env: Send {
    /// Starts an episode. `Some(seed)` reseeds the generator exactly as `reset(seed=seed)` does in Gymnasium;
    /// `None` continues the current generator (the first unseeded reset seeds from OS entropy, as Gymnasium).
    fn reset(&mut self, seed: Option<u64>) -> Vec<f32>;
    /// Advances one step. Errors on an action out of range or a step without a running episode.
    fn step(&mut self, action: usize) -> Result<Step, EnvError>;
    /// Length of the observation vector.
    fn obs_dim(&self) -> usize;
    /// Number of discrete actions.
    fn n_actions(&self) -> usize;
    /// Gymnasium's `max_episode_steps`.
    fn max_episode_steps(&self) -> usize;
    /// Gymnasium's `reward_threshold`: the mean test return that counts as solving the task.
    fn solve_threshold(&self) -> f64;
    /// Gymnasium id, e.g. `CartPole-v0`.
    fn id(&self) -> &'static str;
    /// Overwrites the internal float64 state (classic control; used by the `set` conformance case).
    /// Resets the step counter. Environments without such a state return an error.
    fn set_state(&mut self, _state: &[f64]) -> Result<Vec<f32>, EnvError> {
        Err(EnvError::BadState {
            env: self.id(),
            msg: "setting the internal state is not supported".into(),
        })
    }
}

/// Static facts about a registered environment.
#[derive(Debug, Clone, Copy)]
pub struct EnvSpec {
    pub id: &'static str,
    pub obs_dim: usize,
    pub n_actions: usize,
    pub max_episode_steps: usize,
    pub solve_threshold: f64,
}

/// Every registered environment id.
pub fn known_ids() -> Vec<&'static str> {
    vec![
        "CartPole-v0",
        "CartPole-v1",
        "Acrobot-v1",
        "MountainCar-v0",
        "LunarLander-v2",
        "LunarLander-v3",
    ]
}

/// Builds an environment by Gymnasium id.
pub fn make(id: &str) -> Result<Box<dyn Env>, EnvError> {
    match id {
        "LunarLander-v2" => Ok(Box::new(lunar_lander::LunarLander::new("LunarLander-v2"))),
        "LunarLander-v3" => Ok(Box::new(lunar_lander::LunarLander::new("LunarLander-v3"))),
        _ => Err(EnvError::UnknownId { id: id.to_string() }),
    }
}
