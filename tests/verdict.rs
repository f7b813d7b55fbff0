//! The committed results regenerate from the committed per-run files (`results/runs/`): one cell of
//! `results/readings.csv` and one row of `results/ablations.csv` recomputed directly from the runs' `eval.csv`
//! files with code independent of the library's statistics, every committed table rebuilt by
//! `arld report results/runs`, the verdict tables rebuilt again from `results/evaluations.csv.gz` alone, and the
//! README's results table the committed one.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::ARLD;

fn results() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/results"))
}

/// The default-variant run directories of one configuration: `results/runs/ENV/METHOD-NET/seedN`.
fn run_dirs(env: &str, method: &str, net: &str) -> BTreeMap<u64, PathBuf> {
    variant_run_dirs(env, method, net, "")
}

/// The run directories of one configuration: `results/runs/ENV/METHOD-NET/VARIANT/seedN` (`""`: the default).
fn variant_run_dirs(env: &str, method: &str, net: &str, variant: &str) -> BTreeMap<u64, PathBuf> {
    let dir = common::committed_runs()
        .join(env)
        .join(format!("{method}-{net}"))
        .join(variant);
    std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(|entry| {
            let path = entry.unwrap().path();
            let seed = path
                .file_name()?
                .to_str()?
                .strip_prefix("seed")?
                .parse()
                .ok()?;
            Some((seed, path))
        })
        .collect()
}

/// The (step, mean) points of one run's eval.csv, straight from the CSV text.
fn curve(run: &Path) -> Vec<(u64, f64)> {
    let text = std::fs::read_to_string(run.join("eval.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("step,mean,std,min,max"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0].parse().unwrap(), f[1].parse().unwrap())
        })
        .collect()
}

/// An integer key of the run's config.toml, read as text.
fn config_value(run: &Path, key: &str) -> u64 {
    let text = std::fs::read_to_string(run.join("config.toml")).unwrap();
    text.lines()
        .find_map(|l| l.strip_prefix(&format!("{key} = ")))
        .unwrap_or_else(|| panic!("{key} in {}", run.display()))
        .parse()
        .unwrap()
}

fn middle(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// The row of a committed CSV table whose line starts with `key` (its first columns, comma-separated).
fn committed_row(table: &str, key: &str) -> BTreeMap<String, String> {
    let text = std::fs::read_to_string(results().join(table)).expect("the committed table");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let row = lines
        .find(|l| l.starts_with(&format!("{key},")))
        .unwrap_or_else(|| panic!("{key} is in {table}"));
    header
        .iter()
        .map(|h| h.to_string())
        .zip(row.split(',').map(str::to_string))
        .collect()
}

#[test]
fn acrobot_gdqn_cell_recomputed_from_the_per_run_files() {
    // GDQN-B on Acrobot: many seeds hit -100 at the first test and then fall back, so the readings differ.
    let (target, k) = (-100.0, 3usize);
    let runs = run_dirs("Acrobot-v1", "gdqn", "bootstrap");
    assert_eq!(runs.len(), 20);
    let mut first = Vec::new();
    let mut held = Vec::new();
    let mut finals = Vec::new();
    for run in runs.values() {
        let train_steps = config_value(run, "train_steps");
        let curve = curve(run);
        let hit = curve
            .iter()
            .find(|p| p.1 >= target)
            .map_or(train_steps, |p| p.0);
        first.push(hit as f64);
        let mut sustained = train_steps;
        for i in 0..curve.len() {
            let end = (i + k).min(curve.len() - 1);
            if (i..=end).all(|j| curve[j].1 >= target) {
                sustained = curve[i].0;
                break;
            }
        }
        held.push(sustained as f64);
        let last: Vec<f64> = curve.iter().rev().take(10).map(|p| p.1).collect();
        finals.push(last.iter().sum::<f64>() / last.len() as f64);
    }
    let row = committed_row("readings.csv", "Acrobot-v1,gdqn,bootstrap");
    assert_eq!(row["seeds"], "20");
    let number = |key: &str| row[key].parse::<f64>().unwrap();
    assert_eq!(number("first_hit_median"), middle(first));
    assert_eq!(number("sustained_median"), middle(held));
    let final_median = middle(finals);
    // Written with two decimals.
    assert!(
        (number("final_score_median") - final_median).abs() <= 0.005 + 1e-9,
        "final score {} vs {final_median}",
        row["final_score_median"]
    );
}

/// First-hit steps of every seed of a configuration: the first evaluation at `target`, or the whole run.
fn first_hits(runs: &BTreeMap<u64, PathBuf>, target: f64) -> Vec<f64> {
    runs.values()
        .map(|run| {
            let train_steps = config_value(run, "train_steps");
            curve(run)
                .iter()
                .find(|p| p.1 >= target)
                .map_or(train_steps, |p| p.0) as f64
        })
        .collect()
}

#[test]
fn mountaincar_time_limit_ablation_row_recomputed_from_the_per_run_files() {
    // DQN-B on MountainCar-v0 with time limits as terminal against its default: the ablation that finds why
    // our DQN fails there, so the row VERDICT.md leans on most.
    let target = -110.0;
    let ablation = variant_run_dirs(
        "MountainCar-v0",
        "dqn",
        "bootstrap",
        "timeout_as_terminal-true",
    );
    let default = run_dirs("MountainCar-v0", "dqn", "bootstrap");
    assert_eq!((ablation.len(), default.len()), (20, 20));
    let (hits, default_hits) = (first_hits(&ablation, target), first_hits(&default, target));
    let solved = |runs: &BTreeMap<u64, PathBuf>| {
        runs.values()
            .filter(|run| curve(run).iter().any(|p| p.1 >= target))
            .count()
            .to_string()
    };
    let row = committed_row(
        "ablations.csv",
        "MountainCar-v0,timeout_as_terminal-true,dqn,bootstrap",
    );
    let number = |key: &str| row[key].parse::<f64>().unwrap();
    assert_eq!(row["seeds"], "20");
    assert_eq!(row["solved"], solved(&ablation));
    assert_eq!(row["default_solved"], solved(&default));
    assert_eq!(number("first_hit_median"), middle(hits));
    assert_eq!(number("default_first_hit_median"), middle(default_hits));
}

fn arld(args: &[&str], out: &Path) {
    // From the repository's root, so that paths in the outputs read as in the committed files.
    let status = Command::new(ARLD)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .arg("-o")
        .arg(out)
        .output()
        .expect("arld runs");
    assert!(
        status.status.success(),
        "arld {args:?}: {}",
        String::from_utf8_lossy(&status.stderr)
    );
}

fn assert_same(fresh: &Path, names: &[&str]) {
    for name in names {
        let new = std::fs::read(fresh.join(name)).unwrap();
        let committed = std::fs::read(results().join(name)).unwrap();
        assert!(
            new == committed,
            "results/{name} does not match a fresh computation"
        );
    }
}

const VERDICT_TABLES: [&str; 6] = [
    "readings.md",
    "readings.csv",
    "claims.md",
    "claims.csv",
    "ablations.md",
    "ablations.csv",
];

/// The whole report, and VERDICT.md rendered from VERDICT.in.md's quotes of it: a number VERDICT.md gives is
/// the committed tables' (and the report fails, naming the sentence, when a difference the text relies on has
/// crossed its threshold).
#[test]
fn committed_tables_regenerate_from_the_per_run_files() {
    let out = tempfile::tempdir().unwrap();
    std::fs::copy(
        results().join("VERDICT.in.md"),
        out.path().join("VERDICT.in.md"),
    )
    .unwrap();
    arld(&["report", "results/runs"], out.path());
    assert_same(out.path(), &VERDICT_TABLES);
    assert_same(
        out.path(),
        &[
            "table.md",
            "table.csv",
            "evaluations.csv.gz",
            "report.md",
            "effort.md",
            "effort.csv",
            "VERDICT.md",
        ],
    );
}

#[test]
fn the_readmes_results_table_is_the_committed_table() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let block = readme
        .split("<!-- RESULTS -->\n")
        .nth(1)
        .and_then(|rest| rest.split("<!-- /RESULTS -->").next())
        .expect("README.md has a <!-- RESULTS --> block");
    let table = std::fs::read_to_string(results().join("table.md")).unwrap();
    let rows: String = table
        .lines()
        .filter(|l| l.starts_with('|'))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_eq!(
        block, rows,
        "README.md's results table is not results/table.md's (copy the table's rows between the markers)"
    );
}

#[test]
fn committed_verdict_tables_regenerate_from_the_evaluations_alone() {
    let out = tempfile::tempdir().unwrap();
    let evaluations = results().join("evaluations.csv.gz");
    arld(
        &[
            "report",
            "--from-evaluations",
            evaluations.to_str().unwrap(),
        ],
        out.path(),
    );
    assert_same(out.path(), &VERDICT_TABLES);
}
