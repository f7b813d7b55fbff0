//! n-step returns for DQfD's optional n-step loss (Hester et al.): each transition is stored with
//! `R = Σ_{i<k} γ^i r_{t+i}`, the observation `k` steps later and the discount `γ^k` of its value, where
//! `k = n`, or fewer when the episode ends first (0 discount when it terminated). Transitions therefore reach
//! the memory `n − 1` steps late, and all at once at the end of an episode. [`super::Replay`] owns the queue.

use super::{ReplayError, Transition};
use crate::task::Action;
use std::collections::VecDeque;

/// The n-step return of a transition (DQfD): `reward = Σ_{i<k} γ^i r_{t+i}`, the observation `k` steps
/// later, and `discount = γ^k`, or 0 when the episode terminated within those `k ≤ n` steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct NStepReturn<'a> {
    pub reward: f32,
    pub next_obs: &'a [f32],
    pub discount: f32,
}

/// A transition waiting for its n-step return: an owned copy of a [`Transition`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(bound = "")]
pub(super) struct Pending<A: Action> {
    obs: Vec<f32>,
    action: A,
    reward: f32,
    next_obs: Vec<f32>,
    terminal: bool,
    is_demo: bool,
}

impl<A: Action> Pending<A> {
    fn transition(&self) -> Transition<'_, A> {
        Transition {
            obs: &self.obs,
            action: self.action.borrow(),
            reward: self.reward,
            next_obs: &self.next_obs,
            terminal: self.terminal,
            is_demo: self.is_demo,
        }
    }
}

/// Holds the last `n` transitions of the current episode until their n-step returns are known.
#[derive(Clone, Debug)]
pub(super) struct NStepQueue<A: Action> {
    n: usize,
    gamma: f32,
    pending: VecDeque<Pending<A>>,
}

/// Where completed transitions go (the memory's slot writer).
type Store<'s, A> = dyn FnMut(Transition<'_, A>, NStepReturn<'_>) -> Result<(), ReplayError> + 's;

impl<A: Action> NStepQueue<A> {
    pub(super) fn new(n: usize, gamma: f32) -> Self {
        Self {
            n: n.max(1),
            gamma,
            pending: VecDeque::with_capacity(n.max(1)),
        }
    }

    /// The transitions waiting for their n-step return (for snapshots).
    pub(super) fn pending(&self) -> Vec<&Pending<A>> {
        self.pending.iter().collect()
    }

    /// Replaces the waiting transitions (from a snapshot).
    pub(super) fn set_pending(&mut self, pending: Vec<Pending<A>>) {
        self.pending = pending.into();
    }

    /// Adds a transition and stores every transition whose n-step return is now complete.
    /// A terminal transition completes the whole episode.
    pub(super) fn push(
        &mut self,
        t: Transition<'_, A>,
        mut store: impl FnMut(Transition<'_, A>, NStepReturn<'_>) -> Result<(), ReplayError>,
    ) -> Result<(), ReplayError> {
        self.pending.push_back(Pending {
            obs: t.obs.to_vec(),
            action: A::owned(t.action),
            reward: t.reward,
            next_obs: t.next_obs.to_vec(),
            terminal: t.terminal,
            is_demo: t.is_demo,
        });
        if t.terminal {
            return self.end_episode(store);
        }
        if self.pending.len() == self.n {
            self.emit_front(&mut store)?;
        }
        Ok(())
    }

    /// The episode ended (termination or time limit): stores the rest with shortened horizons.
    pub(super) fn end_episode(
        &mut self,
        mut store: impl FnMut(Transition<'_, A>, NStepReturn<'_>) -> Result<(), ReplayError>,
    ) -> Result<(), ReplayError> {
        while !self.pending.is_empty() {
            self.emit_front(&mut store)?;
        }
        Ok(())
    }

    fn emit_front(&mut self, store: &mut Store<'_, A>) -> Result<(), ReplayError> {
        let (mut reward, mut scale) = (0.0f32, 1.0f32);
        for t in &self.pending {
            reward += scale * t.reward;
            scale *= self.gamma;
        }
        let last = self.pending.back().expect("emit_front on an empty queue");
        let discount = if last.terminal { 0.0 } else { scale };
        let n = NStepReturn {
            reward,
            next_obs: &last.next_obs,
            discount,
        };
        store(self.pending[0].transition(), n)?;
        self.pending.pop_front();
        Ok(())
    }
}
#[cfg(test)]
mod tests {
    use crate::replay::{Batch, Replay, ReplayConfig, Transition};
    use rand::SeedableRng;

    /// Pushes transition `i` of an episode: observation `i`, reward `i + 1`.
    fn push(replay: &mut Replay, i: usize, terminal: bool) {
        replay
            .push(Transition {
                obs: &[i as f32],
                action: 0,
                reward: (i + 1) as f32,
                next_obs: &[(i + 1) as f32],
                terminal,
                is_demo: false,
            })
            .unwrap();
    }

    /// Stored n-step returns equal a direct sum over the episode, including the shortened ones at its end.
    #[test]
    fn n_step_returns_match_a_direct_computation() {
        let (n, gamma) = (3, 0.5f32);
        let cfg = ReplayConfig {
            capacity: 16,
            prioritized: false,
            n_step: n,
            gamma,
            ..ReplayConfig::default()
        };
        let mut replay = Replay::new(1, &cfg);
        let len = 5;
        for i in 0..len {
            push(&mut replay, i, i + 1 == len);
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
            n_step: 10,
            gamma: 0.9,
            ..ReplayConfig::default()
        };
        let mut replay = Replay::new(1, &cfg);
        push(&mut replay, 0, false);
        push(&mut replay, 1, false);
        assert_eq!(replay.len(), 0, "held back until the return is known");
        replay.end_episode().unwrap();
        let mut batch = Batch::default();
        replay.sample(8, 1.0, &mut rand_pcg::Pcg64::seed_from_u64(1), &mut batch);
        for k in 0..batch.len() {
            let i = batch.obs[k] as usize;
            let expect = if i == 0 { 0.9f32 * 0.9 } else { 0.9 };
            assert!((batch.nstep_discounts[k] - expect).abs() < 1e-6);
        }
    }
}
