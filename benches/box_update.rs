//! Benchmarks of the actor-critic hot path and of how close its kernels come to the core's peak.
//!
//! - `fma_peak`: the core's own ceiling, measured: independent fused multiply-adds in registers at each SIMD
//!   level the CPU has (8 lanes with AVX2+FMA, 16 with AVX-512), two floating-point operations each. Its
//!   throughput is the peak in FLOP/s that the kernels are compared against.
//! - `critic_fwd_bwd`: one forward and backward pass of a critic as TD3 and SAC run it (Pendulum-v1: 3
//!   observations and 1 action in, two heads out), batch 256, at widths 64-64 and 256-256. Its throughput is
//!   the FLOP/s of the products (2 per multiply-add: forward, weight gradients, and the input gradients of every
//!   layer but the first), so `critic_fwd_bwd` over `fma_peak` is the kernels' share of the peak.
//! - `td3_update`, `sac_update`: a whole update (targets, critics, the delayed actor, Adam, the soft target
//!   copies) from cycling batches of 256 transitions, at both widths.
//!
//! `ARLD_SIMD` caps the level the kernels use, as in a run; `fma_peak` measures each level the CPU has.

use std::hint::black_box;

use arld::agent::Learner;
use arld::agent::box_agent::{BoxAgent, BoxLearnerConfig};
use arld::agent::sac::SacConfig;
use arld::agent::td3::Td3Config;
use arld::nn::{Mlp, MlpWorkspace, OutputActivation};
use arld::replay::Batch;
use arld::task::BoxColumn;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const OBS_DIM: usize = 3;
const ACTION_DIM: usize = 1;
const HEADS: usize = 2;
const BATCH: usize = 256;
const WIDTHS: [usize; 2] = [64, 256];
/// Batches cycled through, so successive updates see different data.
const N_BATCHES: usize = 8;
/// Multiply-add rounds per call of the peak loop, and independent accumulators (enough to cover the FMA
/// units' latency at two per cycle).
const FMA_ROUNDS: usize = 4096;
const ACCUMULATORS: usize = 12;

/// One call of a level's peak loop.
type FmaRounds = unsafe fn(f32) -> f32;

/// A learner's settings at a hidden width.
type ConfigOfWidth = fn(usize) -> BoxLearnerConfig;

/// Multiply-adds with 8 lanes; returns a value that depends on every one.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fma_rounds_avx2(seed: f32) -> f32 {
    use std::arch::x86_64::*;
    let a = _mm256_set1_ps(0.999_9);
    let b = _mm256_set1_ps(1e-4);
    let mut acc = [_mm256_set1_ps(seed); ACCUMULATORS];
    for _ in 0..FMA_ROUNDS {
        for x in acc.iter_mut() {
            *x = _mm256_fmadd_ps(*x, a, b);
        }
    }
    let mut sum = _mm256_setzero_ps();
    for x in acc {
        sum = _mm256_add_ps(sum, x);
    }
    let mut lanes = [0.0f32; 8];
    // SAFETY: `lanes` holds the 8 floats the store writes.
    unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), sum) };
    lanes.iter().sum()
}

/// Multiply-adds with 16 lanes; returns a value that depends on every one.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn fma_rounds_avx512(seed: f32) -> f32 {
    use std::arch::x86_64::*;
    let a = _mm512_set1_ps(0.999_9);
    let b = _mm512_set1_ps(1e-4);
    let mut acc = [_mm512_set1_ps(seed); ACCUMULATORS];
    for _ in 0..FMA_ROUNDS {
        for x in acc.iter_mut() {
            *x = _mm512_fmadd_ps(*x, a, b);
        }
    }
    let mut sum = _mm512_setzero_ps();
    for x in acc {
        sum = _mm512_add_ps(sum, x);
    }
    _mm512_reduce_add_ps(sum)
}

fn fma_peak(c: &mut Criterion) {
    let mut group = c.benchmark_group("fma_peak");
    #[cfg(target_arch = "x86_64")]
    {
        let levels: [(&str, usize, bool, FmaRounds); 2] = [
            (
                "avx2",
                8,
                is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"),
                fma_rounds_avx2,
            ),
            (
                "avx512",
                16,
                is_x86_feature_detected!("avx512f"),
                fma_rounds_avx512,
            ),
        ];
        for (name, lanes, available, rounds) in levels {
            if !available {
                continue;
            }
            group.throughput(Throughput::Elements(
                (2 * lanes * ACCUMULATORS * FMA_ROUNDS) as u64,
            ));
            // SAFETY: the CPU has the level's features (checked above).
            group.bench_function(name, |b| b.iter(|| unsafe { rounds(black_box(1.0)) }));
        }
    }
    group.finish();
}

/// Floating-point operations of one forward and backward pass of an MLP of `sizes` over `batch` rows: two per
/// multiply-add of the forward products, of the weight gradients and of the input gradients of every layer but
/// the first.
fn fwd_bwd_flops(sizes: &[usize], batch: usize) -> u64 {
    let products: Vec<usize> = sizes.windows(2).map(|w| w[0] * w[1]).collect();
    let forward: usize = products.iter().sum();
    let input_grads: usize = products[1..].iter().sum();
    (2 * batch * (2 * forward + input_grads)) as u64
}

fn critic_fwd_bwd(c: &mut Criterion) {
    let mut group = c.benchmark_group("critic_fwd_bwd");
    let mut rng = Pcg64::seed_from_u64(5);
    for width in WIDTHS {
        let sizes = [OBS_DIM + ACTION_DIM, width, width, HEADS];
        let net = Mlp::new(&sizes, OutputActivation::Linear, &mut rng);
        let mut ws = MlpWorkspace::new(&net, BATCH);
        let inputs: Vec<Vec<f32>> = (0..N_BATCHES)
            .map(|_| uniform(&mut rng, BATCH * sizes[0]))
            .collect();
        let dy = uniform(&mut rng, BATCH * HEADS);
        let mut grads = vec![0.0f32; net.parameters().len()];
        let mut next = 0;
        group.throughput(Throughput::Elements(fwd_bwd_flops(&sizes, BATCH)));
        group.bench_function(BenchmarkId::new(format!("{width}-{width}"), BATCH), |b| {
            b.iter(|| {
                next = (next + 1) % N_BATCHES;
                net.forward(&inputs[next], BATCH, &mut ws);
                net.backward(&mut ws, &dy, &mut grads, None);
                black_box(grads[0])
            })
        });
    }
    group.finish();
}

fn uniform(rng: &mut Pcg64, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// Pendulum-like batches of one-step transitions: observations in [-1, 1], torques in [-2, 2], rewards in
/// [-16, 0], no episode ends.
fn batches(rng: &mut Pcg64) -> Vec<Batch<Vec<f32>>> {
    (0..N_BATCHES)
        .map(|_| {
            let mut actions = BoxColumn::default();
            for (a, u) in actions
                .rows_mut(BATCH, ACTION_DIM)
                .iter_mut()
                .zip(uniform(rng, BATCH * ACTION_DIM))
            {
                *a = 2.0 * u;
            }
            Batch {
                idx: (0..BATCH).collect(),
                weights: vec![1.0; BATCH],
                obs: uniform(rng, BATCH * OBS_DIM),
                actions,
                rewards: (0..BATCH).map(|_| rng.random_range(-16.0..0.0)).collect(),
                next_obs: uniform(rng, BATCH * OBS_DIM),
                terminal: vec![false; BATCH],
                is_demo: vec![false; BATCH],
                ..Batch::default()
            }
        })
        .collect()
}

fn updates(c: &mut Criterion) {
    let data = batches(&mut Pcg64::seed_from_u64(7));
    let learners: [(&str, ConfigOfWidth); 2] = [
        ("td3_update", |width| {
            let mut config = Td3Config::default();
            (config.common.hidden, config.common.max_batch) = (vec![width, width], BATCH);
            BoxLearnerConfig::Td3(config)
        }),
        ("sac_update", |width| {
            let mut config = SacConfig::default();
            (config.common.hidden, config.common.max_batch) = (vec![width, width], BATCH);
            BoxLearnerConfig::Sac(config)
        }),
    ];
    for (name, config) in learners {
        let mut group = c.benchmark_group(name);
        for width in WIDTHS {
            let mut agent = BoxAgent::new(config(width), OBS_DIM, &[-2.0], &[2.0], 0.99, 1);
            let mut next = 0;
            group.bench_function(BenchmarkId::new(format!("{width}-{width}"), BATCH), |b| {
                b.iter(|| {
                    next = (next + 1) % N_BATCHES;
                    black_box(agent.learn(&data[next]).1[0])
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, fma_peak, critic_fwd_bwd, updates);
criterion_main!(benches);
