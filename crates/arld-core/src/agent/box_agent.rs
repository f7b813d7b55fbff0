//! The actor-critic family behind the [`Learner`] interface: [`BoxAgent`] acts and learns in a box of float32
//! actions with any `ActorCriticLearner` learner (TD3, [`super::td3`]; SAC, [`super::sac`]), from the same replay
//! batches, schedules and snapshots as the DQN family.
//!
//! - Acting: at ε = 1 (a run acting at random before learning starts) a uniform draw from the box, otherwise
//!   the learner's behaviour action (TD3: the actor's action plus Gaussian noise; SAC: a sample of its policy):
//!   actor-critic learners explore by themselves, so a DQN's ε-greedy schedule below 1 does not apply. Every
//!   draw comes from the learner's generator, so the run's seed fixes the actions.
//! - Uncertainty, computed only when the query rule asks for it ([`BoxUncertainty`]): the standard deviation of
//!   the critic heads at the action taken (`critic_spread`), or the heads' disagreement about the best action
//!   near the test action (`action_disagreement`).
//! - Risk (only with a risk critic, `BoxAgent::with_risk_critic`, which a run adds when its query rule reads the
//!   risk): `1 - Q_R` at the action taken ([`super::risk`]); the critic takes one TD step on every batch, before
//!   the learner's update, with the policy's test actions at the next observations.
//! - Learning: the learner reads the replay batch as it is: the n-step return, its observation and `gamma^n`
//!   when the replay keeps them, otherwise the one-step reward, the next observation and `gamma` (0 at a
//!   bootstrap cut; [`Batch::returns`]); demonstrated samples are flagged for the cloning loss. The priorities are the absolute TD
//!   errors of the first critic head.

use super::actor_critic::ActorCriticLearner;
use super::actor_file;
use super::algo::{Algo, BoxLearnerConfig};
use super::risk::{RiskConfig, RiskCritic};
use super::{Learner, UpdateStats};
use crate::nn::Mlp;
use crate::query::{Needs, Signals};
use crate::replay::Batch;
use crate::state::{Persist, StateDict, StateError};
use crate::task::BoxColumn;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// A learner of actions in a box: an `ActorCriticLearner` learner behind [`Learner`].
pub struct BoxAgent {
    /// Which learner `learner` is.
    algo: Algo,
    learner: Box<dyn ActorCriticLearner>,
    obs_dim: usize,
    low: Vec<f32>,
    high: Vec<f32>,
    gamma: f32,
    /// Whether the learner's cloning loss is configured with the Q-filter (off during pre-training).
    q_filter: bool,
    /// ThriftyDAgger's risk critic, when the run's query rule reads the risk.
    risk: Option<RiskCritic>,
    /// What the uncertainty signal measures.
    uncertainty: BoxUncertainty,
}

/// The uncertainty a box learner reports to the query rule (docs/algorithm.md §15): what its critic ensemble
/// disagrees about.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BoxUncertainty {
    /// The critic heads' standard deviation at the agent's action (the critics' variance, as RCMP's).
    #[default]
    CriticVariance,
    /// The heads' disagreement about the best action near the test action (each head's argmax over probe
    /// actions; their standard deviation, in half-widths of the box).
    ActionDisagreement,
}

impl BoxAgent {
    /// The learner of `config` for observations of `obs_dim` numbers and actions in `[low, high]`, discounting
    /// by `gamma`, its weights and every later draw from `seed`.
    pub fn new(
        config: BoxLearnerConfig,
        obs_dim: usize,
        low: &[f32],
        high: &[f32],
        gamma: f32,
        seed: u64,
    ) -> Self {
        let rng = Pcg64::seed_from_u64(seed);
        let algo = config.algo();
        let (learner, q_filter) = config.learner(obs_dim, low, high, rng);
        BoxAgent {
            algo,
            learner,
            obs_dim,
            low: low.to_vec(),
            high: high.to_vec(),
            gamma,
            q_filter,
            risk: None,
            uncertainty: BoxUncertainty::default(),
        }
    }

    /// The agent reporting `uncertainty` to the query rule.
    pub fn with_uncertainty(mut self, uncertainty: BoxUncertainty) -> Self {
        self.uncertainty = uncertainty;
        self
    }

    /// The agent with a risk critic of `config`, its weights drawn from a generator seeded with `seed` (a stream
    /// of its own, so that the learner's draws stay what they are without one).
    pub(crate) fn with_risk_critic(mut self, config: RiskConfig, seed: u64) -> Self {
        let critic = RiskCritic::new(config, self.obs_dim, self.low.len(), seed);
        self.risk = Some(critic);
        self
    }

    /// The policy network of the learner inside (TD3: the tanh actor; SAC: the means and log standard
    /// deviations of its Gaussian).
    pub fn actor(&self) -> &Mlp {
        self.learner.actor()
    }

    /// The learner inside: TD3 or SAC.
    pub fn algo(&self) -> Algo {
        self.algo
    }
}

impl Learner for BoxAgent {
    type Action = Vec<f32>;

    fn begin_episode(&mut self) {}

    fn act(&mut self, obs: &[f32], epsilon: f64, want: Needs) -> (Vec<f32>, Signals) {
        let mut action = vec![0.0; self.low.len()];
        if epsilon >= 1.0 {
            for (d, a) in action.iter_mut().enumerate() {
                *a = self.learner.rng().random_range(self.low[d]..=self.high[d]);
            }
        } else {
            self.learner.act(obs, &mut action);
        }
        let uncertainty = want.uncertainty.then(|| match self.uncertainty {
            BoxUncertainty::CriticVariance => self.learner.critic_spread(obs, &action),
            BoxUncertainty::ActionDisagreement => self.learner.action_disagreement(obs),
        });
        let risk = match (&mut self.risk, want.risk) {
            (Some(critic), true) => Some(critic.risk(obs, &action)),
            _ => None,
        };
        let signals = Signals {
            uncertainty,
            risk,
            ..Signals::default()
        };
        (action, signals)
    }

    fn learn(&mut self, batch: &Batch<Vec<f32>>) -> (UpdateStats, &[f32]) {
        if let Some(critic) = &mut self.risk {
            let learner = &mut self.learner;
            critic.update(batch, &mut |obs, action| learner.test_action(obs, action));
        }
        let (update, priorities) = self.learner.learn(batch, self.gamma);
        let stats = UpdateStats {
            td_loss: update.critic_loss,
            margin_loss: 0.0,
            nstep_loss: 0.0,
            grad_norm: 0.0,
        };
        (stats, priorities)
    }

    fn set_pretraining(&mut self, on: bool) {
        self.learner.set_q_filter(self.q_filter && !on);
    }

    /// The targets follow the online networks by Polyak averaging inside every update: nothing to copy.
    fn end_target_period(&mut self) {}

    fn test_actions(&mut self, obs: &[f32], actions: &mut BoxColumn) {
        let (d, a) = (self.obs_dim, self.low.len());
        let rows = obs.len() / d;
        self.learner.test_action(obs, actions.rows_mut(rows, a));
    }

    /// Writes the actor (the policy a run keeps) as safetensors: one tensor `actor.params` with every weight
    /// and bias layer by layer, its layer sizes, the learner and the box in the header.
    fn save_weights(&self, path: &Path, metadata: &BTreeMap<String, String>) -> anyhow::Result<()> {
        actor_file::write(
            path,
            self.algo,
            self.learner.actor(),
            &self.low,
            &self.high,
            metadata,
        )
    }
}

impl Persist for BoxAgent {
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        let name = format!("{prefix}.{}", self.algo.name());
        self.learner.save_state(&name, state);
        if let Some(critic) = &self.risk {
            critic.save_state(&format!("{prefix}.risk_critic"), state);
        }
    }

    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        let name = format!("{prefix}.{}", self.algo.name());
        self.learner.load_state(&name, state)?;
        match &mut self.risk {
            Some(critic) => critic.load_state(&format!("{prefix}.risk_critic"), state),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::sac::SacConfig;
    use crate::agent::td3::Td3Config;
    use crate::env::{Env, make_continuous};
    use crate::replay::{Replay, ReplayConfig, Transition};
    use crate::train::eval::Evaluator;

    /// A learner for Pendulum-v1 from `seed` with 64-64 networks and batches of 128: TD3, or SAC when `sac`.
    fn pendulum_agent(sac: bool, seed: u64) -> BoxAgent {
        let (hidden, max_batch) = (vec![64, 64], 128);
        let config = if sac {
            let mut config = SacConfig::default();
            (config.common.hidden, config.common.max_batch) = (hidden, max_batch);
            BoxLearnerConfig::Sac(config)
        } else {
            let mut config = Td3Config::default();
            (config.common.hidden, config.common.max_batch) = (hidden, max_batch);
            BoxLearnerConfig::Td3(config)
        };
        BoxAgent::new(config, 3, &[-2.0], &[2.0], 0.99, seed)
    }

    /// Trains `agent` on Pendulum-v1 for `steps` through the run's own parts: a prioritized replay of box
    /// actions with 3-step returns, ε = 1 for the first 1,000 steps, one update per step after them.
    fn train(agent: &mut BoxAgent, replay: &mut Replay<Vec<f32>>, steps: std::ops::Range<usize>) {
        let mut env = make_continuous("Pendulum-v1").unwrap();
        let mut rng = Pcg64::seed_from_u64(7);
        let mut batch = Batch::default();
        let (mut obs, mut next) = (vec![0.0; 3], vec![0.0; 3]);
        env.reset_into(Some(0), &mut obs);
        for step in 0..steps.end {
            let epsilon = if step < 1_000 { 1.0 } else { 0.0 };
            let (action, _) = agent.act(&obs, epsilon, Needs::NOTHING);
            let out = env.step_into(&action, &mut next).unwrap();
            if step >= steps.start {
                replay
                    .push(Transition {
                        obs: &obs,
                        action: &action,
                        reward: out.reward as f32,
                        next_obs: &next,
                        terminal: out.terminated,
                        is_demo: false,
                    })
                    .unwrap();
            }
            obs.copy_from_slice(&next);
            if out.terminated || out.truncated {
                replay.end_episode().unwrap();
                env.reset_into(None, &mut obs);
            }
            if step >= 1_000 && step >= steps.start {
                replay.sample(128, 0.6, &mut rng, &mut batch);
                let (_, priorities) = agent.learn(&batch);
                let priorities = priorities.to_vec();
                replay.update_priorities(&batch.idx, &priorities);
            }
        }
    }

    fn replay() -> Replay<Vec<f32>> {
        let config = ReplayConfig {
            capacity: 20_000,
            n_step: 3,
            gamma: 0.99,
            ..ReplayConfig::default()
        };
        Replay::try_with_action_width(3, 1, &config).unwrap()
    }

    #[test]
    fn learns_pendulum_from_a_prioritized_n_step_replay_of_box_actions() {
        let mut learner = pendulum_agent(false, 0);
        let mut memory = replay();
        train(&mut learner, &mut memory, 0..12_000);
        let envs: Vec<Box<dyn Env<Vec<f32>>>> = (0..10)
            .map(|_| Box::new(make_continuous("Pendulum-v1").unwrap()) as Box<dyn Env<Vec<f32>>>)
            .collect();
        let mut evaluator = Evaluator::new(envs, 1000, 3).unwrap();
        let score = evaluator.evaluate(&mut learner, 12_000).unwrap().mean;
        eprintln!("TD3 behind Learner, prioritized 3-step replay: {score:.1} after 12,000 steps");
        assert!(score > -250.0, "TD3 did not learn Pendulum-v1: {score}");
    }

    #[test]
    fn a_snapshot_continues_to_the_same_bytes() {
        // Two learners act and learn 1,200 steps; one is saved at step 1,100 and loaded into a third, fresh
        // learner built from another seed. The third and the first must then be equal to the last bit; for TD3
        // and for SAC.
        for (sac, name) in [(false, "td3"), (true, "sac")] {
            let (mut a, mut memory_a) = (pendulum_agent(sac, 3), replay());
            train(&mut a, &mut memory_a, 0..1_100);
            let mut b = pendulum_agent(sac, 99);
            {
                let mut state = StateDict::default();
                a.save_state("agent", &mut state);
                b.load_state("agent", &state).unwrap();
            }
            let mut memory_b = memory_a.clone();
            train(&mut a, &mut memory_a, 1_100..1_200);
            train(&mut b, &mut memory_b, 1_100..1_200);
            let (mut sa, mut sb) = (StateDict::default(), StateDict::default());
            a.save_state("agent", &mut sa);
            b.save_state("agent", &mut sb);
            assert!(sa == sb, "{name}: the continued learner differs");
            let updates: u64 = sa.value(&format!("agent.{name}.updates")).unwrap();
            assert_eq!(
                updates, 200,
                "{name}: 100 updates before the snapshot, 100 after"
            );
        }
    }

    #[test]
    fn the_uncertainty_signal_is_the_chosen_measure_and_draws_nothing() {
        // Two learners from one seed, trained alike, one reporting each measure: at every state they act alike (the
        // measure draws no random number) and each signal is its learner's measure at that state and action.
        let (mut variance, mut disagreement) = (
            pendulum_agent(false, 5),
            pendulum_agent(false, 5).with_uncertainty(BoxUncertainty::ActionDisagreement),
        );
        let (mut memory_a, mut memory_b) = (replay(), replay());
        train(&mut variance, &mut memory_a, 0..2_000);
        train(&mut disagreement, &mut memory_b, 0..2_000);
        let want = Needs {
            uncertainty: true,
            ..Needs::default()
        };
        let (mut spread_seen, mut disagreement_seen) = (0.0f32, 0.0f32);
        // The states of a test episode, from the environment's start states.
        let mut env = make_continuous("Pendulum-v1").unwrap();
        let (mut obs, mut next) = (vec![0.0; 3], vec![0.0; 3]);
        env.reset_into(Some(11), &mut obs);
        for k in 0..200 {
            let (a, sa) = variance.act(&obs, 0.0, want);
            let (b, sb) = disagreement.act(&obs, 0.0, want);
            assert_eq!(a, b, "the learners acted differently at state {k}");
            let spread = variance.learner.critic_spread(&obs, &a);
            let apart = disagreement.learner.action_disagreement(&obs);
            assert_eq!(sa.uncertainty, Some(spread));
            assert_eq!(sb.uncertainty, Some(apart));
            (spread_seen, disagreement_seen) =
                (spread_seen.max(spread), disagreement_seen.max(apart));
            let out = env.step_into(&a, &mut next).unwrap();
            obs.copy_from_slice(&next);
            if out.terminated || out.truncated {
                env.reset_into(None, &mut obs);
            }
        }
        // Along an episode both measures see the heads differ; the disagreement is in half-widths, at most 1.
        assert!(spread_seen > 0.0, "the heads' values never differed");
        assert!(
            disagreement_seen > 0.0 && disagreement_seen <= 1.0,
            "{disagreement_seen}"
        );
    }
}
