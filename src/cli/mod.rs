//! Subcommands of the `arld` binary, one file each.
pub mod env_cmd;
pub mod experiment_cmd;
pub mod expert_cmd;
pub mod train_cmd;
