//! A multilayer perceptron of any depth and width, for the actor-critic learners: `sizes[0] -> sizes[1] -> ReLU
//! -> ... -> sizes[last]` with a linear or tanh output, forward and backward of a batch on the matrix kernels of
//! `kernels.rs` (so the same bytes on every instruction set, and a batch row equals that state alone), and the
//! gradient with respect to the input, which an actor's update needs to go back through the critic to the action.
//!
//! Layout: parameters in one flat `Vec<f32>`, layer by layer, each layer's weight stored `[in][out]` (transposed,
//! as the Q-network's trunk: the batch product is `x · W` with `W`'s rows contiguous) followed by its bias.
//! Initialisation is PyTorch's default for `nn.Linear` (`linear::init_linear`), drawn layer by layer.
//! [`MlpWorkspace`] keeps every activation of the last forward for the backward pass and is sized once for a
//! maximum batch: after it exists, a pass allocates nothing.

use rand::Rng;

use crate::state::{Persist, StateDict, StateError};

use super::kernels::{Lanes, Strided, product, relu_backward, transpose};
use super::linear::{MatView, column_sums, init_linear, relu_in_place};
use super::simd::at_simd_level;

/// What the last layer applies to its product.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputActivation {
    /// Nothing: values (a critic).
    Linear,
    /// `tanh`: values in (-1, 1), scaled to an action box by the caller (an actor).
    Tanh,
}

/// A dense network's parameters (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp {
    sizes: Vec<usize>,
    output: OutputActivation,
    params: Vec<f32>,
}

/// The buffers of one forward/backward pair for a network of one shape and at most `max_batch` rows.
#[derive(Debug, Clone)]
pub struct MlpWorkspace {
    max_batch: usize,
    batch: usize,
    /// `activations[0]` is the input, `activations[l]` the output of layer `l` (after its activation).
    activations: Vec<Vec<f32>>,
    /// The gradient entering layer `l`'s product (`dL/dz`), then its input's, reused layer by layer.
    grad_a: Vec<f32>,
    grad_b: Vec<f32>,
    /// One transposed weight matrix (for `dz · Wᵀ`).
    w_t: Vec<f32>,
}

impl Mlp {
    /// A network of layer widths `sizes` (input first, output last; at least two) and output activation
    /// `output`, initialised from `rng`.
    ///
    /// # Panics
    /// If `sizes` has fewer than two entries or a zero width (the callers validate configurations first).
    pub fn new(sizes: &[usize], output: OutputActivation, rng: &mut impl Rng) -> Self {
        assert!(
            sizes.len() >= 2 && sizes.iter().all(|&n| n > 0),
            "an MLP needs an input and an output width, all positive: {sizes:?}"
        );
        let total = sizes.windows(2).map(|w| w[0] * w[1] + w[1]).sum();
        let mut net = Mlp {
            sizes: sizes.to_vec(),
            output,
            params: vec![0.0; total],
        };
        for layer in 0..net.layers() {
            let (n_in, n_out) = (net.sizes[layer], net.sizes[layer + 1]);
            let (w, b) = net.layer_mut(layer);
            // PyTorch's [out][in] weight, stored [in][out].
            init_linear(w, MatView::row_major(n_in, n_out).t(), b, rng);
        }
        net
    }

    /// Number of layers (products).
    pub fn layers(&self) -> usize {
        self.sizes.len() - 1
    }

    /// The layer widths, input first.
    pub fn sizes(&self) -> &[usize] {
        &self.sizes
    }

    /// Input width.
    pub fn input_dim(&self) -> usize {
        self.sizes[0]
    }

    /// Output width.
    pub fn output_dim(&self) -> usize {
        self.sizes[self.sizes.len() - 1]
    }

    /// The output activation.
    pub fn output(&self) -> OutputActivation {
        self.output
    }

    /// Every parameter, layer by layer (weight `[in][out]`, then bias).
    pub fn parameters(&self) -> &[f32] {
        &self.params
    }

    /// Every parameter, mutable (an optimiser's step, a target network's copy).
    pub fn parameters_mut(&mut self) -> &mut [f32] {
        &mut self.params
    }

    /// Where layer `layer`'s weight and bias start in the flat parameters.
    fn offset(&self, layer: usize) -> usize {
        self.sizes[..layer + 1]
            .windows(2)
            .map(|w| w[0] * w[1] + w[1])
            .sum()
    }

    fn layer(&self, layer: usize) -> (&[f32], &[f32]) {
        let (n_in, n_out) = (self.sizes[layer], self.sizes[layer + 1]);
        let at = self.offset(layer);
        self.params[at..at + n_in * n_out + n_out].split_at(n_in * n_out)
    }

    fn layer_mut(&mut self, layer: usize) -> (&mut [f32], &mut [f32]) {
        let (n_in, n_out) = (self.sizes[layer], self.sizes[layer + 1]);
        let at = self.offset(layer);
        self.params[at..at + n_in * n_out + n_out].split_at_mut(n_in * n_out)
    }

    /// `self = tau * online + (1 - tau) * self`, parameter by parameter (a target network's Polyak average).
    ///
    /// # Panics
    /// If the networks differ in shape.
    pub fn soft_update(&mut self, online: &Mlp, tau: f32) {
        assert_eq!(self.sizes, online.sizes, "soft_update: shapes differ");
        for (t, o) in self.params.iter_mut().zip(&online.params) {
            *t = tau * o + (1.0 - tau) * *t;
        }
    }

    /// The outputs of a batch (`x` is `batch * input_dim`, row-major; output `batch * output_dim`). The
    /// activations stay in `ws` for [`Self::backward`].
    ///
    /// # Panics
    /// If `ws` was built for another shape, `batch` exceeds its capacity or `x` has the wrong length.
    pub fn forward<'w>(&self, x: &[f32], batch: usize, ws: &'w mut MlpWorkspace) -> &'w [f32] {
        at_simd_level!(Mlp; self, forward_into(x: &[f32], batch: usize, ws: &mut MlpWorkspace));
        &ws.activations[self.layers()][..batch * self.output_dim()]
    }

    #[inline(always)]
    fn forward_into<S: Lanes>(&self, x: &[f32], batch: usize, ws: &mut MlpWorkspace) {
        ws.check(self, batch);
        assert_eq!(
            x.len(),
            batch * self.input_dim(),
            "forward: x must hold batch * input_dim values"
        );
        ws.batch = batch;
        ws.activations[0][..x.len()].copy_from_slice(x);
        for layer in 0..self.layers() {
            let (n_in, n_out) = (self.sizes[layer], self.sizes[layer + 1]);
            let (w, b) = self.layer(layer);
            let (before, after) = ws.activations.split_at_mut(layer + 1);
            let input = &before[layer][..batch * n_in];
            let out = &mut after[0][..batch * n_out];
            product::<S>(out, Strided::row_major(input, batch, n_in), w, Some(b));
            if layer + 1 < self.layers() {
                relu_in_place(out);
            } else if self.output == OutputActivation::Tanh {
                out.iter_mut().for_each(|v| *v = v.tanh());
            }
        }
    }

    /// Backward pass of the last [`Self::forward`] in `ws` for the loss gradient `dy = dL/d(output)`: writes
    /// the parameter gradients into `grads` (overwritten, the layout of [`Self::parameters`]) and, if given,
    /// the input gradient `dL/dx` into `dx` (`batch * input_dim`).
    ///
    /// # Panics
    /// If `ws` holds no forward pass, or a slice does not match the network.
    pub fn backward(
        &self,
        ws: &mut MlpWorkspace,
        dy: &[f32],
        grads: &mut [f32],
        dx: Option<&mut [f32]>,
    ) {
        let grads = Some(grads);
        at_simd_level!(Mlp; self, backward_impl(ws: &mut MlpWorkspace, dy: &[f32], grads: Option<&mut [f32]>, dx: Option<&mut [f32]>));
    }

    /// The input gradient `dL/dx` alone (`batch * input_dim`) of the last [`Self::forward`] in `ws` for the loss
    /// gradient `dy`: the products of [`Self::backward`] that lead to the input, without the parameter
    /// gradients (an actor's update goes back through the critic to the action but does not change the
    /// critic). `dx` holds the same bytes as [`Self::backward`]'s.
    ///
    /// # Panics
    /// As [`Self::backward`].
    pub fn backward_input(&self, ws: &mut MlpWorkspace, dy: &[f32], dx: &mut [f32]) {
        let (grads, dx) = (None, Some(dx));
        at_simd_level!(Mlp; self, backward_impl(ws: &mut MlpWorkspace, dy: &[f32], grads: Option<&mut [f32]>, dx: Option<&mut [f32]>));
    }

    #[inline(always)]
    fn backward_impl<S: Lanes>(
        &self,
        ws: &mut MlpWorkspace,
        dy: &[f32],
        mut grads: Option<&mut [f32]>,
        dx: Option<&mut [f32]>,
    ) {
        let batch = ws.batch;
        assert!(batch > 0, "backward: the workspace holds no forward pass");
        ws.check(self, batch);
        let last = self.layers() - 1;
        assert_eq!(
            dy.len(),
            batch * self.output_dim(),
            "backward: dy must match the output"
        );
        if let Some(grads) = &grads {
            assert_eq!(
                grads.len(),
                self.params.len(),
                "backward: gradients must match the network"
            );
        }
        let MlpWorkspace {
            activations,
            grad_a,
            grad_b,
            w_t,
            ..
        } = ws;
        // dL/dz of the last layer.
        let dz = &mut grad_a[..dy.len()];
        dz.copy_from_slice(dy);
        if self.output == OutputActivation::Tanh {
            for (g, y) in dz.iter_mut().zip(&activations[last + 1]) {
                *g *= 1.0 - y * y;
            }
        }
        let (mut dz_buf, mut da_buf) = (grad_a, grad_b);
        let mut offset_end = self.params.len();
        for layer in (0..=last).rev() {
            let (n_in, n_out) = (self.sizes[layer], self.sizes[layer + 1]);
            let start = offset_end - (n_in * n_out + n_out);
            let input = &activations[layer][..batch * n_in];
            let dz = &dz_buf[..batch * n_out];
            if let Some(grads) = grads.as_deref_mut() {
                let (g_w, g_b) = grads[start..offset_end].split_at_mut(n_in * n_out);
                column_sums(dz, g_b);
                product::<S>(g_w, Strided::transposed(input, batch, n_in), dz, None);
            }
            offset_end = start;
            if layer == 0 && dx.is_none() {
                break;
            }
            let (w, _) = self.layer(layer);
            transpose::<S>(w, n_in, n_out, w_t);
            let da = &mut da_buf[..batch * n_in];
            product::<S>(
                da,
                Strided::row_major(dz, batch, n_out),
                &w_t[..n_in * n_out],
                None,
            );
            if layer > 0 {
                relu_backward::<S>(da, input);
            }
            std::mem::swap(&mut dz_buf, &mut da_buf);
        }
        if let Some(dx) = dx {
            let n = batch * self.input_dim();
            assert_eq!(
                dx.len(),
                n,
                "backward: dx must hold batch * input_dim values"
            );
            dx.copy_from_slice(&dz_buf[..n]);
        }
    }
}

impl Persist for Mlp {
    /// Writes the parameters into `state` as `{prefix}.params` (the shape is the configuration's).
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        state.put_f32(&format!("{prefix}.params"), &self.params[..]);
    }

    /// Reads the parameters [`Mlp::save_state`] wrote into a network of the same shape.
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        state.f32s_into(&format!("{prefix}.params"), &mut self.params)
    }
}

impl MlpWorkspace {
    /// Buffers for `net`'s shape and batches of at most `max_batch` rows.
    pub fn new(net: &Mlp, max_batch: usize) -> Self {
        let widest = net.sizes.iter().copied().max().unwrap_or(0);
        let largest_layer = net.sizes.windows(2).map(|w| w[0] * w[1]).max().unwrap_or(0);
        MlpWorkspace {
            max_batch,
            batch: 0,
            activations: net
                .sizes
                .iter()
                .map(|&n| vec![0.0; max_batch * n])
                .collect(),
            grad_a: vec![0.0; max_batch * widest],
            grad_b: vec![0.0; max_batch * widest],
            w_t: vec![0.0; largest_layer],
        }
    }

    /// The largest batch this workspace holds.
    pub fn max_batch(&self) -> usize {
        self.max_batch
    }

    fn check(&self, net: &Mlp, batch: usize) {
        assert!(
            batch <= self.max_batch,
            "batch {batch} exceeds the workspace's {}",
            self.max_batch
        );
        assert!(
            self.activations.len() == net.sizes.len()
                && self
                    .activations
                    .iter()
                    .zip(&net.sizes)
                    .all(|(a, &n)| a.len() == self.max_batch * n),
            "the workspace was built for another network shape"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// `L = Σ c_i y_i` for fixed coefficients, so `dL/dy = c`: the loss whose gradients finite differences check.
    fn loss(net: &Mlp, x: &[f32], batch: usize, c: &[f32]) -> f64 {
        let mut ws = MlpWorkspace::new(net, batch);
        let y = net.forward(x, batch, &mut ws);
        y.iter()
            .zip(c)
            .map(|(a, b)| f64::from(*a) * f64::from(*b))
            .sum()
    }

    fn check_gradients(sizes: &[usize], output: OutputActivation) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let net = Mlp::new(sizes, output, &mut rng);
        let batch = 5;
        let x: Vec<f32> = (0..batch * net.input_dim())
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let c: Vec<f32> = (0..batch * net.output_dim())
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let mut ws = MlpWorkspace::new(&net, batch);
        net.forward(&x, batch, &mut ws);
        let mut grads = vec![0.0; net.parameters().len()];
        let mut dx = vec![0.0; x.len()];
        net.backward(&mut ws, &c, &mut grads, Some(&mut dx));
        // The input gradient alone (checked below through `dx`) is the same bytes.
        let mut dx_alone = vec![f32::NAN; x.len()];
        net.backward_input(&mut ws, &c, &mut dx_alone);
        assert_eq!(dx_alone, dx, "backward_input differs from backward's dx");
        // Central differences of the float32 network (losses summed in float64), step 1e-3. Where the step
        // crosses a ReLU kink the two one-sided slopes disagree and the derivative is not defined there: such
        // points are skipped, and there must be few of them.
        let h = 1e-3f32;
        let mut skipped = 0;
        let mut check = |analytic: f32, [down, centre, up]: [f64; 3], what: String| {
            let (left, right) = ((centre - down) / f64::from(h), (up - centre) / f64::from(h));
            if (left - right).abs() > 1e-2 * left.abs().max(right.abs()).max(0.1) {
                skipped += 1;
                return;
            }
            let numeric = (up - down) / (2.0 * f64::from(h));
            let tolerance = 2e-3 * numeric.abs().max(0.5);
            assert!(
                (f64::from(analytic) - numeric).abs() < tolerance,
                "{what}: {analytic} vs {numeric}"
            );
        };
        let centre = loss(&net, &x, batch, &c);
        for (i, analytic) in grads.iter().enumerate() {
            let (mut up, mut down) = (net.clone(), net.clone());
            up.parameters_mut()[i] += h;
            down.parameters_mut()[i] -= h;
            let values = [loss(&down, &x, batch, &c), centre, loss(&up, &x, batch, &c)];
            check(*analytic, values, format!("parameter {i}"));
        }
        for i in 0..x.len() {
            let (mut up, mut down) = (x.clone(), x.clone());
            up[i] += h;
            down[i] -= h;
            let values = [
                loss(&net, &down, batch, &c),
                centre,
                loss(&net, &up, batch, &c),
            ];
            check(dx[i], values, format!("input {i}"));
        }
        let total = net.parameters().len() + x.len();
        assert!(
            skipped * 20 <= total,
            "{skipped} of {total} points at a kink"
        );
    }

    #[test]
    fn gradients_match_finite_differences() {
        check_gradients(&[4, 16, 16, 3], OutputActivation::Linear);
        check_gradients(&[3, 8, 2], OutputActivation::Tanh);
        check_gradients(&[5, 12, 9, 7, 1], OutputActivation::Linear);
        check_gradients(&[2, 1], OutputActivation::Tanh);
    }

    #[test]
    fn a_batch_row_equals_that_state_alone_and_matches_a_plain_computation() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let net = Mlp::new(&[3, 10, 6, 2], OutputActivation::Tanh, &mut rng);
        let x: Vec<f32> = (0..4 * 3).map(|_| rng.random_range(-2.0..2.0)).collect();
        let mut ws = MlpWorkspace::new(&net, 4);
        let batch = net.forward(&x, 4, &mut ws).to_vec();
        let mut one = MlpWorkspace::new(&net, 1);
        for (row, state) in x.chunks(3).enumerate() {
            assert_eq!(
                net.forward(state, 1, &mut one),
                &batch[row * 2..row * 2 + 2]
            );
            // An independent float64 evaluation from the flat parameters.
            let mut a: Vec<f64> = state.iter().map(|v| f64::from(*v)).collect();
            for layer in 0..net.layers() {
                let (w, b) = net.layer(layer);
                let (n_in, n_out) = (net.sizes[layer], net.sizes[layer + 1]);
                let mut z: Vec<f64> = (0..n_out)
                    .map(|o| {
                        f64::from(b[o])
                            + (0..n_in)
                                .map(|i| a[i] * f64::from(w[i * n_out + o]))
                                .sum::<f64>()
                    })
                    .collect();
                if layer + 1 < net.layers() {
                    z.iter_mut().for_each(|v| *v = v.max(0.0));
                } else {
                    z.iter_mut().for_each(|v| *v = v.tanh());
                }
                a = z;
            }
            for (ours, exact) in batch[row * 2..row * 2 + 2].iter().zip(&a) {
                assert!((f64::from(*ours) - exact).abs() < 1e-5, "{ours} vs {exact}");
            }
        }
    }

    #[test]
    fn soft_update_moves_a_target_towards_the_online_network() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        let online = Mlp::new(&[2, 4, 1], OutputActivation::Linear, &mut rng);
        let mut target = Mlp::new(&[2, 4, 1], OutputActivation::Linear, &mut rng);
        let before = target.parameters().to_vec();
        target.soft_update(&online, 0.25);
        for ((t, b), o) in target
            .parameters()
            .iter()
            .zip(&before)
            .zip(online.parameters())
        {
            assert!((t - (0.25 * o + 0.75 * b)).abs() < 1e-6);
        }
    }
}
