//! Cost of one learner step's worth of replay work on a full 100k memory: push one transition,
//! sample a prioritized batch of 32, update those 32 priorities (docs/algorithm.md §3, batch 32).

use std::hint::black_box;

use arld::replay::{Batch, Replay, ReplayConfig, Transition};
use criterion::{Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// LunarLander's observation size, the largest of the paper's tasks.
const OBS_DIM: usize = 8;
const CAPACITY: usize = 100_000;
const BATCH: usize = 32;

fn filled_memory(prioritized: bool, rng: &mut Pcg64) -> Replay {
    let cfg = ReplayConfig {
        capacity: CAPACITY,
        demo_capacity: 3000,
        prioritized,
        ..ReplayConfig::default()
    };
    let mut replay = Replay::new(OBS_DIM, &cfg);
    let mut obs = [0.0f32; OBS_DIM];
    for i in 0..cfg.demo_capacity + CAPACITY {
        obs.iter_mut().for_each(|x| *x = rng.random());
        replay
            .push(Transition {
                obs: &obs,
                action: i % 4,
                reward: rng.random(),
                next_obs: &obs,
                terminal: i.is_multiple_of(100),
                is_demo: i < cfg.demo_capacity,
            })
            .unwrap();
    }
    // Spread the priorities so the tree is not uniform.
    let slots: Vec<usize> = replay.stored_slots().collect();
    let tds: Vec<f32> = slots.iter().map(|_| rng.random::<f32>() * 3.0).collect();
    replay.update_priorities(&slots, &tds);
    replay
}

fn bench_replay_step(c: &mut Criterion) {
    for prioritized in [true, false] {
        let mut rng = Pcg64::seed_from_u64(0);
        let mut replay = filled_memory(prioritized, &mut rng);
        let mut batch = Batch::default();
        let mut obs = [0.0f32; OBS_DIM];
        let mut tds = [0.0f32; BATCH];
        let name = if prioritized {
            "push+sample32+update32/prioritized_100k"
        } else {
            "push+sample32+update32/uniform_100k"
        };
        c.bench_function(name, |b| {
            b.iter(|| {
                obs.iter_mut().for_each(|x| *x = rng.random());
                replay
                    .push(Transition {
                        obs: &obs,
                        action: 1,
                        reward: 0.5,
                        next_obs: &obs,
                        terminal: false,
                        is_demo: false,
                    })
                    .unwrap();
                replay.sample(BATCH, 0.4, &mut rng, &mut batch);
                tds.iter_mut().for_each(|t| *t = rng.random::<f32>() * 3.0);
                replay.update_priorities(&batch.idx, &tds);
                black_box(&batch);
            })
        });
    }
}

criterion_group!(benches, bench_replay_step);
criterion_main!(benches);
