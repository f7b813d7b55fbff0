//! Every hyperparameter of a run in one struct, with its default and its source.
//!
//! A run's configuration is built in layers: [`TrainConfig::preset`] fills in the paper's per-task table and the
//! method's settings (docs/algorithm.md §9), a TOML file may override any field, and `--set key=value` pairs
//! override last. Unknown keys and ill-typed values are rejected up front with the list of valid keys, and
//! [`TrainConfig::validate`] checks the values before any work starts.

use anyhow::{Context, Result, bail, ensure};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;

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
    pub const ALL: [Method; 6] = [
        Method::Dqn,
        Method::Dqfd,
        Method::Gdqn,
        Method::Bdqn,
        Method::Adqn,
        Method::Adqnp,
    ];

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
    pub fn needs_expert(self) -> bool {
        self != Method::Dqn
    }

    pub fn name(self) -> &'static str {
        match self {
            Method::Dqn => "dqn",
            Method::Dqfd => "dqfd",
            Method::Gdqn => "gdqn",
            Method::Bdqn => "bdqn",
            Method::Adqn => "adqn",
            Method::Adqnp => "adqnp",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .with_context(|| {
                format!("unknown method '{s}'; known: dqn, dqfd, gdqn, bdqn, adqn, adqnp")
            })
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
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

impl NetKind {
    pub fn name(self) -> &'static str {
        match self {
            NetKind::Plain => "plain",
            NetKind::Bootstrap => "bootstrap",
            NetKind::Noisy => "noisy",
        }
    }
}

impl std::str::FromStr for NetKind {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "plain" => Ok(NetKind::Plain),
            "bootstrap" => Ok(NetKind::Bootstrap),
            "noisy" => Ok(NetKind::Noisy),
            _ => bail!("unknown network '{s}'; known: plain, bootstrap, noisy"),
        }
    }
}

impl fmt::Display for NetKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The TD loss (docs/algorithm.md §2: squared error by default, Huber as an option).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TdLoss {
    Mse,
    Huber,
}

/// How the adaptive/Bernoulli query rule decides (docs/algorithm.md §8–9).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RuleKind {
    Never,
    Greedy,
    Bernoulli,
    Adaptive,
}

/// All hyperparameters of one training run. Field docs give the default and its source tag
/// (\[P\] paper, \[DQfD\], \[PER\], \[BS\], \[NN\], \[OURS\] as in docs/algorithm.md).
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
    /// Number of bootstrapped heads \[P: 10\].
    pub heads: usize,
    /// TD loss \[P: squared error\].
    pub loss: TdLoss,
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

    /// Proportional prioritized replay (false: uniform) \[P\].
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
    /// Weight λ of the margin loss \[P, per task\].
    pub lambda: f64,
    /// Weight λ1 of DQfD's n-step TD loss; 0 turns it off \[P: 0, the paper drops it; DQfD used 1\].
    pub lambda_n: f64,
    /// Horizon n of the n-step loss \[DQfD: 10\].
    pub n_step: usize,
    /// L2 regularisation weight λ3 on all weights \[P: 0, the paper drops it; DQfD used 1e-5\].
    pub l2: f64,
    /// Demonstration transitions collected before training (DQfD; ADQNP uses half) \[P, per task\].
    pub n_demo: usize,
    /// Pre-training updates on demonstrations only \[P, per task\].
    pub pretrain_steps: usize,

    /// Query rule (set by the method) \[P\].
    pub rule: RuleKind,
    /// Demonstrated transitions that may be asked for during training \[P, per task\].
    pub budget: usize,
    /// Fraction of recent steps whose uncertainty may exceed the current one for a query \[P, per task and net\].
    pub t_query: f64,
    /// Window of recent uncertainties N_r \[OURS: 1000\].
    pub n_r: usize,
    /// Expert steps per query \[P-inf: 5\].
    pub segment_len: usize,
    /// Query probability of BDQN \[OURS: the task's ADQN t_query\].
    pub bernoulli_p: f64,
    /// Use the exact factorised-noise variance instead of the paper's formula \[OURS: false\].
    pub exact_factorised_var: bool,
    /// Expert specification (see `arld expert --help`) \[OURS: the shipped weak expert\].
    pub expert: String,
    /// Demonstration file for pre-training; empty: collect from the expert at the start of the run.
    pub demo_file: String,

    /// Environment steps between evaluations \[P-inf, per task\].
    pub eval_period: usize,
    /// Test episodes per evaluation \[P: 20\].
    pub eval_episodes: usize,
    /// Save the online weights every this many steps into `checkpoints/` (0: only at the end) \[OURS\].
    pub checkpoint_every: usize,
}

/// Per-task numbers of the paper's parameter table (docs/algorithm.md §9).
#[derive(Clone, Copy, Debug)]
pub struct TaskPreset {
    pub gamma: f64,
    pub lr: f64,
    pub train_steps: usize,
    pub n_demo: usize,
    pub replay_size: usize,
    pub pretrain_steps: usize,
    pub lambda: f64,
    pub t_query_bootstrap: f64,
    pub t_query_noisy: f64,
    pub eval_period: usize,
    pub learning_starts: usize,
    pub target_period: usize,
}

/// The paper's per-task parameters for a Gymnasium id (CartPole-v1 and LunarLander-v3 reuse their v0/v2 rows).
pub fn task_preset(env: &str) -> Result<TaskPreset> {
    let p = match env {
        "CartPole-v0" | "CartPole-v1" => TaskPreset {
            gamma: 0.9,
            lr: 1e-4,
            train_steps: 20_000,
            n_demo: 200,
            replay_size: 10_000,
            pretrain_steps: 10_000,
            lambda: 1e-5,
            t_query_bootstrap: 0.05,
            t_query_noisy: 0.5,
            eval_period: 1_000,
            learning_starts: 500,
            // The notes suggest 500; with 500 bootstrapped DQN solved only 3 of 5 seeds within the paper's 20k
            // steps (medians 16k), with 250 all 5 (median 7k, the paper's 8k).
            target_period: 250,
        },
        "Acrobot-v1" => TaskPreset {
            gamma: 0.99,
            lr: 1e-4,
            train_steps: 200_000,
            n_demo: 100,
            replay_size: 100_000,
            pretrain_steps: 10_000,
            lambda: 1.0,
            t_query_bootstrap: 0.3,
            t_query_noisy: 0.3,
            eval_period: 2_000,
            learning_starts: 1_000,
            target_period: 1_000,
        },
        "MountainCar-v0" => TaskPreset {
            gamma: 0.99,
            lr: 1e-3,
            train_steps: 500_000,
            n_demo: 500,
            replay_size: 100_000,
            pretrain_steps: 10_000,
            lambda: 1.0,
            t_query_bootstrap: 0.1,
            t_query_noisy: 0.3,
            eval_period: 10_000,
            learning_starts: 1_000,
            target_period: 1_000,
        },
        "LunarLander-v2" | "LunarLander-v3" => TaskPreset {
            gamma: 0.99,
            lr: 1e-3,
            train_steps: 500_000,
            n_demo: 3_000,
            replay_size: 100_000,
            pretrain_steps: 30_000,
            lambda: 1.0,
            t_query_bootstrap: 0.3,
            t_query_noisy: 0.1,
            eval_period: 5_000,
            learning_starts: 1_000,
            target_period: 1_000,
        },
        other => bail!(
            "{}",
            crate::env::EnvError::UnknownId {
                id: other.to_string()
            }
        ),
    };
    Ok(p)
}

impl TrainConfig {
    /// The paper's configuration for `method` with `net` on `env` (docs/algorithm.md §9).
    pub fn preset(env: &str, method: Method, net: NetKind, seed: u64) -> Result<Self> {
        let p = task_preset(env)?;
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
        let rule = match method {
            Method::Dqn | Method::Dqfd => RuleKind::Never,
            Method::Gdqn => RuleKind::Greedy,
            Method::Bdqn => RuleKind::Bernoulli,
            Method::Adqn | Method::Adqnp => RuleKind::Adaptive,
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
            batch_size: 32,
            learning_starts: p.learning_starts,
            train_freq: 1,
            target_period: p.target_period,
            heads: 10,
            loss: TdLoss::Mse,
            grad_clip: 10.0,
            timeout_as_terminal: false,
            eps_start: 0.9,
            eps_end: 0.01,
            eps_fraction: 0.1,
            eps_greedy_on_top: true,
            prioritized: true,
            alpha: 0.6,
            beta0: 0.4,
            eps_agent: 0.001,
            eps_demo: 1.0,
            margin: 0.8,
            lambda: p.lambda,
            lambda_n: 0.0,
            n_step: 10,
            l2: 0.0,
            n_demo,
            pretrain_steps: if method.pretrains() {
                p.pretrain_steps
            } else {
                0
            },
            rule,
            budget,
            t_query,
            n_r: 1000,
            segment_len: 5,
            bernoulli_p: t_query,
            exact_factorised_var: false,
            expert: "shipped:weak".to_string(),
            demo_file: String::new(),
            eval_period: p.eval_period,
            eval_episodes: 20,
            checkpoint_every: 0,
        })
    }

    /// Applies a TOML file's keys on top of this configuration.
    pub fn apply_file(&mut self, path: &Path) -> Result<()> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config file {}", path.display()))?;
        let table: toml::Table = toml::from_str(&text)
            .with_context(|| format!("config file {} is not valid TOML", path.display()))?;
        for (key, value) in table {
            self.set_value(&key, value)
                .with_context(|| format!("in config file {}", path.display()))?;
        }
        Ok(())
    }

    /// Applies one `key=value` override; the value is read as a TOML literal, or as a string if it is not one.
    pub fn apply_override(&mut self, assignment: &str) -> Result<()> {
        let Some((key, raw)) = assignment.split_once('=') else {
            bail!("override '{assignment}' is not of the form key=value");
        };
        let (key, raw) = (key.trim(), raw.trim());
        let value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(raw.to_string()));
        self.set_value(key, value)
    }

    fn set_value(&mut self, key: &str, value: toml::Value) -> Result<()> {
        let mut table = toml::Table::try_from(&*self).context("serialising the configuration")?;
        if !table.contains_key(key) {
            bail!(
                "unknown config key '{key}'; valid keys: {}",
                Self::valid_keys().join(", ")
            );
        }
        // Integers may be given where floats are expected (`lr=1` means 1.0).
        let value = match (&table[key], value) {
            (toml::Value::Float(_), toml::Value::Integer(i)) => toml::Value::Float(i as f64),
            (_, v) => v,
        };
        let shown = value.to_string();
        table.insert(key.to_string(), value);
        *self = table.try_into().map_err(|e: toml::de::Error| {
            anyhow::anyhow!("bad value {shown} for config key '{key}': {}", e.message())
        })?;
        Ok(())
    }

    /// Names of every configuration key.
    pub fn valid_keys() -> Vec<String> {
        let cfg = Self::preset("CartPole-v0", Method::Dqn, NetKind::Plain, 0)
            .expect("CartPole preset exists");
        toml::Table::try_from(&cfg)
            .expect("config serialises")
            .keys()
            .cloned()
            .collect()
    }

    /// The configuration as TOML, for the run directory.
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("config serialises")
    }

    /// Checks every value before any work starts.
    pub fn validate(&self) -> Result<()> {
        crate::env::make(&self.env).map_err(|e| anyhow::anyhow!("{e}"))?;
        let unit = |name: &str, v: f64| -> Result<()> {
            ensure!(
                (0.0..=1.0).contains(&v),
                "{name} must be in [0, 1], got {v}"
            );
            Ok(())
        };
        unit("t_query", self.t_query)?;
        unit("bernoulli_p", self.bernoulli_p)?;
        unit("eps_start", self.eps_start)?;
        unit("eps_end", self.eps_end)?;
        unit("eps_fraction", self.eps_fraction)?;
        unit("alpha", self.alpha)?;
        unit("beta0", self.beta0)?;
        ensure!(
            self.gamma >= 0.0 && self.gamma <= 1.0,
            "gamma must be in [0, 1], got {}",
            self.gamma
        );
        ensure!(
            self.lr > 0.0 && self.lr.is_finite(),
            "lr must be positive, got {}",
            self.lr
        );
        ensure!(self.train_steps > 0, "train_steps must be positive");
        ensure!(self.batch_size > 0, "batch_size must be positive");
        ensure!(
            self.replay_size >= self.batch_size,
            "replay_size must be at least batch_size"
        );
        ensure!(self.train_freq > 0, "train_freq must be positive");
        ensure!(self.target_period > 0, "target_period must be positive");
        ensure!(self.eval_period > 0, "eval_period must be positive");
        ensure!(self.eval_episodes > 0, "eval_episodes must be positive");
        ensure!(self.segment_len > 0, "segment_len must be positive");
        ensure!(self.n_r > 0, "n_r must be positive");
        ensure!(self.heads > 0, "heads must be positive");
        ensure!(
            self.margin >= 0.0 && self.lambda >= 0.0,
            "margin and lambda must be non-negative"
        );
        ensure!(
            self.l2 >= 0.0 && self.l2.is_finite(),
            "l2 must be non-negative, got {}",
            self.l2
        );
        ensure!(self.grad_clip > 0.0, "grad_clip must be positive");
        ensure!(
            self.lambda_n >= 0.0,
            "lambda_n must be non-negative, got {}",
            self.lambda_n
        );
        ensure!(self.n_step >= 1, "n_step must be at least 1");
        if self.rule == RuleKind::Adaptive && self.net == NetKind::Plain {
            bail!(
                "the adaptive query rule needs an uncertainty estimate, which a plain network does not have; \
                 use --net bootstrap (divergence) or --net noisy (variance)"
            );
        }
        if self.method.pretrains() {
            ensure!(
                self.n_demo > 0 || !self.demo_file.is_empty(),
                "{} pre-trains on demonstrations: n_demo must be positive",
                self.method
            );
        }
        Ok(())
    }

    /// A short name for the run directory: `CartPole-v0_adqn-bootstrap_seed3`.
    pub fn run_name(&self) -> String {
        format!(
            "{}_{}-{}_seed{}",
            self.env, self.method, self.net, self.seed
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert_eq!(
            (c.budget, c.n_demo, c.t_query, c.rule),
            (200, 0, 0.5, RuleKind::Adaptive)
        );
    }

    #[test]
    fn overrides_parse_typed_values() {
        let mut c = TrainConfig::preset("CartPole-v0", Method::Dqn, NetKind::Plain, 0).unwrap();
        c.apply_override("lr=0.001").unwrap();
        c.apply_override("train_steps=5000").unwrap();
        c.apply_override("prioritized=false").unwrap();
        c.apply_override("loss=huber").unwrap();
        c.apply_override("gamma=1").unwrap();
        assert_eq!(
            (c.lr, c.train_steps, c.prioritized, c.loss, c.gamma),
            (0.001, 5000, false, TdLoss::Huber, 1.0)
        );
    }

    #[test]
    fn unknown_key_lists_valid_keys() {
        let mut c = TrainConfig::preset("CartPole-v0", Method::Dqn, NetKind::Plain, 0).unwrap();
        let err = format!("{:#}", c.apply_override("learning_rate=0.1").unwrap_err());
        assert!(err.contains("unknown config key 'learning_rate'"), "{err}");
        assert!(err.contains("lr") && err.contains("t_query"), "{err}");
    }

    #[test]
    fn bad_values_are_rejected() {
        let mut c =
            TrainConfig::preset("CartPole-v0", Method::Adqn, NetKind::Bootstrap, 0).unwrap();
        let err = format!("{:#}", c.apply_override("train_steps=many").unwrap_err());
        assert!(err.contains("train_steps"), "{err}");
        assert!(c.apply_override("budget=-5").is_err());
        c.apply_override("t_query=1.5").unwrap();
        let err = format!("{:#}", c.validate().unwrap_err());
        assert!(err.contains("t_query"), "{err}");
        let mut c = TrainConfig::preset("CartPole-v0", Method::Adqn, NetKind::Plain, 0).unwrap();
        c.t_query = 0.1;
        let err = format!("{:#}", c.validate().unwrap_err());
        assert!(err.contains("plain network"), "{err}");
    }

    #[test]
    fn toml_round_trip() {
        let c = TrainConfig::preset("LunarLander-v2", Method::Dqfd, NetKind::Bootstrap, 7).unwrap();
        let back: TrainConfig = toml::from_str(&c.to_toml()).unwrap();
        assert_eq!(c, back);
    }
}
