//! A probe of every kind of input a user hands to the binary, done the way a careless or unlucky user would:
//! wrong command-line values, malformed configurations, damaged demonstration files, checkpoints and traces.
//! Each input must end in a clean exit: success when it happens to be valid, otherwise an error message and
//! exit status 1 or 2, never a panic, an abort (a signal), or a hang. The damaged files are made from real
//! ones by cutting them at many points and flipping bytes, so a new parser path is probed without a list of
//! cases to keep up to date. `cargo test --release --test bad_inputs -- --nocapture` prints the table.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::ARLD;

/// How one probe ended.
#[derive(Debug, PartialEq)]
enum Outcome {
    Accepted,
    CleanError,
    Panic(String),
    Abort(String),
    Hang,
}

/// Runs the binary with `args` (within `dir`), at most `limit`, and classifies the exit.
fn probe(dir: &Path, args: &[String], limit: Duration) -> Outcome {
    let mut child = Command::new(ARLD)
        .args(args)
        .current_dir(dir)
        .env("RUST_BACKTRACE", "0")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary starts");
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    });
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(2));
    };
    let text = reader.join().unwrap();
    let Some(status) = status else {
        return Outcome::Hang;
    };
    let shown = format!(
        "{args:?}: {}",
        text.lines().take(3).collect::<Vec<_>>().join(" | ")
    );
    if text.contains("panicked") {
        return Outcome::Panic(shown);
    }
    match status.code() {
        Some(0) => {
            if std::env::var_os("ARLD_PROBE_SHOW_ACCEPTED").is_some() {
                eprintln!("accepted: {args:?}");
            }
            Outcome::Accepted
        }
        Some(1 | 2) if text.contains("error") => Outcome::CleanError,
        _ => Outcome::Abort(format!("{status}: {shown}")),
    }
}

/// The tally of one category.
#[derive(Default)]
struct Tally {
    tried: usize,
    accepted: usize,
    clean: usize,
    failures: Vec<String>,
    panics: usize,
    aborts: usize,
    hangs: usize,
}

impl Tally {
    fn add(&mut self, outcome: Outcome) {
        self.tried += 1;
        match outcome {
            Outcome::Accepted => self.accepted += 1,
            Outcome::CleanError => self.clean += 1,
            Outcome::Panic(what) => {
                self.panics += 1;
                self.failures.push(format!("panic: {what}"));
            }
            Outcome::Abort(what) => {
                self.aborts += 1;
                self.failures.push(format!("abort: {what}"));
            }
            Outcome::Hang => {
                self.hangs += 1;
                self.failures.push("hang".to_string());
            }
        }
    }
}

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|s| s.to_string()).collect()
}

/// The words of a command line, with the word `{}` replaced by `value` (which may be empty or hold spaces).
fn command(line: &str, value: &str) -> Vec<String> {
    line.split(' ')
        .map(|w| if w == "{}" { value } else { w }.to_string())
        .collect()
}

/// Damaged copies of `bytes`: cut at `cuts` points spread over the file, and `flips` single bytes replaced
/// by characters that break numbers, strings and structure, at positions spread over the first `region` bytes
/// (the whole file, or the part that is not raw numbers).
fn damaged(bytes: &[u8], cuts: usize, flips: usize, region: usize) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    for k in 0..cuts {
        out.push(bytes[..bytes.len() * k / cuts].to_vec());
    }
    let replacements = b"\x00\xff9-e\"{]:,n";
    for k in 0..flips {
        let mut copy = bytes.to_vec();
        let at = (region * (2 * k + 1) / (2 * flips)).min(bytes.len() - 1);
        copy[at] = replacements[k % replacements.len()];
        out.push(copy);
    }
    out
}

/// Writes each of `files` into `dir` and probes the command `line` with `{}` replaced by the file's path.
fn probe_files(dir: &Path, tally: &mut Tally, files: Vec<Vec<u8>>, ext: &str, line: &str) {
    for (i, bytes) in files.into_iter().enumerate() {
        let path: PathBuf = dir.join(format!("input{i}.{ext}"));
        std::fs::write(&path, bytes).unwrap();
        let args: Vec<String> = line
            .split(' ')
            .map(|a| a.replace("{}", path.to_str().unwrap()))
            .collect();
        tally.add(probe(dir, &args, Duration::from_secs(120)));
        let _ = std::fs::remove_dir_all(dir.join("run"));
    }
}

#[test]
fn every_bad_input_is_a_clean_error() {
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let quick = Duration::from_secs(60);
    let mut table: Vec<(&str, Tally)> = Vec::new();

    // Command-line values: each flag with values of the wrong type, sign, size or form.
    let mut cli = Tally::default();
    let numbers = [
        "-1",
        "abc",
        "",
        "1.5",
        "1e3",
        "18446744073709551616",
        "9223372036854775808",
    ];
    for flag in ["--seed", "--episodes"] {
        for v in numbers {
            let line = format!("expert eval --env CartPole-v0 {flag} {{}}");
            cli.add(probe(work, &command(&line, v), quick));
        }
    }
    for v in numbers.iter().chain(&["0"]) {
        for line in [
            "demo collect --env CartPole-v0 --expert scripted --transitions {} -o d.jsonl",
            "reproduce --seeds {} -o s",
        ] {
            cli.add(probe(work, &command(line, v), quick));
        }
    }
    let seed_lists = ["5..3", "a..b", "1,,2", "0..100000000000", "1,1"];
    for seeds in numbers.iter().chain(&["0"]).chain(&seed_lists) {
        let line = "sweep --env CartPole-v0 --method dqn --seeds {} -o s";
        cli.add(probe(work, &command(line, seeds), quick));
    }
    let train = |extra: &[&str]| {
        let mut args = strings(&[
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "-o",
            "run",
        ]);
        args.extend(strings(extra));
        args.push("--print-config".to_string());
        args
    };
    for extra in [
        &["--env", "Pong-v5"][..],
        &["--env", "../../etc"],
        &["--env", ""],
        &["--method", "ppo"],
        &["--net", "transformer"],
        &["--set", "lr"],
        &["--set", "=3"],
        &["--set", "learning_rate=3"],
        &["--set", "lr=fast"],
        &["--set", "t_query=2"],
        &["--set", "budget=-5"],
        &["--expert", "bogus:spec"],
        &["--expert", "noisy:2:shipped:weak"],
        &["--expert", "checkpoint:/nonexistent.safetensors"],
        &["--expert", "web", "--listen", "999.1.1.1:80"],
        &["--expert", "web", "--web-fps", "-1"],
        &["--expert", "web", "--web-timeout", "abc"],
        &["--listen", "127.0.0.1:0"],
        &["--config", "/nonexistent.toml"],
        &["--config", "/dev/zero"],
        &["--config", "/"],
        &["--demos", "/nonexistent.jsonl", "--method", "dqfd"],
    ] {
        cli.add(probe(work, &train(extra), quick));
    }
    for args in [
        &["train", "--resume", "/nonexistent"][..],
        &["train", "--env", "CartPole-v0", "-o", "/dev/null"],
        &["report", "/nonexistent"],
        &["sweep", "--status", "/nonexistent"],
        &["sweep", "--grid", "/nonexistent.toml", "-o", "s"],
        &["env", "check", "/nonexistent.jsonl"],
        &["env", "rollout", "--env", "Nope-v0"],
        &[
            "expert",
            "eval",
            "--env",
            "CartPole-v0",
            "--expert",
            "shipped:superb",
        ],
        &["no-such-command"],
        &["train", "--no-such-flag"],
    ] {
        cli.add(probe(work, &strings(args), quick));
    }
    table.push(("command-line values", cli));

    // Configurations: every key with every wrong value, and malformed documents.
    let mut configs = Tally::default();
    let keys: Vec<String> = String::from_utf8(
        Command::new(ARLD)
            .args("train --env CartPole-v0 --method adqn --print-config".split(' '))
            .output()
            .unwrap()
            .stdout,
    )
    .unwrap()
    .lines()
    .filter_map(|l| l.split_once(" = ").map(|(k, _)| k.to_string()))
    .collect();
    assert!(keys.len() > 40, "{keys:?}");
    let values = [
        "-1",
        "0",
        "nan",
        "inf",
        "-inf",
        "1e300",
        "\"text\"",
        "true",
        "[1]",
        "{ a = 1 }",
        "9223372036854775807",
        "-9223372036854775808",
        "1.5",
        "\"\"",
    ];
    let mut documents: Vec<Vec<u8>> = Vec::new();
    for key in &keys {
        for value in values {
            documents.push(format!("{key} = {value}\n").into_bytes());
        }
    }
    for text in [
        "lr = ",
        "[section]\nlr = 1",
        "lr = 1\nlr = 2",
        "unknown_key = 1",
        "\u{feff}lr = 1",
        "lr = 1 # ok\n\x00",
        "env = \"CartPole-v0\"\nmethod = \"dqn\"\nbudget = 100",
        "method = \"adqn\"\nn_r = 0",
    ] {
        documents.push(text.as_bytes().to_vec());
    }
    documents.push(vec![b'#'; 5 << 20]);
    probe_files(
        work,
        &mut configs,
        documents,
        "toml",
        "train --env CartPole-v0 --method adqn --config {} --print-config",
    );
    table.push(("configurations", configs));

    // Demonstration files: a real one, damaged. A damaged copy that is still valid trains for a few steps.
    let mut demos = Tally::default();
    let demo_file = work.join("real.jsonl");
    assert!(
        Command::new(ARLD)
            .args([
                "demo",
                "collect",
                "--env",
                "CartPole-v0",
                "--expert",
                "scripted"
            ])
            .args(["--transitions", "30", "-o", demo_file.to_str().unwrap()])
            .status()
            .unwrap()
            .success()
    );
    probe_files(
        work,
        &mut demos,
        {
            let bytes = std::fs::read(&demo_file).unwrap();
            damaged(&bytes, 40, 60, bytes.len())
        },
        "jsonl",
        concat!(
            "train --env CartPole-v0 --method dqfd --net plain --demos {} --set pretrain_steps=2 ",
            "--set train_steps=600 --set eval_episodes=1 --quiet -o run"
        ),
    );
    table.push(("demonstration files", demos));

    // Checkpoints: a shipped expert's weights, damaged.
    let mut checkpoints = Tally::default();
    let weights = std::fs::read(root.join("experts/CartPole-v0/weak.safetensors")).unwrap();
    // The header (8 bytes of length, then JSON): a flipped byte in the tensors' data is just another weight.
    let header = 8 + u64::from_le_bytes(weights[..8].try_into().unwrap()) as usize;
    probe_files(
        work,
        &mut checkpoints,
        damaged(&weights, 60, 80, header),
        "safetensors",
        "expert eval --env CartPole-v0 --expert checkpoint:{} --episodes 1",
    );
    table.push(("checkpoints", checkpoints));

    // Conformance traces: the first episodes of the committed trace, damaged.
    let mut traces = Tally::default();
    let trace =
        std::fs::read_to_string(root.join("tests/data/conformance/classic_control.jsonl")).unwrap();
    let head: String = trace.lines().take(60).flat_map(|l| [l, "\n"]).collect();
    probe_files(
        work,
        &mut traces,
        damaged(head.as_bytes(), 40, 60, head.len()),
        "jsonl",
        "env check {}",
    );
    table.push(("traces", traces));

    println!(
        "| category | inputs tried | clean errors | accepted as valid | panics | aborts | hangs |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (name, t) in &table {
        println!(
            "| {name} | {} | {} | {} | {} | {} | {} |",
            t.tried, t.clean, t.accepted, t.panics, t.aborts, t.hangs
        );
    }
    let failures: Vec<&String> = table.iter().flat_map(|(_, t)| &t.failures).collect();
    assert!(
        failures.is_empty(),
        "{} unclean exits:\n{failures:#?}",
        failures.len()
    );
    for (name, t) in &table {
        assert!(
            t.clean > t.tried / 2,
            "{name}: most probes should be errors ({} of {})",
            t.clean,
            t.tried
        );
    }
}
