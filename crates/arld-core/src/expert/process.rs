//! An expert in another process, in any language: [`ProcessExpert`] starts a command and speaks JSON lines with
//! it over its standard input and output (`--expert cmd:"python my_expert.py"`).
//!
//! The protocol (version 1), one JSON object per line, UTF-8:
//! - arld -> expert, once at start: `{"type": "hello", "protocol": 1, "env": "CartPole-v0",
//!   "observation_space": {"type": "box", "shape": [4]}, "action_space": {"type": "discrete", "n": 2}}`.
//!   No answer is expected.
//! - arld -> expert, per query: `{"type": "query", "obs": [0.01, -0.02, 0.03, 0.04]}`.
//! - expert -> arld, per query: `{"action": 1}` (an integer in `0..n`).
//!
//! In a task whose actions are in a box (Pendulum-v1, ...), the hello's action space is
//! `{"type": "box", "shape": [1], "low": [-2.0], "high": [2.0]}` and an answer is `{"action": [0.5]}`: one finite
//! number per dimension, within the bounds ([`WireAction`] is how each kind of action travels).
//!
//! The expert speaks only when asked: arld reads its output only while a query waits for its answer, and an
//! expert that wrote anything else (a line before the first query, a second line to one query, a flood of
//! answers) has broken the protocol: the next query finds it, and the run ends with an error naming the expert
//! and what it wrote. No answer nobody asked for is ever taken as the answer to a later query, and what arld holds
//! of the expert's output is bounded (the pipe, and one line of at most [`MAX_ANSWER_BYTES`]).
//!
//! At the end arld closes the expert's standard input (end of file); an expert should then exit. Anything the
//! expert writes to standard error is kept (the last lines) and shown if it fails. A crash, an answer slower than
//! the timeout, a line that is not such an object (or longer than [`MAX_ANSWER_BYTES`]), or an action the task
//! does not accept (out of range, of the wrong length, not finite) is an error naming the expert: the run stops there and, lacking its summary, stays incomplete.
//! `examples/expert.py` is a complete expert.
//!
//! The expert runs in a process group of its own, and is stopped as a group (on a timeout, and at the end): a
//! child it started that keeps its output open cannot hold the run past the timeout. A stop request (Ctrl-C,
//! SIGTERM) ends the wait for an answer at once with [`crate::interrupt::Interrupted`], so that the run
//! snapshots with the question open.

use super::Expert;
use crate::env::{BoxSpec, EnvSpec};
use crate::task::{Action, TaskSpec};
use anyhow::{Context, Result, anyhow, bail};
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read, Write};
use std::os::fd::AsRawFd;
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long an expert process may take to answer one query unless configured otherwise.
pub const DEFAULT_TIMEOUT_S: f64 = 30.0;

/// The longest timeout an expert may be given: a year (longer ones are no timeout, and overflow a clock).
pub const MAX_TIMEOUT_S: f64 = 365.0 * 86_400.0;

/// Lines of the expert's standard error kept for error messages.
const STDERR_LINES: usize = 20;

/// The longest answer line read from an expert (an answer is a few bytes; a stream without line breaks must not
/// grow the memory without end).
pub const MAX_ANSWER_BYTES: usize = 64 * 1024;

/// The longest line of the expert's standard error kept (a longer one is kept cut at this length).
const MAX_STDERR_LINE_BYTES: usize = 4096;

/// How often a wait for an answer looks whether a stop was requested.
const STOP_POLL: Duration = Duration::from_millis(20);

/// How actions of one kind travel in the protocol: the hello's `action_space` and an answer's `action`.
pub trait WireAction: Action {
    /// The task's action space as the hello describes it.
    fn action_space(spec: &Self::Spec) -> serde_json::Value;
    /// The `action` of an answer as an action of this kind (whether the task accepts it is checked after), or
    /// `None` when it has another shape.
    fn from_wire(value: &serde_json::Value) -> Option<Self>;
    /// An answer of the right shape, for error messages.
    const EXAMPLE: &'static str;
    /// Whether the task accepts `action` as an expert's answer; the error says why not.
    fn check_answer(action: Self::Ref<'_>, spec: &Self::Spec) -> Result<(), String> {
        Self::check(action, spec)
    }
}

impl WireAction for usize {
    fn action_space(spec: &EnvSpec) -> serde_json::Value {
        serde_json::json!({"type": "discrete", "n": spec.n_actions})
    }

    fn from_wire(value: &serde_json::Value) -> Option<usize> {
        value.as_u64().and_then(|a| usize::try_from(a).ok())
    }

    const EXAMPLE: &'static str =
        "{\"action\": 1} (a JSON object with a non-negative integer action)";
}

impl WireAction for Vec<f32> {
    fn action_space(spec: &BoxSpec) -> serde_json::Value {
        serde_json::json!({
            "type": "box",
            "shape": [spec.action_dim()],
            "low": spec.action_low,
            "high": spec.action_high,
        })
    }

    fn from_wire(value: &serde_json::Value) -> Option<Vec<f32>> {
        value
            .as_array()?
            .iter()
            .map(|v| v.as_f64().map(|x| x as f32))
            .collect()
    }

    const EXAMPLE: &'static str =
        "{\"action\": [0.5]} (a JSON object with a list of numbers, one per action dimension)";

    /// An expert's answer must lie in the box (Gymnasium clips an agent's action into it, but an expert outside
    /// it is asked something it does not know).
    fn check_answer(action: &[f32], spec: &BoxSpec) -> Result<(), String> {
        Self::check(action, spec)?;
        let bounds = spec.action_low.iter().zip(spec.action_high);
        match action
            .iter()
            .zip(bounds)
            .position(|(a, (lo, hi))| !(lo..=hi).contains(&a))
        {
            Some(d) => Err(format!(
                "dimension {d} of {}'s actions lies in [{}, {}]",
                spec.id, spec.action_low[d], spec.action_high[d]
            )),
            None => Ok(()),
        }
    }
}

/// An external expert process speaking the JSON-lines protocol of this module, answering actions of kind `A`.
pub struct ProcessExpert<A: WireAction = usize> {
    command: String,
    child: Child,
    stdin: Option<ChildStdin>,
    replies: Replies,
    stderr: Arc<Mutex<VecDeque<String>>>,
    stderr_thread: Option<JoinHandle<()>>,
    timeout: Duration,
    spec: &'static A::Spec,
}

impl<A: WireAction> ProcessExpert<A> {
    /// Starts `command` (run by `sh -c`, so quoting works as in a shell) and sends it the hello for the task
    /// `spec`. `timeout_s` bounds the wait for each answer.
    pub fn spawn(command: &str, spec: &'static A::Spec, timeout_s: f64) -> Result<Self> {
        if !(timeout_s.is_finite() && timeout_s > 0.0) {
            bail!("the expert timeout must be a positive number of seconds, got {timeout_s}");
        }
        if command.trim().is_empty() {
            bail!("expert spec `cmd:` needs a command, e.g. cmd:\"python my_expert.py\"");
        }
        if timeout_s > MAX_TIMEOUT_S {
            bail!(
                "the expert timeout must be at most {MAX_TIMEOUT_S} seconds (a year), got {timeout_s}"
            );
        }
        use std::os::unix::process::CommandExt;
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(format!("exec {command}"))
            // Its own process group, so that it can be stopped with every process it started.
            .process_group(0)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("cannot start expert process `{command}`"))?;
        let replies = Replies {
            stdout: child.stdout.take().expect("stdout is piped"),
            pending: Vec::new(),
            closed: false,
        };
        let stderr_pipe = child.stderr.take().expect("stderr is piped");
        // A reader thread for stderr: a chatty stderr never blocks the expert.
        let stderr = Arc::new(Mutex::new(VecDeque::new()));
        let kept = Arc::clone(&stderr);
        let stderr_thread = std::thread::spawn(move || {
            use std::io::Read;
            let mut reader = BufReader::new(stderr_pipe);
            let mut bytes = Vec::new();
            loop {
                // A line longer than the bound is kept cut, the rest of it read as the next lines.
                bytes.clear();
                let take = MAX_STDERR_LINE_BYTES as u64;
                match reader.by_ref().take(take).read_until(b'\n', &mut bytes) {
                    Ok(0) | Err(_) => break,
                    Ok(_) => {}
                }
                let line = String::from_utf8_lossy(&bytes).trim_end().to_string();
                let mut kept = kept.lock().unwrap_or_else(|e| e.into_inner());
                if kept.len() == STDERR_LINES {
                    kept.pop_front();
                }
                kept.push_back(line);
            }
        });
        let mut expert = Self {
            command: command.to_string(),
            stdin: child.stdin.take(),
            child,
            replies,
            stderr,
            stderr_thread: Some(stderr_thread),
            timeout: Duration::from_secs_f64(timeout_s),
            spec,
        };
        let hello = serde_json::json!({
            "type": "hello",
            "protocol": 1,
            "env": spec.id(),
            "observation_space": {"type": "box", "shape": [spec.obs_dim()]},
            "action_space": A::action_space(spec),
        });
        expert.send(&hello)?;
        Ok(expert)
    }

    fn send(&mut self, message: &serde_json::Value) -> Result<()> {
        let stdin = self.stdin.as_mut().context("stdin closed")?;
        let written = writeln!(stdin, "{message}").and_then(|()| stdin.flush());
        if let Err(e) = written {
            return Err(self.failure(&format!("could not be written to ({e})")));
        }
        Ok(())
    }

    /// An error naming the expert, with its exit status (if it ended) and the last lines of its stderr.
    fn failure(&mut self, what: &str) -> anyhow::Error {
        let status = match self.child.try_wait() {
            Ok(Some(status)) => format!("; it exited with {status}"),
            _ => String::new(),
        };
        // A process that ended has closed its stderr: wait for the reader so the last lines are all there (for
        // a moment only: a child of the expert may still hold the pipe).
        if !status.is_empty()
            && let Some(t) = self.stderr_thread.take()
        {
            for _ in 0..25 {
                if t.is_finished() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            if t.is_finished() {
                let _ = t.join();
            }
        }
        let kept = self.stderr.lock().unwrap_or_else(|e| e.into_inner());
        let tail = if kept.is_empty() {
            String::new()
        } else {
            let lines: Vec<&str> = kept.iter().map(String::as_str).collect();
            format!("\nits last lines on stderr:\n  {}", lines.join("\n  "))
        };
        anyhow!("expert process `{}` {what}{status}{tail}", self.command)
    }

    /// Stops the expert and every process it started (its process group).
    fn kill_group(&mut self) {
        if let Ok(pid) = i32::try_from(self.child.id()) {
            // SAFETY: kill(2) has no memory effects; a negative pid names the expert's process group.
            unsafe {
                libc::kill(-pid, libc::SIGKILL);
            }
        }
        let _ = self.child.kill();
    }

    /// Refuses to ask an expert that has written something nobody asked for (see the module's documentation).
    fn check_unsolicited(&mut self) -> Result<()> {
        match self.replies.unsolicited() {
            Ok(None) => Ok(()),
            Ok(Some(shown)) => Err(self.failure(&format!(
                "wrote {shown:?} without being asked: an expert writes one line to each query, after it (a \
                 flood of answers, or a second line to one query, breaks the protocol)"
            ))),
            Err(e) => Err(self.failure(&format!("could not be read from ({e})"))),
        }
    }

    fn read_answer(&mut self) -> Result<A> {
        let line = match self.replies.answer(Instant::now() + self.timeout) {
            Reply::Stopped => {
                return Err(crate::interrupt::Interrupted(format!(
                    "stopped while expert process `{}` was asked",
                    self.command
                ))
                .into());
            }
            Reply::Line(line) => line,
            Reply::Failed(e) => {
                return Err(self.failure(&format!("could not be read from ({e})")));
            }
            Reply::Closed => {
                // Give a crashing process a moment to be reaped so its exit status can be shown.
                let _ = self.child.wait_timeout_ms(500);
                return Err(self.failure("closed its output without answering the query"));
            }
            Reply::Timeout => {
                self.kill_group();
                return Err(self.failure(&format!(
                    "did not answer within {} s (the expert timeout); it was stopped",
                    self.timeout.as_secs_f64()
                )));
            }
        };
        let action = serde_json::from_str::<serde_json::Value>(&line)
            .ok()
            .and_then(|v| v.get("action").and_then(A::from_wire));
        let Some(action) = action else {
            let shown: String = line.chars().take(200).collect();
            return Err(self.failure(&format!(
                "answered {shown:?}, which is not a line like {}",
                A::EXAMPLE
            )));
        };
        if let Err(why) = A::check_answer(action.borrow(), self.spec) {
            let shown: String = A::to_field(action.borrow()).chars().take(200).collect();
            return Err(self.failure(&format!("answered action {shown}, but {why}")));
        }
        Ok(action)
    }
}

/// The expert's standard output, read only while a query waits for its answer ([`Replies::answer`]).
struct Replies {
    stdout: ChildStdout,
    /// Bytes read and not yet taken as an answer: a line in pieces, or what the expert wrote beyond its answer.
    pending: Vec<u8>,
    /// Whether the expert closed its output.
    closed: bool,
}

/// What waiting for an answer gave.
enum Reply {
    Line(String),
    Closed,
    Timeout,
    /// A stop was requested while waiting.
    Stopped,
    Failed(std::io::Error),
}

impl Replies {
    /// Whether the output has something to read (bytes, or its end) within `ms` milliseconds (`false` also when
    /// a signal ended the wait early: the caller looks at the stop request, then waits again).
    fn ready(&self, ms: i32) -> std::io::Result<bool> {
        let mut fd = libc::pollfd {
            fd: self.stdout.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: `fd` is one valid pollfd that outlives the call.
        let n = unsafe { libc::poll(&mut fd, 1, ms) };
        if n < 0 {
            let e = std::io::Error::last_os_error();
            return if e.kind() == std::io::ErrorKind::Interrupted {
                Ok(false)
            } else {
                Err(e)
            };
        }
        Ok(n > 0)
    }

    /// Reads what the output holds now (one read, which does not wait: [`Replies::ready`] said it would not).
    fn fill(&mut self) -> std::io::Result<()> {
        let mut chunk = [0u8; 4096];
        let n = self.stdout.read(&mut chunk)?;
        self.closed |= n == 0;
        self.pending.extend_from_slice(&chunk[..n]);
        Ok(())
    }

    /// The beginning of what the expert wrote without being asked (before a query is sent), if it wrote anything.
    fn unsolicited(&mut self) -> std::io::Result<Option<String>> {
        if self.pending.is_empty() && !self.closed && self.ready(0)? {
            self.fill()?;
        }
        if self.pending.is_empty() {
            return Ok(None);
        }
        let first = self
            .pending
            .split(|&b| b == b'\n')
            .next()
            .unwrap_or_default();
        Ok(Some(
            String::from_utf8_lossy(first).chars().take(200).collect(),
        ))
    }

    /// The answer line (without its line break), waiting at most until `deadline` and ending the wait at once
    /// when a stop is requested. A line longer than [`MAX_ANSWER_BYTES`] is an error, so that an output without
    /// line breaks cannot grow the memory.
    fn answer(&mut self, deadline: Instant) -> Reply {
        loop {
            if let Some(end) = self.pending.iter().position(|&b| b == b'\n') {
                let mut line: Vec<u8> = self.pending.drain(..=end).collect();
                line.pop();
                if line.last() == Some(&b'\r') {
                    line.pop();
                }
                if line.len() <= MAX_ANSWER_BYTES {
                    return Reply::Line(String::from_utf8_lossy(&line).into_owned());
                }
                return Reply::Failed(too_long());
            }
            if self.pending.len() > MAX_ANSWER_BYTES {
                return Reply::Failed(too_long());
            }
            if self.closed {
                // A last line without its line break is still an answer.
                return match std::mem::take(&mut self.pending) {
                    line if line.is_empty() => Reply::Closed,
                    line => Reply::Line(String::from_utf8_lossy(&line).into_owned()),
                };
            }
            if crate::interrupt::requested() {
                // Whatever arrives later belongs to the question a resumed run asks again.
                return Reply::Stopped;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Reply::Timeout;
            }
            let wait = left.min(STOP_POLL).as_millis().max(1) as i32;
            match self.ready(wait) {
                Ok(true) => {
                    if let Err(e) = self.fill() {
                        return Reply::Failed(e);
                    }
                }
                Ok(false) => {}
                Err(e) => return Reply::Failed(e),
            }
        }
    }
}

fn too_long() -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::InvalidData,
        format!("a line is longer than {MAX_ANSWER_BYTES} bytes"),
    )
}

/// Waiting for a child with a bound (std has no timed wait).
trait WaitTimeout {
    fn wait_timeout_ms(&mut self, ms: u64) -> std::io::Result<()>;
}

impl WaitTimeout for Child {
    fn wait_timeout_ms(&mut self, ms: u64) -> std::io::Result<()> {
        for _ in 0..ms / 10 {
            if self.try_wait()?.is_some() {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        Ok(())
    }
}

impl<A: WireAction> Expert<A> for ProcessExpert<A> {
    fn act(&mut self, obs: &[f32]) -> Result<A> {
        self.check_unsolicited()?;
        self.send(&serde_json::json!({"type": "query", "obs": obs}))?;
        self.read_answer()
    }
    fn describe(&self) -> String {
        format!("cmd:{}", self.command)
    }
}

impl<A: WireAction> Drop for ProcessExpert<A> {
    /// Closes the expert's input (its signal to exit), gives it a moment, then stops it.
    fn drop(&mut self) {
        drop(self.stdin.take());
        let _ = self.child.wait_timeout_ms(1000);
        // What it started and left running goes with it.
        self.kill_group();
        let _ = self.child.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> &'static EnvSpec {
        crate::env::spec("CartPole-v0").unwrap()
    }

    fn expert(script: &str, timeout: f64) -> Result<ProcessExpert> {
        ProcessExpert::spawn(script, spec(), timeout)
    }

    #[test]
    fn answers_are_read_and_hello_is_sent() {
        // A shell expert: checks the hello, then answers 1 when the first observation value is positive.
        let script = r#"sh -c 'read hello; case "$hello" in *'"'"'"env":"CartPole-v0"'"'"'*) ;; *) exit 3;; esac;
            while read q; do case "$q" in *'"'"'"obs":[-'"'"'*) echo "{\"action\": 0}";; *) echo "{\"action\": 1}";; esac; done'"#;
        let mut e = expert(script, 10.0).unwrap();
        assert_eq!(e.act(&[0.5, 0.0, 0.0, 0.0]).unwrap(), 1);
        assert_eq!(e.act(&[-0.5, 0.0, 0.0, 0.0]).unwrap(), 0);
        assert!(e.describe().starts_with("cmd:"));
    }

    #[test]
    fn crash_is_an_error_with_status_and_stderr() {
        let mut e = expert("sh -c 'read h; read q; echo boom >&2; exit 4'", 10.0).unwrap();
        let msg = format!("{:#}", e.act(&[0.0; 4]).unwrap_err());
        assert!(msg.contains("closed its output"), "{msg}");
        assert!(msg.contains("boom"), "{msg}");
        assert!(msg.contains("exit status: 4"), "{msg}");
    }

    #[test]
    fn hang_times_out() {
        let mut e = expert("sleep 30", 0.3).unwrap();
        let msg = format!("{:#}", e.act(&[0.0; 4]).unwrap_err());
        assert!(msg.contains("did not answer within 0.3 s"), "{msg}");
    }

    #[test]
    fn garbage_and_out_of_range_are_errors() {
        let mut e = expert("sh -c 'while read l; do echo not json; done'", 10.0).unwrap();
        let msg = format!("{:#}", e.act(&[0.0; 4]).unwrap_err());
        assert!(msg.contains("\"not json\""), "{msg}");
        let mut e = expert(
            "sh -c 'read h; while read l; do echo \"{\\\"action\\\": 7}\"; done'",
            10.0,
        )
        .unwrap();
        let msg = format!("{:#}", e.act(&[0.0; 4]).unwrap_err());
        assert!(msg.contains("answered action 7"), "{msg}");
        assert!(msg.contains("2 actions"), "{msg}");
    }

    /// A box task's hello names its bounds; answers are lists of numbers, and one of the wrong length, outside
    /// the box, too large for an f32 or not a list is an error naming the expert and the task.
    #[test]
    fn box_actions_are_lists_of_numbers_within_the_box() {
        let pendulum = crate::env::box_spec("Pendulum-v1").unwrap();
        let boxed =
            |script: &str| ProcessExpert::<Vec<f32>>::spawn(script, pendulum, 10.0).unwrap();
        // Checks the hello, then answers the torque 0.5 to a positive first observation value, -1.5 otherwise.
        let script = r#"sh -c 'read hello; case "$hello" in *'"'"'"action_space":{"high":[2.0],"low":[-2.0],"shape":[1],"type":"box"}'"'"'*) ;; *) echo "$hello" >&2; exit 3;; esac;
            while read q; do case "$q" in *'"'"'"obs":[-'"'"'*) echo "{\"action\": [-1.5]}";; *) echo "{\"action\": [0.5]}";; esac; done'"#;
        let mut e = boxed(script);
        assert_eq!(e.act(&[0.5, 0.0, 0.0]).unwrap(), vec![0.5]);
        assert_eq!(e.act(&[-0.5, 0.0, 0.0]).unwrap(), vec![-1.5]);
        for (answer, expected) in [
            ("[0.1, 0.2]", "an action has 2 values, not 1"),
            (
                "[2.5]",
                "dimension 0 of Pendulum-v1's actions lies in [-2, 2]",
            ),
            ("[1e40]", "not a finite number"),
            ("1", "a list of numbers"),
            ("[\\\"a\\\"]", "a list of numbers"),
        ] {
            let script = format!(
                "sh -c 'read h; while read l; do echo \"{{\\\"action\\\": {answer}}}\"; done'"
            );
            let msg = format!("{:#}", boxed(&script).act(&[0.0; 3]).unwrap_err());
            assert!(
                msg.contains(expected) && msg.contains("expert process"),
                "{answer}: {msg}"
            );
        }
    }

    #[test]
    fn missing_program_and_bad_timeout_are_errors() {
        // Either the hello already fails to be written or the first query finds the process gone.
        let msg = match expert("/nonexistent/expert-program", 10.0) {
            Err(e) => format!("{e:#}"),
            Ok(mut e) => format!("{:#}", e.act(&[0.0; 4]).unwrap_err()),
        };
        assert!(msg.contains("/nonexistent/expert-program"), "{msg}");
        assert!(expert("true", 0.0).is_err());
        assert!(expert("  ", 1.0).is_err());
    }
}
