//! Conformance of the environments with traces recorded from Gymnasium 1.4.0.
//!
//! The traces live in `$ARLD_CONFORMANCE_DIR`, or else in the repository's `tests/data/conformance`. A missing
//! directory fails the tests: without the traces nothing shows that the environments are Gymnasium's.
//! Classic control and LunarLander are separate tests because LunarLander is a separate module (Box2D).

use arld::env::conformance::{EnvReport, check_file};
use std::path::PathBuf;

const LUNAR_LANDER_TRACE: &str = "lunar_lander.jsonl";

fn conformance_dir() -> PathBuf {
    let dir = match std::env::var_os("ARLD_CONFORMANCE_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/conformance"),
    };
    assert!(
        dir.is_dir(),
        "conformance traces not found at {}; set ARLD_CONFORMANCE_DIR to the directory of the *.jsonl traces",
        dir.display()
    );
    dir
}

/// Every `*.jsonl` trace in the conformance directory, sorted.
fn trace_files() -> Vec<PathBuf> {
    let dir = conformance_dir();
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|err| panic!("cannot list {}: {err}", dir.display()))
        .map(|entry| entry.expect("directory entry").path())
        .filter(|path| path.extension().is_some_and(|ext| ext == "jsonl"))
        .collect();
    files.sort();
    files
}

fn print_reports(file: &std::path::Path, reports: &[EnvReport]) {
    for report in reports {
        println!(
            "{}: {} episodes {} exact {} diverged {} max|dobs| {:.3e} max|drew| {:.3e} first divergence {:?}",
            file.display(),
            report.env,
            report.episodes,
            report.episodes_exact,
            report.episodes_diverged(),
            report.max_obs_deviation,
            report.max_reward_deviation,
            report.first_divergence
        );
    }
}

/// Every trace except LunarLander's: CartPole, Acrobot and MountainCar within 1e-6 on every observation
/// and reward, with the same episode ends.
#[test]
fn classic_control_traces_conform() {
    let files: Vec<PathBuf> = trace_files()
        .into_iter()
        .filter(|path| !path.ends_with(LUNAR_LANDER_TRACE))
        .collect();
    assert!(!files.is_empty(), "no classic control traces found");
    let mut seen = Vec::new();
    let mut failures = Vec::new();
    for file in &files {
        let reports = check_file(file).unwrap_or_else(|err| panic!("{err}"));
        print_reports(file, &reports);
        for report in reports {
            assert!(report.episodes > 0);
            if !report.passed() {
                failures.push(format!("{}: {}", file.display(), report.env));
            }
            seen.push(report.env);
        }
    }
    assert!(
        failures.is_empty(),
        "environments off their traces: {failures:?}"
    );
    for id in ["CartPole-v1", "Acrobot-v1", "MountainCar-v0"] {
        assert!(seen.iter().any(|env| env == id), "no trace covered {id}");
    }
}

/// LunarLander-v3: seeded episodes within 1e-4, at most 10% of the heuristic episodes diverging.
#[test]
fn lunar_lander_trace_conforms() {
    let file = conformance_dir().join(LUNAR_LANDER_TRACE);
    let reports = check_file(&file).unwrap_or_else(|err| panic!("{err}"));
    print_reports(&file, &reports);
    let report = reports
        .iter()
        .find(|report| report.env == "LunarLander-v3")
        .expect("the LunarLander trace covers LunarLander-v3");
    assert!(report.episodes > 0);
    assert!(
        report.passed(),
        "LunarLander-v3 is off its trace: {report:?}"
    );
}
