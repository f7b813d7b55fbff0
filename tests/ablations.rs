//! The ablation keys of the open choices (docs/algorithm.md section 8): each changes what it says and only that,
//! checked on real runs against counts recomputed from the run's own episode and query logs.

use arld::lab::run_one;
use arld::train::{ConfigInput, Method, NetKind, TrainConfig, run_dir};
use std::path::Path;

fn config(method: Method, overrides: &[&str]) -> TrainConfig {
    let mut input = ConfigInput::new("CartPole-v0", method, NetKind::Bootstrap, 7);
    for o in ["train_steps=2000", "eval_period=1000"]
        .iter()
        .chain(overrides)
    {
        input.apply_override(o).unwrap();
    }
    input.resolve().unwrap()
}

/// (length, demonstrated steps) of every episode, from episodes.csv.
fn episodes(dir: &Path) -> Vec<(usize, usize)> {
    let text = std::fs::read_to_string(dir.join("episodes.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("episode,step,return,length,demo_steps"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[3].parse().unwrap(), f[4].parse().unwrap())
        })
        .collect()
}

#[test]
fn queries_from_learning_starts_asks_nothing_before_the_first_update() {
    let dir = tempfile::tempdir().unwrap();
    let first_query = |overrides: &[&str], name: &str| -> (usize, u64) {
        let cfg = config(Method::Adqn, overrides);
        let out = dir.path().join(name);
        run_one(&cfg, Some(&out), false).unwrap();
        let steps = run_dir::read_query_steps(&out).unwrap().unwrap();
        (cfg.learning_starts, *steps.first().expect("some queries"))
    };
    // The paper's rule asks from the first steps, before any update.
    let (learning_starts, first) = first_query(&[], "default");
    assert!((first as usize) < learning_starts, "first query at {first}");
    // The ablation: the first update comes after step learning_starts - 1, and so does the first query.
    let (learning_starts, first) = first_query(&["queries_from_learning_starts=true"], "ablation");
    assert!(
        first as usize + 1 >= learning_starts,
        "first query at {first}, learning starts at {learning_starts}"
    );
}

#[test]
fn a_budget_in_queries_buys_whole_segments() {
    // Greedy queries from the first step: with the budget in queries, query k's segment runs min(5, steps left in
    // its episode), so the transitions demonstrated follow from the episode lengths alone.
    let dir = tempfile::tempdir().unwrap();
    let budget = 30;
    let cfg = config(
        Method::Gdqn,
        &[&format!("budget={budget}"), "budget_unit=queries"],
    );
    let summary = run_one(&cfg, Some(dir.path()), false).unwrap();
    let log = episodes(dir.path());

    let (mut queries_left, mut expected) = (budget, Vec::new());
    for &(length, _) in &log {
        let mut demonstrated = 0;
        let mut t = 0;
        while t < length && queries_left > 0 {
            let segment = cfg.segment_len.min(length - t);
            demonstrated += segment;
            t += segment;
            queries_left -= 1;
        }
        expected.push(demonstrated);
    }
    let logged: Vec<usize> = log.iter().map(|&(_, d)| d).collect();
    assert_eq!(logged, expected);
    assert_eq!(summary.demos_queried, expected.iter().sum::<usize>());
    assert!(
        summary.demos_queried > budget,
        "more transitions than queries"
    );
    let query_rows = run_dir::read_query_steps(dir.path()).unwrap().unwrap();
    assert_eq!(query_rows.len(), budget);

    // The paper's reading: the same number spends transitions, the last segment cut at the budget.
    let cfg = config(Method::Gdqn, &[&format!("budget={budget}")]);
    let summary = run_one(&cfg, None, false).unwrap();
    assert_eq!(summary.demos_queried, budget);
}
