//! The classic-control tasks' one representation: the whole state is `N` float64 values (Gymnasium's
//! `env.unwrapped.state`), all zero until the first reset.
//!
//! A task writes only its dynamics, as a [`ClassicTask`] on that array. [`Classic`] holds the array and makes
//! the task a [`Dynamics`] (with [`Env::set_state`](super::Env::set_state) overwriting the array); the
//! environment, a [`Simulated`] of it, gets `state()`, and for a task registered under one id
//! ([`SingleId`]) also `new()` and `Default`.

use super::{Dynamics, EnvRng, Geometry, Simulated};
use crate::rng::NumpyRng;
use std::marker::PhantomData;

/// The dynamics of a classic-control task whose state is `N` float64 values.
pub trait ClassicTask<const N: usize> {
    /// Draws the initial state from the reset's generator.
    fn reset(state: &mut [f64; N], rng: &mut NumpyRng);
    /// One step with an action in range; returns the reward and whether the task terminated.
    fn step(state: &mut [f64; N], action: usize) -> (f64, bool);
    /// Writes the observation of `state` into `obs`.
    fn observe(state: &[f64; N], obs: &mut [f32]);
    /// What a viewer needs to draw `state`.
    fn geometry(state: &[f64; N]) -> Geometry;
}

/// A classic-control task registered under one Gymnasium id.
pub trait SingleId {
    /// The id `new()` builds.
    const ID: &'static str;
}

/// The state of the classic-control task `T`: `N` float64 values.
#[derive(Debug, Clone)]
pub struct Classic<T, const N: usize> {
    state: [f64; N],
    task: PhantomData<fn() -> T>,
}

impl<T: ClassicTask<N>, const N: usize> Dynamics for Classic<T, N> {
    fn reset(&mut self, rng: &mut NumpyRng) {
        T::reset(&mut self.state, rng);
    }

    fn step(&mut self, action: usize, _rng: &mut EnvRng) -> (f64, bool) {
        T::step(&mut self.state, action)
    }

    fn observe(&self, obs: &mut [f32]) {
        T::observe(&self.state, obs);
    }

    /// The whole state, in float64 (Gymnasium's `env.unwrapped.state`).
    fn state_mut(&mut self) -> Option<&mut [f64]> {
        Some(&mut self.state)
    }

    fn geometry(&self) -> Option<Geometry> {
        Some(T::geometry(&self.state))
    }
}

impl<T: ClassicTask<N>, const N: usize> Simulated<Classic<T, N>> {
    /// The task registered as `id`, its state zero until the first reset; panics if `id` is not registered.
    pub fn classic(id: &str) -> Self {
        Simulated::with_physics(
            id,
            Classic {
                state: [0.0; N],
                task: PhantomData,
            },
        )
    }

    /// The float64 state (Gymnasium's `env.unwrapped.state`).
    pub fn state(&self) -> [f64; N] {
        self.physics().state
    }
}

impl<T: ClassicTask<N> + SingleId, const N: usize> Simulated<Classic<T, N>> {
    /// The task, under its one id.
    pub fn new() -> Self {
        Self::classic(T::ID)
    }
}

impl<T: ClassicTask<N> + SingleId, const N: usize> Default for Simulated<Classic<T, N>> {
    fn default() -> Self {
        Self::new()
    }
}
