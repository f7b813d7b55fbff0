//! Acrobot-v1, as Gymnasium 1.x computes it.
//!
//! Two links hang from a fixed pivot; the action applies torque -1, 0 or +1 at the joint between them. The
//! goal is to swing the tip above the pivot by one link length: terminal when
//! `-cos(th1) - cos(th1 + th2) > 1`. The dynamics are the "book" equations of Sutton & Barto (the RLPy port
//! Gymnasium uses), integrated by one classical Runge-Kutta-4 step over dt = 0.2 s in float64. Afterwards
//! the angles are wrapped to [-pi, pi] and the speeds clipped to +-4 pi and +-9 pi. Reward is -1 per step
//! and 0 on the terminating one; the limit is 500 steps (docs/environments.md, "Classic control").
//!
//! Two float32 details of Gymnasium are kept: the state drawn at reset (4 draws of `uniform(-0.1, 0.1)`)
//! is cast to float32 (after a step it is float64 again), and the observation
//! `[cos th1, sin th1, cos th2, sin th2, dth1, dth2]` is float32. Gymnasium evaluates the trigonometric
//! functions of the float32 reset state in float32 (NumPy's own float32 `cos`/`sin`); here they are evaluated
//! in float64 and rounded, which agrees except in about one case in a thousand, by one float32 ulp.

use super::Simulated;
use super::classic::{Classic, ClassicTask, SingleId};
use crate::rng::NumpyRng;
use std::f64::consts::PI;

const DT: f64 = 0.2;
const LINK_LENGTH_1: f64 = 1.0;
/// Only drawn: the dynamics use the second link's centre of mass.
const LINK_LENGTH_2: f64 = 1.0;
const LINK_MASS_1: f64 = 1.0;
const LINK_MASS_2: f64 = 1.0;
/// Positions of the links' centres of mass.
const LINK_COM_1: f64 = 0.5;
const LINK_COM_2: f64 = 0.5;
/// Moment of inertia of both links.
const LINK_MOI: f64 = 1.0;
const GRAVITY: f64 = 9.8;
const MAX_VEL_1: f64 = 4.0 * PI;
const MAX_VEL_2: f64 = 9.0 * PI;
const TORQUES: [f64; 3] = [-1.0, 0.0, 1.0];

/// Acrobot-v1 with its 500-step limit.
pub type Acrobot = Simulated<Classic<AcrobotPhysics, 4>>;

/// Acrobot's dynamics, on the float64 state `[theta1, theta2, dtheta1, dtheta2]`.
#[derive(Debug, Clone)]
pub struct AcrobotPhysics;

impl SingleId for AcrobotPhysics {
    const ID: &'static str = "Acrobot-v1";
}

/// Time derivative of the state under `torque` ("book" dynamics; operation order as in Gymnasium's `_dsdt`).
#[inline]
fn derivatives(state: [f64; 4], torque: f64) -> [f64; 4] {
    let (m1, m2, l1, lc1, lc2) = (
        LINK_MASS_1,
        LINK_MASS_2,
        LINK_LENGTH_1,
        LINK_COM_1,
        LINK_COM_2,
    );
    let (i1, i2, g) = (LINK_MOI, LINK_MOI, GRAVITY);
    let [theta1, theta2, dtheta1, dtheta2] = state;
    let cos_theta2 = theta2.cos();
    let sin_theta2 = theta2.sin();
    let d1 = m1 * (lc1 * lc1) + m2 * (l1 * l1 + lc2 * lc2 + 2.0 * l1 * lc2 * cos_theta2) + i1 + i2;
    let d2 = m2 * (lc2 * lc2 + l1 * lc2 * cos_theta2) + i2;
    let phi2 = m2 * lc2 * g * (theta1 + theta2 - PI / 2.0).cos();
    let phi1 = -m2 * l1 * lc2 * (dtheta2 * dtheta2) * sin_theta2
        - 2.0 * m2 * l1 * lc2 * dtheta2 * dtheta1 * sin_theta2
        + (m1 * lc1 + m2 * l1) * g * (theta1 - PI / 2.0).cos()
        + phi2;
    let ddtheta2 =
        (torque + d2 / d1 * phi1 - m2 * l1 * lc2 * (dtheta1 * dtheta1) * sin_theta2 - phi2)
            / (m2 * (lc2 * lc2) + i2 - (d2 * d2) / d1);
    let ddtheta1 = -(d2 * ddtheta2 + phi1) / d1;
    [dtheta1, dtheta2, ddtheta1, ddtheta2]
}

/// `state + scale * slope`, element by element.
#[inline]
fn offset(state: [f64; 4], scale: f64, slope: [f64; 4]) -> [f64; 4] {
    std::array::from_fn(|i| state[i] + scale * slope[i])
}

/// One RK4 step over `DT` (Gymnasium's `rk4` with `t = [0, dt]`).
#[inline]
fn rk4_step(state: [f64; 4], torque: f64) -> [f64; 4] {
    let half_dt = DT / 2.0;
    let k1 = derivatives(state, torque);
    let k2 = derivatives(offset(state, half_dt, k1), torque);
    let k3 = derivatives(offset(state, half_dt, k2), torque);
    let k4 = derivatives(offset(state, DT, k3), torque);
    let sixth = DT / 6.0;
    std::array::from_fn(|i| state[i] + sixth * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// Gymnasium's `wrap`: shifts by whole periods until `low <= x <= high`.
#[inline]
fn wrap(mut x: f64, low: f64, high: f64) -> f64 {
    let period = high - low;
    while x > high {
        x -= period;
    }
    while x < low {
        x += period;
    }
    x
}

/// Gymnasium's `bound`: `min(max(x, low), high)`.
#[inline]
fn bound(x: f64, low: f64, high: f64) -> f64 {
    x.max(low).min(high)
}

impl ClassicTask<4> for AcrobotPhysics {
    fn reset(state: &mut [f64; 4], rng: &mut NumpyRng) {
        for value in state {
            // Gymnasium stores the drawn state as float32.
            *value = f64::from(rng.uniform(-0.1, 0.1) as f32);
        }
    }

    fn step(state: &mut [f64; 4], action: usize) -> (f64, bool) {
        let next = rk4_step(*state, TORQUES[action]);
        *state = [
            wrap(next[0], -PI, PI),
            wrap(next[1], -PI, PI),
            bound(next[2], -MAX_VEL_1, MAX_VEL_1),
            bound(next[3], -MAX_VEL_2, MAX_VEL_2),
        ];
        let [theta1, theta2, _, _] = *state;
        let terminated = -theta1.cos() - (theta2 + theta1).cos() > 1.0;
        (if terminated { 0.0 } else { -1.0 }, terminated)
    }

    fn observe(state: &[f64; 4], obs: &mut [f32]) {
        let [theta1, theta2, dtheta1, dtheta2] = *state;
        obs.copy_from_slice(&[
            theta1.cos() as f32,
            theta1.sin() as f32,
            theta2.cos() as f32,
            theta2.sin() as f32,
            dtheta1 as f32,
            dtheta2 as f32,
        ]);
    }

    fn geometry(state: &[f64; 4]) -> super::Geometry {
        super::Geometry::Acrobot {
            theta1: state[0],
            theta2: state[1],
            link_lengths: [LINK_LENGTH_1, LINK_LENGTH_2],
        }
    }
}

/// Torque on the elbow against the first link's angular velocity: the second link then swings the other way,
/// which pumps energy into the first link's swing until the tip clears the bar (about 75 steps).
/// Observation: [cos th1, sin th1, cos th2, sin th2, dth1, dth2]; actions: torque -1, 0, +1.
pub(crate) fn pump(obs: &[f32]) -> usize {
    if obs[4] > 0.0 { 0 } else { 2 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::{Env, EnvError};

    #[test]
    fn wrap_and_bound_follow_gymnasium() {
        assert_eq!(
            wrap(3.0 * PI + 0.5, -PI, PI),
            3.0 * PI + 0.5 - 2.0 * PI - 2.0 * PI
        );
        assert_eq!(wrap(-PI - 0.25, -PI, PI), -PI - 0.25 + 2.0 * PI);
        assert_eq!(wrap(1.0, -PI, PI), 1.0);
        assert_eq!(bound(20.0, -MAX_VEL_1, MAX_VEL_1), MAX_VEL_1);
        assert_eq!(bound(-30.0, -MAX_VEL_2, MAX_VEL_2), -MAX_VEL_2);
    }

    /// Energy check of the dynamics: without torque and with gravity alone the RK4 step from rest at the
    /// bottom stays at rest (the bottom is an equilibrium), and a displaced pendulum swings back.
    #[test]
    fn hanging_rest_is_an_equilibrium() {
        let rest = rk4_step([0.0; 4], 0.0);
        assert!(rest.iter().all(|v| v.abs() < 1e-12), "{rest:?}");
        let displaced = rk4_step([0.3, 0.0, 0.0, 0.0], 0.0);
        assert!(
            displaced[2] < 0.0,
            "gravity must pull link 1 back: {displaced:?}"
        );
    }

    #[test]
    fn reset_state_is_float32() {
        let mut env = Acrobot::new();
        env.reset(Some(5));
        for value in env.state() {
            assert_eq!(value, f64::from(value as f32));
            assert!(value.abs() <= 0.1);
        }
        assert!(matches!(
            env.step(3),
            Err(EnvError::ActionOutOfRange { .. })
        ));
    }
}
