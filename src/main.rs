//! The `arld` command-line tool: argument parsing and wiring only; the work is done by the library.

mod cli;

use clap::{Parser, Subcommand};

/// Active Reinforcement Learning with Demonstration: DQN agents that ask an expert only where they are unsure.
#[derive(Parser)]
#[command(name = "arld", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Gymnasium-exact environments: conformance checks and random rollouts.
    Env {
        #[command(subcommand)]
        cmd: cli::env_cmd::EnvCommand,
    },
    /// Train one agent (DQN, DQfD, GDQN, BDQN, ADQN, ADQNP) and write a run directory.
    Train(cli::train_cmd::TrainArgs),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Env { cmd } => cli::env_cmd::run(cmd),
        Command::Train(args) => cli::train_cmd::run(args),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
