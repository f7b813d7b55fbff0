//! Environments: the [`Env`] trait and Gymnasium-exact implementations, found by Gymnasium id in [`make`].
//!
//! Every environment reproduces Gymnasium 1.x step for step and seed for seed: the physics are ported
//! line by line (float64 for classic control, Box2D 2.3 in float32 for LunarLander), and every random draw
//! comes from [`crate::rng::NumpyRng`], a bit-exact port of NumPy's `PCG64(SeedSequence(seed))`.
//! `../conformance` traces recorded from Gymnasium are the test (see [`conformance`]).
//!
//! One environment type serves every task, [`Simulated`]: a task's [`Physics`] (any discrete task's
//! [`Dynamics`], or a boxed [`continuous::ContinuousDynamics`]) with its registered facts, the reset generator
//! and the step bookkeeping. The registered facts of tasks implemented elsewhere (Python) are kept by
//! [`register`] and [`register_box`].

use crate::rng::NumpyRng;
pub use crate::task::{Action, ActionColumn, BoxSpec, EnvSpec, Goal, TaskSpec};
use thiserror::Error;

pub mod acrobot;
pub mod cartpole;
pub mod classic;
pub mod conformance;
pub mod continuous;
pub mod lunar_lander;
pub(crate) mod mountain_car;
pub mod mountain_car_continuous;
pub mod pendulum;
pub mod registry;
pub mod rollout;

pub use acrobot::Acrobot;
pub use cartpole::CartPole;
pub use lunar_lander::LunarLander;
pub use mountain_car::MountainCar;
pub use rollout::{Episode, mean_std_min_max, return_stats, rollouts};

/// What one environment step reports besides the observation, which [`Env::step_into`] writes into the caller's
/// buffer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    /// Reward of the step (float64 as Gymnasium computes it).
    pub reward: f64,
    /// The episode reached a terminal state of the task.
    pub terminated: bool,
    /// The episode was cut by the time limit (see [`Step::truncated`]).
    pub truncated: bool,
}

/// What one environment step returns (Gymnasium's 5-tuple without `info`), with the observation in a fresh
/// `Vec` ([`Env::step`]; loops that step many times use [`Env::step_into`] and allocate nothing).
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Observation after the step (float32, as Gymnasium returns it).
    pub obs: Vec<f32>,
    /// Reward of the step (float64 as Gymnasium computes it).
    pub reward: f64,
    /// The episode reached a terminal state of the task.
    pub terminated: bool,
    /// The episode was cut by the time limit. As in Gymnasium's `TimeLimit` wrapper this is set on the
    /// limit step even if the episode also terminated on it (learners should let `terminated` win).
    pub truncated: bool,
}

/// Errors from environments: bad ids, bad actions, bad states.
#[derive(Debug, Error)]
pub enum EnvError {
    #[error(
        "unknown environment id '{id}'; arld's tasks are, with {} (`arld env list` describes them). Any other \
         Gymnasium environment trains from Python: arld.Agent(\"adqn\", gymnasium.make(\"{id}\"), expert=...) \
         (pip install ./python)",
        registry::described()
    )]
    UnknownId { id: String },
    #[error(
        "action {action} is out of range for {env}: it has {n_actions} actions (0 to {})",
        n_actions.saturating_sub(1)
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
    #[error("invalid environment parameter {name}: {message}")]
    InvalidParameter { name: &'static str, message: String },
    #[error("{env}: {msg}")]
    External { env: String, msg: String },
    /// The environment's own code raised (an exception of a Python environment): nothing of the step or reset
    /// happened, and a driven run pauses there and takes it again when it goes on.
    #[error("{env} raised: {msg}")]
    Raised { env: String, msg: String },
    /// A built-in task asked for with the other kind of action.
    #[error("{id} has {has}, and this needs a task with {wanted}")]
    KindMismatch {
        id: String,
        has: &'static str,
        wanted: &'static str,
    },
    #[error("cannot register environment '{id}': {msg}")]
    Register { id: String, msg: String },
    #[error("environment '{id}' is registered but not available in this build: {reason}")]
    Unavailable {
        id: &'static str,
        reason: &'static str,
    },
}

/// A Gymnasium-style episodic environment whose actions are of the kind `A` ([`Action`]): discrete (`usize`,
/// the default) or a box of float32 numbers (`Vec<f32>`).
///
/// The time limit is part of the environment (as Gymnasium's `TimeLimit` wrapper is part of `gym.make`):
/// `step` sets `truncated` when the limit is reached (on the limit step, also if it terminated there).
///
/// Observations go into a buffer the caller owns (`obs`, exactly [`Env::obs_dim`] long: a buffer of another
/// length is a bug in the caller and panics), so stepping allocates nothing; [`Env::reset`] and [`Env::step`]
/// return them in a fresh `Vec` instead, for code where one allocation per step does not matter.
pub trait Env<A: Action = usize>: Send {
    /// Starts an episode and writes its first observation into `obs`. `Some(seed)` reseeds the generator exactly
    /// as `reset(seed=seed)` does in Gymnasium; `None` continues the current generator (the first unseeded reset
    /// seeds from OS entropy, as Gymnasium).
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut [f32]);
    /// Advances one step and writes the observation after it into `obs`. Errors on an action out of range or a
    /// step without a running episode (`obs` is then left as it was).
    fn step_into(&mut self, action: A::Ref<'_>, obs: &mut [f32]) -> Result<Outcome, EnvError>;
    /// Why the last [`Env::reset_into`] failed, taken (it is reported once); `None` when it did not, as for
    /// every built-in task (only an environment in another language can fail to reset).
    fn take_reset_error(&mut self) -> Option<EnvError> {
        None
    }
    /// [`Env::reset_into`] into a fresh `Vec`.
    fn reset(&mut self, seed: Option<u64>) -> Vec<f32> {
        let mut obs = vec![0.0; self.obs_dim()];
        self.reset_into(seed, &mut obs);
        obs
    }
    /// [`Env::step_into`] into a fresh `Vec`.
    fn step(&mut self, action: A::Ref<'_>) -> Result<Step, EnvError> {
        let mut obs = vec![0.0; self.obs_dim()];
        let Outcome {
            reward,
            terminated,
            truncated,
        } = self.step_into(action, &mut obs)?;
        Ok(Step {
            obs,
            reward,
            terminated,
            truncated,
        })
    }
    /// The registered facts of this environment (id, sizes, actions, time limit, solve threshold).
    fn spec(&self) -> &'static A::Spec;
    /// Length of the observation vector.
    fn obs_dim(&self) -> usize {
        self.spec().obs_dim()
    }
    /// Gymnasium's `max_episode_steps`.
    fn max_episode_steps(&self) -> usize {
        self.spec().max_episode_steps()
    }
    /// Gymnasium's `reward_threshold`: the mean test return that counts as solving the task.
    fn solve_threshold(&self) -> f64 {
        self.spec().solve_threshold()
    }
    /// Gymnasium id, e.g. `CartPole-v0`.
    fn id(&self) -> &'static str {
        self.spec().id()
    }
    /// The generator the next unseeded reset draws from (`None` before the first reset). With
    /// [`Env::set_generator`] it lets a run put an environment back where it was: restore the generator that
    /// the episode's reset drew from, reset, and replay the episode's actions (our environments are
    /// deterministic given both).
    fn generator(&self) -> Option<NumpyRng>;
    /// Replaces the generator (see [`Env::generator`]).
    fn set_generator(&mut self, rng: Option<NumpyRng>);
    /// Overwrites the internal float64 state (classic control; used by the `set` conformance case).
    /// Resets the step counter. Environments without such a state return an error.
    fn set_state(&mut self, _state: &[f64]) -> Result<Vec<f32>, EnvError> {
        Err(state_not_supported(self.id()))
    }
    /// What a viewer needs to draw the current state (see [`Geometry`]); `None` if the environment has no
    /// drawing. Reading it never changes the environment.
    fn geometry(&self) -> Option<Geometry> {
        None
    }
}

impl dyn Env + '_ {
    /// Number of discrete actions.
    pub fn n_actions(&self) -> usize {
        self.spec().n_actions
    }
}

/// The drawable state of an environment, in the environment's own units, as a viewer (the web expert's page)
/// draws it. Points are `[x, y]` with y up.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "kind")]
pub enum Geometry {
    /// Cart position `x` (metres, the track spans `±x_threshold`) and pole angle `theta` (radians from
    /// upright, positive clockwise) of a pole `pole_length` long.
    CartPole {
        x: f64,
        theta: f64,
        x_threshold: f64,
        pole_length: f64,
    },
    /// Link angles (`theta1` from straight down, `theta2` relative to the first link) and link lengths.
    Acrobot {
        theta1: f64,
        theta2: f64,
        link_lengths: [f64; 2],
    },
    /// The car's position on the hill `hill` (a polyline of `[x, height]`), with the flag at `goal`; with
    /// continuous actions, the force the last step pushed with (its box is [-1, 1]).
    MountainCar {
        position: f64,
        height: f64,
        angle: f64,
        goal: f64,
        hill: Vec<[f64; 2]>,
        #[serde(skip_serializing_if = "Option::is_none")]
        force: Option<f64>,
    },
    /// A pendulum at angle `theta` (radians from upright, counter-clockwise) and the torque the last step
    /// applied (positive counter-clockwise), at most `max_torque` either way.
    Pendulum {
        theta: f64,
        torque: f64,
        max_torque: f64,
    },
    /// The world of LunarLander in metres: viewport size, the moon's surface (left to right), the helipad
    /// between `helipad_x` at `helipad_y`, the hull and leg polygons in world coordinates, which legs touch,
    /// and which engine fired on the last step (0 none, 1 left, 2 main, 3 right); with continuous actions, the
    /// engines' throttles on the last step (`[main, side]`: the main engine's from 0.5 to 1 when it fires, the
    /// side engines' signed, negative for the left engine, from 0.5 to 1 in size when they fire; 0 when off).
    LunarLander {
        width: f64,
        height: f64,
        terrain: Vec<[f64; 2]>,
        helipad_x: [f64; 2],
        helipad_y: f64,
        hull: Vec<[f64; 2]>,
        legs: [Vec<[f64; 2]>; 2],
        leg_contact: [bool; 2],
        engine: usize,
        #[serde(skip_serializing_if = "Option::is_none")]
        throttle: Option<[f64; 2]>,
    },
}

/// Static facts of every registered environment, in registry order (Gymnasium's registrations).
pub const SPECS: [EnvSpec; 6] = [
    EnvSpec {
        id: "CartPole-v0",
        obs_dim: 4,
        n_actions: 2,
        max_episode_steps: 200,
        solve_threshold: 195.0,
    },
    EnvSpec {
        id: "CartPole-v1",
        obs_dim: 4,
        n_actions: 2,
        max_episode_steps: 500,
        solve_threshold: 475.0,
    },
    EnvSpec {
        id: "Acrobot-v1",
        obs_dim: 6,
        n_actions: 3,
        max_episode_steps: 500,
        solve_threshold: -100.0,
    },
    EnvSpec {
        id: "MountainCar-v0",
        obs_dim: 2,
        n_actions: 3,
        max_episode_steps: 200,
        solve_threshold: -110.0,
    },
    EnvSpec {
        id: "LunarLander-v2",
        obs_dim: 8,
        n_actions: 4,
        max_episode_steps: 1000,
        solve_threshold: 200.0,
    },
    EnvSpec {
        id: "LunarLander-v3",
        obs_dim: 8,
        n_actions: 4,
        max_episode_steps: 1000,
        solve_threshold: 200.0,
    },
];

/// The ids of the built-in tasks with discrete actions ([`registry::TASKS`]).
pub fn known_ids() -> Vec<&'static str> {
    registry::ids(false).collect()
}

/// The static facts of a built-in or [`register`]ed environment, or `UnknownId`.
pub fn spec(id: &str) -> Result<&'static EnvSpec, EnvError> {
    REGISTERED.find(&SPECS, id)
}

/// The environments with discrete actions implemented outside the library (e.g. Gymnasium environments from
/// Python), registered at run time.
static REGISTERED: Registered<EnvSpec> = Registered::new();

/// The specs of tasks of one kind of action implemented outside the library, registered at run time. Each
/// distinct spec is allocated once for the life of the process.
struct Registered<S: 'static>(std::sync::Mutex<Vec<&'static S>>);

/// What a registration gives, to compare with a spec already known under its id.
struct Registration<'a, S> {
    id: &'a str,
    /// The facts given, in words.
    given: String,
    /// Whether a built-in spec has the facts given (a registration may leave some out).
    fits_builtin: &'a dyn Fn(&S) -> bool,
    /// Whether a registered spec has the facts given.
    fits: &'a dyn Fn(&S) -> bool,
    /// A known spec's facts, in words.
    describe: &'a dyn Fn(&S) -> String,
}

impl<S> Registered<S> {
    const fn new() -> Self {
        Registered(std::sync::Mutex::new(Vec::new()))
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<&'static S>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl<S: TaskSpec> Registered<S> {
    /// The spec `id` among `builtin` and the registered ones, or `UnknownId`.
    fn find(&self, builtin: &'static [S], id: &str) -> Result<&'static S, EnvError> {
        builtin
            .iter()
            .find(|spec| spec.id() == id)
            .or_else(|| self.lock().iter().copied().find(|spec| spec.id() == id))
            .ok_or_else(|| EnvError::UnknownId { id: id.to_string() })
    }

    /// The spec of a checked registration: the built-in or registered spec of its id when that has the facts
    /// given (an error naming both when not), else a new spec, `make` of the id, registered.
    fn register(
        &self,
        builtin: &'static [S],
        new: Registration<'_, S>,
        make: impl FnOnce(&'static str) -> S,
    ) -> Result<&'static S, EnvError> {
        let Registration { id, given, .. } = &new;
        // An id in use: a spec with the facts given is the answer, another an error naming both.
        let in_use =
            |known: &'static S, fits: &dyn Fn(&S) -> bool, clash: &dyn Fn(String) -> String| {
                if fits(known) {
                    Ok(known)
                } else {
                    Err(registration_error(id, clash((new.describe)(known))))
                }
            };
        if let Some(known) = builtin.iter().find(|spec| spec.id() == *id) {
            return in_use(known, new.fits_builtin, &|had| {
                format!(
                    "the built-in {id} has {had}, this one {given}; register it under another id"
                )
            });
        }
        let mut registered = self.lock();
        if let Some(&known) = registered.iter().find(|spec| spec.id() == *id) {
            return in_use(known, new.fits, &|had| {
                format!("it was registered before with {had}, now with {given}")
            });
        }
        let spec: &'static S =
            Box::leak(Box::new(make(Box::leak(id.to_string().into_boxed_str()))));
        registered.push(spec);
        Ok(spec)
    }
}

/// The error of registering `id` for the reason `msg`.
fn registration_error(id: &str, msg: String) -> EnvError {
    EnvError::Register {
        id: id.to_string(),
        msg,
    }
}

/// The first check of every registration, that the id is not empty; then the error of registering `id` for a
/// reason.
fn registering(id: &str) -> Result<impl Fn(String) -> EnvError + '_, EnvError> {
    if id.trim().is_empty() {
        return Err(registration_error(id, "the id is empty".into()));
    }
    Ok(move |msg| registration_error(id, msg))
}

/// Registers an environment implemented outside the library so that configurations can name it and an
/// [`Env`] implementation can return its spec. `reward_threshold: None` means the task has no solve threshold
/// (then no run counts as solved). The id of a built-in environment is accepted only with the built-in facts;
/// registering an id again with other facts is an error.
pub fn register(
    id: &str,
    obs_dim: usize,
    n_actions: usize,
    max_episode_steps: usize,
    reward_threshold: Option<f64>,
) -> Result<&'static EnvSpec, EnvError> {
    let bad = registering(id)?;
    if obs_dim == 0 || n_actions == 0 || max_episode_steps == 0 {
        return Err(bad(format!(
            "observation size ({obs_dim}), number of actions ({n_actions}) and time limit \
             ({max_episode_steps}) must all be positive"
        )));
    }
    let solve_threshold = match reward_threshold {
        Some(t) if t.is_nan() => return Err(bad("the reward threshold is NaN".into())),
        Some(t) => t,
        None => f64::INFINITY,
    };
    let same = |s: &EnvSpec| {
        (s.obs_dim, s.n_actions, s.max_episode_steps) == (obs_dim, n_actions, max_episode_steps)
            && (s.solve_threshold == solve_threshold)
    };
    let describe = |s: &EnvSpec| {
        format!(
            "{} observation values, {} actions, time limit {}, threshold {}",
            s.obs_dim, s.n_actions, s.max_episode_steps, s.solve_threshold
        )
    };
    let given = format!(
        "{obs_dim} observation values, {n_actions} actions, time limit {max_episode_steps}, threshold \
         {solve_threshold}"
    );
    if box_spec(id).is_ok() {
        return Err(bad(
            "the id names a task with actions in a box; register the discrete task under another id".into(),
        ));
    }
    let new = Registration {
        id,
        given,
        fits_builtin: &same,
        fits: &same,
        describe: &describe,
    };
    REGISTERED.register(&SPECS, new, |id| EnvSpec {
        id,
        obs_dim,
        n_actions,
        max_episode_steps,
        solve_threshold,
    })
}

/// The continuous-action task registered as `id` (Gymnasium's spelling; see [`continuous`]).
/// `LunarLanderContinuous-v3` is Gymnasium's `gym.make("LunarLander-v3", continuous=True)`; see
/// [`continuous_id`] for that spelling.
pub fn make_continuous(id: &str) -> Result<continuous::ContinuousEnv, EnvError> {
    match &registry::task(id)?.body {
        registry::Body::Box { spec, physics, .. } => {
            Ok(continuous::ContinuousEnv::with_spec(spec, physics()))
        }
        registry::Body::Discrete { .. } => Err(EnvError::KindMismatch {
            id: id.to_string(),
            has: "discrete actions",
            wanted: "actions in a box",
        }),
    }
}

/// The registered id of `gym.make(id, continuous=True)` where a task has both kinds of action
/// (`LunarLander-v3` and `LunarLander-v2` give `LunarLanderContinuous-v3`); `None` for any other id.
pub fn continuous_id(id: &str) -> Option<&'static str> {
    registry::TASKS
        .iter()
        .find(|task| task.id == id && task.is_box() || task.continuous_of.contains(&id))
        .map(|task| task.id)
}

/// The registered facts of a continuous-action task: a built-in one (its id as [`make_continuous`] takes it) or
/// one [`register_box`]ed.
pub fn box_spec(id: &str) -> Result<&'static BoxSpec, EnvError> {
    REGISTERED_BOXES.find(&continuous::CONTINUOUS_SPECS, id)
}

/// The continuous-action tasks implemented outside the library, registered at run time (bounds included).
static REGISTERED_BOXES: Registered<BoxSpec> = Registered::new();

/// Registers a task with actions in a box, implemented outside the library (a Gymnasium environment with a
/// `Box` action space, from Python), so that configurations can name it and an [`Env`] implementation can
/// return its spec: `low` and `high` are the box's bounds (finite, `low < high` in every dimension).
/// `reward_threshold: None` means the task has no solve threshold. As for [`register`]: the id of a built-in
/// task is accepted only with its built-in facts, an id registered again must come with the same facts, and an
/// id known for discrete actions is refused.
pub fn register_box(
    id: &str,
    obs_dim: usize,
    low: &[f32],
    high: &[f32],
    max_episode_steps: usize,
    reward_threshold: Option<f64>,
) -> Result<&'static BoxSpec, EnvError> {
    let bad = registering(id)?;
    if obs_dim == 0 || low.is_empty() || max_episode_steps == 0 {
        return Err(bad(format!(
            "observation size ({obs_dim}), action dimension ({}) and time limit ({max_episode_steps}) must all \
             be positive",
            low.len()
        )));
    }
    if low.len() != high.len() {
        return Err(bad(format!(
            "the action box has {} lower and {} upper bounds",
            low.len(),
            high.len()
        )));
    }
    if let Some(d) =
        (0..low.len()).find(|&d| !(low[d].is_finite() && high[d].is_finite() && low[d] < high[d]))
    {
        return Err(bad(format!(
            "the action box's dimension {d} is [{}, {}]; every dimension needs finite bounds, low below high \
             (rescale an unbounded action, e.g. with gymnasium.wrappers.RescaleAction or ClipAction)",
            low[d], high[d]
        )));
    }
    if reward_threshold.is_some_and(f64::is_nan) {
        return Err(bad("the reward threshold is NaN".into()));
    }
    if spec(id).is_ok() {
        return Err(bad(
            "the id names a task with discrete actions; register the box task under another id"
                .into(),
        ));
    }
    let describe = |s: &BoxSpec| {
        format!(
            "{} observation values, actions in [{:?}, {:?}], time limit {}, threshold {:?}",
            s.obs_dim, s.action_low, s.action_high, s.max_episode_steps, s.solve_threshold
        )
    };
    let same = |s: &BoxSpec| {
        (
            s.obs_dim,
            s.action_low,
            s.action_high,
            s.max_episode_steps,
            s.solve_threshold,
        ) == (obs_dim, low, high, max_episode_steps, reward_threshold)
    };
    let given = format!(
        "{obs_dim} observation values, actions in [{low:?}, {high:?}], time limit {max_episode_steps}, \
         threshold {reward_threshold:?}"
    );
    // A built-in task registered without a threshold keeps its own (Gymnasium registers none for Pendulum-v1;
    // arld's is -200).
    let same_as_builtin = |s: &BoxSpec| {
        (s.obs_dim, s.action_low, s.action_high, s.max_episode_steps)
            == (obs_dim, low, high, max_episode_steps)
            && (reward_threshold.is_none() || s.solve_threshold == reward_threshold)
    };
    let new = Registration {
        id,
        given,
        fits_builtin: &same_as_builtin,
        fits: &same,
        describe: &describe,
    };
    REGISTERED_BOXES.register(&continuous::CONTINUOUS_SPECS, new, |id| BoxSpec {
        id,
        obs_dim,
        action_low: Box::leak(low.to_vec().into_boxed_slice()),
        action_high: Box::leak(high.to_vec().into_boxed_slice()),
        max_episode_steps,
        solve_threshold: reward_threshold,
        goal: Goal::Absent(
            "is a Python environment: its success (SB3's info[\"is_success\"]) does not reach arld's replay, so \
             no transition says it succeeded",
        ),
    })
}

/// The facts of any task, discrete (built in or registered) or continuous, by id.
pub fn task_spec(id: &str) -> Result<&'static dyn TaskSpec, EnvError> {
    match box_spec(id) {
        Ok(spec) => Ok(spec),
        Err(_) => Ok(spec(id)?),
    }
}

/// A continuous-action task by id, boxed for a run.
pub fn make_box(id: &str) -> Result<Box<dyn Env<Vec<f32>>>, EnvError> {
    Ok(Box::new(make_continuous(id)?))
}

/// Builds an environment with discrete actions by Gymnasium id (a built-in task: one registered from Python is
/// made in Python).
pub fn make(id: &str) -> Result<Box<dyn Env>, EnvError> {
    match &registry::task(id)?.body {
        registry::Body::Discrete { spec, make, .. } => Ok(make(spec)),
        registry::Body::Box { .. } => Err(EnvError::KindMismatch {
            id: id.to_string(),
            has: "actions in a box",
            wanted: "discrete actions",
        }),
    }
}

/// How an episode began: with the run's seed (its first episode) or from the generator the reset drew from.
/// With the episode's actions it puts an environment back where it was ([`replay_episode`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EpisodeStart {
    Seed(u64),
    Generator([u64; 6]),
}

/// Puts `env` where an episode that began at `start` stands after `actions`: resets it the same way and takes the
/// same actions (our environments are deterministic given both). Writes the last observation into `obs`.
pub fn replay_episode<A: Action>(
    env: &mut dyn Env<A>,
    start: EpisodeStart,
    actions: &[A],
    obs: &mut Vec<f32>,
) -> Result<(), EnvError> {
    obs.resize(env.obs_dim(), 0.0);
    match start {
        EpisodeStart::Seed(seed) => env.reset_into(Some(seed), obs),
        EpisodeStart::Generator(words) => {
            env.set_generator(Some(NumpyRng::from_words(words)));
            env.reset_into(None, obs);
        }
    }
    for a in actions {
        env.step_into(a.borrow(), obs)?;
    }
    Ok(())
}

/// The physics of a built-in task, which [`Simulated`] makes an [`Env`]: the initial state, a step with a valid
/// action, and what the viewer and the conformance `set` case need.
pub trait Dynamics: Send {
    /// Draws the initial state from the reset's generator.
    fn reset(&mut self, rng: &mut NumpyRng);
    /// One step with an action in range; `rng` holds the episode's generator (a task that draws while stepping
    /// draws from it). Returns the reward and whether the task terminated.
    fn step(&mut self, action: usize, rng: &mut EnvRng) -> (f64, bool);
    /// Writes the observation of the current state into `obs`.
    fn observe(&self, obs: &mut [f32]);
    /// The float64 state that [`Env::set_state`] overwrites; `None` (the default) for a task without one.
    fn state_mut(&mut self) -> Option<&mut [f64]> {
        None
    }
    /// See [`Env::geometry`].
    fn geometry(&self) -> Option<Geometry> {
        None
    }
}

/// What [`Simulated`] needs of a task's physics, whatever its kind of action: every [`Dynamics`] of discrete
/// actions has it, and so has a [`continuous::ContinuousDynamics`] of actions in a box (boxed).
pub trait Physics: Send {
    /// The kind of the task's actions.
    type Action: Action;
    /// Draws the initial state from the reset's generator.
    fn reset(&mut self, rng: &mut NumpyRng);
    /// Checks `action` against `spec` (an error names it) and takes one step with it, drawing from the
    /// episode's generator `rng` what the step draws; returns the reward and whether the task terminated.
    fn step(
        &mut self,
        spec: &'static <Self::Action as Action>::Spec,
        action: <Self::Action as Action>::Ref<'_>,
        rng: &mut EnvRng,
    ) -> Result<(f64, bool), EnvError>;
    /// Writes the observation of the current state into `obs`.
    fn observe(&self, obs: &mut [f32]);
    /// Overwrites the internal float64 state (see [`Env::set_state`]) of the task `env`.
    fn set_state(&mut self, env: &'static str, state: &[f64]) -> Result<(), EnvError>;
    /// See [`Env::geometry`].
    fn geometry(&self) -> Option<Geometry> {
        None
    }
}

impl<D: Dynamics> Physics for D {
    type Action = usize;

    fn reset(&mut self, rng: &mut NumpyRng) {
        Dynamics::reset(self, rng);
    }

    fn step(
        &mut self,
        spec: &'static EnvSpec,
        action: usize,
        rng: &mut EnvRng,
    ) -> Result<(f64, bool), EnvError> {
        if action >= spec.n_actions {
            return Err(EnvError::ActionOutOfRange {
                env: spec.id,
                action,
                n_actions: spec.n_actions,
            });
        }
        Ok(Dynamics::step(self, action, rng))
    }

    fn observe(&self, obs: &mut [f32]) {
        Dynamics::observe(self, obs);
    }

    fn set_state(&mut self, env: &'static str, state: &[f64]) -> Result<(), EnvError> {
        let target = self.state_mut().ok_or_else(|| state_not_supported(env))?;
        check_state(env, state, target.len())?;
        target.copy_from_slice(state);
        Ok(())
    }

    fn geometry(&self) -> Option<Geometry> {
        Dynamics::geometry(self)
    }
}

/// A built-in environment: a task's [`Physics`] with what every task keeps besides its physics, its
/// registered facts, the reset generator ([`EnvRng`]) and the step bookkeeping ([`EpisodeClock`]).
#[derive(Debug, Clone)]
pub struct Simulated<P: Physics> {
    spec: &'static <P::Action as Action>::Spec,
    rng: EnvRng,
    clock: EpisodeClock,
    physics: P,
}

impl<P: Physics> Simulated<P> {
    /// The task `spec` with `physics`.
    pub(crate) fn with_spec(spec: &'static <P::Action as Action>::Spec, physics: P) -> Self {
        Simulated {
            spec,
            rng: EnvRng::default(),
            clock: EpisodeClock::new(spec.id(), spec.max_episode_steps()),
            physics,
        }
    }

    /// The task's physics (its state).
    pub fn physics(&self) -> &P {
        &self.physics
    }
}

impl<D: Dynamics> Simulated<D> {
    /// The registered environment `id` with `physics`; panics if `id` is not registered (built-in ids are).
    pub(crate) fn with_physics(id: &str, physics: D) -> Self {
        Simulated::with_spec(spec(id).unwrap_or_else(|err| panic!("{err}")), physics)
    }
}

impl<P: Physics> Env<P::Action> for Simulated<P> {
    /// Starts an episode and writes its first observation into `obs` (`reset(seed=seed)` in Gymnasium; `None`
    /// continues the current generator).
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut [f32]) {
        self.physics.reset(self.rng.reseed(seed));
        self.clock.start();
        self.physics.observe(obs);
    }

    /// Advances one step with `action` and writes the observation after it into `obs`. An action the task does
    /// not take is an error naming it, and so is a step outside an episode.
    fn step_into(
        &mut self,
        action: <P::Action as Action>::Ref<'_>,
        obs: &mut [f32],
    ) -> Result<Outcome, EnvError> {
        self.clock.check_running()?;
        let (reward, terminated) = self.physics.step(self.spec, action, &mut self.rng)?;
        let outcome = self.clock.finish_step(reward, terminated);
        self.physics.observe(obs);
        Ok(outcome)
    }

    fn spec(&self) -> &'static <P::Action as Action>::Spec {
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
        self.physics.set_state(self.spec.id(), state)?;
        self.clock.start();
        let mut obs = vec![0.0; self.spec.obs_dim()];
        self.physics.observe(&mut obs);
        Ok(obs)
    }

    fn geometry(&self) -> Option<Geometry> {
        self.physics.geometry()
    }
}

fn state_not_supported(env: &'static str) -> EnvError {
    EnvError::BadState {
        env,
        msg: "setting the internal state is not supported".into(),
    }
}

/// The seeding rule every environment shares (Gymnasium's `Env.reset(seed=...)` and `np_random`).
///
/// `Some(seed)` builds a fresh `np.random.default_rng(seed)`; `None` keeps drawing from the current generator,
/// and only the very first unseeded reset takes OS entropy, as Gymnasium does.
#[derive(Debug, Clone, Default)]
pub struct EnvRng {
    rng: Option<NumpyRng>,
}

impl EnvRng {
    /// The current generator (see [`Env::generator`]).
    pub fn get(&self) -> Option<NumpyRng> {
        self.rng.clone()
    }

    /// Replaces the current generator.
    pub fn set(&mut self, rng: Option<NumpyRng>) {
        self.rng = rng;
    }

    /// The generator the last reset left, to keep drawing from within the episode; `None` before any reset.
    pub fn current(&mut self) -> Option<&mut NumpyRng> {
        self.rng.as_mut()
    }

    /// Applies the reset seed and returns the generator to draw the initial state from.
    pub(crate) fn reseed(&mut self, seed: Option<u64>) -> &mut NumpyRng {
        match seed {
            Some(seed) => self.rng.insert(NumpyRng::new(seed)),
            None => self.rng.get_or_insert_with(NumpyRng::from_entropy),
        }
    }
}

/// Step bookkeeping every environment shares: the running flag and Gymnasium's `TimeLimit` counter.
#[derive(Debug, Clone)]
pub struct EpisodeClock {
    env: &'static str,
    max_episode_steps: usize,
    elapsed_steps: usize,
    running: bool,
}

impl EpisodeClock {
    pub fn new(env: &'static str, max_episode_steps: usize) -> Self {
        Self {
            env,
            max_episode_steps,
            elapsed_steps: 0,
            running: false,
        }
    }

    /// A new episode starts (reset or state overwrite).
    #[inline]
    pub fn start(&mut self) {
        self.elapsed_steps = 0;
        self.running = true;
    }

    /// Checks that a step may run now (an episode is running).
    #[inline]
    pub(crate) fn check_running(&self) -> Result<(), EnvError> {
        if self.running {
            Ok(())
        } else {
            Err(EnvError::NeedsReset { env: self.env })
        }
    }

    /// Counts a finished step with `reward` that `terminated` the task or not; returns its outcome, truncated
    /// when `elapsed >= max_episode_steps` (as `TimeLimit` does). After a terminal or truncated step the episode
    /// needs a reset.
    #[inline]
    pub(crate) fn finish_step(&mut self, reward: f64, terminated: bool) -> Outcome {
        self.elapsed_steps += 1;
        let truncated = self.elapsed_steps >= self.max_episode_steps;
        if terminated || truncated {
            self.running = false;
        }
        Outcome {
            reward,
            terminated,
            truncated,
        }
    }

    /// Steps taken in the current episode.
    pub fn elapsed_steps(&self) -> usize {
        self.elapsed_steps
    }

    pub fn max_episode_steps(&self) -> usize {
        self.max_episode_steps
    }
}

/// Checks a state vector given to `set_state`: right length, finite values.
pub(crate) fn check_state(env: &'static str, state: &[f64], len: usize) -> Result<(), EnvError> {
    if state.len() != len {
        return Err(EnvError::BadState {
            env,
            msg: format!("the state has {len} values, got {}", state.len()),
        });
    }
    if let Some(bad) = state.iter().find(|value| !value.is_finite()) {
        return Err(EnvError::BadState {
            env,
            msg: format!("state values must be finite, got {bad}"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The continuous tasks draw their state and the action of their last step, as the task took it (clipped to
    /// its box; the lander's throttles as Gymnasium reads an action: the main engine at 50-100% above 0, a side
    /// engine beyond 0.5 in size, signed); the discrete tasks' drawings have no such fields.
    #[test]
    fn the_continuous_tasks_draw_their_state_and_the_action_of_their_last_step() {
        let mut pendulum = make_continuous("Pendulum-v1").unwrap();
        let mut obs = vec![0.0; 3];
        pendulum.reset_into(Some(3), &mut obs);
        let drawn = |env: &continuous::ContinuousEnv| env.geometry().expect("a drawing");
        let Geometry::Pendulum { torque, .. } = drawn(&pendulum) else {
            panic!("not a pendulum")
        };
        assert_eq!(torque, 0.0);
        pendulum.step_into(&[5.0], &mut obs).unwrap();
        let Geometry::Pendulum {
            theta,
            torque,
            max_torque,
        } = drawn(&pendulum)
        else {
            panic!("not a pendulum")
        };
        assert_eq!((torque, max_torque), (2.0, 2.0));
        assert_eq!([theta.cos() as f32, theta.sin() as f32], obs[..2]);

        let mut car = make_continuous("MountainCarContinuous-v0").unwrap();
        let mut obs = vec![0.0; 2];
        car.reset_into(Some(3), &mut obs);
        car.step_into(&[-0.4], &mut obs).unwrap();
        let Geometry::MountainCar {
            position, force, ..
        } = drawn(&car)
        else {
            panic!("not a car")
        };
        assert_eq!(
            (position as f32, force),
            (obs[0], Some(f64::from(-0.4_f32)))
        );

        let mut lander = make_continuous("LunarLanderContinuous-v3").unwrap();
        let mut obs = vec![0.0; 8];
        lander.reset_into(Some(3), &mut obs);
        for (action, throttle) in [
            ([0.5, -0.8], [0.75, f64::from(-0.8_f32)]),
            ([-0.5, 0.3], [0.0, 0.0]),
            ([2.0, 0.6], [1.0, f64::from(0.6_f32)]),
        ] {
            lander.step_into(&action, &mut obs).unwrap();
            let Geometry::LunarLander { throttle: t, .. } = drawn(&lander) else {
                panic!("not a lander")
            };
            assert_eq!(t, Some(throttle), "{action:?}");
        }

        for id in ["MountainCar-v0", "LunarLander-v2"] {
            let mut env = make(id).unwrap();
            env.reset(Some(3));
            let json = serde_json::to_string(&env.geometry().unwrap()).unwrap();
            assert!(
                !json.contains("force") && !json.contains("throttle"),
                "{json}"
            );
        }
    }

    /// Stepping into one reused buffer (first filled with NaN) follows the same trajectory as fresh vectors
    /// from zeros, so every environment writes the whole observation on every reset and step; a failed step
    /// leaves the buffer as it was.
    #[test]
    fn step_into_a_reused_buffer_writes_every_value_and_matches_fresh_vectors() {
        for spec in SPECS {
            let (mut a, mut b) = (make(spec.id).unwrap(), make(spec.id).unwrap());
            let mut obs = vec![f32::NAN; spec.obs_dim];
            let mut rng = NumpyRng::new(11);
            for episode in 0..3u64 {
                a.reset_into(Some(episode), &mut obs);
                let fresh = b.reset(Some(episode));
                assert_eq!(bits(&obs), bits(&fresh), "{} reset {episode}", spec.id);
                loop {
                    let action = (rng.next_raw_u64() % spec.n_actions as u64) as usize;
                    let outcome = a.step_into(action, &mut obs).unwrap();
                    let step = b.step(action).unwrap();
                    assert_eq!(bits(&obs), bits(&step.obs), "{} step", spec.id);
                    assert_eq!(
                        (
                            outcome.reward.to_bits(),
                            outcome.terminated,
                            outcome.truncated
                        ),
                        (step.reward.to_bits(), step.terminated, step.truncated)
                    );
                    if outcome.terminated || outcome.truncated {
                        break;
                    }
                }
                let before = obs.clone();
                assert!(a.step_into(0, &mut obs).is_err(), "{}", spec.id);
                assert_eq!(bits(&obs), bits(&before), "{} failed step", spec.id);
            }
        }
    }

    /// A box task registered from outside is found by `box_spec` and `task_spec` with the facts given (bounds
    /// kept), again for the same facts, and refused for other facts, bad bounds, or an id of the other kind.
    #[test]
    fn box_tasks_register_once_with_their_bounds() {
        let id = "TestBoxTask-v0";
        let spec = register_box(id, 11, &[-3.0, -1.0], &[3.0, 1.0], 1000, Some(950.0)).unwrap();
        assert_eq!(spec.action_low, &[-3.0, -1.0]);
        assert_eq!(spec.action_high, &[3.0, 1.0]);
        assert!(std::ptr::eq(box_spec(id).unwrap(), spec));
        let any = task_spec(id).unwrap();
        assert_eq!(
            (any.obs_dim(), any.action_width(), any.solve_threshold()),
            (11, 2, 950.0)
        );
        let again = register_box(id, 11, &[-3.0, -1.0], &[3.0, 1.0], 1000, Some(950.0)).unwrap();
        assert!(
            std::ptr::eq(again, spec),
            "the same facts are the same spec"
        );
        let clash =
            register_box(id, 11, &[-3.0, -1.0], &[3.0, 2.0], 1000, Some(950.0)).unwrap_err();
        assert!(clash.to_string().contains("registered before"), "{clash}");
        // Gymnasium's Pendulum-v1 is the built-in one; other bounds under its id are refused.
        let pendulum = register_box("Pendulum-v1", 3, &[-2.0], &[2.0], 200, None).unwrap();
        assert!(std::ptr::eq(pendulum, box_spec("Pendulum-v1").unwrap()));
        assert!(register_box("Pendulum-v1", 3, &[-1.0], &[1.0], 200, None).is_err());
        // With a threshold it must be the built-in's (-200, ours: Gymnasium's has none).
        assert!(register_box("Pendulum-v1", 3, &[-2.0], &[2.0], 200, Some(-200.0)).is_ok());
        assert!(register_box("Pendulum-v1", 3, &[-2.0], &[2.0], 200, Some(-100.0)).is_err());
        for (low, high) in [(-f32::INFINITY, 1.0), (1.0, 1.0), (f32::NAN, 1.0)] {
            let err = register_box("TestBoxBad-v0", 2, &[low], &[high], 10, None).unwrap_err();
            assert!(err.to_string().contains("finite bounds"), "{err}");
        }
        assert!(register_box("TestBoxBad-v0", 2, &[0.0], &[1.0, 2.0], 10, None).is_err());
        assert!(
            box_spec("TestBoxBad-v0").is_err(),
            "nothing is registered on an error"
        );
        assert!(register_box("CartPole-v1", 4, &[-1.0], &[1.0], 500, None).is_err());
        assert!(
            register(id, 11, 3, 1000, None).is_err(),
            "a box id is not a discrete one"
        );
    }

    fn bits(values: &[f32]) -> Vec<u32> {
        values.iter().map(|v| v.to_bits()).collect()
    }
}
