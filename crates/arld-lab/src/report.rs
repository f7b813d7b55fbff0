//! Reports: read finished runs, compute the median steps to solve per configuration, and write the paper's
//! Table 5 with our numbers beside the paper's, the learning-curve figures and a `report.md` that ties them
//! together.
//!
//! The parts fit as follows:
//! - [`arld_core::train::run_dir::load_runs`] reads every complete run below a directory into a [`RunRecord`].
//! - [`super::verdict::cells`] applies the paper's measure per (env, method, net, variant): the first evaluation
//!   that reaches the threshold ([`stats::first_hit`]), and the median over seeds ([`stats::median`];
//!   docs/algorithm.md section 11), beside the other readings.
//! - [`report`] writes `table.md`, `table.csv`, `evaluations.csv.gz`, the figures of [`super::figures`] and
//!   `report.md`.

use super::protocol::env_order;
use super::stats;
use super::sweep::{SWEEP_FILE, SweepGrid};
use super::verdict::Cell;
use super::{figures, plot};
use anyhow::{Context, Result, bail};
use arld_core::paper::{self, PAPER_TASKS, TABLE5_METHODS, TABLE5_NETS};
use arld_core::train::Method;
use arld_core::train::run_dir::{
    self, DEFAULT_VARIANT, EvalPoint, RunRecord, SUMMARY_FILE, load_runs, write_atomic,
};

/// The file of every evaluation of every run (gzip-compressed CSV), which `arld report --from-evaluations` reads.
pub const EVALUATIONS_FILE: &str = "evaluations.csv.gz";
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Every evaluation point of every run, one row each, sorted by configuration, seed and step:
/// `env,method,net,variant,seed,step,mean,std,min,max` (returns rounded to 3 decimals to keep the file compact).
pub fn evaluations_csv(runs: &[RunRecord]) -> String {
    let mut rows: Vec<(&RunRecord, &EvalPoint)> = runs
        .iter()
        .flat_map(|r| r.eval.iter().map(move |p| (r, p)))
        .collect();
    // Sorted by names, as the file reads.
    rows.sort_by_key(|&(r, p)| (r.key(), p.step));
    // The mean is written exactly (the shortest text that reads back as the same f64), so that the readings
    // computed from this file alone equal those computed from the runs; the spread columns to 3 decimals.
    let mut out = String::from("env,method,net,variant,seed,step,mean,std,min,max\n");
    for (r, p) in rows {
        out.push_str(&format!(
            "{},{},{},{},{},{},{},{:.3},{:.3},{:.3}\n",
            r.id.env,
            r.id.method,
            r.id.net,
            r.variant,
            r.id.seed,
            p.step,
            p.mean,
            p.std,
            p.min,
            p.max
        ));
    }
    out
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

/// Table 5 as Markdown and CSV from the `default`-variant configurations ([`super::verdict::cells`]): rows
/// DQN..ADQNP for -B then -N, one column group per environment with our median first hit, the paper's median and
/// the number of seeds; the CSV adds the sustained and median-curve readings of the same cell.
pub fn table5(cells: &[Cell]) -> Result<(String, String)> {
    let defaults: Vec<&Cell> = cells
        .iter()
        .filter(|c| c.variant == DEFAULT_VARIANT)
        .collect();
    let envs = env_order(defaults.iter().map(|c| c.env.as_str()));
    let find = |env: &str, method: &str, net: &str| {
        defaults
            .iter()
            .find(|c| c.env == env && c.method == method && c.net == net)
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
        "Bold: our best median on that task among the methods of the same network. The reading is the first hit"
    )?;
    writeln!(
        md,
        "(the first evaluation at the target); table.csv adds the sustained and median-curve readings."
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
            format!("{env} sustained"),
            format!("{env} median curve"),
        ]);
    }
    csv_writer.write_record(&csv_header)?;
    // Tasks with actions in a box learn with an actor-critic (TD3 or SAC) whose critics' heads are the run's
    // "bootstrap" network: their rows are named for it, not for the DQN family's output stage.
    let all_boxed = envs.iter().all(|env| arld_core::env::box_spec(env).is_ok());
    for (net, suffix) in TABLE5_NETS {
        // A network group no run of the report has (the noisy one of box tasks) gets no rows.
        let any_run = envs
            .iter()
            .any(|env| TABLE5_METHODS.iter().any(|m| find(env, m, net).is_some()));
        if !any_run {
            continue;
        }
        let suffix = if all_boxed { "actor-critic" } else { suffix };
        // Like the paper, bold the best (smallest) median of each task within a network group.
        let best: Vec<f64> = envs
            .iter()
            .map(|env| {
                TABLE5_METHODS
                    .iter()
                    .filter_map(|method| find(env, method, net).map(|c| c.first_hit.median))
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        for method in TABLE5_METHODS {
            let name = match all_boxed {
                true => format!("{} ({suffix})", method.parse::<Method>()?.paper_name()),
                false => format!("{}-{suffix}", method.parse::<Method>()?.paper_name()),
            };
            let mut row = Vec::new();
            let mut csv_row = vec![method.to_string(), net.to_string()];
            for (env, best) in envs.iter().zip(&best) {
                let ours = find(env, method, net);
                let theirs = paper::median_steps(env, method, net);
                let theirs_text = theirs.map_or("-".to_string(), |v| v.to_string());
                match ours {
                    Some(c) => {
                        let ours_text = format_steps(c.first_hit.median);
                        let shown = if c.first_hit.median == *best {
                            format!("**{ours_text}**")
                        } else {
                            ours_text.clone()
                        };
                        row.push(format!("{shown} ({theirs_text}) {}/{}", c.solved, c.seeds));
                        csv_row.extend([
                            ours_text,
                            theirs_text,
                            c.seeds.to_string(),
                            c.solved.to_string(),
                            format_steps(c.sustained.median),
                            c.median_curve.to_string(),
                        ]);
                    }
                    None => {
                        row.push(format!("- ({theirs_text})"));
                        csv_row.extend([
                            "".to_string(),
                            theirs_text,
                            "0".to_string(),
                            "0".to_string(),
                            "".to_string(),
                            "".to_string(),
                        ]);
                    }
                }
            }
            writeln!(md, "| {name} | {} |", row.join(" | "))?;
            csv_writer.write_record(&csv_row)?;
        }
    }
    let csv_bytes = csv_writer
        .into_inner()
        .map_err(|e| anyhow::anyhow!("cannot finish table.csv: {e}"))?;
    Ok((md, String::from_utf8(csv_bytes)?))
}

/// Every configuration (all variants, including nets and methods outside Table 5) as a Markdown table.
fn all_groups_markdown(cells: &[Cell]) -> String {
    let mut md = String::from(
        "| env | method | net | variant | median steps to solve | solved/seeds |\n|---|---|---|---|---|---|\n",
    );
    let order = env_order(cells.iter().map(|c| c.env.as_str()));
    for env in &order {
        for c in cells.iter().filter(|c| &c.env == env) {
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {}/{} |\n",
                c.env,
                paper::method_display_name(&c.method),
                c.net,
                c.variant,
                format_steps(c.first_hit.median),
                c.solved,
                c.seeds
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
fn sweep_completion_notes(root: &Path) -> Result<Vec<String>> {
    let mut notes = Vec::new();
    run_dir::find_runs(root, |dir| {
        let sweep_file = dir.join(SWEEP_FILE);
        if !sweep_file.is_file() {
            return;
        }
        match SweepGrid::from_toml_file(&sweep_file).and_then(|g| g.specs()) {
            Ok(specs) => {
                let complete = specs
                    .iter()
                    .filter(|s| run_dir::is_complete(&dir.join(s.dir_name())))
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
    })?;
    Ok(notes)
}

/// Reads every complete run under `dir` and writes into `out_dir`: `table.md` and `table.csv` (Table 5 layout,
/// ours beside the paper's), the paper's figures as PNG and SVG (see [`figures::paper_figures`]; a figure whose
/// runs are absent is skipped with a note), and `report.md` linking everything with the notes.
///
/// A packed dataset ([`super::pack`]) is first brought up to date: runs finished since it was packed are packed
/// into it, and its packed runs are unpacked where their directories are missing; the report then reads the run
/// directories as for any sweep.
pub fn report(dir: &Path, out_dir: &Path, sustain: usize) -> Result<ReportSummary> {
    if super::pack::is_packed(dir) {
        super::pack::pack(dir).context("cannot pack the dataset's new runs")?;
        super::pack::unpack(dir, dir)?;
    }
    let (runs, mut notes) = load_runs(dir)?;
    let failed = run_dir::find_failed_runs(dir)?;
    check_report_runs(dir, &runs, &failed)?;
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    notes.extend(sweep_completion_notes(dir)?);
    notes.extend(run_notes(&runs));
    let cells = super::verdict::cells(&runs, sustain);
    let mut written = write_tables(&runs, &cells, out_dir, sustain)?;
    let figure_lines = draw_figures(&runs, out_dir, &mut written.files, &mut notes)?;
    let md = report_markdown(dir, &runs, &cells, &failed, &written, &figure_lines, &notes)?;
    let report_path = out_dir.join("report.md");
    write_atomic(&report_path, md.as_bytes())?;
    let mut files = written.files;
    files.push(report_path);
    files.extend(super::quote::render_documents(out_dir)?);
    if !failed.is_empty() {
        notes.push(format!(
            "{} runs failed and are left out (listed with their errors in report.md)",
            failed.len()
        ));
    }
    Ok(ReportSummary {
        runs: runs.len(),
        files,
        notes,
    })
}

/// Refuses a report of no complete run (naming failed runs, if any) or of a run whose evaluation mean is not a
/// number (it would make every statistic of its cell meaningless), before anything is written.
fn check_report_runs(
    dir: &Path,
    runs: &[RunRecord],
    failed: &[(PathBuf, run_dir::Failure)],
) -> Result<()> {
    if runs.is_empty() {
        let failed_note = match failed.first() {
            Some((first, failure)) => format!(
                " ({} failed runs, such as {}: {})",
                failed.len(),
                first.display(),
                failure.message()
            ),
            None => String::new(),
        };
        bail!(
            "no complete run (a directory with {SUMMARY_FILE}) under {}{failed_note}: give the directory a sweep, \
             `arld reproduce` or `arld train -o DIR/NAME` wrote its runs into (e.g. runs/reproduce), or \
             `--from-evaluations results/evaluations.csv.gz` for the committed results",
            dir.display()
        );
    }
    for run in runs {
        if let Some(bad) = run.eval.iter().find(|p| !p.mean.is_finite()) {
            bail!(
                "{}: eval.csv has a mean of {} at step {}; every evaluation's mean return must be a finite number",
                run.dir.display(),
                bad.mean,
                bad.step
            );
        }
    }
    Ok(())
}

/// The report's notes on the runs themselves: a summary whose steps to solve differ from its eval.csv's, and
/// how many runs are of older numerics (stated even when none are: a reader learns that every number
/// regenerates on their own CPU).
fn run_notes(runs: &[RunRecord]) -> Vec<String> {
    let mut notes = Vec::new();
    for run in runs {
        let ours = stats::first_hit(&run.eval, run.solve_threshold, run.train_steps);
        if let Some(recorded) = run.summary.as_ref().map(|s| s.steps_to_solve as u64)
            && recorded != ours
        {
            notes.push(format!(
                "{}: summary.json says steps_to_solve = {recorded}, eval.csv gives {ours} (the table uses eval.csv)",
                run.dir.display()
            ));
        }
    }
    let older = runs
        .iter()
        .filter(|run| {
            run.summary.as_ref().and_then(|s| s.numerics.as_deref())
                != Some(arld_core::math::NUMERICS)
        })
        .count();
    notes.push(if older > 0 {
        format!(
            "{older} of {} runs were computed by an older arld with the C library's elementary functions (no \
             `numerics` in summary.json), whose rounding depends on the CPU: they regenerate byte for byte only \
             with that arld on a CPU with FMA; `arld reproduce` computes them again",
            runs.len()
        )
    } else {
        format!(
            "0 of {} runs are of older numerics: every run was computed with the correctly rounded elementary \
             functions (`\"numerics\": \"{}\"` in summary.json) and regenerates byte for byte with this arld on \
             any x86-64 CPU",
            runs.len(),
            arld_core::math::NUMERICS
        )
    });
    notes
}

/// What [`write_tables`] wrote: the files, and the Markdown of Table 5 and of the verdict that `report.md` shows.
struct Tables {
    files: Vec<PathBuf>,
    table_md: String,
    verdict_md: String,
}

/// Writes Table 5 (`table.md`, `table.csv`), every evaluation (`evaluations.csv.gz`), the verdict and the effort
/// benchmark into `out_dir`.
fn write_tables(
    runs: &[RunRecord],
    cells: &[Cell],
    out_dir: &Path,
    sustain: usize,
) -> Result<Tables> {
    let mut files = Vec::new();
    let (table_md, table_csv) = table5(cells)?;
    let table_md_path = out_dir.join("table.md");
    write_atomic(&table_md_path, table_md.as_bytes())?;
    let table_csv_path = out_dir.join("table.csv");
    write_atomic(&table_csv_path, table_csv.as_bytes())?;
    files.extend([table_md_path, table_csv_path]);
    // Compressed: the committed one holds every evaluation of thousands of runs (40 MB as text).
    let evaluations_path = out_dir.join(EVALUATIONS_FILE);
    write_atomic(
        &evaluations_path,
        &super::pack::gzip(evaluations_csv(runs).as_bytes())?,
    )?;
    files.push(evaluations_path);
    let (verdict_files, verdict_md) = super::verdict::write_verdict(cells, out_dir, sustain)?;
    files.extend(verdict_files);
    files.extend(
        super::effort::write_effort(runs, out_dir, sustain)
            .context("cannot write the effort benchmark")?,
    );
    Ok(Tables {
        files,
        table_md,
        verdict_md,
    })
}

/// Draws the paper's figures into `out_dir` (adding their files to `files`; a figure whose runs are absent is
/// skipped with a note) and returns the lines of `report.md` that show them.
fn draw_figures(
    runs: &[RunRecord],
    out_dir: &Path,
    files: &mut Vec<PathBuf>,
    notes: &mut Vec<String>,
) -> Result<Vec<String>> {
    let mut figure_lines = Vec::new();
    for figure in &figures::paper_figures(runs) {
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
    Ok(figure_lines)
}

/// The text of `report.md`: the counts, Table 5, every configuration, the verdict, the paper's expert
/// statistics, the figures, the failed runs and the notes.
fn report_markdown(
    dir: &Path,
    runs: &[RunRecord],
    cells: &[Cell],
    failed: &[(PathBuf, run_dir::Failure)],
    tables: &Tables,
    figure_lines: &[String],
    notes: &[String],
) -> Result<String> {
    let mut md = String::new();
    writeln!(md, "# Report for {}\n", dir.display())?;
    writeln!(
        md,
        "{} complete runs in {} configurations.\n",
        runs.len(),
        cells.len()
    )?;
    if !failed.is_empty() {
        writeln!(
            md,
            "{} runs failed and are left out: see [Failed runs](#failed-runs).\n",
            failed.len()
        )?;
    }
    writeln!(
        md,
        "## Steps to solve (paper's Table 5 layout)\n\n{}",
        tables.table_md
    )?;
    writeln!(
        md,
        "## All configurations\n\n{}",
        all_groups_markdown(cells)
    )?;
    writeln!(md, "{}", tables.verdict_md)?;
    writeln!(md, "## Expert statistics in the paper\n")?;
    writeln!(
        md,
        "| env | mean ± std | min | avg. steps | target |\n|---|---|---|---|---|"
    )?;
    for (task, expert) in PAPER_TASKS.iter().zip(paper::EXPERT_STATS.iter()) {
        writeln!(
            md,
            "| {} | {} ± {} | {} | {} | {} |",
            task.gym_id,
            expert.mean_return,
            expert.std_return,
            expert.min_return,
            expert.mean_episode_length,
            arld_core::env::spec(task.gym_id)?.solve_threshold
        )?;
    }
    writeln!(md, "\n## Figures\n")?;
    writeln!(
        md,
        "Median over seeds with the interquartile range shaded; dashed lines mark the solve threshold.\n"
    )?;
    for line in figure_lines {
        writeln!(md, "{line}")?;
    }
    if !failed.is_empty() {
        md.push_str(&failed_runs_markdown(dir, failed));
    }
    if !notes.is_empty() {
        writeln!(md, "## Notes\n")?;
        for note in notes {
            writeln!(md, "- {note}")?;
        }
    }
    Ok(md)
}

/// The `Failed runs` section of `report.md`: each failed run below `root`, where it failed and the first line of
/// its error.
fn failed_runs_markdown(root: &Path, failed: &[(PathBuf, run_dir::Failure)]) -> String {
    let mut md = format!(
        "## Failed runs\n\n{} runs ended with an error and have no {SUMMARY_FILE}; each run directory's {} holds the \
         whole error chain, the time and the arld that ran it. Running the sweep again retries them.\n\n",
        failed.len(),
        run_dir::FAILED_FILE
    );
    for (dir, failure) in failed {
        let relative = dir.strip_prefix(root).unwrap_or(dir);
        let at = match failure.phase.as_str() {
            "training" => format!(" at step {}", failure.step),
            "" => String::new(),
            phase => format!(" in {phase}"),
        };
        md.push_str(&format!(
            "- `{}`{at}: {}\n",
            relative.display(),
            failure.message()
        ));
    }
    md.push('\n');
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(points: &[(u64, f64)]) -> Vec<EvalPoint> {
        points
            .iter()
            .map(|&(step, mean)| EvalPoint::constant(step, mean))
            .collect()
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
            .map(|c| stats::first_hit(c, 195.0, 20000) as f64)
            .collect();
        assert_eq!(steps, vec![6000.0, 7000.0, 9000.0, 20000.0]);
        assert_eq!(stats::median(&steps), Some(8000.0));
        assert_eq!(stats::median(&steps[..3]), Some(7000.0));
        assert_eq!(stats::median(&[]), None);
    }
}
