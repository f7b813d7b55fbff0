//! End-to-end test of the web expert in a real headless Chromium: `arld train --expert web` runs short ADQN runs
//! on CartPole-v0 (turn-based, with a question left unanswered until its timeout) and LunarLander-v2 (real time),
//! and a scripted person (tests/e2e/person.mjs, Playwright) answers by pressing keys; in a real-time CartPole run
//! another (tests/e2e/takeover.mjs) also takes over unasked and hands back (and in another run is stopped while
//! holding control, then resumed); at the continuous lander tests/e2e/segments.mjs checks the agent's proposal at
//! every step, the line after each segment and a retry, and tests/e2e/lander_pad.mjs lands it with a scripted
//! gamepad. The runs must complete, and
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

mod common;
use common::ARLD;

fn e2e_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/e2e")
}

/// One browser test at a time: the real-time tests pace a person against the run's clock, and two headless
/// Chromiums plus two runs on a small machine would test the machine's load rather than the page.
static ONE_BROWSER: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Fails with the reason when something the browser test needs is missing; otherwise waits for the other browser
/// tests to finish and returns the guard that keeps them waiting until this one ends (hold it for the test).
#[must_use = "the guard keeps the other browser tests waiting: bind it for the whole test"]
fn check_prerequisites() -> std::sync::MutexGuard<'static, ()> {
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
    ONE_BROWSER
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
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
    /// The scripted person's whole report.
    report: serde_json::Value,
}

/// Starts `arld` with `args` (stdout piped, `--quiet` added) and returns it with the URL it printed.
fn start_arld(args: &[&std::ffi::OsStr], stderr: Stdio) -> (Child, String) {
    let mut arld = Command::new(ARLD)
        .args(args)
        .arg("--quiet")
        .stdout(Stdio::piped())
        .stderr(stderr)
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
    // Keep reading its output, so that a full pipe never blocks it.
    std::thread::spawn(move || lines.for_each(drop));
    assert!(url.starts_with("http://127.0.0.1:") && url.contains("?token="));
    (arld, url)
}

/// Runs the scripted person on `url` until it leaves; its report (the last JSON line it printed).
fn run_person(url: &str, shots: &Path, person_args: &[&str], what: &str) -> serde_json::Value {
    let out = Command::new("node")
        .current_dir(e2e_dir())
        .arg("person.mjs")
        .args(["--url", url, "--shots"])
        .arg(shots)
        .args(person_args)
        .output()
        .expect("start node");
    assert!(
        out.status.success(),
        "the scripted person failed on {what}: {}{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    serde_json::from_slice(
        out.stdout
            .split(|&b| b == b'\n')
            .rfind(|l| l.starts_with(b"{"))
            .expect("the person's report"),
    )
    .unwrap()
}

fn shots_dir(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("../e2e-screenshots")
        .join(name)
}

/// Starts `arld train --expert web ...`, lets the scripted person answer, and returns what both did.
fn run_with_person(env: &str, web_args: &[&str], sets: &[&str], person_args: &[&str]) -> Outcome {
    let tmp = tempfile::tempdir().unwrap().keep();
    let run = tmp.join("run");
    let mut args: Vec<std::ffi::OsString> = [
        "train",
        "--env",
        env,
        "--method",
        "adqn",
        "--net",
        "bootstrap",
        "--expert",
        "web",
        "--listen",
        "127.0.0.1:0",
    ]
    .iter()
    .map(Into::into)
    .collect();
    args.extend(web_args.iter().map(Into::into));
    args.extend(["-o".into(), run.clone().into_os_string()]);
    for s in sets {
        args.extend(["--set".into(), s.into()]);
    }
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let (mut arld, url) = start_arld(&args, Stdio::inherit());
    let shots = shots_dir(env);
    let report = run_person(&url, &shots, person_args, env);
    let status = wait(&mut arld, Duration::from_secs(120), "arld");
    assert!(status.success(), "arld failed on {env}");
    if person_args.contains(&"--reload") {
        assert_eq!(report["reloaded"], true);
    }
    for name in ["training", "asking", "mid-segment"] {
        assert!(shots.join(format!("{name}.png")).is_file(), "{name}.png");
    }
    let refused = &report["refused"];
    for what in [
        "page",
        "script",
        "wrongToken",
        "websocket",
        "other",
        "foreignHost",
        "foreignOrigin",
        "otherPort",
        "repeatedToken",
    ] {
        assert_eq!(refused[what], 403, "{what}: not refused");
    }
    assert!(
        refused["csp"]
            .as_str()
            .unwrap()
            .contains("script-src 'self'")
    );
    Outcome {
        answers: report["answers"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a.as_u64().unwrap() as usize)
            .collect(),
        skipped: report["skipped"].as_u64().unwrap() as usize,
        run,
        report,
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
    let _one_browser = check_prerequisites();

    // CartPole-v0, turn-based; the first question is left to time out; a second tab watches and the answering
    // tab reloads while the run goes on.
    let cart = run_with_person(
        "CartPole-v0",
        &["--web-timeout", "3"],
        &["train_steps=10000", "budget=30", "eval_period=2500"],
        &["--skip", "1", "--reload", "--undo"],
    );
    // The person undid a wrong key (the page showed the state after it, then the question's own state again:
    // person.mjs checks both) and answered; the agent's steps before questions were replayed to them, ending at
    // the question's state (checked by person.mjs), watched once and skipped with a key afterwards.
    let undo = &cart.report["undo"];
    assert!(undo.is_object(), "no undo was tried: {}", cart.report);
    assert_ne!(undo["ahead"], undo["asked"]);
    assert_eq!(undo["back"], undo["asked"]);
    assert_eq!(cart.report["replaysWatched"], 1, "{}", cart.report);
    assert!(cart.report["replaysSkipped"].as_u64().unwrap() >= 1);
    let rows = queries(&cart.run);
    assert!(rows.iter().all(|r| r.expert == "web"));
    let (answered, unanswered): (Vec<_>, Vec<_>) = rows.iter().partition(|r| r.answered);
    // The person skipped `skipped` questions; one more may have timed out before the browser came up.
    assert!(unanswered.len() >= cart.skipped && cart.skipped == 1);
    // The page said the skipped question timed out (it was not replaced silently).
    let notice = &cart.report["timeoutNotices"][0];
    assert!(
        notice["count"].as_u64() >= Some(1)
            && notice["banner"].as_str().unwrap().starts_with("Time is up"),
        "{notice}"
    );
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
    assert_eq!(s["train_steps"], 10000);
    // The unanswered question cost nothing: the budget was spent on answered segments only.
    assert!(s["demos_queried"].as_u64().unwrap() <= 5 * answered.len() as u64);
    assert!(s["demos_queried"].as_u64().unwrap() > 0);

    // LunarLander-v2, real time at 40 steps per second. The budget runs out near step 170; the steps after it
    // train without questions long enough for the page to show the training state on a loaded machine.
    const LANDER_STEPS: u64 = 6000;
    let lander_steps = format!("train_steps={LANDER_STEPS}");
    let lander = run_with_person(
        "LunarLander-v2",
        &["--web-fps", "40"],
        &[
            lander_steps.as_str(),
            "budget=40",
            "eval_period=3000",
            "eval_episodes=2",
        ],
        &["--realtime"],
    );
    let rows = queries(&lander.run);
    assert!(!rows.is_empty() && rows.iter().all(|r| r.answered && r.expert == "web"));
    // Real time without segment_len or --web-segment-s: a question hands the person the default 3 s of play,
    // 120 steps at 40 per second (the budget of 40 cuts the first one short).
    let config = std::fs::read_to_string(lander.run.join("config.toml")).unwrap();
    assert!(config.contains("\nsegment_len = 120\n"), "{config}");
    // Each real-time segment began at once with the person's key (an action's: no countdown is needed).
    assert_eq!(lander.report["countdownsSeen"], 0, "{}", lander.report);
    assert_eq!(
        rows.iter()
            .map(|r| r.expert_action.unwrap())
            .collect::<Vec<_>>(),
        lander.answers
    );
    assert_eq!(summary(&lander.run)["train_steps"], LANDER_STEPS);
}

/// The floats of a JSON array.
fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

#[test]
fn a_stop_while_a_question_is_open_loses_nothing_and_resume_asks_it_again() {
    let _one_browser = check_prerequisites();
    // An evaluation every 20 steps (of 2 episodes): the run has a few when it stops, near step 50, for the charts
    // of the resumed page to draw.
    // The budget runs out near step 60; the steps after it train without questions, long enough for the page
    // to show (and the person to screenshot) the training state even on a loaded machine (at 1500 steps, about
    // 0.2 s of training, a loaded CI machine once reached the end first).
    const TRAIN_STEPS: u64 = 10_000;
    let train_steps = format!("train_steps={TRAIN_STEPS}");
    let run = tempfile::tempdir().unwrap().keep().join("run");
    let run_arg = run.clone().into_os_string();
    let words = [
        "train",
        "--env",
        "CartPole-v0",
        "--method",
        "adqn",
        "--net",
        "bootstrap",
        "--expert",
        "web",
        "--listen",
        "127.0.0.1:0",
        "--set",
        train_steps.as_str(),
        "--set",
        "budget=30",
        "--set",
        "eval_period=20",
        "--set",
        "eval_episodes=2",
        "-o",
    ];
    let mut args: Vec<&std::ffi::OsStr> = words.iter().map(std::ffi::OsStr::new).collect();
    args.push(&run_arg);
    let (mut arld, url) = start_arld(&args, Stdio::piped());

    // The person answers three questions and leaves the fourth open; then a SIGTERM stops the run.
    let before = run_person(
        &url,
        &shots_dir("stop"),
        &["--answer", "3"],
        "the stopped run",
    );
    let answered: Vec<usize> = before["answers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(answered.len(), 3);
    let open = &before["open"];
    assert!(
        open.is_object(),
        "the person saw no fourth question: {before}"
    );
    let killed = Command::new("kill")
        .args(["-TERM", &arld.id().to_string()])
        .status()
        .expect("kill");
    assert!(killed.success());
    let status = wait(&mut arld, Duration::from_secs(20), "arld after SIGTERM");
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut arld.stderr.take().unwrap(), &mut stderr).unwrap();
    assert_eq!(
        status.code(),
        Some(143),
        "exit status after SIGTERM; stderr: {stderr}"
    );
    assert!(
        stderr.contains("while a question was open")
            && stderr.contains(&format!("arld train --resume {}", run.display())),
        "the stop does not say where the run stands and how to continue: {stderr}"
    );
    assert!(run.join("snapshot.safetensors").is_file(), "no snapshot");
    let csv_before = std::fs::read_to_string(run.join("queries.csv")).unwrap();
    let rows = queries(&run);
    assert_eq!(
        rows.iter().map(|r| r.expert_action).collect::<Vec<_>>(),
        answered.iter().map(|&a| Some(a)).collect::<Vec<_>>(),
        "queries.csv after the stop does not hold the person's answers"
    );
    assert!(std::fs::metadata(run.join("episodes.csv")).unwrap().len() > 0);
    // The run's course at the stop, read here from its files: its evaluations (eval.csv: step and mean) and the
    // uncertainties logged with its questions (queries.csv: step, uncertainty, threshold or none).
    let curve_before: Vec<(f64, f64)> = csv::Reader::from_path(run.join("eval.csv"))
        .unwrap()
        .records()
        .map(|r| {
            let r = r.unwrap();
            (r[0].parse().unwrap(), r[1].parse().unwrap())
        })
        .collect();
    let uncertainty_before: Vec<(f64, f64, Option<f64>)> =
        csv::Reader::from_path(run.join("queries.csv"))
            .unwrap()
            .records()
            .map(|r| r.unwrap())
            .filter(|r| !r[2].is_empty())
            .map(|r| {
                let threshold = (!r[3].is_empty()).then(|| r[3].parse().unwrap());
                (r[0].parse().unwrap(), r[2].parse().unwrap(), threshold)
            })
            .collect();
    assert!(!curve_before.is_empty(), "no evaluation before the stop");
    assert!(!uncertainty_before.is_empty(), "{csv_before}");

    // Resumed, the run asks the open question again; the person answers to the end.
    let (mut arld, url) = start_arld(
        &[
            std::ffi::OsStr::new("train"),
            std::ffi::OsStr::new("--resume"),
            run.as_os_str(),
        ],
        Stdio::inherit(),
    );
    let after = run_person(&url, &shots_dir("resumed"), &[], "the resumed run");
    let status = wait(&mut arld, Duration::from_secs(120), "the resumed arld");
    assert!(status.success(), "the resumed run failed");
    let first = &after["first"];
    assert_eq!(
        floats(&first["obs"]),
        floats(&open["obs"]),
        "the resumed run did not ask the open question again"
    );
    assert_eq!(first["agent_action"], open["agent_action"]);
    assert_eq!(first["steps_left"], open["steps_left"]);
    // The status panel is filled as the question is asked again: where the run stood when it stopped.
    assert_eq!(
        first["statusStep"], open["statusStep"],
        "the resumed run's page did not show where it stands: {first}"
    );
    assert!(
        first["panel"].as_str().unwrap().contains(" / ")
            && !first["panel"].as_str().unwrap().starts_with('–'),
        "the step in the status panel: {first}"
    );
    // The charts draw the run's course before the stop as the question is asked again: each evaluation and
    // each question's uncertainty, with the threshold then.
    let charts = &first["charts"];
    let curve_shown: Vec<(f64, f64)> = charts["curve"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
        .collect();
    assert_eq!(curve_shown, curve_before, "{charts}");
    let uncertainty_shown: Vec<(f64, f64, Option<f64>)> = charts["uncertainty"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p[0].as_f64().unwrap(),
                p[1].as_f64().unwrap(),
                p[2].as_f64(),
            )
        })
        .collect();
    assert_eq!(uncertainty_shown, uncertainty_before, "{charts}");
    let csv_after = std::fs::read_to_string(run.join("queries.csv")).unwrap();
    assert!(
        csv_after.starts_with(&csv_before),
        "the answers before the stop changed:\n{csv_before}\n---\n{csv_after}"
    );
    let rows = queries(&run);
    let later: Vec<usize> = after["answers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(
        rows.iter()
            .filter(|r| r.answered)
            .map(|r| r.expert_action.unwrap())
            .collect::<Vec<_>>(),
        [answered, later].concat()
    );
    assert_eq!(summary(&run)["train_steps"], TRAIN_STEPS);
}

/// Runs the scripted person tests/e2e/`script` on `url` until it leaves; its report (the last JSON line it
/// printed).
fn run_script(script: &str, url: &str, shots: &Path) -> serde_json::Value {
    run_script_with(script, url, shots, &[])
}

/// [`run_script`] with the script's own arguments `extra`.
fn run_script_with(script: &str, url: &str, shots: &Path, extra: &[&str]) -> serde_json::Value {
    let out = Command::new("node")
        .current_dir(e2e_dir())
        .arg(script)
        .args(["--url", url, "--shots"])
        .arg(shots)
        .args(extra)
        .output()
        .expect("start node");
    assert!(
        out.status.success(),
        "the scripted person of {script} failed: {}{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    serde_json::from_slice(
        out.stdout
            .split(|&b| b == b'\n')
            .rfind(|l| l.starts_with(b"{"))
            .expect("the person's report"),
    )
    .unwrap()
}

/// The lines of `answers.jsonl`.
fn answer_lines(run: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(run.join("answers.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// The person's takeovers in answers.jsonl, in order: each one's lines (those `started_by` the person, grouped by
/// the step the takeover opened at). Every takeover but the last must have ended with its episode (the script
/// takes over again when the episode ends too soon: tests/e2e/takeover.mjs's `early`), so every later line is of
/// a later episode; and there are as many as the script reports.
fn takeovers<'a>(
    lines: &'a [serde_json::Value],
    report: &serde_json::Value,
) -> Vec<Vec<&'a serde_json::Value>> {
    let mut groups: Vec<Vec<&serde_json::Value>> = Vec::new();
    for l in lines.iter().filter(|l| l["started_by"] == "person") {
        match groups.last_mut() {
            Some(g) if g[0]["question_step"] == l["question_step"] => g.push(l),
            _ => groups.push(vec![l]),
        }
    }
    let early = report["takeover"]["early"].as_array().map_or(0, Vec::len);
    assert_eq!(
        groups.len(),
        early + 1,
        "takeovers logged, and reported: {report}"
    );
    for g in &groups[..early] {
        let episode = g[0]["episode"].as_u64().unwrap();
        let last = g.last().unwrap()["step"].as_u64().unwrap();
        for l in lines.iter().filter(|l| l["step"].as_u64().unwrap() > last) {
            assert!(
                l["episode"].as_u64().unwrap() > episode,
                "an early takeover's episode went on: {l}"
            );
        }
    }
    groups
}

/// Steps and budget (transitions) of [`start_realtime_cartpole`]'s run.
const REALTIME_STEPS: u64 = 4000;
const REALTIME_BUDGET: u64 = 60;

/// Starts `arld train` of a real-time CartPole-v0 run in a new directory: a person answers at 20 steps a second, a
/// quarter second (5 steps) of play per question, within a budget of [`REALTIME_BUDGET`] transitions over
/// [`REALTIME_STEPS`] steps. Returns the run directory, the process and the URL it printed.
fn start_realtime_cartpole(stderr: Stdio) -> (PathBuf, Child, String) {
    let run = tempfile::tempdir().unwrap().keep().join("run");
    let mut args: Vec<std::ffi::OsString> = [
        "train",
        "--env",
        "CartPole-v0",
        "--method",
        "adqn",
        "--net",
        "bootstrap",
        "--expert",
        "web",
        "--web-fps",
        "20",
        "--web-segment-s",
        "0.25",
        "--listen",
        "127.0.0.1:0",
    ]
    .iter()
    .map(Into::into)
    .collect();
    for set in [
        format!("train_steps={REALTIME_STEPS}"),
        format!("budget={REALTIME_BUDGET}"),
        "eval_period=2000".to_string(),
    ] {
        args.extend(["--set".into(), set.into()]);
    }
    args.extend(["-o".into(), run.as_os_str().to_owned()]);
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let (arld, url) = start_arld(&args, stderr);
    (run, arld, url)
}

#[test]
fn a_person_takes_over_unasked_in_real_time_and_hands_back() {
    let _one_browser = check_prerequisites();
    // CartPole-v0 in real time at 20 steps per second, a budget of 60 transitions: the agent asks (the rule's
    // questions), and in between the person presses T, acts for a while and hands back with Esc.
    let (run, mut arld, url) = start_realtime_cartpole(Stdio::inherit());
    let shots = shots_dir("takeover");
    let report = run_script_with("takeover.mjs", &url, &shots, &["--watch"]);
    let status = wait(&mut arld, Duration::from_secs(180), "arld");
    assert!(status.success(), "arld failed: {report}");
    assert!(shots.join("takeover.png").is_file());
    let t = &report["takeover"];

    // The page offered the button while the agent acted, and showed the takeover with the hand-back control.
    assert_eq!(t["offered"]["takeoverButton"]["disabled"], false, "{t}");
    let during = &t["inProgress"];
    assert_eq!(during["className"], "takeover", "{t}");
    assert!(
        during["text"]
            .as_str()
            .unwrap()
            .starts_with("You have control"),
        "{t}"
    );
    assert_eq!(during["pass"]["text"], "Hand back [Esc]");
    assert_eq!(during["pass"]["disabled"], false);
    assert_ne!(
        t["after"]["className"], "takeover",
        "the takeover did not end: {t}"
    );
    assert_eq!(t["after"]["pass"], "Let the agent decide [Esc]", "{t}");

    // answers.jsonl: the person's steps, started by them, in one stretch from the state they took over in.
    let lines = answer_lines(&run);
    let rule: Vec<_> = lines
        .iter()
        .filter(|l| l["started_by"] != "person")
        .collect();
    assert!(!rule.is_empty(), "no question of the rule was answered");
    assert!(rule.iter().all(|l| l["started_by"] == "rule"));
    let all_takeovers = takeovers(&lines, &report);
    let person = all_takeovers.last().unwrap();
    let opened = person[0]["question_step"].as_u64().unwrap();
    assert!(
        person.len() >= 5,
        "the takeover held {} steps",
        person.len()
    );
    for (k, l) in person.iter().enumerate() {
        assert_eq!(l["question_step"].as_u64(), Some(opened), "{l}");
        assert_eq!(l["step"].as_u64(), Some(opened + k as u64), "{l}");
        assert_eq!(l["episode"], person[0]["episode"]);
        assert_eq!(l["expert"], "web");
        assert!(l["threshold"].is_null(), "a takeover has no threshold: {l}");
        assert_eq!(l["agent_action"], t["agentAction"]);
    }
    // It began in the state the page showed when the person took over, with the key they pressed first.
    assert_eq!(floats(&person[0]["obs"]), floats(&t["obs"]));
    assert_eq!(person[0]["action"], t["first"]);
    assert!(person[0]["uncertainty"].is_number());
    if t["endedByEpisode"].is_null() {
        // Handed back: the takeover ended at the step the page showed then (give or take the steps in flight).
        let back = t["handedBackAtStep"].as_u64().unwrap();
        let last = person.last().unwrap()["step"].as_u64().unwrap();
        assert!(
            last + 1 >= back && last < back + 40,
            "last step {last}, handed back at {back}"
        );
    }

    // queries.csv holds the rule's questions only (its columns unchanged); the takeover is not one of them.
    let csv = std::fs::read_to_string(run.join("queries.csv")).unwrap();
    assert!(csv.starts_with(
        "step,episode,uncertainty,threshold,expert_action,agent_action,expert,response_s,answered\n"
    ));
    let asked: Vec<u64> = csv::Reader::from_path(run.join("queries.csv"))
        .unwrap()
        .records()
        .map(|r| r.unwrap()[0].parse().unwrap())
        .collect();
    for t in &all_takeovers {
        assert!(!asked.contains(&t[0]["question_step"].as_u64().unwrap()));
    }
    for l in &rule {
        assert!(asked.contains(&l["question_step"].as_u64().unwrap()));
    }

    // The budget: every step the expert took (asked or taken over) is one unit, within the budget.
    let s = summary(&run);
    assert_eq!(s["demos_queried"].as_u64(), Some(lines.len() as u64));
    assert!(lines.len() as u64 <= REALTIME_BUDGET);
    assert_eq!(s["train_steps"], REALTIME_STEPS);
    assert_eq!(
        report["endScreen"]["rows"]["Takeovers"],
        all_takeovers.len().to_string(),
        "{report}"
    );
    // Watch mode (on after the first question): while the agent acted, its steps went at most at the real-time
    // rate of 20 a second (a quarter more for the page's sampling), and none of that time was the person's (but
    // for the bookkeeping of the agent's questions that went back to it unasked meanwhile: microseconds each).
    let watch = &report["watch"];
    let (steps, seconds) = (
        watch["steps"].as_f64().unwrap(),
        watch["seconds"].as_f64().unwrap(),
    );
    assert!(seconds >= 1.0, "too little watched: {watch}");
    assert!(
        steps > 0.0 && steps <= 25.0 * seconds + 2.0,
        "{steps} steps in {seconds} s: {watch}"
    );
    assert!(watch["personS"].as_f64() < Some(0.05), "{watch}");
    // A request made while paused was pending (the button offered to cancel it) and T again cancelled it: no
    // takeover followed it (the script fails on one nobody asked for), only the one asked for next.
    let cancel = &watch["cancel"];
    assert_eq!(
        cancel["pending"]["takeoverButton"]["text"], "Cancel take over [T]",
        "{cancel}"
    );
    assert!(
        cancel["pending"]["text"]
            .as_str()
            .unwrap()
            .starts_with("You take over at the agent's next step, when the run goes on"),
        "{cancel}"
    );
    assert_eq!(
        cancel["cancelled"]["takeoverButton"]["text"], "Take over [T]",
        "{cancel}"
    );
}

/// A takeover starts only from a request made while the agent acts: a person who presses T the moment each of
/// their segments ends (tests/e2e/takeover.mjs --breath) hits both the agent acting (a takeover opens at once, and
/// they hand it back) and the breath before the agent's next question (the question comes first, and no takeover
/// may open after its segment: the script fails on one nobody asked for). Both must have happened; answers.jsonl
/// holds the rule's segments only (the takeovers were handed back at their opening, before any step).
#[test]
fn a_takeover_asked_for_in_the_breath_before_a_question_never_starts() {
    let _one_browser = check_prerequisites();
    let (run, mut arld, url) = start_realtime_cartpole(Stdio::inherit());
    let report = run_script_with(
        "takeover.mjs",
        &url,
        &shots_dir("takeover-breath"),
        &["--breath"],
    );
    let status = wait(&mut arld, Duration::from_secs(180), "arld");
    assert!(status.success(), "arld failed: {report}");
    let breath = &report["breath"];
    assert!(
        breath["refused"].as_u64() >= Some(1),
        "T never fell in a breath before a question: {report}"
    );
    let lines = answer_lines(&run);
    assert!(!lines.is_empty());
    assert!(
        lines.iter().all(|l| l["started_by"] == "rule"),
        "a takeover took steps: {report}"
    );
    let s = summary(&run);
    assert_eq!(s["demos_queried"].as_u64(), Some(lines.len() as u64));
    assert_eq!(s["train_steps"], REALTIME_STEPS);
}

/// A person takes over in real time (CartPole-v0 at 20 steps a second) and, while they hold control, the run is
/// stopped (SIGTERM, sent by tests/e2e/takeover.mjs once they have had 6 steps). Nothing is lost and nothing is
/// logged twice: queries.csv and answers.jsonl after the resume begin with their bytes at the stop, the takeover's
/// steps are one consecutive stretch from the step it opened at (each logged once) that goes on after the resume,
/// and the budget spent is the lines logged. Resumed, the page opens on the takeover, with the person in control
/// and the status where the run stopped; they hand back, and the run ends with one takeover on its end screen.
#[test]
fn a_stop_while_a_person_holds_control_loses_nothing_and_resume_gives_it_back() {
    let _one_browser = check_prerequisites();
    let (run, mut arld, url) = start_realtime_cartpole(Stdio::piped());
    let pid = arld.id().to_string();
    let shots = shots_dir("takeover-stop");
    let before = run_script_with(
        "takeover.mjs",
        &url,
        &shots,
        &["--stop", "6", "--pid", &pid, "--watch"],
    );
    let status = wait(&mut arld, Duration::from_secs(20), "arld after SIGTERM");
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut arld.stderr.take().unwrap(), &mut stderr).unwrap();
    assert_eq!(status.code(), Some(143), "stderr: {stderr}");
    assert!(
        stderr.contains(&format!("arld train --resume {}", run.display())),
        "{stderr}"
    );
    assert!(run.join("snapshot.safetensors").is_file(), "no snapshot");
    assert!(shots.join("takeover.png").is_file() && shots.join("takeover-stopped.png").is_file());
    let stopped = &before["stopped"];
    assert_eq!(stopped["prompt"]["takeover"], true, "{before}");
    assert!(
        stopped["after"]["ended"]
            .as_str()
            .unwrap()
            .starts_with("The run was stopped"),
        "{before}"
    );
    let csv_before = std::fs::read_to_string(run.join("queries.csv")).unwrap();
    let answers_before = std::fs::read_to_string(run.join("answers.jsonl")).unwrap();
    let lines_before = answer_lines(&run);
    let takeovers_before = takeovers(&lines_before, &before);
    let person_before = takeovers_before.last().unwrap();
    assert!(person_before.len() >= 6, "{before}");
    let opened = person_before[0]["question_step"].as_u64().unwrap();
    // The step the run stopped at: the one after the last logged.
    let stop_step = person_before.last().unwrap()["step"].as_u64().unwrap() + 1;

    let (mut arld, url) = start_arld(
        &[
            std::ffi::OsStr::new("train"),
            std::ffi::OsStr::new("--resume"),
            run.as_os_str(),
        ],
        Stdio::inherit(),
    );
    let after = run_script_with(
        "takeover.mjs",
        &url,
        &shots_dir("takeover-resumed"),
        &["--resumed", "--hold", "6"],
    );
    let status = wait(&mut arld, Duration::from_secs(180), "the resumed arld");
    assert!(status.success(), "the resumed run failed: {after}");
    // The page opened on the takeover, the person in control, and the run waits for their fresh key: the page
    // shows the step the run stopped at and the budget spent then, also a second later, before the key.
    let resumed = &after["takeover"]["resumed"];
    assert_eq!(resumed["prompt"]["takeover"], true, "{after}");
    assert_eq!(resumed["prompt"]["waits"], true, "{after}");
    for shown in [&resumed["status"], &resumed["beforeKey"]["status"]] {
        assert_eq!(shown["step"].as_u64(), Some(stop_step), "{after}");
        assert_eq!(
            shown["budget_used"].as_u64(),
            Some(lines_before.len() as u64),
            "{after}"
        );
        assert_eq!(shown["takeovers"], takeovers_before.len(), "{after}");
    }
    assert_eq!(
        resumed["beforeKey"]["prompt"]["id"], resumed["prompt"]["id"],
        "{after}"
    );

    // Nothing before the stop changed; the takeover's steps are one stretch, each step once, going on after it.
    let csv_after = std::fs::read_to_string(run.join("queries.csv")).unwrap();
    assert!(
        csv_after.starts_with(&csv_before),
        "{csv_before}\n---\n{csv_after}"
    );
    let answers_after = std::fs::read_to_string(run.join("answers.jsonl")).unwrap();
    assert!(answers_after.starts_with(&answers_before));
    let lines = answer_lines(&run);
    let early: usize = takeovers_before[..takeovers_before.len() - 1]
        .iter()
        .map(Vec::len)
        .sum();
    let takeover: Vec<u64> = lines
        .iter()
        .filter(|l| l["started_by"] == "person")
        .skip(early)
        .map(|l| {
            assert_eq!(
                l["question_step"].as_u64(),
                Some(opened),
                "a second takeover: {l}"
            );
            l["step"].as_u64().unwrap()
        })
        .collect();
    assert_eq!(
        takeover,
        (opened..opened + takeover.len() as u64).collect::<Vec<_>>()
    );
    assert!(
        takeover.len() > person_before.len(),
        "the takeover did not go on after the resume: {takeover:?}"
    );
    // The first step after the resume is the stopped one, from the state the page showed, with the person's key.
    let first = &lines[lines_before.len()];
    assert_eq!(first["step"].as_u64(), Some(stop_step), "{first}");
    assert_eq!(floats(&first["obs"]), floats(&resumed["obs"]), "{first}");
    assert_eq!(first["action"], resumed["first"], "{first}");
    let s = summary(&run);
    assert_eq!(s["demos_queried"].as_u64(), Some(lines.len() as u64));
    assert!(lines.len() as u64 <= REALTIME_BUDGET);
    assert_eq!(s["train_steps"], REALTIME_STEPS);
    assert_eq!(
        after["endScreen"]["rows"]["Takeovers"],
        takeovers_before.len().to_string(),
        "{after}"
    );
}

/// A person answers Pendulum-v1 (a torque in [-2, 2]) on the page in real time with each continuous control:
/// a gamepad's stick (headless Chromium has no pad: tests/e2e/continuous.mjs feeds `navigator.getGamepads` a
/// scripted pad through an init script), the same after changing the pad's mapping on the page, a held key and
/// the slider; malformed answers sent on the page's socket are refused with errors naming the problem. Every step
/// of each segment in answers.jsonl is the torque the person's control set, computed here from the control's
/// position and the box: a stick at x gives x times the half-width, a held key the bound, the slider its value.
#[test]
fn a_person_answers_a_box_task_with_a_pad_keys_and_a_slider() {
    let _one_browser = check_prerequisites();
    const TRAIN_STEPS: u64 = 3000;
    // Six questions of 20 steps, up to five more until one comes with a replay, and some handed back.
    const BUDGET: u64 = 240;
    let sets = [
        format!("train_steps={TRAIN_STEPS}"),
        format!("budget={BUDGET}"),
        "eval_period=1500".to_string(),
    ];
    let run = tempfile::tempdir().unwrap().keep().join("run");
    let mut args: Vec<std::ffi::OsString> = [
        "train",
        "--env",
        "Pendulum-v1",
        "--method",
        "adqn",
        "--expert",
        "web",
        "--web-fps",
        "20",
        "--web-segment-s",
        "1",
        "--listen",
        "127.0.0.1:0",
    ]
    .iter()
    .map(|a| a.into())
    .collect();
    for s in &sets {
        args.push("--set".into());
        args.push(s.into());
    }
    args.push("-o".into());
    args.push(run.clone().into_os_string());
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let (mut arld, url) = start_arld(&args, Stdio::inherit());
    let shots = shots_dir("continuous");
    let report = run_script("continuous.mjs", &url, &shots);
    let status = wait(&mut arld, Duration::from_secs(240), "arld");
    assert!(status.success(), "arld failed: {report}");
    assert!(shots.join("gamepad-mapping.png").is_file());
    assert!(shots.join("continuous-answer.png").is_file());

    // The hello described the box, its bound read from the task's spec.
    let spec = arld::env::box_spec("Pendulum-v1").unwrap();
    let hello = &report["hello"];
    assert_eq!(hello["box"]["names"], serde_json::json!(["torque"]));
    assert_eq!(
        floats(&hello["box"]["low"]),
        [f64::from(spec.action_low[0])]
    );
    assert_eq!(
        floats(&hello["box"]["high"]),
        [f64::from(spec.action_high[0])]
    );
    let (low, high) = (
        f64::from(spec.action_low[0]),
        f64::from(spec.action_high[0]),
    );
    let half = (high - low) / 2.0;

    let questions = report["questions"].as_array().unwrap();
    assert!(questions.len() >= 5, "{report}");
    // The mapping shown and changed on the page.
    assert_eq!(questions[0]["padBefore"]["map"][0]["source"], 0, "{report}");
    assert_eq!(questions[1]["padAfter"]["map"][0]["source"], 2, "{report}");
    assert_eq!(questions[1]["padTable"][0][1], "right stick X", "{report}");
    // The torque each control gives, from its position: a stick at x gives x times the half-width.
    // (A held key starts its segment at once and pushes the torque from the centre to the bound in 0.4 s: its
    // steps ramp down to the bound, checked below.)
    // (Questions handed back answer nothing.)
    let expected: Vec<(&serde_json::Value, f64)> = questions
        .iter()
        .filter(|q| !q["control"].as_str().unwrap().starts_with("handed back"))
        .map(|q| {
            let want = match q["control"].as_str().unwrap() {
                "keys" => low,
                "slider" => 0.8,
                _ => q["stick"].as_f64().unwrap() * half,
            };
            (q, want)
        })
        .collect();
    assert!(expected.len() >= 7, "{report}");
    // Nothing but a deliberate gesture answered: a stick held from before the question, pushed during a pause or a
    // replay, and its release, left the question waiting (the script fails otherwise); a replay came within the
    // tries.
    for (q, checks) in [
        (4, ["held", "afterRelease"]),
        (5, ["afterPause", "afterRelease"]),
    ] {
        for check in checks {
            assert_eq!(questions[q]["waited"][check], true, "{check}: {report}");
        }
    }
    assert_eq!(
        report["replayTested"], true,
        "no question came with a replay: {report}"
    );
    let lines = answer_lines(&run);
    // A second of play per question at 20 steps a second: 20 steps (fewer only where the episode's time limit cut
    // the segment), recorded in config.toml, each segment lasting about its steps' time on the page.
    let config = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert!(config.contains("\nsegment_len = 20\n"), "{config}");
    let mut lengths = Vec::new();
    for (q, want) in expected {
        // The question's segment: the lines whose first one starts at the state the page asked in.
        let obs = floats(&q["obs"]);
        let first = lines
            .iter()
            .position(|l| floats(&l["obs"]) == obs)
            .unwrap_or_else(|| panic!("no answer for the question {q}"));
        let question_step = &lines[first]["question_step"];
        let segment: Vec<_> = lines
            .iter()
            .filter(|l| &l["question_step"] == question_step)
            .collect();
        assert!(!segment.is_empty());
        // Paced at the real-time rate, not at full speed (a loaded machine may make it slower; the page may not see
        // a segment the episode's time limit cut to a step or two). The script polls the page, which on a loaded
        // machine sees the segment's first running step and its end late by up to a few tenths of a second: half
        // the real-time span still tells pacing from none (at full speed 20 steps take milliseconds).
        let steps = segment.len() as f64;
        match q["segmentS"].as_f64() {
            Some(played) => assert!(
                played >= 0.5 * (steps - 1.0) / 20.0,
                "{steps} steps at 20 per second played in {played} s: {q}"
            ),
            None => assert!(steps <= 2.0, "a segment of {steps} steps not seen: {q}"),
        }
        lengths.push(segment.len());
        let torques: Vec<f64> = segment
            .iter()
            .map(|l| {
                assert_eq!(l["started_by"], "rule");
                assert_eq!(l["expert"], "web");
                let action = floats(&l["action"]);
                assert_eq!(action.len(), 1, "{l}");
                action[0]
            })
            .collect();
        if q["control"] == "keys" {
            // The ramp: below the centre from the first step, down (never up) to the bound, which a whole
            // segment (a second of play) reaches.
            assert!(
                torques.windows(2).all(|w| w[1] <= w[0])
                    && torques.iter().all(|&t| (want..0.0).contains(&t)),
                "{torques:?}"
            );
            if torques.len() == 20 {
                assert_eq!(torques.last(), Some(&want), "{torques:?}");
            }
        } else {
            for t in &torques {
                assert!(
                    (t - want).abs() < 1e-6,
                    "{}: torque {t} where the control gave {want}",
                    q["control"]
                );
            }
        }
    }
    assert!(
        lengths.iter().all(|&n| n <= 20) && lengths.contains(&20),
        "{lengths:?}"
    );
    // The keyboard's segment in progress showed the torque at its bound.
    let during = &questions[2]["inProgress"];
    assert_eq!(during["axes"]["source"], "keys", "{report}");
    assert_eq!(floats(&during["axes"]["values"]), [low], "{report}");
    // The pendulum was drawn mid-segment (not shown as a table).
    assert_eq!(during["drawing"]["kind"], "Pendulum", "{report}");
    assert!(
        during["drawing"]["share"].as_f64() > Some(0.005),
        "{report}"
    );
    // Malformed answers: refused with their reasons, nothing charged for them.
    let errors = report["errors"].as_array().unwrap();
    let says = |i: usize, what: &str| {
        let m = errors[i]["message"].as_str().unwrap();
        assert!(m.contains(what), "{m}");
    };
    says(0, "not a list of 1 numbers");
    says(1, "dimension 0");
    says(2, "not 1");
    // The handed-back questions cost nothing; every answered step is one unit of the budget.
    let s = summary(&run);
    assert_eq!(s["demos_queried"].as_u64(), Some(lines.len() as u64));
    assert!(lines.len() as u64 <= BUDGET);
    assert_eq!(s["train_steps"], TRAIN_STEPS);
}

/// The continuous tasks on the page with a gamepad (tests/e2e/pad_person.mjs: a scripted pad moved by a
/// controller of the task that reads the state the page drew 250 ms earlier): each is drawn mid-segment (the
/// pendulum, the car on its hill, the lander with its engines' throttle), a trigger at rest reads its lower bound
/// before it ever moved (the lander's main engine -1), and the pad's gestures answer the questions, every step a
/// number within the box.
#[test]
fn a_pad_at_each_continuous_task_sees_it_drawn_and_its_trigger_at_rest() {
    let _one_browser = check_prerequisites();
    for (env, kind) in [
        ("LunarLanderContinuous-v3", "LunarLander"),
        ("Pendulum-v1", "Pendulum"),
        ("MountainCarContinuous-v0", "MountainCar"),
    ] {
        let run = tempfile::tempdir().unwrap().keep().join("run");
        let mut args: Vec<std::ffi::OsString> = [
            "train",
            "--env",
            env,
            "--method",
            "adqn",
            "--expert",
            "web",
            "--web-fps",
            "20",
            "--web-segment-s",
            "2",
            "--listen",
            "127.0.0.1:0",
            "--set",
            "train_steps=1500",
            "--set",
            "budget=80",
            "--set",
            "eval_period=1500",
            "-o",
        ]
        .iter()
        .map(Into::into)
        .collect();
        args.push(run.clone().into_os_string());
        let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
        let (mut arld, url) = start_arld(&args, Stdio::inherit());
        let shots = shots_dir(&format!("pad-{env}"));
        let report = run_script("pad_person.mjs", &url, &shots);
        let status = wait(&mut arld, Duration::from_secs(240), "arld");
        assert!(status.success(), "arld failed on {env}: {report}");
        let spec = arld::env::box_spec(env).unwrap();
        // At rest, before anything moved: a dimension on a trigger reads its lower bound, one on a stick the
        // box's centre.
        let rest = &report["rest"];
        for d in 0..spec.action_dim() {
            let on_trigger = rest["map"][d]["source"].as_u64() == Some(5);
            let (lo, hi) = (
                f64::from(spec.action_low[d]),
                f64::from(spec.action_high[d]),
            );
            let value = if on_trigger { lo } else { (lo + hi) / 2.0 };
            // (The value, then the agent's proposal when a question is open.)
            let shown = rest["shown"][d].as_str().unwrap().split(' ').next();
            assert_eq!(
                shown,
                Some(format!("{value:.2}").as_str()),
                "{env}, dimension {d}: {report}"
            );
        }
        if env == "LunarLanderContinuous-v3" {
            assert_eq!(rest["map"][0]["source"], 5, "{report}");
        }
        assert!(shots.join(format!("{env}-mid-segment.png")).is_file());
        let mid = &report["midSegment"];
        assert_eq!(mid["geometry"]["kind"], kind, "{env}: {report}");
        assert!(
            mid["drawing"]["share"].as_f64() > Some(0.005),
            "{env}: {report}"
        );
        if kind == "LunarLander" {
            // The engines' throttles are drawn: the main engine's and the side engines' (signed).
            assert_eq!(
                mid["geometry"]["throttle"].as_array().map(Vec::len),
                Some(2),
                "{report}"
            );
        }
        let lines = answer_lines(&run);
        assert!(!lines.is_empty(), "{env}: no answer: {report}");
        for l in &lines {
            let action = floats(&l["action"]);
            assert_eq!(action.len(), spec.action_dim(), "{l}");
            for (d, a) in action.iter().enumerate() {
                assert!(
                    (f64::from(spec.action_low[d])..=f64::from(spec.action_high[d])).contains(a),
                    "{l}"
                );
            }
        }
    }
}

/// One HTTP GET of `url` (`http://IP:PORT/PATH`) with plain sockets; the status code.
fn http_status(url: &str) -> u16 {
    use std::io::{Read, Write};
    let rest = url.strip_prefix("http://").expect("an http URL");
    let (host, path) = rest.split_at(rest.find('/').unwrap_or(rest.len()));
    let mut stream = std::net::TcpStream::connect(host).expect("connect to the printed address");
    stream
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut response = String::new();
    let _ = stream.read_to_string(&mut response);
    response
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no HTTP status in {response:?}"))
}

/// Listening on every interface, the printed URL names an address other machines can reach (not 127.0.0.1
/// or 0.0.0.0), and the page answers there; the run waits for the page, and a stop before it opens says so.
#[test]
fn listening_everywhere_prints_a_reachable_url_and_waits_for_the_page() {
    let run = tempfile::tempdir().unwrap().keep().join("run");
    let mut args: Vec<&std::ffi::OsStr> = [
        "train",
        "--env",
        "CartPole-v0",
        "--method",
        "adqn",
        "--expert",
        "web",
        "--listen",
        "0.0.0.0:0",
        "-o",
    ]
    .iter()
    .map(std::ffi::OsStr::new)
    .collect();
    args.push(run.as_os_str());
    let mut arld = Command::new(ARLD)
        .args(&args)
        .arg("--quiet")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start arld");
    let mut lines = BufReader::new(arld.stdout.take().unwrap()).lines();
    let url = loop {
        let line = lines.next().expect("arld printed no URL").unwrap();
        if let Some(i) = line.find("http://") {
            break line[i..].trim().to_string();
        }
    };
    let ip: std::net::IpAddr = url["http://".len()..]
        .rsplit_once(':')
        .unwrap()
        .0
        .trim_matches(['[', ']'])
        .parse()
        .unwrap_or_else(|e| panic!("{url}: {e}"));
    let has_outward = std::net::UdpSocket::bind("0.0.0.0:0")
        .and_then(|s| s.connect("192.0.2.1:9").and_then(|()| s.local_addr()))
        .is_ok_and(|a| !a.ip().is_loopback());
    assert!(!ip.is_unspecified(), "the URL names no address: {url}");
    if has_outward {
        assert!(!ip.is_loopback(), "the URL names this machine only: {url}");
    }
    assert_eq!(
        http_status(&url),
        200,
        "the printed URL does not serve the page"
    );
    // The page was fetched, but no tab is open (no WebSocket): the run waits for one.
    std::thread::sleep(Duration::from_millis(500));
    let killed = Command::new("kill")
        .args(["-TERM", &arld.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let status = wait(&mut arld, Duration::from_secs(20), "arld after SIGTERM");
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut arld.stderr.take().unwrap(), &mut stderr).unwrap();
    assert_eq!(status.code(), Some(143), "{stderr}");
    assert!(
        stderr.contains("before the page was opened"),
        "the run did not wait for the page: {stderr}"
    );
    assert!(!run.join("queries.csv").is_file() || queries(&run).is_empty());
}

/// Starts `arld train` of a real-time LunarLanderContinuous-v3 run (ADQN, run seed 0) in a new directory, asked at
/// every step while budget is left (the greedy rule), with segments of `segment_s` seconds at 20 steps a second,
/// a budget of `budget` transitions over `train_steps` steps. Returns the run directory, the process and the URL.
fn start_greedy_lander(segment_s: &str, budget: u64, train_steps: u64) -> (PathBuf, Child, String) {
    let run = tempfile::tempdir().unwrap().keep().join("run");
    let sets = [
        format!("train_steps={train_steps}"),
        format!("budget={budget}"),
        format!("eval_period={train_steps}"),
        "query_rule=greedy".to_string(),
    ];
    let mut args: Vec<std::ffi::OsString> = [
        "train",
        "--env",
        "LunarLanderContinuous-v3",
        "--method",
        "adqn",
        "--seed",
        "0",
        "--expert",
        "web",
        "--web-fps",
        "20",
        "--web-segment-s",
        segment_s,
        "--listen",
        "127.0.0.1:0",
    ]
    .iter()
    .map(Into::into)
    .collect();
    for set in sets {
        args.extend(["--set".into(), set.into()]);
    }
    args.extend(["-o".into(), run.as_os_str().to_owned()]);
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let (arld, url) = start_arld(&args, Stdio::inherit());
    (run, arld, url)
}

/// The answers of each question, in the order asked: the lines of answers.jsonl grouped by `question_step`.
fn answers_by_question(lines: &[serde_json::Value]) -> Vec<Vec<&serde_json::Value>> {
    let mut groups: Vec<Vec<&serde_json::Value>> = Vec::new();
    for l in lines {
        match groups.last_mut() {
            Some(g) if g[0]["question_step"] == l["question_step"] => g.push(l),
            _ => groups.push(vec![l]),
        }
    }
    groups
}

/// How a segment's answers ended, as the page's line must say it for the lander: computed here from the run's own
/// record of the steps (the last step's `terminated` and reward: +100 for coming to rest, -100 for a crash).
fn lander_outcome(steps: &[&serde_json::Value]) -> serde_json::Value {
    let last = steps.last().unwrap();
    match (last["terminated"].as_bool(), last["truncated"].as_bool()) {
        (Some(true), _) if last["reward"].as_f64().unwrap() > 0.0 => "landed".into(),
        (Some(true), _) => "crashed".into(),
        (_, Some(true)) => "time up".into(),
        _ => serde_json::Value::Null,
    }
}

/// The agent's proposal at every step of a segment, the line after each segment and a retry, at the continuous
/// lander (tests/e2e/segments.mjs): every step the person played carried the agent's proposal (its test-time
/// action, which changes with the state), drawn as a ghost on the canvas and on the sliders; each segment's line
/// gives its steps, return and outcome as the run recorded them (answers.jsonl, summed here); the first question
/// was retried and the retry kept: its answers are the retry's (the side engine held, which the first attempt never
/// fired), marked with the dropped attempt's steps, and both attempts are charged to the budget and the person's
/// time; the second question kept its first attempt.
#[test]
fn a_person_sees_the_agents_proposal_every_step_how_each_segment_went_and_may_retry_it() {
    let _one_browser = check_prerequisites();
    let (run, mut arld, url) = start_greedy_lander("10", 1000, 1500);
    let shots = shots_dir("segments");
    let report = run_script("segments.mjs", &url, &shots);
    let status = wait(&mut arld, Duration::from_secs(240), "arld");
    assert!(status.success(), "arld failed: {report}");
    let spec = arld::env::box_spec("LunarLanderContinuous-v3").unwrap();

    // The ghost: every played step carried a proposal in the box, and they changed with the state.
    let plays = report["plays"].as_array().unwrap();
    assert!(plays.len() >= 50, "{report}");
    let proposals: Vec<Vec<f64>> = plays.iter().map(|p| floats(&p["proposal"])).collect();
    for p in &proposals {
        assert_eq!(p.len(), 2, "a step without the agent's proposal: {report}");
        for (d, a) in p.iter().enumerate() {
            assert!((f64::from(spec.action_low[d])..=f64::from(spec.action_high[d])).contains(a));
        }
    }
    assert!(
        proposals.windows(2).any(|w| w[0] != w[1]),
        "the proposal never changed: {report}"
    );
    // Mid-segment the page drew it: the sliders' marks where the proposal puts them, and its outline.
    let mid = &report["mid"];
    let shown = floats(&mid["prompt"]["proposal"]);
    for d in 0..2 {
        let mark = &mid["marks"][d];
        assert_eq!(mark["hidden"], false, "{mid}");
        let left: f64 = mark["left"]
            .as_str()
            .unwrap()
            .trim_end_matches('%')
            .parse()
            .unwrap();
        let (lo, hi) = (
            f64::from(spec.action_low[d]),
            f64::from(spec.action_high[d]),
        );
        let want = 100.0 * (shown[d].clamp(lo, hi) - lo) / (hi - lo);
        // (The browser keeps a style's percentage to 4 decimals.)
        assert!(
            (left - want).abs() < 1e-3,
            "dimension {d}: {left}% for {want}%: {mid}"
        );
        assert!(
            mark["shown"].as_str().unwrap().contains("(agent: "),
            "{mid}"
        );
    }
    assert!(
        mid["ghostPixels"].as_u64() > Some(100),
        "no ghost drawn: {mid}"
    );

    // The lines, and what the run recorded of each question.
    let segments = report["segments"].as_array().unwrap();
    assert!(segments.len() >= 3, "{report}");
    let (first, retried, second) = (&segments[0], &segments[1], &segments[2]);
    assert_eq!(
        (first["attempt"].as_u64(), retried["attempt"].as_u64()),
        (Some(1), Some(2))
    );
    assert_eq!(second["attempt"], 1);
    let lines = answer_lines(&run);
    let questions = answers_by_question(&lines);
    assert!(questions.len() >= 2, "{report}");
    let dropped = first["steps"].as_u64().unwrap();
    for (answers, line, retried_steps) in [
        (&questions[0], retried, Some(dropped)),
        (&questions[1], second, None),
    ] {
        assert_eq!(
            answers.len() as u64,
            line["steps"].as_u64().unwrap(),
            "{line}"
        );
        let sum: f64 = answers.iter().map(|l| l["reward"].as_f64().unwrap()).sum();
        let shown = line["return"].as_f64().unwrap();
        assert!(
            (sum - shown).abs() < 1e-6 * answers.len() as f64 + 1e-9,
            "{sum} vs {line}"
        );
        assert_eq!(line["outcome"], lander_outcome(answers), "{line}");
        for l in answers {
            assert_eq!(l["retried"].as_u64(), retried_steps, "{l}");
        }
    }
    // The kept retry is the one with the side engine held; the first attempt never touched it.
    assert!(
        questions[0].iter().any(|l| floats(&l["action"])[1] > 0.5),
        "the first question's answers are not the retry's: {:?}",
        questions[0]
    );
    assert!(
        questions[1]
            .iter()
            .all(|l| floats(&l["action"]) == [0.0, 0.0])
    );
    // Both attempts charged: the budget spent is the steps stored plus the dropped ones; the run stores only
    // the kept ones.
    let s = summary(&run);
    assert_eq!(s["demos_queried"].as_u64(), Some(lines.len() as u64));
    assert_eq!(
        report["lastStatus"]["budget_used"].as_u64(),
        Some(lines.len() as u64 + dropped),
        "{report}"
    );
    // The person's time holds both attempts' play at 20 steps a second.
    let played = (dropped + questions[0].len() as u64 + questions[1].len() as u64) as f64 / 20.0;
    assert!(s["person_s"].as_f64().unwrap() >= played, "{s}");
}

/// A scripted person lands the continuous lander through the page with a gamepad (tests/e2e/lander_pad.mjs): the
/// pad moved by Gymnasium's heuristic controller (the script's own port of its formula) reading the state the page
/// showed 4 steps earlier (200 ms at 20 steps a second, about 250 ms with the page's own lag: a person's
/// reaction), paced by the run's steps, not by a clock. Asked at every step (the greedy rule) with segments longer
/// than an episode, the person's segments are whole episodes from their first step. Each segment that ended with
/// its episode landed, as the run recorded it (answers.jsonl: the last step terminated with the +100 of coming to
/// rest) and as the page's line said, and scored above 100: the landing's +100 and the shaping of a controlled
/// descent onto the pad less the engines' fuel (the heuristic scores 200-300 on these episodes at such delays).
/// The run's seed is fixed (0): its first episodes land at every delay from 3 to 7 steps, so a loaded machine's
/// lag does not decide the outcome.
#[test]
fn a_scripted_person_with_a_gamepad_lands_the_continuous_lander() {
    let _one_browser = check_prerequisites();
    let (run, mut arld, url) = start_greedy_lander("60", 1500, 1500);
    let shots = shots_dir("lander-pad");
    let report = run_script_with("lander_pad.mjs", &url, &shots, &["--episodes", "2"]);
    let status = wait(&mut arld, Duration::from_secs(300), "arld");
    assert!(status.success(), "arld failed: {report}");
    let ended: Vec<&serde_json::Value> = report["segments"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| !s["outcome"].is_null())
        .collect();
    assert!(ended.len() >= 2, "{report}");
    assert!(ended.iter().all(|s| s["outcome"] == "landed"), "{report}");
    let lines = answer_lines(&run);
    let landed: Vec<_> = answers_by_question(&lines)
        .into_iter()
        .filter(|q| q.last().unwrap()["terminated"] == true)
        .collect();
    assert_eq!(landed.len(), ended.len(), "{report}");
    for q in &landed {
        assert_eq!(lander_outcome(q), "landed");
        let ret: f64 = q.iter().map(|l| l["reward"].as_f64().unwrap()).sum();
        assert!(ret > 100.0, "a return of {ret} over {} steps", q.len());
        assert!(q.iter().all(|l| l["expert"] == "web"));
    }
    assert!(report["steps"].as_u64() > Some(200), "{report}");
}
