//! `arld`: Active Reinforcement Learning with Demonstration, as one library.
//!
//! The workspace's crates under the names the command line, the tests, the benches and the examples use:
//! - the core (`arld-core`: environments, networks, replay, agents, query rules, experts, the run) at the top
//!   level: [`train`], [`env`], [`agent`], ...;
//! - the web expert (`arld-web`) as [`expert::web`], beside the other kinds of expert; [`expert::from_spec`] and
//!   [`expert::build`] here build every kind, the web expert included;
//! - the laboratory (`arld-lab`: configured runs, sweeps, Slurm, reports, verdict, figures) as [`lab`].
//!
//! The binary `arld` (src/main.rs, src/cli) is a thin command-line layer over them.

pub use arld_core::*;
pub use arld_lab as lab;

/// Experts: the core's kinds, the web expert, and the factory that builds every kind from its spec.
pub mod expert {
    pub use arld_core::expert::*;
    pub use arld_web as web;
    pub use arld_web::{build, from_spec};
}
