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
//!
//! `cargo bench --bench box_update -- --account` prints instead, at the process's level (`ARLD_SIMD`), two
//! tables measured as the minimum over interleaved repetitions (robust on a loaded machine, and the peak and the
//! work it is compared with are measured side by side):
//! - the kernels' share of the peak: `critic_fwd_bwd` at both widths against the level's FMA loop;
//! - the per-step account of short training runs (TD3 on Pendulum-v1, the bootstrapped DQN on LunarLander-v2)
//!   at both widths: FLOPs of the matrix products per environment step, counted (`arld::nn::product_flops`),
//!   split into the network's part of a learning step (the update and acting) and the rest (the environment,
//!   replay, evaluation; a second run that never learns and acts at random), and the query rule's share (the
//!   same run with adaptive queries, adqn); TD3's network part split further into critic, targets, actor and
//!   acting from the layer sizes (checked against the count); CPU time per step of each part, and the fraction
//!   of the step's FLOP limit (its FLOPs at the peak over its time) reached.

use std::hint::black_box;

use arld::agent::Learner;
use arld::agent::algo::BoxLearnerConfig;
use arld::agent::box_agent::BoxAgent;
use arld::agent::sac::SacConfig;
use arld::agent::td3::Td3Config;
use arld::nn::{Mlp, MlpWorkspace, OutputActivation};
use arld::replay::Batch;
use arld::task::BoxColumn;
use std::time::Instant;

use arld::lab::run_one;
use arld::nn::{SimdLevel, product_flops, simd_level};
use arld::train::{ConfigInput, Method, NetKind, TrainConfig};
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group};
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

/// One critic forward and backward pass of the account's kernel table.
type CriticPass = Box<dyn FnMut()>;

/// A learner's product FLOPs per learning step by part, from a run's configuration.
type UpdateParts = fn(&TrainConfig) -> Vec<(&'static str, u64)>;

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

fn main() {
    if std::env::args().any(|arg| arg == "--account") {
        account();
    } else {
        benches();
        Criterion::default().configure_from_args().final_summary();
    }
}

/// Interleaved repetitions of the account's kernel table; each figure is the fastest of its repetitions, each
/// repetition short enough (a critic pass, or `PEAK_CALLS` calls of the peak loop) to run between two
/// preemptions on a loaded machine.
const TRIALS: usize = 300;
/// Calls of the peak loop per timed repetition.
const PEAK_CALLS: usize = 20;
/// Training runs of each kind in the step account (the fastest counts).
const RUN_TRIALS: usize = 3;

/// The peak loop of the process's level and its FLOPs per call (`None` at the scalar level).
fn level_peak() -> Option<(FmaRounds, u64)> {
    #[cfg(target_arch = "x86_64")]
    {
        let flops = |lanes: usize| (2 * lanes * ACCUMULATORS * FMA_ROUNDS) as u64;
        match simd_level() {
            SimdLevel::Avx512 => return Some((fma_rounds_avx512, flops(16))),
            SimdLevel::Avx2 => return Some((fma_rounds_avx2, flops(8))),
            SimdLevel::Scalar => {}
        }
    }
    None
}

/// Seconds per call of `f`, timing `calls` calls.
fn seconds_per_call(calls: usize, mut f: impl FnMut()) -> f64 {
    let start = Instant::now();
    for _ in 0..calls {
        f();
    }
    start.elapsed().as_secs_f64() / calls as f64
}

/// The CPU time this process has used, in seconds: a run's cost without the time other processes held the
/// cores.
fn cpu_seconds() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a valid timespec for the call to write.
    let status = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    assert_eq!(status, 0, "clock_gettime(CLOCK_PROCESS_CPUTIME_ID) failed");
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

/// Floating-point operations of a forward pass of an MLP of `sizes` over `batch` rows.
fn forward_flops(sizes: &[usize], batch: usize) -> u64 {
    (2 * batch * sizes.windows(2).map(|w| w[0] * w[1]).sum::<usize>()) as u64
}

/// The account (see the module docs).
fn account() {
    let Some((peak_loop, peak_call_flops)) = level_peak() else {
        println!(
            "the account compares with the FMA peak of a vector level; ARLD_SIMD=scalar has none"
        );
        return;
    };
    let level = simd_level().name();
    // The kernels against the peak, interleaved.
    let mut rng = Pcg64::seed_from_u64(5);
    let mut passes: Vec<(usize, u64, CriticPass)> = Vec::new();
    for width in WIDTHS {
        let sizes = [OBS_DIM + ACTION_DIM, width, width, HEADS];
        let net = Mlp::new(&sizes, OutputActivation::Linear, &mut rng);
        let mut ws = MlpWorkspace::new(&net, BATCH);
        let input = uniform(&mut rng, BATCH * sizes[0]);
        let dy = uniform(&mut rng, BATCH * HEADS);
        let mut grads = vec![0.0f32; net.parameters().len()];
        let pass = move || {
            net.forward(&input, BATCH, &mut ws);
            net.backward(&mut ws, &dy, &mut grads, None);
            black_box(grads[0]);
        };
        passes.push((width, fwd_bwd_flops(&sizes, BATCH), Box::new(pass)));
    }
    let (mut peak, mut best) = (f64::INFINITY, vec![f64::INFINITY; passes.len()]);
    for _ in 0..TRIALS {
        // SAFETY: `level_peak` returns the loop of the level the CPU was found to have.
        peak = peak.min(seconds_per_call(PEAK_CALLS, || {
            black_box(unsafe { peak_loop(black_box(1.0)) });
        }));
        for ((_, _, pass), best) in passes.iter_mut().zip(&mut best) {
            *best = best.min(seconds_per_call(1, pass));
        }
    }
    let peak_flops = peak_call_flops as f64 / peak;
    println!(
        "kernels at {level}: fma_peak {:.1} GFLOP/s",
        peak_flops / 1e9
    );
    println!("| kernel | width | GFLOP/s | share of the peak |");
    println!("|---|---|---|---|");
    for ((width, flops, _), seconds) in passes.iter().zip(&best) {
        let rate = *flops as f64 / seconds;
        println!(
            "| critic_fwd_bwd | {width}-{width} | {:.1} | {:.0}% |",
            rate / 1e9,
            100.0 * rate / peak_flops
        );
    }
    println!();
    step_account(peak_flops, level);
}

/// One learner's runs in the step account: the task, the network and the learner's product FLOPs of one update
/// from the layer sizes, split into parts (`None`: not split).
struct Learning {
    name: &'static str,
    env: &'static str,
    net: NetKind,
    update_parts: Option<UpdateParts>,
}

/// TD3's product FLOPs per learning step on Pendulum-v1 in the run `cfg` (its hidden widths, batch and critic
/// heads on one torso; the actor updated every `policy_delay`-th update): the critic's forward and backward, the
/// targets' two forward passes, the actor's share of its update (its forward, the critic's forward and its
/// backward to the input, the actor's backward), and acting (the actor's forward of one state).
fn td3_update_parts(cfg: &TrainConfig) -> Vec<(&'static str, u64)> {
    let batch = cfg.batch_size;
    let sizes = |input: usize, output: usize| {
        let mut sizes = vec![input];
        sizes.extend(&cfg.hidden);
        sizes.push(output);
        sizes
    };
    let (actor, critic) = (
        sizes(OBS_DIM, ACTION_DIM),
        sizes(OBS_DIM + ACTION_DIM, cfg.heads),
    );
    let critic_input_grads = forward_flops(&critic, batch);
    let actor_update =
        forward_flops(&critic, batch) + critic_input_grads + fwd_bwd_flops(&actor, batch);
    vec![
        ("critic", fwd_bwd_flops(&critic, batch)),
        (
            "targets",
            forward_flops(&actor, batch) + forward_flops(&critic, batch),
        ),
        ("actor", actor_update / Td3Config::default().policy_delay),
        ("acting", forward_flops(&actor, 1)),
    ]
}

/// The CPU time and product FLOPs of a short run (the fastest of `RUN_TRIALS`).
///
/// # Panics
/// If the run fails (the account's runs are fixed; a failure is a defect).
fn run_cost(cfg: &TrainConfig) -> (f64, u64) {
    let (mut seconds, mut flops) = (f64::INFINITY, 0);
    for _ in 0..RUN_TRIALS {
        let before = product_flops();
        let start = cpu_seconds();
        run_one(cfg, None, false).unwrap();
        seconds = seconds.min(cpu_seconds() - start);
        flops = product_flops() - before;
    }
    (seconds, flops)
}

/// A short run of `learning` with `method` at hidden width `width` (two layers): `steps` steps, updates from
/// step `starts`, one evaluation episode at the end.
///
/// # Panics
/// If the run cannot be configured (the account's runs are fixed; a failure is a defect).
fn run_config(
    learning: &Learning,
    method: Method,
    width: usize,
    steps: usize,
    starts: usize,
) -> TrainConfig {
    let mut input = ConfigInput::new(learning.env, method, learning.net, 0);
    for (key, value) in [
        ("train_steps", steps),
        ("learning_starts", starts),
        ("eval_period", steps),
        ("eval_episodes", 1),
    ] {
        input.set(key, value as i64).unwrap();
    }
    input.set("hidden", vec![width as i64; 2]).unwrap();
    input.resolve().unwrap()
}

/// The per-step account of short runs of each learner at both widths (see the module docs).
fn step_account(peak_flops: f64, level: &str) {
    const STEPS: usize = 1200;
    const STARTS: usize = 200;
    let learners = [
        Learning {
            name: "TD3",
            env: "Pendulum-v1",
            net: NetKind::Bootstrap,
            update_parts: Some(td3_update_parts),
        },
        Learning {
            name: "DQN (10 bootstrapped heads)",
            env: "LunarLander-v2",
            net: NetKind::Bootstrap,
            update_parts: None,
        },
    ];
    println!(
        "per-step account at {level} ({STEPS}-step runs, updates from step {STARTS}; MFLOP and µs per step)"
    );
    println!("| learner | width | part | MFLOP | µs | share of the step's FLOP limit |");
    println!("|---|---|---|---|---|---|");
    for learning in &learners {
        for width in WIDTHS {
            let cfg = run_config(learning, Method::Dqn, width, STEPS, STARTS);
            let (run_s, run_f) = run_cost(&cfg);
            let (rest_s, rest_f) =
                run_cost(&run_config(learning, Method::Dqn, width, STEPS, STEPS));
            let (query_s, query_f) =
                run_cost(&run_config(learning, Method::Adqn, width, STEPS, STARTS));
            let updates = (STEPS - STARTS) as f64;
            let per = |s: f64, f: f64, n: f64| (s / n * 1e6, f / n / 1e6);
            let rest = per(rest_s, rest_f as f64, STEPS as f64);
            let update = per(run_s - rest_s, (run_f - rest_f) as f64, updates);
            let query = per(query_s - run_s, query_f as f64 - run_f as f64, STEPS as f64);
            let step = (rest.0 + update.0, rest.1 + update.1);
            let row = |part: &str, (us, mflop): (f64, f64)| {
                let limit = 100.0 * mflop * 1e6 / peak_flops / (us * 1e-6);
                println!(
                    "| {} | {width}-{width} | {part} | {mflop:.2} | {us:.0} | {limit:.0}% |",
                    learning.name
                );
            };
            row("whole step (learning, no queries)", step);
            row("update and acting (replay sample, networks, Adam)", update);
            if let Some(parts) = learning.update_parts {
                let parts = parts(&cfg);
                let counted = (run_f - rest_f) as f64 / updates;
                let split: u64 = parts.iter().map(|(_, f)| f).sum();
                assert!(
                    (split as f64 - counted).abs() < 1.0,
                    "{}: the parts' {split} FLOPs per step differ from the {counted} counted",
                    learning.name
                );
                for (part, flops) in parts {
                    println!(
                        "| {} | {width}-{width} | update: {part} | {:.2} | | |",
                        learning.name,
                        flops as f64 / 1e6
                    );
                }
            }
            row("the rest (environment, replay, evaluation)", rest);
            let (us, mflop) = query;
            println!(
                "| {} | {width}-{width} | query rule (the adqn run minus the dqn run) | {mflop:.2} | {us:.0} | |",
                learning.name
            );
        }
    }
}
