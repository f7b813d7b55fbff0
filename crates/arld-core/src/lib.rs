//! `arld-core`: the core of arld (Active Reinforcement Learning with Demonstration).
//!
//! DQN-family agents (prioritized double DQN with plain, bootstrapped or noisy output stages) that learn
//! from an expert's demonstrations, either collected before training (DQfD) or asked for during training
//! only where the agent is unsure (Active DQN, Chen et al.). This crate holds everything one training run needs
//! and is organised along its flow:
//!
//! - [`env`]: the [`env::Env`] trait and Gymnasium-exact environments; [`rng`]: NumPy-compatible seeding.
//! - [`nn`]: the fixed-shape Q-network (plain, K heads or noisy output), forward, backward, Adam, safetensors;
//!   dense networks of any shape for the actor-critic learners.
//! - [`replay`]: sum-tree prioritized replay with a permanent demonstration part.
//! - [`agent`]: the [`agent::Learner`] interface a run trains through, and the DQN family implementing it: acting
//!   (exploration, head sampling, noise), the learner (losses, target network), the test-time policy; and the
//!   actor-critic family for actions in a box ([`agent::box_agent`]: TD3 and SAC, through the same run loop).
//! - [`query`]: uncertainty measures, query rules and budget accounting.
//! - [`expert`]: the [`expert::Expert`] trait and its kinds (the web expert's server and page are `arld-web`).
//! - [`train`]: one run: [`train::RunBuilder`], its one entry point, the loop as named steps, the run
//!   directory's format and its full-state snapshots.
//! - [`paper`]: the paper's tables (tasks, parameters, expert statistics, steps to solve) as data.
//! - [`build_info`]: the version and the git commit this arld was built from ([`VERSION`], [`GIT_COMMIT`]).
//! - [`files`]: the one atomic file write every saved file goes through.
//! - [`dir_lock`]: one process at a time in a run (or sweep) directory, whether the CLI or Python runs it.
//! - [`state`]: a component's state as named raw arrays and small values (what snapshots are made of).
//! - [`math`]: the correctly rounded elementary functions every computation uses (one result on every CPU).
//! - [`errors`]: an error and its causes on one line, as the command line and Python show it.
//! - [`interrupt`]: SIGTERM/SIGINT as a stop request that the training loop polls.
//! - [`tboard`]: a minimal TensorBoard event-file writer for scalar curves.
//!
//! Above it: `arld-web` (the web expert), `arld-lab` (sweeps, Slurm, reports: the laboratory), the `arld` command
//! line, and the Python bindings (which use this crate and `arld-web` only).

pub mod agent;
pub mod build_info;
pub mod dir_lock;
pub mod env;
pub mod errors;
pub mod expert;
pub mod files;
pub mod interrupt;
pub mod math;
pub mod nn;
pub mod paper;
pub mod query;
pub mod replay;
pub mod rng;
pub mod state;
pub mod task;
pub mod tboard;
pub mod train;

pub use build_info::{GIT_COMMIT, VERSION};
