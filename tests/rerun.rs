//! The committed runs are reproducible: a few short runs of `results/runs`, drawn with a seeded generator over
//! every committed CartPole-v0 and Acrobot-v1 run of today's numerics, are computed again from their own
//! `config.toml` and must give `eval.csv` and `queries.csv` byte for byte.
//!
//! The draw's seed is `DRAW_SEED`, or `ARLD_RERUN_DRAW` when set: another seed checks another sample. Every
//! committed run, of every task, must be of today's numerics (its summary.json says `"numerics":
//! "correctly-rounded"`): a run of the older numerics depended on the CPU's elementary functions.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use arld::rng::NumpyRng;
use arld::train::run_dir;

use common::ARLD;

/// The draw's seed when `ARLD_RERUN_DRAW` is not set.
const DRAW_SEED: u64 = 20261124;
/// How many runs of each task are computed again (CartPole-v0 runs take about 2 s, Acrobot-v1 about 10 s).
const DRAWS: [(&str, usize); 2] = [("CartPole-v0", 3), ("Acrobot-v1", 1)];

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn is_current_numerics(run: &Path) -> bool {
    let text = std::fs::read_to_string(run.join("summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("{}: summary.json: {e}", run.display()));
    summary.get("numerics").and_then(|v| v.as_str()) == Some("correctly-rounded")
}

/// `count` distinct entries of `runs`, drawn uniformly without replacement.
fn draw(runs: &[PathBuf], count: usize, rng: &mut NumpyRng) -> Vec<PathBuf> {
    let mut pool = runs.to_vec();
    let mut chosen = Vec::new();
    while chosen.len() < count && !pool.is_empty() {
        let i = ((rng.random() * pool.len() as f64) as usize).min(pool.len() - 1);
        chosen.push(pool.swap_remove(i));
    }
    chosen
}

/// `results/report.md` counts 0 runs of older numerics because there are none: checked here over every committed
/// run, independently of the report.
#[test]
fn every_committed_run_is_of_todays_numerics() {
    let all = run_dir::find_runs(common::committed_runs(), |_| {}).unwrap();
    let older: Vec<&PathBuf> = all.iter().filter(|r| !is_current_numerics(r)).collect();
    assert!(
        older.is_empty(),
        "{} of {} committed runs are of the older numerics, such as {}",
        older.len(),
        all.len(),
        older
            .first()
            .map(|r| r.display().to_string())
            .unwrap_or_default()
    );
    let report = std::fs::read_to_string(repo().join("results/report.md")).unwrap();
    assert!(
        report.contains(&format!("- 0 of {} runs are of older numerics", all.len())),
        "results/report.md does not count 0 of the {} committed runs as older numerics",
        all.len()
    );
}

#[test]
fn committed_short_runs_compute_again_byte_for_byte() {
    let seed = match std::env::var("ARLD_RERUN_DRAW") {
        Ok(text) => text
            .parse()
            .unwrap_or_else(|_| panic!("ARLD_RERUN_DRAW={text:?} is not an unsigned integer")),
        Err(_) => DRAW_SEED,
    };
    let mut rng = NumpyRng::new(seed);
    let out = tempfile::tempdir().unwrap();
    for (env, count) in DRAWS {
        let root = common::committed_runs().join(env);
        let all = run_dir::find_runs(&root, |_| {}).unwrap();
        assert!(
            all.len() >= count,
            "{env}: only {} committed runs",
            all.len()
        );
        for (k, run) in draw(&all, count, &mut rng).iter().enumerate() {
            let fresh = out.path().join(format!("{env}-{k}"));
            let status = Command::new(ARLD)
                .current_dir(repo())
                .args(["train", "--quiet", "--config"])
                .arg(run.join("config.toml"))
                .arg("-o")
                .arg(&fresh)
                .output()
                .expect("arld runs");
            assert!(
                status.status.success(),
                "arld train --config {}/config.toml failed: {}",
                run.display(),
                String::from_utf8_lossy(&status.stderr)
            );
            for file in ["eval.csv", "queries.csv"] {
                let committed = std::fs::read(run.join(file)).unwrap();
                let again = std::fs::read(fresh.join(file)).unwrap();
                assert!(
                    committed.len() > 20,
                    "{}/{file} is nearly empty",
                    run.display()
                );
                assert!(
                    committed == again,
                    "{}/{file} differs when the run is computed again (draw seed {seed})",
                    run.display()
                );
            }
        }
    }
}
