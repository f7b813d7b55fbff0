//! Slurm submission of sweeps: one job array whose tasks each run a shard of the sweep's runs
//! (`arld sweep --grid DIR/sweep.toml -o DIR --shard I/N`), the same command that runs a sweep locally.
//!
//! The job is requeueable (`--requeue`), and Slurm sends the batch script a signal some minutes before the time
//! limit ([`SlurmOptions::signal_lead_s`]). The script passes it on to `arld` as SIGTERM, which makes every run in
//! progress write its snapshot and stop; the script then requeues its own array task, and the next attempt
//! continues those runs from their snapshots. A node lost or a job requeued by the scheduler (preemption,
//! `scontrol requeue`) ends the same way: Slurm sends SIGTERM first. Finished runs are never run twice: a run is
//! complete when its `summary.json` exists.
//!
//! [`job_script`] writes the script (it is plain text, printed by `--dry-run`); [`submit`] hands it to `sbatch`.

use anyhow::{Context, Result, bail};
use std::path::Path;
use std::process::Command;

/// How the job array is asked for.
#[derive(Debug, Clone, PartialEq)]
pub struct SlurmOptions {
    /// `--partition`; the cluster's default partition when `None`.
    pub partition: Option<String>,
    /// `--time` of one array task (Slurm's formats: `MM`, `HH:MM:SS`, `D-HH:MM`, ...); the partition's default
    /// when `None`.
    pub time: Option<String>,
    /// Array tasks running at once (`%N` of `--array`); no limit when `None`.
    pub array_parallelism: Option<usize>,
    /// Number of array tasks; each runs `ceil(runs / shards)` runs or fewer.
    pub shards: usize,
    /// Cores per array task, and runs in parallel within it (`--cpus-per-task`, `arld sweep --jobs`).
    pub cpus_per_task: usize,
    /// Seconds before the time limit at which runs are told to snapshot and stop (`--signal`).
    pub signal_lead_s: u64,
}

impl SlurmOptions {
    /// Checks the values that Slurm would otherwise reject later, or misread.
    pub fn validate(&self) -> Result<()> {
        if self.shards == 0 {
            bail!("a Slurm sweep needs at least one array task (shards >= 1)");
        }
        if self.cpus_per_task == 0 {
            bail!("cpus per task must be at least 1");
        }
        if self.array_parallelism == Some(0) {
            bail!("--array-parallelism must be at least 1");
        }
        if let Some(p) = &self.partition
            && (p.is_empty()
                || !p
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_.,".contains(c)))
        {
            bail!("partition name {p:?} may only contain letters, digits, '-', '_', '.' and ','");
        }
        if let Some(t) = &self.time
            && (t.is_empty()
                || !t
                    .chars()
                    .all(|c| c.is_ascii_digit() || c == ':' || c == '-'))
        {
            bail!(
                "time limit {t:?} is not in a Slurm format (minutes, MM:SS, HH:MM:SS, D-HH, D-HH:MM or D-HH:MM:SS)"
            );
        }
        Ok(())
    }
}

/// Exit code of `arld sweep` when it stopped because it was asked to (SIGTERM/SIGINT) after snapshotting its
/// runs: the batch script requeues its task on it.
pub const EXIT_INTERRUPTED: u8 = 75;

/// Quotes a string for a POSIX shell.
fn shell_quote(text: &str) -> String {
    format!("'{}'", text.replace('\'', r"'\''"))
}

/// The sbatch script of a sweep in `sweep_dir` (which holds `sweep.toml`), run with the `arld` binary at `arld`.
/// Output of each task goes to `sweep_dir/slurm/JOBID_TASK.out` (appended across requeued attempts).
pub fn job_script(sweep_dir: &Path, arld: &Path, opts: &SlurmOptions) -> Result<String> {
    opts.validate()?;
    let dir = std::path::absolute(sweep_dir)
        .with_context(|| format!("cannot resolve {}", sweep_dir.display()))?;
    let dir_text = dir
        .to_str()
        .with_context(|| format!("{} is not valid UTF-8", dir.display()))?;
    let arld_text = arld
        .to_str()
        .with_context(|| format!("{} is not valid UTF-8", arld.display()))?;
    let mut array = format!("0-{}", opts.shards - 1);
    if let Some(n) = opts.array_parallelism {
        array.push_str(&format!("%{n}"));
    }
    let mut s = String::from("#!/bin/bash\n");
    s.push_str(
        "# Written by `arld sweep --slurm`: one array task per shard of the sweep's runs.\n",
    );
    s.push_str("#SBATCH --job-name=arld-sweep\n");
    s.push_str(&format!("#SBATCH --array={array}\n"));
    s.push_str(&format!("#SBATCH --cpus-per-task={}\n", opts.cpus_per_task));
    s.push_str("#SBATCH --ntasks=1\n");
    if let Some(p) = &opts.partition {
        s.push_str(&format!("#SBATCH --partition={p}\n"));
    }
    if let Some(t) = &opts.time {
        s.push_str(&format!("#SBATCH --time={t}\n"));
    }
    s.push_str("#SBATCH --requeue\n");
    s.push_str("#SBATCH --open-mode=append\n");
    s.push_str(&format!("#SBATCH --output={dir_text}/slurm/%A_%a.out\n"));
    s.push_str(&format!(
        "#SBATCH --signal=B:USR1@{}\n\n",
        opts.signal_lead_s
    ));
    s.push_str(&format!(
        "echo \"== $(date -u +%FT%TZ) task ${{SLURM_ARRAY_TASK_ID}} attempt ${{SLURM_RESTART_COUNT:-0}} on $(hostname -s)\"\n\
# Near the time limit Slurm sends USR1 to this script: arld is told to snapshot its runs and stop (SIGTERM), and\n\
# the task requeues itself; the next attempt continues the runs from their snapshots.\n\
near_limit=0\n\
trap 'near_limit=1; kill -TERM \"$child\" 2>/dev/null' USR1\n\
# A scheduler's requeue or cancel sends SIGTERM to the whole job: arld snapshots its runs and stops.\n\
trap 'kill -TERM \"$child\" 2>/dev/null' TERM\n\
{arld} sweep --grid {grid} -o {out} --shard \"${{SLURM_ARRAY_TASK_ID}}/{shards}\" --jobs {jobs} &\n\
child=$!\n\
status=0\n\
while true; do\n\
\x20 wait \"$child\"; status=$?\n\
\x20 kill -0 \"$child\" 2>/dev/null || break\ndone\n\
if [ \"$near_limit\" = 1 ] && [ \"$status\" = {interrupted} ]; then\n\
\x20 scontrol requeue \"${{SLURM_ARRAY_JOB_ID}}_${{SLURM_ARRAY_TASK_ID}}\"\n\
fi\n\
exit \"$status\"\n",
        arld = shell_quote(arld_text),
        grid = shell_quote(&format!("{dir_text}/{}", super::sweep::SWEEP_FILE)),
        out = shell_quote(dir_text),
        shards = opts.shards,
        jobs = opts.cpus_per_task,
        interrupted = EXIT_INTERRUPTED,
    ));
    Ok(s)
}

/// Submits `script` with `sbatch` and returns the job id.
pub fn submit(script: &Path) -> Result<String> {
    let output = Command::new("sbatch")
        .arg("--parsable")
        .arg(script)
        .output()
        .context("cannot run sbatch (is Slurm installed and SLURM_CONF set?)")?;
    if !output.status.success() {
        bail!(
            "sbatch refused the job ({}): {}",
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    let text = String::from_utf8_lossy(&output.stdout);
    // `--parsable` prints `JOBID` or `JOBID;CLUSTER`.
    let id = text.trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        bail!("sbatch printed no job id: {:?}", text.trim());
    }
    Ok(id)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options() -> SlurmOptions {
        SlurmOptions {
            partition: Some("gpu".into()),
            time: Some("2:00:00".into()),
            array_parallelism: Some(4),
            shards: 10,
            cpus_per_task: 2,
            signal_lead_s: 300,
        }
    }

    #[test]
    fn script_asks_for_a_requeueable_array_with_an_early_signal() {
        let script =
            job_script(Path::new("/data/sweep"), Path::new("/opt/arld"), &options()).unwrap();
        for line in [
            "#SBATCH --array=0-9%4",
            "#SBATCH --partition=gpu",
            "#SBATCH --time=2:00:00",
            "#SBATCH --requeue",
            "#SBATCH --signal=B:USR1@300",
            "#SBATCH --cpus-per-task=2",
            "#SBATCH --output=/data/sweep/slurm/%A_%a.out",
            "'/opt/arld' sweep --grid '/data/sweep/sweep.toml' -o '/data/sweep' --shard \"${SLURM_ARRAY_TASK_ID}/10\" --jobs 2 &",
        ] {
            assert!(
                script.lines().any(|l| l == line),
                "missing {line:?} in\n{script}"
            );
        }
        let plain = job_script(
            Path::new("/s"),
            Path::new("/a"),
            &SlurmOptions {
                partition: None,
                time: None,
                array_parallelism: None,
                ..options()
            },
        )
        .unwrap();
        assert!(plain.contains("#SBATCH --array=0-9\n"));
        assert!(!plain.contains("--partition") && !plain.contains("--time"));
    }

    #[test]
    fn bad_options_are_refused() {
        for (opts, word) in [
            (
                SlurmOptions {
                    time: Some("two hours".into()),
                    ..options()
                },
                "time limit",
            ),
            (
                SlurmOptions {
                    partition: Some("a b".into()),
                    ..options()
                },
                "partition",
            ),
            (
                SlurmOptions {
                    array_parallelism: Some(0),
                    ..options()
                },
                "array-parallelism",
            ),
            (
                SlurmOptions {
                    shards: 0,
                    ..options()
                },
                "array task",
            ),
        ] {
            let err = job_script(Path::new("/s"), Path::new("/a"), &opts).unwrap_err();
            assert!(format!("{err}").contains(word), "{err}");
        }
    }

    #[test]
    fn single_quotes_survive_shell_quoting() {
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
    }
}
