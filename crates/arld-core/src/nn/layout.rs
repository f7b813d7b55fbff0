//! Where each tensor of the network lives in one flat vector: the output stage's kind ([`OutputKind`]), the
//! hidden widths ([`HiddenLayers`]), the [`Layout`] of segments in storage order, and [`TensorsMut`], the split of a flat vector (parameters
//! or gradients) into its tensors.

use std::ops::Range;

/// The output stage of the Q-network.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OutputKind {
    /// One linear layer `h_L -> A` (`h_L`: the last hidden layer's width).
    Plain,
    /// `heads` independent linear heads `h_L -> A` on a shared trunk (Bootstrapped DQN).
    Bootstrap { heads: usize },
    /// A factorised NoisyLinear `h_L -> A` (NoisyNet).
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

/// The deepest trunk a Q-network may have: at most this many hidden layers.
pub const MAX_DEPTH: usize = 8;

/// The widths of a Q-network's hidden layers, first to last: 1 to [`MAX_DEPTH`] of them. A small copyable
/// value (no heap), so a [`Layout`] and an agent's configuration stay `Copy`; it reads as a `&[usize]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HiddenLayers {
    /// The widths in use are `widths[..depth]`; the rest are zero.
    widths: [usize; MAX_DEPTH],
    depth: usize,
}

impl HiddenLayers {
    /// The widths `hidden`, if there are 1 to [`MAX_DEPTH`] of them; `None` otherwise. Whether each width is
    /// in range is the caller's check (a configuration's `validate`, the network's constructor).
    pub fn new(hidden: &[usize]) -> Option<Self> {
        if hidden.is_empty() || hidden.len() > MAX_DEPTH {
            return None;
        }
        let mut widths = [0; MAX_DEPTH];
        widths[..hidden.len()].copy_from_slice(hidden);
        Some(Self {
            widths,
            depth: hidden.len(),
        })
    }

    /// The widths, first hidden layer first.
    pub fn as_slice(&self) -> &[usize] {
        &self.widths[..self.depth]
    }
}

impl std::ops::Deref for HiddenLayers {
    type Target = [usize];

    fn deref(&self) -> &[usize] {
        self.as_slice()
    }
}

/// A contiguous piece of the flat parameter vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
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
/// The trunk is, layer after layer, `fc{i}_w [in][n_i]`, `fc{i}_b [n_i]` (i = 1..=depth, `n_i = hidden[i-1]`,
/// the first layer's input being `obs_dim`): for two layers `fc1_w [obs_dim][h1]`, `fc1_b`, `fc2_w [h1][h2]`,
/// `fc2_b`. `out_w`/`out_b` are the output layer, reading the last hidden layer (width `h_L`): for `Plain` and
/// `Bootstrap` the (fused) weight `[h_L][K*A]` and bias `[K*A]` (head k owns columns `k*A..(k+1)*A`); for
/// `Noisy` the means `mu_w [A][h_L]` and `mu_b [A]`, followed by `sigma_w [A][h_L]` and `sigma_b [A]` (empty
/// segments otherwise). The trunk segments past `depth` are empty.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Layout {
    pub obs_dim: usize,
    pub n_actions: usize,
    pub kind: OutputKind,
    /// Widths of the hidden layers.
    pub hidden: HiddenLayers,
    /// Columns of the output GEMM: `heads * n_actions`.
    pub out_width: usize,
    /// The trunk layers' weights and biases, `fc_w[i]`/`fc_b[i]` for the file's `fc{i+1}`.
    pub fc_w: [Segment; MAX_DEPTH],
    pub fc_b: [Segment; MAX_DEPTH],
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
        hidden: HiddenLayers,
    ) -> Self {
        let out_width = kind.heads() * n_actions;
        let mut next = 0;
        let mut take = |len: usize| {
            let segment = Segment { start: next, len };
            next += len;
            segment
        };
        let (mut fc_w, mut fc_b) = (
            [Segment::default(); MAX_DEPTH],
            [Segment::default(); MAX_DEPTH],
        );
        let mut inputs = obs_dim;
        for (i, &width) in hidden.iter().enumerate() {
            fc_w[i] = take(inputs * width);
            fc_b[i] = take(width);
            inputs = width;
        }
        let last = inputs;
        let noisy = matches!(kind, OutputKind::Noisy);
        // Field initialisers run in the order written, which is the storage order.
        let mut layout = Self {
            obs_dim,
            n_actions,
            kind,
            hidden,
            out_width,
            fc_w,
            fc_b,
            out_w: take(last * out_width),
            out_b: take(out_width),
            sigma_w: take(if noisy { last * n_actions } else { 0 }),
            sigma_b: take(if noisy { n_actions } else { 0 }),
            len: 0,
        };
        layout.len = next;
        layout
    }

    pub fn heads(&self) -> usize {
        self.kind.heads()
    }

    /// Number of hidden layers.
    pub fn depth(&self) -> usize {
        self.hidden.len()
    }

    /// Width of the last hidden layer, the features `phi(s)` the output stage reads.
    pub fn last_width(&self) -> usize {
        self.hidden[self.depth() - 1]
    }

    /// Width of the input of trunk layer `i` (0-based): `obs_dim` for the first, the previous width otherwise.
    pub fn input_width(&self, i: usize) -> usize {
        if i == 0 {
            self.obs_dim
        } else {
            self.hidden[i - 1]
        }
    }
}

/// Mutable views of one trunk layer's tensors.
pub(crate) struct LayerMut<'a> {
    pub w: &'a mut [f32],
    pub b: &'a mut [f32],
}

/// Mutable views of every tensor of one flat vector (parameters or gradients), split without copying.
pub(crate) struct TensorsMut<'a> {
    /// The trunk layers, first to last; those past the network's depth are empty.
    pub fc: [LayerMut<'a>; MAX_DEPTH],
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
        // `from_fn` calls in index order: weight then bias of layer 0, then layer 1, ...
        let fc = std::array::from_fn(|i| LayerMut {
            w: take(layout.fc_w[i]),
            b: take(layout.fc_b[i]),
        });
        Self {
            fc,
            out_w: take(layout.out_w),
            out_b: take(layout.out_b),
            sigma_w: take(layout.sigma_w),
            sigma_b: take(layout.sigma_b),
        }
    }
}
