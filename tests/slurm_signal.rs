//! The job script's "time limit near" path, without a cluster: the script `arld sweep --slurm` submits (to a
//! stand-in `sbatch`) is run by bash as Slurm would run one array task; USR1, which Slurm sends some minutes
//! before the time limit, makes the runs snapshot and arld exit with status 75, and the task asks to be
//! requeued (a stand-in `scontrol` records it). Running the task again (the requeued attempt) continues the runs
//! from their snapshots, and results.csv equals an uninterrupted local sweep's. (tests/slurm.rs covers requeueing
//! on a real Slurm.)

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::ARLD;

fn sweep_args(out: &Path) -> Vec<String> {
    [
        "sweep",
        "--env",
        "CartPole-v0",
        "--method",
        "dqn,adqn",
        "--net",
        "bootstrap",
        "--seeds",
        "1",
        "--set",
        "train_steps=12000",
        "--set",
        "eval_period=2000",
        "--set",
        "eval_episodes=3",
        "--set",
        "snapshot_every=500",
        "-o",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain([out.display().to_string()])
    .collect()
}

/// Any `snapshot.safetensors` under `dir`.
fn find_snapshot(dir: &Path) -> Option<PathBuf> {
    for entry in std::fs::read_dir(dir).ok()?.flatten() {
        let path = entry.path();
        if path.is_dir() {
            if let Some(found) = find_snapshot(&path) {
                return Some(found);
            }
        } else if path
            .file_name()
            .is_some_and(|n| n == "snapshot.safetensors")
        {
            return Some(path);
        }
    }
    None
}

fn write_script(path: &Path, body: &str) {
    std::fs::write(path, format!("#!/bin/sh\n{body}\n")).unwrap();
    let status = Command::new("chmod").arg("+x").arg(path).status().unwrap();
    assert!(status.success());
}

#[test]
fn usr1_near_the_time_limit_snapshots_stops_with_75_and_the_requeued_task_continues() {
    let work = tempfile::tempdir().unwrap();
    let bin = work.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let requeues = work.path().join("scontrol.log");
    write_script(&bin.join("sbatch"), "echo 42");
    write_script(
        &bin.join("scontrol"),
        &format!("echo \"$@\" >> '{}'", requeues.display()),
    );
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );

    // The uninterrupted local sweep.
    let local = work.path().join("local");
    let out = Command::new(ARLD)
        .args(sweep_args(&local))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // "Submit" the array (one task for both runs) to the stand-in sbatch.
    let remote = work.path().join("remote");
    let out = Command::new(ARLD)
        .args(sweep_args(&remote))
        .args(["--slurm", "--shards", "1"])
        .env("PATH", &path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let script = remote.join("slurm").join("job.sh");
    assert!(std::fs::read_to_string(&script).unwrap().contains("USR1"));
    let task = |attempt: &str| {
        let mut cmd = Command::new("bash");
        cmd.arg(&script)
            .env("PATH", &path)
            .env("SLURM_ARRAY_JOB_ID", "42")
            .env("SLURM_ARRAY_TASK_ID", "0")
            .env("SLURM_RESTART_COUNT", attempt)
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        cmd
    };

    // Attempt 0: USR1 once a run has a snapshot (the run is then well under way).
    let mut child = task("0").spawn().unwrap();
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the task ended ({status}) before it could be signalled");
        }
        if find_snapshot(&remote).is_some() {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "no snapshot after 2 minutes"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // bash's own `kill` (no procps needed).
    let kill = Command::new("bash")
        .args(["-c", &format!("kill -USR1 {}", child.id())])
        .status()
        .unwrap();
    assert!(kill.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(75), "{err}");
    assert!(
        find_snapshot(&remote).is_some(),
        "no snapshot left to continue from"
    );
    assert!(!remote.join("results.csv").exists());
    let asked = std::fs::read_to_string(&requeues).unwrap_or_default();
    assert_eq!(asked.trim(), "requeue 42_0");

    // Attempt 1 (the requeued task): continues from the snapshots, to the local sweep's results.
    let out = task("1").output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(find_snapshot(&remote).is_none());
    assert_eq!(
        std::fs::read_to_string(remote.join("results.csv")).unwrap(),
        std::fs::read_to_string(local.join("results.csv")).unwrap()
    );
    // Only one request to requeue: the second attempt finished.
    assert_eq!(
        std::fs::read_to_string(&requeues).unwrap().lines().count(),
        1
    );
}
