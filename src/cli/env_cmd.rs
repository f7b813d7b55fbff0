//! `arld env ...`: conformance checks against Gymnasium traces and random-policy rollouts.
use clap::Subcommand;
use std::process::ExitCode;

#[derive(Subcommand)]
pub enum EnvCommand {}

pub fn run(cmd: EnvCommand) -> anyhow::Result<ExitCode> {
    match cmd {}
}
