//! Whole-run speed: environment steps per second of a full training run (acting, stepping, replay, one
//! prioritized double-DQN update per step), with 10 bootstrapped heads on CartPole-v0 and LunarLander-v2.
use arld::lab::run_one;
use arld::train::{ConfigInput, Method, NetKind};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

fn whole_run(c: &mut Criterion) {
    let mut group = c.benchmark_group("train_run");
    group.sample_size(10);
    for (env, steps) in [("CartPole-v0", 5_000usize), ("LunarLander-v2", 5_000)] {
        let mut input = ConfigInput::new(env, Method::Dqn, NetKind::Bootstrap, 0);
        for (key, value) in [
            ("train_steps", steps),
            ("learning_starts", 0),
            ("eval_period", steps),
            ("eval_episodes", 1),
        ] {
            input.set(key, value as i64).unwrap();
        }
        let cfg = input.resolve().unwrap();
        group.throughput(Throughput::Elements(steps as u64));
        group.bench_function(format!("{env}/bootstrap10/{steps}_steps"), |b| {
            b.iter(|| run_one(&cfg, None, false).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, whole_run);
criterion_main!(benches);
