//! Statistics for comparing methods over seeds: the readings of "steps to solve", the final score, a seeded
//! percentile bootstrap of the median and the Mann–Whitney U test.
//!
//! Three readings of steps to solve are reported side by side because they rank methods differently
//! (docs/algorithm.md §11): the *first hit* (the paper's reading: the first evaluation whose mean reaches the
//! target), the *sustained* reading (the first evaluation from which the mean stays at the target for the next K
//! evaluations, so that a lucky early test followed by collapse does not count) and the *median curve* (the first
//! step at which the median over seeds of the evaluation curves reaches the target). A seed or curve that never
//! solves counts as the whole training length, as in the paper's Table 5.

use rand::{Rng, SeedableRng};

use crate::train::run_dir::EvalPoint;

/// First evaluation step whose mean reaches `target`, else `train_steps` (the paper's reading).
pub fn first_hit(curve: &[EvalPoint], target: f64, train_steps: u64) -> u64 {
    crate::train::run_dir::steps_to_solve(curve, target, train_steps).0
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
    median(values)?;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut draw = vec![0.0; values.len()];
    let mut medians: Vec<f64> = (0..resamples.max(1))
        .map(|_| {
            for slot in draw.iter_mut() {
                *slot = values[rng.random_range(0..values.len())];
            }
            median(&draw).expect("a non-empty resample of numbers")
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
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    if a.is_empty() || b.is_empty() || a.iter().chain(b).any(|v| v.is_nan()) {
        return None;
    }
    // Mid-ranks of the pooled sample, and the tie term Σ (t³ − t).
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
    let u = u1.max(n1 * n2 - u1);
    let sigma = (n1 * n2 / 12.0 * ((n + 1.0) - ties / (n * (n - 1.0)))).sqrt();
    if sigma == 0.0 {
        return None;
    }
    let z = (u - n1 * n2 / 2.0 - 0.5) / sigma;
    // Two-sided: 2 · P(Z > z) = erfc(z / √2).
    Some((u1, libm::erfc(z / std::f64::consts::SQRT_2).min(1.0)))
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
}
