//! Dense-layer building blocks around the matrix product (`kernels.rs`): the element-wise passes (ReLU, bias
//! gradients; ReLU's backward pass is in `kernels.rs`, in the level's vectors) and PyTorch's initialisation.
//!
//! A [`MatView`] says how a `rows x cols` matrix is laid out inside a slice (row and column strides), so
//! the initialisation can write PyTorch's `[out][in]` draws into a transposed storage.

use rand::Rng;

/// Layout of a `rows x cols` matrix inside a slice: element `(r, c)` is at `r * row_stride + c * col_stride`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct MatView {
    pub rows: usize,
    pub cols: usize,
    pub row_stride: usize,
    pub col_stride: usize,
}

impl MatView {
    /// A dense row-major matrix.
    pub fn row_major(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            row_stride: cols,
            col_stride: 1,
        }
    }

    /// The transpose of this matrix (same storage).
    pub fn t(self) -> Self {
        Self {
            rows: self.cols,
            cols: self.rows,
            row_stride: self.col_stride,
            col_stride: self.row_stride,
        }
    }
}

/// ReLU in place.
#[inline(always)]
pub(crate) fn relu_in_place(values: &mut [f32]) {
    for v in values.iter_mut() {
        *v = v.max(0.0);
    }
}

/// Bias gradient: the column sums of the row-major gradient `rows` (width `out.len()`), written to `out`.
#[inline(always)]
pub(crate) fn column_sums(rows: &[f32], out: &mut [f32]) {
    out.fill(0.0);
    for row in rows.chunks_exact(out.len()) {
        for (o, r) in out.iter_mut().zip(row) {
            *o += r;
        }
    }
}

/// PyTorch's default `nn.Linear` initialisation, `U[-1/sqrt(fan_in), 1/sqrt(fan_in)]` for weights and
/// biases, drawn in PyTorch's order (the `[out][in]` weight row by row, then the bias).
///
/// The weight is written to `weight` in the layout `weight_view` describes for the `[out][in]` matrix, so a
/// transposed storage receives the same numbers as PyTorch's would for the same draws.
pub(crate) fn init_linear(
    weight: &mut [f32],
    weight_view: MatView,
    bias: &mut [f32],
    rng: &mut impl Rng,
) {
    let fan_in = weight_view.cols;
    let bound = 1.0 / (fan_in as f32).sqrt();
    for out in 0..weight_view.rows {
        for input in 0..weight_view.cols {
            weight[out * weight_view.row_stride + input * weight_view.col_stride] =
                rng.random_range(-bound..bound);
        }
    }
    for b in bias.iter_mut() {
        *b = rng.random_range(-bound..bound);
    }
}
