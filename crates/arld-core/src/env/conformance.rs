//! Conformance checking: replays Gymnasium-recorded traces against our environments.
//!
//! A trace file (format in `conformance/README.md`) is JSON lines: a `meta` line, then per episode a `start`
//! line (environment id, case, seed, the first observation, for the `set` case the float64 state to set)
//! followed by its `step` lines (action, observation, reward, terminated, truncated). A task with discrete actions
//! states its number of actions at the start and an action index per step; a task with actions in a box states
//! its `action_dim` and bounds and a float32 vector per step (`tests/data/continuous/conformance.jsonl`). The task
//! is found in the registry by id or by a spelling a trace uses ([`super::registry::find`]). [`check_reader`] streams
//! such a file line by line: it resets one environment per id the way the case prescribes, replays the
//! recorded actions and compares what comes back. Per environment it fills an [`EnvReport`]: episodes,
//! episodes reproduced bit for bit, largest observation and reward deviations, the first divergence and the
//! verdict of the environment's [`Tolerance`].
//!
//! Broken input (unreadable file, malformed JSON, step without start, actions out of range, unknown ids) is
//! a [`ConformanceError`] that names the file and line; a mismatch between our environment and the trace is
//! not an error but a divergence in the report.

use super::registry::{self, Body};
use super::{Env, EnvError, Step};
use serde::Deserialize;
use std::collections::HashMap;
use std::fmt;
use std::io::BufRead;
use std::path::Path;
use thiserror::Error;

/// How closely an environment must follow its trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerance {
    /// Largest allowed absolute deviation of any observation component and of the reward.
    pub abs: f64,
    /// Fraction of `heuristic` episodes allowed to diverge (`seed` and `set` episodes must all match).
    pub heuristic_divergence_allowed: f64,
}

impl Tolerance {
    /// Classic control is float64 arithmetic in the same order as Gymnasium: 1e-6 on everything, no divergence.
    pub(crate) const CLASSIC_CONTROL: Tolerance = Tolerance {
        abs: 1e-6,
        heuristic_divergence_allowed: 0.0,
    };
    /// Box2D runs in float32 and long episodes are chaotic: 1e-4, and up to 10% of the long heuristic
    /// episodes may drift away (conformance README).
    pub(crate) const BOX2D: Tolerance = Tolerance {
        abs: 1e-4,
        heuristic_divergence_allowed: 0.1,
    };

    /// The tolerance that applies to an environment id.
    pub(crate) fn for_env(id: &str) -> Tolerance {
        if id.starts_with("LunarLander") {
            Self::BOX2D
        } else {
            Self::CLASSIC_CONTROL
        }
    }
}

/// Where and how an environment first left its trace.
#[derive(Debug, Clone, PartialEq)]
pub struct Divergence {
    /// Episode number within this environment's episodes in the file (from 0).
    pub episode: usize,
    /// The trace case (`seed`, `set`, `heuristic`) and its seed.
    pub case: String,
    pub seed: u64,
    /// Step of the episode (0 is the reset observation; steps count from 1 as in the trace's `t`).
    pub step: usize,
    /// 1-based line of the trace file.
    pub line: usize,
    /// What differed.
    pub what: String,
}

impl fmt::Display for Divergence {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "episode {} ({} {}), step {} (line {}): {}",
            self.episode, self.case, self.seed, self.step, self.line, self.what
        )
    }
}

/// Replay result for one environment of one trace file.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvReport {
    pub env: String,
    pub tolerance: Tolerance,
    /// Episodes replayed.
    pub episodes: usize,
    /// Episodes reproduced bit for bit (every observation, reward, flag and the length).
    pub episodes_exact: usize,
    /// Episodes that left the tolerance somewhere (deviation, flags or length), by case.
    pub diverged_by_case: Vec<(String, usize, usize)>,
    /// Largest absolute observation deviation over all compared observations.
    pub max_obs_deviation: f64,
    /// Largest absolute reward deviation over all compared steps.
    pub max_reward_deviation: f64,
    /// Steps compared.
    pub steps: usize,
    pub first_divergence: Option<Divergence>,
}

impl EnvReport {
    fn new(env: &str) -> Self {
        Self {
            env: env.to_string(),
            tolerance: Tolerance::for_env(env),
            episodes: 0,
            episodes_exact: 0,
            diverged_by_case: Vec::new(),
            max_obs_deviation: 0.0,
            max_reward_deviation: 0.0,
            steps: 0,
            first_divergence: None,
        }
    }

    /// Episodes that diverged, all cases together.
    pub fn episodes_diverged(&self) -> usize {
        self.diverged_by_case
            .iter()
            .map(|(_, diverged, _)| diverged)
            .sum()
    }

    /// The verdict: no `seed`/`set` episode diverged, and the `heuristic` divergences stay within the allowance.
    pub fn passed(&self) -> bool {
        self.diverged_by_case
            .iter()
            .all(|(case, diverged, episodes)| {
                if case == "heuristic" {
                    *diverged as f64
                        <= self.tolerance.heuristic_divergence_allowed * *episodes as f64
                } else {
                    *diverged == 0
                }
            })
    }

    fn case_counts(&mut self, case: &str) -> &mut (String, usize, usize) {
        let index = match self.diverged_by_case.iter().position(|(c, _, _)| c == case) {
            Some(index) => index,
            None => {
                self.diverged_by_case.push((case.to_string(), 0, 0));
                self.diverged_by_case.len() - 1
            }
        };
        &mut self.diverged_by_case[index]
    }
}

/// Broken trace input (as opposed to an environment that does not match it).
#[derive(Debug, Error)]
pub enum ConformanceError {
    // The underlying errors are part of the message (not `#[source]`), so chains print them once.
    #[error("cannot read {file}: {error}")]
    Io { file: String, error: std::io::Error },
    #[error("{file}:{line}: malformed trace line: {msg}")]
    Malformed {
        file: String,
        line: usize,
        msg: String,
    },
    #[error("{file}:{line}: {error}")]
    Env {
        file: String,
        line: usize,
        error: EnvError,
    },
}

/// One line of a trace file. Unknown fields (e.g. `action_seed`, `state` on steps) are ignored.
#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
enum TraceLine {
    Meta {},
    Start(StartLine),
    Step(StepLine),
}

/// The start of an episode in a trace: how the environment was reset, and the first observation.
#[derive(Debug, Deserialize)]
struct StartLine {
    env: String,
    case: String,
    seed: u64,
    /// Discrete actions: their number.
    n_actions: Option<usize>,
    /// Actions in a box: the dimension and bounds.
    action_dim: Option<usize>,
    action_low: Option<Vec<f32>>,
    action_high: Option<Vec<f32>>,
    max_episode_steps: usize,
    obs: Vec<f64>,
    state: Option<Vec<f64>>,
}

/// One step of an episode in a trace: the action and what the environment gave back.
#[derive(Debug, Deserialize)]
struct StepLine {
    env: String,
    t: usize,
    action: TraceAction,
    obs: Vec<f64>,
    reward: f64,
    terminated: bool,
    truncated: bool,
}

/// A recorded action: an index (discrete actions) or a float32 vector (a box).
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum TraceAction {
    Index(usize),
    Vector(Vec<f32>),
}

/// The environment a trace's episodes replay in, of either kind of action.
enum Replayed {
    Discrete(Box<dyn Env>),
    Boxed(Box<dyn Env<Vec<f32>>>),
}

impl Replayed {
    /// The built-in task a trace names (by id or by a spelling of the registry).
    fn make(id: &str) -> Result<Self, EnvError> {
        let task = registry::find(id)?;
        Ok(match &task.body {
            Body::Discrete { spec, make, .. } => Replayed::Discrete(make(spec)),
            Body::Box { .. } => Replayed::Boxed(super::make_box(task.id)?),
        })
    }

    /// Whether the trace's start line states this task's actions and time limit; else what differs.
    fn check_start(
        &self,
        n_actions: Option<usize>,
        bounds: (Option<usize>, Option<&[f32]>, Option<&[f32]>),
        max_episode_steps: usize,
    ) -> Result<(), String> {
        let (id, limit, ours, theirs) = match self {
            Replayed::Discrete(env) => (
                env.id(),
                env.max_episode_steps(),
                format!("{} actions", env.n_actions()),
                n_actions.map(|n| format!("{n} actions")),
            ),
            Replayed::Boxed(env) => {
                let spec = env.spec();
                let box_of = |dim: usize, low: &[f32], high: &[f32]| {
                    format!("{dim}-dimensional actions in [{low:?}, {high:?}]")
                };
                let theirs = match bounds {
                    (Some(dim), Some(low), Some(high)) => Some(box_of(dim, low, high)),
                    _ => None,
                };
                (
                    env.id(),
                    env.max_episode_steps(),
                    box_of(spec.action_low.len(), spec.action_low, spec.action_high),
                    theirs,
                )
            }
        };
        let Some(theirs) = theirs else {
            return Err(format!(
                "{id} has {ours}: a start line of it needs them (`n_actions`, or `action_dim`, `action_low` and \
                 `action_high`)"
            ));
        };
        if ours != theirs || limit != max_episode_steps {
            return Err(format!(
                "{id} has {ours} and a {limit}-step limit, the trace says {theirs} and {max_episode_steps}"
            ));
        }
        Ok(())
    }

    fn reset(&mut self, seed: u64) -> Vec<f32> {
        match self {
            Replayed::Discrete(env) => env.reset(Some(seed)),
            Replayed::Boxed(env) => env.reset(Some(seed)),
        }
    }

    fn set_state(&mut self, state: &[f64]) -> Result<Vec<f32>, EnvError> {
        match self {
            Replayed::Discrete(env) => env.set_state(state),
            Replayed::Boxed(env) => env.set_state(state),
        }
    }

    /// Whether a recorded action is of this task's kind and in its range: a wrong kind is a malformed line
    /// (`Err(Ok(message))`), an index out of range the environment's error (`Err(Err(error))`).
    fn check_action(&self, action: &TraceAction) -> Result<(), Result<String, EnvError>> {
        match (self, action) {
            (Replayed::Discrete(env), TraceAction::Index(a)) if *a >= env.n_actions() => {
                Err(Err(EnvError::ActionOutOfRange {
                    env: env.id(),
                    action: *a,
                    n_actions: env.n_actions(),
                }))
            }
            (Replayed::Discrete(_), TraceAction::Index(_))
            | (Replayed::Boxed(_), TraceAction::Vector(_)) => Ok(()),
            (Replayed::Discrete(env), TraceAction::Vector(_)) => Err(Ok(format!(
                "{} has discrete actions, the step records a vector",
                env.id()
            ))),
            (Replayed::Boxed(env), TraceAction::Index(_)) => Err(Ok(format!(
                "{} has actions in a box, the step records an index",
                env.id()
            ))),
        }
    }

    /// One step with a recorded action [`Replayed::check_action`] accepted.
    fn step(&mut self, action: &TraceAction) -> Result<Step, EnvError> {
        match (self, action) {
            (Replayed::Discrete(env), TraceAction::Index(a)) => env.step(*a),
            (Replayed::Boxed(env), TraceAction::Vector(a)) => env.step(a),
            (env, _) => Err(EnvError::BadState {
                env: env.id(),
                msg: "an action of the other kind (check_action refuses it)".into(),
            }),
        }
    }

    fn id(&self) -> &'static str {
        match self {
            Replayed::Discrete(env) => env.id(),
            Replayed::Boxed(env) => env.id(),
        }
    }
}

/// The episode being replayed.
struct Episode {
    env: String,
    case: String,
    seed: u64,
    /// Index in this environment's episodes.
    index: usize,
    /// Last step number seen (0 after `start`).
    t: usize,
    /// Our environment ended (or could not continue) before the trace did.
    ended: bool,
    diverged: bool,
    exact: bool,
}

/// The longest line of a trace file (a step line is a few hundred bytes; a start line with a recorded state a
/// few kilobytes).
pub(crate) const MAX_LINE_BYTES: usize = 1 << 20;

/// Replays a trace file. See [`check_reader`].
pub fn check_file(path: &Path) -> Result<Vec<EnvReport>, ConformanceError> {
    let file_name = path.display().to_string();
    // Only a regular file: a named pipe or a device is refused at once (a pipe without a writer never ends).
    let file = crate::files::open_regular(path).map_err(|error| ConformanceError::Io {
        file: file_name.clone(),
        error,
    })?;
    check_reader(std::io::BufReader::new(file), &file_name)
}

/// Replays a trace streamed from `reader` (`file_name` is used in messages) against the registered
/// environments; returns one report per environment in order of first appearance.
pub fn check_reader(
    mut reader: impl BufRead,
    file_name: &str,
) -> Result<Vec<EnvReport>, ConformanceError> {
    let mut replay = Replay {
        file_name,
        envs: HashMap::new(),
        reports: Vec::new(),
        episode: None,
    };
    let mut bytes = Vec::new();
    for index in 0.. {
        let line = index + 1;
        // Lines are bounded: an input without line breaks (`/dev/zero`) is an error, not all of the memory.
        let more = crate::files::read_line_bounded(&mut reader, &mut bytes, MAX_LINE_BYTES)
            .map_err(|error| ConformanceError::Io {
                file: format!("{file_name}:{line}"),
                error,
            })?;
        if !more {
            break;
        }
        let text = std::str::from_utf8(&bytes)
            .map_err(|_| malformed(file_name, line, "not UTF-8".into()))?;
        if text.trim().is_empty() {
            continue;
        }
        let parsed: TraceLine = serde_json::from_str(text)
            .map_err(|err| malformed(file_name, line, err.to_string()))?;
        match parsed {
            TraceLine::Meta {} => {}
            TraceLine::Start(start) => replay.start(line, start)?,
            TraceLine::Step(step) => replay.step(line, step)?,
        }
    }
    if let Some(done) = replay.episode.take() {
        finish_episode(&mut replay.reports, done);
    }
    Ok(replay.reports)
}

/// A trace being replayed: the environments it names, a report for each, and the episode under way.
struct Replay<'f> {
    file_name: &'f str,
    envs: HashMap<String, Replayed>,
    reports: Vec<EnvReport>,
    episode: Option<Episode>,
}

/// The error of a line of the trace `file` that is not what a trace holds.
fn malformed(file: &str, line: usize, msg: String) -> ConformanceError {
    ConformanceError::Malformed {
        file: file.to_string(),
        line,
        msg,
    }
}

/// The error of our environment at a line of the trace `file`.
fn env_failed(file: &str, line: usize, error: EnvError) -> ConformanceError {
    ConformanceError::Env {
        file: file.to_string(),
        line,
        error,
    }
}

impl Replay<'_> {
    /// A start line: ends the episode under way, resets (or sets) the environment as the trace did and compares
    /// the first observation.
    fn start(&mut self, line: usize, start: StartLine) -> Result<(), ConformanceError> {
        let env_id = start.env;
        let file = self.file_name;
        let malformed = |msg| malformed(file, line, msg);
        if let Some(done) = self.episode.take() {
            finish_episode(&mut self.reports, done);
        }
        if !self.envs.contains_key(&env_id) {
            let built = Replayed::make(&env_id).map_err(|err| env_failed(file, line, err))?;
            self.envs.insert(env_id.clone(), built);
            self.reports.push(EnvReport::new(&env_id));
        }
        let env = self.envs.get_mut(&env_id).expect("inserted above");
        let bounds = (
            start.action_dim,
            start.action_low.as_deref(),
            start.action_high.as_deref(),
        );
        env.check_start(start.n_actions, bounds, start.max_episode_steps)
            .map_err(malformed)?;
        let first_obs = match start.case.as_str() {
            "seed" | "heuristic" => env.reset(start.seed),
            "set" => {
                let state = start
                    .state
                    .ok_or_else(|| malformed("a `set` start line needs a `state`".into()))?;
                // Gymnasium: reset(seed=0), then the state is overwritten.
                env.reset(0);
                env.set_state(&state)
                    .map_err(|err| env_failed(file, line, err))?
            }
            other => {
                return Err(malformed(format!(
                    "unknown case '{other}' (expected seed, set or heuristic)"
                )));
            }
        };
        let report = report_for(&mut self.reports, &env_id);
        let mut current = Episode {
            env: env_id,
            case: start.case,
            seed: start.seed,
            index: report.episodes,
            t: 0,
            ended: false,
            diverged: false,
            exact: true,
        };
        report.episodes += 1;
        compare_obs(report, &mut current, line, &first_obs, &start.obs).map_err(malformed)?;
        self.episode = Some(current);
        Ok(())
    }

    /// A step line: steps the environment with the recorded action and compares what it gives back (nothing
    /// more once our episode ended before the trace's).
    fn step(&mut self, line: usize, step_line: StepLine) -> Result<(), ConformanceError> {
        let (t, action, reward) = (step_line.t, &step_line.action, step_line.reward);
        let file = self.file_name;
        let malformed = |msg| malformed(file, line, msg);
        let env_error = |err| env_failed(file, line, err);
        let current = self
            .episode
            .as_mut()
            .ok_or_else(|| malformed("step line before any start line".into()))?;
        if step_line.env != current.env {
            return Err(malformed(format!(
                "step of {} inside an episode of {}",
                step_line.env, current.env
            )));
        }
        if t != current.t + 1 {
            return Err(malformed(format!("step t={t} follows t={}", current.t)));
        }
        current.t = t;
        let env = self.envs.get_mut(&current.env).expect("created at start");
        env.check_action(action).map_err(|problem| match problem {
            Ok(msg) => malformed(msg),
            Err(err) => env_error(err),
        })?;
        let report = report_for(&mut self.reports, &current.env);
        if current.ended {
            return Ok(());
        }
        let step = env.step(action).map_err(env_error)?;
        report.steps += 1;
        compare_obs(report, current, line, &step.obs, &step_line.obs).map_err(malformed)?;
        let reward_deviation = (step.reward - reward).abs();
        report.max_reward_deviation = report.max_reward_deviation.max(reward_deviation);
        if step.reward != reward {
            current.exact = false;
        }
        if reward_deviation > report.tolerance.abs || reward_deviation.is_nan() {
            diverge(
                report,
                current,
                line,
                format!("reward {} vs {reward}", step.reward),
            );
        }
        let (terminated, truncated) = (step_line.terminated, step_line.truncated);
        if (step.terminated, step.truncated) != (terminated, truncated) {
            current.exact = false;
            diverge(
                report,
                current,
                line,
                format!(
                    "terminated/truncated {}/{} vs {terminated}/{truncated}",
                    step.terminated, step.truncated
                ),
            );
        }
        if (step.terminated || step.truncated) && !(terminated || truncated) {
            // Our episode is over, the trace's is not: the rest of it cannot be replayed.
            current.ended = true;
        }
        Ok(())
    }
}

fn report_for<'a>(reports: &'a mut [EnvReport], env: &str) -> &'a mut EnvReport {
    reports
        .iter_mut()
        .find(|report| report.env == env)
        .expect("report created with the environment")
}

/// Compares an observation with the trace's; a length mismatch is a malformed trace.
fn compare_obs(
    report: &mut EnvReport,
    episode: &mut Episode,
    line: usize,
    ours: &[f32],
    expected: &[f64],
) -> Result<(), String> {
    if ours.len() != expected.len() {
        return Err(format!(
            "observation has {} values, {} has {}",
            expected.len(),
            report.env,
            ours.len()
        ));
    }
    let mut worst = 0.0f64;
    let mut exact = true;
    for (&mine, &theirs) in ours.iter().zip(expected) {
        let mine = f64::from(mine);
        exact &= mine == theirs;
        let deviation = (mine - theirs).abs();
        // NaN deviations count as infinitely far.
        worst = worst.max(if deviation.is_nan() {
            f64::INFINITY
        } else {
            deviation
        });
    }
    report.max_obs_deviation = report.max_obs_deviation.max(worst);
    if !exact {
        episode.exact = false;
    }
    if worst > report.tolerance.abs {
        diverge(
            report,
            episode,
            line,
            format!("observation deviates by {worst:.3e}"),
        );
    }
    Ok(())
}

fn diverge(report: &mut EnvReport, episode: &mut Episode, line: usize, what: String) {
    episode.exact = false;
    if !episode.diverged {
        episode.diverged = true;
        if report.first_divergence.is_none() {
            report.first_divergence = Some(Divergence {
                episode: episode.index,
                case: episode.case.clone(),
                seed: episode.seed,
                step: episode.t,
                line,
                what,
            });
        }
    }
}

fn finish_episode(reports: &mut [EnvReport], episode: Episode) {
    let report = report_for(reports, &episode.env);
    if episode.exact && !episode.ended {
        report.episodes_exact += 1;
    }
    let counts = report.case_counts(&episode.case);
    counts.2 += 1;
    if episode.diverged {
        counts.1 += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(text: &str) -> Result<Vec<EnvReport>, ConformanceError> {
        check_reader(text.as_bytes(), "trace.jsonl")
    }

    /// Writes a trace of CartPole-v1 from our own environment (so it matches by construction) with the
    /// given actions; `tamper` may edit each step line's JSON before it is written.
    fn own_trace(actions: &[usize], tamper: impl Fn(usize, &mut serde_json::Value)) -> String {
        let mut env = super::super::make("CartPole-v1").unwrap();
        let obs = env.reset(Some(7));
        let mut lines = vec![
            r#"{"kind":"meta"}"#.to_string(),
            serde_json::json!({"kind":"start","env":"CartPole-v1","case":"seed","seed":7,"action_seed":7,
                "n_actions":2,"max_episode_steps":500,"obs":obs})
            .to_string(),
        ];
        for (i, &action) in actions.iter().enumerate() {
            let step = env.step(action).unwrap();
            let mut value = serde_json::json!({"kind":"step","env":"CartPole-v1","case":"seed","seed":7,
                "t":i + 1,"action":action,"obs":step.obs,"reward":step.reward,
                "terminated":step.terminated,"truncated":step.truncated});
            tamper(i + 1, &mut value);
            lines.push(value.to_string());
        }
        lines.join("\n")
    }

    #[test]
    fn own_trace_matches_exactly() {
        let reports = check(&own_trace(&[0, 1, 1, 0, 1], |_, _| {})).unwrap();
        assert_eq!(reports.len(), 1);
        let report = &reports[0];
        assert_eq!(
            (report.episodes, report.episodes_exact, report.steps),
            (1, 1, 5)
        );
        assert_eq!(report.max_obs_deviation, 0.0);
        assert!(report.passed() && report.first_divergence.is_none());
    }

    #[test]
    fn perturbed_observation_is_a_divergence_at_its_step() {
        let trace = own_trace(&[0, 1, 1, 0, 1], |t, value| {
            if t == 3 {
                let x = value["obs"][1].as_f64().unwrap();
                value["obs"][1] = serde_json::json!(x + 1e-3);
            }
        });
        let report = &check(&trace).unwrap()[0];
        assert!(!report.passed());
        assert_eq!(report.episodes_exact, 0);
        let divergence = report.first_divergence.as_ref().unwrap();
        assert_eq!(
            (divergence.episode, divergence.step, divergence.line),
            (0, 3, 5)
        );
        assert!((report.max_obs_deviation - 1e-3).abs() < 1e-6);
    }

    #[test]
    fn tiny_deviation_within_tolerance_passes_but_is_not_exact() {
        let trace = own_trace(&[1, 1], |t, value| {
            if t == 2 {
                value["reward"] = serde_json::json!(1.0 + 1e-9);
            }
        });
        let report = &check(&trace).unwrap()[0];
        assert!(report.passed());
        assert_eq!(report.episodes_exact, 0);
    }

    #[test]
    fn wrong_flags_diverge() {
        let trace = own_trace(&[1, 1], |t, value| {
            if t == 2 {
                value["terminated"] = serde_json::json!(true);
            }
        });
        let report = &check(&trace).unwrap()[0];
        assert!(!report.passed());
        assert!(
            report
                .first_divergence
                .as_ref()
                .unwrap()
                .what
                .contains("terminated")
        );
    }

    #[test]
    fn malformed_line_names_file_and_line() {
        let mut trace = own_trace(&[1, 1], |_, _| {});
        trace.push_str("\n{\"kind\":\"step\", oops}");
        let err = check(&trace).unwrap_err();
        assert!(
            matches!(err, ConformanceError::Malformed { line: 5, .. }),
            "{err:?}"
        );
        assert!(err.to_string().starts_with("trace.jsonl:5:"), "{err}");
    }

    #[test]
    fn missing_fields_are_malformed() {
        let err = check(r#"{"kind":"start","env":"CartPole-v1"}"#).unwrap_err();
        assert!(
            matches!(err, ConformanceError::Malformed { line: 1, .. }),
            "{err}"
        );
    }

    #[test]
    fn unknown_env_id_is_an_error_listing_known_ids() {
        let trace = r#"{"kind":"meta"}
{"kind":"start","env":"Pong-v5","case":"seed","seed":0,"n_actions":6,"max_episode_steps":100,"obs":[0.0]}"#;
        let err = check(trace).unwrap_err();
        assert!(
            matches!(
                &err,
                ConformanceError::Env {
                    line: 2,
                    error: EnvError::UnknownId { .. },
                    ..
                }
            ),
            "{err:?}"
        );
        let message = err.to_string();
        assert!(
            message.contains("Pong-v5") && message.contains("CartPole-v1"),
            "{message}"
        );
    }

    #[test]
    fn action_out_of_range_is_an_error() {
        let trace = own_trace(&[1, 1], |t, value| {
            if t == 2 {
                value["action"] = serde_json::json!(5);
            }
        });
        let err = check(&trace).unwrap_err();
        assert!(
            matches!(
                &err,
                ConformanceError::Env {
                    line: 4,
                    error: EnvError::ActionOutOfRange { action: 5, .. },
                    ..
                }
            ),
            "{err:?}"
        );
    }

    #[test]
    fn step_before_start_is_malformed() {
        let trace = r#"{"kind":"step","env":"CartPole-v1","t":1,"action":0,"obs":[0,0,0,0],"reward":1.0,"terminated":false,"truncated":false}"#;
        assert!(matches!(
            check(trace),
            Err(ConformanceError::Malformed { line: 1, .. })
        ));
    }

    #[test]
    fn missing_file_is_an_io_error() {
        let err = check_file(Path::new("/nonexistent/trace.jsonl")).unwrap_err();
        assert!(matches!(err, ConformanceError::Io { .. }));
        assert!(err.to_string().contains("/nonexistent/trace.jsonl"));
    }

    #[test]
    fn heuristic_allowance_is_ten_percent() {
        let mut report = EnvReport::new("LunarLander-v3");
        report.diverged_by_case = vec![("seed".into(), 0, 5), ("heuristic".into(), 1, 10)];
        assert!(report.passed());
        report.diverged_by_case[1].1 = 2;
        assert!(!report.passed());
        report.diverged_by_case = vec![("seed".into(), 1, 5), ("heuristic".into(), 0, 10)];
        assert!(!report.passed());
    }
}
