//! `arld env ...`: conformance checks against Gymnasium traces, random-policy rollouts, the registry.
//!
//! `check` streams trace files through [`arld::env::conformance`] and prints one table row per environment
//! and file; `rollout` plays a policy for a number of seeded episodes and prints return and length
//! statistics; `list` prints the registered environments.

use anyhow::bail;
use arld::env;
use arld::env::conformance::{EnvReport, check_file};
use arld::rng::NumpyRng;
use clap::{Subcommand, ValueEnum};
use rand::Rng;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Subcommand)]
pub enum EnvCommand {
    /// Replay Gymnasium conformance traces and report how closely each environment follows them.
    ///
    /// Each FILE holds JSON lines as recorded from Gymnasium (a meta line, then per episode a start line
    /// and its step lines; a task with actions in a box records float32 action vectors, as
    /// tests/data/continuous/conformance.jsonl does). Every episode is reset with its seed (or set to its recorded state), the
    /// recorded actions are replayed, and observations, rewards and episode ends are compared. Classic
    /// control must stay within 1e-6 on every observation and reward; LunarLander within 1e-4 on the
    /// seeded episodes, with at most 10% of the long heuristic episodes allowed to drift. Exits with a
    /// non-zero status if any environment fails or a file cannot be read or parsed.
    ///
    /// Table columns: episodes replayed; episodes reproduced bit for bit; episodes outside the tolerance;
    /// steps compared; largest absolute observation and reward deviations; verdict; first divergence
    /// (episode, case and seed, step, trace line, what differed).
    Check {
        /// Trace files (JSON lines).
        #[arg(required = true, value_name = "FILE")]
        files: Vec<PathBuf>,
    },
    /// Play a policy for several seeded episodes and print the mean and standard deviation of return and length.
    ///
    /// Episode i is reset with seed SEED+i; the random policy draws its actions (an index, or a point of the
    /// action box, uniformly) from a generator seeded with SEED, so a run is reproducible. Standard deviations are population ones (NumPy's `np.std`).
    Rollout {
        /// Gymnasium id of a built-in task, discrete or with actions in a box, e.g. CartPole-v1 or Pendulum-v1
        /// (`arld env list` shows them all).
        #[arg(long = "env", value_name = "ID")]
        env_id: String,
        /// Policy that chooses the actions.
        #[arg(long, value_enum, default_value_t = RolloutPolicy::Random)]
        policy: RolloutPolicy,
        /// Number of episodes.
        #[arg(long, default_value_t = 100, value_name = "N", value_parser = super::count(super::MAX_EPISODES))]
        episodes: usize,
        /// Base seed (a non-negative integer): episode i resets with SEED+i, and the policy's generator is
        /// seeded with SEED.
        #[arg(long, default_value_t = 0, value_name = "S", allow_negative_numbers = true, value_parser = super::seed)]
        seed: u64,
        /// Print one JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// List the built-in tasks, discrete and with actions in a box: actions, sizes, time limits, solve
    /// thresholds and the preset's steps.
    List,
}

/// Policies `rollout` can play.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum RolloutPolicy {
    /// Uniformly random actions.
    Random,
}

pub fn run(cmd: EnvCommand) -> anyhow::Result<ExitCode> {
    match cmd {
        EnvCommand::Check { files } => check(&files),
        EnvCommand::Rollout {
            env_id,
            policy,
            episodes,
            seed,
            json,
        } => rollout(&env_id, policy, episodes, seed, json),
        EnvCommand::List => {
            list();
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// Every built-in task of the registry: id, actions, sizes, time limit, threshold, the preset's steps and what
/// the task is.
fn list() {
    println!(
        "{:<25} {:<22} {:>7} {:>9} {:>9}  {:>12}  about",
        "id", "actions", "obs dim", "max steps", "threshold", "preset steps"
    );
    for task in &env::registry::TASKS {
        let (obs_dim, max_steps, threshold) = task.facts();
        let preset = arld::train::TrainConfig::preset(
            task.id,
            arld::train::Method::Dqn,
            arld::train::NetKind::Bootstrap,
            0,
        )
        .map_or_else(|_| "-".to_string(), |cfg| cfg.train_steps.to_string());
        println!(
            "{:<25} {:<22} {:>7} {:>9} {:>9}  {:>12}  {}",
            task.id,
            task.actions(),
            obs_dim,
            max_steps,
            threshold.map_or_else(|| "none".to_string(), |t| t.to_string()),
            preset,
            task.about
        );
    }
    println!(
        "\nTasks with actions in a box learn with TD3 or SAC (`arld train --env Pendulum-v1 --algo td3|sac`); the \
         others with the DQN family. Thresholds are Gymnasium's (Pendulum-v1's -200 is arld's: Gymnasium gives none)."
    );
}

fn check(files: &[PathBuf]) -> anyhow::Result<ExitCode> {
    let mut rows: Vec<(String, EnvReport)> = Vec::new();
    for file in files {
        let reports = check_file(file)?;
        let name = file
            .file_name()
            .map(|name| name.to_string_lossy().into_owned())
            .unwrap_or_else(|| file.display().to_string());
        rows.extend(reports.into_iter().map(|report| (name.clone(), report)));
    }
    println!(
        "{:<24} {:<25} {:>8} {:>6} {:>8} {:>7} {:>11} {:>11}  {:<6} first divergence",
        "file",
        "env",
        "episodes",
        "exact",
        "diverged",
        "steps",
        "max |dobs|",
        "max |drew|",
        "result"
    );
    let mut all_passed = true;
    for (file, report) in &rows {
        let passed = report.passed();
        all_passed &= passed;
        let first = report
            .first_divergence
            .as_ref()
            .map_or_else(|| "-".to_string(), ToString::to_string);
        println!(
            "{:<24} {:<25} {:>8} {:>6} {:>8} {:>7} {:>11.3e} {:>11.3e}  {:<6} {}",
            file,
            report.env,
            report.episodes,
            report.episodes_exact,
            report.episodes_diverged(),
            report.steps,
            report.max_obs_deviation,
            report.max_reward_deviation,
            if passed { "PASS" } else { "FAIL" },
            first
        );
    }
    if rows.is_empty() {
        bail!("the trace files contain no episodes");
    }
    Ok(if all_passed {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

fn rollout(
    env_id: &str,
    policy: RolloutPolicy,
    episodes: usize,
    seed: u64,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let last_seed = super::last_seed(seed, episodes)?;
    let task = env::registry::task(env_id)?;
    let mut action_rng = NumpyRng::new(seed);
    let seeds = |i: usize| Some(seed + i as u64);
    // Uniformly random actions: an index, or a point of the box drawn dimension by dimension.
    let episodes_played = match &task.body {
        env::registry::Body::Discrete { spec, make, .. } => {
            let n_actions = spec.n_actions;
            env::rollouts(make(spec).as_mut(), episodes, seeds, |_| {
                Ok::<_, anyhow::Error>(match policy {
                    RolloutPolicy::Random => action_rng.random_range(0..n_actions),
                })
            })?
        }
        env::registry::Body::Box { spec, .. } => {
            let mut box_env = env::make_box(task.id)?;
            env::rollouts(box_env.as_mut(), episodes, seeds, |_| {
                Ok::<_, anyhow::Error>(match policy {
                    RolloutPolicy::Random => spec
                        .action_low
                        .iter()
                        .zip(spec.action_high)
                        .map(|(&low, &high)| action_rng.random_range(low..high))
                        .collect::<Vec<f32>>(),
                })
            })?
        }
    };
    let (return_mean, return_std, _, _) = env::return_stats(&episodes_played);
    let lengths: Vec<f64> = episodes_played.iter().map(|e| e.length as f64).collect();
    let (length_mean, length_std, _, _) = env::mean_std_min_max(&lengths);
    let policy_name = match policy {
        RolloutPolicy::Random => "random",
    };
    if json {
        let summary = serde_json::json!({
            "env": task.id,
            "policy": policy_name,
            "episodes": episodes,
            "seeds": [seed, last_seed],
            "return_mean": return_mean,
            "return_std": return_std,
            "length_mean": length_mean,
            "length_std": length_std,
        });
        println!("{summary}");
    } else {
        println!(
            "{} policy={policy_name} episodes={episodes} seeds={seed}..={last_seed}",
            task.id
        );
        println!("return  {return_mean:.3} +- {return_std:.3}");
        println!("length  {length_mean:.3} +- {length_std:.3}");
    }
    Ok(ExitCode::SUCCESS)
}
