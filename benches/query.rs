//! Per-step cost of the query machinery: one uncertainty plus one adaptive-rule decision, as paid at every
//! agent decision of an Active DQN run (K = 10 heads and 4 actions for the bootstrapped network; a 64-wide
//! penultimate layer for the noisy one; window N_r = 1000 already full, i.e. steady state).

use std::hint::black_box;

use arld::query::{AdaptiveQuantileRule, OrderStatistics, js_divergence, noisy_variance};
use criterion::{Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64;

const HEADS: usize = 10;
const ACTIONS: usize = 4;
const FEATURES: usize = 64;
const N_R: usize = 1000;
/// Distinct inputs cycled through, so the benchmark does not measure one cached case.
const POOL: usize = 4096;

fn normal_vec(rng: &mut Pcg64, len: usize, scale: f32) -> Vec<f32> {
    (0..len)
        .map(|_| {
            let z: f32 = StandardNormal.sample(rng);
            z * scale
        })
        .collect()
}

/// An adaptive rule whose window is already full of uncertainties drawn like the benchmarked ones.
fn full_rule(rng: &mut Pcg64, mut draw: impl FnMut(&mut Pcg64) -> f32) -> AdaptiveQuantileRule {
    let mut rule = AdaptiveQuantileRule::new(N_R, 0.3).expect("valid rule");
    for _ in 0..2 * N_R {
        let _ = rule.observe(draw(rng));
    }
    rule
}

fn bench_query(c: &mut Criterion) {
    let mut rng = Pcg64::seed_from_u64(12345);
    let q_pool = normal_vec(&mut rng, POOL * HEADS * ACTIONS, 2.0);
    let feature_pool: Vec<f32> = normal_vec(&mut rng, POOL * FEATURES, 1.0)
        .into_iter()
        .map(|x| x.max(0.0))
        .collect();
    let sigma_w: Vec<f32> = (0..FEATURES)
        .map(|_| rng.random_range(0.02..0.08))
        .collect();
    let sigma_b = 0.06f32;

    c.bench_function("js_divergence K=10 A=4", |b| {
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % POOL;
            let q = &q_pool[i * HEADS * ACTIONS..(i + 1) * HEADS * ACTIONS];
            black_box(js_divergence(black_box(q), HEADS, ACTIONS))
        })
    });

    c.bench_function("noisy_variance p=64", |b| {
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % POOL;
            let phi = &feature_pool[i * FEATURES..(i + 1) * FEATURES];
            black_box(noisy_variance(black_box(phi), &sigma_w, sigma_b, false))
        })
    });

    c.bench_function("adaptive decide N_r=1000", |b| {
        let mut rule = full_rule(&mut rng.clone(), |r| r.random());
        let mut stream = Pcg64::seed_from_u64(7);
        b.iter(|| black_box(rule.observe(stream.random())))
    });

    c.bench_function("js_divergence + adaptive decide (per step)", |b| {
        let mut i = 0;
        let mut rule = full_rule(&mut rng.clone(), |r| {
            let q = normal_vec(r, HEADS * ACTIONS, 2.0);
            js_divergence(&q, HEADS, ACTIONS)
        });
        b.iter(|| {
            i = (i + 1) % POOL;
            let q = &q_pool[i * HEADS * ACTIONS..(i + 1) * HEADS * ACTIONS];
            black_box(rule.observe(js_divergence(black_box(q), HEADS, ACTIONS)))
        })
    });

    c.bench_function("noisy_variance + adaptive decide (per step)", |b| {
        let mut i = 0;
        let mut rule = full_rule(&mut rng.clone(), |r| {
            let phi: Vec<f32> = normal_vec(r, FEATURES, 1.0)
                .into_iter()
                .map(|x| x.max(0.0))
                .collect();
            noisy_variance(&phi, &sigma_w, sigma_b, false)
        });
        b.iter(|| {
            i = (i + 1) % POOL;
            let phi = &feature_pool[i * FEATURES..(i + 1) * FEATURES];
            black_box(rule.observe(noisy_variance(black_box(phi), &sigma_w, sigma_b, false)))
        })
    });

    // The tree alone, against the sorted-Vec-with-binary-search alternative the notes mention (section 8).
    c.bench_function("order statistics: insert + remove + kth, n=1000", |b| {
        let mut tree = OrderStatistics::new();
        let mut window = std::collections::VecDeque::new();
        let mut stream = Pcg64::seed_from_u64(8);
        for _ in 0..N_R {
            let v: f32 = stream.random();
            tree.insert(v);
            window.push_back(v);
        }
        b.iter(|| {
            let v: f32 = stream.random();
            let threshold = tree.kth_largest(N_R * 3 / 10);
            tree.insert(v);
            window.push_back(v);
            tree.remove(window.pop_front().unwrap());
            black_box(threshold)
        })
    });

    c.bench_function("sorted Vec: insert + remove + kth, n=1000", |b| {
        let mut sorted: Vec<f32> = Vec::with_capacity(N_R + 1);
        let mut window = std::collections::VecDeque::new();
        let mut stream = Pcg64::seed_from_u64(8);
        for _ in 0..N_R {
            let v: f32 = stream.random();
            let at = sorted.partition_point(|x| x.total_cmp(&v).is_lt());
            sorted.insert(at, v);
            window.push_back(v);
        }
        b.iter(|| {
            let v: f32 = stream.random();
            let threshold = sorted[sorted.len() - 1 - N_R * 3 / 10];
            let at = sorted.partition_point(|x| x.total_cmp(&v).is_lt());
            sorted.insert(at, v);
            window.push_back(v);
            let old = window.pop_front().unwrap();
            let at = sorted.partition_point(|x| x.total_cmp(&old).is_lt());
            sorted.remove(at);
            black_box(threshold)
        })
    });
}

criterion_group!(benches, bench_query);
criterion_main!(benches);
