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
//! interval, the raw Mann–Whitney p and the Holm-adjusted p within its family ([`Family`]), two one-sided tests of
//! equivalence within [`EQUIVALENCE_MARGIN`], and the paired Wilcoxon test on the seeds both share (the same seed
//! gives both rules the same initial weights, the same replay and rule random streams and the same first resets).
//! A run's AUC is an exactly rounded sum ([`exact_sum`]), so equal curves give equal AUCs and ties stay ties.

use super::plot::{Band, Curve, FigureContent, Panel, XScale};
use super::protocol::{
    DESIGN_SEEDS, EFFORT_NET, EFFORT_SCREEN_TASKS, EQUIVALENCE_MARGIN, HELD_OUT_SEEDS,
    OWN_RULE_CANDIDATES, PAPER_SEEDS, SECOND_HELD_OUT_CELLS, SECOND_HELD_OUT_RULE,
    SECOND_HELD_OUT_SEEDS, TEST_LEVEL, env_order, is_effort_variant, paper_budget, scaled_budget,
};
use super::stats::{
    bootstrap_median_interval, detectable_difference, equivalence_p, exact_sum, final_score,
    hodges_lehmann, holm, mann_whitney, median, sample_sd, sustained, wilcoxon_signed_rank,
};
use super::verdict::FINAL_EVALUATIONS;
use anyhow::Result;
use arld_core::train::run_dir::{DEFAULT_VARIANT, RunRecord, canonical_rule};
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// Episodes behind the random policy's and the expert's reference returns.
pub const REFERENCE_EPISODES: usize = 100;
/// Seed of the reference episodes (episode i resets with `REFERENCE_SEED + i`).
pub const REFERENCE_SEED: u64 = 1_000_000;
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
    first_hit: f64,
    sustained: f64,
    final_score: f64,
    transitions: f64,
    questions: f64,
    last_question: Option<f64>,
    /// Questions asked before each evaluation: (evaluation step, count), for the figure.
    questions_at: Vec<(u64, u64)>,
}

/// Which seeds a cell holds: the design and screen seeds, the first held-out test's or the second's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Group {
    Screen,
    HeldOut,
    SecondHeldOut,
}

impl Group {
    fn of(seed: u64) -> Group {
        if HELD_OUT_SEEDS.contains(&seed) {
            Group::HeldOut
        } else if SECOND_HELD_OUT_SEEDS.contains(&seed) {
            Group::SecondHeldOut
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
        }
    }
}

/// One cell's key: task, rule label, network, budget, seed group.
type CellKey = (String, String, String, usize, Group);

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
    let label = match &run.config.query_rule {
        Some(rule) => rule.clone(),
        None => BASELINES
            .iter()
            .find(|(_, m)| *m == method)
            .map(|(l, _)| l.to_string())
            .expect("a querying method"),
    };
    Some((label, budget))
}

/// Mean returns of the random policy (a uniform draw from the actions, or from the box) and of the shipped weak
/// expert on `env`.
fn references(env: &str) -> Result<(f64, f64)> {
    use arld_core::env::{self, rollouts};
    let mut rng = rand_pcg::Pcg64::seed_from_u64(REFERENCE_SEED);
    let seeds = |i: usize| Some(REFERENCE_SEED + i as u64);
    let random = match env::box_spec(env) {
        Ok(spec) => rollouts(
            env::make_box(env)?.as_mut(),
            REFERENCE_EPISODES,
            seeds,
            |_| {
                let (low, high) = (spec.action_low.iter(), spec.action_high.iter());
                let action = low.zip(high).map(|(&l, &h)| rng.random_range(l..=h));
                Ok::<_, anyhow::Error>(action.collect())
            },
        )?,
        Err(_) => {
            let mut e = env::make(env)?;
            let n_actions = e.n_actions();
            rollouts(e.as_mut(), REFERENCE_EPISODES, seeds, |_| {
                Ok::<_, anyhow::Error>(rng.random_range(0..n_actions))
            })?
        }
    };
    let stats = arld_core::expert::pipeline::evaluate_spec(
        "shipped:weak",
        env,
        REFERENCE_EPISODES,
        REFERENCE_SEED,
        30.0,
    )?;
    let random_mean = random.iter().map(|e| e.ret).sum::<f64>() / random.len() as f64;
    Ok((random_mean, stats.mean))
}

/// What `run` measured; its evaluation means are finite ([`super::report::report`] refuses a run otherwise).
fn metrics(run: &RunRecord, reference: (f64, f64), k: usize) -> RunMetrics {
    let (random, expert) = reference;
    let span = expert - random;
    let auc = if run.eval.is_empty() {
        f64::NAN
    } else {
        // The mean return first (an exactly rounded sum), then normalised: runs whose means have equal sums get
        // equal AUCs, whatever the order of their evaluations.
        (exact_sum(run.eval.iter().map(|p| p.mean)) / run.eval.len() as f64 - random) / span
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
        questions_at,
    }
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

/// The AUCs of `cell` and `other` on the seeds both have, in seed order (pair i is one seed).
fn shared(cell: &[RunMetrics], other: &[RunMetrics]) -> (Vec<f64>, Vec<f64>) {
    let mut pairs: Vec<(u64, f64, f64)> = cell
        .iter()
        .filter_map(|m| {
            let o = other.iter().find(|o| o.seed == m.seed)?;
            Some((m.seed, m.auc, o.auc))
        })
        .collect();
    pairs.sort_by_key(|p| p.0);
    pairs.iter().map(|p| (p.1, p.2)).unzip()
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

/// A family of comparisons, within which Holm's adjustment runs.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Family {
    /// One task's cells on the design and screen seeds: every rule against every paper rule at the same budget
    /// and network, and the paper rules among themselves.
    Screen(String),
    /// One task's cells on the first held-out seeds.
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
        match self {
            Family::Screen(env) => format!("{env}, seeds outside the held-out ones"),
            Family::HeldOut(env) => format!("{env}, held-out seeds {}", seed_span(&HELD_OUT_SEEDS)),
            Family::SecondTest => format!(
                "the second held-out test ({SECOND_HELD_OUT_RULE} against the paper rules, seeds {})",
                seed_span(&SECOND_HELD_OUT_SEEDS)
            ),
            Family::SecondPaper => format!(
                "the paper rules among themselves, seeds {}",
                seed_span(&SECOND_HELD_OUT_SEEDS)
            ),
            Family::Budgets(env) => {
                format!("{env}, largest budget against smallest (design seeds)")
            }
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
        a: &CellKey,
        b: &CellKey,
        cell_a: &[RunMetrics],
        cell_b: &[RunMetrics],
    ) -> Self {
        let (ours, theirs) = shared(cell_a, cell_b);
        Comparison {
            family,
            a: a.clone(),
            b: b.clone(),
            seeds: ours.len(),
            shift: hodges_lehmann(&ours, &theirs, 0.95),
            p: mann_whitney(&ours, &theirs).map(|(_, p)| p),
            holm: None,
            tost: equivalence_p(&ours, &theirs, EQUIVALENCE_MARGIN),
            tost_holm: None,
            paired: wilcoxon_signed_rank(&ours, &theirs),
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
            format!("level (within ±{EQUIVALENCE_MARGIN})")
        } else {
            "no difference detected".to_string()
        }
    }
}

/// Holm's adjustment of the unpaired, equivalence and paired p-values within each family.
fn adjust(comparisons: &mut [Comparison]) {
    let families: std::collections::BTreeSet<Family> =
        comparisons.iter().map(|c| c.family.clone()).collect();
    for family in families {
        let idx: Vec<usize> = (0..comparisons.len())
            .filter(|&i| comparisons[i].family == family)
            .collect();
        // The second held-out test's family is its fixed set of comparisons: while some have not run, they count
        // as tests that found nothing (p = 1), so that a partial family is never adjusted more leniently.
        let size = if family == Family::SecondTest {
            SECOND_HELD_OUT_CELLS.len() * BASELINES.len()
        } else {
            0
        };
        let padded = |values: Vec<Option<f64>>| -> Vec<Option<f64>> {
            let missing = size.saturating_sub(values.len());
            values
                .into_iter()
                .chain(std::iter::repeat_n(Some(1.0), missing))
                .collect()
        };
        let p = holm(&padded(idx.iter().map(|&i| comparisons[i].p).collect()));
        let t = holm(&padded(idx.iter().map(|&i| comparisons[i].tost).collect()));
        let w = holm(&padded(
            idx.iter()
                .map(|&i| comparisons[i].paired.map(|x| x.1))
                .collect(),
        ));
        for (j, &i) in idx.iter().enumerate() {
            comparisons[i].holm = p[j];
            comparisons[i].tost_holm = t[j];
            comparisons[i].paired_holm = w[j];
        }
    }
}

/// Every comparison of a cell with a paper rule at the same task, budget, network and seed group, each pair
/// once (the paper rules among themselves: the later of the three against the earlier), Holm-adjusted within
/// its family.
fn comparisons(cells: &BTreeMap<CellKey, Vec<RunMetrics>>) -> Vec<Comparison> {
    let mut out = Vec::new();
    for (key, cell) in cells {
        for (label, _) in BASELINES {
            let rank = rank_rule(&key.1);
            if rank <= rank_rule(label) {
                continue;
            }
            let base = (
                key.0.clone(),
                label.to_string(),
                key.2.clone(),
                key.3,
                key.4,
            );
            let Some(other) = cells.get(&base) else {
                continue;
            };
            let family = match key.4 {
                Group::Screen => Family::Screen(key.0.clone()),
                Group::HeldOut => Family::HeldOut(key.0.clone()),
                Group::SecondHeldOut if rank == BASELINES.len() => Family::SecondTest,
                Group::SecondHeldOut => Family::SecondPaper,
            };
            out.push(Comparison::new(family, key, &base, cell, other));
        }
    }
    out
}

/// The budget comparisons of "What the expert's effort buys": for every rule run at two budgets or more on a
/// task, its largest budget against its smallest, on the design seeds.
fn budget_comparisons(cells: &BTreeMap<CellKey, Vec<RunMetrics>>) -> Vec<Comparison> {
    let mut by_rule: BTreeMap<(String, String, String), Vec<&CellKey>> = BTreeMap::new();
    for (key, cell) in cells {
        if key.4 == Group::Screen && cell.iter().any(|m| DESIGN_SEEDS.contains(&m.seed)) {
            by_rule
                .entry((key.0.clone(), key.1.clone(), key.2.clone()))
                .or_default()
                .push(key);
        }
    }
    let design = |key: &CellKey| -> Vec<RunMetrics> {
        cells[key]
            .iter()
            .filter(|m| DESIGN_SEEDS.contains(&m.seed))
            .cloned()
            .collect()
    };
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
            hi,
            lo,
            &design(hi),
            &design(lo),
        ));
    }
    out
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
         both have (each pair once). Shift: the Hodges-Lehmann shift of the AUC (the rule minus the other) with \
         its 95% interval; p: two-sided Mann-Whitney, raw and Holm-adjusted within the family of the table; \
         equivalence: two one-sided tests that the shift lies within ±{EQUIVALENCE_MARGIN}, Holm-adjusted; paired: \
         the Hodges-Lehmann shift of the seed-by-seed differences and the Wilcoxon signed-rank p, raw and \
         Holm-adjusted (the same seed gives both rules the same initial weights, the same replay and rule random \
         streams and the same first resets). The reading follows the adjusted p at {TEST_LEVEL}: significantly \
         higher or lower, level (equivalent within the margin), or no difference detected.\n"
    );
    let families: std::collections::BTreeSet<Family> =
        comparisons.iter().map(|c| c.family.clone()).collect();
    let order = |f: &Family| match f {
        Family::Screen(e) | Family::HeldOut(e) | Family::Budgets(e) => (
            arld_core::paper::task_index(e).unwrap_or(usize::MAX),
            e.clone(),
        ),
        _ => (usize::MAX, String::new()),
    };
    let mut families: Vec<Family> = families.into_iter().collect();
    families.sort_by_key(|f| {
        let kind = match f {
            Family::Screen(_) => 0,
            Family::HeldOut(_) => 1,
            Family::SecondTest => 2,
            Family::SecondPaper => 3,
            Family::Budgets(_) => 4,
        };
        (kind, order(f))
    });
    for family in families {
        let rows: Vec<&Comparison> = comparisons.iter().filter(|c| c.family == family).collect();
        let _ = writeln!(
            out,
            "\n### {} ({} comparisons)\n\n| task | rule | net | budget | against | seeds | shift | p | Holm p | \
             equivalence Holm p | reading | paired shift | paired p | paired Holm p |\n|---|---|---|---|---|---|\
             ---|---|---|---|---|---|---|---|",
            family.describe(),
            rows.len()
        );
        for c in rows {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
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
            );
        }
    }
    out
}

/// effort_comparisons.csv: every comparison of [`comparison_tables`] with full precision.
fn comparisons_csv(comparisons: &[Comparison]) -> String {
    let mut out = String::from(
        "family,env,rule,net,budget,held_out,against,against_budget,seeds,shift,shift_lo,shift_hi,p,p_holm,\
         equivalence_p,equivalence_p_holm,paired_shift,paired_p,paired_p_holm,reading\n",
    );
    let v = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x}"));
    for c in comparisons {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
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
        );
    }
    out
}

/// The smallest AUC difference each task's test detects with 80% power at [`PAPER_SEEDS`] seeds a rule, from the
/// robust standard deviation of the paper rules' AUCs at the paper's budget with [`EFFORT_NET`] (pooled over the three,
/// seeds outside the held-out ones): for one comparison at the level, and at the first step of Holm's procedure
/// over the task's screen family.
fn detectable(measured: &Measured) -> String {
    let (cells, comparisons, envs) = measured.parts();
    let mut out = format!(
        "## The smallest detectable difference\n\nThe smallest shift of the AUC that a two-sided Mann-Whitney test \
         at {TEST_LEVEL} detects with 80% power with {PAPER_SEEDS} seeds a rule (normal approximation, the \
         test's efficiency 3/pi), from the spread of the paper rules' AUCs at the paper's budget with the {} \
         network (the interquartile range over 1.349, a standard deviation robust to seeds that never learn, \
         pooled over GDQN, BDQN and ADQN, seeds outside the held-out ones): for one comparison, \
         and at the first step of Holm's procedure over the task's screen family (level divided by its size). \
         Differences smaller than these are not ruled out by \"no difference detected\".\n\n| task | robust sd of the \
         AUC | one comparison | screen family | first Holm step |\n|---|---|---|---|---|",
        EFFORT_NET.name()
    );
    for env in envs {
        let variances: Vec<f64> = BASELINES
            .iter()
            .filter_map(|(label, _)| {
                let cell = cells.get(&paper_cell(env, label, EFFORT_NET.name(), Group::Screen))?;
                let aucs: Vec<f64> = cell.iter().map(|m| m.auc).collect();
                robust_sd(&aucs).map(|sd| sd * sd)
            })
            .collect();
        if variances.is_empty() {
            continue;
        }
        let sd = (exact_sum(variances.iter().copied()) / variances.len() as f64).sqrt();
        let n = PAPER_SEEDS as usize;
        let m = comparisons
            .iter()
            .filter(|c| c.family == Family::Screen(env.clone()) && c.p.is_some())
            .count()
            .max(1);
        let _ = write!(
            out,
            "\n| {env} | {sd:.3} | {:.3} | {m} | {:.3} |",
            detectable_difference(sd, n, TEST_LEVEL, 0.8),
            detectable_difference(sd, n, TEST_LEVEL / m as f64, 0.8)
        );
    }
    out.push('\n');
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

/// The second held-out test: its rule against GDQN, BDQN and ADQN in each of its cells, the primary analysis
/// (unpaired, Holm over the family) and the secondary one (paired), and what it says.
fn second_test(cells: &BTreeMap<CellKey, Vec<RunMetrics>>, comparisons: &[Comparison]) -> String {
    let mut out = format!(
        "## The second held-out test\n\n`{SECOND_HELD_OUT_RULE}` against GDQN, BDQN and ADQN at a fraction of \
         the paper's budget, {} network, seeds {} (fixed in crates/arld-lab/src/protocol.rs before any of these runs). \
         Primary analysis: two-sided Mann-Whitney of the AUC, Holm-adjusted over the test's comparisons; the rule \
         wins a cell if it is significantly higher than all three paper rules there. Shift: the rule minus the \
         paper rule, Hodges-Lehmann with 95% interval. Equivalence: two one-sided tests within \
         ±{EQUIVALENCE_MARGIN}, Holm-adjusted. Paired (secondary): Wilcoxon signed-rank on the shared seeds.\n\n\
         | cell | seeds | against | shift | p | Holm p | equivalence Holm p | reading | paired shift | paired Holm \
         p |\n|---|---|---|---|---|---|---|---|---|---|",
        EFFORT_NET.name(),
        seed_span(&SECOND_HELD_OUT_SEEDS)
    );
    let full = SECOND_HELD_OUT_SEEDS.count();
    let rule = canonical_rule(SECOND_HELD_OUT_RULE);
    let mut readings = Vec::new();
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
        let (mut above, mut below, mut level) = (0, 0, 0);
        let mut ruled_out = Vec::new();
        for (label, method) in BASELINES {
            let Some(c) = find(comparisons, &key(&rule), &key(label)) else {
                let _ = write!(
                    out,
                    "\n| {name} | – | {} | – | – | – | – | not run yet | – | – |",
                    method.to_uppercase()
                );
                continue;
            };
            let _ = write!(
                out,
                "\n| {name} | {} | {} | {} | {} |",
                c.seeds,
                method.to_uppercase(),
                c.test_cells(),
                fmt_p(c.paired_holm),
            );
            if c.significant() && c.shift_value() > 0.0 {
                above += 1;
            } else if c.significant() {
                below += 1;
            } else if c.level() {
                level += 1;
            }
            if let Some((_, (_, hi))) = c.shift {
                ruled_out.push(format!("{hi:+.3} over {}", method.to_uppercase()));
            }
        }
        let verdict = if above == BASELINES.len() {
            "a win: significantly higher than all three paper rules".to_string()
        } else {
            format!(
                "no win: significantly higher than {above} of the three paper rules, significantly lower than \
                 {below}, level with {level}; gains above {} are ruled out at 95%",
                ruled_out.join(", ")
            )
        };
        readings.push(format!("{name}: {verdict}."));
    }
    if !any {
        return format!(
            "## The second held-out test\n\nNot run yet: `arld reproduce --part held_out_2` runs \
             `{SECOND_HELD_OUT_RULE}` and the paper's rules on seeds {}.\n",
            seed_span(&SECOND_HELD_OUT_SEEDS)
        );
    }
    out.push_str("\n\n");
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
    for run in runs {
        let Some((rule, budget)) = rule_and_budget(run) else {
            continue;
        };
        beyond_paper |= run.variant != DEFAULT_VARIANT;
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
    let mut all = comparisons(&cells);
    all.extend(budget_comparisons(&cells));
    adjust(&mut all);
    let envs = env_order(cells.keys().map(|k| k.0.as_str()));
    let mut md = String::new();
    let mut csv = String::from(
        "env,rule,net,budget,budget_scale,seeds,held_out,auc_median,auc_lo,auc_hi,first_hit_median,first_hit_lo,\
         first_hit_hi,sustained_median,sustained_lo,sustained_hi,final_median,final_lo,final_hi,p_vs_gdqn,\
         p_vs_bdqn,p_vs_adqn,transitions_median,questions_median,last_question_median,random_return,expert_return\n",
    );
    writeln!(
        md,
        "AUC: the mean over evaluations of (return - random) / (expert - random), random and expert being the \
         mean returns of the uniform random policy and of the shipped weak expert over {REFERENCE_EPISODES} \
         episodes (seeds {REFERENCE_SEED}..); medians over seeds with bootstrap 95% intervals; p: the raw two-sided \
         Mann-Whitney p of the AUC against the paper's rule at the same budget and network, on the seeds both \
         have (\"Every comparison\" gives each one's shift, interval, Holm-adjusted p and equivalence test; \
         words such as \"significantly\" follow the adjusted p); effort: demonstrated transitions, questions asked (each a segment of up to segment_len steps, a \
         context switch for a person) and the step of the last question (medians). Sustained: {k} more \
         evaluations at the target after the first.\n"
    )?;
    for env in &envs {
        let (random, expert) = refs[env];
        writeln!(
            md,
            "## {env}\n\nrandom {random:.2}, expert {expert:.2}, the paper's budget {}.\n",
            paper_budget(env)
        )?;
        for held_out in [Group::Screen, Group::HeldOut, Group::SecondHeldOut] {
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
            }
            writeln!(
                md,
                "| rule | net | budget | seeds | AUC | first hit | sustained | final | p vs GDQN | p vs BDQN | \
                 p vs ADQN | transitions | questions | last question |\n|---|---|---|---|---|---|---|---|---|---|\
                 ---|---|---|---|"
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
                // The same row in both tables: the key, the four readings, the three p values, the effort.
                let readings = [&auc, &first, &sus, &fin];
                let mut md_row = format!("| {} | {} | {} | {} |", key.1, key.2, key.3, cell.len());
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
                for (m, (lo, hi), shown) in readings {
                    write!(md_row, " {shown} |")?;
                    write!(csv_row, ",{m},{lo},{hi}")?;
                }
                for p in &ps {
                    write!(md_row, " {} |", fmt_p(*p))?;
                    write!(csv_row, ",{}", p.map_or(String::new(), |p| format!("{p}")))?;
                }
                writeln!(
                    md,
                    "{md_row} {transitions:.0} | {questions:.0} | {} |",
                    last.map_or("–".into(), |s| format!("{s:.0}")),
                )?;
                writeln!(
                    csv,
                    "{csv_row},{transitions},{questions},{},{random},{expert}",
                    last.map_or(String::new(), |s| format!("{s}")),
                )?;
            }
            writeln!(md)?;
        }
    }
    let measured = Measured {
        cells,
        comparisons: all,
        envs,
    };
    let (cells, all, envs) = measured.parts();
    writeln!(md, "{}", screen(&measured))?;
    writeln!(md, "{}", detectable(&measured))?;
    writeln!(md, "{}", effort_buys(&measured))?;
    writeln!(md, "{}", design_choice(cells))?;
    writeln!(md, "{}", goal_verdict(&measured))?;
    writeln!(md, "{}", second_test(cells, all))?;
    writeln!(md, "{}", comparison_tables(all))?;
    let figures = figures(cells, envs);
    Ok(Some(EffortReport {
        markdown: md,
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
         the {} network, on its seeds outside the held-out ones (two-sided Mann-Whitney of the AUC, Holm-adjusted p < \
         {TEST_LEVEL} within the task's family of \"Every comparison\"; in parentheses, the paper's rules it \
         differs from).\n\n| task | seeds per rule | higher than all three | \
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
            if above.len() == BASELINES.len() {
                all.push(rule.1.clone());
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
    let mut out = format!(
        "## What the expert's effort buys\n\nFor each rule run at two budgets or more, on the design seeds \
         {} that every budget has: the median AUC and, in parentheses, the median first hit at each \
         budget, as a multiple of the paper's; then the largest budget against the smallest: the Hodges-Lehmann \
         shift of the AUC with its 95% interval, the Mann-Whitney p and the Holm-adjusted p over the task's \
         budget comparisons.\n",
        seed_span(&DESIGN_SEEDS)
    );
    for env in envs {
        let mut per_rule: BTreeMap<(usize, String, String), BTreeMap<usize, Vec<RunMetrics>>> =
            BTreeMap::new();
        for (key, cell) in cells
            .iter()
            .filter(|(k, _)| &k.0 == env && k.4 == Group::Screen)
        {
            let design: Vec<RunMetrics> = cell
                .iter()
                .filter(|m| DESIGN_SEEDS.contains(&m.seed))
                .cloned()
                .collect();
            if !design.is_empty() {
                per_rule
                    .entry((rank_rule(&key.1), key.1.clone(), key.2.clone()))
                    .or_default()
                    .insert(key.3, design);
            }
        }
        per_rule.retain(|_, by_budget| by_budget.len() >= 2);
        if per_rule.is_empty() {
            continue;
        }
        let budgets: std::collections::BTreeSet<usize> = per_rule
            .values()
            .flat_map(|by_budget| by_budget.keys().copied())
            .collect();
        let header: Vec<String> = budgets
            .iter()
            .map(|&b| format!("{} ({b})", budget_multiple(env, b)))
            .collect();
        let _ = writeln!(
            out,
            "\n### {env}\n\n| rule | net | {} | largest vs smallest |\n|---|---|{}---|",
            header.join(" | "),
            "---|".repeat(budgets.len())
        );
        for ((_, rule, net), by_budget) in &per_rule {
            let row: Vec<String> = budgets
                .iter()
                .map(|b| {
                    by_budget.get(b).map_or("–".to_string(), |cell| {
                        let auc = median(&design_aucs(cell));
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
        "## The held-out test\n\nSignificance follows the Holm-adjusted p within each task's held-out family \
         (\"Every comparison\"); shift: the rule minus the paper rule, Hodges-Lehmann with 95% interval.\n\n",
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
            let Some(cell) = cells.get(&key(&rule)).filter(|_| complete) else {
                incomplete.push(env.as_str());
                continue;
            };
            tasks += 1;
            let mut all_higher = true;
            let _ = cell;
            for (label, _) in BASELINES {
                let side = significant_side(comparisons, &key(&rule), &key(label));
                all_higher &= side == Some(true);
                if side == Some(false) {
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
            wins += usize::from(all_higher);
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
            "- **{rule}, {net}**: significantly higher than all three paper rules on {wins} of {tasks} tasks, \
             significantly lower {losses} times: {verdict}.",
        );
        for line in lines {
            let _ = writeln!(out, "  - {line}");
        }
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
            let design = design_aucs(cell);
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
