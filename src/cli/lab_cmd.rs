//! The laboratory's commands (arld-lab): `arld sweep`, `arld report`, `arld reproduce` and `arld runs`: many
//! seeded runs in parallel, their tables and figures, and the runs' packs.
use anyhow::{Context, Result, bail};
use arld::lab::protocol::{paper_grids, part_names};
use arld::lab::report::report;
use arld::lab::run_spec;
use arld::lab::slurm::{self, SlurmOptions};
use arld::lab::sweep::{RunState, Shard, SweepGrid, SweepOutcome, run_grid_shard, sweep_status};
use arld::lab::verdict;
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args)]
#[command(
    after_help = "Examples:\n  arld sweep --env CartPole-v0 --method dqn,adqn --net bootstrap,noisy --seeds 5 -o runs/sweep\n  \
arld sweep --grid grid.toml -o runs/sweep       # [sweep] envs = [...], methods = [...], nets = [...], seeds = 20\n\n\
A sweep is resumable: finished runs (with summary.json) are skipped, an interrupted run continues from its snapshot \
(Ctrl-C or SIGTERM makes the runs in progress write one and stop; exit code 75).\n\n\
On a Slurm cluster, --slurm submits the sweep as a job array (one task per shard of runs; requeueable) instead of \
running it here:\n  arld sweep --env CartPole-v0 --method dqn,adqn --seeds 20 -o runs/sweep --slurm --partition cpu --time 4:00:00\n  \
arld sweep --status runs/sweep                   # runs done, running, failed and pending, and on which node"
)]
pub struct SweepArgs {
    /// TOML file with a [sweep] table (envs, methods, nets, seeds, t_query, experts, set, vary).
    #[arg(long, conflicts_with_all = ["env", "method", "net"])]
    grid: Option<PathBuf>,
    /// Tasks, as Gymnasium ids (comma-separated or repeated): CartPole-v0, Acrobot-v1, MountainCar-v0,
    /// LunarLander-v2, ..., and the box tasks Pendulum-v1, MountainCarContinuous-v0, LunarLanderContinuous-v3
    /// (`arld env list` lists them all).
    #[arg(long)]
    env: Vec<String>,
    /// Methods: dqn, dqfd, gdqn, bdqn, adqn, adqnp (for a box task, TD3 or SAC learns: --set algo=sac).
    #[arg(long)]
    method: Vec<String>,
    /// Networks: plain, bootstrap, noisy.
    #[arg(long, default_value = "bootstrap,noisy")]
    net: Vec<String>,
    /// Seeds: a count ("20"), a range ("3..8") or a list ("0,4,9").
    #[arg(long, default_value = "5")]
    seeds: String,
    /// t_query values to sweep (a variant per value).
    #[arg(long)]
    t_query: Vec<String>,
    /// Experts to sweep (a variant per spec): shipped:weak, shipped:perfect, scripted, checkpoint:PATH,
    /// noisy:P:SPEC, cmd:COMMAND (`arld expert eval --help` explains each).
    #[arg(long)]
    expert: Vec<String>,
    /// Config override applied to every run (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    overrides: Vec<String>,
    /// A variant per override (repeatable), e.g. --vary n_r=100 --vary n_r=10000; runs go to `.../n_r-100/seedN`.
    /// Overrides joined by `;` vary together: --vary 'budget=50;query_rule=paced'.
    #[arg(long, value_name = "KEY=VALUE")]
    vary: Vec<String>,
    /// Parallel runs (0: one per core).
    #[arg(long, default_value_t = 0)]
    jobs: usize,
    /// Sweep directory.
    #[arg(long, short, required_unless_present = "status")]
    out: Option<PathBuf>,
    /// Run only shard I of N of the sweep's runs (0 <= I < N; runs dealt round-robin), e.g. --shard 3/8.
    #[arg(long, value_name = "I/N")]
    shard: Option<Shard>,

    /// Show which runs of the sweep in DIR are done, running, failed (with the first line of the error in their
    /// failed.json) or pending, and where; runs nothing.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["grid", "env", "method", "out", "shard", "slurm"])]
    status: Option<PathBuf>,
    /// Submit the sweep to Slurm as a job array instead of running it here.
    #[arg(long, conflicts_with = "shard")]
    slurm: bool,
    /// Slurm partition [default: the cluster's default].
    #[arg(long, requires = "slurm")]
    partition: Option<String>,
    /// Time limit of one array task, in Slurm's format (e.g. 4:00:00) [default: the partition's].
    #[arg(long, requires = "slurm")]
    time: Option<String>,
    /// Array tasks running at once [default: no limit].
    #[arg(long, requires = "slurm")]
    array_parallelism: Option<usize>,
    /// Array tasks [default: one per run]; each runs its share of the runs, --jobs at a time.
    #[arg(long, requires = "slurm")]
    shards: Option<usize>,
    /// Seconds before the time limit at which runs snapshot and the task requeues itself.
    #[arg(long, requires = "slurm", default_value_t = 300)]
    signal_lead: u64,
    /// With --slurm: write and print the job script, but do not submit it.
    #[arg(long, requires = "slurm")]
    dry_run: bool,
}

#[derive(Args)]
#[command(
    after_help = "Your own analysis can quote the report: a file NAME.in.md in the output directory is written \
out as NAME.md with every {{FILE|SECTION|ROW|COLUMN}} replaced by that cell of a table the report wrote, e.g. \
{{readings.md|Acrobot-v1|ADQN-B|first hit|value}}. A quote may check what its sentence relies on \
({{readings.md|Acrobot-v1|GDQN-B|first hit/p|<0.05|as-p}} writes \"p = 0.031\"); when the runs move a checked \
value across, the report fails and names the line to read again. The syntax: crates/arld-lab/src/quote.rs; an example: \
results/VERDICT.in.md. Not with --from-evaluations."
)]
pub struct ReportArgs {
    /// A sweep directory (any directory holding run directories), or with --from-evaluations an
    /// evaluations.csv.gz written by an earlier report (e.g. results/evaluations.csv.gz; or that file decompressed).
    dir: PathBuf,
    /// Where tables and figures go [default: DIR/report, or the CSV's directory with --from-evaluations].
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Evaluations a sustained solve must hold for after reaching the target (the "sustained" reading).
    #[arg(long, default_value_t = arld::lab::verdict::DEFAULT_SUSTAIN)]
    sustain: usize,
    /// Read DIR as an evaluations.csv.gz and write only the readings, claims and ablations tables (no figures).
    #[arg(long)]
    from_evaluations: bool,
}

#[derive(Args)]
#[command(
    after_help = "The full protocol is 20 seeds x 6 methods x 2 networks on the four tasks (Table 5, \
Figures 2-3), plus the t_query sweep (Figure 4) and the expert-quality sweep on LunarLander (Figure 5); beyond the \
paper, the N_r study and the ablations of the open choices (parts n_r and ablations). --quick runs \
the methods comparison on CartPole-v0 with 3 seeds. Interrupt it any time: the same command again continues \
where it stopped."
)]
pub struct ReproduceArgs {
    /// Only these environments (repeatable): the paper's four tasks, or a task with actions in a box (part
    /// continuous) [default: every task of the parts run].
    #[arg(long)]
    env: Vec<String>,
    /// Seeds per configuration (0..SEEDS).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(1..=arld::lab::sweep::MAX_SEEDS))]
    seeds: u64,
    /// A few minutes on CartPole-v0: the methods comparison with 3 seeds.
    #[arg(long)]
    quick: bool,
    /// Which parts: methods, t_query, experts, n_r, ablations, effort, held_out, held_out_2, continuous
    /// (repeatable) [default: all].
    #[arg(long)]
    part: Vec<String>,
    /// Parallel runs (0: one per core).
    #[arg(long, default_value_t = 0)]
    jobs: usize,
    /// Output directory: every part's runs go into one tree, `ENV/METHOD-NET[/VARIANT]/seedN`.
    #[arg(long, short, default_value = "runs/reproduce")]
    out: PathBuf,
    /// Where the report goes [default: OUT/report].
    #[arg(long, value_name = "DIR")]
    report: Option<PathBuf>,
}

pub fn run_sweep(args: SweepArgs) -> Result<ExitCode> {
    if let Some(dir) = &args.status {
        return print_status(dir);
    }
    let out = args
        .out
        .clone()
        .expect("clap requires --out without --status");
    let grid = match &args.grid {
        Some(path) => SweepGrid::from_toml_file(path)?,
        None => {
            if args.env.is_empty() || args.method.is_empty() {
                bail!("give --grid FILE, or at least --env and --method");
            }
            SweepGrid::from_cli_values(
                &args.env,
                &args.method,
                &args.net,
                &args.seeds,
                &args.t_query,
                &args.expert,
                &args.overrides,
                &args.vary,
            )?
        }
    };
    if args.slurm {
        return submit_slurm(&args, &grid, &out);
    }
    arld::interrupt::install()?;
    let Some(outcome) = interruptible(run_grid_shard(
        &grid, &out, args.jobs, args.shard, &run_spec,
    ))?
    else {
        return Ok(ExitCode::from(slurm::EXIT_INTERRUPTED));
    };
    for (path, problem) in &outcome.damaged {
        println!("damaged and run again: {} ({problem})", path.display());
    }
    println!(
        "{} runs ({} already complete, {} the same as a finished run, {} run now); results: {}",
        outcome.total,
        outcome.already_complete,
        outcome.reused,
        outcome.completed,
        outcome.results_csv.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn submit_slurm(args: &SweepArgs, grid: &SweepGrid, out: &std::path::Path) -> Result<ExitCode> {
    let runs = grid.specs()?.len();
    let opts = SlurmOptions {
        partition: args.partition.clone(),
        time: args.time.clone(),
        array_parallelism: args.array_parallelism,
        shards: args.shards.unwrap_or(runs).min(runs),
        cpus_per_task: args.jobs.max(1),
        signal_lead_s: args.signal_lead,
    };
    let arld = std::env::current_exe()?;
    let script = slurm::job_script(out, &arld, &opts)?;
    if args.dry_run {
        print!("{script}");
        return Ok(ExitCode::SUCCESS);
    }
    arld::lab::sweep::prepare_sweep_dir(grid, out)?;
    std::fs::create_dir_all(out.join("slurm"))?;
    let path = out.join("slurm").join("job.sh");
    arld::files::write_atomic(&path, script.as_bytes())?;
    let job = slurm::submit(&path)?;
    println!(
        "submitted job array {job}: {runs} runs in {} tasks (script {})
         follow it with:  squeue -j {job}    arld sweep --status {}
         task output:     {}/slurm/{job}_<task>.out
         when it is done: arld report {}",
        opts.shards,
        path.display(),
        out.display(),
        out.display(),
        out.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn print_status(dir: &std::path::Path) -> Result<ExitCode> {
    let runs = sweep_status(dir)?;
    let (mut done, mut running, mut failed, mut interrupted, mut pending) = (0, 0, 0, 0, 0);
    let mut older = 0;
    for (spec, state) in &runs {
        let name = spec.dir_name();
        match state {
            RunState::Done => {
                done += 1;
                older += usize::from(arld::train::run_dir::is_stale(&dir.join(&name)));
            }
            RunState::Running { host, slurm_job } => {
                running += 1;
                let job = slurm_job
                    .as_ref()
                    .map(|j| format!(" (Slurm job {j})"))
                    .unwrap_or_default();
                println!("running      {} on {host}{job}", name.display());
            }
            RunState::Failed { host, error, step } => {
                failed += 1;
                let at = step.map(|s| format!(" at step {s}")).unwrap_or_default();
                println!("failed       {} on {host}{at}: {error}", name.display());
            }
            RunState::Interrupted { host } => {
                interrupted += 1;
                println!("interrupted  {} (last on {host})", name.display());
            }
            RunState::Pending => pending += 1,
        }
    }
    let older = if older > 0 {
        format!(
            " ({older} by an older arld with the C library's elementary functions: the sweep computes them again)"
        )
    } else {
        String::new()
    };
    println!(
        "{} runs: {done} done{older}, {running} running, {failed} failed, {interrupted} interrupted, {pending} \
         pending",
        runs.len()
    );
    Ok(ExitCode::SUCCESS)
}

pub fn run_report(args: ReportArgs) -> Result<ExitCode> {
    if args.from_evaluations {
        let runs = verdict::runs_from_evaluations_csv(&args.dir)?;
        let out = args.out.unwrap_or_else(|| {
            args.dir
                .parent()
                .map_or_else(|| PathBuf::from("."), std::path::Path::to_path_buf)
        });
        std::fs::create_dir_all(&out)
            .with_context(|| format!("cannot create {}", out.display()))?;
        let cells = verdict::cells(&runs, args.sustain);
        let (files, _) = verdict::write_verdict(&cells, &out, args.sustain)?;
        println!("{} runs; wrote:", runs.len());
        for f in &files {
            println!("  {}", f.display());
        }
        return Ok(ExitCode::SUCCESS);
    }
    let out = args.out.unwrap_or_else(|| args.dir.join("report"));
    print_report(&args.dir, &out, args.sustain)
}

fn print_report(dir: &std::path::Path, out: &std::path::Path, sustain: usize) -> Result<ExitCode> {
    let summary = report(dir, out, sustain)?;
    for note in &summary.notes {
        eprintln!("note: {note}");
    }
    println!("{} runs; wrote:", summary.runs);
    for f in &summary.files {
        println!("  {}", f.display());
    }
    let table = out.join("table.md");
    if let Ok(text) = arld::files::read_text_bounded(&table, 16 << 20) {
        println!("\n{text}");
    }
    Ok(ExitCode::SUCCESS)
}

/// The outcome of a sweep, or `None` when it was stopped (Ctrl-C, SIGTERM): then its runs in progress wrote
/// snapshots, and the same command continues them.
fn interruptible(outcome: Result<SweepOutcome>) -> Result<Option<SweepOutcome>> {
    match outcome {
        Ok(outcome) => Ok(Some(outcome)),
        Err(err) if arld::interrupt::requested() => {
            eprintln!(
                "stopped: the runs in progress wrote snapshots; the same command continues them\n{err:#}"
            );
            Ok(None)
        }
        Err(err) => Err(err),
    }
}

pub fn run_reproduce(args: ReproduceArgs) -> Result<ExitCode> {
    let (envs, seeds, parts) = if args.quick {
        (
            vec!["CartPole-v0".to_string()],
            3,
            vec!["methods".to_string()],
        )
    } else {
        (args.env.clone(), args.seeds, args.part.clone())
    };
    let known = part_names();
    for p in &parts {
        if !known.contains(&p.as_str()) {
            bail!("unknown part '{p}'; known parts: {}", known.join(", "));
        }
    }
    for e in &envs {
        arld::env::registry::task(e)?;
    }
    arld::interrupt::install()?;
    let mut ran_any = false;
    for (name, mut grid) in paper_grids(seeds) {
        if !parts.is_empty() && !parts.iter().any(|p| p == name) {
            continue;
        }
        if !envs.is_empty() {
            grid.envs.retain(|e| envs.contains(e));
        }
        if grid.envs.is_empty() {
            continue;
        }
        ran_any = true;
        eprintln!("== {name}: {} runs", grid.specs()?.len());
        let Some(outcome) =
            interruptible(run_grid_shard(&grid, &args.out, args.jobs, None, &run_spec))?
        else {
            return Ok(ExitCode::from(slurm::EXIT_INTERRUPTED));
        };
        eprintln!(
            "   {} complete ({} were already, {} the same as a finished run)",
            outcome.total, outcome.already_complete, outcome.reused
        );
    }
    if !ran_any {
        bail!("nothing to run: no part of the protocol covers {envs:?}");
    }
    let report_dir = args.report.unwrap_or_else(|| args.out.join("report"));
    print_report(&args.out, &report_dir, arld::lab::verdict::DEFAULT_SUSTAIN)
}

/// `arld runs`: a directory of runs as a compact dataset and back.
#[derive(clap::Subcommand)]
pub enum RunsCommand {
    /// Pack every finished run below DIR into gzip-compressed CSV tables per task (DIR/TASK/*.csv.gz), merged
    /// with the runs already packed there. Checks that every run comes back byte for byte before writing.
    #[command(
        after_help = "The tables: runs.csv.gz (the index), configs.csv.gz and summaries.csv.gz (one column per \
key), eval.csv.gz, queries.csv.gz and episodes.csv.gz (the logs' rows after a `run` column), verbatim.csv.gz (a \
file the tables cannot give back exactly) and layout.json. In pandas:\n  \
pd.concat(pd.read_csv(f) for f in glob.glob(\"DIR/*/eval.csv.gz\"))\n\n\
Binary files (weights, snapshots, event files) are not packed; the run directories are left as they are."
    )]
    Pack {
        /// A directory of runs (`TASK/METHOD-NET[/VARIANT]/seedN`), such as results/runs.
        dir: PathBuf,
    },
    /// Write every packed run of DIR as a run directory below OUT, byte for byte as it was packed. Only missing
    /// files are written; a file that is there with other bytes stops the command and is not replaced.
    Unpack {
        /// A packed dataset, such as results/runs.
        dir: PathBuf,
        /// Where the run directories go [default: DIR itself].
        #[arg(long, short)]
        out: Option<PathBuf>,
    },
}

pub fn run_runs(cmd: RunsCommand) -> Result<ExitCode> {
    use arld::lab::pack;
    match cmd {
        RunsCommand::Pack { dir } => {
            let s = pack::pack(&dir)?;
            for path in &s.left_out {
                eprintln!(
                    "not packed (not a text file of a run, or too long for a dataset): {}",
                    path.display()
                );
            }
            println!(
                "{} runs packed in {} ({} new; {} tables written, {} files kept verbatim)",
                s.runs,
                dir.display(),
                s.added,
                s.tables_written,
                s.verbatim
            );
        }
        RunsCommand::Unpack { dir, out } => {
            let out = out.unwrap_or_else(|| dir.clone());
            let s = pack::unpack(&dir, &out)?;
            println!(
                "{} runs unpacked into {}: {} files written, {} already there",
                s.runs,
                out.display(),
                s.written,
                s.present
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
