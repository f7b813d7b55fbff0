//! The task registry: every built-in task declared once, in [`TASKS`].
//!
//! An entry holds what the rest of arld needs to know of a task: its Gymnasium id and the other spellings that
//! name it, the kind of its actions with its registered facts (an [`EnvSpec`] or a [`BoxSpec`]) and how its
//! environment is made, its scripted controller, the schedule of its preset (the row of the paper's table it
//! follows, steps, evaluation period), the folder of its shipped experts and its conformance traces. `arld env
//! list`, the command line's help, the unknown-id message, [`super::make`], [`super::make_continuous`], the
//! presets ([`crate::train::TrainConfig::preset`]), the scripted experts and Python derive from it, so adding a
//! task is one entry here (plus its physics). Nothing falls back silently: an id that is in no entry (and not
//! registered at run time from Python, [`super::register`]) is refused with the list of tasks.

use super::continuous::{CONTINUOUS_SPECS, ContinuousDynamics};
use super::{
    Acrobot, BoxSpec, CartPole, Env, EnvError, EnvSpec, LunarLander, MountainCar, SPECS,
    lunar_lander, mountain_car_continuous, pendulum,
};
use super::{acrobot, cartpole, mountain_car};

/// A task's kind of action with its registered facts, how its environment is made and its scripted controller.
pub enum Body {
    /// Discrete actions.
    Discrete {
        spec: &'static EnvSpec,
        make: fn(&'static EnvSpec) -> Box<dyn Env>,
        /// A hand-written controller (the `scripted` expert).
        scripted: fn(&[f32]) -> usize,
    },
    /// Actions in a box of float32 numbers.
    Box {
        spec: &'static BoxSpec,
        physics: fn() -> Box<dyn ContinuousDynamics>,
        /// A hand-written controller (the `scripted` expert).
        scripted: fn(&[f32]) -> Vec<f32>,
    },
}

/// The schedule of a task's preset: what the paper's table does not give (docs/algorithm.md §9, §15).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schedule {
    /// The row of the paper's Table 1 whose parameters the task takes (discrete tasks); `None` for a task with
    /// actions in a box, which takes the box defaults of TD3 and SAC.
    pub paper_row: Option<&'static str>,
    /// Environment steps of a run; `None`: the paper row's (or the box defaults').
    pub train_steps: Option<usize>,
    /// Environment steps between evaluations.
    pub eval_period: usize,
    /// Environment steps before learning starts.
    pub learning_starts: usize,
    /// Steps (or updates) between target network copies (a box learner's targets follow by Polyak averaging:
    /// 1).
    pub target_period: usize,
}

/// One built-in task.
pub struct Task {
    /// Gymnasium's id, as `gym.make` takes it (for the continuous lander, the id Gymnasium registered until 1.0;
    /// see [`Task::continuous_of`]).
    pub id: &'static str,
    /// What the task is, in a few words.
    pub about: &'static str,
    /// Its actions, facts, environment and scripted controller.
    pub body: Body,
    /// Its preset's schedule.
    pub schedule: Schedule,
    /// The folder of its shipped experts under `experts/` (CartPole-v1 and LunarLander-v3 share their v0 and
    /// v2 experts: the tasks differ only in their time limit and Box2D fixes).
    pub experts: &'static str,
    /// The ids whose `gym.make(id, continuous=True)` gives this task.
    pub continuous_of: &'static [&'static str],
    /// Other names of the task, as traces recorded from Gymnasium write them ([`find`]).
    pub spellings: &'static [&'static str],
    /// Files of traces recorded from Gymnasium that hold episodes of the task (in the repository; `arld env
    /// check` replays them).
    pub traces: &'static [&'static str],
}

impl Task {
    /// Whether the task's actions are in a box.
    pub(crate) fn is_box(&self) -> bool {
        matches!(self.body, Body::Box { .. })
    }

    /// The number of discrete actions, or the box's bounds, in words.
    pub fn actions(&self) -> String {
        match &self.body {
            Body::Discrete { spec, .. } => format!("{} discrete", spec.n_actions),
            Body::Box { spec, .. } => {
                let range = |i: usize| format!("[{}, {}]", spec.action_low[i], spec.action_high[i]);
                let ranges: Vec<String> = (0..spec.action_low.len()).map(range).collect();
                format!("box {}", ranges.join(" x "))
            }
        }
    }

    /// Observation size, time limit and solve threshold (`None`: the task has none).
    pub fn facts(&self) -> (usize, usize, Option<f64>) {
        match &self.body {
            Body::Discrete { spec, .. } => (
                spec.obs_dim,
                spec.max_episode_steps,
                Some(spec.solve_threshold).filter(|t| t.is_finite()),
            ),
            Body::Box { spec, .. } => (spec.obs_dim, spec.max_episode_steps, spec.solve_threshold),
        }
    }
}

/// Discrete tasks' controllers and constructors, as function pointers for the table.
fn make_cartpole(spec: &'static EnvSpec) -> Box<dyn Env> {
    Box::new(CartPole::new(spec.id))
}
fn make_acrobot(_: &'static EnvSpec) -> Box<dyn Env> {
    Box::new(Acrobot::new())
}
fn make_mountain_car(_: &'static EnvSpec) -> Box<dyn Env> {
    Box::new(MountainCar::new())
}
fn make_lander(spec: &'static EnvSpec) -> Box<dyn Env> {
    Box::new(LunarLander::new(spec.id))
}

/// The classic-control traces (CartPole-v1, Acrobot-v1, MountainCar-v0).
const CLASSIC_TRACES: &[&str] = &["tests/data/conformance/classic_control.jsonl"];
const LANDER_TRACES: &[&str] = &["tests/data/conformance/lunar_lander.jsonl"];
const CONTINUOUS_TRACES: &[&str] = &["tests/data/continuous/conformance.jsonl"];

/// The paper's schedule of a discrete task: its row, 5,000-step evaluations, 1,000 steps before learning and a
/// target copy every 1,000 steps, unless the entry says otherwise.
const fn paper(row: &'static str) -> Schedule {
    Schedule {
        paper_row: Some(row),
        train_steps: None,
        eval_period: 5_000,
        learning_starts: 1_000,
        target_period: 1_000,
    }
}

/// The schedule of a task with actions in a box: `train_steps` steps tested every `eval_period`, learning after
/// 1,000, the targets following every step \[OURS\].
const fn boxed(train_steps: usize, eval_period: usize) -> Schedule {
    Schedule {
        paper_row: None,
        train_steps: Some(train_steps),
        eval_period,
        learning_starts: 1_000,
        target_period: 1,
    }
}

/// CartPole: the notes suggest a target period of 500; with 500 bootstrapped DQN solved only 3 of 5 seeds within
/// the paper's 20k steps (medians 16k), with 250 all 5 (median 7k, the paper's 8k).
const CARTPOLE: Schedule = Schedule {
    eval_period: 1_000,
    learning_starts: 500,
    target_period: 250,
    ..paper("CartPole-v0")
};

/// Every built-in task, discrete ones first, in Gymnasium's registration order (laid out as a table, three lines a
/// task: its id and words, its actions, its preset and names).
#[rustfmt::skip]
pub static TASKS: [Task; 9] = [
    // CartPole-v0's physics are CartPole-v1's, whose traces test them.
    Task { id: "CartPole-v0", about: "balance a pole on a cart (200 steps)",
        body: Body::Discrete { spec: &SPECS[0], make: make_cartpole, scripted: cartpole::balance },
        schedule: CARTPOLE, experts: "CartPole-v0", continuous_of: &[], spellings: &[], traces: &[] },
    Task { id: "CartPole-v1", about: "balance a pole on a cart (500 steps)",
        body: Body::Discrete { spec: &SPECS[1], make: make_cartpole, scripted: cartpole::balance },
        schedule: CARTPOLE, experts: "CartPole-v0", continuous_of: &[], spellings: &[], traces: CLASSIC_TRACES },
    Task { id: "Acrobot-v1", about: "swing a two-link arm's tip above a bar",
        body: Body::Discrete { spec: &SPECS[2], make: make_acrobot, scripted: acrobot::pump },
        schedule: Schedule { eval_period: 2_000, ..paper("Acrobot-v1") }, experts: "Acrobot-v1", continuous_of: &[], spellings: &[], traces: CLASSIC_TRACES },
    Task { id: "MountainCar-v0", about: "drive an underpowered car up a hill (sparse reward)",
        body: Body::Discrete { spec: &SPECS[3], make: make_mountain_car, scripted: mountain_car::push_with_motion },
        schedule: Schedule { eval_period: 10_000, ..paper("MountainCar-v0") }, experts: "MountainCar-v0", continuous_of: &[], spellings: &[], traces: CLASSIC_TRACES },
    // LunarLander-v2's world is LunarLander-v3's less the v3 fixes; the traces are v3's.
    Task { id: "LunarLander-v2", about: "land a craft on a pad with four engine choices (Box2D)",
        body: Body::Discrete { spec: &SPECS[4], make: make_lander, scripted: lunar_lander::heuristic_action },
        schedule: paper("LunarLander-v2"), experts: "LunarLander-v2", continuous_of: &[], spellings: &[], traces: &[] },
    Task { id: "LunarLander-v3", about: "land a craft on a pad with four engine choices (Box2D, v3 fixes)",
        body: Body::Discrete { spec: &SPECS[5], make: make_lander, scripted: lunar_lander::heuristic_action },
        schedule: paper("LunarLander-v2"), experts: "LunarLander-v2", continuous_of: &[], spellings: &[], traces: LANDER_TRACES },
    Task { id: "Pendulum-v1", about: "swing a pendulum up and hold it upright with a torque",
        body: Body::Box { spec: &CONTINUOUS_SPECS[0], physics: || Box::new(pendulum::Pendulum::default()), scripted: |obs| pendulum::swing_up(obs).to_vec() },
        schedule: boxed(20_000, 1_000), experts: "Pendulum-v1", continuous_of: &[], spellings: &[], traces: CONTINUOUS_TRACES },
    Task { id: "MountainCarContinuous-v0", about: "drive an underpowered car up a hill with a throttle (sparse reward)",
        body: Body::Box { spec: &CONTINUOUS_SPECS[1], physics: || Box::new(mountain_car_continuous::MountainCarContinuous::default()), scripted: |obs| mountain_car_continuous::momentum(obs, 0.6).to_vec() },
        schedule: boxed(100_000, 5_000), experts: "MountainCarContinuous-v0", continuous_of: &[], spellings: &[], traces: CONTINUOUS_TRACES },
    Task { id: "LunarLanderContinuous-v3", about: "land a craft on a pad with throttled main and side engines (Box2D)",
        body: Body::Box { spec: &CONTINUOUS_SPECS[2], physics: || Box::new(lunar_lander::LunarLanderContinuous::default()), scripted: |obs| lunar_lander::heuristic_throttle(obs).to_vec() },
        schedule: boxed(300_000, 10_000), experts: "LunarLanderContinuous-v3", continuous_of: &["LunarLander-v3", "LunarLander-v2"], spellings: &["LunarLanderContinuous"], traces: CONTINUOUS_TRACES },
];

/// The built-in task `id`, or `UnknownId` (whose message lists every task).
pub fn task(id: &str) -> Result<&'static Task, EnvError> {
    TASKS
        .iter()
        .find(|task| task.id == id)
        .ok_or_else(|| EnvError::UnknownId { id: id.to_string() })
}

/// The built-in task `name` names: its id or one of its [`Task::spellings`]; else `UnknownId`.
pub fn find(name: &str) -> Result<&'static Task, EnvError> {
    task(name).or_else(|error| {
        TASKS
            .iter()
            .find(|task| task.spellings.contains(&name))
            .ok_or(error)
    })
}

/// The ids of the built-in tasks, discrete or with actions in a box.
pub fn ids(boxed: bool) -> impl Iterator<Item = &'static str> {
    TASKS
        .iter()
        .filter(move |task| task.is_box() == boxed)
        .map(|task| task.id)
}

/// Every built-in task in words, for messages and help: the discrete ones, then those with actions in a box.
pub fn described() -> String {
    let discrete: Vec<&str> = ids(false).collect();
    let boxed: Vec<&str> = ids(true).collect();
    format!(
        "discrete actions: {}; actions in a box: {}",
        discrete.join(", "),
        boxed.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_entry_agrees_with_its_spec_and_makes_its_task() {
        for task in &TASKS {
            match &task.body {
                Body::Discrete { spec, make, .. } => {
                    assert_eq!(spec.id, task.id);
                    assert_eq!(make(spec).id(), task.id);
                }
                Body::Box { spec, .. } => {
                    assert_eq!(spec.id, task.id);
                    assert_eq!(
                        super::super::make_continuous(task.id).unwrap().id(),
                        task.id
                    );
                }
            }
        }
        let listed: usize = SPECS.len() + CONTINUOUS_SPECS.len();
        assert_eq!(TASKS.len(), listed, "every spec has one entry");
    }

    #[test]
    fn an_unknown_id_is_refused_naming_every_task() {
        let msg = task("Pendulum-v9").err().unwrap().to_string();
        for t in &TASKS {
            assert!(msg.contains(t.id), "{msg} lacks {}", t.id);
        }
        assert!(super::super::make_continuous("Pendulum-v9").is_err());
        assert!(super::super::make_continuous("CartPole-v0").is_err());
        assert!(super::super::make("Pendulum-v1").is_err());
    }
}
