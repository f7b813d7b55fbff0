//! A run directory is a vault: real `arld` processes, given hostile or clumsy inputs, write nothing outside the
//! run directory, delete nothing a user put there, never mix two runs, never panic on a value read from a
//! file, and never read an input without bound.
//!
//! Hostile snapshots are made from real ones: the test reads the safetensors file, changes a value or an array,
//! and, when the file carries a checksum (`crc32c` in its metadata), computes it again here from the format's
//! definition (CRC-32C of the arrays' bytes, then of the header with the checksum's digits as `00000000`), so
//! that the change reaches the checks behind the checksum.

#[path = "../fuzz/harness.rs"]
mod harness;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const ARLD: &str = env!("CARGO_BIN_EXE_arld");

/// A short CartPole-v0 run into `dir` with a checkpoint half-way, with `--overwrite` when asked.
fn short_train(dir: &str, overwrite: bool) -> Output {
    let mut a = vec![
        "train",
        "--quiet",
        "--env",
        "CartPole-v0",
        "--set",
        "train_steps=1000",
        "--set",
        "checkpoint_every=500",
        "-o",
        dir,
    ];
    if overwrite {
        a.push("--overwrite");
    }
    arld(&a)
}

fn arld(args: &[&str]) -> Output {
    Command::new(ARLD).args(args).output().expect("run arld")
}

fn spawn(args: &[&str]) -> Child {
    Command::new(ARLD)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start arld")
}

/// Runs `command` in `sh` with at most `limit` of memory and `deadline` of time; `None` if it had to be killed.
fn bounded(command: &str, limit_kib: u64, deadline: Duration) -> Option<Output> {
    bounded_peak(command, limit_kib, deadline).map(|(out, _)| out)
}

/// [`bounded`], with the most memory the command held at once (its peak resident set, KiB).
// The child is reaped by wait4 (which reports its resources), not by `Child::wait`.
#[allow(clippy::zombie_processes)]
fn bounded_peak(command: &str, limit_kib: u64, deadline: Duration) -> Option<(Output, u64)> {
    use std::io::Read;
    // `exec`: the shell becomes the command, whose resources wait4 reports.
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(format!("ulimit -v {limit_kib}; exec {command}"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sh");
    let drain = |mut pipe: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            let _ = pipe.read_to_end(&mut bytes);
            bytes
        })
    };
    let out = drain(Box::new(child.stdout.take().unwrap()));
    let err = drain(Box::new(child.stderr.take().unwrap()));
    let pid = child.id() as i32;
    let started = Instant::now();
    let (mut status, mut usage) = (0, unsafe { std::mem::zeroed::<libc::rusage>() });
    loop {
        // SAFETY: wait4 writes only the status and the usage given.
        let done = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if done == pid {
            break;
        }
        if started.elapsed() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    use std::os::unix::process::ExitStatusExt;
    let output = Output {
        status: std::process::ExitStatus::from_raw(status),
        stdout: out.join().unwrap(),
        stderr: err.join().unwrap(),
    };
    Some((output, usage.ru_maxrss as u64))
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Asserts that `out` is a clean failure: a non-zero exit status (not a signal, not a panic) whose message
/// holds every one of `needles`.
fn assert_refused(out: &Output, needles: &[&str]) {
    let err = stderr(out);
    assert!(
        !out.status.success() && out.status.code().is_some(),
        "expected a clean failure, got {:?}: {err}",
        out.status
    );
    assert!(!err.contains("panicked"), "a panic: {err}");
    for needle in needles {
        assert!(err.contains(needle), "expected {needle:?} in: {err}");
    }
}

/// Removes whatever is at `path` (a file, a link, a folder).
fn clear(path: &Path) {
    match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.is_dir() => std::fs::remove_dir_all(path).unwrap(),
        Ok(_) => std::fs::remove_file(path).unwrap(),
        Err(_) => {}
    }
}

/// The arguments of a CartPole run in `dir` long enough to be caught running, snapshotting often.
fn long_run(dir: &Path) -> Vec<String> {
    [
        "train",
        "--quiet",
        "--env",
        "CartPole-v0",
        "--method",
        "dqn",
        "--set",
        "train_steps=30000",
        "--set",
        "snapshot_every=400",
        "-o",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain([dir.display().to_string()])
    .collect()
}

/// Waits until `path` exists (the child still running), at most a minute.
fn wait_for(path: &Path, child: &mut Child) {
    let started = Instant::now();
    while !path.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("arld ended ({status}) before {} appeared", path.display());
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "{} never appeared",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// A run in `dir` killed (SIGKILL) after its first snapshot: an interrupted run to continue.
fn interrupted_run(dir: &Path) {
    let args = long_run(dir);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut child = spawn(&args);
    wait_for(&dir.join("snapshot.json"), &mut child);
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(dir.join("snapshot.safetensors").is_file());
}

fn resume(dir: &Path, extra: &[&str]) -> Output {
    let d = dir.display().to_string();
    let mut args = vec!["train", "--quiet", "--resume", &d];
    args.extend(extra);
    arld(&args)
}

/// A snapshot file taken apart: its header (JSON) and its arrays' bytes.
struct Snapshot {
    header: serde_json::Map<String, serde_json::Value>,
    data: Vec<u8>,
}

impl Snapshot {
    fn read(path: &Path) -> Self {
        let bytes = std::fs::read(path).unwrap();
        let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
        Snapshot {
            header: serde_json::from_slice(&bytes[8..8 + n]).unwrap(),
            data: bytes[8 + n..].to_vec(),
        }
    }

    fn metadata(&mut self) -> &mut serde_json::Map<String, serde_json::Value> {
        self.header["__metadata__"].as_object_mut().unwrap()
    }

    /// The small values (JSON text in the metadata), changed by `change`.
    fn change_values(&mut self, change: impl FnOnce(&mut serde_json::Value)) {
        let meta = self.metadata();
        let mut values: serde_json::Value =
            serde_json::from_str(meta["values"].as_str().unwrap()).unwrap();
        change(&mut values);
        meta["values"] = values.to_string().into();
    }

    /// The bytes of the array `name`.
    fn array(&mut self, name: &str) -> &mut [u8] {
        let offsets = &self.header[name]["data_offsets"];
        let (start, end) = (
            offsets[0].as_u64().unwrap() as usize,
            offsets[1].as_u64().unwrap() as usize,
        );
        &mut self.data[start..end]
    }

    /// Writes the file, with its checksum computed again when it has one.
    fn write(&mut self, path: &Path) {
        let checksummed = self.metadata().contains_key("crc32c");
        if checksummed {
            self.metadata()["crc32c"] = "00000000".into();
        }
        let mut header = serde_json::to_vec(&self.header).unwrap();
        header.resize(header.len().next_multiple_of(8), b' ');
        if checksummed {
            let crc = crc32c::crc32c_append(crc32c::crc32c(&self.data), &header);
            let text = String::from_utf8(header).unwrap().replacen(
                "\"crc32c\":\"00000000\"",
                &format!("\"crc32c\":\"{crc:08x}\""),
                1,
            );
            header = text.into_bytes();
        }
        let mut bytes = (header.len() as u64).to_le_bytes().to_vec();
        bytes.extend(&header);
        bytes.extend(&self.data);
        std::fs::write(path, bytes).unwrap();
    }
}

/// Every entry below `dir` (but the lock and temporary files a killed process left, and the record of a
/// failure) with its kind, length and CRC-32C (a link: its
/// target), to show that nothing changed.
fn contents(dir: &Path) -> Vec<String> {
    let mut all = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            // A killed writer's temporary file, which the next process tidies away, is no change either.
            let leftover = name.starts_with('.') && name.contains(".tmp");
            if name == ".arld.lock" || name == "failed.json" || leftover {
                continue;
            }
            let meta = std::fs::symlink_metadata(&path).unwrap();
            let shown = path.display();
            if meta.file_type().is_symlink() {
                let target = std::fs::read_link(&path).unwrap();
                all.push(format!("{shown} -> {}", target.display()));
            } else if meta.is_dir() {
                all.push(format!("{shown}/"));
                stack.push(path);
            } else {
                let bytes = std::fs::read(&path).unwrap();
                all.push(format!(
                    "{shown}: {} bytes, crc {:08x}",
                    bytes.len(),
                    crc32c::crc32c(&bytes)
                ));
            }
        }
    }
    all.sort();
    all
}

#[test]
fn a_snapshot_naming_a_file_outside_the_run_is_refused() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    interrupted_run(&dir);
    let victim = work.path().join("victim.txt");
    std::fs::write(
        &victim,
        "a file of the user's, outside the run\n".repeat(100),
    )
    .unwrap();
    let before = std::fs::read(&victim).unwrap();
    let path = dir.join("snapshot.safetensors");
    let mut snapshot = Snapshot::read(&path);
    snapshot.change_values(|v| v["log"]["events_file"] = "../victim.txt".into());
    snapshot.write(&path);
    let out = resume(&dir, &[]);
    assert_refused(&out, &["../victim.txt"]);
    assert_eq!(
        std::fs::read(&victim).unwrap(),
        before,
        "the file outside was changed"
    );
}

#[test]
fn a_log_that_is_a_link_is_refused_and_what_it_names_kept() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    interrupted_run(&dir);
    for name in ["episodes.csv", "queries.csv"] {
        let elsewhere = work.path().join(format!("elsewhere-{name}"));
        std::fs::copy(dir.join(name), &elsewhere).unwrap();
        std::fs::write(dir.join("moved"), std::fs::read(dir.join(name)).unwrap()).unwrap();
        std::fs::remove_file(dir.join(name)).unwrap();
        std::os::unix::fs::symlink(&elsewhere, dir.join(name)).unwrap();
        let before = contents(work.path());
        let out = resume(&dir, &[]);
        assert_refused(&out, &[name, "symbolic link"]);
        assert_eq!(contents(work.path()), before, "{name}: something changed");
        std::fs::remove_file(dir.join(name)).unwrap();
        std::fs::rename(dir.join("moved"), dir.join(name)).unwrap();
    }
    // With the logs back, the run continues and finishes.
    let out = resume(&dir, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.join("summary.json").is_file());
}

#[test]
fn an_unreadable_snapshot_is_kept_and_only_restart_starts_over() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    interrupted_run(&dir);
    let path = dir.join("snapshot.safetensors");
    let real = std::fs::read(&path).unwrap();
    let n = u64::from_le_bytes(real[..8].try_into().unwrap()) as usize;
    // A link to a device, a folder, and the snapshot with one byte of its arrays changed.
    let mut damaged = real.clone();
    damaged[8 + n + (real.len() - 8 - n) / 2] ^= 0x10;
    type Place = fn(&Path, &[u8]);
    let cases: [(&str, Place, &[&str]); 3] = [
        (
            "link",
            |p, _| std::os::unix::fs::symlink("/dev/zero", p).unwrap(),
            &["symbolic link"],
        ),
        (
            "folder",
            |p, _| {
                std::fs::create_dir(p).unwrap();
                std::fs::write(p.join("notes.txt"), "mine").unwrap();
            },
            &["directory"],
        ),
        (
            "damaged",
            |p, bytes| std::fs::write(p, bytes).unwrap(),
            &["damaged"],
        ),
    ];
    for (what, place, needles) in cases {
        clear(&path);
        place(&path, &damaged);
        let before = contents(&dir);
        let out = resume(&dir, &[]);
        assert_refused(&out, needles);
        assert!(
            stderr(&out).contains("snapshot.safetensors"),
            "{what}: {}",
            stderr(&out)
        );
        assert_eq!(contents(&dir), before, "{what}: the run directory changed");
    }
    // The damaged snapshot is still there; --restart starts the run over and finishes it.
    assert_eq!(std::fs::read(&path).unwrap(), damaged);
    let out = resume(&dir, &["--restart"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.join("summary.json").is_file());
    assert!(!path.exists());
}

#[test]
fn overwrite_removes_only_what_a_run_writes() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let d = dir.display().to_string();
    let args = |overwrite: bool| short_train(&d, overwrite);
    let out = args(false);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.join("checkpoints/step_00000500.safetensors").is_file());
    // A file of the user's inside the checkpoints folder, then a folder in the place of a run file.
    let thesis = dir.join("checkpoints/my_thesis.tex");
    std::fs::write(&thesis, "\\section{Results}").unwrap();
    let before = contents(&dir);
    assert_refused(&args(true), &["my_thesis.tex"]);
    assert_eq!(contents(&dir), before, "--overwrite changed the directory");
    std::fs::remove_file(&thesis).unwrap();
    std::fs::remove_file(dir.join("eval.csv")).unwrap();
    std::fs::create_dir(dir.join("eval.csv")).unwrap();
    std::fs::write(dir.join("eval.csv/plot-data.txt"), "mine").unwrap();
    let before = contents(&dir);
    assert_refused(&args(true), &["eval.csv", "directory"]);
    assert_eq!(contents(&dir), before, "--overwrite changed the directory");
    // With only the run's files, --overwrite replaces the run.
    std::fs::remove_dir_all(dir.join("eval.csv")).unwrap();
    let out = args(true);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.join("summary.json").is_file());
}

#[test]
fn a_second_process_in_a_run_directory_is_refused_naming_the_first() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let args = long_run(&dir);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut first = spawn(&args);
    wait_for(&dir.join("snapshot.json"), &mut first);
    let holder = format!("process {}", first.id());
    let d = dir.display().to_string();
    let mut overwrite = args.clone();
    overwrite.push("--overwrite");
    for second in [
        overwrite,
        vec!["train", "--quiet", "--resume", &d],
        vec!["train", "--quiet", "--resume", &d, "--restart"],
    ] {
        let out = arld(&second);
        assert_refused(&out, &[&holder]);
    }
    // The first run was not disturbed: it finishes as a run alone in its directory does.
    let out = first.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let alone = work.path().join("alone");
    let args = long_run(&alone);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    assert!(arld(&args).status.success());
    for name in ["eval.csv", "episodes.csv", "weights.safetensors"] {
        assert_eq!(
            std::fs::read(dir.join(name)).unwrap(),
            std::fs::read(alone.join(name)).unwrap(),
            "{name} differs from a run alone"
        );
    }
}

#[test]
fn values_read_from_a_snapshot_are_checked_into_errors() {
    let work = tempfile::tempdir().unwrap();
    // A bootstrapped run (10 heads) whose snapshot then names head 99, or holds action 7 in its replay memory.
    let dir = work.path().join("run");
    interrupted_run(&dir);
    let path = dir.join("snapshot.safetensors");
    let real = std::fs::read(&path).unwrap();
    let mut snapshot = Snapshot::read(&path);
    snapshot.change_values(|v| v["agent.active_head"] = 99.into());
    snapshot.write(&path);
    assert_refused(&resume(&dir, &[]), &["head 99"]);
    std::fs::write(&path, &real).unwrap();
    let mut snapshot = Snapshot::read(&path);
    snapshot.array("replay.actions")[..8].copy_from_slice(&7u64.to_le_bytes());
    snapshot.write(&path);
    assert_refused(&resume(&dir, &[]), &["action 7"]);
    std::fs::write(&path, &real).unwrap();
    let mut snapshot = Snapshot::read(&path);
    snapshot.change_values(|v| v["loop"]["ep_actions"] = serde_json::json!([0, 1, 5]));
    snapshot.write(&path);
    assert_refused(&resume(&dir, &[]), &["action 5"]);
}

#[test]
fn numbers_too_large_for_a_clock_are_errors_not_panics() {
    let work = tempfile::tempdir().unwrap();
    let out = work.path().join("run").display().to_string();
    let base = [
        "train",
        "--quiet",
        "--env",
        "CartPole-v0",
        "--method",
        "adqn",
        "-o",
        &out,
    ];
    let mut timeout = base.to_vec();
    timeout.extend(["--expert", "cmd:cat", "--set", "expert_timeout=1e300"]);
    assert_refused(&arld(&timeout), &["expert_timeout"]);
    let mut fps = base.to_vec();
    fps.extend([
        "--expert",
        "web",
        "--listen",
        "127.0.0.1:0",
        "--web-fps",
        "1e-300",
        "--web-no-wait",
    ]);
    let command = fps
        .iter()
        .map(|a| format!("'{a}'"))
        .collect::<Vec<_>>()
        .join(" ");
    let run = bounded(
        &format!("'{ARLD}' {command}"),
        4 << 20,
        Duration::from_secs(30),
    )
    .expect("arld --web-fps 1e-300 did not end");
    assert_refused(&run, &["fps"]);
}

#[test]
fn an_endless_input_is_read_with_a_bound() {
    // `env check` on an endless device, and on a file of 64 GiB without line breaks (sparse: no disk used),
    // under a memory cap of 1 GiB: a reader without a bound fails on its allocation (an abort), or is killed at
    // the deadline.
    let dir = tempfile::tempdir().unwrap();
    let long = dir.path().join("no-line-breaks.jsonl");
    std::fs::File::create(&long)
        .unwrap()
        .set_len(64 << 30)
        .unwrap();
    for (input, needles) in [
        ("/dev/zero", ["/dev/zero", "a device"]),
        (
            long.to_str().unwrap(),
            ["no-line-breaks.jsonl", "longer than"],
        ),
    ] {
        let out = bounded(
            &format!("'{ARLD}' env check '{input}'"),
            1 << 20,
            Duration::from_secs(60),
        )
        .unwrap_or_else(|| panic!("arld env check {input} did not end"));
        assert_refused(&out, &needles);
    }
}

#[test]
fn a_named_pipe_given_as_input_is_refused_at_once() {
    // Opening a pipe nobody writes to waits forever; arld refuses it, naming it.
    let dir = tempfile::tempdir().unwrap();
    let pipe = dir.path().join("trace.jsonl");
    let made = Command::new("mkfifo").arg(&pipe).status().expect("mkfifo");
    assert!(made.success());
    let out = bounded(
        &format!("'{ARLD}' env check '{}'", pipe.display()),
        1 << 20,
        Duration::from_secs(30),
    )
    .expect("arld env check on a named pipe did not end");
    assert_refused(&out, &["trace.jsonl", "a named pipe"]);
}

/// A run of ADQN asking the process expert `command` (its first question comes within its first steps).
fn expert_run(dir: &Path, command: &str, timeout_s: &str) -> Vec<String> {
    [
        "train",
        "--quiet",
        "--env",
        "CartPole-v0",
        "--method",
        "adqn",
        "--expert",
        command,
        "--set",
        &format!("expert_timeout={timeout_s}"),
        "--set",
        "train_steps=5000",
        "-o",
        &dir.display().to_string(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

#[test]
fn a_process_experts_children_do_not_outlive_its_timeout() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let pid_file = work.path().join("grandchild.pid");
    // The expert starts a child that keeps its output open and never answers.
    let command = format!(
        "cmd:sh -c 'sleep 1000 & echo $! > {}; read h; read q; wait'",
        pid_file.display()
    );
    let args = expert_run(&dir, &command, "0.5");
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let started = Instant::now();
    let mut child = spawn(&args);
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            panic!("the run did not end after its expert's timeout");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    assert_refused(&out, &["did not answer within 0.5 s"]);
    let pid = std::fs::read_to_string(&pid_file).unwrap();
    let proc = PathBuf::from(format!("/proc/{}", pid.trim()));
    let gone = Instant::now();
    while proc.exists() && gone.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(20));
    }
    // A zombie (reaped by nobody yet) is gone too; anything else is still running.
    let state = std::fs::read_to_string(proc.join("stat")).unwrap_or_default();
    let running = !state.is_empty() && !state.contains(") Z");
    if running {
        let _ = Command::new("kill").args(["-9", pid.trim()]).status();
    }
    assert!(
        !running,
        "the expert's child {} outlived the run",
        pid.trim()
    );
}

#[test]
fn sigterm_ends_the_wait_for_a_process_expert_at_once() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let asked = work.path().join("asked");
    // The expert notes the question, then takes its time (up to its 60 s timeout).
    let command = format!(
        "cmd:sh -c 'read h; read q; touch {}; sleep 100'",
        asked.display()
    );
    let args = expert_run(&dir, &command, "60");
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let mut child = spawn(&args);
    wait_for(&asked, &mut child);
    let signalled = Instant::now();
    Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    while child.try_wait().unwrap().is_none() {
        if signalled.elapsed() > Duration::from_secs(10) {
            let _ = child.kill();
            panic!("SIGTERM did not end the wait for the expert");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let took = signalled.elapsed();
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(143), "{}", stderr(&out));
    assert!(took < Duration::from_secs(5), "the stop took {took:?}");
    assert!(
        dir.join("snapshot.safetensors").is_file(),
        "{}",
        stderr(&out)
    );
    assert!(stderr(&out).contains("--resume"), "{}", stderr(&out));
}

#[test]
fn an_answer_without_line_breaks_is_bounded() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let args = expert_run(
        &dir,
        "cmd:sh -c 'read h; read q; yes | tr -d \"\\n\"'",
        "60",
    );
    let command = args
        .iter()
        .map(|a| format!("'{}'", a.replace('\'', "'\\''")))
        .collect::<Vec<_>>();
    let out = bounded(
        &format!("'{ARLD}' {}", command[..].join(" ")),
        1 << 20,
        Duration::from_secs(60),
    )
    .expect("the run did not end");
    assert_refused(&out, &["longer than 65536 bytes"]);
}

#[test]
fn every_changed_bit_of_a_snapshot_is_refused() {
    // A snapshot of the fuzz target's configuration (what fuzz/run.sh seeds the fuzzer with), read in process.
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let d = dir.display().to_string();
    let mut args = vec![
        "train",
        "--quiet",
        "--env",
        "CartPole-v0",
        "--method",
        "dqn",
        "--net",
        "bootstrap",
        "--seed",
        "0",
    ];
    for assignment in harness::SNAPSHOT_SEED_CONFIG {
        args.extend(["--set", assignment]);
    }
    args.extend(["-o", &d]);
    let mut child = spawn(&args);
    wait_for(&dir.join("snapshot.json"), &mut child);
    child.kill().unwrap();
    child.wait().unwrap();
    let bytes = std::fs::read(dir.join("snapshot.safetensors")).unwrap();
    assert!(harness::snapshot(&bytes), "the snapshot itself is read");
    // One bit of every byte (a different bit from byte to byte), each change on its own.
    let mut changed = bytes.clone();
    let mut accepted = Vec::new();
    for i in 0..bytes.len() {
        let bit = 1u8 << (i % 8);
        changed[i] ^= bit;
        let outcome = std::panic::catch_unwind(|| harness::snapshot(&changed));
        assert!(
            outcome.is_ok(),
            "byte {i}, bit {bit:#04x}: the reader panicked"
        );
        if matches!(outcome, Ok(true)) {
            accepted.push(i);
        }
        changed[i] ^= bit;
    }
    assert!(
        accepted.is_empty(),
        "{} of {} changed bytes were accepted, the first at {:?}",
        accepted.len(),
        bytes.len(),
        &accepted[..accepted.len().min(10)]
    );
}

#[test]
fn idle_connections_to_the_web_page_cannot_use_up_the_runs_files() {
    use std::io::BufRead;
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    // A web run whose questions go back to the agent at once, allowed 160 open files; 200 idle connections.
    let command = format!(
        "ulimit -n 160; exec '{ARLD}' train --quiet --env CartPole-v0 --method adqn --expert web \
         --listen 127.0.0.1:0 --web-no-wait --web-timeout 0.01 --set train_steps=10000 \
         --set snapshot_every=500 -o '{}'",
        dir.display()
    );
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(command)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    let url = lines
        .by_ref()
        .map_while(Result::ok)
        .find_map(|l| l.find("http://").map(|i| l[i..].to_string()))
        .expect("the run printed its URL");
    let authority = url["http://".len()..].split('/').next().unwrap();
    let addr: std::net::SocketAddr = authority.parse().unwrap();
    let held: Vec<std::net::TcpStream> = (0..200)
        .filter_map(|_| {
            std::net::TcpStream::connect_timeout(&addr, Duration::from_millis(100)).ok()
        })
        .collect();
    assert!(held.len() > 32, "only {} connections opened", held.len());
    let started = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            panic!("the run did not end");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    drop(held);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.join("summary.json").is_file());
}

/// The most memory (KiB) a process may hold on an endless or flooding input.
const PEAK_KIB: u64 = 200 << 10;

/// `args` quoted for `sh`.
fn shell(args: &[&str]) -> String {
    let quoted: Vec<String> = args
        .iter()
        .map(|a| format!("'{}'", a.replace('\'', "'\\''")))
        .collect();
    format!("'{ARLD}' {}", quoted.join(" "))
}

/// Runs arld with `args` under a memory cap of 1 GiB and a minute: it must end, and hold less than [`PEAK_KIB`].
fn run_small(args: &[&str]) -> Output {
    let (out, peak) = bounded_peak(&shell(args), 1 << 20, Duration::from_secs(60))
        .unwrap_or_else(|| panic!("arld {args:?} did not end"));
    assert!(
        peak < PEAK_KIB,
        "arld {args:?} held {peak} KiB: {}",
        stderr(&out)
    );
    eprintln!("arld {args:?}: peak {peak} KiB");
    out
}

fn mkfifo(path: &Path) {
    let made = Command::new("mkfifo").arg(path).status().expect("mkfifo");
    assert!(made.success());
}

/// A sparse file of `len` bytes (no disk used).
fn sparse(path: &Path, len: u64) {
    std::fs::File::create(path).unwrap().set_len(len).unwrap();
}

/// A short finished run at `dir`.
fn finished_run(dir: &Path) {
    let d = dir.display().to_string();
    let out = arld(&[
        "train",
        "--quiet",
        "--env",
        "CartPole-v0",
        "--method",
        "dqn",
        "--set",
        "train_steps=600",
        "--set",
        "eval_period=300",
        "-o",
        &d,
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// A packed dataset of two short runs: `ROOT/CartPole-v0/dqn-single/seed{0,1}`, packed into `ROOT/CartPole-v0/`
/// (the run directories removed).
fn packed_dataset(root: &Path) -> PathBuf {
    for seed in 0..2 {
        finished_run(&root.join(format!("CartPole-v0/dqn-single/seed{seed}")));
    }
    let out = arld(&["runs", "pack", root.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    std::fs::remove_dir_all(root.join("CartPole-v0/dqn-single")).unwrap();
    root.join("CartPole-v0")
}

fn gunzip(path: &Path) -> String {
    use std::io::Read;
    let mut text = String::new();
    flate2::read::GzDecoder::new(std::fs::File::open(path).unwrap())
        .read_to_string(&mut text)
        .unwrap();
    text
}

fn gzip_to(path: &Path, text: &str) {
    use std::io::Write;
    let mut out = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    out.write_all(text.as_bytes()).unwrap();
    std::fs::write(path, out.finish().unwrap()).unwrap();
}

/// Every path below `dir` (links not followed), to show that nothing was written there.
fn listing(dir: &Path) -> Vec<PathBuf> {
    let mut all = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if std::fs::symlink_metadata(&path).unwrap().is_dir() {
                stack.push(path.clone());
            }
            all.push(path);
        }
    }
    all.sort();
    all
}

#[test]
fn unpacking_never_writes_through_a_link_planted_in_out() {
    let work = tempfile::tempdir().unwrap();
    let root = work.path().join("data");
    packed_dataset(&root);
    let elsewhere = work.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    let r = root.display().to_string();
    for planted in [
        "CartPole-v0",
        "CartPole-v0/dqn-single",
        "CartPole-v0/dqn-single/seed1",
    ] {
        let out_dir = work.path().join("out");
        clear(&out_dir);
        let link = out_dir.join(planted);
        std::fs::create_dir_all(link.parent().unwrap()).unwrap();
        std::os::unix::fs::symlink(&elsewhere, &link).unwrap();
        let o = out_dir.display().to_string();
        assert_refused(
            &arld(&["runs", "unpack", &r, "-o", &o]),
            &[planted, "symbolic link"],
        );
        assert!(
            listing(&elsewhere).is_empty(),
            "a link at {planted}: unpacking wrote {:?}",
            listing(&elsewhere)
        );
    }
    // Without the link, the runs come back.
    let out_dir = work.path().join("clean");
    let o = out_dir.display().to_string();
    let out = arld(&["runs", "unpack", &r, "-o", &o]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        out_dir
            .join("CartPole-v0/dqn-single/seed1/summary.json")
            .is_file()
    );
}

#[test]
fn a_packed_dataset_with_two_copies_of_a_run_or_a_lying_layout_is_refused() {
    let work = tempfile::tempdir().unwrap();
    let root = work.path().join("data");
    let task = packed_dataset(&root);
    let r = root.display().to_string();
    let out_dir = work.path().join("out");
    let o = out_dir.display().to_string();
    let unpack = || arld(&["runs", "unpack", &r, "-o", &o]);
    // The run listed twice in the index.
    let runs = task.join("runs.csv.gz");
    let index = gunzip(&runs);
    let mut lines: Vec<&str> = index.lines().collect();
    lines.push(lines[1]);
    gzip_to(&runs, &(lines.join("\n") + "\n"));
    assert_refused(&unpack(), &["dqn-single/seed0", "twice"]);
    gzip_to(&runs, &index);
    // The run's configuration twice, the second copy with another seed.
    let configs = task.join("configs.csv.gz");
    let table = gunzip(&configs);
    let row = table.lines().nth(1).unwrap().to_string();
    let header: Vec<&str> = table.lines().next().unwrap().split(',').collect();
    let seed_column = header.iter().position(|c| *c == "seed").unwrap();
    let mut other: Vec<String> = row.split(',').map(str::to_string).collect();
    other[seed_column] = "7".into();
    gzip_to(&configs, &format!("{table}{}\n", other.join(",")));
    assert_refused(&unpack(), &["config.toml", "twice"]);
    gzip_to(&configs, &table);
    // layout.json saying the seed is a string: `seed = "0"` would be written.
    let layout_path = task.join("layout.json");
    let layout_text = std::fs::read_to_string(&layout_path).unwrap();
    let mut layout: serde_json::Value = serde_json::from_str(&layout_text).unwrap();
    layout["config_string_columns"]
        .as_array_mut()
        .unwrap()
        .push("seed".into());
    std::fs::write(&layout_path, layout.to_string()).unwrap();
    assert_refused(&unpack(), &["`seed`", "layout.json"]);
    assert!(
        !out_dir.exists(),
        "a refused unpack wrote {:?}",
        listing(&out_dir)
    );
    // layout.json an endless device, or a named pipe: refused at once, naming it.
    std::fs::remove_file(&layout_path).unwrap();
    std::os::unix::fs::symlink("/dev/zero", &layout_path).unwrap();
    assert_refused(
        &run_small(&["runs", "unpack", &r, "-o", &o]),
        &["layout.json", "a device"],
    );
    std::fs::remove_file(&layout_path).unwrap();
    mkfifo(&layout_path);
    assert_refused(
        &run_small(&["runs", "unpack", &r, "-o", &o]),
        &["layout.json", "a named pipe"],
    );
    std::fs::remove_file(&layout_path).unwrap();
    std::fs::write(&layout_path, &layout_text).unwrap();
    // A table that decompresses to 2 GiB of zeros from 2 MB.
    {
        use std::io::Write;
        let bomb = std::fs::File::create(task.join("eval.csv.gz")).unwrap();
        let mut out = flate2::write::GzEncoder::new(bomb, flate2::Compression::best());
        let zeros = vec![0u8; 1 << 20];
        for _ in 0..2048 {
            out.write_all(&zeros).unwrap();
        }
        out.finish().unwrap();
    }
    assert_refused(
        &run_small(&["runs", "unpack", &r, "-o", &o]),
        &["eval.csv.gz", "decompresses to more than"],
    );
}

#[test]
fn packing_a_huge_file_of_a_run_is_bounded() {
    let work = tempfile::tempdir().unwrap();
    let root = work.path().join("runs");
    let run = root.join("CartPole-v0/dqn-single/seed0");
    finished_run(&run);
    let r = root.display().to_string();
    // A 1.5 GB file of the user's: left out (as binary files are), not read whole.
    let notes = run.join("notes.txt");
    sparse(&notes, 1_500_000_000);
    let out = run_small(&["runs", "pack", &r]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("notes.txt"), "{}", stderr(&out));
    std::fs::remove_file(&notes).unwrap();
    // A run's own log of 1.5 GB: refused, naming it.
    std::fs::remove_dir_all(root.join("CartPole-v0")).unwrap();
    finished_run(&run);
    sparse(&run.join("queries.csv"), 1_500_000_000);
    assert_refused(
        &run_small(&["runs", "pack", &r]),
        &["queries.csv", "longer than"],
    );
}

#[test]
fn endless_evaluations_and_grids_are_refused_within_bounds() {
    let work = tempfile::tempdir().unwrap();
    let o = work.path().join("out").display().to_string();
    assert_refused(
        &run_small(&["report", "--from-evaluations", "/dev/zero", "-o", &o]),
        &["/dev/zero", "a device"],
    );
    assert_refused(
        &run_small(&["sweep", "--grid", "/dev/zero", "-o", &o]),
        &["/dev/zero", "a device"],
    );
    let pipe = work.path().join("grid.toml");
    mkfifo(&pipe);
    let p = pipe.display().to_string();
    assert_refused(
        &run_small(&["sweep", "--grid", &p, "-o", &o]),
        &["grid.toml", "a named pipe"],
    );
}

#[test]
fn a_demonstration_or_dataset_file_that_is_a_pipe_or_huge_is_refused_at_once() {
    let work = tempfile::tempdir().unwrap();
    let pipe = work.path().join("demos.jsonl");
    mkfifo(&pipe);
    let o = work.path().join("run").display().to_string();
    let demo = format!("demo_file={}", pipe.display());
    assert_refused(
        &run_small(&[
            "train",
            "--quiet",
            "--env",
            "CartPole-v0",
            "--method",
            "dqfd",
            "--set",
            &demo,
            "-o",
            &o,
        ]),
        &["demos.jsonl", "a named pipe"],
    );
    // A Minari dataset whose data file is a named pipe, or 3 GB long.
    let dataset = work.path().join("dataset");
    let from =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/minari/arld-test/cartpole-v0");
    let copied = Command::new("cp")
        .arg("-r")
        .arg(&from)
        .arg(&dataset)
        .status()
        .unwrap();
    assert!(copied.success());
    let part = dataset.join("data/1/part-0.arrow");
    let d = dataset.display().to_string();
    let converted = work.path().join("demos-out.jsonl").display().to_string();
    let convert = [
        "demo",
        "convert",
        "--env",
        "CartPole-v1",
        "-o",
        &converted,
        &d,
    ];
    std::fs::remove_file(&part).unwrap();
    mkfifo(&part);
    assert_refused(&run_small(&convert), &["part-0.arrow", "a named pipe"]);
    std::fs::remove_file(&part).unwrap();
    sparse(&part, 3_000_000_000);
    assert_refused(&run_small(&convert), &["part-0.arrow", "longer than"]);
}

#[test]
fn a_process_expert_flooding_answers_ends_the_run_within_bounds() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let mut args = expert_run(&dir, "cmd:yes '{\"action\": 0}'", "60");
    args.extend(["--set".to_string(), "budget=100000".to_string()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    assert_refused(&run_small(&args), &["without being asked"]);
    // An expert that answers each query with two lines: the second is never taken as the next answer.
    let twice = "cmd:sh -c 'read h; while read q; do echo \"{\\\"action\\\": 1}\"; echo \"{\\\"action\\\": 0}\"; done'";
    let dir = work.path().join("twice");
    let args = expert_run(&dir, twice, "60");
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    assert_refused(&run_small(&args), &["without being asked"]);
}

/// An HTTP request to `addr` after `path` (with the run's token), on a new connection: the status line of the
/// answer.
fn http_status(addr: std::net::SocketAddr, request: &str) -> String {
    use std::io::{BufRead, Write};
    let mut stream = std::net::TcpStream::connect_timeout(&addr, Duration::from_secs(5)).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    stream.write_all(request.as_bytes()).unwrap();
    let mut line = String::new();
    let _ = std::io::BufReader::new(stream).read_line(&mut line);
    line
}

#[test]
fn the_person_is_served_past_a_crowd_of_idle_and_slow_connections() {
    use std::io::{BufRead, Write};
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let mut child = Command::new(ARLD)
        .args([
            "train",
            "--quiet",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--expert",
            "web",
            "--listen",
            "127.0.0.1:0",
            "--web-no-wait",
            "--web-timeout",
            "0.01",
            "--set",
            "train_steps=1000000",
            "-o",
        ])
        .arg(&dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    let url = lines
        .by_ref()
        .map_while(Result::ok)
        .find_map(|l| l.find("http://").map(|i| l[i..].trim().to_string()))
        .expect("the run printed its URL");
    let rest = &url["http://".len()..];
    let (authority, path) = rest.split_at(rest.find('/').unwrap());
    let addr: std::net::SocketAddr = authority.parse().unwrap();
    let query = &path[path.find('?').unwrap()..];
    // 48 idle connections, and 8 slow ones that send a request a byte at a time.
    let mut held: Vec<std::net::TcpStream> = (0..48)
        .map(|_| std::net::TcpStream::connect_timeout(&addr, Duration::from_secs(5)).unwrap())
        .collect();
    for _ in 0..8 {
        let mut slow = std::net::TcpStream::connect_timeout(&addr, Duration::from_secs(5)).unwrap();
        slow.write_all(b"GET / HT").unwrap();
        held.push(slow);
    }
    std::thread::sleep(Duration::from_millis(300));
    let started = Instant::now();
    let page = http_status(
        addr,
        &format!("GET /{query} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n\r\n"),
    );
    let socket = http_status(
        addr,
        &format!(
            "GET /ws{query} HTTP/1.1\r\nHost: {authority}\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n\
             Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n"
        ),
    );
    let waited = started.elapsed();
    let _ = child.kill();
    let _ = child.wait();
    drop(held);
    assert!(page.starts_with("HTTP/1.1 200"), "the page: {page:?}");
    assert!(
        socket.starts_with("HTTP/1.1 101"),
        "the WebSocket: {socket:?}"
    );
    assert!(waited < Duration::from_secs(5), "served after {waited:?}");
}

#[test]
fn overwrite_leaves_files_that_only_look_like_a_runs() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    let d = dir.display().to_string();
    let train = |overwrite: bool| short_train(&d, overwrite);
    assert!(train(false).status.success());
    for mine in [
        ".important.tmp.bak",
        "checkpoints/step_5.safetensors",
        ".eval.csv.tmp",
    ] {
        let path = dir.join(mine);
        std::fs::write(&path, "the user's").unwrap();
        let before = contents(&dir);
        assert_refused(&train(true), &[mine.rsplit('/').next().unwrap()]);
        assert_eq!(contents(&dir), before, "--overwrite changed the directory");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "the user's");
        std::fs::remove_file(&path).unwrap();
    }
    // What a killed writer of the run left is the run's: removed with it.
    std::fs::write(dir.join(".eval.csv.tmp4194305-0"), "half").unwrap();
    let out = train(true);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!dir.join(".eval.csv.tmp4194305-0").exists());
}

#[test]
fn a_consistently_forged_snapshot_is_refused() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    interrupted_run(&dir);
    let path = dir.join("snapshot.safetensors");
    let real = std::fs::read(&path).unwrap();
    let mut snapshot = Snapshot::read(&path);
    snapshot.change_values(|v| v["loop"]["step"] = 1_000_000_000_000u64.into());
    snapshot.write(&path);
    assert_refused(&resume(&dir, &[]), &["step 1000000000000", "loop"]);
    std::fs::write(&path, &real).unwrap();
    let mut snapshot = Snapshot::read(&path);
    snapshot.array("replay.terminal")[0] = 7;
    snapshot.write(&path);
    assert_refused(&resume(&dir, &[]), &["replay.terminal", "holds 7"]);
    // The real snapshot still resumes, and the run finishes.
    std::fs::write(&path, &real).unwrap();
    let out = resume(&dir, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn a_killed_writers_temporary_file_is_removed_when_the_run_goes_on() {
    let work = tempfile::tempdir().unwrap();
    let dir = work.path().join("run");
    interrupted_run(&dir);
    // As a writer killed before its rename leaves it (another process's id).
    let leftover = dir.join(".eval.csv.tmp4194305-3");
    std::fs::write(&leftover, "step,mean\n").unwrap();
    let mine = dir.join(".eval.csv.tmp.bak");
    std::fs::write(&mine, "the user's").unwrap();
    let out = resume(&dir, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        !leftover.exists(),
        "the leftover stayed in the finished run"
    );
    assert_eq!(std::fs::read_to_string(&mine).unwrap(), "the user's");
}
