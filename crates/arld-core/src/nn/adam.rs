//! Gradients, gradient-norm clipping and the Adam optimiser (docs/algorithm.md §2: Adam, eps 1e-8,
//! gradient-norm clip 10).
//!
//! [`Grads`] shares the network's flat parameter layout, so clipping and the Adam step are single loops
//! over contiguous slices. The loops keep independent lanes (no cross-element reductions except in the
//! norm, which uses 16 partial sums) so the compiler vectorises them.

#[cfg(test)]
use super::Segment;
use super::simd::simd_dispatch;
use super::{Layout, QNet, SimdLevel, simd_level};
use crate::state::{Persist, StateDict, StateError};

/// Gradients of every parameter of a [`QNet`], in the same flat layout.
#[derive(Clone, Debug)]
pub struct Grads {
    pub(crate) layout: Layout,
    pub(crate) data: Vec<f32>,
}

impl Grads {
    /// Zero gradients for `net`'s shape.
    pub fn new(net: &QNet) -> Self {
        Self {
            layout: *net.layout(),
            data: vec![0.0; net.num_parameters()],
        }
    }

    /// All gradients, in the parameter order of [`QNet::parameters`].
    pub fn as_slice(&self) -> &[f32] {
        &self.data
    }

    #[cfg(test)]
    pub(crate) fn tensor(&self, segment: Segment) -> &[f32] {
        &self.data[segment.range()]
    }

    /// Euclidean norm over all gradients together (as `torch.nn.utils.clip_grad_norm_` computes it).
    pub fn global_norm(&self) -> f32 {
        simd_dispatch!(self.global_norm_avx2(), self.global_norm_impl())
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn global_norm_avx2(&self) -> f32 {
        self.global_norm_impl()
    }

    #[inline(always)]
    fn global_norm_impl(&self) -> f32 {
        let mut partial = [0.0f32; 16];
        let chunks = self.data.chunks_exact(16);
        let tail: f32 = chunks.remainder().iter().map(|g| g * g).sum();
        for chunk in chunks {
            for lane in 0..16 {
                partial[lane] += chunk[lane] * chunk[lane];
            }
        }
        (partial.iter().sum::<f32>() + tail).sqrt()
    }

    /// Multiplies every gradient by `s`.
    pub fn scale(&mut self, s: f32) {
        simd_dispatch!(
            scale_avx2(&mut self.data, s),
            scale_slice(&mut self.data, s)
        )
    }
}

#[inline(always)]
fn scale_slice(values: &mut [f32], s: f32) {
    for v in values.iter_mut() {
        *v *= s;
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn scale_avx2(values: &mut [f32], s: f32) {
    scale_slice(values, s)
}

/// Rescales `grads` so their global norm is at most `max_norm`, like `torch.nn.utils.clip_grad_norm_`:
/// factor `max_norm / (norm + 1e-6)` when that is below 1. Returns the norm before clipping.
pub fn clip_grad_norm(grads: &mut Grads, max_norm: f32) -> f32 {
    let norm = grads.global_norm();
    let factor = max_norm / (norm + 1e-6);
    if factor < 1.0 {
        grads.scale(factor);
    }
    norm
}

/// Adam (Kingma & Ba 2015) with PyTorch's bias-corrected update:
/// `m = b1 m + (1-b1) g`, `v = b2 v + (1-b2) g²`,
/// `p -= lr / (1-b1^t) * m / (sqrt(v) / sqrt(1-b2^t) + eps)`, with `b1 = 0.9`, `b2 = 0.999`, `eps = 1e-8`.
#[derive(Clone, Debug)]
pub struct Adam {
    lr: f32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    /// Number of steps taken (`t` in the bias corrections).
    step: u64,
    first_moment: Vec<f32>,
    second_moment: Vec<f32>,
}

impl Adam {
    pub const BETA1: f32 = 0.9;
    pub const BETA2: f32 = 0.999;
    pub const EPS: f32 = 1e-8;

    /// An optimiser for `net`'s parameters with learning rate `lr` and zero moments.
    pub fn new(net: &QNet, lr: f32) -> Self {
        Self::for_parameters(net.num_parameters(), lr)
    }

    /// An optimiser for `count` parameters in one flat slice (an [`super::Mlp`]'s) with zero moments.
    pub fn for_parameters(count: usize, lr: f32) -> Self {
        Self {
            lr,
            beta1: Self::BETA1,
            beta2: Self::BETA2,
            eps: Self::EPS,
            step: 0,
            first_moment: vec![0.0; count],
            second_moment: vec![0.0; count],
        }
    }

    pub fn lr(&self) -> f32 {
        self.lr
    }

    pub fn set_lr(&mut self, lr: f32) {
        self.lr = lr;
    }

    /// Number of steps taken so far.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// One update of `net` with `grads`.
    ///
    /// # Panics
    /// If `net` or `grads` has a different size from the network this optimiser was built for.
    pub fn step(&mut self, net: &mut QNet, grads: &Grads) {
        self.step_parameters(net.parameters_mut(), &grads.data);
    }

    /// One update of the flat parameters `params` with their gradients `grads`.
    ///
    /// # Panics
    /// If `params` or `grads` has a different length from the parameters this optimiser was built for.
    pub fn step_parameters(&mut self, params: &mut [f32], grads: &[f32]) {
        assert_eq!(
            params.len(),
            self.first_moment.len(),
            "Adam: network size changed"
        );
        assert_eq!(
            grads.len(),
            params.len(),
            "Adam: gradients do not match the network"
        );
        self.step += 1;
        // Scalars in double precision, as PyTorch computes them from the Python step count.
        let t = self.step as f64;
        let bias_correction1 = 1.0 - (self.beta1 as f64).powf(t);
        let bias_correction2 = 1.0 - (self.beta2 as f64).powf(t);
        let step_size = (self.lr as f64 / bias_correction1) as f32;
        let inv_sqrt_bias_correction2 = (1.0 / bias_correction2.sqrt()) as f32;
        let coefficients = AdamCoefficients {
            beta1_complement: 1.0 - self.beta1,
            beta2: self.beta2,
            beta2_complement: 1.0 - self.beta2,
            step_size,
            inv_sqrt_bias_correction2,
            eps: self.eps,
        };
        coefficients.update(
            params,
            grads,
            &mut self.first_moment,
            &mut self.second_moment,
        );
    }
}

impl Persist for Adam {
    /// Writes the step count and both moments into `state` under `prefix`.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        state.put_value(&format!("{prefix}.step"), &self.step);
        state.put_f32(&format!("{prefix}.m"), &self.first_moment);
        state.put_f32(&format!("{prefix}.v"), &self.second_moment);
    }

    /// Reads what [`Adam::save_state`] wrote.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        self.step = state.value(&format!("{prefix}.step"))?;
        state.f32s_into(&format!("{prefix}.m"), &mut self.first_moment)?;
        state.f32s_into(&format!("{prefix}.v"), &mut self.second_moment)
    }
}

/// The per-step scalars of one Adam update.
struct AdamCoefficients {
    beta1_complement: f32,
    beta2: f32,
    beta2_complement: f32,
    /// `lr / (1 - beta1^t)`.
    step_size: f32,
    /// `1 / sqrt(1 - beta2^t)`.
    inv_sqrt_bias_correction2: f32,
    eps: f32,
}

/// Moments below this are set to zero (see [`AdamCoefficients::update_impl`]).
const FLUSH_BELOW: f32 = 1e-30;

impl AdamCoefficients {
    /// The element-wise Adam update of `params` with their gradients `grads` and moments `m`, `v` (PyTorch's
    /// formula, see [`Adam`]).
    fn update(&self, params: &mut [f32], grads: &[f32], m: &mut [f32], v: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if simd_level() >= SimdLevel::Avx512 {
            // SAFETY: the AVX-512 level is only selected when the CPU supports it (`SimdLevel::detected`).
            unsafe { self.update_avx512(params, grads, m, v) };
            return;
        }
        simd_dispatch!(
            self.update_avx2(params, grads, m, v),
            self.update_impl(params, grads, m, v)
        )
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn update_avx2(&self, params: &mut [f32], grads: &[f32], m: &mut [f32], v: &mut [f32]) {
        self.update_impl(params, grads, m, v)
    }

    /// The AVX-512 twin: 16-lane square roots and divisions, which bound the update (each lane computes the
    /// same IEEE operations as the other twins, so the same bytes).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2")]
    fn update_avx512(&self, params: &mut [f32], grads: &[f32], m: &mut [f32], v: &mut [f32]) {
        self.update_impl(params, grads, m, v)
    }

    #[inline(always)]
    fn update_impl(&self, params: &mut [f32], grads: &[f32], m: &mut [f32], v: &mut [f32]) {
        for (((p, &g), m), v) in params
            .iter_mut()
            .zip(grads)
            .zip(m.iter_mut())
            .zip(v.iter_mut())
        {
            let m_new = *m + self.beta1_complement * (g - *m);
            let v_new = self.beta2 * *v + self.beta2_complement * g * g;
            // Moments of parameters whose gradient stays zero (dead ReLU units) decay geometrically into the
            // subnormal range, where arithmetic is far slower; flushing them to zero removes that cost
            // and changes each update by less than 1e-26.
            *m = if m_new.abs() < FLUSH_BELOW {
                0.0
            } else {
                m_new
            };
            *v = if v_new < FLUSH_BELOW { 0.0 } else { v_new };
            let denom = v.sqrt() * self.inv_sqrt_bias_correction2 + self.eps;
            *p -= self.step_size * *m / denom;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::OutputKind;
    use rand::SeedableRng;

    /// Adam from the textbook formula (Kingma & Ba, Algorithm 1, with eps added to sqrt(v_hat)), in f64.
    fn reference_adam(
        params: &mut [f64],
        m: &mut [f64],
        v: &mut [f64],
        grads: &[f64],
        t: i32,
        lr: f64,
    ) {
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8f64);
        for i in 0..params.len() {
            m[i] = b1 * m[i] + (1.0 - b1) * grads[i];
            v[i] = b2 * v[i] + (1.0 - b2) * grads[i] * grads[i];
            let m_hat = m[i] / (1.0 - b1.powi(t));
            let v_hat = v[i] / (1.0 - b2.powi(t));
            params[i] -= lr * m_hat / (v_hat.sqrt() + eps);
        }
    }

    #[test]
    fn adam_matches_the_textbook_update_over_several_steps() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let mut net = QNet::new(3, 2, OutputKind::Bootstrap { heads: 2 }, &mut rng);
        let lr = 1e-2;
        let mut adam = Adam::new(&net, lr);
        let n = net.num_parameters();
        let mut reference: Vec<f64> = net.parameters().iter().map(|&p| p as f64).collect();
        let (mut m, mut v) = (vec![0.0f64; n], vec![0.0f64; n]);
        let mut grads = Grads::new(&net);
        for t in 1..=5 {
            // Gradients of varied sign and magnitude, including exact zeros.
            for (i, g) in grads.data.iter_mut().enumerate() {
                *g = if i % 7 == 0 {
                    0.0
                } else {
                    ((i * 31 + t * 17) as f32 * 0.173).sin() * 10f32.powi((i % 5) as i32 - 2)
                };
            }
            let g64: Vec<f64> = grads.data.iter().map(|&g| g as f64).collect();
            adam.step(&mut net, &grads);
            reference_adam(&mut reference, &mut m, &mut v, &g64, t as i32, lr as f64);
        }
        assert_eq!(adam.steps(), 5);
        for (i, (&p, &r)) in net.parameters().iter().zip(&reference).enumerate() {
            assert!(
                (p as f64 - r).abs() < 1e-6 + 1e-5 * r.abs(),
                "param {i}: {p} vs reference {r}"
            );
        }
    }

    /// Moments of parameters whose gradient falls to zero decay to exactly zero, never through the slow
    /// subnormal range (f32 subnormals are below 1.18e-38).
    #[test]
    fn vanishing_moments_are_flushed_to_zero_not_left_subnormal() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let mut net = QNet::new(2, 2, OutputKind::Plain, &mut rng);
        let mut adam = Adam::new(&net, 1e-3);
        let mut grads = Grads::new(&net);
        grads.data.iter_mut().for_each(|g| *g = 1e-3);
        adam.step(&mut net, &grads);
        grads.data.iter_mut().for_each(|g| *g = 0.0);
        let mut seen_zero = false;
        for _ in 0..100_000 {
            adam.step(&mut net, &grads);
            for x in adam.first_moment.iter().chain(&adam.second_moment) {
                assert!(!x.is_subnormal(), "a moment became subnormal: {x:e}");
            }
            seen_zero |= adam.second_moment.iter().all(|&v| v == 0.0);
        }
        assert!(seen_zero, "the second moments never reached zero");
    }

    #[test]
    fn first_adam_step_moves_each_parameter_by_lr_against_the_gradient_sign() {
        // With m = (1-b1) g and v = (1-b2) g², the bias-corrected step is lr * g/|g| (up to eps).
        let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
        let mut net = QNet::new(2, 3, OutputKind::Plain, &mut rng);
        let before = net.parameters().to_vec();
        let mut grads = Grads::new(&net);
        for (i, g) in grads.data.iter_mut().enumerate() {
            *g = if i % 2 == 0 {
                0.5 + i as f32
            } else {
                -0.01 * (i as f32 + 1.0)
            };
        }
        let mut adam = Adam::new(&net, 1e-3);
        adam.step(&mut net, &grads);
        for ((&a, &b), &g) in net.parameters().iter().zip(&before).zip(&grads.data) {
            let expected = b - 1e-3 * g.signum();
            assert!((a - expected).abs() < 1e-6, "{a} vs {expected}");
        }
    }

    #[test]
    fn clipping_rescales_to_the_maximum_norm_and_reports_the_original() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let net = QNet::new(4, 2, OutputKind::Noisy, &mut rng);
        let mut grads = Grads::new(&net);
        for (i, g) in grads.data.iter_mut().enumerate() {
            *g = ((i as f32) * 0.37).cos();
        }
        let expected_norm = grads
            .data
            .iter()
            .map(|&g| (g as f64).powi(2))
            .sum::<f64>()
            .sqrt();
        let original = grads.data.clone();
        let norm = clip_grad_norm(&mut grads, 10.0);
        assert!((norm as f64 - expected_norm).abs() < 1e-3 * expected_norm);
        assert!(expected_norm > 10.0, "test needs a norm above the limit");
        let factor = 10.0 / (expected_norm + 1e-6);
        for (&c, &o) in grads.data.iter().zip(&original) {
            assert!((c as f64 - o as f64 * factor).abs() < 1e-5);
        }
        // Below the limit nothing changes.
        let before = grads.data.clone();
        clip_grad_norm(&mut grads, 1e6);
        assert_eq!(grads.data, before);
    }
}
