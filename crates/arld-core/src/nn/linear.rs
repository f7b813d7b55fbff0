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
/// Each sum starts from +0 and adds the rows in order. Blocks of 64 columns keep their sums in registers over
/// all rows (summing into `out` row by row waited on a store and a reload for every row).
#[inline(always)]
pub(crate) fn column_sums(rows: &[f32], out: &mut [f32]) {
    const BLOCK: usize = 64;
    let n = out.len();
    let mut start = 0;
    while start + BLOCK <= n {
        let mut sums = [0.0f32; BLOCK];
        for row in rows.chunks_exact(n) {
            let row: &[f32; BLOCK] = row[start..start + BLOCK]
                .try_into()
                .expect("a block inside the row");
            for (s, r) in sums.iter_mut().zip(row) {
                *s += r;
            }
        }
        out[start..start + BLOCK].copy_from_slice(&sums);
        start += BLOCK;
    }
    let rest = &mut out[start..];
    rest.fill(0.0);
    for row in rows.chunks_exact(n) {
        for (o, r) in rest.iter_mut().zip(&row[start..]) {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Each column's sum is the in-order sum from +0 of that column, for widths below, at and past the
    /// 64-column block (including a -0 column, which must sum to +0 as the plain loop does).
    #[test]
    fn column_sums_add_each_column_in_row_order() {
        for (rows, n) in [(5, 3), (32, 64), (7, 130), (1, 64), (3, 65)] {
            let mut data: Vec<f32> = (0..rows * n)
                .map(|i| ((i * 37 % 101) as f32 - 50.0) * 1e-3 * (1.0 + i as f32))
                .collect();
            for r in 0..rows {
                data[r * n] = -0.0;
            }
            let mut out = vec![f32::NAN; n];
            column_sums(&data, &mut out);
            for c in 0..n {
                let mut sum = 0.0f32;
                for r in 0..rows {
                    sum += data[r * n + c];
                }
                assert_eq!(out[c].to_bits(), sum.to_bits(), "{rows}x{n}, column {c}");
            }
            assert_eq!(out[0].to_bits(), 0.0f32.to_bits());
        }
    }
}
