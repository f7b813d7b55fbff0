//! The paper's claims, tested on finished runs: the readings table (three readings of steps to solve with
//! bootstrap intervals and Mann–Whitney p-values against ADQN, and the final score) and the claims table
//! (each claim of the paper's results section, its evidence in the paper, ours under each reading, and the
//! verdict with the test that decides it), and the ablations table (each variant of an open choice against the
//! default of the same method and network).
//!
//! Everything here is computed from [`RunRecord`]s, so the tables regenerate from the run directories or from
//! `results/evaluations.csv.gz` alone ([`runs_from_evaluations_csv`]). The paper's own numbers come from
//! [`super::paper`]; nothing is typed in by hand.

use super::protocol::env_order;
use super::stats::{
    bootstrap_median_interval, final_score, mann_whitney, median, median_curve_hit, sustained,
};
use anyhow::{Context, Result, bail};
use arld_core::paper::{self, PAPER_TASKS, TABLE5_NETS};
use arld_core::train::TrainConfig;
use arld_core::train::run_dir::{
    DEFAULT_VARIANT, EXPERT_VARIANT_PREFIX, EvalPoint, RunId, RunRecord, T_QUERY_VARIANT_PREFIX,
};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Evaluations a sustained solve must hold for after the first one, unless told otherwise.
pub const DEFAULT_SUSTAIN: usize = 3;
/// Evaluations averaged into the final score.
pub const FINAL_EVALUATIONS: usize = 10;
/// Significance level of every decision below.
pub const ALPHA: f64 = 0.05;
const BOOTSTRAP_RESAMPLES: usize = 10_000;
const BOOTSTRAP_SEED: u64 = 0;
/// The methods the paper compares without pre-training.
const NO_PRETRAINING: [&str; 4] = ["dqn", "gdqn", "bdqn", "adqn"];
/// The methods that use demonstrations.
const WITH_DEMONSTRATIONS: [&str; 5] = ["gdqn", "bdqn", "adqn", "dqfd", "adqnp"];

/// A reading of steps to solve: per-seed values, their median and a bootstrap 95% interval.
#[derive(Debug, Clone)]
pub struct Reading {
    pub per_seed: Vec<f64>,
    pub median: f64,
    pub interval: (f64, f64),
}

impl Reading {
    fn new(per_seed: Vec<f64>) -> Self {
        let median = median(&per_seed).unwrap_or(f64::NAN);
        let interval =
            bootstrap_median_interval(&per_seed, 0.95, BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED)
                .unwrap_or((f64::NAN, f64::NAN));
        Reading {
            per_seed,
            median,
            interval,
        }
    }
}

/// One configuration (env, method, net, variant) over its seeds.
#[derive(Debug, Clone)]
pub struct Cell {
    pub env: String,
    pub method: String,
    pub net: String,
    pub variant: String,
    pub seeds: usize,
    /// Seeds whose curve ever reached the target.
    pub solved: usize,
    pub first_hit: Reading,
    pub sustained: Reading,
    /// First step at which the median-over-seeds curve reaches the target.
    pub median_curve: u64,
    /// Mean of the last [`FINAL_EVALUATIONS`] evaluations, per seed, and their median.
    pub final_score: Reading,
}

/// Groups runs per configuration and computes every reading; `k` is the sustained reading's K.
pub fn cells(runs: &[RunRecord], k: usize) -> Vec<Cell> {
    arld_core::train::run_dir::configurations(runs)
        .into_iter()
        .map(|members| {
            let reading = |f: &dyn Fn(&RunRecord) -> f64| {
                Reading::new(members.iter().map(|r| f(r)).collect())
            };
            let curves: Vec<Vec<EvalPoint>> = members.iter().map(|r| r.eval.clone()).collect();
            let first = members[0];
            Cell {
                env: first.id.env.clone(),
                method: first.id.method.name().to_string(),
                net: first.id.net.name().to_string(),
                variant: first.variant.clone(),
                seeds: members.len(),
                solved: members
                    .iter()
                    .filter(|r| r.eval.iter().any(|p| p.mean >= r.solve_threshold))
                    .count(),
                first_hit: reading(&|r| {
                    sustained(&r.eval, r.solve_threshold, 0, r.train_steps) as f64
                }),
                sustained: reading(&|r| {
                    sustained(&r.eval, r.solve_threshold, k, r.train_steps) as f64
                }),
                median_curve: median_curve_hit(&curves, first.solve_threshold, first.train_steps),
                final_score: reading(&|r| {
                    final_score(&r.eval, FINAL_EVALUATIONS).unwrap_or(f64::NAN)
                }),
            }
        })
        .collect()
}

fn find<'a>(
    cells: &'a [Cell],
    env: &str,
    method: &str,
    net: &str,
    variant: &str,
) -> Option<&'a Cell> {
    cells
        .iter()
        .find(|c| c.env == env && c.method == method && c.net == net && c.variant == variant)
}

/// The two-sided Mann–Whitney p-value of two readings' per-seed values (`None` when undefined).
fn p_value(a: &Reading, b: &Reading) -> Option<f64> {
    mann_whitney(&a.per_seed, &b.per_seed).map(|(_, p)| p)
}

fn fmt_num(v: f64) -> String {
    if v.is_nan() {
        "-".into()
    } else if v.fract() == 0.0 && v.abs() < 1e12 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

fn fmt_p(p: Option<f64>) -> String {
    match p {
        None => "-".into(),
        Some(p) if p < 0.001 => "<0.001".into(),
        Some(p) => format!("{p:.3}"),
    }
}

/// A reading's median, lower and upper bound, each written by `num`.
fn parts(r: &Reading, num: fn(f64) -> String) -> [String; 3] {
    [num(r.median), num(r.interval.0), num(r.interval.1)]
}

/// A reading for Markdown: `median [lo, hi]`.
fn show(r: &Reading) -> String {
    let [m, lo, hi] = parts(r, fmt_num);
    format!("{m} [{lo}, {hi}]")
}

/// A number for CSV, in full (empty when undefined).
fn num(v: f64) -> String {
    if v.is_nan() {
        String::new()
    } else {
        format!("{v}")
    }
}

/// A reading for CSV: `median,lo,hi`.
fn csv_reading(r: &Reading) -> String {
    parts(r, num).join(",")
}

/// A p-value for CSV (empty when undefined).
fn pv(p: Option<f64>) -> String {
    p.map_or(String::new(), |p| format!("{p:.6}"))
}

/// The readings table of the `default` variant: one row per (env, net, method), in the paper's order.
pub fn readings_table(cells: &[Cell], k: usize) -> (String, String) {
    let mut md = String::new();
    let mut csv = String::from(
        "env,method,net,seeds,solved,first_hit_median,first_hit_lo,first_hit_hi,first_hit_p_vs_adqn,\
         sustained_median,sustained_lo,sustained_hi,sustained_p_vs_adqn,median_curve,final_score_median,\
         final_score_lo,final_score_hi,final_score_p_vs_adqn,paper_median\n",
    );
    let _ = writeln!(
        md,
        "Steps to solve under three readings (median over seeds [bootstrap 95% interval], two-sided Mann–Whitney \
         p against ADQN of the same network): **first hit** (the paper's: first evaluation at the target), \
         **sustained** (at the target for that evaluation and the next {k}), **median curve** (first step where the \
         median-over-seeds curve reaches the target); never solving counts as the whole run. **Final score**: the \
         mean of the last {FINAL_EVALUATIONS} evaluations, median over seeds.\n"
    );
    let envs = env_order(cells.iter().map(|c| c.env.as_str()));
    for env in &envs {
        let _ = writeln!(md, "\n### {env}\n");
        let _ = writeln!(
            md,
            "| method | seeds (solved) | first hit | p | sustained | p | median curve | final score | p | paper |\n\
             |---|---|---|---|---|---|---|---|---|---|"
        );
        for (net, suffix) in TABLE5_NETS {
            for method in paper::TABLE5_METHODS {
                let Some(cell) = find(cells, env, method, net, DEFAULT_VARIANT) else {
                    continue;
                };
                let adqn = find(cells, env, "adqn", net, DEFAULT_VARIANT);
                let p = |f: fn(&Cell) -> &Reading| {
                    adqn.filter(|a| a.method != cell.method || cell.method != "adqn")
                        .filter(|_| method != "adqn")
                        .and_then(|a| p_value(f(cell), f(a)))
                };
                let (p_first, p_sustained, p_final) = (
                    p(|c| &c.first_hit),
                    p(|c| &c.sustained),
                    p(|c| &c.final_score),
                );
                let paper_median = paper::median_steps(env, method, net);
                // The same row in both tables, each entry as (markdown cell, CSV fields).
                let reading = |r: &Reading| (show(r), csv_reading(r));
                let p_entry = |p: Option<f64>| (fmt_p(p), pv(p));
                let entries = [
                    reading(&cell.first_hit),
                    p_entry(p_first),
                    reading(&cell.sustained),
                    p_entry(p_sustained),
                    (cell.median_curve.to_string(), cell.median_curve.to_string()),
                    reading(&cell.final_score),
                    p_entry(p_final),
                    (
                        paper_median.map_or("-".into(), |v| v.to_string()),
                        paper_median.map_or(String::new(), |v| v.to_string()),
                    ),
                ];
                let name = paper::method_display_name(method);
                let mut md_row = format!("| {name}-{suffix} | {} ({}) |", cell.seeds, cell.solved);
                let mut csv_row = format!("{env},{method},{net},{},{}", cell.seeds, cell.solved);
                for (md_cell, csv_fields) in entries {
                    let _ = write!(md_row, " {md_cell} |");
                    let _ = write!(csv_row, ",{csv_fields}");
                }
                let _ = writeln!(md, "{md_row}");
                let _ = writeln!(csv, "{csv_row}");
            }
        }
    }
    (md, csv)
}

/// Whether a variant is one of the studies of the open choices (`KEY-VALUE`: the N_r study and the ablations,
/// docs/algorithm.md §13), as opposed to the default, the t_query sweep, the expert-quality sweep or the effort
/// benchmark.
fn is_open_choice_variant(variant: &str) -> bool {
    variant != DEFAULT_VARIANT
        && !variant.starts_with(T_QUERY_VARIANT_PREFIX)
        && !variant.starts_with(EXPERT_VARIANT_PREFIX)
        && !super::protocol::is_effort_variant(variant)
}

/// The N_r study and the ablations against the default: for every (env, variant, net, method) with a default
/// cell to compare with, the first-hit reading and the final score of the variant next to the default's, each
/// with the two-sided Mann–Whitney p of variant against default, and the first-hit p against ADQN under the same
/// variant (does the variant change the ranking?).
pub fn variants_table(cells: &[Cell]) -> (String, String) {
    let mut md = String::from(
        "The N_r study and the ablations of the open choices (docs/algorithm.md §13), each against the default \
         configuration of the same method and network: median over seeds [bootstrap 95% interval] of the first hit \
         (never solving counts as the whole run) and of the final score (mean of the last evaluations), with the \
         two-sided Mann–Whitney p of the variant against the default, and the first-hit p against ADQN under the \
         same variant.\n",
    );
    let mut csv = String::from(
        "env,variant,method,net,seeds,solved,first_hit_median,first_hit_lo,first_hit_hi,default_first_hit_median,\
         first_hit_p_vs_default,first_hit_p_vs_adqn,final_score_median,final_score_lo,final_score_hi,\
         default_final_score_median,final_score_p_vs_default,default_seeds,default_solved\n",
    );
    for env in env_order(cells.iter().map(|c| c.env.as_str())) {
        let mut variants: Vec<&str> = cells
            .iter()
            .filter(|c| c.env == env && is_open_choice_variant(&c.variant))
            .map(|c| c.variant.as_str())
            .collect();
        variants.sort_unstable();
        variants.dedup();
        for variant in variants {
            let mut rows = String::new();
            for (net, suffix) in TABLE5_NETS {
                for method in paper::TABLE5_METHODS {
                    let (Some(cell), Some(default)) = (
                        find(cells, &env, method, net, variant),
                        find(cells, &env, method, net, DEFAULT_VARIANT),
                    ) else {
                        continue;
                    };
                    let p_default = p_value(&cell.first_hit, &default.first_hit);
                    let p_adqn = find(cells, &env, "adqn", net, variant)
                        .filter(|_| method != "adqn")
                        .and_then(|a| p_value(&cell.first_hit, &a.first_hit));
                    let p_final = p_value(&cell.final_score, &default.final_score);
                    let _ = writeln!(
                        rows,
                        "| {}-{suffix} | {} ({}) | {} | {} ({}) | {} | {} | {} | {} | {} |",
                        paper::method_display_name(method),
                        cell.seeds,
                        cell.solved,
                        show(&cell.first_hit),
                        fmt_num(default.first_hit.median),
                        default.solved,
                        fmt_p(p_default),
                        fmt_p(p_adqn),
                        show(&cell.final_score),
                        fmt_num(default.final_score.median),
                        fmt_p(p_final),
                    );
                    let _ = writeln!(
                        csv,
                        "{env},{variant},{method},{net},{},{},{},{},{},{},{},{},{},{},{}",
                        cell.seeds,
                        cell.solved,
                        csv_reading(&cell.first_hit),
                        num(default.first_hit.median),
                        pv(p_default),
                        pv(p_adqn),
                        csv_reading(&cell.final_score),
                        num(default.final_score.median),
                        pv(p_final),
                        default.seeds,
                        default.solved,
                    );
                }
            }
            if rows.is_empty() {
                continue;
            }
            let _ = write!(
                md,
                "\n### {env}, {variant}\n\n\
                 | method | seeds (solved) | first hit | default (solved) | p vs default | p vs ADQN | final score | \
                 default | p vs default |\n|---|---|---|---|---|---|---|---|---|\n{rows}"
            );
        }
    }
    if csv.lines().count() == 1 {
        md.push_str(
            "\nNo run here varies an open choice against a default of the same method and network \
             (`arld reproduce --part n_r --part ablations` makes them).\n",
        );
    }
    (md, csv)
}

/// A verdict on one claim.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Reproduced,
    NotReproduced,
    Inconclusive,
}

impl Verdict {
    pub fn label(self) -> &'static str {
        match self {
            Verdict::Reproduced => "reproduced",
            Verdict::NotReproduced => "not reproduced",
            Verdict::Inconclusive => "inconclusive",
        }
    }
}

/// One row of the claims table.
#[derive(Debug, Clone)]
pub struct Claim {
    pub claim: String,
    pub paper: String,
    /// What our runs show, under each reading where readings apply.
    pub ours: String,
    pub verdict: Verdict,
    /// The rule that decided the verdict.
    pub test: String,
}

/// Which reading of steps to solve a comparison uses.
#[derive(Clone, Copy)]
enum Which {
    First,
    Sustained,
    MedianCurve,
}

const READINGS: [(Which, &str); 3] = [
    (Which::First, "first hit"),
    (Which::Sustained, "sustained"),
    (Which::MedianCurve, "median curve"),
];

fn value(cell: &Cell, which: Which) -> f64 {
    match which {
        Which::First => cell.first_hit.median,
        Which::Sustained => cell.sustained.median,
        Which::MedianCurve => cell.median_curve as f64,
    }
}

/// "`a` needs fewer steps than `b`" on one task: (a's median below b's under each reading, and whether b is
/// significantly faster than a under the paper's first-hit reading).
fn faster(a: &Cell, b: &Cell) -> ([bool; 3], bool) {
    let lower = READINGS.map(|(which, _)| value(a, which) < value(b, which));
    let b_significantly_faster = b.first_hit.median < a.first_hit.median
        && p_value(&a.first_hit, &b.first_hit).is_some_and(|p| p < ALPHA);
    (lower, b_significantly_faster)
}

fn counts_text(counts: [usize; 3], of: usize) -> String {
    READINGS
        .iter()
        .zip(counts)
        .map(|((_, name), c)| format!("{name} {c}/{of}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// How many of `tasks` the paper's Table 5 gives `a` a lower median than every method of `others`, with `net`.
fn table5_wins(a: &str, others: &[&str], tasks: &[&str], net: &str) -> usize {
    tasks
        .iter()
        .filter(|task| {
            let mine = paper::median_steps(task, a, net);
            others
                .iter()
                .all(|o| matches!((mine, paper::median_steps(task, o, net)), (Some(m), Some(t)) if m < t))
        })
        .count()
}

/// What a claim is held to: the number of tasks on which the method must be best, and where that number comes
/// from (the paper's Table 5, or the claim read as stated where the paper has no runs).
struct Standard {
    wins: usize,
    evidence: String,
}

impl Standard {
    /// The paper's own count in its Table 5.
    fn table5(a: &str, others: &[&str], tasks: &[&str], net: &str) -> Self {
        let wins = table5_wins(a, others, tasks, net);
        Self {
            wins,
            evidence: format!("Table 5: best on {wins}/{} tasks", tasks.len()),
        }
    }

    /// The claim carried to tasks the paper did not run: best on every one.
    fn every(tasks: &[&str]) -> Self {
        Self {
            wins: tasks.len(),
            evidence: format!(
                "not run in the paper (its closing sentence proposes actor-critic learners); read as best on {n}/{n} \
                 tasks",
                n = tasks.len()
            ),
        }
    }
}

/// "Method `a` beats every method of `others` on `tasks`" as a claim, with `net`. The verdict: reproduced when `a`
/// has the lowest first-hit median on at least `standard.wins` of our tasks and no rival is significantly faster
/// anywhere; not reproduced when a rival is significantly faster on some task; inconclusive otherwise (or with
/// tasks missing).
fn beats_claim(
    cells: &[Cell],
    claim: String,
    (a, others): (&str, &[&str]),
    tasks: &[&str],
    net: &str,
    standard: Standard,
) -> Claim {
    let paper_wins = standard.wins;
    let mut counts = [0usize; 3];
    let mut missing = Vec::new();
    let mut beaten = Vec::new();
    for task in tasks {
        let ours = find(cells, task, a, net, DEFAULT_VARIANT);
        let rivals: Option<Vec<&Cell>> = others
            .iter()
            .map(|o| find(cells, task, o, net, DEFAULT_VARIANT))
            .collect();
        let (Some(ours), Some(rivals)) = (ours, rivals) else {
            missing.push(*task);
            continue;
        };
        let mut best = [true; 3];
        for rival in &rivals {
            let (lower, significantly) = faster(ours, rival);
            for i in 0..3 {
                best[i] &= lower[i];
            }
            if significantly {
                beaten.push(format!(
                    "{} on {task}",
                    paper::method_display_name(&rival.method)
                ));
            }
        }
        for i in 0..3 {
            counts[i] += best[i] as usize;
        }
    }
    let measured = tasks.len() - missing.len();
    let verdict = if !beaten.is_empty() {
        Verdict::NotReproduced
    } else if missing.is_empty() && counts[0] >= paper_wins {
        Verdict::Reproduced
    } else {
        Verdict::Inconclusive
    };
    let mut ours = counts_text(counts, measured);
    let faster = format!(
        "; significantly faster than {}: ",
        paper::method_display_name(a)
    );
    append_list(&mut ours, &faster, &beaten, ", ");
    append_list(&mut ours, "; no runs for ", &missing, ", ");
    Claim {
        claim,
        paper: standard.evidence,
        ours,
        verdict,
        test: format!(
            "lowest first-hit median on >= {paper_wins} tasks and no rival faster with Mann-Whitney p < {ALPHA}"
        ),
    }
}

/// Appends `label` and the `items` joined by `separator` to `text`, when there are items.
fn append_list<S: std::borrow::Borrow<str>>(
    text: &mut String,
    label: &str,
    items: &[S],
    separator: &str,
) {
    if !items.is_empty() {
        text.push_str(label);
        text.push_str(&items.join(separator));
    }
}

fn net_suffix(net: &str) -> &'static str {
    TABLE5_NETS
        .iter()
        .find(|(n, _)| *n == net)
        .map_or("?", |(_, s)| s)
}

/// A claim as stated: its text, the method and its rivals, and the tasks it is read on.
type Stated<'a, T> = (T, (&'a str, &'a [&'a str]), &'a [&'a str]);

/// The claims of the paper's results section, tested on `cells`: on the paper's tasks, then read again on the
/// tasks with actions in a box (learned by TD3 or SAC), where `expert_mean` gives the shipped weak expert's mean
/// return.
pub fn claims(cells: &[Cell], expert_mean: &dyn Fn(&str) -> Option<f64>) -> Vec<Claim> {
    let all_tasks: Vec<&str> = PAPER_TASKS.iter().map(|t| t.gym_id).collect();
    let harder = ["Acrobot-v1", "MountainCar-v0", "LunarLander-v2"];
    let hardest = ["MountainCar-v0", "LunarLander-v2"];
    let trio = &NO_PRETRAINING[..3];
    let mut out = Vec::new();
    for (net, _) in TABLE5_NETS {
        let s = net_suffix(net);
        let stated: [Stated<String>; 3] = [
            (
                format!(
                    "ADQN-{s} needs the fewest steps among DQN, GDQN, BDQN and ADQN (no pre-training)"
                ),
                ("adqn", trio),
                &all_tasks,
            ),
            (
                format!("ADQN-{s} is faster than DQfD-{s} except on CartPole"),
                ("adqn", &["dqfd"]),
                &harder,
            ),
            (
                format!(
                    "ADQNP-{s} improves over DQfD-{s} on the harder tasks (MountainCar, LunarLander)"
                ),
                ("adqnp", &["dqfd"]),
                &hardest,
            ),
        ];
        for (claim, (a, others), on) in stated {
            let standard = Standard::table5(a, others, on, net);
            out.push(beats_claim(cells, claim, (a, others), on, net, standard));
        }
    }
    out.push(end_above_expert(
        cells,
        "Methods with demonstrations end above the expert",
        &|env| paper::expert_stats(env).map(|e| e.mean_return),
    ));
    out.push(t_query_insensitive(cells));
    out.push(expert_robustness(cells));
    out.extend(continuous_claims(cells, expert_mean));
    out
}

/// The paper's claims 1-4 read again on the tasks with actions in a box, where our runs exist: the networks are
/// the critics' heads (`bootstrap`), the expert the shipped weak one, and each claim must hold on every task.
fn continuous_claims(cells: &[Cell], expert_mean: &dyn Fn(&str) -> Option<f64>) -> Vec<Claim> {
    let tasks: Vec<&str> = arld_core::env::registry::ids(true)
        .filter(|env| cells.iter().any(|c| c.env == *env))
        .collect();
    if tasks.is_empty() {
        return Vec::new();
    }
    let net = "bootstrap";
    // The paper's "harder tasks" are those a learner without the expert does not solve quickly; among the box
    // tasks, every one but the pendulum.
    let harder: Vec<&str> = tasks
        .iter()
        .copied()
        .filter(|env| *env != "Pendulum-v1")
        .collect();
    let trio = &NO_PRETRAINING[..3];
    let read_again: [Stated<&str>; 3] = [
        (
            "Continuous: ADQN needs the fewest steps among DQN, GDQN, BDQN and ADQN (no pre-training)",
            ("adqn", trio),
            &tasks,
        ),
        (
            "Continuous: ADQN is faster than DQfD",
            ("adqn", &["dqfd"]),
            &tasks,
        ),
        (
            "Continuous: ADQNP improves over DQfD on the harder tasks (the car, the lander)",
            ("adqnp", &["dqfd"]),
            &harder,
        ),
    ];
    let mut out: Vec<Claim> = read_again
        .into_iter()
        .map(|(claim, methods, on)| {
            beats_claim(cells, claim.into(), methods, on, net, Standard::every(on))
        })
        .collect();
    out.push(end_above_expert(
        cells,
        "Continuous: methods with demonstrations end above the expert",
        &|env| {
            if tasks.contains(&env) {
                expert_mean(env)
            } else {
                None
            }
        },
    ));
    out
}

/// "Methods with demonstrations end above the expert": each such configuration's final score against the expert's
/// mean return (`expert_mean`: the paper's on its tasks; `None` leaves a task out). Reproduced when every median
/// final score is above it; not reproduced when some configuration's whole bootstrap interval lies below it;
/// inconclusive otherwise.
fn end_above_expert(
    cells: &[Cell],
    claim: &str,
    expert_mean: &dyn Fn(&str) -> Option<f64>,
) -> Claim {
    let (mut above, mut total, mut below) = (0, 0, Vec::new());
    for cell in cells.iter().filter(|c| {
        c.variant == DEFAULT_VARIANT && WITH_DEMONSTRATIONS.contains(&c.method.as_str())
    }) {
        let Some(expert) = expert_mean(&cell.env) else {
            continue;
        };
        total += 1;
        if cell.final_score.median > expert {
            above += 1;
        }
        if cell.final_score.interval.1 < expert {
            below.push(format!(
                "{}-{} on {} ({})",
                paper::method_display_name(&cell.method),
                net_suffix(&cell.net),
                cell.env,
                fmt_num(cell.final_score.median)
            ));
        }
    }
    let verdict = if total == 0 {
        Verdict::Inconclusive
    } else if !below.is_empty() {
        Verdict::NotReproduced
    } else if above == total {
        Verdict::Reproduced
    } else {
        Verdict::Inconclusive
    };
    let mut ours = format!("{above}/{total} configurations end above the expert's mean");
    append_list(&mut ours, "; clearly below: ", &below, ", ");
    Claim {
        claim: claim.into(),
        paper: "Figures 1-2: the learned policies outperform the imperfect expert".into(),
        ours,
        verdict,
        test: format!(
            "median of the last {FINAL_EVALUATIONS} evaluations above the expert's mean; not reproduced if the \
             95% bootstrap interval lies below it"
        ),
    }
}

/// Pairs of cells of one (env, method, net) that differ only in their variant, selected by `prefix`.
fn variants<'a>(
    cells: &'a [Cell],
    prefix: &str,
) -> BTreeMap<(String, String, String), Vec<&'a Cell>> {
    let mut out: BTreeMap<_, Vec<&Cell>> = BTreeMap::new();
    for cell in cells.iter().filter(|c| c.variant.starts_with(prefix)) {
        out.entry((cell.env.clone(), cell.method.clone(), cell.net.clone()))
            .or_default()
            .push(cell);
    }
    out
}

/// "ADQN is insensitive to t_query": within each (env, net), every pair of t_query values compared with
/// Mann–Whitney on first-hit steps, Bonferroni-corrected. Reproduced when no pair differs; not reproduced when one
/// does; inconclusive without at least two t_query values of five seeds each.
fn t_query_insensitive(cells: &[Cell]) -> Claim {
    let (mut pairs, mut differing, mut settings) = (Vec::new(), Vec::new(), 0);
    for ((env, _, net), group) in variants(cells, T_QUERY_VARIANT_PREFIX) {
        if group.len() < 2 || group.iter().any(|c| c.seeds < 5) {
            continue;
        }
        settings += 1;
        let medians: Vec<String> = group
            .iter()
            .map(|c| format!("{} {}", c.variant, fmt_num(c.first_hit.median)))
            .collect();
        pairs.push(format!(
            "{env} -{}: {}",
            net_suffix(&net),
            medians.join(", ")
        ));
        let comparisons = group.len() * (group.len() - 1) / 2;
        for (i, a) in group.iter().enumerate() {
            for b in &group[i + 1..] {
                if let Some(p) = p_value(&a.first_hit, &b.first_hit)
                    && p * (comparisons as f64) < ALPHA
                {
                    differing.push(format!(
                        "{env} -{}: {} vs {} (p = {p:.4})",
                        net_suffix(&net),
                        a.variant,
                        b.variant
                    ));
                }
            }
        }
    }
    let verdict = match (settings, differing.is_empty()) {
        (0, _) => Verdict::Inconclusive,
        (_, false) => Verdict::NotReproduced,
        (_, true) => Verdict::Reproduced,
    };
    let mut ours =
        format!("{settings} task/network settings with >= 2 t_query values of >= 5 seeds");
    if !pairs.is_empty() {
        let _ = write!(ours, " ({})", pairs.join("; "));
    }
    append_list(&mut ours, "; differing: ", &differing, "; ");
    Claim {
        claim: "ADQN is insensitive to t_query in {0.05, 0.1, 0.3, 0.5}".into(),
        paper: "Figure 3: similar curves for every t_query".into(),
        ours,
        verdict,
        test: format!(
            "no pair of t_query values differs in first-hit steps (Mann-Whitney, Bonferroni, {ALPHA})"
        ),
    }
}

/// "ADQN is robust to a weak but policy-consistent expert while DQfD is not" (LunarLander): per network, the
/// final score with the weak expert against the perfect one. Reproduced when ADQN is not significantly worse with
/// the weak expert and DQfD is; not reproduced when ADQN is significantly worse; inconclusive otherwise.
fn expert_robustness(cells: &[Cell]) -> Claim {
    let worse = |method: &str, net: &str| -> Option<(f64, f64, Option<f64>)> {
        let cell = |spec: &str| {
            find(
                cells,
                "LunarLander-v2",
                method,
                net,
                &format!("{EXPERT_VARIANT_PREFIX}{spec}"),
            )
        };
        let (weak, perfect) = (cell("shipped-weak")?, cell("shipped-perfect")?);
        let p = p_value(&weak.final_score, &perfect.final_score);
        Some((weak.final_score.median, perfect.final_score.median, p))
    };
    let significantly_worse = |r: Option<(f64, f64, Option<f64>)>| {
        r.map(|(weak, perfect, p)| weak < perfect && p.is_some_and(|p| p < ALPHA))
    };
    let mut parts = Vec::new();
    let mut verdicts = Vec::new();
    for (net, s) in TABLE5_NETS {
        let (adqn, dqfd) = (worse("adqn", net), worse("dqfd", net));
        for (name, r) in [("ADQN", adqn), ("DQfD", dqfd)] {
            if let Some((weak, perfect, p)) = r {
                parts.push(format!(
                    "{name}-{s}: final {} with the weak expert vs {} with the perfect one (p = {})",
                    fmt_num(weak),
                    fmt_num(perfect),
                    fmt_p(p)
                ));
            }
        }
        verdicts.push(
            match (significantly_worse(adqn), significantly_worse(dqfd)) {
                (Some(true), _) => Verdict::NotReproduced,
                (Some(false), Some(true)) => Verdict::Reproduced,
                _ => Verdict::Inconclusive,
            },
        );
    }
    let verdict = if verdicts.contains(&Verdict::NotReproduced) {
        Verdict::NotReproduced
    } else if verdicts.iter().all(|v| *v == Verdict::Reproduced) {
        Verdict::Reproduced
    } else {
        Verdict::Inconclusive
    };
    Claim {
        claim: "On LunarLander, ADQN is robust to the weak expert while DQfD is not".into(),
        paper: "Figure 4: DQfD degrades with the weak expert, ADQN much less".into(),
        ours: if parts.is_empty() {
            "no expert-quality runs".into()
        } else {
            parts.join("; ")
        },
        verdict,
        test: format!(
            "final score, weak vs perfect expert, one-sided reading of a two-sided Mann-Whitney at {ALPHA}: ADQN not \
             worse, DQfD worse"
        ),
    }
}

/// The claims as Markdown and CSV.
pub fn claims_table(claims: &[Claim]) -> (String, String) {
    let mut md = String::from(
        "| claim | the paper's evidence | ours | verdict | decided by |\n|---|---|---|---|---|\n",
    );
    let mut csv = String::from("claim,paper,ours,verdict,test\n");
    let quote = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
    for c in claims {
        let _ = writeln!(
            md,
            "| {} | {} | {} | **{}** | {} |",
            c.claim,
            c.paper,
            c.ours,
            c.verdict.label(),
            c.test
        );
        let _ = writeln!(
            csv,
            "{},{},{},{},{}",
            quote(&c.claim),
            quote(&c.paper),
            quote(&c.ours),
            c.verdict.label(),
            quote(&c.test)
        );
    }
    (md, csv)
}

/// Writes `readings.md`, `readings.csv`, `claims.md`, `claims.csv`, `ablations.md` and `ablations.csv` into
/// `out_dir`; returns the files and a Markdown section with the claims and readings tables for `report.md`.
pub fn write_verdict(cells: &[Cell], out_dir: &Path, k: usize) -> Result<(Vec<PathBuf>, String)> {
    let (readings_md, readings_csv) = readings_table(cells, k);
    let expert_mean = |env: &str| {
        arld_core::env::box_spec(env)
            .is_ok()
            .then(|| {
                super::reference::references(env)
                    .ok()
                    .map(|(_, expert)| expert)
            })
            .flatten()
    };
    let (claims_md, claims_csv) = claims_table(&claims(cells, &expert_mean));
    let (variants_md, variants_csv) = variants_table(cells);
    let mut files = Vec::new();
    for (name, text) in [
        ("readings.md", &readings_md),
        ("readings.csv", &readings_csv),
        ("claims.md", &claims_md),
        ("claims.csv", &claims_csv),
        ("ablations.md", &variants_md),
        ("ablations.csv", &variants_csv),
    ] {
        let path = out_dir.join(name);
        arld_core::files::write_atomic(&path, text.as_bytes())?;
        files.push(path);
    }
    let section = format!(
        "## The paper's claims\n\n{claims_md}\n## Three readings of steps to solve\n\n{readings_md}"
    );
    Ok((files, section))
}

/// Rebuilds run records from an `evaluations.csv.gz` (as `arld report` writes it: one row per evaluation point;
/// the same CSV decompressed is read too).
/// The target comes from the environment's registration and the training length from the method's preset, so
/// the committed file alone regenerates every table.
pub fn runs_from_evaluations_csv(path: &Path) -> Result<Vec<RunRecord>> {
    let bytes = arld_core::files::read_bounded(path, super::pack::MAX_TABLE_BYTES)
        .with_context(|| format!("cannot read {}", path.display()))?;
    // As `arld report` writes it (gzip), or decompressed.
    let text = if bytes.starts_with(&[0x1f, 0x8b]) {
        super::pack::gunzip(&bytes).with_context(|| format!("cannot read {}", path.display()))?
    } else {
        bytes
    };
    let mut reader = csv::Reader::from_reader(text.as_slice());
    let headers = reader.headers()?.clone();
    let expected = [
        "env", "method", "net", "variant", "seed", "step", "mean", "std", "min", "max",
    ];
    if headers.iter().ne(expected) {
        bail!(
            "{}: expected the columns {}",
            path.display(),
            expected.join(",")
        );
    }
    let mut runs: BTreeMap<(String, String, String, String, u64), Vec<EvalPoint>> = BTreeMap::new();
    for (i, row) in reader.records().enumerate() {
        let row = row.with_context(|| format!("{}: line {}", path.display(), i + 2))?;
        let number = |k: usize| -> Result<f64> {
            row[k].parse::<f64>().with_context(|| {
                format!(
                    "{}: line {}: {} is not a number",
                    path.display(),
                    i + 2,
                    expected[k]
                )
            })
        };
        let seed: u64 = row[4]
            .parse()
            .with_context(|| format!("{}: line {}: bad seed", path.display(), i + 2))?;
        let point = EvalPoint {
            step: row[5]
                .parse()
                .with_context(|| format!("{}: line {}: bad step", path.display(), i + 2))?,
            mean: number(6)?,
            std: number(7)?,
            min: number(8)?,
            max: number(9)?,
        };
        runs.entry((
            row[0].into(),
            row[1].into(),
            row[2].into(),
            row[3].into(),
            seed,
        ))
        .or_default()
        .push(point);
    }
    runs.into_iter()
        .map(|((env, method, net, variant, seed), mut eval)| {
            eval.sort_by_key(|p| p.step);
            let preset = TrainConfig::preset(&env, method.parse()?, net.parse()?, seed)?;
            let id = RunId {
                method: method.parse()?,
                net: net.parse()?,
                env,
                seed,
            };
            // Any built-in task, of either kind of action; one without a threshold is never solved.
            let (_, _, threshold) = arld_core::env::registry::task(&id.env)?.facts();
            let threshold = threshold.unwrap_or(f64::INFINITY);
            Ok(RunRecord::from_curve(
                path.to_path_buf(),
                id,
                variant,
                eval,
                threshold,
                (preset.train_steps as u64, preset.eval_period as u64),
            ))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(env: &str, method: &str, net: &str, seed: u64, means: &[f64]) -> RunRecord {
        let spec = arld_core::env::spec(env).unwrap();
        let id = RunId {
            env: env.into(),
            method: method.parse().unwrap(),
            net: net.parse().unwrap(),
            seed,
        };
        let eval = EvalPoint::constant_curve(1000, means);
        let variant = DEFAULT_VARIANT.into();
        RunRecord::from_curve(
            "x".into(),
            id,
            variant,
            eval,
            spec.solve_threshold,
            (20_000, 1000),
        )
    }

    #[test]
    fn an_ablation_row_compares_the_variant_with_its_default() {
        // DQN-B on CartPole: by default the target at the 7th test, with the variant at the 2nd, 8 seeds each.
        let mut runs = Vec::new();
        for seed in 0..8 {
            runs.push(run(
                "CartPole-v0",
                "dqn",
                "bootstrap",
                seed,
                &[0., 0., 0., 0., 0., 0., 200.0],
            ));
            let mut variant = run("CartPole-v0", "dqn", "bootstrap", seed, &[0., 200.0]);
            variant.variant = "target_period-500".into();
            runs.push(variant);
        }
        let (md, csv) = variants_table(&cells(&runs, DEFAULT_SUSTAIN));
        let rows: Vec<&str> = csv.lines().skip(1).collect();
        assert_eq!(rows.len(), 1, "{csv}");
        let fields: Vec<&str> = rows[0].split(',').collect();
        assert_eq!(
            &fields[..6],
            [
                "CartPole-v0",
                "target_period-500",
                "dqn",
                "bootstrap",
                "8",
                "8"
            ]
        );
        // First hit 2000 against the default's 7000; every variant seed ahead of every default seed.
        assert_eq!((fields[6], fields[9]), ("2000", "7000"));
        let p: f64 = fields[10].parse().unwrap();
        assert!(p < 0.001, "p = {p}");
        assert!(md.contains("### CartPole-v0, target_period-500"), "{md}");
        // Without variants the table says so instead of being empty.
        let (md, csv) = variants_table(&cells(&runs[..1], DEFAULT_SUSTAIN));
        assert_eq!(csv.lines().count(), 1);
        assert!(md.contains("No run here varies an open choice"), "{md}");
    }

    #[test]
    fn a_clearly_faster_rival_refutes_the_claim() {
        // On CartPole, DQN solves at 1000 in 8 seeds, ADQN at 5000: DQN is significantly faster.
        let mut runs = Vec::new();
        for seed in 0..8 {
            runs.push(run("CartPole-v0", "dqn", "bootstrap", seed, &[200.0; 10]));
            runs.push(run(
                "CartPole-v0",
                "gdqn",
                "bootstrap",
                seed,
                &[0., 0., 0., 0., 0., 0., 200.0],
            ));
            runs.push(run(
                "CartPole-v0",
                "bdqn",
                "bootstrap",
                seed,
                &[0., 0., 0., 0., 0., 0., 200.0],
            ));
            runs.push(run(
                "CartPole-v0",
                "adqn",
                "bootstrap",
                seed,
                &[0., 0., 0., 0., 200.0, 200.0, 200.0, 200.0],
            ));
        }
        let cells = cells(&runs, 3);
        let claim = beats_claim(
            &cells,
            "c".into(),
            ("adqn", &["dqn", "gdqn", "bdqn"]),
            &["CartPole-v0"],
            "bootstrap",
            Standard::table5(
                "adqn",
                &["dqn", "gdqn", "bdqn"],
                &["CartPole-v0"],
                "bootstrap",
            ),
        );
        assert_eq!(claim.verdict, Verdict::NotReproduced, "{claim:?}");
        assert!(claim.ours.contains("DQN on CartPole-v0"), "{}", claim.ours);
        // Against GDQN and BDQN alone, ADQN is best on every reading and no rival is faster: reproduced.
        let claim = beats_claim(
            &cells,
            "c".into(),
            ("adqn", &["gdqn", "bdqn"]),
            &["CartPole-v0"],
            "bootstrap",
            Standard::table5("adqn", &["gdqn", "bdqn"], &["CartPole-v0"], "bootstrap"),
        );
        assert_eq!(claim.verdict, Verdict::Reproduced, "{claim:?}");
        assert_eq!(claim.ours, "first hit 1/1, sustained 1/1, median curve 1/1");
    }

    #[test]
    fn readings_table_matches_a_direct_computation() {
        // Two seeds: first hits 1000 and 3000 (median 2000); sustained (K=3) 3000 and never (20000).
        let runs = vec![
            run(
                "CartPole-v0",
                "adqn",
                "bootstrap",
                0,
                &[195.0, 10.0, 195.0, 195.0, 195.0, 195.0],
            ),
            run(
                "CartPole-v0",
                "adqn",
                "bootstrap",
                1,
                &[10.0, 10.0, 196.0, 10.0],
            ),
        ];
        let cells = cells(&runs, 3);
        assert_eq!(cells[0].first_hit.median, 2000.0);
        assert_eq!(cells[0].sustained.per_seed, vec![3000.0, 20000.0]);
        // Median curve: step 3000 has medians (195 + 196) / 2 >= 195; step 1000 has (195 + 10) / 2.
        assert_eq!(cells[0].median_curve, 3000);
        let (_, csv) = readings_table(&cells, 3);
        assert!(
            csv.lines()
                .nth(1)
                .unwrap()
                .starts_with("CartPole-v0,adqn,bootstrap,2,2,2000,"),
            "{csv}"
        );
    }
}
