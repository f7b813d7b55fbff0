//! The fuzz targets' inputs, replayed by the ordinary test suite: every input that once crashed a parser
//! (`fuzz/regressions/<target>/`) must now be handled without a panic, and every committed seed input
//! (`fuzz/seeds/<target>/`, real files arld writes) must be accepted, which shows the harness reaches the parser.
//! `fuzz/run.sh` runs the targets themselves (cargo-fuzz, libFuzzer).

#[path = "../fuzz/harness.rs"]
mod harness;

use std::path::Path;

type Target = fn(&[u8]) -> bool;

const TARGETS: [(&str, Target); 7] = [
    ("config", harness::config),
    ("demos", harness::demos),
    ("checkpoint", harness::checkpoint),
    ("trace", harness::trace),
    ("run_dir", harness::run_dir),
    ("packed", harness::packed),
    ("web", harness::web),
];

/// The files of `fuzz/<kind>/<target>/` (none when the folder does not exist).
fn inputs(kind: &str, target: &str) -> Vec<std::path::PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz")
        .join(kind)
        .join(target);
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut files: Vec<_> = entries.map(|e| e.unwrap().path()).collect();
    files.sort();
    files
}

#[test]
fn inputs_that_once_crashed_a_parser_are_handled() {
    let mut replayed = 0;
    for (target, run) in TARGETS {
        for file in inputs("regressions", target) {
            let data = std::fs::read(&file).unwrap();
            let outcome = std::panic::catch_unwind(|| run(&data));
            assert!(outcome.is_ok(), "{target}: {} panics", file.display());
            replayed += 1;
        }
    }
    assert!(
        replayed > 0,
        "no regression inputs found under fuzz/regressions"
    );
}

#[test]
fn the_seed_inputs_are_accepted_and_their_damaged_copies_are_not() {
    for (target, run) in TARGETS {
        let seeds = inputs("seeds", target);
        assert!(!seeds.is_empty(), "fuzz/seeds/{target} is empty");
        for file in seeds {
            let data = std::fs::read(&file).unwrap();
            assert!(
                run(&data),
                "{target}: the seed {} is refused",
                file.display()
            );
            // Every seed cut short (mid-line, or its last line missing its end) is refused (or, for a config, may still be a valid config) without a panic.
            for cut in [1, data.len() / 2, data.len() - 2] {
                let outcome = std::panic::catch_unwind(|| run(&data[..cut]));
                assert!(
                    outcome.is_ok(),
                    "{target}: {} cut at {cut} panics",
                    file.display()
                );
                // A config cut short may still be one; so may a run's or a task's files cut after their last
                // line's first field (a log row's other fields may be empty).
                if !matches!(target, "config" | "run_dir" | "packed") {
                    assert!(
                        !outcome.unwrap(),
                        "{target}: {} cut at {cut} accepted",
                        file.display()
                    );
                }
            }
        }
    }
}
