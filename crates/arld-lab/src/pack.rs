//! Runs packed into a dataset: a directory of run directories (`TASK/METHOD-NET[/VARIANT]/seedN/`) kept as a few
//! gzip-compressed CSV tables per task, which pandas, polars and DuckDB read in one line, and from which every run
//! directory comes back byte for byte.
//!
//! A packed task directory `ROOT/TASK/` holds:
//! - `runs.csv.gz`: one row per run (`run`, the run's path below the task directory; `files`, the files it holds;
//!   `config_absent`, `summary_absent`, the keys of the task's configuration and summary columns its files lack);
//! - `configs.csv.gz` and `summaries.csv.gz`: one row per run, one column per key of `config.toml` and
//!   `summary.json` (strings unquoted, other values as the file wrote them, `[64, 64]` for an array);
//! - `eval.csv.gz`, `queries.csv.gz`, `episodes.csv.gz`: the rows of each run's log, after a `run` column;
//! - `verbatim.csv.gz`: any file the tables cannot give back exactly (`run`, `file`, `text`);
//! - `layout.json`: which configuration and summary columns are strings throughout (their cells unquoted).
//!
//! Packing checks before it writes anything that every run comes back from the tables byte for byte (a file that
//! would not goes to `verbatim.csv.gz` whole), and its output depends only on the runs, so packing the same runs
//! again changes no byte. Unpacking writes only the files that are missing and refuses to replace a file whose
//! bytes differ. Runs are read and written through [`arld_core::train::run_dir`]'s names for the files; binary files
//! (weights, snapshots, event files) are not part of a dataset and are left where they are.

use anyhow::{Context, Result, bail, ensure};
use arld_core::files::write_atomic;
use arld_core::train::run_dir::{self, CONFIG_FILE, SUMMARY_FILE};
use flate2::Compression;
use flate2::read::GzDecoder;
use flate2::write::GzEncoder;
use std::collections::{BTreeMap, BTreeSet};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// The index of a packed task directory; its presence marks the directory as packed.
pub const RUNS_TABLE: &str = "runs.csv.gz";
const LAYOUT_FILE: &str = "layout.json";
/// The logs kept as row tables: the run's file and the table that holds its rows.
const LOG_TABLES: [(&str, &str); 3] = [
    (run_dir::EVAL_FILE, "eval.csv.gz"),
    (run_dir::QUERIES_FILE, "queries.csv.gz"),
    (run_dir::EPISODES_FILE, "episodes.csv.gz"),
];
const CONFIGS_TABLE: &str = "configs.csv.gz";
const SUMMARIES_TABLE: &str = "summaries.csv.gz";
const VERBATIM_TABLE: &str = "verbatim.csv.gz";
/// The format of `layout.json`.
const FORMAT: u32 = 1;
/// The largest table file a reader reads (far above the committed dataset's largest, about 11 MB).
pub(crate) const MAX_TABLE_BYTES: u64 = 1 << 30;
/// The most bytes a table decompresses to (the committed dataset's largest: about 100 MB)...
const MAX_TABLE_TEXT_BYTES: u64 = 1 << 30;
/// ... and at most this many times its compressed bytes (with [`SMALL_TABLE_TEXT_BYTES`] more): the committed
/// tables shrink about ten times, where a crafted stream (a "gzip bomb") shrinks a thousand times.
const MAX_TABLE_RATIO: u64 = 64;
const SMALL_TABLE_TEXT_BYTES: u64 = 1 << 20;
/// The largest file of a run directory a dataset keeps (a run's logs are a few megabytes); a longer one is left
/// out, as binary files are, or, if it is one of the run's tables, refused.
const MAX_RUN_FILE_BYTES: u64 = 256 << 20;

/// The files of one run, by name.
type RunFiles = BTreeMap<String, Vec<u8>>;
/// A key file as its keys and the text of each value, in the file's order.
type KeyValues = Vec<(String, String)>;
/// Runs by their path below a task directory (`adqn-bootstrap/budget-125/seed0`).
type TaskRuns = BTreeMap<String, RunFiles>;

/// Whether `root` holds a packed dataset (a task directory with a run index).
pub fn is_packed(root: &Path) -> bool {
    task_dirs(root).is_ok_and(|dirs| !dirs.is_empty())
}

/// The packed task directories below `root`, by task name.
fn task_dirs(root: &Path) -> Result<Vec<(String, PathBuf)>> {
    let mut tasks = Vec::new();
    let entries =
        std::fs::read_dir(root).with_context(|| format!("cannot list {}", root.display()))?;
    for entry in entries {
        let entry = entry?;
        if entry.path().join(RUNS_TABLE).is_file() {
            tasks.push((
                entry.file_name().to_string_lossy().into_owned(),
                entry.path(),
            ));
        }
    }
    tasks.sort();
    Ok(tasks)
}

/// What [`pack`] did.
#[derive(Debug, Default)]
pub struct PackSummary {
    /// Runs in the dataset after packing.
    pub runs: usize,
    /// Runs that were not in it before.
    pub added: usize,
    /// Tables whose bytes changed.
    pub tables_written: usize,
    /// Files kept whole in `verbatim.csv.gz`.
    pub verbatim: usize,
    /// Files of run directories that a dataset does not keep (binary files), as paths.
    pub left_out: Vec<PathBuf>,
}

/// Packs every complete run below `root` (unpacked directories and the runs already packed there) into the tables
/// of its task directory. A run both packed and unpacked must have the same bytes in both places.
pub fn pack(root: &Path) -> Result<PackSummary> {
    let mut summary = PackSummary::default();
    let mut tasks: BTreeMap<String, TaskRuns> = BTreeMap::new();
    for (task, dir) in task_dirs(root)? {
        tasks.insert(task, read_task(&dir)?);
    }
    let before: usize = tasks.values().map(BTreeMap::len).sum();
    for dir in run_dir::find_runs(root, |_| {})? {
        let relative = dir.strip_prefix(root).unwrap_or(&dir);
        let mut parts = relative.iter().map(|p| p.to_string_lossy().into_owned());
        let (Some(task), rest) = (parts.next(), parts.collect::<Vec<_>>()) else {
            bail!("{} is a run, not a directory of runs", root.display());
        };
        ensure!(
            !rest.is_empty(),
            "cannot pack the run {}: a dataset holds runs at TASK/..., not a run directly below {}",
            dir.display(),
            root.display()
        );
        let run = rest.join("/");
        let files = read_run_files(&dir, &mut summary.left_out)?;
        let runs = tasks.entry(task).or_default();
        match runs.get(&run) {
            Some(packed) if *packed != files => {
                let differing = files
                    .keys()
                    .chain(packed.keys())
                    .find(|name| files.get(*name) != packed.get(*name))
                    .cloned()
                    .unwrap_or_default();
                bail!(
                    "{} differs from the packed run of the same path ({differing}); move one of them away first",
                    dir.display()
                );
            }
            Some(_) => {}
            None => {
                runs.insert(run, files);
            }
        }
    }
    summary.runs = tasks.values().map(BTreeMap::len).sum();
    summary.added = summary.runs - before;
    for (task, runs) in &tasks {
        let tables = encode_task(runs)?;
        // Read back from the bytes about to be written: every run must come back whole.
        let back = decode_task(&tables)
            .with_context(|| format!("the tables of {task} do not read back"))?;
        ensure!(
            back == *runs,
            "the tables of {task} do not give back every run byte for byte (a bug in the packer; nothing written)"
        );
        summary.verbatim += count_rows(&tables[VERBATIM_TABLE])?;
        let dir = root.join(task);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        for (name, bytes) in &tables {
            let path = dir.join(name);
            let there = arld_core::files::read_bounded(&path, MAX_TABLE_BYTES).ok();
            if there.as_deref() != Some(bytes.as_slice()) {
                write_atomic(&path, bytes)?;
                summary.tables_written += 1;
            }
        }
    }
    Ok(summary)
}

/// What [`unpack`] did.
#[derive(Debug, Default)]
pub struct UnpackSummary {
    pub runs: usize,
    /// Files written (they were missing).
    pub written: usize,
    /// Files that were there with the same bytes.
    pub present: usize,
}

/// Writes every packed run of `root` below `out` (`out/TASK/RUN/FILE`), only the files that are missing; a file
/// that is there with other bytes is an error naming it, and nothing is replaced.
pub fn unpack(root: &Path, out: &Path) -> Result<UnpackSummary> {
    let tasks = task_dirs(root)?;
    ensure!(
        !tasks.is_empty(),
        "{} holds no packed runs (no TASK/{RUNS_TABLE})",
        root.display()
    );
    let mut summary = UnpackSummary::default();
    let mut missing = Vec::new();
    for (task, dir) in tasks {
        ensure!(
            plain_name(&task),
            "{} names a task {task:?}, which is not a plain directory name",
            root.display()
        );
        for (run, files) in read_task(&dir)? {
            summary.runs += 1;
            let run_dir = format!("{task}/{run}");
            // Every directory on the way is a real one inside OUT (or not there yet): never a link out of it.
            if !inside(out, &run_dir, false)? {
                for name in files.keys() {
                    missing.push((run_dir.clone(), name.clone(), files[name].clone()));
                }
                continue;
            }
            for (name, bytes) in files {
                let path = out.join(&run_dir).join(&name);
                match std::fs::symlink_metadata(&path) {
                    Ok(meta) if !meta.is_file() => bail!(
                        "{} is in the way: it is {}, not a regular file",
                        path.display(),
                        arld_core::files::kind_name(meta.file_type())
                    ),
                    Ok(_) => {
                        let there = arld_core::files::read_bounded(&path, MAX_RUN_FILE_BYTES)
                            .with_context(|| format!("cannot read {}", path.display()))?;
                        ensure!(
                            there == bytes,
                            "{} differs from the packed run: not replaced (move it away to unpack)",
                            path.display()
                        );
                        summary.present += 1;
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                        missing.push((run_dir.clone(), name, bytes))
                    }
                    Err(e) => {
                        return Err(e)
                            .with_context(|| format!("cannot inspect {}", path.display()));
                    }
                }
            }
        }
    }
    // Whole files, summary.json last in each run (a run is complete when its summary exists).
    missing.sort_by(|(a, name_a, _), (b, name_b, _)| {
        (a, name_a == SUMMARY_FILE).cmp(&(b, name_b == SUMMARY_FILE))
    });
    if !missing.is_empty() {
        std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    }
    for (run_dir, name, bytes) in missing {
        inside(out, &run_dir, true)?;
        let path = out.join(&run_dir).join(&name);
        write_unsynced(&path, &bytes)?;
        summary.written += 1;
    }
    Ok(summary)
}

/// Whether every directory of `relative` (`/`-separated, checked by [`check_run_path`]) below `out` is a real
/// directory, not a link (`false`: one is not there yet; with `create`, the missing ones are made). Anything else
/// on the way (a symbolic link, planted to lead the files out of `out`, or a file) is an error naming it.
fn inside(out: &Path, relative: &str, create: bool) -> Result<bool> {
    let mut dir = out.to_path_buf();
    for part in relative.split('/') {
        dir.push(part);
        match std::fs::symlink_metadata(&dir) {
            Ok(meta) if meta.is_dir() => {}
            Ok(meta) => bail!(
                "{} is {}, where unpacking makes a directory: nothing is written through it (move it away)",
                dir.display(),
                arld_core::files::kind_name(meta.file_type())
            ),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound && create => {
                std::fs::create_dir(&dir)
                    .with_context(|| format!("cannot create {}", dir.display()))?;
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
            Err(e) => return Err(e).with_context(|| format!("cannot inspect {}", dir.display())),
        }
    }
    Ok(true)
}

/// Writes a whole file through a temporary one renamed over it, without syncing each to the disk (an unpack writes
/// thousands of files, and the tables it comes from stay): a reader never sees a part of a file.
fn write_unsynced(path: &Path, bytes: &[u8]) -> Result<()> {
    let name = path
        .file_name()
        .with_context(|| format!("{} names no file", path.display()))?;
    let tmp = path.with_file_name(format!(
        ".{}.{}.unpack.tmp",
        name.to_string_lossy(),
        std::process::id()
    ));
    // A new file only (never through a link or into a file planted under the temporary name).
    let _ = std::fs::remove_file(&tmp);
    let written = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .and_then(|mut file| file.write_all(bytes));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(e).with_context(|| format!("cannot write {}", tmp.display()));
    }
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// Reads every packed run of `root`, as `TASK/RUN` paths and their files.
pub fn read_packed(root: &Path) -> Result<BTreeMap<String, RunFiles>> {
    let mut all = BTreeMap::new();
    for (task, dir) in task_dirs(root)? {
        for (run, files) in read_task(&dir)? {
            all.insert(format!("{task}/{run}"), files);
        }
    }
    Ok(all)
}

/// The text files of a run directory that a dataset keeps; binary files are listed in `left_out`.
fn read_run_files(dir: &Path, left_out: &mut Vec<PathBuf>) -> Result<RunFiles> {
    let mut files = RunFiles::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))? {
        let entry = entry?;
        let path = entry.path();
        let meta = std::fs::symlink_metadata(&path)?;
        if !meta.is_file() {
            if !meta.is_dir() {
                left_out.push(path);
            }
            continue;
        }
        let name = entry.file_name().to_string_lossy().into_owned();
        if !plain_name(&name) {
            left_out.push(path);
            continue;
        }
        let tabled = name == CONFIG_FILE
            || name == SUMMARY_FILE
            || LOG_TABLES.iter().any(|(file, _)| *file == name);
        if meta.len() > MAX_RUN_FILE_BYTES && !tabled {
            left_out.push(path);
            continue;
        }
        let bytes =
            arld_core::files::read_bounded(&path, MAX_RUN_FILE_BYTES).with_context(|| {
                format!(
                    "cannot pack {}: a dataset keeps a run's logs whole",
                    path.display()
                )
            })?;
        if name.ends_with(".tmp") || std::str::from_utf8(&bytes).is_err() {
            left_out.push(path);
            continue;
        }
        files.insert(name, bytes);
    }
    Ok(files)
}

/// The tables of one task, by file name, gzip-compressed.
fn encode_task(runs: &TaskRuns) -> Result<BTreeMap<&'static str, Vec<u8>>> {
    let mut verbatim: Vec<[String; 3]> = Vec::new();
    // A file of no table's kind (a user's notes, a failure record) is kept whole.
    for (run, files) in runs {
        for (name, bytes) in files {
            let tabled = name == CONFIG_FILE
                || name == SUMMARY_FILE
                || LOG_TABLES.iter().any(|(file, _)| file == name);
            if !tabled {
                verbatim.push([
                    run.clone(),
                    name.clone(),
                    String::from_utf8_lossy(bytes).into_owned(),
                ]);
            }
        }
    }
    // The configuration and summary, split into keys and value texts; a file that is not of the form is verbatim.
    let configs = split_all(runs, CONFIG_FILE, split_toml, &mut verbatim);
    let summaries = split_all(runs, SUMMARY_FILE, split_json, &mut verbatim);
    let config_table = KeyTable::build(&configs, runs, CONFIG_FILE, &mut verbatim, Syntax::Toml);
    let summary_table =
        KeyTable::build(&summaries, runs, SUMMARY_FILE, &mut verbatim, Syntax::Json);
    let mut tables = BTreeMap::new();
    for (file, table) in LOG_TABLES {
        let (header, rows) = log_rows(runs, file, &mut verbatim)?;
        let mut out = csv_writer();
        let mut head = vec!["run".to_string()];
        head.extend(header);
        out.write_record(&head)?;
        for row in rows {
            out.write_record(&row)?;
        }
        tables.insert(table, gzip(&out.into_inner()?)?);
    }
    let mut index = csv_writer();
    index.write_record(["run", "files", "config_absent", "summary_absent"])?;
    for (run, files) in runs {
        let names: Vec<&str> = files.keys().map(String::as_str).collect();
        index.write_record([
            run.as_str(),
            &names.join(" "),
            &config_table.absent(run),
            &summary_table.absent(run),
        ])?;
    }
    tables.insert(RUNS_TABLE, gzip(&index.into_inner()?)?);
    tables.insert(CONFIGS_TABLE, gzip(&config_table.csv()?)?);
    tables.insert(SUMMARIES_TABLE, gzip(&summary_table.csv()?)?);
    verbatim.sort();
    let mut text = csv_writer();
    text.write_record(["run", "file", "text"])?;
    for row in &verbatim {
        text.write_record(row)?;
    }
    tables.insert(VERBATIM_TABLE, gzip(&text.into_inner()?)?);
    let layout = serde_json::json!({
        "format": FORMAT,
        "config_string_columns": config_table.string_columns(),
        "summary_string_columns": summary_table.string_columns(),
    });
    let mut layout = serde_json::to_string_pretty(&layout)?;
    layout.push('\n');
    tables.insert(LAYOUT_FILE, layout.into_bytes());
    Ok(tables)
}

/// Reads a packed task directory.
fn read_task(dir: &Path) -> Result<TaskRuns> {
    let mut tables = BTreeMap::new();
    for name in TASK_FILES {
        let path = dir.join(name);
        let bytes = arld_core::files::read_bounded(&path, MAX_TABLE_BYTES).with_context(|| {
            format!(
                "cannot read {} (a packed task directory holds it)",
                path.display()
            )
        })?;
        tables.insert(name, bytes);
    }
    decode_task(&tables)
        .with_context(|| format!("the packed runs of {} are unreadable", dir.display()))
}

/// The files of a packed task directory.
pub const TASK_FILES: [&str; 8] = [
    RUNS_TABLE,
    CONFIGS_TABLE,
    SUMMARIES_TABLE,
    VERBATIM_TABLE,
    LAYOUT_FILE,
    LOG_TABLES[0].1,
    LOG_TABLES[1].1,
    LOG_TABLES[2].1,
];

/// Rebuilds a task's runs from the bytes of its files, given in the order of [`TASK_FILES`] (what `arld runs
/// unpack` and `arld report` read from a packed directory, without the file system): each run's path and the
/// number of its files.
pub fn decode_tables(files: [&[u8]; 8]) -> Result<Vec<(String, usize)>> {
    let tables = TASK_FILES
        .into_iter()
        .zip(files)
        .map(|(name, bytes)| (name, bytes.to_vec()))
        .collect();
    Ok(decode_task(&tables)?
        .into_iter()
        .map(|(run, files)| (run, files.len()))
        .collect())
}

/// Rebuilds a task's runs from its tables.
fn decode_task(tables: &BTreeMap<&'static str, Vec<u8>>) -> Result<TaskRuns> {
    let table = |name: &str| -> Result<&Vec<u8>> {
        tables
            .get(name)
            .with_context(|| format!("{name} is missing"))
    };
    let layout: serde_json::Value =
        serde_json::from_slice(table(LAYOUT_FILE)?).context("layout.json is not JSON")?;
    ensure!(
        layout["format"] == FORMAT,
        "layout.json is of format {} (this arld reads format {FORMAT})",
        layout["format"]
    );
    let strings = |key: &str| -> BTreeSet<String> {
        layout[key]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|v| v.as_str().map(str::to_string))
            .collect()
    };
    let mut runs = TaskRuns::new();
    let mut absent: BTreeMap<String, [BTreeSet<String>; 2]> = BTreeMap::new();
    let (header, index) = run_table(table(RUNS_TABLE)?, RUNS_TABLE)?;
    ensure!(
        header.len() == 4,
        "{RUNS_TABLE}: {} columns, not 4",
        header.len()
    );
    for row in &index {
        let run = row[0].to_string();
        check_run_path(&run)?;
        let words = |i: usize| {
            row[i]
                .split(' ')
                .filter(|w| !w.is_empty())
                .map(str::to_string)
        };
        let files: RunFiles = words(1).map(|name| (name, Vec::new())).collect();
        if let Some(bad) = files.keys().find(|name| !plain_name(name)) {
            bail!("{RUNS_TABLE} names a file {bad:?} of {run}, which is not a plain file name");
        }
        absent.insert(run.clone(), [words(2).collect(), words(3).collect()]);
        ensure!(
            runs.insert(run.clone(), files).is_none(),
            "{RUNS_TABLE} lists the run {run} twice (two copies of one run cannot both be unpacked)"
        );
    }
    let mut filled: BTreeSet<(String, String)> = BTreeSet::new();
    let mut put = |runs: &mut TaskRuns, run: &str, name: &str, bytes: Vec<u8>| -> Result<()> {
        let files = runs.get_mut(run).with_context(|| {
            format!("a table names the run {run}, which {RUNS_TABLE} does not list")
        })?;
        let slot = files.get_mut(name).with_context(|| {
            format!("a table holds {run}/{name}, which {RUNS_TABLE} does not list")
        })?;
        ensure!(
            filled.insert((run.to_string(), name.to_string())),
            "the tables hold {run}/{name} twice (two copies of one file cannot both be unpacked)"
        );
        *slot = bytes;
        Ok(())
    };
    let (header, verbatim) = run_table(table(VERBATIM_TABLE)?, VERBATIM_TABLE)?;
    ensure!(
        header.len() == 3,
        "{VERBATIM_TABLE}: {} columns, not 3",
        header.len()
    );
    let mut verbatim_files = BTreeSet::new();
    for row in &verbatim {
        put(&mut runs, &row[0], &row[1], row[2].as_bytes().to_vec())?;
        verbatim_files.insert((row[0].to_string(), row[1].to_string()));
    }
    for (syntax, file, table_name, string_key, which) in [
        (
            Syntax::Toml,
            CONFIG_FILE,
            CONFIGS_TABLE,
            "config_string_columns",
            0,
        ),
        (
            Syntax::Json,
            SUMMARY_FILE,
            SUMMARIES_TABLE,
            "summary_string_columns",
            1,
        ),
    ] {
        let string_columns = strings(string_key);
        let (header, rows) = run_table(table(table_name)?, table_name)?;
        for row in &rows {
            let run = &row[0];
            if verbatim_files.contains(&(run.to_string(), file.to_string())) {
                continue;
            }
            let missing = &absent
                .get(run)
                .with_context(|| format!("{table_name} names {run}, unlisted"))?[which];
            let mut pairs = Vec::new();
            for (key, cell) in header.iter().zip(row.iter()).skip(1) {
                if !missing.contains(key) {
                    pairs.push((
                        key.clone(),
                        syntax.value_text(cell, string_columns.contains(key)),
                    ));
                }
            }
            let text = syntax.render(&pairs);
            // The types layout.json gives the columns must be the types the run's files have.
            let named = PathBuf::from(format!("{run}/{file}"));
            match syntax {
                Syntax::Toml => run_dir::check_config_types(&text, &named),
                Syntax::Json => run_dir::check_summary_types(&text, &named),
            }
            .with_context(|| {
                format!("{table_name} and {LAYOUT_FILE} do not give back a run's {file}")
            })?;
            put(&mut runs, run, file, text.into_bytes())?;
        }
    }
    for (file, table_name) in LOG_TABLES {
        let (header, rows) = run_table(table(table_name)?, table_name)?;
        let mut texts: BTreeMap<String, csv::Writer<Vec<u8>>> = BTreeMap::new();
        for (run, files) in &runs {
            if files.contains_key(file)
                && !verbatim_files.contains(&(run.clone(), file.to_string()))
            {
                let mut w = csv_writer();
                w.write_record(&header[1..])?;
                texts.insert(run.clone(), w);
            }
        }
        for row in &rows {
            let w = texts.get_mut(&row[0]).with_context(|| {
                format!(
                    "{table_name} holds rows of {}, which has no {file}",
                    &row[0]
                )
            })?;
            w.write_record(row.iter().skip(1))?;
        }
        for (run, w) in texts {
            put(&mut runs, &run, file, w.into_inner()?)?;
        }
    }
    for (run, files) in &runs {
        for name in files.keys() {
            ensure!(
                filled.contains(&(run.clone(), name.clone())),
                "{RUNS_TABLE} lists {run}/{name}, which no table holds"
            );
        }
    }
    Ok(runs)
}

/// A table's header and rows, checked: a `run` column first and as many fields in every row as in the header.
fn run_table(gz: &[u8], name: &str) -> Result<(Vec<String>, Vec<csv::StringRecord>)> {
    let mut reader = csv_reader(std::io::Cursor::new(gunzip(gz).context(name.to_string())?));
    let header: Vec<String> = reader
        .headers()
        .context(name.to_string())?
        .iter()
        .map(str::to_string)
        .collect();
    ensure!(
        header.first().map(String::as_str) == Some("run"),
        "{name}: no run column"
    );
    let mut rows = Vec::new();
    for row in reader.records() {
        let row = row.with_context(|| name.to_string())?;
        ensure!(
            row.len() == header.len(),
            "{name}: a row of {} fields where the header has {}",
            row.len(),
            header.len()
        );
        rows.push(row);
    }
    Ok((header, rows))
}

/// A run path from a table: relative, `/`-separated, no `..`, nothing that leaves the task directory.
fn check_run_path(run: &str) -> Result<()> {
    let ok = !run.is_empty()
        && run
            .split('/')
            .all(|part| !part.is_empty() && part != "." && part != ".." && !part.contains('\\'));
    ensure!(
        ok,
        "{RUNS_TABLE} names a run at {run:?}, which is not a path below its task directory"
    );
    Ok(())
}

/// A file name a dataset keeps: no separator, no space, not `.` or `..`.
fn plain_name(name: &str) -> bool {
    !name.is_empty()
        && name != "."
        && name != ".."
        && !name.contains(['/', '\\', ' ', '\t', '\n', '\r'])
}

/// The two syntaxes of the key files.
#[derive(Clone, Copy)]
enum Syntax {
    /// `config.toml` as the run writes it: `key = value` lines, an array one element a line.
    Toml,
    /// `summary.json` as the run writes it: a pretty-printed object of scalars, no final newline.
    Json,
}

impl Syntax {
    /// The value's text in the file from a table cell.
    fn value_text(self, cell: &str, string: bool) -> String {
        match (self, string) {
            (Syntax::Toml, true) => toml::Value::String(cell.to_string()).to_string(),
            (Syntax::Json, true) => serde_json::Value::String(cell.to_string()).to_string(),
            (Syntax::Toml, false) => match cell.strip_prefix('[').and_then(|c| c.strip_suffix(']'))
            {
                Some("") => "[]".to_string(),
                Some(items) => {
                    let mut text = "[\n".to_string();
                    for item in items.split(", ") {
                        text.push_str(&format!("    {item},\n"));
                    }
                    text.push(']');
                    text
                }
                None => cell.to_string(),
            },
            (Syntax::Json, false) => cell.to_string(),
        }
    }

    /// The file from its keys and value texts.
    fn render(self, pairs: &[(String, String)]) -> String {
        match self {
            Syntax::Toml => pairs.iter().map(|(k, v)| format!("{k} = {v}\n")).collect(),
            Syntax::Json => {
                let body: Vec<String> = pairs
                    .iter()
                    .map(|(k, v)| format!("  {}: {v}", serde_json::Value::String(k.clone())))
                    .collect();
                if body.is_empty() {
                    "{}".to_string()
                } else {
                    format!("{{\n{}\n}}", body.join(",\n"))
                }
            }
        }
    }

    /// A cell from a value's text: strings unquoted where the column is all strings, an array inline.
    fn cell(self, text: &str, string_column: bool) -> Option<String> {
        match self {
            Syntax::Toml if string_column => toml_string(text),
            Syntax::Json if string_column => serde_json::from_str::<String>(text).ok(),
            Syntax::Toml => Some(match text.strip_prefix("[\n") {
                Some(rest) => {
                    let items: Vec<&str> = rest
                        .lines()
                        .filter_map(|l| l.trim().strip_suffix(','))
                        .collect();
                    format!("[{}]", items.join(", "))
                }
                None => text.to_string(),
            }),
            Syntax::Json => Some(text.to_string()),
        }
    }

    fn is_string(self, text: &str) -> bool {
        match self {
            Syntax::Toml => toml_string(text).is_some(),
            Syntax::Json => serde_json::from_str::<String>(text).is_ok(),
        }
    }
}

/// The string a TOML value text holds, if it is a string.
fn toml_string(text: &str) -> Option<String> {
    let table: toml::Table = toml::from_str(&format!("v = {text}")).ok()?;
    table.get("v")?.as_str().map(str::to_string)
}

/// `config.toml` as keys and value texts, or `None` when it is not of the form a run writes.
fn split_toml(text: &str) -> Option<KeyValues> {
    let mut pairs: Vec<(String, String)> = Vec::new();
    let mut lines = text.split_inclusive('\n');
    while let Some(line) = lines.next() {
        let line = line.strip_suffix('\n')?;
        let (key, value) = line.split_once(" = ")?;
        if key.is_empty() || !key.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') {
            return None;
        }
        let mut value = value.to_string();
        if value == "[" {
            loop {
                let next = lines.next()?.strip_suffix('\n')?;
                value.push('\n');
                value.push_str(next);
                if next == "]" {
                    break;
                }
            }
        }
        pairs.push((key.to_string(), value));
    }
    Some(pairs)
}

/// `summary.json` as keys and value texts, or `None` when it is not of the form a run writes.
fn split_json(text: &str) -> Option<KeyValues> {
    let body = text.strip_prefix("{\n")?.strip_suffix("\n}")?;
    let mut pairs = Vec::new();
    for line in body.split('\n') {
        let line = line.strip_prefix("  ")?;
        let line = line.strip_suffix(',').unwrap_or(line);
        let (key, value) = line.split_once("\": ")?;
        let key: String = serde_json::from_str(&format!("{key}\"")).ok()?;
        let value_json: serde_json::Value = serde_json::from_str(value).ok()?;
        if value_json.is_object() || value_json.is_array() {
            return None;
        }
        pairs.push((key, value.to_string()));
    }
    Some(pairs)
}

/// The key files of every run, split; a file that does not split goes to `verbatim`.
fn split_all(
    runs: &TaskRuns,
    file: &str,
    split: fn(&str) -> Option<KeyValues>,
    verbatim: &mut Vec<[String; 3]>,
) -> BTreeMap<String, KeyValues> {
    let mut out = BTreeMap::new();
    for (run, files) in runs {
        let Some(bytes) = files.get(file) else {
            continue;
        };
        let text = String::from_utf8_lossy(bytes);
        match split(&text) {
            Some(pairs) => {
                out.insert(run.clone(), pairs);
            }
            None => verbatim.push([run.clone(), file.to_string(), text.into_owned()]),
        }
    }
    out
}

/// A table of one key file: its columns (the union of the keys, in an order every run's keys follow) and cells.
struct KeyTable {
    columns: Vec<String>,
    strings: BTreeSet<String>,
    rows: BTreeMap<String, BTreeMap<String, String>>,
}

impl KeyTable {
    /// Builds the table; a run whose file would not come back exactly goes to `verbatim`.
    fn build(
        split: &BTreeMap<String, KeyValues>,
        runs: &TaskRuns,
        file: &str,
        verbatim: &mut Vec<[String; 3]>,
        syntax: Syntax,
    ) -> Self {
        let columns = key_order(split.values());
        let mut strings: BTreeSet<String> = columns.iter().cloned().collect();
        for pairs in split.values() {
            for (key, value) in pairs {
                if !syntax.is_string(value) {
                    strings.remove(key);
                }
            }
        }
        let position: BTreeMap<&String, usize> =
            columns.iter().enumerate().map(|(i, c)| (c, i)).collect();
        let mut rows = BTreeMap::new();
        for (run, pairs) in split {
            let original = &runs[run][file];
            let in_order = pairs
                .windows(2)
                .all(|w| position[&w[0].0] < position[&w[1].0]);
            let cells: Option<BTreeMap<String, String>> = pairs
                .iter()
                .map(|(k, v)| syntax.cell(v, strings.contains(k)).map(|c| (k.clone(), c)))
                .collect();
            let back = cells.as_ref().map(|cells| {
                let pairs: Vec<(String, String)> = pairs
                    .iter()
                    .map(|(k, _)| (k.clone(), syntax.value_text(&cells[k], strings.contains(k))))
                    .collect();
                syntax.render(&pairs)
            });
            match (in_order, cells, back) {
                (true, Some(cells), Some(back)) if back.as_bytes() == original.as_slice() => {
                    rows.insert(run.clone(), cells);
                }
                _ => verbatim.push([
                    run.clone(),
                    file.to_string(),
                    String::from_utf8_lossy(original).into_owned(),
                ]),
            }
        }
        KeyTable {
            columns,
            strings,
            rows,
        }
    }

    /// The keys of the table's columns that the run's file lacks, space-separated (empty for a run without one).
    fn absent(&self, run: &str) -> String {
        match self.rows.get(run) {
            Some(cells) => self
                .columns
                .iter()
                .filter(|c| !cells.contains_key(*c))
                .cloned()
                .collect::<Vec<_>>()
                .join(" "),
            None => String::new(),
        }
    }

    fn string_columns(&self) -> Vec<&String> {
        self.columns
            .iter()
            .filter(|c| self.strings.contains(*c))
            .collect()
    }

    fn csv(&self) -> Result<Vec<u8>> {
        let mut out = csv_writer();
        let mut head = vec!["run"];
        head.extend(self.columns.iter().map(String::as_str));
        out.write_record(&head)?;
        for (run, cells) in &self.rows {
            let mut row = vec![run.as_str()];
            row.extend(
                self.columns
                    .iter()
                    .map(|c| cells.get(c).map_or("", String::as_str)),
            );
            out.write_record(&row)?;
        }
        Ok(out.into_inner()?)
    }
}

/// The union of the runs' key sequences, in an order that keeps each run's order where the runs agree (a key
/// comes after every key that precedes it in some run; ties in order of first appearance).
fn key_order<'a>(runs: impl Iterator<Item = &'a KeyValues>) -> Vec<String> {
    let mut first_seen: Vec<String> = Vec::new();
    let mut before: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for pairs in runs {
        for (i, (key, _)) in pairs.iter().enumerate() {
            if !before.contains_key(key) {
                first_seen.push(key.clone());
                before.insert(key.clone(), BTreeSet::new());
            }
            if i > 0 {
                let prev = pairs[i - 1].0.clone();
                before.get_mut(key).expect("inserted above").insert(prev);
            }
        }
    }
    // Kahn's order over "comes right after" edges; keys on a cycle (runs that disagree) keep first-seen order.
    let mut order = Vec::new();
    let mut placed = BTreeSet::new();
    while order.len() < first_seen.len() {
        let next = first_seen
            .iter()
            .find(|k| !placed.contains(*k) && before[*k].iter().all(|b| placed.contains(b)))
            .or_else(|| first_seen.iter().find(|k| !placed.contains(*k)))
            .expect("a key is left")
            .clone();
        placed.insert(next.clone());
        order.push(next);
    }
    order
}

/// The header and the rows (`run` first) of one log over all runs; a log that would not come back goes to
/// `verbatim`.
fn log_rows(
    runs: &TaskRuns,
    file: &str,
    verbatim: &mut Vec<[String; 3]>,
) -> Result<(Vec<String>, Vec<Vec<String>>)> {
    let mut header: Option<Vec<String>> = None;
    let mut rows = Vec::new();
    for (run, files) in runs {
        let Some(bytes) = files.get(file) else {
            continue;
        };
        let mut reader = csv_reader(bytes.as_slice());
        let parsed: Option<(Vec<String>, Vec<Vec<String>>)> = (|| {
            let head: Vec<String> = reader.headers().ok()?.iter().map(str::to_string).collect();
            let body: Vec<Vec<String>> = reader
                .records()
                .map(|r| r.ok().map(|r| r.iter().map(str::to_string).collect()))
                .collect::<Option<_>>()?;
            Some((head, body))
        })();
        let fits = parsed.as_ref().is_some_and(|(head, body)| {
            header.as_ref().is_none_or(|h| h == head)
                && !head.is_empty()
                && body.iter().all(|r| r.len() == head.len())
                && rewrite(head, body).is_ok_and(|back| back == *bytes)
        });
        match (fits, parsed) {
            (true, Some((head, body))) => {
                header.get_or_insert(head);
                rows.extend(body.into_iter().map(|r| {
                    let mut row = vec![run.clone()];
                    row.extend(r);
                    row
                }));
            }
            _ => verbatim.push([
                run.clone(),
                file.to_string(),
                String::from_utf8_lossy(bytes).into_owned(),
            ]),
        }
    }
    Ok((header.unwrap_or_default(), rows))
}

/// A log's text from its header and rows, as the unpacker writes it.
fn rewrite(head: &[String], body: &[Vec<String>]) -> Result<Vec<u8>> {
    let mut w = csv_writer();
    w.write_record(head)?;
    for row in body {
        w.write_record(row)?;
    }
    Ok(w.into_inner()?)
}

fn csv_writer() -> csv::Writer<Vec<u8>> {
    csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .flexible(false)
        .from_writer(Vec::new())
}

fn csv_reader<R: Read>(source: R) -> csv::Reader<R> {
    csv::ReaderBuilder::new().flexible(true).from_reader(source)
}

fn count_rows(gz: &[u8]) -> Result<usize> {
    Ok(csv_reader(std::io::Cursor::new(gunzip(gz)?))
        .records()
        .count())
}

/// Deterministic gzip (no file name, no time stamp), best compression.
pub(crate) fn gzip(bytes: &[u8]) -> Result<Vec<u8>> {
    let mut enc = GzEncoder::new(Vec::new(), Compression::best());
    enc.write_all(bytes)?;
    Ok(enc.finish()?)
}

/// Decompresses a table, bounded: at most [`MAX_TABLE_TEXT_BYTES`], and at most [`MAX_TABLE_RATIO`] times the
/// compressed bytes (an error names the bound), so that a crafted stream cannot fill the memory.
pub(crate) fn gunzip(bytes: &[u8]) -> Result<Vec<u8>> {
    let bound = (bytes.len() as u64)
        .saturating_mul(MAX_TABLE_RATIO)
        .saturating_add(SMALL_TABLE_TEXT_BYTES)
        .min(MAX_TABLE_TEXT_BYTES);
    let mut out = Vec::new();
    GzDecoder::new(bytes)
        .take(bound + 1)
        .read_to_end(&mut out)
        .context("not a whole gzip stream")?;
    ensure!(
        (out.len() as u64) <= bound,
        "a table of {} compressed bytes decompresses to more than {bound} bytes, more than a table of runs \
         does (a crafted stream?)",
        bytes.len()
    );
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes a run directory below `root` with the given files.
    fn run(root: &Path, path: &str, files: &[(&str, &str)]) {
        let dir = root.join(path);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, text) in files {
            std::fs::write(dir.join(name), text).unwrap();
        }
    }

    /// Every file below `dir` with its bytes, by path relative to `dir`.
    fn tree(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
        let mut out = BTreeMap::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for entry in std::fs::read_dir(&d).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                } else {
                    let rel = path.strip_prefix(dir).unwrap().to_path_buf();
                    out.insert(rel, std::fs::read(&path).unwrap());
                }
            }
        }
        out
    }

    const SUMMARY: &str = "{\n  \"env\": \"CartPole-v0\",\n  \"seed\": 3,\n  \"final_score\": 199.5,\n  \"expert\": null\n}";

    /// Runs of several shapes: keys missing, a string column with a number-like value, a column that is a string
    /// in one run and a number in another, quoted CSV fields, a header-only log, a file of another form, and a
    /// binary file that a dataset leaves out.
    fn sample(root: &Path) {
        run(
            root,
            "CartPole-v0/adqn-bootstrap/seed0",
            &[
                (
                    "config.toml",
                    "env = \"CartPole-v0\"\nseed = 0\nhidden = [\n    64,\n    64,\n]\nquery_rule = \"\"\nx = \"1\"\n",
                ),
                ("summary.json", SUMMARY),
                (
                    "eval.csv",
                    "step,mean,std,min,max\n1000,9.5,0.5,9,10\n2000,200,0,200,200\n",
                ),
                (
                    "queries.csv",
                    "step,expert,answered\n5,\"noisy:0.4, shipped\",true\n",
                ),
            ],
        );
        run(
            root,
            "CartPole-v0/adqn-bootstrap/tq0.1/seed1",
            &[
                ("config.toml", "env = \"CartPole-v0\"\nseed = 1\nx = 2\n"),
                (
                    "summary.json",
                    "{\n  \"env\": \"CartPole-v0\",\n  \"seed\": 1,\n  \"expert\": \"shipped:weak\"\n}",
                ),
                ("eval.csv", "step,mean,std,min,max\n"),
                ("queries.csv", "step,expert,answered\n"),
                ("notes.txt", "my own notes\r\nwith CRLF"),
            ],
        );
        run(
            root,
            "Acrobot-v1/dqn-noisy/seed0",
            &[
                (
                    "config.toml",
                    "# a comment a run never writes\nenv = \"Acrobot-v1\"\n",
                ),
                ("summary.json", "{\"env\": \"Acrobot-v1\"}"),
                ("eval.csv", "step,mean\r\n1,2\r\n"),
            ],
        );
        std::fs::write(
            root.join("Acrobot-v1/dqn-noisy/seed0/weights.safetensors"),
            [0xff, 0xfe, 0],
        )
        .unwrap();
    }

    #[test]
    fn packed_runs_unpack_byte_for_byte() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("runs");
        sample(&root);
        let original = tree(&root);
        let summary = pack(&root).unwrap();
        assert_eq!(summary.runs, 3);
        assert_eq!(summary.left_out.len(), 1, "the binary file is left out");
        // The Acrobot run's three files and the notes are kept whole.
        assert_eq!(summary.verbatim, 4);
        // Only the tables go elsewhere: unpack them alone into a fresh directory.
        let packed = dir.path().join("packed");
        for task in ["CartPole-v0", "Acrobot-v1"] {
            std::fs::create_dir_all(packed.join(task)).unwrap();
            for entry in std::fs::read_dir(root.join(task)).unwrap() {
                let path = entry.unwrap().path();
                if path.is_file() {
                    std::fs::copy(&path, packed.join(task).join(path.file_name().unwrap()))
                        .unwrap();
                }
            }
        }
        let out = dir.path().join("out");
        let unpacked = unpack(&packed, &out).unwrap();
        assert_eq!(unpacked.runs, 3);
        let mut expected = original.clone();
        expected.retain(|path, _| !path.ends_with("weights.safetensors"));
        assert_eq!(tree(&out), expected);
        // The summaries table is one column per key, strings unquoted, null kept as null.
        let table =
            gunzip(&std::fs::read(root.join("CartPole-v0/summaries.csv.gz")).unwrap()).unwrap();
        let table = String::from_utf8(table).unwrap();
        assert_eq!(
            table,
            "run,env,seed,final_score,expert\n\
             adqn-bootstrap/seed0,CartPole-v0,3,199.5,null\n\
             adqn-bootstrap/tq0.1/seed1,CartPole-v0,1,,\"\"\"shipped:weak\"\"\"\n"
        );
    }

    /// The sample tree, packed, in a temporary directory (removed when the first value drops).
    fn packed_sample() -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("runs");
        sample(&root);
        pack(&root).unwrap();
        (dir, root)
    }

    #[test]
    fn packing_again_changes_no_byte_and_unpacking_again_writes_nothing() {
        let (_dir, root) = packed_sample();
        let first = tree(&root);
        let again = pack(&root).unwrap();
        assert_eq!(again.tables_written, 0);
        assert_eq!(again.added, 0);
        assert_eq!(tree(&root), first);
        let unpacked = unpack(&root, &root).unwrap();
        assert_eq!(unpacked.written, 0);
        assert_eq!(tree(&root), first);
    }

    #[test]
    fn unpacking_never_replaces_a_file_with_other_bytes() {
        let (_dir, root) = packed_sample();
        let eval = root.join("CartPole-v0/adqn-bootstrap/seed0/eval.csv");
        std::fs::write(&eval, "step,mean,std,min,max\n").unwrap();
        let err = unpack(&root, &root).unwrap_err().to_string();
        assert!(err.contains("eval.csv") && err.contains("differs"), "{err}");
        assert_eq!(
            std::fs::read_to_string(&eval).unwrap(),
            "step,mean,std,min,max\n"
        );
        // Packing refuses the same difference rather than choosing one side.
        let err = pack(&root).unwrap_err().to_string();
        assert!(err.contains("differs from the packed run"), "{err}");
    }

    #[test]
    fn a_table_naming_a_path_outside_its_task_is_refused() {
        let (dir, root) = packed_sample();
        let index = root.join("Acrobot-v1").join(RUNS_TABLE);
        let text = String::from_utf8(gunzip(&std::fs::read(&index).unwrap()).unwrap()).unwrap();
        let hostile = text.replace("dqn-noisy/seed0", "../../escaped");
        std::fs::write(&index, gzip(hostile.as_bytes()).unwrap()).unwrap();
        let out = dir.path().join("out");
        let err = format!("{:#}", unpack(&root, &out).unwrap_err());
        assert!(err.contains("not a path below its task directory"), "{err}");
        assert!(!dir.path().join("escaped").exists());
    }
}
