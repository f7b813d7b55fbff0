//! Sweeps and reports end to end with a fake, deterministic run function that writes the run-directory files
//! the training code writes (config.toml, eval.csv, episodes.csv, queries.csv, summary.json last).

use anyhow::{Result, bail};
use arld::lab::report;
use arld::lab::sweep::{self, RunSpec, SweepGrid};
use arld::train::run_dir::{self, EvalPoint, Summary};
use arld::train::{Method, NetKind};
use std::collections::BTreeSet;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

const TRAIN_STEPS: u64 = 10_000;
const EVAL_PERIOD: u64 = 1_000;

fn threshold(env: &str) -> f64 {
    match env {
        "CartPole-v0" => 195.0,
        "Acrobot-v1" => -100.0,
        "LunarLander-v2" => 200.0,
        _ => 0.0,
    }
}

/// The designed solve step of a fake run: seed 3 never solves; the others solve at (2 + seed + method index)k
/// steps, later for larger t_query values and some experts, so configurations differ; a designed step past the
/// end of training means the run never solves.
fn designed_solve_step(spec: &RunSpec) -> Option<u64> {
    if spec.id.seed == 3 {
        return None;
    }
    let method_index = [
        Method::Dqn,
        Method::Dqfd,
        Method::Gdqn,
        Method::Bdqn,
        Method::Adqn,
        Method::Adqnp,
    ]
    .iter()
    .position(|m| *m == spec.id.method)
    .unwrap() as u64;
    let t_query_shift = spec.t_query.map_or(0, |t| (t * 10.0) as u64);
    let expert_shift = spec.expert.as_deref().map_or(0, |e| match e {
        _ if e.contains("noisy") => 3,
        _ if e.contains("weak") => 1,
        _ => 0,
    });
    let step = EVAL_PERIOD * (2 + spec.id.seed + method_index + t_query_shift + expert_shift);
    (step <= TRAIN_STEPS).then_some(step)
}

fn fake_mean(spec: &RunSpec, step: u64) -> f64 {
    let target = threshold(&spec.id.env);
    match designed_solve_step(spec) {
        Some(solve) if step >= solve => target + 5.0 + spec.id.seed as f64,
        _ => target - 100.0 + step as f64 / 1000.0 + spec.id.seed as f64 * 0.25,
    }
}

/// Writes a complete fake run through the run-directory module, or, with `interrupt`, only the files a killed run
/// would have left.
fn write_fake_run(spec: &RunSpec, dir: &Path, interrupt: bool) -> Result<()> {
    let t_query = spec.t_query.unwrap_or(0.05);
    let expert = format!("{:?}", spec.expert.as_deref().unwrap_or("shipped:weak"));
    std::fs::write(
        dir.join(run_dir::CONFIG_FILE),
        format!(
            "env = \"{}\"\nmethod = \"{}\"\nnet = \"{}\"\nseed = {}\nt_query = {t_query}\nexpert = {expert}\n\
             train_steps = {TRAIN_STEPS}\neval_period = {EVAL_PERIOD}\ngamma = 0.9\n",
            spec.id.env, spec.id.method, spec.id.net, spec.id.seed
        ),
    )?;
    let last = if interrupt {
        3 * EVAL_PERIOD
    } else {
        TRAIN_STEPS
    };
    let curve: Vec<EvalPoint> = (EVAL_PERIOD..=last)
        .step_by(EVAL_PERIOD as usize)
        .map(|step| {
            let mean = fake_mean(spec, step);
            EvalPoint {
                step,
                mean,
                std: 1.5,
                min: mean - 3.0,
                max: mean + 3.0,
            }
        })
        .collect();
    run_dir::write_curve(dir, &curve)?;
    std::fs::write(
        dir.join(run_dir::EPISODES_FILE),
        format!("{}1,200,200,200,0\n", run_dir::EPISODES_HEADER),
    )?;
    let mut queries = String::from(run_dir::QUERIES_HEADER);
    if spec.id.method != Method::Dqn && spec.id.method != Method::Dqfd {
        for k in 0..(20 + spec.id.seed) {
            // Queries thin out over training; the uncertainty columns may be empty.
            let event = run_dir::QueryEvent {
                step: (k * k * 20) as usize,
                episode: (k / 5) as usize,
                uncertainty: None,
                threshold: None,
                expert_action: Some(1),
                agent_action: 0,
                expert: "checkpoint".into(),
                response_s: None,
                answered: true,
                started_by: run_dir::StartedBy::Rule,
                retried: 0,
            };
            queries.push_str(&event.csv_row());
        }
    }
    std::fs::write(dir.join(run_dir::QUERIES_FILE), queries)?;
    if interrupt {
        bail!("interrupted");
    }
    let solve = designed_solve_step(spec);
    run_dir::write_summary(
        dir,
        &Summary {
            env: spec.id.env.clone(),
            method: spec.id.method,
            net: spec.id.net,
            algo: None,
            seed: spec.id.seed,
            steps_to_solve: solve.unwrap_or(TRAIN_STEPS) as usize,
            solved: solve.is_some(),
            solve_threshold: threshold(&spec.id.env),
            train_steps: TRAIN_STEPS as usize,
            final_score: fake_mean(spec, TRAIN_STEPS),
            demos_pretrain: 0,
            demos_queried: 20,
            episodes: 1,
            wall_time_s: 0.1,
            cpu_time_s: None,
            steps_per_s: 1e5,
            numerics: Some(arld::math::NUMERICS.to_string()),
            arld_version: None,
            git_commit: None,
            expert: None,
            person_s: None,
        },
    )
}

fn small_grid() -> SweepGrid {
    SweepGrid {
        envs: vec!["CartPole-v0".into(), "Acrobot-v1".into()],
        methods: vec![Method::Dqn, Method::Adqn, Method::Dqfd],
        nets: vec![NetKind::Bootstrap],
        seeds: vec![0, 1, 2, 3],
        ..SweepGrid::default()
    }
}

fn data_rows(csv_text: &str) -> Vec<&str> {
    csv_text.lines().skip(1).collect()
}

#[test]
fn an_interrupted_sweep_resumes_to_the_same_results_as_an_uninterrupted_one() {
    let grid = small_grid();
    let total = grid.specs().unwrap().len();

    let uninterrupted = tempfile::tempdir().unwrap();
    let outcome = sweep::run_grid(&grid, uninterrupted.path(), 2, &|spec, dir| {
        write_fake_run(spec, dir, false)
    })
    .unwrap();
    assert_eq!(
        (outcome.total, outcome.completed, outcome.already_complete),
        (total, total, 0)
    );
    let expected = std::fs::read_to_string(uninterrupted.path().join(sweep::RESULTS_FILE)).unwrap();

    // First attempt: after 7 runs every further run is "killed", leaving partial files and no summary.json.
    let resumed = tempfile::tempdir().unwrap();
    let started = AtomicUsize::new(0);
    let interrupted = sweep::run_grid(&grid, resumed.path(), 2, &|spec, dir| {
        let n = started.fetch_add(1, Ordering::SeqCst);
        write_fake_run(spec, dir, n >= 7)
    });
    let message = format!("{:#}", interrupted.unwrap_err());
    assert!(
        message.contains(&format!("{} of {total} runs failed", total - 7)),
        "{message}"
    );
    let partial = std::fs::read_to_string(resumed.path().join(sweep::RESULTS_FILE)).unwrap();
    assert_eq!(
        data_rows(&partial).len(),
        7 * 10,
        "only complete runs are collected"
    );

    // Second attempt: only the missing runs are performed, and their partial directories are cleared first.
    let calls = AtomicUsize::new(0);
    let outcome = sweep::run_grid(&grid, resumed.path(), 2, &|spec, dir| {
        calls.fetch_add(1, Ordering::SeqCst);
        assert_eq!(
            std::fs::read_dir(dir)?.count(),
            0,
            "the run directory is empty when a run starts"
        );
        write_fake_run(spec, dir, false)
    })
    .unwrap();
    assert_eq!(calls.load(Ordering::SeqCst), total - 7);
    assert_eq!(
        (outcome.already_complete, outcome.completed),
        (7, total - 7)
    );

    let actual = std::fs::read_to_string(resumed.path().join(sweep::RESULTS_FILE)).unwrap();
    assert_eq!(actual, expected);
    let rows = data_rows(&actual);
    assert_eq!(rows.len(), total * (TRAIN_STEPS / EVAL_PERIOD) as usize);
    assert_eq!(
        rows.iter().collect::<BTreeSet<_>>().len(),
        rows.len(),
        "no duplicate rows"
    );

    // Collecting again (e.g. `arld report` after the sweep) rewrites the same file.
    sweep::collect_results(resumed.path()).unwrap();
    assert_eq!(
        std::fs::read_to_string(resumed.path().join(sweep::RESULTS_FILE)).unwrap(),
        expected
    );
    // The recorded grid reads back as the grid that ran.
    let recorded = SweepGrid::from_toml_file(&resumed.path().join(sweep::SWEEP_FILE)).unwrap();
    assert_eq!(recorded, grid);
}

#[test]
fn results_rows_match_each_runs_eval_csv_in_sorted_order() {
    let grid = small_grid();
    let dir = tempfile::tempdir().unwrap();
    sweep::run_grid(&grid, dir.path(), 1, &|spec, dir| {
        write_fake_run(spec, dir, false)
    })
    .unwrap();
    let text = std::fs::read_to_string(dir.path().join(sweep::RESULTS_FILE)).unwrap();
    assert_eq!(
        text.lines().next().unwrap(),
        "env,method,net,variant,seed,step,mean,std,min,max"
    );
    // Independent expectation: rebuild every row from the design and sort it the same way.
    let mut expected = Vec::new();
    for spec in grid.specs().unwrap() {
        for step in (EVAL_PERIOD..=TRAIN_STEPS).step_by(EVAL_PERIOD as usize) {
            let mean = fake_mean(&spec, step);
            let key = (
                spec.id.env.clone(),
                spec.id.method.to_string(),
                spec.id.net.to_string(),
                spec.id.seed,
                step,
            );
            expected.push((
                key,
                format!(
                    "{},{},{},default,{},{step},{mean},1.5,{},{}",
                    spec.id.env,
                    spec.id.method,
                    spec.id.net,
                    spec.id.seed,
                    mean - 3.0,
                    mean + 3.0
                ),
            ));
        }
    }
    expected.sort();
    let expected: Vec<String> = expected.into_iter().map(|(_, row)| row).collect();
    assert_eq!(data_rows(&text), expected);
}

#[test]
fn failing_and_panicking_runs_are_reported_without_stopping_the_others() {
    let grid = SweepGrid {
        envs: vec!["CartPole-v0".into()],
        ..small_grid()
    };
    let dir = tempfile::tempdir().unwrap();
    let result = sweep::run_grid(&grid, dir.path(), 2, &|spec, dir| {
        match (spec.id.method, spec.id.seed) {
            (Method::Adqn, 1) => panic!("simulated bug"),
            (Method::Dqn, 2) => Ok(()), // returns without summary.json
            _ => write_fake_run(spec, dir, false),
        }
    });
    let message = format!("{:#}", result.unwrap_err());
    assert!(message.contains("2 of 12 runs failed"), "{message}");
    assert!(
        message.contains("adqn-bootstrap/seed1") && message.contains("simulated bug"),
        "{message}"
    );
    assert!(
        message.contains("dqn-bootstrap/seed2") && message.contains("summary.json"),
        "{message}"
    );
    let (runs, _) = run_dir::load_runs(dir.path()).unwrap();
    assert_eq!(runs.len(), 10);
}

#[test]
fn malformed_sweep_files_give_clear_errors() {
    let error = |text: &str| format!("{:#}", SweepGrid::from_toml_str(text).unwrap_err());
    let base = "envs = [\"CartPole-v0\"]\nmethods = [\"adqn\"]\nnets = [\"noisy\"]\nseeds = 2\n";

    let unknown = error(&format!("[sweep]\n{base}tquery = [0.1]\n"));
    assert!(
        unknown.contains("tquery") && unknown.contains("t_query") && unknown.contains("experts"),
        "{unknown}"
    );
    let outside = error(&format!("[sweeep]\n{base}"));
    assert!(
        outside.contains("sweeep") && outside.contains("[sweep]"),
        "{outside}"
    );
    let missing = error("[sweep]\nenvs = [\"CartPole-v0\"]\nmethods = [\"adqn\"]\nseeds = 2\n");
    assert!(missing.contains("nets"), "{missing}");
    let method = error(
        &base
            .replace("adqn", "adqm")
            .replace("envs", "[sweep]\nenvs"),
    );
    assert!(
        method.contains("adqm") && method.contains("adqnp"),
        "{method}"
    );
    let seeds = error(&format!(
        "[sweep]\n{}",
        base.replace("seeds = 2", "seeds = \"many\"")
    ));
    assert!(seeds.contains("seeds"), "{seeds}");
    let t_query = error(&format!("[sweep]\n{base}t_query = [1.5]\n"));
    assert!(t_query.contains("t_query"), "{t_query}");
    let clash = error(&format!(
        "[sweep]\n{base}t_query = [0.1]\nset = [\"t_query=0.3\"]\n"
    ));
    assert!(clash.contains("t_query=0.3"), "{clash}");
    let syntax = error("[sweep\nenvs = 1");
    assert!(syntax.contains("invalid sweep file"), "{syntax}");
}

fn report_fixture(dir: &Path) {
    // Table 5 and figures 1/2 (bootstrap only), a t_query study and an expert study: each in its own sub-sweep,
    // as `arld reproduce` lays them out.
    let methods = SweepGrid {
        envs: vec!["CartPole-v0".into(), "Acrobot-v1".into()],
        methods: vec![Method::Dqn, Method::Gdqn, Method::Adqn, Method::Dqfd],
        nets: vec![NetKind::Bootstrap],
        seeds: vec![0, 1, 2, 3],
        ..SweepGrid::default()
    };
    let t_query = SweepGrid {
        envs: vec!["CartPole-v0".into()],
        methods: vec![Method::Adqn],
        nets: vec![NetKind::Bootstrap],
        seeds: vec![0, 1, 2],
        t_query: vec![0.05, 0.1, 0.3, 0.5],
        ..SweepGrid::default()
    };
    let experts = SweepGrid {
        envs: vec!["LunarLander-v2".into()],
        methods: vec![Method::Adqn, Method::Dqfd],
        nets: vec![NetKind::Bootstrap],
        seeds: vec![0, 1, 2],
        experts: vec![
            "shipped:perfect".into(),
            "noisy:0.4:shipped:perfect".into(),
            "shipped:weak".into(),
        ],
        ..SweepGrid::default()
    };
    let run_fn = |spec: &RunSpec, dir: &Path| write_fake_run(spec, dir, false);
    sweep::run_grid(&methods, &dir.join("methods"), 2, &run_fn).unwrap();
    sweep::run_grid(&t_query, &dir.join("t_query"), 2, &run_fn).unwrap();
    sweep::run_grid(&experts, &dir.join("experts"), 2, &run_fn).unwrap();
}

#[test]
fn report_writes_table_with_paper_values_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    report_fixture(dir.path());
    let out = dir.path().join("report");
    let summary = report::report(dir.path(), &out, arld::lab::verdict::DEFAULT_SUSTAIN).unwrap();
    // To look at the figures: ARLD_TEST_KEEP_REPORT=/some/dir cargo test --test experiment_sweep report_writes
    if let Ok(keep) = std::env::var("ARLD_TEST_KEEP_REPORT") {
        std::fs::create_dir_all(&keep).unwrap();
        for entry in std::fs::read_dir(&out).unwrap() {
            let entry = entry.unwrap();
            std::fs::copy(entry.path(), Path::new(&keep).join(entry.file_name())).unwrap();
        }
    }
    assert_eq!(summary.runs, 4 * 2 * 4 + 4 * 3 + 2 * 3 * 3);

    // Median steps to solve of ADQN-B on CartPole: seeds 0..2 solve at (2 + seed + 4)k, seed 3 never (10k):
    // sorted 6k 7k 8k 10k, median (7k + 8k) / 2.
    let table_csv = std::fs::read_to_string(out.join("table.csv")).unwrap();
    let mut reader = csv::Reader::from_reader(table_csv.as_bytes());
    let headers = reader.headers().unwrap().clone();
    let column = |name: &str| headers.iter().position(|h| h == name).unwrap();
    let adqn_b = reader
        .records()
        .map(|r| r.unwrap())
        .find(|r| &r[0] == "adqn" && &r[1] == "bootstrap")
        .unwrap();
    assert_eq!(&adqn_b[column("CartPole-v0 ours")], "7500");
    assert_eq!(&adqn_b[column("CartPole-v0 paper")], "7000");
    assert_eq!(&adqn_b[column("CartPole-v0 seeds")], "4");
    assert_eq!(&adqn_b[column("CartPole-v0 solved")], "3");
    assert_eq!(&adqn_b[column("Acrobot-v1 paper")], "25000");
    let table_md = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(
        table_md.contains("| ADQN-B | 7500 (7000) 3/4 |"),
        "{table_md}"
    );
    assert!(
        table_md.contains("| ADQNP-B | - (6000) | - (49000) |"),
        "{table_md}"
    );
    // DQN (method index 0) solves first in the design, so it is the bold best of the -B group.
    assert!(
        table_md.contains("| DQN-B | **3500** (8000) 3/4 | **3500** (57000) 3/4 |"),
        "{table_md}"
    );

    // Figures present for what ran, skipped with a note for what did not.
    for name in [
        "fig1_methods_bootstrap",
        "fig2_pretraining_bootstrap",
        "fig3_t_query_bootstrap",
        "fig4_experts_bootstrap",
        "fig5_queries_bootstrap",
    ] {
        let png = std::fs::read(out.join(format!("{name}.png"))).unwrap();
        assert!(
            png.len() > 10_000 && png.starts_with(b"\x89PNG\r\n\x1a\n"),
            "{name}.png"
        );
        let svg = std::fs::read_to_string(out.join(format!("{name}.svg"))).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.contains("environment steps"),
            "{name}.svg"
        );
    }
    assert!(!out.join("fig1_methods_noisy.png").exists());
    assert!(
        summary
            .notes
            .iter()
            .any(|n| n.contains("fig1_methods_noisy skipped")),
        "{:?}",
        summary.notes
    );
    let report_md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        report_md.contains("fig3_t_query_bootstrap.png")
            && report_md.contains("fig4_experts_noisy skipped")
    );
    // The t_query variants are told apart in the full list.
    assert!(
        report_md.contains("| CartPole-v0 | ADQN | bootstrap | tq0.3 |"),
        "{report_md}"
    );
    // No temporary files are left behind.
    assert!(
        std::fs::read_dir(&out).unwrap().all(|e| !e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .starts_with('.'))
    );
}

#[test]
fn group_medians_follow_the_design_for_every_configuration() {
    let dir = tempfile::tempdir().unwrap();
    report_fixture(dir.path());
    let (runs, notes) = run_dir::load_runs(dir.path()).unwrap();
    assert!(notes.is_empty(), "{notes:?}");
    for group in arld::lab::verdict::cells(&runs, arld::lab::verdict::DEFAULT_SUSTAIN) {
        // Rebuild the specs of this group and compute the median by hand from the designed solve steps.
        let mut steps: Vec<u64> = runs
            .iter()
            .filter(|r| {
                r.id.env == group.env
                    && r.id.method.name() == group.method
                    && r.id.net.name() == group.net
                    && r.variant == group.variant
            })
            .map(|r| {
                let spec = RunSpec {
                    id: r.id.clone(),
                    t_query: r.config.t_query.filter(|_| r.variant.starts_with("tq")),
                    expert: r
                        .config
                        .expert
                        .clone()
                        .filter(|_| r.variant.starts_with("expert")),
                    set: vec![],
                    vary: None,
                };
                designed_solve_step(&spec).unwrap_or(TRAIN_STEPS)
            })
            .collect();
        steps.sort();
        let n = steps.len();
        let expected = if n % 2 == 1 {
            steps[n / 2] as f64
        } else {
            (steps[n / 2 - 1] + steps[n / 2]) as f64 / 2.0
        };
        assert_eq!(
            group.first_hit.median, expected,
            "{} {} {} {}",
            group.env, group.method, group.net, group.variant
        );
    }
    // summary.json and eval.csv agree on every fake run, so the report raises no disagreement.
    let out = dir.path().join("report");
    let summary = report::report(dir.path(), &out, arld::lab::verdict::DEFAULT_SUSTAIN).unwrap();
    assert!(
        !summary
            .notes
            .iter()
            .any(|n| n.contains("summary.json says")),
        "{:?}",
        summary.notes
    );
}

#[test]
fn report_skips_damaged_runs_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let grid = SweepGrid {
        envs: vec!["CartPole-v0".into()],
        methods: vec![Method::Dqn],
        ..small_grid()
    };
    sweep::run_grid(&grid, dir.path(), 1, &|spec, dir| {
        write_fake_run(spec, dir, false)
    })
    .unwrap();
    let damaged = dir.path().join("CartPole-v0/dqn-bootstrap/seed2/eval.csv");
    std::fs::write(&damaged, "step,mean,std,min,max\n1000,oops,1,2,3\n").unwrap();
    let (runs, notes) = run_dir::load_runs(dir.path()).unwrap();
    assert_eq!(runs.len(), 3);
    assert!(notes.len() == 1 && notes[0].contains("seed2"), "{notes:?}");
    let curve: Vec<EvalPoint> = runs[0].eval.clone();
    assert_eq!(curve.len(), 10);
}

#[test]
fn runs_start_seed_by_seed_and_a_sweep_directory_keeps_its_overrides() {
    let grid = small_grid();
    let dir = tempfile::tempdir().unwrap();
    let order = std::sync::Mutex::new(Vec::new());
    sweep::run_grid(&grid, dir.path(), 1, &|spec, run_dir| {
        order.lock().unwrap().push(spec.id.seed);
        write_fake_run(spec, run_dir, false)
    })
    .unwrap();
    let order = order.into_inner().unwrap();
    let mut sorted = order.clone();
    sorted.sort();
    assert_eq!(
        order, sorted,
        "with one job, all runs of seed 0 come before any run of seed 1, ..."
    );

    // Extending the sweep with more seeds is fine; changing its overrides is refused.
    let more_seeds = SweepGrid {
        seeds: vec![0, 1, 2, 3, 4],
        ..grid.clone()
    };
    let outcome = sweep::run_grid(&more_seeds, dir.path(), 1, &|s, d| {
        write_fake_run(s, d, false)
    })
    .unwrap();
    assert_eq!((outcome.already_complete, outcome.completed), (24, 6));
    let changed = SweepGrid {
        set: vec!["gamma=0.5".into()],
        ..more_seeds
    };
    let error = sweep::run_grid(&changed, dir.path(), 1, &|_, _| unreachable!()).unwrap_err();
    assert!(format!("{error:#}").contains("gamma=0.5"), "{error:#}");
}

/// A complete run of an older arld (its summary has no `numerics`: the C library's elementary functions) is run
/// again by the next sweep, and is not taken as the source of an identical variant's files; current runs are not.
#[test]
fn runs_of_the_c_librarys_elementary_functions_are_run_again() {
    let grid = small_grid();
    let total = grid.specs().unwrap().len();
    let dir = tempfile::tempdir().unwrap();
    sweep::run_grid(&grid, dir.path(), 2, &|spec, d| {
        write_fake_run(spec, d, false)
    })
    .unwrap();
    let specs = grid.specs().unwrap();
    let old = dir.path().join(specs[3].dir_name());
    let summary_path = old.join(run_dir::SUMMARY_FILE);
    let mut summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary_path).unwrap()).unwrap();
    summary.as_object_mut().unwrap().remove("numerics").unwrap();
    std::fs::write(&summary_path, serde_json::to_string(&summary).unwrap()).unwrap();
    assert!(run_dir::is_stale(&old));

    let rerun = std::sync::Mutex::new(Vec::new());
    let outcome = sweep::run_grid(&grid, dir.path(), 2, &|spec, d| {
        rerun.lock().unwrap().push(d.to_path_buf());
        write_fake_run(spec, d, false)
    })
    .unwrap();
    assert_eq!(rerun.into_inner().unwrap(), vec![old.clone()]);
    assert_eq!(
        (outcome.already_complete, outcome.completed),
        (total - 1, 1)
    );
    assert!(
        !run_dir::is_stale(&old),
        "the run again says how it computed"
    );
}

/// An interrupted run whose snapshot an older arld wrote (no `numerics` in its header) starts again from a clean
/// directory; one whose snapshot this arld wrote is left for the run to resume.
#[test]
fn snapshots_of_the_c_librarys_elementary_functions_are_not_resumed() {
    let grid = small_grid();
    let specs = grid.specs().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let snapshot = |numerics: Option<&str>| {
        let mut meta = serde_json::json!({"format": "1"});
        if let Some(n) = numerics {
            meta["numerics"] = n.into();
        }
        let mut header = serde_json::to_vec(&serde_json::json!({ "__metadata__": meta })).unwrap();
        header.resize(header.len().next_multiple_of(8), b' ');
        let mut bytes = (header.len() as u64).to_le_bytes().to_vec();
        bytes.extend(header);
        bytes
    };
    let (old, current) = (
        dir.path().join(specs[0].dir_name()),
        dir.path().join(specs[1].dir_name()),
    );
    for (run, numerics) in [(&old, None), (&current, Some(arld::math::NUMERICS))] {
        std::fs::create_dir_all(run).unwrap();
        std::fs::write(
            run.join(arld::train::snapshot::SNAPSHOT_FILE),
            snapshot(numerics),
        )
        .unwrap();
        std::fs::write(run.join("marker"), b"").unwrap();
    }
    assert!(arld::train::snapshot::is_stale(&old));
    assert!(!arld::train::snapshot::is_stale(&current));
    let outcome = sweep::run_grid(&grid, dir.path(), 1, &|spec, d| {
        if d == old {
            assert!(
                !d.join("marker").exists(),
                "the old snapshot's directory is cleared"
            );
        }
        if d == current {
            assert!(
                d.join("marker").exists(),
                "the current snapshot is kept to resume"
            );
        }
        write_fake_run(spec, d, false)
    });
    let outcome = outcome.unwrap();
    assert_eq!(outcome.completed, outcome.total);
}
