//! Dense-layer building blocks: a bounds-checked wrapper around the `gemm` crate's strided matrix
//! product, and the small element-wise passes around it (bias + ReLU, ReLU backward, bias gradients).
//!
//! All matrices live in plain `f32` slices; a [`MatView`] says how a `rows x cols` matrix is laid out
//! inside its slice (row and column strides), so transposes cost nothing: `view.t()` swaps the strides.
//! [`matmul`] checks every view against its slice before handing raw pointers to `gemm`, which makes the
//! one `unsafe` block in the network sound.

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

    /// Number of slice elements the view touches (one past the last element).
    fn span(&self) -> usize {
        if self.rows == 0 || self.cols == 0 {
            0
        } else {
            (self.rows - 1) * self.row_stride + (self.cols - 1) * self.col_stride + 1
        }
    }
}

/// `dst = scale * lhs · rhs`.
///
/// Single-threaded (`gemm::Parallelism::None`): one training run owns one core.
///
/// # Panics
/// If the shapes do not chain or a view reaches outside its slice (programming errors, never input errors).
pub(crate) fn matmul(
    dst: &mut [f32],
    dst_view: MatView,
    lhs: &[f32],
    lhs_view: MatView,
    rhs: &[f32],
    rhs_view: MatView,
    scale: f32,
) {
    assert_eq!(
        lhs_view.cols, rhs_view.rows,
        "matmul: inner dimensions differ"
    );
    assert_eq!(dst_view.rows, lhs_view.rows, "matmul: row counts differ");
    assert_eq!(dst_view.cols, rhs_view.cols, "matmul: column counts differ");
    assert!(
        dst_view.span() <= dst.len(),
        "matmul: destination view exceeds its slice"
    );
    assert!(
        lhs_view.span() <= lhs.len(),
        "matmul: left view exceeds its slice"
    );
    assert!(
        rhs_view.span() <= rhs.len(),
        "matmul: right view exceeds its slice"
    );
    if dst_view.rows == 0 || dst_view.cols == 0 {
        return;
    }
    // SAFETY: every element the product reads or writes lies inside its slice (checked above: the
    // largest offset of each view is below the slice length), `dst` is borrowed mutably and so cannot
    // alias `lhs` or `rhs`, and all strides fit in `isize` because they index existing slices.
    unsafe {
        gemm::gemm(
            dst_view.rows,
            dst_view.cols,
            lhs_view.cols,
            dst.as_mut_ptr(),
            dst_view.col_stride as isize,
            dst_view.row_stride as isize,
            false,
            lhs.as_ptr(),
            lhs_view.col_stride as isize,
            lhs_view.row_stride as isize,
            rhs.as_ptr(),
            rhs_view.col_stride as isize,
            rhs_view.row_stride as isize,
            1.0,
            scale,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// Adds `bias` to every row of the row-major `rows` (width `bias.len()`) and applies ReLU in place.
#[inline(always)]
pub(crate) fn add_bias_relu(rows: &mut [f32], bias: &[f32]) {
    for row in rows.chunks_exact_mut(bias.len()) {
        for (value, b) in row.iter_mut().zip(bias) {
            *value = (*value + b).max(0.0);
        }
    }
}

/// ReLU backward in place: zero the gradient wherever the layer's output was not positive.
///
/// `activations` holds the post-ReLU outputs, so `a > 0` is exactly "the unit was active".
#[inline(always)]
pub(crate) fn relu_backward(grad: &mut [f32], activations: &[f32]) {
    // A select rather than a conditional store, so the loop vectorises.
    for (g, &a) in grad.iter_mut().zip(activations) {
        *g = if a > 0.0 { *g } else { 0.0 };
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Naive triple loop on explicit views: the independent oracle for `matmul`.
    fn naive(lhs: &[f32], lv: MatView, rhs: &[f32], rv: MatView) -> Vec<f64> {
        let mut out = vec![0.0f64; lv.rows * rv.cols];
        for r in 0..lv.rows {
            for c in 0..rv.cols {
                for k in 0..lv.cols {
                    out[r * rv.cols + c] += lhs[r * lv.row_stride + k * lv.col_stride] as f64
                        * rhs[k * rv.row_stride + c * rv.col_stride] as f64;
                }
            }
        }
        out
    }

    #[test]
    fn matmul_matches_naive_product_for_all_transpose_combinations() {
        let (m, k, n) = (7, 5, 3);
        let lhs: Vec<f32> = (0..m * k).map(|i| (i as f32 * 0.37).sin()).collect();
        let rhs: Vec<f32> = (0..k * n).map(|i| (i as f32 * 0.91).cos()).collect();
        for lhs_transposed in [false, true] {
            for rhs_transposed in [false, true] {
                let lv = if lhs_transposed {
                    MatView::row_major(k, m).t()
                } else {
                    MatView::row_major(m, k)
                };
                let rv = if rhs_transposed {
                    MatView::row_major(n, k).t()
                } else {
                    MatView::row_major(k, n)
                };
                let expected = naive(&lhs, lv, &rhs, rv);
                let mut dst = vec![1.0f32; m * n];
                matmul(&mut dst, MatView::row_major(m, n), &lhs, lv, &rhs, rv, 2.0);
                for (d, e) in dst.iter().zip(&expected) {
                    assert!((*d as f64 - 2.0 * e).abs() < 1e-5, "{d} vs {}", 2.0 * e);
                }
            }
        }
    }

    #[test]
    #[should_panic(expected = "exceeds")]
    fn matmul_rejects_views_outside_their_slices() {
        let a = vec![0.0f32; 6];
        let mut d = vec![0.0f32; 4];
        matmul(
            &mut d,
            MatView::row_major(2, 2),
            &a,
            MatView::row_major(2, 4),
            &a,
            MatView::row_major(4, 2),
            1.0,
        );
    }
}
