//! The effort benchmark's tables (`effort.md`, `effort.csv`) and figures: every query rule, at every budget, on
//! the same tasks and seeds, read as what the expert's effort bought.
//!
//! A run belongs to the benchmark when it asks the expert without pre-training (GDQN, BDQN, ADQN) and varies at
//! most its query rule and budget ([`super::protocol::effort_grids`]). For each task, rule, network and budget
//! (a *cell*), over its seeds:
//! - the normalised area under the evaluation curve: the mean over evaluations of
//!   `(return - random) / (expert - random)`, with the random policy's and the shipped weak expert's mean
//!   returns over [`REFERENCE_EPISODES`] episodes computed here (0: as good as random, 1: as good as the
//!   expert over the whole run);
//! - first-hit and sustained steps to solve and the final score (the readings of [`super::verdict`]);
//! - the effort spent: demonstrated transitions, questions asked, and the step of the last question;
//! - medians with bootstrap 95% intervals, and two-sided Mann–Whitney p-values of the AUC against GDQN, BDQN
//!   and ADQN at the same budget and network, on the seeds both cells have.
//!
//! Seeds in [`super::protocol::HELD_OUT_SEEDS`] and [`super::protocol::SECOND_HELD_OUT_SEEDS`] are never pooled
//! with the others: they form cells of their own (the two held-out tests), reported in sections of their own.
//!
//! Every comparison of a rule with a paper rule is reported with the Hodges–Lehmann shift of the AUC and its 95%
//! interval, the raw Mann–Whitney p and the Holm-adjusted p within its family ([`Family`], one per question), the
//! one-sided p that the rule lies above, two one-sided tests of equivalence within the task's margin (what one
//! doubling of the expert's budget buys, [`Doubling`]), and the paired Wilcoxon test on the seeds both share (the
//! same seed gives both rules the same initial weights, the same replay and rule random streams and the same first
//! resets). "Beats all three paper rules" is a directional claim ([`Claim`]): the intersection-union test of the
//! three one-sided tests, Holm-adjusted over the claims asked together. A run's mean return is the exact sum of its
//! evaluation means as the decimals `eval.csv` holds ([`Decimal`]), so equal curves give equal AUCs and equal paired
//! differences stay ties. Each rule's worth in the expert's own unit ([`EffortMultiple`]) is the budget at which
//! asking at random reaches its AUC, as a multiple of its own budget; the power table says how many seeds a test
//! needs to see a rule worth twice the effort.

use super::plot::{Band, Curve, FigureContent, Panel, XScale};
use super::protocol::{
    BOX_CANDIDATES, BOX_DESIGN_SEEDS, BOX_HELD_OUT_RULE, BOX_HELD_OUT_SEEDS, BOX_HELD_OUT_TASKS,
    DESIGN_SEEDS, EFFORT_NET, EFFORT_SCREEN_TASKS, HELD_OUT_SEEDS, OWN_RULE_CANDIDATES,
    PAPER_SEEDS, SECOND_HELD_OUT_CELLS, SECOND_HELD_OUT_RULE, SECOND_HELD_OUT_SEEDS, TEST_LEVEL,
    UNCERTAINTY_LABEL, env_order, is_effort_variant, paper_budget, scaled_budget,
};
use super::reference::{REFERENCE_EPISODES, REFERENCE_SEED, references};
use super::stats::{
    Decimal, OnCurve, bootstrap_median_interval, budget_equivalent, detectable_difference,
    equivalence_p, exact_sum, final_score, hodges_lehmann, holm, intersection_union, mann_whitney,
    mann_whitney_greater, median, sample_sd, seeds_needed, sustained, wilcoxon_signed_rank,
};
use super::verdict::FINAL_EVALUATIONS;
use anyhow::Result;
use arld_core::train::BoxUncertainty;
use arld_core::train::run_dir::{DEFAULT_VARIANT, RunRecord, canonical_rule};
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

const BOOTSTRAP_RESAMPLES: usize = 10_000;
const BOOTSTRAP_SEED: u64 = 0;
/// The paper's rules, as the baselines every rule is compared with: (label, method).
const BASELINES: [(&str, &str); 3] = [
    ("greedy (GDQN)", "gdqn"),
    ("bernoulli (BDQN)", "bdqn"),
    ("adaptive (ADQN)", "adqn"),
];

/// What one run of the benchmark measured.
#[derive(Clone, Debug)]
struct RunMetrics {
    seed: u64,
    auc: f64,
    /// The exact sum of the evaluation means, as the decimals `eval.csv` holds, and their count; `None` where a
    /// mean is not finite or the sum leaves 128 bits (the AUC then comes from [`exact_sum`]).
    mean_return: Option<(Decimal, u64)>,
    /// The expert's mean return minus the random policy's: one unit of normalised AUC in returns.
    span: f64,
    first_hit: f64,
    sustained: f64,
    final_score: f64,
    transitions: f64,
    questions: f64,
    last_question: Option<f64>,
    /// The share of the questions asked before learning starts (`None` without questions or a recorded start).
    before_learning: Option<f64>,
    /// The step of the question that takes the count to half of all questions asked (`None` without questions).
    half_asked_by: Option<f64>,
    /// Questions asked before each evaluation: (evaluation step, count), for the figure.
    questions_at: Vec<(u64, u64)>,
}

/// Which seeds a cell holds: the design and screen seeds, the first held-out test's or the second's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Group {
    Screen,
    HeldOut,
    SecondHeldOut,
    /// The continuous held-out test's seeds.
    BoxHeldOut,
}

impl Group {
    fn of(seed: u64) -> Group {
        if HELD_OUT_SEEDS.contains(&seed) {
            Group::HeldOut
        } else if SECOND_HELD_OUT_SEEDS.contains(&seed) {
            Group::SecondHeldOut
        } else if BOX_HELD_OUT_SEEDS.contains(&seed) {
            Group::BoxHeldOut
        } else {
            Group::Screen
        }
    }

    /// effort.csv's `held_out` column.
    fn csv(self) -> &'static str {
        match self {
            Group::Screen => "false",
            Group::HeldOut => "true",
            Group::SecondHeldOut => "second",
            Group::BoxHeldOut => "continuous",
        }
    }
}

/// One cell's key: task, rule label, network, budget, seed group.
type CellKey = (String, String, String, usize, Group);

/// The key of the cell beside `key`'s with the rule `label` (the same task, network, budget and seed group).
fn with_rule(key: &CellKey, label: &str) -> CellKey {
    (
        key.0.clone(),
        label.to_string(),
        key.2.clone(),
        key.3,
        key.4,
    )
}

/// The key of `rule`'s cell at the paper's budget for `env` with network `net`, in seed group `held_out`.
fn paper_cell(env: &str, rule: &str, net: &str, held_out: Group) -> CellKey {
    (
        env.to_string(),
        rule.to_string(),
        net.to_string(),
        paper_budget(env),
        held_out,
    )
}

/// The rule and budget of a benchmark run, as its configuration records them; `None` for runs outside the
/// benchmark.
fn rule_and_budget(run: &RunRecord) -> Option<(String, usize)> {
    let method = run.id.method.name();
    if !["gdqn", "bdqn", "adqn"].contains(&method) {
        return None;
    }
    let variant = run.variant.as_str();
    if variant != DEFAULT_VARIANT && !is_effort_variant(variant) {
        return None;
    }
    // A run whose configuration records no budget (made by hand, or outside the benchmark) is left out.
    let budget = run.config.budget?;
    let mut label = match &run.config.query_rule {
        Some(rule) => rule.clone(),
        None => BASELINES
            .iter()
            .find(|(_, m)| *m == method)
            .map(|(l, _)| l.to_string())
            .expect("a querying method"),
    };
    if run.config.asking.from_learning_starts == Some(true) {
        label.push_str(" from learning_starts");
    }
    if run.config.asking.uncertainty == Some(BoxUncertainty::ActionDisagreement) {
        label.push_str(UNCERTAINTY_LABEL);
    }
    Some((label, budget))
}

/// What `run` measured; its evaluation means are finite ([`super::report::report`] refuses a run otherwise).
fn metrics(run: &RunRecord, reference: (f64, f64), k: usize) -> RunMetrics {
    let (random, expert) = reference;
    let span = expert - random;
    let n = run.eval.len() as u64;
    let mean_return = Decimal::sum(run.eval.iter().map(|p| p.mean)).map(|sum| (sum, n));
    let auc = match mean_return {
        _ if run.eval.is_empty() => f64::NAN,
        // The mean return first (the exact decimal sum, or an exactly rounded one), then normalised: runs whose
        // means have equal sums get equal AUCs, whatever the order of their evaluations.
        Some((sum, n)) => (sum.to_f64() / n as f64 - random) / span,
        None => (exact_sum(run.eval.iter().map(|p| p.mean)) / n as f64 - random) / span,
    };
    let questions = run.query_steps.as_ref().map_or(0, Vec::len);
    let questions_at = run
        .eval
        .iter()
        .map(|p| {
            let asked = run
                .query_steps
                .as_ref()
                .map_or(0, |q| q.iter().filter(|&&s| s < p.step).count() as u64);
            (p.step, asked)
        })
        .collect();
    RunMetrics {
        seed: run.id.seed,
        auc,
        mean_return,
        span,
        first_hit: sustained(&run.eval, run.solve_threshold, 0, run.train_steps) as f64,
        sustained: sustained(&run.eval, run.solve_threshold, k, run.train_steps) as f64,
        final_score: final_score(&run.eval, FINAL_EVALUATIONS).unwrap_or(f64::NAN),
        transitions: run.demos_queried().unwrap_or(0) as f64,
        questions: questions as f64,
        last_question: run
            .query_steps
            .as_ref()
            .and_then(|q| q.last())
            .map(|&s| s as f64),
        before_learning: spent_before(run),
        half_asked_by: run
            .query_steps
            .as_ref()
            .filter(|q| !q.is_empty())
            .map(|q| q[(q.len() - 1) / 2] as f64),
        questions_at,
    }
}

/// The share of `run`'s questions asked before the step at which learning starts.
fn spent_before(run: &RunRecord) -> Option<f64> {
    let steps = run.query_steps.as_ref().filter(|q| !q.is_empty())?;
    let start = run.config.asking.learning_starts?;
    let before = steps.iter().filter(|&&s| s < start).count();
    Some(before as f64 / steps.len() as f64)
}

/// Median and bootstrap 95% interval, formatted `m [lo, hi]`.
fn reading(values: &[f64], digits: usize) -> (f64, (f64, f64), String) {
    let m = median(values).unwrap_or(f64::NAN);
    let (lo, hi) = bootstrap_median_interval(values, 0.95, BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED)
        .unwrap_or((f64::NAN, f64::NAN));
    let f = |v: f64| format!("{v:.digits$}");
    (m, (lo, hi), format!("{} [{}, {}]", f(m), f(lo), f(hi)))
}

/// "p = 0.473" or "p < 0.001", for prose.
fn p_phrase(p: Option<f64>) -> String {
    match fmt_p(p).strip_prefix('<') {
        Some(bound) => format!("p < {bound}"),
        None => format!("p = {}", fmt_p(p)),
    }
}

fn fmt_p(p: Option<f64>) -> String {
    match p {
        None => "–".into(),
        Some(p) if p < 0.001 => "<0.001".into(),
        Some(p) => format!("{p:.3}"),
    }
}

/// The runs of `cell` and `other` on the seeds both have, in seed order (pair i is one seed).
fn shared_runs<'a>(
    cell: &'a [RunMetrics],
    other: &'a [RunMetrics],
) -> Vec<(&'a RunMetrics, &'a RunMetrics)> {
    let mut pairs: Vec<(&RunMetrics, &RunMetrics)> = cell
        .iter()
        .filter_map(|m| Some((m, other.iter().find(|o| o.seed == m.seed)?)))
        .collect();
    pairs.sort_by_key(|p| p.0.seed);
    pairs
}

/// The AUCs of `cell` and `other` on the seeds both have, in seed order (pair i is one seed).
fn shared(cell: &[RunMetrics], other: &[RunMetrics]) -> (Vec<f64>, Vec<f64>) {
    shared_runs(cell, other)
        .iter()
        .map(|(a, b)| (a.auc, b.auc))
        .unzip()
}

/// The paired comparison of seed-matched runs: the Hodges–Lehmann shift of the AUC differences and the Wilcoxon
/// p, from the differences of the runs' exact mean returns ([`Decimal::paired_differences`]), so that equal
/// differences are ties; `None` where a run's means cannot be held exactly or no difference is non-zero.
fn paired_test(pairs: &[(&RunMetrics, &RunMetrics)]) -> Option<(f64, f64)> {
    let a: Option<Vec<(Decimal, u64)>> = pairs.iter().map(|p| p.0.mean_return).collect();
    let b: Option<Vec<(Decimal, u64)>> = pairs.iter().map(|p| p.1.mean_return).collect();
    let (d, unit) = Decimal::paired_differences(&a?, &b?)?;
    let (shift, p) = wilcoxon_signed_rank(&d)?;
    Some((shift * unit / pairs.first()?.0.span, p))
}

/// The AUC p-value of `cell` against `other` on the seeds both have; with the sign of the difference of medians.
fn compare(cell: &[RunMetrics], other: Option<&Vec<RunMetrics>>) -> (Option<f64>, f64) {
    let Some(other) = other else {
        return (None, 0.0);
    };
    let (ours, theirs) = shared(cell, other);
    let p = mann_whitney(&ours, &theirs).map(|(_, p)| p);
    let diff = median(&ours).unwrap_or(f64::NAN) - median(&theirs).unwrap_or(f64::NAN);
    (p, diff)
}

/// The rule that stands for asking the expert at random: its budget curve is the unit of the expert's effort
/// ([`EffortMultiple`]), and the AUC one doubling of its budget buys is the equivalence margin ([`Doubling`]). It is
/// BDQN's Bernoulli draw, which asks with a fixed probability from the first step until the budget is spent. `paced`
/// draws at random too, but spreads the budget over the whole run, and the design seeds showed that spreading alone
/// loses (docs/algorithm.md §14): on its curve every rule that asks early would look worth many times the effort for
/// when it asks, not for which states it picks.
const REFERENCE_RULE: &str = "bernoulli (BDQN)";

/// A family of comparisons, within which Holm's adjustment runs: one question each.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Family {
    /// The screen: one task's rules against each paper rule at the paper's budget with the benchmark's network,
    /// on the seeds outside the held-out ones.
    Screen(String),
    /// One task's rules against each paper rule at the other budgets, on the seeds outside the held-out ones.
    BudgetGrid(String),
    /// The paper rules among themselves on one task, in one seed group (the screen's or the first held-out test's).
    PaperRules(String, Group),
    /// One task's cells on the first held-out seeds: the held-out rule against each paper rule.
    HeldOut(String),
    /// The second held-out test: its rule against each paper rule in each of its cells.
    SecondTest,
    /// The paper rules among themselves on the second held-out seeds.
    SecondPaper,
    /// One task's budget comparisons of "What the expert's effort buys" (the largest budget against the smallest).
    Budgets(String),
}

impl Family {
    fn describe(&self) -> String {
        let held_out = |env: &str| format!("held-out seeds {}", seed_span(&held_out_seeds(env)));
        match self {
            Family::Screen(env) => format!("{env}, seeds outside the held-out ones"),
            Family::BudgetGrid(env) => {
                format!("{env}, the other budgets, seeds outside the held-out ones")
            }
            Family::PaperRules(env, Group::HeldOut | Group::BoxHeldOut) => {
                format!("{env}, the paper rules among themselves, {}", held_out(env))
            }
            Family::PaperRules(env, _) => {
                format!("{env}, the paper rules among themselves, seeds outside the held-out ones")
            }
            Family::HeldOut(env) => format!("{env}, {}", held_out(env)),
            Family::SecondTest => format!(
                "the second held-out test ({SECOND_HELD_OUT_RULE} against the paper rules, seeds {})",
                seed_span(&SECOND_HELD_OUT_SEEDS)
            ),
            Family::SecondPaper => format!(
                "the paper rules among themselves, seeds {}",
                seed_span(&SECOND_HELD_OUT_SEEDS)
            ),
            Family::Budgets(env) => {
                format!(
                    "{env}, largest budget against smallest (every seed outside the held-out ones)"
                )
            }
        }
    }

    /// The task of a family of one task's cells.
    fn env(&self) -> Option<&str> {
        match self {
            Family::Screen(e)
            | Family::BudgetGrid(e)
            | Family::PaperRules(e, _)
            | Family::HeldOut(e)
            | Family::Budgets(e) => Some(e),
            Family::SecondTest | Family::SecondPaper => None,
        }
    }

    /// The order of the report's tables: the screen, the other budgets, the held-out tests, the paper rules among
    /// themselves, the budget comparisons.
    fn kind(&self) -> usize {
        match self {
            Family::Screen(_) => 0,
            Family::BudgetGrid(_) => 1,
            Family::HeldOut(_) => 2,
            Family::SecondTest => 3,
            Family::PaperRules(_, Group::Screen) => 4,
            Family::PaperRules(..) => 5,
            Family::SecondPaper => 6,
            Family::Budgets(_) => 7,
        }
    }
}

/// One comparison of a rule's AUC with another's on the seeds both have (`a` the rule, `b` the other).
#[derive(Clone, Debug)]
struct Comparison {
    family: Family,
    a: CellKey,
    b: CellKey,
    seeds: usize,
    /// Hodges–Lehmann shift of a over b and its 95% interval.
    shift: Option<(f64, (f64, f64))>,
    p: Option<f64>,
    holm: Option<f64>,
    /// The one-sided Mann–Whitney p that a lies above b (the directional claims' tests, [`Claim`]).
    p_greater: Option<f64>,
    /// The task's equivalence margin ([`Doubling`]); `None` where more effort buys no measurable AUC.
    margin: Option<f64>,
    /// Two one-sided tests of equivalence within the margin, raw and Holm-adjusted in the family.
    tost: Option<f64>,
    tost_holm: Option<f64>,
    /// Paired: Hodges–Lehmann shift of the seed-by-seed differences and the Wilcoxon p, raw and adjusted.
    paired: Option<(f64, f64)>,
    paired_holm: Option<f64>,
}

impl Comparison {
    fn new(
        family: Family,
        (a, cell_a): (&CellKey, &[RunMetrics]),
        (b, cell_b): (&CellKey, &[RunMetrics]),
        margin: Option<f64>,
    ) -> Self {
        let pairs = shared_runs(cell_a, cell_b);
        let (ours, theirs): (Vec<f64>, Vec<f64>) =
            pairs.iter().map(|(x, y)| (x.auc, y.auc)).unzip();
        Comparison {
            family,
            a: a.clone(),
            b: b.clone(),
            seeds: ours.len(),
            shift: hodges_lehmann(&ours, &theirs, 0.95),
            p: mann_whitney(&ours, &theirs).map(|(_, p)| p),
            holm: None,
            p_greater: mann_whitney_greater(&ours, &theirs),
            margin,
            tost: margin.and_then(|m| equivalence_p(&ours, &theirs, m)),
            tost_holm: None,
            paired: paired_test(&pairs),
            paired_holm: None,
        }
    }

    fn significant(&self) -> bool {
        self.holm.is_some_and(|p| p < TEST_LEVEL)
    }

    fn level(&self) -> bool {
        self.tost_holm.is_some_and(|p| p < TEST_LEVEL)
    }

    fn shift_value(&self) -> f64 {
        self.shift.map_or(f64::NAN, |s| s.0)
    }

    /// Whether the 95% interval of the shift rules out a gain of one doubling of the expert's budget (its upper
    /// end below the margin); `None` without a margin.
    fn doubling_ruled_out(&self) -> Option<bool> {
        let (_, (_, hi)) = self.shift?;
        self.margin.map(|m| hi < m)
    }

    /// "+0.012 [-0.020, +0.041]".
    fn shift_text(&self) -> String {
        match self.shift {
            Some((s, (lo, hi))) => format!("{s:+.3} [{lo:+.3}, {hi:+.3}]"),
            None => "–".into(),
        }
    }

    /// The test's Markdown cells, as both comparison tables show them: shift, p, Holm p, equivalence Holm p,
    /// reading and paired shift.
    fn test_cells(&self) -> String {
        format!(
            "{} | {} | {} | {} | {} | {}",
            self.shift_text(),
            fmt_p(self.p),
            fmt_p(self.holm),
            fmt_p(self.tost_holm),
            self.reading(),
            self.paired.map_or("–".into(), |x| format!("{:+.3}", x.0)),
        )
    }

    /// What the comparison says in words: significantly higher or lower (adjusted p), level (adjusted TOST), or
    /// no difference detected.
    fn reading(&self) -> String {
        if self.significant() {
            if self.shift_value() > 0.0 {
                "significantly higher"
            } else {
                "significantly lower"
            }
            .to_string()
        } else if self.level() {
            format!("level (within ±{:.3})", self.margin.unwrap_or(f64::NAN))
        } else {
            "no difference detected".to_string()
        }
    }
}

/// Holm's adjustment of the unpaired, equivalence and paired p-values within each family.
fn adjust(comparisons: &mut [Comparison]) {
    for (family, idx) in by_family(comparisons, |c| c.family.clone()) {
        // The second held-out test's family is its fixed set of comparisons: while some have not run, they count
        // as tests that found nothing (p = 1), so that a partial family is never adjusted more leniently.
        let size = if family == Family::SecondTest {
            SECOND_HELD_OUT_CELLS.len() * BASELINES.len()
        } else {
            0
        };
        let p = holm_padded(idx.iter().map(|&i| comparisons[i].p).collect(), size);
        let t = holm_padded(idx.iter().map(|&i| comparisons[i].tost).collect(), size);
        let w = holm_padded(
            idx.iter()
                .map(|&i| comparisons[i].paired.map(|x| x.1))
                .collect(),
            size,
        );
        for (j, &i) in idx.iter().enumerate() {
            comparisons[i].holm = p[j];
            comparisons[i].tost_holm = t[j];
            comparisons[i].paired_holm = w[j];
        }
    }
}

/// The indices of `items` in groups of one family each, the families in their order.
fn by_family<T, F: Ord>(items: &[T], family: impl Fn(&T) -> F) -> BTreeMap<F, Vec<usize>> {
    let mut groups: BTreeMap<F, Vec<usize>> = BTreeMap::new();
    for (i, item) in items.iter().enumerate() {
        groups.entry(family(item)).or_default().push(i);
    }
    groups
}

/// Holm's adjustment of `p` in a family fixed at `size` tests: those not run yet count as p = 1.
fn holm_padded(p: Vec<Option<f64>>, size: usize) -> Vec<Option<f64>> {
    let n = p.len();
    let missing = size.saturating_sub(n);
    let mut adjusted = holm(
        &p.into_iter()
            .chain(std::iter::repeat_n(Some(1.0), missing))
            .collect::<Vec<_>>(),
    );
    adjusted.truncate(n);
    adjusted
}

/// Every comparison of a cell with a paper rule at the same task, budget, network and seed group, each pair
/// once (the paper rules among themselves: the later of the three against the earlier), Holm-adjusted within
/// its family; the equivalence margins are the tasks' ([`Doubling`]).
fn comparisons(
    cells: &BTreeMap<CellKey, Vec<RunMetrics>>,
    margins: &BTreeMap<String, Option<f64>>,
) -> Vec<Comparison> {
    let mut out = Vec::new();
    for (key, cell) in cells {
        for (label, _) in BASELINES {
            let rank = rank_rule(&key.1);
            if rank <= rank_rule(label) {
                continue;
            }
            let base = with_rule(key, label);
            let Some(other) = cells.get(&base) else {
                continue;
            };
            let env = key.0.clone();
            let paper_rule = rank < BASELINES.len();
            let family = match key.4 {
                Group::SecondHeldOut if paper_rule => Family::SecondPaper,
                Group::SecondHeldOut => Family::SecondTest,
                group if paper_rule => Family::PaperRules(env, group),
                Group::HeldOut | Group::BoxHeldOut => Family::HeldOut(env),
                Group::Screen if key.3 == paper_budget(&env) && key.2 == EFFORT_NET.name() => {
                    Family::Screen(env)
                }
                Group::Screen => Family::BudgetGrid(env),
            };
            let margin = margins.get(&key.0).copied().flatten();
            out.push(Comparison::new(family, (key, cell), (&base, other), margin));
        }
    }
    out
}

/// The budget comparisons of "What the expert's effort buys": for every rule run at two budgets or more on a
/// task, its largest budget against its smallest, on every seed outside the held-out ones that both have.
fn budget_comparisons(cells: &BTreeMap<CellKey, Vec<RunMetrics>>) -> Vec<Comparison> {
    let mut by_rule: BTreeMap<(String, String, String), Vec<&CellKey>> = BTreeMap::new();
    for key in cells.keys().filter(|k| k.4 == Group::Screen) {
        by_rule
            .entry((key.0.clone(), key.1.clone(), key.2.clone()))
            .or_default()
            .push(key);
    }
    let mut out = Vec::new();
    for ((env, _, _), keys) in by_rule {
        let (Some(lo), Some(hi)) = (
            keys.iter().min_by_key(|k| k.3),
            keys.iter().max_by_key(|k| k.3),
        ) else {
            continue;
        };
        if lo.3 == hi.3 {
            continue;
        }
        out.push(Comparison::new(
            Family::Budgets(env),
            (hi, &cells[*hi]),
            (lo, &cells[*lo]),
            None,
        ));
    }
    out
}

/// What one doubling of the expert's budget buys on a task: the reference rule's ([`REFERENCE_RULE`]) shift of the
/// AUC from its smallest budget to its largest, over the doublings between them. It is the equivalence margin: two
/// rules are level when the difference between them is smaller than what doubling the expert's effort buys, so
/// that "level" says "worth between half and twice the effort"; where the shift is not positive, more effort buys
/// no measurable AUC and equivalence has no scale (no margin).
#[derive(Clone, Debug)]
struct Doubling {
    comparison: Comparison,
    doublings: f64,
}

impl Doubling {
    fn of(budgets: &[Comparison]) -> BTreeMap<String, Doubling> {
        budgets
            .iter()
            .filter(|c| c.a.1 == REFERENCE_RULE && c.a.2 == EFFORT_NET.name())
            .map(|c| {
                let doublings = (c.a.3 as f64 / c.b.3 as f64).log2();
                let d = Doubling {
                    comparison: c.clone(),
                    doublings,
                };
                (c.a.0.clone(), d)
            })
            .collect()
    }

    /// The AUC one doubling buys (the shift over the doublings).
    fn per_doubling(&self) -> f64 {
        self.comparison.shift_value() / self.doublings
    }

    fn margin(&self) -> Option<f64> {
        Some(self.per_doubling()).filter(|m| *m > 0.0)
    }
}

/// A directional claim: a rule's cell above all three paper rules at the same task, budget, network and seeds. Its
/// test is the intersection-union test of the three one-sided Mann–Whitney tests (each at the full level; the
/// claim holds only if all three do, so no adjustment is needed among them), and the claims asked together (one
/// task's screen, one held-out test's cells) are one family, Holm-adjusted.
#[derive(Clone, Debug)]
struct Claim {
    family: ClaimFamily,
    cell: CellKey,
    /// The intersection-union p (the largest of the three one-sided p-values) and its Holm adjustment.
    p: Option<f64>,
    holm: Option<f64>,
}

/// The families of [`Claim`]s: one question each.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum ClaimFamily {
    /// Does any rule beat all three paper rules on this task at the paper's budget (the screen)?
    Screen(String),
    /// The first held-out test: does its rule beat all three in each task and network?
    HeldOut,
    /// The second held-out test: does its rule beat all three in each of its cells?
    SecondTest,
    /// The continuous held-out test: does its rule beat all three on each of its tasks?
    BoxTest,
}

impl Claim {
    /// Every cell of a rule that is not a paper rule, in the screen or a held-out test, as a claim.
    fn all(cells: &BTreeMap<CellKey, Vec<RunMetrics>>, comparisons: &[Comparison]) -> Vec<Claim> {
        let mut out: Vec<Claim> = Vec::new();
        for key in cells.keys().filter(|k| rank_rule(&k.1) == BASELINES.len()) {
            let family = match key.4 {
                Group::Screen if key.3 == paper_budget(&key.0) && key.2 == EFFORT_NET.name() => {
                    ClaimFamily::Screen(key.0.clone())
                }
                Group::Screen => continue,
                Group::HeldOut => ClaimFamily::HeldOut,
                Group::SecondHeldOut => ClaimFamily::SecondTest,
                Group::BoxHeldOut => ClaimFamily::BoxTest,
            };
            let one_sided: Vec<Option<f64>> = BASELINES
                .iter()
                .map(|(label, _)| {
                    find(comparisons, key, &with_rule(key, label)).and_then(|c| c.p_greater)
                })
                .collect();
            out.push(Claim {
                family,
                cell: key.clone(),
                p: intersection_union(&one_sided),
                holm: None,
            });
        }
        for (family, idx) in by_family(&out, |c| c.family.clone()) {
            let size = match family {
                ClaimFamily::SecondTest => SECOND_HELD_OUT_CELLS.len(),
                ClaimFamily::BoxTest => BOX_HELD_OUT_TASKS.len(),
                _ => 0,
            };
            let adjusted = holm_padded(idx.iter().map(|&i| out[i].p).collect(), size);
            for (j, &i) in idx.iter().enumerate() {
                out[i].holm = adjusted[j];
            }
        }
        out
    }

    fn won(&self) -> bool {
        self.holm.is_some_and(|p| p < TEST_LEVEL)
    }

    /// What the claim's numbers say: a win; a loss where the rule is significantly below a paper rule; negative
    /// where the intervals rule out a gain of one budget doubling over some paper rule; otherwise inconclusive.
    fn reading(&self, comparisons: &[Comparison]) -> String {
        let against: Vec<&Comparison> = BASELINES
            .iter()
            .filter_map(|(label, _)| {
                let base = (
                    self.cell.0.clone(),
                    label.to_string(),
                    self.cell.2.clone(),
                    self.cell.3,
                    self.cell.4,
                );
                find(comparisons, &self.cell, &base)
            })
            .collect();
        let name = |c: &Comparison| method_of(&c.b.1).to_uppercase();
        let names = |v: Vec<&&Comparison>| v.iter().map(|c| name(c)).collect::<Vec<_>>().join(", ");
        let lower: Vec<&&Comparison> = against
            .iter()
            .filter(|c| c.significant() && c.shift_value() < 0.0)
            .collect();
        let ruled_out: Vec<&&Comparison> = against
            .iter()
            .filter(|c| c.doubling_ruled_out() == Some(true))
            .collect();
        if self.won() {
            "a win: above all three paper rules".to_string()
        } else if !lower.is_empty() {
            format!("a loss: significantly below {}", names(lower))
        } else if !ruled_out.is_empty() {
            format!(
                "negative: a gain worth one doubling of the expert's budget is ruled out at 95% over {}",
                names(ruled_out)
            )
        } else if against.iter().any(|c| c.margin.is_none()) {
            "inconclusive: more effort buys no measurable AUC on this task, so no gain is ruled out in its unit"
                .to_string()
        } else {
            "inconclusive: the 95% intervals leave a gain worth one doubling of the expert's budget open over \
             all three paper rules"
                .to_string()
        }
    }
}

/// The method of a paper rule's label ("greedy (GDQN)" -> "gdqn"); the label itself for other rules.
fn method_of(label: &str) -> &str {
    BASELINES
        .iter()
        .find(|(l, _)| *l == label)
        .map_or(label, |(_, m)| m)
}

/// The comparison of cell `a` with paper rule cell `b` (in either order), with a's shift.
fn find<'a>(comparisons: &'a [Comparison], a: &CellKey, b: &CellKey) -> Option<&'a Comparison> {
    comparisons
        .iter()
        .find(|c| (&c.a == a && &c.b == b) || (&c.a == b && &c.b == a))
}

/// Whether `a` is significantly above (`Some(true)`) or below (`Some(false)`) `b` after Holm's adjustment.
fn significant_side(comparisons: &[Comparison], a: &CellKey, b: &CellKey) -> Option<bool> {
    let c = find(comparisons, a, b).filter(|c| c.significant())?;
    let above = c.shift_value() > 0.0;
    Some(if &c.a == a { above } else { !above })
}

/// "p = 0.012, Holm 0.036".
fn adjusted_phrase(c: &Comparison) -> String {
    format!("{}, Holm {}", p_phrase(c.p), fmt_p(c.holm))
}

/// effort.md's section "Every comparison": one table per family.
fn comparison_tables(comparisons: &[Comparison]) -> String {
    let mut out = format!(
        "## Every comparison\n\nEach rule against each paper rule at the same budget and network, on the seeds \
         both have (each pair once), in one family per question. Shift: the Hodges-Lehmann shift of the AUC (the \
         rule minus the other) with its 95% interval (order statistics from the exact null distribution of U); p: \
         two-sided Mann-Whitney, raw and Holm-adjusted within the family of the table; one-sided p: that the rule \
         lies above the other (the tests of \"beats all three\"); equivalence: two one-sided tests that the shift \
         lies within the task's margin (the AUC one doubling of the expert's budget buys, \"The margin\"), \
         Holm-adjusted; paired: the Hodges-Lehmann shift of the seed-by-seed differences and the Wilcoxon \
         signed-rank p, raw and Holm-adjusted (the differences of the runs' mean returns held exactly, so that equal \
         differences are ties; the same seed gives both rules the same initial weights, the same replay and rule \
         random streams and the same first resets). The reading follows the adjusted p at {TEST_LEVEL}: \
         significantly higher or lower, level (equivalent within the margin), or no difference detected.\n"
    );
    let families: std::collections::BTreeSet<Family> =
        comparisons.iter().map(|c| c.family.clone()).collect();
    let mut families: Vec<Family> = families.into_iter().collect();
    families.sort_by_key(|f| {
        let env = f.env().unwrap_or_default();
        (
            f.kind(),
            arld_core::paper::task_index(env).unwrap_or(usize::MAX),
            env.to_string(),
        )
    });
    for family in families {
        let rows: Vec<&Comparison> = comparisons.iter().filter(|c| c.family == family).collect();
        let _ = writeln!(
            out,
            "\n### {} ({} comparisons)\n\n| task | rule | net | budget | against | seeds | shift | p | Holm p | \
             equivalence Holm p | reading | paired shift | paired p | paired Holm p | one-sided p |\n|---|---|---|\
             ---|---|---|---|---|---|---|---|---|---|---|---|",
            family.describe(),
            rows.len()
        );
        for c in rows {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                c.a.0,
                c.a.1,
                c.a.2,
                if c.a.3 == c.b.3 {
                    c.a.3.to_string()
                } else {
                    format!("{} vs {}", c.a.3, c.b.3)
                },
                if c.a.1 == c.b.1 {
                    budget_multiple(&c.b.0, c.b.3)
                } else {
                    c.b.1.clone()
                },
                c.seeds,
                c.test_cells(),
                fmt_p(c.paired.map(|x| x.1)),
                fmt_p(c.paired_holm),
                fmt_p(c.p_greater),
            );
        }
    }
    out
}

/// effort_comparisons.csv: every comparison of [`comparison_tables`] with full precision.
fn comparisons_csv(comparisons: &[Comparison]) -> String {
    let mut out = String::from(
        "family,env,rule,net,budget,held_out,against,against_budget,seeds,shift,shift_lo,shift_hi,p,p_holm,\
         equivalence_p,equivalence_p_holm,paired_shift,paired_p,paired_p_holm,reading,p_greater,margin\n",
    );
    let v = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x}"));
    for c in comparisons {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            csv_field(&c.family.describe()),
            c.a.0,
            csv_field(&c.a.1),
            c.a.2,
            c.a.3,
            c.a.4.csv(),
            csv_field(&c.b.1),
            c.b.3,
            c.seeds,
            v(c.shift.map(|s| s.0)),
            v(c.shift.map(|s| s.1.0)),
            v(c.shift.map(|s| s.1.1)),
            v(c.p),
            v(c.holm),
            v(c.tost),
            v(c.tost_holm),
            v(c.paired.map(|x| x.0)),
            v(c.paired.map(|x| x.1)),
            v(c.paired_holm),
            csv_field(&c.reading()),
            v(c.p_greater),
            v(c.margin),
        );
    }
    out
}

/// effort.md's section "The margin": what one doubling of the expert's budget buys on each task ([`Doubling`]).
fn margin_section(measured: &Measured) -> String {
    let mut out = format!(
        "## The margin: what one doubling of the expert's budget buys\n\nThe equivalence margin of each task is \
         the AUC that one doubling of the budget of asking at random ({REFERENCE_RULE}, {} network) buys: its \
         Hodges-Lehmann shift from its smallest budget to its largest, on every seed outside the held-out ones, over \
         the doublings between them. Two rules are called level only when two one-sided tests put the difference \
         between them inside it: worth between half and twice the expert's effort. Where the shift is not positive, \
         more effort buys no measurable AUC and nothing is called level.\n\n| task | budgets | seeds | shift of \
         the AUC | doublings | AUC per doubling | margin |\n|---|---|---|---|---|---|---|",
        EFFORT_NET.name()
    );
    for env in &measured.envs {
        let Some(d) = measured.doublings.get(env) else {
            continue;
        };
        let c = &d.comparison;
        let _ = write!(
            out,
            "\n| {env} | {} vs {} | {} | {} | {:.0} | {:+.4} | {} |",
            c.a.3,
            c.b.3,
            c.seeds,
            c.shift_text(),
            d.doublings,
            d.per_doubling(),
            d.margin()
                .map_or("none".to_string(), |m| format!("±{m:.4}"))
        );
    }
    out.push('\n');
    out
}

/// effort.md's power table: from the design seeds, the seeds per cell a test needs to detect a rule worth twice the
/// expert's effort (an AUC above the paper rules' by what one doubling buys on the design seeds) with 80% power at
/// the one-sided level, and the multiple of the effort the protocol's [`PAPER_SEEDS`] seeds detect.
fn power(measured: &Measured) -> String {
    let (cells, _, envs) = measured.parts();
    let joint = 0.8_f64.powf(1.0 / BASELINES.len() as f64);
    let mut out = format!(
        "## Power: the seeds a rule worth twice the effort needs\n\nFrom the design seeds {design} alone: the \
         spread of the AUC (the interquartile range over 1.349, a standard deviation robust to seeds that never \
         learn, pooled over GDQN, BDQN and ADQN at the paper's budget, {net} network) and the AUC one doubling of \
         the budget of asking at random buys there ({REFERENCE_RULE}'s Hodges-Lehmann shift from its smallest \
         budget to its largest over the doublings). A rule worth twice the effort lies that much above the paper \
         rules. Seeds per rule for 80% power with a one-sided Mann-Whitney test at {TEST_LEVEL} (the normal \
         approximation, the test's efficiency 3/pi): for one comparison; for \"beats all three\" in one cell (the \
         intersection-union test: each of the three comparisons at {TEST_LEVEL}, each with power 0.8^(1/3) = \
         {joint:.3} so that all three succeed together with 0.8 at least when they are independent); and for a test \
         of one cell per task, Holm over its cells, one per task of the same kind of action (the first step at \
         {TEST_LEVEL} over their number). Then the multiple of the expert's effort the same tests detect with \
         {PAPER_SEEDS} seeds a rule (2 to the power of the detectable shift over the AUC per doubling).\n",
        design = seed_span(&DESIGN_SEEDS),
        net = EFFORT_NET.name(),
    );
    // One table per kind of action: a held-out test of one cell per task is a family of the tasks of its kind.
    for boxed in [false, true] {
        let kind: Vec<&String> = envs
            .iter()
            .filter(|env| arld_core::env::box_spec(env).is_ok() == boxed)
            .collect();
        if !kind.is_empty() {
            out.push_str(&power_table(cells, &kind, joint));
        }
    }
    out.push_str(
        "\n\"–\": more effort bought no measurable AUC on the design seeds, so no rule is worth a multiple of \
         it there.\n",
    );
    out
}

/// The power table of the tasks `envs` (of one kind of action): one row per task with its design seeds' spread
/// and the AUC per doubling, then the seeds needed and the multiple detectable with [`PAPER_SEEDS`] seeds.
fn power_table(cells: &BTreeMap<CellKey, Vec<RunMetrics>>, envs: &[&String], joint: f64) -> String {
    let m = envs.len();
    let mut out = format!(
        "\n| task | robust sd of the AUC | AUC per doubling | seeds: one comparison | seeds: beats all three, one \
         cell | seeds: beats all three, {m} cells | detectable at {PAPER_SEEDS} seeds: one comparison | \
         detectable at {PAPER_SEEDS} seeds: beats all three, {m} cells |\n|---|---|---|---|---|---|---|---|"
    );
    let design = |cell: &Vec<RunMetrics>| design_aucs(cell);
    for &env in envs {
        let variances: Vec<f64> = BASELINES
            .iter()
            .filter_map(|(label, _)| {
                let cell = cells.get(&paper_cell(env, label, EFFORT_NET.name(), Group::Screen))?;
                robust_sd(&design(cell)).map(|sd| sd * sd)
            })
            .collect();
        let reference: Vec<(usize, &Vec<RunMetrics>)> = cells
            .iter()
            .filter(|(k, _)| {
                &k.0 == env
                    && k.1 == REFERENCE_RULE
                    && k.2 == EFFORT_NET.name()
                    && k.4 == Group::Screen
            })
            .map(|(k, c)| (k.3, c))
            .collect();
        let (Some(&(lo, low)), Some(&(hi, high))) = (reference.first(), reference.last()) else {
            continue;
        };
        if variances.is_empty() || lo == hi {
            continue;
        }
        let sd = (exact_sum(variances.iter().copied()) / variances.len() as f64).sqrt();
        let per_doubling = hodges_lehmann(&design(high), &design(low), 0.95)
            .map_or(f64::NAN, |(shift, _)| {
                shift / (hi as f64 / lo as f64).log2()
            });
        let needed = |alpha: f64, power: f64| {
            seeds_needed(sd, per_doubling, alpha, power)
                .map_or("–".to_string(), |n| n.to_string())
        };
        let multiple = |alpha: f64, power: f64| {
            let shift = detectable_difference(sd, PAPER_SEEDS as usize, alpha, power);
            if per_doubling > 0.0 {
                format!("{}x", fmt_multiple(2f64.powf(shift / per_doubling)))
            } else {
                "–".to_string()
            }
        };
        let _ = write!(
            out,
            "\n| {env} | {sd:.3} | {per_doubling:+.4} | {} | {} | {} | {} | {} |",
            needed(TEST_LEVEL, 0.8),
            needed(TEST_LEVEL, joint),
            needed(TEST_LEVEL / m as f64, joint),
            multiple(TEST_LEVEL, 0.8),
            multiple(TEST_LEVEL / m as f64, joint),
        );
    }
    out.push('\n');
    out
}

/// A multiple of the effort as text: "2.1", "0.25", "16".
fn fmt_multiple(v: f64) -> String {
    // Two significant digits, decided on the rounded value (0.996 is "1.0", not "1.00").
    if v >= 9.95 {
        format!("{v:.0}")
    } else if v >= 0.995 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// Resamples behind the interval of an effort multiple.
const MULTIPLE_RESAMPLES: usize = 2000;

/// A rule's worth in the expert's own unit: the budget at which asking at random ([`REFERENCE_RULE`]) reaches the
/// rule's median AUC, on the reference's curve of median AUCs over its budgets (made non-decreasing, interpolated
/// in log budget: [`budget_equivalent`]), as a multiple of the rule's budget; with a seeded percentile bootstrap
/// interval over seeds (seeds both have resampled together, the others each on their own side). Outside the
/// curve's range the multiple is censored: above its largest budget over the rule's, or below its smallest.
#[derive(Clone, Copy, Debug)]
struct EffortMultiple {
    estimate: OnCurve,
    interval: (OnCurve, OnCurve),
    /// The curve's smallest and largest budget over the rule's: the censoring bounds.
    bounds: (f64, f64),
}

impl EffortMultiple {
    /// The multiple of `key`'s cell, for cells of the benchmark's network on a task whose reference has run at two
    /// budgets or more.
    fn of(key: &CellKey, cells: &BTreeMap<CellKey, Vec<RunMetrics>>) -> Option<EffortMultiple> {
        if key.2 != EFFORT_NET.name() {
            return None;
        }
        let reference: Vec<(usize, &Vec<RunMetrics>)> = cells
            .iter()
            .filter(|(k, _)| {
                k.0 == key.0 && k.1 == REFERENCE_RULE && k.2 == key.2 && k.4 == Group::Screen
            })
            .map(|(k, c)| (k.3, c))
            .collect();
        if reference.len() < 2 {
            return None;
        }
        let seeds = |c: &[RunMetrics]| -> std::collections::BTreeSet<u64> {
            c.iter()
                .filter(|m| !m.auc.is_nan())
                .map(|m| m.seed)
                .collect()
        };
        let ref_seeds = reference
            .iter()
            .map(|(_, c)| seeds(c))
            .reduce(|x, y| x.intersection(&y).copied().collect())?;
        let cell = &cells[key];
        let cell_seeds = seeds(cell);
        let both: Vec<u64> = cell_seeds.intersection(&ref_seeds).copied().collect();
        let cell_only: Vec<u64> = cell_seeds.difference(&ref_seeds).copied().collect();
        let ref_only: Vec<u64> = ref_seeds.difference(&cell_seeds).copied().collect();
        let auc = |c: &[RunMetrics], seed: u64| {
            c.iter()
                .find(|m| m.seed == seed)
                .map_or(f64::NAN, |m| m.auc)
        };
        // Per stratum, the AUC of each seed in the cell and at each reference budget.
        let column =
            |c: &[RunMetrics], s: &[u64]| s.iter().map(|&x| auc(c, x)).collect::<Vec<f64>>();
        let cell_both = column(cell, &both);
        let cell_alone = column(cell, &cell_only);
        let ref_both: Vec<Vec<f64>> = reference.iter().map(|(_, c)| column(c, &both)).collect();
        let ref_alone: Vec<Vec<f64>> = reference
            .iter()
            .map(|(_, c)| column(c, &ref_only))
            .collect();
        let budget = key.3 as f64;
        let at =
            |pick_both: &[usize], pick_cell: &[usize], pick_ref: &[usize]| -> Option<OnCurve> {
                let y: Vec<f64> = pick_both
                    .iter()
                    .map(|&i| cell_both[i])
                    .chain(pick_cell.iter().map(|&i| cell_alone[i]))
                    .collect();
                let curve: Vec<(f64, f64)> = reference
                    .iter()
                    .enumerate()
                    .map(|(r, (b, _))| {
                        let v: Vec<f64> = pick_both
                            .iter()
                            .map(|&i| ref_both[r][i])
                            .chain(pick_ref.iter().map(|&i| ref_alone[r][i]))
                            .collect();
                        Some((*b as f64, median(&v)?))
                    })
                    .collect::<Option<_>>()?;
                Some(match budget_equivalent(&curve, median(&y)?)? {
                    OnCurve::At(b) => OnCurve::At(b / budget),
                    censored => censored,
                })
            };
        let all = |n: usize| (0..n).collect::<Vec<usize>>();
        let estimate = at(
            &all(both.len()),
            &all(cell_only.len()),
            &all(ref_only.len()),
        )?;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(BOOTSTRAP_SEED);
        let mut draw = |n: usize| {
            (0..n)
                .map(|_| rng.random_range(0..n))
                .collect::<Vec<usize>>()
        };
        let key_of = |o: OnCurve| match o {
            OnCurve::Below => f64::NEG_INFINITY,
            OnCurve::At(x) => x,
            OnCurve::Above => f64::INFINITY,
        };
        let mut values: Vec<f64> = (0..MULTIPLE_RESAMPLES)
            .filter_map(|_| {
                let (b, c, r) = (
                    draw(both.len()),
                    draw(cell_only.len()),
                    draw(ref_only.len()),
                );
                at(&b, &c, &r).map(key_of)
            })
            .collect();
        if values.is_empty() {
            return None;
        }
        values.sort_by(f64::total_cmp);
        let pick = |q: f64| {
            let v = values[((q * values.len() as f64).floor() as usize).min(values.len() - 1)];
            if v == f64::NEG_INFINITY {
                OnCurve::Below
            } else if v == f64::INFINITY {
                OnCurve::Above
            } else {
                OnCurve::At(v)
            }
        };
        let (first, last) = (
            reference[0].0 as f64,
            reference[reference.len() - 1].0 as f64,
        );
        Some(EffortMultiple {
            estimate,
            interval: (pick(0.025), pick(0.975)),
            bounds: (first / budget, last / budget),
        })
    }

    /// One end or the estimate as text: "2.1x", "> 4x", "< 0.25x".
    fn side(&self, o: OnCurve) -> String {
        match o {
            OnCurve::Below => format!("< {}x", fmt_multiple(self.bounds.0)),
            OnCurve::At(x) => format!("{}x", fmt_multiple(x)),
            OnCurve::Above => format!("> {}x", fmt_multiple(self.bounds.1)),
        }
    }

    /// "2.1x [1.4x, 3.0x]".
    fn text(&self) -> String {
        format!(
            "{} [{}, {}]",
            self.side(self.estimate),
            self.side(self.interval.0),
            self.side(self.interval.1)
        )
    }

    /// effort.csv's value: the number, or the bound with `>` or `<` where censored.
    fn csv(&self, o: OnCurve) -> String {
        match o {
            OnCurve::Below => format!("<{}", self.bounds.0),
            OnCurve::At(x) => format!("{x}"),
            OnCurve::Above => format!(">{}", self.bounds.1),
        }
    }
}

/// effort.md's headline: every rule's worth in the expert's own unit, at each budget, on the seeds outside the
/// held-out ones.
fn headline(measured: &Measured) -> String {
    let (cells, _, envs) = measured.parts();
    let mut out = format!(
        "## The expert's effort in its own unit\n\nWhat each rule's AUC is worth in the expert's effort: the budget \
         at which asking at random ({REFERENCE_RULE}) reaches the rule's median AUC, as a multiple of the rule's \
         budget, read on asking at random's curve of median AUCs over its budgets (1/4 to 4 times the paper's; made \
         non-decreasing by isotonic regression and interpolated in log budget), with a seeded percentile bootstrap \
         95% interval over seeds ({MULTIPLE_RESAMPLES} resamples; seeds the rule and the curve share are resampled \
         together). \"2x\": asking at random needs twice the rule's budget for the same AUC; \"0.5x\": half of it. \
         Outside the curve the multiple is censored: \"> 4x\" when the rule's AUC lies above the curve's largest \
         budget (4 times the paper's budget, for a rule at the paper's), \"< 0.25x\" when it lies below the \
         curve's smallest budget. {net} network, seeds outside the held-out ones; the held-out cells have \
         theirs in their tables (the column \"effort multiple\") and in effort.csv.\n",
        net = EFFORT_NET.name()
    );
    for env in envs {
        let keys: Vec<&CellKey> = cells
            .keys()
            .filter(|k| &k.0 == env && k.2 == EFFORT_NET.name() && k.4 == Group::Screen)
            .collect();
        let budgets: std::collections::BTreeSet<usize> = keys.iter().map(|k| k.3).collect();
        let mut rules: Vec<(usize, String)> = keys
            .iter()
            .map(|k| (rank_rule(&k.1), k.1.clone()))
            .collect();
        rules.sort();
        rules.dedup();
        if measured.multiples.keys().all(|k| &k.0 != env) {
            continue;
        }
        let (header, rule) = budget_columns(env, &budgets);
        let _ = writeln!(out, "\n### {env}\n\n| rule | {header} |\n|---|{rule}");
        for (_, rule) in rules {
            let row: Vec<String> = budgets
                .iter()
                .map(|&b| {
                    let key = (
                        env.clone(),
                        rule.clone(),
                        EFFORT_NET.name().to_string(),
                        b,
                        Group::Screen,
                    );
                    measured
                        .multiples
                        .get(&key)
                        .map_or("–".to_string(), EffortMultiple::text)
                })
                .collect();
            let _ = writeln!(out, "| {rule} | {} |", row.join(" | "));
        }
    }
    out
}

/// A scale of `values` robust to the seeds that never learn: the interquartile range over 1.349 (the standard
/// deviation for normal data); the sample standard deviation where the quartiles coincide.
fn robust_sd(values: &[f64]) -> Option<f64> {
    let iqr = super::stats::quantile(values, 0.75)? - super::stats::quantile(values, 0.25)?;
    if iqr > 0.0 {
        Some(iqr / 1.349)
    } else {
        sample_sd(values)
    }
}

/// The second held-out test: its rule against GDQN, BDQN and ADQN in each of its cells, the primary analysis of
/// its directional claim (beats all three: the intersection-union test, Holm over the cells), the two-sided analysis
/// fixed before its runs, and the paired one (secondary), and what they say.
fn second_test(measured: &Measured) -> String {
    let (cells, comparisons, _) = measured.parts();
    let mut out = format!(
        "## The second held-out test\n\n`{SECOND_HELD_OUT_RULE}` against GDQN, BDQN and ADQN at a fraction of \
         the paper's budget, {} network, seeds {} (fixed in crates/arld-lab/src/protocol.rs before any of these runs). \
         Its claim is directional: the rule wins a cell if its AUC is above all three paper rules there. Primary \
         analysis: the intersection-union test of that claim (three one-sided Mann-Whitney tests, each at \
         {TEST_LEVEL}: its p is the largest one-sided p), Holm-adjusted over the test's {} cells. The analysis fixed \
         before the runs (two-sided Mann-Whitney, Holm over the nine comparisons: \"Holm p\") is kept beside it. \
         Shift: the rule minus the paper rule, Hodges-Lehmann with 95% interval. Equivalence: two one-sided tests \
         within the task's margin (\"The margin\"), Holm-adjusted. Paired (secondary): Wilcoxon signed-rank on the \
         shared seeds.\n\n\
         | cell | seeds | against | shift | p | Holm p | equivalence Holm p | reading | paired shift | paired Holm \
         p | one-sided p |\n|---|---|---|---|---|---|---|---|---|---|---|",
        EFFORT_NET.name(),
        seed_span(&SECOND_HELD_OUT_SEEDS),
        SECOND_HELD_OUT_CELLS.len(),
    );
    let full = SECOND_HELD_OUT_SEEDS.count();
    let rule = canonical_rule(SECOND_HELD_OUT_RULE);
    let mut readings = Vec::new();
    let mut claim_rows = Vec::new();
    let mut any = false;
    for (env, scale) in SECOND_HELD_OUT_CELLS {
        let budget = scaled_budget(env, scale);
        let key = |label: &str| {
            (
                env.to_string(),
                label.to_string(),
                EFFORT_NET.name().to_string(),
                budget,
                Group::SecondHeldOut,
            )
        };
        let name = format!("{env} {} ({budget})", budget_multiple(env, budget));
        let counts: Vec<usize> = std::iter::once(rule.as_str())
            .chain(BASELINES.iter().map(|(l, _)| *l))
            .map(|l| cells.get(&key(l)).map_or(0, Vec::len))
            .collect();
        if counts.iter().all(|&c| c == 0) {
            readings.push(format!("{name}: not run yet."));
            continue;
        }
        any = true;
        if !counts.iter().all(|&c| c == full) {
            readings.push(format!(
                "{name}: incomplete ({} of {full} seeds for the slowest rule so far); no reading until every rule \
                 has every seed.",
                counts.iter().min().unwrap_or(&0)
            ));
            continue;
        }
        let mut ruled_out = Vec::new();
        for (label, method) in BASELINES {
            let Some(c) = find(comparisons, &key(&rule), &key(label)) else {
                let _ = write!(
                    out,
                    "\n| {name} | – | {} | – | – | – | – | not run yet | – | – | – |",
                    method.to_uppercase()
                );
                continue;
            };
            let _ = write!(
                out,
                "\n| {name} | {} | {} | {} | {} | {} |",
                c.seeds,
                method.to_uppercase(),
                c.test_cells(),
                fmt_p(c.paired_holm),
                fmt_p(c.p_greater),
            );
            if let Some((_, (_, hi))) = c.shift {
                ruled_out.push(format!("{hi:+.3} over {}", method.to_uppercase()));
            }
        }
        if let Some(claim) = measured.claims.iter().find(|cl| cl.cell == key(&rule)) {
            claim_rows.push(format!(
                "| {name} | {} | {} | {} |",
                fmt_p(claim.p),
                fmt_p(claim.holm),
                claim.reading(comparisons)
            ));
        }
        readings.push(format!(
            "{name}: gains above {} are ruled out at 95%.",
            ruled_out.join(", ")
        ));
    }
    if !any {
        return format!(
            "## The second held-out test\n\nNot run yet: `arld reproduce --part held_out_2` runs \
             `{SECOND_HELD_OUT_RULE}` and the paper's rules on seeds {}.\n",
            seed_span(&SECOND_HELD_OUT_SEEDS)
        );
    }
    out.push_str("\n\n");
    if !claim_rows.is_empty() {
        let _ = writeln!(
            out,
            "The claim, cell by cell (the primary analysis):\n\n| cell | intersection-union p | Holm p over the \
             cells | reading |\n|---|---|---|---|\n{}\n",
            claim_rows.join("\n")
        );
    }
    for r in readings {
        let _ = writeln!(out, "- {r}");
    }
    out
}

/// What the effort benchmark wrote.
pub struct EffortReport {
    /// Markdown (also the body of effort.md).
    pub markdown: String,
    pub csv: String,
    /// effort_comparisons.csv: every comparison with its shift, interval and raw and adjusted p-values.
    pub comparisons_csv: String,
    pub figures: Vec<(String, FigureContent)>,
}

/// Computes the effort tables and figures from `runs`; `None` when no run belongs to the benchmark beyond the
/// paper's methods at their own budget.
pub fn effort(runs: &[RunRecord], k: usize) -> Result<Option<EffortReport>> {
    let mut cells: BTreeMap<CellKey, Vec<RunMetrics>> = BTreeMap::new();
    let mut refs: BTreeMap<String, (f64, f64)> = BTreeMap::new();
    let mut beyond_paper = false;
    let mut cost: BTreeMap<String, Cost> = BTreeMap::new();
    for run in runs {
        let Some((rule, budget)) = rule_and_budget(run) else {
            continue;
        };
        beyond_paper |= run.variant != DEFAULT_VARIANT;
        if let Some(summary) = &run.summary {
            cost.entry(run.id.env.clone()).or_default().add(summary);
        }
        let env = run.id.env.clone();
        if !refs.contains_key(&env) {
            refs.insert(env.clone(), references(&env)?);
        }
        let held_out = Group::of(run.id.seed);
        cells
            .entry((env, rule, run.id.net.name().to_string(), budget, held_out))
            .or_default()
            .push(metrics(run, refs[&run.id.env], k));
    }
    if !beyond_paper {
        return Ok(None);
    }
    // The budget comparisons first: the reference rule's gives each task's margin, which the others use.
    let mut budgets = budget_comparisons(&cells);
    adjust(&mut budgets);
    let doublings = Doubling::of(&budgets);
    let margins: BTreeMap<String, Option<f64>> = doublings
        .iter()
        .map(|(env, d)| (env.clone(), d.margin()))
        .collect();
    let mut all = comparisons(&cells, &margins);
    adjust(&mut all);
    all.extend(budgets);
    let claims = Claim::all(&cells, &all);
    let multiples: BTreeMap<CellKey, EffortMultiple> = cells
        .keys()
        .filter_map(|k| Some((k.clone(), EffortMultiple::of(k, &cells)?)))
        .collect();
    let envs = env_order(cells.keys().map(|k| k.0.as_str()));
    let mut md = String::new();
    let mut csv = String::from(
        "env,rule,net,budget,budget_scale,seeds,held_out,auc_median,auc_lo,auc_hi,first_hit_median,first_hit_lo,\
         first_hit_hi,sustained_median,sustained_lo,sustained_hi,final_median,final_lo,final_hi,p_vs_gdqn,\
         p_vs_bdqn,p_vs_adqn,transitions_median,questions_median,last_question_median,random_return,expert_return,\
         effort_multiple,effort_multiple_lo,effort_multiple_hi,before_learning_median,half_asked_by_median\n",
    );
    writeln!(
        md,
        "AUC: the mean over evaluations of (return - random) / (expert - random), random and expert being the \
         mean returns of the uniform random policy and of the shipped weak expert over {REFERENCE_EPISODES} \
         episodes (seeds {REFERENCE_SEED}..); medians over seeds with bootstrap 95% intervals; effort multiple: \
         the rule's worth in the expert's own unit (\"The expert's effort in its own unit\"); p: the raw two-sided \
         Mann-Whitney p of the AUC against the paper's rule at the same budget and network, on the seeds both \
         have (\"Every comparison\" gives each one's shift, interval, Holm-adjusted p and equivalence test; \
         words such as \"significantly\" follow the adjusted p); effort: demonstrated transitions, questions asked (each a segment of up to segment_len steps, a \
         context switch for a person), the step of the last question, the share of the questions asked before learning \
         starts and the step by which half of them were asked (medians). Sustained: {k} more \
         evaluations at the target after the first.\n"
    )?;
    for env in &envs {
        let (random, expert) = refs[env];
        writeln!(
            md,
            "## {env}\n\nrandom {random:.2}, expert {expert:.2}, the paper's budget {}.\n",
            paper_budget(env)
        )?;
        for held_out in [
            Group::Screen,
            Group::HeldOut,
            Group::SecondHeldOut,
            Group::BoxHeldOut,
        ] {
            let keys: Vec<&CellKey> = cells
                .keys()
                .filter(|k| &k.0 == env && k.4 == held_out)
                .collect();
            if keys.is_empty() {
                continue;
            }
            match held_out {
                Group::Screen => {}
                Group::HeldOut => {
                    writeln!(md, "### Held-out seeds ({})\n", seed_span(&HELD_OUT_SEEDS))?
                }
                Group::SecondHeldOut => writeln!(
                    md,
                    "### Second held-out seeds ({})\n",
                    seed_span(&SECOND_HELD_OUT_SEEDS)
                )?,
                Group::BoxHeldOut => writeln!(
                    md,
                    "### Continuous held-out seeds ({})\n",
                    seed_span(&BOX_HELD_OUT_SEEDS)
                )?,
            }
            writeln!(
                md,
                "| rule | net | budget | seeds | AUC | effort multiple | first hit | sustained | final | p vs GDQN | \
                 p vs BDQN | p vs ADQN | transitions | questions | last question | before learning | half asked by |\n\
                 |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
            )?;
            let mut ordered = keys.clone();
            ordered.sort_by_key(|k| (k.3, k.2.clone(), rank_rule(&k.1), k.1.clone()));
            for key in ordered {
                let cell = &cells[key];
                let base = |method_label: &str| {
                    cells.get(&(
                        key.0.clone(),
                        method_label.to_string(),
                        key.2.clone(),
                        key.3,
                        key.4,
                    ))
                };
                let vals = |f: fn(&RunMetrics) -> f64| cell.iter().map(f).collect::<Vec<f64>>();
                let auc = reading(&vals(|m| m.auc), 3);
                let first = reading(&vals(|m| m.first_hit), 0);
                let sus = reading(&vals(|m| m.sustained), 0);
                let fin = reading(&vals(|m| m.final_score), 1);
                let ps: Vec<Option<f64>> = BASELINES
                    .iter()
                    .map(|(label, _)| {
                        if *label == key.1 {
                            None
                        } else {
                            compare(cell, base(label)).0
                        }
                    })
                    .collect();
                let transitions = median(&vals(|m| m.transitions)).unwrap_or(f64::NAN);
                let questions = median(&vals(|m| m.questions)).unwrap_or(f64::NAN);
                let last: Vec<f64> = cell.iter().filter_map(|m| m.last_question).collect();
                let last = median(&last);
                let before: Vec<f64> = cell.iter().filter_map(|m| m.before_learning).collect();
                let before = median(&before);
                let half: Vec<f64> = cell.iter().filter_map(|m| m.half_asked_by).collect();
                let half = median(&half);
                // The same row in both tables: the key, the four readings, the three p values, the effort.
                let readings = [&auc, &first, &sus, &fin];
                let multiple = multiples.get(key);
                let mut md_row = format!(
                    "| {} | {} | {} | {} | {} | {} |",
                    key.1,
                    key.2,
                    key.3,
                    cell.len(),
                    auc.2,
                    multiple.map_or("–".to_string(), EffortMultiple::text)
                );
                let mut csv_row = format!(
                    "{},{},{},{},{},{},{}",
                    key.0,
                    csv_field(&key.1),
                    key.2,
                    key.3,
                    key.3 as f64 / paper_budget(&key.0).max(1) as f64,
                    cell.len(),
                    key.4.csv(),
                );
                for (i, (m, (lo, hi), shown)) in readings.into_iter().enumerate() {
                    if i > 0 {
                        write!(md_row, " {shown} |")?;
                    }
                    write!(csv_row, ",{m},{lo},{hi}")?;
                }
                for p in &ps {
                    write!(md_row, " {} |", fmt_p(*p))?;
                    write!(csv_row, ",{}", p.map_or(String::new(), |p| format!("{p}")))?;
                }
                let step = |v: Option<f64>| v.map_or("–".into(), |s| format!("{s:.0}"));
                writeln!(
                    md,
                    "{md_row} {transitions:.0} | {questions:.0} | {} | {} | {} |",
                    step(last),
                    before.map_or("–".into(), |b| format!("{:.0}%", 100.0 * b)),
                    step(half),
                )?;
                let multiple_csv = multiple.map_or(",,".to_string(), |m| {
                    format!(
                        "{},{},{}",
                        m.csv(m.estimate),
                        m.csv(m.interval.0),
                        m.csv(m.interval.1)
                    )
                });
                writeln!(
                    csv,
                    "{csv_row},{transitions},{questions},{},{random},{expert},{multiple_csv},{},{}",
                    last.map_or(String::new(), |s| format!("{s}")),
                    before.map_or(String::new(), |b| format!("{b}")),
                    half.map_or(String::new(), |s| format!("{s}")),
                )?;
            }
            writeln!(md)?;
        }
    }
    let measured = Measured {
        cells,
        comparisons: all,
        claims,
        doublings,
        multiples,
        envs,
    };
    let (cells, all, envs) = measured.parts();
    let mut body = String::new();
    writeln!(body, "{}", headline(&measured))?;
    body.push_str(&md);
    writeln!(body, "{}", screen(&measured))?;
    writeln!(body, "{}", margin_section(&measured))?;
    writeln!(body, "{}", power(&measured))?;
    writeln!(body, "{}", effort_buys(&measured))?;
    writeln!(body, "{}", design_choice(cells))?;
    writeln!(body, "{}", goal_verdict(&measured))?;
    writeln!(body, "{}", second_test(&measured))?;
    writeln!(body, "{}", box_design_choice(cells))?;
    writeln!(body, "{}", box_test(&measured))?;
    writeln!(body, "{}", cost_section(&cost, envs))?;
    writeln!(body, "{}", comparison_tables(all))?;
    let figures = figures(cells, envs);
    Ok(Some(EffortReport {
        markdown: body,
        csv,
        comparisons_csv: comparisons_csv(all),
        figures,
    }))
}

/// What the benchmark measured, as the sections of the report read it: the cells, every comparison with its
/// adjusted p-values, and the tasks in the report's order.
struct Measured {
    cells: BTreeMap<CellKey, Vec<RunMetrics>>,
    comparisons: Vec<Comparison>,
    /// The directional claims "beats all three paper rules", with their intersection-union tests.
    claims: Vec<Claim>,
    /// What one doubling of the expert's budget buys on each task (the margins).
    doublings: BTreeMap<String, Doubling>,
    /// Every cell's worth in the expert's own unit, where the reference curve exists.
    multiples: BTreeMap<CellKey, EffortMultiple>,
    envs: Vec<String>,
}

impl Measured {
    fn parts(
        &self,
    ) -> (
        &BTreeMap<CellKey, Vec<RunMetrics>>,
        &[Comparison],
        &[String],
    ) {
        (&self.cells, &self.comparisons, &self.envs)
    }
}

/// The paper's rules first, then the others alphabetically.
fn rank_rule(label: &str) -> usize {
    BASELINES
        .iter()
        .position(|(l, _)| *l == label)
        .unwrap_or(BASELINES.len())
}

fn csv_field(s: &str) -> String {
    if s.contains(',') || s.contains('"') {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The AUCs of a cell's runs on the design seeds ([`DESIGN_SEEDS`]): the own rule is chosen, and budgets are
/// compared, on these only, whatever other seeds a cell has.
fn design_aucs(cell: &[RunMetrics]) -> Vec<f64> {
    cell.iter()
        .filter(|m| DESIGN_SEEDS.contains(&m.seed))
        .map(|m| m.auc)
        .collect()
}

/// The rule screen read at the paper's budget with the benchmark's network, on every seed that is not held out:
/// per task, the rules whose AUC is significantly higher than each of GDQN, BDQN and ADQN, higher than some of
/// them, and lower than some of them (two-sided Mann–Whitney, Holm-adjusted p < [`TEST_LEVEL`] within the
/// task's screen family).
fn screen(measured: &Measured) -> String {
    let (cells, comparisons, envs) = measured.parts();
    let mut out = format!(
        "## The screen at the paper's budget\n\nEvery rule against GDQN, BDQN and ADQN at the paper's budget with \
         the {} network, on its seeds outside the held-out ones. Higher than all three: the directional claim, its \
         intersection-union test (three one-sided Mann-Whitney tests of the AUC, each at {TEST_LEVEL}) Holm-adjusted \
         over the task's rules; higher or lower than some: two-sided Mann-Whitney, Holm-adjusted p < {TEST_LEVEL} \
         within the task's screen family of \"Every comparison\" (in parentheses, the paper's rules it differs \
         from).\n\n| task | seeds per rule | higher than all three | \
         higher than some | lower than some |\n|---|---|---|---|---|",
        EFFORT_NET.name()
    );
    let net = EFFORT_NET.name();
    for env in envs {
        let key = |label: &str| paper_cell(env, label, net, Group::Screen);
        let rules: Vec<&CellKey> = cells
            .keys()
            .filter(|k| {
                k.0 == *env && k.4 == Group::Screen && k.2 == net && k.3 == paper_budget(env)
            })
            .filter(|k| rank_rule(&k.1) == BASELINES.len())
            .collect();
        if rules.is_empty() {
            continue;
        }
        let counts: Vec<usize> = rules.iter().map(|k| cells[*k].len()).collect();
        let (fewest, most) = (
            counts.iter().min().unwrap_or(&0),
            counts.iter().max().unwrap_or(&0),
        );
        let (mut all, mut some, mut lower) = (Vec::new(), Vec::new(), Vec::new());
        for rule in rules {
            let (mut above, mut below) = (Vec::new(), Vec::new());
            for (label, method) in BASELINES {
                if let Some(higher) = significant_side(comparisons, rule, &key(label)) {
                    let side = if higher { &mut above } else { &mut below };
                    side.push(method.to_uppercase());
                }
            }
            let named = |against: &[String]| format!("{} ({})", rule.1, against.join(", "));
            let claim = measured.claims.iter().find(|c| &c.cell == rule);
            if let Some(claim) = claim.filter(|c| c.won()) {
                all.push(format!("{} (Holm {})", rule.1, fmt_p(claim.holm)));
            } else if !above.is_empty() {
                some.push(named(&above));
            }
            if !below.is_empty() {
                lower.push(named(&below));
            }
        }
        let list = |v: &[String]| {
            if v.is_empty() {
                "none".to_string()
            } else {
                v.join("; ")
            }
        };
        let seeds = if fewest == most {
            format!("{most}")
        } else {
            format!("{fewest}-{most}")
        };
        let _ = write!(
            out,
            "\n| {env} | {seeds} | {} | {} | {} |",
            list(&all),
            list(&some),
            list(&lower)
        );
    }
    out.push('\n');
    out
}

/// Seeds `a..b` as "a-(b-1)", for prose and headings.
fn seed_span(seeds: &std::ops::Range<u64>) -> String {
    format!("{}-{}", seeds.start, seeds.end.saturating_sub(1))
}

/// The budget columns of a table of `env`: each budget as its multiple of the paper's with its transitions, joined
/// for a Markdown header row, and the matching separator cells.
fn budget_columns<'a>(env: &str, budgets: impl IntoIterator<Item = &'a usize>) -> (String, String) {
    let names: Vec<String> = budgets
        .into_iter()
        .map(|&b| format!("{} ({b})", budget_multiple(env, b)))
        .collect();
    let rule = "---|".repeat(names.len());
    (names.join(" | "), rule)
}

/// A budget as a multiple of the paper's for `env`: "1/4", "1/2", "1", "2", "4" (or a decimal).
fn budget_multiple(env: &str, budget: usize) -> String {
    let scale = budget as f64 / paper_budget(env).max(1) as f64;
    let fractions = [(0.25, "1/4"), (0.5, "1/2")];
    match fractions.iter().find(|(v, _)| (scale - v).abs() < 1e-9) {
        Some((_, text)) => text.to_string(),
        None if scale.fract() == 0.0 => format!("{scale:.0}"),
        None => format!("{scale:.2}"),
    }
}

/// What more or less of the expert's effort bought, task by task: for every rule run at two budgets or more
/// (design seeds only), its median AUC and first hit at each budget, and the AUC at the largest budget against
/// the smallest (Mann–Whitney).
fn effort_buys(measured: &Measured) -> String {
    let (cells, comparisons, envs) = measured.parts();
    let mut out = String::from(
        "## What the expert's effort buys\n\nFor each rule run at two budgets or more, on every seed outside the \
         held-out ones: the median AUC and, in parentheses, the median first hit at each budget, as a multiple of \
         the paper's; then the largest budget against the smallest, on the seeds both have: the Hodges-Lehmann \
         shift of the AUC with its 95% interval, the Mann-Whitney p and the Holm-adjusted p over the task's \
         budget comparisons.\n",
    );
    for env in envs {
        let mut per_rule: BTreeMap<(usize, String, String), BTreeMap<usize, Vec<RunMetrics>>> =
            BTreeMap::new();
        for (key, cell) in cells
            .iter()
            .filter(|(k, _)| &k.0 == env && k.4 == Group::Screen)
        {
            per_rule
                .entry((rank_rule(&key.1), key.1.clone(), key.2.clone()))
                .or_default()
                .insert(key.3, cell.clone());
        }
        per_rule.retain(|_, by_budget| by_budget.len() >= 2);
        if per_rule.is_empty() {
            continue;
        }
        let budgets: std::collections::BTreeSet<usize> = per_rule
            .values()
            .flat_map(|by_budget| by_budget.keys().copied())
            .collect();
        let (header, rule) = budget_columns(env, &budgets);
        let _ = writeln!(
            out,
            "\n### {env}\n\n| rule | net | {header} | largest vs smallest |\n|---|---|{rule}---|"
        );
        for ((_, rule, net), by_budget) in &per_rule {
            let row: Vec<String> = budgets
                .iter()
                .map(|b| {
                    by_budget.get(b).map_or("–".to_string(), |cell| {
                        let auc = median(&cell.iter().map(|m| m.auc).collect::<Vec<_>>());
                        let hit = median(&cell.iter().map(|m| m.first_hit).collect::<Vec<_>>());
                        format!(
                            "{:.3} ({:.0})",
                            auc.unwrap_or(f64::NAN),
                            hit.unwrap_or(f64::NAN)
                        )
                    })
                })
                .collect();
            let (smallest, largest) = (by_budget.first_key_value(), by_budget.last_key_value());
            let change = match (smallest, largest) {
                (Some((&lo, _)), Some((&hi, _))) => {
                    let key = |b: usize| (env.clone(), rule.clone(), net.clone(), b, Group::Screen);
                    match find(comparisons, &key(hi), &key(lo)) {
                        Some(c) => format!(
                            "{} vs {}: shift {}, {}",
                            budget_multiple(env, hi),
                            budget_multiple(env, lo),
                            c.shift_text(),
                            adjusted_phrase(c)
                        ),
                        None => "–".to_string(),
                    }
                }
                _ => "–".to_string(),
            };
            let _ = writeln!(out, "| {rule} | {net} | {} | {change} |", row.join(" | "));
        }
    }
    out
}

/// The own rule's choice on the design seeds: each candidate's median AUC on every screening task at the
/// paper's budget with the screen's network, their mean, and the candidate with the highest mean.
fn design_choice(cells: &BTreeMap<CellKey, Vec<RunMetrics>>) -> String {
    let mut out = format!(
        "## The own rule's design choice\n\nMedian normalised AUC on the design seeds at the paper's budget with \
         the {} network; the held-out test runs the candidate with the highest mean over the screening tasks.\n\n\
         | candidate | {} | mean |\n|---|{}---|\n",
        EFFORT_NET.name(),
        EFFORT_SCREEN_TASKS.join(" | "),
        "---|".repeat(EFFORT_SCREEN_TASKS.len())
    );
    let mut best: Option<(f64, &str)> = None;
    for candidate in OWN_RULE_CANDIDATES {
        let medians: Vec<Option<f64>> = EFFORT_SCREEN_TASKS
            .iter()
            .map(|env| {
                let key = paper_cell(env, candidate, EFFORT_NET.name(), Group::Screen);
                cells.get(&key).and_then(|c| median(&design_aucs(c)))
            })
            .collect();
        let complete: Option<Vec<f64>> = medians.iter().copied().collect();
        let mean = complete.map(|v| v.iter().sum::<f64>() / v.len() as f64);
        let cell = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
        let row: Vec<String> = medians.iter().map(|&m| cell(m)).collect();
        let _ = writeln!(
            out,
            "| {candidate} | {} | {} |",
            row.join(" | "),
            cell(mean)
        );
        if let Some(mean) = mean
            && best.is_none_or(|(b, _)| mean > b)
        {
            best = Some((mean, candidate));
        }
    }
    let _ = writeln!(
        out,
        "\n{}",
        match best {
            Some((_, candidate)) => format!("The highest mean: **{candidate}**."),
            None => "No candidate has run on every screening task yet.".to_string(),
        }
    );
    out
}

/// The goal of the benchmark, read on the held-out cells at the paper's budget: a rule whose AUC is
/// significantly higher than each of GDQN, BDQN and ADQN on at least 3 of the 4 tasks, and never significantly
/// lower, for each network.
fn goal_verdict(measured: &Measured) -> String {
    let (cells, comparisons, envs) = measured.parts();
    let mut out = String::from(
        "## The held-out test\n\nThe goal is directional: a rule above each of GDQN, BDQN and ADQN on at least 3 of \
         the 4 tasks, and never below one. A task counts as won when the intersection-union test of \"above all \
         three\" (three one-sided Mann-Whitney tests, each at the level) succeeds after Holm's adjustment over the \
         test's cells (every task and network); \"below\" follows the two-sided p, Holm-adjusted within each \
         task's held-out family (\"Every comparison\"); shift: the rule minus the paper rule, Hodges-Lehmann with \
         95% interval.\n\n",
    );
    let candidates: std::collections::BTreeSet<(String, String)> = cells
        .keys()
        .filter(|k| {
            k.4 == Group::HeldOut && rank_rule(&k.1) == BASELINES.len() && k.3 == paper_budget(&k.0)
        })
        .map(|k| (k.1.clone(), k.2.clone()))
        .collect();
    if candidates.is_empty() {
        let _ = writeln!(
            out,
            "Not run yet: the held-out seeds {} are fixed in crates/arld-lab/src/protocol.rs and no \
             run of them exists. A rule is chosen on the design seeds first.",
            seed_span(&HELD_OUT_SEEDS)
        );
        return out;
    }
    let full = HELD_OUT_SEEDS.count();
    let mut claim_rows = Vec::new();
    for (rule, net) in candidates {
        let (mut wins, mut losses, mut tasks) = (0, 0, 0);
        let mut lines = Vec::new();
        let mut incomplete = Vec::new();
        for env in envs {
            let key = |label: &str| paper_cell(env, label, &net, Group::HeldOut);
            // A task counts once the rule and the three paper rules have every held-out seed.
            let complete = std::iter::once(rule.as_str())
                .chain(BASELINES.iter().map(|(label, _)| *label))
                .all(|label| cells.get(&key(label)).is_some_and(|c| c.len() == full));
            if !complete {
                incomplete.push(env.as_str());
                continue;
            }
            tasks += 1;
            for (label, _) in BASELINES {
                if significant_side(comparisons, &key(&rule), &key(label)) == Some(false) {
                    losses += 1;
                }
                let text = find(comparisons, &key(&rule), &key(label)).map_or(
                    "not compared".to_string(),
                    |c| {
                        format!(
                            "shift {}, {}: {}",
                            c.shift_text(),
                            adjusted_phrase(c),
                            c.reading()
                        )
                    },
                );
                lines.push(format!("{env} vs {label}: {text}"));
            }
            if let Some(claim) = measured.claims.iter().find(|c| c.cell == key(&rule)) {
                wins += usize::from(claim.won());
                claim_rows.push(format!(
                    "| {rule} | {net} | {env} | {} | {} | {} |",
                    fmt_p(claim.p),
                    fmt_p(claim.holm),
                    claim.reading(comparisons)
                ));
            }
        }
        let met = tasks == envs.len() && wins >= 3 && losses == 0;
        let verdict = if met {
            "the goal is met".to_string()
        } else if wins + incomplete.len() >= 3 && losses == 0 {
            format!(
                "no verdict yet: the held-out runs of {} are not complete ({full} seeds per cell)",
                incomplete.join(", ")
            )
        } else if incomplete.is_empty() {
            "the goal is not met".to_string()
        } else {
            format!(
                "the goal is not met, whatever the held-out runs still missing ({}) show",
                incomplete.join(", ")
            )
        };
        let _ = writeln!(
            out,
            "- **{rule}, {net}**: above all three paper rules on {wins} of {tasks} tasks, significantly lower \
             {losses} times: {verdict}.",
        );
        for line in lines {
            let _ = writeln!(out, "  - {line}");
        }
    }
    if !claim_rows.is_empty() {
        let _ = writeln!(
            out,
            "\nThe claim \"above all three\", task by task:\n\n| rule | net | task | intersection-union p | Holm p \
             over the cells | reading |\n|---|---|---|---|---|---|\n{}",
            claim_rows.join("\n")
        );
    }
    out
}

/// The families of rules the figures show apart, one panel each ([`rule_family`]).
const RULE_FAMILIES: [&str; 4] = [
    "the paper's rules",
    "rules that pace the budget",
    "rules from the literature",
    "ranked (ours)",
];

/// The family of a rule's label ([`RULE_FAMILIES`]): the paper's three, the rules that spread the budget over the
/// run, our `ranked` variants, and the other rules from the literature.
fn rule_family(label: &str) -> usize {
    let name = label.split('(').next().unwrap_or(label).trim();
    match name {
        _ if rank_rule(label) < BASELINES.len() => 0,
        "paced" | "budget_paced" | "variable" | "calibrated" => 1,
        "ranked" => 3,
        _ => 2,
    }
}

/// AUC against effort (a panel per task, a line per rule over budgets, on the design seeds as the table "What the
/// expert's effort buys") and cumulative questions against training step at the paper's budget (a row of panels
/// per task, a panel per family of rules, a line per rule), both with the benchmark's network ([`EFFORT_NET`]).
fn figures(
    cells: &BTreeMap<CellKey, Vec<RunMetrics>>,
    envs: &[String],
) -> Vec<(String, FigureContent)> {
    let band_of = |per_x: &BTreeMap<u64, Vec<f64>>| -> Vec<Band> {
        per_x
            .iter()
            .filter_map(|(&x, v)| {
                Some(Band {
                    x: x as f64,
                    median: median(v)?,
                    lower_quartile: super::stats::quantile(v, 0.25)?,
                    upper_quartile: super::stats::quantile(v, 0.75)?,
                })
            })
            .collect()
    };
    // One style per rule across tasks and both figures: the paper's rules first, then the others alphabetically.
    let mut lines: Vec<(usize, String, String)> = cells
        .keys()
        .filter(|k| k.4 == Group::Screen && k.2 == EFFORT_NET.name())
        .map(|k| (rank_rule(&k.1), k.1.clone(), k.2.clone()))
        .collect();
    lines.sort();
    lines.dedup();
    // A panel shows one family of rules (a column of the figure); within it each rule has its own colour, and
    // each family its own line pattern, so no two rules of the figure look alike.
    let style_of = |rule: &str, net: &str| {
        let family = rule_family(rule);
        let member = lines
            .iter()
            .filter(|(_, r, _)| rule_family(r) == family)
            .position(|(_, r, n)| r == rule && n == net)
            .unwrap_or(0);
        super::plot::family_style(family, member)
    };
    let rule_order: Vec<&String> = lines.iter().map(|(_, rule, _)| rule).collect();
    // The rules run at a budget other than the paper's, in the same order.
    let budget_rules: Vec<&String> = rule_order
        .iter()
        .copied()
        .filter(|rule| {
            cells.keys().any(|k| {
                &k.1 == *rule
                    && k.4 == Group::Screen
                    && k.2 == EFFORT_NET.name()
                    && k.3 != paper_budget(&k.0)
            })
        })
        .collect();
    let mut auc_panels = Vec::new();
    let mut question_panels = Vec::new();
    for env in envs {
        type PerX = BTreeMap<u64, Vec<f64>>;
        let mut by_rule: BTreeMap<(String, String), PerX> = BTreeMap::new();
        let mut questions: BTreeMap<(String, String), PerX> = BTreeMap::new();
        let in_figures =
            |k: &CellKey| &k.0 == env && k.4 == Group::Screen && k.2 == EFFORT_NET.name();
        for (key, cell) in cells.iter().filter(|(k, _)| in_figures(k)) {
            let design: Vec<f64> = cell.iter().map(|m| m.auc).collect();
            if !design.is_empty() {
                by_rule
                    .entry((key.1.clone(), key.2.clone()))
                    .or_default()
                    .entry(key.3 as u64)
                    .or_default()
                    .extend(design);
            }
            if key.3 == paper_budget(env) {
                let per_step = questions.entry((key.1.clone(), key.2.clone())).or_default();
                for m in cell {
                    // Every run starts at no question (step 0), so a rule that asks at once rises from 0.
                    per_step.entry(0).or_default().push(0.0);
                    for &(step, asked) in &m.questions_at {
                        per_step.entry(step).or_default().push(asked as f64);
                    }
                }
            }
        }
        let curves = |lines: &BTreeMap<(String, String), PerX>, min_points: usize| -> Vec<Curve> {
            let mut curves = lines
                .iter()
                .filter(|(_, per)| per.len() >= min_points)
                .map(|((rule, net), per)| Curve {
                    label: rule.clone(),
                    color: style_of(rule, net),
                    points: band_of(per),
                })
                .collect::<Vec<_>>();
            // The legend lists rules in the order of their styles' ranking: the paper's first.
            curves.sort_by_key(|c| rule_order.iter().position(|r| **r == c.label));
            curves
        };
        // Budgets as log2 of the multiple of the paper's: 1/4 .. 4 evenly spaced.
        let paper = paper_budget(env).max(1) as f64;
        let mut auc = curves(&by_rule, 2);
        for point in auc.iter_mut().flat_map(|c| c.points.iter_mut()) {
            point.x = (point.x / paper).log2();
        }
        // The few rules run at several budgets share one panel, each in its own colour.
        for curve in &mut auc {
            let member = budget_rules.iter().position(|r| **r == curve.label);
            curve.color = super::plot::family_style(0, member.unwrap_or(budget_rules.len()));
        }
        if !auc.is_empty() {
            auc_panels.push(Panel::new(env.clone(), None, auc));
        }
        let asked = curves(&questions, 1);
        for (family, name) in RULE_FAMILIES.iter().enumerate() {
            let of_family: Vec<Curve> = asked
                .iter()
                .filter(|c| rule_family(&c.label) == family)
                .cloned()
                .collect();
            if !of_family.is_empty() {
                question_panels.push(Panel::new(format!("{env}: {name}"), None, of_family));
            }
        }
    }
    let mut out = Vec::new();
    if !auc_panels.is_empty() {
        out.push((
            "effort_auc".to_string(),
            FigureContent {
                title: format!(
                    "What the expert's effort buys: normalised AUC against the budget ({} network)",
                    EFFORT_NET.name()
                ),
                x_label: "budget (multiple of the paper's, log scale)".into(),
                x_scale: XScale::Log2Multiple,
                y_label: "normalised AUC (median, IQR over seeds)".into(),
                panels: auc_panels,
            },
        ));
    }
    if !question_panels.is_empty() {
        out.push((
            "effort_questions".to_string(),
            FigureContent {
                title: format!(
                    "When each rule asks: questions asked so far, at the paper's budget ({} network)",
                    EFFORT_NET.name()
                ),
                x_label: "training step".into(),
                x_scale: XScale::Steps,
                y_label: "questions asked (median, IQR over seeds)".into(),
                panels: question_panels,
            },
        ));
    }
    out
}

/// Writes effort.md, effort.csv and the figures into `out_dir`; returns the files written.
pub fn write_effort(
    runs: &[RunRecord],
    out_dir: &Path,
    k: usize,
) -> Result<Vec<std::path::PathBuf>> {
    let Some(report) = effort(runs, k)? else {
        return Ok(Vec::new());
    };
    let mut files = Vec::new();
    let md_path = out_dir.join("effort.md");
    let figure_links: String = report
        .figures
        .iter()
        .map(|(name, content)| format!("![{}]({name}.png)\n\n", content.title))
        .collect();
    let md = format!(
        "# The effort benchmark: which rule spends the expert's effort best\n\nWritten by `arld report` from \
         the run directories; every number is recomputed from them.\n\n{}\n## Figures\n\n{figure_links}\
         (The AUC-against-budget figure appears once a rule has runs at two budgets or more.)\n",
        report.markdown
    );
    arld_core::files::write_atomic(&md_path, md.as_bytes())?;
    files.push(md_path);
    let csv_path = out_dir.join("effort.csv");
    arld_core::files::write_atomic(&csv_path, report.csv.as_bytes())?;
    files.push(csv_path);
    let comparisons_path = out_dir.join("effort_comparisons.csv");
    arld_core::files::write_atomic(&comparisons_path, report.comparisons_csv.as_bytes())?;
    files.push(comparisons_path);
    for (name, content) in &report.figures {
        files.extend(super::plot::draw_figure(content, out_dir, name)?);
    }
    Ok(files)
}

/// The held-out seeds of `env`'s kind of task: the continuous test's for a task with actions in a box.
fn held_out_seeds(env: &str) -> std::ops::Range<u64> {
    if arld_core::env::box_spec(env).is_ok() {
        BOX_HELD_OUT_SEEDS
    } else {
        HELD_OUT_SEEDS
    }
}

/// The median AUC of each of [`BOX_CANDIDATES`] on [`BOX_DESIGN_SEEDS`] at `env`'s preset budget, best first; ties
/// in the candidates' order.
fn box_ranking(
    cells: &BTreeMap<CellKey, Vec<RunMetrics>>,
    env: &str,
) -> Vec<(&'static str, f64, usize)> {
    let mut ranked: Vec<(&'static str, f64, usize)> = BOX_CANDIDATES
        .iter()
        .filter_map(|&label| {
            let cell = cells.get(&paper_cell(env, label, EFFORT_NET.name(), Group::Screen))?;
            let aucs: Vec<f64> = cell
                .iter()
                .filter(|m| BOX_DESIGN_SEEDS.contains(&m.seed))
                .map(|m| m.auc)
                .collect();
            Some((label, median(&aucs)?, aucs.len()))
        })
        .collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    ranked
}

/// "The continuous rule's design choice": the candidates ranked by their median AUC on the design seeds on each
/// task of the continuous held-out test. At one budget, the rank by median AUC is the rank by effort multiple
/// (both read the same reference curve), without its censoring.
fn box_design_choice(cells: &BTreeMap<CellKey, Vec<RunMetrics>>) -> String {
    let mut out = format!(
        "## The continuous rule's design choice\n\nThe candidates for the continuous held-out test (every rule of \
         the continuous benchmark that is not the paper's), ranked by their median normalised AUC on the design \
         seeds {} at the preset's budget: at one budget this is their rank by the effort multiple, without its \
         censoring. The best one on the test's tasks is the rule the held-out seeds test \
         (crates/arld-lab/src/protocol.rs, `BOX_HELD_OUT_RULE`).\n",
        seed_span(&BOX_DESIGN_SEEDS)
    );
    for env in BOX_HELD_OUT_TASKS {
        let ranked = box_ranking(cells, env);
        if ranked.is_empty() {
            let _ = writeln!(out, "\n{env}: no design runs yet.");
            continue;
        }
        let _ = writeln!(
            out,
            "\n| {env} | median AUC | design seeds |\n|---|---|---|"
        );
        for (label, auc, n) in ranked {
            let _ = writeln!(out, "| {label} | {auc:.3} | {n} |");
        }
    }
    out
}

/// "The continuous held-out test": its rule against each paper rule on each of [`BOX_HELD_OUT_TASKS`] at the
/// preset's budget, on [`BOX_HELD_OUT_SEEDS`]: the intersection-union test of "above all three", Holm-adjusted
/// over the test's tasks, and each comparison's shift; reported whatever it says.
fn box_test(measured: &Measured) -> String {
    let (cells, comparisons, _) = measured.parts();
    let mut out = format!(
        "## The continuous held-out test\n\nFixed before its runs: the rule `{BOX_HELD_OUT_RULE}` (the design \
         choice above) against GDQN, BDQN and ADQN at the preset's budget on {}, seeds {} ({} per cell). The \
         claim: the rule's AUC lies above each of the three (the intersection-union test of three one-sided \
         Mann-Whitney tests, each at {TEST_LEVEL}), Holm-adjusted over the test's tasks.\n",
        BOX_HELD_OUT_TASKS.join(", "),
        seed_span(&BOX_HELD_OUT_SEEDS),
        BOX_HELD_OUT_SEEDS.count(),
    );
    let full = BOX_HELD_OUT_SEEDS.count();
    for env in BOX_HELD_OUT_TASKS {
        let key = |label: &str| paper_cell(env, label, EFFORT_NET.name(), Group::BoxHeldOut);
        let have: Vec<usize> = std::iter::once(BOX_HELD_OUT_RULE)
            .chain(BASELINES.iter().map(|(label, _)| *label))
            .map(|label| cells.get(&key(label)).map_or(0, Vec::len))
            .collect();
        if have.iter().any(|&n| n < full) {
            let _ = writeln!(
                out,
                "\n{env}: not complete yet ({} of {} runs).",
                have.iter().sum::<usize>(),
                full * have.len()
            );
            continue;
        }
        let claim = measured
            .claims
            .iter()
            .find(|c| c.cell == key(BOX_HELD_OUT_RULE));
        let verdict = match claim {
            Some(c) if c.won() => "above all three",
            Some(_) => "not shown: not above all three at this level",
            None => "not tested",
        };
        let _ = writeln!(
            out,
            "\n| {env} | shift | one-sided p | Holm p over the tasks | reading |\n|---|---|---|---|---|"
        );
        for (label, _) in BASELINES {
            let row = find(comparisons, &key(BOX_HELD_OUT_RULE), &key(label)).map_or(
                "| – | – | – | not compared |".to_string(),
                |c| {
                    format!(
                        "| {} | {} | – | {} |",
                        c.shift_text(),
                        fmt_p(c.p_greater),
                        c.reading()
                    )
                },
            );
            let _ = writeln!(out, "| against {label} {row}");
        }
        let _ = writeln!(
            out,
            "| above all three (intersection-union) | – | {} | {} | {verdict} |",
            fmt_p(claim.and_then(|c| c.p)),
            fmt_p(claim.and_then(|c| c.holm)),
        );
    }
    out
}

/// What one task's benchmark runs cost: how many, their wall time in seconds and their environment steps.
#[derive(Default)]
struct Cost {
    runs: usize,
    seconds: Vec<f64>,
    steps: u64,
}

impl Cost {
    fn add(&mut self, summary: &arld_core::train::run_dir::Summary) {
        self.runs += 1;
        self.seconds.push(summary.wall_time_s);
        self.steps += summary.train_steps as u64;
    }
}

/// "What the runs cost": per task, the benchmark's runs, their core-hours (each run uses one core) and steps per
/// second, as their `summary.json` files record them (on whatever machine, under whatever load, they ran).
fn cost_section(cost: &BTreeMap<String, Cost>, envs: &[String]) -> String {
    let mut out = String::from(
        "## What the runs cost\n\nThe benchmark's runs per task (every rule, budget and seed group of this report, \
         the paper rules' runs at the paper's budget included), the core-hours their `summary.json` files record \
         (wall time; a run uses one core) and the environment steps per second over all of them.\n\n| task | runs | \
         core-hours | steps per second |\n|---|---|---|---|\n",
    );
    for env in envs {
        let Some(c) = cost.get(env) else { continue };
        let seconds = exact_sum(c.seconds.iter().copied());
        let _ = writeln!(
            out,
            "| {env} | {} | {:.2} | {:.0} |",
            c.runs,
            seconds / 3600.0,
            c.steps as f64 / seconds.max(f64::MIN_POSITIVE)
        );
    }
    out
}
