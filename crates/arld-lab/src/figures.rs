//! The paper's figures: which figures a report draws and what goes into them, built from run records.
//!
//! - [`median_curve`] and [`questions_so_far`] reduce the runs of one configuration to a [`Band`] per step: the
//!   median over seeds (the paper plots medians, docs/algorithm.md section 11) and the interquartile range.
//! - [`paper_figures`] selects runs for each figure of the paper's Section 4 and builds a [`FigureContent`]
//!   (one panel per environment, one line per method or setting), or says why a figure is skipped;
//!   [`super::plot`] draws it.

use super::plot::{Band, Curve, FigureContent, PALETTE, Panel, XScale};
use super::protocol::{self, env_order};
use super::stats::quantile;
use arld_core::paper::TABLE5_METHODS;
use arld_core::train::run_dir::{DEFAULT_VARIANT, EXPERT_VARIANT_PREFIX, RunRecord};
use arld_core::train::{Method, NetKind};
use std::collections::BTreeMap;

#[derive(Debug, Clone)]
pub struct PaperFigure {
    pub name: String,
    pub content: Option<FigureContent>,
    pub skip_reason: String,
}

/// A method's colour: its index in [`TABLE5_METHODS`], so a method keeps its colour across figures.
fn method_color(method: Method) -> usize {
    TABLE5_METHODS
        .iter()
        .position(|m| *m == method.name())
        .unwrap_or(6)
}

/// Median and quartiles over the given values of each x, in x order.
fn bands(per_x: BTreeMap<u64, Vec<f64>>) -> Vec<Band> {
    per_x
        .into_iter()
        .filter_map(|(x, values)| {
            Some(Band {
                x: x as f64,
                median: quantile(&values, 0.5)?,
                lower_quartile: quantile(&values, 0.25)?,
                upper_quartile: quantile(&values, 0.75)?,
            })
        })
        .collect()
}

/// Median learning curve over runs (seeds): at each evaluation step, the median and quartiles of the seeds'
/// mean test returns. A step only some seeds reached is summarised over those seeds.
pub fn median_curve(runs: &[&RunRecord]) -> Vec<Band> {
    let mut per_step: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    for run in runs {
        for point in &run.eval {
            per_step.entry(point.step).or_default().push(point.mean);
        }
    }
    bands(per_step)
}

/// Points per tenfold of steps in [`questions_so_far`].
const POINTS_PER_DECADE: u32 = 20;

/// Questions asked so far against training step, median and quartiles over the runs that logged queries: at
/// steps 10^(1 + k/20) (and the last step of training) each run counts its questions at steps up to there. The x
/// of a point is log10 of its step ([`XScale::Log10Steps`]): the questions of every method fall in the first few
/// percent of a run, which a linear axis shows as one vertical line.
pub fn questions_so_far(runs: &[&RunRecord]) -> Vec<Band> {
    let logged: Vec<&Vec<u64>> = runs.iter().filter_map(|r| r.query_steps.as_ref()).collect();
    let Some(last) = runs
        .iter()
        .filter(|r| r.query_steps.is_some())
        .map(|r| r.train_steps)
        .max()
    else {
        return Vec::new();
    };
    let mut at: Vec<u64> = (0..)
        .map(|k| {
            10f64
                .powf(1.0 + f64::from(k) / f64::from(POINTS_PER_DECADE))
                .round() as u64
        })
        .take_while(|&step| step < last)
        .collect();
    at.dedup();
    at.push(last);
    let mut per_step: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    for queries in logged {
        for &step in &at {
            let asked = queries.iter().filter(|&&q| q <= step).count();
            per_step.entry(step).or_default().push(asked as f64);
        }
    }
    let mut points = bands(per_step);
    for point in &mut points {
        point.x = point.x.log10();
    }
    points
}

/// The curve of the runs of `pool` that `member` selects, summarised by `reduce`; `None` when it selects none.
fn curve(
    pool: &[&RunRecord],
    member: impl Fn(&RunRecord) -> bool,
    label: String,
    color: usize,
    reduce: fn(&[&RunRecord]) -> Vec<Band>,
) -> Option<Curve> {
    let group: Vec<&RunRecord> = pool.iter().copied().filter(|r| member(r)).collect();
    (!group.is_empty()).then(|| Curve {
        label,
        color,
        points: reduce(&group),
    })
}

/// Readable legend text for an expert spec of the expert-quality study.
fn expert_label(spec: &str) -> String {
    match spec {
        "shipped:perfect" => "perfect expert".to_string(),
        "shipped:weak" => "weak (snapshot) expert".to_string(),
        other => match other
            .strip_prefix("noisy:")
            .and_then(|rest| rest.split_once(':'))
        {
            Some((p, inner)) if p.parse::<f64>().is_ok() => {
                format!(
                    "{} + {}% random actions",
                    expert_label(inner),
                    (p.parse::<f64>().unwrap_or(0.0) * 100.0).round()
                )
            }
            _ => other.to_string(),
        },
    }
}

fn net_words(net: NetKind) -> (&'static str, &'static str) {
    match net {
        NetKind::Bootstrap => ("bootstrapped", "B"),
        NetKind::Noisy => ("noisy", "N"),
        NetKind::Plain => ("plain", "P"),
    }
}

const RETURN_LABEL: &str = "mean test return (20 episodes)";
const STEPS_LABEL: &str = "environment steps";

/// Panels per environment, one curve per method, for the default-variant runs of `methods` among `runs` (one
/// network's).
fn methods_figure(runs: &[&RunRecord], methods: &[Method], title: String) -> Option<FigureContent> {
    let selected: Vec<&RunRecord> = runs
        .iter()
        .copied()
        .filter(|r| r.variant == DEFAULT_VARIANT && methods.contains(&r.id.method))
        .collect();
    let panels = env_panels(&selected, true, |in_env| {
        method_curves(in_env, methods, median_curve)
    });
    steps_figure(title, RETURN_LABEL, panels)
}

/// One panel per environment of `selected`, in the paper's order, with the curves `curves` draws from the
/// environment's runs, and the task's solve threshold when `threshold`.
fn env_panels(
    selected: &[&RunRecord],
    threshold: bool,
    curves: impl Fn(&[&RunRecord]) -> Vec<Curve>,
) -> Vec<Panel> {
    env_order(selected.iter().map(|r| r.id.env.as_str()))
        .iter()
        .map(|env| {
            let in_env: Vec<&RunRecord> = selected
                .iter()
                .copied()
                .filter(|r| &r.id.env == env)
                .collect();
            let solve = in_env.first().map(|r| r.solve_threshold);
            Panel::new(env.clone(), solve.filter(|_| threshold), curves(&in_env))
        })
        .collect()
}

/// A curve per method of `methods` that has runs among `runs`, summarised by `reduce`.
fn method_curves(
    runs: &[&RunRecord],
    methods: &[Method],
    reduce: fn(&[&RunRecord]) -> Vec<Band>,
) -> Vec<Curve> {
    methods
        .iter()
        .filter_map(|method| {
            curve(
                runs,
                |r| r.id.method == *method,
                method.paper_name(),
                method_color(*method),
                reduce,
            )
        })
        .collect()
}

/// One median curve per value of a varied setting (`values`, in legend order) that has runs among `runs`:
/// `has(run, value)` tells a run's value, `label` the legend text, and the i-th value takes colour `colors[i]`.
fn setting_curves<T>(
    runs: &[&RunRecord],
    values: &[T],
    has: impl Fn(&RunRecord, &T) -> bool,
    label: impl Fn(&T) -> String,
    colors: [usize; PALETTE.len()],
) -> Vec<Curve> {
    values
        .iter()
        .enumerate()
        .filter_map(|(i, value)| {
            curve(
                runs,
                |r| has(r, value),
                label(value),
                colors[i % PALETTE.len()],
                median_curve,
            )
        })
        .collect()
}

/// A figure of `panels` over environment steps with the given title and y label; `None` without panels (the
/// figure's runs are absent).
fn steps_figure(title: String, y_label: &str, panels: Vec<Panel>) -> Option<FigureContent> {
    (!panels.is_empty()).then(|| FigureContent {
        title,
        x_label: STEPS_LABEL.to_string(),
        x_scale: XScale::Steps,
        y_label: y_label.to_string(),
        panels,
    })
}

/// ADQN runs of the t_query study (variant `tqVALUE`): panels per environment, one curve per value of t_query
/// (as each run's configuration records it).
fn t_query_figure(runs: &[&RunRecord], title: String) -> Option<FigureContent> {
    let t_query = RunRecord::t_query_study;
    let selected: Vec<&RunRecord> = runs
        .iter()
        .copied()
        .filter(|r| r.id.method == Method::Adqn && t_query(r).is_some())
        .collect();
    let mut values: Vec<f64> = selected.iter().filter_map(|r| t_query(r)).collect();
    values.sort_by(f64::total_cmp);
    values.dedup();
    let panels = env_panels(&selected, true, |in_env| {
        setting_curves(
            in_env,
            &values,
            |r, value| t_query(r) == Some(*value),
            |value| format!("t_query = {value}"),
            [4, 3, 5, 1, 6, 2, 0, 7],
        )
    });
    steps_figure(title, RETURN_LABEL, panels)
}

/// ADQN and DQfD runs of the expert-quality study (variant `expert-...`): a panel per (environment, method),
/// one curve per expert.
fn expert_figure(runs: &[&RunRecord], suffix: &str, title: String) -> Option<FigureContent> {
    let selected: Vec<&RunRecord> = runs
        .iter()
        .copied()
        .filter(|r| r.id.method == Method::Adqn || r.id.method == Method::Dqfd)
        .filter(|r| r.variant.starts_with(EXPERT_VARIANT_PREFIX) && !r.variant.contains('_'))
        .collect();
    // Legend order and colours follow the paper's order of experts; unknown specs come after, alphabetically.
    let mut experts: Vec<String> = selected
        .iter()
        .map(|r| r.config.expert.clone().unwrap_or_else(|| r.variant.clone()))
        .collect();
    experts.sort_by_key(|e| {
        (
            protocol::EXPERT_QUALITY_SPECS
                .iter()
                .position(|s| s == e)
                .unwrap_or(usize::MAX),
            e.clone(),
        )
    });
    experts.dedup();
    let envs = env_order(selected.iter().map(|r| r.id.env.as_str()));
    let mut panels = Vec::new();
    for env in &envs {
        for method in [Method::Adqn, Method::Dqfd] {
            let in_panel: Vec<&RunRecord> = selected
                .iter()
                .copied()
                .filter(|r| &r.id.env == env && r.id.method == method)
                .collect();
            if in_panel.is_empty() {
                continue;
            }
            let curves = setting_curves(
                &in_panel,
                &experts,
                |r, expert| r.config.expert.as_ref().unwrap_or(&r.variant) == expert,
                |expert| expert_label(expert),
                [4, 1, 3, 5, 6, 2, 0, 7],
            );
            panels.push(Panel::new(
                format!("{env}: {}-{suffix}", method.paper_name()),
                in_panel.first().map(|r| r.solve_threshold),
                curves,
            ));
        }
    }
    steps_figure(title, RETURN_LABEL, panels)
}

/// Questions asked so far for the querying methods (default variant) on a logarithmic step axis, one panel per
/// environment.
fn query_figure(runs: &[&RunRecord], title: String) -> Option<FigureContent> {
    let methods = [Method::Gdqn, Method::Bdqn, Method::Adqn, Method::Adqnp];
    let selected: Vec<&RunRecord> = runs
        .iter()
        .copied()
        .filter(|r| r.variant == DEFAULT_VARIANT && methods.contains(&r.id.method))
        .filter(|r| r.query_steps.is_some())
        .collect();
    let panels = env_panels(&selected, false, |in_env| {
        method_curves(in_env, &methods, questions_so_far)
    });
    let mut figure = steps_figure(
        title,
        "questions asked so far (median, IQR over seeds)",
        panels,
    )?;
    figure.x_scale = XScale::Log10Steps;
    figure.x_label = "environment steps (log scale)".into();
    Some(figure)
}

/// The paper's figures built from `runs`, in the paper's order, each for bootstrapped and noisy nets:
/// `fig1_methods_*` (DQN, GDQN, BDQN, ADQN), `fig2_pretraining_*` (DQfD, ADQN, ADQNP), `fig3_t_query_*`,
/// `fig4_experts_*`, and `fig5_queries_*` (a query timeline, not in the paper).
pub fn paper_figures(runs: &[RunRecord]) -> Vec<PaperFigure> {
    let mut figures = Vec::new();
    for net in [NetKind::Bootstrap, NetKind::Noisy] {
        let (words, suffix) = net_words(net);
        let runs: Vec<&RunRecord> = runs.iter().filter(|r| r.id.net == net).collect();
        let mut push = |name: String, content: Option<FigureContent>, missing: String| {
            let skip_reason = if content.is_some() {
                String::new()
            } else {
                missing
            };
            figures.push(PaperFigure {
                name,
                content,
                skip_reason,
            });
        };
        push(
            format!("fig1_methods_{net}"),
            methods_figure(
                &runs,
                &[Method::Dqn, Method::Gdqn, Method::Bdqn, Method::Adqn],
                format!("Comparison between methods with {words} DQN (-{suffix})"),
            ),
            format!("no complete default-variant run of DQN, GDQN, BDQN or ADQN with net = {net}"),
        );
        push(
            format!("fig2_pretraining_{net}"),
            methods_figure(
                &runs,
                &[Method::Dqfd, Method::Adqn, Method::Adqnp],
                format!("ADQN, DQfD and ADQNP based on {words} DQN (-{suffix})"),
            ),
            format!("no complete default-variant run of DQfD, ADQN or ADQNP with net = {net}"),
        );
        push(
            format!("fig3_t_query_{net}"),
            t_query_figure(
                &runs,
                format!("ADQN-{suffix} with t_query in {{0.05, 0.1, 0.3, 0.5}} ({words} DQN)"),
            ),
            format!("no complete ADQN run of a t_query sweep (variant tqVALUE) with net = {net}"),
        );
        push(
            format!("fig4_experts_{net}"),
            expert_figure(
                &runs,
                suffix,
                format!(
                    "Effect of the expert's quality on ADQN-{suffix} and DQfD-{suffix} ({words} DQN)"
                ),
            ),
            format!(
                "no complete ADQN or DQfD run of an expert sweep (variant expert-...) with net = {net}"
            ),
        );
        push(
            format!("fig5_queries_{net}"),
            query_figure(
                &runs,
                format!("When the agent asks: questions asked so far (-{suffix}, {words} DQN)"),
            ),
            format!(
                "no complete default-variant run of a querying method with a queries.csv and net = {net}"
            ),
        );
    }
    figures.sort_by(|a, b| a.name.cmp(&b.name));
    figures
}

#[cfg(test)]
mod tests {
    use super::*;
    use arld_core::train::run_dir::{EvalPoint, RunId};
    use std::path::PathBuf;

    fn run(seed: u64, means: &[f64], queries: Option<Vec<u64>>) -> RunRecord {
        let id = RunId {
            env: "CartPole-v0".into(),
            method: Method::Adqn,
            net: NetKind::Bootstrap,
            seed,
        };
        let eval = EvalPoint::constant_curve(1000, means);
        let dir = PathBuf::from(format!("seed{seed}"));
        RunRecord {
            query_steps: queries,
            ..RunRecord::from_curve(dir, id, DEFAULT_VARIANT.into(), eval, 195.0, (3000, 1000))
        }
    }

    #[test]
    fn median_curve_takes_per_step_median_and_quartiles_over_seeds() {
        let runs = [
            run(0, &[10.0, 100.0], None),
            run(1, &[30.0, 200.0], None),
            run(2, &[20.0, 150.0], None),
        ];
        let refs: Vec<&RunRecord> = runs.iter().collect();
        let curve = median_curve(&refs);
        assert_eq!(curve.len(), 2);
        assert_eq!(
            (
                curve[0].x,
                curve[0].median,
                curve[0].lower_quartile,
                curve[0].upper_quartile
            ),
            (1000.0, 20.0, 15.0, 25.0)
        );
        assert_eq!(curve[1].median, 150.0);
    }

    #[test]
    fn questions_so_far_counts_the_questions_up_to_each_step_on_a_log_axis() {
        let runs = [
            run(0, &[], Some(vec![0, 5, 999, 1000, 2999])),
            run(1, &[], Some(vec![10, 20, 30])),
            run(2, &[], None),
        ];
        let refs: Vec<&RunRecord> = runs.iter().collect();
        let points = questions_so_far(&refs);
        let at = |step: f64| {
            let p = points
                .iter()
                .find(|p| (p.x - step.log10()).abs() < 1e-9)
                .unwrap_or_else(|| panic!("no point at step {step}: {points:?}"));
            (p.lower_quartile, p.median, p.upper_quartile)
        };
        // Seed 2 logged nothing and is left out. At step 10: seed 0 asked 2 (steps 0, 5), seed 1 asked 1.
        assert_eq!(at(10.0).1, 1.5);
        // At step 1000 (10^3): 4 and 3; at the last step, 3000: 5 and 3.
        assert_eq!(at(1000.0).1, 3.5);
        assert_eq!(at(3000.0).1, 4.0);
        assert_eq!(points.last().map(|p| p.x), Some(3000f64.log10()));
        // 20 points per tenfold from 10 to 10^3.45 (the last below 3000), then 3000.
        assert_eq!(points.len(), 51);
    }

    #[test]
    fn expert_labels_are_readable() {
        assert_eq!(
            expert_label("noisy:0.4:shipped:perfect"),
            "perfect expert + 40% random actions"
        );
        assert_eq!(expert_label("file:x.safetensors"), "file:x.safetensors");
    }
}
