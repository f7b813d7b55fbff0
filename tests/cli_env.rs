//! The `arld env` subcommands as a user runs them: exit codes and messages, especially on bad input.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Output;

mod common;
use common::{arld, stderr, stdout};

/// A failed run: non-zero exit, no panic, and `needles` in the error message.
fn assert_clean_failure(output: &Output, needles: &[&str]) {
    let message = stderr(output);
    assert!(!output.status.success(), "expected failure, got {output:?}");
    assert!(!message.contains("panicked"), "panicked: {message}");
    for needle in needles {
        assert!(
            message.contains(needle),
            "'{needle}' missing from: {message}"
        );
    }
}

fn write_trace(dir: &Path, name: &str, lines: &[&str]) -> PathBuf {
    let path = dir.join(name);
    let mut file = std::fs::File::create(&path).unwrap();
    for line in lines {
        writeln!(file, "{line}").unwrap();
    }
    path
}

fn classic_trace() -> PathBuf {
    let dir = match std::env::var_os("ARLD_CONFORMANCE_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/conformance"),
    };
    let path = dir.join("classic_control.jsonl");
    assert!(
        path.is_file(),
        "{} missing; set ARLD_CONFORMANCE_DIR",
        path.display()
    );
    path
}

/// The first lines of the real CartPole trace: meta, start of seed 0, its first step.
const META: &str = r#"{"kind":"meta"}"#;
const START: &str = r#"{"kind":"start","env":"CartPole-v1","case":"seed","seed":0,"action_seed":0,"n_actions":2,"max_episode_steps":500,"obs":[0.013696168549358845,-0.023021329194307327,-0.04590264707803726,-0.04834723472595215]}"#;
const STEP: &str = r#"{"kind":"step","env":"CartPole-v1","case":"seed","seed":0,"t":1,"action":1,"obs":[0.013235742226243019,0.17272774875164032,-0.04686959087848663,-0.3551521897315979],"reward":1.0,"terminated":false,"truncated":false}"#;

#[test]
fn check_passes_on_the_classic_control_trace() {
    let output = arld(&["env", "check", classic_trace().to_str().unwrap()]);
    let table = stdout(&output);
    assert!(output.status.success(), "{table}\n{}", stderr(&output));
    for id in ["CartPole-v1", "Acrobot-v1", "MountainCar-v0"] {
        let row = table.lines().find(|line| line.contains(id)).expect(id);
        assert!(row.contains("PASS"), "{row}");
    }
}

#[test]
fn check_passes_on_a_hand_cut_trace() {
    let dir = tempfile::tempdir().unwrap();
    let trace = write_trace(dir.path(), "ok.jsonl", &[META, START, STEP]);
    let output = arld(&["env", "check", trace.to_str().unwrap()]);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(stdout(&output).contains("PASS"));
}

#[test]
fn check_fails_with_exit_code_on_divergence() {
    let dir = tempfile::tempdir().unwrap();
    // Same step with the cart 0.01 further right than Gymnasium put it.
    let shifted = STEP.replace("0.013235742226243019", "0.023235742226243019");
    let trace = write_trace(dir.path(), "off.jsonl", &[META, START, &shifted]);
    let output = arld(&["env", "check", trace.to_str().unwrap()]);
    assert_eq!(output.status.code(), Some(1), "{output:?}");
    let table = stdout(&output);
    assert!(
        table.contains("FAIL") && table.contains("line 3"),
        "{table}"
    );
}

#[test]
fn malformed_line_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let trace = write_trace(
        dir.path(),
        "bad.jsonl",
        &[META, START, "{\"kind\": \"step\", nope"],
    );
    let output = arld(&["env", "check", trace.to_str().unwrap()]);
    assert_clean_failure(&output, &["bad.jsonl:3:", "malformed"]);
}

#[test]
fn unknown_env_in_trace_lists_known_ids() {
    let dir = tempfile::tempdir().unwrap();
    let start = START.replace("CartPole-v1", "CartPole-v9");
    let trace = write_trace(dir.path(), "unknown.jsonl", &[META, &start]);
    let output = arld(&["env", "check", trace.to_str().unwrap()]);
    assert_clean_failure(
        &output,
        &[
            "unknown.jsonl:2:",
            "CartPole-v9",
            "arld's tasks",
            "Acrobot-v1",
            "Pendulum-v1",
        ],
    );
}

#[test]
fn action_out_of_range_in_trace_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let step = STEP.replace(r#""action":1"#, r#""action":7"#);
    let trace = write_trace(dir.path(), "action.jsonl", &[META, START, &step]);
    let output = arld(&["env", "check", trace.to_str().unwrap()]);
    assert_clean_failure(&output, &["action.jsonl:3:", "action 7 is out of range"]);
}

#[test]
fn missing_trace_file_is_reported() {
    let output = arld(&["env", "check", "/nonexistent/trace.jsonl"]);
    assert_clean_failure(&output, &["/nonexistent/trace.jsonl"]);
}

#[test]
fn rollout_unknown_env_lists_known_ids() {
    let output = arld(&["env", "rollout", "--env", "Pendulum-v2", "--episodes", "2"]);
    assert_clean_failure(
        &output,
        &[
            "Pendulum-v2",
            "arld's tasks",
            "CartPole-v0",
            "MountainCar-v0",
            "Pendulum-v1",
        ],
    );
}

#[test]
fn rollout_rejects_zero_episodes() {
    let output = arld(&["env", "rollout", "--env", "CartPole-v1", "--episodes", "0"]);
    assert_clean_failure(&output, &["--episodes"]);
}

/// JSON rollout: reproducible from the seed, and on CartPole (reward 1 per step) return equals length.
#[test]
fn rollout_json_is_reproducible_and_consistent() {
    let args = [
        "env",
        "rollout",
        "--env",
        "CartPole-v0",
        "--episodes",
        "20",
        "--seed",
        "3",
        "--json",
    ];
    let first = arld(&args);
    let second = arld(&args);
    assert!(first.status.success(), "{}", stderr(&first));
    assert_eq!(first.stdout, second.stdout);
    let summary: serde_json::Value = serde_json::from_slice(&first.stdout).unwrap();
    assert_eq!(summary["env"], "CartPole-v0");
    assert_eq!(summary["episodes"], 20);
    assert_eq!(summary["return_mean"], summary["length_mean"]);
    let length_mean = summary["length_mean"].as_f64().unwrap();
    assert!((8.0..=200.0).contains(&length_mean), "{summary}");
    let other_seed = arld(&[
        "env",
        "rollout",
        "--env",
        "CartPole-v0",
        "--episodes",
        "20",
        "--seed",
        "4",
        "--json",
    ]);
    assert_ne!(first.stdout, other_seed.stdout);
}

/// Every task of the registry, discrete and with actions in a box, in `env list`; each box task's bounds as its
/// spec gives them.
#[test]
fn list_shows_every_task_of_both_kinds() {
    let output = arld(&["env", "list"]);
    let table = stdout(&output);
    assert!(output.status.success(), "{}", stderr(&output));
    for task in &arld::env::registry::TASKS {
        let row = table
            .lines()
            .find(|line| line.split_whitespace().next() == Some(task.id))
            .unwrap_or_else(|| panic!("{} missing from:\n{table}", task.id));
        let (obs_dim, max_steps, _) = task.facts();
        let fields: Vec<&str> = row.split_whitespace().collect();
        assert!(fields.contains(&obs_dim.to_string().as_str()), "{row}");
        assert!(fields.contains(&max_steps.to_string().as_str()), "{row}");
    }
    let lander = table
        .lines()
        .find(|l| l.starts_with("LunarLanderContinuous-v3"))
        .unwrap();
    assert!(lander.contains("box [-1, 1] x [-1, 1]"), "{lander}");
}

/// A random rollout of a box task draws actions in the box from the seed: the same seed gives the same returns,
/// and they are those of the library's environment stepped with the same draws (computed here independently).
#[test]
fn rollout_plays_box_tasks_reproducibly() {
    use arld::rng::NumpyRng;
    use rand::Rng;
    let run = |seed: &str| {
        let output = arld(&[
            "env",
            "rollout",
            "--env",
            "Pendulum-v1",
            "--episodes",
            "3",
            "--seed",
            seed,
            "--json",
        ]);
        assert!(output.status.success(), "{}", stderr(&output));
        serde_json::from_str::<serde_json::Value>(&stdout(&output)).unwrap()
    };
    let (a, b) = (run("7"), run("7"));
    assert_eq!(a, b);
    let mut env = arld::env::make_continuous("Pendulum-v1").unwrap();
    let mut rng = NumpyRng::new(7);
    let mut returns = Vec::new();
    for i in 0..3u64 {
        use arld::env::Env;
        env.reset(Some(7 + i));
        let mut total = 0.0;
        loop {
            let action = [rng.random_range(-2.0f32..2.0)];
            let step = env.step(&action).unwrap();
            total += step.reward;
            if step.terminated || step.truncated {
                break;
            }
        }
        returns.push(total);
    }
    let mean = returns.iter().sum::<f64>() / 3.0;
    let got = a["return_mean"].as_f64().unwrap();
    assert!((got - mean).abs() <= 1e-9 * mean.abs(), "{got} vs {mean}");
    assert_eq!(a["env"], "Pendulum-v1");
    assert_ne!(run("8")["return_mean"], a["return_mean"]);
}

/// `env check` reads the continuous traces (float32 action vectors, the lander recorded under the name Gymnasium
/// gives it) and passes them.
#[test]
fn check_reads_the_continuous_traces() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/continuous/conformance.jsonl");
    let output = arld(&["env", "check", path.to_str().unwrap()]);
    let table = stdout(&output);
    assert!(output.status.success(), "{table}\n{}", stderr(&output));
    for id in [
        "Pendulum-v1",
        "MountainCarContinuous-v0",
        "LunarLanderContinuous",
    ] {
        let row = table.lines().find(|line| line.contains(id)).expect(id);
        assert!(row.contains("PASS"), "{row}");
    }
}

/// A trace whose step records the other kind of action is malformed, named with its line.
#[test]
fn check_refuses_an_action_of_the_other_kind() {
    let dir = tempfile::tempdir().unwrap();
    let step = STEP.replace(r#""action":1"#, r#""action":[0.5]"#);
    let path = write_trace(dir.path(), "t.jsonl", &[META, START, &step]);
    let output = arld(&["env", "check", path.to_str().unwrap()]);
    assert_clean_failure(&output, &["t.jsonl:3", "discrete actions", "vector"]);
}

/// An unknown id is refused naming the tasks of both kinds; a continuous id that is not arld's never becomes
/// another task.
#[test]
fn unknown_ids_are_refused_with_every_task() {
    for args in [
        vec!["env", "rollout", "--env", "Pendulum-v9"],
        vec![
            "train",
            "--env",
            "MountainCarContinuous-v9",
            "--method",
            "dqn",
        ],
    ] {
        let output = arld(&args);
        assert_clean_failure(
            &output,
            &["CartPole-v0", "Pendulum-v1", "LunarLanderContinuous-v3"],
        );
    }
}
