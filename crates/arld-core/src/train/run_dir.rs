//! The run directory: which files a run writes, what each holds, and how they are written and read. Training
//! ([`super::log::RunLog`]), sweeps, reports and tests all go through here, so the format has one owner.
//!
//! A run directory holds `config.toml` (the resolved configuration), `eval.csv` (the evaluation curve:
//! `step,mean,std,min,max`), `episodes.csv`, `queries.csv`, `answers.jsonl` (every step the expert took, as a
//! transition with its question: `AnswerStep`), a TensorBoard event file, `weights.safetensors`,
//! optional `checkpoints/step_NNNNNNNN.safetensors`, and `summary.json` ([`Summary`]), written last: a run is
//! complete exactly when it exists ([`is_complete`]). A run that ended with an error instead leaves `failed.json`
//! ([`Failure`]: the error chain, the step, the time, the arld version and commit), which the summary of a later
//! attempt that finishes the run removes. Whole files are written with
//! [`crate::files::write_atomic`]; the episode, query and answer logs and the event file are append-only streams.
//!
//! Inside a sweep, runs live at `ENV/METHOD-NET[/VARIANT]/seedN` ([`sweep_run_path`]); [`load_runs`] finds the
//! complete runs below a directory and reads each into a [`RunRecord`] for reports.

use super::config::{Algo, BoxUncertainty, ConfigInput, Method, NetKind, TrainConfig};
use crate::expert::demos::DemoStep;
pub use crate::files::write_atomic;
use crate::query::RuleSpec;
use crate::replay::Transition;
use crate::task::Action;
use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The resolved configuration (TOML).
pub const CONFIG_FILE: &str = "config.toml";
/// The evaluation curve (CSV).
pub const EVAL_FILE: &str = "eval.csv";
/// One row per episode (CSV).
pub const EPISODES_FILE: &str = "episodes.csv";
/// One row per query (CSV).
pub const QUERIES_FILE: &str = "queries.csv";
/// One line per step the expert took (JSON lines of [`AnswerStep`]).
pub(crate) const ANSWERS_FILE: &str = "answers.jsonl";
/// The summary, written last: its presence marks the run complete.
pub const SUMMARY_FILE: &str = "summary.json";
/// Why the run ended with an error ([`Failure`]); removed when a later attempt finishes the run.
pub const FAILED_FILE: &str = "failed.json";
/// The final online weights.
pub(crate) const WEIGHTS_FILE: &str = "weights.safetensors";
/// Periodic weights (`checkpoint_every`).
pub const CHECKPOINTS_DIR: &str = "checkpoints";
/// Header of [`EPISODES_FILE`].
pub const EPISODES_HEADER: &str = "episode,step,return,length,demo_steps\n";
/// Header of [`QUERIES_FILE`].
pub const QUERIES_HEADER: &str =
    "step,episode,uncertainty,threshold,expert_action,agent_action,expert,response_s,answered\n";
/// Variant label of a run that varies neither t_query nor the expert.
pub const DEFAULT_VARIANT: &str = "default";
/// Prefix of a t_query variant's name (`tq0.05`).
pub const T_QUERY_VARIANT_PREFIX: &str = "tq";
/// Prefix of an expert variant's name (`expert-shipped-weak`).
pub const EXPERT_VARIANT_PREFIX: &str = "expert-";

/// Path of the checkpoint written after `step` environment steps.
pub(crate) fn checkpoint_path(dir: &Path, step: usize) -> PathBuf {
    dir.join(CHECKPOINTS_DIR)
        .join(format!("step_{step:08}.safetensors"))
}

/// Whether `dir` holds a complete run (its summary exists).
pub fn is_complete(dir: &Path) -> bool {
    dir.join(SUMMARY_FILE).is_file()
}

/// The prefix of a TensorBoard event file's name.
const EVENTS_PREFIX: &str = "events.out.tfevents.";

/// The lock file a process running the run holds in its directory ([`crate::dir_lock`]: one process per run
/// directory, whether the CLI or Python runs it).
pub const LOCK_FILE: &str = ".arld.lock";

/// Whether `name` is the name of a run's TensorBoard event file (one file name, no path).
pub(crate) fn is_events_file(name: &str) -> bool {
    name.starts_with(EVENTS_PREFIX) && !name.contains('/') && name != ".." && name.len() < 256
}

/// The regular files a run owns in its directory, by name.
fn own_files() -> [&'static str; 10] {
    use super::snapshot::{SNAPSHOT_FILE, SNAPSHOT_INFO_FILE};
    [
        CONFIG_FILE,
        EVAL_FILE,
        EPISODES_FILE,
        QUERIES_FILE,
        ANSWERS_FILE,
        SUMMARY_FILE,
        FAILED_FILE,
        WEIGHTS_FILE,
        SNAPSHOT_FILE,
        SNAPSHOT_INFO_FILE,
    ]
}

/// Checks that every entry of `dir` a run writes is what the run would have put there: a regular file (its
/// files, its event files) or a real directory (`checkpoints`). A symbolic link, a device, a pipe or a
/// directory in such a place is an error naming it: a run never writes through a link to a file elsewhere.
pub(crate) fn check_own_entries(dir: &Path) -> Result<()> {
    for name in own_files() {
        crate::files::own_file_exists(&dir.join(name))?;
    }
    let checkpoints = dir.join(CHECKPOINTS_DIR);
    if let Ok(meta) = std::fs::symlink_metadata(&checkpoints)
        && !meta.is_dir()
    {
        bail!(
            "{} is {}, where the run keeps its checkpoints folder; move it away",
            checkpoints.display(),
            crate::files::kind_name(meta.file_type())
        );
    }
    let entries = match std::fs::read_dir(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        entries => entries.with_context(|| format!("cannot read {}", dir.display()))?,
    };
    for entry in entries {
        let entry = entry.with_context(|| format!("cannot read {}", dir.display()))?;
        if is_events_file(&entry.file_name().to_string_lossy()) {
            crate::files::own_file_exists(&entry.path())?;
        }
    }
    Ok(())
}

/// Whether `name` is an entry a run writes into its directory, by its exact name: its files, checkpoints,
/// TensorBoard events, snapshot, and the temporary files of its atomic writes (exactly of their form, see
/// [`crate::files::is_temporary_of`]: a user's `.notes.tmp.bak` is none).
fn is_run_entry(name: &str) -> bool {
    own_files().contains(&name)
        || name == CHECKPOINTS_DIR
        || is_events_file(name)
        || own_files()
            .iter()
            .any(|file| crate::files::is_temporary_of(name, file))
}

/// Whether `name` is the name a run gives a checkpoint (`step_NNNNNNNN.safetensors`, [`checkpoint_path`]),
/// exactly: `step_5.safetensors` is none.
fn is_checkpoint_name(name: &str) -> bool {
    name.strip_prefix("step_")
        .and_then(|n| n.strip_suffix(".safetensors"))
        .filter(|digits| digits.bytes().all(|b| b.is_ascii_digit()))
        .and_then(|digits| digits.parse::<usize>().ok())
        .is_some_and(|step| {
            checkpoint_path(Path::new(""), step).file_name() == Some(std::ffi::OsStr::new(name))
        })
}

/// Whether `name` is an entry a run writes into its `checkpoints` folder: a checkpoint, or the temporary file
/// of its atomic write, each by its exact name.
fn is_checkpoint_entry(name: &str) -> bool {
    is_checkpoint_name(name)
        || name
            .strip_prefix('.')
            .and_then(|n| n.split(".tmp").next())
            .is_some_and(|target| {
                is_checkpoint_name(target) && crate::files::is_temporary_of(name, target)
            })
}

/// Removes what writers of the run's files killed before their commit left in `dir` and its checkpoints
/// folder (their temporary files, exactly by name; a writer of this process is left alone): done when a run
/// starts, resumes and finishes.
pub(crate) fn remove_leftovers(dir: &Path) -> Result<()> {
    let tidy = |path: &Path| {
        crate::files::remove_leftovers(path)
            .with_context(|| format!("cannot tidy {}", dir.display()))
    };
    for name in own_files() {
        tidy(&dir.join(name))?;
    }
    let checkpoints = dir.join(CHECKPOINTS_DIR);
    let entries = match std::fs::read_dir(&checkpoints) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        entries => entries.with_context(|| format!("cannot read {}", checkpoints.display()))?,
    };
    let mut targets = BTreeSet::new();
    for entry in entries {
        let name = entry?.file_name().to_string_lossy().into_owned();
        if let Some(target) = name.strip_prefix('.').and_then(|n| n.split(".tmp").next())
            && is_checkpoint_name(target)
        {
            targets.insert(target.to_string());
        }
    }
    for target in targets {
        tidy(&checkpoints.join(target))?;
    }
    Ok(())
}

/// Makes `dir` ready for a new run, so that nothing of an earlier run is mixed into it: a missing or empty
/// directory (but for the lock, [`LOCK_FILE`]) is fine; a non-empty one is refused, unless `overwrite`, when
/// the files a run writes are removed by name, and only if it holds nothing else (`--overwrite` never deletes
/// anything a run did not write: another file, a folder, a link, or a file of the user's inside `checkpoints`
/// is refused, naming it, before anything is removed).
pub(crate) fn prepare_new_run(dir: &Path, overwrite: bool) -> Result<()> {
    let meta = match std::fs::symlink_metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        meta => meta.with_context(|| format!("cannot inspect {}", dir.display()))?,
    };
    let meta = if meta.file_type().is_symlink() {
        std::fs::metadata(dir)
            .with_context(|| format!("cannot follow the link {}", dir.display()))?
    } else {
        meta
    };
    if !meta.is_dir() {
        bail!(
            "the run directory {} exists and is not a directory",
            dir.display()
        );
    }
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read {}", dir.display()))?
        .map(|e| Ok(e?.file_name().to_string_lossy().into_owned()))
        .filter(|n| !matches!(n, Ok(n) if n == LOCK_FILE))
        .collect::<std::io::Result<_>>()
        .with_context(|| format!("cannot read {}", dir.display()))?;
    if names.is_empty() {
        return Ok(());
    }
    names.sort();
    if !overwrite {
        let what = if dir.join(super::snapshot::SNAPSHOT_FILE).is_file() {
            format!(
                "an interrupted run (continue it with `arld train --resume {}`)",
                dir.display()
            )
        } else if is_complete(dir) {
            "a finished run".to_string()
        } else if let Ok(Some(failure)) = read_failure(dir) {
            format!("a failed run ({FAILED_FILE}: {})", failure.message())
        } else {
            names.join(", ")
        };
        bail!(
            "the run directory {} is not empty: it holds {what}; give --overwrite to replace it, or another --out",
            dir.display()
        );
    }
    // Everything to remove is checked before anything is: a refusal leaves the directory as it was.
    let refuse = |path: &Path, why: &str| -> Result<()> {
        bail!(
            "--overwrite removes only the files a run writes, and {} {why}; move it away or choose another --out",
            path.display()
        )
    };
    let mut doomed = Vec::new();
    for name in &names {
        let path = dir.join(name);
        let kind = path
            .symlink_metadata()
            .with_context(|| format!("cannot inspect {}", path.display()))?
            .file_type();
        if !is_run_entry(name) {
            refuse(&path, "is something no run writes")?;
        } else if name == CHECKPOINTS_DIR && kind.is_dir() {
            let mut inside = Vec::new();
            for entry in std::fs::read_dir(&path)
                .with_context(|| format!("cannot read {}", path.display()))?
            {
                let entry = entry.with_context(|| format!("cannot read {}", path.display()))?;
                let file = entry.path();
                if !is_checkpoint_entry(&entry.file_name().to_string_lossy()) {
                    refuse(&file, "is no checkpoint, something no run writes")?;
                } else if !entry.file_type()?.is_file() {
                    refuse(
                        &file,
                        &format!("is {}", crate::files::kind_name(entry.file_type()?)),
                    )?;
                }
                inside.push(file);
            }
            doomed.extend(inside);
            doomed.push(path);
        } else if !kind.is_file() {
            refuse(
                &path,
                &format!(
                    "is {}, where a run keeps a regular file",
                    crate::files::kind_name(kind)
                ),
            )?;
        } else {
            doomed.push(path);
        }
    }
    for path in doomed {
        let removed = if path.symlink_metadata()?.is_dir() {
            std::fs::remove_dir(&path)
        } else {
            std::fs::remove_file(&path)
        };
        removed
            .with_context(|| format!("cannot remove {} to overwrite the run", path.display()))?;
    }
    Ok(())
}

/// Clears the directory of an unfinished run for a new attempt from step 0 (a run stopped before its first
/// snapshot), as [`prepare_new_run`] with `overwrite` does, but keeps its `failed.json`: an earlier attempt's
/// failure stays recorded until an attempt finishes the run.
pub(crate) fn prepare_restart(dir: &Path) -> Result<()> {
    let failed = dir.join(FAILED_FILE);
    let kept = if crate::files::own_file_exists(&failed)? {
        Some(
            crate::files::read_bounded(&failed, MAX_KEY_FILE_BYTES)
                .with_context(|| format!("cannot read {}", failed.display()))?,
        )
    } else {
        None
    };
    prepare_new_run(dir, true)?;
    if let Some(bytes) = kept {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        write_atomic(&failed, &bytes)?;
    }
    Ok(())
}

/// One evaluation: `eval_episodes` test episodes without exploration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalPoint {
    pub step: u64,
    pub mean: f64,
    pub std: f64,
    pub min: f64,
    pub max: f64,
}

impl EvalPoint {
    /// A point whose test episodes all returned `mean` (no spread), for tests and examples.
    pub fn constant(step: u64, mean: f64) -> Self {
        Self {
            step,
            mean,
            std: 0.0,
            min: mean,
            max: mean,
        }
    }

    /// A curve evaluated every `period` steps from step `period` on, the test episodes of evaluation i all
    /// returning `means[i]`, for tests and examples.
    pub fn constant_curve(period: u64, means: &[f64]) -> Vec<Self> {
        (1..)
            .zip(means)
            .map(|(i, &mean)| Self::constant(i * period, mean))
            .collect()
    }
}

/// One query: the agent asked the expert to take over (a row of [`QUERIES_FILE`]), or a person took over unasked
/// (`started_by` [`StartedBy::Person`]: kept with the run's questions, and in its snapshots, so that the
/// person's steps in `ANSWERS_FILE` are tied to it, but never a row of [`QUERIES_FILE`], which holds the
/// rule's questions only and keeps its columns).
///
/// Its actions are of the run's kind `A`: a discrete run's columns are the indices as they always were, a box
/// run's the numbers of each action separated by spaces ([`Action::to_field`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "")]
pub struct QueryEvent<A: Action = usize> {
    pub step: usize,
    pub episode: usize,
    pub uncertainty: Option<f32>,
    pub threshold: Option<f32>,
    /// The expert's action; `None` when nobody answered (the agent's action was taken).
    pub expert_action: Option<A>,
    pub agent_action: A,
    /// Who was asked: the expert's kind (`checkpoint`, `scripted`, `web`, ...).
    pub expert: String,
    /// Seconds the expert took to answer, for experts that measure it (a person); `None` for programs, whose
    /// answers are instant (and would make the file depend on the machine's speed).
    pub response_s: Option<f64>,
    /// Whether the expert answered (`false`: the query went back to the agent and cost no budget).
    pub answered: bool,
    /// What opened the segment: the query rule, or a person who took over (absent from the rule's events in
    /// snapshots, as before takeovers).
    #[serde(default, skip_serializing_if = "StartedBy::is_rule")]
    pub started_by: StartedBy,
    /// Steps of the person's attempts at this question that they retried and dropped (charged to the budget,
    /// never stored); absent when they kept their first attempt, as before retries.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub retried: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// What opened an expert's segment.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StartedBy {
    /// The query rule asked.
    #[default]
    Rule,
    /// A person took over unasked (the web page's "Take over").
    Person,
}

impl StartedBy {
    /// Whether the query rule opened the segment.
    pub(crate) fn is_rule(&self) -> bool {
        *self == StartedBy::Rule
    }

    /// The name written to `AnswerStep::started_by`.
    pub fn as_str(self) -> &'static str {
        match self {
            StartedBy::Rule => STARTED_BY_RULE,
            StartedBy::Person => STARTED_BY_PERSON,
        }
    }
}

impl<A: Action> QueryEvent<A> {
    /// The event as a line of [`QUERIES_FILE`] (columns of [`QUERIES_HEADER`]; `None` is an empty field).
    pub fn csv_row(&self) -> String {
        let opt = |v: Option<String>| v.unwrap_or_default();
        format!(
            "{},{},{},{},{},{},{},{},{}\n",
            self.step,
            self.episode,
            opt(self.uncertainty.map(|x| x.to_string())),
            opt(self.threshold.map(|x| x.to_string())),
            opt(self.expert_action.as_ref().map(|x| A::to_field(x.borrow()))),
            A::to_field(self.agent_action.borrow()),
            csv_field(&self.expert),
            opt(self.response_s.map(|x| format!("{x:.3}"))),
            self.answered
        )
    }
}

/// Who started the expert's segment a step belongs to, as [`AnswerStep::started_by`] says it: the query rule.
pub(crate) const STARTED_BY_RULE: &str = "rule";
/// ... or a person who took over unasked.
pub(crate) const STARTED_BY_PERSON: &str = "person";

/// One line of [`ANSWERS_FILE`]: a step the expert took, as the transition the run stored as a demonstration
/// (observation, action, reward, next observation, how the episode ended there), with the question that opened
/// the expert's segment (the row of [`QUERIES_FILE`] at `question_step`; for a person's takeover, the step they
/// took over at, which has no row there): the agent's proposal then, its uncertainty and the rule's threshold
/// (none for a takeover), who answered and how long the answer took. These are the person's
/// answers kept for use again (`python -m arld.minari export` writes them as a Minari dataset).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "")]
pub(crate) struct AnswerStep<A: Action = usize> {
    pub step: usize,
    /// The transition, written as the fields of a demonstration file's line (`episode` to `truncated`).
    #[serde(flatten)]
    pub taken: DemoStep<A>,
    /// The step of the question that opened this segment (`None` when the run does not know it: a run continued
    /// from a snapshot written before queries were kept in snapshots).
    pub question_step: Option<usize>,
    /// The agent's action at the question (what it proposed).
    pub agent_action: Option<A>,
    pub uncertainty: Option<f32>,
    pub threshold: Option<f32>,
    /// Seconds the answer to the question took (a person; `None` for programs).
    pub response_s: Option<f64>,
    /// Who answered: the expert's kind (`scripted`, `web`, ...).
    pub expert: String,
    /// What opened the segment: [`STARTED_BY_RULE`], the query rule asked, or [`STARTED_BY_PERSON`], a person
    /// took over unasked.
    pub started_by: String,
    /// Steps of the person's attempts at the question that their retry replaced ([`QueryEvent::retried`]):
    /// these steps are the retry's; absent when the first attempt was kept.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub retried: usize,
}

impl<A: Action> AnswerStep<A> {
    /// The step taken by the expert at `step` of the run in `episode` (`taken` as the run stored it, `ended` its
    /// `(terminated, truncated)`), tied to `question` (the last question asked, which opened its segment).
    pub fn new(
        (step, episode): (usize, usize),
        taken: &Transition<'_, A>,
        (terminated, truncated): (bool, bool),
        question: Option<&QueryEvent<A>>,
    ) -> Self {
        Self {
            step,
            taken: DemoStep {
                episode,
                obs: taken.obs.to_vec(),
                action: A::owned(taken.action),
                reward: taken.reward,
                next_obs: taken.next_obs.to_vec(),
                terminated,
                truncated,
            },
            question_step: question.map(|q| q.step),
            agent_action: question.map(|q| q.agent_action.clone()),
            uncertainty: question.and_then(|q| q.uncertainty),
            threshold: question.and_then(|q| q.threshold),
            response_s: question.and_then(|q| q.response_s),
            expert: question.map(|q| q.expert.clone()).unwrap_or_default(),
            started_by: question
                .map_or(StartedBy::Rule, |q| q.started_by)
                .as_str()
                .to_string(),
            retried: question.map_or(0, |q| q.retried),
        }
    }

    /// The step as one line of [`ANSWERS_FILE`].
    pub(crate) fn json_line(&self) -> Result<String> {
        let mut line = serde_json::to_string(self)?;
        line.push('\n');
        Ok(line)
    }
}

/// `s` as one CSV field: quoted (inner quotes doubled) when it holds a comma, quote or line break.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// What a finished run reports (`summary.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub env: String,
    pub method: Method,
    pub net: NetKind,
    /// The learner of a task with actions in a box (TD3 or SAC); absent for the DQN family and from older
    /// summaries (whose box runs were TD3's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub algo: Option<Algo>,
    pub seed: u64,
    /// First evaluation step whose mean reaches the solve threshold; `train_steps` if none does.
    pub steps_to_solve: usize,
    pub solved: bool,
    pub solve_threshold: f64,
    pub train_steps: usize,
    /// Mean test return of the last evaluation.
    pub final_score: f64,
    /// Demonstrated transitions used before training (pre-training).
    pub demos_pretrain: usize,
    /// Demonstrated transitions the expert gave in answer to queries during training. It is the budget spent
    /// when the budget counts transitions, but neither the budget spent when it counts questions
    /// ([`crate::query::BudgetUnit`]) nor the number of questions (`queries.csv` has a row per question).
    /// Summaries of earlier versions call it `queries_used`.
    #[serde(alias = "queries_used")]
    pub demos_queried: usize,
    pub episodes: usize,
    /// Wall-clock seconds of the whole run, over all its sessions when it was resumed from a snapshot.
    pub wall_time_s: f64,
    /// CPU seconds of the thread that trained, over all sessions: the run's cost, which a busy machine or a
    /// paused process does not inflate (absent from older summaries, and where the system cannot tell it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_time_s: Option<f64>,
    pub steps_per_s: f64,
    /// How the run's elementary functions (sin, exp, pow, ...) were computed: [`crate::math::NUMERICS`] for
    /// runs of this arld; absent for runs of arld before `src/math.rs`, which used the C library's, whose results
    /// depend on the CPU (such a run regenerates byte for byte only with that arld on a CPU like the one it ran
    /// on; sweeps run it again, see [`is_stale`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub numerics: Option<String>,
    /// The arld version ([`crate::build_info::VERSION`]) and git commit ([`crate::build_info::GIT_COMMIT`])
    /// that finished the run (absent from older summaries; reports do not read them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arld_version: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub git_commit: Option<String>,
    /// The expert the run used (its spec, e.g. `shipped:weak`, or `python:module.name` for a Python expert);
    /// absent when the method uses none, and from older summaries.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expert: Option<String>,
    /// Seconds a person spent answering the queries (a web expert), over all the run's sessions; absent for
    /// programs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub person_s: Option<f64>,
}

/// Whether the complete run in `dir` was computed with other elementary functions than this arld's
/// ([`Summary::numerics`]), so that this arld would not regenerate it byte for byte.
pub fn is_stale(dir: &Path) -> bool {
    read_summary(dir).is_ok_and(|s| s.numerics.as_deref() != Some(crate::math::NUMERICS))
}

/// First evaluation step whose mean reaches `threshold`, or `train_steps` if none does (docs/algorithm.md §11).
pub fn steps_to_solve(curve: &[EvalPoint], threshold: f64, train_steps: u64) -> (u64, bool) {
    match curve.iter().find(|p| p.mean >= threshold) {
        Some(p) => (p.step, true),
        None => (train_steps, false),
    }
}

/// The evaluation curve as CSV text (`step,mean,std,min,max`).
pub fn curve_csv(curve: &[EvalPoint]) -> String {
    let mut s = String::from("step,mean,std,min,max\n");
    for p in curve {
        s.push_str(&format!(
            "{},{},{},{},{}\n",
            p.step, p.mean, p.std, p.min, p.max
        ));
    }
    s
}

/// Which run: its task, method, network and seed, as a sweep plans it and a run directory records it.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RunId {
    pub env: String,
    pub method: Method,
    pub net: NetKind,
    pub seed: u64,
}

impl RunId {
    /// The run `cfg` configures.
    pub fn of(cfg: &TrainConfig) -> Self {
        Self {
            env: cfg.env.clone(),
            method: cfg.method,
            net: cfg.net,
            seed: cfg.seed,
        }
    }
}

/// Everything a report needs from one complete run directory.
#[derive(Debug, Clone)]
pub struct RunRecord {
    /// The run directory.
    pub dir: PathBuf,
    /// Task, method, network and seed.
    pub id: RunId,
    /// Variant label (`default`, `tq0.05`, `expert-shipped-weak`, ...).
    pub variant: String,
    /// Score that counts as solving the task.
    pub solve_threshold: f64,
    /// Environment steps of training (a seed that never solves counts as this many).
    pub train_steps: u64,
    /// Environment steps between evaluations.
    pub eval_period: u64,
    /// Evaluation curve in step order.
    pub eval: Vec<EvalPoint>,
    /// Environment step of every query, in log order; `None` when the run has no `queries.csv`.
    pub query_steps: Option<Vec<u64>>,
    /// What the run's `config.toml` records of its setting (nothing for a run without one).
    pub config: RecordedConfig,
    /// The run's `summary.json`; `None` for records not read from a run directory.
    pub summary: Option<Summary>,
}

/// What reports read of a run's `config.toml`, key by key, so that configurations written by earlier versions
/// still load: each is `None` where the file has no such key.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordedConfig {
    pub t_query: Option<f64>,
    /// The expert spec.
    pub expert: Option<String>,
    /// The budget, in its unit.
    pub budget: Option<usize>,
    /// The query rule, in canonical form ([`canonical_rule`]) so that one spec written two ways is one rule;
    /// `None` also when the key is empty (the method's own rule asks).
    pub query_rule: Option<String>,
    /// When its questions may come.
    pub asking: RecordedAsking,
}

/// When a run's questions may come, as its `config.toml` records it: from `learning_starts` on only, and that step;
/// and what a box task's query rule read (`None`: the default, the critics' variance).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RecordedAsking {
    pub from_learning_starts: Option<bool>,
    pub learning_starts: Option<u64>,
    pub uncertainty: Option<BoxUncertainty>,
}

impl RecordedConfig {
    /// The values of a `config.toml` read as a table.
    fn of(table: &toml::Table) -> Self {
        let text_of = |key: &str| table.get(key).and_then(|v| v.as_str());
        Self {
            t_query: table
                .get("t_query")
                .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64))),
            expert: text_of("expert").map(str::to_string),
            budget: table
                .get("budget")
                .and_then(|v| v.as_integer())
                .and_then(|b| usize::try_from(b).ok()),
            query_rule: text_of("query_rule")
                .filter(|rule| !rule.is_empty())
                .map(canonical_rule),
            asking: RecordedAsking {
                from_learning_starts: table
                    .get("queries_from_learning_starts")
                    .and_then(|v| v.as_bool()),
                learning_starts: table
                    .get("learning_starts")
                    .and_then(|v| v.as_integer())
                    .and_then(|s| u64::try_from(s).ok()),
                uncertainty: text_of("uncertainty").and_then(|u| u.parse().ok()),
            },
        }
    }
}

impl RunRecord {
    /// The record of a run known only by its evaluation curve (no run directory: no configuration, summary or
    /// query log), such as a row group of `evaluations.csv.gz`.
    pub fn from_curve(
        dir: PathBuf,
        id: RunId,
        variant: String,
        eval: Vec<EvalPoint>,
        solve_threshold: f64,
        (train_steps, eval_period): (u64, u64),
    ) -> Self {
        Self {
            dir,
            id,
            variant,
            solve_threshold,
            train_steps,
            eval_period,
            eval,
            query_steps: None,
            config: RecordedConfig::default(),
            summary: None,
        }
    }

    /// Demonstrated transitions the expert gave during training ([`Summary::demos_queried`]); `None` without a
    /// summary.
    pub fn demos_queried(&self) -> Option<u64> {
        self.summary.as_ref().map(|s| s.demos_queried as u64)
    }

    /// The run's identity as reports sort and group runs: the names of its env, method, net and variant, then
    /// its seed.
    pub fn key(&self) -> (&str, &str, &str, &str, u64) {
        let RunId {
            env,
            method,
            net,
            seed,
        } = &self.id;
        (env, method.name(), net.name(), &self.variant, *seed)
    }

    /// The t_query of a run of the t_query study (variant `tqVALUE`, [`T_QUERY_VARIANT_PREFIX`]), as its config
    /// records it; `None` for any other run.
    pub fn t_query_study(&self) -> Option<f64> {
        self.config
            .t_query
            .filter(|_| self.variant.starts_with(T_QUERY_VARIANT_PREFIX))
    }
}

/// A query rule spec in canonical form (parameters in key order, numbers as Rust prints them; see
/// [`RuleSpec`]), or as written when it does not parse.
pub fn canonical_rule(spec: &str) -> String {
    spec.parse::<RuleSpec>()
        .map_or_else(|_| spec.to_string(), |s| s.to_string())
}

/// Whether the complete run in `dir` is whole: its summary, configuration and evaluation curve are present and
/// parse (its query log too, when there is one), and the curve ends at the run's last step with the summary's
/// final score (a curve cut short does not). An error says what is missing or damaged. Sweeps run again any run that fails this.
pub fn check_complete(dir: &Path) -> Result<()> {
    if !is_complete(dir) {
        bail!("it has no {SUMMARY_FILE}");
    }
    for file in [CONFIG_FILE, EVAL_FILE] {
        if !dir.join(file).is_file() {
            bail!("it has {SUMMARY_FILE} but no {file}");
        }
    }
    let run = read_run(dir, Path::new(""))?;
    let summary = run.summary.as_ref().expect("read from a run directory");
    match run.eval.iter().max_by_key(|p| p.step) {
        None => bail!("{EVAL_FILE} has no evaluation"),
        // Training always evaluates after its last step.
        Some(last) if last.step != summary.train_steps as u64 => bail!(
            "{EVAL_FILE} ends at step {}, before the run's last step {} (a truncated curve)",
            last.step,
            summary.train_steps
        ),
        Some(last) if last.mean.to_bits() != summary.final_score.to_bits() => bail!(
            "{EVAL_FILE} ends at step {} with mean {}, but {SUMMARY_FILE} has final score {} (a truncated curve)",
            last.step,
            last.mean,
            summary.final_score
        ),
        Some(_) => Ok(()),
    }
}

/// The resolved configuration of the run in `dir`: its `config.toml` over the preset of `id` (the file's own
/// `env`, `method`, `net` and `seed` win), so that keys added since the run was made take their defaults.
pub fn read_config(dir: &Path, id: &RunId) -> Result<TrainConfig> {
    let mut input = ConfigInput::new(&id.env, id.method, id.net, id.seed);
    input.apply_file(&dir.join(CONFIG_FILE))?;
    input.resolve()
}

/// The configuration of the run in `dir` exactly as its `config.toml` has it: neither resolved over a preset nor
/// validated (a run driven from Python records an expert that only Python supplies); a key that an older file
/// lacks is not taken from a preset, as [`read_config`] takes it.
pub(crate) fn read_written_config(dir: &Path) -> Result<TrainConfig> {
    let path = dir.join(CONFIG_FILE);
    let bytes = crate::files::read_bounded(&path, MAX_KEY_FILE_BYTES)
        .with_context(|| format!("cannot read {}", path.display()))?;
    parse_written_config(&bytes, &path)
}

/// A run's configuration from the bytes of its `config.toml` (`path` names it in the error), as
/// [`read_written_config`] reads it.
fn parse_written_config(bytes: &[u8], path: &Path) -> Result<TrainConfig> {
    let text = std::str::from_utf8(bytes)
        .with_context(|| format!("{} is not UTF-8 text", path.display()))?;
    toml::from_str(text).with_context(|| format!("{} is not a run configuration", path.display()))
}

/// Checks the text of a run's `config.toml` (`path` names it in the error): TOML whose every key that this arld
/// knows holds a string exactly where this arld writes one (`seed = "1"` is refused). Keys it does not know (an
/// older or newer run's) are not checked, nor missing keys.
pub fn check_config_types(text: &str, path: &Path) -> Result<()> {
    static STRINGS: std::sync::OnceLock<BTreeMap<String, bool>> = std::sync::OnceLock::new();
    let strings = STRINGS.get_or_init(|| {
        let preset = ConfigInput::new("CartPole-v0", Method::Adqn, NetKind::Bootstrap, 0)
            .resolve()
            .expect("the preset resolves");
        let table: toml::Table =
            toml::from_str(&preset.to_toml()).expect("a configuration reads back");
        table.into_iter().map(|(k, v)| (k, v.is_str())).collect()
    });
    let table: toml::Table =
        toml::from_str(text).with_context(|| format!("{} is not a TOML table", path.display()))?;
    check_strings(
        table.iter().map(|(k, v)| (k, Some(v.is_str()))),
        strings,
        path,
    )
}

/// Checks the text of a run's `summary.json` as [`check_config_types`] checks a configuration (a `null` stands
/// for a value a run did not have, of any type).
pub fn check_summary_types(text: &str, path: &Path) -> Result<()> {
    static STRINGS: std::sync::OnceLock<BTreeMap<String, bool>> = std::sync::OnceLock::new();
    let strings = STRINGS.get_or_init(|| {
        // A summary with every value present, for the kind of each.
        let some = Summary {
            env: String::new(),
            method: Method::Adqn,
            net: NetKind::Bootstrap,
            algo: Some(Algo::Td3),
            seed: 0,
            steps_to_solve: 0,
            solved: false,
            solve_threshold: 0.0,
            train_steps: 0,
            final_score: 0.0,
            demos_pretrain: 0,
            demos_queried: 0,
            episodes: 0,
            wall_time_s: 0.0,
            cpu_time_s: Some(0.0),
            steps_per_s: 0.0,
            numerics: Some(String::new()),
            arld_version: Some(String::new()),
            git_commit: Some(String::new()),
            expert: Some(String::new()),
            person_s: Some(0.0),
        };
        let serde_json::Value::Object(object) =
            serde_json::to_value(some).expect("a summary serialises")
        else {
            unreachable!("a summary is an object")
        };
        object
            .into_iter()
            .map(|(k, v)| (k, v.is_string()))
            .collect()
    });
    let object: serde_json::Map<String, serde_json::Value> = serde_json::from_str(text)
        .with_context(|| format!("{} is not a JSON object", path.display()))?;
    let kinds = object
        .iter()
        .map(|(k, v)| (k, (!v.is_null()).then(|| v.is_string())));
    check_strings(kinds, strings, path)
}

/// Refuses a key whose value is a string (`Some(true)`) where `strings` says its values are none, or the other
/// way round (`None`: a value of any kind).
fn check_strings<'a>(
    kinds: impl Iterator<Item = (&'a String, Option<bool>)>,
    strings: &BTreeMap<String, bool>,
    path: &Path,
) -> Result<()> {
    for (key, is_string) in kinds {
        if let (Some(&expected), Some(found)) = (strings.get(key), is_string)
            && expected != found
        {
            bail!(
                "{}: `{key}` holds {}, where a run writes {}",
                path.display(),
                if found {
                    "a string"
                } else {
                    "a value that is no string"
                },
                if expected {
                    "a string"
                } else {
                    "a value that is no string"
                }
            );
        }
    }
    Ok(())
}

/// Gives `to` the files of the finished run `from` as the run `config` configures (a run of the same
/// computation under another name): every regular file of `from` but its configuration and summary, then `config`
/// as its `config.toml`, and the summary last, so that the copy is complete only once whole. Whatever `to` held
/// is removed first.
pub fn copy_finished_run(from: &Path, to: &Path, config: &TrainConfig) -> Result<()> {
    if to.exists() {
        std::fs::remove_dir_all(to)
            .with_context(|| format!("cannot clear incomplete run directory {}", to.display()))?;
    }
    std::fs::create_dir_all(to).with_context(|| format!("cannot create {}", to.display()))?;
    for entry in
        std::fs::read_dir(from).with_context(|| format!("cannot read {}", from.display()))?
    {
        let entry = entry?;
        let name = entry.file_name();
        if !entry.file_type()?.is_file() || name == SUMMARY_FILE || name == CONFIG_FILE {
            continue;
        }
        let bytes = crate::files::read_bounded(&entry.path(), MAX_LOG_BYTES)
            .with_context(|| format!("cannot read {}", entry.path().display()))?;
        write_atomic(&to.join(&name), &bytes)?;
    }
    write_atomic(&to.join(CONFIG_FILE), config.to_toml().as_bytes())?;
    let summary = crate::files::read_bounded(&from.join(SUMMARY_FILE), MAX_KEY_FILE_BYTES)
        .with_context(|| format!("cannot read {}", from.join(SUMMARY_FILE).display()))?;
    write_atomic(&to.join(SUMMARY_FILE), &summary)?;
    check_complete(to).context("the copy is not whole")
}

/// Reads `summary.json` of a run directory.
pub(crate) fn read_summary(dir: &Path) -> Result<Summary> {
    let path = dir.join(SUMMARY_FILE);
    let bytes = crate::files::read_bounded(&path, MAX_KEY_FILE_BYTES)
        .with_context(|| format!("cannot read {}", path.display()))?;
    parse_summary(&bytes, &path)
}

/// The largest `summary.json` or `config.toml` a reader reads (theirs are about 2 KB).
const MAX_KEY_FILE_BYTES: u64 = 16 << 20;
/// The largest `eval.csv` or `queries.csv` a reader reads (far above a run of millions of steps).
const MAX_LOG_BYTES: u64 = 1 << 30;

/// A run summary from the bytes of `path` (named in the error).
pub fn parse_summary(bytes: &[u8], path: &Path) -> Result<Summary> {
    serde_json::from_slice(bytes)
        .with_context(|| format!("{} is not a run summary", path.display()))
}

/// Writes `summary.json` (last: it marks the run complete), then removes the `failed.json` of an earlier
/// attempt.
pub fn write_summary(dir: &Path, summary: &Summary) -> Result<()> {
    let json = serde_json::to_string_pretty(summary)?;
    write_atomic(&dir.join(SUMMARY_FILE), json.as_bytes())?;
    remove_leftovers(dir)?;
    match std::fs::remove_file(dir.join(FAILED_FILE)) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            Err(e).with_context(|| format!("cannot remove {}", dir.join(FAILED_FILE).display()))
        }
        _ => Ok(()),
    }
}

/// Why a run ended with an error: the contents of [`FAILED_FILE`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    /// The error, outermost message first, then each cause.
    pub error: Vec<String>,
    /// Where the run was: `setup` (the expert, the demonstrations), `pre-training` or `training`.
    pub phase: String,
    /// The environment step during which it failed, counted from 1 as the logs count (0 before training on the
    /// environment began).
    pub step: usize,
    /// When, in RFC 3339 (UTC) and in seconds since the Unix epoch.
    pub time: String,
    pub unix_s: u64,
    /// The arld that ran it ([`crate::build_info`]).
    pub arld_version: String,
    pub git_commit: String,
}

impl Failure {
    /// The failure `err` at `step` of `phase`, now, by this arld.
    pub fn new(err: &anyhow::Error, phase: &str, step: usize) -> Self {
        let unix_s = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        Self {
            error: err.chain().map(|cause| cause.to_string()).collect(),
            phase: phase.to_string(),
            step,
            time: rfc3339_utc(unix_s),
            unix_s,
            arld_version: crate::build_info::VERSION.to_string(),
            git_commit: crate::build_info::GIT_COMMIT.to_string(),
        }
    }

    /// The error on one line: the causes joined by `: ` (leaving out one whose text an outer message already
    /// holds), cut at the first line break.
    pub fn message(&self) -> String {
        let mut line = String::new();
        for cause in &self.error {
            let cause = cause.trim();
            if !line.contains(cause) {
                if !line.is_empty() {
                    line.push_str(": ");
                }
                line.push_str(cause);
            }
        }
        line.lines().next().unwrap_or("").to_string()
    }
}

/// Writes `failed.json` into the run directory `dir`.
pub(crate) fn write_failure(dir: &Path, failure: &Failure) -> Result<()> {
    let json = serde_json::to_string_pretty(failure)?;
    Ok(write_atomic(&dir.join(FAILED_FILE), json.as_bytes())?)
}

/// The `failed.json` of the run directory `dir`, if it has one.
pub fn read_failure(dir: &Path) -> Result<Option<Failure>> {
    let path = dir.join(FAILED_FILE);
    let text = match crate::files::read_text_bounded(&path, MAX_KEY_FILE_BYTES) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        text => text.with_context(|| format!("cannot read {}", path.display()))?,
    };
    serde_json::from_str(&text)
        .map(Some)
        .with_context(|| format!("{} is not a run failure", path.display()))
}

/// `unix_s` seconds since the Unix epoch as an RFC 3339 time in UTC (`2025-03-01T12:00:00Z`).
fn rfc3339_utc(unix_s: u64) -> String {
    let (days, secs) = (unix_s / 86_400, unix_s % 86_400);
    // Civil date from days since 1970-01-01 (the proleptic Gregorian calendar, in 400-year eras).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

/// Rewrites `eval.csv` with the whole curve so far.
pub fn write_curve(dir: &Path, curve: &[EvalPoint]) -> Result<()> {
    Ok(write_atomic(
        &dir.join(EVAL_FILE),
        curve_csv(curve).as_bytes(),
    )?)
}

/// Reads `eval.csv` of a run directory, in step order.
pub(crate) fn read_curve(dir: &Path) -> Result<Vec<EvalPoint>> {
    let path = dir.join(EVAL_FILE);
    let bytes = crate::files::read_bounded(&path, MAX_LOG_BYTES)
        .with_context(|| format!("cannot read {}", path.display()))?;
    parse_curve(&bytes, &path)
}

/// An evaluation curve from the bytes of an `eval.csv` at `path` (named in errors), in step order.
pub fn parse_curve(bytes: &[u8], path: &Path) -> Result<Vec<EvalPoint>> {
    let mut reader = csv::Reader::from_reader(bytes);
    let mut points = Vec::new();
    for (line, row) in reader.deserialize::<EvalPoint>().enumerate() {
        points.push(row.with_context(|| format!("{}: bad row {}", path.display(), line + 1))?);
    }
    points.sort_by_key(|p| p.step);
    Ok(points)
}

/// The `step` column of `queries.csv` (other columns may be empty and are not needed here); `None` when the
/// run has no query log.
pub fn read_query_steps(dir: &Path) -> Result<Option<Vec<u64>>> {
    let path = dir.join(QUERIES_FILE);
    if !path.is_file() {
        return Ok(None);
    }
    let bytes = crate::files::read_bounded(&path, MAX_LOG_BYTES)
        .with_context(|| format!("cannot read {}", path.display()))?;
    parse_query_steps(&bytes, &path).map(Some)
}

/// The `step` column of the bytes of a `queries.csv` at `path` (named in errors).
pub fn parse_query_steps(bytes: &[u8], path: &Path) -> Result<Vec<u64>> {
    let mut reader = csv::Reader::from_reader(bytes);
    let column = reader
        .headers()
        .with_context(|| format!("{}: bad header", path.display()))?
        .iter()
        .position(|h| h == "step")
        .with_context(|| format!("{} has no `step` column", path.display()))?;
    let mut steps = Vec::new();
    for (line, record) in reader.records().enumerate() {
        let record = record.with_context(|| format!("{}: bad row {}", path.display(), line + 1))?;
        let value = record.get(column).unwrap_or("");
        steps.push(
            value
                .trim()
                .parse()
                .with_context(|| format!("{}: bad step '{value}'", path.display()))?,
        );
    }
    Ok(steps)
}

/// The uncertainty logged with each question in `queries.csv` (step, uncertainty, threshold; rows without an
/// uncertainty left out), in the log's order; empty when the run has no query log.
pub(crate) fn read_query_uncertainties(dir: &Path) -> Result<Vec<(u64, f32, Option<f32>)>> {
    let path = dir.join(QUERIES_FILE);
    if !path.is_file() {
        return Ok(Vec::new());
    }
    let bytes = crate::files::read_bounded(&path, MAX_LOG_BYTES)
        .with_context(|| format!("cannot read {}", path.display()))?;
    parse_query_uncertainties(&bytes, &path)
}

/// The step, uncertainty and threshold columns of the bytes of a `queries.csv` at `path` (named in errors).
pub(crate) fn parse_query_uncertainties(
    bytes: &[u8],
    path: &Path,
) -> Result<Vec<(u64, f32, Option<f32>)>> {
    let mut reader = csv::Reader::from_reader(bytes);
    let headers = reader
        .headers()
        .with_context(|| format!("{}: bad header", path.display()))?
        .clone();
    let column = |name: &str| {
        headers
            .iter()
            .position(|h| h == name)
            .with_context(|| format!("{} has no `{name}` column", path.display()))
    };
    let (step, uncertainty, threshold) = (
        column("step")?,
        column("uncertainty")?,
        column("threshold")?,
    );
    let number = |value: &str, what: &str| -> Result<Option<f32>> {
        let value = value.trim();
        if value.is_empty() {
            return Ok(None);
        }
        let parsed: f32 = value
            .parse()
            .with_context(|| format!("{}: bad {what} '{value}'", path.display()))?;
        Ok(Some(parsed))
    };
    let mut rows = Vec::new();
    for (line, record) in reader.records().enumerate() {
        let record = record.with_context(|| format!("{}: bad row {}", path.display(), line + 1))?;
        let field = |c: usize| record.get(c).unwrap_or("");
        let Some(u) = number(field(uncertainty), "uncertainty")? else {
            continue;
        };
        let at = field(step).trim();
        let at = at
            .parse()
            .with_context(|| format!("{}: bad step '{at}'", path.display()))?;
        rows.push((at, u, number(field(threshold), "threshold")?));
    }
    Ok(rows)
}

/// Where a run of a sweep lives below the sweep directory: `ENV/METHOD-NET[/VARIANT]/seedN`, e.g.
/// `CartPole-v0/adqn-bootstrap/tq0.05/seed3`. `variant_from_path` reads the variant back.
pub fn sweep_run_path(
    env: &str,
    method: Method,
    net: NetKind,
    variant: Option<&str>,
    seed: u64,
) -> PathBuf {
    let mut path = PathBuf::from(env);
    path.push(format!("{method}-{net}"));
    if let Some(variant) = variant {
        path.push(variant);
    }
    path.push(format!("seed{seed}"));
    path
}

/// The variant label from a run's path inside a sweep: the components between `METHOD-NET` and `seedN`
/// ([`DEFAULT_VARIANT`] for a run outside that layout).
pub(crate) fn variant_from_path(
    relative: &Path,
    method: Method,
    net: NetKind,
    seed: u64,
) -> String {
    let parts: Vec<String> = relative
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    let method_net = format!("{method}-{net}");
    if parts.last().map(String::as_str) != Some(format!("seed{seed}").as_str()) {
        return DEFAULT_VARIANT.to_string();
    }
    match parts.iter().rposition(|p| *p == method_net) {
        Some(i) if i + 2 < parts.len() => parts[i + 1..parts.len() - 1].join("/"),
        _ => DEFAULT_VARIANT.to_string(),
    }
}

/// Reads one complete run directory; `relative` is its path below the directory being reported on.
pub(crate) fn read_run(dir: &Path, relative: &Path) -> Result<RunRecord> {
    let summary = read_summary(dir)?;
    // config.toml is optional for a report: it only adds t_query, the expert and the eval period.
    let config_path = dir.join(CONFIG_FILE);
    let config = match crate::files::read_bounded(&config_path, MAX_KEY_FILE_BYTES) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        read => Some(read.with_context(|| format!("cannot read {}", config_path.display()))?),
    };
    let eval = read_curve(dir)?;
    let query_steps = read_query_steps(dir)?;
    run_record(dir, relative, summary, config.as_deref(), eval, query_steps)
}

/// A run's record from what its files hold: its summary, the bytes of its `config.toml` (if it has one), its
/// evaluation curve and its query steps (if it has a query log).
pub fn run_record(
    dir: &Path,
    relative: &Path,
    summary: Summary,
    config: Option<&[u8]>,
    eval: Vec<EvalPoint>,
    query_steps: Option<Vec<u64>>,
) -> Result<RunRecord> {
    // Read key by key so that configurations written by earlier versions still load.
    let config: toml::Table = match config {
        Some(bytes) => {
            let text = std::str::from_utf8(bytes)
                .with_context(|| format!("{}/{CONFIG_FILE} is not UTF-8 text", dir.display()))?;
            toml::from_str(text)
                .with_context(|| format!("{}/{CONFIG_FILE} is not valid TOML", dir.display()))?
        }
        None => toml::Table::new(),
    };
    let train_steps = summary.train_steps as u64;
    let eval_period = config
        .get("eval_period")
        .and_then(|v| v.as_integer())
        .filter(|&p| p > 0)
        .map(|p| p as u64)
        .or_else(|| {
            eval.windows(2)
                .map(|w| w[1].step.saturating_sub(w[0].step))
                .find(|&d| d > 0)
        })
        .unwrap_or_else(|| (train_steps / 20).max(1));
    Ok(RunRecord {
        dir: dir.to_path_buf(),
        variant: variant_from_path(relative, summary.method, summary.net, summary.seed),
        id: RunId {
            env: summary.env.clone(),
            method: summary.method,
            net: summary.net,
            seed: summary.seed,
        },
        solve_threshold: summary.solve_threshold,
        train_steps,
        eval_period,
        eval,
        query_steps,
        config: RecordedConfig::of(&config),
        summary: Some(summary),
    })
}

/// Every complete run directory below `root` (a directory holding `summary.json`; hidden directories are
/// skipped), in path order; `visit` sees every directory walked, before its runs are looked for.
pub fn find_runs(root: &Path, mut visit: impl FnMut(&Path)) -> Result<Vec<PathBuf>> {
    if !root.is_dir() {
        bail!("{} is not a directory", root.display());
    }
    let mut run_dirs = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        visit(&dir);
        if is_complete(&dir) {
            run_dirs.push(dir);
            continue;
        }
        let entries =
            std::fs::read_dir(&dir).with_context(|| format!("cannot list {}", dir.display()))?;
        let mut subdirs = Vec::new();
        for entry in entries {
            let entry = entry?;
            let hidden = entry.file_name().to_string_lossy().starts_with('.');
            if entry.file_type()?.is_dir() && !hidden {
                subdirs.push(entry.path());
            }
        }
        subdirs.sort();
        stack.extend(subdirs.into_iter().rev());
    }
    run_dirs.sort();
    Ok(run_dirs)
}

/// Every failed run below `root` (a directory holding `failed.json` and no `summary.json`), in path order, with
/// its failure (an unreadable `failed.json` gives a failure whose error says so).
pub fn find_failed_runs(root: &Path) -> Result<Vec<(PathBuf, Failure)>> {
    let mut failed = Vec::new();
    find_runs(root, |dir| {
        if !is_complete(dir) && dir.join(FAILED_FILE).is_file() {
            let failure = read_failure(dir).and_then(|f| f.context("it vanished"));
            let failure = failure.unwrap_or_else(|err| Failure {
                error: vec![format!("{FAILED_FILE} is unreadable: {err:#}")],
                phase: String::new(),
                step: 0,
                time: String::new(),
                unix_s: 0,
                arld_version: String::new(),
                git_commit: String::new(),
            });
            failed.push((dir.to_path_buf(), failure));
        }
    })?;
    failed.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(failed)
}

/// Finds every complete run below `root` and reads it. Runs that cannot be read are left out and described in
/// the returned notes, so one damaged run does not hide the others. Runs come back in path order.
pub fn load_runs(root: &Path) -> Result<(Vec<RunRecord>, Vec<String>)> {
    let mut runs = Vec::new();
    let mut notes = Vec::new();
    for dir in find_runs(root, |_| {})? {
        let relative = dir.strip_prefix(root).unwrap_or(&dir).to_path_buf();
        match read_run(&dir, &relative) {
            Ok(run) => runs.push(run),
            Err(err) => notes.push(format!("skipped run {}: {err:#}", dir.display())),
        }
    }
    Ok((runs, notes))
}

/// Runs grouped per configuration (env, method, net, variant), in the order the names sort, each group's runs in
/// seed order: the one grouping reports and verdicts share.
pub fn configurations(runs: &[RunRecord]) -> Vec<Vec<&RunRecord>> {
    let mut groups: std::collections::BTreeMap<(&str, &str, &str, &str), Vec<&RunRecord>> =
        std::collections::BTreeMap::new();
    for run in runs {
        let (env, method, net, variant, _seed) = run.key();
        groups
            .entry((env, method, net, variant))
            .or_default()
            .push(run);
    }
    groups
        .into_values()
        .map(|mut members| {
            members.sort_by_key(|r| r.id.seed);
            members
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(step: u64, mean: f64) -> EvalPoint {
        EvalPoint::constant(step, mean)
    }

    #[test]
    fn the_uncertainties_of_a_query_log_skip_rows_without_one_and_name_a_bad_field() {
        let path = Path::new("run/queries.csv");
        // A question with a threshold, one of a rule without one, and the rest of a segment taken back (no
        // uncertainty): written by hand in the log's columns.
        let log = format!(
            "{QUERIES_HEADER}12,0,0.5,0.25,1,0,web,1.000,true\n\
             30,1,0.75,,0,0,web,0.500,true\n\
             31,1,,,,1,web,2.000,false\n"
        );
        let rows = parse_query_uncertainties(log.as_bytes(), path).unwrap();
        assert_eq!(rows, vec![(12, 0.5, Some(0.25)), (30, 0.75, None)]);
        let bad = format!("{QUERIES_HEADER}12,0,high,0.25,1,0,web,1.000,true\n");
        let err = parse_query_uncertainties(bad.as_bytes(), path).unwrap_err();
        assert!(
            format!("{err:#}").contains("run/queries.csv: bad uncertainty 'high'"),
            "{err:#}"
        );
        let no_column = parse_query_uncertainties(b"step,episode\n1,0\n", path).unwrap_err();
        assert!(format!("{no_column:#}").contains("no `uncertainty` column"));
    }

    #[test]
    fn variant_comes_from_the_sweep_layout() {
        let v = |p: &str| variant_from_path(Path::new(p), Method::Adqn, NetKind::Noisy, 3);
        assert_eq!(v("t/CartPole-v0/adqn-noisy/tq0.1/seed3"), "tq0.1");
        assert_eq!(v("CartPole-v0/adqn-noisy/seed3"), DEFAULT_VARIANT);
        assert_eq!(v("my-run"), DEFAULT_VARIANT);
        assert_eq!(v(""), DEFAULT_VARIANT);
        let path = sweep_run_path(
            "CartPole-v0",
            Method::Adqn,
            NetKind::Noisy,
            Some("tq0.1"),
            3,
        );
        assert_eq!(v(path.to_str().unwrap()), "tq0.1");
    }

    #[test]
    fn summary_and_curve_round_trip_through_a_run_directory() {
        let dir = tempfile::tempdir().unwrap();
        let curve = vec![point(1000, 20.5), point(2000, 195.25)];
        write_curve(dir.path(), &curve).unwrap();
        assert_eq!(read_curve(dir.path()).unwrap(), curve);
        assert!(!is_complete(dir.path()));
        let summary = Summary {
            env: "CartPole-v0".into(),
            method: Method::Bdqn,
            net: NetKind::Noisy,
            algo: None,
            seed: 4,
            steps_to_solve: 2000,
            solved: true,
            solve_threshold: 195.0,
            train_steps: 3000,
            final_score: 195.25,
            demos_pretrain: 0,
            demos_queried: 12,
            episodes: 30,
            wall_time_s: 1.5,
            cpu_time_s: Some(1.4),
            steps_per_s: 2000.0,
            numerics: Some(crate::math::NUMERICS.to_string()),
            arld_version: Some(crate::build_info::VERSION.to_string()),
            git_commit: Some(crate::build_info::GIT_COMMIT.to_string()),
            expert: Some("shipped:weak".into()),
            person_s: None,
        };
        write_summary(dir.path(), &summary).unwrap();
        assert!(is_complete(dir.path()));
        assert_eq!(read_summary(dir.path()).unwrap(), summary);
        let record = read_run(dir.path(), Path::new("CartPole-v0/bdqn-noisy/seed4")).unwrap();
        assert_eq!(
            (record.id.method, record.id.net, record.eval_period),
            (Method::Bdqn, NetKind::Noisy, 1000)
        );
        assert_eq!(record.query_steps, None);
        assert_eq!(record.config, RecordedConfig::default());
        assert_eq!(record.demos_queried(), Some(12));
        assert_eq!(record.summary, Some(summary));
        // What the configuration records, the rule in one spelling whichever way it was written.
        std::fs::write(
            dir.path().join(CONFIG_FILE),
            "budget = 250\nt_query = 0.3\nquery_rule = \"paced( horizon = 0.50 )\"\nqueries_from_learning_starts = true\nlearning_starts = 700\n",
        )
        .unwrap();
        for (relative, study) in [
            ("CartPole-v0/bdqn-noisy/tq0.3/seed4", Some(0.3)),
            ("CartPole-v0/bdqn-noisy/seed4", None),
        ] {
            let record = read_run(dir.path(), Path::new(relative)).unwrap();
            let expected = RecordedConfig {
                t_query: Some(0.3),
                expert: None,
                budget: Some(250),
                query_rule: Some("paced(horizon=0.5)".into()),
                asking: RecordedAsking {
                    from_learning_starts: Some(true),
                    learning_starts: Some(700),
                    uncertainty: None,
                },
            };
            assert_eq!(record.config, expected);
            assert_eq!(record.t_query_study(), study, "{relative}");
        }
    }

    #[test]
    fn a_summary_of_an_earlier_version_loads_and_is_written_with_todays_names() {
        let old = r#"{"env":"CartPole-v0","method":"gdqn","net":"plain","seed":0,"steps_to_solve":1,
            "solved":false,"solve_threshold":195.0,"train_steps":1,"final_score":0.0,"demos_pretrain":0,
            "queries_used":37,"episodes":0,"wall_time_s":0.0,"steps_per_s":0.0}"#;
        let summary = parse_summary(old.as_bytes(), Path::new("old.json")).unwrap();
        assert_eq!(summary.demos_queried, 37);
        let written: serde_json::Value = serde_json::to_value(&summary).unwrap();
        assert_eq!(written["demos_queried"], 37);
        assert!(written.get("queries_used").is_none());
        let both = old.replace("\"episodes\"", "\"demos_queried\":37,\"episodes\"");
        assert!(parse_summary(both.as_bytes(), Path::new("both.json")).is_err());
    }

    #[test]
    fn a_failure_round_trips_and_a_summary_removes_it() {
        let dir = tempfile::tempdir().unwrap();
        let err = anyhow::anyhow!("the process exited with status 3\nstderr: boom")
            .context("the expert (cmd) failed to answer");
        let failure = Failure::new(&err, "training", 1234);
        assert_eq!(failure.error.len(), 2);
        assert_eq!(
            failure.message(),
            "the expert (cmd) failed to answer: the process exited with status 3"
        );
        write_failure(dir.path(), &failure).unwrap();
        assert_eq!(read_failure(dir.path()).unwrap(), Some(failure.clone()));
        let failed = find_failed_runs(dir.path()).unwrap();
        assert_eq!(failed, vec![(dir.path().to_path_buf(), failure)]);
        let summary_text = r#"{"env":"CartPole-v0","method":"dqn","net":"plain","seed":0,"steps_to_solve":1,
            "solved":false,"solve_threshold":195.0,"train_steps":1,"final_score":0.0,"demos_pretrain":0,
            "queries_used":0,"episodes":0,"wall_time_s":0.0,"steps_per_s":0.0}"#;
        let summary: Summary = serde_json::from_str(summary_text).unwrap();
        assert_eq!((summary.arld_version, summary.git_commit), (None, None));
        write_summary(dir.path(), &serde_json::from_str(summary_text).unwrap()).unwrap();
        assert_eq!(read_failure(dir.path()).unwrap(), None);
        assert!(find_failed_runs(dir.path()).unwrap().is_empty());
    }

    #[test]
    fn times_are_written_in_rfc3339() {
        assert_eq!(rfc3339_utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(rfc3339_utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(rfc3339_utc(1_735_689_599), "2024-12-31T23:59:59Z");
    }

    #[test]
    fn steps_to_solve_takes_first_evaluation_at_threshold() {
        let curve = vec![
            point(1000, 50.0),
            point(2000, 195.0),
            point(3000, 120.0),
            point(4000, 200.0),
        ];
        assert_eq!(steps_to_solve(&curve, 195.0, 20_000), (2000, true));
    }

    #[test]
    fn a_run_that_never_solves_counts_the_full_training_length() {
        let curve = vec![point(1000, 50.0), point(2000, 194.9)];
        assert_eq!(steps_to_solve(&curve, 195.0, 20_000), (20_000, false));
        assert_eq!(steps_to_solve(&[], 195.0, 500), (500, false));
    }
}
