//! `arld train`: one training run with the paper's presets, a config file and `--set` overrides.
use arld::expert::web::WebOptions;
use arld::lab::run_one;
use arld::train::session::{Begin, Session};
use arld::train::{Algo, ConfigInput, Method, NetKind, TrainConfig};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args)]
#[command(
    after_help = "Examples:\n  arld train --env CartPole-v0 --method dqn --net bootstrap --seed 0\n  \
arld train --env Acrobot-v1 --method adqn --net noisy --set t_query=0.1 --set train_steps=50000\n  \
arld train --env CartPole-v0 --method adqn --expert web     (a person answers in the browser)\n\n\
Configuration is layered: the paper's preset for the task and method, then --config FILE (TOML with any of the \
keys), then each --set key=value. `arld train --env ID --method M --print-config` shows every key with its value.\n\n\
A run snapshots itself every `snapshot_every` steps and when stopped (Ctrl-C, SIGTERM); `arld train --resume RUN_DIR` \
continues it to the results an uninterrupted run gives (a run stopped before its first snapshot starts again from step 0); \
a snapshot that cannot be read (damaged, or a link, folder or device in its place) is an error that keeps it, and \
`arld train --resume RUN_DIR --restart` starts the run over. One process works in a run directory at a time: a second \
`arld train` there is refused, naming the one that holds it. \
A run that ends with an error writes failed.json in its directory: the error, the step, the time, the arld version and commit."
)]
pub struct TrainArgs {
    #[arg(long, required_unless_present_any = ["resume", "config"], help = super::ENV_HELP)]
    env: Option<String>,
    /// Learning method [default: the config file's `method`, else dqn].
    #[arg(long, value_enum)]
    method: Option<Method>,
    /// Output stage of the Q-network: plain, bootstrap (10 heads, "-B") or noisy ("-N") [default: the config
    /// file's `net`, else bootstrap].
    #[arg(long, value_enum)]
    net: Option<NetKind>,
    /// Learner of a task with actions in a box (Pendulum-v1, MountainCarContinuous-v0,
    /// LunarLanderContinuous-v3): td3 or sac [default: the config file's `algo`, else td3]. The method keeps its
    /// meaning: adqn is an active TD3 (or SAC) asking the expert where its critics disagree.
    #[arg(long, value_enum)]
    algo: Option<Algo>,
    /// Seed of every random draw of the run (a non-negative integer; the same seed gives the same bytes)
    /// [default: the config file's `seed`, else 0].
    #[arg(long, allow_negative_numbers = true, value_parser = super::seed)]
    seed: Option<u64>,
    /// TOML file of config keys over the preset (a run's config.toml is one); --env, --method, --net, --seed
    /// and --set win over it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override one config key (repeatable), e.g. --set lr=0.001.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// Who answers the agent's questions (overrides the config's `expert`): shipped:weak, shipped:perfect
    /// (arld's own experts, inside the binary), scripted, checkpoint:PATH, noisy:P:SPEC, cmd:COMMAND (a program in
    /// any language speaking JSON lines, e.g. cmd:"python3 examples/expert.py"), web (a person answers in a
    /// browser: the run prints the URL to open) [default: the preset's, shipped:weak].
    #[arg(long)]
    expert: Option<String>,
    /// Web expert: the address to listen on [default: 127.0.0.1:8765; port 0 picks a free one]. Another
    /// address than 127.0.0.1 is reachable from other machines (the run warns).
    #[arg(long, value_name = "IP:PORT")]
    listen: Option<String>,
    /// Web expert: answer in real time, the environment advancing N steps per second with the held key (the
    /// no-op action when none is held) [default: turn-based, one step per key].
    #[arg(long, value_name = "N")]
    web_fps: Option<String>,
    /// Web expert in real time: each question hands the person S seconds of play (ceil(S x N) steps at
    /// --web-fps N), unless `segment_len` is set [default: 3].
    #[arg(long, value_name = "S")]
    web_segment_s: Option<String>,
    /// Web expert: a question nobody answers within S seconds goes back to the agent, logged as unanswered
    /// and not charged to the budget [default: the run waits].
    #[arg(long, value_name = "S")]
    web_timeout: Option<String>,
    /// Web expert: start training at once instead of waiting for the page to be opened.
    #[arg(long)]
    web_no_wait: bool,
    /// Demonstrations for pre-training (DQfD, ADQNP): a file of `arld demo collect`, or a Minari dataset in
    /// the Arrow format (its directory, or its id such as person/answers-v0, looked up under
    /// MINARI_DATASETS_PATH, else ~/.minari/datasets) [default: collected from the expert].
    #[arg(long, value_name = "FILE|DATASET")]
    demos: Option<PathBuf>,
    /// Run directory [default: runs/<env>_<method>-<net>_seed<seed>].
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Replace the run in the output directory (without it, a directory that is not empty is refused, so that
    /// nothing of an earlier run is mixed into the new one).
    #[arg(long)]
    overwrite: bool,
    /// Print the resolved configuration as TOML and exit.
    #[arg(long)]
    print_config: bool,
    /// Continue the interrupted run in RUN_DIR from its snapshot, with the configuration it was started with
    /// (its config.toml); a run stopped before its first snapshot starts again from step 0.
    #[arg(long, value_name = "RUN_DIR", conflicts_with_all = ["env", "config", "overrides", "expert", "demos", "out", "overwrite", "print_config"])]
    resume: Option<PathBuf>,
    /// With --resume: start the run in RUN_DIR over from step 0 with its configuration, discarding its snapshot
    /// and logs (its failed.json is kept until the run finishes).
    #[arg(long, requires = "resume")]
    restart: bool,
    /// Hide the progress bar.
    #[arg(long)]
    quiet: bool,
}

/// Resolves the layered configuration of a `train` invocation.
pub fn resolve(args: &TrainArgs) -> anyhow::Result<TrainConfig> {
    if let Some(dir) = &args.resume {
        // The run's own config.toml names its environment, method, network and seed.
        let config = dir.join(arld::train::run_dir::CONFIG_FILE);
        anyhow::ensure!(
            config.is_file(),
            "{} holds no run to resume: it has no {} (the configuration a run writes when it starts)",
            dir.display(),
            arld::train::run_dir::CONFIG_FILE
        );
        anyhow::ensure!(
            !arld::train::run_dir::is_complete(dir),
            "{} holds a finished run (it has {}): there is nothing to resume",
            dir.display(),
            arld::train::run_dir::SUMMARY_FILE
        );
        // The preset under it is the one of the env, method, net and seed the file names.
        let placeholder = arld::train::run_dir::RunId {
            env: "CartPole-v0".into(),
            method: Method::Dqn,
            net: NetKind::Bootstrap,
            seed: 0,
        };
        return arld::train::run_dir::read_config(dir, &placeholder);
    }
    // The identity flags win over the config file's keys, which win over the defaults.
    let mut input = ConfigInput::new("", Method::Dqn, NetKind::Bootstrap, 0);
    if let Some(path) = &args.config {
        input.apply_file(path)?;
    }
    if let Some(env) = &args.env {
        input.set("env", env.as_str())?;
    }
    anyhow::ensure!(
        !input.env().is_empty(),
        "no environment: give --env, or an `env` key in the config file"
    );
    if let Some(method) = args.method {
        input.set("method", method.name())?;
    }
    if let Some(net) = args.net {
        input.set("net", net.name())?;
    }
    if let Some(algo) = args.algo {
        input.set("algo", algo.name())?;
    }
    if let Some(seed) = args.seed {
        input.set_seed(seed);
    }
    for o in &args.overrides {
        input.apply_override(o)?;
    }
    if let Some(e) = &args.expert {
        input.set("expert", e.as_str())?;
    }
    if let Some(d) = &args.demos {
        input.set("demo_file", d.display().to_string())?;
    }
    // The web expert's flags complete its spec (`web:listen=...,fps=...,timeout=...`).
    let no = Some("no".to_string()).filter(|_| args.web_no_wait);
    let web = [
        ("listen", &args.listen),
        ("fps", &args.web_fps),
        ("segment_s", &args.web_segment_s),
        ("timeout", &args.web_timeout),
        ("wait", &no),
    ];
    if web.iter().any(|(_, v)| v.is_some()) {
        let expert = input.resolve()?.expert;
        let Some(rest) = expert.strip_prefix("web") else {
            anyhow::bail!(
                "--listen, --web-fps, --web-segment-s, --web-timeout and --web-no-wait need --expert web"
            );
        };
        let mut options = rest.trim_start_matches(':').to_string();
        for (key, value) in web {
            if let Some(v) = value {
                options.push_str(&format!(",{key}={v}"));
            }
        }
        input.set("expert", options.parse::<WebOptions>()?.to_spec())?;
    }
    input.resolve()
}

pub fn run(args: TrainArgs) -> anyhow::Result<ExitCode> {
    let cfg = resolve(&args)?;
    if args.print_config {
        print!("{}", cfg.to_toml());
        return Ok(ExitCode::SUCCESS);
    }
    let dir = args
        .resume
        .clone()
        .or_else(|| args.out.clone())
        .unwrap_or_else(|| PathBuf::from("runs").join(cfg.run_name()));
    // One process per run directory: the lock is taken before anything in it is removed or written.
    let session = Session::lock(&dir)?;
    session.begin(match &args.resume {
        None => Begin::New {
            overwrite: args.overwrite,
        },
        Some(_) if args.restart => Begin::Restart,
        Some(_) => Begin::Resume,
    })?;
    arld::interrupt::install()?;
    let s = match run_one(&cfg, Some(&dir), !args.quiet) {
        Ok(s) => s,
        Err(err) if arld::interrupt::requested() => {
            // One line: what stopped the run, where it stands, how to continue.
            let signal = arld::interrupt::signal().map_or("a stop request", |(_, name)| name);
            let message = format!("{err:#}").replace('\n', " ");
            if session.has_snapshot() {
                eprintln!(
                    "arld: {signal}: {message}; the run is incomplete; continue with: arld train --resume {}",
                    dir.display()
                );
            } else {
                eprintln!("arld: {signal}: the run stopped before its first snapshot: {message}");
            }
            return Ok(ExitCode::from(arld::interrupt::exit_status()));
        }
        Err(err) => {
            // Whatever ended it, the run stays incomplete: no summary.json, its logs whole up to here.
            eprintln!("error: {}", arld::errors::error_line(&err));
            if let Some(incomplete) = session.close_failed() {
                eprintln!("{incomplete}");
            }
            return Ok(ExitCode::FAILURE);
        }
    };
    println!(
        "{}: steps to solve {}{}, final score {:.2}, demonstrated transitions {}, {:.0} steps/s, {:.1} s -> {}",
        cfg.run_name(),
        s.steps_to_solve,
        if s.solved { "" } else { " (not solved)" },
        s.final_score,
        demonstrated(s.demos_pretrain, s.demos_queried),
        s.steps_per_s,
        s.wall_time_s,
        dir.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// The demonstrated transitions of a finished run, as its closing line says them: those it pre-trained on and
/// those it asked for during training (`150 pre-training + 0 asked`), or the one count that is not zero.
fn demonstrated(pretrain: usize, queried: usize) -> String {
    match (pretrain, queried) {
        (0, queried) => format!("{queried} asked"),
        (pretrain, 0) => format!("{pretrain} in pre-training"),
        (pretrain, queried) => format!("{pretrain} in pre-training + {queried} asked"),
    }
}
