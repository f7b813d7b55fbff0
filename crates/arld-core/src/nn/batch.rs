//! The batched passes: [`QNet::forward`] of a batch of states (activations kept in the [`Workspace`]) and
//! [`QNet::backward`] of the last forward, for a loss gradient with respect to the Q-values.

use super::kernels::{Lanes, Strided, product, relu_backward, transpose};
use super::linear::{column_sums, relu_in_place};
use super::simd::at_simd_level;
use super::{Grads, NoiseSample, OutputKind, QNet, TensorsMut, Workspace, noisy};

impl QNet {
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
        let (depth, n_last) = (l.depth(), l.last_width());
        ws.batch = batch;

        ws.x[..batch * d].copy_from_slice(x);
        // The trunk, layer by layer: h[i] = relu(input · W_i + b_i), the input being x or h[i-1].
        for i in 0..depth {
            let (before, rest) = ws.h.split_at_mut(i);
            let n_in = l.input_width(i);
            let input = match before.last() {
                Some(previous) => &previous[..batch * n_in],
                None => &ws.x[..batch * d],
            };
            let h = &mut rest[0][..batch * l.hidden[i]];
            product::<S>(
                h,
                Strided::row_major(input, batch, n_in),
                self.tensor(l.fc_w[i]),
                Some(self.tensor(l.fc_b[i])),
            );
            relu_in_place(h);
        }
        let h2 = Strided::row_major(&ws.h[depth - 1][..batch * n_last], batch, n_last);

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
                        copy_row(q_row, &fused_row[columns.clone()]);
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
                transpose::<S>(&ws.w_eff, a, n_last, &mut ws.w_eff_t);
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
        let (depth, n2) = (l.depth(), l.last_width());
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
                        copy_row(&mut fused_row[columns.clone()], dq_row);
                    }
                }
                d_fused
            }
            OutputKind::Plain | OutputKind::Noisy => dq,
        };
        // `h2`/`d_h2`: the last hidden layer (the second in the paper's network) and its gradient.
        let h2 = &ws.h[depth - 1][..batch * n2];
        let d_h2 = &mut ws.d_h[depth - 1][..batch * n2];
        let w_t = &mut ws.w_t;
        column_sums(d_out, g.out_b);
        match l.kind {
            OutputKind::Noisy => {
                // dL/dW_eff as [A][h_L] = d_out^T · h_L; it is also dL/dmu_w.
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
                product::<S>(g.out_w, Strided::transposed(h2, batch, n2), d_out, None);
                transpose::<S>(self.tensor(l.out_w), n2, width, w_t);
                product::<S>(d_h2, Strided::row_major(d_out, batch, width), w_t, None);
                // The 1/K trunk scaling of Bootstrapped DQN.
                if l.heads() > 1 {
                    let trunk_scale = 1.0 / l.heads() as f32;
                    d_h2.iter_mut().for_each(|v| *v *= trunk_scale);
                }
            }
        }
        // The trunk, last layer first: through the ReLU, the layer's gradients, then its input's gradient.
        let fc = g.fc;
        for i in (0..depth).rev() {
            let (n_in, n) = (l.input_width(i), l.hidden[i]);
            let (d_before, d_rest) = ws.d_h.split_at_mut(i);
            let d_h = &mut d_rest[0][..batch * n];
            relu_backward::<S>(d_h, &ws.h[i][..batch * n]);
            column_sums(d_h, fc[i].b);
            let input = match i {
                0 => &ws.x[..batch * d],
                _ => &ws.h[i - 1][..batch * n_in],
            };
            product::<S>(fc[i].w, Strided::transposed(input, batch, n_in), d_h, None);
            if let Some(d_input) = d_before.last_mut() {
                transpose::<S>(self.tensor(l.fc_w[i]), n_in, n, &mut ws.w_t);
                product::<S>(
                    &mut d_input[..batch * n_in],
                    Strided::row_major(d_h, batch, n),
                    &ws.w_t,
                    None,
                );
            }
        }
    }
}

/// `dst.copy_from_slice(src)` for the bootstrap reorder's rows of one action count: 2, 3 and 4 floats (the tasks'
/// action counts) are copied as fixed-size arrays, a few moves instead of a call to `memcpy` per row.
#[inline(always)]
fn copy_row(dst: &mut [f32], src: &[f32]) {
    #[inline(always)]
    fn fixed<const N: usize>(dst: &mut [f32], src: &[f32]) {
        let dst: &mut [f32; N] = dst.try_into().expect("rows of equal length");
        *dst = *<&[f32; N]>::try_from(src).expect("rows of equal length");
    }
    match dst.len() {
        2 => fixed::<2>(dst, src),
        3 => fixed::<3>(dst, src),
        4 => fixed::<4>(dst, src),
        _ => dst.copy_from_slice(src),
    }
}
