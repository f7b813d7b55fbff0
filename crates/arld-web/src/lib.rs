//! The web expert: a person answers the agent's queries in a browser.
//!
//! [`WebServer::start`] binds a local web server ([`server`], axum on a tokio runtime thread of its own) and
//! prints the URL to open, with a random access token from the operating system (not from the run's seed, so
//! the run's own random draws are untouched). It can start before the environment is known (a Python program
//! creates it first); [`WebExpert::new`] then gives it the run's [`Page`]: the environment's name, its actions
//! with their keys, and the [`FrameSource`] that shows it ([`frames`]: the built-in tasks drawn from their
//! geometry, rendered frames of any other environment, or its observation as a table). The run starts once a
//! page is open ([`WebExpert::wait_for_page`], unless `wait=no`).
//!
//! Training runs at full speed while the page shows it (in real time the person may choose watch mode: the agent's
//! own steps at the real-time rate, outside any question, so not the person's time): the environment, step, episode, budget, the uncertainty
//! against the adaptive threshold, the test-return curve, and the person's own time (questions left at most,
//! seconds spent, an estimate of the time still needed at their pace). When the agent asks, the run waits for
//! the person, who answers with the keyboard or the buttons for the whole segment, either turn-based (one step
//! per key) or in real time (`fps`: after a deliberate gesture, and a countdown unless the gesture was the action
//! itself (an action's key, a stick leaving its dead zone), the environment advances at that rate
//! with the held key, or the no-op action when none is held; a question's segment lasts `segment_s` seconds of play,
//! 3 by default: [`WebOptions::segment_steps`]). Before a question the page replays the agent's
//! own steps since the person's last one (during the breath after their last segment), and in turn-based mode the person can undo their last key: both
//! rebuild the environment from the query's episode ([`arld_core::env::replay_episode`]) where the frame source
//! can show such a copy. Undo works one key ahead: the page shows the state after a key on a copy, and the run
//! takes that key only when the next one comes, so an undone key never reaches the training loop. A question goes back to the agent ([`Answer::Unanswered`]) when the person hands
//! it back or, with a `timeout`, when nobody answers in time (after a hand-back the agent's questions in the next
//! [`HANDBACK_QUIET_STEPS`] steps of the episode go back to it unasked). In real time the person may also take
//! over unasked ("Take over", key T, while the agent acts: [`Person::wants_control`]; offered only then, not while
//! a question opens, and a request not yet taken can be cancelled: [`server::Takeover`]): from the state the agent is
//! in, a segment opens as a question's does (a fresh key, the countdown, then the held key), charged to the budget
//! the same way and logged with `started_by: "person"`, until they hand back (Esc), the episode ends or the budget
//! is spent. The person may pause the run; their time
//! leaves out pauses and time with no tab open. A Python program's run handed back to it between two steps
//! ([`Person::handed_over`]: `learn` returned, or a stop) shows where it stands until it goes on. A stop request
//! (Ctrl-C, SIGTERM) ends any wait at once with [`arld_core::interrupt::Interrupted`], so that the run snapshots with
//! the question open. Resumed, the run asks it again; a real-time segment that was in progress goes on only after
//! a fresh key and the countdown, as at its opening (the person had no control while the run was stopped), and
//! the charts start from the run's course before the stop ([`Person::resumed_history`]): the test-return curve
//! from its evaluations (the snapshot's curve, which `eval.csv` holds too) and the uncertainty chart from the
//! uncertainties logged with its questions in `queries.csv`, the only ones a run keeps with their steps (the
//! rule's window in the snapshot has no steps), so before the resume the chart shows the steps where the agent
//! asked. The page ([`protocol`] describes its messages) is plain HTML, CSS and JavaScript embedded
//! in the binary; at the end it shows how the run ended and what the person gave ([`Person::finish`]).
//!
//! At every step of a segment the page shows the agent's proposal there ([`Query::propose`]: its test-time action,
//! a ghost of it on the drawing and the controls). In real time a question's segment is played ahead on a copy of the
//! environment (`WebExpert::play_ahead`): a line after it says how it went ([`protocol::SegmentEnd`]), and in the
//! breath after it the person may play it again from its start state; the run then takes the attempt kept, step for
//! step, and charges the dropped ones ([`Person::retried_steps`]).
//!
//! Actions in a box (the continuous tasks: [`WebExpert::start_box`]) take the same path: [`PageAction`] says how
//! each kind of action is described to the page, checked when it comes back and replayed on a copy; the page
//! sets a box action with keys held toward a bound, a slider per dimension or a gamepad's sticks and triggers, and
//! sends it as a list of numbers.
//!
//! The training thread never waits for the server except while a question is open (or the run is paused): it
//! publishes to a shared board (throttled to about 15 updates a second) and reads keys from a channel.

pub mod frames;
pub mod protocol;
pub mod server;

use anyhow::{Context, Result, bail};
use arld_core::env::{Env, EpisodeStart};
use arld_core::expert::process::WireAction;
pub use arld_core::expert::web_options::{DEFAULT_LISTEN, WebOptions};
use arld_core::expert::{Answer, Expert, Person, Progress, Query, RunEnd, RunHistory};
use arld_core::query::BudgetUnit;
use frames::FrameSource;
use protocol::{
    ActionCheck, ActionKeys, BoxControls, EndScreen, Hello, Prompt, SegmentEnd, ServerMsg, Status,
};
use server::{Input, KeyInput, Shared};
use std::collections::VecDeque;
use std::io::Write;
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

/// Live updates per second while training runs.
const UPDATES_PER_S: f64 = 15.0;
/// How often a wait for the person looks for a stop request.
const STOP_POLL: Duration = Duration::from_millis(50);
/// The agent's steps replayed to the person before a question, at most (the page plays them within 1 s, during the
/// breath after the person's last segment).
pub const REPLAY_MAX_STEPS: usize = 200;
/// Real time: the countdown between the person's key and the start of their segment.
pub const REALTIME_COUNTDOWN: Duration = Duration::from_millis(750);
/// Real time: the breath between the end of the person's segment and the next question.
pub const REALTIME_BREATH: Duration = Duration::from_secs(1);
/// After the person hands a question back, the agent's questions in the next this many steps of the same episode
/// go back to it unasked (logged unanswered, nothing charged): the person said they would rather not.
pub const HANDBACK_QUIET_STEPS: usize = 100;

/// The web server and the address to open: started before the run knows its environment (a Python user creates
/// it first and passes it as the expert), it shows "waiting for the run" until a [`WebExpert`] takes it.
pub struct WebServer {
    shared: Arc<Shared>,
    keys: mpsc::Receiver<KeyInput>,
    options: WebOptions,
    url: String,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl WebServer {
    /// Binds `options.listen`, starts serving and prints the URL to open on standard output.
    pub fn start(options: &WebOptions) -> Result<Self> {
        let server = Self::bind(options)?;
        server.announce()?;
        Ok(server)
    }

    /// Prints the URL to open on standard output.
    pub fn announce(&self) -> Result<()> {
        let mut out = std::io::stdout().lock();
        writeln!(out, "The agent asks a person: open {}", self.url)?;
        out.flush()?;
        Ok(())
    }

    /// Binds `options.listen` and starts serving, without printing the URL (a Python program prints it once
    /// its run is accepted: [`WebServer::announce`]).
    pub fn bind(options: &WebOptions) -> Result<Self> {
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
        let (keys_tx, keys) = mpsc::channel();
        let shared = Arc::new(Shared::new(token.clone(), addr, keys_tx));
        let (stop, stop_rx) = tokio::sync::oneshot::channel();
        let thread = server::spawn(listener, Arc::clone(&shared), stop_rx)?;
        let url = format!("http://{}/?token={token}", reachable(addr));
        Ok(Self {
            shared,
            keys,
            options: options.clone(),
            url,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The page's URL with its token.
    pub fn url(&self) -> &str {
        &self.url
    }

    pub fn options(&self) -> &WebOptions {
        &self.options
    }
}

/// The address to print for a server bound to `addr`: itself, or for every interface (`0.0.0.0`, `::`) this
/// machine's address on its default route (what another machine reaches), else the loopback address.
pub fn reachable(addr: SocketAddr) -> SocketAddr {
    if !addr.ip().is_unspecified() {
        return addr;
    }
    // Connecting a UDP socket sends nothing: it only picks the interface the route goes through.
    let outward = |probe: SocketAddr| {
        let local = if probe.is_ipv4() {
            "0.0.0.0:0"
        } else {
            "[::]:0"
        };
        std::net::UdpSocket::bind(local)
            .and_then(|s| s.connect(probe).and_then(|()| s.local_addr()))
            .ok()
            .map(|a| a.ip())
            .filter(|ip| !ip.is_unspecified() && !ip.is_loopback())
    };
    let ip = if addr.is_ipv4() {
        outward(SocketAddr::from(([192, 0, 2, 1], 9)))
    } else {
        outward("[2001:db8::1]:9".parse().expect("an address"))
    };
    let loopback: IpAddr = if addr.is_ipv4() {
        [127, 0, 0, 1].into()
    } else {
        std::net::Ipv6Addr::LOCALHOST.into()
    };
    SocketAddr::new(ip.unwrap_or(loopback), addr.port())
}

impl Drop for WebServer {
    /// Tells the open tabs that the run is over (unless the expert already did), gives them a moment to receive
    /// it, and stops the server.
    fn drop(&mut self) {
        if !self.shared.ended() {
            let message = if arld_core::interrupt::requested() {
                "The run was stopped. Your answers are saved; resumed, it continues where it stopped."
            } else {
                "The run is over."
            };
            let msg = ServerMsg::End {
                message: message.into(),
                outcome: None,
            }
            .to_json();
            self.shared.publish(msg, |b, m| {
                b.end = Some(m.clone());
                b.prompt = None;
            });
        }
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

/// The kinds of action a person gives on the page: discrete actions (an index, keys and buttons) and actions in
/// a box (a list of numbers, from keys, sliders and a pad's sticks), side by side. How an action travels and is
/// checked is the core's [`WireAction`], as for an expert process.
pub trait PageAction: WireAction {
    /// How the page controls the task `env`: its box (its dimensions named `names` where given), or `None`
    /// for buttons.
    fn controls(env: &str, names: Option<&[String]>) -> Result<Option<BoxControls>>;
    /// The check of an action the page sends.
    fn checker(env: &str, n_actions: usize) -> Result<ActionCheck>;
    /// A fresh copy of the built-in environment `env` (to replay the agent's steps, or show a key's result),
    /// `None` for an environment arld does not build.
    fn make(env: &str) -> Option<Box<dyn Env<Self>>>;
}

impl PageAction for usize {
    fn controls(_: &str, _: Option<&[String]>) -> Result<Option<BoxControls>> {
        Ok(None)
    }
    fn checker(_: &str, n_actions: usize) -> Result<ActionCheck> {
        Ok(protocol::discrete_check(n_actions))
    }
    fn make(env: &str) -> Option<Box<dyn Env>> {
        arld_core::env::make(env).ok()
    }
}

impl PageAction for Vec<f32> {
    fn controls(env: &str, names: Option<&[String]>) -> Result<Option<BoxControls>> {
        let controls = BoxControls::of(arld_core::env::box_spec(env)?);
        Ok(Some(match names {
            Some(names) => controls.named(names)?,
            None => controls,
        }))
    }
    fn checker(env: &str, _: usize) -> Result<ActionCheck> {
        Ok(protocol::box_check(arld_core::env::box_spec(env)?))
    }
    fn make(env: &str) -> Option<Box<dyn Env<Vec<f32>>>> {
        arld_core::env::make_box(env).ok()
    }
}

/// What the page shows of an environment and how the person acts in it.
pub struct Page<A: PageAction = usize> {
    pub env: String,
    /// Discrete actions with their keys (none for a box: its controls come from the task's bounds).
    pub actions: Vec<ActionKeys>,
    /// The action taken in real time when nothing is held.
    pub noop: A,
    pub solve_threshold: f64,
    pub frames: Box<dyn FrameSource<A>>,
    /// Actions in a box: a name for each dimension (`None`: arld's names where it knows the task, else
    /// `action[d]`).
    pub dim_names: Option<Vec<String>>,
}

impl Page<Vec<f32>> {
    /// A task with actions in a box: a built-in one drawn from its geometry, another (a Python program's,
    /// registered under arld's name for it with facts added) its observation as a labelled table; nothing held is
    /// the box's centre.
    pub fn builtin_box(env_id: &str) -> Result<Self> {
        let spec = arld_core::env::box_spec(env_id)?;
        let noop = spec
            .action_low
            .iter()
            .zip(spec.action_high)
            .map(|(lo, hi)| (lo + hi) / 2.0)
            .collect();
        Ok(Self {
            env: env_id.to_string(),
            actions: Vec::new(),
            noop,
            solve_threshold: spec.solve_threshold.unwrap_or(f64::INFINITY),
            frames: if arld_core::env::continuous::known_continuous_ids().contains(&env_id) {
                Box::new(frames::GeometryFrames)
            } else {
                Box::new(frames::ObservationTable::new(
                    spec.obs_dim,
                    protocol::box_obs_labels(env_id),
                ))
            },
            dim_names: None,
        })
    }
}

impl Page {
    /// A built-in task: drawn from its geometry, with arrow and WASD keys.
    pub fn builtin(env_id: &str) -> Result<Self> {
        let spec = arld_core::env::spec(env_id)?;
        let (actions, noop) = protocol::action_keys(env_id)
            .with_context(|| format!("the web expert has no keys for {env_id}"))?;
        Ok(Self {
            env: env_id.to_string(),
            actions,
            noop,
            solve_threshold: spec.solve_threshold,
            frames: Box::new(frames::GeometryFrames),
            dim_names: None,
        })
    }
}

/// What the person gave: the counts shown on the page and in the summary, carried across a resume in the
/// run's snapshot.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
struct Effort {
    /// Seconds the run waited for the person (questions open, real-time segments), pauses and time with no
    /// tab open excluded.
    person_s: f64,
    /// Keys (or buttons) that answered a question or a step.
    keys: usize,
    /// Opening questions answered, and handed back or timed out.
    answered: usize,
    unanswered: usize,
    /// Keys taken back (turn-based).
    #[serde(default)]
    undone: usize,
    /// Segments the person took over unasked (absent from the state of runs without any).
    #[serde(default, skip_serializing_if = "is_zero")]
    takeovers: usize,
    /// Segments the person played again (absent from the state of runs without any).
    #[serde(default, skip_serializing_if = "is_zero")]
    retries: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// A person in a browser, as an [`Expert`] of actions of kind `A` (discrete, or in a box).
pub struct WebExpert<A: PageAction = usize> {
    server: WebServer,
    frames: Box<dyn FrameSource<A>>,
    noop: A,
    next_prompt: u64,
    prompt_open: bool,
    last_update: Option<Instant>,
    last_eval: Option<u64>,
    /// When the last real-time step was taken.
    last_tick: Instant,
    /// The person's next answer, given while the page showed the state after their previous key (which the
    /// run takes only now, so that the key could still be undone).
    carried: Option<Answer<A>>,
    /// Where the person's last step left the episode: how it began and the number of its steps.
    last_person: Option<(EpisodeStart, usize)>,
    /// The run's latest status when it was not published yet (updates are throttled).
    unsent: Option<Status>,
    effort: Effort,
    /// Whether a stop was requested (Ctrl-C, SIGTERM): [`arld_core::interrupt::requested`] unless the program
    /// that owns the signals says otherwise ([`WebExpert::set_stop_check`]).
    stop_requested: Box<dyn FnMut() -> bool + Send>,
    /// Whether the page shows a hand-over note ([`Person::handed_over`]), lifted when the run goes on.
    handed: bool,
    /// Where the person last handed a question back: the episode (its number) and its steps then.
    handed_back: Option<(usize, usize)>,
    /// The episode in progress, by number (from [`Person::observe`]).
    episode: usize,
    /// Real time: when the person's last segment ended.
    segment_ended: Option<Instant>,
    /// The answer being given is a hand-back (Esc), not a timeout.
    handing_back: bool,
    /// The question being asked went back to the agent unasked (within [`HANDBACK_QUIET_STEPS`]).
    declined: bool,
    /// The segment in progress is the person's takeover ([`Query::taken_over`]).
    taking_over: bool,
    /// The run was resumed from a snapshot ([`Expert::restore`]) and has not asked yet: a real-time segment in
    /// progress goes on only after a fresh key and the countdown, as a segment's opening does.
    resumed: bool,
    /// The last answer's gesture was the action itself (a real-time segment then starts without the countdown).
    answered_acting: bool,
    /// Real time: the person's segment, played on a copy and kept: its actions after the first, each with the
    /// observation it was chosen at, which the run takes one a step ([`WebExpert::play_ahead`]).
    queue: VecDeque<(A, Vec<f32>)>,
    /// The last answer came from [`Self::queue`] (its step was shown as the person played it).
    fed: bool,
    /// Steps of the attempts the person retried at the question just answered, for [`Person::retried_steps`].
    retried: usize,
}

/// A segment played on a copy: each step's action with the observation it acted on, their return, and the last
/// step's reward and ending.
struct Played<A> {
    steps: Vec<(A, Vec<f32>)>,
    ret: f64,
    last_reward: f64,
    terminated: bool,
    truncated: bool,
}

impl WebExpert {
    /// Starts the server for the built-in task `env_id`, prints the URL and (unless `options.wait` is off)
    /// waits for the page to be opened.
    pub fn start(options: &WebOptions, env_id: &str) -> Result<Self> {
        let page = Page::builtin(env_id)?;
        let mut expert = Self::new(WebServer::start(options)?, page);
        expert.wait_for_page()?;
        Ok(expert)
    }

    /// The expert of `server` for a run on the environment `page` describes; the open tabs learn of it at once.
    pub fn new(server: WebServer, page: Page) -> Self {
        Self::for_page(server, page).expect("discrete actions always have a page")
    }
}

impl WebExpert<Vec<f32>> {
    /// Starts the server for the built-in task `env_id` of actions in a box ([`WebExpert::start`]).
    pub fn start_box(options: &WebOptions, env_id: &str) -> Result<Self> {
        let page = Page::builtin_box(env_id)?;
        let mut expert = Self::for_page(WebServer::start(options)?, page)?;
        expert.wait_for_page()?;
        Ok(expert)
    }
}

impl<A: PageAction> WebExpert<A> {
    /// The expert of `server` for a run on the environment `page` describes; the open tabs learn of it at once.
    pub fn for_page(server: WebServer, page: Page<A>) -> Result<Self> {
        // Undo needs a copy of the environment (see `copy_of`): a source that draws what it is given, of an
        // environment arld builds.
        let undo = server.options.fps.is_none()
            && page.frames.shows_copies()
            && A::make(&page.env).is_some();
        let check = A::checker(&page.env, page.actions.len())?;
        let hello = Hello {
            undo,
            controls: A::controls(&page.env, page.dim_names.as_deref())?,
            noop: serde_json::to_value(&page.noop)?,
            env: page.env,
            actions: page.actions,
            fps: server.options.fps,
            timeout: server.options.timeout,
            solve_threshold: page.solve_threshold,
        };
        let msg = ServerMsg::Hello(&hello).to_json();
        server.shared.publish(msg, |b, m| {
            b.hello = Some(m.clone());
            b.check = Some(check);
        });
        Ok(Self {
            server,
            frames: page.frames,
            noop: page.noop,
            next_prompt: 0,
            prompt_open: false,
            last_update: None,
            last_eval: None,
            last_tick: Instant::now(),
            carried: None,
            last_person: None,
            unsent: None,
            effort: Effort::default(),
            stop_requested: Box::new(arld_core::interrupt::requested),
            handed: false,
            handed_back: None,
            episode: 0,
            segment_ended: None,
            handing_back: false,
            declined: false,
            taking_over: false,
            resumed: false,
            answered_acting: false,
            queue: VecDeque::new(),
            fed: false,
            retried: 0,
        })
    }

    /// Replaces the check for a stop request (a Python program: its own signal handling).
    pub fn set_stop_check(&mut self, check: Box<dyn FnMut() -> bool + Send>) {
        self.stop_requested = check;
    }

    /// The page's URL with its token.
    pub fn url(&self) -> &str {
        self.server.url()
    }

    /// Prints the URL to open on standard output ([`WebServer::announce`]): a Python program's run, once its
    /// page is made.
    pub fn announce(&self) -> Result<()> {
        self.server.announce()
    }

    fn stopped(&mut self, what: &str) -> Result<()> {
        if (self.stop_requested)() {
            return Err(arld_core::interrupt::Interrupted(format!("stopped {what}")).into());
        }
        Ok(())
    }

    /// Waits until a page is open (unless the options say not to), so that the run starts with the person.
    pub fn wait_for_page(&mut self) -> Result<()> {
        if !self.server.options.wait || self.server.shared.open_tabs() > 0 {
            return Ok(());
        }
        eprintln!("arld: the run starts when the page is open");
        while self.server.shared.open_tabs() == 0 {
            self.stopped("before the page was opened")?;
            std::thread::sleep(STOP_POLL);
        }
        Ok(())
    }

    /// Publishes what the page shows of the environment, when it changed.
    fn publish_frame(&mut self, env: &dyn Env<A>, obs: &[f32]) -> Result<()> {
        if let Some(msg) = self.frames.frame(env, obs)? {
            self.server
                .shared
                .publish(msg, |b, m| b.frame = Some(m.clone()));
        }
        Ok(())
    }

    fn publish_prompt(&mut self, prompt: Option<&Prompt>) {
        self.prompt_open = prompt.is_some();
        let msg = ServerMsg::Prompt { prompt }.to_json();
        self.server
            .shared
            .publish(msg, |b, m| b.prompt = prompt.map(|_| m.clone()));
    }

    /// Shows `obs` of `env` and opens a prompt for it; returns the prompt's id.
    fn show_question(
        &mut self,
        env: &dyn Env<A>,
        obs: &[f32],
        agent_action: Option<serde_json::Value>,
        (steps_left, undo): (usize, bool),
        proposal: Option<serde_json::Value>,
    ) -> Result<u64> {
        self.next_prompt += 1;
        let id = self.next_prompt;
        self.publish_frame(env, obs)?;
        self.publish_prompt(Some(&Prompt {
            id,
            agent_action,
            steps_left,
            waits: true,
            undo,
            starts_in: None,
            obs: obs.to_vec(),
            takeover: self.taking_over,
            proposal,
        }));
        Ok(id)
    }

    /// Shows the query's own state and opens its prompt.
    fn show_query(&mut self, query: &Query<'_, A>) -> Result<u64> {
        self.show_question(
            query.env,
            query.obs,
            agent_action(query),
            (query.steps_left, false),
            proposal(query, query.obs),
        )
    }

    /// Waits while the person has paused the run (the clock waits too).
    fn wait_while_paused(&mut self) -> Result<Duration> {
        let started = Instant::now();
        while self.server.shared.paused() {
            self.stopped("while the run was paused")?;
            std::thread::sleep(STOP_POLL);
        }
        Ok(started.elapsed())
    }

    /// Waits for the person's answer to prompt `id`, until the timeout if there is one (pauses do not count).
    /// `None`: the person took their last key back (only accepted when `undo` is).
    fn wait_for_key(&mut self, id: u64, undo: bool) -> Result<Option<Answer<A>>> {
        let asked = Instant::now();
        let absent_before = self.server.shared.absent_at(asked);
        let mut paused = Duration::ZERO;
        let timeout = self.server.options.timeout.map(Duration::from_secs_f64);
        loop {
            // A stop request (Ctrl-C, SIGTERM) ends the wait within a poll: the run snapshots with the question
            // open and asks it again when resumed.
            self.stopped("while the person had a question open")?;
            paused += self.wait_while_paused()?;
            let waited = asked.elapsed().saturating_sub(paused);
            if timeout.is_some_and(|t| waited >= t) {
                return Ok(Some(Answer::Unanswered {
                    waited_s: waited.as_secs_f64(),
                }));
            }
            let wait = timeout.map_or(STOP_POLL, |t| t.saturating_sub(waited).min(STOP_POLL));
            let input = match self.server.keys.recv_timeout(wait) {
                // Keys meant for an earlier prompt (pressed twice, or late) are dropped.
                Ok(key) if key.id != id => continue,
                Ok(key) => key.input,
                Err(mpsc::RecvTimeoutError::Timeout) => continue,
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    bail!("the web expert's server stopped while a question was open")
                }
            };
            let waited_s = asked.elapsed().saturating_sub(paused).as_secs_f64();
            // The person's response time: the wait while a tab was open and the run not paused.
            let response_s = self.server.shared.present_since(asked, absent_before);
            let response_s = response_s.as_secs_f64();
            match input {
                // Handed back: the agent acts; nothing is charged.
                Input::HandBack => {
                    self.handing_back = true;
                    return Ok(Some(Answer::Unanswered { waited_s }));
                }
                Input::Undo if undo => return Ok(None),
                Input::Undo | Input::Retry => {}
                Input::Action { action, acting } => {
                    let action = self.action_of(&action)?;
                    self.answered_acting = acting;
                    self.last_tick = Instant::now();
                    self.effort.keys += 1;
                    return Ok(Some(Answer::Action {
                        action,
                        response_s: Some(response_s),
                    }));
                }
            }
        }
    }

    /// The query's environment rebuilt from the start of its episode through `actions` (a prefix of the
    /// episode's), when the page can show such a copy (its frames are drawn from the environment they are given)
    /// and arld can build the environment.
    fn rebuild(&self, query: &Query<'_, A>, actions: &[A]) -> Option<(Box<dyn Env<A>>, Vec<f32>)> {
        if !self.frames.shows_copies() {
            return None;
        }
        let mut env = A::make(query.env.id())?;
        let mut obs = Vec::new();
        arld_core::env::replay_episode(&mut *env, query.episode.start, actions, &mut obs).ok()?;
        Some((env, obs))
    }

    /// A copy of the environment the query shows, when it can be rebuilt and reaches the query's observation.
    fn copy_of(&self, query: &Query<'_, A>) -> Option<(Box<dyn Env<A>>, Vec<f32>)> {
        self.rebuild(query, query.episode.actions)
            .filter(|(_, obs)| obs == query.obs)
    }

    /// Before a question: shows the person the agent's own steps since their last one in this episode (or since
    /// the episode began), at most [`REPLAY_MAX_STEPS`].
    fn replay_agent_steps(&mut self, query: &Query<'_, A>) -> Result<()> {
        let actions = query.episode.actions;
        let from = replay_from(
            self.last_person,
            query.episode.start,
            actions.len(),
            REPLAY_MAX_STEPS,
        );
        if from >= actions.len() {
            return Ok(());
        }
        let Some((mut env, mut obs)) = self.rebuild(query, &actions[..from]) else {
            return Ok(());
        };
        // The state the person left, then the state after each of the agent's steps: the last is the question's.
        let mut frames = Vec::with_capacity(actions.len() - from + 1);
        frames.extend(self.frames.frame(&*env, &obs)?);
        for a in &actions[from..] {
            if env.step_into(a.borrow(), &mut obs).is_err() {
                return Ok(());
            }
            frames.extend(self.frames.frame(&*env, &obs)?);
        }
        if obs != query.obs {
            // Not the state the question shows (an environment arld cannot rebuild exactly): no replay.
            return Ok(());
        }
        let frames = frames
            .iter()
            .map(|f| serde_json::from_str(f))
            .collect::<Result<Vec<serde_json::Value>, _>>()?;
        let msg = ServerMsg::Replay { frames }.to_json();
        self.server.shared.publish(msg, |_, _| {});
        Ok(())
    }

    /// Turn-based: the person's key for the query's state, with the chance to undo it. Where the environment can
    /// be copied and the segment goes on, the page shows the state after the key on a copy and waits for the
    /// next key: a key there is carried to the next step (the run takes this one), an undo asks this step again.
    fn ask_turn(&mut self, query: &Query<'_, A>) -> Result<Answer<A>> {
        let mut carried = self.carried.take();
        loop {
            let answer = match carried.take() {
                Some(answer) => answer,
                None => {
                    let id = self.show_query(query)?;
                    match self.wait_for_key(id, false)? {
                        Some(answer) => answer,
                        None => continue,
                    }
                }
            };
            let Answer::Action { action, .. } = &answer else {
                return Ok(answer);
            };
            if query.steps_left <= 1 {
                return Ok(answer);
            }
            let Some((mut copy, mut obs)) = self.copy_of(query) else {
                return Ok(answer);
            };
            let ended = copy
                .step_into(action.borrow(), &mut obs)
                .map(|o| o.terminated || o.truncated)
                .unwrap_or(true);
            if ended {
                return Ok(answer);
            }
            let ghost = proposal(query, &obs);
            let shown = self.show_question(&*copy, &obs, None, (query.steps_left - 1, true), ghost);
            let next = shown.and_then(|id| self.wait_for_key(id, true));
            match next {
                // Undone: this step is asked again from its own state.
                Ok(None) => {
                    self.effort.undone += 1;
                    self.effort.keys = self.effort.keys.saturating_sub(1);
                }
                // The next key (or a hand-back): the run takes this step now and that answer next.
                Ok(Some(next)) => {
                    self.carried = Some(next);
                    return Ok(answer);
                }
                // A stop: the run takes this key first (the person's answers are never lost), then stops.
                Err(err) if arld_core::interrupt::is_stop(&err) => return Ok(answer),
                Err(err) => return Err(err),
            }
        }
    }

    /// Real time: only the segment's opening question waits for a fresh key, then a countdown where needed; the
    /// later steps take the held key (or the no-op action) at the set rate. So does the first step after a resume
    /// (`resumed`) of a segment in progress: the person had no control while the run was stopped. The countdown is
    /// needed unless the answer's gesture was the action itself (a fresh action key, a stick or trigger leaving
    /// rest: the person acts already), and always after a resume. A question's segment is played ahead on a copy
    /// where the environment can be copied ([`Self::play_ahead`]: the person may retry it), and the run then
    /// takes its steps as played; a takeover (open-ended) and a resumed segment are played on the run itself.
    fn ask_realtime(&mut self, query: &Query<'_, A>, fps: f64, resumed: bool) -> Result<Answer<A>> {
        if query.agent_action.is_none()
            && !resumed
            && let Some(action) = self.next_queued(query)
        {
            return Ok(Answer::Action {
                action,
                response_s: None,
            });
        }
        if query.agent_action.is_some() || resumed {
            let id = self.show_query(query)?;
            let answer = self.wait_for_fresh_key(id)?;
            let Answer::Action { response_s, .. } = answer else {
                return Ok(answer);
            };
            self.count_down(query, id, resumed)?;
            if !query.taken_over
                && !resumed
                && let Some(copy) = self.copy_of(query)
            {
                let action = self.play_ahead(query, fps, copy)?;
                return Ok(Answer::Action { action, response_s });
            }
            return Ok(Answer::Action {
                action: self.held(),
                response_s,
            });
        }
        self.next_prompt += 1;
        let id = self.next_prompt;
        self.publish_frame(query.env, query.obs)?;
        self.publish_prompt(Some(&Prompt {
            id,
            agent_action: None,
            steps_left: query.steps_left,
            waits: false,
            undo: false,
            starts_in: None,
            obs: query.obs.to_vec(),
            takeover: self.taking_over,
            proposal: proposal(query, query.obs),
        }));
        self.stopped("during a real-time segment")?;
        self.wait_while_paused()?;
        self.pace(fps);
        // A takeover goes on until the person hands back (from any of its prompts).
        if self.taking_over && self.handed_back_now() {
            self.handing_back = true;
            return Ok(Answer::Unanswered { waited_s: 0.0 });
        }
        Ok(Answer::Action {
            action: self.held(),
            response_s: None,
        })
    }

    /// Waits for the person's fresh key for prompt `id` (the page never sends an undo in real time).
    fn wait_for_fresh_key(&mut self, id: u64) -> Result<Answer<A>> {
        loop {
            if let Some(answer) = self.wait_for_key(id, false)? {
                return Ok(answer);
            }
        }
    }

    /// Real time, after the key that answers prompt `id`: the countdown, unless the key was the action itself
    /// (and always after a resume); then the segment's clock starts.
    fn count_down(&mut self, query: &Query<'_, A>, id: u64, resumed: bool) -> Result<()> {
        if !self.answered_acting || resumed {
            self.publish_prompt(Some(&Prompt {
                id,
                agent_action: agent_action(query),
                steps_left: query.steps_left,
                waits: false,
                undo: false,
                starts_in: Some(REALTIME_COUNTDOWN.as_secs_f64()),
                obs: query.obs.to_vec(),
                takeover: self.taking_over,
                proposal: proposal(query, query.obs),
            }));
            let started = Instant::now();
            let mut paused = Duration::ZERO;
            while started.elapsed().saturating_sub(paused) < REALTIME_COUNTDOWN {
                self.stopped("during the countdown to a real-time segment")?;
                paused += self.wait_while_paused()?;
                std::thread::sleep(STOP_POLL.min(REALTIME_COUNTDOWN / 10));
            }
        }
        self.last_tick = Instant::now();
        Ok(())
    }

    /// The next step of the segment played ahead, when the run is where the person played it (else the rest is
    /// dropped and the person plays on the run itself).
    fn next_queued(&mut self, query: &Query<'_, A>) -> Option<A> {
        let (action, obs) = self.queue.pop_front()?;
        if obs != query.obs {
            self.queue.clear();
            return None;
        }
        self.fed = true;
        Some(action)
    }

    /// Real time, a question's segment played on a copy of the environment (`copy`: its state at the question)
    /// at `fps`, the agent's proposal shown at every step; then how it went ([`ServerMsg::Segment`]), and, while
    /// budget is left for another attempt, the chance to play it again from the same state during the breath
    /// after it (R on the page). The run takes the attempt kept: its first action is returned, the rest wait in
    /// [`Self::queue`]; the dropped attempts' steps are charged to the budget ([`Person::retried_steps`]). A
    /// hand-back (or a timeout) at a retry's question keeps the attempt before it.
    fn play_ahead(
        &mut self,
        query: &Query<'_, A>,
        fps: f64,
        (mut env, mut obs): (Box<dyn Env<A>>, Vec<f32>),
    ) -> Result<A> {
        let (mut allowed, mut attempt, mut dropped) = (query.steps_left, 1, 0);
        loop {
            let played = self.play(query, fps, &mut *env, &mut obs, allowed)?;
            let steps = played.steps.len();
            let room = retry_room(query, dropped + steps, attempt);
            self.next_prompt += 1;
            let id = self.next_prompt;
            self.publish_prompt(None);
            let line = SegmentEnd {
                id,
                steps,
                ret: played.ret,
                outcome: protocol::segment_outcome(
                    query.env.id(),
                    played.terminated,
                    played.truncated,
                    played.last_reward,
                ),
                retry_s: (room > 0).then_some(REALTIME_BREATH.as_secs_f64()),
                attempt,
            };
            self.server
                .shared
                .publish(ServerMsg::Segment(&line).to_json(), |_, _| {});
            let again = room > 0 && self.wait_for_retry(id)?;
            if again {
                (env, obs) = self
                    .copy_of(query)
                    .context("the segment's start state cannot be rebuilt for a retry")?;
                let id = self.show_query(query)?;
                if let Answer::Action { .. } = self.wait_for_fresh_key(id)? {
                    self.count_down(query, id, false)?;
                    dropped += steps;
                    attempt += 1;
                    self.effort.retries += 1;
                    allowed = room.min(query.steps_left);
                    continue;
                }
            }
            let mut steps = played.steps.into_iter();
            let (first, _) = steps.next().expect("a segment plays at least one step");
            self.queue = steps.collect();
            self.retried = dropped;
            self.fed = true;
            return Ok(first);
        }
    }

    /// Plays up to `max` steps on `env` (a copy, at `obs`) at `fps`: at each the held action (or the no-op),
    /// with the state and the agent's proposal shown. Returns each step's action with the observation it acted
    /// on, and how the steps went.
    fn play(
        &mut self,
        query: &Query<'_, A>,
        fps: f64,
        env: &mut dyn Env<A>,
        obs: &mut [f32],
        max: usize,
    ) -> Result<Played<A>> {
        let mut played = Played {
            steps: Vec::with_capacity(max),
            ret: 0.0,
            last_reward: 0.0,
            terminated: false,
            truncated: false,
        };
        for k in 0..max {
            if k > 0 {
                self.next_prompt += 1;
                self.publish_frame(env, obs)?;
                self.publish_prompt(Some(&Prompt {
                    id: self.next_prompt,
                    agent_action: None,
                    steps_left: max - k,
                    waits: false,
                    undo: false,
                    starts_in: None,
                    obs: obs.to_vec(),
                    takeover: false,
                    proposal: proposal(query, obs),
                }));
                self.stopped("during a real-time segment")?;
                self.wait_while_paused()?;
                self.pace(fps);
            }
            let action = self.held();
            let before = obs.to_vec();
            let out = env
                .step_into(action.borrow(), obs)
                .context("a copy of the environment failed to step")?;
            played.steps.push((action, before));
            played.ret += out.reward;
            played.last_reward = out.reward;
            (played.terminated, played.truncated) = (out.terminated, out.truncated);
            if out.terminated || out.truncated {
                break;
            }
        }
        self.publish_frame(env, obs)?;
        Ok(played)
    }

    /// After a segment: whether the person asks to play it again (segment `id`) within the breath (pauses
    /// excluded); other keys are dropped.
    fn wait_for_retry(&mut self, id: u64) -> Result<bool> {
        let started = Instant::now();
        let mut paused = Duration::ZERO;
        loop {
            self.stopped("after a segment")?;
            paused += self.wait_while_paused()?;
            let left = REALTIME_BREATH.saturating_sub(started.elapsed().saturating_sub(paused));
            if left.is_zero() {
                return Ok(false);
            }
            match self.server.keys.recv_timeout(left.min(STOP_POLL)) {
                Ok(key) if key.id == id && key.input == Input::Retry => return Ok(true),
                Ok(_) | Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    bail!("the web expert's server stopped after a segment")
                }
            }
        }
    }

    /// Real time: waits for the next step's time at `fps` steps a second after the last one; keeps the rate, but
    /// does not race to catch up after a slow step (or a pause).
    fn pace(&mut self, fps: f64) {
        let period = Duration::from_secs_f64(1.0 / fps);
        let next = self.last_tick + period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
        self.last_tick = Instant::now()
            .checked_sub(period)
            .map_or(next, |late| next.max(late));
    }

    /// Shows `status` on the page (and keeps it for a page that connects later).
    fn publish_status(&self, status: &Status) {
        let msg = ServerMsg::Status(status).to_json();
        self.server
            .shared
            .publish(msg, |b, m| b.status = Some(m.clone()));
    }

    /// Shows the status held back by the throttle of updates, if any.
    fn publish_unsent_status(&mut self) {
        if let Some(status) = self.unsent.take() {
            self.publish_status(&status);
        }
    }

    /// Real time, during a takeover: whether the person handed back since the last step (keys meant for
    /// anything else are dropped: only the held key acts in a running segment).
    fn handed_back_now(&mut self) -> bool {
        let mut handed = false;
        while let Ok(key) = self.server.keys.try_recv() {
            handed |= key.input == Input::HandBack;
        }
        handed
    }

    /// One step of a question: the agent's steps since the person's last one replayed first (on the step that
    /// opens a segment), then the person's answer. A takeover opens at once: the person watched the agent's
    /// steps and asked for it, so there is no replay, no breath and no quiet interval.
    fn ask(&mut self, query: &Query<'_, A>) -> Result<Answer<A>> {
        self.lift_hand_over();
        self.fed = false;
        if query.agent_action.is_some() {
            // A segment opens: the steps of one played ahead are the run's already (or it ended early).
            self.queue.clear();
        }
        let resumed = std::mem::take(&mut self.resumed);
        if resumed && query.agent_action.is_none() {
            // A segment in progress at the stop: the page shows where the run stands before the person goes on.
            self.carried = None;
            self.publish_unsent_status();
        }
        self.taking_over = query.taken_over;
        if query.agent_action.is_some() && query.taken_over {
            self.carried = None;
            // What the person saw the agent do is the latest status.
            self.publish_unsent_status();
        } else if query.agent_action.is_some() {
            // No takeover while a question opens (its breath, replay and segment): one asked for while the agent
            // acted is answered by the question itself, and none can be asked for until the agent acts again.
            self.server.shared.offer_takeover(false);
            // Shortly after a hand-back in the same episode the question is not asked again.
            if let Some((episode, at)) = self.handed_back {
                if episode == self.episode
                    && query.episode.actions.len() < at + HANDBACK_QUIET_STEPS
                {
                    self.declined = true;
                    return Ok(Answer::Unanswered { waited_s: 0.0 });
                }
                self.handed_back = None;
            }
            // A segment opens: nothing can be carried over from the last one (it ended with its last step).
            self.carried = None;
            self.publish_unsent_status();
            self.replay_agent_steps(query)?;
            // Real time: a breath after the person's last segment before the next question (the replay plays
            // meanwhile: the person's wait is the longer of the two, not their sum).
            if let Some(ended) = self.segment_ended.take() {
                while ended.elapsed() < REALTIME_BREATH {
                    self.stopped("before a question")?;
                    std::thread::sleep(
                        STOP_POLL.min(REALTIME_BREATH.saturating_sub(ended.elapsed())),
                    );
                }
            }
        }
        let answer = match self.server.options.fps {
            None => self.ask_turn(query)?,
            Some(fps) => self.ask_realtime(query, fps, resumed)?,
        };
        match answer {
            Answer::Action { .. } => {
                self.last_person = Some((query.episode.start, query.episode.actions.len() + 1));
                // (A segment played ahead had its breath after its last step was played.)
                if self.server.options.fps.is_some() && query.steps_left <= 1 && !self.fed {
                    self.segment_ended = Some(Instant::now());
                }
            }
            Answer::Unanswered { .. } => {
                self.publish_prompt(None);
                if std::mem::take(&mut self.handing_back) {
                    self.handed_back = Some((self.episode, query.episode.actions.len()));
                }
            }
        }
        Ok(answer)
    }
}

impl<A: PageAction> WebExpert<A> {
    /// An action the page sent (the server checked it: see [`protocol::ActionCheck`]).
    fn action_of(&self, value: &serde_json::Value) -> Result<A> {
        A::from_wire(value)
            .with_context(|| format!("the page sent an action of the wrong kind: {value}"))
    }

    /// Real time: the action held on the page, or the no-op action when nothing is held.
    fn held(&self) -> A {
        self.server
            .shared
            .held()
            .and_then(|v| A::from_wire(&v))
            .unwrap_or_else(|| self.noop.clone())
    }

    /// The run goes on: the hand-over note leaves the page.
    fn lift_hand_over(&mut self) {
        if std::mem::take(&mut self.handed) {
            let msg = ServerMsg::Resumed.to_json();
            self.server.shared.publish(msg, |b, _| b.handed = None);
        }
    }

    /// What the person gave, with the run's outcome, for the end screen.
    fn end_screen(&self, end: &RunEnd) -> EndScreen {
        EndScreen {
            solved: end.solved,
            steps_to_solve: end.steps_to_solve,
            train_steps: end.train_steps,
            final_score: end.final_score,
            run_dir: end.dir.as_ref().map(|d| d.display().to_string()),
            answered: self.effort.answered,
            unanswered: self.effort.unanswered,
            keys: self.effort.keys,
            undone: self.effort.undone,
            takeovers: self.effort.takeovers,
            person_s: self.effort.person_s,
        }
    }
}

/// Where the replay before a question starts, in the episode's steps (`len` so far, begun at `start`): at the
/// person's last step when it was in this episode, else at the episode's start; the last `cap` steps at most.
fn replay_from(
    last_person: Option<(EpisodeStart, usize)>,
    start: EpisodeStart,
    len: usize,
    cap: usize,
) -> usize {
    let from = match last_person {
        Some((episode, at)) if episode == start && at <= len => at,
        _ => 0,
    };
    from.max(len.saturating_sub(cap))
}

/// The agent's test-time action at `obs` (a state of the query's segment), as the page shows it, when the run
/// gives it ([`Query::propose`]).
fn proposal<A: PageAction>(query: &Query<'_, A>, obs: &[f32]) -> Option<serde_json::Value> {
    let propose = query.propose?;
    serde_json::to_value(propose(obs)).ok()
}

/// Steps another attempt at `query` may take, after `spent` steps given to it in `attempts` attempts: the budget
/// left then (counting queries, an attempt costs one query).
fn retry_room<A: PageAction>(query: &Query<'_, A>, spent: usize, attempts: usize) -> usize {
    match query.unit {
        BudgetUnit::Transitions => query.budget_left.saturating_sub(spent),
        BudgetUnit::Queries if query.budget_left >= attempts => usize::MAX,
        BudgetUnit::Queries => 0,
    }
}

/// The agent's proposal of `query`, as the page shows it.
fn agent_action<A: PageAction>(query: &Query<'_, A>) -> Option<serde_json::Value> {
    query
        .agent_action
        .and_then(|a| serde_json::to_value(A::owned(a)).ok())
}

impl<A: PageAction> Expert<A> for WebExpert<A> {
    fn act(&mut self, _obs: &[f32]) -> Result<A> {
        bail!(
            "the web expert answers the agent's queries during training only; it cannot give demonstrations \
             before training (give pre-training demonstrations with --demos FILE)"
        )
    }

    fn describe(&self) -> String {
        self.server.options.to_spec()
    }

    fn answer(&mut self, query: &Query<'_, A>) -> Result<Answer<A>> {
        let started = Instant::now();
        let absent_before = self.server.shared.absent_at(started);
        let result = self.ask(query);
        // The person's time: the whole wait, less the time they were absent (the run paused, or no tab open).
        let present = self.server.shared.present_since(started, absent_before);
        self.effort.person_s += present.as_secs_f64();
        if query.agent_action.is_some() && query.taken_over {
            if let Ok(Answer::Action { .. }) = result {
                self.effort.takeovers += 1;
            }
        } else if query.agent_action.is_some() && !std::mem::take(&mut self.declined) {
            match result {
                Ok(Answer::Action { .. }) => self.effort.answered += 1,
                Ok(Answer::Unanswered { .. }) => self.effort.unanswered += 1,
                Err(_) => {}
            }
        }
        result
    }

    fn state(&self) -> Option<String> {
        Some(serde_json::to_string(&self.effort).expect("counts serialise"))
    }

    fn restore(&mut self, state: &str) -> Result<()> {
        self.effort = serde_json::from_str(state)
            .map_err(|e| anyhow::anyhow!("the snapshot's web expert state is damaged: {e}"))?;
        self.resumed = true;
        Ok(())
    }

    fn person(&mut self) -> Option<&mut dyn Person<A>> {
        Some(self)
    }
}

impl<A: PageAction> Person<A> for WebExpert<A> {
    fn person_seconds(&self) -> Option<f64> {
        Some(self.effort.person_s)
    }

    fn shows_proposals(&self) -> bool {
        true
    }
    fn retried_steps(&mut self) -> usize {
        std::mem::take(&mut self.retried)
    }
    fn shows_uncertainty(&self) -> bool {
        true
    }
    /// The charts of a resumed run start from its course before the stop: the test-return curve from its
    /// evaluations, the uncertainty chart from the uncertainties logged with its questions (the only ones a run
    /// keeps with their steps), the latest [`server::UNCERTAINTY_HISTORY`] of them.
    fn resumed_history(&mut self, history: &RunHistory) {
        self.last_eval = history.curve.last().map(|&(step, _)| step);
        let keep = history
            .uncertainty
            .len()
            .saturating_sub(server::UNCERTAINTY_HISTORY);
        let uncertainty: Vec<(usize, f32, Option<f32>)> = history.uncertainty[keep..]
            .iter()
            .map(|&(step, u, threshold)| (step as usize, u, threshold))
            .collect();
        let msg = ServerMsg::History {
            uncertainty: &uncertainty,
            curve: &history.curve,
        }
        .to_json();
        self.server.shared.publish(msg, |b, _| {
            b.uncertainty = uncertainty.clone();
            b.curve = history.curve.clone();
        });
    }
    /// Real time only: the page's "Take over (T)" asked since the last step (turn-based, every step waits for
    /// the agent's questions anyway).
    fn wants_control(&mut self) -> bool {
        self.server.options.fps.is_some() && self.server.shared.take_takeover()
    }
    fn observe(&mut self, p: &Progress<'_, A>) {
        self.lift_hand_over();
        self.episode = p.episode;
        // A step of a segment played ahead: the page showed it as the person played it.
        let fed = std::mem::take(&mut self.fed);
        // Real time: the person may take over while the agent acts and budget is left; in watch mode the agent's
        // steps go at the real-time rate (outside any question: not the person's answering time).
        let mut watching = false;
        if let Some(fps) = self.server.options.fps {
            let acts = !p.queries.expert_in_control() && p.step < p.train_steps;
            self.server
                .shared
                .offer_takeover(acts && p.queries.budget_left() > 0);
            watching = acts && self.server.shared.watching();
            if watching {
                self.pace(fps);
            }
        }
        if self.prompt_open && !p.queries.expert_in_control() && self.carried.is_none() {
            self.publish_prompt(None);
        }
        // A pause holds the run between steps too. (A stop request during it is seen by the loop's next
        // snapshot point.)
        let _ = self.wait_while_paused();
        if let Some((step, mean)) = p.last_eval
            && self.last_eval != Some(step)
        {
            self.last_eval = Some(step);
            let msg = ServerMsg::Eval { step, mean }.to_json();
            self.server
                .shared
                .publish(msg, |b, _| b.curve.push((step, mean)));
        }
        let threshold = p.queries.rule().threshold();
        let (budget, used) = (p.queries.budget(), p.queries.budget_spent());
        let left = budget.saturating_sub(used);
        let status = Status {
            step: p.step,
            train_steps: p.train_steps,
            episode: p.episode,
            budget,
            budget_used: used,
            queries: p.queries.queries(),
            uncertainty: p.uncertainty,
            threshold,
            last_eval: p.last_eval,
            person_s: self.effort.person_s,
            keys: self.effort.keys,
            answered: self.effort.answered,
            takeovers: self.effort.takeovers,
            // Each question takes at least one unit of the budget.
            questions_left_max: left,
            // This person's pace so far: their seconds per unit of budget spent.
            time_left_s: (used > 0 && self.effort.person_s > 0.0)
                .then(|| self.effort.person_s / used as f64 * left as f64),
        };
        let now = Instant::now();
        let due = self
            .last_update
            .is_none_or(|t| now.duration_since(t).as_secs_f64() >= 1.0 / UPDATES_PER_S);
        // While a segment runs the steps are slow (the person's pace): show each one. Otherwise the latest
        // status waits for the next update, or for a question (which shows where the run stands).
        let shown = fed || !p.queries.expert_in_control();
        if !due && shown && !watching && p.step < p.train_steps {
            self.unsent = Some(status);
            return;
        }
        self.last_update = Some(now);
        if let Some(u) = p.uncertainty {
            self.server.shared.push_uncertainty((p.step, u, threshold));
        }
        self.unsent = None;
        self.publish_status(&status);
        // The frame shows the state the agent acts in next (a table source needs no observation here: it
        // shows the one of the last question), unless the page is a step ahead, showing the state after the
        // person's next key (carried to the next step).
        if self.carried.is_some() || fed {
            return;
        }
        if let Err(err) = self.publish_frame(p.env, &[]) {
            eprintln!("warning: the web expert cannot show the environment: {err:#}");
        }
    }

    fn handed_over(&mut self, end: &RunEnd, note: &str) {
        self.server.shared.offer_takeover(false);
        // The page's status shows where the run stands (the latest one may wait, throttled).
        self.publish_unsent_status();
        let stopped = (self.stop_requested)();
        let outcome = self.end_screen(end);
        let msg = ServerMsg::Handed {
            message: note.to_string(),
            outcome: &outcome,
            stopped,
        }
        .to_json();
        self.server
            .shared
            .publish(msg, |b, m| b.handed = Some(m.clone()));
        self.handed = true;
        // A question left open by a stop is closed on the page (it is asked again when the run goes on); after
        // the note, so that the page does not take it for a question that timed out.
        if self.prompt_open {
            self.publish_prompt(None);
        }
    }

    fn finish(&mut self, end: &RunEnd) {
        self.lift_hand_over();
        self.server.shared.offer_takeover(false);
        let outcome = self.end_screen(end);
        let msg = ServerMsg::End {
            message: "The run is over.".into(),
            outcome: Some(&outcome),
        }
        .to_json();
        self.server.shared.publish(msg, |b, m| {
            b.end = Some(m.clone());
            b.prompt = None;
        });
    }
}

/// Starts a web expert for the environment `env_id` ([`WebExpert::start`]), as the expert factory of
/// `arld_core::expert` takes it ([`arld_core::expert::WebStart`]).
pub fn start(options: &WebOptions, env_id: &str) -> Result<Box<dyn Expert>> {
    Ok(Box::new(WebExpert::start(options, env_id)?))
}

/// Starts a web expert for the box task `env_id` ([`WebExpert::start_box`]), as the box experts' factory takes
/// it ([`arld_core::expert::boxed::BoxWebStart`]).
pub fn start_box(options: &WebOptions, env_id: &str) -> Result<Box<dyn Expert<Vec<f32>>>> {
    Ok(Box::new(WebExpert::start_box(options, env_id)?))
}

/// Builds an expert from a spec, every kind including the web expert ([`arld_core::expert::from_spec`]).
pub fn from_spec(spec: &str, env_id: &str, seed: u64, timeout_s: f64) -> Result<Box<dyn Expert>> {
    build(&spec.parse()?, env_id, seed, timeout_s)
}

/// Builds the expert of a parsed spec, every kind including the web expert.
pub fn build(
    spec: &arld_core::expert::ExpertSpec,
    env_id: &str,
    seed: u64,
    timeout_s: f64,
) -> Result<Box<dyn Expert>> {
    arld_core::expert::build_with(spec, env_id, seed, timeout_s, start)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_replay_starts_where_the_person_left_this_episode_and_keeps_the_last_steps() {
        let (a, b) = (
            EpisodeStart::Seed(7),
            EpisodeStart::Generator([1, 2, 3, 4, 5, 6]),
        );
        // Each case: where the person left (episode, steps), the episode now (start, steps), the cap; and the
        // first step to replay, counted by hand.
        for (last, start, len, cap, from) in [
            (None, a, 30, 200, 0),
            (None, a, 300, 200, 100),
            (Some((a, 12)), a, 30, 200, 12),
            (Some((a, 12)), a, 12, 200, 12),
            (Some((a, 12)), a, 500, 200, 300),
            (Some((a, 12)), b, 30, 200, 0),
            (Some((b, 40)), b, 30, 200, 0),
        ] {
            assert_eq!(
                replay_from(last, start, len, cap),
                from,
                "{last:?} {start:?} {len}"
            );
        }
    }
}
