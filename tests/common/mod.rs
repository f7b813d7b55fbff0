//! What the integration tests share: the committed runs, unpacked from the results dataset.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// `results/runs` with every committed run's directory in place: the dataset's packed tables
/// (`results/runs/TASK/*.csv.gz`) are unpacked there once per test process (only missing files are written, and git
/// ignores them), so a test reads the runs' own files as a sweep wrote them.
pub fn committed_runs() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("results/runs");
        arld::experiment::pack::unpack(&dir, &dir).unwrap_or_else(|e| {
            panic!(
                "cannot unpack the committed runs in {}: {e:#}",
                dir.display()
            )
        });
        dir
    })
}
