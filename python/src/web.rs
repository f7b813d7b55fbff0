//! `arld.WebExpert`: a person answering in the browser, as the expert of a run from Python.
//!
//! [`PyWebExpert`] starts the web server when it is created (it prints the URL and keeps it as `.url`), before
//! any environment is known; [`expert`] then turns it into the library's [`WebExpert`] for the run's
//! environment. A built-in task is drawn from its geometry; a Gymnasium environment made with
//! `render_mode="rgb_array"` is shown from its `render()` frames; any other one as its observation in a table.
//! The keys: the `keys=` mapping where given, else the environment's `get_keys_to_action()` where it has one
//! (Gymnasium's `play` convention), else a number key per action. The labels: `labels=`, else
//! `get_action_meanings()`, else the names of an `actions` enum of the environment (MiniGrid's `Actions`).
//! Actions in a box ([`GymAction`] for `Vec<f32>`) are set with keys toward each bound, a slider or a pad's stick
//! per dimension; `labels=` names the dimensions (else arld's names for a task it knows, e.g. Pendulum's torque).
//! The URL is printed once the run has accepted the environment (a refused environment prints none).

use arld_core::expert::Expert;
use arld_web::frames::{FrameSource, ObservationTable, RenderedFrames, RgbImage};
use arld_web::protocol::ActionKeys;
use arld_web::{Page, PageAction, WebExpert, WebOptions, WebServer};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString, PyTuple};
use std::collections::BTreeMap;
use std::sync::Mutex;

/// Keys the page keeps for itself: Escape hands a question back.
const RESERVED_KEYS: &[&str] = &["Escape"];

/// `arld.WebExpert(listen="127.0.0.1:0", fps=None, timeout=None, keys=None, wait=True, labels=None,
/// segment_s=None)`: starts the
/// page's server (its URL is `.url`, printed when a run takes it). Pass it as `expert=` to `arld.Agent`; it serves
/// one run. `fps`: real time at that many steps a second (default: turn-based, one step per key); `timeout`:
/// seconds a question waits before it goes back to the agent; `keys`: `{"ArrowLeft": 0, "d": 1, ...}`
/// (`KeyboardEvent.key` names; before the environment's `get_keys_to_action()`; discrete actions only); `wait`:
/// whether training starts only once the page is open; `labels`: what each action does, one string per action
/// (actions in a box: a name per dimension); `segment_s`: real time, the seconds of play a question hands the
/// person (3 by default; the run's `segment_len` unless that is given).
#[pyclass(name = "WebExpert", module = "arld._arld")]
pub struct PyWebExpert {
    server: Mutex<Option<WebServer>>,
    url: String,
    spec: String,
    keys: Option<BTreeMap<String, usize>>,
    labels: Option<Vec<String>>,
}

#[pymethods]
impl PyWebExpert {
    #[new]
    #[pyo3(signature = (listen="127.0.0.1:0", fps=None, timeout=None, keys=None, wait=true, labels=None, segment_s=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        listen: &str,
        fps: Option<f64>,
        timeout: Option<f64>,
        keys: Option<BTreeMap<String, usize>>,
        wait: bool,
        labels: Option<Vec<String>>,
        segment_s: Option<f64>,
    ) -> PyResult<Self> {
        let mut spec = format!("listen={listen},wait={}", if wait { "yes" } else { "no" });
        spec.extend(fps.map(|v| format!(",fps={v}")));
        spec.extend(segment_s.map(|v| format!(",segment_s={v}")));
        spec.extend(timeout.map(|v| format!(",timeout={v}")));
        let options: WebOptions = spec
            .parse()
            .map_err(|e: anyhow::Error| PyValueError::new_err(format!("{e:#}")))?;
        if let Some(k) = keys
            .as_ref()
            .and_then(|k| k.keys().find(|k| RESERVED_KEYS.contains(&k.as_str())))
        {
            return Err(PyValueError::new_err(format!(
                "keys: {k} is the page's own key (it hands a question back to the agent); choose another"
            )));
        }
        if let Some(l) = labels
            .as_ref()
            .and_then(|l| l.iter().find(|l| l.trim().is_empty()))
        {
            return Err(PyValueError::new_err(format!(
                "labels: {l:?} is empty; give each action a word or two"
            )));
        }
        let server =
            WebServer::bind(&options).map_err(|e| PyRuntimeError::new_err(format!("{e:#}")))?;
        Ok(Self {
            spec: options.to_spec(),
            url: server.url().to_string(),
            server: Mutex::new(Some(server)),
            keys,
            labels,
        })
    }

    /// The address to open, with its access token.
    #[getter]
    fn url(&self) -> String {
        self.url.clone()
    }

    /// The options as an expert spec (`web:listen=...,fps=...`): the run's configuration reads the real-time
    /// segment's length from it.
    #[getter]
    fn spec(&self) -> String {
        self.spec.clone()
    }

    fn __repr__(&self) -> String {
        format!("arld.WebExpert(url={:?})", self.url)
    }
}

/// The library's web expert for a run, when `obj` is an `arld.WebExpert` (`None` otherwise), for actions of kind
/// `A` (discrete, or in a box). `env` is the run's environment bridge (its Gymnasium environment as `.env`), or
/// `None` for the built-in task `id`; `keep` keeps a Python exception (a Ctrl-C) to raise when the run returns;
/// `stop` is set when the run is asked to stop.
pub fn expert<A: GymAction>(
    obj: &Bound<'_, PyAny>,
    env: Option<&Bound<'_, PyAny>>,
    id: &str,
    keep: impl Fn(PyErr) -> String + Send + Sync + Clone + 'static,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> anyhow::Result<Option<Box<dyn Expert<A>>>> {
    let Ok(web) = obj.cast::<PyWebExpert>() else {
        return Ok(None);
    };
    let web = web.borrow();
    let server = web
        .server
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .take()
        .ok_or_else(|| {
            anyhow::anyhow!(
                "this arld.WebExpert served a run already: create a new one for each run"
            )
        })?;
    let cannot_show =
        |e: &dyn std::fmt::Display| anyhow::anyhow!("arld.WebExpert cannot show {id}: {e}");
    let page = match env {
        None => A::builtin_page(id)?,
        Some(bridge) => {
            let gym = bridge.getattr("env").map_err(|e| anyhow::anyhow!("{e}"))?;
            A::gym_page(&gym, id, &web, Box::new(keep.clone())).map_err(|e| cannot_show(&e))?
        }
    };
    let mut expert =
        WebExpert::for_page(server, page).map_err(|e| cannot_show(&format!("{e:#}")))?;
    expert.announce()?;
    // A stop in Python (Ctrl-C, or SIGTERM during `learn`): the main thread, which alone runs Python's signal
    // handlers, sets `stop` while the run trains in its own thread; the wait for the page, on the main thread,
    // asks Python itself. The KeyboardInterrupt is raised once the run has paused with the question open.
    expert.set_stop_check(Box::new(move || {
        stop.load(std::sync::atomic::Ordering::Relaxed)
            || Python::attach(|py| match py.check_signals() {
                Ok(()) => false,
                Err(err) => {
                    keep(err);
                    true
                }
            })
    }));
    expert.wait_for_page()?;
    Ok(Some(Box::new(expert)))
}

/// A Gymnasium environment, as Python holds it.
type Gym<'py> = Bound<'py, PyAny>;
/// Keeps a Python exception (to raise when the run returns) and gives its text for the Rust error.
type Keep = Box<dyn Fn(PyErr) -> String + Send + Sync>;

/// A kind of action a person gives on the page of a Python program's run: how the page of its environment is
/// made.
pub trait GymAction: PageAction {
    /// The page of the built-in task `id`.
    fn builtin_page(id: &str) -> anyhow::Result<Page<Self>>;
    /// The page of the Gymnasium environment `gym`, registered as `id`: its frames or its observation, and how
    /// the person acts (`keys=` and `labels=` as given to `web`).
    fn gym_page(gym: &Gym<'_>, id: &str, web: &PyWebExpert, keep: Keep) -> PyResult<Page<Self>>;
}

impl GymAction for usize {
    fn builtin_page(id: &str) -> anyhow::Result<Page> {
        Page::builtin(id)
    }

    fn gym_page(gym: &Gym<'_>, id: &str, web: &PyWebExpert, keep: Keep) -> PyResult<Page> {
        let spec = arld_core::env::spec(id).map_err(|e| PyValueError::new_err(e.to_string()))?;
        let (keys, labels) = (web.keys.as_ref(), web.labels.as_deref());
        let (actions, noop) = gym_actions(gym, spec.n_actions, keys, labels)?;
        let frames: Box<dyn FrameSource> = match rendered(gym, keep)? {
            Some(frames) => Box::new(frames),
            None => Box::new(ObservationTable::new(spec.obs_dim, None)),
        };
        Ok(Page {
            env: spec.id.to_string(),
            actions,
            noop,
            solve_threshold: spec.solve_threshold,
            frames,
            dim_names: None,
        })
    }
}

/// Actions in a box: the task's bounds give the controls (keys toward each bound, a slider and a pad's stick per
/// dimension); `labels=` names the dimensions. `keys=` maps keys to discrete actions and is refused here.
impl GymAction for Vec<f32> {
    fn builtin_page(id: &str) -> anyhow::Result<Page<Vec<f32>>> {
        Page::builtin_box(id)
    }

    fn gym_page(
        gym: &Gym<'_>,
        id: &str,
        web: &PyWebExpert,
        keep: Keep,
    ) -> PyResult<Page<Vec<f32>>> {
        if web.keys.is_some() {
            return Err(PyValueError::new_err(
                "keys= maps keys to discrete actions, but its actions are in a box: the arrows and WASD push \
                 each dimension toward its bounds (name the dimensions with labels=)",
            ));
        }
        let mut page =
            Page::builtin_box(id).map_err(|e| PyValueError::new_err(format!("{e:#}")))?;
        if let Some(frames) = rendered(gym, keep)? {
            page.frames = Box::new(frames);
        }
        page.dim_names = web.labels.clone();
        Ok(page)
    }
}

/// The environment's own frames when it was made with `render_mode="rgb_array"`, else `None`.
fn rendered(gym: &Gym<'_>, keep: Keep) -> PyResult<Option<RenderedFrames>> {
    let render_mode: Option<String> = gym.getattr("render_mode")?.extract().unwrap_or(None);
    if render_mode.as_deref() != Some("rgb_array") {
        return Ok(None);
    }
    let gym: Py<PyAny> = gym.clone().unbind();
    Ok(Some(RenderedFrames::new(Box::new(move || {
        Python::attach(|py| rgb_frame(gym.bind(py)))
            .map_err(|e| anyhow::anyhow!("render() failed: {}", keep(e)))
    }))))
}

/// The environment's current frame from `render()`: a height x width x 3 (or 4: the alpha is dropped) array of
/// bytes.
fn rgb_frame(gym: &Bound<'_, PyAny>) -> PyResult<RgbImage> {
    let frame = gym.call_method0("render")?;
    let shape: Vec<usize> = frame.getattr("shape")?.extract()?;
    let dtype: String = frame.getattr("dtype")?.str()?.extract()?;
    let [height, width, channels] = shape[..] else {
        return Err(PyValueError::new_err(format!(
            "render() returned an array of shape {shape:?}, not height x width x 3"
        )));
    };
    if dtype != "uint8" || !(channels == 3 || channels == 4) {
        return Err(PyValueError::new_err(format!(
            "render() returned {dtype} of shape {shape:?}; rgb_array frames are uint8, height x width x 3"
        )));
    }
    let bytes: Vec<u8> = frame.call_method0("tobytes")?.extract()?;
    let pixels = if channels == 3 {
        bytes
    } else {
        bytes
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect()
    };
    Ok(RgbImage {
        width: width as u32,
        height: height as u32,
        pixels,
    })
}

/// The actions' labels and keys, and the no-op action (taken in real time when no key is held).
fn gym_actions(
    gym: &Bound<'_, PyAny>,
    n_actions: usize,
    keys: Option<&BTreeMap<String, usize>>,
    labels: Option<&[String]>,
) -> PyResult<(Vec<ActionKeys>, usize)> {
    let unwrapped = gym.getattr("unwrapped")?;
    if let Some(labels) = labels.filter(|l| l.len() != n_actions) {
        return Err(PyValueError::new_err(format!(
            "labels= names {} actions, but the environment has {n_actions}",
            labels.len()
        )));
    }
    let meanings: Option<Vec<String>> = unwrapped
        .call_method0("get_action_meanings")
        .ok()
        .and_then(|m| m.extract().ok())
        .or_else(|| enum_names(&unwrapped))
        .filter(|m: &Vec<String>| m.len() == n_actions);
    let mut noop = meanings
        .as_ref()
        .and_then(|m| m.iter().position(|s| s == "NOOP"))
        .unwrap_or(0);
    let mut per_action: Vec<Vec<String>> = vec![Vec::new(); n_actions];
    let out_of_range = |a: usize, whose: &str| {
        PyValueError::new_err(format!(
            "{whose} maps a key to action {a}, but the environment has {n_actions} actions"
        ))
    };
    let env_keys = [gym, &unwrapped]
        .into_iter()
        .find_map(|o| o.call_method0("get_keys_to_action").ok())
        .and_then(|m| m.cast_into::<PyDict>().ok())
        .filter(|_| keys.is_none());
    if let Some(map) = env_keys {
        for (combo, action) in map.iter() {
            let action: usize = action.extract()?;
            if action >= n_actions {
                return Err(out_of_range(action, "get_keys_to_action()"));
            }
            let combo: Vec<Bound<'_, PyAny>> = match combo.cast::<PyTuple>() {
                Ok(t) => t.iter().collect(),
                Err(_) => vec![combo.clone()],
            };
            match combo.as_slice() {
                [] => noop = action,
                // One key per action on the page: combinations of keys are left out.
                [key] => per_action[action].extend(key_name(key)),
                _ => {}
            }
        }
    } else if let Some(keys) = keys {
        for (key, &action) in keys {
            if action >= n_actions {
                return Err(out_of_range(action, "keys="));
            }
            let key = if key.chars().count() == 1 {
                key.to_lowercase()
            } else {
                key.clone()
            };
            per_action[action].push(key);
        }
    }
    // An action left without a key gets its number (1-9, then 0).
    let mut used: Vec<String> = per_action.iter().flatten().cloned().collect();
    for (i, keys) in per_action.iter_mut().enumerate() {
        let digit = ((i + 1) % 10).to_string();
        if keys.is_empty() && i < 10 && !used.contains(&digit) {
            used.push(digit.clone());
            keys.push(digit);
        }
    }
    let actions = per_action
        .into_iter()
        .enumerate()
        .map(|(i, keys)| ActionKeys {
            label: match (labels, meanings.as_ref()) {
                (Some(l), _) => l[i].clone(),
                (None, Some(m)) => m[i].to_lowercase().replace('_', " "),
                (None, None) => format!("action {i}"),
            },
            keys,
        })
        .collect();
    Ok((actions, noop))
}

/// The member names of the environment's `actions` enum (MiniGrid's `Actions`: left, right, forward, ...) in the
/// order of their values 0, 1, ...; `None` when it has no such enum or its values are not 0..n.
fn enum_names(unwrapped: &Bound<'_, PyAny>) -> Option<Vec<String>> {
    let actions = unwrapped.getattr("actions").ok()?;
    let mut members: Vec<(usize, String)> = actions
        .try_iter()
        .ok()?
        .map(|m| {
            let m = m.ok()?;
            Some((
                m.getattr("value").ok()?.extract().ok()?,
                m.getattr("name").ok()?.extract().ok()?,
            ))
        })
        .collect::<Option<_>>()?;
    members.sort();
    members
        .iter()
        .enumerate()
        .all(|(i, (v, _))| *v == i)
        .then(|| members.into_iter().map(|(_, name)| name).collect())
}

/// A key of Gymnasium's `play` convention (a character, or a pygame key code) as `KeyboardEvent.key`.
fn key_name(key: &Bound<'_, PyAny>) -> Option<String> {
    if let Ok(s) = key.cast::<PyString>() {
        let s = s.to_string();
        return Some(if s.chars().count() == 1 {
            s.to_lowercase()
        } else {
            s
        });
    }
    let code: i64 = key.extract().ok()?;
    // pygame's arrow keys (SDL2 scancode-based codes).
    Some(match code {
        1_073_741_904 => "ArrowLeft".into(),
        1_073_741_903 => "ArrowRight".into(),
        1_073_741_906 => "ArrowUp".into(),
        1_073_741_905 => "ArrowDown".into(),
        32 => " ".into(),
        33..=126 => char::from(code as u8).to_lowercase().to_string(),
        _ => return None,
    })
}
