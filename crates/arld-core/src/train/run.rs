//! One run of training, read top to bottom. [`RunBuilder`] gathers what a run is given (its environments, its
//! expert and demonstrations, snapshots, a snapshot to continue from, a driver) and is the one entry point for the
//! command line, sweeps, Slurm shards and Python. `Run::execute` is the whole algorithm of every method in the
//! paper (DQN, DQfD, GDQN, BDQN, ADQN and ADQNP, with a plain, bootstrapped or noisy network): `resume`,
//! `pretrain`, `begin_training`, then for each environment step `choose` (the agent acts, or the query rule asks
//! the expert, or a person takes over unasked), `step_env`, `learn`, `report`, `snapshot_point` and `drive`, then `finish`. Each step returns what
//! the loop does next (`Choice`, `Flow`); none hides a `return`, `break` or `continue`.

use super::eval::Evaluator;
use super::run_dir::StartedBy;
use super::session::record_failure;
use super::{
    Algo, Checkpointer, QueryEvent, RunLog, SeedPurpose, Summary, TrainConfig, epsilon_at,
    pretrain_update, push_demos, run_dir, seed_for, steps_to_solve, update_checked,
};
use crate::agent::actor_critic::ActorCriticConfig;
use crate::agent::algo::BoxLearnerConfig;
use crate::agent::box_agent::BoxAgent;
use crate::agent::risk::RiskConfig;
use crate::agent::sac::SacConfig;
use crate::agent::td3::Td3Config;
use crate::agent::{DqnAgent, Learner};
use crate::env::{self, Action, BoxSpec, Env, TaskSpec};
use crate::expert::demos::Demonstrations;
use crate::expert::{
    Answer, EpisodeTrace, Expert, Person, Progress, Propose, Query, RunEnd, RunHistory,
};
use crate::interrupt;
use crate::query::{DecisionInput, Needs, OracleView, QueryController};
use crate::replay::{Batch, Replay, ReplayConfig, Transition};
use crate::state::{Persist, StateDict};
use crate::task::ActionColumn;
use anyhow::{Context, Result, ensure};
use cpu_time::ThreadTime;
use rand::SeedableRng;
use rand_pcg::Pcg64;
use std::path::Path;
use std::time::Instant;

/// The name under which a snapshot holds the learner's state.
pub const AGENT_STATE: &str = "agent";

/// What a run is given, and the one way to start it: `RunBuilder::new(&cfg)`, the parts a run needs beyond its
/// configuration, then [`RunBuilder::train`].
///
/// - Environments: by default the configuration's environment, made once for training and once per test
///   episode (the lockstep evaluation); [`Self::env`] and [`Self::test_envs`] give others (any [`Env`], e.g. one
///   stepping a Gymnasium environment in Python).
/// - [`Self::expert`] is asked during training by the querying methods (and observes every step: an interactive
///   one shows the run); [`Self::demos`] are the demonstrations DQfD and ADQNP pre-train on.
/// - [`Self::snapshots`]: every `cfg.snapshot_every` steps (and pre-training updates), and when a stop is
///   requested ([`crate::interrupt`]: SIGTERM/SIGINT), the whole state of the run goes to the checkpointer's run
///   directory; then a stop request ends the run with an [`crate::interrupt::Interrupted`] error.
/// - [`Self::resume_from`]: the run continues from a snapshot, to the same results as an uninterrupted run. The
///   log must then come from [`RunLog::resume`] at the snapshot's log position ([`super::session::resume_position`]).
/// - [`Self::start_from`]: a new run whose learner begins as another run's ended (its weights, target and
///   optimiser; everything else, the counters, replay, schedules and budget, begins afresh): Stable-Baselines3's
///   second `learn`.
/// - [`Self::driver`]: the run is driven from outside and has no fixed end. After every environment step the
///   driver says whether to go on, pause (it then holds the whole live run, [`PausedRun`], until it says to go
///   on or stop) or stop; the run ends (its summary, weights and `summary.json`) only when the driver stops it.
///   `cfg.train_steps` is then the horizon of the schedules (ε, β) and of the last evaluation, not a limit: past
///   it ε stays at `eps_end` and β at 1. Pausing and going on changes nothing in the run: it is the same loop,
///   so two stretches equal one of their total length.
pub struct RunBuilder<'a, L: Learner = DqnAgent> {
    cfg: &'a TrainConfig,
    /// Builds the agent for the task `spec` (its observations and actions), from the run's seed.
    make_agent: AgentMaker<L>,
    make_env: EnvMaker<L::Action>,
    env: Option<Box<dyn Env<L::Action>>>,
    test_envs: Option<Vec<Box<dyn Env<L::Action>>>>,
    expert: Option<&'a mut dyn Expert<L::Action>>,
    demos: Option<&'a Demonstrations<L::Action>>,
    checkpointer: Option<&'a mut Checkpointer>,
    resume_from: Option<&'a StateDict<'a>>,
    start_from: Option<&'a StateDict<'a>>,
    driver: Option<&'a mut dyn Driver<L>>,
}

/// Builds a run's agent for a task from the run's configuration (and seed).
pub(crate) type AgentMaker<L> =
    fn(&TrainConfig, &'static <<L as Learner>::Action as Action>::Spec) -> L;

/// Makes the environment `id` for a run of actions of the kind `A`.
pub(crate) type EnvMaker<A> = fn(&str) -> Result<Box<dyn Env<A>>>;

impl<'a> RunBuilder<'a> {
    /// A run of `cfg` in the configuration's own environments, with no expert, demonstrations, snapshots or
    /// driver.
    pub fn new(cfg: &'a TrainConfig) -> Self {
        RunBuilder::with_agent(cfg, dqn_agent)
    }
}

impl<'a> RunBuilder<'a, BoxAgent> {
    /// A run of `cfg` in a task with actions in a box, learned by TD3 ([`BoxAgent`]), otherwise as
    /// [`RunBuilder::new`].
    pub fn for_box(cfg: &'a TrainConfig) -> Self {
        RunBuilder::for_learner(cfg, box_agent, box_env)
    }
}

/// A learner with a run of its own: the builder of a run of `cfg` learned by it in the configuration's own
/// environments ([`RunBuilder::new`] for the DQN family, [`RunBuilder::for_box`] for the box learners). The
/// laboratory and Python start their runs here, whatever the kind of action.
pub trait OwnRun: Learner + Sized {
    /// A run of `cfg` learned by this learner, with no expert, demonstrations, snapshots or driver.
    fn builder(cfg: &TrainConfig) -> RunBuilder<'_, Self>;
}

impl OwnRun for DqnAgent {
    fn builder(cfg: &TrainConfig) -> RunBuilder<'_, Self> {
        RunBuilder::new(cfg)
    }
}

impl OwnRun for BoxAgent {
    fn builder(cfg: &TrainConfig) -> RunBuilder<'_, Self> {
        RunBuilder::for_box(cfg)
    }
}

/// The configuration's actor-critic learner (`algo`: TD3 or SAC) for the task `spec`, with its networks (the
/// hidden widths, at least two critic heads: more heads are a larger ensemble), learning rate and batch, seeded
/// from the run's seed. A method that pre-trains (dqfd, adqnp) clones the demonstrated actions with the weight
/// `lambda` and the Q-filter (off while pre-training; docs/algorithm.md §17); the others do not clone. A run whose
/// query rule reads the risk gets a risk critic (docs/algorithm.md §20) of the critics' widths, learning rate,
/// batch and Polyak rate, discounting by the run's gamma, its weights from a stream of its own. The one place the
/// configuration's keys become the chosen learner's settings ([`BoxLearnerConfig`]).
pub fn box_agent(cfg: &TrainConfig, spec: &'static BoxSpec) -> BoxAgent {
    let (hidden, heads, lr) = (cfg.hidden.clone(), cfg.heads.max(2), cfg.lr as f32);
    let bc_weight = if cfg.method.pretrains() {
        cfg.lambda as f32
    } else {
        0.0
    };
    let settings = &cfg.box_settings;
    let common = ActorCriticConfig {
        hidden,
        heads,
        max_batch: cfg.batch_size,
        bc_weight,
        ..ActorCriticConfig::with_learning_rate(lr)
    };
    let common = ActorCriticConfig {
        tau: settings.tau.map_or(common.tau, |v| v as f32),
        ..common
    };
    let tau = common.tau;
    let config = match cfg.algo {
        Algo::Td3 => {
            let d = Td3Config::default();
            // A setting given (float64 in the configuration) or the learner's default.
            let or = |given: Option<f64>, default: f32| given.map_or(default, |v| v as f32);
            BoxLearnerConfig::Td3(Td3Config {
                common,
                policy_delay: settings.policy_delay.map_or(d.policy_delay, |p| p as u64),
                target_noise: or(settings.target_noise, d.target_noise),
                noise_clip: or(settings.noise_clip, d.noise_clip),
                exploration_noise: or(settings.exploration_noise, d.exploration_noise),
            })
        }
        Algo::Sac => {
            let mut sac = SacConfig {
                common,
                alpha_lr: settings.alpha_lr.map_or(lr, |v| v as f32),
                target_entropy: settings.target_entropy.map(|v| v as f32),
                ..SacConfig::default()
            };
            if let Some(alpha) = settings.initial_alpha {
                sac.initial_alpha = alpha as f32;
            }
            BoxLearnerConfig::Sac(sac)
        }
    };
    let seed = seed_for(cfg.seed, SeedPurpose::Agent);
    let agent = BoxAgent::new(
        config,
        spec.obs_dim,
        spec.action_low,
        spec.action_high,
        cfg.gamma as f32,
        seed,
    )
    .with_uncertainty(settings.uncertainty.unwrap_or_default());
    // The configuration was validated: its rule builds, and reads the risk only in a task with a goal.
    let reads_risk = cfg.query_rule().is_ok_and(|rule| rule.needs().risk);
    if !reads_risk {
        return agent;
    }
    let risk = RiskConfig {
        hidden: cfg.hidden.clone(),
        lr: cfg.lr as f32,
        gamma: cfg.gamma as f32,
        tau,
        max_batch: cfg.batch_size,
        goal: spec.goal,
    };
    agent.with_risk_critic(risk, seed_for(cfg.seed, SeedPurpose::RiskCritic))
}

/// The continuous-action task `id`, as a run makes it.
fn box_env(id: &str) -> Result<Box<dyn Env<Vec<f32>>>> {
    Ok(env::make_box(id)?)
}

/// The environment `id` of discrete actions, as a run makes it.
fn discrete_env(id: &str) -> Result<Box<dyn Env>> {
    Ok(env::make(id)?)
}

/// The DQN-family agent of `cfg` ([`TrainConfig::dqn_agent_config`]), seeded from the run's seed.
fn dqn_agent(cfg: &TrainConfig, spec: &'static crate::env::EnvSpec) -> DqnAgent {
    DqnAgent::new(
        &cfg.dqn_agent_config(),
        spec.obs_dim,
        spec.n_actions,
        seed_for(cfg.seed, SeedPurpose::Agent),
    )
}

impl<'a> RunBuilder<'a> {
    /// A run of `cfg` whose agent of discrete actions `make_agent` builds, otherwise as [`RunBuilder::new`].
    pub(crate) fn with_agent<L: Learner<Action = usize>>(
        cfg: &'a TrainConfig,
        make_agent: AgentMaker<L>,
    ) -> RunBuilder<'a, L> {
        RunBuilder::for_learner(cfg, make_agent, discrete_env)
    }
}

impl<'a, L: Learner> RunBuilder<'a, L> {
    /// A run of `cfg` whose agent `make_agent` builds (any [`Learner`], of any kind of action), in environments
    /// `make_env` makes by id unless [`Self::env`] and [`Self::test_envs`] give them.
    pub(crate) fn for_learner(
        cfg: &'a TrainConfig,
        make_agent: AgentMaker<L>,
        make_env: EnvMaker<L::Action>,
    ) -> Self {
        Self {
            cfg,
            make_agent,
            make_env,
            env: None,
            test_envs: None,
            expert: None,
            demos: None,
            checkpointer: None,
            resume_from: None,
            start_from: None,
            driver: None,
        }
    }

    /// The environment to train in (the configuration's environment by default).
    pub fn env(mut self, env: Box<dyn Env<L::Action>>) -> Self {
        self.env = Some(env);
        self
    }

    /// The environments of the test episodes, one per episode (`eval_episodes` of them).
    pub fn test_envs(mut self, envs: Vec<Box<dyn Env<L::Action>>>) -> Self {
        self.test_envs = Some(envs);
        self
    }

    /// The expert the run asks (and that observes it), if any.
    pub fn expert(mut self, expert: Option<&'a mut dyn Expert<L::Action>>) -> Self {
        self.expert = expert;
        self
    }

    /// The demonstrations the run pre-trains on, if any.
    pub fn demos(mut self, demos: Option<&'a Demonstrations<L::Action>>) -> Self {
        self.demos = demos;
        self
    }

    /// Snapshots of the whole run into `checkpointer`'s run directory.
    pub fn snapshots(mut self, checkpointer: &'a mut Checkpointer) -> Self {
        self.checkpointer = Some(checkpointer);
        self
    }

    /// The snapshot the run continues from, if any.
    pub fn resume_from(mut self, state: Option<&'a StateDict<'a>>) -> Self {
        self.resume_from = state;
        self
    }

    /// The learner's state to begin with (a snapshot's, read with [`super::snapshot::read_snapshot`]): its
    /// weights, target and optimiser, where a learner of this run's configuration could have left them; the run
    /// itself (steps, replay, schedules, budget, evaluations) starts afresh.
    pub fn start_from(mut self, state: Option<&'a StateDict<'a>>) -> Self {
        self.start_from = state;
        self
    }

    /// Drives the run from outside: it ends when `driver` stops it.
    pub fn driver(mut self, driver: &'a mut dyn Driver<L>) -> Self {
        self.driver = Some(driver);
        self
    }

    /// Trains, logging into `log`, and returns the run's summary and the trained agent. When the run ends with
    /// an error (other than a stop request) and writes a run directory, `failed.json` records the error, the
    /// phase and the step ([`run_dir::Failure`]).
    pub fn train(mut self, log: &'a mut RunLog<L::Action>) -> Result<(Summary, L)> {
        match self.prepare() {
            Ok((env, parts)) => Run::new(self, env, parts, log).execute(),
            Err(err) => {
                if let Some(dir) = log.dir() {
                    record_failure(dir, &err, "setup", 0);
                }
                Err(err)
            }
        }
    }

    /// The environment and the parts of the run a snapshot holds, each from the run's seed.
    fn prepare(&mut self) -> Result<Prepared<L>> {
        let cfg = self.cfg;
        // Every way in (the command line, sweeps, Slurm shards, Python) builds its run here, so this is where a
        // configuration that did not come through `ConfigInput::resolve` (a snapshot's, Python's) is checked.
        cfg.validate()?;
        ensure!(
            !cfg.method.queries() || self.expert.is_some(),
            "{} asks an expert during training, but none was given",
            cfg.method
        );
        let env = match self.env.take() {
            Some(env) => env,
            None => (self.make_env)(&cfg.env)?,
        };
        let test_envs = match self.test_envs.take() {
            Some(envs) => envs,
            None => (0..cfg.eval_episodes)
                .map(|_| (self.make_env)(&cfg.env))
                .collect::<Result<_>>()?,
        };
        ensure!(
            test_envs.len() == cfg.eval_episodes,
            "{} test environments for {} test episodes (eval_episodes): give one per episode",
            test_envs.len(),
            cfg.eval_episodes
        );
        let obs_dim = env.obs_dim();
        let mut agent = (self.make_agent)(cfg, env.spec());
        if let Some(state) = self.start_from {
            agent.load_state(AGENT_STATE, state).context(
                "the learner to start from does not fit this run's network (its widths, heads or kind)",
            )?;
        }
        let evaluator =
            Evaluator::new(test_envs, seed_for(cfg.seed, SeedPurpose::EvalEnv), obs_dim)?;
        let pretrain_demos = self.demos.map(|d| d.transitions.len()).unwrap_or(0);
        let replay = Replay::try_with_action_width(
            obs_dim,
            env.spec().action_width(),
            &ReplayConfig {
                demo_capacity: pretrain_demos + cfg.query_transitions(),
                ..cfg.replay_config()
            },
        )?;
        let parts = Parts {
            agent,
            replay,
            queries: cfg.query_controller()?,
            replay_rng: Pcg64::seed_from_u64(seed_for(cfg.seed, SeedPurpose::Replay)),
            query_rng: Pcg64::seed_from_u64(seed_for(cfg.seed, SeedPurpose::Query)),
            evaluator,
            obs: Vec::new(),
        };
        Ok((env, parts))
    }
}

/// The training environment and the parts of a run, as [`RunBuilder::prepare`] makes them.
type Prepared<L> = (Box<dyn Env<<L as Learner>::Action>>, Parts<L>);

/// The parts of a run that learn or draw: with the [`LoopState`] and the expert's state, what a snapshot holds.
struct Parts<L: Learner> {
    agent: L,
    replay: Replay<L::Action>,
    queries: QueryController,
    replay_rng: Pcg64,
    query_rng: Pcg64,
    evaluator: Evaluator<L::Action>,
    /// The observation the agent acts on; empty until training starts (a snapshot taken in pre-training has
    /// none).
    obs: Vec<f32>,
}

/// A run in progress: what it was given, its parts, and where its loop stands.
struct Run<'a, L: Learner> {
    cfg: &'a TrainConfig,
    env: Box<dyn Env<L::Action>>,
    expert: Option<&'a mut dyn Expert<L::Action>>,
    demos: Option<&'a Demonstrations<L::Action>>,
    log: &'a mut RunLog<L::Action>,
    checkpointer: Option<&'a mut Checkpointer>,
    resume_from: Option<&'a StateDict<'a>>,
    driver: Option<&'a mut dyn Driver<L>>,
    parts: Parts<L>,
    st: LoopState<L::Action>,
    clock: RunClock,
    batch: Batch<L::Action>,
    /// The observation a step writes (swapped with `parts.obs` after each step: no allocation).
    next_obs: Vec<f32>,
    /// The seed of the training environment's first reset.
    env_seed: u64,
    /// The last step a run can take: `train_steps`, or none for a driven run (whose `train_steps` is its
    /// schedules' horizon, not its end).
    last_step: usize,
    /// The environment step taken last, for the driver.
    last: LastStep<L::Action>,
}

/// The ε the agent acts with at `step`: the schedule's ([`epsilon_at`]), or 1 (a uniformly random action)
/// before learning starts when the run acts randomly there (`random_before_learning`).
fn acting_epsilon(cfg: &TrainConfig, step: usize) -> f64 {
    if cfg.random_before_learning && step + 1 < cfg.learning_starts {
        return 1.0;
    }
    epsilon_at(cfg, step)
}

/// Who acts at the step in progress, or what the loop does instead.
enum Choice<A> {
    /// Step the environment with `action`; `uncertainty` is the agent's, when it was computed.
    Act { action: A, uncertainty: Option<f32> },
    /// Take the same step again (a driver went on after a stop while the expert was asked).
    Again,
    /// End the run here.
    End,
}

/// How the environment took the step in progress.
enum Took {
    /// The step (and the reset after an episode's end) is done.
    Done,
    /// The environment raised, the run paused, and its driver went on: take the step (or the reset) again.
    Again,
    /// The environment raised and the run ends here.
    End,
}

/// What the loop does after a step.
#[derive(PartialEq, Eq)]
enum Flow {
    Go,
    End,
}

/// Who acts, as the query rule decided when no question was open.
enum Turn<A: Action> {
    Agent(A),
    Ask(OpenQuestion<A>),
}

impl<'a, L: Learner> Run<'a, L> {
    fn new(
        given: RunBuilder<'a, L>,
        env: Box<dyn Env<L::Action>>,
        parts: Parts<L>,
        log: &'a mut RunLog<L::Action>,
    ) -> Self {
        let cfg = given.cfg;
        Self {
            cfg,
            env,
            expert: given.expert,
            demos: given.demos,
            log,
            checkpointer: given.checkpointer,
            resume_from: given.resume_from,
            last_step: if given.driver.is_some() {
                usize::MAX
            } else {
                cfg.train_steps
            },
            driver: given.driver,
            parts,
            st: LoopState::default(),
            clock: RunClock::start(),
            batch: Batch::default(),
            next_obs: Vec::new(),
            env_seed: seed_for(cfg.seed, SeedPurpose::TrainEnv),
            last: LastStep::default(),
        }
    }

    /// The whole run; a failure is recorded in the run directory with the phase and step it happened at.
    fn execute(mut self) -> Result<(Summary, L)> {
        match self.steps() {
            Ok(summary) => Ok((summary, self.parts.agent)),
            Err(err) => {
                self.record_failure(&err);
                Err(err)
            }
        }
    }

    /// The run from where it stands to its summary.
    fn steps(&mut self) -> Result<Summary> {
        self.resume()?;
        self.pretrain()?;
        self.begin_training();
        if self.resume_from.is_some() {
            self.show_where_resumed();
        }
        while self.driver.is_some() || self.st.step < self.cfg.train_steps {
            let (took, uncertainty) = match self.st.env_pending.clone() {
                // The environment raised at this step: its step, or its reset, is taken again.
                Some(EnvRetry::Step {
                    action,
                    uncertainty,
                }) => (self.step_env(action, uncertainty)?, uncertainty),
                Some(EnvRetry::Reset { uncertainty }) => {
                    (self.reset_env(uncertainty)?, uncertainty)
                }
                None => match self.choose()? {
                    Choice::Act {
                        action,
                        uncertainty,
                    } => (self.step_env(action, uncertainty)?, uncertainty),
                    Choice::Again => continue,
                    Choice::End => break,
                },
            };
            match took {
                Took::Done => {}
                Took::Again => continue,
                Took::End => break,
            }
            self.learn()?;
            self.report(uncertainty)?;
            self.st.step += 1;
            // Not after the last step: the results follow.
            if self.st.step < self.cfg.train_steps {
                let (step, steps) = (self.st.step, self.cfg.train_steps);
                self.snapshot_point(step, || format!("stopped at step {step} of {steps}"))?;
            }
            if self.drive()? == Flow::End {
                break;
            }
        }
        self.finish()
    }

    /// Continues from a snapshot: every part back where it was.
    fn resume(&mut self) -> Result<()> {
        let Some(state) = self.resume_from else {
            return Ok(());
        };
        let parts = &mut self.parts;
        parts.agent.load_state(AGENT_STATE, state)?;
        parts.replay.load_state("replay", state)?;
        parts.queries.load_state("query", state)?;
        parts.replay_rng = state.text("rng.replay")?;
        parts.query_rng = state.text("rng.query")?;
        let eval_generators: Vec<Option<[u64; 6]>> = state.value("rng.eval_envs")?;
        parts.evaluator.set_generators(&eval_generators)?;
        let expert_state: Option<String> = state.value("expert")?;
        if let (Some(e), Some(saved)) = (self.expert.as_deref_mut(), expert_state) {
            e.restore(&saved)?;
        }
        self.st = state.value("loop")?;
        self.st
            .check(self.cfg, self.last_step, parts.replay.n_agent())
            .context("the snapshot's loop state `loop` is not one a run reaches")?;
        self.clock.carry(&self.st);
        if let (true, Some(EnvRetry::Reset { .. })) = (self.st.training, &self.st.env_pending) {
            // An episode had ended and the environment raised on its reset: the reset is taken again, from the
            // generator it was to draw from.
            let generator = self.st.ep_generator.map(crate::rng::NumpyRng::from_words);
            self.env.set_generator(generator);
            self.parts.obs.resize(self.env.obs_dim(), 0.0);
        } else if self.st.training {
            // The environment: the generator its episode's reset drew from, the reset, the actions taken.
            env::replay_episode(
                &mut *self.env,
                self.st.episode_start(self.env_seed),
                &self.st.ep_actions,
                &mut parts.obs,
            )?;
            ensure!(
                parts.obs == state.f32s("obs")?,
                "replaying the episode in progress did not reach the snapshot's observation"
            );
        }
        Ok(())
    }

    /// Pre-training on demonstrations only (DQfD, ADQNP; §9), with a snapshot point after every update.
    fn pretrain(&mut self) -> Result<()> {
        let cfg = self.cfg;
        if !cfg.method.pretrains() || self.st.training {
            return Ok(());
        }
        let demos = self
            .demos
            .context("this method pre-trains on demonstrations, but none were given")?;
        self.log
            .set_prefix(format!("{} pre-training", cfg.run_name()));
        if self.resume_from.is_none() {
            push_demos(cfg, &mut self.parts.replay, demos)?;
        }
        self.parts.agent.set_pretraining(true);
        while self.st.pretrain_done < cfg.pretrain_steps {
            let parts = &mut self.parts;
            pretrain_update(
                cfg,
                &mut parts.agent,
                &mut parts.replay,
                &mut parts.replay_rng,
                &mut self.batch,
                self.st.pretrain_done + 1,
            )?;
            self.st.pretrain_done += 1;
            let done = self.st.pretrain_done;
            self.snapshot_point(done, || {
                format!("stopped after {done} pre-training updates")
            })?;
        }
        self.parts.agent.set_pretraining(false);
        self.parts.agent.end_target_period();
        Ok(())
    }

    /// The first reset of the training environment (unless a resumed run is past it).
    fn begin_training(&mut self) {
        self.log.set_prefix(self.cfg.run_name());
        if !self.st.training {
            self.st.training = true;
            self.parts.obs = self.env.reset(Some(self.env_seed));
            self.parts.agent.begin_episode();
        }
    }

    /// Who acts at this step: the agent, or the expert when a query is running or the rule asks for one now (or
    /// a resumed run asks again the question that was open when it stopped).
    fn choose(&mut self) -> Result<Choice<L::Action>> {
        let mut uncertainty = None;
        let mut open = self.st.pending.take();
        if open.is_none() && !self.parts.queries.expert_in_control() {
            let (turn, signal) = self.decide()?;
            uncertainty = signal;
            match turn {
                Turn::Agent(action) => {
                    return Ok(Choice::Act {
                        action,
                        uncertainty,
                    });
                }
                Turn::Ask(question) => open = Some(question),
            }
        }
        let asked = match open {
            Some(question) => self.ask_open(question),
            None => self.ask_in_segment(),
        };
        match asked {
            Ok(action) => Ok(Choice::Act {
                action,
                uncertainty,
            }),
            Err(err) if interrupt::is_stop(&err) => self.stop_while_asking(err),
            Err(err) => Err(err),
        }
    }

    /// The agent's action and whether the query rule asks the expert instead (or the expert takes over unasked:
    /// [`Self::take_over`]); the agent's uncertainty when it was computed.
    fn decide(&mut self) -> Result<(Turn<L::Action>, Option<f32>)> {
        if let Some(turn) = self.take_over() {
            return Ok(turn);
        }
        let (cfg, step) = (self.cfg, self.st.step);
        let epsilon = acting_epsilon(cfg, step);
        if cfg.queries_from_learning_starts && step + 1 < cfg.learning_starts {
            // Ablation: no queries before the first update; the rule does not see these steps.
            let parts = &mut self.parts;
            let action = parts.agent.act(&parts.obs, epsilon, Needs::NOTHING).0;
            return Ok((Turn::Agent(action), None));
        }
        let mut want = self.parts.queries.signals_wanted_now();
        want.uncertainty |= self.person().is_some_and(|p| p.shows_uncertainty());
        let parts = &mut self.parts;
        let (agent_action, signals) = parts.agent.act(&parts.obs, epsilon, want);
        let oracle = if want.oracle {
            Some(peek_expert(
                &mut self.expert,
                &parts.obs,
                parts.queries.rule().name(),
            )?)
        } else {
            None
        };
        let input = DecisionInput {
            step,
            train_steps: cfg.train_steps,
            agent_action: L::Action::index(agent_action.borrow()),
            signals: &signals,
            oracle: oracle.as_ref(),
        };
        let decision = parts.queries.decide(&input, &mut parts.query_rng);
        let turn = if decision.query {
            Turn::Ask(OpenQuestion {
                agent_action,
                score: decision.score,
                threshold: decision.threshold,
                started_by: StartedBy::Rule,
            })
        } else {
            Turn::Agent(agent_action)
        };
        Ok((turn, signals.uncertainty))
    }

    /// A person takes over unasked ([`Person::wants_control`], polled only while budget is left): a segment
    /// opens, charged like a question's ([`QueryController::open_segment_by_person`]), and the expert is asked
    /// with the agent's proposal. The query rule does not decide at this step and its statistics (the adaptive
    /// window) do not see it. `None`: the agent (or the rule) decides as usual.
    fn take_over(&mut self) -> Option<(Turn<L::Action>, Option<f32>)> {
        let parts = &mut self.parts;
        if parts.queries.budget_left() == 0 {
            return None;
        }
        let person = self.expert.as_deref_mut()?.person()?;
        if !person.wants_control() {
            return None;
        }
        // The agent's uncertainty at the takeover is logged with it, where the rule or the page reads it.
        let want = Needs {
            uncertainty: parts.queries.needs().uncertainty || person.shows_uncertainty(),
            ..Needs::NOTHING
        };
        let epsilon = acting_epsilon(self.cfg, self.st.step);
        let (agent_action, signals) = parts.agent.act(&parts.obs, epsilon, want);
        parts.queries.open_segment_by_person();
        let question = OpenQuestion {
            agent_action,
            score: signals.uncertainty,
            threshold: None,
            started_by: StartedBy::Person,
        };
        Some((Turn::Ask(question), signals.uncertainty))
    }

    /// Asks the question that opens a segment; its answer (or the agent's action, when nobody answered) acts.
    /// On a stop while it is asked, the question stays open for the run to ask again.
    fn ask_open(&mut self, question: OpenQuestion<L::Action>) -> Result<L::Action> {
        let agent_action = question.agent_action.clone();
        let asked = ask_expert(
            &mut self.expert,
            &mut self.parts,
            &*self.env,
            self.st.episode(self.env_seed),
            Some(&agent_action),
            !question.started_by.is_rule(),
        );
        let answer = match asked {
            Ok(answer) => answer,
            Err(err) => {
                if interrupt::is_stop(&err) {
                    self.st.pending = Some(question);
                }
                return Err(err);
            }
        };
        // A person who retried their segment gave the steps of the attempts they dropped too: they are charged
        // to the budget (never stored), and the log says how many.
        let retried = self.person().map_or(0, |p| p.retried_steps());
        if retried > 0 {
            self.parts.queries.charge_retried(retried);
        }
        let (expert_action, response_s) = match answer {
            Answer::Action { action, response_s } => (Some(action), response_s),
            Answer::Unanswered { waited_s } => {
                self.parts.queries.withdraw();
                (None, Some(waited_s))
            }
        };
        let (action_taken, answered) = (expert_action.clone(), expert_action.is_some());
        self.log.query(&QueryEvent {
            step: self.st.step,
            episode: self.st.episode,
            uncertainty: question.score,
            threshold: question.threshold,
            expert_action,
            agent_action: agent_action.clone(),
            expert: self.expert_kind(),
            response_s,
            answered,
            started_by: question.started_by,
            retried,
        })?;
        Ok(action_taken.unwrap_or(agent_action))
    }

    /// The expert's action at a later step of its segment; when nobody answers, the agent takes the rest of the
    /// segment back, and the log says so (a person's takeover ends so: they hand back when done, and the query
    /// log, which holds the rule's questions, has nothing to say).
    fn ask_in_segment(&mut self) -> Result<L::Action> {
        let answer = ask_expert(
            &mut self.expert,
            &mut self.parts,
            &*self.env,
            self.st.episode(self.env_seed),
            None,
            self.log.last_started_by() == Some(StartedBy::Person),
        )?;
        let waited_s = match answer {
            Answer::Action { action, .. } => return Ok(action),
            Answer::Unanswered { waited_s } => waited_s,
        };
        let parts = &mut self.parts;
        parts.queries.withdraw();
        let epsilon = acting_epsilon(self.cfg, self.st.step);
        let agent_action = parts.agent.act(&parts.obs, epsilon, Needs::NOTHING).0;
        if self.log.last_started_by() == Some(StartedBy::Person) {
            return Ok(agent_action);
        }
        self.log.query(&QueryEvent {
            step: self.st.step,
            episode: self.st.episode,
            uncertainty: None,
            threshold: None,
            expert_action: None,
            agent_action: agent_action.clone(),
            expert: self.expert_kind(),
            response_s: Some(waited_s),
            answered: false,
            started_by: StartedBy::Rule,
            retried: 0,
        })?;
        Ok(agent_action)
    }

    /// A stop while the expert is asked (a person who has not answered yet): the snapshot holds the run as it
    /// stands, with the open question, so that a resumed run asks it again. A driven run (Python) pauses there
    /// instead: its driver raises the stop, and when it goes on the same question is asked again.
    fn stop_while_asking(&mut self, err: anyhow::Error) -> Result<Choice<L::Action>> {
        if self.driver.is_some() {
            return Ok(match self.pause()? {
                Control::Continue => Choice::Again,
                Control::Pause | Control::Stop => Choice::End,
            });
        }
        let (step, steps) = (self.st.step, self.cfg.train_steps);
        self.snapshot_point(step, || {
            format!("stopped at step {step} of {steps} while a question was open")
        })?;
        Err(err)
    }

    /// Steps the environment; an expert's transition is stored as a demonstration (margin loss, bonus
    /// priority). An episode's end logs it and resets the environment. When the environment raises (a Python
    /// environment in a driven run), nothing of the step happened: the run pauses, and takes it again when it goes
    /// on.
    fn step_env(&mut self, action: L::Action, uncertainty: Option<f32>) -> Result<Took> {
        self.next_obs.resize(self.parts.obs.len(), 0.0);
        let s = match self.env.step_into(action.borrow(), &mut self.next_obs) {
            Ok(s) => s,
            Err(err) => {
                return self.env_raised(
                    err,
                    EnvRetry::Step {
                        action,
                        uncertainty,
                    },
                );
            }
        };
        let (cfg, parts, st) = (self.cfg, &mut self.parts, &mut self.st);
        st.env_pending = None;
        let by_expert = parts.queries.expert_in_control();
        if by_expert {
            parts.queries.record_expert_step();
            st.ep_demo += 1;
        }
        let taken = Transition {
            obs: &parts.obs,
            action: action.borrow(),
            reward: s.reward as f32,
            next_obs: &self.next_obs,
            terminal: s.terminated || (s.truncated && cfg.timeout_as_terminal),
            is_demo: by_expert,
        };
        if by_expert {
            let ended = (s.terminated, s.truncated);
            self.log.answered((st.step, st.episode), &taken, ended)?;
        }
        parts.replay.push(taken)?;
        st.ep_return += s.reward;
        st.ep_len += 1;
        self.last = LastStep {
            action: Some(action.clone()),
            reward: s.reward,
            terminated: s.terminated,
            truncated: s.truncated,
            ended: (s.terminated || s.truncated).then_some((st.ep_return, st.ep_len)),
        };
        st.ep_actions.push(action);
        std::mem::swap(&mut parts.obs, &mut self.next_obs);
        if s.terminated || s.truncated {
            let step = st.step;
            self.log
                .episode(st.episode, step + 1, st.ep_return, st.ep_len, st.ep_demo)?;
            st.episode += 1;
            (st.ep_return, st.ep_len, st.ep_demo) = (0.0, 0, 0);
            parts.replay.end_episode()?;
            st.ep_actions.clear();
            st.ep_generator = self.env.generator().map(|g| g.to_words());
            return self.reset_env(uncertainty);
        }
        Ok(Took::Done)
    }

    /// The reset after an episode's end (the step that ended it is done); when the environment raises, the run
    /// pauses, and resets again when it goes on.
    fn reset_env(&mut self, uncertainty: Option<f32>) -> Result<Took> {
        self.env.reset_into(None, &mut self.parts.obs);
        if let Some(err) = self.env.take_reset_error() {
            return self.env_raised(err, EnvRetry::Reset { uncertainty });
        }
        self.st.env_pending = None;
        self.parts.agent.begin_episode();
        self.parts.queries.end_episode();
        Ok(Took::Done)
    }

    /// The environment failed to take `retry`: an error, unless its own code raised in a driven run, which then
    /// pauses whole (its driver raises the exception) with `retry` to take again when it goes on.
    fn env_raised(&mut self, err: env::EnvError, retry: EnvRetry<L::Action>) -> Result<Took> {
        if !matches!(err, env::EnvError::Raised { .. }) || self.driver.is_none() {
            return Err(err.into());
        }
        self.st.env_pending = Some(retry);
        Ok(match self.pause()? {
            Control::Continue => Took::Again,
            Control::Pause | Control::Stop => Took::End,
        })
    }

    /// One prioritized double-DQN update per `train_freq` steps once learning has started, hard target copies,
    /// and the training scalars every 1000 updates.
    fn learn(&mut self) -> Result<()> {
        let (cfg, step, parts) = (self.cfg, self.st.step, &mut self.parts);
        if cfg.target_period_in_steps && (step + 1).is_multiple_of(cfg.target_period) {
            // Counted in environment steps (as Stable-Baselines3): after the step, before its update.
            parts.agent.end_target_period();
        }
        let due = step + 1 >= cfg.learning_starts && (step + 1).is_multiple_of(cfg.train_freq);
        if !due || parts.replay.len() < cfg.batch_size {
            return Ok(());
        }
        // A driven run may go past `train_steps`, the schedule's horizon: β then stays at 1.
        let progress = (step as f64 / cfg.train_steps as f64).min(1.0);
        let beta = cfg.beta0 + (1.0 - cfg.beta0) * progress;
        let (replay_rng, batch) = (&mut parts.replay_rng, &mut self.batch);
        parts
            .replay
            .sample(cfg.batch_size, beta as f32, replay_rng, batch);
        let stats = update_checked(cfg, &mut parts.agent, &mut parts.replay, batch, || {
            format!("step {}", step + 1)
        })?;
        self.st.updates += 1;
        if !cfg.target_period_in_steps && self.st.updates.is_multiple_of(cfg.target_period) {
            parts.agent.end_target_period();
        }
        if self.st.updates.is_multiple_of(1000) {
            let log = &mut *self.log;
            log.scalar("train/td_loss", step + 1, stats.td_loss)?;
            log.scalar("train/margin_loss", step + 1, stats.margin_loss)?;
            log.scalar("train/epsilon", step + 1, epsilon_at(cfg, step) as f32)?;
            log.scalar(
                // The tag keeps its name in the event files: it counts demonstrated transitions.
                "query/budget_used",
                step + 1,
                parts.queries.transitions_used() as f32,
            )?;
            if let Some(thr) = parts.queries.rule().threshold() {
                log.scalar("query/threshold", step + 1, thr)?;
            }
        }
        Ok(())
    }

    /// A resumed run shows its expert where it stands before anything else (a person's page fills its status
    /// before the question that was open is asked again).
    /// Its history first: the evaluations so far and, for an expert that shows the uncertainty (a person's
    /// page), the uncertainties logged with the questions (the only ones a run keeps with their steps). The
    /// charts are no reason to refuse a resume: a query log that cannot be read leaves a warning and no points.
    fn show_where_resumed(&mut self) {
        if let Some(person) = self.expert.as_deref_mut().and_then(|e| e.person()) {
            let logged = match self.log.dir() {
                Some(dir) if person.shows_uncertainty() => {
                    super::run_dir::read_query_uncertainties(dir)
                }
                _ => Ok(Vec::new()),
            };
            let uncertainty = logged.unwrap_or_else(|err| {
                eprintln!("warning: the uncertainty chart starts empty: {err:#}");
                Vec::new()
            });
            let curve = self.log.curve().iter().map(|p| (p.step, p.mean)).collect();
            person.resumed_history(&RunHistory { curve, uncertainty });
            person.observe(&Progress {
                step: self.st.step,
                train_steps: self.cfg.train_steps,
                episode: self.st.episode,
                env: &*self.env,
                uncertainty: None,
                queries: &self.parts.queries,
                last_eval: self.log.curve().last().map(|p| (p.step, p.mean)),
            });
        }
    }

    /// After a step: the evaluation without exploration every `eval_period` steps, the expert's view of the run,
    /// progress, and the weights every `checkpoint_every` steps.
    fn report(&mut self, uncertainty: Option<f32>) -> Result<()> {
        let (cfg, done, parts) = (self.cfg, self.st.step + 1, &mut self.parts);
        if done.is_multiple_of(cfg.eval_period) || done == cfg.train_steps {
            let point = parts.evaluator.evaluate(&mut parts.agent, done)?;
            self.log.eval(point)?;
        }
        if let Some(person) = self.expert.as_deref_mut().and_then(|e| e.person()) {
            person.observe(&Progress {
                step: done,
                train_steps: cfg.train_steps,
                episode: self.st.episode,
                env: &*self.env,
                uncertainty,
                queries: &parts.queries,
                last_eval: self.log.curve().last().map(|p| (p.step, p.mean)),
            });
        }
        if done.is_multiple_of(500) {
            self.log.progress(done);
        }
        if cfg.checkpoint_every > 0
            && done.is_multiple_of(cfg.checkpoint_every)
            && let Some(dir) = self.log.dir()
        {
            let path = run_dir::checkpoint_path(dir, done);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent)?;
            }
            let metadata = weights_metadata(cfg, done);
            parts.agent.save_weights(&path, &metadata)?;
        }
        Ok(())
    }

    /// A snapshot point: snapshots the run when `at` is due or a stop was asked for, and on a stop ends the run
    /// with what was done (`stopped`) and where the snapshot is. Nothing in a run without snapshots.
    fn snapshot_point(&mut self, at: usize, stopped: impl FnOnce() -> String) -> Result<()> {
        let Some(ck) = self.checkpointer.as_deref_mut() else {
            return Ok(());
        };
        let stop = interrupt::requested();
        if stop || ck.due(at) {
            self.clock.stamp(&mut self.st);
            let expert_state = self.expert.as_deref().and_then(|e| e.state());
            snapshot(ck, &self.st, &self.parts, expert_state, self.log, stop)?;
        }
        if stop {
            let message = format!("{}; snapshot in {}", stopped(), ck.path().display());
            return Err(interrupt::Interrupted(message).into());
        }
        Ok(())
    }

    /// A driven run: its driver may pause it (and hold the live run meanwhile) or stop it.
    fn drive(&mut self) -> Result<Flow> {
        let Some(driver) = self.driver.as_deref_mut() else {
            return Ok(Flow::Go);
        };
        let view = StepView {
            step: self.st.step,
            episode: self.st.episode,
            transitions_used: self.parts.queries.transitions_used(),
            log: self.log,
            agent: &self.parts.agent,
            last: &self.last,
            obs: &self.parts.obs,
        };
        let mut control = driver.after_step(&view)?;
        if control == Control::Pause {
            control = self.pause()?;
        }
        Ok(if control == Control::Continue {
            Flow::Go
        } else {
            Flow::End
        })
    }

    /// Hands the live run to the driver (its logs whole) until it says go on or stop. A run without a driver
    /// has nobody to hand it to: it stops.
    fn pause(&mut self) -> Result<Control> {
        let mut summary = self.summary();
        summary.person_s = self.person().and_then(|p| p.person_seconds());
        self.write_summary(&summary)?;
        self.clock.stamp(&mut self.st);
        let expert_state = self.expert.as_deref().and_then(|e| e.state());
        let Some(driver) = self.driver.as_deref_mut() else {
            return Ok(Control::Stop);
        };
        let mut paused = PausedRun {
            summary,
            agent: &self.parts.agent,
            log: self.log,
            cfg: self.cfg,
            st: &self.st,
            parts: &self.parts,
            expert_state,
            expert: self
                .expert
                .as_mut()
                .map(|e| &mut **e as &mut dyn Expert<L::Action>),
        };
        driver.paused(&mut paused)
    }

    /// The logs closed with `summary` at the current step (see [`finish_log`]).
    fn write_summary(&mut self, summary: &Summary) -> Result<()> {
        finish_log(self.cfg, &self.parts.agent, self.log, summary, self.st.step)
    }

    /// The end of the run: its summary, the expert told how it went, the weights and `summary.json`, and the
    /// snapshot removed.
    fn finish(&mut self) -> Result<Summary> {
        let mut summary = self.summary();
        let dir = self.log.dir().map(|d| d.to_path_buf());
        if let Some(person) = self.person() {
            summary.person_s = person.person_seconds();
            person.finish(&RunEnd {
                solved: summary.solved,
                steps_to_solve: summary.steps_to_solve,
                // The steps trained: fewer than configured when a Python program closes its run early.
                train_steps: summary.train_steps,
                final_score: summary.final_score,
                dir,
            });
        }
        self.write_summary(&summary)?;
        if let Some(ck) = self.checkpointer.as_deref_mut() {
            ck.remove()?;
        }
        Ok(summary)
    }

    /// The run's summary so far.
    fn summary(&self) -> Summary {
        summarize(
            self.cfg,
            &*self.env,
            self.log,
            &self.st,
            &self.parts.queries,
            &self.clock,
            self.demos.map(|d| d.transitions.len()).unwrap_or(0),
        )
    }

    /// The person's hooks of the run's expert, when it is a person.
    fn person(&mut self) -> Option<&mut dyn Person<L::Action>> {
        self.expert.as_deref_mut()?.person()
    }

    /// The kind of the run's expert, for the query log.
    fn expert_kind(&self) -> String {
        self.expert.as_deref().map(|e| e.kind()).unwrap_or_default()
    }

    /// Records a failure in the run directory, with the phase and the step in progress (the one the logs and
    /// the error name, not past the last one).
    fn record_failure(&self, err: &anyhow::Error) {
        let Some(dir) = self.log.dir() else {
            return;
        };
        let (phase, step) = if self.st.training {
            ("training", (self.st.step + 1).min(self.last_step))
        } else if self.st.pretrain_done > 0 {
            ("pre-training", 0)
        } else {
            ("setup", 0)
        };
        record_failure(dir, err, phase, step);
    }
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
pub struct StepView<'a, L: Learner = DqnAgent> {
    /// Environment steps done.
    pub step: usize,
    /// Episodes finished.
    pub episode: usize,
    /// Demonstrated transitions the expert gave so far (whatever the budget's unit; the budget spent in its unit
    /// is [`QueryController::budget_spent`](crate::query::QueryController::budget_spent)).
    pub transitions_used: usize,
    pub log: &'a RunLog<L::Action>,
    pub agent: &'a L,
    /// The environment step just taken (what Stable-Baselines3's callbacks see of it).
    pub last: &'a LastStep<L::Action>,
    /// The observation the agent acts on next: the step's next observation, or the reset's after an episode's
    /// end.
    pub obs: &'a [f32],
}

/// The environment step a run took last, as its driver sees it.
#[derive(Clone, Debug)]
pub struct LastStep<A> {
    /// The action taken (the agent's or the expert's); `None` before the first step.
    pub action: Option<A>,
    pub reward: f64,
    pub terminated: bool,
    pub truncated: bool,
    /// The return and length of the episode this step ended, when it ended one.
    pub ended: Option<(f64, usize)>,
}

impl<A> Default for LastStep<A> {
    fn default() -> Self {
        Self {
            action: None,
            reward: 0.0,
            terminated: false,
            truncated: false,
            ended: None,
        }
    }
}

/// Steers a run from outside ([`RunBuilder::driver`]) (e.g. a Python `learn` call that trains for a while, returns,
/// and is called again).
pub trait Driver<L: Learner = DqnAgent> {
    /// Called after every environment step.
    fn after_step(&mut self, at: &StepView<'_, L>) -> Result<Control>;
    /// Called when `after_step` paused the run; returns [`Control::Continue`] or [`Control::Stop`] (a pause
    /// again is a stop).
    fn paused(&mut self, run: &mut PausedRun<'_, L>) -> Result<Control>;
}

/// A paused run, whole: its summary so far, the agent, the log, and a snapshot of everything on request.
pub struct PausedRun<'a, L: Learner = DqnAgent> {
    pub summary: Summary,
    pub agent: &'a L,
    pub log: &'a mut RunLog<L::Action>,
    cfg: &'a TrainConfig,
    st: &'a LoopState<L::Action>,
    parts: &'a Parts<L>,
    expert_state: Option<String>,
    expert: Option<&'a mut dyn Expert<L::Action>>,
}

impl<L: Learner> PausedRun<'_, L> {
    /// Writes a snapshot of the run (the format of [`Checkpointer`]) into `dir` and waits until it is there.
    pub fn snapshot(&mut self, dir: &Path) -> Result<()> {
        let mut ck = Checkpointer::new(dir, self.cfg);
        let expert_state = self.expert_state.clone();
        snapshot(&mut ck, self.st, self.parts, expert_state, self.log, true)
    }

    /// Tells the run's expert that the run is handed to its program, and why (`note`): a person's page shows
    /// where the run stands until it goes on ([`Person::handed_over`]).
    pub fn hand_over(&mut self, note: &str) {
        let end = RunEnd {
            solved: self.summary.solved,
            steps_to_solve: self.summary.steps_to_solve,
            train_steps: self.summary.train_steps,
            final_score: self.summary.final_score,
            dir: self.log.dir().map(|d| d.to_path_buf()),
        };
        if let Some(person) = self.expert.as_deref_mut().and_then(|e| e.person()) {
            person.handed_over(&end, note);
        }
    }
}

/// Where the loop stands; with the agent, replay, query controller and generators, the whole run.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
struct LoopState<A: Action> {
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
    ep_actions: Vec<A>,
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
    pending: Option<OpenQuestion<A>>,
    /// What the environment raised on (a Python environment), for the run to take again when it goes on.
    /// Absent from other snapshots.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    env_pending: Option<EnvRetry<A>>,
}

impl<A: Action> Default for LoopState<A> {
    fn default() -> Self {
        Self {
            pretrain_done: 0,
            training: false,
            step: 0,
            episode: 0,
            ep_return: 0.0,
            ep_len: 0,
            ep_demo: 0,
            updates: 0,
            ep_actions: Vec::new(),
            ep_generator: None,
            elapsed_s: 0.0,
            cpu_s: 0.0,
            pending: None,
            env_pending: None,
        }
    }
}

impl<A: Action> LoopState<A> {
    /// Checks that the values hold together, with each other, with the configuration `cfg` (a run ends at
    /// `last_step`) and with the replay memory (`n_agent` transitions of the agent stored), as every state the
    /// loop reaches does: a snapshot edited with its checksum made again must not make a run count steps it never
    /// took.
    fn check(&self, cfg: &TrainConfig, last_step: usize, n_agent: usize) -> Result<()> {
        let pretrain_steps = if cfg.method.pretrains() {
            cfg.pretrain_steps
        } else {
            0
        };
        ensure!(
            self.step <= last_step,
            "it is at step {}, past the run's last step {last_step}",
            self.step
        );
        ensure!(
            self.pretrain_done <= pretrain_steps
                && (!self.training || self.pretrain_done == pretrain_steps),
            "{} pre-training updates done, of the {pretrain_steps} the run makes{}",
            self.pretrain_done,
            if self.training {
                " before training"
            } else {
                ""
            }
        );
        ensure!(
            self.training || (self.step, self.episode, self.ep_len, self.updates) == (0, 0, 0, 0),
            "it has not begun training, yet counts steps, episodes or updates"
        );
        ensure!(
            self.episode <= self.step && self.ep_len <= self.step && self.updates <= self.step,
            "{} episodes, {} steps in the episode in progress and {} updates do not fit in {} steps",
            self.episode,
            self.ep_len,
            self.updates,
            self.step
        );
        ensure!(
            self.ep_actions.len() == self.ep_len && self.ep_demo <= self.ep_len,
            "the episode in progress has {} steps, {} actions and {} steps by the expert",
            self.ep_len,
            self.ep_actions.len(),
            self.ep_demo
        );
        ensure!(
            n_agent <= self.step,
            "the replay memory holds {n_agent} of the agent's transitions, more than the {} steps taken",
            self.step
        );
        ensure!(
            self.ep_return.is_finite()
                && [self.elapsed_s, self.cpu_s]
                    .iter()
                    .all(|t| t.is_finite() && *t >= 0.0),
            "a return or time that is not a finite number (return {}, {} s, {} s of CPU)",
            self.ep_return,
            self.elapsed_s,
            self.cpu_s
        );
        Ok(())
    }

    /// How the episode in progress began (the first with the run's environment seed).
    fn episode_start(&self, env_seed: u64) -> env::EpisodeStart {
        self.ep_generator.map_or(
            env::EpisodeStart::Seed(env_seed),
            env::EpisodeStart::Generator,
        )
    }

    /// The episode in progress, for an expert that rebuilds its state.
    fn episode(&self, env_seed: u64) -> EpisodeTrace<'_, A> {
        EpisodeTrace {
            start: self.episode_start(env_seed),
            actions: &self.ep_actions,
        }
    }
}

/// What the environment raised on at the step in progress: the step with the action chosen (nothing of it
/// happened), or the reset after the episode it ended (the step itself is done). `uncertainty` is the agent's at
/// that step, for the step's report.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
enum EnvRetry<A: Action> {
    Step { action: A, uncertainty: Option<f32> },
    Reset { uncertainty: Option<f32> },
}

/// A query the agent decided on at the step in progress (or a person's takeover), before the expert's answer.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
struct OpenQuestion<A: Action> {
    agent_action: A,
    score: Option<f32>,
    threshold: Option<f32>,
    /// Who opened the segment (a resumed run asks a takeover open at the stop again as a takeover); absent
    /// from snapshots of the rule's questions, as before takeovers.
    #[serde(default, skip_serializing_if = "StartedBy::is_rule")]
    started_by: StartedBy,
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
    fn carry<A: Action>(&mut self, st: &LoopState<A>) {
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
    fn stamp<A: Action>(&self, st: &mut LoopState<A>) {
        let (wall, cpu) = self.totals();
        (st.elapsed_s, st.cpu_s) = (wall, cpu.unwrap_or(0.0));
    }
}

/// Writes a snapshot of the run; when the run stops after it (`stopping`), waits until it is on disk.
fn snapshot<L: Learner>(
    checkpointer: &mut Checkpointer,
    st: &LoopState<L::Action>,
    parts: &Parts<L>,
    expert_state: Option<String>,
    log: &mut RunLog<L::Action>,
    stopping: bool,
) -> Result<()> {
    let mut state = StateDict::default();
    parts.agent.save_state(AGENT_STATE, &mut state);
    parts.replay.save_state("replay", &mut state);
    parts.queries.save_state("query", &mut state);
    state.put_text("rng.replay", &parts.replay_rng);
    state.put_text("rng.query", &parts.query_rng);
    state.put_value("rng.eval_envs", &parts.evaluator.generators());
    state.put_value("expert", &expert_state);
    state.put_value("loop", st);
    state.put_f32("obs", &parts.obs);
    state.put_value("log", &log.position()?);
    let position = serde_json::json!({
        "phase": if st.training { "train" } else { "pretrain" },
        "pretrain_updates": st.pretrain_done,
        "step": st.step,
        "episode": st.episode,
        "episode_step": st.ep_len,
        "expert_in_control": parts.queries.expert_in_control(),
        // The snapshot's recorded key (demonstrated transitions), kept for the files already written.
        "budget_used": parts.queries.transitions_used(),
    });
    checkpointer.save(&state, position)?;
    if stopping {
        checkpointer.wait()?;
    }
    Ok(())
}

/// The run's summary after `st.step` environment steps.
fn summarize<A: Action>(
    cfg: &TrainConfig,
    env: &dyn Env<A>,
    log: &RunLog<A>,
    st: &LoopState<A>,
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
        algo: cfg.boxed().then_some(cfg.algo),
        seed: cfg.seed,
        steps_to_solve: steps as usize,
        solved,
        solve_threshold: threshold,
        train_steps: st.step,
        final_score: log.curve().last().map(|p| p.mean).unwrap_or(f64::NAN),
        demos_pretrain: pretrain_demos,
        demos_queried: queries.transitions_used(),
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
fn finish_log<L: Learner>(
    cfg: &TrainConfig,
    agent: &L,
    log: &mut RunLog<L::Action>,
    summary: &Summary,
    step: usize,
) -> Result<()> {
    if let Some(dir) = log.dir() {
        agent.save_weights(
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

/// The expert's action and Q-values for an oracle query rule (no question asked, no budget spent).
fn peek_expert<A: Action>(
    expert: &mut Option<&mut dyn Expert<A>>,
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

/// Asks the expert for the action at the run's observation (one step of a segment; `agent_action` on the step
/// that opens it) and checks that the answer is an action of the environment. A person who is shown the agent's
/// proposal at every step gets the agent's test-time action to ask ([`Query::propose`]).
fn ask_expert<L: Learner>(
    expert: &mut Option<&mut dyn Expert<L::Action>>,
    parts: &mut Parts<L>,
    env: &dyn Env<L::Action>,
    episode: EpisodeTrace<'_, L::Action>,
    agent_action: Option<&L::Action>,
    taken_over: bool,
) -> Result<Answer<L::Action>> {
    let expert = expert
        .as_deref_mut()
        .context("the query rule asked for the expert, but none was given")?;
    let proposes = expert.person().is_some_and(|p| p.shows_proposals());
    let Parts {
        agent,
        queries,
        obs,
        ..
    } = parts;
    let agent = std::cell::RefCell::new((agent, <L::Action as Action>::Column::default()));
    let propose = |obs: &[f32]| {
        let (agent, column) = &mut *agent.borrow_mut();
        agent.test_actions(obs, column);
        L::Action::owned(column.get(0))
    };
    let query = Query {
        obs,
        env,
        episode,
        agent_action: agent_action.map(|a| a.borrow()),
        steps_left: queries.segment_left(),
        budget_left: queries.budget_left(),
        unit: queries.unit(),
        taken_over,
        propose: proposes.then_some(&propose as &Propose<'_, L::Action>),
    };
    let answer = expert
        .answer(&query)
        .with_context(|| format!("the expert ({}) failed to answer", expert.describe()))?;
    if let Answer::Action { action, .. } = &answer
        && let Err(why) = L::Action::check(action.borrow(), env.spec())
    {
        anyhow::bail!(
            "the expert ({}) answered action {}, but {why}",
            expert.describe(),
            L::Action::to_field(action.borrow())
        );
    }
    Ok(answer)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::{ConfigInput, Method, NetKind};

    /// A resumed run's time is what its snapshot carried plus this session's; the CPU time of an idle thread
    /// does not grow with the wall clock.
    #[test]
    fn the_run_clock_carries_time_across_a_resume() {
        let mut clock = RunClock::start();
        let st = LoopState::<usize> {
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
        let mut saved = LoopState::<usize>::default();
        clock.stamp(&mut saved);
        assert!(saved.elapsed_s >= wall && saved.cpu_s >= cpu);
        // A snapshot of an older version, without the fields, counts from zero.
        let old: LoopState<usize> = serde_json::from_str(
            r#"{"pretrain_done":0,"training":false,"step":0,"episode":0,"ep_return":0.0,"ep_len":0,
                "ep_demo":0,"updates":0,"ep_actions":[],"ep_generator":null}"#,
        )
        .unwrap();
        assert_eq!((old.elapsed_s, old.cpu_s), (0.0, 0.0));
    }

    /// A configuration that did not come through `ConfigInput::resolve` (as Python's and a snapshot's do not)
    /// is checked where every run starts: the error is `validate`'s own, and nothing is written.
    #[test]
    fn a_run_refuses_a_configuration_that_validate_refuses() {
        let input = ConfigInput::new("CartPole-v0", Method::Adqn, NetKind::Bootstrap, 0);
        let good = input.resolve().unwrap();
        for (key, change) in [
            (
                "gamma",
                (|c: &mut TrainConfig| c.gamma = 1.5) as fn(&mut TrainConfig),
            ),
            ("batch_size", |c| c.batch_size = 0),
            ("expert", |c| c.expert = "no-such-expert".into()),
        ] {
            let mut cfg = good.clone();
            change(&mut cfg);
            let expected = cfg.validate().unwrap_err().to_string();
            assert!(expected.contains(key), "{key}: {expected}");
            let dir = tempfile::tempdir().unwrap();
            let mut log = RunLog::create(dir.path(), &cfg.to_toml(), 10, false).unwrap();
            let err = RunBuilder::new(&cfg)
                .train(&mut log)
                .err()
                .expect("refused");
            assert_eq!(err.to_string(), expected, "{key}");
        }
    }
}
