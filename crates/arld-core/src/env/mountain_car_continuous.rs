//! MountainCarContinuous-v0, as Gymnasium 1.x computes it.
//!
//! The car of MountainCar-v0 with a continuous force in [-1, 1] (power 0.0015); the flag is at 0.45, the reward
//! is 100 on reaching it minus `0.1 a^2` per step (the action as given, before clipping), the limit 999 steps and
//! the threshold 90. The initial position is `uniform(-0.6, -0.4)`, the velocity 0.
//!
//! Gymnasium computes one step in Python on NumPy scalars, and the types change along the episode: the state is a
//! float64 array after reset but a float32 array after every step, and a float32 action's products with Python
//! numbers stay float32 (NumPy 2's rule: a Python float is cast to the other operand's type). So each value here
//! carries the type NumPy gives it (`Scalar`), and each operation rounds as NumPy's would.

use super::continuous::{ContinuousDynamics, state_of_len};
// The valley, the speed limit and the goal velocity of MountainCar-v0.
use super::mountain_car::{GOAL_VELOCITY, MAX_POSITION, MAX_SPEED, MIN_POSITION};
use crate::rng::NumpyRng;

/// The action box (one force).
const MIN_ACTION: f64 = -1.0;
const MAX_ACTION: f64 = 1.0;
/// The flag (MountainCar-v0's is at 0.5).
const GOAL_POSITION: f64 = 0.45;
/// The force's scale.
const POWER: f64 = 0.0015;

/// A scripted controller for MountainCarContinuous-v0 (the scripted expert of the task): push with `throttle`
/// (in (0, 1]) in the direction the car moves, forwards when it stands still, so that each swing gains energy.
/// The fuel cost is `0.1 throttle^2` a step, so less throttle may pay despite more swings: on seeds 0-9 of
/// Gymnasium's task, throttle 0.6 returns 95.6 and full throttle 89.4, just below the threshold of 90 (a weak
/// expert that still always finishes). `tests/experts.rs` checks both on other seeds.
pub fn momentum(obs: &[f32], throttle: f32) -> [f32; 1] {
    [if obs[1] < 0.0 { -throttle } else { throttle }]
}

/// A number as NumPy types it: a float32 scalar, a float64 scalar, or a Python float (float64, but "weak": with a
/// float32 operand it is cast to float32 first).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    F32(f32),
    F64(f64),
    Py(f64),
}

use Scalar::{F32, F64, Py};

impl Scalar {
    fn value(self) -> f64 {
        match self {
            F32(x) => f64::from(x),
            F64(x) | Py(x) => x,
        }
    }

    /// `self OP other` with NumPy's result type: float32 only when one side is float32 and the other float32 or
    /// a Python float; float64 when a side is a float64 scalar; a Python float when both are.
    fn op(self, other: Scalar, f32_op: fn(f32, f32) -> f32, f64_op: fn(f64, f64) -> f64) -> Scalar {
        match (self, other) {
            (F32(a), F32(b)) => F32(f32_op(a, b)),
            (F32(a), Py(b)) => F32(f32_op(a, b as f32)),
            (Py(a), F32(b)) => F32(f32_op(a as f32, b)),
            (Py(a), Py(b)) => Py(f64_op(a, b)),
            (a, b) => F64(f64_op(a.value(), b.value())),
        }
    }

    fn add(self, other: Scalar) -> Scalar {
        self.op(other, |a, b| a + b, |a, b| a + b)
    }

    fn sub(self, other: Scalar) -> Scalar {
        self.op(other, |a, b| a - b, |a, b| a - b)
    }

    fn mul(self, other: Scalar) -> Scalar {
        self.op(other, |a, b| a * b, |a, b| a * b)
    }

    /// `self > other`, `self < other`, ... as NumPy compares: in float32 when a float32 meets a Python float.
    fn cmp(self, other: Scalar) -> Option<std::cmp::Ordering> {
        match (self, other) {
            (F32(a), Py(b)) => a.partial_cmp(&(b as f32)),
            (Py(a), F32(b)) => (a as f32).partial_cmp(&b),
            (a, b) => a.value().partial_cmp(&b.value()),
        }
    }

    fn gt(self, other: f64) -> bool {
        self.cmp(Py(other)) == Some(std::cmp::Ordering::Greater)
    }

    fn lt(self, other: f64) -> bool {
        self.cmp(Py(other)) == Some(std::cmp::Ordering::Less)
    }

    fn ge(self, other: f64) -> bool {
        matches!(
            self.cmp(Py(other)),
            Some(std::cmp::Ordering::Greater | std::cmp::Ordering::Equal)
        )
    }

    fn eq(self, other: f64) -> bool {
        self.cmp(Py(other)) == Some(std::cmp::Ordering::Equal)
    }
}

/// The car's state `[position, velocity]`, float64 after reset and float32 after a step (as Gymnasium keeps it),
/// and the force of the last step, clipped to the box (drawing only).
#[derive(Debug, Clone)]
pub struct MountainCarContinuous {
    position: Scalar,
    velocity: Scalar,
    force: f64,
}

impl Default for MountainCarContinuous {
    fn default() -> Self {
        MountainCarContinuous {
            position: F64(0.0),
            velocity: F64(0.0),
            force: 0.0,
        }
    }
}

impl ContinuousDynamics for MountainCarContinuous {
    fn reset(&mut self, rng: &mut NumpyRng) {
        self.position = F64(rng.uniform(-0.6, -0.4));
        self.velocity = F64(0.0);
        self.force = 0.0;
    }

    fn step(&mut self, action: &[f32], _rng: &mut NumpyRng) -> (f64, bool) {
        let a = F32(action[0]);
        // Python's max and min keep the action's own type unless a bound wins.
        let force = if Py(MIN_ACTION).cmp(a) == Some(std::cmp::Ordering::Greater) {
            Py(MIN_ACTION)
        } else {
            a
        };
        let force = if Py(MAX_ACTION).cmp(force) == Some(std::cmp::Ordering::Less) {
            Py(MAX_ACTION)
        } else {
            force
        };
        // math.cos of 3 * position (float32 once the state is float32), then times 0.0025: a Python float.
        let cos = Py(3.0).mul(self.position).value().cos();
        let gravity = Py(0.0025 * cos);
        let mut velocity = self.velocity.add(force.mul(Py(POWER)).sub(gravity));
        if velocity.gt(MAX_SPEED) {
            velocity = Py(MAX_SPEED);
        }
        if velocity.lt(-MAX_SPEED) {
            velocity = Py(-MAX_SPEED);
        }
        let mut position = self.position.add(velocity);
        if position.gt(MAX_POSITION) {
            position = Py(MAX_POSITION);
        }
        if position.lt(MIN_POSITION) {
            position = Py(MIN_POSITION);
        }
        if position.eq(MIN_POSITION) && velocity.lt(0.0) {
            velocity = Py(0.0);
        }
        let terminated = position.ge(GOAL_POSITION) && velocity.ge(GOAL_VELOCITY);
        let base = if terminated { 100.0 } else { 0.0 };
        let a = f64::from(action[0]);
        let reward = base - a.powi(2) * 0.1;
        // np.array([position, velocity], dtype=np.float32)
        self.position = F32(position.value() as f32);
        self.velocity = F32(velocity.value() as f32);
        self.force = force.value();
        (reward, terminated)
    }

    fn observe(&self, obs: &mut [f32]) {
        obs.copy_from_slice(&[self.position.value() as f32, self.velocity.value() as f32]);
    }

    fn set_state(&mut self, state: &[f64]) -> Result<(), String> {
        let [position, velocity] = state_of_len::<2>(state)?;
        self.position = F64(position);
        self.velocity = F64(velocity);
        Ok(())
    }

    fn geometry(&self) -> Option<super::Geometry> {
        Some(super::mountain_car::geometry(
            self.position.value(),
            GOAL_POSITION,
            Some(self.force),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numpy_types_a_float32_with_a_python_float_as_float32() {
        // 0.1 is not exact in float32: the float32 sum differs from the float64 one.
        let sum = F32(1.0).add(Py(0.1));
        assert_eq!(sum, F32(1.0_f32 + 0.1_f32));
        assert_eq!(F64(1.0).add(F32(0.1)), F64(1.0 + f64::from(0.1_f32)));
        assert_eq!(Py(1.0).add(Py(0.1)), Py(1.1));
    }

    #[test]
    fn the_left_wall_stops_the_car_and_the_flag_ends_the_episode() {
        let mut car = MountainCarContinuous::default();
        car.set_state(&[-1.19, -0.05]).unwrap();
        let (reward, terminated) = car.step(&[-1.0], &mut NumpyRng::new(0));
        assert_eq!(car.position.value(), f64::from(MIN_POSITION as f32));
        assert_eq!(car.velocity.value(), 0.0);
        assert!(!terminated);
        assert!((reward + 0.1).abs() < 1e-12);
        car.set_state(&[0.44, 0.07]).unwrap();
        let (reward, terminated) = car.step(&[0.5], &mut NumpyRng::new(0));
        assert!(terminated);
        assert!((reward - (100.0 - 0.025)).abs() < 1e-12);
    }
}
