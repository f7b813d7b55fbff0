//! Real `arld` processes that meet each other or are killed: the sweep directory's lock (a second sweep is
//! refused naming the holder; the lock of a SIGKILLed sweep is taken over), damaged runs (run again, listed),
//! and runs whose configuration equals a finished one (its files taken, not run again).

use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::ARLD;

fn sweep_args<'a>(out: &'a str, train_steps: &'a str) -> Vec<&'a str> {
    vec![
        "sweep",
        "--env",
        "CartPole-v0",
        "--method",
        "dqn",
        "--seeds",
        "2",
        "--set",
        train_steps,
        "--jobs",
        "1",
        "-o",
        out,
    ]
}

fn output(args: &[&str]) -> Output {
    Command::new(ARLD).args(args).output().expect("arld runs")
}

/// Waits (up to a minute, not a timing assertion: only a bound on a hang) until `path` exists.
fn wait_for(path: &Path, child: &mut Child) {
    let start = Instant::now();
    while !path.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!(
                "the sweep ended ({status}) before {} appeared",
                path.display()
            );
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no {}",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Every `summary.json` below `dir`, sorted.
fn run_dirs(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.file_name().unwrap() == "summary.json" {
                found.push(path.parent().unwrap().to_path_buf());
            }
        }
    }
    found.sort();
    found
}

#[test]
fn concurrent_killed_and_damaged_sweeps_end_with_the_uninterrupted_results() {
    const STEPS: &str = "train_steps=20000";
    let dir = tempfile::tempdir().unwrap();
    let reference = dir.path().join("reference");
    let out = dir.path().join("sweep");
    let o = out.to_str().unwrap();
    let lock = out.join(".lock");
    let done = output(&sweep_args(reference.to_str().unwrap(), STEPS));
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let expected = std::fs::read_to_string(reference.join("results.csv")).unwrap();
    assert!(expected.lines().count() > 3, "{expected}");

    // Two sweeps at once: the second is refused, naming the holder.
    let mut first = Command::new(ARLD)
        .args(sweep_args(o, STEPS))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for(&lock, &mut first);
    let second = output(&sweep_args(o, STEPS));
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert!(!second.status.success(), "the second sweep ran: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let host = arld::lab::sweep::host_name();
    assert!(
        stderr.contains(&format!("process {}", first.id())) && stderr.contains(&host),
        "the message names the holder (pid {}, host {host}): {stderr}",
        first.id()
    );

    // SIGKILL: no chance to release the lock. The rerun takes the stale lock over and finishes the sweep.
    first.kill().unwrap();
    first.wait().unwrap();
    assert!(lock.exists(), "a SIGKILLed sweep leaves its lock behind");
    let rerun = output(&sweep_args(o, STEPS));
    let stderr = String::from_utf8_lossy(&rerun.stderr);
    assert!(rerun.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!("process {}", first.id())) && stderr.contains("taking it over"),
        "{stderr}"
    );
    assert!(!lock.exists(), "the lock is released when the sweep ends");
    assert_eq!(
        std::fs::read_to_string(out.join("results.csv")).unwrap(),
        expected
    );

    // Damaged complete runs (a curve cut short, a configuration lost) are run again and listed.
    let runs = run_dirs(&out);
    assert!(runs.len() >= 2, "{runs:?}");
    let eval = runs[0].join("eval.csv");
    let text = std::fs::read_to_string(&eval).unwrap();
    let cut = text.trim_end().rfind('\n').unwrap() + 1;
    std::fs::write(&eval, &text[..cut]).unwrap();
    std::fs::remove_file(runs[1].join("config.toml")).unwrap();
    let repaired = output(&sweep_args(o, STEPS));
    let stdout = String::from_utf8_lossy(&repaired.stdout);
    assert!(
        repaired.status.success(),
        "{}",
        String::from_utf8_lossy(&repaired.stderr)
    );
    for run in &runs[..2] {
        assert!(
            stdout.contains(&format!("damaged and run again: {}", run.display())),
            "{stdout}"
        );
    }
    assert_eq!(
        std::fs::read_to_string(out.join("results.csv")).unwrap(),
        expected
    );
}

/// A sweep extended with t_query values, one of them the task's default for ADQN-B (CartPole-v0: 0.05): that
/// variant takes the files of the finished default runs, and they are the bytes an independent sweep that runs
/// it writes. The other value runs.
#[test]
fn a_variant_equal_to_a_finished_run_takes_its_files_which_match_running_it() {
    let tmp = tempfile::tempdir().unwrap();
    let (extended, fresh) = (tmp.path().join("extended"), tmp.path().join("fresh"));
    let sweep = |out: &Path, t_query: Option<&str>| -> Output {
        let mut args = vec![
            "sweep",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--net",
            "bootstrap",
            "--seeds",
            "2",
            "--set",
            "train_steps=1500",
            "--set",
            "eval_period=500",
            "--jobs",
            "1",
            "-o",
            out.to_str().unwrap(),
        ];
        if let Some(t) = t_query {
            args.extend(["--t-query", t]);
        }
        let out = output(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        out
    };
    sweep(&extended, None);
    let out = sweep(&extended, Some("0.05,0.5"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("4 runs (0 already complete, 2 the same as a finished run, 2 run now)"),
        "{stdout}"
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        stderr.matches("whose files it takes").count(),
        2,
        "{stderr}"
    );
    assert!(
        !stderr.contains("tq0.5/seed0: the same configuration"),
        "{stderr}"
    );
    sweep(&fresh, Some("0.05"));
    for seed in ["seed0", "seed1"] {
        let variant = Path::new("CartPole-v0/adqn-bootstrap/tq0.05").join(seed);
        for file in [
            "config.toml",
            "eval.csv",
            "queries.csv",
            "episodes.csv",
            "weights.safetensors",
        ] {
            let taken = std::fs::read(extended.join(&variant).join(file)).unwrap();
            let ran = std::fs::read(fresh.join(&variant).join(file)).unwrap();
            assert!(
                taken == ran,
                "{}/{file} differs from running it",
                variant.display()
            );
        }
    }
}
