//! How the training loop treats an expert's answers: a question nobody answers goes back to the agent, is logged
//! as unanswered in queries.csv and costs no budget; answered questions record the expert's kind and response
//! time; an action out of range is an error, not a panic.

use anyhow::Result;
use arld::expert::{Answer, Expert, Person, Progress, Query};
use arld::train::{ConfigInput, Method, NetKind, RunBuilder, RunLog, TrainConfig};

/// Leaves every other opening question unanswered and answers everything else with action 1.
struct Flaky {
    openings: usize,
    answer: usize,
}

impl Expert for Flaky {
    fn act(&mut self, _obs: &[f32]) -> Result<usize> {
        Ok(self.answer)
    }
    fn describe(&self) -> String {
        "flaky:test".into()
    }
    fn answer(&mut self, query: &Query) -> Result<Answer> {
        if query.agent_action.is_some() {
            self.openings += 1;
            if self.openings % 2 == 1 {
                return Ok(Answer::Unanswered { waited_s: 1.5 });
            }
        }
        Ok(Answer::Action {
            action: self.answer,
            response_s: Some(0.25),
        })
    }
}

fn config(budget: usize) -> TrainConfig {
    let mut input = ConfigInput::new("CartPole-v0", Method::Gdqn, NetKind::Bootstrap, 3);
    for o in [
        format!("budget={budget}"),
        "train_steps=300".into(),
        "learning_starts=100".into(),
        "eval_period=300".into(),
        "eval_episodes=1".into(),
    ] {
        input.apply_override(&o).unwrap();
    }
    input.resolve().unwrap()
}

#[test]
fn unanswered_questions_cost_no_budget_and_are_logged() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(20);
    let mut log = RunLog::create(dir.path(), &cfg.to_toml(), 300, false).unwrap();
    let mut expert = Flaky {
        openings: 0,
        answer: 1,
    };
    let (summary, _) = RunBuilder::new(&cfg)
        .expert(Some(&mut expert))
        .train(&mut log)
        .unwrap();
    // Greedy queries ask until the budget is spent: 4 answered segments of 5 steps, each after a question that
    // went back to the agent (segments are cut by episode ends, so there may be more).
    assert_eq!(summary.demos_queried, 20);
    let text = std::fs::read_to_string(dir.path().join("queries.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "step,episode,uncertainty,threshold,expert_action,agent_action,expert,response_s,answered"
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), expert.openings);
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row[6], "flaky");
        if i % 2 == 0 {
            assert_eq!((row[4], row[7], row[8]), ("", "1.500", "false"), "row {i}");
        } else {
            assert_eq!((row[4], row[7], row[8]), ("1", "0.250", "true"), "row {i}");
        }
    }
    // The step after an unanswered question asks again (greedy): the agent acted on the question's step.
    let step = |r: &Vec<&str>| r[0].parse::<usize>().unwrap();
    assert_eq!(step(&rows[1]), step(&rows[0]) + 1);
    // Demonstrated steps in the episode log add up to the budget spent.
    let episodes = std::fs::read_to_string(dir.path().join("episodes.csv")).unwrap();
    let demo_steps: usize = episodes
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap().parse::<usize>().unwrap())
        .sum();
    assert!(demo_steps <= 20);
}

#[test]
fn an_answer_out_of_range_is_an_error() {
    let cfg = config(10);
    let mut log = RunLog::in_memory();
    let mut expert = Flaky {
        openings: 1,
        answer: 7,
    };
    let err = RunBuilder::new(&cfg)
        .expert(Some(&mut expert))
        .train(&mut log)
        .err()
        .expect("an out-of-range answer must fail the run");
    assert!(format!("{err:#}").contains("action 7"), "{err:#}");
}

#[test]
fn program_experts_report_their_kind_and_no_response_time() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(10);
    cfg.expert = "scripted".into();
    let mut log = RunLog::create(dir.path(), &cfg.to_toml(), 300, false).unwrap();
    let mut expert = arld::expert::from_spec("scripted", "CartPole-v0", 0, 30.0).unwrap();
    RunBuilder::new(&cfg)
        .expert(Some(expert.as_mut()))
        .train(&mut log)
        .unwrap();
    let text = std::fs::read_to_string(dir.path().join("queries.csv")).unwrap();
    for line in text.lines().skip(1) {
        let row: Vec<&str> = line.split(',').collect();
        assert_eq!((row[6], row[7], row[8]), ("scripted", "", "true"));
    }
    assert_eq!(
        arld::expert::from_spec("noisy:0.5:scripted", "CartPole-v0", 0, 30.0)
            .unwrap()
            .kind(),
        "noisy"
    );
}

#[test]
fn pre_training_from_a_web_expert_is_refused_up_front() {
    let mut input = ConfigInput::new("CartPole-v0", Method::Adqnp, NetKind::Bootstrap, 0);
    input.set("expert", "web").unwrap();
    let err = input
        .resolve()
        .expect_err("a person cannot give demonstrations before training");
    assert!(format!("{err:#}").contains("--demos"), "{err:#}");
    input.set("demo_file", "demos.jsonl").unwrap();
    assert!(input.resolve().is_ok());
}

/// Answers with action 0 and records, after every step, whether the step's uncertainty was computed.
struct Watching {
    shows: bool,
    computed: Vec<(usize, bool)>,
}

impl Expert for Watching {
    fn act(&mut self, _obs: &[f32]) -> Result<usize> {
        Ok(0)
    }
    fn describe(&self) -> String {
        "watching:test".into()
    }
    fn person(&mut self) -> Option<&mut dyn Person> {
        Some(self)
    }
}

impl Person for Watching {
    fn shows_uncertainty(&self) -> bool {
        self.shows
    }
    fn observe(&mut self, p: &Progress) {
        let in_segment = p.queries.expert_in_control();
        if !in_segment {
            self.computed.push((p.step, p.uncertainty.is_some()));
        }
    }
}

#[test]
fn an_expert_that_shows_the_uncertainty_sees_it_after_the_budget_is_spent() {
    let mut input = ConfigInput::new("CartPole-v0", Method::Adqn, NetKind::Bootstrap, 5);
    for o in [
        "budget=10",
        "train_steps=400",
        "learning_starts=100",
        "eval_period=400",
        "eval_episodes=1",
    ] {
        input.apply_override(o).unwrap();
    }
    let cfg = input.resolve().unwrap();
    for shows in [false, true] {
        let mut expert = Watching {
            shows,
            computed: Vec::new(),
        };
        let (summary, _) = RunBuilder::new(&cfg)
            .expert(Some(&mut expert))
            .train(&mut RunLog::in_memory())
            .unwrap();
        assert_eq!(summary.demos_queried, 10, "the budget is spent");
        let late: Vec<bool> = expert
            .computed
            .iter()
            .filter(|(s, _)| *s >= 350)
            .map(|(_, c)| *c)
            .collect();
        assert!(!late.is_empty());
        // A program's run computes no uncertainty once no rule reads it; a person's page gets it to the end.
        assert!(
            late.iter().all(|&c| c == shows),
            "shows_uncertainty = {shows}: {late:?}"
        );
    }
}

/// Answers the rule's questions with action 0; takes over unasked once, at the first step the agent is about to
/// act after step `at` was reported, answers action 1 for `hold` steps and hands back.
struct TakesOver {
    at: usize,
    hold: usize,
    last_step: usize,
    asked: bool,
    held: usize,
}

impl Person for TakesOver {
    fn observe(&mut self, p: &Progress) {
        self.last_step = p.step;
    }
    fn wants_control(&mut self) -> bool {
        let now = !self.asked && self.last_step >= self.at;
        self.asked |= now;
        now
    }
}

impl Expert for TakesOver {
    fn person(&mut self) -> Option<&mut dyn Person> {
        Some(self)
    }
    fn act(&mut self, _obs: &[f32]) -> Result<usize> {
        Ok(0)
    }
    fn describe(&self) -> String {
        "takes-over:test".into()
    }
    fn answer(&mut self, query: &Query) -> Result<Answer> {
        if !query.taken_over {
            return Ok(Answer::Action {
                action: 0,
                response_s: None,
            });
        }
        if self.held == self.hold {
            return Ok(Answer::Unanswered { waited_s: 0.0 });
        }
        self.held += 1;
        Ok(Answer::Action {
            action: 1,
            response_s: Some(0.5),
        })
    }
}

#[test]
fn a_takeover_is_charged_like_a_question_and_leaves_the_rule_alone() {
    let mut input = ConfigInput::new("CartPole-v0", Method::Adqn, NetKind::Bootstrap, 7);
    for o in [
        "budget=100",
        "train_steps=600",
        "learning_starts=100",
        "eval_period=600",
        "eval_episodes=1",
    ] {
        input.apply_override(o).unwrap();
    }
    let cfg = input.resolve().unwrap();
    let run = |at: usize| {
        let dir = tempfile::tempdir().unwrap();
        let mut log = RunLog::create(dir.path(), &cfg.to_toml(), 600, false).unwrap();
        let mut expert = TakesOver {
            at,
            hold: 3,
            last_step: 0,
            asked: false,
            held: 0,
        };
        let (summary, _) = RunBuilder::new(&cfg)
            .expert(Some(&mut expert))
            .train(&mut log)
            .unwrap();
        let read = |name: &str| std::fs::read_to_string(dir.path().join(name)).unwrap();
        (summary, read("queries.csv"), read("answers.jsonl"))
    };
    // No takeover (step 10^6 never comes): the run as it always was.
    let (plain, plain_queries, _) = run(1_000_000);
    let at = 150;
    let (summary, queries, answers) = run(at);
    let lines: Vec<serde_json::Value> = answers
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let person: Vec<&serde_json::Value> = lines
        .iter()
        .filter(|l| l["started_by"] == "person")
        .collect();
    // Three steps in a row from where the person took over, tied to the takeover (no threshold), with action 1.
    assert_eq!(person.len(), 3, "{answers}");
    let opened = person[0]["question_step"].as_u64().unwrap() as usize;
    assert!((at..at + 20).contains(&opened), "took over at {opened}");
    for (k, l) in person.iter().enumerate() {
        assert_eq!(l["step"].as_u64(), Some((opened + k) as u64));
        assert_eq!(l["question_step"].as_u64(), Some(opened as u64));
        assert_eq!(l["action"], 1);
        assert!(l["threshold"].is_null() && l["uncertainty"].is_number());
        assert_eq!(l["expert"], "takes-over");
        assert_eq!(l["response_s"], 0.5);
    }
    assert!(lines.iter().any(|l| l["started_by"] == "rule"));
    // Charged like answers: every demonstrated step is one unit of the budget.
    assert_eq!(summary.demos_queried, lines.len());
    // queries.csv holds the rule's questions only: up to the takeover, the same rows as the run without it (the
    // takeover's poll changed nothing before it), and no row at its step, the hand-back included.
    let steps = |csv: &str| -> Vec<usize> {
        csv.lines()
            .skip(1)
            .map(|l| l.split(',').next().unwrap().parse().unwrap())
            .collect()
    };
    let before = |csv: &str, at: usize| -> Vec<String> {
        csv.lines()
            .skip(1)
            .filter(|l| l.split(',').next().unwrap().parse::<usize>().unwrap() < at)
            .map(str::to_string)
            .collect()
    };
    assert_eq!(before(&queries, opened), before(&plain_queries, opened));
    assert!(
        !before(&queries, opened).is_empty(),
        "no question before the takeover"
    );
    assert!(!steps(&queries).contains(&opened));
    assert!(!steps(&queries).contains(&(opened + 3)));
    assert!(plain.demos_queried > 0);
}
