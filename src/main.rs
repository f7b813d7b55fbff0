//! The `arld` command-line tool: argument parsing and wiring only; the work is done by the library.

mod cli;

use clap::{Parser, Subcommand};

/// Active Reinforcement Learning with Demonstration: agents that ask an expert only where they are unsure (DQN
/// family on discrete actions; TD3 or SAC on actions in a box).
#[derive(Parser)]
#[command(
    name = "arld",
    version = arld::build_info::VERSION_LINE,
    about,
    long_about = None,
    after_help = "Start here (every command's --help says more):\n  \
arld reproduce --quick                                    # the paper's comparison, CartPole-v0, 3 seeds\n  \
arld train --env CartPole-v0 --method adqn                # active DQN asking the shipped expert\n  \
arld train --env Pendulum-v1 --method adqn --algo sac     # active SAC, actions in a box\n  \
arld train --env CartPole-v0 --method adqn --expert web   # you answer the agent in a browser\n\n\
Methods: dqn, dqfd, gdqn, bdqn, adqn, adqnp. Tasks: `arld env list`."
)]
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
    /// Train one agent and write a run directory: a method (DQN, DQfD, GDQN, BDQN, ADQN, ADQNP) with a DQN
    /// learner, or TD3 or SAC (--algo) on a task with actions in a box.
    Train(cli::train_cmd::TrainArgs),
    /// Experts: measure one's statistics (shipped, scripted, checkpoint, cmd:), or train and select your own as
    /// the paper did.
    Expert {
        #[command(subcommand)]
        cmd: cli::expert_cmd::ExpertCommand,
    },
    /// Run a grid of runs (environments x methods x networks x seeds) in parallel; resumable.
    Sweep(Box<cli::lab_cmd::SweepArgs>),
    /// Tables (median steps to solve next to the paper's) and figures from a directory of runs.
    Report(cli::lab_cmd::ReportArgs),
    /// The paper's experimental protocol, sweep plus report, with one command (--quick: a few minutes).
    Reproduce(cli::lab_cmd::ReproduceArgs),
    /// Runs as a compact dataset: pack run directories into tables per task, and unpack them byte for byte.
    Runs {
        #[command(subcommand)]
        cmd: cli::lab_cmd::RunsCommand,
    },
    /// Demonstrations: collect expert episodes into a file that DQfD pre-training reads, or convert a Minari
    /// dataset into one.
    Demo {
        #[command(subcommand)]
        cmd: cli::expert_cmd::DemoCommand,
    },
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    // The instruction-set cap is read once per process; a bad value is reported here, before any work.
    if let Err(err) = arld::nn::SimdLevel::from_env() {
        eprintln!("error: {err}");
        return std::process::ExitCode::FAILURE;
    }
    let result = match cli.command {
        Command::Env { cmd } => cli::env_cmd::run(cmd),
        Command::Train(args) => cli::train_cmd::run(args),
        Command::Expert { cmd } => cli::expert_cmd::run_expert(cmd),
        Command::Demo { cmd } => cli::expert_cmd::run_demo(cmd),
        Command::Sweep(args) => cli::lab_cmd::run_sweep(*args),
        Command::Report(args) => cli::lab_cmd::run_report(args),
        Command::Reproduce(args) => cli::lab_cmd::run_reproduce(args),
        Command::Runs { cmd } => cli::lab_cmd::run_runs(cmd),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {}", arld::errors::error_line(&err));
            std::process::ExitCode::FAILURE
        }
    }
}
