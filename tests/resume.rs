//! Runs that survive SIGKILL: a run is killed at several moments (mid-pre-training, mid-episode, while the expert
//! drives a query segment, and at seeded random delays; discrete runs and a box run that pre-trains), continued each time with `arld train --resume`, and its
//! outputs compared byte for byte with an uninterrupted run of the same configuration (summary: all but the wall
//! time and steps/s; weights: every tensor and the metadata).

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::ARLD;

fn train_args(args: &[&str], out: &Path) -> Vec<String> {
    let mut v: Vec<String> = ["train", "--quiet"].iter().map(|s| s.to_string()).collect();
    v.extend(args.iter().map(|s| s.to_string()));
    v.push("-o".into());
    v.push(out.display().to_string());
    v
}

fn finish(child: Child) {
    let out = child.wait_with_output().expect("wait for arld");
    assert!(
        out.status.success(),
        "arld failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn spawn(args: &[String]) -> Child {
    Command::new(ARLD)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start arld")
}

/// What `snapshot.json` says about where the run was.
fn snapshot_position(dir: &Path) -> Option<serde_json::Value> {
    let text = std::fs::read_to_string(dir.join("snapshot.json")).ok()?;
    let info: serde_json::Value = serde_json::from_str(&text).ok()?;
    Some(info["position"].clone())
}

/// A moment to kill at: when the latest snapshot matches, or after a delay.
enum Moment {
    When(&'static str, fn(&serde_json::Value) -> bool),
    After(Duration),
}

/// Starts (or resumes) the run and SIGKILLs it at `moment`; returns what the last snapshot said, or `None` if
/// the run finished first.
fn kill_at(start: &[String], dir: &Path, moment: &Moment) -> Option<serde_json::Value> {
    let args = if dir.join("snapshot.safetensors").is_file() {
        vec![
            "train".to_string(),
            "--quiet".to_string(),
            "--resume".to_string(),
            dir.display().to_string(),
        ]
    } else {
        start.to_vec()
    };
    let before = snapshot_position(dir);
    let mut child = spawn(&args);
    let started = Instant::now();
    loop {
        if let Ok(Some(status)) = child.try_wait() {
            assert!(status.success(), "arld failed before it could be killed");
            return None;
        }
        let due = match moment {
            Moment::After(d) => started.elapsed() >= *d,
            Moment::When(_, matches) => snapshot_position(dir)
                .filter(|p| Some(p) != before.as_ref())
                .is_some_and(|p| matches(&p)),
        };
        if due {
            child.kill().expect("SIGKILL arld");
            let _ = child.wait();
            return snapshot_position(dir);
        }
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "the run neither finished nor reached the moment to kill"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
}

fn summary_without_time(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let map = v.as_object_mut().unwrap();
    map.remove("wall_time_s");
    map.remove("steps_per_s");
    map.remove("cpu_time_s");
    v
}

type Weights = (
    Vec<(String, Vec<u8>)>,
    std::collections::BTreeMap<String, String>,
);

/// Weights compared tensor by tensor and metadata by key (the header's key order is not fixed).
fn weights(dir: &Path) -> Weights {
    let bytes = std::fs::read(dir.join("weights.safetensors")).unwrap();
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    let file = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut tensors: Vec<(String, Vec<u8>)> = file
        .tensors()
        .into_iter()
        .map(|(n, v)| (n, v.data().to_vec()))
        .collect();
    tensors.sort();
    let meta = meta
        .metadata()
        .clone()
        .unwrap_or_default()
        .into_iter()
        .collect();
    (tensors, meta)
}

/// Kills the run at each moment, resumes it to the end, and compares with an uninterrupted run.
fn survives(args: &[&str], moments: &[Moment]) -> Vec<String> {
    let work = tempfile::tempdir().unwrap();
    let full = work.path().join("full");
    finish(spawn(&train_args(args, &full)));
    let cut = work.path().join("cut");
    let mut start = train_args(args, &cut);
    // A run killed before its first snapshot starts again from nothing.
    start.push("--overwrite".into());
    let mut hits = Vec::new();
    for moment in moments {
        match kill_at(&start, &cut, moment) {
            Some(position) => hits.push(match moment {
                Moment::When(what, _) => format!("{what}: {position}"),
                Moment::After(d) => format!("after {d:?}: {position}"),
            }),
            None => hits.push("finished before the kill".to_string()),
        }
    }
    // Resume to the end.
    let args_end = if cut.join("snapshot.safetensors").is_file() {
        vec![
            "train".to_string(),
            "--quiet".to_string(),
            "--resume".to_string(),
            cut.display().to_string(),
        ]
    } else {
        start.clone()
    };
    if !cut.join("summary.json").is_file() {
        finish(spawn(&args_end));
    }
    for name in ["eval.csv", "episodes.csv", "queries.csv", "answers.jsonl"] {
        let a = std::fs::read(full.join(name)).unwrap();
        let b = std::fs::read(cut.join(name)).unwrap();
        assert!(a == b, "{name} differs after kills at {hits:#?}");
    }
    assert_eq!(
        summary_without_time(&full),
        summary_without_time(&cut),
        "{hits:#?}"
    );
    assert!(
        weights(&full) == weights(&cut),
        "weights differ after kills at {hits:#?}"
    );
    assert!(
        !cut.join("snapshot.safetensors").exists(),
        "a finished run keeps no snapshot"
    );
    hits
}

fn in_pretraining(p: &serde_json::Value) -> bool {
    p["phase"] == "pretrain"
}
fn mid_episode(p: &serde_json::Value) -> bool {
    p["phase"] == "train" && p["episode_step"].as_u64().unwrap_or(0) > 0
}
fn mid_segment(p: &serde_json::Value) -> bool {
    p["expert_in_control"] == true
}

/// Seeded delays: the "random moments" are the same on every run of the test.
fn delays(seed: u64, n: usize, max_ms: u64) -> Vec<Moment> {
    let mut x = seed;
    (0..n)
        .map(|_| {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            Moment::After(Duration::from_millis(20 + (x >> 33) % max_ms))
        })
        .collect()
}

#[test]
fn a_cartpole_dqfd_noisy_run_killed_five_times_ends_byte_identical() {
    let mut moments = vec![
        Moment::When("mid-pre-training", in_pretraining),
        Moment::When("mid-episode", mid_episode),
    ];
    moments.extend(delays(7, 4, 400));
    let hits = survives(
        &[
            "--env",
            "CartPole-v0",
            "--method",
            "dqfd",
            "--net",
            "noisy",
            "--seed",
            "1",
            "--set",
            "train_steps=4000",
            "--set",
            "pretrain_steps=1500",
            "--set",
            "eval_period=1000",
            "--set",
            "eval_episodes=3",
            "--set",
            "snapshot_every=97",
        ],
        &moments,
    );
    assert!(hits[0].contains("\"pretrain\""), "{hits:#?}");
    assert!(hits[1].contains("\"train\""), "{hits:#?}");
    eprintln!("CartPole-v0 DQfD-N kills: {hits:#?}");
}

/// A network of three hidden layers learns CartPole a little and, killed and resumed, ends as the run never
/// stopped; its weights file holds the third layer, `fc3`.
#[test]
fn a_cartpole_dqn_with_three_hidden_layers_learns_and_resumes_byte_identical() {
    let args = [
        "--env",
        "CartPole-v0",
        "--method",
        "dqn",
        "--net",
        "plain",
        "--seed",
        "3",
        "--set",
        "hidden=[32, 32, 32]",
        "--set",
        "train_steps=10000",
        "--set",
        "eval_period=2000",
        "--set",
        "eval_episodes=5",
        "--set",
        "snapshot_every=211",
    ];
    let mut moments = vec![Moment::When("mid-episode", mid_episode)];
    moments.extend(delays(11, 2, 300));
    let hits = survives(&args, &moments);
    eprintln!("CartPole-v0 DQN 32-32-32 kills: {hits:#?}");

    // survives() compared this run with an uninterrupted one; read that run again to look at what it learned.
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    finish(spawn(&train_args(&args, &dir)));
    let eval = std::fs::read_to_string(dir.join("eval.csv")).unwrap();
    let means: Vec<f64> = eval
        .lines()
        .skip(1)
        .map(|line| line.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    assert_eq!(means.len(), 5, "{eval}");
    // A policy that ignores the pole holds it for about 20 steps; the best test here must do three times better.
    let best = means.iter().copied().fold(f64::MIN, f64::max);
    assert!(best >= 60.0, "the 32-32-32 network did not learn: {eval}");

    let bytes = std::fs::read(dir.join("weights.safetensors")).unwrap();
    let file = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    for (name, shape) in [
        ("fc1.weight", [32, 4]),
        ("fc2.weight", [32, 32]),
        ("fc3.weight", [32, 32]),
        ("out.weight", [2, 32]),
    ] {
        assert_eq!(file.tensor(name).unwrap().shape(), shape, "{name}");
    }
    assert!(file.tensor("fc4.weight").is_err());
}

#[test]
fn a_lunarlander_adqn_bootstrap_run_killed_five_times_ends_byte_identical() {
    let mut moments = vec![
        Moment::When("mid-query-segment", mid_segment),
        Moment::When("mid-episode", mid_episode),
    ];
    moments.extend(delays(11, 4, 600));
    let hits = survives(
        &[
            "--env",
            "LunarLander-v2",
            "--method",
            "adqn",
            "--net",
            "bootstrap",
            "--seed",
            "2",
            "--set",
            "train_steps=4000",
            "--set",
            "learning_starts=500",
            "--set",
            "eval_period=2000",
            "--set",
            "eval_episodes=2",
            "--set",
            "snapshot_every=89",
        ],
        &moments,
    );
    assert!(hits[0].contains("\"expert_in_control\":true"), "{hits:#?}");
    eprintln!("LunarLander-v2 ADQN-B kills: {hits:#?}");
}

/// A box run whose query rule reads the risk (thrifty on MountainCarContinuous-v0: a risk critic trained next to
/// TD3's critics, and the rule's records of every risk and uncertainty) survives kills in a query segment,
/// mid-episode and at random moments: the questions, answers and weights come out byte for byte.
#[test]
fn a_mountain_car_thrifty_td3_run_killed_five_times_ends_byte_identical() {
    let args: Vec<&str> = "--env MountainCarContinuous-v0 --method adqn --expert scripted --seed 6 \
         --set query_rule=thrifty(alpha=0.05) --set train_steps=4000 --set learning_starts=300 --set budget=150 \
         --set eval_period=1000 --set eval_episodes=1 --set hidden=[32,32] --set batch_size=32 \
         --set snapshot_every=97"
        .split_whitespace()
        .collect();
    let mut moments = vec![Moment::When("mid-query-segment", mid_segment)];
    moments.push(Moment::When("mid-episode", mid_episode));
    moments.extend(delays(17, 3, 400));
    let hits = survives(&args, &moments);
    eprintln!("MountainCarContinuous-v0 thrifty (TD3) kills: {hits:#?}");
}

/// A box run that pre-trains (adqnp: TD3 cloning the swing-up's demonstrations, then asking it) survives kills
/// in pre-training, mid-episode and in a query segment.
#[test]
fn a_pendulum_adqnp_td3_run_killed_in_pre_training_ends_byte_identical() {
    let mut moments = vec![
        Moment::When("mid-pre-training", in_pretraining),
        Moment::When("mid-query-segment", mid_segment),
        Moment::When("mid-episode", mid_episode),
    ];
    moments.extend(delays(13, 2, 300));
    let hits = survives(
        &[
            "--env",
            "Pendulum-v1",
            "--method",
            "adqnp",
            "--expert",
            "scripted",
            "--seed",
            "5",
            "--set",
            "train_steps=2500",
            "--set",
            "learning_starts=300",
            "--set",
            "pretrain_steps=1200",
            "--set",
            "n_demo=400",
            "--set",
            "budget=200",
            "--set",
            "eval_period=1000",
            "--set",
            "eval_episodes=2",
            "--set",
            "snapshot_every=97",
        ],
        &moments,
    );
    assert!(hits[0].contains("\"pretrain\""), "{hits:#?}");
    eprintln!("Pendulum-v1 ADQNP (TD3) kills: {hits:#?}");
}

#[test]
fn a_snapshot_of_another_configuration_is_refused() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let args = train_args(
        &[
            "--env",
            "CartPole-v0",
            "--method",
            "dqn",
            "--set",
            "train_steps=3000",
            "--set",
            "snapshot_every=100",
        ],
        &dir,
    );
    let pos = kill_at(&args, &dir, &Moment::When("mid-episode", mid_episode));
    assert!(pos.is_some(), "the run finished before it could be killed");
    // The run's configuration changed under the snapshot: resuming must refuse and say why.
    let config = dir.join("config.toml");
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(&config, text.replace("seed = 0", "seed = 5")).unwrap();
    let out = Command::new(ARLD)
        .args(["train", "--quiet", "--resume"])
        .arg(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("another configuration") && err.contains("seed = 0"),
        "{err}"
    );
    std::fs::write(&config, &text).unwrap();
    // A snapshot another arld version (or snapshot format) wrote: refused, naming both versions.
    let snapshot = dir.join("snapshot.safetensors");
    let original = std::fs::read(&snapshot).unwrap();
    for (key, value, expected) in [
        ("arld", "0.0.1", "written by arld 0.0.1, this is arld"),
        ("format", "0", "format version 0, this arld reads version"),
    ] {
        std::fs::write(&snapshot, with_metadata(&original, key, value)).unwrap();
        let out = Command::new(ARLD)
            .args(["train", "--quiet", "--resume"])
            .arg(&dir)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains(expected), "{err}");
    }
    // The snapshot as written, with its configuration, still continues.
    std::fs::write(&snapshot, &original).unwrap();
    finish(spawn(&[
        "train".to_string(),
        "--quiet".to_string(),
        "--resume".to_string(),
        dir.display().to_string(),
    ]));
    assert!(dir.join("summary.json").is_file());
    let out = Command::new(ARLD)
        .args(["train", "--resume"])
        .arg(work.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("holds no run to resume"));
}

/// A safetensors file's bytes with one `__metadata__` entry changed (the header rewritten with its checksum, the
/// data kept).
fn with_metadata(file: &[u8], key: &str, value: &str) -> Vec<u8> {
    let n = u64::from_le_bytes(file[..8].try_into().unwrap()) as usize;
    let mut header: serde_json::Value = serde_json::from_slice(&file[8..8 + n]).unwrap();
    assert!(
        header["__metadata__"].get(key).is_some(),
        "no {key} in the header"
    );
    header["__metadata__"][key] = value.into();
    // The checksum (format 2: CRC-32C of the arrays, then of the header with its digits as 00000000) made
    // again, so that the change is refused for what it says, not as damage.
    let checksummed = header["__metadata__"].get("crc32c").is_some();
    if checksummed {
        header["__metadata__"]["crc32c"] = "00000000".into();
    }
    let mut text = serde_json::to_vec(&header).unwrap();
    text.resize(text.len().next_multiple_of(8), b' ');
    if checksummed {
        let crc = crc32c::crc32c_append(crc32c::crc32c(&file[8 + n..]), &text);
        let placeholder = b"\"crc32c\":\"00000000\"";
        let at = text
            .windows(placeholder.len())
            .position(|w| w == placeholder)
            .unwrap();
        let digits = at + placeholder.len() - 9;
        text[digits..digits + 8].copy_from_slice(format!("{crc:08x}").as_bytes());
    }
    let mut out = (text.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(&text);
    out.extend_from_slice(&file[8 + n..]);
    out
}

/// The rows of a CSV log: the header must be `header`, and every row must end with a newline and have as many
/// fields as the header, each a number (or empty, or a word where the column holds words).
fn parse_log(dir: &Path, name: &str, header: &str) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert!(
        text.starts_with(header),
        "{name} does not begin with its header: {text:?}"
    );
    assert!(text.ends_with('\n'), "{name} ends in a torn row: {text:?}");
    let columns = header.trim_end().split(',').count();
    text.lines()
        .skip(1)
        .map(|line| {
            let fields: Vec<String> = line.split(',').map(str::to_string).collect();
            assert_eq!(fields.len(), columns, "{name}: torn row {line:?}");
            for f in &fields {
                assert!(
                    f.is_empty()
                        || f.parse::<f64>().is_ok()
                        || f.chars().all(|c| c.is_ascii_alphabetic()),
                    "{name}: bad field {f:?} in {line:?}"
                );
            }
            fields
        })
        .collect()
}

/// Starts a run, waits until it has evaluated once, sends it `signal`, and returns its exit status and stderr.
fn stop_with(signal: &str, args: &[String], dir: &Path) -> (Option<i32>, String) {
    let child = spawn(args);
    let started = Instant::now();
    while !dir.join("eval.csv").is_file() {
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "the run never evaluated"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let status = Command::new("kill")
        .args([format!("-{signal}"), child.id().to_string()])
        .status()
        .expect("run kill");
    assert!(status.success());
    let out = child.wait_with_output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_run_stopped_with_sigint_or_sigterm_leaves_whole_logs_and_says_where_it_stopped() {
    let work = tempfile::tempdir().unwrap();
    let args = [
        "--env",
        "CartPole-v0",
        "--method",
        "adqn",
        "--set",
        "train_steps=60000",
    ];
    let full = work.path().join("full");
    finish(spawn(&train_args(&args, &full)));
    for (signal, code) in [("INT", 130), ("TERM", 143)] {
        let dir = work.path().join(signal);
        let (status, err) = stop_with(signal, &train_args(&args, &dir), &dir);
        assert_eq!(status, Some(code), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(
            err.contains(&format!("SIG{signal}")) && err.contains("--resume"),
            "{err}"
        );
        // Every log whole, with its header; the run marked incomplete at the step its message names.
        let eval = parse_log(&dir, "eval.csv", "step,mean,std,min,max\n");
        let episodes = parse_log(
            &dir,
            "episodes.csv",
            "episode,step,return,length,demo_steps\n",
        );
        let queries = parse_log(
            &dir,
            "queries.csv",
            "step,episode,uncertainty,threshold,expert_action,agent_action,expert,response_s,answered\n",
        );
        assert!(!eval.is_empty() && !episodes.is_empty() && !queries.is_empty());
        let step = snapshot_position(&dir).expect("snapshot.json")["step"]
            .as_u64()
            .unwrap();
        assert!(
            err.contains(&format!("stopped at step {step} of 60000")),
            "{err}"
        );
        assert!(step < 60000);
        let last =
            |rows: &[Vec<String>], col: usize| rows.last().unwrap()[col].parse::<u64>().unwrap();
        assert!(last(&eval, 0) <= step && last(&episodes, 1) <= step && last(&queries, 0) < step);
        assert!(!dir.join("summary.json").exists());
        assert!(arld::train::run_dir::check_complete(&dir).is_err());
        // The same command again is refused (it would mix two runs); --resume continues to the results of an
        // uninterrupted run.
        let out = Command::new(ARLD)
            .args(train_args(&args, &dir))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1));
        let refusal = String::from_utf8_lossy(&out.stderr);
        assert!(
            refusal.contains("not empty")
                && refusal.contains("--resume")
                && refusal.contains("--overwrite"),
            "{refusal}"
        );
        finish(spawn(&[
            "train".to_string(),
            "--quiet".to_string(),
            "--resume".to_string(),
            dir.display().to_string(),
        ]));
        for name in ["eval.csv", "episodes.csv", "queries.csv", "answers.jsonl"] {
            assert!(
                std::fs::read(full.join(name)).unwrap() == std::fs::read(dir.join(name)).unwrap(),
                "{name} differs after SIG{signal} and --resume"
            );
        }
        assert_eq!(summary_without_time(&full), summary_without_time(&dir));
    }
}

#[test]
fn overwrite_clears_an_earlier_run_and_nothing_else() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let with = |extra: &[&str]| {
        let mut a = vec![
            "--env",
            "CartPole-v0",
            "--method",
            "dqn",
            "--set",
            "train_steps=2000",
        ];
        a.extend_from_slice(extra);
        train_args(&a, &dir)
    };
    finish(spawn(&with(&["--set", "checkpoint_every=1000"])));
    assert!(dir.join("checkpoints/step_00001000.safetensors").is_file());
    // A finished run is not replaced without --overwrite.
    let out = Command::new(ARLD).args(with(&[])).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("a finished run"));
    // With it, the new run's directory holds only its own files: no checkpoints of the earlier run.
    finish(spawn(&with(&["--overwrite"])));
    assert!(!dir.join("checkpoints").exists());
    assert!(dir.join("summary.json").is_file());
    // A directory holding anything a run does not write is never cleared.
    std::fs::write(dir.join("notes.txt"), "mine").unwrap();
    let out = Command::new(ARLD)
        .args(with(&["--overwrite"]))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("notes.txt") && err.contains("no run writes"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(dir.join("summary.json").is_file());
    // A file where the run directory should be is refused.
    let file = work.path().join("file");
    std::fs::write(&file, "x").unwrap();
    let out = Command::new(ARLD)
        .args(train_args(&["--env", "CartPole-v0"], &file))
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("is not a directory"));
}
