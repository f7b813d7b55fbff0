//! Subcommands of the `arld` binary, one file each.
pub mod env_cmd;
pub mod expert_cmd;
pub mod lab_cmd;
pub mod train_cmd;

/// A command-line count from 1 to `max`: clap names the flag and the range when a value is out of it.
pub fn count(max: u64) -> clap::builder::RangedU64ValueParser<usize> {
    clap::builder::RangedU64ValueParser::<usize>::new().range(1..=max)
}

/// The most episodes a command plays or evaluates (far above any use; keeps a typo from running for days).
pub const MAX_EPISODES: u64 = 1_000_000;

/// The seed of the last of `episodes` episodes seeded `seed`, `seed + 1`, ...: an error when it passes the
/// largest seed.
pub fn last_seed(seed: u64, episodes: usize) -> anyhow::Result<u64> {
    use anyhow::Context;
    seed.checked_add(episodes as u64 - 1)
        .context("--seed plus --episodes overflows the 64-bit seed range")
}

/// Help of every `--env`: the built-in tasks of both kinds, and where the full list is.
pub const ENV_HELP: &str = "Task, as its Gymnasium id. Discrete actions (DQN family): CartPole-v0, CartPole-v1, \
Acrobot-v1, MountainCar-v0, LunarLander-v2, LunarLander-v3. Actions in a box (TD3 or SAC, see --algo): Pendulum-v1, \
MountainCarContinuous-v0, LunarLanderContinuous-v3. `arld env list` lists every task with its sizes and solve \
threshold; other Gymnasium environments train from Python (arld.Agent).";

/// The largest seed: the largest integer a config file holds.
pub const MAX_SEED: u64 = i64::MAX as u64;

/// Parses a seed: an integer from 0 to [`MAX_SEED`]; anything else is an error that says what a seed is. The
/// flags that take one allow a leading `-`, so that `--seed -1` reaches this message.
pub fn seed(text: &str) -> Result<u64, String> {
    let what = format!("seeds are non-negative integers, from 0 to {MAX_SEED}; got '{text}'");
    match text.parse::<u64>() {
        Ok(seed) if seed <= MAX_SEED => Ok(seed),
        _ => Err(what),
    }
}
