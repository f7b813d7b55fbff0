//! Sweeps: many training runs over a grid (environments x methods x networks x seeds, plus optional t_query
//! values and expert specs), run in parallel, resumable, and gathered into one `results.csv`.
//!
//! The parts fit as follows:
//! - [`SweepGrid`] is the grid, built from CLI values or a TOML file (`[sweep]` table); [`SweepGrid::specs`]
//!   expands it into [`RunSpec`]s, each with a stable, readable directory name ([`RunSpec::dir_name`]).
//! - [`run_grid`] writes the grid to `sweep.toml` in the sweep directory and calls [`run_sweep`], which runs
//!   every spec through a caller-supplied run function on `jobs` threads. The sweep knows nothing about
//!   training: a run is a directory, and it is complete exactly when its `summary.json` exists (the training
//!   code writes it last, atomically). That makes the sweep resumable: complete runs are skipped, incomplete
//!   ones are cleared and run again (or continue from their snapshot). A complete run of an older arld that
//!   used the C library's elementary functions ([`run_dir::is_stale`]) is run again, so that every run of a
//!   sweep regenerates byte for byte with this arld on any CPU. A pending run whose resolved
//!   configuration equals that of a finished variant of the same environment, method, network and seed takes
//!   its files instead of running: runs are deterministic.
//! - [`collect_results`] reads every complete run under a directory and writes `results.csv`, one row per
//!   evaluation point.

use anyhow::{Context, Result, bail};
use arld_core::train::run_dir::{
    self, DEFAULT_VARIANT, EXPERT_VARIANT_PREFIX, RunId, RunRecord, T_QUERY_VARIANT_PREFIX,
    write_atomic,
};
use arld_core::train::{ConfigInput, Method, NetKind, TrainConfig};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Name of the file that records a sweep's grid inside its directory.
pub const SWEEP_FILE: &str = "sweep.toml";
/// Name of the file that gathers every evaluation point of a sweep.
pub const RESULTS_FILE: &str = "results.csv";

/// The grid of a sweep. Every combination of `envs x methods x nets x t_query x experts x seeds` is one run;
/// an empty `t_query` or `experts` list means "not varied" (the training code's per-task default applies).
/// `set` holds `key=value` overrides applied to every run (same syntax as `arld train --set`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepGrid {
    pub envs: Vec<String>,
    pub methods: Vec<Method>,
    pub nets: Vec<NetKind>,
    #[serde(deserialize_with = "deserialize_seeds")]
    pub seeds: Vec<u64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub t_query: Vec<f64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub experts: Vec<String>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub set: Vec<String>,
    /// Variants by override: each `key=value` entry is one variant of every run (e.g. `n_r=100`, or an
    /// ablation such as `timeout_as_terminal=true`), named `key-value` in the run's path.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub vary: Vec<String>,
}

/// Keys accepted in the `[sweep]` table (listed in error messages).
const GRID_KEYS: [&str; 8] = [
    "envs", "methods", "nets", "seeds", "t_query", "experts", "set", "vary",
];

/// `seeds = 20` (meaning 0..20) or `seeds = [0, 3, 7]`.
#[derive(Deserialize)]
#[serde(untagged)]
enum SeedsValue {
    Count(u64),
    List(Vec<u64>),
}

fn deserialize_seeds<'de, D: serde::Deserializer<'de>>(
    deserializer: D,
) -> Result<Vec<u64>, D::Error> {
    match SeedsValue::deserialize(deserializer) {
        Ok(SeedsValue::Count(n)) => {
            check_seed_count(n).map_err(serde::de::Error::custom)?;
            Ok((0..n).collect())
        }
        Ok(SeedsValue::List(list)) => Ok(list),
        Err(_) => Err(serde::de::Error::custom(
            "`seeds` must be a count (seeds = 20 means seeds 0..19) or a list of non-negative integers",
        )),
    }
}

/// The whole sweep file: a single `[sweep]` table.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SweepFile {
    sweep: SweepGrid,
}

/// The most seeds a sweep runs per configuration (the paper used 20).
pub const MAX_SEEDS: u64 = 10_000;
/// The longest sweep file read (a grid is a few hundred bytes).
const MAX_GRID_BYTES: u64 = 4 << 20;

/// Parses seeds given on a command line: `20` (seeds 0..19), `3..8` (seeds 3..7) or `0,4,9`; at most
/// [`MAX_SEEDS`] of them (their values are checked with the rest of the grid, [`SweepGrid::validate`]).
pub fn parse_seeds(text: &str) -> Result<Vec<u64>> {
    let text = text.trim();
    let parse = |s: &str| -> Result<u64> {
        s.trim()
            .parse::<u64>()
            .with_context(|| format!("'{s}' is not a non-negative integer seed"))
    };
    let seeds: Vec<u64> = if let Some((start, end)) = text.split_once("..") {
        let (start, end) = (parse(start)?, parse(end)?);
        if start >= end {
            bail!("seed range '{text}' is empty (use START..END with START < END)");
        }
        check_seed_count(end - start)?;
        (start..end).collect()
    } else if text.contains(',') {
        text.split(',').map(parse).collect::<Result<_>>()?
    } else {
        let n = parse(text)?;
        check_seed_count(n)?;
        (0..n).collect()
    };
    check_seed_count(seeds.len() as u64)?;
    Ok(seeds)
}

fn check_seed_count(n: u64) -> Result<()> {
    if n > MAX_SEEDS {
        bail!("--seeds asks for {n} seeds per configuration; a sweep runs at most {MAX_SEEDS}");
    }
    Ok(())
}

/// Characters allowed in names that become directory names.
fn is_path_safe(name: &str) -> bool {
    !name.is_empty()
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

/// Turns an expert spec into a directory-name fragment: `noisy:0.4:shipped:perfect` -> `noisy-0.4-shipped-perfect`;
/// likewise a `vary` override: `n_r=100` -> `n_r-100`.
fn dir_fragment(spec: &str) -> String {
    spec.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '_') {
                c
            } else {
                '-'
            }
        })
        .collect()
}

/// The overrides of one `vary` entry: `key=value`, or several joined by `;` to vary them together (one variant,
/// e.g. `budget=100;query_rule=paced`).
fn vary_parts(entry: &str) -> impl Iterator<Item = &str> {
    entry.split(';').map(str::trim).filter(|p| !p.is_empty())
}

/// Splits command-line list values: each value may itself be comma-separated (`--envs A,B --envs C`).
fn split_values(values: &[String]) -> Vec<String> {
    values
        .iter()
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .filter(|v| !v.is_empty())
        .map(str::to_string)
        .collect()
}

impl SweepGrid {
    /// Builds and validates a grid from command-line values. List values may be repeated or comma-separated;
    /// `seeds` is parsed by [`parse_seeds`] (`20`, `3..8` or `0,4,9`); `t_query` values are numbers; `set` and
    /// `vary` entries are `key=value` overrides kept whole (they may contain commas).
    #[allow(clippy::too_many_arguments)]
    pub fn from_cli_values(
        envs: &[String],
        methods: &[String],
        nets: &[String],
        seeds: &str,
        t_query: &[String],
        experts: &[String],
        set: &[String],
        vary: &[String],
    ) -> Result<Self> {
        let t_query = split_values(t_query)
            .iter()
            .map(|t| {
                t.parse::<f64>()
                    .with_context(|| format!("t_query value '{t}' is not a number"))
            })
            .collect::<Result<Vec<f64>>>()?;
        let methods = split_values(methods)
            .iter()
            .map(|m| m.parse::<Method>())
            .collect::<Result<Vec<_>>>()?;
        let nets = split_values(nets)
            .iter()
            .map(|n| n.parse::<NetKind>())
            .collect::<Result<Vec<_>>>()?;
        let grid = SweepGrid {
            envs: split_values(envs),
            methods,
            nets,
            seeds: parse_seeds(seeds)?,
            t_query,
            experts: split_values(experts),
            set: set.to_vec(),
            vary: vary.to_vec(),
        };
        grid.validate()?;
        Ok(grid)
    }

    /// Parses a sweep file (`[sweep]` table) and validates it.
    pub fn from_toml_str(text: &str) -> Result<Self> {
        let file: SweepFile = toml::from_str(text).map_err(|err| {
            anyhow::anyhow!(
                "invalid sweep file: {}\nA sweep file holds one [sweep] table with the keys: {} \
                 (envs, methods, nets and seeds are required)",
                err.to_string().trim_end(),
                GRID_KEYS.join(", ")
            )
        })?;
        file.sweep.validate()?;
        Ok(file.sweep)
    }

    /// Reads and validates a sweep file.
    pub fn from_toml_file(path: &Path) -> Result<Self> {
        let text = arld_core::files::read_text_bounded(path, MAX_GRID_BYTES)
            .with_context(|| format!("cannot read {}", path.display()))?;
        Self::from_toml_str(&text).with_context(|| format!("in sweep file {}", path.display()))
    }

    /// The grid as a sweep file, readable back by [`SweepGrid::from_toml_str`].
    pub fn to_toml_string(&self) -> Result<String> {
        let file = SweepFile {
            sweep: self.clone(),
        };
        Ok(toml::to_string(&file)?)
    }

    /// Checks the grid: every list non-empty and free of duplicates, `set` entries of the
    /// form key=value that do not clash with a varied dimension, and every run's configuration resolves (known
    /// environment, values valid for its method): all before any run starts.
    pub fn validate(&self) -> Result<()> {
        fn check_list<T: PartialEq + std::fmt::Debug>(
            name: &str,
            list: &[T],
            required: bool,
        ) -> Result<()> {
            if required && list.is_empty() {
                bail!("sweep key `{name}` must list at least one value");
            }
            for (i, value) in list.iter().enumerate() {
                if list[..i].contains(value) {
                    bail!("sweep key `{name}` lists {value:?} twice");
                }
            }
            Ok(())
        }
        check_list("envs", &self.envs, true)?;
        check_list("methods", &self.methods, true)?;
        check_list("nets", &self.nets, true)?;
        check_seed_count(self.seeds.len() as u64)?;
        check_list("seeds", &self.seeds, true)?;
        let max_seed = arld_core::train::config::MAX_SEED;
        if let Some(s) = self.seeds.iter().find(|&&s| s > max_seed) {
            bail!("seed {s} is too large for the field `seed`: at most {max_seed}");
        }
        check_list("t_query", &self.t_query, false)?;
        check_list("experts", &self.experts, false)?;
        check_list("vary", &self.vary, false)?;
        for env in &self.envs {
            if !is_path_safe(env) {
                bail!("environment id '{env}' may only contain letters, digits, '-', '_' and '.'");
            }
        }
        for expert in &self.experts {
            if expert.trim().is_empty() || expert.contains('"') || expert.contains('\\') {
                bail!(
                    "expert spec {expert:?} must be non-empty and contain no quotes or backslashes"
                );
            }
        }
        let fragments: BTreeSet<String> = self.experts.iter().map(|e| dir_fragment(e)).collect();
        if fragments.len() != self.experts.len() {
            bail!(
                "two expert specs map to the same directory name: {:?}",
                self.experts
            );
        }
        let override_key = |entry: &str, list: &str| -> Result<String> {
            let Some((key, _)) = entry.split_once('=') else {
                bail!("override '{entry}' in `{list}` is not of the form key=value");
            };
            let key = key.trim();
            if key.is_empty() {
                bail!("override '{entry}' in `{list}` has an empty key");
            }
            Ok(key.to_string())
        };
        let vary_keys = self
            .vary
            .iter()
            .flat_map(|entry| vary_parts(entry))
            .map(|part| override_key(part, "vary"))
            .collect::<Result<BTreeSet<String>>>()?;
        for entry in &self.vary {
            for part in vary_parts(entry) {
                let key = override_key(part, "vary")?;
                let dedicated = ["env", "method", "net", "seed", "t_query", "expert"];
                if dedicated.contains(&key.as_str()) {
                    bail!(
                        "`vary` entry '{entry}' varies `{key}`, which has its own sweep key (envs, methods, \
                         nets, seeds, t_query, experts)"
                    );
                }
            }
            if !is_path_safe(&dir_fragment(entry)) {
                bail!("`vary` entry '{entry}' cannot name a directory");
            }
        }
        let fragments: BTreeSet<String> = self.vary.iter().map(|e| dir_fragment(e)).collect();
        if fragments.len() != self.vary.len() {
            bail!(
                "two `vary` entries map to the same directory name: {:?}",
                self.vary
            );
        }
        for entry in &self.set {
            let key = override_key(entry, "set")?;
            let varied = ["env", "method", "net", "seed"]
                .into_iter()
                .chain((!self.t_query.is_empty()).then_some("t_query"))
                .chain((!self.experts.is_empty()).then_some("expert"));
            for dimension in varied {
                if key == dimension {
                    bail!("override '{entry}' in `set` fixes `{key}`, which the grid varies");
                }
            }
            if vary_keys.contains(&key) {
                bail!("override '{entry}' in `set` fixes `{key}`, which `vary` varies");
            }
        }
        // The seed does not change which values are valid: resolving one seed per configuration suffices.
        let first_seed = self.seeds[0];
        for spec in self.expand().iter().filter(|s| s.id.seed == first_seed) {
            spec.config().with_context(|| {
                format!(
                    "the sweep's run {} is misconfigured",
                    spec.dir_name().display()
                )
            })?;
        }
        Ok(())
    }

    /// Expands the grid into runs, in a fixed order: env, method, net, t_query, expert, vary, seed.
    pub fn specs(&self) -> Result<Vec<RunSpec>> {
        self.validate()?;
        Ok(self.expand())
    }

    fn expand(&self) -> Vec<RunSpec> {
        let t_queries: Vec<Option<f64>> = if self.t_query.is_empty() {
            vec![None]
        } else {
            self.t_query.iter().copied().map(Some).collect()
        };
        let experts: Vec<Option<&String>> = if self.experts.is_empty() {
            vec![None]
        } else {
            self.experts.iter().map(Some).collect()
        };
        let varies: Vec<Option<&String>> = if self.vary.is_empty() {
            vec![None]
        } else {
            self.vary.iter().map(Some).collect()
        };
        let mut specs = Vec::new();
        for env in &self.envs {
            for &method in &self.methods {
                for &net in &self.nets {
                    for &t_query in &t_queries {
                        for expert in &experts {
                            for vary in &varies {
                                for &seed in &self.seeds {
                                    specs.push(RunSpec {
                                        id: RunId {
                                            env: env.clone(),
                                            method,
                                            net,
                                            seed,
                                        },
                                        t_query,
                                        expert: expert.cloned(),
                                        set: self.set.clone(),
                                        vary: vary.cloned(),
                                    });
                                }
                            }
                        }
                    }
                }
            }
        }
        specs
    }
}

/// One run of a sweep: the paper's preset for (env, method, net), the grid's `set` overrides (`key=value`, as
/// `arld train --set`) and its `vary` override, then the varied t_query and expert, if any.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSpec {
    /// Task, method, network and seed.
    pub id: RunId,
    pub t_query: Option<f64>,
    pub expert: Option<String>,
    pub set: Vec<String>,
    /// The grid's `vary` override of this run, if any (`key=value`).
    pub vary: Option<String>,
}

impl RunSpec {
    /// The run's configuration as given.
    pub fn config_input(&self) -> Result<ConfigInput> {
        let mut input = ConfigInput::new(&self.id.env, self.id.method, self.id.net, self.id.seed);
        let varied = self.vary.iter().flat_map(|entry| vary_parts(entry));
        for o in self.set.iter().map(String::as_str).chain(varied) {
            input.apply_override(o)?;
        }
        if let Some(t) = self.t_query {
            input.set("t_query", t)?;
        }
        if let Some(e) = &self.expert {
            input.set("expert", e.as_str())?;
        }
        Ok(input)
    }

    /// The run's resolved configuration.
    pub fn config(&self) -> Result<TrainConfig> {
        self.config_input()?.resolve()
    }

    /// The varied dimensions beyond env/method/net/seed (e.g. `tq0.05`), or `None` when nothing else varies.
    pub fn variant(&self) -> Option<String> {
        let parts: Vec<String> = [
            self.t_query.map(|t| format!("{T_QUERY_VARIANT_PREFIX}{t}")),
            self.expert
                .as_ref()
                .map(|e| format!("{EXPERT_VARIANT_PREFIX}{}", dir_fragment(e))),
            self.vary.as_deref().map(dir_fragment),
        ]
        .into_iter()
        .flatten()
        .collect();
        (!parts.is_empty()).then(|| parts.join("_"))
    }

    /// The run's directory relative to the sweep directory: `ENV/METHOD-NET[/VARIANT]/seedN`, e.g.
    /// `CartPole-v0/adqn-bootstrap/tq0.05/seed3`. Reports recover the variant from this layout.
    pub fn dir_name(&self) -> PathBuf {
        run_dir::sweep_run_path(
            &self.id.env,
            self.id.method,
            self.id.net,
            self.variant().as_deref(),
            self.id.seed,
        )
    }

    /// The variant label used in results and reports (`default` when nothing beyond the basics varies).
    pub fn variant_label(&self) -> String {
        self.variant()
            .unwrap_or_else(|| DEFAULT_VARIANT.to_string())
    }
}

/// The signature of a function that performs one run into an (empty, existing) directory and must leave
/// `summary.json` there when it succeeds.
pub type RunFn<'a> = dyn Fn(&RunSpec, &Path) -> Result<()> + Sync + 'a;

/// A run that failed: its directory and the error chain.
#[derive(Debug, Clone)]
pub struct RunFailure {
    pub run_dir: PathBuf,
    pub error: String,
}

/// What a sweep did.
#[derive(Debug, Clone, Default)]
pub struct SweepOutcome {
    /// Runs in the sweep.
    pub total: usize,
    /// Runs already complete before this call (skipped).
    pub already_complete: usize,
    /// Runs that took the files of a finished run with the same resolved configuration instead of running.
    pub reused: usize,
    /// Runs performed by this call that succeeded.
    pub completed: usize,
    /// Path of the `results.csv` written at the end.
    pub results_csv: PathBuf,
    /// Runs that had a summary but were damaged (a file missing or unreadable), with what was wrong: they
    /// were run again.
    pub damaged: Vec<(PathBuf, String)>,
}

/// Records `grid` in `dir/sweep.toml`, runs it with [`run_sweep`] and returns the outcome.
///
/// A directory that already holds a sweep may be resumed or extended (more seeds, environments, ...), but not
/// with different `set` overrides: its complete runs would silently mix two configurations.
pub fn run_grid(grid: &SweepGrid, dir: &Path, jobs: usize, run_fn: &RunFn) -> Result<SweepOutcome> {
    run_grid_shard(grid, dir, jobs, None, run_fn)
}

/// [`run_grid`] for one shard of the grid's runs (all of them when `shard` is `None`). Several shards may run
/// at once on different machines sharing the directory (a Slurm job array): each writes `results.csv` only when
/// it finds every run of the whole sweep complete, so the last shard to finish writes the full file.
pub fn run_grid_shard(
    grid: &SweepGrid,
    dir: &Path,
    jobs: usize,
    shard: Option<Shard>,
    run_fn: &RunFn,
) -> Result<SweepOutcome> {
    let all_specs = grid.specs()?;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create sweep directory {}", dir.display()))?;
    // One process per directory (per shard of it: the shards of a Slurm array share the directory).
    let lock_name = shard.map_or_else(
        || LOCK_FILE.to_string(),
        |s| format!("{LOCK_FILE}-shard-{}-of-{}", s.index, s.count),
    );
    let _lock = super::dir_lock::DirLock::acquire(dir, &lock_name)?;
    // A packed dataset's runs are finished runs: unpacked first, the sweep skips them as it skips any other.
    if super::pack::is_packed(dir) {
        super::pack::unpack(dir, dir)?;
    }
    prepare_sweep_dir(grid, dir)?;
    let Some(shard) = shard else {
        return run_sweep_inner(&all_specs, dir, jobs, run_fn, true);
    };
    let specs = shard.select(&all_specs);
    let mut outcome = run_sweep_inner(&specs, dir, jobs, run_fn, false)?;
    let all_complete = all_specs
        .iter()
        .all(|spec| run_dir::is_complete(&dir.join(spec.dir_name())));
    if all_complete {
        outcome.results_csv = collect_results(dir)?.path;
    }
    Ok(outcome)
}

/// The lock file of a sweep directory (see [`super::dir_lock`]); a shard's is `.lock-shard-I-of-N`.
pub const LOCK_FILE: &str = ".lock";

/// Creates the sweep directory and records the grid in its `sweep.toml`, refusing a directory that holds a
/// sweep with other `set` overrides.
pub fn prepare_sweep_dir(grid: &SweepGrid, dir: &Path) -> Result<()> {
    let recorded = dir.join(SWEEP_FILE);
    if recorded.is_file() {
        let previous = SweepGrid::from_toml_file(&recorded)?;
        if previous.set != grid.set {
            bail!(
                "{} was run with overrides {:?}, not {:?}; use another directory for a sweep with different settings",
                dir.display(),
                previous.set,
                grid.set
            );
        }
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create sweep directory {}", dir.display()))?;
    write_atomic(&dir.join(SWEEP_FILE), grid.to_toml_string()?.as_bytes())?;
    Ok(())
}

/// One part of a sweep's runs: `index` of `count` (`arld sweep --shard 2/8`). Runs are dealt round-robin in the
/// grid's order, so every shard gets a similar mix of environments and methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// The runs of this shard.
    pub fn select(&self, specs: &[RunSpec]) -> Vec<RunSpec> {
        specs
            .iter()
            .enumerate()
            .filter(|(i, _)| i % self.count == self.index)
            .map(|(_, spec)| spec.clone())
            .collect()
    }
}

impl std::str::FromStr for Shard {
    type Err = anyhow::Error;

    /// `I/N` with `0 <= I < N`.
    fn from_str(text: &str) -> Result<Self> {
        let (index, count) = text
            .split_once('/')
            .with_context(|| format!("shard '{text}' is not of the form I/N (e.g. 0/4)"))?;
        let parse = |s: &str, what: &str| -> Result<usize> {
            s.trim().parse::<usize>().with_context(|| {
                format!("shard '{text}': {what} '{s}' is not a non-negative integer")
            })
        };
        let (index, count) = (parse(index, "index")?, parse(count, "count")?);
        if count == 0 || index >= count {
            bail!("shard '{text}' must satisfy 0 <= I < N (shards are numbered from 0)");
        }
        Ok(Shard { index, count })
    }
}

/// Runs every spec into `dir/<spec.dir_name()>` on `jobs` threads (each run single-threaded; `jobs` = 0 means
/// one per available core), seed by seed (all configurations of the first seed, then the next, in the order
/// seeds first appear in `specs`). Runs whose `summary.json` exists are skipped (unless stale, see the module
/// docs); a directory without it is cleared
/// and run again. A failing (or panicking) run does not stop the others: failures are collected and returned
/// together as an error after all runs. `results.csv` is rewritten at the end either way.
/// An overall progress bar (runs done / total, ETA) is drawn only when stderr is a terminal.
pub fn run_sweep(
    specs: &[RunSpec],
    dir: &Path,
    jobs: usize,
    run_fn: &RunFn,
) -> Result<SweepOutcome> {
    run_sweep_inner(specs, dir, jobs, run_fn, true)
}

/// [`run_sweep`], with `results.csv` collected at the end when `collect` (a shard leaves that to the whole
/// sweep): the runs still to do, the ones an identical finished run gives, then the rest on `jobs` threads.
fn run_sweep_inner(
    specs: &[RunSpec],
    dir: &Path,
    jobs: usize,
    run_fn: &RunFn,
    collect: bool,
) -> Result<SweepOutcome> {
    let names: BTreeSet<PathBuf> = specs.iter().map(RunSpec::dir_name).collect();
    if names.len() != specs.len() {
        bail!("the sweep lists the same run twice (two specs share a directory name)");
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create sweep directory {}", dir.display()))?;
    let (mut pending, damaged) = pending_runs(specs, dir);
    let already_complete = specs.len() - pending.len();
    let reused = reuse_identical_runs(&mut pending, dir);
    let bar = sweep_bar(specs.len(), already_complete);
    let (completed, failures) = run_pending(&pending, dir, jobs, run_fn, &bar);
    bar.finish_and_clear();
    let collected = if collect {
        collect_results(dir).map(|c| c.path)
    } else {
        Ok(dir.join(RESULTS_FILE))
    };
    refuse_failures(failures, specs.len(), &collected)?;
    Ok(SweepOutcome {
        total: specs.len(),
        already_complete,
        reused,
        completed,
        results_csv: collected?,
        damaged,
    })
}

/// The runs of `specs` still to do in `dir`, seed by seed (every configuration gets its first seeds early, so
/// a partial sweep already reports on all), and the finished runs among them whose files are damaged (run
/// again, and said so: never silently left out). A finished run of an older arld (stale) is run again too.
fn pending_runs<'s>(
    specs: &'s [RunSpec],
    dir: &Path,
) -> (Vec<&'s RunSpec>, Vec<(PathBuf, String)>) {
    let mut damaged = Vec::new();
    let mut stale = Vec::new();
    let mut pending: Vec<&RunSpec> = specs
        .iter()
        .filter(|spec| {
            let path = dir.join(spec.dir_name());
            if !run_dir::is_complete(&path) {
                return true;
            }
            match run_dir::check_complete(&path) {
                Ok(()) if run_dir::is_stale(&path) => {
                    stale.push(path);
                    true
                }
                Ok(()) => false,
                Err(err) => {
                    eprintln!(
                        "run {} is damaged ({err:#}); running it again",
                        path.display()
                    );
                    damaged.push((path, format!("{err:#}")));
                    true
                }
            }
        })
        .collect();
    if let Some(first) = stale.first() {
        eprintln!(
            "{} complete runs (such as {}) were computed by an older arld with the C library's elementary \
             functions, whose results depend on the CPU; running them again",
            stale.len(),
            first.display(),
        );
    }
    let mut seed_order: Vec<u64> = Vec::new();
    for spec in specs {
        if !seed_order.contains(&spec.id.seed) {
            seed_order.push(spec.id.seed);
        }
    }
    pending.sort_by_key(|spec| seed_order.iter().position(|&s| s == spec.id.seed));
    (pending, damaged)
}

/// Takes out of `pending` each run whose resolved configuration equals a finished run's (a variant whose
/// override is the default, such as `tq0.3` where 0.3 is the task's t_query): it takes that run's files, since
/// runs are deterministic and running it again would only write the same bytes. Returns how many did.
fn reuse_identical_runs(pending: &mut Vec<&RunSpec>, dir: &Path) -> usize {
    let mut reused = 0;
    pending.retain(|spec| {
        let path = dir.join(spec.dir_name());
        if path
            .join(arld_core::train::snapshot::SNAPSHOT_FILE)
            .is_file()
        {
            return true;
        }
        let Some(source) = identical_run(spec, dir) else {
            return true;
        };
        match spec
            .config()
            .and_then(|config| run_dir::copy_finished_run(&source, &path, &config))
        {
            Ok(()) => {
                eprintln!(
                    "run {}: the same configuration as {}, whose files it takes",
                    path.display(),
                    source.display()
                );
                reused += 1;
                false
            }
            Err(err) => {
                eprintln!(
                    "run {}: could not take the files of {} ({err:#}); running it",
                    path.display(),
                    source.display()
                );
                true
            }
        }
    });
    reused
}

/// The sweep's overall progress bar (runs done of `total`, ETA), drawn only when stderr is a terminal.
fn sweep_bar(total: usize, done: usize) -> ProgressBar {
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(Some(total as u64), ProgressDrawTarget::stderr_with_hz(2))
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "sweep [{elapsed_precise}] {wide_bar} {pos}/{len} runs, ETA {eta} {msg}",
        )
        .expect("the progress template is valid"),
    );
    bar.set_position(done as u64);
    bar.reset_eta();
    bar
}

/// Runs the `pending` runs on `jobs` threads (0: one per available core), each taking the next run until none
/// is left or a stop is asked (the runs in progress then snapshot themselves; no new run starts). A failing
/// run does not stop the others. Returns how many finished and the failures, sorted by run directory.
fn run_pending(
    pending: &[&RunSpec],
    dir: &Path,
    jobs: usize,
    run_fn: &RunFn,
    bar: &ProgressBar,
) -> (usize, Vec<RunFailure>) {
    let jobs = if jobs == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        jobs
    };
    let jobs = jobs.min(pending.len()).max(1);
    let next = AtomicUsize::new(0);
    let failures = Mutex::new(Vec::<RunFailure>::new());
    let completed = AtomicUsize::new(0);
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            scope.spawn(|| {
                while !arld_core::interrupt::requested() {
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    let Some(spec) = pending.get(index) else {
                        break;
                    };
                    let run_dir = dir.join(spec.dir_name());
                    match run_one_spec(spec, &run_dir, &status_path(dir, spec), run_fn) {
                        Ok(()) => {
                            completed.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(err) => {
                            let failure = RunFailure {
                                run_dir: run_dir.clone(),
                                error: format!("{err:#}"),
                            };
                            bar.suspend(|| {
                                eprintln!("run {} failed: {}", run_dir.display(), failure.error)
                            });
                            let mut failures = failures.lock().unwrap_or_else(|e| e.into_inner());
                            failures.push(failure);
                            bar.set_message(format!("({} failed)", failures.len()));
                        }
                    }
                    bar.inc(1);
                }
            });
        }
    });
    let mut failures = failures.into_inner().unwrap_or_else(|e| e.into_inner());
    failures.sort_by(|a, b| a.run_dir.cmp(&b.run_dir));
    (completed.into_inner(), failures)
}

/// The error naming every failed run of the sweep's `total` (rerunning the sweep retries only those), with
/// where the complete runs' results are (`collected`); none when no run failed.
fn refuse_failures(
    failures: Vec<RunFailure>,
    total: usize,
    collected: &Result<PathBuf>,
) -> Result<()> {
    if failures.is_empty() {
        return Ok(());
    }
    let list: Vec<String> = failures
        .iter()
        .map(|f| format!("  {}: {}", f.run_dir.display(), f.error))
        .collect();
    let note = match collected {
        Ok(path) => format!("results of the complete runs are in {}", path.display()),
        Err(err) => format!("results.csv could not be written either: {err:#}"),
    };
    bail!(
        "{} of {} runs failed (rerun the same sweep to retry only those; {note}):\n{}",
        failures.len(),
        total,
        list.join("\n")
    )
}

/// A finished run in the sweep directory, other than `spec`'s own, with the same environment, method, network
/// and seed (any variant) and the same resolved configuration as `spec`.
fn identical_run(spec: &RunSpec, dir: &Path) -> Option<PathBuf> {
    let config = spec.config().ok()?;
    let own = dir.join(spec.dir_name());
    let base = dir
        .join(&spec.id.env)
        .join(format!("{}-{}", spec.id.method, spec.id.net));
    let seed = format!("seed{}", spec.id.seed);
    let mut candidates = vec![base.join(&seed)];
    let mut variants: Vec<PathBuf> = std::fs::read_dir(&base)
        .ok()?
        .flatten()
        .map(|entry| entry.path().join(&seed))
        .collect();
    variants.sort();
    candidates.extend(variants);
    candidates.into_iter().find(|candidate| {
        *candidate != own
            && run_dir::check_complete(candidate).is_ok()
            && !run_dir::is_stale(candidate)
            && run_dir::read_config(candidate, &spec.id).is_ok_and(|other| other == config)
    })
}

/// Clears an incomplete run directory, performs the run, and checks that it left `summary.json`.
/// A panic inside `run_fn` is turned into an error so that one broken run cannot take down the sweep.
fn run_one_spec(spec: &RunSpec, path: &Path, status: &Path, run_fn: &RunFn) -> Result<()> {
    // An interrupted run with a snapshot continues from it; any other incomplete run starts again, and so does
    // one whose snapshot an older arld computed with other elementary functions.
    let has_snapshot = path
        .join(arld_core::train::snapshot::SNAPSHOT_FILE)
        .is_file();
    let stale = has_snapshot && arld_core::train::snapshot::is_stale(path);
    if stale {
        eprintln!(
            "run {}: its snapshot was computed by an older arld with the C library's elementary functions; \
             starting the run again",
            path.display()
        );
    }
    // The failed.json of an earlier attempt stays until an attempt finishes the run.
    let failed = path.join(run_dir::FAILED_FILE);
    let earlier_failure = arld_core::files::read_bounded(&failed, MAX_GRID_BYTES).ok();
    if path.exists() && (!has_snapshot || stale) {
        std::fs::remove_dir_all(path)
            .with_context(|| format!("cannot clear incomplete run directory {}", path.display()))?;
    }
    std::fs::create_dir_all(path).with_context(|| format!("cannot create {}", path.display()))?;
    if let Some(bytes) = earlier_failure
        && !failed.exists()
    {
        write_atomic(&failed, &bytes)?;
    }
    RunStatus::running().write(status)?;
    let result = (|| {
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run_fn(spec, path)));
        match outcome {
            Ok(result) => result?,
            Err(panic) => {
                let message = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "unknown panic".to_string());
                bail!("the run panicked: {message}");
            }
        }
        if !run_dir::is_complete(path) {
            bail!("the run returned without writing {}", run_dir::SUMMARY_FILE);
        }
        run_dir::check_complete(path).context("the run's files are not whole")?;
        Ok(())
    })();
    let interrupted = result.as_ref().is_err_and(|e| {
        e.chain()
            .any(|c| c.is::<arld_core::interrupt::Interrupted>())
    });
    let outcome = match &result {
        Ok(()) => RunStatus::finished("done", None),
        Err(_) if interrupted => RunStatus::finished("interrupted", None),
        Err(err) => RunStatus::finished("failed", Some(format!("{err:#}"))),
    };
    // The status file is informative only (`arld sweep --status`): failing to write it must not hide the
    // run's own outcome.
    let _ = outcome.write(status);
    result
}

/// The folder of a sweep directory that says, for each run, which machine and process runs it (or ran it, and
/// how it ended): `.status/<run directory>.json`. It stays outside the run directories, which hold only what
/// the run itself writes.
pub const STATUS_DIR: &str = ".status";

/// Where the status of `spec`'s run in the sweep directory `dir` is kept.
pub fn status_path(dir: &Path, spec: &RunSpec) -> PathBuf {
    let mut path = dir.join(STATUS_DIR).join(spec.dir_name());
    let name = format!(
        "{}.json",
        path.file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned())
    );
    path.set_file_name(name);
    path
}

/// Contents of [`STATUS_FILE`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunStatus {
    /// `running`, `done` or `failed`.
    pub state: String,
    pub host: String,
    pub pid: u32,
    /// Seconds since the Unix epoch of the last change.
    pub since_unix: u64,
    /// The Slurm job that runs it (`JOBID_TASK`), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slurm_job: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl RunStatus {
    fn running() -> Self {
        Self::finished("running", None)
    }

    fn finished(state: &str, error: Option<String>) -> Self {
        let slurm_job = match (
            std::env::var("SLURM_ARRAY_JOB_ID"),
            std::env::var("SLURM_ARRAY_TASK_ID"),
            std::env::var("SLURM_JOB_ID"),
        ) {
            (Ok(array), Ok(task), _) => Some(format!("{array}_{task}")),
            (_, _, Ok(job)) => Some(job),
            _ => None,
        };
        RunStatus {
            state: state.to_string(),
            host: host_name(),
            pid: std::process::id(),
            since_unix: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
            slurm_job,
            error,
        }
    }

    fn write(&self, path: &Path) -> Result<()> {
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        write_atomic(path, serde_json::to_string_pretty(self)?.as_bytes())?;
        Ok(())
    }

    /// Reads a status file, if there is a readable one.
    pub fn read(path: &Path) -> Option<Self> {
        let text = arld_core::files::read_text_bounded(path, MAX_GRID_BYTES).ok()?;
        serde_json::from_str(&text).ok()
    }
}

pub use super::dir_lock::host_name;

/// Where one run of a sweep stands.
#[derive(Debug, Clone, PartialEq)]
pub enum RunState {
    /// `summary.json` exists.
    Done,
    /// A process says it runs it (on `host`, in Slurm job `slurm_job` if any).
    Running {
        host: String,
        slurm_job: Option<String>,
    },
    /// The run failed with this error (its first line; `failed.json` in the run directory has it all), at this
    /// environment step when it failed while training (it is retried when the sweep runs again).
    Failed {
        host: String,
        error: String,
        step: Option<usize>,
    },
    /// Started but its process is gone (killed or its node lost); the sweep continues it when run again.
    Interrupted { host: String },
    /// Not started.
    Pending,
}

/// The state of every run of the sweep in `dir` (from its `sweep.toml`), in the grid's order.
pub fn sweep_status(dir: &Path) -> Result<Vec<(RunSpec, RunState)>> {
    let file = dir.join(SWEEP_FILE);
    if !file.is_file() {
        bail!(
            "{} is not a sweep directory: it has no {SWEEP_FILE}",
            dir.display()
        );
    }
    let grid = SweepGrid::from_toml_file(&file)?;
    let this_host = host_name();
    Ok(grid
        .specs()?
        .into_iter()
        .map(|spec| {
            let path = dir.join(spec.dir_name());
            let status = RunStatus::read(&status_path(dir, &spec));
            let running_here = status.as_ref().is_some_and(|status| {
                status.state == "running"
                    && (status.host != this_host
                        || Path::new(&format!("/proc/{}", status.pid)).exists())
            });
            // The run's own failed.json says why it failed (also when the sweep's status file is gone or was
            // written elsewhere); a new attempt in progress wins over it.
            let failure = run_dir::read_failure(&path).ok().flatten();
            let state = if run_dir::is_complete(&path) {
                RunState::Done
            } else if let (Some(failure), false) = (&failure, running_here) {
                RunState::Failed {
                    host: status.map_or_else(|| "unknown".to_string(), |s| s.host),
                    error: failure.message(),
                    step: (failure.phase == "training").then_some(failure.step),
                }
            } else {
                match status {
                    None => {
                        if path.exists() {
                            RunState::Interrupted {
                                host: "unknown".to_string(),
                            }
                        } else {
                            RunState::Pending
                        }
                    }
                    Some(status) if status.state == "failed" => RunState::Failed {
                        host: status.host,
                        error: status
                            .error
                            .unwrap_or_default()
                            .lines()
                            .next()
                            .unwrap_or("")
                            .to_string(),
                        step: None,
                    },
                    Some(status) => {
                        // On this machine a dead process can be told apart from a live one; elsewhere the
                        // status file is taken at its word.
                        let gone = status.host == this_host
                            && !Path::new(&format!("/proc/{}", status.pid)).exists();
                        if gone || status.state != "running" {
                            RunState::Interrupted { host: status.host }
                        } else {
                            RunState::Running {
                                host: status.host,
                                slurm_job: status.slurm_job,
                            }
                        }
                    }
                }
            };
            (spec, state)
        })
        .collect())
}

/// What [`collect_results`] wrote.
#[derive(Debug, Clone)]
pub struct CollectedResults {
    /// Path of `results.csv`.
    pub path: PathBuf,
    /// Complete runs read.
    pub runs: usize,
    /// Data rows written.
    pub rows: usize,
    /// Runs that could not be read or were duplicates, one line each (they are left out of the file).
    pub problems: Vec<String>,
}

/// Reads every complete run under `dir` and writes `dir/results.csv` atomically: one row per evaluation
/// point, columns `env,method,net,variant,seed,step,mean,std,min,max`, sorted by those keys in that order,
/// with no duplicate (env, method, net, variant, seed, step).
pub fn collect_results(dir: &Path) -> Result<CollectedResults> {
    let (runs, mut problems) = run_dir::load_runs(dir)?;
    let path = dir.join(RESULTS_FILE);
    let (bytes, rows, duplicates) = results_csv_bytes(&runs)?;
    problems.extend(duplicates);
    write_atomic(&path, &bytes)?;
    Ok(CollectedResults {
        path,
        runs: runs.len(),
        rows,
        problems,
    })
}

/// The content of `results.csv` for these runs, the number of data rows, and notes on dropped duplicates.
pub fn results_csv_bytes(runs: &[RunRecord]) -> Result<(Vec<u8>, usize, Vec<String>)> {
    // (run, step): the run's key, then the evaluation's step.
    type Key<'a> = ((&'a str, &'a str, &'a str, &'a str, u64), u64);
    let mut rows: Vec<(Key, &run_dir::EvalPoint, &Path)> = Vec::new();
    for run in runs {
        for point in &run.eval {
            rows.push(((run.key(), point.step), point, run.dir.as_path()));
        }
    }
    // Stable sort: among equal keys the first run directory in path order wins.
    rows.sort_by(|a, b| a.0.cmp(&b.0).then_with(|| a.2.cmp(b.2)));
    let mut notes = Vec::new();
    let mut writer = csv::Writer::from_writer(Vec::new());
    writer.write_record([
        "env", "method", "net", "variant", "seed", "step", "mean", "std", "min", "max",
    ])?;
    let mut written = 0;
    let mut previous: Option<Key> = None;
    for (key, point, run_dir) in rows {
        if previous == Some(key) {
            notes.push(format!(
                "duplicate evaluation at step {} in {} left out",
                key.1,
                run_dir.display()
            ));
            continue;
        }
        previous = Some(key);
        let ((env, method, net, variant, seed), step) = key;
        writer.write_record([
            env.to_string(),
            method.to_string(),
            net.to_string(),
            variant.to_string(),
            seed.to_string(),
            step.to_string(),
            point.mean.to_string(),
            point.std.to_string(),
            point.min.to_string(),
            point.max.to_string(),
        ])?;
        written += 1;
    }
    let bytes = writer
        .into_inner()
        .map_err(|e| anyhow::anyhow!("cannot finish results.csv: {e}"))?;
    Ok((bytes, written, notes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> SweepGrid {
        SweepGrid {
            envs: vec!["CartPole-v0".into()],
            methods: vec![Method::Adqn, Method::Bdqn],
            nets: vec![NetKind::Bootstrap],
            seeds: vec![0, 1],
            t_query: vec![0.05, 0.3],
            experts: vec!["noisy:0.4:shipped:perfect".into()],
            set: vec!["eval_episodes=5".into()],
            vary: vec![],
        }
    }

    #[test]
    fn vary_makes_one_variant_per_override_and_refuses_clashes() {
        let varied = SweepGrid {
            t_query: vec![],
            experts: vec![],
            methods: vec![Method::Adqn],
            vary: vec!["n_r=100".into(), "n_r=10000".into()],
            ..grid()
        };
        let specs = varied.specs().unwrap();
        assert_eq!(specs.len(), 2 * 2);
        assert_eq!(
            specs[2].dir_name(),
            PathBuf::from("CartPole-v0/adqn-bootstrap/n_r-10000/seed0")
        );
        assert_eq!(specs[2].variant_label(), "n_r-10000");
        assert_eq!(specs[2].config().unwrap().n_r, 10_000);
        // The variant survives the sweep file (Slurm tasks read it back).
        let text = varied.to_toml_string().unwrap();
        assert_eq!(SweepGrid::from_toml_str(&text).unwrap(), varied);
        for (vary, set, expected) in [
            ("t_query=0.2", "", "has its own sweep key"),
            ("n_r=100", "n_r=50", "which `vary` varies"),
            ("n_r", "", "not of the form key=value"),
            ("budget=5", "", "cannot be set"),
        ] {
            let grid = SweepGrid {
                methods: vec![Method::Dqn],
                t_query: vec![],
                experts: vec![],
                vary: vec![vary.into()],
                set: [set]
                    .into_iter()
                    .filter(|s| !s.is_empty())
                    .map(String::from)
                    .collect(),
                ..grid()
            };
            let err = format!("{:#}", grid.validate().unwrap_err());
            assert!(err.contains(expected), "{vary} / {set}: {err}");
        }
    }

    #[test]
    fn specs_have_unique_readable_directories_and_carry_overrides() {
        let specs = grid().specs().unwrap();
        assert_eq!(specs.len(), 2 * 2 * 2);
        let names: BTreeSet<PathBuf> = specs.iter().map(RunSpec::dir_name).collect();
        assert_eq!(names.len(), specs.len());
        assert_eq!(
            specs[0].dir_name(),
            PathBuf::from(
                "CartPole-v0/adqn-bootstrap/tq0.05_expert-noisy-0.4-shipped-perfect/seed0"
            )
        );
        let cfg = specs[0].config().unwrap();
        assert_eq!(
            (cfg.eval_episodes, cfg.t_query, cfg.expert.as_str()),
            (5, 0.05, "noisy:0.4:shipped:perfect")
        );
        let plain = SweepGrid {
            t_query: vec![],
            experts: vec![],
            ..grid()
        }
        .specs()
        .unwrap();
        assert_eq!(
            plain[3].dir_name(),
            PathBuf::from("CartPole-v0/bdqn-bootstrap/seed1")
        );
        assert_eq!(plain[3].variant_label(), DEFAULT_VARIANT);
    }

    #[test]
    fn sweep_file_round_trips_and_accepts_a_seed_count() {
        let text = grid().to_toml_string().unwrap();
        assert_eq!(SweepGrid::from_toml_str(&text).unwrap(), grid());
        let counted = SweepGrid::from_toml_str(
            "[sweep]\nenvs = [\"Acrobot-v1\"]\nmethods = [\"dqn\"]\nnets = [\"noisy\"]\nseeds = 3\n",
        )
        .unwrap();
        assert_eq!(counted.seeds, vec![0, 1, 2]);
    }

    #[test]
    fn cli_values_accept_repeated_and_comma_separated_lists() {
        let strings = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let built = SweepGrid::from_cli_values(
            &strings(&["CartPole-v0"]),
            &strings(&["adqn,bdqn"]),
            &strings(&["bootstrap"]),
            "0..2",
            &strings(&["0.05", "0.3"]),
            &strings(&["noisy:0.4:shipped:perfect"]),
            &strings(&["eval_episodes=5"]),
            &[],
        )
        .unwrap();
        assert_eq!(built, grid());
        let bad = SweepGrid::from_cli_values(&[], &[], &[], "2", &[], &[], &[], &[]).unwrap_err();
        assert!(format!("{bad}").contains("envs"), "{bad}");
    }

    #[test]
    fn seeds_parse_from_count_range_and_list() {
        assert_eq!(parse_seeds("3").unwrap(), vec![0, 1, 2]);
        assert_eq!(parse_seeds("5..8").unwrap(), vec![5, 6, 7]);
        assert_eq!(parse_seeds("4, 9").unwrap(), vec![4, 9]);
        assert!(parse_seeds("x").is_err());
        assert!(parse_seeds("8..5").is_err());
    }
}
