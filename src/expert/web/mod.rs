//! The web expert: a person answers the agent's queries in a browser.
//!
//! [`WebExpert::start`] binds a local web server ([`server`], axum on a tokio runtime thread of its own) and
//! prints the URL to open, with a random access token from the operating system (not from the run's seed, so
//! the run's own random draws are untouched). Training runs at full speed while the page shows it: the
//! environment drawn from its [`Geometry`](crate::env::Geometry), step, episode, budget, the uncertainty against
//! the adaptive threshold, the test-return curve. When the agent asks, the run waits for the person, who answers
//! with the keyboard (arrows or WASD) or the buttons for the whole segment, either turn-based (one step per key)
//! or in real time (`fps`: the environment advances at that rate with the held key, or the no-op action when none
//! is held). With a `timeout`, a question nobody answers in time goes back to the agent
//! ([`Answer::Unanswered`]). The page ([`protocol`] describes its messages) is plain HTML, CSS and JavaScript
//! embedded in the binary.
//!
//! The training thread never waits for the server except while a question is open: it publishes to a shared
//! board (throttled to about 15 updates a second) and reads keys from a channel.

pub mod protocol;
pub mod server;

use super::{Answer, Expert, Progress, Query};
use crate::env::Env;
use anyhow::{Context, Result, bail, ensure};
use protocol::{Hello, Prompt, ServerMsg, Status};
use server::{KeyInput, Shared};
use std::io::Write;
use std::net::SocketAddr;
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

/// The default address: this machine only.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8765";
/// Live updates per second while training runs.
const UPDATES_PER_S: f64 = 15.0;
/// How often a wait for the person looks for a stop request.
const STOP_POLL: Duration = Duration::from_millis(50);

/// How the web expert listens and how the person answers. Written as the spec `web:listen=ADDR,fps=N,timeout=S`
/// (every part optional, e.g. `web` or `web:fps=10`).
#[derive(Clone, Debug, PartialEq)]
pub struct WebOptions {
    pub listen: SocketAddr,
    /// Real-time steps per second; `None`: turn-based.
    pub fps: Option<f64>,
    /// Seconds a question waits before it goes back to the agent; `None`: it waits for ever.
    pub timeout: Option<f64>,
}

impl Default for WebOptions {
    fn default() -> Self {
        Self {
            listen: DEFAULT_LISTEN.parse().expect("valid default address"),
            fps: None,
            timeout: None,
        }
    }
}

impl std::str::FromStr for WebOptions {
    type Err = anyhow::Error;
    /// Parses `listen=ADDR,fps=N,timeout=S` (any subset, any order; empty: the defaults).
    fn from_str(s: &str) -> Result<Self> {
        let mut o = WebOptions::default();
        for part in s.split(',').filter(|p| !p.is_empty()) {
            let (key, value) = part
                .split_once('=')
                .with_context(|| format!("web expert option '{part}' is not key=value"))?;
            let positive = |what: &str, max: f64| -> Result<f64> {
                let v: f64 = value
                    .parse()
                    .with_context(|| format!("web expert {what} '{value}' is not a number"))?;
                ensure!(
                    v.is_finite() && v > 0.0 && v <= max,
                    "web expert {what} must be in (0, {max}], got {value}"
                );
                Ok(v)
            };
            match key {
                "listen" => o.listen = value.parse().with_context(|| {
                    format!(
                        "web expert listen address '{value}' is not IP:PORT (e.g. {DEFAULT_LISTEN})"
                    )
                })?,
                "fps" => o.fps = Some(positive("fps", 1000.0)?),
                "timeout" => o.timeout = Some(positive("timeout", 1e6)?),
                _ => bail!("unknown web expert option '{key}'; known: listen, fps, timeout"),
            }
        }
        Ok(o)
    }
}

impl WebOptions {
    /// The options as the spec suffix that [`FromStr`](std::str::FromStr) reads back.
    pub fn to_spec(&self) -> String {
        let mut parts = vec![format!("listen={}", self.listen)];
        parts.extend(self.fps.map(|v| format!("fps={v}")));
        parts.extend(self.timeout.map(|v| format!("timeout={v}")));
        format!("web:{}", parts.join(","))
    }
}

/// A person in a browser, as an [`Expert`].
pub struct WebExpert {
    shared: Arc<Shared>,
    keys: mpsc::Receiver<KeyInput>,
    options: WebOptions,
    url: String,
    noop: usize,
    next_prompt: u64,
    prompt_open: bool,
    last_update: Option<Instant>,
    last_eval: Option<u64>,
    /// When the last real-time step was taken.
    last_tick: Instant,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl WebExpert {
    /// Starts the server for `env_id` and prints the URL to open on standard output.
    pub fn start(options: &WebOptions, env_id: &str) -> Result<Self> {
        let spec = crate::env::spec(env_id)?;
        let (actions, noop) = protocol::action_keys(env_id)
            .with_context(|| format!("the web expert cannot show {env_id}"))?;
        let listener = std::net::TcpListener::bind(options.listen).with_context(|| {
            format!(
                "the web expert cannot listen on {} (choose another with --listen)",
                options.listen
            )
        })?;
        let addr = listener.local_addr()?;
        if !addr.ip().is_loopback() {
            eprintln!(
                "warning: the web expert listens on {addr}, which other machines may reach; anyone with the \
                 URL and its token can answer the agent's queries"
            );
        }
        let mut bytes = [0u8; 16];
        getrandom::fill(&mut bytes)
            .map_err(|e| anyhow::anyhow!("no random token from the operating system: {e}"))?;
        let token: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        let hello = Hello {
            env: env_id.to_string(),
            actions,
            noop,
            fps: options.fps,
            timeout: options.timeout,
            solve_threshold: spec.solve_threshold,
            client: 0,
        };
        let (keys_tx, keys) = mpsc::channel();
        let shared = Arc::new(Shared::new(token.clone(), hello, spec.n_actions, keys_tx));
        let (stop, stop_rx) = tokio::sync::oneshot::channel();
        let thread = server::spawn(listener, Arc::clone(&shared), stop_rx)?;
        let host = if addr.ip().is_unspecified() {
            SocketAddr::new([127, 0, 0, 1].into(), addr.port())
        } else {
            addr
        };
        let url = format!("http://{host}/?token={token}");
        let mut out = std::io::stdout().lock();
        writeln!(out, "The agent asks a person: open {url}")?;
        out.flush()?;
        Ok(Self {
            shared,
            keys,
            options: options.clone(),
            url,
            noop,
            next_prompt: 0,
            prompt_open: false,
            last_update: None,
            last_eval: None,
            last_tick: Instant::now(),
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The page's URL with its token.
    pub fn url(&self) -> &str {
        &self.url
    }

    fn publish_frame(&self, env: &dyn Env, obs: &[f32]) {
        let geometry = env.geometry();
        let msg = ServerMsg::Frame {
            geometry: geometry.as_ref(),
            obs,
        }
        .to_json();
        self.shared.publish(msg, |b, m| b.frame = Some(m.clone()));
    }

    fn publish_prompt(&mut self, prompt: Option<&Prompt>) {
        self.prompt_open = prompt.is_some();
        let msg = ServerMsg::Prompt { prompt }.to_json();
        self.shared
            .publish(msg, |b, m| b.prompt = prompt.map(|_| m.clone()));
    }

    /// Waits for the key that answers prompt `id`, until the timeout if there is one.
    fn wait_for_key(&mut self, id: u64) -> Result<Answer> {
        let asked = Instant::now();
        let deadline = self
            .options
            .timeout
            .map(|t| asked + Duration::from_secs_f64(t));
        loop {
            // A stop request (Ctrl-C, SIGTERM) ends the wait within a poll: the run snapshots with the question
            // open and asks it again when resumed.
            if crate::interrupt::requested() {
                return Err(crate::interrupt::Interrupted(
                    "stopped while the person had a question open".into(),
                )
                .into());
            }
            let wait = match deadline {
                Some(d) => d.saturating_duration_since(Instant::now()),
                None => STOP_POLL,
            }
            .min(STOP_POLL);
            match self.keys.recv_timeout(wait) {
                // Keys meant for an earlier prompt (pressed twice, or late) are dropped.
                Ok(key) if key.id != id => {}
                Ok(key) => {
                    self.last_tick = Instant::now();
                    return Ok(Answer::Action {
                        action: key.action,
                        response_s: Some(asked.elapsed().as_secs_f64()),
                    });
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    if deadline.is_some_and(|d| Instant::now() >= d) {
                        self.publish_prompt(None);
                        return Ok(Answer::Unanswered {
                            waited_s: asked.elapsed().as_secs_f64(),
                        });
                    }
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    bail!("the web expert's server stopped while a question was open")
                }
            }
        }
    }
}

impl Expert for WebExpert {
    fn act(&mut self, _obs: &[f32]) -> Result<usize> {
        bail!(
            "the web expert answers the agent's queries during training only; it cannot give demonstrations \
             before training (give pre-training demonstrations with --demos FILE)"
        )
    }

    fn describe(&self) -> String {
        self.options.to_spec()
    }

    fn answer(&mut self, query: &Query) -> Result<Answer> {
        // In real time only the segment's first step waits for the person; the others run at the set rate.
        let realtime = self.options.fps.filter(|_| query.agent_action.is_none());
        self.next_prompt += 1;
        let id = self.next_prompt;
        self.publish_frame(query.env, query.obs);
        self.publish_prompt(Some(&Prompt {
            id,
            agent_action: query.agent_action,
            steps_left: query.steps_left,
            waits: realtime.is_none(),
            obs: query.obs.to_vec(),
        }));
        match realtime {
            None => self.wait_for_key(id),
            Some(fps) => {
                let period = Duration::from_secs_f64(1.0 / fps);
                let next = self.last_tick + period;
                std::thread::sleep(next.saturating_duration_since(Instant::now()));
                // Keep the rate, but do not race to catch up after a slow step.
                self.last_tick = Instant::now()
                    .checked_sub(period)
                    .map_or(next, |late| next.max(late));
                Ok(Answer::Action {
                    action: self.shared.held().unwrap_or(self.noop),
                    response_s: None,
                })
            }
        }
    }

    fn observe(&mut self, p: &Progress) {
        if self.prompt_open && !p.queries.expert_in_control() {
            self.publish_prompt(None);
        }
        if let Some((step, mean)) = p.last_eval
            && self.last_eval != Some(step)
        {
            self.last_eval = Some(step);
            let msg = ServerMsg::Eval { step, mean }.to_json();
            self.shared.publish(msg, |b, _| b.curve.push((step, mean)));
        }
        let now = Instant::now();
        let due = self
            .last_update
            .is_none_or(|t| now.duration_since(t).as_secs_f64() >= 1.0 / UPDATES_PER_S);
        // While a segment runs the steps are slow (the person's pace): show each one.
        if !due && !p.queries.expert_in_control() && p.step < p.train_steps {
            return;
        }
        self.last_update = Some(now);
        let threshold = p.queries.rule().threshold();
        if let Some(u) = p.uncertainty {
            self.shared.push_uncertainty((p.step, u, threshold));
        }
        let status = Status {
            step: p.step,
            train_steps: p.train_steps,
            episode: p.episode,
            budget: p.queries.budget(),
            budget_used: p.queries.budget_spent(),
            queries: p.queries.queries(),
            uncertainty: p.uncertainty,
            threshold,
            last_eval: p.last_eval,
        };
        let msg = ServerMsg::Status(&status).to_json();
        self.shared.publish(msg, |b, m| b.status = Some(m.clone()));
        // The frame shows the state the agent acts in next (the observation is not needed for drawing).
        self.publish_frame(p.env, &[]);
    }
}

impl Drop for WebExpert {
    /// Tells the open tabs that the run is over, gives them a moment to receive it, and stops the server.
    fn drop(&mut self) {
        let message = if crate::interrupt::requested() {
            "The run was stopped. Your answers are saved; resumed, it continues where it stopped."
        } else {
            "The run is over."
        };
        let msg = ServerMsg::End {
            message: message.into(),
        }
        .to_json();
        self.shared.publish(msg, |b, m| {
            b.end = Some(m.clone());
            b.prompt = None;
        });
        let started = Instant::now();
        while self.shared.open_tabs() > 0 && started.elapsed() < Duration::from_secs(2) {
            std::thread::sleep(Duration::from_millis(20));
        }
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse_and_round_trip() {
        assert_eq!("".parse::<WebOptions>().unwrap(), WebOptions::default());
        let o: WebOptions = "fps=12.5,listen=0.0.0.0:9000,timeout=30".parse().unwrap();
        assert_eq!(o.listen, "0.0.0.0:9000".parse().unwrap());
        assert_eq!((o.fps, o.timeout), (Some(12.5), Some(30.0)));
        assert_eq!(
            o.to_spec()
                .strip_prefix("web:")
                .unwrap()
                .parse::<WebOptions>()
                .unwrap(),
            o
        );
        for bad in [
            "fps=0",
            "fps=-3",
            "fps=nan",
            "timeout=inf",
            "listen=localhost",
            "listen=1.2.3.4",
            "speed=3",
            "fps",
        ] {
            assert!(bad.parse::<WebOptions>().is_err(), "{bad} accepted");
        }
    }
}
