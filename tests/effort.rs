//! The effort benchmark's readings recomputed from the committed per-run files, independently of
//! `crates/arld-lab/src/effort.rs`: each run's normalised AUC from its `eval.csv` and the reference returns that
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
        // ADQN asking from learning_starts on: its rule and the setting, as the continuous grid spells them.
        "adaptive from learning_starts" => runs
            .join("adqn-bootstrap")
            .join("query_rule-adaptive-queries_from_learning_starts-true"),
        // ADQN reading the critics' action disagreement (the box learners' other uncertainty).
        "adaptive on action disagreement" => runs
            .join("adqn-bootstrap")
            .join("query_rule-adaptive-uncertainty-action_disagreement"),
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

/// The median AUC over the seeds outside the held-out ones (0-99) of the runs in `dir`, recomputed.
fn screen_median_in(dir: &Path, random: f64, expert: f64) -> Option<f64> {
    let aucs: Vec<f64> = (0..100)
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
        Some(arld::lab::protocol::HELD_OUT_RULE),
        "the rule fixed for the held-out test is not the design seeds' choice"
    );
}

/// The continuous held-out test's rule is the design seeds' choice: of the candidates, the highest median AUC on
/// the design seeds (0-9) at the preset's budget on each task of the test, recomputed from the runs.
#[test]
fn the_continuous_held_out_rule_is_the_design_seeds_choice() {
    use arld::lab::protocol::{BOX_CANDIDATES, BOX_HELD_OUT_RULE, BOX_HELD_OUT_TASKS};
    let rows = effort_rows();
    for env in BOX_HELD_OUT_TASKS {
        let row = rows
            .iter()
            .find(|r| r["env"] == env && r["budget_scale"] == "1")
            .expect("the task's rows");
        let random: f64 = row["random_return"].parse().unwrap();
        let expert: f64 = row["expert_return"].parse().unwrap();
        let mut best: Option<(f64, &str)> = None;
        for candidate in BOX_CANDIDATES {
            if let Some(m) = design_median(env, candidate, random, expert)
                && best.is_none_or(|(b, _)| m > b)
            {
                best = Some((m, candidate));
            }
        }
        assert_eq!(
            best.map(|(_, c)| c),
            Some(BOX_HELD_OUT_RULE),
            "{env}: the rule fixed for the continuous held-out test is not the design seeds' choice"
        );
    }
}

/// Every entry of effort.md's "What the expert's effort buys" tables is the median AUC of that rule's runs at
/// that budget on every seed outside the held-out ones, recomputed from their eval.csv.
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
                let ours = screen_median_in(&dir, *random, *expert).unwrap_or_else(|| {
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

/// effort.md's screen table, recomputed from effort_comparisons.csv (the Holm-adjusted p-values and shifts that
/// `every_comparison_is_recomputed_from_the_runs` checks): per task, the rules significantly higher than all three
/// paper rules, higher than some, and lower than some.
#[test]
fn the_screen_lists_the_rules_that_differ_from_the_paper_rules() {
    let rows = effort_rows();
    let cells = paper_budget_rows(&rows);
    let section = effort_md_section("The screen at the paper's budget");
    let comparisons = comparison_rows();
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
        let (mut all, mut some, mut lower) = (Vec::new(), Vec::new(), Vec::new());
        let (mut claims, mut aboves) = (Vec::new(), Vec::new());
        let mut rules: Vec<&str> = of_env
            .iter()
            .map(|r| r["rule"].as_str())
            .filter(|rule| !baselines.iter().any(|b| b.0 == *rule))
            .collect();
        rules.sort();
        for rule in rules {
            let row = of_env.iter().find(|r| r["rule"] == rule).unwrap();
            let (mut above, mut below) = (Vec::new(), Vec::new());
            let mut one_sided: Vec<Option<f64>> = Vec::new();
            for (label, name, _) in baselines {
                // The Holm-adjusted p of the task's screen family (recomputed from the runs by
                // `every_comparison_is_recomputed_from_the_runs`) and the sign of the shift.
                let Some(c) = comparisons.iter().find(|c| {
                    c["env"] == env
                        && c["rule"] == rule
                        && c["against"] == label
                        && c["net"] == "bootstrap"
                        && c["held_out"] == "false"
                        && c["budget"] == row["budget"]
                        && c["against_budget"] == row["budget"]
                }) else {
                    one_sided.push(None);
                    continue;
                };
                one_sided.push(c["p_greater"].parse().ok());
                let p: f64 = match c["p_holm"].as_str() {
                    "" => continue,
                    text => text.parse().unwrap(),
                };
                if p < 0.05 {
                    if c["shift"].parse::<f64>().unwrap() > 0.0 {
                        above.push(name);
                    } else {
                        below.push(name);
                    }
                }
            }
            let named = |v: &[&str]| format!("{rule} ({})", v.join(", "));
            // "Above all three": the largest of the three one-sided p-values (the intersection-union test).
            let iut: Option<f64> = one_sided
                .iter()
                .try_fold(0.0_f64, |worst, p| p.map(|p| worst.max(p)));
            claims.push((rule.to_string(), iut));
            aboves.push((rule.to_string(), named(&above), above.is_empty()));
            if !below.is_empty() {
                lower.push(named(&below));
            }
        }
        // Holm over the task's claims, then the rules whose adjusted p is below the level.
        let mut order: Vec<usize> = (0..claims.len())
            .filter(|&i| claims[i].1.is_some())
            .collect();
        order.sort_by(|&i, &j| {
            claims[i]
                .1
                .unwrap()
                .partial_cmp(&claims[j].1.unwrap())
                .unwrap()
        });
        let mut adjusted = vec![None; claims.len()];
        let mut running: f64 = 0.0;
        for (rank, &i) in order.iter().enumerate() {
            running = running.max(((order.len() - rank) as f64 * claims[i].1.unwrap()).min(1.0));
            adjusted[i] = Some(running);
        }
        for (i, (rule, text, none_above)) in aboves.iter().enumerate() {
            match adjusted[i] {
                Some(p) if p < 0.05 => {
                    let shown = if p < 0.001 {
                        "<0.001".to_string()
                    } else {
                        format!("{p:.3}")
                    };
                    all.push(format!("{rule} (Holm {shown})"));
                }
                _ if !none_above => some.push(text.clone()),
                _ => {}
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
    use arld::lab::protocol::{PAPER_SEEDS, effort_grids, held_out_grids};
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

/// A line of a CSV file split into fields (double-quoted fields may hold commas and doubled quotes).
fn csv_fields(line: &str) -> Vec<String> {
    let (mut fields, mut field, mut quoted, mut chars) =
        (Vec::new(), String::new(), false, line.chars().peekable());
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut field)),
            _ => field.push(c),
        }
    }
    fields.push(field);
    fields
}

/// The exactly rounded sum of `values`, in 128-bit fixed point at 2^-80 (every evaluation mean of these runs is a
/// multiple of 2^-80 well inside the range), rounded to f64 once at the end.
fn fixed_point_sum(values: &[f64]) -> f64 {
    const SCALE: f64 = (1u128 << 80) as f64;
    let total: i128 = values
        .iter()
        .map(|&v| {
            let scaled = v * SCALE;
            assert!(
                scaled.fract() == 0.0 && scaled.abs() < 1e38,
                "{v} is not a multiple of 2^-80"
            );
            scaled as i128
        })
        .sum();
    total as f64 / SCALE
}

/// The AUC of a run as effort.md defines it: the mean evaluation return (summed exactly), normalised.
fn exact_run_auc(dir: &Path, random: f64, expert: f64) -> f64 {
    let text = std::fs::read_to_string(dir.join("eval.csv")).unwrap();
    let means: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse::<f64>().unwrap())
        .collect();
    (fixed_point_sum(&means) / means.len() as f64 - random) / (expert - random)
}

/// P(Z > z) for the standard normal.
fn upper_tail(z: f64) -> f64 {
    0.5 * libm::erfc(z / std::f64::consts::SQRT_2)
}

/// Two-sided Mann-Whitney p (normal approximation with tie and continuity corrections), by counting pairs.
fn mw_p(a: &[f64], b: &[f64]) -> Option<f64> {
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    let u: f64 = a
        .iter()
        .map(|x| {
            b.iter()
                .map(|y| {
                    if x > y {
                        1.0
                    } else if x == y {
                        0.5
                    } else {
                        0.0
                    }
                })
                .sum::<f64>()
        })
        .sum();
    let mut all: Vec<f64> = a.iter().chain(b).copied().collect();
    all.sort_by(|x, y| x.partial_cmp(y).unwrap());
    let mut ties = 0.0;
    for group in all.chunk_by(|x, y| x == y) {
        let t = group.len() as f64;
        ties += t * t * t - t;
    }
    let n = n1 + n2;
    let var = n1 * n2 / 12.0 * ((n + 1.0) - ties / (n * (n - 1.0)));
    if var <= 0.0 {
        return None;
    }
    let z = ((u - n1 * n2 / 2.0).abs() - 0.5) / var.sqrt();
    Some((2.0 * upper_tail(z)).min(1.0))
}

/// The Hodges-Lehmann shift of a over b and its 95% interval: the k-th smallest and largest differences, k the
/// largest count with P(U <= k - 1) <= 0.025 under the null, from the exact null distribution of U counted as the
/// rank sums of every subset of the pooled ranks.
fn hl(a: &[f64], b: &[f64]) -> (f64, f64, f64) {
    let mut d: Vec<f64> = a
        .iter()
        .flat_map(|x| b.iter().map(move |y| x - y))
        .collect();
    d.sort_by(|x, y| x.partial_cmp(y).unwrap());
    let (m, n) = (a.len(), b.len());
    // ways[j][w]: subsets of j of the ranks 1..=i seen so far with rank sum w.
    let total_rank = (m + n) * (m + n + 1) / 2;
    let mut ways = vec![vec![0u128; total_rank + 1]; m + 1];
    ways[0][0] = 1;
    for rank in 1..=m + n {
        for j in (1..=m.min(rank)).rev() {
            for w in (rank..=total_rank).rev() {
                ways[j][w] += ways[j - 1][w - rank];
            }
        }
    }
    // U = W - m(m+1)/2.
    let offset = m * (m + 1) / 2;
    let all: u128 = ways[m].iter().sum();
    let mut cumulative = 0u128;
    let mut k = 0;
    for u in 0..=m * n {
        cumulative += ways[m][u + offset];
        if cumulative as f64 / all as f64 > 0.025 * (1.0 + 1e-12) {
            break;
        }
        k += 1;
    }
    let k = k.max(1);
    (median(d.clone()), d[k - 1], d[d.len() - k])
}

/// A decimal text such as "-123.45" as an integer at `scale` decimals.
fn scaled(text: &str, scale: usize) -> i128 {
    let (negative, digits) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text),
    };
    let (whole, fraction) = digits.split_once('.').unwrap_or((digits, ""));
    assert!(
        !digits.contains('e') && fraction.len() <= scale,
        "{text} at {scale} decimals"
    );
    let value: i128 = format!("{whole}{fraction:0<scale$}").parse().unwrap();
    if negative { -value } else { value }
}

/// A run's evaluation means as written in its eval.csv.
fn mean_texts(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join("eval.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().to_string())
        .collect()
}

/// The two-sided Wilcoxon signed-rank p of paired runs (normal approximation with tie and continuity corrections,
/// zero differences dropped), their differences taken exactly from the decimal texts of the means: a difference
/// of sums at a common scale (every run of a comparison has the same number of evaluations).
fn paired_p(a: &[PathBuf], b: &[PathBuf]) -> Option<f64> {
    let texts: Vec<(Vec<String>, Vec<String>)> = a
        .iter()
        .zip(b)
        .map(|(x, y)| (mean_texts(x), mean_texts(y)))
        .collect();
    let scale = texts
        .iter()
        .flat_map(|(x, y)| x.iter().chain(y))
        .map(|t| t.split_once('.').map_or(0, |(_, f)| f.len()))
        .max()
        .unwrap_or(0);
    let mut d: Vec<i128> = texts
        .iter()
        .map(|(x, y)| {
            assert_eq!(
                x.len(),
                y.len(),
                "runs of one comparison evaluate equally often"
            );
            x.iter().map(|t| scaled(t, scale)).sum::<i128>()
                - y.iter().map(|t| scaled(t, scale)).sum::<i128>()
        })
        .filter(|&v| v != 0)
        .collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by_key(|v| v.abs());
    let n = d.len() as f64;
    let (mut plus, mut ties) = (0.0, 0.0);
    let mut start = 0;
    for group in d.chunk_by(|x, y| x.abs() == y.abs()) {
        let t = group.len() as f64;
        let rank = start as f64 + (t + 1.0) / 2.0;
        plus += rank * group.iter().filter(|&&v| v > 0).count() as f64;
        ties += t * t * t - t;
        start += group.len();
    }
    let sigma = (n * (n + 1.0) * (2.0 * n + 1.0) / 24.0 - ties / 48.0).sqrt();
    let z = ((plus - n * (n + 1.0) / 4.0).abs() - 0.5).max(0.0) / sigma;
    Some((2.0 * upper_tail(z)).min(1.0))
}

/// The one-sided Mann-Whitney p that a lies above b (normal approximation with tie and continuity corrections).
fn mw_greater(a: &[f64], b: &[f64]) -> Option<f64> {
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    let u: f64 = a
        .iter()
        .flat_map(|x| b.iter().map(move |y| (x, y)))
        .map(|(x, y)| {
            if x > y {
                1.0
            } else if x == y {
                0.5
            } else {
                0.0
            }
        })
        .sum();
    let mut all: Vec<f64> = a.iter().chain(b).copied().collect();
    all.sort_by(|x, y| x.partial_cmp(y).unwrap());
    let ties: f64 = all
        .chunk_by(|x, y| x == y)
        .map(|g| (g.len() as f64).powi(3) - g.len() as f64)
        .sum();
    let n = n1 + n2;
    let var = n1 * n2 / 12.0 * ((n + 1.0) - ties / (n * (n - 1.0)));
    (var > 0.0).then(|| upper_tail((u - n1 * n2 / 2.0 - 0.5) / var.sqrt()).min(1.0))
}

/// The runs of a cell: the directories that may hold a rule's runs at a budget (the default variant at the
/// paper's budget, `budget-B` otherwise or for held-out seeds), the seeds of the cell's group only.
fn cell_dirs(
    env: &str,
    rule: &str,
    net: &str,
    budget: &str,
    group: &str,
) -> BTreeMap<u64, PathBuf> {
    let runs = common::committed_runs().join(env);
    let paper = arld::lab::protocol::paper_budget(env).to_string();
    let (method_dir, spec) = match rule {
        "greedy (GDQN)" => (format!("gdqn-{net}"), None),
        "bernoulli (BDQN)" => (format!("bdqn-{net}"), None),
        "adaptive (ADQN)" => (format!("adqn-{net}"), None),
        "adaptive from learning_starts" => (
            format!("adqn-{net}"),
            Some("adaptive-queries_from_learning_starts-true".to_string()),
        ),
        "adaptive on action disagreement" => (
            format!("adqn-{net}"),
            Some("adaptive-uncertainty-action_disagreement".to_string()),
        ),
        spec => (format!("adqn-{net}"), Some(spelled(spec))),
    };
    let base = runs.join(method_dir);
    let mut variants = vec![match &spec {
        None => base.join(format!("budget-{budget}")),
        Some(s) => base.join(format!("budget-{budget}-query_rule-{s}")),
    }];
    if budget == paper {
        variants.push(match &spec {
            None => base.clone(),
            Some(s) => base.join(format!("query_rule-{s}")),
        });
    }
    let in_group = |seed: u64| match group {
        "true" => (100..120).contains(&seed),
        "second" => (120..140).contains(&seed),
        "continuous" => (300..340).contains(&seed),
        _ => !(100..140).contains(&seed) && !(300..340).contains(&seed),
    };
    let mut out = BTreeMap::new();
    for dir in variants {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().to_string();
            let Some(seed) = name
                .strip_prefix("seed")
                .and_then(|s| s.parse::<u64>().ok())
            else {
                continue;
            };
            if in_group(seed) && entry.path().join("summary.json").is_file() {
                out.insert(seed, entry.path());
            }
        }
    }
    out
}

/// Every comparison of a rule with a paper rule in effort_comparisons.csv, recomputed from the runs' eval.csv with
/// this file's own code: the seeds both share, the Hodges-Lehmann shift and interval, the Mann-Whitney p, and
/// Holm's adjustment within each family.
#[test]
fn every_comparison_is_recomputed_from_the_runs() {
    let refs: BTreeMap<String, (f64, f64)> = effort_rows()
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
    let rows = comparison_rows();
    let mut auc_cache: BTreeMap<PathBuf, f64> = BTreeMap::new();
    let mut families: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    let mut checked = 0;
    let mut paired_checked = 0;
    for row in &rows {
        let (env, group) = (row["env"].as_str(), row["held_out"].as_str());
        let (random, expert) = refs[env];
        let mut auc = |dir: &PathBuf| {
            *auc_cache
                .entry(dir.clone())
                .or_insert_with(|| exact_run_auc(dir, random, expert))
        };
        let a = cell_dirs(env, &row["rule"], &row["net"], &row["budget"], group);
        let b = cell_dirs(
            env,
            &row["against"],
            &row["net"],
            &row["against_budget"],
            group,
        );
        let shared: Vec<u64> = a.keys().filter(|s| b.contains_key(s)).copied().collect();
        assert_eq!(shared.len().to_string(), row["seeds"], "{row:?}");
        let xs: Vec<f64> = shared.iter().map(|s| auc(&a[s])).collect();
        let ys: Vec<f64> = shared.iter().map(|s| auc(&b[s])).collect();
        let close = |ours: f64, column: &str| {
            let theirs: f64 = row[column].parse().unwrap();
            assert!(
                (ours - theirs).abs() < 1e-9,
                "{column}: {ours} recomputed, {theirs} in the file: {row:?}"
            );
        };
        let (shift, lo, hi) = hl(&xs, &ys);
        close(shift, "shift");
        close(lo, "shift_lo");
        close(hi, "shift_hi");
        let p = mw_p(&xs, &ys);
        if let Some(p) = p {
            close(p, "p");
            let holm: f64 = row["p_holm"].parse().unwrap();
            families
                .entry(row["family"].clone())
                .or_default()
                .push((p, holm));
        } else {
            assert_eq!(row["p"], "", "{row:?}");
        }
        match mw_greater(&xs, &ys) {
            Some(p) => close(p, "p_greater"),
            None => assert_eq!(row["p_greater"], "", "{row:?}"),
        }
        let runs_a: Vec<PathBuf> = shared.iter().map(|s| a[s].clone()).collect();
        let runs_b: Vec<PathBuf> = shared.iter().map(|s| b[s].clone()).collect();
        match paired_p(&runs_a, &runs_b) {
            Some(p) => {
                close(p, "paired_p");
                paired_checked += 1;
            }
            None => assert_eq!(row["paired_p"], "", "{row:?}"),
        }
        checked += 1;
    }
    assert!(
        paired_checked >= 300,
        "{paired_checked} paired tests checked"
    );
    // Holm within each family: the i-th smallest of m p-values times (m - i + 1), made monotone, capped at 1.
    for (family, mut tests) in families {
        tests.sort_by(|x, y| x.0.partial_cmp(&y.0).unwrap());
        // The second held-out test's family is fixed at its nine comparisons; those not run yet count as p = 1.
        let fixed = if family.starts_with("the second held-out test") {
            9
        } else {
            0
        };
        let m = tests.len().max(fixed);
        let mut running: f64 = 0.0;
        for (i, (p, holm)) in tests.iter().enumerate() {
            running = running.max(((m - i) as f64 * p).min(1.0));
            assert!(
                (running - holm).abs() < 1e-9,
                "{family}: Holm {running} recomputed, {holm} in the file"
            );
        }
    }
    assert!(checked >= 300, "{checked} comparisons checked");
}

/// A NaN mean in a run's eval.csv is refused by name before any file is written (it used to panic in the
/// bootstrap).
#[test]
fn a_nan_mean_is_a_named_error() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path().join("runs");
    for method in ["bdqn", "adqn"] {
        for seed in 0..3 {
            let from = common::committed_runs().join(format!(
                "Acrobot-v1/{method}-bootstrap/budget-25/seed{seed}"
            ));
            let to = runs.join(format!(
                "Acrobot-v1/{method}-bootstrap/budget-25/seed{seed}"
            ));
            std::fs::create_dir_all(&to).unwrap();
            for file in ["config.toml", "eval.csv", "summary.json", "queries.csv"] {
                if from.join(file).is_file() {
                    std::fs::copy(from.join(file), to.join(file)).unwrap();
                }
            }
        }
    }
    let eval = runs.join("Acrobot-v1/bdqn-bootstrap/budget-25/seed1/eval.csv");
    let text = std::fs::read_to_string(&eval).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut fields: Vec<String> = lines[2].split(',').map(String::from).collect();
    fields[1] = "NaN".into();
    lines[2] = fields.join(",");
    std::fs::write(&eval, lines.join("\n") + "\n").unwrap();
    let out = tmp.path().join("report");
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_arld"))
        .args([
            "report",
            runs.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains("seed1: eval.csv has a mean of NaN at step"),
        "{stderr}"
    );
    assert!(!out.join("effort.md").exists() && !out.join("table.md").exists());
}

/// The rows of results/effort_comparisons.csv as maps from column name to text.
fn comparison_rows() -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(results().join("effort_comparisons.csv")).unwrap();
    let mut lines = text.lines();
    let header = csv_fields(lines.next().unwrap());
    lines
        .map(|l| header.iter().cloned().zip(csv_fields(l)).collect())
        .collect()
}

/// The paired p the audit of issue 51 computed with the tie between two paired differences kept (CartPole-v0,
/// ranked(horizon=0.1) against GDQN at the paper's budget: 0.3506, where float subtraction had given 0.3411).
#[test]
fn the_paired_test_keeps_the_audits_tie() {
    let row = comparison_rows()
        .into_iter()
        .find(|r| {
            r["env"] == "CartPole-v0"
                && r["rule"] == "ranked(horizon=0.1)"
                && r["against"] == "greedy (GDQN)"
                && r["net"] == "bootstrap"
                && r["held_out"] == "false"
        })
        .expect("the comparison");
    let p: f64 = row["paired_p"].parse().unwrap();
    assert!((p - 0.3506).abs() < 5e-5, "paired p {p}");
}

/// Every effort multiple of effort.csv, recomputed from the runs with this file's own code: the rule's median AUC
/// read on asking at random's curve of median AUCs (BDQN, bootstrapped heads, seeds outside the held-out ones) over
/// its budgets, made non-decreasing by pooling adjacent violators and interpolated linearly in log budget, as a
/// multiple of the rule's budget; censored (">" or "<" the curve's range) outside it.
#[test]
fn every_effort_multiple_is_read_on_the_curve_of_asking_at_random() {
    let rows = effort_rows();
    let medians = |env: &str, rule: &str, budget: &str, group: &str, random: f64, expert: f64| {
        let dirs = cell_dirs(env, rule, "bootstrap", budget, group);
        median(
            dirs.values()
                .map(|d| exact_run_auc(d, random, expert))
                .collect(),
        )
    };
    let mut checked = 0;
    for row in rows.iter().filter(|r| !r["effort_multiple"].is_empty()) {
        let env = row["env"].as_str();
        let (random, expert): (f64, f64) = (
            row["random_return"].parse().unwrap(),
            row["expert_return"].parse().unwrap(),
        );
        let mut budgets: Vec<u64> = rows
            .iter()
            .filter(|r| {
                r["env"] == env
                    && r["rule"] == "bernoulli (BDQN)"
                    && r["net"] == "bootstrap"
                    && r["held_out"] == "false"
            })
            .map(|r| r["budget"].parse().unwrap())
            .collect();
        budgets.sort();
        let curve: Vec<f64> = budgets
            .iter()
            .map(|b| {
                medians(
                    env,
                    "bernoulli (BDQN)",
                    &b.to_string(),
                    "false",
                    random,
                    expert,
                )
            })
            .collect();
        // Pool adjacent violators: each point the mean of its block.
        let mut blocks: Vec<(f64, usize)> = Vec::new();
        for &v in &curve {
            blocks.push((v, 1));
            while blocks.len() > 1 {
                let (s1, c1) = blocks[blocks.len() - 1];
                let (s0, c0) = blocks[blocks.len() - 2];
                if s0 / c0 as f64 <= s1 / c1 as f64 {
                    break;
                }
                blocks.pop();
                *blocks.last_mut().unwrap() = (s0 + s1, c0 + c1);
            }
        }
        let fitted: Vec<f64> = blocks
            .iter()
            .flat_map(|&(s, c)| std::iter::repeat_n(s / c as f64, c))
            .collect();
        let y = medians(
            env,
            &row["rule"],
            &row["budget"],
            &row["held_out"],
            random,
            expert,
        );
        let budget: f64 = row["budget"].parse().unwrap();
        let expected = if y < fitted[0] {
            format!("<{}", budgets[0] as f64 / budget)
        } else if y == fitted[0] {
            format!("{}", budgets[0] as f64 / budget)
        } else if y > fitted[fitted.len() - 1] {
            format!(">{}", budgets[budgets.len() - 1] as f64 / budget)
        } else {
            let i = (1..fitted.len()).find(|&i| fitted[i] >= y).unwrap();
            let (x0, x1) = ((budgets[i - 1] as f64).ln(), (budgets[i] as f64).ln());
            let t = (y - fitted[i - 1]) / (fitted[i] - fitted[i - 1]);
            format!("{}", (x0 + t * (x1 - x0)).exp() / budget)
        };
        let theirs = &row["effort_multiple"];
        match (expected.parse::<f64>(), theirs.parse::<f64>()) {
            (Ok(ours), Ok(them)) => assert!(
                (ours - them).abs() < 1e-6 * ours.abs().max(1.0),
                "{row:?}: {ours} recomputed"
            ),
            _ => assert_eq!(&expected, theirs, "{row:?}"),
        }
        checked += 1;
    }
    assert!(checked >= 100, "{checked} effort multiples checked");
}
