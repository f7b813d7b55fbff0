//! Every hyperparameter of a run in one struct, with its default and its source.
//!
//! A run's configuration goes from low level to high level once, before any work:
//! - [`ConfigInput`] is the configuration *as given*: the run's identity (task, method, network, seed) and the
//!   values of a TOML file and of `--set key=value` pairs, in order, later ones winning. Unknown keys are
//!   rejected as they arrive, with the list of valid keys.
//! - [`ConfigInput::resolve`] turns it into a [`TrainConfig`]: the paper's per-task table and the method's
//!   settings ([`TrainConfig::preset`], docs/algorithm.md §9), then the given values; a value the method does
//!   not use (a budget for DQN, pre-training steps for ADQN, a query threshold for GDQN) is an error, and
//!   [`TrainConfig::validate`], the one place every value is checked, runs last.
//!
//! What follows from the method is derived from it, never stored: the query rule ([`TrainConfig::query_rule`];
//! BDQN's query probability is the task's `t_query`), whether the run pre-trains ([`Method::pretrains`]), and the
//! demonstration counts of the preset. The agent and the replay memory receive their own parts
//! ([`TrainConfig::dqn_agent_config`], [`TrainConfig::replay_config`]).

use crate::agent::DqnAgentConfig;
pub use crate::agent::{Algo, TdLoss};
use crate::nn::{HIDDEN, HiddenLayers, MAX_DEPTH, MAX_HIDDEN, OutputKind};
use crate::query::{
    BudgetUnit, QueryController, QueryError, QueryRule, RuleDefaults, RuleSpec, check_signals,
};
use crate::replay::ReplayConfig;
use anyhow::{Context, Result, bail, ensure};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;

/// An enum with fixed names, from one list of `Variant => "name"`: `ALL` (every choice, in the order listed),
/// `name()` (the name on the command line and in files and directory names, which serde and clap also use),
/// `Display` (the name) and `FromStr` (by [`parse_named`], which names `what` and every known name on error).
macro_rules! fixed_names {
    ($ty:ident, $what:literal, { $($variant:ident => $name:literal),+ $(,)? }) => {
        impl $ty {
            /// Every choice, in declaration order.
            pub const ALL: [$ty; [$($name),+].len()] = [$($ty::$variant),+];

            /// The choice's name: command line, files, directory names.
            pub fn name(self) -> &'static str {
                match self {
                    $($ty::$variant => $name,)+
                }
            }
        }

        impl std::str::FromStr for $ty {
            type Err = anyhow::Error;
            fn from_str(s: &str) -> Result<Self> {
                parse_named(s, &$ty::ALL, $ty::name, $what)
            }
        }

        impl fmt::Display for $ty {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

/// The learning method (docs/algorithm.md §9).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Prioritized double DQN, no expert.
    Dqn,
    /// Deep Q-learning from Demonstrations: pre-training on demonstrations collected before training.
    Dqfd,
    /// Greedy queries: the expert drives the first `budget` steps.
    Gdqn,
    /// Bernoulli queries with a fixed probability, in 5-step segments.
    Bdqn,
    /// Active DQN: adaptive uncertainty-based queries (the paper's Algorithm 1).
    Adqn,
    /// Active DQN with pre-training on half the demonstrations and half the budget.
    Adqnp,
}

impl Method {
    /// Does the method pre-train on demonstrations collected before training?
    pub fn pretrains(self) -> bool {
        matches!(self, Method::Dqfd | Method::Adqnp)
    }

    /// Does the method query the expert during training?
    pub fn queries(self) -> bool {
        matches!(
            self,
            Method::Gdqn | Method::Bdqn | Method::Adqn | Method::Adqnp
        )
    }

    /// Does the method need an expert at all?
    pub(crate) fn needs_expert(self) -> bool {
        self != Method::Dqn
    }

    /// The name the paper prints (DQfD keeps its lower-case f).
    pub fn paper_name(self) -> String {
        crate::paper::method_display_name(self.name())
    }
}

fixed_names!(Method, "method", {
    Dqn => "dqn",
    Dqfd => "dqfd",
    Gdqn => "gdqn",
    Bdqn => "bdqn",
    Adqn => "adqn",
    Adqnp => "adqnp",
});

/// The choice of `all` whose `name` is `s`; the error names what was asked for and every known name.
fn parse_named<T: Copy>(s: &str, all: &[T], name: fn(T) -> &'static str, what: &str) -> Result<T> {
    all.iter()
        .copied()
        .find(|&v| name(v) == s)
        .with_context(|| {
            let known: Vec<&str> = all.iter().map(|&v| name(v)).collect();
            format!("unknown {what} '{s}'; known: {}", known.join(", "))
        })
}

pub use crate::agent::box_agent::BoxUncertainty;

fixed_names!(BoxUncertainty, "box uncertainty", {
    CriticVariance => "critic_variance",
    ActionDisagreement => "action_disagreement",
});

/// The settings of TD3 and SAC beyond the shared ones (network, learning rate, batch, discount), as config keys:
/// each `None` stands for its default, which [`BoxSettings::value`] gives with its source.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BoxSettings {
    /// Polyak rate of the target networks \[TD3, SAC: 0.005\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tau: Option<f64>,
    /// TD3: critic updates per actor and target update \[TD3: 2\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy_delay: Option<usize>,
    /// TD3: standard deviation of the target policy's smoothing noise, in half-widths of the box \[TD3: 0.2\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_noise: Option<f64>,
    /// TD3: the clip of that noise, in half-widths \[TD3: 0.5\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_clip: Option<f64>,
    /// TD3: standard deviation of the exploration noise, in half-widths \[TD3: 0.1\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exploration_noise: Option<f64>,
    /// SAC: the entropy the temperature steers towards \[SAC: -dim(A)\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_entropy: Option<f64>,
    /// SAC: the temperature's learning rate \[OURS: `lr`\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_lr: Option<f64>,
    /// SAC: the temperature before the first update \[SAC: 1\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_alpha: Option<f64>,
    /// The uncertainty the learner reports to the query rule \[OURS: critic_variance\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<BoxUncertainty>,
}

/// Which box learner a setting of [`BoxSettings`] belongs to (`None`: both).
fn box_setting_owner(key: &str) -> Option<Option<Algo>> {
    match key {
        "tau" => Some(None),
        "policy_delay" | "target_noise" | "noise_clip" | "exploration_noise" => {
            Some(Some(Algo::Td3))
        }
        "target_entropy" | "alpha_lr" | "initial_alpha" => Some(Some(Algo::Sac)),
        "uncertainty" => Some(None),
        _ => None,
    }
}

impl BoxSettings {
    /// Checks the given values.
    fn validate(&self) -> Result<()> {
        let check = |name: &str, v: Option<f64>, ok: fn(f64) -> bool, what: &str| -> Result<()> {
            match v {
                Some(v) if !ok(v) => bail!("{name} must be {what}, got {v}"),
                _ => Ok(()),
            }
        };
        check("tau", self.tau, |v| v > 0.0 && v <= 1.0, "in (0, 1]")?;
        let non_negative = |v: f64| v >= 0.0 && v.is_finite();
        let positive = |v: f64| v > 0.0 && v.is_finite();
        check(
            "target_noise",
            self.target_noise,
            non_negative,
            "non-negative and finite",
        )?;
        check(
            "noise_clip",
            self.noise_clip,
            non_negative,
            "non-negative and finite",
        )?;
        check(
            "exploration_noise",
            self.exploration_noise,
            non_negative,
            "non-negative and finite",
        )?;
        check(
            "target_entropy",
            self.target_entropy,
            f64::is_finite,
            "finite",
        )?;
        check("alpha_lr", self.alpha_lr, positive, "positive and finite")?;
        check(
            "initial_alpha",
            self.initial_alpha,
            positive,
            "positive and finite",
        )?;
        ensure!(
            self.policy_delay
                .is_none_or(|d| (1..=MAX_STEPS).contains(&d)),
            "policy_delay must be between 1 and {MAX_STEPS}, got {:?}",
            self.policy_delay
        );
        Ok(())
    }

    /// These settings with each one equal to its default ([`BoxSettings::values`] of unset settings) unset.
    fn given_only(&self, lr: f64, action_dim: usize) -> BoxSettings {
        let defaults = BoxSettings::default().values(lr, action_dim);
        let given = self.values(lr, action_dim);
        let keep = |i: usize| given[i].1 != defaults[i].1;
        BoxSettings {
            tau: self.tau.filter(|_| keep(0)),
            policy_delay: self.policy_delay.filter(|_| keep(1)),
            target_noise: self.target_noise.filter(|_| keep(2)),
            noise_clip: self.noise_clip.filter(|_| keep(3)),
            exploration_noise: self.exploration_noise.filter(|_| keep(4)),
            target_entropy: self.target_entropy.filter(|_| keep(5)),
            alpha_lr: self.alpha_lr.filter(|_| keep(6)),
            initial_alpha: self.initial_alpha.filter(|_| keep(7)),
            uncertainty: self.uncertainty.filter(|_| keep(8)),
        }
    }

    /// Each key's value in a run with learning rate `lr` and actions of `action_dim` dimensions: the given one or
    /// its default.
    pub fn values(&self, lr: f64, action_dim: usize) -> [(&'static str, toml::Value); 9] {
        // The defaults are the learners' own (`Td3Config::default`, `SacConfig::default`).
        let (td3, sac) = (
            crate::agent::td3::Td3Config::default(),
            crate::agent::sac::SacConfig::default(),
        );
        // A float32 default as the decimal it is written as (0.005, not 0.004999999888241291).
        let decimal = |x: f32| x.to_string().parse::<f64>().unwrap_or(f64::from(x));
        let f = |v: Option<f64>, default: f32| toml::Value::Float(v.unwrap_or(decimal(default)));
        [
            ("tau", f(self.tau, td3.common.tau)),
            (
                "policy_delay",
                toml::Value::Integer(self.policy_delay.unwrap_or(td3.policy_delay as usize) as i64),
            ),
            ("target_noise", f(self.target_noise, td3.target_noise)),
            ("noise_clip", f(self.noise_clip, td3.noise_clip)),
            (
                "exploration_noise",
                f(self.exploration_noise, td3.exploration_noise),
            ),
            (
                "target_entropy",
                f(
                    self.target_entropy,
                    sac.target_entropy.unwrap_or(-(action_dim as f32)),
                ),
            ),
            ("alpha_lr", toml::Value::Float(self.alpha_lr.unwrap_or(lr))),
            ("initial_alpha", f(self.initial_alpha, sac.initial_alpha)),
            (
                "uncertainty",
                toml::Value::String(self.uncertainty.unwrap_or_default().name().to_string()),
            ),
        ]
    }
}

/// The output stage of the Q-network (docs/algorithm.md §2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum NetKind {
    /// One linear output layer.
    Plain,
    /// K bootstrapped linear heads on a shared trunk ("-B" methods).
    Bootstrap,
    /// A factorised NoisyLinear output layer ("-N" methods).
    Noisy,
}

fixed_names!(NetKind, "network", {
    Plain => "plain",
    Bootstrap => "bootstrap",
    Noisy => "noisy",
});

/// All hyperparameters of one training run, resolved and validated ([`ConfigInput::resolve`]). Field docs give
/// the default and its source tag (\[P\] paper, \[DQfD\], \[PER\], \[BS\], \[NN\], \[OURS\] as in
/// docs/algorithm.md).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// Gymnasium id of the task.
    pub env: String,
    /// Learning method.
    pub method: Method,
    /// Output stage of the network.
    pub net: NetKind,
    /// Seed of every random draw of the run.
    pub seed: u64,

    /// Discount factor \[P, per task\].
    pub gamma: f64,
    /// Adam learning rate \[P, per task\].
    pub lr: f64,
    /// Environment steps of training (pre-training updates excluded) \[P, per task\].
    pub train_steps: usize,
    /// Agent part of the replay memory \[P, per task\].
    pub replay_size: usize,
    /// Minibatch size \[OURS: 32\].
    pub batch_size: usize,
    /// Environment steps before the first update \[OURS: 500 CartPole, 1000 otherwise\].
    pub learning_starts: usize,
    /// Environment steps between updates \[OURS: 1\].
    pub train_freq: usize,
    /// Hard target-network copy period in updates \[OURS: 250 CartPole, 1000 otherwise\].
    pub target_period: usize,
    /// `target_period` counts environment steps, not updates: the target network is copied after every
    /// `target_period`-th step counted from the first, before that step's update (also before learning starts),
    /// as Stable-Baselines3's DQN copies when `_n_calls % target_update_interval == 0` \[OURS: false; Python's
    /// `defaults="sb3"`: true\]. Written to a configuration only when true.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub target_period_in_steps: bool,
    /// Number of bootstrapped heads \[P: 10\].
    pub heads: usize,
    /// Widths of the network's hidden layers, first to last: 1 to 8 layers, each 1 to 4096 wide \[P: 64, 64\].
    /// Any depth and widths run on the same kernels.
    #[serde(default = "paper_hidden")]
    pub hidden: Vec<usize>,
    /// TD loss \[P: squared error\].
    pub loss: TdLoss,
    /// Double DQN's TD target, the online network picking the next action and the target network valuing it
    /// \[P: true\]; false: the target network's maximum, as in the original DQN (and Stable-Baselines3's).
    pub double_q: bool,
    /// Global gradient-norm clip \[OURS: 10\].
    pub grad_clip: f64,
    /// Treat time-limit truncation as terminal (the 2018 Gym behaviour) \[OURS: false\].
    pub timeout_as_terminal: bool,

    /// ε-greedy start value \[P: 0.9\].
    pub eps_start: f64,
    /// ε-greedy final value \[P: 0.01\].
    pub eps_end: f64,
    /// Fraction of training over which ε is annealed linearly \[OURS: 0.1\].
    pub eps_fraction: f64,
    /// Use ε-greedy on top of bootstrapped/noisy exploration \[P: true\].
    pub eps_greedy_on_top: bool,
    /// Act uniformly at random before `learning_starts` (the steps before the first update), as
    /// Stable-Baselines3's DQN does, instead of by the policy and ε \[OURS: false; Python's `defaults="sb3"`:
    /// true\]. Written to a configuration only when true.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub random_before_learning: bool,
    /// The learner of a task with actions in a box: `td3` or `sac` \[OURS: td3\]; unused by discrete tasks.
    /// Written to a configuration only when it is not td3.
    #[serde(default, skip_serializing_if = "Algo::is_td3")]
    pub algo: Algo,
    /// The settings of the box learners (TD3 and SAC), each `None` at its source's value ([`BoxSettings`],
    /// docs/algorithm.md §15-§16) and then left out of a configuration file; refused for a discrete task, and the
    /// one learner's settings for the other.
    #[serde(flatten)]
    pub box_settings: BoxSettings,

    /// Proportional prioritized replay (false: uniform) \[P; OURS: uniform for actions in a box, docs/algorithm.md §18\].
    pub prioritized: bool,
    /// Priority exponent α \[PER: 0.6\].
    pub alpha: f64,
    /// Initial importance-sampling exponent β, annealed to 1 over training \[PER: 0.4\].
    pub beta0: f64,
    /// Priority bonus of agent transitions \[DQfD: 0.001\].
    pub eps_agent: f64,
    /// Priority bonus of demonstration transitions \[DQfD: 1.0\].
    pub eps_demo: f64,

    /// Large-margin loss margin M \[DQfD: 0.8\].
    pub margin: f64,
    /// Weight λ of the margin loss \[P, per task\]; in a box task, the weight of dqfd's and adqnp's behaviour
    /// cloning loss (docs/algorithm.md §17) \[OURS: 100\].
    pub lambda: f64,
    /// Weight λ1 of DQfD's n-step TD loss; 0 turns it off \[P: 0, the paper drops it; DQfD used 1\]. Refused in a
    /// box task (TD3 and SAC have no second loss).
    pub lambda_n: f64,
    /// Horizon n of the n-step loss \[DQfD: 10\]; in a box task, of the critics' n-step target (1: the one-step
    /// target) \[OURS: 1\].
    pub n_step: usize,
    /// L2 regularisation weight λ3 on all weights \[P: 0, the paper drops it; DQfD used 1e-5\].
    pub l2: f64,
    /// Demonstration transitions collected before training (DQfD; ADQNP uses half) \[P, per task\].
    pub n_demo: usize,
    /// Pre-training updates on demonstrations only \[P, per task\].
    pub pretrain_steps: usize,

    /// Demonstrated transitions that may be asked for during training \[P, per task\] (queries instead when
    /// `budget_unit = "queries"`).
    pub budget: usize,
    /// What `budget` counts: `transitions` (the paper's reading) or `queries` (each a segment of up to
    /// `segment_len` transitions; an ablation) \[OURS: transitions\].
    #[serde(default)]
    pub budget_unit: BudgetUnit,
    /// Ask the expert only from `learning_starts` on, when the network has started learning (an ablation; the
    /// paper's rule asks from the first step, when the uncertainty is that of the untrained network)
    /// \[OURS: false\].
    #[serde(default)]
    pub queries_from_learning_starts: bool,
    /// Fraction of recent steps whose uncertainty may exceed the current one for a query (ADQN, ADQNP), and
    /// BDQN's query probability \[P, per task and net\].
    pub t_query: f64,
    /// Window of recent uncertainties N_r \[OURS: 1000\].
    pub n_r: usize,
    /// The query rule, as a spec `NAME` or `NAME(key=value, ...)` (`arld rules` lists them, docs/algorithm.md
    /// section 14 says where each comes from); empty: the method's own (greedy for GDQN, bernoulli for BDQN,
    /// adaptive for ADQN and ADQNP), whose parameters default to `t_query` and `n_r` \[OURS: empty\].
    #[serde(default)]
    pub query_rule: String,
    /// Expert steps per query \[P-inf: 5\]; when not given and the expert is a person in real time
    /// (`web:fps=N`), the steps of its `segment_s` seconds of play (3 s by default).
    pub segment_len: usize,
    /// Use the exact factorised-noise variance instead of the paper's formula \[OURS: false\].
    pub exact_factorised_var: bool,
    /// Expert specification (see `arld expert --help`) \[OURS: the shipped weak expert\].
    pub expert: String,
    /// Seconds an expert may take to answer one query; an expert process (`cmd:...`) slower than this is stopped
    /// and the run fails \[OURS: 30\].
    pub expert_timeout: f64,
    /// Demonstration file for pre-training; empty: collect from the expert at the start of the run;
    /// `python:demos` (`DEMOS_FROM_PYTHON`): given to `arld.Agent(demos=...)` in Python, which only Python
    /// can supply again.
    pub demo_file: String,

    /// Environment steps between evaluations \[P-inf, per task\].
    pub eval_period: usize,
    /// Test episodes per evaluation \[P: 20\].
    pub eval_episodes: usize,
    /// Save the online weights every this many steps into `checkpoints/` (0: only at the end) \[OURS\].
    pub checkpoint_every: usize,
    /// Write a full-state snapshot of the run (`snapshot.safetensors`, to resume it exactly) every this many
    /// environment steps, and every this many pre-training updates; 0: only when stopped by SIGTERM/SIGINT
    /// \[OURS: 100000; the sync to disk runs in the background, and what a snapshot costs the run is measured
    /// by `cargo bench --bench snapshot` (figures in the README)\].
    pub snapshot_every: usize,
}

/// Our per-task choices beside the paper's parameters ([`crate::paper::TaskParameters`]): what the paper does not
/// give (a built-in task's come from its entry in the registry, [`crate::env::registry::Schedule`]).
#[derive(Clone, Copy, Debug)]
struct TaskSchedule {
    eval_period: usize,
    learning_starts: usize,
    target_period: usize,
}

/// General defaults for an environment registered at run time ([`crate::env::register`]), e.g. a Gymnasium
/// environment from Python: the paper's Acrobot-like settings with a 1000-step evaluation period \[OURS\].
const EXTERNAL_TASK: (crate::paper::TaskParameters, TaskSchedule) = (
    crate::paper::TaskParameters {
        gamma: 0.99,
        lr: 1e-4,
        train_steps: 100_000,
        n_demo: 200,
        replay_size: 100_000,
        pretrain_steps: 10_000,
        lambda: 1.0,
        t_query_bootstrap: 0.1,
        t_query_noisy: 0.3,
    },
    TaskSchedule {
        eval_period: 1_000,
        learning_starts: 1_000,
        target_period: 1_000,
    },
);

/// General defaults for a task with actions in a box (learned by TD3, [`crate::agent::box_agent`]): TD3's
/// discount and learning rate (Fujimoto et al. 2018), a replay of every step and 1,000 steps before learning
/// starts \[OURS\]. The target networks follow by Polyak averaging, so the target period is unused.
/// The rest (discount, replay size, margin weight, query thresholds, evaluation period) is [`EXTERNAL_TASK`]'s.
const BOX_TASK: (crate::paper::TaskParameters, TaskSchedule) = (
    crate::paper::TaskParameters {
        lr: 1e-3,
        train_steps: 20_000,
        n_demo: 1_000,
        pretrain_steps: 1_000,
        ..EXTERNAL_TASK.0
    },
    TaskSchedule {
        target_period: 1,
        ..EXTERNAL_TASK.1
    },
);

/// The horizon of the critics' n-step target in a task with actions in a box: with 3, the active TD3 with the
/// shipped weak expert held the threshold at the end of every design run on MountainCarContinuous-v0 and
/// LunarLanderContinuous-v3 (5 of 5 each), with 1 on 2 of 5 (docs/algorithm.md §21) \[OURS\].
const BOX_N_STEP: usize = 3;

/// The weight of the behaviour cloning loss (`lambda`) of dqfd and adqnp in a task with actions in a box: with
/// 100 pre-training imitates the demonstrator, with 1 or 10 it does not (docs/algorithm.md §17) \[OURS\].
const BOX_CLONING_WEIGHT: f64 = 100.0;

/// The paper's parameters and our schedule for a Gymnasium id: a built-in task's from its entry in the registry
/// (its row of the paper's table, or [`BOX_TASK`] for actions in a box, with the entry's schedule); an
/// environment registered at run time (from Python) gets [`EXTERNAL_TASK`] ([`BOX_TASK`] for actions in a box).
/// An id that is neither is refused.
fn task_preset(env: &str) -> Result<(crate::paper::TaskParameters, TaskSchedule)> {
    let unknown = |e: crate::env::EnvError| anyhow::anyhow!("{e}");
    let Ok(task) = crate::env::registry::task(env) else {
        return match crate::env::box_spec(env) {
            Ok(_) => Ok(BOX_TASK),
            Err(_) => crate::env::spec(env)
                .map(|_| EXTERNAL_TASK)
                .map_err(unknown),
        };
    };
    let s = task.schedule;
    let base = match s.paper_row {
        Some(row) => *crate::paper::task_parameters(row).ok_or_else(|| {
            anyhow::anyhow!("the registry names the paper's row {row}, which it lacks")
        })?,
        None => BOX_TASK.0,
    };
    let parameters = crate::paper::TaskParameters {
        train_steps: s.train_steps.unwrap_or(base.train_steps),
        ..base
    };
    let schedule = TaskSchedule {
        eval_period: s.eval_period,
        learning_starts: s.learning_starts,
        target_period: s.target_period,
    };
    Ok((parameters, schedule))
}

/// Upper limits of the validated sizes: far beyond any experiment, low enough that a typo cannot ask for more
/// memory or time than a machine has.
const MAX_STEPS: usize = 1_000_000_000;
const MAX_BATCH: usize = 65_536;
const MAX_HEADS: usize = 256;
const MAX_N_STEP: usize = 10_000;
const MAX_WINDOW: usize = 10_000_000;
const MAX_EVAL_EPISODES: usize = 100_000;
const MAX_REPLAY_BYTES: f64 = 16.0 * (1u64 << 30) as f64;

fn format_bytes(bytes: f64) -> String {
    const GIB: f64 = (1u64 << 30) as f64;
    if bytes >= GIB {
        format!("{:.1} GiB", bytes / GIB)
    } else {
        format!("{:.1} MiB", bytes / (1u64 << 20) as f64)
    }
}

/// The keys that name a run rather than tune it: the preset is chosen from them.
const IDENTITY_KEYS: [&str; 4] = ["env", "method", "net", "seed"];

/// The largest config file read (a whole configuration is about 1 KB).
/// The largest seed: a run's configuration is TOML, whose integers are signed 64-bit.
pub const MAX_SEED: u64 = i64::MAX as u64;
/// The config file size limit.
pub(crate) const MAX_CONFIG_BYTES: u64 = 4 << 20;

/// A run's configuration as given (low level): its identity and the values of config files and `--set` pairs
/// in the order given. [`ConfigInput::resolve`] makes the [`TrainConfig`] from it.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigInput {
    env: String,
    method: Method,
    net: NetKind,
    seed: u64,
    /// `(key, value, where it was given)`, later entries winning.
    given: Vec<(String, toml::Value, String)>,
}

impl ConfigInput {
    /// A run of `method` with `net` on `env`, before any value is given.
    pub fn new(env: &str, method: Method, net: NetKind, seed: u64) -> Self {
        Self {
            env: env.to_string(),
            method,
            net,
            seed,
            given: Vec::new(),
        }
    }

    /// The environment id given so far (empty if none was).
    pub fn env(&self) -> &str {
        &self.env
    }

    /// Sets the seed (a command-line flag: every u64 up to [`MAX_SEED`] is checked when resolved).
    pub fn set_seed(&mut self, seed: u64) {
        self.seed = seed;
    }

    /// Takes every key of a TOML file (a run's `config.toml` is one).
    pub fn apply_file(&mut self, path: &Path) -> Result<()> {
        let bytes = crate::files::read_bounded(path, MAX_CONFIG_BYTES).with_context(|| {
            format!(
                "cannot read config file {} (a configuration is a few hundred bytes)",
                path.display()
            )
        })?;
        let text = String::from_utf8(bytes)
            .with_context(|| format!("config file {} is not UTF-8", path.display()))?;
        self.apply_text(&text, path)
    }

    /// Takes every key of a TOML document (the content of the config file `path`, named in errors).
    pub fn apply_text(&mut self, text: &str, path: &Path) -> Result<()> {
        let table: toml::Table = toml::from_str(text)
            .with_context(|| format!("config file {} is not valid TOML", path.display()))?;
        let origin = format!("config file {}", path.display());
        for (key, value) in table {
            self.set_from(&key, value, &origin)
                .with_context(|| format!("in {origin}"))?;
        }
        Ok(())
    }

    /// Takes one `key=value` pair; the value is read as a TOML literal, or as a string if it is not one.
    pub fn apply_override(&mut self, assignment: &str) -> Result<()> {
        let Some((key, raw)) = assignment.split_once('=') else {
            bail!("override '{assignment}' is not of the form key=value");
        };
        let (key, raw) = (key.trim(), raw.trim());
        let value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(raw.to_string()));
        self.set_from(key, value, &format!("--set {assignment}"))
    }

    /// Takes one typed value (a sweep's t_query, a command-line flag).
    pub fn set(&mut self, key: &str, value: impl Into<toml::Value>) -> Result<()> {
        self.set_from(key, value.into(), &format!("`{key}`"))
    }

    fn set_from(&mut self, key: &str, value: toml::Value, origin: &str) -> Result<()> {
        let shown = value.to_string();
        let bad = |e: toml::de::Error| {
            anyhow::anyhow!(
                "bad value {shown} for config key '{key}': {}",
                plain_terms(e.message())
            )
        };
        match key {
            "env" => self.env = value.try_into().map_err(bad)?,
            "method" => self.method = value.try_into().map_err(bad)?,
            "net" => self.net = value.try_into().map_err(bad)?,
            "seed" => self.seed = value.try_into().map_err(bad)?,
            _ if TrainConfig::valid_keys().iter().any(|k| k == key) => {
                self.given
                    .push((key.to_string(), value, origin.to_string()));
            }
            _ => bail!(
                "unknown config key '{key}'; valid keys: {}",
                TrainConfig::valid_keys().join(", ")
            ),
        }
        Ok(())
    }

    /// The resolved, validated configuration: the paper's preset for the task, method and network, then the
    /// given values in order. A value the method does not use (other than the preset's own) is an error.
    pub fn resolve(&self) -> Result<TrainConfig> {
        let preset = TrainConfig::preset(&self.env, self.method, self.net, self.seed)?;
        let boxed = preset.boxed();
        let preset_table = TrainConfig::preset_table(&preset);
        let mut cfg = preset;
        // The learner first: which box settings a run takes depends on it, wherever `algo` stands among the values.
        if boxed
            && let Some((_, toml::Value::String(name), origin)) =
                self.given.iter().rev().find(|(key, ..)| key == "algo")
        {
            cfg.algo = name
                .parse()
                .with_context(|| format!("{origin}: config key `algo`"))?;
        }
        for (key, value, origin) in &self.given {
            debug_assert!(!IDENTITY_KEYS.contains(&key.as_str()));
            let mut table = TrainConfig::preset_table(&cfg);
            // Integers may be given where floats are expected (`lr=1` means 1.0).
            let value = match (&table[key], value) {
                (toml::Value::Float(_), toml::Value::Integer(i)) => toml::Value::Float(*i as f64),
                (_, v) => v.clone(),
            };
            if value != preset_table[key]
                && let Some(why) = unused_by(key, self.method, self.net, boxed, cfg.algo)
            {
                bail!("{origin}: {why}, so `{key}` cannot be set");
            }
            let shown = value.to_string();
            table.insert(key.clone(), value);
            cfg = table.try_into().map_err(|e: toml::de::Error| {
                anyhow::anyhow!(
                    "{origin}: bad value {shown} for config key '{key}': {}",
                    plain_terms(e.message())
                )
            })?;
            // The table gave every box setting its default: those stay unset (and out of config.toml).
            cfg.box_settings = cfg.box_settings.given_only(cfg.lr, cfg.action_dim());
        }
        if let Some(steps) = self.real_time_segment(&cfg.expert) {
            cfg.segment_len = steps;
        }
        cfg.validate()?;
        Ok(cfg)
    }

    /// A person in real time answers for seconds of play: the steps of a question's segment when `expert` (a
    /// spec) is the web expert in real time ([`ExpertSpec::segment_steps`]: its `segment_s` at its `fps`), the
    /// method asks during training and `segment_len` is not given; `None` otherwise (an unreadable spec is
    /// refused by `validate`). [`ConfigInput::resolve`] applies it to the configuration's own expert, a Python
    /// program to its `arld.WebExpert`'s options.
    ///
    /// [`ExpertSpec::segment_steps`]: crate::expert::ExpertSpec::segment_steps
    pub fn real_time_segment(&self, expert: &str) -> Option<usize> {
        if !self.method.queries() || self.given.iter().any(|(key, ..)| key == "segment_len") {
            return None;
        }
        expert
            .parse::<crate::expert::ExpertSpec>()
            .ok()?
            .segment_steps()
    }
}

/// `demo_file` of a run whose demonstrations were given in Python (`arld.Agent(demos=...)`): a record of where
/// they came from, not a path.
pub(crate) const DEMOS_FROM_PYTHON: &str = "python:demos";

/// The paper's hidden widths (docs/algorithm.md §2), also those of a configuration that names none.
fn paper_hidden() -> Vec<usize> {
    vec![HIDDEN, HIDDEN]
}

/// A value-type error of the configuration's reader in the words of a config file (and of Python), not of
/// Rust's types: `expected usize` becomes `expected a whole number (0 or more)`.
fn plain_terms(message: &str) -> String {
    const TERMS: [(&str, &str); 9] = [
        ("expected usize", "expected a whole number (0 or more)"),
        ("expected u64", "expected a whole number (0 or more)"),
        ("expected u32", "expected a whole number (0 or more)"),
        ("expected i64", "expected a whole number"),
        ("expected f64", "expected a number"),
        ("expected f32", "expected a number"),
        ("expected a boolean", "expected true or false"),
        ("expected a sequence", "expected a list"),
        ("floating point", "number"),
    ];
    TERMS
        .iter()
        .fold(message.to_string(), |text, (rust, plain)| {
            text.replace(rust, plain)
        })
}

/// Why a key means nothing for this method and network (`None`: it is used). The preset's value of such a key
/// is inert; giving another value would change nothing, which is always a mistake.
fn unused_by(key: &str, method: Method, net: NetKind, boxed: bool, algo: Algo) -> Option<String> {
    if let Some(owner) = box_setting_owner(key) {
        return match owner {
            _ if !boxed => Some(format!(
                "`{key}` is a setting of the learners of a task with actions in a box (TD3, SAC), and a task \
                 with discrete actions learns with the DQN family"
            )),
            None if key == "uncertainty" && !method.queries() => Some(format!(
                "`uncertainty` chooses what the query rule reads, and {method} does not ask the expert during \
                 training"
            )),
            Some(owner) if owner != algo => Some(format!(
                "`{key}` is a setting of {owner}, and this run learns with {algo} (choose the learner with --algo \
                 or the key `algo`)"
            )),
            _ => None,
        };
    }
    match key {
        "algo" if !boxed => Some(
            "a task with discrete actions learns with the DQN family; `algo` chooses the learner (TD3 or SAC) \
             of a task with actions in a box"
                .to_string(),
        ),
        "margin" | "double_q" | "loss" | "grad_clip" | "l2" | "target_period" | "target_period_in_steps"
            if boxed =>
        {
            Some(
                "a task with actions in a box learns with TD3 or SAC (docs/algorithm.md §15-§17), which have no \
                 large-margin loss, double-Q switch, TD loss choice, gradient clipping or L2 term, and whose target \
                 networks follow by Polyak averaging, not every target period"
                    .to_string(),
            )
        }
        "lambda" if boxed && !method.pretrains() => Some(format!(
            "in a task with actions in a box `lambda` is the cloning weight of the methods that pre-train (dqfd, \
             adqnp); {method} does not clone"
        )),
        "budget"
        | "budget_unit"
        | "segment_len"
        | "queries_from_learning_starts"
        | "query_rule"
            if !method.queries() =>
        {
            Some(format!("{method} does not ask the expert during training"))
        }
        "t_query" if !matches!(method, Method::Bdqn | Method::Adqn | Method::Adqnp) => Some(
            format!("{method} has no query threshold (only bdqn, adqn and adqnp use t_query)"),
        ),
        "n_r" if !matches!(method, Method::Adqn | Method::Adqnp) => Some(format!(
            "{method} keeps no window of uncertainties (only adqn and adqnp do)"
        )),
        "n_demo" | "pretrain_steps" | "demo_file" if !method.pretrains() => {
            Some(format!("{method} does not pre-train on demonstrations"))
        }
        "expert" | "expert_timeout" if !method.needs_expert() => {
            Some(format!("{method} never asks an expert"))
        }
        "heads" if net != NetKind::Bootstrap => {
            Some(format!("a {net} network has no bootstrapped heads"))
        }
        "exact_factorised_var" if net != NetKind::Noisy => {
            Some(format!("a {net} network has no noisy layer"))
        }
        _ => None,
    }
}

impl TrainConfig {
    /// The paper's configuration for `method` with `net` on `env` (docs/algorithm.md §9), before any value
    /// given by the user; [`ConfigInput::resolve`] starts from it.
    pub fn preset(env: &str, method: Method, net: NetKind, seed: u64) -> Result<Self> {
        ensure!(
            seed <= MAX_SEED,
            "seed {seed} is too large for the field `seed`: at most {MAX_SEED} (the largest integer a config \
             file holds)"
        );
        let (p, schedule) = task_preset(env)?;
        let boxed = crate::env::box_spec(env).is_ok();
        ensure!(
            !boxed || net == NetKind::Bootstrap,
            "{env} has actions in a box: its learners (TD3, SAC) have an ensemble of critic heads (config key \
             `heads`), neither a noisy layer nor a single plain output, so --net {net} would change nothing but \
             the query threshold; leave --net at bootstrap (the critics' heads) and choose the learner with --algo"
        );
        // A task with actions in a box is learned by TD3 (or SAC): one-step returns, two critic heads, batches
        // of 128 from a uniform replay (docs/algorithm.md §18), uniform actions before learning starts (as
        // Stable-Baselines3's TD3) \[OURS\].
        let t_query = match net {
            NetKind::Noisy => p.t_query_noisy,
            _ => p.t_query_bootstrap,
        };
        // ADQNP: half the demonstrations for pre-training and half the budget [P].
        let (n_demo, budget) = match method {
            Method::Dqn => (0, 0),
            Method::Dqfd => (p.n_demo, 0),
            Method::Gdqn | Method::Bdqn | Method::Adqn => (0, p.n_demo),
            Method::Adqnp => (p.n_demo / 2, p.n_demo / 2),
        };
        Ok(Self {
            env: env.to_string(),
            method,
            net,
            seed,
            gamma: p.gamma,
            lr: p.lr,
            train_steps: p.train_steps,
            replay_size: p.replay_size,
            batch_size: if boxed { 128 } else { 32 },
            learning_starts: schedule.learning_starts,
            train_freq: 1,
            target_period: schedule.target_period,
            heads: if boxed { 2 } else { 10 },
            hidden: paper_hidden(),
            loss: TdLoss::Mse,
            double_q: true,
            grad_clip: 10.0,
            timeout_as_terminal: false,
            eps_start: 0.9,
            eps_end: 0.01,
            eps_fraction: 0.1,
            eps_greedy_on_top: true,
            prioritized: !boxed,
            alpha: 0.6,
            beta0: 0.4,
            eps_agent: 0.001,
            eps_demo: 1.0,
            margin: 0.8,
            // In a box task the weight of the cloning loss of the methods that pre-train (§17: 100 imitates).
            lambda: if boxed && method.pretrains() {
                BOX_CLONING_WEIGHT
            } else {
                p.lambda
            },
            lambda_n: 0.0,
            // Box tasks: three-step returns as the critics' target, which keep what the active TD3 learns on the
            // design seeds (docs/algorithm.md §21) \[OURS\].
            n_step: if boxed { BOX_N_STEP } else { 10 },
            l2: 0.0,
            n_demo,
            pretrain_steps: if method.pretrains() {
                p.pretrain_steps
            } else {
                0
            },
            budget,
            budget_unit: BudgetUnit::Transitions,
            queries_from_learning_starts: false,
            random_before_learning: boxed,
            algo: Algo::Td3,
            box_settings: BoxSettings::default(),
            target_period_in_steps: false,
            t_query,
            n_r: 1000,
            query_rule: String::new(),
            segment_len: 5,
            exact_factorised_var: false,
            expert: "shipped:weak".to_string(),
            expert_timeout: crate::expert::process::DEFAULT_TIMEOUT_S,
            demo_file: String::new(),
            eval_period: schedule.eval_period,
            eval_episodes: 20,
            checkpoint_every: 0,
            snapshot_every: 100_000,
        })
    }

    /// Names of every configuration key.
    pub fn valid_keys() -> Vec<String> {
        Self::preset_table(
            &Self::preset("CartPole-v0", Method::Dqn, NetKind::Plain, 0)
                .expect("CartPole preset exists"),
        )
        .keys()
        .cloned()
        .collect()
    }

    /// The keys a configuration file leaves out at their default (false), so that the files of runs that do
    /// not use them stay as they were before the keys existed.
    fn omitted_at_default(&self) -> Vec<(&'static str, toml::Value)> {
        let action_dim = self.action_dim();
        let mut keys = vec![
            ("random_before_learning", self.random_before_learning.into()),
            ("target_period_in_steps", self.target_period_in_steps.into()),
            ("algo", self.algo.name().into()),
        ];
        keys.extend(self.box_settings.values(self.lr, action_dim));
        keys
    }

    /// The configuration as JSON with every key, also those a configuration file leaves out at their default
    /// (for the Python package, whose configuration dicts hold every key).
    pub fn to_json(&self) -> String {
        let mut value = serde_json::to_value(self).expect("config serialises");
        if let Some(map) = value.as_object_mut() {
            for (key, set) in self.omitted_at_default() {
                let set = serde_json::to_value(set).expect("a config value serialises");
                map.entry(key).or_insert(set);
            }
        }
        value.to_string()
    }

    /// Every key and its value (also those a configuration file leaves out).
    fn preset_table(cfg: &Self) -> toml::Table {
        let mut table = toml::Table::try_from(cfg).expect("config serialises");
        for (key, set) in cfg.omitted_at_default() {
            table.entry(key).or_insert(set);
        }
        table
    }

    /// The configuration as TOML, for the run directory. A task with actions in a box records its learner
    /// (`algo`) also when it is TD3, whose name serde leaves out (so that the files of discrete runs stay as they
    /// were): it is written where serde writes it for SAC, before `prioritized`.
    pub fn to_toml(&self) -> String {
        let text = toml::to_string_pretty(self).expect("config serialises");
        if !self.boxed() || !self.algo.is_td3() {
            return text;
        }
        match text.find("\nprioritized = ") {
            Some(at) => format!("{}\nalgo = \"td3\"{}", &text[..at], &text[at..]),
            None => text,
        }
    }

    /// The keys whose values differ between `self` and `other`, each as `key = <self's> (<other's>)`, in key
    /// order.
    pub fn differences(&self, other: &TrainConfig) -> Vec<String> {
        let (a, b) = (Self::preset_table(self), Self::preset_table(other));
        let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
        keys.sort();
        keys.dedup();
        let shown = |v: Option<&toml::Value>| v.map_or("(none)".to_string(), |v| v.to_string());
        keys.into_iter()
            .filter(|k| a.get(*k) != b.get(*k))
            .map(|k| format!("{k} = {} ({})", shown(a.get(k)), shown(b.get(k))))
            .collect()
    }

    /// Checks every value: the one place a run's configuration is validated (called by
    /// [`ConfigInput::resolve`]). Limits on sizes keep a typo from asking for more memory than a machine has.
    pub fn validate(&self) -> Result<()> {
        let env = crate::env::task_spec(&self.env).map_err(|e| anyhow::anyhow!("{e}"))?;
        self.check_learning()?;
        self.check_exploration_and_replay()?;
        self.check_losses()?;
        self.check_demonstrations()?;
        self.check_query_rule()?;
        self.check_expert()?;
        // Evaluation and checkpoints.
        count("eval_period", self.eval_period, MAX_STEPS)?;
        count("eval_episodes", self.eval_episodes, MAX_EVAL_EPISODES)?;
        self.check_memory(env.obs_dim())
    }

    /// The learning settings: discount, learning rate, steps, batches, target copies, the network's shape.
    fn check_learning(&self) -> Result<()> {
        unit("gamma", self.gamma)?;
        positive("lr", self.lr)?;
        count("train_steps", self.train_steps, MAX_STEPS)?;
        count("batch_size", self.batch_size, MAX_BATCH)?;
        ensure!(
            self.learning_starts <= MAX_STEPS,
            "learning_starts must be at most {MAX_STEPS}, got {}",
            self.learning_starts
        );
        count("train_freq", self.train_freq, MAX_STEPS)?;
        count("target_period", self.target_period, MAX_STEPS)?;
        count("heads", self.heads, MAX_HEADS)?;
        ensure!(
            (1..=MAX_DEPTH).contains(&self.hidden.len())
                && self.hidden.iter().all(|w| (1..=MAX_HIDDEN).contains(w)),
            "hidden must give the widths of the network's hidden layers, 1 to {MAX_DEPTH} layers each between 1 \
             and {MAX_HIDDEN} wide (e.g. [256, 256] or [64, 64, 64]), got {:?}",
            self.hidden
        );
        positive("grad_clip", self.grad_clip)?;
        self.box_settings.validate()
    }

    /// The ε schedule, and the replay memory (which checks its own settings: α, the priority bonuses ε).
    fn check_exploration_and_replay(&self) -> Result<()> {
        unit("eps_start", self.eps_start)?;
        unit("eps_end", self.eps_end)?;
        unit("eps_fraction", self.eps_fraction)?;
        self.replay_config().validate()?;
        unit("beta0", self.beta0)?;
        ensure!(
            self.replay_size >= self.batch_size,
            "replay_size must be at least batch_size ({}), got {}",
            self.batch_size,
            self.replay_size
        );
        Ok(())
    }

    /// The losses' weights and the n-step return.
    fn check_losses(&self) -> Result<()> {
        non_negative("margin", self.margin)?;
        non_negative("lambda", self.lambda)?;
        non_negative("lambda_n", self.lambda_n)?;
        count("n_step", self.n_step, MAX_N_STEP)?;
        ensure!(
            self.lambda_n == 0.0 || !self.boxed(),
            "lambda_n weighs the DQN family's extra n-step loss, which TD3 and SAC do not have: in {} (actions in \
             a box) n_step > 1 makes the n-step return the critics' target instead; leave lambda_n at 0",
            self.env
        );
        non_negative("l2", self.l2)
    }

    /// Pre-training and its demonstrations, and the query window.
    fn check_demonstrations(&self) -> Result<()> {
        ensure!(
            self.pretrain_steps <= MAX_STEPS,
            "pretrain_steps must be at most {MAX_STEPS}, got {}",
            self.pretrain_steps
        );
        if self.method.pretrains() {
            ensure!(
                self.n_demo > 0 || !self.demo_file.is_empty(),
                "{} pre-trains on demonstrations: n_demo must be positive",
                self.method
            );
        }
        count("n_r", self.n_r, MAX_WINDOW)
    }

    /// The query rule and its controller (they own t_query, N_r and the segment length): the signals the rule
    /// reads must be ones this network and task give.
    fn check_query_rule(&self) -> Result<()> {
        let rule = self
            .query_rule()
            .context("config key `query_rule` (or the method's own rule)")?;
        let risk = match crate::env::box_spec(&self.env) {
            Ok(spec) => spec.goal.check(spec.id),
            Err(_) => Err(format!(
                "{} has discrete actions, and the risk critic is built for the learners of actions in a box \
                 (TD3, SAC)",
                self.env
            )),
        };
        check_signals(
            &*rule,
            self.net != NetKind::Plain,
            self.net == NetKind::Bootstrap,
            risk,
        )
        .map_err(|e| match e {
            QueryError::NoUncertaintySource { .. } if self.query_rule.is_empty() => anyhow::anyhow!(
                "{e} (the {} method needs an uncertainty estimate, which a plain network does not have: \
                 use --net bootstrap (divergence) or --net noisy (variance))",
                self.method
            ),
            e => e.into(),
        })?;
        self.query_controller()?;
        Ok(())
    }

    /// The expert a method needs (one that can demonstrate, when the method pre-trains on its demonstrations),
    /// and how long it may take to answer.
    fn check_expert(&self) -> Result<()> {
        if self.method.needs_expert() {
            ensure!(
                !self.expert.trim().is_empty(),
                "{} needs an expert: `expert` must not be empty; give one with --expert (shipped:weak, the \
                 preset's, or scripted, checkpoint:PATH, cmd:COMMAND, web: `arld expert eval --help` lists them)",
                self.method
            );
            let spec: crate::expert::ExpertSpec = self
                .expert
                .parse()
                .context("config key `expert` is not an expert spec")?;
            ensure!(
                !self.method.pretrains() || !self.demo_file.is_empty() || spec.demonstrates(),
                "{} pre-trains on demonstrations collected from the expert before training, which the expert \
                 `{}` cannot give (it answers queries during training only): give them with --demos FILE \
                 (`demo_file`)",
                self.method,
                self.expert
            );
        }
        let max_timeout = crate::expert::process::MAX_TIMEOUT_S;
        ensure!(
            self.expert_timeout.is_finite()
                && self.expert_timeout > 0.0
                && self.expert_timeout <= max_timeout,
            "expert_timeout must be a positive number of seconds, at most {max_timeout} (a year), got {}",
            self.expert_timeout
        );
        Ok(())
    }

    /// Memory: the replay memory, allocated whole at the start for observations of `obs_dim` values.
    fn check_memory(&self, obs_dim: usize) -> Result<()> {
        let bytes = self.replay_config().memory_bytes(obs_dim);
        ensure!(
            bytes <= MAX_REPLAY_BYTES,
            "replay_size {} with {} demonstration slots (n_demo + budget) would need {} of memory for the \
             replay memory; the limit is {}",
            self.replay_size,
            self.replay_config().demo_capacity,
            format_bytes(bytes),
            format_bytes(MAX_REPLAY_BYTES)
        );
        ensure!(
            self.replay_size <= MAX_STEPS && self.budget <= MAX_STEPS && self.n_demo <= MAX_STEPS,
            "replay_size, budget and n_demo must be at most {MAX_STEPS} transitions"
        );
        Ok(())
    }

    /// The run's query rule spec: `query_rule` if given, else the method's (§8–9): never (DQN, DQfD), greedy
    /// (GDQN), Bernoulli with probability `t_query` (BDQN), adaptive with threshold `t_query` over `n_r` steps
    /// (ADQN, ADQNP).
    pub(crate) fn rule_spec(&self) -> Result<RuleSpec, QueryError> {
        if !self.query_rule.trim().is_empty() {
            return self.query_rule.parse();
        }
        let name = match self.method {
            Method::Dqn | Method::Dqfd => "never",
            Method::Gdqn => "greedy",
            Method::Bdqn => "bernoulli",
            Method::Adqn | Method::Adqnp => "adaptive",
        };
        name.parse()
    }

    /// What the rule's parameters default to: this run's t_query, N_r, budget, segment length and length.
    pub(crate) fn rule_defaults(&self) -> RuleDefaults {
        RuleDefaults {
            t_query: self.t_query,
            n_r: self.n_r,
            budget: self.budget,
            segment_len: self.segment_len,
            train_steps: self.train_steps,
            unit: self.budget_unit,
        }
    }

    /// The run's query rule, built from `Self::rule_spec`.
    pub fn query_rule(&self) -> Result<Box<dyn QueryRule>, QueryError> {
        self.rule_spec()?.build(&self.rule_defaults())
    }

    /// The query rule under the run's budget and segment length.
    pub(crate) fn query_controller(&self) -> Result<QueryController, QueryError> {
        Ok(
            QueryController::new(self.query_rule()?, self.budget, self.segment_len)?
                .counting(self.budget_unit),
        )
    }

    /// The most demonstrated transitions queries can bring during training (the budget, converted when it counts
    /// queries).
    pub(crate) fn query_transitions(&self) -> usize {
        self.budget_unit
            .max_transitions(self.budget, self.segment_len)
    }

    /// Demonstrations that enter replay before training: the pre-training set.
    pub(crate) fn pretrain_demos(&self) -> usize {
        if self.method.pretrains() {
            self.n_demo
        } else {
            0
        }
    }

    /// The replay memory's part of the configuration; its permanent demonstration part holds the pre-training
    /// demonstrations and the budget of queried ones.
    pub fn replay_config(&self) -> ReplayConfig {
        ReplayConfig {
            capacity: self.replay_size,
            demo_capacity: self
                .pretrain_demos()
                .saturating_add(self.query_transitions()),
            prioritized: self.prioritized,
            alpha: self.alpha as f32,
            eps_agent: self.eps_agent as f32,
            eps_demo: self.eps_demo as f32,
            // DQfD's optional n-step loss needs each transition's n-step return; the actor-critic learners of a
            // box task take the n-step return as their critics' target when `n_step` > 1 (§17). With one step
            // the memory keeps none, and their target is the one-step one.
            n_step: if self.lambda_n > 0.0 || (self.n_step > 1 && self.boxed()) {
                self.n_step
            } else {
                0
            },
            gamma: self.gamma as f32,
        }
    }

    /// Whether the run's task has actions in a box (learned by TD3 or SAC).
    pub fn boxed(&self) -> bool {
        crate::env::box_spec(&self.env).is_ok()
    }

    /// The dimension of a box task's actions (1 for a discrete task, whose box settings are unused).
    fn action_dim(&self) -> usize {
        crate::env::box_spec(&self.env).map_or(1, |spec| spec.action_low.len())
    }

    /// The agent's part of the configuration.
    pub fn dqn_agent_config(&self) -> DqnAgentConfig {
        DqnAgentConfig {
            output: match self.net {
                NetKind::Plain => OutputKind::Plain,
                NetKind::Bootstrap => OutputKind::Bootstrap { heads: self.heads },
                NetKind::Noisy => OutputKind::Noisy,
            },
            hidden: self.hidden_widths(),
            batch_size: self.batch_size,
            lr: self.lr as f32,
            gamma: self.gamma as f32,
            loss: self.loss,
            double_q: self.double_q,
            grad_clip: self.grad_clip as f32,
            margin: self.margin as f32,
            lambda: self.lambda as f32,
            lambda_n: self.lambda_n as f32,
            l2: self.l2 as f32,
            exact_factorised_var: self.exact_factorised_var,
        }
    }

    /// The hidden widths of `hidden`. [`Self::validate`] checks them; a configuration read without that check
    /// (a snapshot's own) gets the paper's widths for a malformed value, so that loading its weights fails on
    /// their sizes instead of the network being built with impossible ones.
    pub(crate) fn hidden_widths(&self) -> HiddenLayers {
        HiddenLayers::new(&self.hidden)
            .filter(|h| h.iter().all(|w| (1..=MAX_HIDDEN).contains(w)))
            .or_else(|| HiddenLayers::new(&[HIDDEN, HIDDEN]))
            .expect("the paper's two widths")
    }

    /// The demonstration file the run pre-trains on (`demo_file`), if it names one; an error for demonstrations
    /// that were given in Python ([`DEMOS_FROM_PYTHON`]), which a run outside Python cannot read again.
    pub(crate) fn demo_path(&self) -> Result<Option<&std::path::Path>> {
        match self.demo_file.as_str() {
            "" => Ok(None),
            DEMOS_FROM_PYTHON => anyhow::bail!(
                "this run pre-trained on demonstrations given in Python (demo_file = \"{DEMOS_FROM_PYTHON}\"): \
                 continue it from Python with the same demos=, or give a demonstration file (--demos FILE)"
            ),
            path => Ok(Some(std::path::Path::new(path))),
        }
    }

    /// The expert the run asks (`expert`): during training, or for the demonstrations it pre-trains on unless
    /// they come from `demo_file`; `None` when it asks none.
    pub fn expert_used(&self) -> Option<&str> {
        let asks = self.method.queries() || (self.method.pretrains() && self.demo_file.is_empty());
        asks.then_some(self.expert.as_str())
    }

    /// A short name for the run directory: `CartPole-v0_adqn-bootstrap_seed3`; in a task with actions in a box
    /// the learner stands where the network's output stage does (`Pendulum-v1_adqn-sac_seed3`).
    pub fn run_name(&self) -> String {
        let learner = if self.boxed() {
            self.algo.name()
        } else {
            self.net.name()
        };
        format!("{}_{}-{learner}_seed{}", self.env, self.method, self.seed)
    }
}

/// A value in [0, 1].
fn unit(name: &str, v: f64) -> Result<()> {
    ensure!(
        (0.0..=1.0).contains(&v),
        "{name} must be in [0, 1], got {v}"
    );
    Ok(())
}

/// A non-negative finite value.
fn non_negative(name: &str, v: f64) -> Result<()> {
    ensure!(
        v >= 0.0 && v.is_finite(),
        "{name} must be non-negative and finite, got {v}"
    );
    Ok(())
}

/// A positive finite value.
fn positive(name: &str, v: f64) -> Result<()> {
    ensure!(
        v > 0.0 && v.is_finite(),
        "{name} must be positive and finite, got {v}"
    );
    Ok(())
}

/// A count between 1 and `max`.
fn count(name: &str, v: usize, max: usize) -> Result<()> {
    ensure!(
        (1..=max).contains(&v),
        "{name} must be between 1 and {max}, got {v}"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// In a box task `n_step` > 1 makes the replay keep n-step returns (which TD3 and SAC take as their target),
    /// `n_step` = 1 keeps none; in a discrete task only the n-step loss (`lambda_n` > 0) needs them. lambda_n is
    /// refused for a box task, with its reason.
    #[test]
    fn n_step_acts_for_box_learners_and_lambda_n_is_refused_there() {
        let box_run =
            |sets: &[&str]| resolve("Pendulum-v1", Method::Adqn, NetKind::Bootstrap, sets);
        assert_eq!(box_run(&["n_step=3"]).unwrap().replay_config().n_step, 3);
        assert_eq!(box_run(&["n_step=1"]).unwrap().replay_config().n_step, 0);
        // The box preset: three-step returns (docs/algorithm.md §21).
        assert_eq!(box_run(&[]).unwrap().replay_config().n_step, BOX_N_STEP);
        let err = format!("{:#}", box_run(&["lambda_n=0.5"]).unwrap_err());
        assert!(err.contains("lambda_n") && err.contains("n-step"), "{err}");
        let discrete =
            |sets: &[&str]| resolve("CartPole-v0", Method::Dqfd, NetKind::Bootstrap, sets);
        assert_eq!(discrete(&["n_step=3"]).unwrap().replay_config().n_step, 0);
        assert_eq!(
            discrete(&["n_step=3", "lambda_n=1"])
                .unwrap()
                .replay_config()
                .n_step,
            3
        );
    }

    fn resolve(env: &str, method: Method, net: NetKind, sets: &[&str]) -> Result<TrainConfig> {
        let mut input = ConfigInput::new(env, method, net, 0);
        for s in sets {
            input.apply_override(s)?;
        }
        input.resolve()
    }

    /// A real-time person's question lasts seconds of play: `segment_len` follows the web expert's `segment_s`
    /// (3 s by default) at its `fps` unless it is given; turn-based and other experts keep the preset's 5 steps;
    /// the config.toml written and read back gives the same segment.
    #[test]
    fn a_real_time_web_expert_sets_the_segment_in_seconds_unless_segment_len_is_given() {
        let len = |sets: &[&str]| {
            resolve("CartPole-v0", Method::Adqn, NetKind::Bootstrap, sets)
                .unwrap()
                .segment_len
        };
        assert_eq!(len(&[]), 5);
        assert_eq!(len(&["expert=\"web\""]), 5);
        assert_eq!(len(&["expert=\"web:fps=20\""]), 60);
        assert_eq!(len(&["expert=\"web:fps=40,segment_s=0.5\""]), 20);
        assert_eq!(len(&["expert=\"web:fps=20\"", "segment_len=7"]), 7);
        // Given at the preset's own value, it is given all the same.
        assert_eq!(len(&["segment_len=5", "expert=\"web:fps=20\""]), 5);
        // A method that never asks has no segment to set (and refuses `segment_len` given).
        let sets = ["expert=\"web:fps=20\"", "demo_file=\"d.csv\""];
        let dqfd = resolve("CartPole-v0", Method::Dqfd, NetKind::Plain, &sets).unwrap();
        assert_eq!(dqfd.segment_len, 5);
        let sets = ["expert=\"web:fps=20,segment_s=2\""];
        let cfg = resolve("Pendulum-v1", Method::Adqn, NetKind::Bootstrap, &sets).unwrap();
        assert_eq!(cfg.segment_len, 40);
        let mut again = ConfigInput::new("Pendulum-v1", Method::Adqn, NetKind::Bootstrap, 0);
        again
            .apply_text(&cfg.to_toml(), Path::new("config.toml"))
            .unwrap();
        assert_eq!(again.resolve().unwrap(), cfg);
    }

    /// The learner of a box task: recorded in config.toml (also TD3, which serde leaves out elsewhere) and read
    /// back to the same configuration; TD3's and SAC's own settings are keys with their learners' defaults, set
    /// for the one and refused for the other, and for discrete tasks; `algo` on a discrete task and a network
    /// other than the critics' heads on a box task are refused with the reason.
    #[test]
    fn box_learners_and_their_settings_are_keys_of_their_own() {
        let td3 = resolve("Pendulum-v1", Method::Adqn, NetKind::Bootstrap, &[]).unwrap();
        let text = td3.to_toml();
        assert!(text.contains("\nalgo = \"td3\"\nprioritized = "), "{text}");
        let mut again = ConfigInput::new("Pendulum-v1", Method::Adqn, NetKind::Bootstrap, 0);
        again.apply_text(&text, Path::new("config.toml")).unwrap();
        assert_eq!(again.resolve().unwrap(), td3);
        let discrete = resolve("CartPole-v0", Method::Adqn, NetKind::Bootstrap, &[]).unwrap();
        assert!(!discrete.to_toml().contains("algo"));
        assert_eq!(td3.run_name(), "Pendulum-v1_adqn-td3_seed0");
        assert_eq!(discrete.run_name(), "CartPole-v0_adqn-bootstrap_seed0");

        // TD3's defaults are the learner's own, SAC's target entropy is -dim(A) of the task.
        let table = TrainConfig::preset_table(&td3);
        assert_eq!(table["policy_delay"], toml::Value::Integer(2));
        assert_eq!(table["tau"], toml::Value::Float(0.005));
        let lander = resolve(
            "LunarLanderContinuous-v3",
            Method::Dqn,
            NetKind::Bootstrap,
            &[],
        )
        .unwrap();
        assert_eq!(
            TrainConfig::preset_table(&lander)["target_entropy"],
            toml::Value::Float(-2.0)
        );

        let set = resolve(
            "Pendulum-v1",
            Method::Adqn,
            NetKind::Bootstrap,
            &["policy_delay=3", "exploration_noise=0.2", "tau=0.01"],
        )
        .unwrap();
        assert_eq!(set.box_settings.policy_delay, Some(3));
        assert_eq!(set.box_settings.tau, Some(0.01));
        let text = set.to_toml();
        assert!(text.contains("policy_delay = 3"), "{text}");
        // The uncertainty the rule reads: written when chosen, left out at its default, refused where nothing
        // reads it.
        let chosen = |sets: &[&str]| {
            resolve("Pendulum-v1", Method::Adqn, NetKind::Bootstrap, sets)
                .unwrap()
                .to_toml()
        };
        let text = chosen(&["uncertainty=\"action_disagreement\""]);
        assert!(
            text.contains("uncertainty = \"action_disagreement\""),
            "{text}"
        );
        let text = chosen(&["uncertainty=\"critic_variance\""]);
        assert!(!text.contains("uncertainty"), "{text}");
        for silent in [Method::Dqn, Method::Dqfd] {
            let sets = ["uncertainty=\"action_disagreement\""];
            let e = error("Pendulum-v1", silent, NetKind::Bootstrap, &sets);
            assert!(e.contains("does not ask the expert"), "{silent}: {e}");
        }
        // `algo` wins wherever it stands: SAC's keys after or before it.
        let sac = resolve(
            "Pendulum-v1",
            Method::Adqn,
            NetKind::Bootstrap,
            &["target_entropy=-0.5", "algo=\"sac\""],
        )
        .unwrap();
        assert_eq!(
            (sac.algo, sac.box_settings.target_entropy),
            (Algo::Sac, Some(-0.5))
        );
        assert_eq!(sac.run_name(), "Pendulum-v1_adqn-sac_seed0");

        let refused = |env: &str, net: NetKind, sets: &[&str], needle: &str| {
            let e = error(env, Method::Adqn, net, sets);
            assert!(e.contains(needle), "{sets:?}: {e}");
        };
        refused(
            "Pendulum-v1",
            NetKind::Bootstrap,
            &["algo=\"sac\"", "policy_delay=3"],
            "setting of td3",
        );
        refused(
            "Pendulum-v1",
            NetKind::Bootstrap,
            &["target_entropy=-0.5"],
            "setting of sac",
        );
        refused(
            "CartPole-v0",
            NetKind::Bootstrap,
            &["tau=0.01"],
            "DQN family",
        );
        refused(
            "CartPole-v0",
            NetKind::Bootstrap,
            &["algo=\"sac\""],
            "DQN family",
        );
        refused("Pendulum-v1", NetKind::Noisy, &[], "critics' heads");
        refused("Pendulum-v1", NetKind::Plain, &[], "critics' heads");
        refused(
            "Pendulum-v1",
            NetKind::Bootstrap,
            &["tau=0"],
            "tau must be in (0, 1]",
        );
        refused(
            "Pendulum-v1",
            NetKind::Bootstrap,
            &["policy_delay=0"],
            "policy_delay",
        );
    }

    fn error(env: &str, method: Method, net: NetKind, sets: &[&str]) -> String {
        format!("{:#}", resolve(env, method, net, sets).unwrap_err())
    }

    /// The errors of CartPole-v0 with `method` and `net` and each override of `cases`, each checked to contain
    /// the words paired with its override.
    fn errors_saying(method: Method, net: NetKind, cases: &[(&str, &str)]) -> Vec<String> {
        errors_in("CartPole-v0", method, net, cases)
    }

    /// [`errors_saying`] on the task `env`.
    fn errors_in(env: &str, method: Method, net: NetKind, cases: &[(&str, &str)]) -> Vec<String> {
        cases
            .iter()
            .map(|&(set, words)| {
                let err = error(env, method, net, &[set]);
                assert!(err.contains(words), "{set}: {err}");
                err
            })
            .collect()
    }

    /// In a task with actions in a box the keys of the DQN family's learner are refused when set, with the reason
    /// and the key named, and `lambda` is the cloning weight of the methods that pre-train only; set to their
    /// preset values they pass, as a run's own config.toml gives them.
    #[test]
    fn keys_box_learners_do_not_read_are_refused_in_box_tasks() {
        let box_keys = [
            "margin=0.5",
            "double_q=false",
            "loss=\"huber\"",
            "grad_clip=1.0",
            "l2=0.001",
            "target_period=100",
            "target_period_in_steps=true",
        ];
        let cases: Vec<(&str, &str)> = box_keys.iter().map(|&set| (set, "TD3 or SAC")).collect();
        for (err, (set, _)) in errors_in("Pendulum-v1", Method::Adqn, NetKind::Bootstrap, &cases)
            .iter()
            .zip(&cases)
        {
            let key = set.split('=').next().unwrap();
            assert!(err.contains(&format!("`{key}` cannot be set")), "{err}");
        }
        errors_in(
            "Pendulum-v1",
            Method::Adqn,
            NetKind::Bootstrap,
            &[("lambda=5", "adqn does not clone")],
        );
        let cfg = resolve(
            "Pendulum-v1",
            Method::Dqfd,
            NetKind::Bootstrap,
            &["lambda=5"],
        )
        .unwrap();
        assert_eq!(cfg.lambda, 5.0);
        // The discrete tasks keep them.
        for set in box_keys {
            resolve("CartPole-v0", Method::Adqn, NetKind::Bootstrap, &[set]).unwrap();
        }
        // Preset values pass in a box task (a run's config.toml lists every key).
        let preset =
            TrainConfig::preset("Pendulum-v1", Method::Adqn, NetKind::Bootstrap, 0).unwrap();
        let own = format!("margin={}", preset.margin);
        resolve("Pendulum-v1", Method::Adqn, NetKind::Bootstrap, &[&own]).unwrap();
    }

    #[test]
    fn fixed_names_agree_with_serde_clap_display_and_from_str() {
        use clap::ValueEnum;
        fn check<T>(all: &[T], name: fn(T) -> &'static str)
        where
            T: Copy
                + PartialEq
                + fmt::Debug
                + fmt::Display
                + std::str::FromStr
                + Serialize
                + ValueEnum,
        {
            assert_eq!(all.len(), T::value_variants().len());
            for &v in all {
                let n = name(v);
                assert_eq!(v.to_string(), n);
                assert!(n.parse::<T>().ok() == Some(v));
                assert_eq!(serde_json::to_string(&v).unwrap(), format!("\"{n}\""));
                assert_eq!(v.to_possible_value().unwrap().get_name(), n);
            }
        }
        check(&Method::ALL, Method::name);
        check(&NetKind::ALL, NetKind::name);
        assert_eq!(
            format!("{:#}", "dqn2".parse::<Method>().unwrap_err()),
            "unknown method 'dqn2'; known: dqn, dqfd, gdqn, bdqn, adqn, adqnp"
        );
        assert_eq!(
            format!("{:#}", "big".parse::<NetKind>().unwrap_err()),
            "unknown network 'big'; known: plain, bootstrap, noisy"
        );
    }

    #[test]
    fn presets_follow_the_paper_table() {
        let c = TrainConfig::preset("Acrobot-v1", Method::Adqnp, NetKind::Noisy, 1).unwrap();
        assert_eq!(
            (c.gamma, c.lr, c.train_steps, c.replay_size),
            (0.99, 1e-4, 200_000, 100_000)
        );
        assert_eq!((c.n_demo, c.budget, c.pretrain_steps), (50, 50, 10_000));
        assert_eq!(c.t_query, 0.3);
        let c = TrainConfig::preset("CartPole-v0", Method::Adqn, NetKind::Noisy, 1).unwrap();
        assert_eq!((c.budget, c.n_demo, c.t_query), (200, 0, 0.5));
        assert_eq!(c.rule_spec().unwrap().to_string(), "adaptive");
        assert_eq!(c.rule_defaults().t_query, 0.5);
    }

    #[test]
    fn the_query_rule_follows_the_method_and_bernoulli_p_follows_t_query() {
        let rule = |m| {
            resolve("CartPole-v0", m, NetKind::Bootstrap, &[])
                .unwrap()
                .query_rule()
                .unwrap()
                .name()
        };
        assert_eq!(rule(Method::Dqn), "never");
        assert_eq!(rule(Method::Dqfd), "never");
        assert_eq!(rule(Method::Gdqn), "greedy");
        assert_eq!(rule(Method::Adqn), "adaptive");
        let bdqn = resolve(
            "CartPole-v0",
            Method::Bdqn,
            NetKind::Bootstrap,
            &["t_query=0.2"],
        )
        .unwrap();
        assert_eq!(bdqn.query_rule().unwrap().name(), "bernoulli");
        assert_eq!(bdqn.rule_defaults().t_query, 0.2);
        // query_rule replaces the method's rule; a querying method only; the network must give its signals.
        let paced = resolve(
            "CartPole-v0",
            Method::Adqn,
            NetKind::Bootstrap,
            &["query_rule=paced(horizon=0.5)"],
        )
        .unwrap();
        assert_eq!(paced.query_rule().unwrap().name(), "paced");
        for (method, net, set, says) in [
            (
                Method::Dqn,
                NetKind::Bootstrap,
                "query_rule=paced",
                "does not ask",
            ),
            (
                Method::Adqn,
                NetKind::Bootstrap,
                "query_rule=nope",
                "unknown query rule",
            ),
            (
                Method::Adqn,
                NetKind::Noisy,
                "query_rule=rcmp",
                "bootstrapped",
            ),
            (
                Method::Adqn,
                NetKind::Plain,
                "query_rule=calibrated",
                "no uncertainty",
            ),
            (
                Method::Adqn,
                NetKind::Bootstrap,
                "query_rule=paced(x=1)",
                "no parameter 'x'",
            ),
        ] {
            let err = format!(
                "{:#}",
                resolve("CartPole-v0", method, net, &[set]).unwrap_err()
            );
            assert!(err.contains(says), "{set}: {err}");
        }
    }

    #[test]
    fn overrides_parse_typed_values() {
        let c = resolve(
            "CartPole-v0",
            Method::Dqn,
            NetKind::Plain,
            &[
                "lr=0.001",
                "train_steps=5000",
                "prioritized=false",
                "loss=huber",
                "gamma=1",
            ],
        )
        .unwrap();
        assert_eq!(
            (c.lr, c.train_steps, c.prioritized, c.loss, c.gamma),
            (0.001, 5000, false, TdLoss::Huber, 1.0)
        );
    }

    #[test]
    fn identity_keys_choose_the_preset() {
        let c = resolve(
            "CartPole-v0",
            Method::Dqn,
            NetKind::Plain,
            &["method=adqnp", "net=noisy"],
        )
        .unwrap();
        assert_eq!(
            (c.method, c.net, c.n_demo, c.budget),
            (Method::Adqnp, NetKind::Noisy, 100, 100)
        );
        assert_eq!(c.query_rule().unwrap().name(), "adaptive");
    }

    #[test]
    fn unknown_key_lists_valid_keys() {
        let err = error(
            "CartPole-v0",
            Method::Dqn,
            NetKind::Plain,
            &["learning_rate=0.1"],
        );
        assert!(err.contains("unknown config key 'learning_rate'"), "{err}");
        assert!(err.contains("lr") && err.contains("t_query"), "{err}");
        // The query rule and BDQN's probability are derived from the method: not keys.
        assert!(
            error(
                "CartPole-v0",
                Method::Dqn,
                NetKind::Bootstrap,
                &["rule=adaptive"]
            )
            .contains("unknown config key 'rule'")
        );
        assert!(
            error(
                "CartPole-v0",
                Method::Bdqn,
                NetKind::Bootstrap,
                &["bernoulli_p=0.1"]
            )
            .contains("unknown config key")
        );
    }

    #[test]
    fn overrides_that_contradict_the_method_are_errors() {
        for (method, net, set, words) in [
            (
                Method::Dqn,
                NetKind::Bootstrap,
                "budget=100",
                "does not ask the expert",
            ),
            (
                Method::Dqfd,
                NetKind::Bootstrap,
                "t_query=0.1",
                "no query threshold",
            ),
            (
                Method::Gdqn,
                NetKind::Bootstrap,
                "t_query=0.1",
                "no query threshold",
            ),
            (Method::Bdqn, NetKind::Bootstrap, "n_r=10", "no window"),
            (
                Method::Adqn,
                NetKind::Bootstrap,
                "pretrain_steps=10",
                "does not pre-train",
            ),
            (
                Method::Dqn,
                NetKind::Bootstrap,
                "expert=\"scripted\"",
                "never asks an expert",
            ),
            (
                Method::Dqn,
                NetKind::Noisy,
                "heads=3",
                "no bootstrapped heads",
            ),
            (
                Method::Dqn,
                NetKind::Bootstrap,
                "exact_factorised_var=true",
                "no noisy layer",
            ),
        ] {
            let err = error("CartPole-v0", method, net, &[set]);
            assert!(
                err.contains(words) && err.contains(set.split('=').next().unwrap()),
                "{set}: {err}"
            );
        }
        // The preset's own (inert) value is not a contradiction: a run's config.toml can be given back.
        let dqn = TrainConfig::preset("CartPole-v0", Method::Dqn, NetKind::Bootstrap, 0).unwrap();
        resolve(
            "CartPole-v0",
            Method::Dqn,
            NetKind::Bootstrap,
            &[&format!("t_query={}", dqn.t_query)],
        )
        .unwrap();
    }

    #[test]
    fn bad_values_are_rejected_naming_the_key() {
        let cases = [
            ("train_steps=many", "train_steps"),
            ("budget=-5", "budget"),
            ("t_query=1.5", "t_query"),
            ("eps_agent=0", "eps_agent"),
            ("eps_demo=-1", "eps_demo"),
            ("eps_demo=nan", "eps_demo"),
            ("lr=inf", "lr"),
            ("gamma=1.5", "gamma"),
            ("n_r=0", "n_r"),
            ("segment_len=0", "segment_len"),
            ("eval_episodes=0", "eval_episodes"),
            ("heads=0", "heads"),
            ("margin=-1", "margin"),
        ];
        errors_saying(Method::Adqn, NetKind::Bootstrap, &cases);
        let err = error("CartPole-v0", Method::Adqn, NetKind::Plain, &[]);
        assert!(err.contains("plain network"), "{err}");
    }

    #[test]
    fn demo_file_is_a_path_or_the_record_of_demonstrations_given_in_python() {
        let mut cfg = ConfigInput::new("CartPole-v0", Method::Dqfd, NetKind::Plain, 0)
            .resolve()
            .unwrap();
        assert_eq!(cfg.demo_path().unwrap(), None);
        cfg.demo_file = "runs/demos.safetensors".into();
        assert_eq!(
            cfg.demo_path().unwrap(),
            Some(std::path::Path::new("runs/demos.safetensors"))
        );
        cfg.demo_file = DEMOS_FROM_PYTHON.into();
        let err = cfg.demo_path().unwrap_err().to_string();
        assert!(
            err.contains("given in Python") && err.contains("--demos FILE"),
            "{err}"
        );
        // The record passes validation, and the run asks no expert for demonstrations.
        cfg.validate().unwrap();
        assert_eq!(cfg.expert_used(), None);
    }

    #[test]
    fn hidden_widths_are_configurable_and_the_paper_keeps_64_64() {
        let paper = resolve("CartPole-v0", Method::Adqn, NetKind::Noisy, &[]).unwrap();
        assert_eq!(paper.dqn_agent_config().hidden.as_slice(), [HIDDEN, HIDDEN]);
        assert_eq!(HIDDEN, 64);
        let wide = resolve(
            "CartPole-v0",
            Method::Adqn,
            NetKind::Noisy,
            &["hidden=[256, 32]"],
        )
        .unwrap();
        assert_eq!(wide.dqn_agent_config().hidden.as_slice(), [256, 32]);
        // Any depth from 1 to 8.
        for widths in [&[7][..], &[64, 64, 64], &[5, 9, 3, 11, 2, 4, 6, 8]] {
            let set = format!("hidden={widths:?}");
            let deep = resolve("CartPole-v0", Method::Dqn, NetKind::Plain, &[&set]).unwrap();
            assert_eq!(deep.dqn_agent_config().hidden.as_slice(), widths);
        }
        // config.toml records the widths and gives them back.
        let back: TrainConfig = toml::from_str(&wide.to_toml()).unwrap();
        assert_eq!(back.hidden, vec![256, 32]);
        // A configuration written before the key existed is the paper's network.
        let mut old: toml::Table = toml::from_str(&paper.to_toml()).unwrap();
        assert!(old.remove("hidden").is_some());
        let old = toml::to_string(&old).unwrap();
        assert_eq!(
            toml::from_str::<TrainConfig>(&old).unwrap().hidden,
            vec![64, 64]
        );
        for bad in [
            "hidden=[]",
            "hidden=[64, 64, 64, 64, 64, 64, 64, 64, 64]",
            "hidden=[0, 64]",
            "hidden=[64, 5000]",
            "hidden=[64, 64, 0]",
        ] {
            let err = error("CartPole-v0", Method::Dqn, NetKind::Plain, &[bad]);
            assert!(
                err.contains("1 to 8 layers") && err.contains("hidden"),
                "{bad}: {err}"
            );
        }
    }

    #[test]
    fn type_errors_are_in_the_words_of_a_config_file_not_of_rust() {
        let cases = [
            ("batch_size=-1", "a whole number (0 or more)"),
            ("batch_size=1.5", "a whole number (0 or more)"),
            ("lr=\"x\"", "expected a number"),
            ("hidden=64", "expected a list"),
            ("hidden=[-64, 64]", "a whole number (0 or more)"),
        ];
        for err in errors_saying(Method::Dqn, NetKind::Plain, &cases) {
            for rust in ["usize", "u64", "f64", "f32", "i64", "floating point"] {
                assert!(!err.contains(rust), "{err}");
            }
        }
    }

    #[test]
    fn sizes_are_bounded_with_the_memory_they_would_need() {
        for (set, key) in [
            ("replay_size=10000000000", "replay_size"),
            ("budget=9000000000000000000", "budget"),
        ] {
            let err = error("CartPole-v0", Method::Adqn, NetKind::Bootstrap, &[set]);
            assert!(err.contains(key) && err.contains("GiB"), "{set}: {err}");
        }
    }

    #[test]
    fn every_key_has_a_check_or_cannot_be_wrong() {
        // Keys whose every value of the right type is valid (booleans, enums, free text checked where used).
        let free = [
            "env",
            "method",
            "net",
            "seed",
            "loss",
            "double_q",
            "timeout_as_terminal",
            "queries_from_learning_starts",
            "eps_greedy_on_top",
            "random_before_learning",
            "algo",
            "target_period_in_steps",
            "prioritized",
            "exact_factorised_var",
            "demo_file",
            "checkpoint_every",
            "snapshot_every",
            "learning_starts",
            "pretrain_steps",
            "n_demo",
        ];
        for key in TrainConfig::valid_keys() {
            if free.contains(&key.as_str()) {
                continue;
            }
            let preset =
                TrainConfig::preset("CartPole-v0", Method::Adqn, NetKind::Bootstrap, 0).unwrap();
            let bad: &[&str] = match &TrainConfig::preset_table(&preset)[&key] {
                toml::Value::Float(_) => &["-1.0e300", "nan"],
                // Zero, or a size no machine holds.
                toml::Value::Integer(_) => &["0", "9000000000000000000"],
                // query_rule: empty means the method's own rule; an unknown rule is refused.
                toml::Value::String(_) if key == "query_rule" => &["\"nope\""],
                toml::Value::String(_) => &["\"\""],
                // hidden: a width of zero, or no layer.
                toml::Value::Array(_) => &["[0, 64]", "[]"],
                other => panic!("{key}: unexpected type {other:?}"),
            };
            let rejected = bad.iter().any(|v| {
                let set = format!("{key}={v}");
                resolve("CartPole-v0", Method::Adqn, NetKind::Bootstrap, &[&set]).is_err()
            });
            assert!(rejected, "{key}: every one of {bad:?} was accepted");
        }
    }

    #[test]
    fn toml_round_trip() {
        let c = TrainConfig::preset("LunarLander-v2", Method::Dqfd, NetKind::Bootstrap, 7).unwrap();
        let back: TrainConfig = toml::from_str(&c.to_toml()).unwrap();
        assert_eq!(c, back);
    }
}
