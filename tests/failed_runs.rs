//! Runs that fail, and what they leave: a diverged run and a run whose expert process crashes each write
//! `failed.json` (the error chain, the step, the time, the arld version and commit), which `arld sweep --status`
//! and `arld report` show; a later attempt that finishes the run removes it. `arld train --resume` on a run
//! stopped before its first snapshot starts it again from step 0, to the bytes of a fresh run. `arld --version`
//! names the commit it was built from.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;
use common::{arld, stderr, stdout};

/// The run's `failed.json`, parsed.
fn failure(dir: &Path) -> serde_json::Value {
    let path = dir.join("failed.json");
    let text =
        std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("no {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// Checks the fields every `failed.json` has: the error chain, the phase and step, the time and who ran it.
fn check_failure(failure: &serde_json::Value, needle: &str) {
    let chain: Vec<&str> = failure["error"]
        .as_array()
        .expect("an error chain")
        .iter()
        .map(|c| c.as_str().expect("each cause a string"))
        .collect();
    assert!(
        chain.iter().any(|c| c.contains(needle)),
        "{needle:?} not in {chain:?}"
    );
    assert_eq!(failure["phase"], "training", "{failure}");
    assert!(failure["step"].as_u64().unwrap() > 0, "{failure}");
    assert!(failure["unix_s"].as_u64().unwrap() > 1_600_000_000);
    let time = failure["time"].as_str().unwrap();
    assert!(time.len() == 20 && time.ends_with('Z') && time.as_bytes()[10] == b'T');
    assert_eq!(failure["arld_version"], env!("CARGO_PKG_VERSION"));
    assert!(!failure["git_commit"].as_str().unwrap().is_empty());
}

/// A sweep with two learning rates on CartPole: one diverges within a few hundred steps, leaving `failed.json`
/// with the step the error names; the other finishes. `--status` shows the failed run with the first line of
/// its error, the report lists it with its reason, and running the sweep again leaves the record in place.
#[test]
fn a_diverged_run_leaves_failed_json_that_status_and_report_show() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = dir.path().join("sweep");
    let s = sweep.to_str().unwrap();
    let args = [
        "sweep",
        "--env",
        "CartPole-v0",
        "--method",
        "dqn",
        "--net",
        "plain",
        "--seeds",
        "1",
        "--set",
        "train_steps=1500",
        "--set",
        "learning_starts=300",
        "--set",
        "eval_period=500",
        "--set",
        "eval_episodes=2",
        "--vary",
        "lr=1e12",
        "--vary",
        "lr=0.001",
        "--jobs",
        "1",
        "-o",
        s,
    ];
    let out = arld(&args);
    assert!(!out.status.success(), "the sweep should fail");
    assert!(
        stderr(&out).contains("1 of 2 runs failed"),
        "{}",
        stderr(&out)
    );
    let failed: Vec<PathBuf> = ["lr-1e12", "lr-0.001"]
        .iter()
        .map(|v| sweep.join("CartPole-v0/dqn-plain").join(v).join("seed0"))
        .collect();
    assert!(
        failed[0].is_dir() && failed[1].join("summary.json").is_file(),
        "unexpected layout: {:?}",
        std::fs::read_dir(sweep.join("CartPole-v0/dqn-plain"))
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .collect::<Vec<_>>()
    );
    assert!(!failed[1].join("failed.json").exists());
    let record = failure(&failed[0]);
    check_failure(&record, "diverged at step");
    let step = record["step"].as_u64().unwrap();
    assert!(
        record["error"][0]
            .as_str()
            .unwrap()
            .contains(&format!("diverged at step {step}:")),
        "{record}"
    );
    assert!((300..1500).contains(&step), "{record}");

    let status = arld(&["sweep", "--status", s]);
    assert!(status.status.success(), "{}", stderr(&status));
    let text = stdout(&status);
    let line = text
        .lines()
        .find(|l| l.starts_with("failed"))
        .unwrap_or_else(|| panic!("no failed run in:\n{text}"));
    assert!(
        line.contains("lr-1e12/seed0")
            && line.contains(&format!("at step {step}"))
            && line.contains("diverged at step"),
        "{line}"
    );
    assert!(
        text.contains("1 done") && text.contains("1 failed"),
        "{text}"
    );

    let report_dir = dir.path().join("report");
    let report = arld(&["report", s, "-o", report_dir.to_str().unwrap()]);
    assert!(report.status.success(), "{}", stderr(&report));
    let md = std::fs::read_to_string(report_dir.join("report.md")).unwrap();
    assert!(md.contains("1 runs failed and are left out"), "{md}");
    let listed = md
        .lines()
        .find(|l| l.starts_with("- `CartPole-v0/dqn-plain/lr-1e12/seed0`"))
        .unwrap_or_else(|| panic!("the failed run is not listed in:\n{md}"));
    assert!(
        listed.contains(&format!("at step {step}")) && listed.contains("diverged at step"),
        "{listed}"
    );

    // Running the sweep again retries the failed run, which diverges the same way: the record stays, its step
    // the same.
    let again = arld(&args);
    assert!(!again.status.success());
    assert_eq!(failure(&failed[0])["step"], record["step"]);
}

/// A shell expert that answers action 0, but exits with status 3 after three answers while a file `crash`
/// lies beside it.
fn crashing_expert(dir: &Path) -> (String, PathBuf) {
    let script = dir.join("expert.sh");
    std::fs::write(
        &script,
        "read hello\nn=0\nwhile read q; do\n  n=$((n + 1))\n  if [ -e \"$(dirname \"$0\")/crash\" ] && [ $n -ge 3 ]; then\n    \
         echo 'expert: giving up' >&2\n    exit 3\n  fi\n  echo '{\"action\": 0}'\ndone\n",
    )
    .unwrap();
    let marker = dir.join("crash");
    std::fs::write(&marker, "").unwrap();
    (format!("cmd:sh {}", script.display()), marker)
}

const SHORT_ADQN: [&str; 8] = [
    "train_steps=1500",
    "eval_period=500",
    "eval_episodes=2",
    "learning_starts=100",
    "snapshot_every=100000",
    "t_query=0.3",
    "budget=200",
    "seed=0",
];

/// An expert process that crashes mid-run fails the run of a sweep with `failed.json` naming the expert, its exit
/// status and its last words; `--status` shows it. Once the expert is fixed, the same sweep finishes the run and
/// removes the record.
#[test]
fn a_crashed_expert_leaves_failed_json_until_a_later_attempt_finishes() {
    let dir = tempfile::tempdir().unwrap();
    let (expert, marker) = crashing_expert(dir.path());
    let sweep = dir.path().join("sweep");
    let s = sweep.to_str().unwrap();
    let expert_key = format!("expert={expert}");
    let mut args = vec![
        "sweep",
        "--env",
        "CartPole-v0",
        "--method",
        "adqn",
        "--net",
        "bootstrap",
        "--seeds",
        "1",
        "--jobs",
        "1",
        "--set",
        &expert_key,
        "-o",
        s,
    ];
    for set in &SHORT_ADQN[..5] {
        args.extend(["--set", set]);
    }
    let out = arld(&args);
    assert!(!out.status.success(), "the sweep should fail");
    let run = sweep.join("CartPole-v0/adqn-bootstrap/seed0");
    let record = failure(&run);
    check_failure(&record, "exit status: 3");
    let whole = record["error"].to_string();
    assert!(
        whole.contains("giving up") && whole.contains("failed to answer"),
        "{record}"
    );
    let status = stdout(&arld(&["sweep", "--status", s]));
    let line = status
        .lines()
        .find(|l| l.starts_with("failed"))
        .unwrap_or_else(|| panic!("no failed run in:\n{status}"));
    assert!(
        line.contains("adqn-bootstrap/seed0") && line.contains("failed to answer"),
        "{line}"
    );
    assert!(
        !line.contains("giving up"),
        "--status shows the first line only: {line}"
    );

    std::fs::remove_file(&marker).unwrap();
    let fixed = arld(&args);
    assert!(fixed.status.success(), "{}", stderr(&fixed));
    assert!(run.join("summary.json").is_file());
    assert!(
        !run.join("failed.json").exists(),
        "the finished run keeps failed.json"
    );
    let status = stdout(&arld(&["sweep", "--status", s]));
    assert!(
        status.contains("1 done") && status.contains("0 failed"),
        "{status}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["arld_version"], env!("CARGO_PKG_VERSION"));
    assert!(summary["git_commit"].is_string());
}

/// A run whose expert crashed before the first snapshot: `arld train --resume` says in one line that it starts
/// again from step 0, finishes it (removing `failed.json`), and writes the same eval.csv and queries.csv as a
/// fresh run. A directory without a run's config.toml, and a finished run, are still refused.
#[test]
fn resume_without_a_snapshot_starts_again_to_the_bytes_of_a_fresh_run() {
    let dir = tempfile::tempdir().unwrap();
    let (expert, marker) = crashing_expert(dir.path());
    let train = |out: &Path| -> Output {
        let mut args = vec![
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--quiet",
            "--expert",
            &expert,
            "-o",
            out.to_str().unwrap(),
        ];
        for set in &SHORT_ADQN {
            args.extend(["--set", set]);
        }
        arld(&args)
    };
    let run = dir.path().join("run");
    let crashed = train(&run);
    assert!(!crashed.status.success());
    assert!(
        stderr(&crashed).contains("failed.json records why"),
        "{}",
        stderr(&crashed)
    );
    check_failure(&failure(&run), "exit status: 3");
    assert!(!run.join("snapshot.safetensors").exists());

    std::fs::remove_file(&marker).unwrap();
    let resumed = arld(&["train", "--quiet", "--resume", run.to_str().unwrap()]);
    let said = stderr(&resumed);
    assert!(resumed.status.success(), "{said}");
    let lines: Vec<&str> = said.lines().filter(|l| l.contains("step 0")).collect();
    assert_eq!(lines.len(), 1, "{said}");
    assert!(lines[0].contains("no snapshot"), "{said}");
    assert!(run.join("summary.json").is_file());
    assert!(!run.join("failed.json").exists());

    let fresh = dir.path().join("fresh");
    let out = train(&fresh);
    assert!(out.status.success(), "{}", stderr(&out));
    for file in ["eval.csv", "queries.csv", "episodes.csv", "config.toml"] {
        let (a, b) = (
            std::fs::read(run.join(file)).unwrap(),
            std::fs::read(fresh.join(file)).unwrap(),
        );
        assert!(
            a == b,
            "{file} differs between the restarted run and a fresh one"
        );
    }
    let queries = std::fs::read_to_string(run.join("queries.csv")).unwrap();
    assert!(queries.lines().count() > 1, "the run asked no query");

    // Still refused: a directory without a run's configuration, and a finished run.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let out = arld(&["train", "--resume", empty.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("holds no run to resume"),
        "{}",
        stderr(&out)
    );
    assert_eq!(std::fs::read_dir(&empty).unwrap().count(), 0);
    let out = arld(&["train", "--resume", run.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("finished run"), "{}", stderr(&out));
}

/// `arld --version` prints the version and, built in a git checkout, the commit HEAD names (short, perhaps with
/// `-dirty`).
#[test]
fn version_names_the_commit_it_was_built_from() {
    let out = arld(&["--version"]);
    assert!(out.status.success());
    let text = stdout(&out);
    assert!(
        text.starts_with(&format!("arld {} (git ", env!("CARGO_PKG_VERSION"))),
        "{text}"
    );
    let root = env!("CARGO_MANIFEST_DIR");
    let head = Command::new("git")
        .args(["-C", root, "rev-parse", "HEAD"])
        .output();
    let Some(head) = head.ok().filter(|o| o.status.success()) else {
        eprintln!("not a git checkout (or no git): only the version is checked");
        return;
    };
    let head = String::from_utf8_lossy(&head.stdout).trim().to_string();
    let commit = text
        .trim()
        .trim_end_matches(')')
        .rsplit("(git ")
        .next()
        .unwrap()
        .trim_end_matches("-dirty");
    assert!(
        commit.len() >= 7 && head.starts_with(commit),
        "arld --version says {text:?}, HEAD is {head}"
    );
    assert_eq!(
        arld::GIT_COMMIT,
        text.trim()
            .trim_end_matches(')')
            .rsplit("(git ")
            .next()
            .unwrap()
    );
}
