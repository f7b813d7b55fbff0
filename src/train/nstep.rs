//! n-step returns for DQfD's optional n-step loss (Hester et al.): each transition is stored with
//! `R = Σ_{i<k} γ^i r_{t+i}`, the observation `k` steps later and the discount `γ^k` of its value, where
//! `k = n`, or fewer when the episode ends first (0 discount when it terminated). Transitions therefore reach
//! replay `n − 1` steps late, and all at once at the end of an episode.

use crate::replay::{NStepReturn, Replay, ReplayError};
use std::collections::VecDeque;

/// One environment transition.
#[derive(Clone, Debug, PartialEq)]
pub struct Transition {
    pub obs: Vec<f32>,
    pub action: usize,
    pub reward: f32,
    pub next_obs: Vec<f32>,
    pub terminal: bool,
    pub is_demo: bool,
}

/// Holds the last `n` transitions of the current episode until their n-step returns are known.
pub struct NStepQueue {
    n: usize,
    gamma: f32,
    pending: VecDeque<Transition>,
}

impl NStepQueue {
    pub fn new(n: usize, gamma: f32) -> Self {
        Self {
            n: n.max(1),
            gamma,
            pending: VecDeque::with_capacity(n.max(1)),
        }
    }

    /// Adds a transition and stores every transition whose n-step return is now complete.
    /// A terminal transition completes the whole episode.
    pub fn push(&mut self, t: Transition, replay: &mut Replay) -> Result<(), ReplayError> {
        let terminal = t.terminal;
        self.pending.push_back(t);
        if terminal {
            return self.end_episode(replay);
        }
        if self.pending.len() == self.n {
            self.emit_front(replay)?;
        }
        Ok(())
    }

    /// The episode ended (termination or time limit): stores the rest with shortened horizons.
    pub fn end_episode(&mut self, replay: &mut Replay) -> Result<(), ReplayError> {
        while !self.pending.is_empty() {
            self.emit_front(replay)?;
        }
        Ok(())
    }

    fn emit_front(&mut self, replay: &mut Replay) -> Result<(), ReplayError> {
        let (mut reward, mut scale) = (0.0f32, 1.0f32);
        for t in &self.pending {
            reward += scale * t.reward;
            scale *= self.gamma;
        }
        let last = self.pending.back().expect("emit_front on an empty queue");
        let discount = if last.terminal { 0.0 } else { scale };
        let first = &self.pending[0];
        let n = NStepReturn {
            reward,
            next_obs: &last.next_obs,
            discount,
        };
        replay.push_with_n_step(
            &first.obs,
            first.action,
            first.reward,
            &first.next_obs,
            first.terminal,
            first.is_demo,
            Some(n),
        )?;
        self.pending.pop_front();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::replay::{Batch, ReplayConfig};
    use rand::SeedableRng;

    fn t(i: usize, terminal: bool) -> Transition {
        Transition {
            obs: vec![i as f32],
            action: 0,
            reward: (i + 1) as f32,
            next_obs: vec![(i + 1) as f32],
            terminal,
            is_demo: false,
        }
    }

    /// Stored n-step returns equal a direct sum over the episode, including the shortened ones at its end.
    #[test]
    fn n_step_returns_match_a_direct_computation() {
        let (n, gamma) = (3, 0.5f32);
        let cfg = ReplayConfig {
            capacity: 16,
            prioritized: false,
            n_step: true,
            ..ReplayConfig::default()
        };
        let mut replay = Replay::new(1, &cfg);
        let mut q = NStepQueue::new(n, gamma);
        let len = 5;
        for i in 0..len {
            q.push(t(i, i + 1 == len), &mut replay).unwrap();
        }
        assert_eq!(replay.len(), len);
        let mut batch = Batch::default();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(0);
        replay.sample(64, 1.0, &mut rng, &mut batch);
        for k in 0..batch.len() {
            let i = batch.obs[k] as usize;
            let end = (i + n).min(len);
            let expect: f32 = (i..end)
                .map(|j| gamma.powi((j - i) as i32) * (j + 1) as f32)
                .sum();
            assert!(
                (batch.nstep_rewards[k] - expect).abs() < 1e-6,
                "R for step {i}"
            );
            assert_eq!(batch.nstep_next_obs[k], end as f32);
            let disc = if end == len {
                0.0
            } else {
                gamma.powi(n as i32)
            };
            assert_eq!(batch.nstep_discounts[k], disc, "discount for step {i}");
        }
    }

    #[test]
    fn truncated_episodes_keep_bootstrapping() {
        let cfg = ReplayConfig {
            capacity: 16,
            prioritized: false,
            n_step: true,
            ..ReplayConfig::default()
        };
        let mut replay = Replay::new(1, &cfg);
        let mut q = NStepQueue::new(10, 0.9);
        q.push(t(0, false), &mut replay).unwrap();
        q.push(t(1, false), &mut replay).unwrap();
        assert_eq!(replay.len(), 0, "held back until the return is known");
        q.end_episode(&mut replay).unwrap();
        let mut batch = Batch::default();
        replay.sample(8, 1.0, &mut rand_pcg::Pcg64::seed_from_u64(1), &mut batch);
        for k in 0..batch.len() {
            let i = batch.obs[k] as usize;
            let expect = if i == 0 { 0.9f32 * 0.9 } else { 0.9 };
            assert!((batch.nstep_discounts[k] - expect).abs() < 1e-6);
        }
        assert!(
            replay.push(&[0.0], 0, 0.0, &[1.0], false, false).is_err(),
            "n-step memory needs returns"
        );
    }
}
