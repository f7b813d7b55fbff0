//! LunarLander (discrete, and `LunarLanderContinuous-v3`) against Gymnasium: the heuristic controller on the
//! recorded trace, Gymnasium's random-policy statistics and the heuristic controller's performance.
//!
//! The trace (`lunar_lander.jsonl`, recorded from Gymnasium 1.4.0 with pybox2d) is the exact reference and
//! is replayed in full by `tests/conformance.rs`; here it checks the heuristic controller's actions. The
//! statistical tests compare the returns and lengths of the random and heuristic policies with Gymnasium's own
//! over the same seeds (`statistics.json`, two-sample Kolmogorov–Smirnov) and catch physics that drift on
//! average even where no trace covers them (docs/environments.md).

use arld::env::continuous::ContinuousEnv;
use arld::env::lunar_lander::{LunarLander, heuristic_action, heuristic_throttle};
use arld::env::{Env, make, make_continuous};
use rand::{Rng, SeedableRng};
use serde_json::Value;
use std::path::PathBuf;

/// The Gymnasium trace: in `$ARLD_CONFORMANCE_DIR`, or else in the repository's `tests/data/conformance`
/// (the same rule as `tests/conformance.rs`, which replays it in full).
fn trace_path() -> PathBuf {
    let dir = match std::env::var_os("ARLD_CONFORMANCE_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/conformance"),
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

/// Plays one episode of a continuous-action task from `reset(seed)` with `policy`; returns (return, length).
fn play_continuous(
    env: &mut ContinuousEnv,
    seed: u64,
    mut policy: impl FnMut(&[f32]) -> [f32; 2],
) -> (f64, usize) {
    let mut obs = vec![0.0; env.spec().obs_dim];
    env.reset_into(Some(seed), &mut obs);
    let (mut total, mut length) = (0.0, 0);
    loop {
        let action = policy(&obs);
        let step = env
            .step_into(&action, &mut obs)
            .expect("valid action on a running episode");
        total += step.reward;
        length += 1;
        if step.terminated || step.truncated {
            return (total, length);
        }
    }
}

/// Gymnasium's own per-seed returns and lengths (`statistics.json`, recorded by `record.py`).
fn gymnasium_statistics() -> Value {
    read_statistics(trace_path().with_file_name("statistics.json"))
}

/// Gymnasium's own per-seed returns and lengths of `LunarLanderContinuous-v3`
/// (`tests/data/continuous/lander_statistics.json`, recorded by `record_statistics.py` next to it).
fn continuous_statistics() -> Value {
    read_statistics(
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/continuous/lander_statistics.json"),
    )
}

fn read_statistics(path: PathBuf) -> Value {
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|err| panic!("cannot read {}: {err}", path.display()));
    serde_json::from_str(&text).expect("the statistics are valid JSON")
}

fn sample(stats: &Value, policy: &str, field: &str) -> Vec<f64> {
    stats[policy][field]
        .as_array()
        .unwrap_or_else(|| panic!("statistics.json has no {policy}.{field}"))
        .iter()
        .map(|v| v.as_f64().expect("number"))
        .collect()
}

/// The two-sample Kolmogorov–Smirnov statistic: the largest distance between the empirical CDFs.
fn ks_statistic(a: &[f64], b: &[f64]) -> f64 {
    let mut a = a.to_vec();
    let mut b = b.to_vec();
    a.sort_by(f64::total_cmp);
    b.sort_by(f64::total_cmp);
    let (mut i, mut j, mut d) = (0, 0, 0.0f64);
    while i < a.len() && j < b.len() {
        // Step past every copy of the smaller value in both samples, then compare the CDFs there.
        let x = a[i].min(b[j]);
        while i < a.len() && a[i] <= x {
            i += 1;
        }
        while j < b.len() && b[j] <= x {
            j += 1;
        }
        d = d.max((i as f64 / a.len() as f64 - j as f64 / b.len() as f64).abs());
    }
    d
}

/// Survival function of Kolmogorov's limiting distribution, Q(x) = 2 Σ (−1)^(k−1) exp(−2k²x²).
fn kolmogorov_sf(x: f64) -> f64 {
    if x < 0.2 {
        return 1.0; // the series converges slowly here and the value is 1 to 1e-9
    }
    let sum: f64 = (1..=100)
        .map(|k| {
            let k = k as f64;
            let sign = if k as u64 % 2 == 1 { 1.0 } else { -1.0 };
            sign * (-2.0 * k * k * x * x).exp()
        })
        .sum();
    (2.0 * sum).clamp(0.0, 1.0)
}

/// Asymptotic two-sample KS test: (D, p-value), with the effective size n·m/(n+m).
fn ks_two_sample(a: &[f64], b: &[f64]) -> (f64, f64) {
    let d = ks_statistic(a, b);
    let (n, m) = (a.len() as f64, b.len() as f64);
    (d, kolmogorov_sf((n * m / (n + m)).sqrt() * d))
}

#[test]
fn ks_test_agrees_with_scipy() {
    // scipy.stats.kstwobign.sf at the same points, and ks_2samp's statistic on the same samples.
    assert!((kolmogorov_sf(0.3) - 0.9999906941986655).abs() < 1e-12);
    assert!((kolmogorov_sf(2.0) - 0.0006709252557796953).abs() < 1e-12);
    let a: Vec<f64> = (0..20).map(|i| 0.1 * i as f64).collect();
    let b: Vec<f64> = (0..25).map(|i| 0.15 * i as f64 + 0.3).collect();
    let (d, p) = ks_two_sample(&a, &b);
    assert!((d - 0.56).abs() < 1e-12, "D = {d}");
    assert!((p - 0.0018813950881696633).abs() < 1e-9, "p = {p}");
    let a: Vec<f64> = (0..300).map(|i| ((i * 37) % 101) as f64 / 10.0).collect();
    let b: Vec<f64> = (0..200)
        .map(|i| ((i * 53) % 97) as f64 / 9.0 - 0.5)
        .collect();
    let (d, p) = ks_two_sample(&a, &b);
    assert!((d - 0.055).abs() < 1e-12, "D = {d}");
    assert!((p - 0.8609621873640216).abs() < 1e-9, "p = {p}");
}

/// Returns and lengths of `episodes` episodes from seeds 0.. of `env`, under uniformly random actions drawn
/// from a generator of our own (Gymnasium's used Python's `random`, so the samples are compared as
/// distributions) or under the heuristic controller.
fn lander_sample(env: &mut dyn Env, episodes: u64, random: bool) -> (Vec<f64>, Vec<f64>) {
    let mut actions = rand_pcg::Pcg64::seed_from_u64(2024);
    (0..episodes)
        .map(|seed| {
            let (ret, len) = if random {
                play(env, seed, |_| actions.random_range(0..4))
            } else {
                play(env, seed, heuristic_action)
            };
            (ret, len as f64)
        })
        .unzip()
}

/// Returns and lengths of `episodes` episodes of the continuous lander from seeds 0.., under uniformly random
/// actions in the box from a generator of our own (compared as distributions) or under the heuristic.
fn continuous_sample(env: &mut ContinuousEnv, episodes: u64, random: bool) -> (Vec<f64>, Vec<f64>) {
    let mut actions = rand_pcg::Pcg64::seed_from_u64(2024);
    (0..episodes)
        .map(|seed| {
            let (ret, len) = if random {
                play_continuous(env, seed, |_| {
                    [(); 2].map(|_| actions.random_range(-1.0f32..=1.0))
                })
            } else {
                play_continuous(env, seed, heuristic_throttle)
            };
            (ret, len as f64)
        })
        .unzip()
}

/// Our samples (from `ours(episodes, random)`) against Gymnasium's: the smallest KS p-value over the four
/// comparisons (returns and lengths, random and heuristic policies).
fn smallest_p_value(stats: &Value, mut ours: impl FnMut(u64, bool) -> (Vec<f64>, Vec<f64>)) -> f64 {
    let mut smallest = 1.0f64;
    for (policy, random) in [("random", true), ("heuristic", false)] {
        let episodes = sample(stats, policy, "returns").len() as u64;
        let (returns, lengths) = ours(episodes, random);
        for (field, ours) in [("returns", returns), ("lengths", lengths)] {
            let (d, p) = ks_two_sample(&ours, &sample(stats, policy, field));
            println!("{policy} {field}: D = {d:.4}, p = {p:.4}");
            smallest = smallest.min(p);
        }
    }
    smallest
}

#[test]
fn lander_statistics_match_gymnasium_ks() {
    // Returns and lengths of the random (300 seeds) and heuristic (200 seeds) policies against Gymnasium's
    // own: no two-sample KS test may reject at the 1% level.
    let stats = gymnasium_statistics();
    let mut env = make("LunarLander-v2").expect("LunarLander-v2 is registered");
    let p = smallest_p_value(&stats, |n, random| lander_sample(env.as_mut(), n, random));
    assert!(
        p > 0.01,
        "a KS test rejects Gymnasium's distribution: p = {p}"
    );
}

#[test]
fn continuous_lander_statistics_match_gymnasium_ks() {
    // The same comparison for LunarLanderContinuous-v3: uniform random actions in [-1, 1]² (300 seeds) and the
    // heuristic's continuous branch (200 seeds) against Gymnasium's own.
    let stats = continuous_statistics();
    let mut env = make_continuous("LunarLanderContinuous-v3").expect("registered");
    let p = smallest_p_value(&stats, |n, random| continuous_sample(&mut env, n, random));
    assert!(
        p > 0.01,
        "a KS test rejects Gymnasium's distribution: p = {p}"
    );
}

#[test]
fn continuous_ks_comparison_notices_discrete_engines() {
    // The test can fail: the discrete lander's statistics (full-throttle engines, other random actions) are
    // rejected against the continuous lander's.
    let stats = continuous_statistics();
    let mut env = make("LunarLander-v3").expect("registered");
    let p = smallest_p_value(&stats, |n, random| lander_sample(env.as_mut(), n, random));
    assert!(
        p < 1e-4,
        "the discrete lander passed for the continuous one: p = {p}"
    );
}

#[test]
fn ks_comparison_notices_wrong_gravity() {
    // The same comparison with gravity -8 instead of -10 must reject: the test can fail.
    let stats = gymnasium_statistics();
    let mut env = LunarLander::with_gravity("LunarLander-v2", -8.0).expect("valid gravity");
    let p = smallest_p_value(&stats, |n, random| lander_sample(&mut env, n, random));
    assert!(p < 1e-4, "gravity -8 went unnoticed: p = {p}");
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
fn continuous_heuristic_controller_lands() {
    // Gymnasium's continuous heuristic averages 284.6 over seeds 0..199 (lander_statistics.json).
    let mut env = make_continuous("LunarLanderContinuous-v3").expect("registered");
    let returns: Vec<f64> = (0..20)
        .map(|seed| play_continuous(&mut env, seed, heuristic_throttle).0)
        .collect();
    let mean = returns.iter().sum::<f64>() / returns.len() as f64;
    println!("continuous heuristic returns {returns:?}, mean {mean:.2}");
    assert!(mean > 200.0, "continuous heuristic mean return {mean}");
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
