//! Factorised Gaussian noise for the NoisyNet output layer (docs/algorithm.md §6, Fortunato et al. 2018).
//!
//! The layer computes `y = (mu_w + sigma_w ⊙ eps_w) x + mu_b + sigma_b ⊙ eps_b` with factorised noise
//! `eps_w[j,i] = f(eps_j) f(eps_i)`, `eps_b[j] = f(eps_j)`, `f(x) = sgn(x) sqrt|x|`, `eps ~ N(0,1)`.
//! A [`NoiseSample`] holds the already-transformed factors `f(eps_i)` (one per input) and `f(eps_j)` (one per
//! output); the network turns a sample into effective weights once per forward pass ([`effective_weights`])
//! and, in the backward pass, derives the sigma gradients from the mu gradients ([`sigma_gradients`]):
//! since `W = mu + sigma ⊙ eps`, `dL/dsigma = eps ⊙ dL/dmu`.

use rand::Rng;
use rand_distr::StandardNormal;

use super::HIDDEN;
use crate::state::{Persist, StateDict, StateError};

/// `f(x) = sgn(x) sqrt|x|`, the factorised-noise transform of NoisyNet (docs/algorithm.md §6).
#[inline]
pub fn noise_transform(x: f32) -> f32 {
    x.signum() * x.abs().sqrt()
}

/// One draw of factorised noise for an `inputs -> n_actions` noisy layer.
///
/// A fresh sample (from [`NoiseSample::new`]) is all zeros, i.e. it gives the mean weights, until
/// [`NoiseSample::resample`] is called.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseSample {
    /// `f(eps_i)` for the layer's inputs.
    input_factors: Vec<f32>,
    /// `f(eps_j)` for the layer's outputs (one per action).
    output_factors: Vec<f32>,
}

impl NoiseSample {
    /// A zero sample for a layer of the default width ([`HIDDEN`] inputs) with `n_actions` outputs.
    pub fn new(n_actions: usize) -> Self {
        Self::with_inputs(HIDDEN, n_actions)
    }

    /// A zero sample for a layer with `inputs` inputs (the network's second hidden width) and `n_actions`
    /// outputs.
    pub fn with_inputs(inputs: usize, n_actions: usize) -> Self {
        Self {
            input_factors: vec![0.0; inputs],
            output_factors: vec![0.0; n_actions],
        }
    }

    /// Draws new noise: the input factors first, then one output factor per action, each
    /// `f(eps)` with `eps ~ N(0, 1)` from the caller's generator.
    pub fn resample(&mut self, rng: &mut impl Rng) {
        for factor in self
            .input_factors
            .iter_mut()
            .chain(self.output_factors.iter_mut())
        {
            let eps: f32 = rng.sample(StandardNormal);
            *factor = noise_transform(eps);
        }
    }

    /// Number of outputs (actions) this sample is for.
    pub fn n_actions(&self) -> usize {
        self.output_factors.len()
    }

    /// `f(eps_i)`, one per input unit.
    pub fn input_factors(&self) -> &[f32] {
        &self.input_factors
    }

    /// `f(eps_j)`, one per output unit; also the bias noise `eps_b`.
    pub fn output_factors(&self) -> &[f32] {
        &self.output_factors
    }

    /// Sets the factors directly (tests and replays of a recorded sample).
    pub fn set_factors(&mut self, input_factors: &[f32], output_factors: &[f32]) {
        assert_eq!(
            output_factors.len(),
            self.output_factors.len(),
            "noise sample: wrong action count"
        );
        assert_eq!(
            input_factors.len(),
            self.input_factors.len(),
            "noise sample: wrong input count"
        );
        self.input_factors.copy_from_slice(input_factors);
        self.output_factors.copy_from_slice(output_factors);
    }

    /// Resets to the zero sample (mean weights).
    pub fn clear(&mut self) {
        self.input_factors.fill(0.0);
        self.output_factors.fill(0.0);
    }
}

impl Persist for NoiseSample {
    /// Writes the factors into `state` under `prefix`.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        state.put_f32(&format!("{prefix}.input"), &self.input_factors);
        state.put_f32(&format!("{prefix}.output"), &self.output_factors);
    }

    /// Reads what [`NoiseSample::save_state`] wrote.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        state.f32s_into(&format!("{prefix}.input"), &mut self.input_factors)?;
        state.f32s_into(&format!("{prefix}.output"), &mut self.output_factors)
    }
}

/// The parameters of the noisy output layer: `mu_w`, `sigma_w` are `[A][inputs]` (PyTorch layout),
/// `mu_b`, `sigma_b` are `[A]`.
pub(crate) struct NoisyParams<'a> {
    pub mu_w: &'a [f32],
    pub sigma_w: &'a [f32],
    pub mu_b: &'a [f32],
    pub sigma_b: &'a [f32],
}

/// Builds the effective weights `mu + sigma ⊙ eps` of one forward pass.
///
/// The result `w_eff` is `[A][inputs]` like `mu_w`. `input`/`output` are the noise factors (all zeros for
/// the mean network).
#[inline(always)]
pub(crate) fn effective_weights(
    layer: &NoisyParams,
    input: &[f32],
    output: &[f32],
    w_eff: &mut [f32],
    b_eff: &mut [f32],
) {
    let NoisyParams {
        mu_w,
        sigma_w,
        mu_b,
        sigma_b,
    } = *layer;
    for ((&eps_out, w_row), (mu_row, sigma_row)) in
        output.iter().zip(w_eff.chunks_exact_mut(input.len())).zip(
            mu_w.chunks_exact(input.len())
                .zip(sigma_w.chunks_exact(input.len())),
        )
    {
        for (((w, &mu), &sigma), &eps_in) in w_row.iter_mut().zip(mu_row).zip(sigma_row).zip(input)
        {
            *w = mu + sigma * (eps_out * eps_in);
        }
    }
    for (((b, &mu), &sigma), &eps) in b_eff.iter_mut().zip(mu_b).zip(sigma_b).zip(output) {
        *b = mu + sigma * eps;
    }
}

/// `dL/dsigma = eps ⊙ dL/dmu` for the weights (`[A][inputs]`) and the bias (`[A]`).
#[inline(always)]
pub(crate) fn sigma_gradients(
    grad_mu_w: &[f32],
    grad_mu_b: &[f32],
    input: &[f32],
    output: &[f32],
    grad_sigma_w: &mut [f32],
    grad_sigma_b: &mut [f32],
) {
    for ((&eps_out, g_mu), g_sigma) in output
        .iter()
        .zip(grad_mu_w.chunks_exact(input.len()))
        .zip(grad_sigma_w.chunks_exact_mut(input.len()))
    {
        for ((gs, &gm), &eps_in) in g_sigma.iter_mut().zip(g_mu).zip(input) {
            *gs = gm * (eps_out * eps_in);
        }
    }
    for ((gs, &gm), &eps) in grad_sigma_b.iter_mut().zip(grad_mu_b).zip(output) {
        *gs = gm * eps;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn transform_is_signed_square_root() {
        assert_eq!(noise_transform(4.0), 2.0);
        assert_eq!(noise_transform(-9.0), -3.0);
        assert_eq!(noise_transform(0.0), 0.0);
    }

    /// E[f(eps)^2] = E|eps| = sqrt(2/pi) (docs/algorithm.md §7): checks the draws are transformed
    /// standard normals, not raw ones (whose second moment is 1).
    #[test]
    fn resampled_factors_have_the_factorised_second_moment() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let mut sample = NoiseSample::new(4);
        let (mut sum_sq, mut count) = (0.0f64, 0usize);
        for _ in 0..2000 {
            sample.resample(&mut rng);
            for &f in sample.input_factors().iter().chain(sample.output_factors()) {
                sum_sq += (f as f64) * (f as f64);
                count += 1;
            }
        }
        let second_moment = sum_sq / count as f64;
        let expected = (2.0 / std::f64::consts::PI).sqrt();
        assert!(
            (second_moment - expected).abs() < 0.01,
            "{second_moment} vs {expected}"
        );
    }
}
