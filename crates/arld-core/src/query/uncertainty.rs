//! The two uncertainty measures of Active DQN (paper sections 4.3 and 4.4; docs/algorithm.md section 7).
//!
//! - [`js_divergence`]: disagreement between the K heads of a bootstrapped Q-network. Each head's Q-values are
//!   turned into a policy by a temperature-1 softmax, and the uncertainty is the generalised Jensen-Shannon
//!   divergence of those K policies. It lies in `[0, min(ln K, ln |A|)]`.
//! - [`noisy_variance`]: predictive variance of one action's Q-value under the noise of a noisy output layer,
//!   read as Bayesian linear regression on the penultimate features.
//!
//! - [`head_variance`]: RCMP's epistemic uncertainty, the variance over heads of each action's Q-value averaged
//!   over actions; [`q_gap`]: the best minus the worst Q-value of one head (student-initiated advising).
//!
//! All are called once per agent decision, so both are allocation-free for the network sizes used here.

/// The variance over `heads` of each action's Q-value (population variance, divided by `heads`), averaged over
/// the `n_actions` actions; `q` is laid out `[head][action]`. Computed in `f64` in a fixed order.
///
/// # Panics
/// If `heads` or `n_actions` is zero, or `q.len() != heads * n_actions`.
pub fn head_variance(q: &[f32], heads: usize, n_actions: usize) -> f32 {
    assert!(heads > 0 && n_actions > 0 && q.len() == heads * n_actions);
    let mut total = 0.0f64;
    for a in 0..n_actions {
        let mean = (0..heads).map(|k| q[k * n_actions + a] as f64).sum::<f64>() / heads as f64;
        let var = (0..heads)
            .map(|k| {
                let d = q[k * n_actions + a] as f64 - mean;
                d * d
            })
            .sum::<f64>()
            / heads as f64;
        total += var;
    }
    (total / n_actions as f64) as f32
}

/// The best minus the worst of one head's Q-values.
pub fn q_gap(q: &[f32]) -> f32 {
    let max = q.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let min = q.iter().copied().fold(f32::INFINITY, f32::min);
    max - min
}

/// Largest action count handled with a stack buffer; larger action spaces fall back to a heap buffer.
const STACK_ACTIONS: usize = 32;

/// Generalised Jensen-Shannon divergence between the softmax policies of `heads` bootstrapped Q-heads.
///
/// `q` holds the Q-values laid out `[head][action]` (length `heads * n_actions`). With
/// `pi_k = softmax(Q_k)` at temperature 1 (paper section 4.3, no rescaling of Q, docs/algorithm.md section 7):
///
/// `U_D = H(mean_k pi_k) - mean_k H(pi_k)`, natural-log entropies.
///
/// The result is in nats, `0` for identical heads and at most `min(ln heads, ln n_actions)`. Tiny negative
/// values produced by cancellation when the heads nearly agree are clamped to `0`. Non-finite Q-values give NaN.
///
/// Computed in `f64` internally; no allocation for `n_actions <= 32`.
///
/// # Panics
/// If `heads` or `n_actions` is zero, or `q.len() != heads * n_actions` (a caller's shape bug, not user input).
pub fn js_divergence(q: &[f32], heads: usize, n_actions: usize) -> f32 {
    assert!(
        heads > 0 && n_actions > 0,
        "js_divergence needs at least one head and one action"
    );
    assert_eq!(
        q.len(),
        heads * n_actions,
        "js_divergence: q must be laid out [head][action] with {heads} heads and {n_actions} actions"
    );
    if n_actions <= STACK_ACTIONS {
        let mut mean_policy = [0.0f64; STACK_ACTIONS];
        let mut exps = [0.0f64; STACK_ACTIONS];
        js_divergence_with_buffers(
            q,
            heads,
            &mut mean_policy[..n_actions],
            &mut exps[..n_actions],
        )
    } else {
        let mut mean_policy = vec![0.0f64; n_actions];
        let mut exps = vec![0.0f64; n_actions];
        js_divergence_with_buffers(q, heads, &mut mean_policy, &mut exps)
    }
}

/// Body of [`js_divergence`]. `mean_policy` (zeroed) and `exps` are scratch buffers of length `n_actions`.
fn js_divergence_with_buffers(
    q: &[f32],
    heads: usize,
    mean_policy: &mut [f64],
    exps: &mut [f64],
) -> f32 {
    let n_actions = mean_policy.len();
    let inv_heads = 1.0 / heads as f64;
    let mut mean_head_entropy = 0.0f64;
    for head_q in q.chunks_exact(n_actions) {
        // Softmax shifted by the maximum so exp never overflows. With z_a = Q_a - max and s = sum_a e^{z_a}:
        // ln pi_a = z_a - ln s, hence H(pi) = ln s - sum_a pi_a z_a, with no log of a possibly-zero pi_a.
        let max_q = head_q.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v)) as f64;
        let mut sum_exp = 0.0f64;
        let mut weighted_shift = 0.0f64;
        for (&value, exp) in head_q.iter().zip(exps.iter_mut()) {
            let shifted = value as f64 - max_q;
            *exp = shifted.exp();
            sum_exp += *exp;
            weighted_shift += *exp * shifted;
        }
        let inv_sum = 1.0 / sum_exp;
        for (&exp, mean) in exps.iter().zip(mean_policy.iter_mut()) {
            *mean += exp * inv_sum * inv_heads;
        }
        mean_head_entropy += (sum_exp.ln() - weighted_shift * inv_sum) * inv_heads;
    }
    // 0 ln 0 = 0: actions whose mean probability underflowed contribute nothing.
    let entropy_of_mean: f64 = mean_policy
        .iter()
        .filter(|&&p| p > 0.0)
        .map(|&p| -p * p.ln())
        .sum();
    let divergence = entropy_of_mean - mean_head_entropy;
    if divergence.is_nan() {
        f32::NAN
    } else {
        divergence.max(0.0) as f32
    }
}

/// Predictive variance of one action's Q-value under a noisy output layer (paper section 4.4).
///
/// `features` is phi(s), the input of the noisy layer (the penultimate activations); `sigma_w_row` is the row
/// `sigma_w[a, :]` and `sigma_b` the entry `sigma_b[a]` for the action `a` the agent would take (the caller picks
/// the row; docs/algorithm.md section 7).
///
/// - Default (`exact_factorised = false`), the paper's form for independent Gaussian weights:
///   `Var[Q(s,a)] = sum_i sigma_w[a,i]^2 phi_i^2 + sigma_b[a]^2`.
/// - `exact_factorised = true`, the exact variance under factorised noise (docs/algorithm.md sections 6-7):
///   the noise term is `f(e_a) (sum_i sigma_w[a,i] f(e_i) phi_i + sigma_b[a])` with `f(x) = sgn(x) sqrt|x|`,
///   `E[f(e)] = 0` and `E[f(e)^2] = E|e| = sqrt(2/pi)`; cross terms vanish, so
///   `Var = (2/pi) sum_i sigma_w[a,i]^2 phi_i^2 + sqrt(2/pi) sigma_b[a]^2`.
///
/// # Panics
/// If `features` and `sigma_w_row` differ in length (a caller's shape bug).
pub fn noisy_variance(
    features: &[f32],
    sigma_w_row: &[f32],
    sigma_b: f32,
    exact_factorised: bool,
) -> f32 {
    assert_eq!(
        features.len(),
        sigma_w_row.len(),
        "noisy_variance: features and the sigma_w row must have the same length"
    );
    // Eight independent accumulators so the sum vectorises without relying on float reassociation.
    let mut lanes = [0.0f32; 8];
    let feature_chunks = features.chunks_exact(8);
    let sigma_chunks = sigma_w_row.chunks_exact(8);
    let (feature_tail, sigma_tail) = (feature_chunks.remainder(), sigma_chunks.remainder());
    for (phi, sigma) in feature_chunks.zip(sigma_chunks) {
        for lane in 0..8 {
            let term = sigma[lane] * phi[lane];
            lanes[lane] += term * term;
        }
    }
    let mut weight_part: f32 = lanes.iter().sum();
    for (&phi, &sigma) in feature_tail.iter().zip(sigma_tail) {
        let term = sigma * phi;
        weight_part += term * term;
    }
    let bias_part = sigma_b * sigma_b;
    if exact_factorised {
        const TWO_OVER_PI: f32 = std::f32::consts::FRAC_2_PI;
        let sqrt_two_over_pi = TWO_OVER_PI.sqrt();
        TWO_OVER_PI * weight_part + sqrt_two_over_pi * bias_part
    } else {
        weight_part + bias_part
    }
}

#[cfg(test)]
mod tests {

    #[test]
    fn head_variance_and_q_gap_match_their_definitions() {
        // Two heads, three actions: per action the variance of {a, b} is ((a - b) / 2)^2.
        let q = [1.0f32, 5.0, -2.0, 3.0, 5.0, 2.0];
        let expected = ((1.0f64 - 3.0) / 2.0).powi(2) + 0.0 + ((-2.0f64 - 2.0) / 2.0).powi(2);
        assert_eq!(head_variance(&q, 2, 3), (expected / 3.0) as f32);
        assert_eq!(head_variance(&[4.0, 4.0, 4.0], 3, 1), 0.0);
        assert_eq!(q_gap(&q[..3]), 7.0);
        assert_eq!(q_gap(&[2.5]), 0.0);
    }

    use super::*;
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    use rand_pcg::Pcg64;

    /// Straightforward f64 reference: explicit softmax, explicit entropies -sum p ln p, explicit mean.
    fn naive_jsd(q: &[f32], heads: usize, n_actions: usize) -> f64 {
        let policies: Vec<Vec<f64>> = (0..heads)
            .map(|k| {
                let row: Vec<f64> = q[k * n_actions..(k + 1) * n_actions]
                    .iter()
                    .map(|&v| v as f64)
                    .collect();
                let max = row.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                let exps: Vec<f64> = row.iter().map(|v| (v - max).exp()).collect();
                let total: f64 = exps.iter().sum();
                exps.iter().map(|e| e / total).collect()
            })
            .collect();
        let entropy =
            |p: &[f64]| -> f64 { p.iter().filter(|&&x| x > 0.0).map(|&x| -x * x.ln()).sum() };
        let mean: Vec<f64> = (0..n_actions)
            .map(|a| policies.iter().map(|p| p[a]).sum::<f64>() / heads as f64)
            .collect();
        let mean_entropy = policies.iter().map(|p| entropy(p)).sum::<f64>() / heads as f64;
        entropy(&mean) - mean_entropy
    }

    /// Logits whose softmax is (approximately) the given two-action distribution.
    fn logits_for(p0: f64, p1: f64) -> [f32; 2] {
        [p0.ln() as f32, p1.ln() as f32]
    }

    #[test]
    fn paper_example_opposed_confident_heads_are_more_uncertain() {
        // Paper section 4.3: heads giving (1, 0) and (0, 1) must be more uncertain than (0.5, 0.4) and (0.4, 0.5).
        // Large logits give near-one-hot softmaxes; the second state uses logits whose softmax normalises
        // (0.5, 0.4) and (0.4, 0.5).
        let opposed = [20.0f32, 0.0, 0.0, 20.0];
        let [a0, a1] = logits_for(0.5, 0.4);
        let [b0, b1] = logits_for(0.4, 0.5);
        let mild = [a0, a1, b0, b1];
        let u_opposed = js_divergence(&opposed, 2, 2);
        let u_mild = js_divergence(&mild, 2, 2);
        assert!(
            u_opposed > u_mild,
            "opposed {u_opposed} should exceed mild {u_mild}"
        );
        // Near-one-hot opposed heads reach the bound ln 2; the mild pair stays far below it.
        assert!((u_opposed as f64 - 2f64.ln()).abs() < 1e-6);
        assert!((u_mild as f64 - naive_jsd(&mild, 2, 2)).abs() < 1e-6);
    }

    #[test]
    fn identical_heads_have_zero_divergence() {
        let head = [0.3f32, -1.2, 4.0, 2.5];
        let q: Vec<f32> = head.iter().cycle().take(head.len() * 10).cloned().collect();
        assert!(js_divergence(&q, 10, 4).abs() < 1e-7);
    }

    #[test]
    fn large_action_space_uses_heap_fallback_consistently() {
        let mut rng = Pcg64::seed_from_u64(7);
        let (heads, n_actions) = (3, 50);
        let q: Vec<f32> = (0..heads * n_actions)
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut rng);
                z as f32
            })
            .collect();
        let got = js_divergence(&q, heads, n_actions) as f64;
        assert!((got - naive_jsd(&q, heads, n_actions)).abs() < 1e-6);
    }

    #[test]
    #[should_panic(expected = "laid out")]
    fn js_divergence_rejects_wrong_shape() {
        let _ = js_divergence(&[0.0; 5], 2, 2);
    }

    fn q_strategy() -> impl Strategy<Value = (usize, usize, Vec<f32>)> {
        (1usize..12, 1usize..8).prop_flat_map(|(heads, n_actions)| {
            (
                Just(heads),
                Just(n_actions),
                proptest::collection::vec(-50.0f32..50.0, heads * n_actions),
            )
        })
    }

    proptest! {
        #[test]
        fn js_divergence_is_bounded_and_matches_naive((heads, n_actions, q) in q_strategy()) {
            let u = js_divergence(&q, heads, n_actions) as f64;
            let bound = (heads as f64).ln().min((n_actions as f64).ln());
            prop_assert!(u >= 0.0);
            prop_assert!(u <= bound + 1e-6, "u = {} above bound {}", u, bound);
            let reference = naive_jsd(&q, heads, n_actions);
            prop_assert!((u - reference.max(0.0)).abs() < 1e-5, "u = {} reference = {}", u, reference);
        }

        #[test]
        fn js_divergence_is_zero_for_copies_of_one_head(
            head in proptest::collection::vec(-30.0f32..30.0, 1..8), copies in 1usize..10,
        ) {
            let n_actions = head.len();
            let q: Vec<f32> = head.iter().cycle().take(n_actions * copies).cloned().collect();
            prop_assert!(js_divergence(&q, copies, n_actions) < 1e-6);
        }
    }

    /// Empirical variance of samples.
    fn sample_variance(samples: &[f64]) -> f64 {
        let n = samples.len() as f64;
        let mean = samples.iter().sum::<f64>() / n;
        samples.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0)
    }

    /// Fixed layer parameters for one output row, with fan-in p.
    struct RowParameters {
        features: Vec<f32>,
        mu_w: Vec<f32>,
        sigma_w: Vec<f32>,
        mu_b: f32,
        sigma_b: f32,
    }

    fn row_parameters() -> RowParameters {
        // Weight and bias variance parts of comparable size, so a wrong factor on either shows up.
        RowParameters {
            features: vec![0.9, -1.3, 0.0, 2.1, 0.4, -0.7, 1.6, 0.25, -2.0, 0.8],
            mu_w: vec![0.1, -0.3, 0.5, 0.2, -0.1, 0.05, 0.4, -0.25, 0.3, 0.0],
            sigma_w: vec![0.3, 0.1, 0.5, 0.2, 0.6, 0.15, 0.25, 0.4, 0.35, 0.05],
            mu_b: 0.2,
            sigma_b: 0.9,
        }
    }

    const MONTE_CARLO_SAMPLES: usize = 400_000;

    /// Output of one factorised noisy row: y = sum_i (mu_i + sigma_i f(e_out) f(e_i)) phi_i + mu_b + sigma_b f(e_out).
    fn factorised_samples(params: &RowParameters, rng: &mut Pcg64) -> Vec<f64> {
        let scale = |x: f64| x.signum() * x.abs().sqrt();
        (0..MONTE_CARLO_SAMPLES)
            .map(|_| {
                let out_noise = scale(StandardNormal.sample(rng));
                let mut y = params.mu_b as f64 + params.sigma_b as f64 * out_noise;
                for i in 0..params.features.len() {
                    let in_noise = scale(StandardNormal.sample(rng));
                    let weight =
                        params.mu_w[i] as f64 + params.sigma_w[i] as f64 * out_noise * in_noise;
                    y += weight * params.features[i] as f64;
                }
                y
            })
            .collect()
    }

    #[test]
    fn exact_factorised_variance_matches_monte_carlo() {
        let params = row_parameters();
        let mut rng = Pcg64::seed_from_u64(2024);
        let empirical = sample_variance(&factorised_samples(&params, &mut rng));
        let exact = noisy_variance(&params.features, &params.sigma_w, params.sigma_b, true) as f64;
        assert!(
            (empirical / exact - 1.0).abs() < 0.02,
            "empirical {empirical} exact {exact}"
        );
        // The paper's independent-noise form is visibly different under factorised noise: the flag matters.
        let paper = noisy_variance(&params.features, &params.sigma_w, params.sigma_b, false) as f64;
        assert!(
            (empirical / paper - 1.0).abs() > 0.1,
            "empirical {empirical} paper {paper}"
        );
    }

    #[test]
    fn paper_variance_matches_monte_carlo_with_independent_gaussian_noise() {
        let params = row_parameters();
        let mut rng = Pcg64::seed_from_u64(99);
        let samples: Vec<f64> = (0..MONTE_CARLO_SAMPLES)
            .map(|_| {
                let bias_noise: f64 = StandardNormal.sample(&mut rng);
                let mut y = params.mu_b as f64 + params.sigma_b as f64 * bias_noise;
                for i in 0..params.features.len() {
                    let weight_noise: f64 = StandardNormal.sample(&mut rng);
                    let weight = params.mu_w[i] as f64 + params.sigma_w[i] as f64 * weight_noise;
                    y += weight * params.features[i] as f64;
                }
                y
            })
            .collect();
        let empirical = sample_variance(&samples);
        let paper = noisy_variance(&params.features, &params.sigma_w, params.sigma_b, false) as f64;
        assert!(
            (empirical / paper - 1.0).abs() < 0.02,
            "empirical {empirical} paper {paper}"
        );
    }

    proptest! {
        #[test]
        fn noisy_variance_matches_direct_sum(
            pairs in proptest::collection::vec((-3.0f32..3.0, 0.0f32..1.0), 0..70), sigma_b in 0.0f32..1.0,
        ) {
            let (features, sigma_w): (Vec<f32>, Vec<f32>) = pairs.into_iter().unzip();
            let weight_part: f64 =
                features.iter().zip(&sigma_w).map(|(&p, &s)| (s as f64 * p as f64).powi(2)).sum();
            let bias_part = (sigma_b as f64).powi(2);
            let paper = noisy_variance(&features, &sigma_w, sigma_b, false) as f64;
            let exact = noisy_variance(&features, &sigma_w, sigma_b, true) as f64;
            let two_over_pi = 2.0 / std::f64::consts::PI;
            prop_assert!((paper - (weight_part + bias_part)).abs() <= 1e-5 * (1.0 + paper));
            let expected_exact = two_over_pi * weight_part + two_over_pi.sqrt() * bias_part;
            prop_assert!((exact - expected_exact).abs() <= 1e-5 * (1.0 + exact));
        }
    }
}
