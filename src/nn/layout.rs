//! Where each tensor of the network lives in one flat vector: the output stage's kind ([`OutputKind`]),
//! the [`Layout`] of segments in storage order, and [`TensorsMut`], the split of a flat vector (parameters
//! or gradients) into its tensors.

use std::ops::Range;

use super::HIDDEN;

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
    pub(super) fn new(obs_dim: usize, n_actions: usize, kind: OutputKind) -> Self {
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
