//! End-to-end test of the web expert in a real headless Chromium: `arld train --expert web` runs short ADQN runs
//! on CartPole-v0 (turn-based, with a question left unanswered until its timeout) and LunarLander-v2 (real time),
//! and a scripted person (tests/e2e/person.mjs, Playwright) answers by pressing keys. The runs must complete, and
//! queries.csv must show the person's answers. The script itself checks the drawing is not blank, that requests
//! without the token get 403 and that a watching tab's messages are refused; screenshots go to
//! target/e2e-screenshots/.
//!
//! Needs Debian's `chromium` (/usr/bin/chromium, or $CHROMIUM), `node`, and `npm ci` in tests/e2e
//! (`scripts/test --setup` installs all three); without them the test fails, naming what is missing and that
//! command.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn e2e_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/e2e")
}

/// Fails with the reason when something the browser test needs is missing.
fn check_prerequisites() {
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    let mut missing = Vec::new();
    if !Path::new(&chromium).is_file() {
        missing.push(format!("Chromium at {chromium} (Debian's chromium)"));
    }
    if Command::new("node").arg("--version").output().is_err() {
        missing.push("node (Debian's nodejs)".to_string());
    }
    if !e2e_dir().join("node_modules/playwright-core").is_dir() {
        missing.push(
            "playwright-core (in tests/e2e/node_modules, from its package-lock.json)".to_string(),
        );
    }
    assert!(
        missing.is_empty(),
        "the web expert's browser test cannot run; missing: {}; `scripts/test --setup` installs them",
        missing.join(", ")
    );
}

/// Waits for `child`, killing it if it is still running after `limit` (a hang guard, not a timing check).
fn wait(child: &mut Child, limit: Duration, what: &str) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            return status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("{what} did not finish within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

struct Outcome {
    /// The person's answers to opening questions, in order.
    answers: Vec<usize>,
    skipped: usize,
    run: PathBuf,
}

/// Starts `arld train --expert web ...`, lets the scripted person answer, and returns what both did.
fn run_with_person(env: &str, web_args: &[&str], sets: &[&str], person_args: &[&str]) -> Outcome {
    let tmp = tempfile::tempdir().unwrap().keep();
    let run = tmp.join("run");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_arld"));
    cmd.args([
        "train",
        "--env",
        env,
        "--method",
        "adqn",
        "--net",
        "bootstrap",
    ])
    .args(["--expert", "web", "--listen", "127.0.0.1:0", "--quiet"])
    .args(web_args)
    .arg("-o")
    .arg(&run);
    for s in sets {
        cmd.args(["--set", s]);
    }
    let mut arld = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start arld");
    let mut lines = BufReader::new(arld.stdout.take().unwrap()).lines();
    let url = loop {
        let line = lines
            .next()
            .expect("arld exited before printing the URL")
            .unwrap();
        if let Some(i) = line.find("http://") {
            break line[i..].trim().to_string();
        }
    };
    assert!(url.starts_with("http://127.0.0.1:") && url.contains("?token="));
    let shots = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("../e2e-screenshots")
        .join(env);
    let person = Command::new("node")
        .current_dir(e2e_dir())
        .arg("person.mjs")
        .args(["--url", &url, "--shots"])
        .arg(&shots)
        .args(person_args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start node");
    let out = person.wait_with_output().expect("node");
    let status = wait(&mut arld, Duration::from_secs(120), "arld");
    assert!(
        out.status.success(),
        "the scripted person failed on {env}: {}{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(status.success(), "arld failed on {env}");
    let report: serde_json::Value = serde_json::from_slice(
        out.stdout
            .split(|&b| b == b'\n')
            .rfind(|l| l.starts_with(b"{"))
            .expect("the person's report"),
    )
    .unwrap();
    if person_args.contains(&"--reload") {
        assert_eq!(report["reloaded"], true);
    }
    for name in ["training", "asking", "mid-segment"] {
        assert!(shots.join(format!("{name}.png")).is_file(), "{name}.png");
    }
    let refused = &report["refused"];
    for what in ["page", "script", "wrongToken", "websocket", "other"] {
        assert_eq!(refused[what], 403, "{what} without the token");
    }
    Outcome {
        answers: report["answers"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a.as_u64().unwrap() as usize)
            .collect(),
        skipped: report["skipped"].as_u64().unwrap() as usize,
        run,
    }
}

#[derive(Debug, serde::Deserialize)]
struct Row {
    expert_action: Option<usize>,
    expert: String,
    response_s: Option<f64>,
    answered: bool,
}

fn queries(run: &Path) -> Vec<Row> {
    csv::Reader::from_path(run.join("queries.csv"))
        .unwrap()
        .deserialize()
        .map(|r| r.unwrap())
        .collect()
}

fn summary(run: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn a_scripted_person_answers_in_headless_chromium() {
    check_prerequisites();

    // CartPole-v0, turn-based; the first question is left to time out; a second tab watches and the answering
    // tab reloads while the run goes on.
    let cart = run_with_person(
        "CartPole-v0",
        &["--web-timeout", "3"],
        &["train_steps=2500", "budget=30", "eval_period=500"],
        &["--skip", "1", "--reload"],
    );
    let rows = queries(&cart.run);
    assert!(rows.iter().all(|r| r.expert == "web"));
    let (answered, unanswered): (Vec<_>, Vec<_>) = rows.iter().partition(|r| r.answered);
    // The person skipped `skipped` questions; one more may have timed out before the browser came up.
    assert!(unanswered.len() >= cart.skipped && cart.skipped == 1);
    assert!(
        unanswered
            .iter()
            .all(|r| r.expert_action.is_none() && r.response_s.unwrap() >= 3.0)
    );
    assert_eq!(
        answered
            .iter()
            .map(|r| r.expert_action.unwrap())
            .collect::<Vec<_>>(),
        cart.answers,
        "queries.csv does not show the person's answers"
    );
    assert!(answered.iter().all(|r| r.response_s.is_some()));
    let s = summary(&cart.run);
    assert_eq!(s["train_steps"], 2500);
    // The unanswered question cost nothing: the budget was spent on answered segments only.
    assert!(s["queries_used"].as_u64().unwrap() <= 5 * answered.len() as u64);
    assert!(s["queries_used"].as_u64().unwrap() > 0);

    // LunarLander-v2, real time at 40 steps per second.
    let lander = run_with_person(
        "LunarLander-v2",
        &["--web-fps", "40"],
        &[
            "train_steps=2500",
            "budget=40",
            "eval_period=1250",
            "eval_episodes=2",
        ],
        &["--realtime"],
    );
    let rows = queries(&lander.run);
    assert!(!rows.is_empty() && rows.iter().all(|r| r.answered && r.expert == "web"));
    assert_eq!(
        rows.iter()
            .map(|r| r.expert_action.unwrap())
            .collect::<Vec<_>>(),
        lander.answers
    );
    assert_eq!(summary(&lander.run)["train_steps"], 2500);
}
