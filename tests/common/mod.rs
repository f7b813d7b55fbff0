//! What the integration tests share: the `arld` binary they run, reading what it printed, and the committed runs
//! unpacked from the results dataset. Each test file that needs it says `mod common;`; not every file uses every
//! item, hence the `dead_code` allowance.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The `arld` binary Cargo built for these tests.
pub const ARLD: &str = env!("CARGO_BIN_EXE_arld");

/// Runs `arld` with `args` and waits for it.
pub fn arld(args: &[&str]) -> Output {
    Command::new(ARLD)
        .args(args)
        .output()
        .expect("the arld binary runs")
}

/// What a finished command printed on standard output.
pub fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// What a finished command printed on standard error.
pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// `results/runs` with every committed run's directory in place: the dataset's packed tables
/// (`results/runs/TASK/*.csv.gz`) are unpacked there once per test process (only missing files are written, and git
/// ignores them), so a test reads the runs' own files as a sweep wrote them.
pub fn committed_runs() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("results/runs");
        arld::lab::pack::unpack(&dir, &dir).unwrap_or_else(|e| {
            panic!(
                "cannot unpack the committed runs in {}: {e:#}",
                dir.display()
            )
        });
        dir
    })
}
