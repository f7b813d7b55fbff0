//! The reference returns that put a task's scores on one scale: the mean return of the uniform random policy and
//! of the shipped weak expert over [`REFERENCE_EPISODES`] episodes of fixed seeds, computed by the report itself so
//! that the normalised AUC (effort.md) and the expert's mean on the box tasks (claims.md) need no typed number.

use anyhow::Result;
use rand::{Rng, SeedableRng};

/// Episodes behind the random policy's and the expert's reference returns.
pub const REFERENCE_EPISODES: usize = 100;
/// Seed of the reference episodes (episode i resets with `REFERENCE_SEED + i`).
pub const REFERENCE_SEED: u64 = 1_000_000;

/// Mean returns of the random policy (a uniform draw from the actions, or from the box) and of the shipped weak
/// expert on `env`.
pub fn references(env: &str) -> Result<(f64, f64)> {
    use arld_core::env::{self, rollouts};
    let mut rng = rand_pcg::Pcg64::seed_from_u64(REFERENCE_SEED);
    let seeds = |i: usize| Some(REFERENCE_SEED + i as u64);
    let random = match env::box_spec(env) {
        Ok(spec) => rollouts(
            env::make_box(env)?.as_mut(),
            REFERENCE_EPISODES,
            seeds,
            |_| {
                let (low, high) = (spec.action_low.iter(), spec.action_high.iter());
                let action = low.zip(high).map(|(&l, &h)| rng.random_range(l..=h));
                Ok::<_, anyhow::Error>(action.collect())
            },
        )?,
        Err(_) => {
            let mut e = env::make(env)?;
            let n_actions = e.n_actions();
            rollouts(e.as_mut(), REFERENCE_EPISODES, seeds, |_| {
                Ok::<_, anyhow::Error>(rng.random_range(0..n_actions))
            })?
        }
    };
    let stats = arld_core::expert::pipeline::evaluate_spec(
        "shipped:weak",
        env,
        REFERENCE_EPISODES,
        REFERENCE_SEED,
        30.0,
    )?;
    let random_mean = random.iter().map(|e| e.ret).sum::<f64>() / random.len() as f64;
    Ok((random_mean, stats.mean))
}
