//! Stepping speed of each environment: random actions, reset at every episode end, reported in steps/s.
//! For LunarLander the resets (a new Box2D world each) are a noticeable part of the figure, as in training.
//!
//! Each iteration runs a fixed batch of steps through the `Env` trait object exactly as the training loop
//! does (`make(id)`, `step_into` one reused observation buffer, `reset_into` on `terminated || truncated`), so
//! the figure includes the time-limit bookkeeping.

use arld::env::{Env, make};
use arld::rng::NumpyRng;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rand::Rng;
use std::hint::black_box;

const STEPS_PER_ITERATION: u64 = 10_000;

fn run_steps(
    env: &mut dyn Env,
    obs: &mut [f32],
    rng: &mut NumpyRng,
    episode_seed: &mut u64,
) -> f64 {
    let mut total_reward = 0.0;
    for _ in 0..STEPS_PER_ITERATION {
        let action = rng.random_range(0..env.n_actions());
        let step = env
            .step_into(action, obs)
            .expect("valid action in a running episode");
        total_reward += step.reward;
        if step.terminated || step.truncated {
            *episode_seed += 1;
            env.reset_into(Some(*episode_seed), obs);
        }
    }
    total_reward
}

fn bench_env_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("env_step");
    group.throughput(Throughput::Elements(STEPS_PER_ITERATION));
    for id in [
        "CartPole-v1",
        "Acrobot-v1",
        "MountainCar-v0",
        "LunarLander-v2",
    ] {
        let mut env = make(id).expect("registered environment");
        let mut rng = NumpyRng::new(0);
        let mut episode_seed = 0;
        let mut obs = env.reset(Some(episode_seed));
        group.bench_function(id, |b| {
            b.iter(|| {
                black_box(run_steps(
                    env.as_mut(),
                    &mut obs,
                    &mut rng,
                    &mut episode_seed,
                ))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_env_step);
criterion_main!(benches);
