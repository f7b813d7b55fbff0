//! Runtime selection of wider SIMD for the network's element-wise loops.
//!
//! The crate is compiled for the baseline x86-64 target (SSE2), so the auto-vectorised loops around the
//! GEMMs (bias + ReLU, ReLU backward, bias gradients, the single-state forward, Adam, clipping) would use
//! 4-lane vectors. Each hot entry point therefore has a twin compiled with `#[target_feature(enable =
//! "avx2")]` that calls the same `#[inline(always)]` body; [`simd_dispatch!`] picks the twin when the
//! running CPU has AVX2. (Passing a closure to one generic AVX2 function does not work reliably: LLVM
//! may keep a large closure out of line, and it is then compiled for the baseline.)
//! The `gemm` crate does its own runtime dispatch.
//!
//! Results do not depend on the path taken: Rust never fuses `a * b + c` into an FMA on its own and every
//! loop keeps its element order, so both paths compute bit-identical values.

/// `simd_dispatch!(avx2_call, baseline_call)`: evaluates `avx2_call` (a call of a function compiled with
/// `#[target_feature(enable = "avx2")]`) when the CPU supports AVX2, else `baseline_call`.
macro_rules! simd_dispatch {
    ($avx2:expr, $baseline:expr) => {{
        #[cfg(target_arch = "x86_64")]
        let result = if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { $avx2 }
        } else {
            $baseline
        };
        #[cfg(not(target_arch = "x86_64"))]
        let result = $baseline;
        result
    }};
}

pub(crate) use simd_dispatch;
