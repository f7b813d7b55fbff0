//! Sweeps on a real Slurm: a one-node cluster on localhost (munged, slurmctld, slurmd) started from a
//! configuration written into a temporary directory. If the cluster cannot start, the test fails and says why.
//!
//! Needs Debian's `slurm-wlm` and `munge` and root (Slurm runs the jobs as root here): `scripts/test --setup`
//! installs them; without them the test fails, naming what is missing and that command.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

mod common;
use common::ARLD;

/// One cluster at a time: the tests' clusters share the node name and ports.
static ONE_CLUSTER: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn run(cmd: &mut Command) -> Output {
    let shown = format!("{cmd:?}");
    cmd.output()
        .unwrap_or_else(|e| panic!("cannot run {shown}: {e} (is Slurm installed? {SETUP})"))
}

/// The one command that installs what these tests need.
const SETUP: &str = "`scripts/test --setup` installs Slurm (slurm-wlm) and MUNGE (munge)";

/// Whether `program` is on the PATH or in the system directories daemons live in.
fn installed(program: &str) -> bool {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin", "/sbin"].map(PathBuf::from))
        .any(|dir| dir.join(program).is_file())
}

/// Fails, naming what is missing and the command that installs it, when the machine lacks Slurm or MUNGE.
fn check_prerequisites() {
    let missing: Vec<&str> = [
        "slurmctld",
        "slurmd",
        "sbatch",
        "squeue",
        "sinfo",
        "munged",
        "munge",
        "unmunge",
    ]
    .into_iter()
    .filter(|program| !installed(program))
    .collect();
    assert!(
        missing.is_empty(),
        "the Slurm tests cannot run; missing: {}; {SETUP}",
        missing.join(", ")
    );
}

fn text(out: &[u8]) -> String {
    String::from_utf8_lossy(out).into_owned()
}

/// A one-node Slurm cluster on localhost; its daemons are stopped when it is dropped.
struct Cluster {
    dir: tempfile::TempDir,
    conf: PathBuf,
    _one_at_a_time: std::sync::MutexGuard<'static, ()>,
}

impl Cluster {
    fn start() -> Cluster {
        check_prerequisites();
        let guard = ONE_CLUSTER.lock().unwrap_or_else(|e| e.into_inner());
        let host = text(&run(Command::new("hostname").arg("-s")).stdout)
            .trim()
            .to_string();
        assert!(!host.is_empty(), "hostname -s printed nothing");
        start_munge();
        let dir = tempfile::tempdir().expect("temporary directory");
        let d = dir.path();
        for sub in ["state", "spool"] {
            std::fs::create_dir_all(d.join(sub)).unwrap();
        }
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        let conf = d.join("slurm.conf");
        let p = |name: &str| d.join(name).display().to_string();
        std::fs::write(
            &conf,
            format!(
                "ClusterName=arldtest\n\
                 SlurmctldHost={host}(127.0.0.1)\n\
                 SlurmctldPort=16817\n\
                 SlurmdPort=16818\n\
                 SlurmUser=root\n\
                 SlurmdUser=root\n\
                 AuthType=auth/munge\n\
                 ProctrackType=proctrack/linuxproc\n\
                 TaskPlugin=task/none\n\
                 JobAcctGatherType=jobacct_gather/none\n\
                 SelectType=select/cons_tres\n\
                 SelectTypeParameters=CR_Core\n\
                 ReturnToService=2\n\
                 MpiDefault=none\n\
                 KillWait=30\n\
                 StateSaveLocation={}\n\
                 SlurmdSpoolDir={}\n\
                 SlurmctldPidFile={}\n\
                 SlurmdPidFile={}\n\
                 SlurmctldLogFile={}\n\
                 SlurmdLogFile={}\n\
                 NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory=1000\n\
                 PartitionName=debug Nodes={host} Default=YES MaxTime=INFINITE State=UP\n",
                p("state"),
                p("spool"),
                p("slurmctld.pid"),
                p("slurmd.pid"),
                p("slurmctld.log"),
                p("slurmd.log"),
            ),
        )
        .unwrap();
        let cluster = Cluster {
            dir,
            conf,
            _one_at_a_time: guard,
        };
        let out = run(Command::new("slurmctld")
            .arg("-c")
            .arg("-f")
            .arg(&cluster.conf));
        assert!(
            out.status.success(),
            "slurmctld did not start: {}{}",
            text(&out.stderr),
            cluster.logs()
        );
        let out = run(Command::new("slurmd").arg("-f").arg(&cluster.conf));
        assert!(
            out.status.success(),
            "slurmd did not start: {}{}",
            text(&out.stderr),
            cluster.logs()
        );
        let started = Instant::now();
        loop {
            let out = run(cluster.cmd("sinfo").args(["-h", "-o", "%T"]));
            let state = text(&out.stdout);
            if state.trim() == "idle" {
                break;
            }
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "the Slurm node did not become idle within 60 s (sinfo: {:?} {}){}",
                state.trim(),
                text(&out.stderr),
                cluster.logs()
            );
            std::thread::sleep(Duration::from_millis(500));
        }
        cluster
    }

    fn cmd(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", &self.conf);
        c
    }

    fn logs(&self) -> String {
        let mut s = String::new();
        for name in ["slurmctld.log", "slurmd.log"] {
            let log = std::fs::read_to_string(self.dir.path().join(name)).unwrap_or_default();
            let tail: Vec<&str> = log.lines().rev().take(15).collect();
            s.push_str(&format!("\n--- last lines of {name}:\n"));
            for line in tail.into_iter().rev() {
                s.push_str(line);
                s.push('\n');
            }
        }
        s
    }

    /// Waits until job `job` has left the queue.
    fn wait_for(&self, job: &str, limit: Duration) {
        let started = Instant::now();
        loop {
            let out = run(self.cmd("squeue").args(["-h", "-j", job, "-o", "%i %T %r"]));
            let queue = text(&out.stdout);
            if queue.trim().is_empty() {
                return;
            }
            assert!(
                started.elapsed() < limit,
                "job {job} still queued after {limit:?}:\n{queue}{}",
                self.logs()
            );
            std::thread::sleep(Duration::from_secs(1));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let mut pids = Vec::new();
        for pid_file in ["slurmd.pid", "slurmctld.pid"] {
            if let Ok(pid) = std::fs::read_to_string(self.dir.path().join(pid_file)) {
                let _ = Command::new("kill").arg(pid.trim()).status();
                pids.push(pid.trim().to_string());
            }
        }
        // Wait for the daemons to exit, so the next cluster can take the ports.
        let started = Instant::now();
        while pids
            .iter()
            .any(|p| Path::new(&format!("/proc/{p}")).exists())
            && started.elapsed() < Duration::from_secs(20)
        {
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

/// Starts MUNGE (the authentication Slurm uses) unless it already answers.
fn start_munge() {
    let works = || {
        Command::new("sh")
            .args(["-c", "munge -n | unmunge"])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if works() {
        return;
    }
    let out = run(Command::new("sh").args([
        "-c",
        "mkdir -p /run/munge && chown munge:munge /run/munge && su -s /bin/sh munge -c /usr/sbin/munged",
    ]));
    assert!(
        out.status.success(),
        "munged did not start (it needs root and the munge package; {SETUP}): {}",
        text(&out.stderr)
    );
    std::thread::sleep(Duration::from_millis(500));
    assert!(works(), "munged started but `munge -n | unmunge` fails");
}

/// The sweep both tests run: CartPole-v0, 2 methods x 3 seeds, short runs.
fn sweep_args(out: &Path) -> Vec<String> {
    [
        "sweep",
        "--env",
        "CartPole-v0",
        "--method",
        "dqn,adqn",
        "--net",
        "bootstrap",
        "--seeds",
        "3",
        "--set",
        "train_steps=3000",
        "--set",
        "eval_period=1000",
        "--set",
        "eval_episodes=3",
        "-o",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain([out.display().to_string()])
    .collect()
}

#[test]
fn an_array_sweep_on_slurm_gives_the_results_of_a_local_sweep() {
    let cluster = Cluster::start();
    let work = tempfile::tempdir().unwrap();
    let local = work.path().join("local");
    let out = run(Command::new(ARLD)
        .args(sweep_args(&local))
        .args(["--jobs", "2"]));
    assert!(
        out.status.success(),
        "local sweep failed: {}",
        text(&out.stderr)
    );

    let remote = work.path().join("slurm");
    let out = run(cluster.cmd(ARLD).args(sweep_args(&remote)).args([
        "--slurm",
        "--array-parallelism",
        "2",
        "--time",
        "20:00",
    ]));
    assert!(
        out.status.success(),
        "submission failed: {}",
        text(&out.stderr)
    );
    let said = text(&out.stdout);
    let job = said
        .split_whitespace()
        .nth(3)
        .map(|j| j.trim_end_matches(':').to_string())
        .unwrap_or_else(|| panic!("no job id in {said:?}"));
    assert!(
        said.contains("--status"),
        "says how to follow the job: {said}"
    );
    cluster.wait_for(&job, Duration::from_secs(600));

    let status = run(Command::new(ARLD).args(["sweep", "--status"]).arg(&remote));
    let status_text = text(&status.stdout);
    let outputs: String = std::fs::read_dir(remote.join("slurm"))
        .map(|d| {
            d.flatten()
                .filter(|e| e.path().extension().is_some_and(|x| x == "out"))
                .map(|e| std::fs::read_to_string(e.path()).unwrap_or_default())
                .collect()
        })
        .unwrap_or_default();
    assert!(
        status_text.contains("6 runs: 6 done"),
        "{status_text}\ntask output:\n{outputs}{}",
        cluster.logs()
    );
    let local_csv = std::fs::read(local.join("results.csv")).unwrap();
    let remote_csv = std::fs::read(remote.join("results.csv")).unwrap_or_else(|e| {
        panic!("no results.csv from the Slurm sweep ({e}); task output:\n{outputs}")
    });
    assert_eq!(
        text(&remote_csv),
        text(&local_csv),
        "results.csv of the Slurm sweep differs from the local sweep's"
    );
    // Every array task ran on the cluster's node.
    assert_eq!(outputs.matches("== ").count(), 6, "{outputs}");
}

#[test]
fn a_requeued_job_continues_its_runs_from_their_snapshots() {
    let cluster = Cluster::start();
    let work = tempfile::tempdir().unwrap();
    // Longer runs with frequent snapshots, so the job is requeued while a run is half done.
    let args = |out: &Path| {
        let mut a = sweep_args(out);
        let i = a.iter().position(|s| s == "train_steps=3000").unwrap();
        a[i] = "train_steps=12000".to_string();
        a.extend(["--set".to_string(), "snapshot_every=500".to_string()]);
        let i = a.iter().position(|s| s == "--seeds").unwrap();
        a[i + 1] = "1".to_string();
        a
    };
    let local = work.path().join("local");
    let out = run(Command::new(ARLD).args(args(&local)).args(["--jobs", "2"]));
    assert!(
        out.status.success(),
        "local sweep failed: {}",
        text(&out.stderr)
    );

    let remote = work.path().join("slurm");
    let out = run(cluster
        .cmd(ARLD)
        .args(args(&remote))
        .args(["--slurm", "--time", "20:00"]));
    assert!(
        out.status.success(),
        "submission failed: {}",
        text(&out.stderr)
    );
    let said = text(&out.stdout);
    let job = said
        .split_whitespace()
        .nth(3)
        .map(|j| j.trim_end_matches(':').to_string())
        .unwrap_or_else(|| panic!("no job id in {said:?}"));

    // Wait until a run of task 0 has written a snapshot, then requeue that task while it runs.
    let run_dir = remote.join("CartPole-v0/dqn-bootstrap/seed0");
    let started = Instant::now();
    while !run_dir.join("snapshot.json").is_file() {
        assert!(
            !run_dir.join("summary.json").is_file(),
            "the run finished before it could be requeued"
        );
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "no snapshot appeared in {}{}",
            run_dir.display(),
            cluster.logs()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let task = format!("{job}_0");
    let out = run(cluster.cmd("scontrol").args(["requeue", &task]));
    assert!(
        out.status.success(),
        "scontrol requeue failed: {}",
        text(&out.stderr)
    );
    // Slurm holds a requeued job back for a while (BeginTime); let it start again at once.
    let started = Instant::now();
    loop {
        let out = run(cluster.cmd("scontrol").args([
            "update",
            &format!("JobId={task}"),
            "StartTime=now",
        ]));
        if out.status.success() || started.elapsed() > Duration::from_secs(60) {
            break;
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    cluster.wait_for(&job, Duration::from_secs(600));

    let log =
        std::fs::read_to_string(remote.join(format!("slurm/{job}_0.out"))).unwrap_or_default();
    assert!(
        log.contains("attempt 1"),
        "the task did not run a second time:\n{log}"
    );
    assert!(
        log.contains("seed0: continuing from its snapshot"),
        "the requeued task did not continue the run from its snapshot:\n{log}"
    );
    let local_csv = text(&std::fs::read(local.join("results.csv")).unwrap());
    let remote_csv = text(
        &std::fs::read(remote.join("results.csv")).unwrap_or_else(|e| {
            panic!("no results.csv from the Slurm sweep ({e}); task 0 output:\n{log}")
        }),
    );
    assert_eq!(
        remote_csv, local_csv,
        "results changed by the requeue; task 0 output:\n{log}"
    );
}
