//! Gymnasium's LunarLander (v2 and v3, discrete actions, and `LunarLanderContinuous-v3`; no wind), reproduced
//! step for step.
//!
//! Gymnasium simulates the lander with pybox2d, a Box2D 2.3 core in float32. This module drives the
//! same engine (Box2D 2.3.1, bundled by the `wrapped2d` crate) through the same sequence of calls, so
//! that a seed and an action sequence give Gymnasium's observations and rewards: bit for bit in flight,
//! and within a few float32 roundings once the legs touch the ground (the Box2D builds differ in the
//! last bit of some contact computations; the conformance traces stay within about 1e-5). The parts:
//!
//! - `Scene`: one Box2D world with the terrain, the lander body and its two legs, built exactly as
//!   Gymnasium's `reset` builds it (body and fixture creation order, float32 conversions of the float64
//!   Python values, the joint reference angle pybox2d computes implicitly).
//! - `ContactDetector`: the contact listener; a lander contact ends the game, leg contacts are tracked
//!   by begin/end events exactly as Gymnasium's `ContactDetector` does (not by polling after the step).
//! - [`LunarLander`]: the [`Env`] implementation: NumPy-exact random draws (terrain, initial push,
//!   engine dispersion), engine impulses, observation normalisation, reward shaping, the time limit.
//! - [`LunarLanderContinuous`]: the same world with continuous engines, for [`super::continuous::ContinuousEnv`];
//!   `Engines` reads either kind of action as Gymnasium does.
//! - [`heuristic_action`] and [`heuristic_throttle`]: Gymnasium's built-in heuristic controller (discrete and
//!   continuous), used as the scripted expert.
//!
//! Every float64 quantity of the Python code (observations, shaping, impulse arithmetic) is computed in
//! `f64` in the same operation order, and narrowed to `f32` where pybox2d hands it to Box2D.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use wrapped2d::b2;
use wrapped2d::dynamics::world::callbacks::ContactAccess;
use wrapped2d::user_data::{UserData, UserDataTypes};

use super::{Dynamics, EnvError, EnvRng, Simulated};
use crate::rng::NumpyRng;

// Constants of Gymnasium's lunar_lander.py (pixels unless stated; SCALE converts pixels to metres).
const FPS: f64 = 50.0;
const SCALE: f64 = 30.0;
/// Gymnasium's default gravity (m/s², vertical).
pub(crate) const DEFAULT_GRAVITY: f32 = -10.0;
const MAIN_ENGINE_POWER: f64 = 13.0;
const SIDE_ENGINE_POWER: f64 = 0.6;
/// Bound of the random force applied to the lander at the start (newtons).
const INITIAL_RANDOM: f64 = 1000.0;
/// Lander hull, counter-clockwise from the top left.
const LANDER_POLY: [(f64, f64); 6] = [
    (-14.0, 17.0),
    (-17.0, 0.0),
    (-17.0, -10.0),
    (17.0, -10.0),
    (17.0, 0.0),
    (14.0, 17.0),
];
const LEG_AWAY: f64 = 20.0;
const LEG_DOWN: f64 = 18.0;
const LEG_W: f64 = 2.0;
const LEG_H: f64 = 8.0;
const LEG_SPRING_TORQUE: f64 = 40.0;
const SIDE_ENGINE_HEIGHT: f64 = 14.0;
const SIDE_ENGINE_AWAY: f64 = 12.0;
/// How far below the lander's origin the main engine fires (Gymnasium's literal `4`).
const MAIN_ENGINE_Y_LOCATION: f64 = 4.0;
const VIEWPORT_W: f64 = 600.0;
const VIEWPORT_H: f64 = 400.0;
/// Number of terrain segments.
const CHUNKS: usize = 11;

/// Observation length. The four actions are 0 do nothing, 1 fire left orientation engine, 2 fire main engine,
/// 3 fire right engine; the action count and time limit are the registered spec's ([`super::SPECS`]).
const OBS_DIM: usize = 8;

/// What a Box2D body is, stored as its user data so the contact listener can tell bodies apart.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
enum BodyRole {
    #[default]
    Moon,
    Lander,
    /// Leg 0 is Gymnasium's `legs[0]` (created with `i = -1`, to the right of the hull), leg 1 `legs[1]`.
    Leg(usize),
}

/// User data types of the LunarLander world: only bodies carry data.
struct LanderUserData;

impl UserDataTypes for LanderUserData {
    type BodyData = BodyRole;
    type JointData = ();
    type FixtureData = ();
}

type World = b2::World<LanderUserData>;

/// Contact state written by the listener during `World::step` and read by the environment afterwards.
#[derive(Debug, Default)]
struct ContactFlags {
    game_over: AtomicBool,
    leg_contact: [AtomicBool; 2],
}

/// Gymnasium's `ContactDetector`: any begin-contact touching the lander body is game over; a leg's
/// ground contact is set on begin-contact and cleared on end-contact.
struct ContactDetector {
    flags: Arc<ContactFlags>,
}

impl ContactDetector {
    fn roles(contact: &ContactAccess<LanderUserData>) -> [BodyRole; 2] {
        [*contact.body_a.user_data(), *contact.body_b.user_data()]
    }
}

impl b2::ContactListener<LanderUserData> for ContactDetector {
    fn begin_contact(&mut self, contact: ContactAccess<LanderUserData>) {
        let roles = Self::roles(&contact);
        if roles.contains(&BodyRole::Lander) {
            self.flags.game_over.store(true, Ordering::Relaxed);
        }
        for (leg, flag) in self.flags.leg_contact.iter().enumerate() {
            if roles.contains(&BodyRole::Leg(leg)) {
                flag.store(true, Ordering::Relaxed);
            }
        }
    }

    fn end_contact(&mut self, contact: ContactAccess<LanderUserData>) {
        let roles = Self::roles(&contact);
        for (leg, flag) in self.flags.leg_contact.iter().enumerate() {
            if roles.contains(&BodyRole::Leg(leg)) {
                flag.store(false, Ordering::Relaxed);
            }
        }
    }
}

/// A point in metres, narrowed to Box2D's float32 as pybox2d narrows Python floats.
fn vec2(x: f64, y: f64) -> b2::Vec2 {
    b2::Vec2 {
        x: x as f32,
        y: y as f32,
    }
}

/// One episode's Box2D world: moon (terrain), lander and legs.
struct Scene {
    world: World,
    lander: b2::BodyHandle,
    legs: [b2::BodyHandle; 2],
    flags: Arc<ContactFlags>,
    /// The moon's surface points `(x, y)` in metres, left to right (drawing only).
    terrain: Vec<[f64; 2]>,
    /// Height of the helipad (metres, float64 as in Python): the observation's vertical origin.
    helipad_y: f64,
}

impl Scene {
    /// Builds the world as Gymnasium's `reset` does, drawing the terrain heights and the initial push
    /// from `rng` in Gymnasium's order (12 heights, then the push's x and y).
    fn build(rng: &mut NumpyRng, gravity: f32) -> Self {
        let w = VIEWPORT_W / SCALE;
        let h = VIEWPORT_H / SCALE;

        let mut world = World::new(&b2::Vec2 { x: 0.0, y: gravity });
        let flags = Arc::new(ContactFlags::default());
        world.set_contact_listener(Box::new(ContactDetector {
            flags: Arc::clone(&flags),
        }));

        // Terrain: random heights, flattened under the helipad, then smoothed with a 3-point mean whose
        // left neighbour of the first point is the last height (Python's index -1).
        let mut height: Vec<f64> = (0..=CHUNKS).map(|_| rng.uniform(0.0, h / 2.0)).collect();
        let chunk_x: Vec<f64> = (0..CHUNKS)
            .map(|i| w / (CHUNKS - 1) as f64 * i as f64)
            .collect();
        let helipad_y = h / 4.0;
        height[CHUNKS / 2 - 2..=CHUNKS / 2 + 2].fill(helipad_y);
        let smooth_y: Vec<f64> = (0..CHUNKS)
            .map(|i| {
                let left = if i == 0 {
                    height[CHUNKS]
                } else {
                    height[i - 1]
                };
                0.33 * (left + height[i] + height[i + 1])
            })
            .collect();

        let moon = world.create_body_with(&b2::BodyDef::new(), BodyRole::Moon);
        {
            let mut moon_body = world.body_mut(moon);
            // pybox2d's `shapes=` keyword: a fixture with the default definition (friction 0.2).
            let ground = b2::EdgeShape::new_with(&vec2(0.0, 0.0), &vec2(w, 0.0));
            moon_body.create_fixture(&ground, &mut b2::FixtureDef::new());
            for i in 0..CHUNKS - 1 {
                let edge = b2::EdgeShape::new_with(
                    &vec2(chunk_x[i], smooth_y[i]),
                    &vec2(chunk_x[i + 1], smooth_y[i + 1]),
                );
                let mut def = b2::FixtureDef {
                    density: 0.0,
                    friction: 0.1,
                    ..b2::FixtureDef::new()
                };
                moon_body.create_fixture(&edge, &mut def);
            }
        }

        let initial_x = VIEWPORT_W / SCALE / 2.0;
        let initial_y = VIEWPORT_H / SCALE;
        let lander_def = b2::BodyDef {
            body_type: b2::BodyType::Dynamic,
            position: vec2(initial_x, initial_y),
            angle: 0.0,
            ..b2::BodyDef::new()
        };
        let lander = world.create_body_with(&lander_def, BodyRole::Lander);
        {
            let hull: Vec<b2::Vec2> = LANDER_POLY
                .iter()
                .map(|&(x, y)| vec2(x / SCALE, y / SCALE))
                .collect();
            let shape = b2::PolygonShape::new_with(&hull);
            let mut def = b2::FixtureDef {
                density: 5.0,
                friction: 0.1,
                restitution: 0.0,
                filter: b2::Filter {
                    category_bits: 0x0010,
                    mask_bits: 0x001, // collide only with the ground
                    group_index: 0,
                },
                ..b2::FixtureDef::new()
            };
            let mut body = world.body_mut(lander);
            body.create_fixture(&shape, &mut def);
            let push_x = rng.uniform(-INITIAL_RANDOM, INITIAL_RANDOM);
            let push_y = rng.uniform(-INITIAL_RANDOM, INITIAL_RANDOM);
            body.apply_force_to_center(&vec2(push_x, push_y), true);
        }

        let mut legs = Vec::with_capacity(2);
        for (leg_index, side) in [-1.0f64, 1.0].into_iter().enumerate() {
            let leg_def = b2::BodyDef {
                body_type: b2::BodyType::Dynamic,
                position: vec2(initial_x - side * LEG_AWAY / SCALE, initial_y),
                angle: (side * 0.05) as f32,
                ..b2::BodyDef::new()
            };
            let leg = world.create_body_with(&leg_def, BodyRole::Leg(leg_index));
            legs.push(leg);
            {
                let shape =
                    b2::PolygonShape::new_box((LEG_W / SCALE) as f32, (LEG_H / SCALE) as f32);
                let mut def = b2::FixtureDef {
                    density: 1.0,
                    restitution: 0.0,
                    filter: b2::Filter {
                        category_bits: 0x0020,
                        mask_bits: 0x001,
                        group_index: 0,
                    },
                    ..b2::FixtureDef::new()
                };
                world.body_mut(leg).create_fixture(&shape, &mut def);
            }
            // pybox2d's revoluteJointDef(bodyA=..., bodyB=...) sets the reference angle to
            // bodyB.angle - bodyA.angle; the limits below are relative to it.
            let reference_angle =
                (world.body(leg).angle() as f64 - world.body(lander).angle() as f64) as f32;
            let (lower, upper) = if side < 0.0 {
                (0.9 - 0.5, 0.9)
            } else {
                (-0.9, -0.9 + 0.5)
            };
            let mut joint = b2::RevoluteJointDef::new(lander, leg);
            joint.local_anchor_a = vec2(0.0, 0.0);
            joint.local_anchor_b = vec2(side * LEG_AWAY / SCALE, LEG_DOWN / SCALE);
            joint.reference_angle = reference_angle;
            joint.enable_motor = true;
            joint.enable_limit = true;
            joint.max_motor_torque = LEG_SPRING_TORQUE as f32;
            joint.motor_speed = (0.3 * side) as f32;
            joint.lower_angle = lower as f32;
            joint.upper_angle = upper as f32;
            world.create_joint(&joint);
        }

        let terrain = chunk_x
            .iter()
            .zip(&smooth_y)
            .map(|(&x, &y)| [x, y])
            .collect();
        Scene {
            world,
            lander,
            legs: [legs[0], legs[1]],
            flags,
            terrain,
            helipad_y,
        }
    }

    /// An engine's push: the impulse `(-offset * power) * throttle` at the world point `at` (Gymnasium's
    /// `ApplyLinearImpulse` for the particle the engine throws out at `offset` from the lander, multiplied in
    /// Python's order: the engine's power first, then the throttle).
    fn push(&mut self, (ox, oy): (f64, f64), at: (f64, f64), power: f64, throttle: f64) {
        let impulse = vec2(-ox * power * throttle, -oy * power * throttle);
        self.world
            .body_mut(self.lander)
            .apply_linear_impulse(&impulse, &vec2(at.0, at.1), true);
    }

    /// Fires the `engines` with the given dispersion draws and advances the world by one frame.
    fn advance(&mut self, engines: Engines, dispersion: [f64; 2]) {
        let (angle, position) = {
            let lander = self.world.body(self.lander);
            (lander.angle() as f64, *lander.position())
        };
        let (pos_x, pos_y) = (position.x as f64, position.y as f64);
        let tip = (angle.sin(), angle.cos());
        let side = (-tip.1, tip.0);

        if engines.main > 0.0 {
            let ox = tip.0 * (MAIN_ENGINE_Y_LOCATION / SCALE + 2.0 * dispersion[0])
                + side.0 * dispersion[1];
            let oy = -tip.1 * (MAIN_ENGINE_Y_LOCATION / SCALE + 2.0 * dispersion[0])
                - side.1 * dispersion[1];
            self.push(
                (ox, oy),
                (pos_x + ox, pos_y + oy),
                MAIN_ENGINE_POWER,
                engines.main,
            );
        }

        if engines.side > 0.0 {
            let direction = engines.direction;
            let lever = 3.0 * dispersion[1] + direction * SIDE_ENGINE_AWAY / SCALE;
            let ox = tip.0 * dispersion[0] + side.0 * lever;
            let oy = -tip.1 * dispersion[0] - side.1 * lever;
            // Gymnasium offsets the side engines by 17 pixels horizontally, not SIDE_ENGINE_HEIGHT.
            let at = (
                pos_x + ox - tip.0 * 17.0 / SCALE,
                pos_y + oy + tip.1 * SIDE_ENGINE_HEIGHT / SCALE,
            );
            self.push((ox, oy), at, SIDE_ENGINE_POWER, engines.side);
        }

        self.world.step((1.0 / FPS) as f32, 6 * 30, 2 * 30);
    }

    /// Gymnasium's float64 state list (before its cast to the float32 observation).
    fn state(&self) -> [f64; OBS_DIM] {
        let lander = self.world.body(self.lander);
        let pos = *lander.position();
        let vel = *lander.linear_velocity();
        let contact = |leg: usize| {
            if self.flags.leg_contact[leg].load(Ordering::Relaxed) {
                1.0
            } else {
                0.0
            }
        };
        [
            (pos.x as f64 - VIEWPORT_W / SCALE / 2.0) / (VIEWPORT_W / SCALE / 2.0),
            (pos.y as f64 - (self.helipad_y + LEG_DOWN / SCALE)) / (VIEWPORT_H / SCALE / 2.0),
            vel.x as f64 * (VIEWPORT_W / SCALE / 2.0) / FPS,
            vel.y as f64 * (VIEWPORT_H / SCALE / 2.0) / FPS,
            lander.angle() as f64,
            20.0 * lander.angular_velocity() as f64 / FPS,
            contact(0),
            contact(1),
        ]
    }

    /// The drawable state: hull and legs in world coordinates, terrain, helipad, contacts, and the engines of the
    /// last step (`throttle` for continuous actions).
    fn geometry(&self, engines: Engines, throttle: bool) -> super::Geometry {
        let place = |body: b2::BodyHandle, local: &[(f64, f64)]| -> Vec<[f64; 2]> {
            let b = self.world.body(body);
            let (p, a) = (*b.position(), b.angle() as f64);
            let (sin, cos) = a.sin_cos();
            local
                .iter()
                .map(|&(x, y)| {
                    [
                        p.x as f64 + cos * x - sin * y,
                        p.y as f64 + sin * x + cos * y,
                    ]
                })
                .collect()
        };
        let hull: Vec<(f64, f64)> = LANDER_POLY
            .iter()
            .map(|&(x, y)| (x / SCALE, y / SCALE))
            .collect();
        let (w, h) = (LEG_W / SCALE, LEG_H / SCALE);
        let leg = [(-w, -h), (w, -h), (w, h), (-w, h)];
        super::Geometry::LunarLander {
            width: VIEWPORT_W / SCALE,
            height: VIEWPORT_H / SCALE,
            terrain: self.terrain.clone(),
            helipad_x: [
                self.terrain[CHUNKS / 2 - 1][0],
                self.terrain[CHUNKS / 2 + 1][0],
            ],
            helipad_y: self.helipad_y,
            hull: place(self.lander, &hull),
            legs: [place(self.legs[0], &leg), place(self.legs[1], &leg)],
            leg_contact: [0, 1].map(|i| self.flags.leg_contact[i].load(Ordering::Relaxed)),
            engine: engines.drawn(),
            throttle: throttle.then_some([engines.main, engines.side * engines.direction]),
        }
    }

    fn game_over(&self) -> bool {
        self.flags.game_over.load(Ordering::Relaxed)
    }

    fn lander_awake(&self) -> bool {
        self.world.body(self.lander).is_awake()
    }
}

/// The shaping potential of a state: closer to the pad, slower, more upright and with legs down is
/// better (Gymnasium's `shaping`; the reward is its change plus fuel costs and terminal bonuses).
fn shaping(s: &[f64; OBS_DIM]) -> f64 {
    -100.0 * (s[0] * s[0] + s[1] * s[1]).sqrt()
        - 100.0 * (s[2] * s[2] + s[3] * s[3]).sqrt()
        - 100.0 * s[4].abs()
        + 10.0 * s[6]
        + 10.0 * s[7]
}

/// The engines one step fires: the main engine's and the side engines' throttles (Gymnasium's `m_power` and
/// `s_power`, 0 when an engine is off) and the side engines' direction (-1 left, +1 right).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Engines {
    main: f64,
    side: f64,
    direction: f64,
}

impl Engines {
    /// A discrete action (0 no-op, 1 left, 2 main, 3 right): full throttle on the engine it names.
    fn discrete(action: usize) -> Self {
        let side = action == 1 || action == 3;
        Engines {
            main: if action == 2 { 1.0 } else { 0.0 },
            side: if side { 1.0 } else { 0.0 },
            direction: if side { action as f64 - 2.0 } else { 0.0 },
        }
    }

    /// A continuous action `[main, lateral]` as Gymnasium reads it: clipped to [-1, 1] in float32 and widened
    /// to float64; the main engine fires above 0 at 50-100% throttle, a side engine when the lateral value's
    /// magnitude exceeds 0.5, at that magnitude (at most 1), on the side of its sign.
    pub fn continuous(action: [f32; 2]) -> Self {
        let [main, lateral] = action.map(|a| f64::from(a.clamp(-1.0, 1.0)));
        let mut engines = Engines {
            main: 0.0,
            side: 0.0,
            direction: 0.0,
        };
        if main > 0.0 {
            engines.main = (main.clamp(0.0, 1.0) + 1.0) * 0.5;
        }
        if lateral.abs() > 0.5 {
            engines.direction = lateral.signum();
            engines.side = lateral.abs().clamp(0.5, 1.0);
        }
        engines
    }

    /// The discrete action whose engine the drawing shows (the main engine first).
    fn drawn(self) -> usize {
        if self.main > 0.0 {
            2
        } else if self.side > 0.0 {
            (2.0 + self.direction) as usize
        } else {
            0
        }
    }
}

/// Gymnasium's LunarLander with discrete actions and no wind (`LunarLander-v2` / `LunarLander-v3`).
pub type LunarLander = Simulated<LunarLanderPhysics>;

/// The lander's world and what the reward and the drawing need from the previous frame.
pub struct LunarLanderPhysics {
    /// Vertical gravity of the world (Gymnasium's `gravity` keyword; -10 in the registered task).
    gravity: f32,
    scene: Option<Scene>,
    prev_shaping: f64,
    /// The engines the last step fired (drawing only).
    last_engines: Engines,
    /// The observation the last frame computed.
    obs: [f32; OBS_DIM],
}

// SAFETY: `wrapped2d::World` holds raw pointers to a C++ `b2World` (and its bodies) that this struct
// owns exclusively: no pointer or handle to it ever leaves the struct, and the contact listener only
// shares atomics with it. Box2D keeps no thread-affine state, so the whole world may move to another
// thread together with its owner. (Box2D 2.3 bumps a few global profiling counters in its distance
// and time-of-impact routines; they are statistics that the simulation never reads.)
unsafe impl Send for LunarLanderPhysics {}

impl LunarLander {
    /// Creates the environment under the Gymnasium id it answers to (`LunarLander-v2` or `-v3`: the
    /// same task with the same limits). Call [`Env::reset`] before stepping.
    pub fn new(id: &'static str) -> Self {
        Self::with_gravity(id, DEFAULT_GRAVITY).expect("the default gravity is valid")
    }

    /// The same task under another gravity, as `gym.make("LunarLander-v3", gravity=g)`; Gymnasium accepts
    /// -12 < g < 0. Used to show that the statistical tests notice wrong physics.
    pub fn with_gravity(id: &'static str, gravity: f32) -> Result<Self, EnvError> {
        if !(gravity > -12.0 && gravity < 0.0) {
            return Err(EnvError::InvalidParameter {
                name: "gravity",
                message: format!(
                    "must lie strictly between -12 and 0 (Gymnasium's range), got {gravity}"
                ),
            });
        }
        let physics = LunarLanderPhysics {
            gravity,
            scene: None,
            prev_shaping: 0.0,
            last_engines: Engines::discrete(0),
            obs: [0.0; OBS_DIM],
        };
        Ok(Simulated::with_physics(id, physics))
    }
}

impl LunarLanderPhysics {
    /// One frame of Gymnasium's `step` without the time limit: engines, physics, observation, reward.
    fn frame(
        &mut self,
        engines: Engines,
        first: bool,
        rng: &mut NumpyRng,
    ) -> ([f32; OBS_DIM], f64, bool) {
        let scene = self
            .scene
            .as_mut()
            .expect("frame() runs only after reset() built the world");
        // Two dispersion draws on every frame, whether or not an engine fires.
        let dispersion = [
            rng.uniform(-1.0, 1.0) / SCALE,
            rng.uniform(-1.0, 1.0) / SCALE,
        ];
        scene.advance(engines, dispersion);
        let state = scene.state();

        let shaping_now = shaping(&state);
        let mut reward = if first {
            0.0
        } else {
            shaping_now - self.prev_shaping
        };
        self.prev_shaping = shaping_now;
        reward -= engines.main * 0.30;
        reward -= engines.side * 0.03;

        let mut terminated = false;
        if scene.game_over() || state[0].abs() >= 1.0 {
            terminated = true;
            reward = -100.0;
        }
        if !scene.lander_awake() {
            terminated = true;
            reward = 100.0;
        }
        (state.map(|v| v as f32), reward, terminated)
    }
}

impl Dynamics for LunarLanderPhysics {
    fn reset(&mut self, rng: &mut NumpyRng) {
        // Drop the old world before building the new one (Gymnasium destroys, then creates).
        self.scene = None;
        self.scene = Some(Scene::build(rng, self.gravity));
        self.last_engines = Engines::discrete(0);
        // Gymnasium's reset returns the observation of one no-op step (outside the time limit count).
        (self.obs, _, _) = self.frame(Engines::discrete(0), true, rng);
    }

    fn step(&mut self, action: usize, rng: &mut EnvRng) -> (f64, bool) {
        let rng = rng
            .current()
            .expect("a step runs only after reset() set the generator");
        self.fire(Engines::discrete(action), rng)
    }

    fn observe(&self, obs: &mut [f32]) {
        obs.copy_from_slice(&self.obs);
    }

    fn geometry(&self) -> Option<super::Geometry> {
        self.scene
            .as_ref()
            .map(|scene| scene.geometry(self.last_engines, false))
    }
}

impl LunarLanderPhysics {
    /// One step of the episode with `engines`: returns the reward and whether the task terminated.
    fn fire(&mut self, engines: Engines, rng: &mut NumpyRng) -> (f64, bool) {
        let (next, reward, terminated) = self.frame(engines, false, rng);
        self.last_engines = engines;
        self.obs = next;
        (reward, terminated)
    }
}

/// Gymnasium's LunarLander with continuous engines (`LunarLanderContinuous-v3`, that is
/// `gym.make("LunarLander-v3", continuous=True)`): the same world, an action `[main, lateral]` in [-1, 1]²
/// (see `Engines::continuous`).
pub struct LunarLanderContinuous(LunarLanderPhysics);

impl Default for LunarLanderContinuous {
    fn default() -> Self {
        LunarLanderContinuous(LunarLanderPhysics {
            gravity: DEFAULT_GRAVITY,
            scene: None,
            prev_shaping: 0.0,
            last_engines: Engines::discrete(0),
            obs: [0.0; OBS_DIM],
        })
    }
}

impl super::continuous::ContinuousDynamics for LunarLanderContinuous {
    fn reset(&mut self, rng: &mut NumpyRng) {
        // Gymnasium resets the continuous lander with the action [0, 0]: no engine fires, as with discrete 0.
        Dynamics::reset(&mut self.0, rng);
    }

    fn step(&mut self, action: &[f32], rng: &mut NumpyRng) -> (f64, bool) {
        self.0
            .fire(Engines::continuous([action[0], action[1]]), rng)
    }

    fn observe(&self, obs: &mut [f32]) {
        obs.copy_from_slice(&self.0.obs);
    }

    fn set_state(&mut self, _state: &[f64]) -> Result<(), String> {
        Err("the lander's state is a Box2D world: it cannot be set from numbers".into())
    }

    fn geometry(&self) -> Option<super::Geometry> {
        let physics = &self.0;
        physics
            .scene
            .as_ref()
            .map(|scene| scene.geometry(physics.last_engines, true))
    }
}

/// What Gymnasium's heuristic lander controller (`heuristic` in lunar_lander.py) wants to correct:
/// `(angle_todo, hover_todo)`.
///
/// It steers the tilt towards the pad and holds a hover height proportional to the horizontal offset;
/// once a leg touches it only brakes the fall. Gymnasium evaluates it on the float32 observation with
/// NumPy 2 scalar rules (Python float constants become float32), so the arithmetic here is `f32`.
/// `obs` must have the 8 LunarLander components.
fn heuristic_todo(s: &[f32]) -> (f32, f32) {
    // The angle should point towards the centre, at most 0.4 rad either way.
    let angle_targ = (s[0] * 0.5 + s[2] * 1.0).clamp(-0.4, 0.4);
    // The target height is proportional to the horizontal offset.
    let hover_targ = 0.55 * s[0].abs();
    let angle_todo = (angle_targ - s[4]) * 0.5 - s[5] * 1.0;
    let hover_todo = (hover_targ - s[1]) * 0.5 - s[3] * 0.5;
    if s[6] != 0.0 || s[7] != 0.0 {
        // After touchdown only reduce the fall speed.
        (0.0, -s[3] * 0.5)
    } else {
        (angle_todo, hover_todo)
    }
}

/// Gymnasium's heuristic lander controller, discrete branch: the engine that corrects most.
pub fn heuristic_action(obs: &[f32]) -> usize {
    let (angle_todo, hover_todo) = heuristic_todo(obs);
    if hover_todo > angle_todo.abs() && hover_todo > 0.05 {
        2
    } else if angle_todo < -0.05 {
        3
    } else if angle_todo > 0.05 {
        1
    } else {
        0
    }
}

/// Gymnasium's heuristic lander controller, continuous branch: `[hover_todo * 20 - 1, -angle_todo * 20]`
/// clipped to [-1, 1], in float32 as NumPy computes it from the float32 observation.
pub fn heuristic_throttle(obs: &[f32]) -> [f32; 2] {
    let (angle_todo, hover_todo) = heuristic_todo(obs);
    [hover_todo * 20.0 - 1.0, -angle_todo * 20.0].map(|a| a.clamp(-1.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::env::Env;

    #[test]
    fn step_before_reset_and_bad_actions_are_errors() {
        let mut env = LunarLander::new("LunarLander-v2");
        assert!(matches!(env.step(0), Err(EnvError::NeedsReset { .. })));
        env.reset(Some(0));
        assert!(matches!(
            env.step(env.spec().n_actions),
            Err(EnvError::ActionOutOfRange {
                action: 4,
                n_actions: 4,
                ..
            })
        ));
        // A rejected action leaves the episode running.
        assert!(env.step(0).is_ok());
    }

    #[test]
    fn unseeded_reset_continues_the_generator() {
        // reset(Some(s)) then reset(None) must equal the same sequence on a fresh environment, and the
        // second episode must differ from the first (the generator moved on, it was not reseeded).
        let sequence = |env: &mut LunarLander| {
            let first = env.reset(Some(5));
            env.step(2).expect("running");
            let second = env.reset(None);
            (first, second)
        };
        let (first_a, second_a) = sequence(&mut LunarLander::new("LunarLander-v3"));
        let (first_b, second_b) = sequence(&mut LunarLander::new("LunarLander-v3"));
        assert_eq!(first_a, first_b);
        assert_eq!(second_a, second_b);
        assert_ne!(first_a, second_a);
    }

    #[test]
    fn time_limit_truncates_at_1000_steps() {
        // Find an episode the heuristic hovers through (some seeds reach the limit) and check the flags:
        // not truncated before step 1000, truncated on it, and no step after it without a reset.
        let mut env = LunarLander::new("LunarLander-v2");
        let limit = env.max_episode_steps();
        assert_eq!(limit, 1000);
        let mut found = false;
        for seed in 0..200 {
            let mut obs = env.reset(Some(seed));
            let mut steps = 0;
            let last = loop {
                let step = env.step(heuristic_action(&obs)).expect("running episode");
                steps += 1;
                obs = step.obs.clone();
                if step.terminated || step.truncated {
                    break step;
                }
                assert!(steps < limit, "no truncation at the limit");
            };
            if steps == limit {
                assert!(last.truncated);
                assert!(matches!(env.step(0), Err(EnvError::NeedsReset { .. })));
                found = true;
                break;
            }
            assert!(!last.truncated && last.terminated);
        }
        assert!(
            found,
            "no heuristic episode over seeds 0..200 reached the time limit"
        );
    }

    #[test]
    fn landing_or_crash_ends_with_the_terminal_reward() {
        // Every terminated episode ends with the +100 (asleep) or -100 (crash, out of view) reward.
        let mut env = LunarLander::new("LunarLander-v3");
        for seed in 0..10 {
            let mut obs = env.reset(Some(seed));
            loop {
                let step = env.step(heuristic_action(&obs)).expect("running episode");
                obs = step.obs;
                if step.terminated {
                    assert!(
                        step.reward == 100.0 || step.reward == -100.0,
                        "{}",
                        step.reward
                    );
                    break;
                }
                assert!(step.reward.abs() < 100.0);
                if step.truncated {
                    break;
                }
            }
        }
    }
}
