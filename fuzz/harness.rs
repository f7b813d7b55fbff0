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

/// A demonstration file (JSON lines), read as discrete actions and as actions in a box.
pub fn demos(data: &[u8]) -> bool {
    use arld::expert::demos::Demonstrations;
    let path = Path::new("fuzz.jsonl");
    let discrete = Demonstrations::<usize>::read(data, data.len() as u64, path, None).is_ok();
    let boxed = Demonstrations::<Vec<f32>>::read(data, data.len() as u64, path, None).is_ok();
    discrete || boxed
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

/// The `--set` overrides of the run whose snapshot is fuzz/seeds/snapshot/'s seed (long enough that fuzz/run.sh
/// sees its first snapshot before the run ends and removes it: 2,000 steps take 40 ms).
pub const SNAPSHOT_SEED_CONFIG: [&str; 4] = [
    "train_steps=200000",
    "snapshot_every=300",
    "replay_size=400",
    "learning_starts=100",
];

/// The line that separates the files within the inputs of the `run_dir` and `packed` targets.
pub const SEPARATOR: &[u8] = b"\n%%%%\n";

/// The input's parts between [`SEPARATOR`]s; `None` unless there are exactly `N`.
fn parts<const N: usize>(data: &[u8]) -> Option<[&[u8]; N]> {
    let mut parts = Vec::with_capacity(N);
    let mut rest = data;
    while let Some(at) = rest
        .windows(SEPARATOR.len())
        .position(|window| window == SEPARATOR)
    {
        parts.push(&rest[..at]);
        rest = &rest[at + SEPARATOR.len()..];
    }
    parts.push(rest);
    parts.try_into().ok()
}

/// A run directory as `arld report` reads it: its `summary.json`, `config.toml`, `eval.csv` and `queries.csv`
/// in this order, separated by [`SEPARATOR`]; an empty `config.toml` or `queries.csv` part stands for a run
/// without that file.
pub fn run_dir(data: &[u8]) -> bool {
    use arld::train::run_dir;
    let Some([summary, config, eval, queries]) = parts::<4>(data) else {
        return false;
    };
    let dir = Path::new("fuzz/CartPole-v0/adqn-bootstrap/seed0");
    let Ok(summary) = run_dir::parse_summary(summary, &dir.join("summary.json")) else {
        return false;
    };
    let Ok(eval) = run_dir::parse_curve(eval, &dir.join("eval.csv")) else {
        return false;
    };
    let query_steps = if queries.is_empty() {
        None
    } else {
        let Ok(steps) = run_dir::parse_query_steps(queries, &dir.join("queries.csv")) else {
            return false;
        };
        Some(steps)
    };
    let config = (!config.is_empty()).then_some(config);
    let Ok(record) = run_dir::run_record(dir, Path::new(""), summary, config, eval, query_steps)
    else {
        return false;
    };
    // What the report computes of one run (the statistics over runs take it from here).
    let _ = run_dir::steps_to_solve(&record.eval, record.solve_threshold, record.train_steps);
    // The curve writes out and reads back to itself.
    let text = run_dir::curve_csv(&record.eval);
    let again = run_dir::parse_curve(text.as_bytes(), Path::new("again.csv"))
        .expect("a written curve reads back");
    assert_eq!(again.len(), record.eval.len());
    true
}

/// A packed task directory's files (arld::lab::pack::TASK_FILES, in that order, separated by
/// [`SEPARATOR`]), its CSV tables uncompressed: the harness compresses them, so that the fuzzer changes the
/// tables' text rather than gzip's bytes.
pub fn packed(data: &[u8]) -> bool {
    use std::io::Write;
    let Some(parts) = parts::<8>(data) else {
        return false;
    };
    let files: Vec<Vec<u8>> = arld::lab::pack::TASK_FILES
        .iter()
        .zip(parts)
        .map(|(name, part)| {
            if name.ends_with(".gz") {
                let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
                gz.write_all(part).expect("compressing into memory");
                gz.finish().expect("compressing into memory")
            } else {
                part.to_vec()
            }
        })
        .collect();
    let files: [&[u8]; 8] = std::array::from_fn(|i| files[i].as_slice());
    arld::lab::pack::decode_tables(files).is_ok()
}

/// A message a page sends the web expert's server (JSON text), parsed and checked as the server parses each
/// message, for a task of discrete actions (LunarLander-v2's four) and for one of actions in a box
/// (LunarLanderContinuous-v3's): a message accepted with an action holds an action the task takes (checked here
/// from the task's spec, not by the server's check).
pub fn web(data: &[u8]) -> bool {
    use arld::expert::web::protocol::{ClientMsg, box_check, discrete_check};
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let action = |msg: &ClientMsg| match msg {
        ClientMsg::Key { action, .. } => Some(action.clone()),
        ClientMsg::Hold { action } => action.clone(),
        _ => None,
    };
    let discrete = ClientMsg::parse(text, &discrete_check(4));
    if let Some(a) = discrete.as_ref().ok().and_then(action) {
        assert!(a.as_u64().is_some_and(|a| a < 4), "accepted the action {a}");
    }
    let spec = arld::env::box_spec("LunarLanderContinuous-v3").expect("a task of the registry");
    let boxed = ClientMsg::parse(text, &box_check(spec));
    if let Some(a) = boxed.as_ref().ok().and_then(action) {
        let values: Vec<f64> = a
            .as_array()
            .expect("a box's action is a list")
            .iter()
            .map(|v| v.as_f64().expect("of numbers"))
            .collect();
        assert_eq!(values.len(), spec.action_low.len(), "accepted {a}");
        for (i, v) in values.iter().enumerate() {
            let (lo, hi) = (
                f64::from(spec.action_low[i]),
                f64::from(spec.action_high[i]),
            );
            assert!(
                (lo..=hi).contains(v),
                "accepted {a}: dimension {i} out of [{lo}, {hi}]"
            );
        }
    }
    discrete.is_ok() || boxed.is_ok()
}
