//! Bad input to `arld train`, `arld expert`, `arld demo` and `arld sweep`: a clear message naming the problem,
//! a non-zero exit, no panic, and nothing written.

use std::path::Path;
use std::process::Command;

mod common;
use common::{ARLD, arld};

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
        &["CartPole-v9", "arld's tasks", "Acrobot-v1"],
    );
    // Each error says what to do: a task arld lacks points to the box tasks and to Python, an empty expert to
    // the specs, a negative seed says what a seed is.
    fails_with(
        &["train", "--env", "Hopper-v4", "-o", o],
        &["Hopper-v4", "Pendulum-v1", "arld env list", "arld.Agent"],
    );
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--expert",
            "",
            "-o",
            o,
        ],
        &["must not be empty", "--expert", "scripted"],
    );
    for command in [
        &["train", "--env", "CartPole-v0", "--seed", "-1"][..],
        &[
            "expert",
            "eval",
            "--env",
            "CartPole-v0",
            "--expert",
            "scripted",
            "--seed",
            "-1",
        ],
        &["env", "rollout", "--env", "CartPole-v0", "--seed", "-5"],
    ] {
        fails_with(command, &["seeds are non-negative integers"]);
    }
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    fails_with(
        &["report", empty.to_str().unwrap()],
        &["no complete run", "arld reproduce", "--from-evaluations"],
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
        summary["demos_queried"].as_u64().unwrap() > 0
            && summary["demos_queried"].as_u64().unwrap() <= 200
    );
    let queries = std::fs::read_to_string(out.join("queries.csv")).unwrap();
    assert!(queries.lines().count() > 1, "ADQN asked no query");
    answers_agree_with_the_logs(&out);
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

/// `answers.jsonl` against what the other logs say independently: every episode's count of expert steps is
/// `episodes.csv`'s `demo_steps`; every step names an answered question of `queries.csv` with its agent's action
/// and uncertainty, and a question's own step takes the action `queries.csv` says the expert answered; within a
/// segment each step starts where the previous one ended.
fn answers_agree_with_the_logs(out: &Path) {
    let text = std::fs::read_to_string(out.join("answers.jsonl")).unwrap();
    let answers: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(!answers.is_empty(), "the expert took no step");
    let csv = std::fs::read_to_string(out.join("queries.csv")).unwrap();
    let asked: std::collections::HashMap<u64, Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|r| r[8] == "true")
        .map(|r| (r[0].parse().unwrap(), r))
        .collect();
    let episodes = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    for row in episodes.lines().skip(1) {
        let r: Vec<&str> = row.split(',').collect();
        let episode: u64 = r[0].parse().unwrap();
        let taken = answers
            .iter()
            .filter(|a| a["episode"].as_u64() == Some(episode))
            .count();
        assert_eq!(taken.to_string(), r[4], "expert steps of episode {episode}");
    }
    for (i, a) in answers.iter().enumerate() {
        let q = a["question_step"].as_u64().unwrap();
        let row = asked
            .get(&q)
            .unwrap_or_else(|| panic!("step {} names no answered question: {a}", a["step"]));
        assert_eq!(a["agent_action"].to_string(), row[5], "{a}");
        assert_eq!(
            a["uncertainty"].as_f64().map(|u| u as f32),
            row[2].parse::<f32>().ok(),
            "{a}"
        );
        assert_eq!(a["started_by"], "rule");
        if a["step"].as_u64() == Some(q) {
            assert_eq!(a["action"].to_string(), row[4], "{a}");
        } else {
            let prev = &answers[i - 1];
            assert_eq!(prev["question_step"].as_u64(), Some(q), "{a}");
            assert_eq!(
                prev["step"].as_u64().unwrap() + 1,
                a["step"].as_u64().unwrap()
            );
            assert_eq!(prev["next_obs"], a["obs"], "{a}");
        }
    }
}

/// A short ADQN run with the expert in another process (`examples/expert.py` through `cmd:`): it completes, and
/// the experts that crash, hang, babble or answer out of range each stop the run with a message naming the
/// expert, a non-zero exit and no summary (the run stays incomplete).
#[test]
fn expert_process_runs_and_its_failures_are_clear() {
    assert!(
        Command::new("python3")
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success()),
        "python3 is missing (it runs examples/expert.py here); `scripts/test --setup` installs it"
    );
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
            "cmd:sh -c 'read h; while read l; do echo hello there; done'",
            &[],
            &["\"hello there\"", "{\"action\": 1}"],
        ),
        (
            "cmd:sh -c 'read h; while read l; do echo {\\\"action\\\":7}; done'",
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

/// The example expert's Pendulum-v1 controller (examples/expert.py), computed here again in f64.
fn example_pendulum(obs: &[f32]) -> f64 {
    let (cos, sin, speed) = (obs[0] as f64, obs[1] as f64, obs[2] as f64);
    let torque = if cos > 0.85 {
        -(10.0 * sin.atan2(cos) + 2.0 * speed)
    } else if speed * (10.0 - (0.5 * speed * speed + 10.0 * cos)) >= 0.0 {
        2.0
    } else {
        -2.0
    };
    torque.clamp(-2.0, 2.0)
}

/// An expert process answers a task whose actions are in a box (Pendulum-v1) with lists of numbers: every
/// answered step in answers.jsonl is the example expert's torque at its observation, and an answer outside the box
/// stops the run with a message naming the expert and the bounds.
#[test]
fn an_expert_process_answers_box_actions() {
    let dir = tempfile::tempdir().unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/expert.py");
    let run = |expert: &str, name: &str| {
        let out = dir.path().join(name);
        let args = [
            "train",
            "--env",
            "Pendulum-v1",
            "--method",
            "adqn",
            "--quiet",
            "--expert",
            expert,
            "--set",
            "train_steps=1500",
            "--set",
            "eval_period=1500",
            "--set",
            "eval_episodes=1",
            "--set",
            "budget=100",
            "-o",
            out.to_str().unwrap(),
        ];
        (arld(&args), out)
    };
    let (ok, out) = run(&format!("cmd:python3 {}", script.display()), "good");
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let answers = std::fs::read_to_string(out.join("answers.jsonl")).unwrap();
    let steps: Vec<serde_json::Value> = answers
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        steps.len(),
        100,
        "the budget of 100 answered steps is spent"
    );
    for step in &steps {
        let obs: Vec<f32> = serde_json::from_value(step["obs"].clone()).unwrap();
        let action: Vec<f32> = serde_json::from_value(step["action"].clone()).unwrap();
        assert_eq!(action, vec![example_pendulum(&obs) as f32], "{step}");
        assert_eq!(step["expert"], "cmd", "{step}");
    }

    let (bad, out) = run(
        "cmd:sh -c 'read h; while read l; do echo {\\\"action\\\":[2.5]}; done'",
        "bad",
    );
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && !stderr.contains("panicked"),
        "{stderr}"
    );
    for needle in ["expert process", "answered action 2.5", "lies in [-2, 2]"] {
        assert!(stderr.contains(needle), "expected '{needle}' in: {stderr}");
    }
    assert!(
        !out.join("summary.json").exists(),
        "the run must stay incomplete"
    );
}

/// Run from a copy of the checkout's root (its `experts/` as git has them), `expert train` writes its experts
/// into `experts-trained/<env>` and leaves the shipped ones as they are; told to write into the shipped experts'
/// folder, it refuses before any work.
#[test]
fn expert_train_reuses_only_a_run_of_the_same_configuration_and_never_replaces_shipped_experts() {
    let work = tempfile::tempdir().unwrap();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let shipped = |dir: &std::path::Path| -> Vec<(String, Vec<u8>)> {
        let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir.join("experts/CartPole-v0"))
            .unwrap()
            .map(|e| {
                let e = e.unwrap();
                (
                    e.file_name().to_string_lossy().into_owned(),
                    std::fs::read(e.path()).unwrap(),
                )
            })
            .collect();
        files.sort();
        files
    };
    let copy = work.path().join("experts/CartPole-v0");
    std::fs::create_dir_all(&copy).unwrap();
    for (name, bytes) in shipped(root) {
        std::fs::write(copy.join(name), bytes).unwrap();
    }
    let expert_train = |extra: &[&str]| {
        Command::new(ARLD)
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
    // The default output is ./experts-trained/<env> of the working directory; the run,
    // ./runs/expert_<env>_seed0; the copy of the shipped experts is untouched.
    let selection = work
        .path()
        .join("experts-trained/CartPole-v0/selection.json");
    assert!(selection.is_file());
    assert!(
        work.path()
            .join("experts-trained/CartPole-v0/weak.safetensors")
            .is_file()
    );
    assert_eq!(shipped(work.path()), shipped(root));
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
    // Into the shipped experts (the copy, or the checkout's own folder): refused, naming what to do.
    for out in [copy.clone(), root.join("experts/CartPole-v0")] {
        let refused = expert_train(&["-o", out.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&refused.stderr);
        assert_eq!(refused.status.code(), Some(1), "{err}");
        assert!(
            err.contains("holds shipped experts") && err.contains("--out DIR"),
            "{err}"
        );
    }
    assert_eq!(shipped(work.path()), shipped(root));
}

/// Values too large for their field, counts of zero, sizes no machine has: each named in a clear error before
/// any work, and nothing written.
#[test]
fn numbers_out_of_range_name_their_field() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = out.to_str().unwrap();
    let too_big = "9223372036854775808";
    fails_with(
        &["train", "--env", "CartPole-v0", "--seed", too_big, "-o", o],
        &["seed", too_big],
    );
    fails_with(
        &[
            "train",
            "--env",
            "CartPole-v0",
            "--set",
            &format!("seed={too_big}"),
            "-o",
            o,
        ],
        &["seed"],
    );
    fails_with(
        &["expert", "eval", "--env", "CartPole-v0", "--episodes", "0"],
        &["--episodes", "0"],
    );
    fails_with(
        &["env", "rollout", "--env", "CartPole-v0", "--episodes", "0"],
        &["--episodes", "0"],
    );
    let demos = dir.path().join("d.jsonl");
    let d = demos.to_str().unwrap();
    let collect = "demo collect --env CartPole-v0 --expert scripted --transitions 0 -o";
    fails_with(
        &collect.split(' ').chain([d]).collect::<Vec<_>>(),
        &["--transitions", "0"],
    );
    let sweep = dir.path().join("sweep");
    let s = sweep.to_str().unwrap();
    let listed = format!("1,{too_big}");
    for (seeds, needles) in [
        ("100000000000", ["seeds", "at most 10000"]),
        ("0..100000000000", ["seeds", "at most 10000"]),
        (listed.as_str(), ["seed", too_big]),
    ] {
        let sweep = "sweep --env CartPole-v0 --method dqn -o";
        fails_with(
            &sweep
                .split(' ')
                .chain([s, "--seeds", seeds])
                .collect::<Vec<_>>(),
            &needles,
        );
    }
    fails_with(
        &["reproduce", "--seeds", "100000000000", "-o", s],
        &["--seeds", "100000000000"],
    );
    assert!(!out.exists() && !sweep.exists() && !demos.exists());
}

/// An output path that is a device, a directory or a symbolic link is refused, and left as it was.
#[test]
fn outputs_are_written_only_to_regular_files() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("target.jsonl");
    std::fs::write(&target, "kept").unwrap();
    let link = dir.path().join("link.jsonl");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let sub = dir.path().join("sub");
    std::fs::create_dir(&sub).unwrap();
    for (path, what) in [
        (Path::new("/dev/null"), "a device"),
        (link.as_path(), "a symbolic link"),
        (sub.as_path(), "a directory"),
    ] {
        let stderr = fails_with(
            &[
                "demo",
                "collect",
                "--env",
                "CartPole-v0",
                "--expert",
                "scripted",
                "--transitions",
                "20",
                "-o",
                path.to_str().unwrap(),
            ],
            &[what],
        );
        // The reason once, not repeated by the error's chain.
        assert_eq!(stderr.matches(what).count(), 1, "{stderr}");
    }
    use std::os::unix::fs::FileTypeExt;
    assert!(
        std::fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device()
    );
    assert!(link.symlink_metadata().unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "kept");
    // Nothing left behind: no temporary file beside any of them (link.jsonl, sub, target.jsonl).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
    assert_eq!(std::fs::read_dir(&sub).unwrap().count(), 0);
}

/// Demonstration files whose header promises what the file cannot hold, or nothing at all, are refused when
/// loaded, before anything is allocated for them.
#[test]
fn demonstration_headers_are_checked_against_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let header = |transitions: u64| {
        format!(
            "{{\"format\":\"arld-demos\",\"version\":1,\"env\":\"CartPole-v0\",\"expert\":\"x\",\"seed\":0,\
             \"obs_dim\":4,\"n_actions\":2,\"transitions\":{transitions},\"episodes\":1}}\n"
        )
    };
    for (name, text, needle) in [
        (
            "huge.jsonl",
            header(100_000_000_000_000),
            "more than a file of",
        ),
        ("none.jsonl", header(0), "no transitions"),
        ("empty.jsonl", String::new(), "empty demonstration file"),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        for method in ["dqfd", "adqnp"] {
            fails_with(
                &[
                    "train",
                    "--env",
                    "CartPole-v0",
                    "--method",
                    method,
                    "--demos",
                    path.to_str().unwrap(),
                    "-o",
                    out.to_str().unwrap(),
                ],
                &[name, needle],
            );
        }
    }
    assert!(!out.exists());
}

/// A learning rate that makes the loss blow up ends the run with "diverged at step N" and a hint, exit 1; the
/// run is incomplete (no summary) and its logs parse. The step is checked against a recomputation: the first
/// update comes at `learning_starts`, so divergence cannot be reported before it.
#[test]
fn a_diverging_run_stops_with_the_step_and_a_hint() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let run = "train --env CartPole-v0 --net plain --set learning_starts=300 --quiet -o";
    let args = |out: &Path, extra: &[&str]| -> Vec<String> {
        let out = out.to_str().unwrap();
        run.split(' ')
            .chain([out])
            .chain(extra.iter().copied())
            .map(String::from)
            .collect()
    };
    let diverging = args(&out, &["--set", "lr=1e12", "--set", "train_steps=5000"]);
    let stderr = fails_with(
        &diverging.iter().map(String::as_str).collect::<Vec<_>>(),
        &["diverged at step", "lower `lr`", "incomplete"],
    );
    let step: usize = stderr
        .split("diverged at step ")
        .nth(1)
        .and_then(|rest| rest.split(':').next())
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("no step in: {stderr}"));
    assert!((300..5000).contains(&step), "{stderr}");
    assert!(!out.join("summary.json").exists());
    let episodes = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    assert!(episodes.starts_with("episode,step,return,length,demo_steps\n"));
    for row in episodes.lines().skip(1) {
        assert_eq!(row.split(',').count(), 5, "torn row {row:?}");
        let at: usize = row.split(',').nth(1).unwrap().parse().unwrap();
        assert!(at <= step, "an episode logged after the divergence: {row}");
    }
    // The same run with a sane learning rate goes on past that step.
    let steps = format!("train_steps={}", step + 200);
    let sane = args(&dir.path().join("sane"), &["--set", &steps]);
    let ok = arld(&sane.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
}

/// A run's config.toml given with --config runs that configuration without --env; the identity flags and --set
/// win over the file's keys; a file without `env` and no --env is a clear error.
#[test]
fn a_config_file_names_the_run_and_flags_win_over_it() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("run.toml");
    std::fs::write(
        &file,
        "env = \"Acrobot-v1\"\nmethod = \"adqn\"\nnet = \"noisy\"\nseed = 7\nlr = 0.002\n",
    )
    .unwrap();
    let file = file.to_str().unwrap();
    let printed = |extra: &[&str]| -> toml::Table {
        let mut args = vec!["train", "--config", file, "--print-config"];
        args.extend_from_slice(extra);
        let out = arld(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        toml::from_str(&String::from_utf8_lossy(&out.stdout)).unwrap()
    };
    let from_file = printed(&[]);
    assert_eq!(from_file["env"].as_str(), Some("Acrobot-v1"));
    assert_eq!(from_file["method"].as_str(), Some("adqn"));
    assert_eq!(from_file["net"].as_str(), Some("noisy"));
    assert_eq!(from_file["seed"].as_integer(), Some(7));
    assert_eq!(from_file["lr"].as_float(), Some(0.002));
    let flagged = printed(&[
        "--env",
        "CartPole-v0",
        "--method",
        "dqn",
        "--net",
        "plain",
        "--seed",
        "3",
        "--set",
        "lr=0.005",
    ]);
    assert_eq!(flagged["env"].as_str(), Some("CartPole-v0"));
    assert_eq!(flagged["method"].as_str(), Some("dqn"));
    assert_eq!(flagged["net"].as_str(), Some("plain"));
    assert_eq!(flagged["seed"].as_integer(), Some(3));
    assert_eq!(flagged["lr"].as_float(), Some(0.005));
    let no_env = dir.path().join("no_env.toml");
    std::fs::write(&no_env, "lr = 0.002\n").unwrap();
    fails_with(
        &["train", "--config", no_env.to_str().unwrap()],
        &["no environment", "--env"],
    );
}

/// Demonstrations collected from a shipped expert, from any working directory, name it `shipped:weak` (the
/// expert inside the binary), never a path of the checkout that built it.
#[test]
fn demonstrations_of_a_shipped_expert_name_it_not_a_path() {
    let work = tempfile::tempdir().unwrap();
    let out = Command::new(ARLD)
        .current_dir(work.path())
        .args([
            "demo",
            "collect",
            "--env",
            "CartPole-v0",
            "--expert",
            "shipped:weak",
        ])
        .args(["--transitions", "50", "-o", "demos.jsonl"])
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(work.path().join("demos.jsonl")).unwrap();
    let header = text.lines().next().unwrap();
    assert!(header.contains("\"shipped:weak\""), "{header}");
    assert!(
        !text.contains(env!("CARGO_MANIFEST_DIR")) && !text.contains("safetensors"),
        "{header}"
    );
}
