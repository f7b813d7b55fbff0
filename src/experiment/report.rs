//! Reports: read finished runs, compute the median steps to solve per configuration, and write the paper's
//! Table 5 with our numbers beside the paper's, the learning-curve figures and a `report.md` that ties them
//! together.
//!
//! The parts fit as follows:
//! - [`load_runs`] walks a directory for complete runs (directories holding `summary.json`) and reads each into a
//!   [`RunRecord`]: identity and threshold from `summary.json`, t_query / expert / eval period from
//!   `config.toml`, the evaluation curve from `eval.csv`, query steps from `queries.csv`. The variant label
//!   comes from the sweep's directory layout (`ENV/METHOD-NET/VARIANT/seedN`, see
//!   [`super::sweep::RunSpec::dir_name`]); a run outside that layout is the `default` variant.
//! - [`steps_to_solve`] and [`median`] implement the paper's measure (docs/algorithm.md section 11); [`group_runs`]
//!   applies them per (env, method, net, variant).
//! - [`report`] writes `table.md`, `table.csv`, the figures of [`super::plot`] and `report.md`.

use super::paper::{self, PAPER_TASKS, TABLE5_METHODS, TABLE5_NETS};
use super::plot;
pub use super::stats::{median, quantile};
use super::sweep::{DEFAULT_VARIANT, SUMMARY_FILE, SWEEP_FILE, SweepGrid, write_atomic};
use anyhow::{Context, Result, bail};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// One evaluation (the same record the training loop writes to `eval.csv`).
pub use crate::train::log::EvalPoint;

/// Everything a report needs from one complete run directory.
#[derive(Debug, Clone)]
pub struct RunRecord {
    /// The run directory.
    pub dir: PathBuf,
    pub env: String,
    pub method: String,
    pub net: String,
    pub seed: u64,
    /// Variant label (`default`, `tq0.05`, `expert-shipped-weak`, ...).
    pub variant: String,
    /// The t_query the run used, if its config records one.
    pub t_query: Option<f64>,
    /// The expert spec the run used, if its config records one.
    pub expert: Option<String>,
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
    /// `steps_to_solve` as the training code recorded it in `summary.json`, for cross-checking.
    pub summary_steps_to_solve: Option<u64>,
}

/// Every evaluation point of every run, one row each, sorted by configuration, seed and step:
/// `env,method,net,variant,seed,step,mean,std,min,max` (returns rounded to 3 decimals to keep the file compact).
pub fn evaluations_csv(runs: &[RunRecord]) -> String {
    let mut rows: Vec<(&RunRecord, &EvalPoint)> = runs
        .iter()
        .flat_map(|r| r.eval.iter().map(move |p| (r, p)))
        .collect();
    rows.sort_by(|(a, p), (b, q)| {
        (&a.env, &a.method, &a.net, &a.variant, a.seed, p.step)
            .cmp(&(&b.env, &b.method, &b.net, &b.variant, b.seed, q.step))
    });
    let mut out = String::from("env,method,net,variant,seed,step,mean,std,min,max\n");
    for (r, p) in rows {
        out.push_str(&format!(
            "{},{},{},{},{},{},{:.3},{:.3},{:.3},{:.3}\n",
            r.env, r.method, r.net, r.variant, r.seed, p.step, p.mean, p.std, p.min, p.max
        ));
    }
    out
}

/// First evaluation step whose mean test return reaches `threshold`, or `train_steps` when none does
/// (docs/algorithm.md section 11: Table 5 prints the full budget, e.g. 500000, for runs that never solve).
pub fn steps_to_solve(curve: &[EvalPoint], threshold: f64, train_steps: u64) -> u64 {
    crate::train::log::steps_to_solve(curve, threshold, train_steps).0
}

fn read_summary(path: &Path) -> Result<serde_json::Value> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not valid JSON", path.display()))
}

fn read_eval_csv(path: &Path) -> Result<Vec<EvalPoint>> {
    let mut reader =
        csv::Reader::from_path(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut points = Vec::new();
    for (line, row) in reader.deserialize::<EvalPoint>().enumerate() {
        points.push(row.with_context(|| format!("{}: bad row {}", path.display(), line + 1))?);
    }
    points.sort_by_key(|p| p.step);
    Ok(points)
}

/// The `step` column of `queries.csv` (other columns may be empty and are not needed here).
fn read_query_steps(path: &Path) -> Result<Vec<u64>> {
    let mut reader =
        csv::Reader::from_path(path).with_context(|| format!("cannot read {}", path.display()))?;
    let column = reader
        .headers()?
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

/// The variant label from a run's path inside a sweep: the components between `METHOD-NET` and `seedN`.
fn variant_from_path(relative: &Path, method: &str, net: &str, seed: u64) -> String {
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

/// Reads one complete run directory; `relative` is its path below the report root.
pub fn read_run(dir: &Path, relative: &Path) -> Result<RunRecord> {
    let summary = read_summary(&dir.join(SUMMARY_FILE))?;
    let text_field = |key: &str| -> Result<String> {
        summary
            .get(key)
            .and_then(|v| v.as_str())
            .map(str::to_string)
            .with_context(|| format!("summary.json has no string `{key}`"))
    };
    let number_field = |key: &str| -> Result<f64> {
        summary
            .get(key)
            .and_then(|v| v.as_f64())
            .with_context(|| format!("summary.json has no number `{key}`"))
    };
    let env = text_field("env")?;
    let method = text_field("method")?.to_lowercase();
    let net = text_field("net")?.to_lowercase();
    let seed = summary
        .get("seed")
        .and_then(|v| v.as_u64())
        .context("summary.json has no integer `seed`")?;
    let solve_threshold = number_field("solve_threshold")?;
    let train_steps = number_field("train_steps")? as u64;
    let summary_steps_to_solve = summary.get("steps_to_solve").and_then(|v| v.as_u64());

    // config.toml is optional for a report: it only adds t_query, the expert and the eval period.
    let config: toml::Table = match std::fs::read_to_string(dir.join("config.toml")) {
        Ok(text) => toml::from_str(&text)
            .with_context(|| format!("{}/config.toml is not valid TOML", dir.display()))?,
        Err(_) => toml::Table::new(),
    };
    let t_query = config
        .get("t_query")
        .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)));
    let expert = config
        .get("expert")
        .and_then(|v| v.as_str())
        .map(str::to_string);

    let eval = read_eval_csv(&dir.join("eval.csv"))?;
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
    let queries_path = dir.join("queries.csv");
    let query_steps = if queries_path.is_file() {
        Some(read_query_steps(&queries_path)?)
    } else {
        None
    };
    let variant = variant_from_path(relative, &method, &net, seed);
    Ok(RunRecord {
        dir: dir.to_path_buf(),
        env,
        method,
        net,
        seed,
        variant,
        t_query,
        expert,
        solve_threshold,
        train_steps,
        eval_period,
        eval,
        query_steps,
        summary_steps_to_solve,
    })
}

/// Finds every complete run below `root` (a directory holding `summary.json`; hidden directories are skipped)
/// and reads it. Runs that cannot be read are left out and described in the returned notes, so one damaged run
/// does not hide the others. Runs come back in path order.
pub fn load_runs(root: &Path) -> Result<(Vec<RunRecord>, Vec<String>)> {
    if !root.is_dir() {
        bail!("{} is not a directory", root.display());
    }
    let mut run_dirs = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        if dir.join(SUMMARY_FILE).is_file() {
            run_dirs.push(dir);
            continue;
        }
        let entries =
            std::fs::read_dir(&dir).with_context(|| format!("cannot list {}", dir.display()))?;
        for entry in entries {
            let entry = entry?;
            let hidden = entry.file_name().to_string_lossy().starts_with('.');
            if entry.file_type()?.is_dir() && !hidden {
                stack.push(entry.path());
            }
        }
    }
    run_dirs.sort();
    let mut runs = Vec::new();
    let mut notes = Vec::new();
    for dir in run_dirs {
        let relative = dir.strip_prefix(root).unwrap_or(&dir).to_path_buf();
        match read_run(&dir, &relative) {
            Ok(run) => runs.push(run),
            Err(err) => notes.push(format!("skipped run {}: {err:#}", dir.display())),
        }
    }
    Ok((runs, notes))
}

/// Runs of one configuration (env, method, net, variant) and their steps to solve.
#[derive(Debug, Clone)]
pub struct RunGroup {
    pub env: String,
    pub method: String,
    pub net: String,
    pub variant: String,
    /// Seeds in ascending order.
    pub seeds: Vec<u64>,
    /// Steps to solve of each seed, in the order of `seeds`.
    pub steps_to_solve: Vec<u64>,
    /// Seeds that reached the threshold within training.
    pub solved: usize,
    /// Median steps to solve over seeds.
    pub median_steps_to_solve: f64,
}

/// Groups runs per (env, method, net, variant) and computes their steps to solve.
pub fn group_runs(runs: &[RunRecord]) -> Vec<RunGroup> {
    let mut groups: BTreeMap<(&str, &str, &str, &str), Vec<&RunRecord>> = BTreeMap::new();
    for run in runs {
        groups
            .entry((&run.env, &run.method, &run.net, &run.variant))
            .or_default()
            .push(run);
    }
    groups
        .into_iter()
        .map(|((env, method, net, variant), mut members)| {
            members.sort_by_key(|r| r.seed);
            let steps: Vec<u64> = members
                .iter()
                .map(|r| steps_to_solve(&r.eval, r.solve_threshold, r.train_steps))
                .collect();
            let solved = members
                .iter()
                .filter(|r| r.eval.iter().any(|p| p.mean >= r.solve_threshold))
                .count();
            let as_f64: Vec<f64> = steps.iter().map(|&s| s as f64).collect();
            RunGroup {
                env: env.to_string(),
                method: method.to_string(),
                net: net.to_string(),
                variant: variant.to_string(),
                seeds: members.iter().map(|r| r.seed).collect(),
                median_steps_to_solve: median(&as_f64).unwrap_or(f64::NAN),
                steps_to_solve: steps,
                solved,
            }
        })
        .collect()
}

/// Environments in table order: the paper's tasks first in its column order, then any others alphabetically.
pub fn env_order<'a>(envs: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let mut list: Vec<&str> = envs.into_iter().collect();
    list.sort_by_key(|env| {
        (
            paper::paper_task_index(env).unwrap_or(usize::MAX),
            env.to_string(),
        )
    });
    list.dedup();
    list.into_iter().map(str::to_string).collect()
}

fn format_steps(value: f64) -> String {
    if value.is_nan() {
        "-".to_string()
    } else if value.fract() == 0.0 {
        format!("{value:.0}")
    } else {
        format!("{value:.1}")
    }
}

/// Table 5 as Markdown and CSV from the `default`-variant groups: rows DQN..ADQNP for -B then -N, one column
/// group per environment with our median, the paper's median and the number of seeds.
pub fn table5(groups: &[RunGroup]) -> Result<(String, String)> {
    let defaults: Vec<&RunGroup> = groups
        .iter()
        .filter(|g| g.variant == DEFAULT_VARIANT)
        .collect();
    let envs = env_order(defaults.iter().map(|g| g.env.as_str()));
    let find = |env: &str, method: &str, net: &str| {
        defaults
            .iter()
            .find(|g| g.env == env && g.method == method && g.net == net)
            .copied()
    };
    let mut md = String::new();
    writeln!(
        md,
        "Median environment steps to solve over seeds: ours, with the paper's Table 5 value in parentheses"
    )?;
    writeln!(
        md,
        "and the number of seeds (solved/total). A seed that never solves counts as the full training length."
    )?;
    writeln!(
        md,
        "Bold: our best median on that task among the methods of the same network."
    )?;
    writeln!(md)?;
    let header: Vec<String> = envs.iter().map(|e| e.to_string()).collect();
    writeln!(md, "| method | {} |", header.join(" | "))?;
    writeln!(md, "|---|{}", "---|".repeat(envs.len()))?;
    let mut csv_writer = csv::Writer::from_writer(Vec::new());
    let mut csv_header = vec!["method".to_string(), "net".to_string()];
    for env in &envs {
        csv_header.extend([
            format!("{env} ours"),
            format!("{env} paper"),
            format!("{env} seeds"),
            format!("{env} solved"),
        ]);
    }
    csv_writer.write_record(&csv_header)?;
    for (net, suffix) in TABLE5_NETS {
        // Like the paper, bold the best (smallest) median of each task within a network group.
        let best: Vec<f64> = envs
            .iter()
            .map(|env| {
                TABLE5_METHODS
                    .iter()
                    .filter_map(|method| find(env, method, net).map(|g| g.median_steps_to_solve))
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        for method in TABLE5_METHODS {
            let name = format!("{}-{suffix}", paper::method_display_name(method));
            let mut cells = Vec::new();
            let mut csv_row = vec![method.to_string(), net.to_string()];
            for (env, best) in envs.iter().zip(&best) {
                let ours = find(env, method, net);
                let theirs = paper::paper_median_steps(env, method, net);
                let theirs_text = theirs.map_or("-".to_string(), |v| v.to_string());
                match ours {
                    Some(g) => {
                        let ours_text = format_steps(g.median_steps_to_solve);
                        let shown = if g.median_steps_to_solve == *best {
                            format!("**{ours_text}**")
                        } else {
                            ours_text.clone()
                        };
                        cells.push(format!(
                            "{shown} ({theirs_text}) {}/{}",
                            g.solved,
                            g.seeds.len()
                        ));
                        csv_row.extend([
                            ours_text,
                            theirs_text,
                            g.seeds.len().to_string(),
                            g.solved.to_string(),
                        ]);
                    }
                    None => {
                        cells.push(format!("- ({theirs_text})"));
                        csv_row.extend([
                            "".to_string(),
                            theirs_text,
                            "0".to_string(),
                            "0".to_string(),
                        ]);
                    }
                }
            }
            writeln!(md, "| {name} | {} |", cells.join(" | "))?;
            csv_writer.write_record(&csv_row)?;
        }
    }
    let csv_bytes = csv_writer
        .into_inner()
        .map_err(|e| anyhow::anyhow!("cannot finish table.csv: {e}"))?;
    Ok((md, String::from_utf8(csv_bytes)?))
}

/// Every group (all variants, including nets and methods outside Table 5) as a Markdown table.
fn all_groups_markdown(groups: &[RunGroup]) -> String {
    let mut md = String::from(
        "| env | method | net | variant | median steps to solve | solved/seeds |\n|---|---|---|---|---|---|\n",
    );
    let order = env_order(groups.iter().map(|g| g.env.as_str()));
    for env in &order {
        for g in groups.iter().filter(|g| &g.env == env) {
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {}/{} |\n",
                g.env,
                paper::method_display_name(&g.method),
                g.net,
                g.variant,
                format_steps(g.median_steps_to_solve),
                g.solved,
                g.seeds.len()
            ));
        }
    }
    md
}

/// What [`report`] produced.
#[derive(Debug, Clone, Default)]
pub struct ReportSummary {
    /// Complete runs read.
    pub runs: usize,
    /// Files written (tables, figures, report.md).
    pub files: Vec<PathBuf>,
    /// Notes: skipped figures, unreadable runs, incomplete sweeps, disagreements with summary.json.
    pub notes: Vec<String>,
}

/// Counts how many runs each `sweep.toml` below `root` lists and how many of those are complete.
fn sweep_completion_notes(root: &Path) -> Vec<String> {
    let mut notes = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let sweep_file = dir.join(SWEEP_FILE);
        if sweep_file.is_file() {
            match SweepGrid::from_toml_file(&sweep_file).and_then(|g| g.specs()) {
                Ok(specs) => {
                    let complete = specs
                        .iter()
                        .filter(|s| dir.join(s.dir_name()).join(SUMMARY_FILE).is_file())
                        .count();
                    if complete < specs.len() {
                        notes.push(format!(
                            "sweep {} is incomplete: {complete} of {} runs finished",
                            dir.display(),
                            specs.len()
                        ));
                    }
                }
                Err(err) => notes.push(format!("cannot read {}: {err:#}", sweep_file.display())),
            }
        }
        if dir.join(SUMMARY_FILE).is_file() {
            continue;
        }
        if let Ok(entries) = std::fs::read_dir(&dir) {
            let mut subdirs: Vec<PathBuf> = entries
                .flatten()
                .filter(|e| {
                    e.file_type().is_ok_and(|t| t.is_dir())
                        && !e.file_name().to_string_lossy().starts_with('.')
                })
                .map(|e| e.path())
                .collect();
            subdirs.sort();
            stack.extend(subdirs.into_iter().rev());
        }
    }
    notes
}

/// Reads every complete run under `dir` and writes into `out_dir`: `table.md` and `table.csv` (Table 5 layout,
/// ours beside the paper's), the paper's figures as PNG and SVG (see [`plot::paper_figures`]; a figure whose
/// runs are absent is skipped with a note), and `report.md` linking everything with the notes.
pub fn report(dir: &Path, out_dir: &Path, sustain: usize) -> Result<ReportSummary> {
    let (runs, mut notes) = load_runs(dir)?;
    if runs.is_empty() {
        bail!(
            "no complete run (a directory with {SUMMARY_FILE}) under {}",
            dir.display()
        );
    }
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    notes.extend(sweep_completion_notes(dir));
    for run in &runs {
        let ours = steps_to_solve(&run.eval, run.solve_threshold, run.train_steps);
        if let Some(recorded) = run.summary_steps_to_solve
            && recorded != ours
        {
            notes.push(format!(
                "{}: summary.json says steps_to_solve = {recorded}, eval.csv gives {ours} (the table uses eval.csv)",
                run.dir.display()
            ));
        }
    }
    let groups = group_runs(&runs);
    let mut files = Vec::new();
    let (table_md, table_csv) = table5(&groups)?;
    let table_md_path = out_dir.join("table.md");
    write_atomic(&table_md_path, table_md.as_bytes())?;
    let table_csv_path = out_dir.join("table.csv");
    write_atomic(&table_csv_path, table_csv.as_bytes())?;
    files.extend([table_md_path, table_csv_path]);
    let evaluations_path = out_dir.join("evaluations.csv");
    write_atomic(&evaluations_path, evaluations_csv(&runs).as_bytes())?;
    files.push(evaluations_path);

    let (verdict_files, verdict_md) = super::verdict::write_verdict(&runs, out_dir, sustain)?;
    files.extend(verdict_files);

    let figures = plot::paper_figures(&runs);
    let mut figure_lines = Vec::new();
    for figure in &figures {
        match &figure.content {
            None => notes.push(format!(
                "figure {} skipped: {}",
                figure.name, figure.skip_reason
            )),
            Some(content) => {
                let written = plot::draw_figure(content, out_dir, &figure.name)
                    .with_context(|| format!("cannot draw figure {}", figure.name))?;
                figure_lines.push(format!(
                    "### {}\n\n![{}]({}.png)\n",
                    content.title, figure.name, figure.name
                ));
                files.extend(written);
            }
        }
    }

    let mut md = String::new();
    writeln!(md, "# Report for {}\n", dir.display())?;
    writeln!(
        md,
        "{} complete runs in {} configurations.\n",
        runs.len(),
        groups.len()
    )?;
    writeln!(
        md,
        "## Steps to solve (paper's Table 5 layout)\n\n{table_md}"
    )?;
    writeln!(
        md,
        "## All configurations\n\n{}",
        all_groups_markdown(&groups)
    )?;
    writeln!(md, "{verdict_md}")?;
    writeln!(md, "## Expert statistics in the paper\n")?;
    writeln!(
        md,
        "| env | mean ± std | min | avg. steps | target |\n|---|---|---|---|---|"
    )?;
    for (task, stats) in PAPER_TASKS.iter().zip(paper::EXPERT_STATS.iter()) {
        writeln!(
            md,
            "| {} | {} ± {} | {} | {} | {} |",
            task.gym_id,
            stats.mean_return,
            stats.std_return,
            stats.min_return,
            stats.mean_episode_length,
            stats.target_score
        )?;
    }
    writeln!(md, "\n## Figures\n")?;
    writeln!(
        md,
        "Median over seeds with the interquartile range shaded; dashed lines mark the solve threshold.\n"
    )?;
    for line in &figure_lines {
        writeln!(md, "{line}")?;
    }
    if !notes.is_empty() {
        writeln!(md, "## Notes\n")?;
        for note in &notes {
            writeln!(md, "- {note}")?;
        }
    }
    let report_path = out_dir.join("report.md");
    write_atomic(&report_path, md.as_bytes())?;
    files.push(report_path);
    Ok(ReportSummary {
        runs: runs.len(),
        files,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(points: &[(u64, f64)]) -> Vec<EvalPoint> {
        points
            .iter()
            .map(|&(step, mean)| EvalPoint {
                step,
                mean,
                std: 0.0,
                min: mean,
                max: mean,
            })
            .collect()
    }

    #[test]
    fn steps_to_solve_takes_the_first_evaluation_at_or_above_the_threshold() {
        let solving = curve(&[(1000, 20.0), (2000, 195.0), (3000, 150.0), (4000, 200.0)]);
        assert_eq!(steps_to_solve(&solving, 195.0, 20_000), 2000);
        let never = curve(&[(1000, 20.0), (2000, 194.9)]);
        assert_eq!(steps_to_solve(&never, 195.0, 20_000), 20_000);
        assert_eq!(steps_to_solve(&[], 195.0, 20_000), 20_000);
        // Negative thresholds (Acrobot, MountainCar): "reaches" means >=.
        assert_eq!(
            steps_to_solve(&curve(&[(5, -120.0), (10, -100.0)]), -100.0, 50),
            10
        );
    }

    #[test]
    fn median_of_seeds_with_one_never_solving_matches_a_hand_count() {
        // Four seeds solve at 7000, 6000, 9000 and one never does (counts as 20000): sorted 6000 7000 9000 20000,
        // median = (7000 + 9000) / 2 as in the paper's even-count medians.
        let seeds = [
            curve(&[(6000, 195.0)]),
            curve(&[(5000, 100.0), (7000, 199.0)]),
            curve(&[(9000, 196.0)]),
            curve(&[(1000, 10.0), (20000, 190.0)]),
        ];
        let steps: Vec<f64> = seeds
            .iter()
            .map(|c| steps_to_solve(c, 195.0, 20000) as f64)
            .collect();
        assert_eq!(steps, vec![6000.0, 7000.0, 9000.0, 20000.0]);
        assert_eq!(median(&steps), Some(8000.0));
        assert_eq!(median(&steps[..3]), Some(7000.0));
        assert_eq!(median(&[]), None);
    }

    #[test]
    fn quantiles_interpolate_between_order_statistics() {
        let values = [4.0, 1.0, 3.0, 2.0, 5.0];
        assert_eq!(quantile(&values, 0.25), Some(2.0));
        assert_eq!(quantile(&values, 0.75), Some(4.0));
        assert_eq!(quantile(&[1.0, 2.0], 0.25), Some(1.25));
    }

    #[test]
    fn variant_comes_from_the_sweep_layout() {
        let v = |p: &str| variant_from_path(Path::new(p), "adqn", "noisy", 3);
        assert_eq!(v("t/CartPole-v0/adqn-noisy/tq0.1/seed3"), "tq0.1");
        assert_eq!(v("CartPole-v0/adqn-noisy/seed3"), DEFAULT_VARIANT);
        assert_eq!(v("my-run"), DEFAULT_VARIANT);
        assert_eq!(v(""), DEFAULT_VARIANT);
    }
}
