//! Where each tensor of the network lives in one flat vector: the output stage's kind ([`OutputKind`]),
//! the [`Layout`] of segments in storage order, and [`TensorsMut`], the split of a flat vector (parameters
//! or gradients) into its tensors.

use std::ops::Range;

/// The output stage of the Q-network.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OutputKind {
    /// One linear layer `h2 -> A` (`h2`: the second hidden layer's width).
    Plain,
    /// `heads` independent linear heads `h2 -> A` on a shared trunk (Bootstrapped DQN).
    Bootstrap { heads: usize },
    /// A factorised NoisyLinear `h2 -> A` (NoisyNet).
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
/// The trunk is `fc1_w [obs_dim][h1]`, `fc1_b [h1]`, `fc2_w [h1][h2]`, `fc2_b [h2]` with `[h1, h2] = hidden`.
/// `out_w`/`out_b` are the output layer: for `Plain` and `Bootstrap` the (fused) weight `[h2][K*A]` and
/// bias `[K*A]` (head k owns columns `k*A..(k+1)*A`); for `Noisy` the means `mu_w [A][h2]` and `mu_b [A]`,
/// followed by `sigma_w [A][h2]` and `sigma_b [A]` (empty segments otherwise).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Layout {
    pub obs_dim: usize,
    pub n_actions: usize,
    pub kind: OutputKind,
    /// Widths of the two hidden layers.
    pub hidden: [usize; 2],
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
    pub(super) fn new(
        obs_dim: usize,
        n_actions: usize,
        kind: OutputKind,
        hidden: [usize; 2],
    ) -> Self {
        let [h1, h2] = hidden;
        let out_width = kind.heads() * n_actions;
        let mut next = 0;
        let mut take = |len: usize| {
            let segment = Segment { start: next, len };
            next += len;
            segment
        };
        let noisy = matches!(kind, OutputKind::Noisy);
        // Field initialisers run in the order written, which is the storage order.
        let mut layout = Self {
            obs_dim,
            n_actions,
            kind,
            hidden,
            out_width,
            fc1_w: take(obs_dim * h1),
            fc1_b: take(h1),
            fc2_w: take(h1 * h2),
            fc2_b: take(h2),
            out_w: take(h2 * out_width),
            out_b: take(out_width),
            sigma_w: take(if noisy { h2 * n_actions } else { 0 }),
            sigma_b: take(if noisy { n_actions } else { 0 }),
            len: 0,
        };
        layout.len = next;
        layout
    }

    pub fn heads(&self) -> usize {
        self.kind.heads()
    }

    /// Width of the second hidden layer, the features `phi(s)` the output stage reads.
    pub fn h2(&self) -> usize {
        self.hidden[1]
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
        // Cuts the next `segment.len` values off the front of what is left; called in storage order.
        let mut rest = data;
        let mut take = |segment: Segment| {
            let (tensor, tail) = std::mem::take(&mut rest).split_at_mut(segment.len);
            rest = tail;
            tensor
        };
        Self {
            fc1_w: take(layout.fc1_w),
            fc1_b: take(layout.fc1_b),
            fc2_w: take(layout.fc2_w),
            fc2_b: take(layout.fc2_b),
            out_w: take(layout.out_w),
            out_b: take(layout.out_b),
            sigma_w: take(layout.sigma_w),
            sigma_b: take(layout.sigma_b),
        }
    }
}
