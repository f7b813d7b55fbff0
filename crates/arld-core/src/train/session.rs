//! Opening a run directory, in one place for the command line, the laboratory and Python: the lock (one process,
//! and in it one run, at a time: [`Session::lock`]), how the run begins there ([`Begin`]: a new run, `--overwrite`
//! removing only the files a run writes, resuming from its snapshot or restarting from step 0), whether a
//! finished run is reused ([`reuse_or_clear`]), the run's log and the snapshot it continues from, refused when
//! its recorded configuration differs ([`open`], [`open_log`]), and the failure record (`failed.json`:
//! `record_failure`; a directory a failed attempt wrote nothing into is removed again: [`Session::close_failed`]).

use super::log::{LogPosition, RunLog};
use super::snapshot::{Checkpointer, SNAPSHOT_FILE};
use super::{TrainConfig, run_dir};
use crate::dir_lock::{DirLock, Holder};
use crate::state::StateDict;
use anyhow::{Context, Result, ensure};
use std::path::{Path, PathBuf};

/// A run directory held by this process: the lock is released when the session is dropped.
#[derive(Debug)]
pub struct Session {
    dir: PathBuf,
    /// Whether the directory did not exist before [`Session::lock`] created it.
    created: bool,
    lock: DirLock,
}

/// How a run begins in the directory of a [`Session`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Begin {
    /// A new run: the directory must be empty, or, with `overwrite`, hold only the files a run writes (removed).
    New { overwrite: bool },
    /// Continue the interrupted run from its snapshot; a run stopped before its first snapshot starts again.
    Resume,
    /// Start the run over from step 0 with its configuration, keeping its `failed.json` until it finishes.
    Restart,
}

impl Session {
    /// Takes the lock of the run directory `dir` (created if missing): one process, and in it one run, at a
    /// time. Refused naming the holder ([`held_by_this_process`] tells whether it is this process).
    pub fn lock(dir: &Path) -> Result<Self> {
        ensure!(
            !dir.exists() || dir.is_dir(),
            "the run directory {} exists and is not a directory",
            dir.display()
        );
        let created = !dir.exists();
        std::fs::create_dir_all(dir).map_err(|e| {
            anyhow::anyhow!("cannot create the run directory {}: {e}", dir.display())
        })?;
        let lock = DirLock::acquire(dir, run_dir::LOCK_FILE)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            created,
            lock,
        })
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Whether the run directory holds a snapshot to continue from.
    pub fn has_snapshot(&self) -> bool {
        self.dir.join(SNAPSHOT_FILE).is_file()
    }

    /// Makes the directory ready for the run to begin as `how` says (announcing a restart on standard error).
    pub fn begin(&self, how: Begin) -> Result<()> {
        let dir = &self.dir;
        match how {
            Begin::New { overwrite } => run_dir::prepare_new_run(dir, overwrite),
            Begin::Restart => {
                eprintln!(
                    "arld: starting the run in {} over from step 0 (--restart)",
                    dir.display()
                );
                run_dir::prepare_restart(dir)
            }
            Begin::Resume => {
                // Killed before its first snapshot: nothing to continue from, so the run starts again. Only a
                // missing snapshot means that: anything else in its place is an error that keeps it.
                let snapshot =
                    crate::files::own_file_exists(&dir.join(SNAPSHOT_FILE)).map_err(|e| {
                        anyhow::anyhow!("cannot resume the run: {e}; --restart starts it over")
                    })?;
                if snapshot {
                    return Ok(());
                }
                eprintln!(
                    "arld: {} has no snapshot yet (the run stopped before its first one): starting it again from step 0",
                    dir.display()
                );
                run_dir::prepare_restart(dir)
            }
        }
    }

    /// Ends the session of a run that failed. A directory this session created, into which the run wrote
    /// nothing (refused before it began: bad demonstrations, an expert that cannot start), is removed again,
    /// so that the same command can be given again: `None`. Otherwise the run stays incomplete, its logs whole
    /// up to where it stopped: the sentence that says so.
    pub fn close_failed(self) -> Option<String> {
        let Self { dir, created, lock } = self;
        if !dir.join(run_dir::CONFIG_FILE).is_file() {
            if created {
                drop(lock);
                let _ = std::fs::remove_file(dir.join(run_dir::FAILED_FILE));
                let _ = std::fs::remove_dir(&dir);
            }
            return None;
        }
        let why = if dir.join(run_dir::FAILED_FILE).is_file() {
            format!("; {} records why", run_dir::FAILED_FILE)
        } else {
            String::new()
        };
        Some(format!(
            "the run in {} is incomplete: its logs (episodes.csv, queries.csv, eval.csv once an evaluation ran) \
             end where it stopped, and it has no summary.json{why}",
            dir.display()
        ))
    }
}

/// Whether the lock of the run directory `dir` is held by this process (by another of its runs).
pub fn held_by_this_process(dir: &Path) -> bool {
    std::fs::read_to_string(dir.join(run_dir::LOCK_FILE))
        .ok()
        .and_then(|text| serde_json::from_str::<Holder>(&text).ok())
        .is_some_and(|h| h.pid == std::process::id())
}

/// Whether `dir` holds the finished run of exactly `cfg` (to be reused: `true`). A finished run of another
/// configuration is refused, naming the keys that differ; an interrupted run with a snapshot is left to
/// continue; any other leftovers of a run are cleared, so that no earlier run's files (checkpoints) mix into
/// the new one.
pub fn reuse_or_clear(cfg: &TrainConfig, dir: &Path) -> Result<bool> {
    if run_dir::is_complete(dir) {
        let earlier = run_dir::read_config(dir, &run_dir::RunId::of(cfg)).with_context(|| {
            format!(
                "the finished run's {} is not valid",
                dir.join(run_dir::CONFIG_FILE).display()
            )
        })?;
        let differences = earlier.differences(cfg);
        ensure!(
            differences.is_empty(),
            "{} holds a finished run of another configuration; its values (and the ones asked for) differ in: \
             {}; give another run directory, or the same settings",
            dir.display(),
            differences.join(", ")
        );
        return Ok(true);
    }
    if !dir.join(SNAPSHOT_FILE).is_file() {
        run_dir::prepare_new_run(dir, true)?;
    }
    Ok(false)
}

/// A run opened in its directory (or in memory): its log, the snapshot it continues from, and the
/// checkpointer that snapshots it (in a directory only).
pub struct Opened<A: crate::task::Action> {
    pub log: RunLog<A>,
    pub snapshot: Option<StateDict<'static>>,
    pub checkpointer: Option<Checkpointer>,
}

/// Opens the run of `cfg` in `dir`, continuing from the snapshot there if it has one (refused if the snapshot
/// or the directory's config.toml belongs to another configuration), or in memory without `dir` (no progress
/// bar). An error here is recorded in the directory's `failed.json` as the `setup` phase.
pub fn open<A: crate::task::Action>(
    dir: Option<&Path>,
    cfg: &TrainConfig,
    progress: bool,
) -> Result<Opened<A>> {
    let Some(dir) = dir else {
        return Ok(Opened {
            log: RunLog::in_memory(),
            snapshot: None,
            checkpointer: None,
        });
    };
    let mut checkpointer = Checkpointer::new(dir, cfg);
    let opened = checkpointer.load().and_then(|snapshot| {
        let log = open_log(Some(dir), cfg, snapshot.as_ref(), progress)?;
        Ok((snapshot, log))
    });
    let (snapshot, log) = opened.map_err(|err| record_setup_failure(Some(dir), err))?;
    if snapshot.is_some() {
        eprintln!("{}: continuing from its snapshot", dir.display());
    }
    Ok(Opened {
        log,
        snapshot,
        checkpointer: Some(checkpointer),
    })
}

/// The log position recorded in a snapshot.
pub fn resume_position<A: crate::task::Action>(state: &StateDict) -> Result<LogPosition<A>> {
    Ok(state.value("log")?)
}

/// The log of a run of `cfg`: in memory without `dir`; in `dir`, continuing its files when the run continues
/// from `snapshot` and `dir` holds that run (its config.toml must record `cfg`, or the run is refused, naming the
/// keys that differ), else a new run's files. The command line, sweeps and Python all open a run's log here.
pub fn open_log<A: crate::task::Action>(
    dir: Option<&Path>,
    cfg: &TrainConfig,
    snapshot: Option<&StateDict>,
    progress: bool,
) -> Result<RunLog<A>> {
    let steps = cfg.train_steps as u64;
    let Some(dir) = dir else {
        return Ok(match snapshot {
            Some(state) => RunLog::in_memory_resumed(&resume_position(state)?),
            None => RunLog::in_memory_with_progress(steps, progress),
        });
    };
    match snapshot {
        Some(state) if dir.join(run_dir::CONFIG_FILE).is_file() => {
            let differences = run_dir::read_written_config(dir)?.differences(cfg);
            ensure!(
                differences.is_empty(),
                "{} holds another run (its config.toml differs: {}); give another directory",
                dir.display(),
                differences.join(", ")
            );
            RunLog::resume(dir, &resume_position(state)?, steps, progress)
        }
        _ => RunLog::create(dir, &cfg.to_toml(), steps, progress),
    }
}

/// Records `err`, an error before training began, as the `setup` phase in the `failed.json` of `dir` (when
/// there is one and it exists), and gives it back.
pub fn record_setup_failure(dir: Option<&Path>, err: anyhow::Error) -> anyhow::Error {
    if let Some(dir) = dir.filter(|dir| dir.is_dir()) {
        record_failure(dir, &err, "setup", 0);
    }
    err
}

/// Writes `failed.json` for the error `err` into the run directory `dir`, unless `err` is a stop request (the
/// run is then interrupted, not failed). The run's own error matters more than this file: a write that fails
/// is only warned about.
pub(crate) fn record_failure(dir: &Path, err: &anyhow::Error, phase: &str, step: usize) {
    if crate::interrupt::is_stop(err) {
        return;
    }
    let failure = run_dir::Failure::new(err, phase, step);
    if let Err(write_err) = run_dir::write_failure(dir, &failure) {
        eprintln!("warning: the run failed, and recording why failed too: {write_err:#}");
    }
}
