//! The single-state path for acting: [`QNet::q_values_single`] computes one state's Q-values without a
//! workspace, with the same chain of operations (so the same numbers) as that state's row of a batch.

use super::kernels::{Lanes, Strided, product};
use super::linear::relu_in_place;
use super::simd::at_simd_level;
use super::{HIDDEN, NoiseSample, OutputKind, QNet};

impl QNet {
    /// Q-values of one state, `[head][action]` (length `heads * n_actions`), for acting: the same numbers
    /// as that state's row of a batched [`Self::forward`]. `noise` as in [`Self::forward`].
    pub fn q_values_single(&self, obs: &[f32], noise: Option<&NoiseSample>, q_out: &mut [f32]) {
        let mut features = [0.0f32; HIDDEN];
        self.q_values_single_with_features(obs, noise, q_out, &mut features);
    }

    /// [`Self::q_values_single`] that also returns the penultimate activations `phi(s)` (64 values), which
    /// the noisy predictive-variance uncertainty needs (docs/algorithm.md §7).
    ///
    /// # Panics
    /// If `obs` or `q_out` has the wrong length, or the noise sample is for another action count.
    pub fn q_values_single_with_features(
        &self,
        obs: &[f32],
        noise: Option<&NoiseSample>,
        q_out: &mut [f32],
        features: &mut [f32; HIDDEN],
    ) {
        at_simd_level!(self, single_impl(obs: &[f32], noise: Option<&NoiseSample>, q_out: &mut [f32], features: &mut [f32; HIDDEN]));
    }

    #[inline(always)]
    fn single_impl<S: Lanes>(
        &self,
        obs: &[f32],
        noise: Option<&NoiseSample>,
        q_out: &mut [f32],
        features: &mut [f32; HIDDEN],
    ) {
        let l = &self.layout;
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
        let mut h1 = [0.0f32; HIDDEN];
        product::<S>(
            &mut h1,
            Strided::row_major(obs, 1, l.obs_dim),
            self.tensor(l.fc1_w),
            Some(self.tensor(l.fc1_b)),
        );
        relu_in_place(&mut h1);
        product::<S>(
            features,
            Strided::row_major(&h1, 1, HIDDEN),
            self.tensor(l.fc2_w),
            Some(self.tensor(l.fc2_b)),
        );
        relu_in_place(features);
        match l.kind {
            OutputKind::Plain | OutputKind::Bootstrap { .. } => {
                // With batch 1, [head][batch][action] is the fused [K*A] order.
                product::<S>(
                    q_out,
                    Strided::row_major(features, 1, HIDDEN),
                    self.tensor(l.out_w),
                    Some(self.tensor(l.out_b)),
                );
            }
            OutputKind::Noisy => {
                let zero_in = [0.0f32; HIDDEN];
                let (eps_in, eps_out) = match noise {
                    Some(sample) => {
                        assert_eq!(
                            sample.n_actions(),
                            l.n_actions,
                            "q_values_single: wrong noise sample"
                        );
                        (sample.input_factors(), Some(sample.output_factors()))
                    }
                    None => (&zero_in, None),
                };
                let (mu_w, sigma_w) = (self.tensor(l.out_w), self.tensor(l.sigma_w));
                let (mu_b, sigma_b) = (self.tensor(l.out_b), self.tensor(l.sigma_b));
                // The batched forward's chain, with the effective weights built on the fly
                // (noisy::effective_weights: w = mu + sigma * (eps_out * eps_in), b = mu + sigma * eps_out).
                for (action, q) in q_out.iter_mut().enumerate() {
                    let e_out = eps_out.map_or(0.0, |e| e[action]);
                    let rows = action * HIDDEN..(action + 1) * HIDDEN;
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
