//! The Q-network: an MLP `obs_dim -> h1 -> ReLU -> ... -> h_L -> ReLU -> output stage` (docs/algorithm.md §2),
//! with forward and backward written by hand on the matrix kernels of `kernels.rs`. The paper's network has
//! two hidden layers, `h1 = h2 = 64` ([`HIDDEN`]); any other depth from 1 to [`MAX_DEPTH`] and widths
//! ([`QNet::with_hidden`]) run on the same kernels, in the same fixed order of operations.
//!
//! The output stage is one of ([`OutputKind`]):
//! - `Plain`: one linear layer `h_L -> A` (`h_L`: the last hidden layer's width);
//! - `Bootstrap { heads: K }`: K independent linear heads `h_L -> A` on the shared trunk; in the backward
//!   pass the gradient entering the trunk is scaled by `1/K` while the heads get their full gradient
//!   (docs/algorithm.md §4, Osband et al. 2016);
//! - `Noisy`: a factorised NoisyLinear `h_L -> A` (docs/algorithm.md §6), the only noisy layer.
//!
//! How the parts fit:
//! - [`QNet`] (this file) holds the parameters only, in one flat `Vec<f32>` (so Adam, clipping and target
//!   copies are single loops over one slice), and initialises them. `layout.rs` says where each tensor
//!   lives: trunk and plain/bootstrap weights are stored transposed, `[in][out]`, so the batch product is
//!   `x · W` with `W`'s rows contiguous (the kernels vectorise across output columns); the K heads are fused
//!   into one `[h_L][K*A]` matrix so the output stage is one product. The noisy layer keeps PyTorch's
//!   `[out][in]` layout (its effective weights are rebuilt every pass anyway, and [`QNet::noisy_sigmas`]
//!   hands out `sigma_w` as `[A][h_L]`). Files use PyTorch's layout for every tensor.
//! - `batch.rs`: [`QNet::forward`] and [`QNet::backward`] of a batch; `single.rs`: [`QNet::q_values_single`],
//!   one state for acting, the same numbers as its row of a batch.
//! - [`Workspace`] (`workspace.rs`) holds every buffer a forward/backward pair needs, sized once for a
//!   maximum batch, and remembers the activations of its last forward for the backward pass.
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
mod batch;
mod io;
mod kernels;
mod layout;
mod linear;
mod mlp;
mod noisy;
mod simd;
mod single;
#[cfg(test)]
mod tests;
mod workspace;

use rand::Rng;

pub use adam::{Adam, Grads, clip_grad_norm};
pub(crate) use io::with_sorted_metadata;
pub use io::{MAX_MODEL_FILE_BYTES, ModelFileError, parse_model};
pub use kernels::product_flops;
pub use layout::{HiddenLayers, MAX_DEPTH, OutputKind};
pub use mlp::{Mlp, MlpWorkspace, OutputActivation};
pub use noisy::{NoiseSample, noise_transform};
pub use simd::{SimdCapError, SimdLevel, simd_level};
pub use workspace::Workspace;

use crate::state::{Persist, StateDict, StateError};
pub(crate) use layout::{Layout, Segment, TensorsMut};
use linear::{MatView, init_linear};

/// Width of both hidden layers in the paper's network (docs/algorithm.md §2), the default.
pub const HIDDEN: usize = 64;

/// The widest hidden layer a network may have (acting keeps one layer's activations on the stack).
pub const MAX_HIDDEN: usize = 4096;

/// The Q-network's parameters (see the module docs for the layout). Cheap to clone, e.g. for a target net.
#[derive(Clone, Debug)]
pub struct QNet {
    layout: Layout,
    params: Vec<f32>,
}

impl QNet {
    /// Width of both hidden layers in the paper's network.
    pub const HIDDEN: usize = HIDDEN;

    /// A freshly initialised network of the paper's widths (both hidden layers [`HIDDEN`] wide); see
    /// [`Self::with_hidden`].
    pub fn new(obs_dim: usize, n_actions: usize, kind: OutputKind, rng: &mut impl Rng) -> Self {
        Self::with_hidden(obs_dim, n_actions, kind, &[HIDDEN, HIDDEN], rng)
    }

    /// A freshly initialised network with hidden layers `hidden = [h1, ..., h_L]` wide (1 to [`MAX_DEPTH`]
    /// layers).
    ///
    /// Hidden layers and plain/bootstrap heads use PyTorch's `nn.Linear` default,
    /// `U[-1/sqrt(fan_in), 1/sqrt(fan_in)]` for weights and biases, drawn layer by layer in PyTorch order
    /// (fc1, fc2, ..., then head 0, 1, ...: each head independently, Osband et al.). The noisy layer draws
    /// `mu ~ U[-1/sqrt(h_L), 1/sqrt(h_L)]` and sets `sigma = 0.5/sqrt(h_L)` (docs/algorithm.md §6).
    ///
    /// # Panics
    /// If `obs_dim`, `n_actions`, the number of heads or a width is zero, a width exceeds [`MAX_HIDDEN`], or
    /// there are no or more than [`MAX_DEPTH`] hidden layers (configurations are validated upstream).
    pub fn with_hidden(
        obs_dim: usize,
        n_actions: usize,
        kind: OutputKind,
        hidden: &[usize],
        rng: &mut impl Rng,
    ) -> Self {
        assert!(obs_dim > 0, "QNet: obs_dim must be positive");
        assert!(
            hidden.iter().all(|&h| (1..=MAX_HIDDEN).contains(&h)),
            "QNet: hidden widths must be 1..={MAX_HIDDEN}, got {hidden:?}"
        );
        let hidden = HiddenLayers::new(hidden).unwrap_or_else(|| {
            panic!("QNet: a network has 1 to {MAX_DEPTH} hidden layers, got {hidden:?}")
        });
        assert!(n_actions > 0, "QNet: n_actions must be positive");
        assert!(
            kind.heads() > 0,
            "QNet: a bootstrapped network needs at least one head"
        );
        let layout = Layout::new(obs_dim, n_actions, kind, hidden);
        let mut params = vec![0.0f32; layout.len];
        let t = TensorsMut::split(&layout, &mut params);
        // Stored transposed: the PyTorch [out][in] matrix is the transpose of our [in][out] storage.
        for (i, layer) in t.fc.into_iter().take(layout.depth()).enumerate() {
            let view = MatView::row_major(layout.input_width(i), hidden[i]).t();
            init_linear(layer.w, view, layer.b, rng);
        }
        let n2 = layout.last_width();
        match kind {
            OutputKind::Plain | OutputKind::Bootstrap { .. } => {
                let width = layout.out_width;
                for head in 0..kind.heads() {
                    // Head k is columns k*A..(k+1)*A of the fused [h_L][K*A] matrix: as an [A][h_L]
                    // matrix it starts at column k*A with row stride 1 and column stride K*A.
                    let view = MatView {
                        rows: n_actions,
                        cols: n2,
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
                init_linear(t.out_w, MatView::row_major(n_actions, n2), t.out_b, rng);
                let sigma = 0.5 / (n2 as f32).sqrt();
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

    /// Widths of the hidden layers, `[h1, ..., h_L]`.
    pub fn hidden(&self) -> &[usize] {
        self.layout.hidden.as_slice()
    }

    /// Width of the last hidden layer: the length of the features `phi(s)`.
    pub fn features_len(&self) -> usize {
        self.layout.last_width()
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

    /// `(sigma_w [A][h_L] row-major, sigma_b [A])` of a noisy network; `None` otherwise.
    pub fn noisy_sigmas(&self) -> Option<(&[f32], &[f32])> {
        match self.layout.kind {
            OutputKind::Noisy => Some((
                self.tensor(self.layout.sigma_w),
                self.tensor(self.layout.sigma_b),
            )),
            _ => None,
        }
    }
}

impl Persist for QNet {
    /// Writes the parameters into `state` as `{prefix}.params`.
    fn save_state<'a>(&'a self, prefix: &str, state: &mut StateDict<'a>) {
        state.put_f32(&format!("{prefix}.params"), &self.params[..]);
    }

    /// Reads the parameters [`QNet::save_state`] wrote (the shapes must match this network's).
    fn load_state(&mut self, prefix: &str, state: &StateDict<'_>) -> Result<(), StateError> {
        state.f32s_into(&format!("{prefix}.params"), &mut self.params)
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
