//! Demonstrations: transitions collected from an expert before training (DQfD), and their file format.
//!
//! File format (`.jsonl`, readable from any language): the first line is a header object
//! `{"format": "arld-demos", "version": 1, "env": ID, "expert": SPEC, "seed": S, "obs_dim": D, "n_actions": A,
//! "transitions": N, "episodes": E}`, then one object per transition in order:
//! `{"episode": e, "obs": [...], "action": a, "reward": r, "next_obs": [...], "terminated": bool,
//! "truncated": bool}`. In a task with actions in a box the header says the box instead of `n_actions`
//! (`"action_dim": K, "low": [...], "high": [...]`, in that place) and each `action` is a list of K numbers
//! within it ([`DemoAction`]: what each kind of action brings; one reader and writer for both). `terminated` is the true end of the task; time-limit truncation is kept apart so that
//! training can bootstrap through it. Collection follows DQfD: whole episodes from the start state, in order,
//! until `N` transitions are gathered (the last episode is cut at `N`). A run's `demo_file` may instead name a
//! Minari dataset (a person's answers exported from a run, or any other of the run's spaces), which
//! [`super::minari`] reads into the same [`Demonstrations`].

use super::Expert;
use super::process::WireAction;
use crate::env::{self, Action, Env};
use crate::replay::Transition;
use crate::task::{BoxSpec, EnvSpec, TaskSpec};
use anyhow::{Context, Result, bail, ensure};
use serde::{Deserialize, Serialize};
use std::io::{BufRead, BufReader};
use std::path::Path;

/// One line of a demonstration file: a demonstrated step with its episode and how the episode ended there.
/// Training reads it as a [`Transition`] ([`DemoStep::transition`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "")]
pub struct DemoStep<A: Action = usize> {
    pub episode: usize,
    pub obs: Vec<f32>,
    pub action: A,
    pub reward: f32,
    pub next_obs: Vec<f32>,
    pub terminated: bool,
    pub truncated: bool,
}

impl<A: Action> DemoStep<A> {
    /// The step as a demonstration transition; the bootstrap cut is true termination only, so training
    /// bootstraps through a time limit.
    pub fn transition(&self) -> Transition<'_, A> {
        Transition {
            obs: &self.obs,
            action: self.action.borrow(),
            reward: self.reward,
            next_obs: &self.next_obs,
            terminal: self.terminated,
            is_demo: true,
        }
    }
}

/// The first line of a demonstration file. The actions are described by `n_actions` (discrete) or by
/// `action_dim`, `low` and `high` (a box); the fields of the other kind are left out, so a file of discrete
/// actions is what it always was.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    format: String,
    version: u32,
    env: String,
    expert: String,
    seed: u64,
    obs_dim: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    n_actions: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    action_dim: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    low: Option<Vec<f32>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    high: Option<Vec<f32>>,
    transitions: usize,
    episodes: usize,
}

/// What a kind of action brings to demonstrations: its tasks' facts and environments by id, and how a file's
/// header describes its actions. Whether a demonstrated action is one the task accepts is the expert's answer
/// check ([`WireAction::check_answer`]: in range, or of the box's dimension, finite and within the box).
pub trait DemoAction: WireAction {
    /// The registered task `id` with actions of this kind.
    fn task(id: &str) -> Result<&'static Self::Spec>;
    /// The task `id`, made to collect demonstrations in.
    fn make_env(id: &str) -> Result<Box<dyn Env<Self>>>;
    /// Writes the description of `spec`'s actions into `header`.
    fn describe(spec: &Self::Spec, header: &mut Header);
    /// Checks that `header` describes `spec`'s actions; the error says how it differs.
    fn check_header(header: &Header, spec: &Self::Spec) -> std::result::Result<(), String>;
}

impl DemoAction for usize {
    fn task(id: &str) -> Result<&'static EnvSpec> {
        Ok(env::spec(id)?)
    }

    fn make_env(id: &str) -> Result<Box<dyn Env>> {
        Ok(env::make(id)?)
    }

    fn describe(spec: &EnvSpec, header: &mut Header) {
        header.n_actions = Some(spec.n_actions);
    }

    fn check_header(header: &Header, spec: &EnvSpec) -> std::result::Result<(), String> {
        match header.n_actions {
            Some(n) if n == spec.n_actions => Ok(()),
            Some(n) => Err(format!(
                "the header says {n} actions, but {} has {}",
                spec.id, spec.n_actions
            )),
            None => Err(format!(
                "the header has no `n_actions`, which {} (discrete actions) needs",
                spec.id
            )),
        }
    }
}

impl DemoAction for Vec<f32> {
    fn task(id: &str) -> Result<&'static BoxSpec> {
        Ok(env::box_spec(id)?)
    }

    fn make_env(id: &str) -> Result<Box<dyn Env<Vec<f32>>>> {
        Ok(env::make_box(id)?)
    }

    fn describe(spec: &BoxSpec, header: &mut Header) {
        header.action_dim = Some(spec.action_dim());
        header.low = Some(spec.action_low.to_vec());
        header.high = Some(spec.action_high.to_vec());
    }

    fn check_header(header: &Header, spec: &BoxSpec) -> std::result::Result<(), String> {
        let (Some(dim), Some(low), Some(high)) = (header.action_dim, &header.low, &header.high)
        else {
            return Err(format!(
                "the header needs `action_dim`, `low` and `high`: {} has actions in a box",
                spec.id
            ));
        };
        if dim != spec.action_dim() || low[..] != *spec.action_low || high[..] != *spec.action_high
        {
            return Err(format!(
                "the header's box ({dim} dimensions, {low:?} to {high:?}) is not {}'s ({} dimensions, {:?} to \
                 {:?})",
                spec.id,
                spec.action_dim(),
                spec.action_low,
                spec.action_high
            ));
        }
        Ok(())
    }
}

/// The most transitions a demonstration set is collected with (about 2 GB in memory for LunarLander).
pub const MAX_TRANSITIONS: usize = 10_000_000;
/// The largest demonstration file read (a LunarLander set of 100k transitions is about 30 MB).
pub const MAX_DEMO_FILE_BYTES: u64 = 4 << 30;
/// Fewer bytes than any transition line takes (the shortest, with empty vectors and one-digit numbers, has 95).
const MIN_TRANSITION_BYTES: u64 = 64;

/// Demonstrations as columns, one entry per transition in episode order (an episode ends at a terminated or
/// truncated transition): how another language hands them over (the Python bindings' `demos=`), read by
/// [`Demonstrations::from_columns`].
#[derive(Clone, Debug, PartialEq)]
pub struct DemoColumns<A: Action = usize> {
    pub obs: Vec<Vec<f32>>,
    pub actions: Vec<A>,
    pub rewards: Vec<f32>,
    pub next_obs: Vec<Vec<f32>>,
    pub terminated: Vec<bool>,
    pub truncated: Vec<bool>,
}

/// A set of demonstrations for one environment, of discrete actions (the default) or of actions in a box
/// (`Demonstrations<Vec<f32>>`): collected, given as columns, saved and loaded the same way.
#[derive(Clone, Debug, PartialEq)]
pub struct Demonstrations<A: Action = usize> {
    pub env: String,
    pub expert: String,
    pub seed: u64,
    pub transitions: Vec<DemoStep<A>>,
}

impl<A: DemoAction> Demonstrations<A> {
    /// Collects `n` transitions from `expert` on `env_id` in whole episodes; episode i resets with seed `seed + i`.
    pub fn collect(env_id: &str, expert: &mut dyn Expert<A>, n: usize, seed: u64) -> Result<Self> {
        let mut env = A::make_env(env_id)?;
        Self::collect_in(env.as_mut(), expert, n, seed)
    }

    /// [`Demonstrations::collect`] in a given environment.
    pub fn collect_in(
        env: &mut dyn Env<A>,
        expert: &mut dyn Expert<A>,
        n: usize,
        seed: u64,
    ) -> Result<Self> {
        let mut transitions = Vec::with_capacity(n.min(1 << 16)); // a hint: grows as episodes come
        let mut episode = 0usize;
        while transitions.len() < n {
            let mut obs = env.reset(Some(seed + episode as u64));
            loop {
                let action = expert
                    .act(&obs)
                    .with_context(|| format!("expert {} failed", expert.describe()))?;
                let s = env.step(action.borrow())?;
                transitions.push(DemoStep {
                    episode,
                    obs: std::mem::take(&mut obs),
                    action,
                    reward: s.reward as f32,
                    next_obs: s.obs.clone(),
                    terminated: s.terminated,
                    truncated: s.truncated,
                });
                obs = s.obs;
                if s.terminated || s.truncated || transitions.len() >= n {
                    break;
                }
            }
            episode += 1;
        }
        Ok(Self {
            env: env.id().to_string(),
            expert: expert.describe(),
            seed,
            transitions,
        })
    }

    /// Demonstrations given as columns (see [`DemoColumns`]). Checks lengths, sizes and actions against
    /// `env_id`.
    pub fn from_columns(env_id: &str, columns: DemoColumns<A>) -> Result<Self> {
        let DemoColumns {
            obs,
            actions,
            rewards,
            next_obs,
            terminated,
            truncated,
        } = columns;
        let spec = A::task(env_id)?;
        let n = actions.len();
        ensure!(
            [
                obs.len(),
                rewards.len(),
                next_obs.len(),
                terminated.len(),
                truncated.len()
            ]
            .iter()
            .all(|&len| len == n),
            "demonstration arrays differ in length: obs {}, actions {n}, rewards {}, next_obs {}, terminated {}, \
             truncated {}",
            obs.len(),
            rewards.len(),
            next_obs.len(),
            terminated.len(),
            truncated.len()
        );
        let mut transitions = Vec::with_capacity(n);
        let mut episode = 0;
        for (i, (((((obs, action), reward), next_obs), terminated), truncated)) in obs
            .into_iter()
            .zip(actions)
            .zip(rewards)
            .zip(next_obs)
            .zip(terminated)
            .zip(truncated)
            .enumerate()
        {
            ensure!(
                obs.len() == spec.obs_dim() && next_obs.len() == spec.obs_dim(),
                "demonstration {i}: observations of {} values expected for {env_id}",
                spec.obs_dim()
            );
            if let Err(why) = A::check_answer(action.borrow(), spec) {
                bail!(
                    "demonstration {i}: action {} is out of range for {env_id}: {why}",
                    A::to_field(action.borrow())
                );
            }
            ensure!(
                reward.is_finite(),
                "demonstration {i}: reward {reward} is not finite"
            );
            transitions.push(DemoStep {
                episode,
                obs,
                action,
                reward,
                next_obs,
                terminated,
                truncated,
            });
            if terminated || truncated {
                episode += 1;
            }
        }
        Ok(Self {
            env: env_id.to_string(),
            expert: "given".to_string(),
            seed: 0,
            transitions,
        })
    }

    /// Number of episodes (whole or cut) in the set.
    pub fn episodes(&self) -> usize {
        self.transitions.last().map(|t| t.episode + 1).unwrap_or(0)
    }

    /// The first `n` transitions (ADQNP pre-trains on half of DQfD's demonstrations).
    pub fn truncated_to(&self, n: usize) -> Self {
        Self {
            transitions: self.transitions[..n.min(self.transitions.len())].to_vec(),
            ..self.clone()
        }
    }

    /// Writes the set atomically ([`crate::files::write_atomic`]).
    pub fn save(&self, path: &Path) -> Result<()> {
        let spec = A::task(&self.env)?;
        let mut header = Header {
            format: "arld-demos".into(),
            version: 1,
            env: self.env.clone(),
            expert: self.expert.clone(),
            seed: self.seed,
            obs_dim: spec.obs_dim(),
            transitions: self.transitions.len(),
            episodes: self.episodes(),
            ..Header::default()
        };
        A::describe(spec, &mut header);
        let mut buf = Vec::new();
        serde_json::to_writer(&mut buf, &header)?;
        buf.push(b'\n');
        for t in &self.transitions {
            serde_json::to_writer(&mut buf, t)?;
            buf.push(b'\n');
        }
        crate::files::write_atomic(path, &buf)?;
        Ok(())
    }

    /// Reads and checks a demonstration file; `expect_env` rejects a file recorded on another environment. A
    /// file with no transitions is an error: the methods that load demonstrations pre-train on them.
    pub fn load(path: &Path, expect_env: Option<&str>) -> Result<Self> {
        use std::io::Read;
        let (file, len) = crate::files::open_bounded(path, MAX_DEMO_FILE_BYTES)
            .with_context(|| format!("cannot read demonstration file {}", path.display()))?;
        Self::read(BufReader::new(file.take(len)), len, path, expect_env)
    }

    /// Parses the `len` bytes of a demonstration file from `reader` (`path` only names it in errors). The
    /// header's counts are checked against `len` before anything is allocated for them.
    pub fn read(
        reader: impl BufRead,
        len: u64,
        path: &Path,
        expect_env: Option<&str>,
    ) -> Result<Self> {
        let mut lines = reader.lines();
        let first = lines
            .next()
            .with_context(|| format!("{}: empty demonstration file", path.display()))??;
        let header: Header = serde_json::from_str(&first)
            .with_context(|| format!("{}:1: not an arld demonstration header", path.display()))?;
        ensure!(
            header.format == "arld-demos",
            "{}:1: unknown format '{}'",
            path.display(),
            header.format
        );
        ensure!(
            header.version == 1,
            "{}:1: unsupported version {}",
            path.display(),
            header.version
        );
        if let Some(want) = expect_env {
            ensure!(
                header.env == want,
                "{} holds demonstrations for {}, but the run is on {want}",
                path.display(),
                header.env
            );
        }
        ensure!(
            header.transitions > 0,
            "{}: the file holds no transitions; DQfD and ADQNP pre-train on demonstrations, so give a file \
             with some (`arld demo collect`)",
            path.display()
        );
        ensure!(
            header.transitions as u64 <= len / MIN_TRANSITION_BYTES,
            "{}: truncated demonstration file: the header announces {} transitions, more than a file of {len} \
             bytes can hold",
            path.display(),
            header.transitions
        );
        let spec =
            A::task(&header.env).map_err(|err| anyhow::anyhow!("{}:1: {err:#}", path.display()))?;
        A::check_header(&header, spec)
            .map_err(|why| anyhow::anyhow!("{}:1: {why}", path.display()))?;
        // Capacity is a hint only: the vector grows with what the file really holds.
        let mut transitions = Vec::with_capacity(header.transitions.min(1 << 16));
        for (i, line) in lines.enumerate() {
            let line = line?;
            if line.trim().is_empty() {
                continue;
            }
            let lineno = i + 2;
            let t: DemoStep<A> = serde_json::from_str(&line)
                .with_context(|| format!("{}:{lineno}: malformed transition", path.display()))?;
            let obs_dim = spec.obs_dim();
            ensure!(
                t.obs.len() == obs_dim && t.next_obs.len() == obs_dim,
                "{}:{lineno}: observation of length {} where {} has {obs_dim}",
                path.display(),
                if t.obs.len() != obs_dim {
                    t.obs.len()
                } else {
                    t.next_obs.len()
                },
                header.env,
            );
            if let Err(why) = A::check_answer(t.action.borrow(), spec) {
                bail!(
                    "{}:{lineno}: action {} out of range: {why}",
                    path.display(),
                    A::to_field(t.action.borrow())
                );
            }
            ensure!(
                t.reward.is_finite(),
                "{}:{lineno}: reward {} is not a finite number",
                path.display(),
                t.reward
            );
            transitions.push(t);
        }
        if transitions.len() != header.transitions {
            bail!(
                "{}: truncated demonstration file: the header announces {} transitions, found {}",
                path.display(),
                header.transitions,
                transitions.len()
            );
        }
        Ok(Self {
            env: header.env,
            expert: header.expert,
            seed: header.seed,
            transitions,
        })
    }
}
