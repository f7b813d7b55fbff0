//! Runs in a task with actions in a box, through the command line and the one run loop: TD3 asks the task's
//! scripted controller where the query rule says so, and every file of the run holds box actions. The expert's
//! answers are checked against the controller recomputed here from each stored observation, and the queries
//! against the answers.

mod common;

use arld::agent::Learner;
use arld::agent::box_agent::BoxAgent;
use arld::env::box_spec;
use arld::env::pendulum::swing_up;
use arld::expert;
use arld::expert::demos::Demonstrations;
use arld::task::{ActionColumn, BoxColumn};
use arld::train::run::box_agent;
use arld::train::{
    self, ConfigInput, Control, Driver, Method, NetKind, PausedRun, RunBuilder, RunLog, StepView,
    TrainConfig,
};
use common::arld;
use serde_json::Value;

/// Fails the test with the command's own error output unless it exited successfully.
fn assert_ran(res: &std::process::Output) {
    assert!(
        res.status.success(),
        "{}",
        String::from_utf8_lossy(&res.stderr)
    );
}

/// A run directory's summary.json.
fn summary_of(run: &std::path::Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(run.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn an_active_td3_run_asks_the_scripted_swing_up_and_logs_box_actions() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let res = arld(&[
        "train",
        "--env",
        "Pendulum-v1",
        "--method",
        "adqn",
        "--expert",
        "scripted",
        "--set",
        "train_steps=1500",
        "--set",
        "eval_period=500",
        "--set",
        "eval_episodes=2",
        "--set",
        "hidden=[32,32]",
        "--set",
        "batch_size=32",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_ran(&res);
    let summary = summary_of(&out);
    assert_eq!(summary["train_steps"], 1500);
    assert_eq!(summary["env"], "Pendulum-v1");

    // Every answered step is the swing-up's action at its observation, one number in [-2, 2].
    let answers = std::fs::read_to_string(out.join("answers.jsonl")).unwrap();
    let steps: Vec<Value> = answers
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(!steps.is_empty(), "the expert was never asked");
    for step in &steps {
        let obs: Vec<f32> = serde_json::from_value(step["obs"].clone()).unwrap();
        let action: Vec<f32> = serde_json::from_value(step["action"].clone()).unwrap();
        assert_eq!(action, swing_up(&obs).to_vec(), "{step}");
        let proposal: Vec<f32> = serde_json::from_value(step["agent_action"].clone()).unwrap();
        assert_eq!(proposal.len(), 1);
        assert!((-2.0..=2.0).contains(&proposal[0]), "{step}");
    }
    assert_eq!(
        summary["demos_queried"].as_u64().unwrap() as usize,
        steps.len(),
        "the budget counts the answered steps"
    );

    // queries.csv: one row per question, the actions as their numbers; each question's expert action is the
    // first answer of its segment.
    let queries = std::fs::read_to_string(out.join("queries.csv")).unwrap();
    let rows: Vec<Vec<&str>> = queries
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert!(!rows.is_empty());
    for row in &rows {
        let step: usize = row[0].parse().unwrap();
        let first = steps
            .iter()
            .find(|s| s["step"].as_u64() == Some(step as u64))
            .unwrap_or_else(|| panic!("no answer at the question's step {step}"));
        let logged: f32 = row[4].parse().unwrap();
        assert_eq!(logged, first["action"][0].as_f64().unwrap() as f32);
        let agent: f32 = row[5].parse().unwrap();
        assert!((-2.0..=2.0).contains(&agent));
    }
}

/// A box run refuses lambda_n (the DQN family's extra n-step loss, which TD3 has not) with its reason.
#[test]
fn a_box_run_refuses_what_it_cannot_do() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let res = arld(&[
        "train",
        "--env",
        "Pendulum-v1",
        "--method",
        "dqn",
        "--set",
        "lambda_n=1",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!res.status.success());
    let err = String::from_utf8_lossy(&res.stderr);
    assert!(err.contains("lambda_n"), "{err}");
    assert!(!out.join("summary.json").exists());
}

/// The configuration of a short box run of `method` over the preset, with `sets` on top.
fn box_config(method: Method, sets: &[(&str, toml::Value)]) -> TrainConfig {
    let mut input = ConfigInput::new("Pendulum-v1", method, NetKind::Bootstrap, 3);
    for (key, value) in sets {
        input.set(key, value.clone()).unwrap();
    }
    input.resolve().unwrap()
}

/// The mean |pi(s) - a_E| of `agent`'s test actions against the swing-up's on `states`.
fn imitation_error(agent: &mut BoxAgent, states: &[Vec<f32>]) -> f64 {
    let mut column = BoxColumn::default();
    let obs: Vec<f32> = states.concat();
    agent.test_actions(&obs, &mut column);
    states
        .iter()
        .enumerate()
        .map(|(i, s)| f64::from((column.get(i)[0] - swing_up(s)[0]).abs()))
        .sum::<f64>()
        / states.len() as f64
}

/// A dqfd run on Pendulum-v1 collects its demonstrations from the scripted swing-up and pre-trains on them
/// (cloning without the Q-filter): its actor then imitates the expert on states of episodes it never saw, far
/// better than the best constant action and than the same agent before pre-training.
#[test]
fn a_dqfd_run_pre_trains_an_actor_that_imitates_the_scripted_expert() {
    let cfg = box_config(
        Method::Dqfd,
        &[
            ("pretrain_steps", 2_000.into()),
            ("train_steps", 1.into()),
            ("eval_period", 1.into()),
            ("eval_episodes", 1.into()),
        ],
    );
    assert_eq!(cfg.lambda, 100.0, "the box preset's cloning weight");
    let spec = box_spec("Pendulum-v1").unwrap();
    let mut expert = expert::boxed::from_spec("scripted", spec, 0, 30.0).unwrap();
    let demos = train::run_demonstrations(&cfg, Some(expert.as_mut()), || {
        Ok(arld::env::make_box("Pendulum-v1")?)
    })
    .unwrap()
    .expect("dqfd pre-trains");
    assert_eq!(demos.transitions.len(), cfg.n_demo);
    // Every demonstrated action is the controller's at its observation.
    assert!(
        demos
            .transitions
            .iter()
            .all(|t| t.action == swing_up(&t.obs).to_vec())
    );
    // Held-out states: the swing-up's own episodes from seeds the run never used.
    let mut scripted = expert::boxed::from_spec("scripted", spec, 0, 30.0).unwrap();
    let held_out: Vec<Vec<f32>> =
        Demonstrations::collect("Pendulum-v1", scripted.as_mut(), 600, 1_000)
            .unwrap()
            .transitions
            .into_iter()
            .map(|t| t.obs)
            .collect();
    let mut actions: Vec<f32> = held_out.iter().map(|s| swing_up(s)[0]).collect();
    actions.sort_by(f32::total_cmp);
    let median = actions[actions.len() / 2];
    let constant = actions
        .iter()
        .map(|a| f64::from((a - median).abs()))
        .sum::<f64>()
        / actions.len() as f64;
    let before = imitation_error(&mut box_agent(&cfg, spec), &held_out);
    let (summary, mut agent) = RunBuilder::for_box(&cfg)
        .demos(Some(&demos))
        .train(&mut RunLog::in_memory())
        .unwrap();
    assert_eq!(summary.demos_pretrain, cfg.n_demo);
    let after = imitation_error(&mut agent, &held_out);
    eprintln!(
        "mean |pi(s) - a_E| on held-out states: {before:.3} before pre-training, {after:.3} after; the best \
         constant action {constant:.3}"
    );
    assert!(
        after < 0.5 * constant && after < 0.5 * before,
        "the pre-trained actor does not imitate: {after} against {constant} (constant) and {before} (before)"
    );
}

/// `arld train --method adqnp` on Pendulum-v1 pre-trains on half the demonstrations, then asks the scripted
/// expert within the other half as its budget; demonstrations from a file (`--demos`) give the same run as
/// the same ones collected by the run itself.
#[test]
fn adqnp_on_pendulum_pre_trains_then_asks_within_its_budget() {
    let dir = tempfile::tempdir().unwrap();
    let run = |out: &std::path::Path, extra: &[&str]| {
        let mut args = vec![
            "train",
            "--env",
            "Pendulum-v1",
            "--method",
            "adqnp",
            "--expert",
            "scripted",
            "--seed",
            "4",
            "--set",
            "train_steps=1500",
            "--set",
            "learning_starts=500",
            "--set",
            "n_demo=200",
            "--set",
            "budget=100",
            "--set",
            "pretrain_steps=100",
            "--set",
            "eval_period=500",
            "--set",
            "eval_episodes=2",
            "--set",
            "hidden=[32,32]",
            "--set",
            "batch_size=32",
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let res = arld(&args);
        assert!(
            res.status.success(),
            "{}",
            String::from_utf8_lossy(&res.stderr)
        );
        serde_json::from_str::<Value>(&std::fs::read_to_string(out.join("summary.json")).unwrap())
            .unwrap()
    };
    let out = dir.path().join("run");
    let summary = run(&out, &[]);
    assert_eq!(summary["demos_pretrain"], 200);
    assert_eq!(summary["demos_queried"], 100, "{summary}");
    let answers = std::fs::read_to_string(out.join("answers.jsonl")).unwrap();
    assert_eq!(answers.lines().count(), 100);
    for line in answers.lines() {
        let step: Value = serde_json::from_str(line).unwrap();
        let obs: Vec<f32> = serde_json::from_value(step["obs"].clone()).unwrap();
        let action: Vec<f32> = serde_json::from_value(step["action"].clone()).unwrap();
        assert_eq!(action, swing_up(&obs).to_vec());
    }
    // The same 200 transitions as a file: the run collects them with the demonstration seed of seed 4.
    let spec = box_spec("Pendulum-v1").unwrap();
    let mut expert = expert::boxed::from_spec("scripted", spec, 0, 30.0).unwrap();
    let seed = train::seed_for(4, train::SeedPurpose::Demonstrations);
    let demos = Demonstrations::collect("Pendulum-v1", expert.as_mut(), 200, seed).unwrap();
    let file = dir.path().join("demos.jsonl");
    demos.save(&file).unwrap();
    let from_file = dir.path().join("from_file");
    let summary = run(&from_file, &["--demos", file.to_str().unwrap()]);
    assert_eq!(summary["demos_pretrain"], 200);
    for name in ["eval.csv", "episodes.csv", "answers.jsonl"] {
        assert_eq!(
            std::fs::read(out.join(name)).unwrap(),
            std::fs::read(from_file.join(name)).unwrap(),
            "{name}"
        );
    }
}

/// Demonstrations of box actions survive a round trip through their file (every number to the bit), and the
/// header says the box; a malformed file is refused with the line named.
#[test]
fn box_demonstration_files_round_trip_and_bad_ones_are_refused_by_line() {
    let dir = tempfile::tempdir().unwrap();
    let spec = box_spec("Pendulum-v1").unwrap();
    let mut expert = expert::boxed::from_spec("noisy:0.3:scripted", spec, 9, 30.0).unwrap();
    let demos = Demonstrations::collect("Pendulum-v1", expert.as_mut(), 450, 7).unwrap();
    assert_eq!(demos.episodes(), 3, "whole episodes of 200, the last cut");
    let path = dir.path().join("demos.jsonl");
    demos.save(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let header: Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    assert_eq!(header["action_dim"], 1);
    assert_eq!(header["low"], serde_json::json!([-2.0]));
    assert_eq!(header["high"], serde_json::json!([2.0]));
    assert!(header.get("n_actions").is_none());
    let back = Demonstrations::<Vec<f32>>::load(&path, Some("Pendulum-v1")).unwrap();
    assert_eq!(back, demos);
    let bits = |d: &Demonstrations<Vec<f32>>| -> Vec<u32> {
        d.transitions
            .iter()
            .flat_map(|t| {
                t.obs
                    .iter()
                    .chain(&t.action)
                    .chain(&t.next_obs)
                    .chain([&t.reward])
            })
            .map(|v| v.to_bits())
            .collect()
    };
    assert_eq!(bits(&back), bits(&demos));
    // A discrete file read as box demonstrations, and a box file read as discrete ones, are refused.
    let mut cart = expert::from_spec("scripted", "CartPole-v0", 0, 30.0).unwrap();
    let discrete = Demonstrations::collect("CartPole-v0", cart.as_mut(), 20, 0).unwrap();
    let cart_path = dir.path().join("cart.jsonl");
    discrete.save(&cart_path).unwrap();
    let err = format!(
        "{:#}",
        Demonstrations::<Vec<f32>>::load(&cart_path, None).unwrap_err()
    );
    assert!(err.contains("cart.jsonl:1:"), "{err}");
    let err = format!(
        "{:#}",
        Demonstrations::<usize>::load(&path, None).unwrap_err()
    );
    assert!(err.contains("demos.jsonl:1:"), "{err}");

    // Line 4 (the third transition) spoiled in one way each: the error names the line and the problem.
    let lines: Vec<&str> = text.lines().collect();
    let spoil = |name: &str, from: &str, to: &str| -> String {
        let mut changed = lines.clone();
        let line = lines[3].replacen(from, to, 1);
        assert_ne!(line, lines[3], "{name}: nothing replaced");
        changed[3] = &line;
        let bad = dir.path().join(format!("{name}.jsonl"));
        std::fs::write(&bad, changed.join("\n") + "\n").unwrap();
        format!(
            "{:#}",
            Demonstrations::<Vec<f32>>::load(&bad, Some("Pendulum-v1")).unwrap_err()
        )
    };
    let action = serde_json::to_string(&demos.transitions[2].action).unwrap();
    for (name, to, says) in [
        ("outside", "[2.5]", "dimension 0"),
        ("two_values", "[0.5,0.5]", "2 values"),
        ("huge", "[1e40]", "out of range"),
        ("empty", "[]", "0 values"),
        ("text", "[\"a\"]", "malformed transition"),
        ("index", "1", "malformed transition"),
    ] {
        let err = spoil(
            name,
            &format!("\"action\":{action}"),
            &format!("\"action\":{to}"),
        );
        assert!(err.contains(":4:"), "{name}: {err}");
        assert!(err.contains(says), "{name}: {err}");
    }
    let obs = serde_json::to_string(&demos.transitions[2].obs).unwrap();
    let err = spoil("short_obs", &format!("\"obs\":{obs}"), "\"obs\":[0.0,1.0]");
    assert!(
        err.contains(":4:") && err.contains("observation of length 2"),
        "{err}"
    );
}

/// `n_step` acts for TD3: a run with three-step returns learns another actor than the same run with one-step
/// ones (before, the replay kept n-step returns only for the DQN family's n-step loss and the two were equal).
#[test]
fn n_step_changes_what_td3_learns() {
    let actor = |n_step: usize| {
        let cfg = box_config(
            Method::Dqn,
            &[
                ("n_step", (n_step as i64).into()),
                ("train_steps", 700.into()),
                ("learning_starts", 300.into()),
                ("eval_period", 700.into()),
                ("eval_episodes", 1.into()),
                ("hidden", toml::Value::Array(vec![16.into(), 16.into()])),
                ("batch_size", 32.into()),
            ],
        );
        let (_, mut agent) = RunBuilder::for_box(&cfg)
            .train(&mut RunLog::in_memory())
            .unwrap();
        let mut column = BoxColumn::default();
        let obs: Vec<f32> = (0..30).map(|k| (k as f32 * 0.7).sin()).collect();
        agent.test_actions(&obs, &mut column);
        (0..10).map(|r| column.get(r)[0]).collect::<Vec<f32>>()
    };
    let (one, again, three) = (actor(1), actor(1), actor(3));
    assert_eq!(one, again, "a run is reproducible");
    assert_ne!(one, three, "n_step = 3 was ignored");
}

/// `arld report` reads runs of a box task like any other: the table's cell for an active TD3 run on Pendulum-v1
/// is the run's own steps to solve (its summary), with one solved seed of one.
#[test]
fn a_report_reads_box_runs() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("runs").join("pendulum");
    let res = arld(&[
        "train",
        "--env",
        "Pendulum-v1",
        "--method",
        "adqn",
        "--set",
        "train_steps=10000",
        "-o",
        run.to_str().unwrap(),
    ]);
    assert_ran(&res);
    let summary = summary_of(&run);
    let steps = summary["steps_to_solve"].as_u64().unwrap();
    assert!(
        steps < 10_000,
        "the shipped weak expert's run did not solve: {summary}"
    );
    let report = dir.path().join("report");
    let res = arld(&[
        "report",
        dir.path().join("runs").to_str().unwrap(),
        "-o",
        report.to_str().unwrap(),
    ]);
    assert_ran(&res);
    let table = std::fs::read_to_string(report.join("table.md")).unwrap();
    let row = table
        .lines()
        .find(|l| l.starts_with("| ADQN (actor-critic) |"))
        .unwrap_or_else(|| panic!("no ADQN (actor-critic) row in\n{table}"));
    assert!(row.contains(&format!("{steps}** (-) 1/1")), "{row}");
}

/// Pauses a box run right after its `episodes`-th episode ends, writes a snapshot into `dir` and stops it there;
/// keeps the step and the budget used at that moment.
struct StopAfterEpisodes {
    episodes: usize,
    dir: std::path::PathBuf,
    at: Option<(usize, usize)>,
}

impl Driver<BoxAgent> for StopAfterEpisodes {
    fn after_step(&mut self, at: &StepView<'_, BoxAgent>) -> anyhow::Result<Control> {
        if self.at.is_none() && at.episode == self.episodes {
            self.at = Some((at.step, at.transitions_used));
            return Ok(Control::Pause);
        }
        Ok(Control::Continue)
    }

    fn paused(&mut self, run: &mut PausedRun<'_, BoxAgent>) -> anyhow::Result<Control> {
        run.snapshot(&self.dir)?;
        Ok(Control::Stop)
    }
}

/// The value at descending position floor(len * alpha) of `values` (the calibrated rules' threshold), by sorting.
fn descending_quantile(values: &[f32], alpha: f64) -> Option<f32> {
    let mut sorted = values.to_vec();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let k = ((values.len() as f64 * alpha).floor() as usize).min(values.len().checked_sub(1)?);
    Some(sorted[k])
}

/// A thrifty run on MountainCarContinuous-v0 (risk critic trained on the flag as its goal), stopped right after
/// its third episode: the snapshot's record of every risk and uncertainty the rule saw has one value per decision
/// (every step the agent acted, and every question), and the rule's thresholds are the (1 - alpha) quantiles of those records, recomputed here;
/// every question came after the first episode (before it there is no threshold) with the threshold of its time
/// logged, and asked for a risk above it or for novelty. A run of another rule holds no risk critic.
#[test]
fn the_thrifty_rule_asks_above_the_quantiles_of_the_risks_it_recorded() {
    let spec = box_spec("MountainCarContinuous-v0").unwrap();
    let config = |rule: &str| {
        let mut input = ConfigInput::new(
            "MountainCarContinuous-v0",
            Method::Adqn,
            NetKind::Bootstrap,
            2,
        );
        // The run stops after its third episode: a budget it cannot spend by then, and a run long enough for the
        // default alpha, budget / (5 train_steps), to be 0.04.
        let sets: toml::Table =
            "train_steps = 15000\nbudget = 3000\nlearning_starts = 500\neval_period = 4000\n\
             eval_episodes = 1\nhidden = [32, 32]\nbatch_size = 32"
                .parse()
                .unwrap();
        input.set("query_rule", rule).unwrap();
        for (key, value) in sets {
            input.set(&key, value).unwrap();
        }
        input.resolve().unwrap()
    };
    let stopped = |cfg: &TrainConfig, dir: &std::path::Path| {
        let mut expert = expert::boxed::from_spec("scripted", spec, 0, 30.0).unwrap();
        let mut driver = StopAfterEpisodes {
            episodes: 3,
            dir: dir.to_path_buf(),
            at: None,
        };
        let mut log = RunLog::in_memory();
        RunBuilder::for_box(cfg)
            .expert(Some(expert.as_mut()))
            .driver(&mut driver)
            .train(&mut log)
            .unwrap();
        let bytes = std::fs::read(dir.join("snapshot.safetensors")).unwrap();
        let state = arld::train::snapshot::read_snapshot(&bytes, cfg).unwrap();
        (state, driver.at.unwrap(), log.query_events().to_vec())
    };
    let work = tempfile::tempdir().unwrap();
    let cfg = config("thrifty");
    let (state, (step, used), queries) = stopped(&cfg, work.path());
    let alpha = cfg.budget as f64 / (cfg.segment_len * cfg.train_steps) as f64;
    assert!(
        used > 0 && used < cfg.budget,
        "asked {used} of {}",
        cfg.budget
    );
    let risks = state.f32s("query.risk.history").unwrap().to_vec();
    let novelty = state.f32s("query.novelty.history").unwrap();
    // One decision per step the agent acted, and one at each question (its step is the expert's first).
    let decisions = step - used + queries.len();
    assert_eq!((risks.len(), novelty.len()), (decisions, decisions));
    assert!(
        risks.iter().all(|r| *r > 0.0 && *r < 1.0),
        "a risk outside (0, 1)"
    );
    let threshold: Option<f32> = state.value("query.risk.threshold").unwrap();
    assert_eq!(threshold, descending_quantile(&risks, alpha));
    let threshold_n: Option<f32> = state.value("query.novelty.threshold").unwrap();
    assert_eq!(threshold_n, descending_quantile(novelty, alpha));
    assert!(!queries.is_empty(), "the rule never asked");
    let (mut for_risk, mut for_novelty) = (0, 0);
    for q in &queries {
        assert!(q.episode >= 1, "a question in the first episode: {q:?}");
        let (risk, t) = (q.uncertainty.unwrap(), q.threshold.unwrap());
        assert!(
            risks.contains(&risk),
            "the question's risk {risk} was not recorded"
        );
        if risk > t {
            for_risk += 1;
        } else {
            for_novelty += 1;
        }
    }
    eprintln!(
        "thrifty on MountainCarContinuous-v0: {} questions ({for_risk} for risk, {for_novelty} for novelty) in \
         {step} steps, {used} transitions; risk threshold {threshold:?} over {} risks",
        queries.len(),
        risks.len()
    );
    assert!(for_risk > 0);
    // The risk critic is in the snapshot of this run and in no other's.
    assert!(state.f32s("agent.risk_critic.net.params").is_ok());
    let other = tempfile::tempdir().unwrap();
    let (state, _, _) = stopped(&config("calibrated"), other.path());
    assert!(state.f32s("agent.risk_critic.net.params").is_err());
}

/// `arld train` with the thrifty rule on MountainCarContinuous-v0 asks within its budget; a task without a goal
/// (Pendulum-v1) and one of discrete actions refuse the rules that read the risk, with the reason.
#[test]
fn a_thrifty_run_asks_within_its_budget_and_tasks_without_a_goal_refuse_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let mut args: Vec<&str> = "train --env MountainCarContinuous-v0 --method adqn --expert scripted \
         --set query_rule=thrifty(alpha=0.05) --set train_steps=4000 --set budget=100 --set learning_starts=500 \
         --set eval_period=4000 --set eval_episodes=1 --set hidden=[32,32] --set batch_size=32 -o"
        .split_whitespace()
        .collect();
    args.push(out.to_str().unwrap());
    let res = arld(&args);
    assert_ran(&res);
    let summary = summary_of(&out);
    let queried = summary["demos_queried"].as_u64().unwrap();
    assert!(queried > 0 && queried <= 100, "{summary}");
    let answers = std::fs::read_to_string(out.join("answers.jsonl")).unwrap();
    assert_eq!(answers.lines().count() as u64, queried);
    for (env, rule, says) in [
        ("Pendulum-v1", "thrifty", "Pendulum-v1 has no goal"),
        ("Pendulum-v1", "risk(alpha=0.1)", "Pendulum-v1 has no goal"),
        ("CartPole-v0", "risk", "CartPole-v0 has discrete actions"),
    ] {
        let out = dir.path().join(format!("refused_{env}"));
        let set = format!("query_rule={rule}");
        let res = arld(&[
            "train",
            "--env",
            env,
            "--method",
            "adqn",
            "--set",
            &set,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(!res.status.success(), "{env} {rule} ran");
        let err = String::from_utf8_lossy(&res.stderr);
        assert!(err.contains(says) && err.contains("risk"), "{err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.join("summary.json").exists());
    }
}
