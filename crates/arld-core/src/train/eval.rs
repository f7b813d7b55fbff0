//! Evaluation of a run: the test episodes of every evaluation, run in lockstep under the network's test policy.

use super::EvalPoint;
use crate::agent::Learner;
use crate::env::{Action, ActionColumn, Env};
use anyhow::{Result, ensure};

/// The test episodes of every evaluation (no exploration), run in lockstep: one environment per episode,
/// all stepped together with one batched forward per step for the environments still running.
///
/// Environment `i` is seeded once with `seed + i` and then continues its own generator from one evaluation
/// to the next. The batched forward computes each row exactly as a single-state forward would
/// ([`Learner::test_actions`]), so lockstep changes the cost, not the actions.
pub struct Evaluator<A: Action = usize> {
    envs: Vec<Box<dyn Env<A>>>,
    /// The length of an observation.
    obs_dim: usize,
    returns: Vec<f64>,
    /// Indices of the environments whose episode is still running, and their observations (row-major).
    running: Vec<usize>,
    obs: Vec<f32>,
    actions: A::Column,
}

impl<A: Action> Evaluator<A> {
    /// One test episode per environment of `envs`, environment `i` seeded `seed + i`, for observations of
    /// `obs_dim` values.
    pub fn new(mut envs: Vec<Box<dyn Env<A>>>, seed: u64, obs_dim: usize) -> Result<Self> {
        ensure!(
            !envs.is_empty(),
            "evaluation needs at least one test environment"
        );
        for (i, env) in envs.iter_mut().enumerate() {
            env.reset(Some(seed + i as u64));
        }
        let episodes = envs.len();
        Ok(Self {
            envs,
            obs_dim,
            returns: Vec::with_capacity(episodes),
            running: Vec::with_capacity(episodes),
            obs: Vec::with_capacity(episodes * obs_dim),
            actions: A::Column::default(),
        })
    }

    /// The state of every test environment's generator (for a run's snapshot).
    pub fn generators(&self) -> Vec<Option<[u64; 6]>> {
        self.envs
            .iter()
            .map(|env| env.generator().map(|g| g.to_words()))
            .collect()
    }

    /// Puts back the generators [`Self::generators`] returned.
    pub(crate) fn set_generators(&mut self, generators: &[Option<[u64; 6]>]) -> Result<()> {
        ensure!(
            generators.len() == self.envs.len(),
            "the snapshot has {} test environments, the run {}",
            generators.len(),
            self.envs.len()
        );
        for (env, words) in self.envs.iter_mut().zip(generators) {
            env.set_generator(words.map(crate::rng::NumpyRng::from_words));
        }
        Ok(())
    }

    /// One episode per environment under `net`'s test policy; the returns' summary at training step `step`.
    pub fn evaluate(
        &mut self,
        agent: &mut impl Learner<Action = A>,
        step: usize,
    ) -> Result<EvalPoint> {
        self.returns.clear();
        self.running.clear();
        let d = self.obs_dim;
        self.obs.clear();
        self.obs.resize(self.envs.len() * d, 0.0);
        for (i, env) in self.envs.iter_mut().enumerate() {
            env.reset_into(None, &mut self.obs[i * d..(i + 1) * d]);
            self.running.push(i);
            self.returns.push(0.0);
        }
        while !self.running.is_empty() {
            agent.test_actions(&self.obs, &mut self.actions);
            // Step every running environment; compact the finished ones out, keeping the order (row `kept` is
            // at or before row `row`, so the running environment's new observation moves up in place).
            let mut kept = 0;
            for row in 0..self.running.len() {
                let i = self.running[row];
                let s = self.envs[i]
                    .step_into(self.actions.get(row), &mut self.obs[row * d..(row + 1) * d])?;
                self.returns[i] += s.reward;
                if !(s.terminated || s.truncated) {
                    self.running[kept] = i;
                    self.obs.copy_within(row * d..(row + 1) * d, kept * d);
                    kept += 1;
                }
            }
            self.running.truncate(kept);
            self.obs.truncate(kept * d);
        }
        let returns = &self.returns;
        let n = returns.len() as f64;
        let mean = returns.iter().sum::<f64>() / n;
        let std = (returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        let min = returns.iter().cloned().fold(f64::INFINITY, f64::min);
        let max = returns.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        Ok(EvalPoint {
            step: step as u64,
            mean,
            std,
            min,
            max,
        })
    }
}
