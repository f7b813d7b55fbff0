//! Subcommands of the `arld` binary, one file each.
pub mod env_cmd;
pub mod experiment_cmd;
pub mod expert_cmd;
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
