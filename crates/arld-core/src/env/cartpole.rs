//! CartPole-v0 and CartPole-v1, as Gymnasium 1.x computes them.
//!
//! A pole balanced on a cart; action 0 pushes the cart left, 1 right, with force 10. The dynamics are the
//! Barto-Sutton-Anderson equations (Florian, "Correct equations for the dynamics of the cart-pole system",
//! with the frictionless simplification) integrated by explicit Euler over tau = 0.02 s, in float64, with
//! the operations in Gymnasium's order so that every rounding matches. The episode terminates when
//! |x| > 2.4 or |theta| > 12 degrees; every step, including the terminating one, is worth 1.
//! v0 and v1 differ only in the time limit (200 vs 500) and the solve threshold (195 vs 475).
//! The initial state is four draws of `uniform(-0.05, 0.05)` (docs/environments.md, "Classic control").

use super::Simulated;
use super::classic::{Classic, ClassicTask};
use crate::rng::NumpyRng;

const GRAVITY: f64 = 9.8;
const MASS_CART: f64 = 1.0;
const MASS_POLE: f64 = 0.1;
const TOTAL_MASS: f64 = MASS_POLE + MASS_CART;
/// Half the pole's length.
const HALF_LENGTH: f64 = 0.5;
const POLE_MASS_LENGTH: f64 = MASS_POLE * HALF_LENGTH;
const FORCE_MAG: f64 = 10.0;
const TAU: f64 = 0.02;
const X_THRESHOLD: f64 = 2.4;
/// 12 degrees, computed as Gymnasium does (`12 * 2 * pi / 360`).
const THETA_THRESHOLD: f64 = 12.0 * 2.0 * std::f64::consts::PI / 360.0;

/// CartPole with its Gymnasium time limit.
pub type CartPole = Simulated<Classic<CartPolePhysics, 4>>;

/// CartPole's dynamics, on the float64 state `[x, x_dot, theta, theta_dot]`.
#[derive(Debug, Clone)]
pub struct CartPolePhysics;

impl CartPole {
    /// `id` is `CartPole-v0` or `CartPole-v1`; any other id panics (use [`super::make`] for user input).
    pub fn new(id: &'static str) -> Self {
        assert!(
            id.starts_with("CartPole-"),
            "CartPole::new called with {id}"
        );
        Simulated::classic(id)
    }

    /// CartPole-v0: 200 steps, solved at 195.
    pub fn v0() -> Self {
        Self::new("CartPole-v0")
    }

    /// CartPole-v1: 500 steps, solved at 475.
    pub fn v1() -> Self {
        Self::new("CartPole-v1")
    }
}

impl ClassicTask<4> for CartPolePhysics {
    fn reset(state: &mut [f64; 4], rng: &mut NumpyRng) {
        rng.uniform_fill(-0.05, 0.05, state);
    }

    fn step(state: &mut [f64; 4], action: usize) -> (f64, bool) {
        let [x, x_dot, theta, theta_dot] = *state;
        let force = if action == 1 { FORCE_MAG } else { -FORCE_MAG };
        let cos_theta = theta.cos();
        let sin_theta = theta.sin();
        // Same association as Gymnasium: rounding must match to reproduce its trajectories.
        let temp = (force + POLE_MASS_LENGTH * (theta_dot * theta_dot) * sin_theta) / TOTAL_MASS;
        let theta_acc = (GRAVITY * sin_theta - cos_theta * temp)
            / (HALF_LENGTH * (4.0 / 3.0 - MASS_POLE * (cos_theta * cos_theta) / TOTAL_MASS));
        let x_acc = temp - POLE_MASS_LENGTH * theta_acc * cos_theta / TOTAL_MASS;
        // Explicit Euler: positions move with the old velocities.
        *state = [
            x + TAU * x_dot,
            x_dot + TAU * x_acc,
            theta + TAU * theta_dot,
            theta_dot + TAU * theta_acc,
        ];
        let [x, _, theta, _] = *state;
        // Written as Gymnasium's four comparisons (a NaN state does not terminate, as there).
        #[allow(clippy::manual_range_contains)]
        let terminated = x < -X_THRESHOLD
            || x > X_THRESHOLD
            || theta < -THETA_THRESHOLD
            || theta > THETA_THRESHOLD;
        (1.0, terminated)
    }

    fn observe(state: &[f64; 4], obs: &mut [f32]) {
        for (o, &value) in obs.iter_mut().zip(state) {
            *o = value as f32;
        }
    }

    fn geometry(state: &[f64; 4]) -> super::Geometry {
        super::Geometry::CartPole {
            x: state[0],
            theta: state[2],
            x_threshold: X_THRESHOLD,
            pole_length: 2.0 * HALF_LENGTH,
        }
    }
}

/// Push the cart towards where the pole is falling, with a little position and velocity feedback to keep the
/// cart near the centre. Observation: [x, x_dot, theta, theta_dot].
pub(crate) fn balance(obs: &[f32]) -> usize {
    let u = 0.1 * obs[0] + 0.5 * obs[1] + 10.0 * obs[2] + 2.0 * obs[3];
    usize::from(u > 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::{Env, EnvError};

    #[test]
    fn versions_differ_only_in_limits() {
        let v0 = CartPole::v0();
        let v1 = CartPole::v1();
        assert_eq!((v0.max_episode_steps(), v0.solve_threshold()), (200, 195.0));
        assert_eq!((v1.max_episode_steps(), v1.solve_threshold()), (500, 475.0));
    }

    /// Balancing by pushing toward the lean keeps the pole up, so v0 ends by truncation at step 200.
    #[test]
    fn time_limit_truncates_and_then_needs_reset() {
        let mut env = CartPole::v0();
        let mut obs = env.reset(Some(3));
        let mut steps = 0;
        loop {
            let action = usize::from(obs[2] + 0.5 * obs[3] > 0.0);
            let step = env.step(action).unwrap();
            steps += 1;
            obs = step.obs;
            if step.terminated || step.truncated {
                assert!(step.truncated && !step.terminated, "fell at step {steps}");
                break;
            }
        }
        assert_eq!(steps, 200);
        assert!(matches!(env.step(0), Err(EnvError::NeedsReset { .. })));
    }

    /// An unseeded reset continues the generator of the last seeded one (Gymnasium's `np_random`).
    /// Python (NumPy 2.4.6): `g = np.random.default_rng(0); g.uniform(-.05, .05, 4);
    /// g.uniform(-.05, .05, 4).astype(np.float32)`
    #[test]
    fn unseeded_reset_continues_the_generator() {
        let mut env = CartPole::v1();
        env.reset(Some(0));
        let second = env.reset(None);
        let expected: [f64; 4] = [
            0.031327024102211,
            0.04127555713057518,
            0.010663577355444431,
            0.02294965647161007,
        ];
        let second: Vec<f64> = second.into_iter().map(f64::from).collect();
        assert_eq!(second, expected);
    }

    #[test]
    fn bad_actions_and_states_are_errors() {
        let mut env = CartPole::v1();
        assert!(matches!(env.step(0), Err(EnvError::NeedsReset { .. })));
        env.reset(Some(0));
        assert!(matches!(
            env.step(2),
            Err(EnvError::ActionOutOfRange {
                action: 2,
                n_actions: 2,
                ..
            })
        ));
        assert!(env.set_state(&[0.0; 3]).is_err());
        assert!(env.set_state(&[0.0, f64::NAN, 0.0, 0.0]).is_err());
    }
}
