//! `arld expert ...` and `arld demo ...`: the expert pipeline, expert statistics, demonstration collection, and
//! Minari datasets written as demonstration files.
use anyhow::{Context, Result};
use arld::expert::demos::{DemoAction, Demonstrations};
use arld::expert::pipeline::{Candidate, evaluate_spec, select_experts};
use arld::expert::{self, SPEC_HELP};
use arld::lab::run_or_reuse;
use arld::train::{ConfigInput, Method, NetKind};
use clap::{Args, Subcommand};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The environment and the expert of `expert eval` and `demo collect`.
#[derive(Args)]
pub struct ExpertArgs {
    #[arg(long, help = super::ENV_HELP)]
    env: String,
    /// The expert: shipped:weak, shipped:perfect, scripted, checkpoint:PATH, noisy:P:SPEC, cmd:COMMAND (each is
    /// explained below).
    #[arg(long)]
    expert: String,
    /// Seconds an expert process (`cmd:...`) may take to answer.
    #[arg(long, default_value_t = expert::process::DEFAULT_TIMEOUT_S)]
    expert_timeout: f64,
}

impl ExpertArgs {
    /// The expert, seeded with `seed`.
    fn build(&self, seed: u64) -> Result<Box<dyn expert::Expert>> {
        expert::from_spec(&self.expert, &self.env, seed, self.expert_timeout)
    }
}

#[derive(Subcommand)]
pub enum ExpertCommand {
    /// Train prioritized double DQN (TD3 for a task with actions in a box), checkpoint it, evaluate every
    /// checkpoint over 100 episodes, and select a weak (paper-like) and a perfect expert.
    Train {
        #[arg(long, help = super::ENV_HELP)]
        env: String,
        /// Seed of the candidates' training run (a non-negative integer).
        #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = super::seed)]
        seed: u64,
        /// Output stage of the network (the paper's experts are plain prioritized double DQN; bootstrapped
        /// heads explore deeper, which MountainCar needs).
        #[arg(long, value_enum, default_value_t = NetKind::Plain)]
        net: NetKind,
        /// How the candidate learns: `dqn` alone (the paper's experts), or a method that learns from its own
        /// expert (`--set expert=...`; the shipped MountainCarContinuous-v0 and LunarLanderContinuous-v3 experts
        /// are TD3 runs that asked the scripted controller, `adqn`).
        #[arg(long, value_enum, default_value_t = Method::Dqn)]
        method: Method,
        /// Where the selected experts (weak.safetensors, perfect.safetensors, selection.json) go [default:
        /// experts-trained/<env> in the working directory]. The shipped experts are inside the binary and never
        /// replaced; a folder that holds them (the repository's experts/<env>) is refused. Use the result as
        /// `--expert checkpoint:DIR/weak.safetensors`.
        #[arg(long, short)]
        out: Option<PathBuf>,
        /// Training run directory [default: runs/expert_<env>_seed<seed>].
        #[arg(long)]
        run_dir: Option<PathBuf>,
        /// Steps between checkpoints [default: the task's evaluation period].
        #[arg(long)]
        checkpoint_every: Option<usize>,
        /// Episodes per checkpoint evaluation.
        #[arg(long, default_value_t = 100, value_parser = super::count(super::MAX_EPISODES))]
        episodes: usize,
        /// Override one training config key (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        overrides: Vec<String>,
    },
    /// Print an expert's statistics: mean and std of the return, min, average steps, and the target.
    #[command(after_help = SPEC_HELP)]
    Eval {
        #[command(flatten)]
        expert: ExpertArgs,
        /// Episodes to play (each from its own seed).
        #[arg(long, default_value_t = 100, value_parser = super::count(super::MAX_EPISODES))]
        episodes: usize,
        /// Episode i resets with seed SEED + i (a non-negative integer).
        #[arg(long, default_value_t = 10_000, allow_negative_numbers = true, value_parser = super::seed)]
        seed: u64,
        /// Print JSON instead of a table row.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Subcommand)]
pub enum DemoCommand {
    /// Collect whole expert episodes until N transitions are gathered, as DQfD does, into a .jsonl file.
    #[command(after_help = SPEC_HELP)]
    Collect {
        #[command(flatten)]
        expert: ExpertArgs,
        /// Number of transitions.
        #[arg(long, value_parser = super::count(arld::expert::demos::MAX_TRANSITIONS as u64))]
        transitions: usize,
        /// Episode i resets with seed SEED + i (a non-negative integer).
        #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = super::seed)]
        seed: u64,
        /// Output file.
        #[arg(long, short)]
        out: PathBuf,
    },
    /// Write a Minari dataset (Arrow format) as a .jsonl demonstration file, read and checked as `demo_file`
    /// reads it: its spaces must be the environment's.
    Convert {
        /// The dataset: its directory, its data/ directory, or its id (namespace/name-vN, under
        /// MINARI_DATASETS_PATH, else ~/.minari/datasets).
        dataset: PathBuf,
        /// The task the demonstrations are for (its Gymnasium id; `arld env list` lists them).
        #[arg(long)]
        env: String,
        /// Output file.
        #[arg(long, short)]
        out: PathBuf,
    },
}

pub fn run_expert(cmd: ExpertCommand) -> Result<ExitCode> {
    match cmd {
        ExpertCommand::Eval {
            expert: args,
            episodes,
            seed,
            json,
        } => {
            super::last_seed(seed, episodes)?;
            let ExpertArgs {
                env,
                expert,
                expert_timeout,
            } = args;
            let s = evaluate_spec(&expert, &env, episodes, seed, expert_timeout)?;
            let target = arld::env::task_spec(&env)?.solve_threshold();
            if json {
                println!(
                    "{}",
                    serde_json::json!({"env": env, "expert": expert, "stats": s, "target": target})
                );
            } else {
                println!("| env | expert | mean ± std | min | avg steps | target |");
                println!("|---|---|---|---|---|---|");
                println!(
                    "| {env} | {expert} | {:.2} ± {:.2} | {:.1} | {:.1} | {target} |",
                    s.mean, s.std, s.min, s.mean_len
                );
                if let Some(p) = arld::paper::expert_stats(&env) {
                    println!(
                        "| {env} | paper's expert | {:.2} ± {:.2} | {:.1} | {:.1} | {target} |",
                        p.mean_return, p.std_return, p.min_return, p.mean_episode_length
                    );
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        ExpertCommand::Train {
            env,
            seed,
            net,
            method,
            out,
            run_dir,
            checkpoint_every,
            episodes,
            overrides,
        } => {
            let out = out.unwrap_or_else(|| PathBuf::from("experts-trained").join(&env));
            anyhow::ensure!(
                !expert::shipped::holds_shipped(&out),
                "{} holds shipped experts, which `expert train` never replaces: give another folder with \
                 --out DIR (the default is experts-trained/{env})",
                out.display()
            );
            let mut input = ConfigInput::new(&env, method, net, seed);
            for o in &overrides {
                input.apply_override(o)?;
            }
            // Checkpoints at every evaluation unless asked otherwise: the candidates of the selection.
            let every = match checkpoint_every {
                Some(every) => every,
                None => input.resolve()?.eval_period,
            };
            input.set("checkpoint_every", every as i64)?;
            let cfg = input.resolve()?;
            let run_dir = run_dir
                .unwrap_or_else(|| PathBuf::from("runs").join(format!("expert_{env}_seed{seed}")));
            // A finished training run of this configuration is reused: only the selection runs again.
            match run_or_reuse(&cfg, &run_dir, true)? {
                None => eprintln!("reusing the finished training run in {}", run_dir.display()),
                Some(summary) => eprintln!("trained: final score {:.2}", summary.final_score),
            }
            eprintln!("evaluating every checkpoint over {episodes} episodes");
            let candidates = evaluate_checkpoints(
                &run_dir.join(arld::train::run_dir::CHECKPOINTS_DIR),
                &env,
                episodes,
            )?;
            let (weak, perfect) = select_experts(&candidates, &env)?;
            std::fs::create_dir_all(&out)
                .with_context(|| format!("cannot create the output folder {}", out.display()))?;
            let command = std::env::args().collect::<Vec<_>>().join(" ");
            let mut selection =
                serde_json::json!({ "env": env, "command": command, "candidates": candidates });
            for (name, idx) in [("weak", weak), ("perfect", perfect)] {
                match idx {
                    Some(i) => {
                        let c = &candidates[i];
                        let bytes =
                            arld::files::read_bounded(&c.path, arld::nn::MAX_MODEL_FILE_BYTES)?;
                        arld::files::write_atomic(
                            &out.join(format!("{name}.safetensors")),
                            &bytes,
                        )?;
                        println!(
                            "{name}: step {} mean {:.2} ± {:.2} (min {:.1}), {:.1} steps",
                            c.step, c.stats.mean, c.stats.std, c.stats.min, c.stats.mean_len
                        );
                        selection[name] = serde_json::to_value(c)?;
                    }
                    None => {
                        println!("{name}: no checkpoint fits; train longer or with another seed")
                    }
                }
            }
            arld::files::write_atomic(
                &out.join("selection.json"),
                serde_json::to_string_pretty(&selection)?.as_bytes(),
            )?;
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// The statistics of every checkpoint in `dir` (a discrete run's Q-networks or a box run's actors), over
/// `episodes` episodes from seed 10,000.
fn evaluate_checkpoints(dir: &Path, env: &str, episodes: usize) -> Result<Vec<Candidate>> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("no checkpoints in {}", dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "safetensors"))
        .collect();
    paths.sort();
    let mut out = Vec::new();
    for path in paths {
        let step = path
            .file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| s.strip_prefix("step_"))
            .and_then(|s| s.parse().ok())
            .unwrap_or(0);
        let spec = format!("checkpoint:{}", path.display());
        let stats = evaluate_spec(
            &spec,
            env,
            episodes,
            10_000,
            expert::process::DEFAULT_TIMEOUT_S,
        )?;
        out.push(Candidate { path, step, stats });
    }
    Ok(out)
}

/// Collects `transitions` demonstrations of `expert` on `env` (episode i reset with seed `seed + i`) into `out`,
/// and says what they hold.
fn collect_into<A: DemoAction>(
    env: &str,
    expert: &mut dyn expert::Expert<A>,
    transitions: usize,
    seed: u64,
    out: &Path,
) -> Result<ExitCode> {
    let demos = Demonstrations::collect(env, expert, transitions, seed)?;
    demos.save(out)?;
    let ret: f32 = demos.transitions.iter().map(|t| t.reward).sum();
    println!(
        "{} transitions in {} episodes (mean return per episode {:.2}) -> {}",
        demos.transitions.len(),
        demos.episodes(),
        ret / demos.episodes().max(1) as f32,
        out.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// Writes the Minari dataset `dataset` as demonstrations for `env` into `out`, and says what they hold.
fn convert_into<A: DemoAction>(dataset: &Path, env: &str, out: &Path) -> Result<ExitCode> {
    let Some(data) = arld::expert::minari::dataset_dir(dataset)? else {
        anyhow::bail!(
            "{} is not a Minari dataset (no data/{} in it)",
            dataset.display(),
            arld::expert::minari::METADATA_FILE
        );
    };
    let demos = arld::expert::minari::load::<A>(&data, env)?;
    demos.save(out)?;
    println!(
        "{} transitions in {} episodes -> {}",
        demos.transitions.len(),
        demos.episodes(),
        out.display()
    );
    Ok(ExitCode::SUCCESS)
}

pub fn run_demo(cmd: DemoCommand) -> Result<ExitCode> {
    match cmd {
        DemoCommand::Convert { dataset, env, out } => {
            if arld::env::box_spec(&env).is_ok() {
                convert_into::<Vec<f32>>(&dataset, &env, &out)
            } else {
                convert_into::<usize>(&dataset, &env, &out)
            }
        }
        DemoCommand::Collect {
            expert,
            transitions,
            seed,
            out,
        } => {
            // A task with actions in a box asks its experts of box actions.
            if let Ok(spec) = arld::env::box_spec(&expert.env) {
                let mut e =
                    expert::boxed::from_spec(&expert.expert, spec, seed, expert.expert_timeout)?;
                collect_into(&expert.env, e.as_mut(), transitions, seed, &out)
            } else {
                let mut e = expert.build(seed)?;
                collect_into(&expert.env, e.as_mut(), transitions, seed, &out)
            }
        }
    }
}
