//! Experts: whoever the agent may ask for an action.
//!
//! The [`Expert`] trait takes an observation and returns an action, or an error: an expert may be slow or
//! interactive (a person answering in a browser, an external process), so nothing here assumes it answers
//! instantly or always. During training the loop asks through [`Expert::answer`] with a [`Query`] (the
//! observation, the environment to draw, the agent's own proposal); the [`Answer`] may be that nobody answered,
//! and [`Person::observe`] lets an interactive expert follow the run. Kinds: [`CheckpointExpert`] (a trained
//! network acting greedily), [`NoisyExpert`] (acts at random with probability p), [`scripted`] controllers,
//! the web expert (a person in a browser: the `arld-web` crate, whose options [`web_options`] parses) and
//! [`process::ProcessExpert`] (another program speaking JSON lines). [`from_spec`] builds one from a short spec
//! ([`build_with`] also the web expert, given its start); [`demos`] collects demonstrations from an expert;
//! [`minari`] reads a Minari dataset as demonstrations.

pub mod boxed;
pub mod demos;
pub mod minari;
pub mod person;
pub mod pipeline;
pub mod process;
pub mod scripted;
pub mod shipped;
pub mod web_options;

use crate::agent::test_policy_action;
pub use person::Person;

use crate::env::{Action, Env, EnvSpec};
use crate::nn::QNet;
use crate::query::{BudgetUnit, OracleView, QueryController};
use anyhow::{Context, Result, bail, ensure};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::path::{Path, PathBuf};

/// Something that can be asked which action to take.
///
/// An expert answers with actions of the kind `A` ([`Action`]): discrete indices (the default) or boxes of
/// numbers.
pub trait Expert<A: Action = usize>: Send {
    /// The expert's action for `obs`. May block (a person, a process) and may fail.
    fn act(&mut self, obs: &[f32]) -> Result<A>;
    /// A short human-readable description, e.g. `checkpoint:experts/CartPole-v0/weak.safetensors`.
    fn describe(&self) -> String;
    /// The kind of expert recorded with each query (`queries.csv`): the description up to its first `:` or
    /// `(`, e.g. `checkpoint`, `scripted`, `web`.
    fn kind(&self) -> String {
        let d = self.describe();
        d.split([':', '(']).next().unwrap_or_default().to_string()
    }
    /// Answers a query of the training loop. Programs answer at once with [`Expert::act`]; an interactive
    /// expert may show `query.env`, take its time, or give the query back ([`Answer::Unanswered`]).
    fn answer(&mut self, query: &Query<'_, A>) -> Result<Answer<A>> {
        Ok(Answer::Action {
            action: self.act(query.obs)?,
            response_s: None,
        })
    }
    /// For oracle query rules only: what the expert would do at `obs` and its Q-values (averaged over heads),
    /// without answering a query (no budget is spent, nothing advances). `None` for experts that have no
    /// Q-values (people, scripts, processes).
    fn peek(&mut self, _obs: &[f32]) -> Option<OracleView> {
        None
    }
    /// The hooks of an expert who is a person ([`Person`]: the web expert): `None` for programs, which only
    /// answer.
    fn person(&mut self) -> Option<&mut dyn Person<A>> {
        None
    }
    /// The state that changes as the expert answers (a generator), as text for a run's snapshot; `None` for
    /// an expert whose answers depend only on the observation.
    fn state(&self) -> Option<String> {
        None
    }
    /// Puts back what [`Expert::state`] returned.
    fn restore(&mut self, state: &str) -> Result<()> {
        anyhow::bail!(
            "the snapshot holds a state for the expert ({} bytes), but {} keeps none",
            state.len(),
            self.describe()
        )
    }
}

/// What the training loop asks the expert at one step of a query's segment.
pub struct Query<'a, A: Action = usize> {
    pub obs: &'a [f32],
    /// The environment in the state `obs` comes from (to draw it; never stepped by the expert).
    pub env: &'a dyn Env<A>,
    /// How the episode in progress began and its actions so far: with them an expert can rebuild the state
    /// (to replay the agent's steps to a person, or let them undo a key on a copy).
    pub episode: EpisodeTrace<'a, A>,
    /// The agent's own proposal, on the step that opens the segment (`None` on the later steps).
    pub agent_action: Option<A::Ref<'a>>,
    /// The agent's test-time action (no exploration, nothing drawn) at any observation, for a person who is shown
    /// it at every step ([`Person::shows_proposals`]); `None` for other experts.
    pub propose: Option<&'a Propose<'a, A>>,
    /// Expert steps left in the segment, this one included.
    pub steps_left: usize,
    /// The budget not yet spent, in its unit (counting transitions, the segment's steps left included): what a
    /// person's retry of the segment may spend ([`Person::retried_steps`]).
    pub budget_left: usize,
    pub unit: BudgetUnit,
    /// Whether the segment is a takeover the expert asked for ([`Person::wants_control`]), not a question of the
    /// query rule.
    pub taken_over: bool,
}

/// The agent's test-time action at an observation ([`Query::propose`]).
pub type Propose<'a, A> = dyn Fn(&[f32]) -> A + 'a;

/// The episode in progress: how it began and the actions taken since.
#[derive(Debug)]
pub struct EpisodeTrace<'a, A: Action = usize> {
    pub start: crate::env::EpisodeStart,
    pub actions: &'a [A],
}

impl<A: Action> Clone for EpisodeTrace<'_, A> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<A: Action> Copy for EpisodeTrace<'_, A> {}

/// What a resumed run kept of its course before the stop, for [`Person::resumed_history`].
#[derive(Clone, Debug, Default)]
pub struct RunHistory {
    /// The evaluations so far: step and mean test return, in step order.
    pub curve: Vec<(u64, f64)>,
    /// The uncertainty logged with each question so far (the query log's rows that have one): step,
    /// uncertainty and the rule's threshold then, in step order.
    pub uncertainty: Vec<(u64, f32, Option<f32>)>,
}

/// How a run ended, for [`Person::finish`].
#[derive(Clone, Debug)]
pub struct RunEnd {
    pub solved: bool,
    /// The first evaluation step that reached the solve threshold (`train_steps` when none did).
    pub steps_to_solve: usize,
    pub train_steps: usize,
    /// The mean test return of the last evaluation.
    pub final_score: f64,
    /// The run directory, when the run writes one.
    pub dir: Option<PathBuf>,
}

/// An expert's reply to a [`Query`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Answer<A = usize> {
    /// The action; an interactive expert also reports how long the answer took (seconds).
    Action { action: A, response_s: Option<f64> },
    /// Nobody answered in time: the agent acts instead, the step is not charged to the budget and the
    /// segment ends.
    Unanswered { waited_s: f64 },
}

/// Where a run stands after a step, for [`Person::observe`].
pub struct Progress<'a, A: Action = usize> {
    /// Environment steps done.
    pub step: usize,
    pub train_steps: usize,
    pub episode: usize,
    /// The environment after the step (reset already if the episode ended).
    pub env: &'a dyn Env<A>,
    /// The uncertainty of this step's agent action, when it was computed.
    pub uncertainty: Option<f32>,
    /// Budget, segments and the query rule (its adaptive threshold).
    pub queries: &'a QueryController,
    /// The latest evaluation: step and mean test return.
    pub last_eval: Option<(u64, f64)>,
}

/// A trained Q-network acting with its test-time policy (greedy, majority vote, or mean weights).
pub struct CheckpointExpert {
    net: QNet,
    q: Vec<f32>,
    /// What the expert is called in records: `checkpoint:PATH`, or `shipped:QUALITY`.
    name: String,
}

impl CheckpointExpert {
    /// Loads a checkpoint and checks that it fits the environment.
    pub fn load(path: &Path, spec: &EnvSpec) -> Result<Self> {
        let (net, meta) = QNet::load(path)
            .with_context(|| format!("cannot load expert checkpoint {}", path.display()))?;
        Self::new(net, &meta, format!("checkpoint:{}", path.display()), spec)
    }

    /// The shipped expert `quality` of the task `spec` ([`shipped::model`]), named `shipped:QUALITY`.
    pub fn shipped(quality: &str, spec: &EnvSpec) -> Result<Self> {
        let bytes =
            shipped::model(spec.id, quality).with_context(|| no_shipped(quality, spec.id))?;
        let name = format!("shipped:{quality}");
        let (net, meta) = crate::nn::parse_model(Path::new(&name), bytes)?;
        Self::new(net, &meta, name, spec)
    }

    fn new(
        net: QNet,
        meta: &std::collections::BTreeMap<String, String>,
        name: String,
        spec: &EnvSpec,
    ) -> Result<Self> {
        ensure!(
            net.obs_dim() == spec.obs_dim && net.n_actions() == spec.n_actions,
            "expert checkpoint {} has {} inputs and {} actions, but {} has {} and {}{}",
            name.trim_start_matches("checkpoint:"),
            net.obs_dim(),
            net.n_actions(),
            spec.id,
            spec.obs_dim,
            spec.n_actions,
            meta.get("env")
                .map(|e| format!(" (it was trained on {e})"))
                .unwrap_or_default()
        );
        let q = vec![0.0; net.heads() * net.n_actions()];
        Ok(Self { net, q, name })
    }
}

/// Why there is no shipped expert `quality` for `env_id`, and what to use instead.
pub(crate) fn no_shipped(quality: &str, env_id: &str) -> String {
    let tasks: Vec<&str> = shipped::tasks().collect();
    format!(
        "no shipped {quality} expert for {env_id}: arld ships experts for {} (and CartPole-v1, LunarLander-v3); \
         train one with `arld expert train --env {env_id}` and give it as `checkpoint:PATH`, or use `scripted` or \
         `cmd:COMMAND`",
        tasks.join(", ")
    )
}

impl Expert for CheckpointExpert {
    fn act(&mut self, obs: &[f32]) -> Result<usize> {
        Ok(test_policy_action(&self.net, &mut self.q, obs))
    }
    fn peek(&mut self, obs: &[f32]) -> Option<OracleView> {
        let action = test_policy_action(&self.net, &mut self.q, obs);
        let (heads, a) = (self.net.heads(), self.net.n_actions());
        let q_values = (0..a)
            .map(|i| (0..heads).map(|k| self.q[k * a + i]).sum::<f32>() / heads as f32)
            .collect();
        Some(OracleView { action, q_values })
    }
    fn describe(&self) -> String {
        self.name.clone()
    }
}

/// Wraps an expert so that it takes a uniformly random action with probability `p` (the paper's "perfect
/// expert with 40% random actions").
pub struct NoisyExpert {
    inner: Box<dyn Expert>,
    p: f64,
    n_actions: usize,
    rng: Pcg64,
}

impl NoisyExpert {
    pub fn new(inner: Box<dyn Expert>, p: f64, n_actions: usize, seed: u64) -> Result<Self> {
        ensure!(
            (0.0..=1.0).contains(&p),
            "the random-action probability must be in [0, 1], got {p}"
        );
        Ok(Self {
            inner,
            p,
            n_actions,
            rng: Pcg64::seed_from_u64(seed),
        })
    }
}

impl Expert for NoisyExpert {
    fn act(&mut self, obs: &[f32]) -> Result<usize> {
        // Ask the inner expert every time, so its own state (if any) advances as without noise.
        let a = self.inner.act(obs)?;
        Ok(if self.rng.random::<f64>() < self.p {
            self.rng.random_range(0..self.n_actions)
        } else {
            a
        })
    }
    fn describe(&self) -> String {
        format!("noisy:{}:{}", self.p, self.inner.describe())
    }
    fn state(&self) -> Option<String> {
        let inner = self.inner.state();
        Some(serde_json::to_string(&(&self.rng, inner)).expect("a generator serialises"))
    }
    fn restore(&mut self, state: &str) -> Result<()> {
        let (rng, inner): (Pcg64, Option<String>) = serde_json::from_str(state)
            .map_err(|e| anyhow::anyhow!("the snapshot's expert state is damaged: {e}"))?;
        self.rng = rng;
        if let Some(inner) = inner {
            self.inner.restore(&inner)?;
        }
        Ok(())
    }
}

/// Help text for expert specs.
pub const SPEC_HELP: &str = "Expert specs:
  shipped:weak, shipped:perfect  arld's own experts for every built-in task (inside the binary; the paper's kind \
of expert, and the best one)
  scripted                       a hand-written controller (Gymnasium's heuristic lander; simple controllers for \
the other tasks, discrete and continuous)
  checkpoint:PATH                a trained network acting greedily (a run's weights.safetensors or a checkpoint)
  noisy:P:SPEC                   SPEC acting at random with probability P (a box task: Gaussian noise of P \
half-widths)
  cmd:COMMAND                    a program in any language speaking JSON lines on stdin/stdout, e.g. \
cmd:\"python3 examples/expert.py\" (the protocol: docs/reference.md, \"An expert in any language\")
  web[:OPTIONS]                  a person answering in a browser (see `arld train --help`)
  python:NAME                    an expert given to arld.Agent in Python (names it in a run's records)";

/// An expert spec, parsed: which expert [`from_spec`] builds. Parsing checks the form of every part, so that a
/// configuration can be refused before any work (a run validates its spec first); building then loads
/// files, starts processes and servers.
#[derive(Clone, Debug, PartialEq)]
pub enum ExpertSpec {
    /// `checkpoint:PATH`.
    Checkpoint(PathBuf),
    /// `shipped:weak` or `shipped:perfect`.
    Shipped(&'static str),
    /// `cmd:COMMAND`.
    Command(String),
    /// `scripted`.
    Scripted,
    /// `web[:OPTIONS]`.
    Web(web_options::WebOptions),
    /// `noisy:P:SPEC`.
    Noisy { p: f64, inner: Box<ExpertSpec> },
    /// `python:NAME`: an expert given in Python (`arld.Agent(expert=...)`), named in a run's records; only the
    /// Python package can supply it.
    Python(String),
}

impl std::str::FromStr for ExpertSpec {
    type Err = anyhow::Error;

    fn from_str(spec: &str) -> Result<Self> {
        let (kind, rest) = spec.split_once(':').unwrap_or((spec, ""));
        Ok(match kind {
            "checkpoint" if !rest.is_empty() => Self::Checkpoint(PathBuf::from(rest)),
            "shipped" if rest == "weak" => Self::Shipped("weak"),
            "shipped" if rest == "perfect" => Self::Shipped("perfect"),
            "cmd" if !rest.trim().is_empty() => Self::Command(rest.to_string()),
            "scripted" if rest.is_empty() => Self::Scripted,
            "web" => Self::Web(rest.parse()?),
            "python" if !rest.trim().is_empty() => Self::Python(rest.to_string()),
            "noisy" => {
                let (p, inner) = rest
                    .split_once(':')
                    .context("noisy expert spec must be noisy:P:SPEC")?;
                let p: f64 = p
                    .parse()
                    .with_context(|| format!("bad probability '{p}' in expert spec '{spec}'"))?;
                ensure!(
                    (0.0..=1.0).contains(&p),
                    "the random-action probability of '{spec}' must be in [0, 1], got {p}"
                );
                Self::Noisy {
                    p,
                    inner: Box::new(inner.parse()?),
                }
            }
            _ => bail!("unknown expert spec '{spec}'. {SPEC_HELP}"),
        })
    }
}

impl ExpertSpec {
    /// Whether this expert can give demonstrations outside a run (collected before training): every kind but
    /// the web expert, which answers a running training loop's queries only.
    pub fn demonstrates(&self) -> bool {
        match self {
            Self::Web(_) => false,
            Self::Noisy { inner, .. } => inner.demonstrates(),
            _ => true,
        }
    }

    /// The steps of a question's segment this expert's person takes in real time ([`WebOptions::segment_steps`]:
    /// seconds of play at the page's rate); `None` for every other expert (a segment is `segment_len` steps).
    ///
    /// [`WebOptions::segment_steps`]: web_options::WebOptions::segment_steps
    pub fn segment_steps(&self) -> Option<usize> {
        match self {
            Self::Web(options) => options.segment_steps(),
            _ => None,
        }
    }
}

/// Starts the web expert with its options for the environment `env_id` (`arld_web::start`): the crate above this
/// one that holds the server and the page hands it to [`build_with`].
pub type WebStart = fn(&web_options::WebOptions, &str) -> Result<Box<dyn Expert>>;

/// Builds an expert from a spec for the environment `env_id`; `seed` seeds any randomness the expert has and
/// `timeout_s` bounds an expert process's answer. Every kind but the web expert ([`build_with`]).
pub fn from_spec(spec: &str, env_id: &str, seed: u64, timeout_s: f64) -> Result<Box<dyn Expert>> {
    build(&spec.parse()?, env_id, seed, timeout_s)
}

/// Builds the expert of a parsed spec ([`from_spec`]); a web expert is refused (see [`build_with`]).
pub fn build(
    spec: &ExpertSpec,
    env_id: &str,
    seed: u64,
    timeout_s: f64,
) -> Result<Box<dyn Expert>> {
    let no_web: WebStart = |_, _| {
        bail!("this program was built without the web expert (the arld-web crate builds it)")
    };
    build_with(spec, env_id, seed, timeout_s, no_web)
}

/// Why a `python:NAME` expert cannot be built here: the object it names lives in a Python process.
pub(crate) const PYTHON_ONLY: &str = "an expert given in Python (`python:NAME`) is answered by that Python object: \
    continue its run from Python (arld.Agent.load(..., expert=...)), or name another expert";

/// Builds the expert of a parsed spec, starting a web expert with `web`.
pub fn build_with(
    spec: &ExpertSpec,
    env_id: &str,
    seed: u64,
    timeout_s: f64,
    web: WebStart,
) -> Result<Box<dyn Expert>> {
    let env_spec = *crate::env::spec(env_id)?;
    Ok(match spec {
        ExpertSpec::Checkpoint(path) => Box::new(CheckpointExpert::load(path, &env_spec)?),
        ExpertSpec::Shipped(quality) => Box::new(CheckpointExpert::shipped(quality, &env_spec)?),
        ExpertSpec::Command(command) => Box::new(process::ProcessExpert::<usize>::spawn(
            command,
            crate::env::spec(env_id)?,
            timeout_s,
        )?),
        ExpertSpec::Scripted => Box::new(scripted::ScriptedExpert::new(env_id)?),
        ExpertSpec::Web(options) => web(options, env_id)?,
        ExpertSpec::Python(_) => bail!(PYTHON_ONLY),
        ExpertSpec::Noisy { p, inner } => {
            let inner = build_with(inner, env_id, seed.wrapping_add(1), timeout_s, web)?;
            Box::new(NoisyExpert::new(inner, *p, env_spec.n_actions, seed)?)
        }
    })
}
