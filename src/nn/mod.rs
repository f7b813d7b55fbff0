//! The Q-network: a fixed-shape MLP `obs_dim -> 64 -> ReLU -> 64 -> ReLU -> output stage`
//! (docs/algorithm.md §2), with forward and backward written by hand on the matrix kernels of `kernels.rs`.
//!
//! The output stage is one of ([`OutputKind`]):
//! - `Plain`: one linear layer `64 -> A`;
//! - `Bootstrap { heads: K }`: K independent linear heads `64 -> A` on the shared trunk; in the backward
//!   pass the gradient entering the trunk is scaled by `1/K` while the heads get their full gradient
//!   (docs/algorithm.md §4, Osband et al. 2016);
//! - `Noisy`: a factorised NoisyLinear `64 -> A` (docs/algorithm.md §6), the only noisy layer.
//!
//! How the parts fit:
//! - [`QNet`] holds the parameters only, in one flat `Vec<f32>` (so Adam, clipping and target copies are
//!   single loops over one slice). Trunk and plain/bootstrap weights are stored transposed, `[in][out]`, so
//!   the batch product is `x · W` with `W`'s rows contiguous (the kernels vectorise across output columns);
//!   the K heads are fused into one `[64][K*A]` matrix so the output stage is one product. The noisy
//!   layer keeps PyTorch's `[out][in]` layout (its effective weights are rebuilt every pass anyway, and
//!   [`QNet::noisy_sigmas`] hands out `sigma_w` as `[A][64]`). Files use PyTorch's layout for every tensor.
//! - [`Workspace`] holds every buffer a forward/backward pair needs, sized once for a maximum batch, and
//!   remembers the activations of its last forward for the backward pass.
//! - [`Grads`], [`clip_grad_norm`] and [`Adam`] (in `adam.rs`) share the parameter layout.
//! - `kernels.rs` holds the matrix product: one fixed chain of fused multiply-adds per output, so every
//!   instruction set gives the same bytes and a batch row equals the single-state result;
//!   `linear.rs` the element-wise passes and the initialisation; `noisy.rs` [`NoiseSample`]; `io.rs`
//!   reads and writes safetensors.
//! - `simd.rs` chooses the [`SimdLevel`] (the CPU's best, capped by `ARLD_SIMD`); forward, backward and the
//!   single-state pass run in a twin compiled for that level (`at_simd_level!`).
//!
//! After the workspaces exist, a training update allocates nothing.

mod adam;
mod io;
mod kernels;
mod linear;
mod noisy;
mod simd;
#[cfg(test)]
mod tests;

use std::ops::Range;

use rand::Rng;

pub use adam::{Adam, Grads, clip_grad_norm};
pub use io::ModelFileError;
pub use noisy::{NoiseSample, noise_transform};
pub use simd::{SimdCapError, SimdLevel, simd_level};

use kernels::{Lanes, Strided, product, transpose};
use linear::{MatView, column_sums, init_linear, relu_backward};
use simd::scalar_has_fma;

/// `at_simd_level!(net, method(arg: Type, ...))`: calls `net.method::<L>(args)` with the [`Lanes`] of the
/// process's [`SimdLevel`], from a twin compiled for that instruction set (so the `#[inline(always)]`
/// kernels inside are compiled for it too).
macro_rules! at_simd_level {
    ($net:expr, $method:ident($($arg:ident: $ty:ty),*)) => {{
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx2,fma")]
        fn avx512(net: &QNet, $($arg: $ty),*) {
            net.$method::<kernels::Avx512>($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        fn avx2(net: &QNet, $($arg: $ty),*) {
            net.$method::<kernels::Avx2>($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "fma")]
        fn scalar_fma(net: &QNet, $($arg: $ty),*) {
            net.$method::<kernels::Scalar>($($arg),*)
        }
        match simd_level() {
            // SAFETY (all three): a level is only selected when the CPU has its features
            // (`SimdLevel::detected`, `scalar_has_fma`).
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx512 => unsafe { avx512($net, $($arg),*) },
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx2 => unsafe { avx2($net, $($arg),*) },
            #[cfg(target_arch = "x86_64")]
            _ if scalar_has_fma() => unsafe { scalar_fma($net, $($arg),*) },
            _ => $net.$method::<kernels::Scalar>($($arg),*),
        }
    }};
}

/// Width of both hidden layers (docs/algorithm.md §2).
pub const HIDDEN: usize = 64;

/// The output stage of the Q-network.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OutputKind {
    /// One linear layer `64 -> A`.
    Plain,
    /// `heads` independent linear heads `64 -> A` on a shared trunk (Bootstrapped DQN).
    Bootstrap { heads: usize },
    /// A factorised NoisyLinear `64 -> A` (NoisyNet).
    Noisy,
}

impl OutputKind {
    /// Number of Q-value heads: K for `Bootstrap`, 1 otherwise.
    pub fn heads(self) -> usize {
        match self {
            OutputKind::Bootstrap { heads } => heads,
            OutputKind::Plain | OutputKind::Noisy => 1,
        }
    }
}

/// A contiguous piece of the flat parameter vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Segment {
    pub start: usize,
    pub len: usize,
}

impl Segment {
    pub fn range(self) -> Range<usize> {
        self.start..self.start + self.len
    }
}

/// Where each tensor lives in the flat parameter vector, in storage order.
///
/// `out_w`/`out_b` are the output layer: for `Plain` and `Bootstrap` the (fused) weight `[64][K*A]` and
/// bias `[K*A]` (head k owns columns `k*A..(k+1)*A`); for `Noisy` the means `mu_w [A][64]` and `mu_b [A]`,
/// followed by `sigma_w [A][64]` and `sigma_b [A]` (empty segments otherwise).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Layout {
    pub obs_dim: usize,
    pub n_actions: usize,
    pub kind: OutputKind,
    /// Columns of the output GEMM: `heads * n_actions`.
    pub out_width: usize,
    pub fc1_w: Segment,
    pub fc1_b: Segment,
    pub fc2_w: Segment,
    pub fc2_b: Segment,
    pub out_w: Segment,
    pub out_b: Segment,
    pub sigma_w: Segment,
    pub sigma_b: Segment,
    pub len: usize,
}

impl Layout {
    fn new(obs_dim: usize, n_actions: usize, kind: OutputKind) -> Self {
        let out_width = kind.heads() * n_actions;
        let mut next = 0;
        let mut take = |len: usize| {
            let segment = Segment { start: next, len };
            next += len;
            segment
        };
        let fc1_w = take(obs_dim * HIDDEN);
        let fc1_b = take(HIDDEN);
        let fc2_w = take(HIDDEN * HIDDEN);
        let fc2_b = take(HIDDEN);
        let out_w = take(HIDDEN * out_width);
        let out_b = take(out_width);
        let noisy = matches!(kind, OutputKind::Noisy);
        let sigma_w = take(if noisy { HIDDEN * n_actions } else { 0 });
        let sigma_b = take(if noisy { n_actions } else { 0 });
        Self {
            obs_dim,
            n_actions,
            kind,
            out_width,
            fc1_w,
            fc1_b,
            fc2_w,
            fc2_b,
            out_w,
            out_b,
            sigma_w,
            sigma_b,
            len: next,
        }
    }

    pub fn heads(&self) -> usize {
        self.kind.heads()
    }
}

/// Mutable views of every tensor of one flat vector (parameters or gradients), split without copying.
pub(crate) struct TensorsMut<'a> {
    pub fc1_w: &'a mut [f32],
    pub fc1_b: &'a mut [f32],
    pub fc2_w: &'a mut [f32],
    pub fc2_b: &'a mut [f32],
    pub out_w: &'a mut [f32],
    pub out_b: &'a mut [f32],
    pub sigma_w: &'a mut [f32],
    pub sigma_b: &'a mut [f32],
}

impl<'a> TensorsMut<'a> {
    /// Splits `data` (laid out by `layout`) into its tensors; the segments are contiguous and in order.
    pub fn split(layout: &Layout, data: &'a mut [f32]) -> Self {
        assert_eq!(
            data.len(),
            layout.len,
            "flat vector does not match the network layout"
        );
        let (fc1_w, rest) = data.split_at_mut(layout.fc1_w.len);
        let (fc1_b, rest) = rest.split_at_mut(layout.fc1_b.len);
        let (fc2_w, rest) = rest.split_at_mut(layout.fc2_w.len);
        let (fc2_b, rest) = rest.split_at_mut(layout.fc2_b.len);
        let (out_w, rest) = rest.split_at_mut(layout.out_w.len);
        let (out_b, rest) = rest.split_at_mut(layout.out_b.len);
        let (sigma_w, sigma_b) = rest.split_at_mut(layout.sigma_w.len);
        Self {
            fc1_w,
            fc1_b,
            fc2_w,
            fc2_b,
            out_w,
            out_b,
            sigma_w,
            sigma_b,
        }
    }
}

/// The Q-network's parameters (see the module docs for the layout). Cheap to clone, e.g. for a target net.
#[derive(Clone, Debug)]
pub struct QNet {
    layout: Layout,
    params: Vec<f32>,
}

impl QNet {
    /// Width of both hidden layers.
    pub const HIDDEN: usize = HIDDEN;

    /// A freshly initialised network.
    ///
    /// Hidden layers and plain/bootstrap heads use PyTorch's `nn.Linear` default,
    /// `U[-1/sqrt(fan_in), 1/sqrt(fan_in)]` for weights and biases, drawn layer by layer in PyTorch order
    /// (fc1, fc2, then head 0, 1, ...: each head independently, Osband et al.). The noisy layer draws
    /// `mu ~ U[-1/sqrt(64), 1/sqrt(64)]` and sets `sigma = 0.5/sqrt(64)` (docs/algorithm.md §6).
    ///
    /// # Panics
    /// If `obs_dim`, `n_actions` or the number of heads is zero (configurations are validated upstream).
    pub fn new(obs_dim: usize, n_actions: usize, kind: OutputKind, rng: &mut impl Rng) -> Self {
        assert!(obs_dim > 0, "QNet: obs_dim must be positive");
        assert!(n_actions > 0, "QNet: n_actions must be positive");
        assert!(
            kind.heads() > 0,
            "QNet: a bootstrapped network needs at least one head"
        );
        let layout = Layout::new(obs_dim, n_actions, kind);
        let mut params = vec![0.0f32; layout.len];
        let t = TensorsMut::split(&layout, &mut params);
        // Stored transposed: the PyTorch [out][in] matrix is the transpose of our [in][out] storage.
        init_linear(
            t.fc1_w,
            MatView::row_major(obs_dim, HIDDEN).t(),
            t.fc1_b,
            rng,
        );
        init_linear(
            t.fc2_w,
            MatView::row_major(HIDDEN, HIDDEN).t(),
            t.fc2_b,
            rng,
        );
        match kind {
            OutputKind::Plain | OutputKind::Bootstrap { .. } => {
                let width = layout.out_width;
                for head in 0..kind.heads() {
                    // Head k is columns k*A..(k+1)*A of the fused [64][K*A] matrix: as an [A][64]
                    // matrix it starts at column k*A with row stride 1 and column stride K*A.
                    let view = MatView {
                        rows: n_actions,
                        cols: HIDDEN,
                        row_stride: 1,
                        col_stride: width,
                    };
                    let columns = head * n_actions;
                    init_linear(
                        &mut t.out_w[columns..],
                        view,
                        &mut t.out_b[columns..columns + n_actions],
                        rng,
                    );
                }
            }
            OutputKind::Noisy => {
                // mu_w, mu_b in PyTorch order; sigma constant (Fortunato et al., factorised variant).
                init_linear(t.out_w, MatView::row_major(n_actions, HIDDEN), t.out_b, rng);
                let sigma = 0.5 / (HIDDEN as f32).sqrt();
                t.sigma_w.fill(sigma);
                t.sigma_b.fill(sigma);
            }
        }
        Self { layout, params }
    }

    /// A network with the given layout and flat parameters (used by the file reader).
    pub(crate) fn from_parts(layout: Layout, params: Vec<f32>) -> Self {
        assert_eq!(params.len(), layout.len);
        Self { layout, params }
    }

    pub(crate) fn layout(&self) -> &Layout {
        &self.layout
    }

    pub fn obs_dim(&self) -> usize {
        self.layout.obs_dim
    }

    pub fn n_actions(&self) -> usize {
        self.layout.n_actions
    }

    pub fn kind(&self) -> OutputKind {
        self.layout.kind
    }

    /// K for `Bootstrap`, 1 otherwise.
    pub fn heads(&self) -> usize {
        self.layout.heads()
    }

    /// Total number of scalar parameters.
    pub fn num_parameters(&self) -> usize {
        self.layout.len
    }

    /// All parameters as one flat slice (layout described in the module docs).
    pub fn parameters(&self) -> &[f32] {
        &self.params
    }

    pub(crate) fn parameters_mut(&mut self) -> &mut [f32] {
        &mut self.params
    }

    fn tensor(&self, segment: Segment) -> &[f32] {
        &self.params[segment.range()]
    }

    /// Writes the parameters into `state` as `{prefix}.params`.
    pub fn save_state<'a>(&'a self, prefix: &str, state: &mut crate::state::StateDict<'a>) {
        state.put_f32(&format!("{prefix}.params"), &self.params[..]);
    }

    /// Reads the parameters [`QNet::save_state`] wrote (the shapes must match this network's).
    pub fn load_state(
        &mut self,
        prefix: &str,
        state: &crate::state::StateDict<'_>,
    ) -> Result<(), crate::state::StateError> {
        state.f32s_into(&format!("{prefix}.params"), &mut self.params)
    }

    /// Hard target update: copies `other`'s parameters into `self` without allocating.
    ///
    /// # Panics
    /// If the two networks have different shapes.
    pub fn copy_from(&mut self, other: &QNet) {
        assert_eq!(
            self.layout, other.layout,
            "copy_from: networks have different shapes"
        );
        self.params.copy_from_slice(&other.params);
    }

    /// `(sigma_w [A][64] row-major, sigma_b [A])` of a noisy network; `None` otherwise.
    pub fn noisy_sigmas(&self) -> Option<(&[f32], &[f32])> {
        match self.layout.kind {
            OutputKind::Noisy => Some((
                self.tensor(self.layout.sigma_w),
                self.tensor(self.layout.sigma_b),
            )),
            _ => None,
        }
    }

    /// Q-values of a batch (`x` is `batch * obs_dim`, row-major). Output layout `[head][batch][action]`.
    ///
    /// `noise`: for a noisy network, `Some(sample)` evaluates it under that noise and `None` with the mean
    /// weights (noise off); ignored by the other kinds. The activations are kept in `ws` for [`Self::backward`].
    /// Each row is computed exactly as [`Self::q_values_single`] computes that state alone.
    ///
    /// # Panics
    /// If `ws` was built for another shape, `batch` exceeds its capacity, `x` has the wrong length, or the
    /// noise sample is for another action count.
    pub fn forward<'w>(
        &self,
        x: &[f32],
        batch: usize,
        noise: Option<&NoiseSample>,
        ws: &'w mut Workspace,
    ) -> &'w [f32] {
        at_simd_level!(self, forward_into(x: &[f32], batch: usize, noise: Option<&NoiseSample>, ws: &mut Workspace));
        ws.q_values()
    }

    #[inline(always)]
    fn forward_into<S: Lanes>(
        &self,
        x: &[f32],
        batch: usize,
        noise: Option<&NoiseSample>,
        ws: &mut Workspace,
    ) {
        let l = &self.layout;
        ws.check_shape(l, batch);
        assert_eq!(
            x.len(),
            batch * l.obs_dim,
            "forward: x must hold batch * obs_dim values"
        );
        let (d, a, width) = (l.obs_dim, l.n_actions, l.out_width);
        ws.batch = batch;

        let x_copy = &mut ws.x[..batch * d];
        x_copy.copy_from_slice(x);
        let h1 = &mut ws.h1[..batch * HIDDEN];
        product::<S>(
            h1,
            Strided::row_major(x_copy, batch, d),
            self.tensor(l.fc1_w),
            Some(self.tensor(l.fc1_b)),
        );
        relu_in_place(h1);
        let h2 = &mut ws.h2[..batch * HIDDEN];
        product::<S>(
            h2,
            Strided::row_major(h1, batch, HIDDEN),
            self.tensor(l.fc2_w),
            Some(self.tensor(l.fc2_b)),
        );
        relu_in_place(h2);
        let h2 = Strided::row_major(h2, batch, HIDDEN);

        let q = &mut ws.q[..batch * width];
        match l.kind {
            OutputKind::Plain => {
                product::<S>(q, h2, self.tensor(l.out_w), Some(self.tensor(l.out_b)));
            }
            OutputKind::Bootstrap { heads } => {
                // One fused product [batch][K*A], then reorder to [head][batch][action].
                let fused = &mut ws.fused[..batch * width];
                product::<S>(fused, h2, self.tensor(l.out_w), Some(self.tensor(l.out_b)));
                for (head, q_head) in q.chunks_exact_mut(batch * a).enumerate().take(heads) {
                    let columns = head * a..(head + 1) * a;
                    for (q_row, fused_row) in
                        q_head.chunks_exact_mut(a).zip(fused.chunks_exact(width))
                    {
                        q_row.copy_from_slice(&fused_row[columns.clone()]);
                    }
                }
            }
            OutputKind::Noisy => {
                match noise {
                    Some(sample) => {
                        assert_eq!(
                            sample.n_actions(),
                            a,
                            "forward: noise sample is for another action count"
                        );
                        ws.noise_in.copy_from_slice(sample.input_factors());
                        ws.noise_out.copy_from_slice(sample.output_factors());
                    }
                    None => {
                        ws.noise_in.fill(0.0);
                        ws.noise_out.fill(0.0);
                    }
                }
                let layer = noisy::NoisyParams {
                    mu_w: self.tensor(l.out_w),
                    sigma_w: self.tensor(l.sigma_w),
                    mu_b: self.tensor(l.out_b),
                    sigma_b: self.tensor(l.sigma_b),
                };
                noisy::effective_weights(
                    &layer,
                    &ws.noise_in,
                    &ws.noise_out,
                    &mut ws.w_eff,
                    &mut ws.b_eff,
                );
                transpose(&ws.w_eff, a, HIDDEN, &mut ws.w_eff_t);
                product::<S>(q, h2, &ws.w_eff_t, Some(&ws.b_eff));
            }
        }
    }

    /// Backward pass of the last [`Self::forward`] stored in `ws`, for the loss gradient `dq = dL/dQ` in
    /// forward's output layout. Overwrites `grads`.
    ///
    /// Bootstrapped: each head gets its full gradient, the trunk gets `1/K` of the summed head gradients
    /// (docs/algorithm.md §4). Noisy: the gradients of `mu` and `sigma` under the forward's noise sample
    /// (all `sigma` gradients are zero for a forward with noise off).
    ///
    /// # Panics
    /// If `ws` holds no forward pass, or `dq`/`grads` do not match the network.
    pub fn backward(&self, ws: &mut Workspace, dq: &[f32], grads: &mut Grads) {
        at_simd_level!(self, backward_impl(ws: &mut Workspace, dq: &[f32], grads: &mut Grads));
    }

    #[inline(always)]
    fn backward_impl<S: Lanes>(&self, ws: &mut Workspace, dq: &[f32], grads: &mut Grads) {
        let l = &self.layout;
        let batch = ws.batch;
        assert!(batch > 0, "backward: the workspace holds no forward pass");
        ws.check_shape(l, batch);
        let (d, a, width) = (l.obs_dim, l.n_actions, l.out_width);
        assert_eq!(
            dq.len(),
            batch * width,
            "backward: dq must have forward's output layout"
        );
        assert_eq!(
            grads.layout, *l,
            "backward: gradients belong to a network of another shape"
        );
        let g = TensorsMut::split(l, &mut grads.data);

        // dL/d(output product) in the product's [batch][width] layout.
        let d_out: &[f32] = match l.kind {
            OutputKind::Bootstrap { heads } => {
                let d_fused = &mut ws.d_fused[..batch * width];
                for (head, dq_head) in dq.chunks_exact(batch * a).enumerate().take(heads) {
                    let columns = head * a..(head + 1) * a;
                    for (dq_row, fused_row) in
                        dq_head.chunks_exact(a).zip(d_fused.chunks_exact_mut(width))
                    {
                        fused_row[columns.clone()].copy_from_slice(dq_row);
                    }
                }
                d_fused
            }
            OutputKind::Plain | OutputKind::Noisy => dq,
        };
        let h1 = &ws.h1[..batch * HIDDEN];
        let h2 = &ws.h2[..batch * HIDDEN];
        let d_h2 = &mut ws.d_h2[..batch * HIDDEN];
        let w_t = &mut ws.w_t;
        column_sums(d_out, g.out_b);
        match l.kind {
            OutputKind::Noisy => {
                // dL/dW_eff as [A][64] = d_out^T · h2; it is also dL/dmu_w.
                product::<S>(g.out_w, Strided::transposed(d_out, batch, a), h2, None);
                noisy::sigma_gradients(
                    g.out_w,
                    g.out_b,
                    &ws.noise_in,
                    &ws.noise_out,
                    g.sigma_w,
                    g.sigma_b,
                );
                product::<S>(d_h2, Strided::row_major(d_out, batch, a), &ws.w_eff, None);
            }
            OutputKind::Plain | OutputKind::Bootstrap { .. } => {
                product::<S>(g.out_w, Strided::transposed(h2, batch, HIDDEN), d_out, None);
                transpose(self.tensor(l.out_w), HIDDEN, width, w_t);
                product::<S>(d_h2, Strided::row_major(d_out, batch, width), w_t, None);
                // The 1/K trunk scaling of Bootstrapped DQN.
                if l.heads() > 1 {
                    let trunk_scale = 1.0 / l.heads() as f32;
                    d_h2.iter_mut().for_each(|v| *v *= trunk_scale);
                }
            }
        }
        relu_backward(d_h2, h2);
        column_sums(d_h2, g.fc2_b);
        product::<S>(g.fc2_w, Strided::transposed(h1, batch, HIDDEN), d_h2, None);
        let d_h1 = &mut ws.d_h1[..batch * HIDDEN];
        transpose(self.tensor(l.fc2_w), HIDDEN, HIDDEN, w_t);
        product::<S>(d_h1, Strided::row_major(d_h2, batch, HIDDEN), w_t, None);
        relu_backward(d_h1, h1);
        column_sums(d_h1, g.fc1_b);
        product::<S>(
            g.fc1_w,
            Strided::transposed(&ws.x[..batch * d], batch, d),
            d_h1,
            None,
        );
    }

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

#[inline(always)]
fn relu_in_place(values: &mut [f32]) {
    for v in values.iter_mut() {
        *v = v.max(0.0);
    }
}

/// Index of the largest value, the first one on ties (as `numpy.argmax`/`torch.argmax`); 0 if empty.
/// NaN values are never selected unless the first value is NaN.
///
/// Written with selects instead of branches: with a handful of actions the comparisons are
/// unpredictable, and a mispredicted branch costs more than the whole scan.
#[inline]
pub fn argmax(values: &[f32]) -> usize {
    let Some(&first) = values.first() else {
        return 0;
    };
    let (mut best, mut best_value) = (0, first);
    for (i, &v) in values.iter().enumerate().skip(1) {
        let better = v > best_value;
        best = if better { i } else { best };
        best_value = if better { v } else { best_value };
    }
    best
}

/// Buffers for forward/backward passes of networks of one shape, up to a maximum batch size.
///
/// Holds the activations of its last forward pass, which the next [`QNet::backward`] uses; keep one
/// workspace per forward whose activations must survive (e.g. the online net on `s` while other passes run).
#[derive(Clone, Debug)]
pub struct Workspace {
    layout: Layout,
    max_batch: usize,
    /// Batch size of the last forward; 0 before the first.
    batch: usize,
    x: Vec<f32>,
    h1: Vec<f32>,
    h2: Vec<f32>,
    /// Output GEMM result `[batch][K*A]` before reordering (bootstrap only).
    fused: Vec<f32>,
    q: Vec<f32>,
    /// Noise factors and effective output weights (`[A][64]` and transposed `[64][A]`) and bias of the
    /// last noisy forward.
    noise_in: [f32; HIDDEN],
    noise_out: Vec<f32>,
    w_eff: Vec<f32>,
    w_eff_t: Vec<f32>,
    b_eff: Vec<f32>,
    d_fused: Vec<f32>,
    d_h2: Vec<f32>,
    d_h1: Vec<f32>,
    /// A transposed weight matrix for the input gradient of a layer (`[out][64]`, the widest layer).
    w_t: Vec<f32>,
}

impl Workspace {
    /// Buffers for `net`'s shape and batches of up to `max_batch` rows.
    pub fn new(net: &QNet, max_batch: usize) -> Self {
        let l = net.layout;
        let noisy = matches!(l.kind, OutputKind::Noisy);
        let bootstrap = matches!(l.kind, OutputKind::Bootstrap { .. });
        let noisy_len = |n: usize| if noisy { n } else { 0 };
        let bootstrap_len = |n: usize| if bootstrap { n } else { 0 };
        Self {
            layout: l,
            max_batch,
            batch: 0,
            x: vec![0.0; max_batch * l.obs_dim],
            h1: vec![0.0; max_batch * HIDDEN],
            h2: vec![0.0; max_batch * HIDDEN],
            fused: vec![0.0; bootstrap_len(max_batch * l.out_width)],
            q: vec![0.0; max_batch * l.out_width],
            noise_in: [0.0; HIDDEN],
            noise_out: vec![0.0; noisy_len(l.n_actions)],
            w_eff: vec![0.0; noisy_len(HIDDEN * l.n_actions)],
            w_eff_t: vec![0.0; noisy_len(HIDDEN * l.n_actions)],
            b_eff: vec![0.0; noisy_len(l.n_actions)],
            d_fused: vec![0.0; bootstrap_len(max_batch * l.out_width)],
            d_h2: vec![0.0; max_batch * HIDDEN],
            d_h1: vec![0.0; max_batch * HIDDEN],
            w_t: vec![0.0; HIDDEN * l.out_width.max(HIDDEN)],
        }
    }

    fn check_shape(&self, layout: &Layout, batch: usize) {
        assert!(
            self.layout == *layout,
            "workspace was built for another network shape ({:?}, obs_dim {}, {} actions)",
            self.layout.kind,
            self.layout.obs_dim,
            self.layout.n_actions
        );
        assert!(
            batch <= self.max_batch,
            "batch {batch} exceeds the workspace's maximum {}",
            self.max_batch
        );
    }

    /// Largest batch this workspace holds.
    pub fn max_batch(&self) -> usize {
        self.max_batch
    }

    /// Batch size of the last forward pass (0 before the first).
    pub fn batch(&self) -> usize {
        self.batch
    }

    /// Penultimate activations `phi` of the last forward, `[batch][64]`.
    pub fn features(&self) -> &[f32] {
        &self.h2[..self.batch * HIDDEN]
    }

    /// Q-values of the last forward, `[head][batch][action]`.
    pub fn q_values(&self) -> &[f32] {
        &self.q[..self.batch * self.layout.out_width]
    }
}
