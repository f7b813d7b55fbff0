//! What each fuzz target does with its input: hand the bytes to one of arld's parsers of user-supplied files,
//! as the command line would. A parser may return an error for any input; it must never panic, abort or
//! allocate without bound. Each returns whether the parser accepted the input. Shared by the fuzz targets
//! (fuzz/fuzz_targets/) and by the test that replays the inputs which once crashed them
//! (tests/fuzz_regressions.rs).

// Each fuzz target uses one of these.
#![allow(dead_code)]

use std::path::Path;

/// A configuration: lines of the form `--set KEY=VALUE` are overrides, the rest is a config file in TOML.
pub fn config(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let (mut toml, mut overrides) = (String::new(), Vec::new());
    for line in text.lines() {
        match line.strip_prefix("--set ") {
            Some(assignment) => overrides.push(assignment),
            None => {
                toml.push_str(line);
                toml.push('\n');
            }
        }
    }
    let mut input = arld::train::ConfigInput::new(
        "CartPole-v0",
        arld::train::Method::Adqn,
        arld::train::NetKind::Bootstrap,
        0,
    );
    if input.apply_text(&toml, Path::new("fuzz.toml")).is_err() {
        return false;
    }
    for assignment in overrides {
        if input.apply_override(assignment).is_err() {
            return false;
        }
    }
    let Ok(cfg) = input.resolve() else {
        return false;
    };
    // A resolved configuration serialises and reads back to itself (what `arld train --resume` relies on).
    let mut again = arld::train::ConfigInput::new("CartPole-v0", cfg.method, cfg.net, 0);
    again
        .apply_text(&cfg.to_toml(), Path::new("resolved.toml"))
        .expect("a resolved configuration reads back");
    assert_eq!(
        again.resolve().expect("and resolves").to_toml(),
        cfg.to_toml()
    );
    true
}

/// A demonstration file (JSON lines).
pub fn demos(data: &[u8]) -> bool {
    arld::expert::demos::Demonstrations::read(
        data,
        data.len() as u64,
        Path::new("fuzz.jsonl"),
        None,
    )
    .is_ok()
}

/// A model file (safetensors with arld's metadata).
pub fn checkpoint(data: &[u8]) -> bool {
    arld::nn::parse_model(Path::new("fuzz.safetensors"), data).is_ok()
}

/// A Gymnasium conformance trace (JSON lines), replayed against the environments.
pub fn trace(data: &[u8]) -> bool {
    arld::env::conformance::check_reader(data, "fuzz.jsonl").is_ok()
}

/// A run's snapshot (safetensors with a checksum), read as `arld train --resume` reads it, for the run of the
/// configuration the seed snapshot recorded (fuzz/seeds/snapshot/).
pub fn snapshot(data: &[u8]) -> bool {
    let mut input = arld::train::ConfigInput::new(
        "CartPole-v0",
        arld::train::Method::Dqn,
        arld::train::NetKind::Bootstrap,
        0,
    );
    for assignment in SNAPSHOT_SEED_CONFIG {
        input
            .apply_override(assignment)
            .expect("the seed's configuration");
    }
    let cfg = input.resolve().expect("the seed's configuration resolves");
    arld::train::snapshot::read_snapshot(data, &cfg).is_ok()
}

/// The `--set` overrides of the run whose snapshot is fuzz/seeds/snapshot/'s seed.
pub const SNAPSHOT_SEED_CONFIG: [&str; 4] = [
    "train_steps=2000",
    "snapshot_every=300",
    "replay_size=400",
    "learning_starts=100",
];
