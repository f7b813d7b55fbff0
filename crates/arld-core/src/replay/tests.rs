//! Tests of the replay memory against independent computations of the PER formulas
//! (docs/algorithm.md §3): sampling frequencies by chi-square, IS weights by the textbook formula,
//! and eviction/priority bookkeeping by direct inspection.

use super::*;
use rand::SeedableRng;
use rand_pcg::Pcg64;

const OBS_DIM: usize = 3;

fn obs_of(value: f32) -> Vec<f32> {
    vec![value, -value, 0.5 * value]
}

fn config(capacity: usize, demo_capacity: usize, prioritized: bool) -> ReplayConfig {
    ReplayConfig {
        capacity,
        demo_capacity,
        prioritized,
        ..ReplayConfig::default()
    }
}

/// Pushes a transition whose reward and observation encode `tag`, so it can be recognised later.
fn push_tagged(replay: &mut Replay, tag: f32, is_demo: bool) -> Result<(), ReplayError> {
    replay.push(Transition {
        obs: &obs_of(tag),
        action: tag as usize % 2,
        reward: tag,
        next_obs: &obs_of(tag + 0.5),
        terminal: (tag as usize).is_multiple_of(3),
        is_demo,
    })
}

/// Upper 0.1% point of the chi-square distribution with `df` degrees of freedom, by the
/// Wilson–Hilferty cube-root normal approximation (z_0.999 = 3.0902).
fn chi2_critical_999(df: usize) -> f64 {
    let k = df as f64;
    let h = 2.0 / (9.0 * k);
    k * (1.0 - h + 3.0902 * h.sqrt()).powi(3)
}

/// Pearson chi-square statistic of observed counts against expected probabilities.
fn chi_square(counts: &[u64], probs: &[f64]) -> f64 {
    let n: u64 = counts.iter().sum();
    counts
        .iter()
        .zip(probs)
        .map(|(&c, &p)| {
            let expected = p * n as f64;
            (c as f64 - expected).powi(2) / expected
        })
        .sum()
}

/// The prioritized [`mixed_memory`] after one batch of `size` drawn at beta 0.4 by a generator seeded with `seed`;
/// the generator and the batch come back for further draws.
fn mixed_sample(size: usize, seed: u64) -> (Replay, Pcg64, Batch) {
    let (mut replay, _) = mixed_memory(true);
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut batch = Batch::default();
    replay.sample(size, 0.4, &mut rng, &mut batch);
    (replay, rng, batch)
}

/// A memory with 3 demonstrations and 9 agent transitions whose TD errors are spread out.
/// Returns it with each stored slot's TD error.
fn mixed_memory(prioritized: bool) -> (Replay, Vec<(usize, f32)>) {
    let mut replay = Replay::new(OBS_DIM, &config(9, 3, prioritized));
    for i in 0..3 {
        push_tagged(&mut replay, 100.0 + i as f32, true).unwrap();
    }
    for i in 0..9 {
        push_tagged(&mut replay, i as f32, false).unwrap();
    }
    let tds = [0.0, 2.5, 0.1, 0.0, 0.3, 1.0, 4.0, 0.05, 0.7, 2.0, 0.0, 1.5];
    let slots: Vec<usize> = replay.stored_slots().collect();
    assert_eq!(slots.len(), tds.len());
    replay.update_priorities(&slots, &tds);
    (replay, slots.into_iter().zip(tds).collect())
}

/// Expected `P(i) = p_i^α / Σ p^α` with `p = |δ| + ε` computed from the configuration alone.
fn expected_probs(cfg: &ReplayConfig, slot_tds: &[(usize, f32)], alpha: f64) -> Vec<f64> {
    let masses: Vec<f64> = slot_tds
        .iter()
        .map(|&(slot, td)| {
            let eps = if slot < cfg.demo_capacity {
                cfg.eps_demo
            } else {
                cfg.eps_agent
            };
            (f64::from(td) + f64::from(eps)).powf(alpha)
        })
        .collect();
    let total: f64 = masses.iter().sum();
    masses.iter().map(|m| m / total).collect()
}

/// Counts how often each slot of `slot_tds` is drawn over `batches` batches of 32.
fn count_draws(
    replay: &mut Replay,
    slot_tds: &[(usize, f32)],
    batches: usize,
    demo_only: bool,
    seed: u64,
) -> Vec<u64> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut batch = Batch::default();
    let mut counts = vec![0u64; slot_tds.len()];
    for _ in 0..batches {
        if demo_only {
            replay.sample_demo_only(32, 0.4, &mut rng, &mut batch);
        } else {
            replay.sample(32, 0.4, &mut rng, &mut batch);
        }
        assert_eq!(batch.len(), 32);
        for &slot in &batch.idx {
            let k = slot_tds
                .iter()
                .position(|&(s, _)| s == slot)
                .expect("sampled an unknown slot");
            counts[k] += 1;
        }
    }
    counts
}

/// The draw counts fit the expected probabilities: chi-square below the 99.9% critical value.
fn assert_draws_fit(counts: &[u64], probs: &[f64]) {
    let stat = chi_square(counts, probs);
    let critical = chi2_critical_999(probs.len() - 1);
    assert!(
        stat < critical,
        "chi-square {stat} >= {critical}; counts {counts:?}"
    );
}

#[test]
fn prioritized_frequencies_match_p_alpha() {
    let (mut replay, slot_tds) = mixed_memory(true);
    let probs = expected_probs(replay.config(), &slot_tds, 0.6);
    let counts = count_draws(&mut replay, &slot_tds, 6000, false, 7);
    assert_draws_fit(&counts, &probs);
    // The test has power: the same counts are far from the α = 1 distribution.
    let wrong = expected_probs(replay.config(), &slot_tds, 1.0);
    assert!(chi_square(&counts, &wrong) > 10.0 * chi2_critical_999(probs.len() - 1));
}

#[test]
fn demo_only_frequencies_match_p_alpha_among_demos() {
    let (mut replay, slot_tds) = mixed_memory(true);
    let demos: Vec<(usize, f32)> = slot_tds.iter().copied().filter(|&(s, _)| s < 3).collect();
    let probs = expected_probs(replay.config(), &demos, 0.6);
    let counts = count_draws(&mut replay, &demos, 3000, true, 11);
    assert_draws_fit(&counts, &probs);
}

#[test]
fn uniform_mode_frequencies_are_uniform_with_unit_weights() {
    let (mut replay, slot_tds) = mixed_memory(false);
    let n = slot_tds.len();
    let counts = count_draws(&mut replay, &slot_tds, 6000, false, 13);
    assert_draws_fit(&counts, &vec![1.0 / n as f64; n]);
    // Power: the priorities are very uneven, so prioritized frequencies would fail this.
    let prioritized = expected_probs(replay.config(), &slot_tds, 0.6);
    assert!(chi_square(&counts, &prioritized) > 10.0 * chi2_critical_999(n - 1));

    let mut rng = Pcg64::seed_from_u64(1);
    let mut batch = Batch::default();
    replay.sample(64, 0.4, &mut rng, &mut batch);
    assert!(batch.weights.iter().all(|&w| w == 1.0));
    replay.sample_demo_only(64, 0.4, &mut rng, &mut batch);
    assert!(batch.weights.iter().all(|&w| w == 1.0));
    assert!(batch.is_demo.iter().all(|&d| d));
}

#[test]
fn is_weights_equal_the_formula() {
    let (mut replay, slot_tds) = mixed_memory(true);
    let probs = expected_probs(replay.config(), &slot_tds, 0.6);
    let n = probs.len() as f64;
    let mut rng = Pcg64::seed_from_u64(3);
    let mut batch = Batch::default();
    for beta in [0.0f32, 0.4, 0.7, 1.0] {
        let raw = |p: f64| (n * p).powf(-f64::from(beta));
        let max_w = probs.iter().map(|&p| raw(p)).fold(0.0, f64::max);
        replay.sample(64, beta, &mut rng, &mut batch);
        for (&slot, &w) in batch.idx.iter().zip(&batch.weights) {
            let k = slot_tds.iter().position(|&(s, _)| s == slot).unwrap();
            let expected = raw(probs[k]) / max_w;
            assert!(
                (f64::from(w) - expected).abs() <= 1e-5 * expected,
                "beta {beta} slot {slot}: {w} vs {expected}"
            );
            assert!(w <= 1.0);
        }
    }
    // Demo-only: N and the maximum are over demonstrations.
    let demos: Vec<(usize, f32)> = slot_tds.iter().copied().filter(|&(s, _)| s < 3).collect();
    let demo_probs = expected_probs(replay.config(), &demos, 0.6);
    let beta = 0.6f64;
    let raw = |p: f64| (3.0 * p).powf(-beta);
    let max_w = demo_probs.iter().map(|&p| raw(p)).fold(0.0, f64::max);
    replay.sample_demo_only(64, beta as f32, &mut rng, &mut batch);
    for (&slot, &w) in batch.idx.iter().zip(&batch.weights) {
        let expected = raw(demo_probs[slot]) / max_w;
        assert!((f64::from(w) - expected).abs() <= 1e-5 * expected);
    }
}

#[test]
fn batch_is_stratified_in_mass_order() {
    // With one draw per equal mass segment, the slots of a batch come out in the order in which
    // the memory lays out its mass: demonstrations, then the agent ring.
    let (mut replay, _) = mixed_memory(true);
    let mut rng = Pcg64::seed_from_u64(5);
    let mut batch = Batch::default();
    for _ in 0..200 {
        replay.sample(8, 0.4, &mut rng, &mut batch);
        assert!(
            batch.idx.windows(2).all(|w| w[0] <= w[1]),
            "{:?}",
            batch.idx
        );
    }
}

#[test]
fn batch_contents_match_stored_transitions() {
    let (replay, _, batch) = mixed_sample(16, 9);
    for (i, &slot) in batch.idx.iter().enumerate() {
        let t = replay.transition(slot).unwrap();
        let tag = t.reward;
        assert_eq!(
            &batch.obs[i * OBS_DIM..(i + 1) * OBS_DIM],
            obs_of(tag).as_slice()
        );
        assert_eq!(
            &batch.next_obs[i * OBS_DIM..(i + 1) * OBS_DIM],
            obs_of(tag + 0.5).as_slice()
        );
        assert_eq!(batch.actions[i], tag as usize % 2);
        assert_eq!(batch.rewards[i], tag);
        assert_eq!(batch.terminal[i], (tag as usize).is_multiple_of(3));
        assert_eq!(batch.is_demo[i], tag >= 100.0);
    }
}

#[test]
fn demos_are_never_evicted_when_the_ring_wraps() {
    let mut replay = Replay::new(OBS_DIM, &config(4, 5, true));
    // Interleave demonstrations with agent transitions while the ring wraps several times.
    let mut demo_tags = Vec::new();
    for i in 0..25usize {
        if i.is_multiple_of(5) {
            let tag = 1000.0 + i as f32;
            push_tagged(&mut replay, tag, true).unwrap();
            demo_tags.push(tag);
        } else {
            push_tagged(&mut replay, i as f32, false).unwrap();
        }
    }
    assert_eq!(replay.n_demo(), 5);
    assert_eq!(replay.n_agent(), 4);
    assert_eq!(replay.len(), 9);
    for (slot, &tag) in demo_tags.iter().enumerate() {
        let t = replay.transition(slot).unwrap();
        assert!(t.is_demo);
        assert_eq!(t.reward, tag);
        assert_eq!(t.obs, obs_of(tag).as_slice());
    }
}

#[test]
fn agent_transitions_are_evicted_first_in_first_out() {
    let capacity = 4;
    let mut replay = Replay::new(OBS_DIM, &config(capacity, 2, true));
    push_tagged(&mut replay, 500.0, true).unwrap();
    for i in 0..11usize {
        push_tagged(&mut replay, i as f32, false).unwrap();
        let mut stored: Vec<f32> = replay
            .stored_slots()
            .filter_map(|s| replay.transition(s))
            .filter(|t| !t.is_demo)
            .map(|t| t.reward)
            .collect();
        stored.sort_by(f32::total_cmp);
        let oldest_kept = (i + 1).saturating_sub(capacity);
        let expected: Vec<f32> = (oldest_kept..=i).map(|k| k as f32).collect();
        assert_eq!(stored, expected, "after pushing agent transition {i}");
    }
    assert_eq!(replay.len(), capacity + 1);
}

#[test]
fn new_transitions_enter_at_the_maximum_priority() {
    let mut replay = Replay::new(OBS_DIM, &config(8, 2, true));
    push_tagged(&mut replay, 0.0, false).unwrap();
    assert_eq!(
        replay.priority(2),
        Some(1.0),
        "the first transition enters at priority 1"
    );
    replay.update_priorities(&[2], &[5.0]);
    let max = 5.0 + replay.config().eps_agent;
    push_tagged(&mut replay, 1.0, false).unwrap();
    assert_eq!(replay.priority(3), Some(max));
    // Lowering every priority does not lower the maximum seen so far.
    replay.update_priorities(&[2, 3], &[0.1, 0.2]);
    push_tagged(&mut replay, 2.0, false).unwrap();
    push_tagged(&mut replay, 3.0, true).unwrap();
    assert_eq!(replay.priority(4), Some(max));
    assert_eq!(replay.priority(0), Some(max));
    assert_eq!(replay.max_priority(), max);
    // The sampling mass of a new transition is max^α: it holds max^α / Σ p^α of the mass.
    let masses: Vec<f64> = replay
        .stored_slots()
        .map(|s| f64::from(replay.priority(s).unwrap()).powf(0.6))
        .collect();
    let share = f64::from(max).powf(0.6) / masses.iter().sum::<f64>();
    let mut rng = Pcg64::seed_from_u64(21);
    let mut batch = Batch::default();
    let mut hits = 0usize;
    let draws = 4000 * 32;
    for _ in 0..4000 {
        replay.sample(32, 0.4, &mut rng, &mut batch);
        hits += batch.idx.iter().filter(|&&s| s == 4).count();
    }
    let freq = hits as f64 / draws as f64;
    let sd = (share * (1.0 - share) / draws as f64).sqrt();
    assert!(
        (freq - share).abs() < 4.0 * sd,
        "frequency {freq} vs share {share}"
    );
}

#[test]
fn update_priorities_adds_epsilon_by_kind() {
    let (replay, slot_tds) = mixed_memory(true);
    for &(slot, td) in &slot_tds {
        let eps = if slot < 3 { 1.0 } else { 0.001 };
        assert_eq!(replay.priority(slot), Some(td + eps), "slot {slot}");
    }
}

#[test]
fn demo_capacity_overflow_is_an_error() {
    let mut replay = Replay::new(OBS_DIM, &config(3, 2, true));
    push_tagged(&mut replay, 1.0, true).unwrap();
    push_tagged(&mut replay, 2.0, true).unwrap();
    assert_eq!(
        push_tagged(&mut replay, 3.0, true),
        Err(ReplayError::DemoCapacityFull { demo_capacity: 2 })
    );
    assert_eq!(replay.n_demo(), 2);
    // The failed push left the memory unchanged and agent transitions still go in.
    assert_eq!(replay.transition(1).unwrap().reward, 2.0);
    push_tagged(&mut replay, 4.0, false).unwrap();
    assert_eq!(replay.len(), 3);

    let mut no_demos = Replay::new(OBS_DIM, &config(3, 0, true));
    assert!(matches!(
        push_tagged(&mut no_demos, 1.0, true),
        Err(ReplayError::DemoCapacityFull { .. })
    ));
    let mut demos_only = Replay::new(OBS_DIM, &config(0, 3, true));
    assert_eq!(
        push_tagged(&mut demos_only, 1.0, false),
        Err(ReplayError::NoAgentCapacity)
    );
}

#[test]
fn bad_transitions_are_rejected() {
    let mut replay = Replay::new(OBS_DIM, &config(3, 0, true));
    let good = obs_of(1.0);
    let t = |obs, reward, next_obs| Transition {
        obs,
        action: 0,
        reward,
        next_obs,
        terminal: false,
        is_demo: false,
    };
    assert!(matches!(
        replay.push(t(&[1.0], 0.0, &good)),
        Err(ReplayError::ObsDimMismatch {
            what: "obs",
            expected: 3,
            got: 1
        })
    ));
    assert!(matches!(
        replay.push(t(&good, 0.0, &[f32::NAN, 0.0, 0.0])),
        Err(ReplayError::NonFinite { what: "next_obs" })
    ));
    assert!(matches!(
        replay.push(t(&good, f32::INFINITY, &good)),
        Err(ReplayError::NonFinite { what: "reward" })
    ));
    assert!(replay.is_empty());
}

#[test]
fn invalid_configs_are_rejected() {
    assert!(ReplayConfig::default().validate().is_ok());
    let bad = [
        ReplayConfig {
            alpha: -0.1,
            ..ReplayConfig::default()
        },
        ReplayConfig {
            alpha: f32::NAN,
            ..ReplayConfig::default()
        },
        ReplayConfig {
            eps_agent: 0.0,
            ..ReplayConfig::default()
        },
        ReplayConfig {
            eps_demo: -1.0,
            ..ReplayConfig::default()
        },
        ReplayConfig {
            capacity: 0,
            demo_capacity: 0,
            ..ReplayConfig::default()
        },
    ];
    for cfg in bad {
        assert!(
            matches!(cfg.validate(), Err(ReplayError::InvalidConfig(_))),
            "{cfg:?}"
        );
        assert!(matches!(
            Replay::try_new(OBS_DIM, &cfg),
            Err(ReplayError::InvalidConfig(_))
        ));
    }
}

#[test]
fn config_round_trips_through_toml_with_defaults_filled_in() {
    let cfg: ReplayConfig = toml::from_str("capacity = 100000\ndemo_capacity = 500").unwrap();
    assert_eq!(
        cfg,
        ReplayConfig {
            capacity: 100_000,
            demo_capacity: 500,
            ..ReplayConfig::default()
        }
    );
    let text = toml::to_string(&cfg).unwrap();
    assert_eq!(toml::from_str::<ReplayConfig>(&text).unwrap(), cfg);
    assert!(toml::from_str::<ReplayConfig>("capcity = 3").is_err());
}

#[test]
fn same_seed_gives_the_same_batches() {
    for prioritized in [true, false] {
        let run = |seed: u64| {
            let (mut replay, _) = mixed_memory(prioritized);
            let mut rng = Pcg64::seed_from_u64(seed);
            let mut batch = Batch::default();
            let mut trace = Vec::new();
            for step in 0..50 {
                replay.sample(32, 0.5, &mut rng, &mut batch);
                trace.extend(batch.idx.iter().copied());
                trace.extend(batch.weights.iter().map(|w| w.to_bits() as usize));
                let tds: Vec<f32> = batch
                    .idx
                    .iter()
                    .map(|&s| (s * step % 7) as f32 * 0.3)
                    .collect();
                let idx = batch.idx.clone();
                replay.update_priorities(&idx, &tds);
                push_tagged(&mut replay, 50.0 + step as f32, false).unwrap();
            }
            trace
        };
        assert_eq!(run(42), run(42));
        assert_ne!(run(42), run(43));
    }
}

#[test]
fn sampling_reuses_the_batch_buffers() {
    let (mut replay, mut rng, mut batch) = mixed_sample(32, 2);
    let buffers = |b: &Batch| {
        let obs = (b.obs.as_ptr(), b.obs.capacity());
        (obs, b.idx.as_ptr(), b.weights.as_ptr())
    };
    let before = buffers(&batch);
    for _ in 0..10 {
        replay.sample(32, 0.4, &mut rng, &mut batch);
    }
    assert_eq!(before, buffers(&batch));
    assert_eq!(batch.obs.len(), 32 * OBS_DIM);
}
