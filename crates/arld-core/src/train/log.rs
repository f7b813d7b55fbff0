//! [`RunLog`] receives a run's events as it trains: it fills the run directory (the format is
//! [`super::run_dir`]'s: config, evaluation curve, episode, query and answer logs, TensorBoard events, summary) and
//! drives the progress bar.

use super::run_dir::{
    self, ANSWERS_FILE, AnswerStep, CONFIG_FILE, EPISODES_FILE, EPISODES_HEADER, EvalPoint,
    QUERIES_FILE, QUERIES_HEADER, QueryEvent, SUMMARY_FILE, Summary, write_atomic,
};
use crate::replay::Transition;
use crate::task::Action;
use crate::tboard::EventWriter;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{BufWriter, IsTerminal, Seek, Write};
use std::path::{Path, PathBuf};

/// Where a run's logs stood when a snapshot was taken: byte lengths of the streams, the event file's name,
/// the evaluation curve, and the queries asked so far (so that a run continued from the snapshot alone, without
/// its run directory, still knows them; empty when read from a snapshot written before they were kept).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "")]
pub struct LogPosition<A: Action = usize> {
    pub episodes: u64,
    pub queries: u64,
    pub events_file: String,
    pub events: u64,
    pub curve: Vec<EvalPoint>,
    #[serde(default)]
    pub query_events: Vec<QueryEvent<A>>,
    /// Byte length of the answer log (0 in a snapshot written before the run kept one: it starts empty then).
    #[serde(default)]
    pub answers: u64,
}

/// Receives a run's events; writes them to a run directory when one is given, and drives the progress bar.
pub struct RunLog<A: Action = usize> {
    dir: Option<PathBuf>,
    curve: Vec<EvalPoint>,
    episodes: Option<BufWriter<File>>,
    queries: Option<BufWriter<File>>,
    answers: Option<BufWriter<File>>,
    events: Option<EventWriter>,
    progress: ProgressBar,
    /// Every query of the run, also kept in memory (a run asks at most its budget, a few thousand).
    query_events: Vec<QueryEvent<A>>,
}

impl<A: Action> RunLog<A> {
    /// A log that keeps results in memory only (tests, sweeps that only need the summary).
    pub fn in_memory() -> Self {
        Self {
            dir: None,
            curve: Vec::new(),
            episodes: None,
            queries: None,
            answers: None,
            events: None,
            progress: ProgressBar::hidden(),
            query_events: Vec::new(),
        }
    }

    /// A log in memory with a progress bar (when `progress` and standard error is a terminal).
    pub(crate) fn in_memory_with_progress(total_steps: u64, progress: bool) -> Self {
        Self {
            progress: progress_bar(total_steps, progress),
            ..Self::in_memory()
        }
    }

    /// A log writing into `dir` (created if needed; an earlier incomplete run there is overwritten).
    /// `progress` shows a bar with steps/s and ETA when standard error is a terminal.
    pub fn create(dir: &Path, config_toml: &str, total_steps: u64, progress: bool) -> Result<Self> {
        Self::create_with(dir, Some(config_toml), total_steps, progress)
    }

    /// [`RunLog::create`]; with `config_toml` `None`, the files of the run in `dir` are left for
    /// [`RunLog::resume`] to reopen.
    fn create_with(
        dir: &Path,
        config_toml: Option<&str>,
        total_steps: u64,
        progress: bool,
    ) -> Result<Self> {
        let bar = progress_bar(total_steps, progress);
        run_dir::check_own_entries(dir)?;
        run_dir::remove_leftovers(dir)?;
        let Some(config_toml) = config_toml else {
            let _ = std::fs::remove_file(dir.join(SUMMARY_FILE));
            return Ok(Self {
                dir: Some(dir.to_path_buf()),
                curve: Vec::new(),
                episodes: None,
                queries: None,
                answers: None,
                events: None,
                progress: bar,
                query_events: Vec::new(),
            });
        };
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create run directory {}", dir.display()))?;
        let _ = std::fs::remove_file(dir.join(SUMMARY_FILE));
        for entry in std::fs::read_dir(dir)?.flatten() {
            if entry
                .file_name()
                .to_string_lossy()
                .starts_with("events.out.tfevents.")
            {
                let _ = std::fs::remove_file(entry.path());
            }
        }
        write_atomic(&dir.join(CONFIG_FILE), config_toml.as_bytes())?;
        let open = |name: &str, header: &str| -> Result<BufWriter<File>> {
            let path = dir.join(name);
            let mut f = BufWriter::new(
                crate::files::open_own_file(&path, true)
                    .with_context(|| format!("cannot create {}", path.display()))?,
            );
            f.write_all(header.as_bytes())?;
            Ok(f)
        };
        let episodes = open(EPISODES_FILE, EPISODES_HEADER)?;
        let queries = open(QUERIES_FILE, QUERIES_HEADER)?;
        let answers = open(ANSWERS_FILE, "")?;
        let events =
            EventWriter::create(dir).context("cannot create the TensorBoard event file")?;
        Ok(Self {
            dir: Some(dir.to_path_buf()),
            curve: Vec::new(),
            episodes: Some(episodes),
            queries: Some(queries),
            answers: Some(answers),
            events: Some(events),
            progress: bar,
            query_events: Vec::new(),
        })
    }

    /// Where the run's logs stand: flushes the streams and returns their lengths and the evaluation curve, so
    /// that [`RunLog::resume`] can put them back exactly there.
    pub fn position(&mut self) -> Result<LogPosition<A>> {
        let len = |f: &mut Option<BufWriter<File>>| -> Result<u64> {
            Ok(match f {
                Some(f) => {
                    f.flush()?;
                    f.get_mut().stream_position()?
                }
                None => 0,
            })
        };
        let episodes = len(&mut self.episodes)?;
        let queries = len(&mut self.queries)?;
        let answers = len(&mut self.answers)?;
        let (events_file, events) = match &mut self.events {
            Some(ev) => (
                ev.path()
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                ev.position()?,
            ),
            None => (String::new(), 0),
        };
        Ok(LogPosition {
            episodes,
            queries,
            events_file,
            events,
            curve: self.curve.clone(),
            query_events: self.query_events.clone(),
            answers,
        })
    }

    /// A log that continues the one in `dir` from `position` (written by [`RunLog::position`] into a
    /// snapshot): the episode and query logs and the event file are cut back to their lengths then, and
    /// `eval.csv` is rewritten from the curve then. Whatever the interrupted run wrote after its snapshot is gone.
    pub fn resume(
        dir: &Path,
        position: &LogPosition<A>,
        total_steps: u64,
        progress: bool,
    ) -> Result<Self> {
        let mut log = Self::create_with(dir, None, total_steps, progress)?;
        let reopen = |name: &str, len: u64| -> Result<BufWriter<File>> {
            let path = dir.join(name);
            let file = crate::files::open_own_file(&path, false)
                .with_context(|| format!("cannot reopen {} to continue the run", path.display()))?;
            let actual = file.metadata()?.len();
            anyhow::ensure!(
                actual >= len,
                "{} is shorter ({actual} bytes) than when the snapshot was written ({len} bytes)",
                path.display()
            );
            file.set_len(len)?;
            let mut f = BufWriter::new(file);
            f.seek(std::io::SeekFrom::Start(len))?;
            Ok(f)
        };
        log.episodes = Some(reopen(EPISODES_FILE, position.episodes)?);
        log.queries = Some(reopen(QUERIES_FILE, position.queries)?);
        // A run from before the answer log has none yet: it starts empty where the snapshot was taken.
        let answers = dir.join(ANSWERS_FILE);
        log.answers = Some(if position.answers == 0 {
            BufWriter::new(
                crate::files::open_own_file(&answers, true)
                    .with_context(|| format!("cannot create {}", answers.display()))?,
            )
        } else {
            reopen(ANSWERS_FILE, position.answers)?
        });
        // The name comes from the snapshot, a file people copy around: it must name an event file of this
        // directory, never a path elsewhere.
        let name = &position.events_file;
        anyhow::ensure!(
            run_dir::is_events_file(name),
            "the snapshot names {name:?} as the run's event file, which is no event file of the run directory"
        );
        let events = dir.join(name);
        log.events = Some(
            EventWriter::reopen(&events, position.events)
                .with_context(|| format!("cannot reopen {}", events.display()))?,
        );
        log.curve = position.curve.clone();
        log.query_events = position.query_events.clone();
        run_dir::write_curve(dir, &log.curve)?;
        Ok(log)
    }

    /// A log in memory only ([`RunLog::in_memory`]) that continues a run from `position`: it knows the queries
    /// asked before the snapshot.
    pub(crate) fn in_memory_resumed(position: &LogPosition<A>) -> Self {
        let mut log = Self::in_memory();
        log.query_events = position.query_events.clone();
        log
    }

    /// Sets the label shown before the progress bar.
    pub(crate) fn set_prefix(&self, prefix: String) {
        self.progress.set_prefix(prefix);
    }

    /// Moves the progress bar to `step`.
    pub fn progress(&self, step: usize) {
        self.progress.set_position(step as u64);
    }

    pub fn episode(
        &mut self,
        episode: usize,
        step: usize,
        ret: f64,
        len: usize,
        demo_steps: usize,
    ) -> Result<()> {
        if let Some(f) = &mut self.episodes {
            writeln!(f, "{episode},{step},{ret},{len},{demo_steps}")?;
        }
        self.scalar("train/episode_return", step, ret as f32)
    }

    /// A question of the rule (a row of the query log), or a person's takeover (kept for the answer log only).
    pub fn query(&mut self, q: &QueryEvent<A>) -> Result<()> {
        self.query_events.push(q.clone());
        if let (Some(f), true) = (&mut self.queries, q.started_by.is_rule()) {
            f.write_all(q.csv_row().as_bytes())?;
        }
        Ok(())
    }

    /// What opened the segment in progress (the last query or takeover logged).
    pub(crate) fn last_started_by(&self) -> Option<super::run_dir::StartedBy> {
        self.query_events.last().map(|q| q.started_by)
    }

    /// A step the expert took (`taken` as the run stored it at `(step, episode)`, `ended` its `(terminated,
    /// truncated)`): written to the answer log with the question that opened its segment (the last query logged).
    pub fn answered(
        &mut self,
        at: (usize, usize),
        taken: &Transition<'_, A>,
        ended: (bool, bool),
    ) -> Result<()> {
        let Some(f) = &mut self.answers else {
            return Ok(());
        };
        let line = AnswerStep::<A>::new(at, taken, ended, self.query_events.last()).json_line()?;
        f.write_all(line.as_bytes())?;
        Ok(())
    }

    pub fn scalar(&mut self, tag: &str, step: usize, value: f32) -> Result<()> {
        if let Some(ev) = &mut self.events {
            ev.scalar(tag, step as u64, value)?;
        }
        Ok(())
    }

    /// Records an evaluation and rewrites `eval.csv`.
    pub fn eval(&mut self, point: EvalPoint) -> Result<()> {
        self.scalar("eval/mean_return", point.step as usize, point.mean as f32)?;
        self.progress.set_message(format!("eval {:.1}", point.mean));
        self.curve.push(point);
        if let Some(dir) = &self.dir {
            run_dir::write_curve(dir, &self.curve)?;
        }
        if let Some(ev) = &mut self.events {
            ev.flush()?;
        }
        Ok(())
    }

    /// Every query so far.
    pub fn query_events(&self) -> &[QueryEvent<A>] {
        &self.query_events
    }

    /// The evaluation curve so far.
    pub fn curve(&self) -> &[EvalPoint] {
        &self.curve
    }

    /// The run directory, if any.
    pub fn dir(&self) -> Option<&Path> {
        self.dir.as_deref()
    }

    /// Flushes the streams and writes `summary.json` last, marking the run complete.
    pub fn finish(&mut self, summary: &Summary) -> Result<()> {
        self.progress.finish_and_clear();
        for f in [&mut self.episodes, &mut self.queries, &mut self.answers]
            .into_iter()
            .flatten()
        {
            f.flush()?;
        }
        if let Some(ev) = &mut self.events {
            ev.flush()?;
        }
        if let Some(dir) = &self.dir {
            run_dir::write_summary(dir, summary)?;
        }
        Ok(())
    }
}

/// The run's progress bar (steps/s and ETA), drawn only when asked for and standard error is a terminal.
fn progress_bar(total_steps: u64, progress: bool) -> ProgressBar {
    if progress && std::io::stderr().is_terminal() {
        let bar =
            ProgressBar::with_draw_target(Some(total_steps), ProgressDrawTarget::stderr_with_hz(4));
        bar.set_style(
            ProgressStyle::with_template(
                "{prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} steps {rate} ETA {eta} {msg}",
            )
            .expect("valid template")
            .with_key(
                "rate",
                |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = write!(w, "{:.0} steps/s", state.per_sec());
                },
            ),
        );
        bar
    } else {
        ProgressBar::hidden()
    }
}
