//! Benchmarks of the Q-network hot path: one double-DQN update (the operation a full reproduction runs
//! ~300 million times) and one single-state forward pass (run at every environment step to act).
//!
//! The update follows docs/algorithm.md §2 and §4: online forward on `s'` for the argmax, target forward
//! on `s'`, online forward on `s`, the gradient of the mean squared TD error (summed over heads), backward,
//! gradient-norm clipping at 10 and an Adam step. Noisy networks draw fresh noise for each of the three
//! passes. Sizes: `obs_dim = 8`, `A = 4` (LunarLander), batches of 32 and 64.

use std::hint::black_box;

use arld::nn::{Adam, Grads, NoiseSample, OutputKind, QNet, Workspace, argmax, clip_grad_norm};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const OBS_DIM: usize = 8;
const N_ACTIONS: usize = 4;
const GAMMA: f32 = 0.99;
/// Minibatches cycled through, so successive updates see different data.
const N_MINIBATCHES: usize = 16;

struct Minibatch {
    obs: Vec<f32>,
    next_obs: Vec<f32>,
    actions: Vec<usize>,
    rewards: Vec<f32>,
    dones: Vec<f32>,
}

struct Learner {
    online: QNet,
    target: QNet,
    adam: Adam,
    grads: Grads,
    ws_obs: Workspace,
    ws_next_online: Workspace,
    ws_next_target: Workspace,
    dq: Vec<f32>,
    noise_online: NoiseSample,
    noise_target: NoiseSample,
    noise_select: NoiseSample,
    noisy: bool,
    rng: Pcg64,
}

impl Learner {
    fn new(kind: OutputKind, batch: usize) -> Self {
        let mut rng = Pcg64::seed_from_u64(1);
        let online = QNet::new(OBS_DIM, N_ACTIONS, kind, &mut rng);
        let target = online.clone();
        Self {
            adam: Adam::new(&online, 1e-4),
            grads: Grads::new(&online),
            ws_obs: Workspace::new(&online, batch),
            ws_next_online: Workspace::new(&online, batch),
            ws_next_target: Workspace::new(&online, batch),
            dq: vec![0.0; kind.heads() * batch * N_ACTIONS],
            noise_online: NoiseSample::new(N_ACTIONS),
            noise_target: NoiseSample::new(N_ACTIONS),
            noise_select: NoiseSample::new(N_ACTIONS),
            noisy: matches!(kind, OutputKind::Noisy),
            online,
            target,
            rng,
        }
    }

    /// One double-DQN update on `mb`; returns the loss so the work cannot be optimised away.
    fn update(&mut self, mb: &Minibatch) -> f32 {
        let batch = mb.actions.len();
        let (noise_online, noise_target, noise_select) = if self.noisy {
            self.noise_online.resample(&mut self.rng);
            self.noise_target.resample(&mut self.rng);
            self.noise_select.resample(&mut self.rng);
            (
                Some(&self.noise_online),
                Some(&self.noise_target),
                Some(&self.noise_select),
            )
        } else {
            (None, None, None)
        };
        let q_next_online =
            self.online
                .forward(&mb.next_obs, batch, noise_select, &mut self.ws_next_online);
        let q_next_target =
            self.target
                .forward(&mb.next_obs, batch, noise_target, &mut self.ws_next_target);
        let q = self
            .online
            .forward(&mb.obs, batch, noise_online, &mut self.ws_obs);
        let heads = self.online.heads();
        let mut loss = 0.0;
        self.dq.fill(0.0);
        for head in 0..heads {
            for b in 0..batch {
                let row = (head * batch + b) * N_ACTIONS;
                let best = argmax(&q_next_online[row..row + N_ACTIONS]);
                let y = mb.rewards[b] + GAMMA * (1.0 - mb.dones[b]) * q_next_target[row + best];
                let td = q[row + mb.actions[b]] - y;
                loss += td * td / batch as f32;
                self.dq[row + mb.actions[b]] = 2.0 * td / batch as f32;
            }
        }
        self.online
            .backward(&mut self.ws_obs, &self.dq, &mut self.grads);
        clip_grad_norm(&mut self.grads, 10.0);
        self.adam.step(&mut self.online, &self.grads);
        loss
    }
}

fn minibatches(batch: usize) -> Vec<Minibatch> {
    let mut rng = Pcg64::seed_from_u64(2);
    (0..N_MINIBATCHES)
        .map(|_| Minibatch {
            obs: (0..batch * OBS_DIM)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect(),
            next_obs: (0..batch * OBS_DIM)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect(),
            actions: (0..batch).map(|_| rng.random_range(0..N_ACTIONS)).collect(),
            rewards: (0..batch).map(|_| rng.random_range(-1.0..1.0)).collect(),
            dones: (0..batch)
                .map(|_| if rng.random_bool(0.05) { 1.0 } else { 0.0 })
                .collect(),
        })
        .collect()
}

const KINDS: [(&str, OutputKind); 3] = [
    ("plain", OutputKind::Plain),
    ("boot10", OutputKind::Bootstrap { heads: 10 }),
    ("noisy", OutputKind::Noisy),
];

fn bench_update(c: &mut Criterion) {
    let mut group = c.benchmark_group("ddqn_update");
    for batch in [32, 64] {
        let data = minibatches(batch);
        for (name, kind) in KINDS {
            let mut learner = Learner::new(kind, batch);
            let mut next = 0;
            group.bench_function(BenchmarkId::new(name, batch), |bencher| {
                bencher.iter(|| {
                    next = (next + 1) % N_MINIBATCHES;
                    black_box(learner.update(&data[next]))
                })
            });
        }
    }
    group.finish();
}

fn bench_single_forward(c: &mut Criterion) {
    let mut group = c.benchmark_group("single_forward");
    let mut rng = Pcg64::seed_from_u64(3);
    let states: Vec<Vec<f32>> = (0..N_MINIBATCHES)
        .map(|_| (0..OBS_DIM).map(|_| rng.random_range(-1.0..1.0)).collect())
        .collect();
    for (name, kind) in KINDS {
        let net = QNet::new(OBS_DIM, N_ACTIONS, kind, &mut rng);
        let mut noise = NoiseSample::new(N_ACTIONS);
        noise.resample(&mut rng);
        let noise = matches!(kind, OutputKind::Noisy).then_some(&noise);
        let mut q = vec![0.0f32; kind.heads() * N_ACTIONS];
        let mut next = 0;
        group.bench_function(name, |bencher| {
            bencher.iter(|| {
                next = (next + 1) % N_MINIBATCHES;
                net.q_values_single(black_box(&states[next]), noise, &mut q);
                black_box(argmax(&q[..N_ACTIONS]))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_update, bench_single_forward);
criterion_main!(benches);
