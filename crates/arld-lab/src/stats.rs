//! Statistics for comparing methods over seeds: the readings of "steps to solve", the final score, a seeded
//! percentile bootstrap of the median, the Mann–Whitney U test and what a comparison of two rules reports beside
//! it: the Hodges–Lehmann shift with its distribution-free interval, two one-sided tests of equivalence within a
//! margin, the paired Wilcoxon signed-rank test, Holm's adjustment within a family, and the smallest difference a
//! test detects with 80% power. Sums of many floats are exactly rounded ([`exact_sum`]), so that equal values in any
//! order give equal sums and ties between runs stay ties; a run's evaluation means can also be summed as the decimals
//! they are written as ([`Decimal`]), so that paired differences that are equal in those decimals compare equal.
//! The Hodges–Lehmann interval takes its order statistics from the exact null distribution of U for small samples
//! ([`u_null_distribution`]), and the effort in the expert's own unit reads a rule's AUC on a reference rule's budget
//! curve ([`budget_equivalent`]).
//!
//! Three readings of steps to solve are reported side by side because they rank methods differently
//! (docs/algorithm.md §11): the *first hit* (the paper's reading: the first evaluation whose mean reaches the
//! target), the *sustained* reading (the first evaluation from which the mean stays at the target for the next K
//! evaluations, so that a lucky early test followed by collapse does not count) and the *median curve* (the first
//! step at which the median over seeds of the evaluation curves reaches the target). A seed or curve that never
//! solves counts as the whole training length, as in the paper's Table 5.

use rand::{Rng, SeedableRng};

use arld_core::train::run_dir::EvalPoint;

/// First evaluation step whose mean reaches `target`, else `train_steps` (the paper's reading).
pub fn first_hit(curve: &[EvalPoint], target: f64, train_steps: u64) -> u64 {
    arld_core::train::run_dir::steps_to_solve(curve, target, train_steps).0
}

/// First evaluation step from which the mean stays at or above `target` for the next `k` evaluations as well.
/// Near the end of a run only the evaluations that exist are required: a run that reaches the target at its last
/// evaluations and holds it to the end counts as solved there. `k = 0` is the first hit.
pub fn sustained(curve: &[EvalPoint], target: f64, k: usize, train_steps: u64) -> u64 {
    (0..curve.len())
        .find(|&i| {
            let last = (i + k).min(curve.len() - 1);
            curve[i..=last].iter().all(|p| p.mean >= target)
        })
        .map_or(train_steps, |i| curve[i].step)
}

/// First step at which the median over seeds of the curves reaches `target`, else `train_steps`. Curves are
/// matched by step; a step that not every curve has is skipped.
pub fn median_curve_hit(curves: &[Vec<EvalPoint>], target: f64, train_steps: u64) -> u64 {
    let Some(first) = curves.first() else {
        return train_steps;
    };
    for step in first.iter().map(|p| p.step) {
        let values: Option<Vec<f64>> = curves
            .iter()
            .map(|curve| curve.iter().find(|p| p.step == step).map(|p| p.mean))
            .collect();
        if let Some(values) = values
            && median(&values).is_some_and(|m| m >= target)
        {
            return step;
        }
    }
    train_steps
}

/// Mean of the last `last` evaluation means (fewer if the curve is shorter); `None` for an empty curve.
pub fn final_score(curve: &[EvalPoint], last: usize) -> Option<f64> {
    let tail = &curve[curve.len().saturating_sub(last)..];
    (!tail.is_empty()).then(|| tail.iter().map(|p| p.mean).sum::<f64>() / tail.len() as f64)
}

/// Median as the paper computes it over seeds: the middle value, or the mean of the two middle values for an
/// even count. `None` for no values; NaNs are ignored.
pub fn median(values: &[f64]) -> Option<f64> {
    quantile(values, 0.5)
}

/// Quantile `q` in [0, 1] with linear interpolation between order statistics (NumPy's default), which gives
/// the paper's median at q = 0.5. `None` for no (non-NaN) values.
pub fn quantile(values: &[f64], q: f64) -> Option<f64> {
    let mut sorted: Vec<f64> = values.iter().copied().filter(|v| !v.is_nan()).collect();
    if sorted.is_empty() {
        return None;
    }
    sorted.sort_by(f64::total_cmp);
    let position = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let below = position.floor() as usize;
    let above = position.ceil() as usize;
    let fraction = position - below as f64;
    Some(sorted[below] + (sorted[above] - sorted[below]) * fraction)
}

/// Percentile-bootstrap interval of the median at `level` (e.g. 0.95) from `resamples` resamples drawn with a
/// generator seeded by `seed`: the same inputs give the same interval. `None` when `values` is empty.
pub fn bootstrap_median_interval(
    values: &[f64],
    level: f64,
    resamples: usize,
    seed: u64,
) -> Option<(f64, f64)> {
    // NaNs are left out, as `median` leaves them out, so that a resample is never all NaN.
    let values: Vec<f64> = values.iter().copied().filter(|v| !v.is_nan()).collect();
    let values = values.as_slice();
    median(values)?;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut draw = vec![0.0; values.len()];
    let mut medians: Vec<f64> = (0..resamples.max(1))
        .map(|_| {
            for slot in draw.iter_mut() {
                *slot = values[rng.random_range(0..values.len())];
            }
            median(&draw).unwrap_or(f64::NAN)
        })
        .collect();
    medians.sort_by(f64::total_cmp);
    let tail = (1.0 - level) / 2.0;
    let at = |q: f64| medians[((q * medians.len() as f64).floor() as usize).min(medians.len() - 1)];
    Some((at(tail), at(1.0 - tail)))
}

/// Two-sided Mann–Whitney U test with the normal approximation, tie correction and continuity correction
/// (`scipy.stats.mannwhitneyu(a, b, method="asymptotic")`). Returns (U of `a`, p-value); `None` when a sample
/// is empty or every value is tied (the test says nothing then).
pub fn mann_whitney(a: &[f64], b: &[f64]) -> Option<(f64, f64)> {
    let (u1, sigma) = u_statistic(a, b)?;
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    let u = u1.max(n1 * n2 - u1);
    let z = (u - n1 * n2 / 2.0 - 0.5) / sigma;
    // Two-sided: 2 · P(Z > z) = erfc(z / √2).
    Some((u1, libm::erfc(z / std::f64::consts::SQRT_2).min(1.0)))
}

/// The exactly rounded sum of `values` (Shewchuk's partial sums, as Python's `math.fsum`): the result does not
/// depend on the order of the values, so two runs whose values are equal as multisets get equal sums. A non-finite
/// value gives the plain sum (NaN or an infinity).
pub fn exact_sum(values: impl IntoIterator<Item = f64>) -> f64 {
    let mut partials: Vec<f64> = Vec::new();
    let mut plain = 0.0;
    for mut x in values {
        plain += x;
        if !x.is_finite() {
            continue;
        }
        let mut kept = 0;
        for i in 0..partials.len() {
            let mut y = partials[i];
            if x.abs() < y.abs() {
                std::mem::swap(&mut x, &mut y);
            }
            let high = x + y;
            let low = y - (high - x);
            if low != 0.0 {
                partials[kept] = low;
                kept += 1;
            }
            x = high;
        }
        partials.truncate(kept);
        partials.push(x);
    }
    if !plain.is_finite() {
        return plain;
    }
    // Add the partials from the largest down, with the half-way correction of the final rounding.
    let Some(mut high) = partials.pop() else {
        return 0.0;
    };
    let mut low = 0.0;
    while let Some(y) = partials.pop() {
        let x = high;
        high = x + y;
        low = y - (high - x);
        if low != 0.0 {
            break;
        }
    }
    if let Some(&next) = partials.last()
        && ((low < 0.0 && next < 0.0) || (low > 0.0 && next > 0.0))
    {
        let y = low * 2.0;
        let x = high + y;
        if y == x - high {
            high = x;
        }
    }
    high
}

/// The standard normal's upper tail P(Z > z).
pub fn normal_upper_tail(z: f64) -> f64 {
    0.5 * libm::erfc(z / std::f64::consts::SQRT_2)
}

/// The standard normal's quantile: the z with P(Z <= z) = `p`, for p in (0, 1) (bisection to full precision).
pub fn normal_quantile(p: f64) -> f64 {
    let (mut lo, mut hi) = (-40.0_f64, 40.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if 1.0 - normal_upper_tail(mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// One-sided Mann–Whitney test of "values of `a` tend to be larger than values of `b`" with the normal
/// approximation, tie correction and continuity correction (`scipy.stats.mannwhitneyu(a, b,
/// alternative="greater", method="asymptotic")`). `None` when a sample is empty, holds a NaN, or every value is
/// tied.
pub fn mann_whitney_greater(a: &[f64], b: &[f64]) -> Option<f64> {
    let (u1, sigma) = u_statistic(a, b)?;
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    Some(normal_upper_tail((u1 - n1 * n2 / 2.0 - 0.5) / sigma).min(1.0))
}

/// U of `a` and the tie-corrected standard deviation of U under the null; `None` as for [`mann_whitney`].
fn u_statistic(a: &[f64], b: &[f64]) -> Option<(f64, f64)> {
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    if a.is_empty() || b.is_empty() || a.iter().chain(b).any(|v| v.is_nan()) {
        return None;
    }
    let mut pooled: Vec<(f64, bool)> = a
        .iter()
        .map(|&v| (v, true))
        .chain(b.iter().map(|&v| (v, false)))
        .collect();
    pooled.sort_by(|x, y| x.0.total_cmp(&y.0));
    let (mut rank_sum_a, mut ties, mut i) = (0.0, 0.0, 0);
    while i < pooled.len() {
        let j = (i..pooled.len())
            .find(|&j| pooled[j].0 != pooled[i].0)
            .unwrap_or(pooled.len());
        let t = (j - i) as f64;
        let mid_rank = (i + 1 + j) as f64 / 2.0;
        rank_sum_a += mid_rank * pooled[i..j].iter().filter(|p| p.1).count() as f64;
        ties += t * t * t - t;
        i = j;
    }
    let n = n1 + n2;
    let u1 = rank_sum_a - n1 * (n1 + 1.0) / 2.0;
    let sigma = (n1 * n2 / 12.0 * ((n + 1.0) - ties / (n * (n - 1.0)))).sqrt();
    (sigma > 0.0).then_some((u1, sigma))
}

/// The Hodges–Lehmann estimate of the shift of `a` over `b` (the median of every difference `a_i - b_j`) and its
/// distribution-free interval at `level` (e.g. 0.95): the k-th smallest and k-th largest differences, k the largest
/// count with P(U <= k - 1) <= (1 - level) / 2 under the null, so that the interval covers the shift with probability
/// at least `level` for continuous data. The null distribution of U is exact ([`u_null_distribution`]) up to
/// [`EXACT_U_LIMIT`] pairs of runs, and its normal approximation (the critical value rounded to the wider side)
/// beyond. `None` when a sample is empty or holds a NaN.
pub fn hodges_lehmann(a: &[f64], b: &[f64], level: f64) -> Option<(f64, (f64, f64))> {
    if a.is_empty() || b.is_empty() || a.iter().chain(b).any(|v| v.is_nan()) {
        return None;
    }
    let mut diffs: Vec<f64> = a
        .iter()
        .flat_map(|x| b.iter().map(move |y| x - y))
        .collect();
    diffs.sort_by(f64::total_cmp);
    let m = diffs.len();
    let k = shift_interval_rank(a.len(), b.len(), level).clamp(1, m.div_ceil(2));
    Some((median(&diffs)?, (diffs[k - 1], diffs[m - k])))
}

/// The largest number of pairs `n1 * n2` for which [`hodges_lehmann`] uses the exact null distribution of U.
pub const EXACT_U_LIMIT: usize = 2500;

/// The rank k of the Hodges–Lehmann interval's ends for samples of `n1` and `n2` at `level`: the largest k with
/// P(U <= k - 1) <= (1 - level) / 2 (exact up to [`EXACT_U_LIMIT`] pairs, the normal approximation rounded to
/// the wider side beyond); 0 when even the extreme differences cover less than `level`.
pub fn shift_interval_rank(n1: usize, n2: usize, level: f64) -> usize {
    let tail = (1.0 - level) / 2.0;
    if n1 * n2 <= EXACT_U_LIMIT {
        let mut cumulative = 0.0;
        let mut k = 0;
        for p in u_null_distribution(n1, n2) {
            cumulative += p;
            // A margin for the rounding of the sums: a tail exactly at the level counts as inside it.
            if cumulative > tail * (1.0 + 1e-12) {
                break;
            }
            k += 1;
        }
        return k;
    }
    let (n1, n2) = (n1 as f64, n2 as f64);
    let z = normal_quantile(0.5 + level / 2.0);
    let c = (n1 * n2 / 2.0 - z * (n1 * n2 * (n1 + n2 + 1.0) / 12.0).sqrt()).floor();
    if c < 0.0 { 0 } else { c as usize + 1 }
}

/// The exact null distribution of the Mann–Whitney U for samples of `n1` and `n2` without ties: P(U = u) for u in
/// 0..=n1 n2, by the recursion P_{i,j}(u) = i/(i+j) P_{i-1,j}(u - j) + j/(i+j) P_{i,j-1}(u).
pub fn u_null_distribution(n1: usize, n2: usize) -> Vec<f64> {
    // row[j] holds P_{i,j} for the current i.
    let mut row: Vec<Vec<f64>> = (0..=n2).map(|_| vec![1.0]).collect();
    for i in 1..=n1 {
        let mut next: Vec<Vec<f64>> = Vec::with_capacity(n2 + 1);
        next.push(vec![1.0]);
        for j in 1..=n2 {
            let total = (i + j) as f64;
            let mut p = vec![0.0; i * j + 1];
            // The larger value is one of a's (U gains j) or one of b's (U unchanged).
            for (u, &q) in row[j].iter().enumerate() {
                p[u + j] += q * i as f64 / total;
            }
            for (u, &q) in next[j - 1].iter().enumerate() {
                p[u] += q * j as f64 / total;
            }
            next.push(p);
        }
        row = next;
    }
    row.pop().unwrap_or_else(|| vec![1.0])
}

/// Two one-sided Mann–Whitney tests that the shift of `a` over `b` lies inside (-margin, +margin): the larger of
/// the p-values of "a - b > -margin" and "a - b < +margin". Below the level, the two are equivalent within the
/// margin. `None` as for [`mann_whitney`].
pub fn equivalence_p(a: &[f64], b: &[f64], margin: f64) -> Option<f64> {
    let raised: Vec<f64> = a.iter().map(|x| x + margin).collect();
    let lowered: Vec<f64> = a.iter().map(|x| x - margin).collect();
    let above = mann_whitney_greater(&raised, b)?;
    let below = mann_whitney_greater(b, &lowered)?;
    Some(above.max(below))
}

/// The paired comparison of two rules from their seed-by-seed differences `d` (pair i being one seed), held as
/// integers so that equal differences compare equal ([`Decimal::paired_differences`]): the Hodges–Lehmann estimate
/// of the paired shift (the median of the Walsh averages of the differences), in the units of `d`, and the two-sided
/// Wilcoxon signed-rank p (zero differences dropped, mid-ranks for ties, the normal approximation with tie and
/// continuity corrections, as `scipy.stats.wilcoxon(d, zero_method="wilcox", correction=True, method="approx")`).
/// `None` without a non-zero difference.
pub fn wilcoxon_signed_rank(d: &[i128]) -> Option<(f64, f64)> {
    // Walsh sums d_i + d_j (i <= j), exact; the shift is the median of their halves.
    let mut walsh: Vec<i128> = Vec::with_capacity(d.len() * (d.len() + 1) / 2);
    for i in 0..d.len() {
        for j in i..d.len() {
            walsh.push(d[i].checked_add(d[j])?);
        }
    }
    walsh.sort_unstable();
    let half = |v: i128| v as f64 / 2.0;
    let shift = match walsh.len() {
        0 => return None,
        n if n % 2 == 1 => half(walsh[n / 2]),
        n => (half(walsh[n / 2 - 1]) + half(walsh[n / 2])) / 2.0,
    };
    let mut nonzero: Vec<i128> = d.iter().copied().filter(|&x| x != 0).collect();
    if nonzero.is_empty() {
        return None;
    }
    nonzero.sort_by_key(|x| x.unsigned_abs());
    let n = nonzero.len() as f64;
    let (mut plus, mut ties, mut i) = (0.0, 0.0, 0);
    while i < nonzero.len() {
        let j = (i..nonzero.len())
            .find(|&j| nonzero[j].unsigned_abs() != nonzero[i].unsigned_abs())
            .unwrap_or(nonzero.len());
        let t = (j - i) as f64;
        let mid_rank = (i + 1 + j) as f64 / 2.0;
        plus += mid_rank * nonzero[i..j].iter().filter(|&&x| x > 0).count() as f64;
        ties += t * t * t - t;
        i = j;
    }
    let mean = n * (n + 1.0) / 4.0;
    let sigma = (n * (n + 1.0) * (2.0 * n + 1.0) / 24.0 - ties / 48.0).sqrt();
    if sigma == 0.0 {
        return None;
    }
    let z = ((plus - mean).abs() - 0.5).max(0.0) / sigma;
    Some((shift, (2.0 * normal_upper_tail(z)).min(1.0)))
}

/// A finite decimal number held exactly, `units x 10^-scale`, in lowest terms (`units` has no trailing zero at a
/// positive scale), so that equal numbers have equal representations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decimal {
    units: i128,
    scale: u32,
}

impl Decimal {
    /// The shortest decimal that reads back as `x`: the text a writer of shortest round-trip numbers (Rust's `{}`,
    /// as `eval.csv` is written) gave it. `None` for a non-finite value or one beyond 128 bits at its scale.
    pub fn of(x: f64) -> Option<Decimal> {
        if !x.is_finite() {
            return None;
        }
        let text = format!("{x:e}");
        let (mantissa, exponent) = text.split_once('e')?;
        let exponent: i64 = exponent.parse().ok()?;
        let (negative, mantissa) = match mantissa.strip_prefix('-') {
            Some(rest) => (true, rest),
            None => (false, mantissa),
        };
        let fraction_digits = mantissa.split_once('.').map_or(0, |(_, f)| f.len()) as i64;
        let digits: i128 = mantissa.replace('.', "").parse().ok()?;
        let power = exponent - fraction_digits;
        let units = if power >= 0 {
            digits.checked_mul(10i128.checked_pow(u32::try_from(power).ok()?)?)?
        } else {
            digits
        };
        let scale = u32::try_from((-power).max(0)).ok()?;
        Some(Decimal::new(if negative { -units } else { units }, scale))
    }

    fn new(mut units: i128, mut scale: u32) -> Decimal {
        while scale > 0 && units % 10 == 0 {
            units /= 10;
            scale -= 1;
        }
        Decimal { units, scale }
    }

    /// The exact sum of `values`, each read as [`Decimal::of`]; `None` if one cannot be, or the sum leaves 128 bits.
    pub fn sum(values: impl IntoIterator<Item = f64>) -> Option<Decimal> {
        let mut total = Decimal::new(0, 0);
        for v in values {
            let v = Decimal::of(v)?;
            let scale = total.scale.max(v.scale);
            total = Decimal::new(
                total.at_scale(scale)?.checked_add(v.at_scale(scale)?)?,
                scale,
            );
        }
        Some(total)
    }

    /// The units of this number at a scale at least its own.
    fn at_scale(self, scale: u32) -> Option<i128> {
        self.units
            .checked_mul(10i128.checked_pow(scale.checked_sub(self.scale)?)?)
    }

    /// The nearest double (the same for equal numbers, since the representation is unique).
    pub fn to_f64(self) -> f64 {
        self.units as f64 / 10f64.powi(self.scale as i32)
    }

    /// The differences of means `sum_a_i / n_a_i - sum_b_i / n_b_i` of paired runs (each a [`Decimal`] sum and its
    /// count), exactly, as integers on one scale: (the integers, the value of one unit). Equal differences give
    /// equal integers. `None` for unequal lengths, a zero count, or a value beyond 128 bits.
    pub fn paired_differences(
        a: &[(Decimal, u64)],
        b: &[(Decimal, u64)],
    ) -> Option<(Vec<i128>, f64)> {
        if a.len() != b.len() {
            return None;
        }
        let all = || a.iter().chain(b);
        let scale = all().map(|(d, _)| d.scale).max().unwrap_or(0);
        let mut common: u64 = 1;
        for &(_, n) in all() {
            if n == 0 {
                return None;
            }
            common = common.checked_mul(n / gcd(common, n))?;
        }
        let mean = |&(d, n): &(Decimal, u64)| d.at_scale(scale)?.checked_mul((common / n) as i128);
        let diffs = a
            .iter()
            .zip(b)
            .map(|(x, y)| mean(x)?.checked_sub(mean(y)?))
            .collect::<Option<Vec<i128>>>()?;
        Some((diffs, 1.0 / (common as f64 * 10f64.powi(scale as i32))))
    }
}

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// The intersection-union test of "above every one of them" from one-sided p-values of each comparison: the
/// largest (each comparison at the full level, no adjustment, Berger 1982); `None` if a comparison said nothing.
pub fn intersection_union(p: &[Option<f64>]) -> Option<f64> {
    p.iter()
        .try_fold(0.0_f64, |worst, p| p.map(|p| worst.max(p)))
        .filter(|_| !p.is_empty())
}

/// Holm's step-down adjustment of a family of p-values: the i-th smallest becomes the largest over j <= i of
/// `(m - j + 1) p_(j)`, capped at 1; `None`s (tests that said nothing) stay `None` and do not count in m.
pub fn holm(p: &[Option<f64>]) -> Vec<Option<f64>> {
    let mut order: Vec<usize> = (0..p.len()).filter(|&i| p[i].is_some()).collect();
    order.sort_by(|&i, &j| {
        p[i].unwrap_or(1.0)
            .total_cmp(&p[j].unwrap_or(1.0))
            .then(i.cmp(&j))
    });
    let m = order.len();
    let mut adjusted = vec![None; p.len()];
    let mut running: f64 = 0.0;
    for (rank, &i) in order.iter().enumerate() {
        let value = ((m - rank) as f64 * p[i].unwrap_or(1.0)).min(1.0);
        running = running.max(value);
        adjusted[i] = Some(running);
    }
    adjusted
}

/// The smallest shift a one-sided Mann–Whitney test at level `alpha` detects with probability `power`, for two
/// samples of `n` with standard deviation `sd`: the t-test's `(z_{1-alpha} + z_power) sd sqrt(2 / n)` over the
/// square root of the test's asymptotic relative efficiency for normal data, 3/pi (a two-sided test at level a is
/// the one-sided one at a / 2).
pub fn detectable_difference(sd: f64, n: usize, alpha: f64, power: f64) -> f64 {
    let z = normal_quantile(1.0 - alpha) + normal_quantile(power);
    z * sd * (2.0 / n as f64).sqrt() / (3.0 / std::f64::consts::PI).sqrt()
}

/// The seeds per rule a one-sided Mann–Whitney test at level `alpha` needs to detect a shift `shift` with
/// probability `power` (the inverse of [`detectable_difference`], rounded up); `None` for a shift that is not
/// positive.
pub fn seeds_needed(sd: f64, shift: f64, alpha: f64, power: f64) -> Option<u64> {
    if shift.is_nan() || shift <= 0.0 || sd.is_nan() {
        return None;
    }
    let z = normal_quantile(1.0 - alpha) + normal_quantile(power);
    let n = 2.0 * (z * sd / shift).powi(2) * std::f64::consts::PI / 3.0;
    Some(n.ceil().max(2.0) as u64)
}

/// Where a rule's value `y` falls on a reference's budget curve `points` ((budget, value), budgets increasing):
/// the smallest budget at which the curve, made non-decreasing by isotonic regression (pool adjacent violators)
/// and interpolated linearly in log budget, reaches `y`. `Below` when `y` lies below the first point, `Above` when
/// it lies above the last; `None` for fewer than two points or a NaN.
pub fn budget_equivalent(points: &[(f64, f64)], y: f64) -> Option<OnCurve> {
    if points.len() < 2 || y.is_nan() || points.iter().any(|p| p.1.is_nan() || p.0 <= 0.0) {
        return None;
    }
    let fitted = isotonic(&points.iter().map(|p| p.1).collect::<Vec<_>>());
    if y < fitted[0] {
        return Some(OnCurve::Below);
    }
    if y == fitted[0] {
        return Some(OnCurve::At(points[0].0));
    }
    for i in 1..points.len() {
        if fitted[i] >= y {
            let (x0, x1) = (points[i - 1].0.ln(), points[i].0.ln());
            let t = (y - fitted[i - 1]) / (fitted[i] - fitted[i - 1]);
            return Some(OnCurve::At((x0 + t * (x1 - x0)).exp()));
        }
    }
    Some(OnCurve::Above)
}

/// A value's place on a budget curve ([`budget_equivalent`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OnCurve {
    /// Below the curve's first point: worth less than its smallest budget.
    Below,
    /// Reached at this budget.
    At(f64),
    /// Above the curve's last point: worth more than its largest budget.
    Above,
}

/// The non-decreasing least-squares fit of `values` (equal weights): adjacent violators pooled into their mean.
pub fn isotonic(values: &[f64]) -> Vec<f64> {
    // Blocks of (sum, count), merged while a block's mean falls below its predecessor's.
    let mut blocks: Vec<(f64, usize)> = Vec::new();
    for &v in values {
        blocks.push((v, 1));
        while blocks.len() >= 2 {
            let (s1, c1) = blocks[blocks.len() - 1];
            let (s0, c0) = blocks[blocks.len() - 2];
            if s0 / c0 as f64 <= s1 / c1 as f64 {
                break;
            }
            blocks.pop();
            let last = blocks.len() - 1;
            blocks[last] = (s0 + s1, c0 + c1);
        }
    }
    blocks
        .iter()
        .flat_map(|&(s, c)| std::iter::repeat_n(s / c as f64, c))
        .collect()
}

/// The sample standard deviation (n - 1 in the denominator) of `values`; `None` for fewer than two.
pub fn sample_sd(values: &[f64]) -> Option<f64> {
    if values.len() < 2 {
        return None;
    }
    let n = values.len() as f64;
    let mean = exact_sum(values.iter().copied()) / n;
    let squares = exact_sum(values.iter().map(|v| (v - mean) * (v - mean)));
    Some((squares / (n - 1.0)).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(means: &[f64]) -> Vec<EvalPoint> {
        means
            .iter()
            .enumerate()
            .map(|(i, &mean)| EvalPoint::constant((i as u64 + 1) * 1000, mean))
            .collect()
    }

    #[test]
    fn readings_differ_on_an_early_lucky_test() {
        // Reaches the target at 1000, collapses, then holds it from 5000 on.
        let c = curve(&[200.0, 20.0, 30.0, 150.0, 196.0, 199.0, 200.0, 195.0]);
        assert_eq!(first_hit(&c, 195.0, 20_000), 1000);
        assert_eq!(sustained(&c, 195.0, 3, 20_000), 5000);
        // Holding to the end counts even with fewer than k evaluations left.
        assert_eq!(sustained(&c, 195.0, 10, 20_000), 5000);
        assert_eq!(sustained(&curve(&[1.0, 2.0]), 195.0, 3, 20_000), 20_000);
    }

    #[test]
    fn median_curve_matches_a_hand_computation() {
        let curves = vec![
            curve(&[0.0, 100.0, 200.0]),
            curve(&[0.0, 200.0, 200.0]),
            curve(&[0.0, 150.0, 10.0]),
        ];
        // Medians per step: 0, 150, 200.
        assert_eq!(median_curve_hit(&curves, 150.0, 9000), 2000);
        assert_eq!(median_curve_hit(&curves, 195.0, 9000), 3000);
        assert_eq!(median_curve_hit(&curves, 250.0, 9000), 9000);
    }

    #[test]
    fn final_score_averages_the_tail() {
        let c = curve(&[0.0, 10.0, 20.0, 30.0]);
        assert_eq!(final_score(&c, 2), Some(25.0));
        assert_eq!(final_score(&c, 10), Some(15.0));
        assert_eq!(final_score(&[], 10), None);
    }

    #[test]
    fn mann_whitney_agrees_with_scipy() {
        // scipy.stats.mannwhitneyu(a, b, method="asymptotic", use_continuity=True), scipy 1.17.1.
        let a = [
            7000.0, 8000.0, 7000.0, 9000.0, 500000.0, 6000.0, 7000.0, 13000.0,
        ];
        let b = [
            8000.0, 8000.0, 9000.0, 20000.0, 500000.0, 500000.0, 7000.0, 11000.0, 15000.0, 9000.0,
        ];
        let (u, p) = mann_whitney(&a, &b).unwrap();
        assert_eq!(u, 22.5);
        assert!((p - 0.12652887797100032).abs() < 1e-12, "p = {p}");
        let a = [1.5, 2.5, 3.1, 4.7, 5.2, 6.0, 7.3];
        let b = [8.1, 9.4, 2.2, 10.5, 11.0, 12.2];
        let (u, p) = mann_whitney(&a, &b).unwrap();
        assert_eq!(u, 6.0);
        assert!((p - 0.03831876314941356).abs() < 1e-12, "p = {p}");
        assert_eq!(mann_whitney(&[1.0, 1.0], &[1.0]), None);
        assert_eq!(mann_whitney(&[], &[1.0]), None);
    }

    #[test]
    fn bootstrap_interval_is_seeded_and_brackets_the_median() {
        let values: Vec<f64> = (0..20).map(|i| (i * 7 % 13) as f64 * 1000.0).collect();
        let a = bootstrap_median_interval(&values, 0.95, 2000, 7).unwrap();
        let b = bootstrap_median_interval(&values, 0.95, 2000, 7).unwrap();
        assert_eq!(a, b);
        let m = median(&values).unwrap();
        assert!(a.0 <= m && m <= a.1, "{a:?} vs {m}");
        // A constant sample has a degenerate interval.
        assert_eq!(
            bootstrap_median_interval(&[5.0; 7], 0.95, 100, 1),
            Some((5.0, 5.0))
        );
        assert_eq!(bootstrap_median_interval(&[], 0.95, 100, 1), None);
    }

    #[test]
    fn quantiles_interpolate_between_order_statistics() {
        let values = [4.0, 1.0, 3.0, 2.0, 5.0];
        assert_eq!(quantile(&values, 0.25), Some(2.0));
        assert_eq!(quantile(&values, 0.75), Some(4.0));
        assert_eq!(quantile(&[1.0, 2.0], 0.25), Some(1.25));
    }

    #[test]
    fn exact_sum_is_order_free_and_exactly_rounded() {
        let v = [0.1, 0.2, 0.3, 1e16, -1e16, 0.7];
        let mut w = v;
        w.reverse();
        assert_eq!(exact_sum(v), exact_sum(w));
        // Python: math.fsum([0.1, 0.2, 0.3, 1e16, -1e16, 0.7]) == 1.3
        assert_eq!(exact_sum(v), 1.3);
        assert_eq!(exact_sum([1e100, 1.0, -1e100, 1e-100]), 1.0);
        assert_eq!(exact_sum(std::iter::empty()), 0.0);
        assert!(exact_sum([1.0, f64::NAN]).is_nan());
    }

    #[test]
    fn holm_steps_down_and_keeps_order() {
        // Hand computation: sorted 0.01, 0.02, 0.04 (m = 3): 0.03, 0.04, 0.04.
        let adjusted = holm(&[Some(0.04), Some(0.01), None, Some(0.02)]);
        let expect = [Some(0.04), Some(0.03), None, Some(0.04)];
        for (a, e) in adjusted.iter().zip(expect) {
            assert!(
                (a.unwrap_or(-1.0) - e.unwrap_or(-1.0)).abs() < 1e-12,
                "{adjusted:?}"
            );
        }
        assert_eq!(holm(&[Some(0.9), Some(0.8)]), vec![Some(1.0), Some(1.0)]);
    }

    #[test]
    fn normal_quantile_inverts_the_tail() {
        assert!((normal_quantile(0.975) - 1.959963984540054).abs() < 1e-9);
        assert!((normal_quantile(0.8) - 0.8416212335729143).abs() < 1e-9);
    }

    #[test]
    fn hodges_lehmann_brackets_the_shift_of_shifted_samples() {
        let b: Vec<f64> = (0..20).map(|i| ((i * 7) % 20) as f64 / 20.0).collect();
        let a: Vec<f64> = b.iter().map(|x| x + 0.3).collect();
        let (shift, (lo, hi)) = hodges_lehmann(&a, &b, 0.95).unwrap();
        assert!((shift - 0.3).abs() < 1e-12, "{shift}");
        assert!(lo < 0.3 && 0.3 < hi && lo > 0.0, "{lo} {hi}");
        // The interval is symmetric in the order statistics: swapping the samples negates it.
        let (back, (blo, bhi)) = hodges_lehmann(&b, &a, 0.95).unwrap();
        assert_eq!((back, blo, bhi), (-shift, -hi, -lo));
    }

    #[test]
    fn equivalence_holds_only_for_a_small_shift() {
        let b: Vec<f64> = (0..20).map(|i| ((i * 7) % 20) as f64 / 200.0).collect();
        let same: Vec<f64> = b.iter().map(|x| x + 0.001).collect();
        let far: Vec<f64> = b.iter().map(|x| x + 0.2).collect();
        assert!(equivalence_p(&same, &b, 0.05).unwrap() < 0.05);
        assert!(equivalence_p(&far, &b, 0.05).unwrap() > 0.5);
        // One-sided, by hand: U = 4.5, ties 3 x 2, sigma = sqrt(22.5), z = (4.5 - 12.5 - 0.5) / sigma.
        let p =
            mann_whitney_greater(&[1.0, 2.0, 3.0, 4.0, 5.0], &[3.0, 4.0, 5.0, 6.0, 7.0]).unwrap();
        assert!((p - 0.9634301001705455).abs() < 1e-9, "{p}");
    }

    #[test]
    fn wilcoxon_matches_a_hand_computation() {
        // d = 1, -2, 3, 4, 0: the zero is dropped; ranks 1, 2, 3, 4; W+ = 8, mean 5, sd sqrt(7.5).
        let (shift, p) = wilcoxon_signed_rank(&[1, -2, 3, 4, 0]).unwrap();
        let z: f64 = (3.0 - 0.5) / 7.5_f64.sqrt();
        assert!(
            (p - libm::erfc(z / std::f64::consts::SQRT_2)).abs() < 1e-12,
            "{p}"
        );
        // Walsh averages of 1, -2, 3, 4, 0: their median is 1.
        assert_eq!(shift, 1.0);
        assert_eq!(wilcoxon_signed_rank(&[0]), None);
    }

    #[test]
    fn paired_differences_keep_the_ties_that_float_subtraction_breaks() {
        // 0.3 - 0.1 and 0.6 - 0.4 are equal, but not in floating point.
        assert_ne!(0.3 - 0.1, 0.6 - 0.4);
        let runs = |v: &[f64]| -> Vec<(Decimal, u64)> {
            v.iter().map(|&x| (Decimal::of(x).unwrap(), 1)).collect()
        };
        let (d, unit) =
            Decimal::paired_differences(&runs(&[0.3, 0.6, 1.0]), &runs(&[0.1, 0.4, 0.5])).unwrap();
        assert_eq!(d[0], d[1]);
        assert_eq!((d[0] as f64 * unit, d[2] as f64 * unit), (0.2, 0.5));
        // Two equal |d| share their mid-rank: ranks 1.5, 1.5, 3; W+ = 6 of mean 3, ties 2^3 - 2 = 6.
        let (_, p) = wilcoxon_signed_rank(&d).unwrap();
        let sigma = (3.0 * 4.0 * 7.0 / 24.0 - 6.0 / 48.0_f64).sqrt();
        assert!((p - 2.0 * normal_upper_tail((3.0 - 0.5) / sigma)).abs() < 1e-12);
        // Means of runs with other counts: (0.1 + 0.2) / 2 - 0.1 = 0.05 exactly.
        let a = [(Decimal::sum([0.1, 0.2]).unwrap(), 2)];
        let b = [(Decimal::of(0.1).unwrap(), 1)];
        let (d, unit) = Decimal::paired_differences(&a, &b).unwrap();
        assert_eq!(d[0] as f64 * unit, 0.05);
    }

    #[test]
    fn decimals_read_back_the_shortest_text() {
        assert_eq!(
            Decimal::of(199.85),
            Some(Decimal {
                units: 19985,
                scale: 2
            })
        );
        assert_eq!(
            Decimal::of(-200.0),
            Some(Decimal {
                units: -200,
                scale: 0
            })
        );
        assert_eq!(Decimal::of(1e-7), Some(Decimal { units: 1, scale: 7 }));
        assert_eq!(Decimal::sum([0.1, 0.2]), Decimal::of(0.3));
        assert_eq!(Decimal::sum([0.1, 0.2]).unwrap().to_f64(), 0.3);
        assert_eq!(Decimal::of(f64::NAN), None);
    }

    /// The null distribution of U for samples of `m` and `n`, by enumerating every assignment of the m + n ranks.
    fn enumerated_u(m: usize, n: usize) -> Vec<f64> {
        let mut counts = vec![0u64; m * n + 1];
        let mut total = 0u64;
        for mask in 0u32..(1 << (m + n)) {
            if mask.count_ones() as usize != m {
                continue;
            }
            // Rank r belongs to a if bit r is set; U counts pairs (a above b).
            let (mut u, mut below) = (0, 0);
            for r in 0..m + n {
                if mask >> r & 1 == 1 {
                    u += below;
                } else {
                    below += 1;
                }
            }
            counts[u] += 1;
            total += 1;
        }
        counts.iter().map(|&c| c as f64 / total as f64).collect()
    }

    #[test]
    fn the_shift_interval_is_the_narrowest_that_covers_by_enumeration() {
        for (m, n) in [(10, 10), (7, 9), (5, 5)] {
            let exact = enumerated_u(m, n);
            for (p, q) in exact.iter().zip(u_null_distribution(m, n)) {
                assert!((p - q).abs() < 1e-12, "{m}x{n}: {p} vs {q}");
            }
            // Coverage of [D_(k), D_(mn+1-k)] for continuous data: P(k <= U <= mn - k).
            let coverage = |k: usize| -> f64 { exact[k..=m * n - k].iter().sum() };
            let k = shift_interval_rank(m, n, 0.95);
            assert!(coverage(k) >= 0.95, "{m}x{n}: k = {k}");
            assert!(
                coverage(k + 1) < 0.95,
                "{m}x{n}: k = {k} is not the narrowest"
            );
        }
        // At 10 seeds a rule the normal approximation's rank is one too far in: its coverage falls short.
        let z = 1.959963984540054;
        let normal = (50.0 - z * (100.0 * 21.0 / 12.0_f64).sqrt()).floor() as usize + 1;
        let exact = enumerated_u(10, 10);
        assert!(exact[normal..=100 - normal].iter().sum::<f64>() < 0.95);
        assert_eq!(normal, shift_interval_rank(10, 10, 0.95) + 1);
        // hodges_lehmann takes those order statistics of the sorted differences.
        let a: Vec<f64> = (0..10).map(|i| (i * i) as f64 * 0.37).collect();
        let b: Vec<f64> = (0..10).map(|i| (i * 3) as f64 * 1.01 + 0.5).collect();
        let mut d: Vec<f64> = a
            .iter()
            .flat_map(|x| b.iter().map(move |y| x - y))
            .collect();
        d.sort_by(f64::total_cmp);
        let k = shift_interval_rank(10, 10, 0.95);
        let (_, (lo, hi)) = hodges_lehmann(&a, &b, 0.95).unwrap();
        assert_eq!((lo, hi), (d[k - 1], d[100 - k]));
    }

    #[test]
    fn detectable_difference_follows_the_normal_formula() {
        // Two-sided at 0.05 is one-sided at 0.025: (1.95996 + 0.84162) * 0.1 * sqrt(2 / 20) / sqrt(3 / pi).
        let d = detectable_difference(0.1, 20, 0.025, 0.8);
        assert!((d - 0.090_657).abs() < 1e-4, "{d}");
        assert!(detectable_difference(0.1, 20, 0.005, 0.8) > d);
        // The seeds needed for a shift invert it: n seeds detect it, n - 1 do not.
        let n = seeds_needed(0.1, 0.05, 0.05, 0.8).unwrap();
        assert!(detectable_difference(0.1, n as usize, 0.05, 0.8) <= 0.05);
        assert!(detectable_difference(0.1, n as usize - 1, 0.05, 0.8) > 0.05);
        assert_eq!(seeds_needed(0.1, 0.0, 0.05, 0.8), None);
    }

    #[test]
    fn the_budget_equivalent_reads_the_isotonic_curve_in_log_budget() {
        assert_eq!(isotonic(&[0.1, 0.3, 0.2, 0.5]), vec![0.1, 0.25, 0.25, 0.5]);
        let curve = [(1.0, 0.1), (2.0, 0.3), (4.0, 0.2), (8.0, 0.5)];
        assert_eq!(budget_equivalent(&curve, 0.05), Some(OnCurve::Below));
        assert_eq!(budget_equivalent(&curve, 0.1), Some(OnCurve::At(1.0)));

        assert_eq!(budget_equivalent(&curve, 0.6), Some(OnCurve::Above));
        // 0.25 is first reached at 2 (the pooled 2-4 block); 0.375 half-way from 4 to 8 in log budget.
        let at = |y| match budget_equivalent(&curve, y) {
            Some(OnCurve::At(b)) => b,
            other => panic!("{other:?}"),
        };
        assert!((at(0.25) - 2.0).abs() < 1e-12);
        assert!((at(0.5) - 8.0).abs() < 1e-12);
        assert!((at(0.375) - 32f64.sqrt()).abs() < 1e-12);
        assert!((at(0.175) - 2f64.powf(0.5)).abs() < 1e-12);
        assert_eq!(budget_equivalent(&curve[..1], 0.2), None);
    }

    #[test]
    fn the_intersection_union_p_is_the_largest() {
        assert_eq!(intersection_union(&[Some(0.01), Some(0.04)]), Some(0.04));
        assert_eq!(intersection_union(&[Some(0.01), None]), None);
        assert_eq!(intersection_union(&[]), None);
    }

    #[test]
    fn bootstrap_survives_nans() {
        let values = [f64::NAN, 1.0, f64::NAN, f64::NAN, f64::NAN];
        let interval = bootstrap_median_interval(&values, 0.95, 200, 3).unwrap();
        assert_eq!(interval, (1.0, 1.0));
    }
}
