//! A training run alive in its own thread between `learn` calls ([`Run`]), and how one starts ([`start_run`]): its
//! environments, expert, demonstrations, run directory (locked), and a snapshot to continue or begin from.

use crate::actions::PyAction;
use crate::demos::DemoArrays;
use crate::envs::PyEnv;
use crate::errors::{ErrorSlot, runtime_error, value_error};
use crate::experts::PyExpert;
use crate::learners::PyLearner;
use crate::lent::{LentRef, in_callback, with_lent};
use crate::policy::{Net, Policy};
use crate::records::eval_dict;
use crate::remote::{Command, Pause, Remote, Report, Waited};
use crate::snapshots::read_snapshot_file;
use crate::web;
use arld_core::agent::DqnAgent;
use arld_core::agent::box_agent::BoxAgent;
use arld_core::env::{self, Env};
use arld_core::expert::Expert;
use arld_core::train::session::{self, Session};
use arld_core::train::{self, Checkpointer, EvalPoint, TrainConfig};
use pyo3::prelude::*;
use pyo3::types::PyList;
use std::path::Path;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::sync::{Arc, Mutex};

/// The next run's key.
pub(crate) static NEXT_RUN: AtomicU64 = AtomicU64::new(1);

/// One training run, alive in its own thread between `learn` calls: `advance` trains it to a step and returns
/// where it stands; the run goes on from there at the next `advance`, exactly as if it had not paused. Every
/// method takes `&self`, so a callback may call them while `advance` waits.
#[pyclass(module = "arld._arld")]
pub(crate) struct Run {
    pub(crate) id: u64,
    pub(crate) commands: Sender<Command>,
    pub(crate) reports: Mutex<Receiver<Report>>,
    pub(crate) interrupt: Arc<AtomicBool>,
    pub(crate) step: Arc<AtomicUsize>,
    pub(crate) errors: ErrorSlot,
    pub(crate) saves: Arc<Mutex<Vec<PathBuf>>>,
    pub(crate) cfg: TrainConfig,
    pub(crate) last: Mutex<Option<Box<Pause>>>,
    pub(crate) started: AtomicBool,
    pub(crate) thread: Mutex<Option<std::thread::JoinHandle<()>>>,
}

impl Drop for Run {
    fn drop(&mut self) {
        let _ = self.commands.send(Command::Stop);
    }
}

impl Run {
    /// Waits for the thread's next report, with the GIL released; Ctrl-C pauses the run and is raised once it
    /// has paused, as is an exception an expert or a callback raised. `progress(step)` is called every tenth of
    /// a second.
    pub(crate) fn wait(&self, py: Python<'_>, progress: Option<&Py<PyAny>>) -> PyResult<Waited> {
        let mut interrupted: Option<PyErr> = None;
        loop {
            let got = py.detach(|| {
                let reports = self.reports.lock().unwrap_or_else(|e| e.into_inner());
                reports.recv_timeout(std::time::Duration::from_millis(100))
            });
            match got {
                Ok(Report::Failed(e)) => {
                    if let Some(p) = self.last().as_mut() {
                        p.finished = true;
                    }
                    return Err(self.errors.raise(py, e, runtime_error));
                }
                Ok(Report::Paused(p)) => {
                    let step = p.summary.train_steps;
                    *self.last() = Some(p);
                    let note = format!(
                        "arld: the run paused whole after step {step} (network, replay, queries and budget kept; \
                         an open question is asked again): learn(..., reset_num_timesteps=False) goes on from there"
                    );
                    if let Some(e) = self.errors.take_with_note(py, &note) {
                        return Err(e);
                    }
                    return match interrupted {
                        Some(e) => Err(e),
                        None => Ok(Waited::Paused(step)),
                    };
                }
                Ok(Report::Saved(saved)) => {
                    return match interrupted {
                        Some(e) => Err(e),
                        None => Ok(Waited::Saved(saved)),
                    };
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(runtime_error("the run's thread ended unexpectedly".into()));
                }
                Err(RecvTimeoutError::Timeout) => {
                    if let Err(e) = py.check_signals() {
                        self.interrupt.store(true, Ordering::Relaxed);
                        interrupted.get_or_insert(e);
                    }
                    if let Some(p) = progress {
                        p.call1(py, (self.step.load(Ordering::Relaxed),))?;
                    }
                }
            }
        }
    }

    pub(crate) fn last(&self) -> std::sync::MutexGuard<'_, Option<Box<Pause>>> {
        self.last.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// `f` of the last pause, or the error that the run has not trained yet.
    pub(crate) fn with_last<R>(&self, f: impl FnOnce(&Pause) -> R) -> PyResult<R> {
        self.last()
            .as_deref()
            .map(f)
            .ok_or_else(|| runtime_error("the run has not trained yet: call learn() first".into()))
    }

    pub(crate) fn refuse_in_callback(&self, what: &str) -> PyResult<()> {
        if in_callback() {
            return Err(runtime_error(format!(
                "{what} cannot be called from inside a callback (the run is waiting for it to return); return \
                 False to stop training there"
            )));
        }
        Ok(())
    }
}

#[pymethods]
impl Run {
    /// Trains until environment step `until` (at least one step), calling `callback(step, episode, budget_used,
    /// queries, last_eval)` after every step (`False` pauses the run there) and `progress(step)` every tenth of
    /// a second. Returns the steps done.
    #[pyo3(signature = (until, callback=None, progress=None))]
    fn advance(
        &self,
        py: Python<'_>,
        until: usize,
        callback: Option<Py<PyAny>>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<usize> {
        self.refuse_in_callback("learn()")?;
        if self.last().as_ref().is_some_and(|p| p.finished) {
            return Err(runtime_error(
                "this run has ended (an error stopped it); start a new one with learn(...)".into(),
            ));
        }
        self.interrupt.store(false, Ordering::Relaxed);
        self.commands
            .send(Command::Advance { until, callback })
            .map_err(|_| runtime_error("the run's thread has ended".into()))?;
        self.started.store(true, Ordering::Relaxed);
        match self.wait(py, progress.as_ref())? {
            Waited::Paused(step) => Ok(step),
            Waited::Saved(_) => Err(runtime_error("unexpected report from the run".into())),
        }
    }

    /// Writes the run's full snapshot (network, optimiser, replay, query state, generators) to the file `path`;
    /// inside a callback, at a pause right after the callback returns.
    fn save(&self, py: Python<'_>, path: &str) -> PyResult<()> {
        if with_lent(self.id, |_| ()).is_some() {
            self.saves
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(path.into());
            return Ok(());
        }
        self.refuse_in_callback("save() of another run")?;
        if !self.started.load(Ordering::Relaxed) {
            return Err(runtime_error(
                "the run has not started: call learn() first".into(),
            ));
        }
        self.commands
            .send(Command::Snapshot(path.into()))
            .map_err(|_| runtime_error("the run's thread has ended".into()))?;
        match self.wait(py, None)? {
            Waited::Saved(r) => r.map_err(runtime_error),
            Waited::Paused(_) => Err(runtime_error("unexpected report from the run".into())),
        }
    }

    /// Ends the run (its thread finishes the log) and waits for the thread.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        self.refuse_in_callback("a learn() that starts a new run")?;
        let _ = self.commands.send(Command::Stop);
        let thread = self.thread.lock().unwrap_or_else(|e| e.into_inner()).take();
        if let Some(t) = thread {
            py.detach(|| {
                let _ = t.join();
            });
        }
        Ok(())
    }

    /// The current policy (a copy of the network, with the exploration of training at its step): the live one
    /// inside a callback, the last pause's otherwise.
    fn policy(&self) -> PyResult<Policy> {
        if let Some(p) = self.live_policy() {
            return Ok(p);
        }
        let (net, step) = self.with_last(|p| (p.net.clone(), p.summary.train_steps))?;
        Ok(Policy::of_run(net, &self.cfg, step))
    }

    /// The live network as a policy, inside this run's callback; `None` elsewhere.
    fn live_policy(&self) -> Option<Policy> {
        let step = self.step.load(Ordering::Relaxed);
        with_lent(self.id, |lent| {
            let net = match lent {
                LentRef::Discrete(agent, _) => Net::Q(Box::new(agent.network().clone())),
                LentRef::Box(agent, _) => agent.net(&self.cfg.env),
            };
            Policy::of_run(net, &self.cfg, step)
        })
    }

    /// The live target network (as a policy), inside this run's callback of a DQN-family run; `None` elsewhere
    /// (TD3's targets follow by Polyak averaging and are not shown). It changes only at a target copy.
    fn live_target_policy(&self) -> Option<Policy> {
        let step = self.step.load(Ordering::Relaxed);
        with_lent(self.id, |lent| match lent {
            LentRef::Discrete(agent, _) => Some(Policy::exploring(
                agent.target_network().clone(),
                &self.cfg,
                step,
            )),
            LentRef::Box(..) => None,
        })
        .flatten()
    }

    /// The live network's test-policy actions for rows of observations (ints, or lists of floats for actions
    /// in a box), inside this run's callback; `None` elsewhere.
    fn live_actions(&self, py: Python<'_>, rows: Vec<Vec<f32>>) -> PyResult<Option<Py<PyAny>>> {
        let check = |obs: &[f32], dim: usize| {
            if obs.len() != dim {
                return Err(value_error(format!(
                    "the observation has {} values, but the network takes {dim}",
                    obs.len()
                )));
            }
            Ok(())
        };
        with_lent(self.id, |lent| match lent {
            LentRef::Discrete(agent, _) => {
                let net = agent.network();
                let mut q = vec![0.0; net.heads() * net.n_actions()];
                let actions = rows
                    .iter()
                    .map(|obs| {
                        check(obs, net.obs_dim())?;
                        Ok(arld_core::agent::test_policy_action(net, &mut q, obs))
                    })
                    .collect::<PyResult<Vec<usize>>>()?;
                Ok(actions.into_pyobject(py)?.into_any().unbind())
            }
            LentRef::Box(agent, _) => {
                let Net::Actor(mut actor) = agent.net(&self.cfg.env) else {
                    unreachable!("a box agent's network is an actor")
                };
                let actions = rows
                    .iter()
                    .map(|obs| {
                        check(obs, actor.obs_dim())?;
                        Ok(actor.act(obs))
                    })
                    .collect::<PyResult<Vec<Vec<f32>>>>()?;
                Ok(actions.into_pyobject(py)?.into_any().unbind())
            }
        })
        .transpose()
    }

    /// The evaluations so far (live inside a callback): dicts of step, mean, std, min, max.
    fn evaluations(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        let list = PyList::empty(py);
        let fill = |curve: &[EvalPoint]| {
            curve
                .iter()
                .try_for_each(|p| list.append(eval_dict(py, p)?))
        };
        match with_lent(self.id, |lent| fill(lent.curve())) {
            Some(filled) => filled?,
            None => self.with_last(|last| fill(&last.curve))??,
        }
        Ok(list.unbind())
    }

    /// The queries so far (live inside a callback): dicts of step, episode, uncertainty, threshold,
    /// expert_action, agent_action (ints, or lists of floats for actions in a box).
    fn queries(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        let list = PyList::empty(py);
        let live = with_lent(self.id, |lent| match lent {
            LentRef::Discrete(_, log) => usize::records(log.query_events()),
            LentRef::Box(_, log) => Vec::<f32>::records(log.query_events()),
        });
        match live {
            Some(records) => records.fill(py, &list)?,
            None => self.with_last(|last| last.queries.fill(py, &list))??,
        }
        Ok(list.unbind())
    }

    /// The summary at the last pause, as JSON text.
    fn summary(&self) -> PyResult<String> {
        self.with_last(|p| serde_json::to_string(&p.summary))?
            .map_err(|e| runtime_error(e.to_string()))
    }

    /// Environment steps done.
    #[getter]
    fn num_timesteps(&self) -> usize {
        self.step.load(Ordering::Relaxed)
    }

    /// ε of the run's exploration at its current step.
    #[getter]
    fn exploration_rate(&self) -> f64 {
        train::epsilon_at(&self.cfg, self.step.load(Ordering::Relaxed))
    }

    /// Whether this run's callback is running on this thread (the live run is lent to it).
    #[getter]
    fn in_callback(&self) -> bool {
        with_lent(self.id, |_| ()).is_some()
    }
}

/// Takes the lock of the run directory `dir` (created if missing) as `arld train` does ([`Session::lock`]): one
/// process, and in it one run, at a time. Refused naming the holder (and, when it is this process, how to end its
/// run).
pub(crate) fn lock_run_dir(dir: &Path) -> anyhow::Result<Session> {
    Session::lock(dir).map_err(|e| {
        if session::held_by_this_process(dir) {
            e.context("another Agent of this Python process runs in it; its close() ends that run")
        } else {
            e
        }
    })
}

/// Starts a training run in its own thread (it waits for `Run.advance`): the configuration as JSON text (from
/// `resolve_config`) and what Python gives the run ([`RunRequest`]).
#[pyfunction]
pub(crate) fn start_run(py: Python<'_>, config: &str, request: RunRequest) -> PyResult<Run> {
    let errors = ErrorSlot::default();
    let cfg: TrainConfig = serde_json::from_str(config).map_err(|e| value_error(e.to_string()))?;
    let (commands_tx, commands_rx) = channel();
    let (reports_tx, reports_rx) = channel();
    let interrupt = Arc::new(AtomicBool::new(false));
    let step = Arc::new(AtomicUsize::new(0));
    let saves = Arc::new(Mutex::new(Vec::new()));
    let id = NEXT_RUN.fetch_add(1, Ordering::Relaxed);
    let mut remote = Remote {
        id,
        saves: saves.clone(),
        only_saving: false,
        until: 0,
        callback: None,
        commands: commands_rx,
        reports: reports_tx.clone(),
        interrupt: interrupt.clone(),
        step: step.clone(),
        errors: errors.clone(),
        env_id: cfg.env.clone(),
    };
    // A person's page is built here, where Python can be asked about the environment (its frames, its keys),
    // and the run waits for the page to open before its thread starts.
    let boxed = env::box_spec(&cfg.env).is_ok();
    let keep = {
        let errors = errors.clone();
        move |e| errors.keep(e)
    };
    let gym = request.env.as_ref().map(|e| e.bind(py));
    let (web_discrete, web_box) = match &request.expert {
        Some(call) if boxed => {
            let web =
                web::expert::<Vec<f32>>(call.bind(py), gym, &cfg.env, keep, interrupt.clone());
            (None, web.map_err(|e| errors.raise(py, e, runtime_error))?)
        }
        Some(call) => {
            let web = web::expert::<usize>(call.bind(py), gym, &cfg.env, keep, interrupt.clone());
            (web.map_err(|e| errors.raise(py, e, runtime_error))?, None)
        }
        None => (None, None),
    };
    // One process per run directory, as `arld train`: the lock is taken here (a second run is refused before
    // anything starts, naming the holder) and held by the run's thread until it ends.
    let lock = match &request.log_dir {
        Some(dir) => {
            Some(lock_run_dir(Path::new(dir)).map_err(|e| errors.raise(py, e, runtime_error))?)
        }
        None => None,
    };
    let inputs = RunInputs {
        cfg: cfg.clone(),
        request,
        errors: errors.clone(),
    };
    let body = move || -> anyhow::Result<()> {
        let _lock = lock;
        // Wait for the first command: the run starts on the first `advance`.
        match remote.commands.recv() {
            Ok(Command::Advance { until, callback }) => {
                (remote.until, remote.callback) = (until, callback)
            }
            _ => return Ok(()),
        }
        if boxed {
            train_in_thread::<BoxAgent>(inputs, &mut remote, web_box)
        } else {
            train_in_thread::<DqnAgent>(inputs, &mut remote, web_discrete)
        }
    };
    let thread = std::thread::Builder::new()
        .name("arld-run".into())
        .spawn(move || {
            if let Err(e) = body() {
                let _ = reports_tx.send(Report::Failed(e));
            }
        })
        .map_err(|e| runtime_error(e.to_string()))?;
    Ok(Run {
        id,
        commands: commands_tx,
        reports: Mutex::new(reports_rx),
        interrupt,
        step,
        errors,
        saves,
        cfg,
        last: Mutex::new(None),
        started: AtomicBool::new(false),
        thread: Mutex::new(Some(thread)),
    })
}

/// What Python gives a run to train with (`start_run`'s second argument, a dict with every key): the
/// environments (Python objects, or `None` for the built-in one of the configuration's id; `test_envs` one per
/// test episode, stepped in lockstep), the expert (a Python callable, or `None` to build the configuration's
/// expert spec) and its name, demonstrations as arrays of rows (or `None` to collect them from the expert on
/// `demo_env`, or on the built-in environment), a run directory, a snapshot file to continue from, and a snapshot
/// file whose learner (weights, target, optimiser) a new run begins with ([`RunBuilder::start_from`]).
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
pub(crate) struct RunRequest {
    pub(crate) env: Option<Py<PyAny>>,
    pub(crate) test_envs: Option<Vec<Py<PyAny>>>,
    pub(crate) expert: Option<Py<PyAny>>,
    pub(crate) expert_name: String,
    pub(crate) demos: Option<DemoArrays>,
    pub(crate) log_dir: Option<String>,
    pub(crate) resume: Option<String>,
    pub(crate) start_from: Option<String>,
    pub(crate) demo_env: Option<Py<PyAny>>,
}

/// What a run's thread is given to train with (see [`start_run`]).
pub(crate) struct RunInputs {
    pub(crate) cfg: TrainConfig,
    pub(crate) request: RunRequest,
    pub(crate) errors: ErrorSlot,
}

/// Trains the run of `inputs` with the learner `L`, driven by `remote`, on the run's thread (after its first
/// command). `web_expert`: a person's page already built, which takes the place of the Python expert.
pub(crate) fn train_in_thread<L: PyLearner>(
    inputs: RunInputs,
    remote: &mut Remote,
    web_expert: Option<Box<dyn Expert<L::Action>>>,
) -> anyhow::Result<()> {
    let RunInputs {
        cfg,
        request,
        errors,
    } = inputs;
    let RunRequest {
        env,
        test_envs,
        expert,
        expert_name,
        demos,
        log_dir,
        resume,
        start_from,
        demo_env,
    } = request;
    let spec = L::Action::spec_of(&cfg.env)?;
    let make = |obj: Option<Py<PyAny>>| -> anyhow::Result<Box<dyn Env<L::Action>>> {
        Ok(match obj {
            Some(obj) => Box::new(PyEnv::<L::Action> {
                obj,
                spec,
                errors: errors.clone(),
                reset_failed: None,
            }),
            None => L::Action::builtin(&cfg.env)?,
        })
    };
    let env = make(env)?;
    let test_envs = match test_envs {
        Some(objs) => objs
            .into_iter()
            .map(|obj| make(Some(obj)))
            .collect::<anyhow::Result<Vec<_>>>()?,
        None => (0..cfg.eval_episodes)
            .map(|_| make(None))
            .collect::<anyhow::Result<Vec<_>>>()?,
    };
    let mut expert: Option<Box<dyn Expert<L::Action>>> = match (web_expert, expert) {
        (Some(web), _) => Some(web),
        (None, Some(call)) => Some(Box::new(PyExpert::<L::Action> {
            call,
            name: expert_name,
            spec,
            errors: errors.clone(),
        })),
        (None, None) if cfg.expert_used().is_some() => Some(L::Action::spec_expert(&cfg)?),
        (None, None) => None,
    };
    let resume_state = match &resume {
        None => None,
        Some(path) => {
            // The snapshot machinery reads `snapshot.safetensors` in a directory: a private copy there.
            let dir = tempfile::tempdir()?;
            std::fs::copy(path, dir.path().join(train::snapshot::SNAPSHOT_FILE))?;
            let mut ck = Checkpointer::new(dir.path(), &cfg);
            ck.load()?
        }
    };
    // The learner a new run begins with: a saved run's (its snapshot), or weights given (set_parameters).
    let given_learner: L;
    let start_state = match &start_from {
        None => None,
        Some(path) if train::snapshot::recorded_config(Path::new(path)).is_ok() => {
            Some(read_snapshot_file(path)?.1)
        }
        Some(path) => {
            given_learner = L::from_weights(&cfg, Path::new(path))?;
            let mut state = arld_core::state::StateDict::default();
            given_learner.save_state(train::run::AGENT_STATE, &mut state);
            Some(state)
        }
    };
    // Demonstrations given as rows, else the run's own (its demo_file, or collected from the expert on
    // `demo_env`): `train::run_demonstrations`, as for the command line.
    let demos = match demos {
        _ if resume_state.is_some() => None,
        Some(given) if cfg.method.pretrains() => {
            Some(given.into_demonstrations::<L::Action>(&cfg)?)
        }
        _ => train::run_demonstrations(
            &cfg,
            expert
                .as_mut()
                .map(|e| &mut **e as &mut dyn Expert<L::Action>),
            || make(demo_env),
        )?,
    };
    let mut log = session::open_log(
        log_dir.as_deref().map(Path::new),
        &cfg,
        resume_state.as_ref(),
        false,
    )?;
    L::builder(&cfg)
        .env(env)
        .test_envs(test_envs)
        .expert(
            expert
                .as_mut()
                .map(|e| &mut **e as &mut dyn Expert<L::Action>),
        )
        .demos(demos.as_ref())
        .driver(remote)
        .resume_from(resume_state.as_ref())
        .start_from(start_state.as_ref())
        .train(&mut log)?;
    Ok(())
}
