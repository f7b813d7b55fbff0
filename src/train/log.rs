//! Everything a run writes: the run directory (config, evaluation curve, episode and query logs, TensorBoard
//! events, weights, summary) and the progress bar.
//!
//! Small result files are rewritten atomically (temporary file, then rename), so an interrupted run never leaves
//! a half-written result; the episode and query logs and the event file are append-only streams. A run is
//! complete exactly when `summary.json` exists: it is written last.

use crate::tboard::EventWriter;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{BufWriter, IsTerminal, Write};
use std::path::{Path, PathBuf};

/// One evaluation: `eval_episodes` test episodes without exploration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalPoint {
    pub step: u64,
    pub mean: f64,
    pub std: f64,
    pub min: f64,
    pub max: f64,
}

/// One query: the agent handed control to the expert.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct QueryEvent {
    pub step: usize,
    pub episode: usize,
    pub uncertainty: Option<f32>,
    pub threshold: Option<f32>,
    pub expert_action: usize,
    pub agent_action: usize,
}

/// What a finished run reports (`summary.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub env: String,
    pub method: String,
    pub net: String,
    pub seed: u64,
    /// First evaluation step whose mean reaches the solve threshold; `train_steps` if none does.
    pub steps_to_solve: usize,
    pub solved: bool,
    pub solve_threshold: f64,
    pub train_steps: usize,
    /// Mean test return of the last evaluation.
    pub final_score: f64,
    /// Demonstrated transitions used: before training (pre-training) and asked for during training.
    pub demos_pretrain: usize,
    pub queries_used: usize,
    pub episodes: usize,
    pub wall_time_s: f64,
    pub steps_per_s: f64,
}

/// First evaluation step whose mean reaches `threshold`, or `train_steps` if none does (docs/algorithm.md §11).
pub fn steps_to_solve(curve: &[EvalPoint], threshold: f64, train_steps: u64) -> (u64, bool) {
    match curve.iter().find(|p| p.mean >= threshold) {
        Some(p) => (p.step, true),
        None => (train_steps, false),
    }
}

/// Writes `bytes` to `path` through a temporary file (synced, then renamed over `path`), so a reader never
/// sees a half-written file; the temporary file is removed if anything fails.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .with_context(|| format!("{} has no file name", path.display()))?;
    let tmp = dir.join(format!(
        ".{}.tmp{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let write = || -> std::io::Result<()> {
        let mut file = std::fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().map_err(|err| {
        let _ = std::fs::remove_file(&tmp);
        anyhow::Error::new(err).context(format!("cannot write {}", path.display()))
    })
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

/// Receives a run's events; writes them to a run directory when one is given, and drives the progress bar.
pub struct RunLog {
    dir: Option<PathBuf>,
    curve: Vec<EvalPoint>,
    episodes: Option<BufWriter<File>>,
    queries: Option<BufWriter<File>>,
    events: Option<EventWriter>,
    progress: ProgressBar,
}

impl RunLog {
    /// A log that keeps results in memory only (tests, sweeps that only need the summary).
    pub fn in_memory() -> Self {
        Self {
            dir: None,
            curve: Vec::new(),
            episodes: None,
            queries: None,
            events: None,
            progress: ProgressBar::hidden(),
        }
    }

    /// A log writing into `dir` (created if needed; an earlier incomplete run there is overwritten).
    /// `progress` shows a bar with steps/s and ETA when standard error is a terminal.
    pub fn create(dir: &Path, config_toml: &str, total_steps: u64, progress: bool) -> Result<Self> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create run directory {}", dir.display()))?;
        let _ = std::fs::remove_file(dir.join("summary.json"));
        for entry in std::fs::read_dir(dir)?.flatten() {
            if entry
                .file_name()
                .to_string_lossy()
                .starts_with("events.out.tfevents.")
            {
                let _ = std::fs::remove_file(entry.path());
            }
        }
        write_atomic(&dir.join("config.toml"), config_toml.as_bytes())?;
        let open = |name: &str, header: &str| -> Result<BufWriter<File>> {
            let path = dir.join(name);
            let mut f = BufWriter::new(
                File::create(&path).with_context(|| format!("cannot create {}", path.display()))?,
            );
            f.write_all(header.as_bytes())?;
            Ok(f)
        };
        let episodes = open("episodes.csv", "episode,step,return,length,demo_steps\n")?;
        let queries = open(
            "queries.csv",
            "step,episode,uncertainty,threshold,expert_action,agent_action\n",
        )?;
        let events =
            EventWriter::create(dir).context("cannot create the TensorBoard event file")?;
        let bar = if progress && std::io::stderr().is_terminal() {
            let bar = ProgressBar::with_draw_target(
                Some(total_steps),
                ProgressDrawTarget::stderr_with_hz(4),
            );
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} steps {rate} ETA {eta} {msg}",
                )
                .expect("valid template")
                .with_key("rate", |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = write!(w, "{:.0} steps/s", state.per_sec());
                }),
            );
            bar
        } else {
            ProgressBar::hidden()
        };
        Ok(Self {
            dir: Some(dir.to_path_buf()),
            curve: Vec::new(),
            episodes: Some(episodes),
            queries: Some(queries),
            events: Some(events),
            progress: bar,
        })
    }

    /// Sets the label shown before the progress bar.
    pub fn set_prefix(&self, prefix: String) {
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

    pub fn query(&mut self, q: &QueryEvent) -> Result<()> {
        if let Some(f) = &mut self.queries {
            let opt = |v: Option<f32>| v.map(|x| x.to_string()).unwrap_or_default();
            writeln!(
                f,
                "{},{},{},{},{},{}",
                q.step,
                q.episode,
                opt(q.uncertainty),
                opt(q.threshold),
                q.expert_action,
                q.agent_action
            )?;
        }
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
            write_atomic(&dir.join("eval.csv"), curve_csv(&self.curve).as_bytes())?;
        }
        if let Some(ev) = &mut self.events {
            ev.flush()?;
        }
        Ok(())
    }

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
        for f in [&mut self.episodes, &mut self.queries]
            .into_iter()
            .flatten()
        {
            f.flush()?;
        }
        if let Some(ev) = &mut self.events {
            ev.flush()?;
        }
        if let Some(dir) = &self.dir {
            let json = serde_json::to_string_pretty(summary)?;
            write_atomic(&dir.join("summary.json"), json.as_bytes())?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(step: u64, mean: f64) -> EvalPoint {
        EvalPoint {
            step,
            mean,
            std: 0.0,
            min: mean,
            max: mean,
        }
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
