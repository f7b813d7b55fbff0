//! Runs in a task with actions in a box, through the command line and the one run loop: TD3 asks the task's
//! scripted controller where the query rule says so, and every file of the run holds box actions. The expert's
//! answers are checked against the controller recomputed here from each stored observation, and the queries
//! against the answers.

mod common;

use arld::env::pendulum::swing_up;
use common::arld;
use serde_json::Value;

#[test]
fn an_active_td3_run_asks_the_scripted_swing_up_and_logs_box_actions() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let res = arld(&[
        "train",
        "--env",
        "Pendulum-v1",
        "--method",
        "adqn",
        "--expert",
        "scripted",
        "--set",
        "train_steps=1500",
        "--set",
        "eval_period=500",
        "--set",
        "eval_episodes=2",
        "--set",
        "hidden=[32,32]",
        "--set",
        "batch_size=32",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["train_steps"], 1500);
    assert_eq!(summary["env"], "Pendulum-v1");

    // Every answered step is the swing-up's action at its observation, one number in [-2, 2].
    let answers = std::fs::read_to_string(out.join("answers.jsonl")).unwrap();
    let steps: Vec<Value> = answers
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(!steps.is_empty(), "the expert was never asked");
    for step in &steps {
        let obs: Vec<f32> = serde_json::from_value(step["obs"].clone()).unwrap();
        let action: Vec<f32> = serde_json::from_value(step["action"].clone()).unwrap();
        assert_eq!(action, swing_up(&obs).to_vec(), "{step}");
        let proposal: Vec<f32> = serde_json::from_value(step["agent_action"].clone()).unwrap();
        assert_eq!(proposal.len(), 1);
        assert!((-2.0..=2.0).contains(&proposal[0]), "{step}");
    }
    assert_eq!(
        summary["demos_queried"].as_u64().unwrap() as usize,
        steps.len(),
        "the budget counts the answered steps"
    );

    // queries.csv: one row per question, the actions as their numbers; each question's expert action is the
    // first answer of its segment.
    let queries = std::fs::read_to_string(out.join("queries.csv")).unwrap();
    let rows: Vec<Vec<&str>> = queries
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert!(!rows.is_empty());
    for row in &rows {
        let step: usize = row[0].parse().unwrap();
        let first = steps
            .iter()
            .find(|s| s["step"].as_u64() == Some(step as u64))
            .unwrap_or_else(|| panic!("no answer at the question's step {step}"));
        let logged: f32 = row[4].parse().unwrap();
        assert_eq!(logged, first["action"][0].as_f64().unwrap() as f32);
        let agent: f32 = row[5].parse().unwrap();
        assert!((-2.0..=2.0).contains(&agent));
    }
}

#[test]
fn a_box_run_refuses_what_it_cannot_do_yet() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let res = arld(&[
        "train",
        "--env",
        "Pendulum-v1",
        "--method",
        "dqfd",
        "--expert",
        "scripted",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!res.status.success());
    let err = String::from_utf8_lossy(&res.stderr);
    assert!(err.contains("pre-trains on demonstrations"), "{err}");
}

/// `arld report` reads runs of a box task like any other: the table's cell for an active TD3 run on Pendulum-v1
/// is the run's own steps to solve (its summary), with one solved seed of one.
#[test]
fn a_report_reads_box_runs() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("runs").join("pendulum");
    let res = arld(&[
        "train",
        "--env",
        "Pendulum-v1",
        "--method",
        "adqn",
        "--set",
        "train_steps=10000",
        "-o",
        run.to_str().unwrap(),
    ]);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).unwrap()).unwrap();
    let steps = summary["steps_to_solve"].as_u64().unwrap();
    assert!(
        steps < 10_000,
        "the shipped weak expert's run did not solve: {summary}"
    );
    let report = dir.path().join("report");
    let res = arld(&[
        "report",
        dir.path().join("runs").to_str().unwrap(),
        "-o",
        report.to_str().unwrap(),
    ]);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    let table = std::fs::read_to_string(report.join("table.md")).unwrap();
    let row = table
        .lines()
        .find(|l| l.starts_with("| ADQN-B |"))
        .unwrap_or_else(|| panic!("no ADQN-B row in\n{table}"));
    assert!(row.contains(&format!("{steps}** (-) 1/1")), "{row}");
}
