//! The single-state path for acting: [`QNet::q_values_single`] computes one state's Q-values without a
//! workspace, with the same chain of operations (so the same numbers) as that state's row of a batch.

use std::cell::RefCell;

use super::kernels::{Lanes, Strided, product};
use super::linear::relu_in_place;
use super::simd::at_simd_level;
use super::{MAX_HIDDEN, NoiseSample, OutputKind, QNet};

thread_local! {
    /// The activations of the hidden layers before the last in the single-state pass (two halves, read from one
    /// and written to the other in turn), and the features when the caller keeps none: grown to the widest
    /// network the thread has run, so acting allocates nothing after its first step.
    static TRUNK: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
    static FEATURES: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// The noise factors of a noisy layer acting with its mean weights.
static ZEROS: [f32; MAX_HIDDEN] = [0.0; MAX_HIDDEN];

/// The first `n` values of a scratch buffer, grown to hold them.
fn scratch(buffer: &mut Vec<f32>, n: usize) -> &mut [f32] {
    if buffer.len() < n {
        buffer.resize(n, 0.0);
    }
    &mut buffer[..n]
}

impl QNet {
    /// Q-values of one state, `[head][action]` (length `heads * n_actions`), for acting: the same numbers
    /// as that state's row of a batched [`Self::forward`]. `noise` as in [`Self::forward`].
    pub fn q_values_single(&self, obs: &[f32], noise: Option<&NoiseSample>, q_out: &mut [f32]) {
        let mut buffer = FEATURES.take();
        let features = scratch(&mut buffer, self.layout.last_width());
        self.q_values_single_with_features(obs, noise, q_out, features);
        FEATURES.set(buffer);
    }

    /// [`Self::q_values_single`] that also returns the penultimate activations `phi(s)` (the last hidden
    /// layer's width of values), which the noisy predictive-variance uncertainty needs (docs/algorithm.md §7).
    ///
    /// # Panics
    /// If `obs`, `q_out` or `features` has the wrong length, or the noise sample is for another shape.
    pub fn q_values_single_with_features(
        &self,
        obs: &[f32],
        noise: Option<&NoiseSample>,
        q_out: &mut [f32],
        features: &mut [f32],
    ) {
        at_simd_level!(self, single_impl(obs: &[f32], noise: Option<&NoiseSample>, q_out: &mut [f32], features: &mut [f32]));
    }

    #[inline(always)]
    fn single_impl<S: Lanes>(
        &self,
        obs: &[f32],
        noise: Option<&NoiseSample>,
        q_out: &mut [f32],
        features: &mut [f32],
    ) {
        let l = &self.layout;
        let (depth, n2) = (l.depth(), l.last_width());
        assert_eq!(
            obs.len(),
            l.obs_dim,
            "q_values_single: observation has the wrong length"
        );
        assert_eq!(
            q_out.len(),
            l.out_width,
            "q_values_single: q_out must hold heads * n_actions values"
        );
        assert_eq!(
            features.len(),
            n2,
            "q_values_single: features must hold the last hidden layer's width"
        );
        // Taken out of the thread's slot rather than borrowed in a closure: the products stay in this function,
        // compiled for the SIMD level.
        let mut buffer = TRUNK.take();
        let widest = l.hidden[..depth - 1].iter().copied().max().unwrap_or(0);
        let (mut input, mut output) = scratch(&mut buffer, 2 * widest).split_at_mut(widest);
        for i in 0..depth {
            let (n_in, n) = (l.input_width(i), l.hidden[i]);
            let layer_input = if i == 0 { obs } else { &input[..n_in] };
            let h = if i + 1 == depth {
                &mut *features
            } else {
                &mut output[..n]
            };
            product::<S>(
                h,
                Strided::row_major(layer_input, 1, n_in),
                self.tensor(l.fc_w[i]),
                Some(self.tensor(l.fc_b[i])),
            );
            relu_in_place(h);
            std::mem::swap(&mut input, &mut output);
        }
        TRUNK.set(buffer);
        match l.kind {
            OutputKind::Plain | OutputKind::Bootstrap { .. } => {
                // With batch 1, [head][batch][action] is the fused [K*A] order.
                product::<S>(
                    q_out,
                    Strided::row_major(features, 1, n2),
                    self.tensor(l.out_w),
                    Some(self.tensor(l.out_b)),
                );
            }
            OutputKind::Noisy => {
                let (eps_in, eps_out) = match noise {
                    Some(sample) => {
                        assert_eq!(
                            sample.n_actions(),
                            l.n_actions,
                            "q_values_single: wrong noise sample"
                        );
                        assert_eq!(
                            sample.input_factors().len(),
                            n2,
                            "q_values_single: noise sample for another layer width"
                        );
                        (sample.input_factors(), Some(sample.output_factors()))
                    }
                    None => (&ZEROS[..n2], None),
                };
                let (mu_w, sigma_w) = (self.tensor(l.out_w), self.tensor(l.sigma_w));
                let (mu_b, sigma_b) = (self.tensor(l.out_b), self.tensor(l.sigma_b));
                // The batched forward's chain, with the effective weights built on the fly
                // (noisy::effective_weights: w = mu + sigma * (eps_out * eps_in), b = mu + sigma * eps_out).
                for (action, q) in q_out.iter_mut().enumerate() {
                    let e_out = eps_out.map_or(0.0, |e| e[action]);
                    let rows = action * n2..(action + 1) * n2;
                    let mut acc = mu_b[action] + sigma_b[action] * e_out;
                    for (((&f, &mu), &sigma), &e_in) in features
                        .iter()
                        .zip(&mu_w[rows.clone()])
                        .zip(&sigma_w[rows])
                        .zip(eps_in)
                    {
                        acc = f.mul_add(mu + sigma * (e_out * e_in), acc);
                    }
                    *q = acc;
                }
            }
        }
    }
}
