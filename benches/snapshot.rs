//! Cost of run snapshots: the time and size of one snapshot with a full 100k LunarLander-v2 replay (ADQN with
//! 10 bootstrapped heads), and what snapshotting every 10k steps costs a run: the measured time of a real
//! LunarLander run with `snapshot_every = 10000`, against the same run without snapshots.
//!
//! `cargo bench --bench snapshot` (plain timing, no criterion: each measurement is seconds long).

use arld::agent::Agent;
use arld::env;
use arld::experiment::run_one;
use arld::replay::{Replay, ReplayConfig, Transition};
use arld::state::StateDict;
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
    let agent = Agent::new(&cfg.agent_config(), obs_dim, n_actions, 1);
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
    let reps = 5;
    let started = Instant::now();
    for _ in 0..reps {
        let mut state = StateDict::default();
        agent.save_state("agent", &mut state);
        replay.save_state("replay", &mut state);
        ck.save(&state, serde_json::json!({})).unwrap();
    }
    let save_s = started.elapsed().as_secs_f64() / reps as f64;
    let started = Instant::now();
    let mut restored = Replay::new(
        obs_dim,
        &ReplayConfig {
            demo_capacity: cfg.budget,
            ..cfg.replay_config()
        },
    );
    for _ in 0..reps {
        let state = ck.load().unwrap().unwrap();
        restored.load_state("replay", &state).unwrap();
    }
    let load_s = started.elapsed().as_secs_f64() / reps as f64;
    println!(
        "snapshot, LunarLander-v2 ADQN-B, replay full ({} agent + {} demonstration transitions): {:.2} MB, \
         save {:.1} ms, load {:.1} ms",
        replay.n_agent(),
        replay.n_demo(),
        ck.last_bytes as f64 / 1e6,
        save_s * 1e3,
        load_s * 1e3
    );
    save_s
}

fn snapshot_every_10k_slowdown(full_save_s: f64) {
    let steps = 60_000;
    let mut times = Vec::new();
    for every in [0usize, 10_000] {
        let cfg = config(steps, every);
        let dir = tempfile::tempdir().unwrap();
        let started = Instant::now();
        run_one(&cfg, Some(&dir.path().join("run")), false).unwrap();
        times.push(started.elapsed().as_secs_f64());
    }
    println!(
        "LunarLander-v2 ADQN-B, {steps} steps: {:.2} s without snapshots, {:.2} s with snapshot_every=10000 \
         ({} snapshots): {:+.2}%",
        times[0],
        times[1],
        steps / 10_000 - 1,
        100.0 * (times[1] / times[0] - 1.0)
    );
    // The same with less timing noise: a snapshot with a full replay costs at most `full_save_s`; the run does
    // 10k steps between two of them.
    let per_10k = times[0] * 10_000.0 / steps as f64;
    println!(
        "one full-replay snapshot per 10k steps: {:.1} ms per {:.2} s of training = {:.2}% of run time",
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
