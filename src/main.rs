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
    /// Experts: train and select them as the paper did, and measure their statistics.
    Expert {
        #[command(subcommand)]
        cmd: cli::expert_cmd::ExpertCommand,
    },
    /// Demonstrations: collect expert episodes into a file that DQfD pre-training reads.
    Demo {
        #[command(subcommand)]
        cmd: cli::expert_cmd::DemoCommand,
    },
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Env { cmd } => cli::env_cmd::run(cmd),
        Command::Train(args) => cli::train_cmd::run(args),
        Command::Expert { cmd } => cli::expert_cmd::run_expert(cmd),
        Command::Demo { cmd } => cli::expert_cmd::run_demo(cmd),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
