//! The one choice between the actor-critic learners of a box task: [`Algo`] (TD3 or SAC), the enum a
//! configuration's `algo` key, the command line's `--algo` and Python's `algo=` name, and everything that
//! differs by it outside the learners' own files: the learner's name (configuration files, snapshots, actor
//! files), its actor's outputs and the test action read from them, and the learner built from its settings
//! ([`BoxLearnerConfig`], which `train::run::box_agent` builds from the configuration). Other modules ask
//! these of `Algo` rather than matching on it.

use super::actor_critic::ActorCriticLearner;
use super::sac::{Sac, SacConfig, SacPart};
use super::td3::{Td3, Td3Config, Td3Part};
use crate::nn::OutputActivation;
use anyhow::{Context, Result};
use rand_pcg::Pcg64;
use serde::{Deserialize, Serialize};
use std::fmt;

/// The actor-critic learner of a task with actions in a box (docs/algorithm.md §15-17).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Algo {
    /// TD3 (Fujimoto et al. 2018).
    #[default]
    Td3,
    /// Soft actor-critic (Haarnoja et al. 2018).
    Sac,
}

impl Algo {
    /// Every learner, in declaration order.
    pub const ALL: [Algo; 2] = [Algo::Td3, Algo::Sac];

    /// The learner's name: command line, configuration files, snapshots, actor files (`td3`, `sac`).
    pub fn name(self) -> &'static str {
        match self {
            Algo::Td3 => "td3",
            Algo::Sac => "sac",
        }
    }

    /// Whether this is TD3, the default (which a configuration file leaves out).
    pub(crate) fn is_td3(&self) -> bool {
        *self == Algo::Td3
    }

    /// The actor's outputs per dimension of the action and their activation (TD3: the tanh action; SAC: the
    /// means and log standard deviations of its Gaussian).
    pub(crate) fn actor(self) -> (usize, OutputActivation) {
        match self {
            Algo::Td3 => Td3Part::ACTOR,
            Algo::Sac => SacPart::ACTOR,
        }
    }

    /// The test-time actions (no exploration) as tanh outputs in (-1, 1), into the rows of `units` (`a` numbers
    /// each), from the actor's outputs `out` at the same rows.
    pub(crate) fn test_units(self, out: &[f32], a: usize, units: &mut [f32]) {
        match self {
            Algo::Td3 => Td3Part::units_of(out, a, units),
            Algo::Sac => SacPart::units_of(out, a, units),
        }
    }
}

impl std::str::FromStr for Algo {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        Algo::ALL
            .into_iter()
            .find(|algo| algo.name() == s)
            .with_context(|| {
                let known: Vec<&str> = Algo::ALL.iter().map(|algo| algo.name()).collect();
                format!(
                    "unknown actor-critic learner '{s}'; known: {}",
                    known.join(", ")
                )
            })
    }
}

impl fmt::Display for Algo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The settings of the learner a `BoxAgent` holds: TD3's or SAC's.
#[derive(Debug, Clone, PartialEq)]
pub enum BoxLearnerConfig {
    Td3(Td3Config),
    Sac(SacConfig),
}

impl BoxLearnerConfig {
    /// The learner these settings are of.
    pub fn algo(&self) -> Algo {
        match self {
            BoxLearnerConfig::Td3(_) => Algo::Td3,
            BoxLearnerConfig::Sac(_) => Algo::Sac,
        }
    }

    /// The learner for observations of `obs_dim` numbers and actions in `[low, high]`, its weights and later
    /// draws from `rng`, and whether its cloning loss is configured with the Q-filter.
    pub(crate) fn learner(
        self,
        obs_dim: usize,
        low: &[f32],
        high: &[f32],
        rng: Pcg64,
    ) -> (Box<dyn ActorCriticLearner>, bool) {
        match self {
            BoxLearnerConfig::Td3(config) => {
                let q_filter = config.common.q_filter;
                (
                    Box::new(Td3::new(config, obs_dim, low, high, rng)),
                    q_filter,
                )
            }
            BoxLearnerConfig::Sac(config) => {
                let q_filter = config.common.q_filter;
                (
                    Box::new(Sac::new(config, obs_dim, low, high, rng)),
                    q_filter,
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    /// The names written by hand here agree with serde's and clap's (derived from the variants), with `Display`
    /// and `FromStr`; an unknown name is refused naming the known ones.
    #[test]
    fn the_names_agree_with_serde_clap_display_and_from_str() {
        assert_eq!(Algo::ALL.len(), Algo::value_variants().len());
        for algo in Algo::ALL {
            let name = algo.name();
            assert_eq!(algo.to_string(), name);
            assert_eq!(name.parse::<Algo>().unwrap(), algo);
            assert_eq!(serde_json::to_string(&algo).unwrap(), format!("\"{name}\""));
            assert_eq!(algo.to_possible_value().unwrap().get_name(), name);
        }
        assert_eq!(
            format!("{:#}", "ppo".parse::<Algo>().unwrap_err()),
            "unknown actor-critic learner 'ppo'; known: td3, sac"
        );
    }
}
