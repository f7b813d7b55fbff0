//! The effort benchmark's readings recomputed from the committed per-run files, independently of
//! `src/experiment/effort.rs`: each run's normalised AUC from its `eval.csv` and the reference returns that
//! `effort.csv` states, the cell's median over seeds, and the own rule's design choice (the candidate with the
//! highest mean, over the screening tasks, of its median AUC on the design seeds).

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn results() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("results")
}

/// The rows of results/effort.csv as maps from column name to text (no field here holds a quoted comma except
/// the rule, which is the second column).
fn effort_rows() -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(results().join("effort.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    lines
        .map(|line| {
            let (env, rest) = line.split_once(',').unwrap();
            let (rule, rest) = if let Some(quoted) = rest.strip_prefix('"') {
                let (rule, rest) = quoted.split_once("\",").unwrap();
                (rule.to_string(), rest)
            } else {
                let (rule, rest) = rest.split_once(',').unwrap();
                (rule.to_string(), rest)
            };
            let mut fields = vec![env.to_string(), rule];
            fields.extend(rest.split(',').map(String::from));
            assert_eq!(fields.len(), header.len(), "effort.csv row {line}");
            header.iter().cloned().zip(fields).collect()
        })
        .collect()
}

/// The text of effort.md's section `title` (a `## ` heading), up to the next section.
fn effort_md_section(title: &str) -> String {
    let md = std::fs::read_to_string(results().join("effort.md")).unwrap();
    md.split(&format!("## {title}\n"))
        .nth(1)
        .and_then(|rest| rest.split("\n## ").next())
        .unwrap_or_else(|| panic!("effort.md has no section \"{title}\""))
        .to_string()
}

/// The mean over a run's evaluations of (return - random) / (expert - random).
fn run_auc(dir: &Path, random: f64, expert: f64) -> f64 {
    let text = std::fs::read_to_string(dir.join("eval.csv")).unwrap();
    let means: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse::<f64>().unwrap())
        .collect();
    assert!(!means.is_empty(), "{}: no evaluation", dir.display());
    means
        .iter()
        .map(|m| (m - random) / (expert - random))
        .sum::<f64>()
        / means.len() as f64
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// A rule spec as a directory name spells it.
fn spelled(spec: &str) -> String {
    spec.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '.' {
                c
            } else {
                '-'
            }
        })
        .collect()
}

/// The directory of a rule's runs at the paper's budget with bootstrapped heads: the paper's methods in their
/// own directories, every other rule as ADQN with `query_rule` set (the variant's name spells the spec).
fn rule_dir(env: &str, rule: &str) -> PathBuf {
    let runs = common::committed_runs().join(env);
    match rule {
        "greedy (GDQN)" => runs.join("gdqn-bootstrap"),
        "bernoulli (BDQN)" => runs.join("bdqn-bootstrap"),
        "adaptive (ADQN)" => runs.join("adqn-bootstrap"),
        spec => runs
            .join("adqn-bootstrap")
            .join(format!("query_rule-{}", spelled(spec))),
    }
}

/// The directory of a rule's runs with bootstrapped heads at a budget other than the paper's: the variant
/// `budget-B`, with `-query_rule-SPEC` for a rule that is not one of the paper's methods.
fn budget_dir(env: &str, rule: &str, budget: &str) -> PathBuf {
    let runs = common::committed_runs().join(env);
    match rule {
        "bernoulli (BDQN)" => runs.join("bdqn-bootstrap").join(format!("budget-{budget}")),
        "adaptive (ADQN)" => runs.join("adqn-bootstrap").join(format!("budget-{budget}")),
        spec => runs
            .join("adqn-bootstrap")
            .join(format!("budget-{budget}-query_rule-{}", spelled(spec))),
    }
}

/// The median AUC over the design seeds (0-9) of a rule's runs, recomputed.
fn design_median(env: &str, rule: &str, random: f64, expert: f64) -> Option<f64> {
    design_median_in(&rule_dir(env, rule), random, expert)
}

/// The median AUC over the design seeds (0-9) of the runs in `dir`, recomputed.
fn design_median_in(dir: &Path, random: f64, expert: f64) -> Option<f64> {
    let aucs: Vec<f64> = (0..10)
        .map(|s| dir.join(format!("seed{s}")))
        .filter(|d| d.join("summary.json").is_file())
        .map(|d| run_auc(&d, random, expert))
        .collect();
    (!aucs.is_empty()).then(|| median(aucs))
}

fn paper_budget_rows(rows: &[BTreeMap<String, String>]) -> Vec<&BTreeMap<String, String>> {
    rows.iter()
        .filter(|r| r["net"] == "bootstrap" && r["held_out"] == "false" && r["budget_scale"] == "1")
        .collect()
}

#[test]
fn every_cell_at_the_paper_budget_has_the_median_auc_of_its_runs() {
    let rows = effort_rows();
    let cells = paper_budget_rows(&rows);
    assert!(
        cells.len() >= 40,
        "only {} cells at the paper's budget",
        cells.len()
    );
    for row in cells {
        let (env, rule) = (&row["env"], &row["rule"]);
        let random: f64 = row["random_return"].parse().unwrap();
        let expert: f64 = row["expert_return"].parse().unwrap();
        let seeds: usize = row["seeds"].parse().unwrap();
        let dir = rule_dir(env, rule);
        let aucs: Vec<f64> = (0..100)
            .map(|s| dir.join(format!("seed{s}")))
            .filter(|d| d.join("summary.json").is_file())
            .map(|d| run_auc(&d, random, expert))
            .collect();
        assert_eq!(
            aucs.len(),
            seeds,
            "{env} {rule}: runs found in {}",
            dir.display()
        );
        let ours = median(aucs);
        let theirs: f64 = row["auc_median"].parse().unwrap();
        assert!(
            (ours - theirs).abs() < 1e-9,
            "{env} {rule}: median AUC {theirs} in effort.csv, {ours} recomputed"
        );
    }
}

#[test]
fn the_design_choice_is_the_candidate_with_the_highest_mean_median_auc() {
    let rows = effort_rows();
    let screen = ["CartPole-v0", "Acrobot-v1", "MountainCar-v0"];
    let refs: BTreeMap<String, (f64, f64)> = rows
        .iter()
        .map(|r| {
            (
                r["env"].clone(),
                (
                    r["random_return"].parse().unwrap(),
                    r["expert_return"].parse().unwrap(),
                ),
            )
        })
        .collect();
    let candidates = [
        "ranked",
        "ranked(horizon=0.1)",
        "ranked(horizon=0.03)",
        "ranked(horizon=0.3)",
        "ranked(horizon=0.1,start=0.01)",
    ];
    let mut best: Option<(f64, &str)> = None;
    for candidate in candidates {
        let medians: Option<Vec<f64>> = screen
            .iter()
            .map(|env| {
                let (random, expert) = refs[*env];
                design_median(env, candidate, random, expert)
            })
            .collect();
        if let Some(m) = medians {
            let mean = m.iter().sum::<f64>() / m.len() as f64;
            if best.is_none_or(|(b, _)| mean > b) {
                best = Some((mean, candidate));
            }
        }
    }
    let md = std::fs::read_to_string(results().join("effort.md")).unwrap();
    let expected = match best {
        Some((_, c)) => format!("The highest mean: **{c}**."),
        None => "No candidate has run on every screening task yet.".to_string(),
    };
    assert!(md.contains(&expected), "effort.md does not say: {expected}");
    assert_eq!(
        best.map(|(_, c)| c),
        Some(arld::experiment::protocol::HELD_OUT_RULE),
        "the rule fixed for the held-out test is not the design seeds' choice"
    );
}

/// Every entry of effort.md's "What the expert's effort buys" tables is the median AUC of that rule's runs at
/// that budget on the design seeds, recomputed from their eval.csv.
#[test]
fn what_the_effort_buys_is_the_median_auc_of_the_runs_at_each_budget() {
    let rows = effort_rows();
    let refs: BTreeMap<String, (f64, f64, String)> = rows
        .iter()
        .filter(|r| r["budget_scale"] == "1")
        .map(|r| {
            (
                r["env"].clone(),
                (
                    r["random_return"].parse().unwrap(),
                    r["expert_return"].parse().unwrap(),
                    r["budget"].clone(),
                ),
            )
        })
        .collect();
    let section = effort_md_section("What the expert's effort buys");
    let mut checked = 0;
    for table in section.split("\n### ").skip(1) {
        let env = table.lines().next().unwrap().trim();
        let (random, expert, paper_budget) = &refs[env];
        let mut lines = table.lines().filter(|l| l.starts_with('|'));
        let header: Vec<&str> = lines.next().unwrap().split('|').map(str::trim).collect();
        // Columns "1/4 (50)": the budget in parentheses.
        let budgets: Vec<Option<&str>> = header
            .iter()
            .map(|h| h.split_once('(').map(|(_, b)| b.trim_end_matches(')')))
            .collect();
        for row in lines.skip(1) {
            let fields: Vec<&str> = row.split('|').map(str::trim).collect();
            let (rule, net) = (fields[1], fields[2]);
            assert_eq!(
                net, "bootstrap",
                "{env} {rule}: only bootstrap runs vary the budget"
            );
            for (field, budget) in fields.iter().zip(&budgets) {
                let Some(budget) = budget else { continue };
                if *field == "–" {
                    continue;
                }
                let dir = if budget == paper_budget {
                    rule_dir(env, rule)
                } else {
                    budget_dir(env, rule, budget)
                };
                let ours = design_median_in(&dir, *random, *expert).unwrap_or_else(|| {
                    panic!("{env} {rule} at {budget}: no run in {}", dir.display())
                });
                let theirs = field.split_whitespace().next().unwrap();
                assert_eq!(
                    format!("{ours:.3}"),
                    theirs,
                    "{env} {rule} at budget {budget}: effort.md says {theirs}, the runs {ours:.3}"
                );
                checked += 1;
            }
        }
    }
    assert!(
        checked >= 20,
        "only {checked} budget cells in effort.md's effort table"
    );
}

/// effort.md's screen table, recomputed from effort.csv (p-values of the Mann-Whitney test that
/// `stats::mann_whitney_agrees_with_scipy` checks, and the AUC medians checked above): per task, the rules
/// significantly higher than all three paper rules, higher than some, and lower than some.
#[test]
fn the_screen_lists_the_rules_that_differ_from_the_paper_rules() {
    let rows = effort_rows();
    let cells = paper_budget_rows(&rows);
    let section = effort_md_section("The screen at the paper's budget");
    let baselines = [
        ("greedy (GDQN)", "GDQN", "p_vs_gdqn"),
        ("bernoulli (BDQN)", "BDQN", "p_vs_bdqn"),
        ("adaptive (ADQN)", "ADQN", "p_vs_adqn"),
    ];
    let mut envs: Vec<&str> = cells.iter().map(|r| r["env"].as_str()).collect();
    envs.dedup();
    let mut checked = 0;
    for env in envs {
        let of_env: Vec<_> = cells.iter().filter(|r| r["env"] == env).collect();
        let auc = |rule: &str| -> f64 {
            of_env.iter().find(|r| r["rule"] == rule).unwrap()["auc_median"]
                .parse()
                .unwrap()
        };
        let (mut all, mut some, mut lower) = (Vec::new(), Vec::new(), Vec::new());
        let mut rules: Vec<&str> = of_env
            .iter()
            .map(|r| r["rule"].as_str())
            .filter(|rule| !baselines.iter().any(|b| b.0 == *rule))
            .collect();
        rules.sort();
        for rule in rules {
            let row = of_env.iter().find(|r| r["rule"] == rule).unwrap();
            let (mut above, mut below) = (Vec::new(), Vec::new());
            for (label, name, column) in baselines {
                let p: f64 = match row[column].as_str() {
                    "" => continue,
                    text => text.parse().unwrap(),
                };
                if p < 0.05 {
                    if auc(rule) > auc(label) {
                        above.push(name);
                    } else {
                        below.push(name);
                    }
                }
            }
            let named = |v: &[&str]| format!("{rule} ({})", v.join(", "));
            if above.len() == 3 {
                all.push(rule.to_string());
            } else if !above.is_empty() {
                some.push(named(&above));
            }
            if !below.is_empty() {
                lower.push(named(&below));
            }
        }
        let list = |v: &[String]| {
            if v.is_empty() {
                "none".to_string()
            } else {
                v.join("; ")
            }
        };
        let line = section
            .lines()
            .find(|l| l.starts_with(&format!("| {env} |")))
            .unwrap_or_else(|| panic!("no screen row for {env}"));
        let fields: Vec<&str> = line.split('|').map(str::trim).collect();
        assert_eq!(
            &fields[3..6],
            &[list(&all), list(&some), list(&lower)],
            "{env}: effort.md's screen row against effort.csv"
        );
        checked += 1;
    }
    assert!(checked >= 4, "the screen covers {checked} tasks");
}

/// The committed runs are what `arld reproduce` computes for the effort benchmark at its default seed count (the
/// paper's 20): every run of the benchmark's grids and of the held-out test is under results/runs, finished.
#[test]
fn every_run_of_the_effort_protocol_is_committed() {
    use arld::experiment::protocol::{PAPER_SEEDS, effort_grids, held_out_grids};
    let seeds: Vec<u64> = (0..PAPER_SEEDS).collect();
    let mut expected = 0;
    let mut missing = Vec::new();
    for grid in effort_grids(&seeds).into_iter().chain(held_out_grids()) {
        for spec in grid.specs().unwrap() {
            expected += 1;
            let dir = common::committed_runs().join(spec.dir_name());
            if !dir.join("summary.json").is_file() {
                missing.push(dir);
            }
        }
    }
    assert!(
        missing.is_empty(),
        "{} of the effort protocol's {expected} runs are not committed (finished), e.g. {}",
        missing.len(),
        missing[0].display()
    );
}
