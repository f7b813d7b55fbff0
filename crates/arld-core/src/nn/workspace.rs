//! [`Workspace`]: the buffers of forward and backward passes for one network shape, sized once for a
//! maximum batch, holding the activations of the last forward for the backward pass.

use super::{Layout, OutputKind, QNet};

/// Buffers for forward/backward passes of networks of one shape, up to a maximum batch size.
///
/// Holds the activations of its last forward pass, which the next [`QNet::backward`] uses; keep one
/// workspace per forward whose activations must survive (e.g. the online net on `s` while other passes run).
#[derive(Clone, Debug)]
pub struct Workspace {
    pub(super) layout: Layout,
    pub(super) max_batch: usize,
    /// Batch size of the last forward; 0 before the first.
    pub(super) batch: usize,
    pub(super) x: Vec<f32>,
    /// The hidden layers' activations, `h[i]` as `[batch][n_i]`, one buffer per layer.
    pub(super) h: Vec<Vec<f32>>,
    /// Output GEMM result `[batch][K*A]` before reordering (bootstrap only).
    pub(super) fused: Vec<f32>,
    pub(super) q: Vec<f32>,
    /// Noise factors and effective output weights (`[A][h_L]` and transposed `[h_L][A]`) and bias of the
    /// last noisy forward.
    pub(super) noise_in: Vec<f32>,
    pub(super) noise_out: Vec<f32>,
    pub(super) w_eff: Vec<f32>,
    pub(super) w_eff_t: Vec<f32>,
    pub(super) b_eff: Vec<f32>,
    pub(super) d_fused: Vec<f32>,
    /// The loss gradients of the hidden layers' activations, shaped as `h`.
    pub(super) d_h: Vec<Vec<f32>>,
    /// A transposed weight matrix for the input gradient of a layer (`[out][in]`, sized for the largest one).
    pub(super) w_t: Vec<f32>,
}

impl Workspace {
    /// Buffers for `net`'s shape and batches of up to `max_batch` rows.
    pub fn new(net: &QNet, max_batch: usize) -> Self {
        let l = net.layout;
        let n_last = l.last_width();
        let per_layer =
            || -> Vec<Vec<f32>> { l.hidden.iter().map(|&n| vec![0.0; max_batch * n]).collect() };
        // The largest weight matrix whose transpose the backward pass takes: the output layer's or a trunk
        // layer's past the first.
        let widest_transpose = (1..l.depth())
            .map(|i| l.hidden[i - 1] * l.hidden[i])
            .fold(n_last * l.out_width, usize::max);
        let noisy = matches!(l.kind, OutputKind::Noisy);
        let bootstrap = matches!(l.kind, OutputKind::Bootstrap { .. });
        let noisy_len = |n: usize| if noisy { n } else { 0 };
        let bootstrap_len = |n: usize| if bootstrap { n } else { 0 };
        Self {
            layout: l,
            max_batch,
            batch: 0,
            x: vec![0.0; max_batch * l.obs_dim],
            h: per_layer(),
            fused: vec![0.0; bootstrap_len(max_batch * l.out_width)],
            q: vec![0.0; max_batch * l.out_width],
            noise_in: vec![0.0; noisy_len(n_last)],
            noise_out: vec![0.0; noisy_len(l.n_actions)],
            w_eff: vec![0.0; noisy_len(n_last * l.n_actions)],
            w_eff_t: vec![0.0; noisy_len(n_last * l.n_actions)],
            b_eff: vec![0.0; noisy_len(l.n_actions)],
            d_fused: vec![0.0; bootstrap_len(max_batch * l.out_width)],
            d_h: per_layer(),
            w_t: vec![0.0; widest_transpose],
        }
    }

    pub(super) fn check_shape(&self, layout: &Layout, batch: usize) {
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

    /// Penultimate activations `phi` of the last forward, `[batch][h_L]`.
    pub fn features(&self) -> &[f32] {
        let last = self
            .h
            .last()
            .expect("a network has at least one hidden layer");
        &last[..self.batch * self.layout.last_width()]
    }

    /// Q-values of the last forward, `[head][batch][action]`.
    pub fn q_values(&self) -> &[f32] {
        &self.q[..self.batch * self.layout.out_width]
    }
}
