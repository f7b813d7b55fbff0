//! The training loop of one run, written to be read top to bottom (CleanRL style): [`train`] is the whole
//! algorithm of every method in the paper — DQN, DQfD, GDQN, BDQN, ADQN and ADQNP, with a plain, bootstrapped or
//! noisy network — and [`TrainConfig`] holds every hyperparameter.

pub mod config;
pub mod log;
pub mod run_dir;
pub mod seeds;
pub mod snapshot;

pub use config::{ConfigInput, Method, NetKind, TdLoss, TrainConfig};
pub use log::{LogPosition, RunLog};
pub use run_dir::{EvalPoint, QueryEvent, Summary, steps_to_solve};
pub use seeds::{SeedPurpose, seed_for};
pub use snapshot::Checkpointer;

use crate::agent::{Agent, test_policy_actions};
use crate::env::{self, Env};
use crate::expert::demos::Demonstrations;
use crate::expert::{Answer, EpisodeTrace, Expert, Progress, Query};
use crate::nn::{QNet, Workspace};
use crate::query::{DecisionInput, Needs, OracleView, QueryController};
use crate::replay::{Batch, Replay, ReplayConfig, Transition};
use crate::state::{Persist, StateDict};
use anyhow::{Context, Result, ensure};
use rand::SeedableRng;
use rand_pcg::Pcg64;
use std::path::Path;
use std::time::Instant;

use cpu_time::ThreadTime;

/// ε-greedy schedule: linear from `eps_start` to `eps_end` over `eps_fraction` of training (§5).
pub fn epsilon_at(cfg: &TrainConfig, step: usize) -> f64 {
    if !cfg.eps_greedy_on_top && cfg.net != NetKind::Plain {
        return 0.0;
    }
    let horizon = (cfg.eps_fraction * cfg.train_steps as f64).max(1.0);
    let frac = (step as f64 / horizon).min(1.0);
    cfg.eps_start + frac * (cfg.eps_end - cfg.eps_start)
}

/// The test episodes of every evaluation (no exploration), run in lockstep: one environment per episode,
/// all stepped together with one batched forward per step for the environments still running.
///
/// Environment `i` is seeded once with `seed + i` and then continues its own generator from one evaluation
/// to the next. The batched forward computes each row exactly as a single-state forward would
/// ([`crate::agent::test_policy_actions`]), so lockstep changes the cost, not the actions.
pub struct Evaluator {
    envs: Vec<Box<dyn Env>>,
    ws: Workspace,
    returns: Vec<f64>,
    /// Indices of the environments whose episode is still running, and their observations (row-major).
    running: Vec<usize>,
    obs: Vec<f32>,
    actions: Vec<usize>,
}

impl Evaluator {
    /// One test episode per environment of `envs`, environment `i` seeded `seed + i`, for networks shaped like
    /// `net`.
    pub fn new(mut envs: Vec<Box<dyn Env>>, seed: u64, net: &QNet) -> Result<Self> {
        ensure!(
            !envs.is_empty(),
            "evaluation needs at least one test environment"
        );
        for (i, env) in envs.iter_mut().enumerate() {
            env.reset(Some(seed + i as u64));
        }
        let episodes = envs.len();
        Ok(Self {
            envs,
            ws: Workspace::new(net, episodes),
            returns: Vec::with_capacity(episodes),
            running: Vec::with_capacity(episodes),
            obs: Vec::with_capacity(episodes * net.obs_dim()),
            actions: Vec::with_capacity(episodes),
        })
    }

    /// The state of every test environment's generator (for a run's snapshot).
    pub fn generators(&self) -> Vec<Option<[u64; 6]>> {
        self.envs
            .iter()
            .map(|env| env.generator().map(|g| g.to_words()))
            .collect()
    }

    /// Puts back the generators [`Self::generators`] returned.
    pub fn set_generators(&mut self, generators: &[Option<[u64; 6]>]) -> Result<()> {
        ensure!(
            generators.len() == self.envs.len(),
            "the snapshot has {} test environments, the run {}",
            generators.len(),
            self.envs.len()
        );
        for (env, words) in self.envs.iter_mut().zip(generators) {
            env.set_generator(words.map(crate::rng::NumpyRng::from_words));
        }
        Ok(())
    }

    /// One episode per environment under `net`'s test policy; the returns' summary at training step `step`.
    pub fn evaluate(&mut self, net: &QNet, step: usize) -> Result<EvalPoint> {
        self.returns.clear();
        self.running.clear();
        let d = net.obs_dim();
        self.obs.clear();
        self.obs.resize(self.envs.len() * d, 0.0);
        for (i, env) in self.envs.iter_mut().enumerate() {
            env.reset_into(None, &mut self.obs[i * d..(i + 1) * d]);
            self.running.push(i);
            self.returns.push(0.0);
        }
        while !self.running.is_empty() {
            self.actions.resize(self.running.len(), 0);
            test_policy_actions(net, &mut self.ws, &self.obs, &mut self.actions);
            // Step every running environment; compact the finished ones out, keeping the order (row `kept` is
            // at or before row `row`, so the running environment's new observation moves up in place).
            let mut kept = 0;
            for row in 0..self.running.len() {
                let i = self.running[row];
                let s = self.envs[i]
                    .step_into(self.actions[row], &mut self.obs[row * d..(row + 1) * d])?;
                self.returns[i] += s.reward;
                if !(s.terminated || s.truncated) {
                    self.running[kept] = i;
                    self.obs.copy_within(row * d..(row + 1) * d, kept * d);
                    kept += 1;
                }
            }
            self.running.truncate(kept);
            self.obs.truncate(kept * d);
        }
        let returns = &self.returns;
        let n = returns.len() as f64;
        let mean = returns.iter().sum::<f64>() / n;
        let std = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        let min = returns.iter().cloned().fold(f64::INFINITY, f64::min);
        let max = returns.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        Ok(EvalPoint {
            step: step as u64,
            mean,
            std,
            min,
            max,
        })
    }
}

/// Trains one agent as `cfg` says and returns its summary and the trained agent.
///
/// `expert` is asked during training by the querying methods; `demos` are the demonstrations that DQfD and ADQNP
/// pre-train on. The loop, in order: pre-training on demonstrations (DQfD, ADQNP); then for every environment
/// step: the agent proposes an action (and its uncertainty), the query rule decides whether the expert acts
/// instead (5-step segments, under the budget; a query nobody answers goes back to the agent at no cost), the
/// transition goes to replay (as a demonstration when the expert acted), one prioritized double-DQN update, the
/// target copy, and periodic evaluation. The expert observes every step (an interactive one shows the run).
pub fn train(
    cfg: &TrainConfig,
    expert: Option<&mut dyn Expert>,
    demos: Option<&Demonstrations>,
    log: &mut RunLog,
) -> Result<(Summary, Agent)> {
    let mut env = env::make(&cfg.env)?;
    let run = Hooks::default();
    train_run(cfg, env.as_mut(), test_envs(cfg)?, expert, demos, log, run)
}

/// The configuration's environment once per test episode, for the lockstep [`Evaluator`].
fn test_envs(cfg: &TrainConfig) -> Result<Vec<Box<dyn Env>>> {
    (0..cfg.eval_episodes)
        .map(|_| Ok(env::make(&cfg.env)?))
        .collect()
}

/// [`train`] in given environments: `env` for training, `test_envs` (one per test episode, `eval_episodes` of
/// them, stepped in lockstep) for evaluation. All must
/// be the configuration's environment; any [`Env`] implementation works, e.g. one stepping a Gymnasium
/// environment in Python.
pub fn train_in(
    cfg: &TrainConfig,
    env: &mut dyn Env,
    test_envs: Vec<Box<dyn Env>>,
    expert: Option<&mut dyn Expert>,
    demos: Option<&Demonstrations>,
    log: &mut RunLog,
) -> Result<(Summary, Agent)> {
    ensure!(
        env.id() == cfg.env && test_envs.iter().all(|e| e.id() == cfg.env),
        "the environments ({}, and the test environments {:?}) are not the configuration's {}",
        env.id(),
        test_envs.iter().map(|e| e.id()).collect::<Vec<_>>(),
        cfg.env
    );
    ensure!(
        test_envs.len() == cfg.eval_episodes,
        "{} test environments for {} test episodes (eval_episodes): give one per episode",
        test_envs.len(),
        cfg.eval_episodes
    );
    train_run(cfg, env, test_envs, expert, demos, log, Hooks::default())
}

/// [`train`] with snapshots: every `cfg.snapshot_every` steps (and pre-training updates), and when a stop is
/// requested ([`crate::interrupt`]: SIGTERM/SIGINT), the whole state of the run goes to `checkpointer`'s run
/// directory; then a stop request ends the run with an [`crate::interrupt::Interrupted`] error. When the
/// directory holds a snapshot, the run continues from it, to the same results as an uninterrupted run. `log`
/// must then come from [`RunLog::resume`] at the snapshot's log position ([`resume_position`]).
pub fn train_resumable(
    cfg: &TrainConfig,
    expert: Option<&mut dyn Expert>,
    demos: Option<&Demonstrations>,
    log: &mut RunLog,
    checkpointer: &mut Checkpointer,
    resume_from: Option<&StateDict>,
) -> Result<(Summary, Agent)> {
    let mut env = env::make(&cfg.env)?;
    train_run(
        cfg,
        env.as_mut(),
        test_envs(cfg)?,
        expert,
        demos,
        log,
        Hooks {
            checkpointer: Some(checkpointer),
            resume_from,
            driver: None,
        },
    )
}

/// [`train_in`] driven from outside ([`Driver`]): the run has no fixed end. After every environment step the
/// driver says whether to go on, pause (it then holds the whole live run, [`PausedRun`], until it says to go
/// on or stop) or stop; the run ends (its summary, weights and `summary.json`) only when the driver stops it.
/// `cfg.train_steps` is then the horizon of the schedules (ε, β) and of the last evaluation, not a limit:
/// past it ε stays at `eps_end` and β at 1. With `resume_from` the run continues from a snapshot. Pausing and
/// going on changes nothing in the run: it is the same loop, so two stretches equal one of their total length.
#[allow(clippy::too_many_arguments)]
pub fn train_driven(
    cfg: &TrainConfig,
    env: &mut dyn Env,
    test_envs: Vec<Box<dyn Env>>,
    expert: Option<&mut dyn Expert>,
    demos: Option<&Demonstrations>,
    log: &mut RunLog,
    driver: &mut dyn Driver,
    resume_from: Option<&StateDict>,
) -> Result<(Summary, Agent)> {
    ensure!(
        test_envs.len() == cfg.eval_episodes,
        "{} test environments for {} test episodes (eval_episodes): give one per episode",
        test_envs.len(),
        cfg.eval_episodes
    );
    let hooks = Hooks {
        checkpointer: None,
        resume_from,
        driver: Some(driver),
    };
    train_run(cfg, env, test_envs, expert, demos, log, hooks)
}

/// What a [`Driver`] says after a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Take the next step.
    Continue,
    /// Hand the live run to [`Driver::paused`].
    Pause,
    /// End the run here.
    Stop,
}

/// Where a run stands after a step, for a [`Driver`].
pub struct StepView<'a> {
    /// Environment steps done.
    pub step: usize,
    /// Episodes finished.
    pub episode: usize,
    /// Demonstrated transitions asked for so far (or queries, as `budget_unit` says).
    pub budget_used: usize,
    pub log: &'a RunLog,
    pub agent: &'a Agent,
}

/// Steers a run of [`train_driven`] from outside (e.g. a Python `learn` call that trains for a while, returns,
/// and is called again).
pub trait Driver {
    /// Called after every environment step.
    fn after_step(&mut self, at: &StepView<'_>) -> Result<Control>;
    /// Called when `after_step` paused the run; returns [`Control::Continue`] or [`Control::Stop`] (a pause
    /// again is a stop).
    fn paused(&mut self, run: &mut PausedRun<'_>) -> Result<Control>;
}

/// A paused run, whole: its summary so far, the agent, the log, and a snapshot of everything on request.
pub struct PausedRun<'a> {
    pub summary: Summary,
    pub agent: &'a Agent,
    pub log: &'a mut RunLog,
    cfg: &'a TrainConfig,
    st: &'a LoopState,
    parts: RunParts<'a>,
}

impl PausedRun<'_> {
    /// Writes a snapshot of the run (the format of [`Checkpointer`]) into `dir` and waits until it is there.
    pub fn snapshot(&mut self, dir: &Path) -> Result<()> {
        let mut ck = Checkpointer::new(dir, self.cfg);
        let parts = self.parts.clone();
        snapshot(&mut ck, self.st, parts, self.log, true)
    }
}

/// The optional parts of a run: snapshots, a snapshot to continue from, a driver.
#[derive(Default)]
struct Hooks<'a> {
    checkpointer: Option<&'a mut Checkpointer>,
    resume_from: Option<&'a StateDict<'a>>,
    driver: Option<&'a mut dyn Driver>,
}

/// The log position recorded in a snapshot.
pub fn resume_position(state: &StateDict) -> Result<log::LogPosition> {
    Ok(state.value("log")?)
}

/// Where the loop stands; with the agent, replay, query controller and generators, the whole run.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
struct LoopState {
    /// Pre-training updates done (all of them once training on the environment has begun).
    pretrain_done: usize,
    /// Whether the environment phase has begun.
    training: bool,
    /// Environment steps done.
    step: usize,
    episode: usize,
    ep_return: f64,
    ep_len: usize,
    ep_demo: usize,
    updates: usize,
    /// The actions of the episode in progress, and the environment's generator before the reset that began
    /// it (words of [`crate::rng::NumpyRng`]; `None` for the first episode, which resets with the run's seed).
    ep_actions: Vec<usize>,
    ep_generator: Option<[u64; 6]>,
    /// Wall-clock and CPU seconds the run spent before this point, over all its sessions (absent from
    /// snapshots of older versions, which then count from their resume).
    #[serde(default)]
    elapsed_s: f64,
    #[serde(default)]
    cpu_s: f64,
    /// The question that was open when the run stopped (the agent had decided to ask, the expert had not
    /// answered): a resumed run asks it again instead of deciding anew. Absent from other snapshots.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pending: Option<OpenQuestion>,
}

impl LoopState {
    /// How the episode in progress began (the first with the run's environment seed).
    fn episode_start(&self, env_seed: u64) -> crate::env::EpisodeStart {
        self.ep_generator.map_or(
            crate::env::EpisodeStart::Seed(env_seed),
            crate::env::EpisodeStart::Generator,
        )
    }

    /// The episode in progress, for an expert that rebuilds its state.
    fn episode(&self, env_seed: u64) -> EpisodeTrace<'_> {
        EpisodeTrace {
            start: self.episode_start(env_seed),
            actions: &self.ep_actions,
        }
    }
}

/// A query the agent decided on at the step in progress, before the expert's answer.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
struct OpenQuestion {
    agent_action: usize,
    score: Option<f32>,
    threshold: Option<f32>,
}

/// The time a run has taken: wall-clock seconds, and CPU seconds of the thread that trains it (which a paused
/// process or a busy machine does not inflate), over this session and the earlier ones its snapshot carried.
struct RunClock {
    wall: Instant,
    cpu: Option<ThreadTime>,
    carried: (f64, f64),
}

impl RunClock {
    fn start() -> Self {
        Self {
            wall: Instant::now(),
            cpu: ThreadTime::try_now().ok(),
            carried: (0.0, 0.0),
        }
    }

    /// Adds the time a resumed run had spent before its snapshot.
    fn carry(&mut self, st: &LoopState) {
        self.carried = (st.elapsed_s, st.cpu_s);
    }

    /// Wall-clock and CPU seconds so far (CPU `None` where the system cannot tell a thread's CPU time).
    fn totals(&self) -> (f64, Option<f64>) {
        let wall = self.carried.0 + self.wall.elapsed().as_secs_f64();
        let cpu = self
            .cpu
            .as_ref()
            .map(|t| self.carried.1 + t.elapsed().as_secs_f64());
        (wall, cpu)
    }

    /// Writes the totals into the loop state a snapshot saves.
    fn stamp(&self, st: &mut LoopState) {
        let (wall, cpu) = self.totals();
        (st.elapsed_s, st.cpu_s) = (wall, cpu.unwrap_or(0.0));
    }
}

/// Everything a snapshot gathers, borrowed from the loop.
#[derive(Clone)]
struct RunParts<'a> {
    agent: &'a Agent,
    replay: &'a Replay,
    queries: &'a QueryController,
    replay_rng: &'a Pcg64,
    query_rng: &'a Pcg64,
    evaluator: &'a Evaluator,
    expert_state: Option<String>,
    obs: &'a [f32],
}

/// Writes a snapshot of the run; when the run stops after it (`stopping`), waits until it is on disk.
fn snapshot(
    checkpointer: &mut Checkpointer,
    st: &LoopState,
    parts: RunParts<'_>,
    log: &mut RunLog,
    stopping: bool,
) -> Result<()> {
    let mut state = StateDict::default();
    parts.agent.save_state("agent", &mut state);
    parts.replay.save_state("replay", &mut state);
    parts.queries.save_state("query", &mut state);
    state.put_text("rng.replay", parts.replay_rng);
    state.put_text("rng.query", parts.query_rng);
    state.put_value("rng.eval_envs", &parts.evaluator.generators());
    state.put_value("expert", &parts.expert_state);
    state.put_value("loop", st);
    state.put_f32("obs", parts.obs);
    state.put_value("log", &log.position()?);
    let position = serde_json::json!({
        "phase": if st.training { "train" } else { "pretrain" },
        "pretrain_updates": st.pretrain_done,
        "step": st.step,
        "episode": st.episode,
        "episode_step": st.ep_len,
        "expert_in_control": parts.queries.expert_in_control(),
        "budget_used": parts.queries.budget_used(),
    });
    checkpointer.save(&state, position)?;
    if stopping {
        checkpointer.wait()?;
    }
    Ok(())
}

/// The run of [`train_loop`]; when it ends with an error (other than a stop request) and writes a run
/// directory, `failed.json` records the error and the step ([`run_dir::Failure`]).
fn train_run(
    cfg: &TrainConfig,
    env: &mut dyn Env,
    test_envs: Vec<Box<dyn Env>>,
    expert: Option<&mut dyn Expert>,
    demos: Option<&Demonstrations>,
    log: &mut RunLog,
    hooks: Hooks<'_>,
) -> Result<(Summary, Agent)> {
    let mut st = LoopState::default();
    // A driven run may go past `train_steps` (its schedules' horizon, not its end).
    let last_step = if hooks.driver.is_some() {
        usize::MAX
    } else {
        cfg.train_steps
    };
    let result = train_loop(cfg, env, test_envs, expert, demos, log, hooks, &mut st);
    if let (Err(err), Some(dir)) = (&result, log.dir()) {
        let (phase, step) = if st.training {
            // The step in progress (the one the logs and the error name), not past the last one.
            ("training", (st.step + 1).min(last_step))
        } else if st.pretrain_done > 0 {
            ("pre-training", 0)
        } else {
            ("setup", 0)
        };
        record_failure(dir, err, phase, step);
    }
    result
}

/// Writes `failed.json` for the error `err` into the run directory `dir`, unless `err` is a stop request (the
/// run is then interrupted, not failed). The run's own error matters more than this file: a write that fails
/// is only warned about.
pub fn record_failure(dir: &std::path::Path, err: &anyhow::Error, phase: &str, step: usize) {
    if crate::interrupt::is_stop(err) {
        return;
    }
    let failure = run_dir::Failure::new(err, phase, step);
    if let Err(write_err) = run_dir::write_failure(dir, &failure) {
        eprintln!("warning: the run failed, and recording why failed too: {write_err:#}");
    }
}

/// The training loop proper; `st` is where it stands, also when it returns an error.
#[allow(clippy::too_many_arguments)]
fn train_loop(
    cfg: &TrainConfig,
    env: &mut dyn Env,
    test_envs: Vec<Box<dyn Env>>,
    mut expert: Option<&mut dyn Expert>,
    demos: Option<&Demonstrations>,
    log: &mut RunLog,
    hooks: Hooks<'_>,
    st: &mut LoopState,
) -> Result<(Summary, Agent)> {
    let Hooks {
        mut checkpointer,
        resume_from,
        mut driver,
    } = hooks;
    let mut clock = RunClock::start();
    let (obs_dim, n_actions) = (env.obs_dim(), env.n_actions());
    ensure!(
        !cfg.method.queries() || expert.is_some(),
        "{} asks an expert during training, but none was given",
        cfg.method
    );

    // Every generator comes from the run's seed.
    let mut agent = Agent::new(
        &cfg.agent_config(),
        obs_dim,
        n_actions,
        seed_for(cfg.seed, SeedPurpose::Agent),
    );
    let mut replay_rng = Pcg64::seed_from_u64(seed_for(cfg.seed, SeedPurpose::Replay));
    let mut query_rng = Pcg64::seed_from_u64(seed_for(cfg.seed, SeedPurpose::Query));
    let env_seed = seed_for(cfg.seed, SeedPurpose::TrainEnv);
    let mut evaluator = Evaluator::new(
        test_envs,
        seed_for(cfg.seed, SeedPurpose::EvalEnv),
        agent.network(),
    )?;

    let pretrain_demos = demos.map(|d| d.transitions.len()).unwrap_or(0);
    let mut replay = Replay::new(
        obs_dim,
        &ReplayConfig {
            demo_capacity: pretrain_demos + cfg.query_transitions(),
            ..cfg.replay_config()
        },
    );
    let mut batch = Batch::default();
    let mut queries = cfg.query_controller()?;
    // The observation the agent acts on and the one the step writes (swapped after each step: no allocation).
    // `obs` stays empty until training starts (a snapshot taken in pre-training has none).
    let mut obs = Vec::new();
    let mut next_obs = Vec::new();

    // The parts of the run a snapshot (or a paused run) holds, borrowed from the loop's state.
    macro_rules! run_parts {
        () => {
            RunParts {
                agent: &agent,
                replay: &replay,
                queries: &queries,
                replay_rng: &replay_rng,
                query_rng: &query_rng,
                evaluator: &evaluator,
                expert_state: expert.as_deref().and_then(|e| e.state()),
                obs: &obs,
            }
        };
    }

    // A snapshot point of the loop: snapshots the run in `$ck` when `$at` is due or a stop was asked for, and on
    // a stop ends the run with `$stopped` (what was done) and where the snapshot is.
    macro_rules! snapshot_point {
        ($ck:expr, $at:expr, $stopped:expr) => {{
            let ck: &mut Checkpointer = $ck;
            let stop = crate::interrupt::requested();
            if stop || ck.due($at) {
                let parts = run_parts!();
                clock.stamp(st);
                snapshot(ck, st, parts, log, stop)?;
            }
            if stop {
                return Err(crate::interrupt::Interrupted(format!(
                    "{}; snapshot in {}",
                    $stopped,
                    ck.path().display()
                ))
                .into());
            }
        }};
    }

    // Continue from a snapshot: every part back where it was.
    if let Some(state) = resume_from {
        agent.load_state("agent", state)?;
        replay.load_state("replay", state)?;
        queries.load_state("query", state)?;
        replay_rng = state.text("rng.replay")?;
        query_rng = state.text("rng.query")?;
        let eval_generators: Vec<Option<[u64; 6]>> = state.value("rng.eval_envs")?;
        evaluator.set_generators(&eval_generators)?;
        let expert_state: Option<String> = state.value("expert")?;
        if let (Some(e), Some(saved)) = (expert.as_deref_mut(), expert_state) {
            e.restore(&saved)?;
        }
        *st = state.value("loop")?;
        clock.carry(st);
        if st.training {
            // The environment: the generator its episode's reset drew from, the reset, the actions taken.
            crate::env::replay_episode(
                &mut *env,
                st.episode_start(env_seed),
                &st.ep_actions,
                &mut obs,
            )?;
            ensure!(
                obs == state.f32s("obs")?,
                "replaying the episode in progress did not reach the snapshot's observation"
            );
        }
    }

    // Pre-training on demonstrations only (DQfD, ADQNP; §9).
    if cfg.method.pretrains() && !st.training {
        let demos =
            demos.context("this method pre-trains on demonstrations, but none were given")?;
        log.set_prefix(format!("{} pre-training", cfg.run_name()));
        if resume_from.is_none() {
            push_demos(cfg, &mut replay, demos)?;
        }
        while st.pretrain_done < cfg.pretrain_steps {
            pretrain_update(
                cfg,
                &mut agent,
                &mut replay,
                &mut replay_rng,
                &mut batch,
                st.pretrain_done + 1,
            )?;
            st.pretrain_done += 1;
            if let Some(ck) = checkpointer.as_deref_mut() {
                snapshot_point!(
                    ck,
                    st.pretrain_done,
                    format!("stopped after {} pre-training updates", st.pretrain_done)
                );
            }
        }
        agent.sync_target();
    }

    log.set_prefix(cfg.run_name());
    if !st.training {
        st.training = true;
        obs = env.reset(Some(env_seed));
        agent.begin_episode();
    }
    while driver.is_some() || st.step < cfg.train_steps {
        let step = st.step;
        let learning = step + 1 >= cfg.learning_starts;
        // 1. Who acts: the agent, or the expert when a query is running or the rule asks for one now (or a
        // resumed run asks again the question that was open when it stopped).
        let mut step_uncertainty = None;
        let mut open = st.pending.take();
        let mut agent_pick = None;
        if open.is_none() && !queries.expert_in_control() {
            if cfg.queries_from_learning_starts && !learning {
                // Ablation: no queries before the first update; the rule does not see these steps.
                agent_pick = Some(agent.act(&obs, epsilon_at(cfg, step), Needs::NOTHING).0);
            } else {
                let mut want = queries.signals_wanted_now();
                want.uncertainty |= expert.as_deref().is_some_and(|e| e.shows_uncertainty());
                let (agent_action, signals) = agent.act(&obs, epsilon_at(cfg, step), want);
                step_uncertainty = signals.uncertainty;
                let oracle = if want.oracle {
                    Some(peek_expert(&mut expert, &obs, queries.rule().name())?)
                } else {
                    None
                };
                let input = DecisionInput {
                    step,
                    train_steps: cfg.train_steps,
                    agent_action,
                    signals: &signals,
                    oracle: oracle.as_ref(),
                };
                let decision = queries.decide(&input, &mut query_rng);
                if decision.query {
                    open = Some(OpenQuestion {
                        agent_action,
                        score: decision.score,
                        threshold: decision.threshold,
                    });
                } else {
                    agent_pick = Some(agent_action);
                }
            }
        }
        // Hands the live run to the driver (its logs whole) until it says go on or stop.
        macro_rules! pause {
            ($driver:expr) => {{
                let mut summary = summarize(cfg, &*env, log, st, &queries, &clock, pretrain_demos);
                summary.person_s = expert.as_deref().and_then(|e| e.person_seconds());
                finish_log(cfg, &agent, log, &summary, st.step)?;
                clock.stamp(st);
                let mut paused = PausedRun {
                    summary,
                    agent: &agent,
                    log,
                    cfg,
                    st,
                    parts: run_parts!(),
                };
                $driver.paused(&mut paused)?
            }};
        }
        // A stop while the expert is asked (a person who has not answered yet): the snapshot holds the run as
        // it stands, with the open question, so that a resumed run asks it again. A driven run (Python) pauses
        // there instead: its driver raises the stop, and when it goes on the same question is asked again.
        macro_rules! stop_while_asking {
            ($err:expr) => {{
                let err: anyhow::Error = $err;
                if let Some(d) = driver.as_deref_mut() {
                    if pause!(d) == Control::Continue {
                        continue;
                    }
                    break;
                }
                if let Some(ck) = checkpointer.as_deref_mut() {
                    snapshot_point!(
                        ck,
                        st.step,
                        format!(
                            "stopped at step {} of {} while a question was open",
                            st.step, cfg.train_steps
                        )
                    );
                }
                return Err(err);
            }};
        }
        let action = if let Some(a) = agent_pick {
            a
        } else if let Some(question) = open {
            let agent_action = question.agent_action;
            let answer = match ask_expert(
                &mut expert,
                &obs,
                &*env,
                st.episode(env_seed),
                Some(agent_action),
                &queries,
            ) {
                Err(err) if crate::interrupt::is_stop(&err) => {
                    st.pending = Some(question);
                    stop_while_asking!(err)
                }
                other => other?,
            };
            let (expert_action, response_s) = match answer {
                Answer::Action { action, response_s } => (Some(action), response_s),
                Answer::Unanswered { waited_s } => {
                    queries.withdraw();
                    (None, Some(waited_s))
                }
            };
            log.query(&QueryEvent {
                step,
                episode: st.episode,
                uncertainty: question.score,
                threshold: question.threshold,
                expert_action,
                agent_action,
                expert: expert.as_deref().map(|e| e.kind()).unwrap_or_default(),
                response_s,
                answered: expert_action.is_some(),
            })?;
            expert_action.unwrap_or(agent_action)
        } else {
            match ask_expert(
                &mut expert,
                &obs,
                &*env,
                st.episode(env_seed),
                None,
                &queries,
            ) {
                Err(err) if crate::interrupt::is_stop(&err) => stop_while_asking!(err),
                Err(err) => return Err(err),
                Ok(Answer::Action { action, .. }) => action,
                // Nobody answered mid-segment: the agent takes the rest of it back, and the log says so.
                Ok(Answer::Unanswered { waited_s }) => {
                    queries.withdraw();
                    let agent_action = agent.act(&obs, epsilon_at(cfg, step), Needs::NOTHING).0;
                    log.query(&QueryEvent {
                        step,
                        episode: st.episode,
                        uncertainty: None,
                        threshold: None,
                        expert_action: None,
                        agent_action,
                        expert: expert.as_deref().map(|e| e.kind()).unwrap_or_default(),
                        response_s: Some(waited_s),
                        answered: false,
                    })?;
                    agent_action
                }
            }
        };
        let by_expert = queries.expert_in_control();
        if by_expert {
            queries.record_expert_step();
            st.ep_demo += 1;
        }

        // 2. Step the environment; expert transitions are stored as demonstrations (margin loss, bonus priority).
        next_obs.resize(obs.len(), 0.0);
        let s = env.step_into(action, &mut next_obs)?;
        st.ep_actions.push(action);
        let terminal = s.terminated || (s.truncated && cfg.timeout_as_terminal);
        replay.push(Transition {
            obs: &obs,
            action,
            reward: s.reward as f32,
            next_obs: &next_obs,
            terminal,
            is_demo: by_expert,
        })?;
        st.ep_return += s.reward;
        st.ep_len += 1;
        std::mem::swap(&mut obs, &mut next_obs);
        if s.terminated || s.truncated {
            log.episode(st.episode, step + 1, st.ep_return, st.ep_len, st.ep_demo)?;
            st.episode += 1;
            (st.ep_return, st.ep_len, st.ep_demo) = (0.0, 0, 0);
            replay.end_episode()?;
            st.ep_actions.clear();
            st.ep_generator = env.generator().map(|g| g.to_words());
            env.reset_into(None, &mut obs);
            agent.begin_episode();
            queries.end_episode();
        }

        // 3. Learn: one prioritized double-DQN update per `train_freq` steps, hard target copies.
        if learning && (step + 1).is_multiple_of(cfg.train_freq) && replay.len() >= cfg.batch_size {
            // A driven run may go past `train_steps`, the schedule's horizon: β then stays at 1.
            let progress = (step as f64 / cfg.train_steps as f64).min(1.0);
            let beta = cfg.beta0 + (1.0 - cfg.beta0) * progress;
            replay.sample(cfg.batch_size, beta as f32, &mut replay_rng, &mut batch);
            let stats = learn(cfg, &mut agent, &mut replay, &batch, || {
                format!("step {}", step + 1)
            })?;
            st.updates += 1;
            if st.updates.is_multiple_of(cfg.target_period) {
                agent.sync_target();
            }
            if st.updates.is_multiple_of(1000) {
                log.scalar("train/td_loss", step + 1, stats.td_loss)?;
                log.scalar("train/margin_loss", step + 1, stats.margin_loss)?;
                log.scalar("train/epsilon", step + 1, epsilon_at(cfg, step) as f32)?;
                log.scalar("query/budget_used", step + 1, queries.budget_used() as f32)?;
                if let Some(thr) = queries.rule().threshold() {
                    log.scalar("query/threshold", step + 1, thr)?;
                }
            }
        }

        // 4. Evaluate without exploration every `eval_period` steps.
        if (step + 1).is_multiple_of(cfg.eval_period) || step + 1 == cfg.train_steps {
            let point = evaluator.evaluate(agent.network(), step + 1)?;
            log.eval(point)?;
        }
        if let Some(expert) = expert.as_deref_mut() {
            expert.observe(&Progress {
                step: step + 1,
                train_steps: cfg.train_steps,
                episode: st.episode,
                env: &*env,
                uncertainty: step_uncertainty,
                queries: &queries,
                last_eval: log.curve().last().map(|p| (p.step, p.mean)),
            });
        }
        if (step + 1).is_multiple_of(500) {
            log.progress(step + 1);
        }
        if cfg.checkpoint_every > 0
            && (step + 1).is_multiple_of(cfg.checkpoint_every)
            && let Some(dir) = log.dir()
        {
            let path = run_dir::checkpoint_path(dir, step + 1);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent)?;
            }
            agent
                .network()
                .save(&path, &weights_metadata(cfg, step + 1))?;
        }
        st.step += 1;

        // 5. Snapshot the whole run when due or asked to stop (not after the last step: the results follow).
        if let Some(ck) = checkpointer.as_deref_mut()
            && st.step < cfg.train_steps
        {
            snapshot_point!(
                ck,
                st.step,
                format!("stopped at step {} of {}", st.step, cfg.train_steps)
            );
        }

        // 6. A driven run: its driver may pause it (and hold the live run meanwhile) or stop it.
        if let Some(d) = driver.as_deref_mut() {
            let view = StepView {
                step: st.step,
                episode: st.episode,
                budget_used: queries.budget_used(),
                log,
                agent: &agent,
            };
            let mut control = d.after_step(&view)?;
            if control == Control::Pause {
                control = pause!(d);
            }
            if control != Control::Continue {
                break;
            }
        }
    }

    let mut summary = summarize(cfg, &*env, log, st, &queries, &clock, pretrain_demos);
    if let Some(expert) = expert {
        summary.person_s = expert.person_seconds();
        expert.finish(&crate::expert::RunEnd {
            solved: summary.solved,
            steps_to_solve: summary.steps_to_solve,
            train_steps: cfg.train_steps,
            final_score: summary.final_score,
            dir: log.dir().map(|d| d.to_path_buf()),
        });
    }
    finish_log(cfg, &agent, log, &summary, st.step)?;
    if let Some(ck) = checkpointer {
        ck.remove()?;
    }
    Ok((summary, agent))
}

/// The run's summary after `st.step` environment steps.
fn summarize(
    cfg: &TrainConfig,
    env: &dyn Env,
    log: &RunLog,
    st: &LoopState,
    queries: &QueryController,
    clock: &RunClock,
    pretrain_demos: usize,
) -> Summary {
    let (wall, cpu) = clock.totals();
    let threshold = env.solve_threshold();
    let (steps, solved) = steps_to_solve(log.curve(), threshold, st.step as u64);
    Summary {
        env: cfg.env.clone(),
        method: cfg.method,
        net: cfg.net,
        seed: cfg.seed,
        steps_to_solve: steps as usize,
        solved,
        solve_threshold: threshold,
        train_steps: st.step,
        final_score: log.curve().last().map(|p| p.mean).unwrap_or(f64::NAN),
        demos_pretrain: pretrain_demos,
        queries_used: queries.budget_used(),
        episodes: st.episode,
        wall_time_s: wall,
        cpu_time_s: cpu,
        steps_per_s: st.step as f64 / wall.max(1e-9),
        numerics: Some(crate::math::NUMERICS.to_string()),
        arld_version: Some(crate::build_info::VERSION.to_string()),
        git_commit: Some(crate::build_info::GIT_COMMIT.to_string()),
        expert: cfg.expert_used().map(str::to_string),
        person_s: None,
    }
}

/// The run directory's results after `step` steps: the weights, then `summary.json`.
fn finish_log(
    cfg: &TrainConfig,
    agent: &Agent,
    log: &mut RunLog,
    summary: &Summary,
    step: usize,
) -> Result<()> {
    if let Some(dir) = log.dir() {
        agent.network().save(
            &dir.join(run_dir::WEIGHTS_FILE),
            &weights_metadata(cfg, step),
        )?;
    }
    log.finish(summary)
}

/// Metadata stored with saved weights: where they come from.
fn weights_metadata(cfg: &TrainConfig, step: usize) -> std::collections::BTreeMap<String, String> {
    [
        ("env", cfg.env.clone()),
        ("method", cfg.method.to_string()),
        ("seed", cfg.seed.to_string()),
        ("step", step.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// DQfD pre-training (§9): the demonstrations enter replay permanently, then `pretrain_steps` updates sample
/// from them alone (TD plus margin loss, prioritized among demonstrations), with the usual target copies.
pub fn pretrain(
    cfg: &TrainConfig,
    agent: &mut Agent,
    replay: &mut Replay,
    demos: &Demonstrations,
    rng: &mut Pcg64,
    batch: &mut Batch,
) -> Result<()> {
    push_demos(cfg, replay, demos)?;
    for update in 1..=cfg.pretrain_steps {
        pretrain_update(cfg, agent, replay, rng, batch, update)?;
    }
    agent.sync_target();
    Ok(())
}

/// The demonstrations enter replay permanently, episode by episode.
fn push_demos(cfg: &TrainConfig, replay: &mut Replay, demos: &Demonstrations) -> Result<()> {
    ensure!(
        demos.env == cfg.env,
        "the demonstrations are for {}, not {}",
        demos.env,
        cfg.env
    );
    for (i, t) in demos.transitions.iter().enumerate() {
        replay.push(t.transition())?;
        if demos
            .transitions
            .get(i + 1)
            .is_none_or(|next| next.episode != t.episode)
        {
            replay.end_episode()?;
        }
    }
    Ok(())
}

/// Pre-training update number `update` (from 1): demonstrations only, prioritized among them.
fn pretrain_update(
    cfg: &TrainConfig,
    agent: &mut Agent,
    replay: &mut Replay,
    rng: &mut Pcg64,
    batch: &mut Batch,
    update: usize,
) -> Result<()> {
    replay.sample_demo_only(cfg.batch_size, cfg.beta0 as f32, rng, batch);
    learn(cfg, agent, replay, batch, || {
        format!("pre-training update {update}")
    })?;
    if update.is_multiple_of(cfg.target_period) {
        agent.sync_target();
    }
    Ok(())
}

/// A run whose learning blew up: a loss or the gradient is no longer a finite number.
#[derive(Debug, thiserror::Error)]
#[error(
    "diverged at {at}: the {what} is {value}; the learning rate may be too high for this task: try a lower \
     `lr` (now {lr}, e.g. --set lr={lower})",
    lower = .lr / 10.0
)]
pub struct Diverged {
    pub at: String,
    pub what: &'static str,
    pub value: f32,
    pub lr: f64,
}

/// One prioritized update on `batch` and the new priorities of its transitions. A loss or gradient that is not
/// finite ends the run with [`Diverged`] (`at` says where), before any priority is taken from it; the weights
/// the update spoiled are never saved, since the run ends there.
fn learn(
    cfg: &TrainConfig,
    agent: &mut Agent,
    replay: &mut Replay,
    batch: &Batch,
    at: impl FnOnce() -> String,
) -> Result<crate::agent::UpdateStats> {
    let (stats, priorities) = agent.update(batch);
    let checked = [
        ("TD loss", stats.td_loss),
        ("margin loss", stats.margin_loss),
        ("n-step loss", stats.nstep_loss),
        ("gradient norm", stats.grad_norm),
    ];
    if let Some(&(what, value)) = checked.iter().find(|(_, v)| !v.is_finite()) {
        return Err(Diverged {
            at: at(),
            what,
            value,
            lr: cfg.lr,
        }
        .into());
    }
    replay.update_priorities(&batch.idx, priorities);
    Ok(stats)
}

/// The expert's action and Q-values for an oracle query rule (no question asked, no budget spent).
fn peek_expert(
    expert: &mut Option<&mut dyn Expert>,
    obs: &[f32],
    rule: &str,
) -> Result<OracleView> {
    let expert = expert
        .as_deref_mut()
        .context("the query rule reads the expert's Q-values, but no expert was given")?;
    let description = expert.describe();
    expert.peek(obs).with_context(|| {
        format!(
            "the {rule} query rule is an oracle reference: it reads the expert's Q-values, which only \
             checkpoint experts give, and {description} has none"
        )
    })
}

/// Asks the expert for the action at `obs` (one step of a segment; `agent_action` on the step that opens it) and
/// checks that the answer is an action of the environment.
fn ask_expert(
    expert: &mut Option<&mut dyn Expert>,
    obs: &[f32],
    env: &dyn Env,
    episode: EpisodeTrace<'_>,
    agent_action: Option<usize>,
    queries: &QueryController,
) -> Result<Answer> {
    let expert = expert
        .as_deref_mut()
        .context("the query rule asked for the expert, but none was given")?;
    let query = Query {
        obs,
        env,
        episode,
        agent_action,
        steps_left: queries.segment_left(),
    };
    let answer = expert
        .answer(&query)
        .with_context(|| format!("the expert ({}) failed to answer", expert.describe()))?;
    if let Answer::Action { action, .. } = answer {
        ensure!(
            action < env.n_actions(),
            "the expert ({}) answered action {action}, but {} has {} actions",
            expert.describe(),
            env.id(),
            env.n_actions()
        );
    }
    Ok(answer)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A resumed run's time is what its snapshot carried plus this session's; the CPU time of an idle thread
    /// does not grow with the wall clock.
    #[test]
    fn the_run_clock_carries_time_across_a_resume() {
        let mut clock = RunClock::start();
        let st = LoopState {
            elapsed_s: 100.0,
            cpu_s: 40.0,
            ..LoopState::default()
        };
        clock.carry(&st);
        std::thread::sleep(std::time::Duration::from_millis(50));
        let (wall, cpu) = clock.totals();
        assert!((100.05..101.0).contains(&wall), "wall {wall}");
        let cpu = cpu.expect("Linux tells a thread's CPU time");
        assert!((40.0..40.04).contains(&cpu), "cpu {cpu}");
        let mut saved = LoopState::default();
        clock.stamp(&mut saved);
        assert!(saved.elapsed_s >= wall && saved.cpu_s >= cpu);
        // A snapshot of an older version, without the fields, counts from zero.
        let old: LoopState = serde_json::from_str(
            r#"{"pretrain_done":0,"training":false,"step":0,"episode":0,"ep_return":0.0,"ep_len":0,
                "ep_demo":0,"updates":0,"ep_actions":[],"ep_generator":null}"#,
        )
        .unwrap();
        assert_eq!((old.elapsed_s, old.cpu_s), (0.0, 0.0));
    }
}
