//! Bad input to `arld train`, `arld expert`, `arld demo` and `arld sweep`: a clear message naming the problem,
//! a non-zero exit, no panic, and nothing written.

use std::path::Path;
use std::process::{Command, Output};

fn arld(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_arld"))
        .args(args)
        .output()
        .expect("runs")
}

/// Asserts failure with a message containing every needle, without a panic, and returns stderr.
fn fails_with(args: &[&str], needles: &[&str]) -> String {
    let out = arld(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{args:?} should fail");
    assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "{args:?}: expected '{n}' in: {stderr}");
    }
    stderr
}

#[test]
fn config_errors_are_reported_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = out.to_str().unwrap();
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--set",
            "learnin_rate=3",
            "-o",
            o,
        ],
        &["learnin_rate", "valid keys", "lr"],
    );
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--set",
            "t_query=1.5",
            "-o",
            o,
        ],
        &["t_query", "[0, 1]"],
    );
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--set",
            "budget=-3",
            "-o",
            o,
        ],
        &["budget"],
    );
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--net",
            "plain",
            "-o",
            o,
        ],
        &["plain network"],
    );
    fails_with(
        &["train", "--env", "CartPole-v9", "-o", o],
        &["CartPole-v9", "known ids", "Acrobot-v1"],
    );
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--expert",
            "oracle",
            "-o",
            o,
        ],
        &["oracle"],
    );
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "lr = [oops").unwrap();
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--config",
            bad.to_str().unwrap(),
            "-o",
            o,
        ],
        &["bad.toml", "TOML"],
    );
    std::fs::write(&bad, "gamma = \"high\"").unwrap();
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--config",
            bad.to_str().unwrap(),
            "-o",
            o,
        ],
        &["gamma"],
    );
    assert!(
        !Path::new(&out).exists(),
        "a failed start must not leave a run directory"
    );
}

#[test]
fn bad_checkpoints_and_demonstrations_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cut = dir.path().join("cut.safetensors");
    std::fs::write(&cut, b"\x10\x00\x00\x00\x00\x00\x00\x00{\"a\":").unwrap();
    let spec = format!("checkpoint:{}", cut.display());
    fails_with(
        &["expert", "eval", "--env", "CartPole-v0", "--expert", &spec],
        &["cut.safetensors"],
    );
    fails_with(
        &[
            "expert",
            "eval",
            "--env",
            "CartPole-v0",
            "--expert",
            "checkpoint:/missing.safetensors",
        ],
        &["/missing"],
    );
    // Demonstrations for MountainCar given to a CartPole run.
    let demos = dir.path().join("mc.jsonl");
    let d = demos.to_str().unwrap();
    let ok = arld(&[
        "demo",
        "collect",
        "--env",
        "MountainCar-v0",
        "--expert",
        "scripted",
        "--transitions",
        "50",
        "-o",
        d,
    ]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let out = dir.path().join("run");
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "dqfd",
            "--demos",
            d,
            "-o",
            out.to_str().unwrap(),
        ],
        &["MountainCar-v0", "CartPole-v0"],
    );
}

#[test]
fn a_short_run_writes_every_result_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = out.to_str().unwrap();
    let args = [
        "train",
        "--env",
        "CartPole-v0",
        "--method",
        "adqn",
        "--net",
        "noisy",
        "--expert",
        "scripted",
        "--set",
        "train_steps=2000",
        "--set",
        "eval_period=1000",
        "--set",
        "eval_episodes=3",
        "-o",
        o,
    ];
    let res = arld(&args);
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
    for f in [
        "config.toml",
        "eval.csv",
        "episodes.csv",
        "queries.csv",
        "weights.safetensors",
        "summary.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["train_steps"], 2000);
    assert!(
        summary["queries_used"].as_u64().unwrap() > 0
            && summary["queries_used"].as_u64().unwrap() <= 200
    );
    let queries = std::fs::read_to_string(out.join("queries.csv")).unwrap();
    assert!(queries.lines().count() > 1, "ADQN asked no query");
    let events = std::fs::read_dir(&out).unwrap().flatten().find(|e| {
        e.file_name()
            .to_string_lossy()
            .starts_with("events.out.tfevents")
    });
    let scalars = arld::tboard::read_scalars(&events.expect("event file").path()).unwrap();
    assert!(scalars.iter().any(|(tag, _, _)| tag == "eval/mean_return"));
    assert!(scalars.iter().any(|(tag, _, _)| tag == "query/budget_used"));
    assert!(
        !std::fs::read_dir(&out)
            .unwrap()
            .flatten()
            .any(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
    );
}

/// A short ADQN run with the expert in another process (`examples/expert.py` through `cmd:`): it completes, and
/// the experts that crash, hang, babble or answer out of range each stop the run with a message naming the
/// expert, a non-zero exit and no summary (the run stays incomplete).
#[test]
fn expert_process_runs_and_its_failures_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/expert.py");
    let good = format!("cmd:python3 {}", script.display());
    let run = |expert: &str, name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec![
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--quiet",
            "--expert",
            expert,
            "--set",
            "train_steps=1500",
            "--set",
            "eval_period=500",
            "--set",
            "eval_episodes=2",
            "--set",
            "learning_starts=100",
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        (arld(&args), out)
    };
    let (ok, out) = run(&good, "good", &[]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let queries = std::fs::read_to_string(out.join("queries.csv")).unwrap();
    assert!(
        queries.lines().count() > 1,
        "the process expert was never asked"
    );
    assert!(out.join("summary.json").exists());

    let cases: [(&str, &[&str], &[&str]); 4] = [
        (
            "cmd:sh -c 'read h; read q; echo dying >&2; exit 3'",
            &[],
            &["closed its output", "dying", "exit status: 3"],
        ),
        (
            "cmd:sleep 60",
            &["--set", "expert_timeout=0.5"],
            &["did not answer within 0.5 s"],
        ),
        (
            "cmd:sh -c 'while read l; do echo hello there; done'",
            &[],
            &["\"hello there\"", "{\"action\": 1}"],
        ),
        (
            "cmd:sh -c 'while read l; do echo {\\\"action\\\":7}; done'",
            &[],
            &["answered action 7", "2 actions"],
        ),
    ];
    for (i, (expert, extra, needles)) in cases.into_iter().enumerate() {
        let (o, out) = run(expert, &format!("bad{i}"), extra);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{expert} should fail");
        assert!(!stderr.contains("panicked"), "{expert} panicked: {stderr}");
        assert!(stderr.contains("expert process"), "{expert}: {stderr}");
        for n in needles {
            assert!(stderr.contains(n), "{expert}: expected '{n}' in: {stderr}");
        }
        assert!(
            !out.join("summary.json").exists(),
            "{expert}: the run must stay incomplete"
        );
    }
}

#[test]
fn expert_train_reuses_only_a_run_of_the_same_configuration_and_writes_into_the_working_directory()
{
    let work = tempfile::tempdir().unwrap();
    let expert_train = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_arld"))
            .current_dir(work.path())
            .args(["expert", "train", "--env", "CartPole-v0", "--episodes", "2"])
            .args(["--set", "train_steps=2000"])
            .args(extra)
            .output()
            .expect("runs")
    };
    let first = expert_train(&[]);
    let err = String::from_utf8_lossy(&first.stderr);
    assert!(first.status.success(), "{err}");
    assert!(err.contains("trained"), "{err}");
    // The default output is ./experts/<env> of the working directory; the run, ./runs/expert_<env>_seed0.
    let selection = work.path().join("experts/CartPole-v0/selection.json");
    assert!(selection.is_file());
    assert!(
        work.path()
            .join("runs/expert_CartPole-v0_seed0/summary.json")
            .is_file()
    );
    // The same configuration again: the finished run is reused.
    let again = expert_train(&[]);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{err}");
    assert!(err.contains("reusing the finished training run"), "{err}");
    // Another configuration: refused, naming every key that differs, and nothing is written.
    std::fs::remove_file(&selection).unwrap();
    let other = expert_train(&["--set", "lr=0.002", "--set", "batch_size=16"]);
    let err = String::from_utf8_lossy(&other.stderr);
    assert_eq!(other.status.code(), Some(1), "{err}");
    assert!(
        err.contains("another configuration")
            && err.contains("lr = ")
            && err.contains("batch_size = 32 (16)"),
        "{err}"
    );
    assert!(!err.contains("train_steps"), "{err}");
    assert!(!selection.exists());
}
