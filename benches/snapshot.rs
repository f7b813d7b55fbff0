//! Cost of run snapshots: the time and size of one snapshot with a full 100k LunarLander-v2 replay (ADQN with
//! 10 bootstrapped heads), and what snapshotting every 10k steps costs a run: the measured time of a real
//! LunarLander run with `snapshot_every = 10000`, against the same run without snapshots.
//!
//! `cargo bench --bench snapshot` (plain timing, no criterion: each measurement is seconds long). The runs
//! with and without snapshots alternate, `ARLD_BENCH_REPS` pairs (default 5) of `ARLD_BENCH_STEPS` steps
//! (default 60000); medians are reported. A snapshot is written in two parts: what the run waits for (the
//! arrays into the operating system's cache) and the sync and rename a background thread does meanwhile. The
//! checksum of format 2 is timed on its own too: a CRC-32C over the whole snapshot.

use arld::agent::DqnAgent;
use arld::env;
use arld::lab::run_one;
use arld::replay::{Replay, ReplayConfig, Transition};
use arld::state::{Persist, StateDict};
use arld::train::{Checkpointer, ConfigInput, Method, NetKind, TrainConfig};
use rand::{Rng, SeedableRng};
use std::time::Instant;

fn config(steps: usize, snapshot_every: usize) -> TrainConfig {
    let mut input = ConfigInput::new("LunarLander-v2", Method::Adqn, NetKind::Bootstrap, 0);
    for (key, value) in [
        ("train_steps", steps),
        ("eval_period", steps),
        ("eval_episodes", 1),
        ("snapshot_every", snapshot_every),
    ] {
        input.set(key, value as i64).unwrap();
    }
    input.resolve().unwrap()
}

/// Returns the seconds one snapshot with a full replay takes to write.
fn full_replay_snapshot() -> f64 {
    let cfg = config(100_000, 0);
    let mut e = env::make(&cfg.env).unwrap();
    let (obs_dim, n_actions) = (e.obs_dim(), e.n_actions());
    let agent = DqnAgent::new(&cfg.dqn_agent_config(), obs_dim, n_actions, 1);
    let mut replay = Replay::new(
        obs_dim,
        &ReplayConfig {
            demo_capacity: cfg.budget,
            ..cfg.replay_config()
        },
    );
    // Fill the replay with real random-policy transitions (agent part full, demonstration part full).
    let mut rng = rand_pcg::Pcg64::seed_from_u64(0);
    let mut obs = e.reset(Some(0));
    let total = cfg.replay_size + cfg.budget;
    for i in 0..total {
        let action = rng.random_range(0..n_actions);
        let s = e.step(action).unwrap();
        replay
            .push(Transition {
                obs: &obs,
                action,
                reward: s.reward as f32,
                next_obs: &s.obs,
                terminal: s.terminated,
                is_demo: i < cfg.budget,
            })
            .unwrap();
        obs = if s.terminated || s.truncated {
            replay.end_episode().unwrap();
            e.reset(None)
        } else {
            s.obs
        };
    }
    let dir = tempfile::tempdir().unwrap();
    let mut ck = Checkpointer::new(dir.path(), &cfg);
    let reps = 11;
    let (mut blocking, mut durable) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        // As in a run: the previous snapshot is durable long before the next one (10k steps later).
        ck.wait().unwrap();
        let started = Instant::now();
        let mut state = StateDict::default();
        agent.save_state("agent", &mut state);
        replay.save_state("replay", &mut state);
        ck.save(&state, serde_json::json!({})).unwrap();
        blocking.push(started.elapsed().as_secs_f64());
        ck.wait().unwrap();
        durable.push(started.elapsed().as_secs_f64());
    }
    let mut restored = Replay::new(
        obs_dim,
        &ReplayConfig {
            demo_capacity: cfg.budget,
            ..cfg.replay_config()
        },
    );
    let mut load = Vec::new();
    for _ in 0..reps {
        let started = Instant::now();
        let state = ck.load().unwrap().unwrap();
        restored.load_state("replay", &state).unwrap();
        load.push(started.elapsed().as_secs_f64());
    }
    // The checksum's own cost (format 2): a CRC-32C over every byte of the snapshot, which a save computes
    // in one more pass over the arrays and a load once more before using them.
    let bytes = std::fs::read(dir.path().join(arld::train::snapshot::SNAPSHOT_FILE)).unwrap();
    let mut crc = Vec::new();
    let mut sum = 0u32;
    for _ in 0..reps {
        let started = Instant::now();
        sum ^= crc32c::crc32c(std::hint::black_box(&bytes));
        crc.push(started.elapsed().as_secs_f64());
    }
    let crc_s = median(&mut crc);
    println!(
        "checksum (CRC-32C) of the {:.2} MB snapshot: {:.2} ms ({:.1} GB/s; median of {reps}; {sum:08x})",
        bytes.len() as f64 / 1e6,
        crc_s * 1e3,
        bytes.len() as f64 / crc_s / 1e9
    );
    let save_s = median(&mut blocking);
    println!(
        "snapshot, LunarLander-v2 ADQN-B, replay full ({} agent + {} demonstration transitions): {:.2} MB; \
         medians of {reps}: the run waits {:.2} ms, durable (synced, renamed) after {:.1} ms, load {:.1} ms",
        replay.n_agent(),
        replay.n_demo(),
        ck.last_bytes as f64 / 1e6,
        save_s * 1e3,
        median(&mut durable) * 1e3,
        median(&mut load) * 1e3
    );
    save_s
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    }
}

fn env_number(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn snapshot_every_10k_slowdown(full_save_s: f64) {
    let steps = env_number("ARLD_BENCH_STEPS", 60_000);
    let reps = env_number("ARLD_BENCH_REPS", 5);
    let (mut without, mut with, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..reps {
        let mut pair = Vec::new();
        for every in [0usize, 10_000] {
            let cfg = config(steps, every);
            let dir = tempfile::tempdir().unwrap();
            let summary = run_one(&cfg, Some(&dir.path().join("run")), false).unwrap();
            pair.push(summary.steps_per_s);
        }
        without.push(pair[0]);
        with.push(pair[1]);
        ratios.push(pair[0] / pair[1] - 1.0);
    }
    let (a, b) = (median(&mut without), median(&mut with));
    println!(
        "LunarLander-v2 ADQN-B, {steps} steps, medians of {reps} alternating pairs: {a:.0} steps/s without \
         snapshots, {b:.0} steps/s with snapshot_every=10000 ({} snapshots): {:+.2}% time (median of the \
         pairs' slowdowns {:+.2}%)",
        (steps - 1) / 10_000,
        100.0 * (a / b - 1.0),
        100.0 * median(&mut ratios)
    );
    // With less timing noise: a run waits `full_save_s` for a snapshot with a full replay (the most any
    // snapshot costs), once per 10k steps.
    let per_10k = 10_000.0 / a;
    println!(
        "one full-replay snapshot per 10k steps: the run waits {:.2} ms per {:.2} s of training = {:.2}% of run \
         time",
        full_save_s * 1e3,
        per_10k,
        100.0 * full_save_s / per_10k
    );
}

fn main() {
    // `cargo test --benches` runs benches with `--bench`-less arguments; measure only under `cargo bench`.
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    let save_s = full_replay_snapshot();
    snapshot_every_10k_slowdown(save_s);
}
