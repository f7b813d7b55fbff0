//! The messages between the server and the page, as JSON objects with a `type` field.
//!
//! Server to page: `welcome` (the tab's id), `hello` (once the run has started: the environment, its actions and
//! keys, the answering mode), `roles` (which tab controls), `status` (step, episode, budget, uncertainty and threshold), `frame`
//! (the environment's [`Geometry`] and observation), `image` (a frame the environment rendered), `table` (the
//! observation, labelled, of an environment without a picture), `eval` (a point of the test-return curve), `history` (the
//! recent uncertainty samples and the curve, for a tab that joins late), `prompt` (the agent asks; `null` when no
//! question is open), `error` (a message was rejected), `handed` (a Python program has the run back: `learn`
//! returned, or it was stopped; it may go on, then `resumed`), `takeover` (real time: whether a takeover is
//! offered, the agent acting, and whether the person asked for one), `watch` (whether the agent's steps go at the
//! real-time rate) and `end` (the run is over).
//!
//! Page to server: `key` (answer prompt `id` with `action`), `pass` (hand prompt `id` back to the agent),
//! `hold` (real time: the action held down, or `null`), `pause` (the run waits, or goes on), `control` (this
//! tab takes control), `takeover` (take over while the agent acts; with `cancel`, withdraw the request), `watch`
//! (real time: the agent's own steps at the real-time rate, or at full speed). An
//! action is an index for discrete actions, and for actions in a box a list of numbers, one per dimension, within the box the hello describes ([`BoxControls`]; checked by the core's
//! [`WireAction::check_answer`], as an expert process's answer is). Anything else, or an action out of range (a
//! number outside the box, or `null`: what `JSON.stringify` makes of NaN), gets an `error` frame and changes
//! nothing.

use arld_core::env::Geometry;
use arld_core::expert::process::WireAction;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// One action as the page shows it: what it does and the keys that give it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ActionKeys {
    pub label: String,
    /// `KeyboardEvent.key` values (lower case for letters).
    pub keys: Vec<String>,
}

impl ActionKeys {
    pub fn new(label: impl Into<String>, keys: &[&str]) -> Self {
        Self {
            label: label.into(),
            keys: keys.iter().map(|k| k.to_string()).collect(),
        }
    }
}

/// The actions of a built-in environment with their keys (arrows and WASD), and the action taken in real time
/// when no key is held. Keys that move something move it the way the arrow points.
pub fn action_keys(env_id: &str) -> Option<(Vec<ActionKeys>, usize)> {
    let a = ActionKeys::new;
    const LEFT: &[&str] = &["ArrowLeft", "a"];
    const RIGHT: &[&str] = &["ArrowRight", "d"];
    const DOWN: &[&str] = &["ArrowDown", "s"];
    const UP: &[&str] = &["ArrowUp", "w"];
    Some(match env_id {
        // CartPole has no action that does nothing; as in Gymnasium's `play`, action 0 stands in for it.
        "CartPole-v0" | "CartPole-v1" => (vec![a("push left", LEFT), a("push right", RIGHT)], 0),
        "Acrobot-v1" => (
            vec![
                a("torque -1", LEFT),
                a("no torque", DOWN),
                a("torque +1", RIGHT),
            ],
            1,
        ),
        "MountainCar-v0" => (
            vec![
                a("push left", LEFT),
                a("coast", DOWN),
                a("push right", RIGHT),
            ],
            1,
        ),
        // Each arrow fires the engine that moves the lander its way (measured in the test below: as in
        // Gymnasium, the left engine's impulse sends the lander left).
        "LunarLander-v2" | "LunarLander-v3" => (
            vec![
                a("do nothing", DOWN),
                a("fire left engine (moves left)", LEFT),
                a("fire main engine (moves up)", UP),
                a("fire right engine (moves right)", RIGHT),
            ],
            0,
        ),
        _ => return None,
    })
}

/// Actions in a box as the page controls them: the bounds and a name for each dimension.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BoxControls {
    pub low: Vec<f32>,
    pub high: Vec<f32>,
    pub names: Vec<String>,
    /// Per dimension, the keys that push it toward its lower and its upper bound (`KeyboardEvent.key` values):
    /// the arrows the way they point, and WASD.
    pub keys: Vec<[Vec<String>; 2]>,
}

impl BoxControls {
    /// The controls of the box task `spec`, its dimensions named where arld knows what they do (also under a
    /// registered id that adds facts to the task's own: `Pendulum-v1[max_episode_steps=...]`).
    pub fn of(spec: &arld_core::env::BoxSpec) -> Self {
        let task = base_id(spec.id);
        let known: &[&str] = match task {
            "Pendulum-v1" => &["torque"],
            "MountainCarContinuous-v0" => &["force"],
            "LunarLanderContinuous-v3" => &["main engine", "lateral"],
            _ => &[],
        };
        let names = (0..spec.action_dim())
            .map(|d| {
                known
                    .get(d)
                    .filter(|_| known.len() == spec.action_dim())
                    .map_or_else(|| format!("action[{d}]"), |n| n.to_string())
            })
            .collect();
        // The lander's main engine fires upward (up and down arrows), its lateral engines sideways.
        let pairs: &[[&[&str]; 2]] = match task {
            "LunarLanderContinuous-v3" => &[UP_DOWN, LEFT_RIGHT],
            _ => &[LEFT_RIGHT, UP_DOWN, [&["j"], &["l"]], [&["k"], &["i"]]],
        };
        let keys = (0..spec.action_dim())
            .map(|d| {
                pairs.get(d).map_or([Vec::new(), Vec::new()], |p| {
                    p.map(|ks| ks.iter().map(|k| k.to_string()).collect())
                })
            })
            .collect();
        Self {
            low: spec.action_low.to_vec(),
            high: spec.action_high.to_vec(),
            names,
            keys,
        }
    }

    /// The same controls with the dimensions named `names` (one non-empty name per dimension).
    pub fn named(self, names: &[String]) -> anyhow::Result<Self> {
        anyhow::ensure!(
            names.len() == self.names.len(),
            "labels= names {} dimensions, but the environment's actions have {}",
            names.len(),
            self.names.len()
        );
        if let Some(empty) = names.iter().find(|n| n.trim().is_empty()) {
            anyhow::bail!("labels: {empty:?} is empty; give each dimension a word or two");
        }
        Ok(Self {
            names: names.to_vec(),
            ..self
        })
    }
}

/// The task's own id of a registered id that adds facts in brackets (`Pendulum-v1[max_episode_steps=200]`: a
/// Python program's Gymnasium environment under arld's name for it).
fn base_id(id: &str) -> &str {
    id.split_once('[').map_or(id, |(base, _)| base)
}

const LEFT_RIGHT: [&[&str]; 2] = [&["ArrowLeft", "a"], &["ArrowRight", "d"]];
const UP_DOWN: [&[&str]; 2] = [&["ArrowDown", "s"], &["ArrowUp", "w"]];

/// The observation's labels of a built-in box task (for its table), where arld knows them.
pub fn box_obs_labels(env_id: &str) -> Option<Vec<String>> {
    let labels: &[&str] = match base_id(env_id) {
        "Pendulum-v1" => &["cos θ", "sin θ", "angular velocity"],
        "MountainCarContinuous-v0" => &["position", "velocity"],
        "LunarLanderContinuous-v3" => &[
            "x",
            "y",
            "x velocity",
            "y velocity",
            "angle",
            "angular velocity",
            "left leg touches",
            "right leg touches",
        ],
        _ => return None,
    };
    Some(labels.iter().map(|l| l.to_string()).collect())
}

/// Checks an action a page sent (a JSON value) against the run's actions; the error says why it is refused.
pub type ActionCheck = Arc<dyn Fn(&serde_json::Value) -> Result<(), String> + Send + Sync>;

/// The check of `n_actions` discrete actions.
pub fn discrete_check(n_actions: usize) -> ActionCheck {
    Arc::new(move |v| match usize::from_wire(v) {
        Some(a) if a < n_actions => Ok(()),
        Some(a) => Err(format!(
            "action {a} is out of range: the environment has {n_actions} actions (0 to {})",
            n_actions.saturating_sub(1)
        )),
        None => Err(format!("action {v} is not an action's index")),
    })
}

/// The check of actions in the box `spec`: a list of finite numbers, one per dimension, within the bounds.
pub fn box_check(spec: &'static arld_core::env::BoxSpec) -> ActionCheck {
    Arc::new(move |v| {
        let action = <Vec<f32>>::from_wire(v).ok_or_else(|| {
            format!(
                "action {v} is not a list of {} numbers (NaN and infinities are not numbers)",
                spec.action_dim()
            )
        })?;
        // A number beyond f32's range becomes an infinity here, which the check refuses.
        <Vec<f32>>::check_answer(&action, spec).map_err(|e| format!("action {v} is refused: {e}"))
    })
}

/// What the page needs to know of the run, sent to each tab once the run has started.
#[derive(Clone, Debug, Serialize)]
pub struct Hello {
    pub env: String,
    /// Discrete actions with their keys (empty for actions in a box).
    pub actions: Vec<ActionKeys>,
    /// The action taken in real time when nothing is held: an index, or the box's centre.
    pub noop: serde_json::Value,
    /// Actions in a box: their bounds and names (absent for discrete actions).
    #[serde(rename = "box", skip_serializing_if = "Option::is_none")]
    pub controls: Option<BoxControls>,
    /// Real-time steps per second; `None`: turn-based (one step per key).
    pub fps: Option<f64>,
    /// Seconds a question stays open; `None`: the run waits.
    pub timeout: Option<f64>,
    /// The return that solves the environment; `null` (infinite) when it has none.
    pub solve_threshold: f64,
    /// Whether the person can take back their last key (turn-based, where the page can show a copy of the
    /// environment that arld rebuilds).
    pub undo: bool,
}

/// Where the run stands.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Status {
    pub step: usize,
    pub train_steps: usize,
    pub episode: usize,
    /// The budget and what is spent of it, in the budget's unit (transitions unless the run counts queries).
    pub budget: usize,
    pub budget_used: usize,
    pub queries: usize,
    pub uncertainty: Option<f32>,
    pub threshold: Option<f32>,
    /// The last test return and its step.
    pub last_eval: Option<(u64, f64)>,
    /// The person's seconds so far, keys pressed and questions answered.
    pub person_s: f64,
    pub keys: usize,
    pub answered: usize,
    /// Segments the person took over unasked.
    pub takeovers: usize,
    /// The questions that can still come, at most (0: the agent trains on its own from here).
    pub questions_left_max: usize,
    /// The person's time still needed at their pace so far, if the budget were spent (`None` before any).
    pub time_left_s: Option<f64>,
}

/// The end screen: how the run ended and what the person gave.
#[derive(Clone, Debug, Serialize)]
pub struct EndScreen {
    pub solved: bool,
    pub steps_to_solve: usize,
    pub train_steps: usize,
    pub final_score: f64,
    pub run_dir: Option<String>,
    pub answered: usize,
    pub unanswered: usize,
    pub keys: usize,
    /// Keys taken back.
    pub undone: usize,
    /// Segments the person took over unasked.
    pub takeovers: usize,
    pub person_s: f64,
}

/// An open question to the person.
#[derive(Clone, Debug, Serialize)]
pub struct Prompt {
    pub id: u64,
    /// The agent's own proposal (on the step that opens a segment): an index, or a box's numbers.
    pub agent_action: Option<serde_json::Value>,
    /// Expert steps left in the segment, this one included.
    pub steps_left: usize,
    /// Whether the run waits for a key (turn-based, or the first step in real time).
    pub waits: bool,
    /// Whether the person's last key can be undone now (turn-based, within a segment, where the environment
    /// can be restored): the page shows the state after it, not yet taken by the run.
    pub undo: bool,
    /// Real time: the segment starts after this many seconds (a countdown once the person pressed a key).
    pub starts_in: Option<f64>,
    pub obs: Vec<f32>,
    /// The segment is the person's takeover (not a question of the agent): they hand back when done.
    pub takeover: bool,
    /// The agent's proposal at this step's state (its test-time action: an index, or a box's numbers), shown as
    /// a ghost at every step of a segment; `None` where the run does not give it.
    pub proposal: Option<serde_json::Value>,
}

/// How a real-time segment went, shown after it (see [`ServerMsg::Segment`]).
#[derive(Clone, Debug, Serialize)]
pub struct SegmentEnd {
    /// The id the page sends back to retry this segment ([`ClientMsg::Retry`]).
    pub id: u64,
    /// Steps played and the sum of their rewards.
    pub steps: usize,
    #[serde(rename = "return")]
    pub ret: f64,
    /// How the segment ended for a task with a goal: see [`segment_outcome`].
    pub outcome: Option<&'static str>,
    /// Whether the person may retry it now (there is budget for another attempt), and for how long (seconds).
    pub retry_s: Option<f64>,
    /// The attempt this was (1 for the first).
    pub attempt: usize,
}

/// How a segment ended, in a task with a goal: for the landers `landed` or `crashed`, for the mountain cars
/// `reached the flag`, for CartPole `the pole fell`, for Acrobot `swung up`, and `time up` when the episode was
/// cut by its time limit; `None` when the episode goes on (or for a task without a goal, Pendulum). `terminated`
/// and `truncated` are the last step's, `last_reward` its reward: a lander that comes to rest gets +100 on that
/// step, one that crashes or flies off -100 (Gymnasium's rewards), which outweighs the shaping.
pub fn segment_outcome(
    env: &str,
    terminated: bool,
    truncated: bool,
    last_reward: f64,
) -> Option<&'static str> {
    if !terminated {
        return truncated.then_some("time up");
    }
    let family = env.split('-').next().unwrap_or(env);
    Some(match family {
        "LunarLander" | "LunarLanderContinuous" if last_reward > 0.0 => "landed",
        "LunarLander" | "LunarLanderContinuous" => "crashed",
        "MountainCar" | "MountainCarContinuous" => "reached the flag",
        "CartPole" => "the pole fell",
        "Acrobot" => "swung up",
        _ => "the episode ended",
    })
}

/// Everything the server sends.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum ServerMsg<'a> {
    Hello(&'a Hello),
    /// This tab's id (compare with [`ServerMsg::Roles`]).
    Welcome {
        client: u64,
    },
    Roles {
        controller: Option<u64>,
    },
    Status(&'a Status),
    Frame {
        geometry: Option<&'a Geometry>,
        obs: &'a [f32],
    },
    /// A frame the environment rendered, as PNG in base64.
    Image {
        png: &'a str,
    },
    /// The observation of an environment that has no picture, with a label per value.
    Table {
        labels: &'a [String],
        obs: &'a [f32],
    },
    Eval {
        step: u64,
        mean: f64,
    },
    History {
        /// `[step, uncertainty, threshold or null]`.
        uncertainty: &'a [(usize, f32, Option<f32>)],
        curve: &'a [(u64, f64)],
    },
    Prompt {
        prompt: Option<&'a Prompt>,
    },
    /// The agent's own steps since the person's last one (their frames, oldest first), sent before a question
    /// so that the person sees how the state they are handed came about.
    Replay {
        frames: Vec<serde_json::Value>,
    },
    /// Whether the run is paused.
    Paused {
        paused: bool,
    },
    /// Real time: whether the agent's own steps go at the real-time rate (watch mode).
    Watch {
        on: bool,
    },
    Error {
        message: String,
    },
    End {
        message: String,
        outcome: Option<&'a EndScreen>,
    },
    /// The run is handed to its program (a Python `learn` returned, or the program stopped it), with where it
    /// stands; it may go on later (then `resumed`). The connection stays open, unlike after `end`.
    Handed {
        message: String,
        outcome: &'a EndScreen,
        /// Whether a stop request handed it over (a question open then is asked again when the run goes on).
        stopped: bool,
    },
    /// The run goes on after `handed`.
    Resumed,
    /// Real time: how the person's segment went, and whether they may retry it.
    Segment(&'a SegmentEnd),
    /// Real time: whether the person can take over now (the agent acts) and whether they asked to.
    Takeover {
        offered: bool,
        pending: bool,
    },
}

impl ServerMsg<'_> {
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("server messages serialise")
    }
}

/// Everything a page may send.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum ClientMsg {
    /// `acting`: the gesture that answered was itself the action (a fresh action key, a stick or trigger leaving
    /// rest), so a real-time segment starts at once, without the countdown that Enter or a pad's A gets.
    Key {
        id: u64,
        action: serde_json::Value,
        #[serde(default)]
        acting: bool,
    },
    /// Hand question `id` back to the agent (logged unanswered, nothing charged); during a takeover, any
    /// prompt of it: the person hands back.
    Pass {
        id: u64,
    },
    /// Undo the last key (prompt `id` shows the state after it; see [`Prompt::undo`]).
    Undo {
        id: u64,
    },
    /// Pause (or resume) the run: it and the person's clock wait.
    Pause {
        paused: bool,
    },
    /// Real time: the agent's own steps at the real-time rate (`on`), so that the person can watch and take over
    /// in time, or at full speed.
    Watch {
        on: bool,
    },
    Hold {
        action: Option<serde_json::Value>,
    },
    Control,
    /// Take over unasked from the state the agent is in (real time): a segment opens at the next step, charged
    /// like a question's, until the person hands back. Only while the agent acts (see `takeover` from the
    /// server); `cancel: true` withdraws a request the run has not taken yet.
    Takeover {
        #[serde(default)]
        cancel: bool,
    },
    /// Real time: play the segment `id` names ([`SegmentEnd::id`]) again from its start state; its answers
    /// replace the first attempt's.
    Retry {
        id: u64,
    },
}

impl ClientMsg {
    /// Parses and checks a page's message, its action by `check`.
    pub fn parse(text: &str, check: &ActionCheck) -> Result<Self, String> {
        let msg: ClientMsg =
            serde_json::from_str(text).map_err(|e| format!("malformed message: {e}"))?;
        let action = match &msg {
            ClientMsg::Key { action, .. } => Some(action),
            ClientMsg::Hold { action } => action.as_ref(),
            ClientMsg::Control
            | ClientMsg::Takeover { .. }
            | ClientMsg::Pass { .. }
            | ClientMsg::Undo { .. }
            | ClientMsg::Retry { .. }
            | ClientMsg::Pause { .. }
            | ClientMsg::Watch { .. } => None,
        };
        if let Some(a) = action {
            check(a)?;
        }
        Ok(msg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn page_messages_are_checked() {
        let two = discrete_check(2);
        assert_eq!(
            ClientMsg::parse(r#"{"type":"key","id":3,"action":1}"#, &two),
            Ok(ClientMsg::Key {
                id: 3,
                action: 1.into(),
                acting: false
            })
        );
        assert_eq!(
            ClientMsg::parse(r#"{"type":"key","id":3,"action":1,"acting":true}"#, &two),
            Ok(ClientMsg::Key {
                id: 3,
                action: 1.into(),
                acting: true
            })
        );
        assert_eq!(
            ClientMsg::parse(r#"{"type":"hold","action":null}"#, &two),
            Ok(ClientMsg::Hold { action: None })
        );
        assert_eq!(
            ClientMsg::parse(r#"{"type":"control"}"#, &two),
            Ok(ClientMsg::Control)
        );
        for bad in [
            r#"{"type":"key","id":3,"action":2}"#,
            r#"{"type":"key","id":3,"action":-1}"#,
            r#"{"type":"key","id":3}"#,
            r#"{"type":"hold","action":7}"#,
            r#"{"type":"quit"}"#,
            r#"{"type":"key","id":1,"action":0,"extra":1}"#,
            r#"{"type":"key","id":1,"action":[0.5]}"#,
            "not json",
            "",
        ] {
            assert!(ClientMsg::parse(bad, &two).is_err(), "{bad} accepted");
        }
    }

    /// Box actions: a list of numbers within the bounds (each refusal says why, checked against the bounds
    /// read from the task's spec here).
    #[test]
    fn box_actions_from_the_page_are_checked_against_the_box() {
        let spec = arld_core::env::box_spec("LunarLanderContinuous-v3").unwrap();
        let check = box_check(spec);
        let key = |a: &str| format!(r#"{{"type":"key","id":1,"action":{a}}}"#);
        assert_eq!(
            ClientMsg::parse(&key("[0.25,-1]"), &check),
            Ok(ClientMsg::Key {
                id: 1,
                action: serde_json::json!([0.25, -1]),
                acting: false
            })
        );
        let hi = spec.action_high[1];
        let just_out = format!("[0,{}]", f64::from(hi) + 0.01);
        for (bad, says) in [
            ("[0.5]", "2 (LunarLanderContinuous-v3"),
            ("[0.5,0.5,0.5]", "not 2"),
            ("[null,0]", "not a list of 2 numbers"),
            ("[1e40,0]", "not a finite number"),
            (just_out.as_str(), "dimension 1"),
            ("[-1.5,0]", "dimension 0"),
            ("1", "not a list"),
            (r#"["0",0]"#, "not a list"),
        ] {
            let err = ClientMsg::parse(&key(bad), &check).expect_err(bad);
            assert!(err.contains(says), "{bad}: {err}");
        }
        let hold = r#"{"type":"hold","action":[2,0]}"#;
        assert!(ClientMsg::parse(hold, &check).is_err());
        let c = BoxControls::of(spec);
        assert_eq!(c.names, ["main engine", "lateral"]);
        assert_eq!(
            (c.low.as_slice(), c.high.as_slice()),
            (spec.action_low, spec.action_high)
        );
    }

    /// A Python program's Gymnasium Pendulum is registered under an id that adds its own facts: its torque and
    /// observation keep their names; `labels=` renames the dimensions, one name each.
    #[test]
    fn a_registered_copy_of_a_known_box_task_keeps_its_names_and_labels_rename_them() {
        let id = "Pendulum-v1[max_episode_steps=200,reward_threshold=None,protocol-test]";
        let spec = arld_core::env::register_box(id, 3, &[-2.0], &[2.0], 200, None).unwrap();
        let c = BoxControls::of(spec);
        assert_eq!(c.names, ["torque"]);
        assert_eq!(c.keys[0][0], ["ArrowLeft", "a"]);
        assert_eq!(box_obs_labels(id).unwrap()[2], "angular velocity");
        let renamed = c.clone().named(&["twist".to_string()]).unwrap();
        assert_eq!(
            (renamed.names.as_slice(), &renamed.low),
            (&["twist".to_string()][..], &c.low)
        );
        let two = ["a".to_string(), "b".to_string()];
        let err = c.clone().named(&two).unwrap_err().to_string();
        assert!(
            err.contains("names 2 dimensions") && err.contains("have 1"),
            "{err}"
        );
        let err = c.named(&[" ".to_string()]).unwrap_err().to_string();
        assert!(err.contains("is empty"), "{err}");
        // Another task's name with the same brackets is not taken for Pendulum's.
        let other = "Swing-v0[max_episode_steps=200,protocol-test]";
        let spec = arld_core::env::register_box(other, 3, &[-2.0], &[2.0], 200, None).unwrap();
        assert_eq!(BoxControls::of(spec).names, ["action[0]"]);
    }

    #[test]
    fn every_builtin_environment_has_keys_for_each_action() {
        for spec in arld_core::env::SPECS {
            let (actions, noop) = action_keys(spec.id).expect("keys for a built-in environment");
            assert_eq!(actions.len(), spec.n_actions, "{}", spec.id);
            assert!(noop < spec.n_actions);
            let mut keys: Vec<_> = actions.iter().flat_map(|a| &a.keys).collect();
            let n = keys.len();
            keys.sort();
            keys.dedup();
            assert_eq!(keys.len(), n, "{}: a key gives two actions", spec.id);
        }
    }

    /// The arrow keys move the lander the way they point: from rest, a few steps of the left arrow's action
    /// leave it moving left, and of the right arrow's, moving right (the side engines push the other way).
    #[test]
    fn lander_arrows_move_the_lander_their_way() {
        let (actions, _) = action_keys("LunarLander-v2").unwrap();
        let of = |key: &str| {
            actions
                .iter()
                .position(|a| a.keys.iter().any(|k| k == key))
                .unwrap()
        };
        let vx_after = |action: usize| {
            let mut env = arld_core::env::make("LunarLander-v2").unwrap();
            let mut obs = env.reset(Some(7));
            for _ in 0..8 {
                env.step_into(action, &mut obs).unwrap();
            }
            obs[2]
        };
        let rest = vx_after(0);
        assert!(
            vx_after(of("ArrowLeft")) < rest - 1e-3,
            "the left arrow does not move the lander left"
        );
        assert!(
            vx_after(of("ArrowRight")) > rest + 1e-3,
            "the right arrow does not move the lander right"
        );
    }
}
