//! LunarLander against Gymnasium: the heuristic controller on the recorded trace, Gymnasium's
//! random-policy statistics and the heuristic controller's performance.
//!
//! The trace (`lunar_lander.jsonl`, recorded from Gymnasium 1.4.0 with pybox2d) is the exact reference and
//! is replayed in full by `tests/conformance.rs`; here it checks the heuristic controller's actions. The
//! statistical tests compare with figures measured with Gymnasium over the same seeds
//! (ENVIRONMENT_NOTES.md, "Reference figures") and catch physics that drift on average even where no
//! trace covers them.

use arld::env::lunar_lander::heuristic_action;
use arld::env::{Env, make};
use rand::{Rng, SeedableRng};
use serde_json::Value;
use std::path::PathBuf;

/// The Gymnasium trace: in `$ARLD_CONFORMANCE_DIR`, or else in `../shared/conformance` next to the crate
/// (the same rule as `tests/conformance.rs`, which replays it in full).
fn trace_path() -> PathBuf {
    let dir = match std::env::var_os("ARLD_CONFORMANCE_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/conformance"),
    };
    dir.join("lunar_lander.jsonl")
}

/// Plays one episode from `reset(seed)` with `policy` choosing the actions; returns (return, length).
fn play(env: &mut dyn Env, seed: u64, mut policy: impl FnMut(&[f32]) -> usize) -> (f64, usize) {
    let mut obs = env.reset(Some(seed));
    let mut total = 0.0;
    let mut length = 0;
    loop {
        let step = env
            .step(policy(&obs))
            .expect("valid action on a running episode");
        total += step.reward;
        length += 1;
        obs = step.obs;
        if step.terminated || step.truncated {
            return (total, length);
        }
    }
}

#[test]
fn heuristic_controller_chooses_the_recorded_actions() {
    // The heuristic episodes of the trace list Gymnasium's own heuristic actions next to the observations
    // they were computed from: our port must choose the same action from the same observation.
    let text = std::fs::read_to_string(trace_path()).expect("trace file is readable");
    let mut previous_obs: Option<Vec<f32>> = None;
    let mut compared = 0;
    for line in text.lines() {
        let record: Value = serde_json::from_str(line).expect("valid JSON line");
        if record["case"] != "heuristic" {
            previous_obs = None;
            continue;
        }
        let obs: Vec<f32> = record["obs"]
            .as_array()
            .expect("obs array")
            .iter()
            .map(|v| v.as_f64().expect("number") as f32)
            .collect();
        if record["kind"] == "step" {
            let before = previous_obs
                .as_ref()
                .expect("a step follows a start or a step");
            let recorded = record["action"].as_u64().expect("action") as usize;
            assert_eq!(
                heuristic_action(before),
                recorded,
                "seed {} step {}",
                record["seed"],
                record["t"]
            );
            compared += 1;
        }
        previous_obs = Some(obs);
    }
    assert!(compared > 500, "only {compared} heuristic steps compared");
}

#[test]
fn random_policy_matches_gymnasium_statistics() {
    // Gymnasium (LunarLander-v3, same task as v2), uniform random actions, reset(seed=s) for s in 0..300:
    // return -186.2 +- 109.5, length 91.6 +- 19.9. The bounds are about 2.4 standard errors of the mean.
    let mut env = make("LunarLander-v2").expect("LunarLander-v2 is registered");
    let mut actions = rand_pcg::Pcg64::seed_from_u64(2024);
    let episodes = 300;
    let (mut return_sum, mut length_sum) = (0.0, 0usize);
    for seed in 0..episodes {
        let (ret, len) = play(env.as_mut(), seed, |_| actions.random_range(0..4));
        return_sum += ret;
        length_sum += len;
    }
    let mean_return = return_sum / episodes as f64;
    let mean_length = length_sum as f64 / episodes as f64;
    println!("random policy: mean return {mean_return:.2}, mean length {mean_length:.2}");
    assert!(
        (mean_return - -186.2).abs() < 15.0,
        "mean return {mean_return}"
    );
    assert!(
        (mean_length - 91.6).abs() < 3.0,
        "mean length {mean_length}"
    );
}

#[test]
fn heuristic_controller_lands() {
    // Gymnasium's heuristic averages 252.8 over seeds 0..99; it must solve the task (mean above 200).
    let mut env = make("LunarLander-v2").expect("LunarLander-v2 is registered");
    let returns: Vec<f64> = (0..20)
        .map(|seed| play(env.as_mut(), seed, heuristic_action).0)
        .collect();
    let mean = returns.iter().sum::<f64>() / returns.len() as f64;
    println!("heuristic returns {returns:?}, mean {mean:.2}");
    assert!(mean > 200.0, "heuristic mean return {mean}");
}

#[test]
fn same_seed_same_episode_across_threads() {
    // The environment is `Send`: an episode played on another thread must equal the one played here.
    let play_seed_7 = || {
        let mut env = make("LunarLander-v3").expect("registered");
        let mut obs = env.reset(Some(7));
        let mut trajectory = vec![obs.clone()];
        for _ in 0..60 {
            let step = env.step(heuristic_action(&obs)).expect("running");
            obs = step.obs;
            trajectory.push(obs.clone());
            if step.terminated || step.truncated {
                break;
            }
        }
        trajectory
    };
    let here = play_seed_7();
    let there = std::thread::spawn(play_seed_7).join().expect("thread ran");
    assert_eq!(here, there);
}
