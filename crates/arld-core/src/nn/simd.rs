//! The instruction-set level the network runs at, and runtime selection of wider SIMD.
//!
//! [`SimdLevel`] is chosen once per process: the best level the CPU supports (AVX-512, AVX2 with FMA, or
//! scalar), capped by the environment variable `ARLD_SIMD` (`scalar`, `avx2` or `avx512`). Every level
//! computes the same bytes: the matrix kernels (`kernels.rs`) fix the order of every accumulation and use a
//! fused multiply-add for every product on every path (a hardware FMA where there is one, otherwise the
//! correctly rounded `fmaf`, which gives the same result), and the element-wise loops never fuse (Rust does
//! not contract `a * b + c` on its own) and keep their element order. The cap exists so one machine can
//! check that claim (the `simd_levels` test) and so a result can be regenerated at the level of another CPU.
//!
//! The crate is compiled for the baseline x86-64 target (SSE2), so the auto-vectorised element-wise loops
//! (bias + ReLU, ReLU backward, bias gradients, Adam, clipping) would use 4-lane vectors. Each hot entry
//! point therefore has a twin compiled with `#[target_feature(enable = "avx2")]` that calls the same
//! `#[inline(always)]` body; [`simd_dispatch!`] picks the twin when the level is AVX2 or above; the network's
//! passes go through `at_simd_level!`, which has one twin per level. (Passing a
//! closure to one generic AVX2 function does not work reliably: LLVM may keep a large closure out of line,
//! and it is then compiled for the baseline.)

use std::sync::OnceLock;

/// The widest instruction set the network's kernels use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum SimdLevel {
    /// One lane at a time (FMA instructions when the CPU has them, else `fmaf`).
    Scalar,
    /// 8-lane AVX2 vectors with FMA.
    Avx2,
    /// 16-lane AVX-512 vectors.
    Avx512,
}

impl SimdLevel {
    /// Every level, narrowest first.
    pub const ALL: [SimdLevel; 3] = [SimdLevel::Scalar, SimdLevel::Avx2, SimdLevel::Avx512];

    /// The name `ARLD_SIMD` accepts.
    pub fn name(self) -> &'static str {
        match self {
            SimdLevel::Scalar => "scalar",
            SimdLevel::Avx2 => "avx2",
            SimdLevel::Avx512 => "avx512",
        }
    }

    /// The widest level this CPU supports.
    pub fn detected() -> SimdLevel {
        #[cfg(target_arch = "x86_64")]
        {
            let fma = std::arch::is_x86_feature_detected!("fma");
            let avx2 = std::arch::is_x86_feature_detected!("avx2");
            if fma && avx2 && std::arch::is_x86_feature_detected!("avx512f") {
                return SimdLevel::Avx512;
            }
            if fma && avx2 {
                return SimdLevel::Avx2;
            }
        }
        SimdLevel::Scalar
    }

    /// The level to use given the value of `ARLD_SIMD` (`None`: unset): the detected level, capped.
    pub fn from_cap(cap: Option<&str>) -> Result<SimdLevel, SimdCapError> {
        let detected = SimdLevel::detected();
        let Some(cap) = cap else {
            return Ok(detected);
        };
        let cap = SimdLevel::ALL
            .into_iter()
            .find(|level| level.name() == cap.trim().to_ascii_lowercase())
            .ok_or_else(|| SimdCapError(cap.to_string()))?;
        Ok(cap.min(detected))
    }

    /// The level from the environment (`ARLD_SIMD`); the check the command line runs before anything else.
    pub fn from_env() -> Result<SimdLevel, SimdCapError> {
        match std::env::var("ARLD_SIMD") {
            Ok(value) => SimdLevel::from_cap(Some(&value)),
            Err(std::env::VarError::NotPresent) => SimdLevel::from_cap(None),
            Err(std::env::VarError::NotUnicode(value)) => {
                Err(SimdCapError(value.to_string_lossy().into_owned()))
            }
        }
    }
}

/// `ARLD_SIMD` holds something other than a level name.
#[derive(Debug, thiserror::Error)]
#[error("ARLD_SIMD must be one of scalar, avx2, avx512 (or unset), got '{0}'")]
pub struct SimdCapError(String);

/// The level of this process: read from `ARLD_SIMD` and the CPU on first use, fixed afterwards.
///
/// # Panics
/// If `ARLD_SIMD` holds an unknown value; the command line checks it with [`SimdLevel::from_env`] first and
/// reports the error instead.
pub fn simd_level() -> SimdLevel {
    static LEVEL: OnceLock<SimdLevel> = OnceLock::new();
    *LEVEL.get_or_init(|| SimdLevel::from_env().unwrap_or_else(|e| panic!("{e}")))
}

/// Whether the scalar path can use FMA instructions (else `f32::mul_add` calls `fmaf`; same results).
pub(crate) fn scalar_has_fma() -> bool {
    static FMA: OnceLock<bool> = OnceLock::new();
    *FMA.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            std::arch::is_x86_feature_detected!("fma")
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            false
        }
    })
}

/// `simd_dispatch!(avx2_call, baseline_call)`: evaluates `avx2_call` (a call of a function compiled with
/// `#[target_feature(enable = "avx2")]`) when the process runs at AVX2 or above, else `baseline_call`.
macro_rules! simd_dispatch {
    ($avx2:expr, $baseline:expr) => {{
        #[cfg(target_arch = "x86_64")]
        let result = if $crate::nn::simd_level() >= $crate::nn::SimdLevel::Avx2 {
            // SAFETY: the AVX2 level is only selected when the CPU supports AVX2 (`SimdLevel::detected`).
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

/// `at_simd_level!(net, method(arg: Type, ...))`: calls `net.method::<L>(args)` with the `Lanes` (`kernels.rs`) of
/// the process's [`SimdLevel`], from a twin compiled for that instruction set (so the `#[inline(always)]`
/// kernels inside are compiled for it too). `net` is a `QNet`; `at_simd_level!(Type; net, ...)` names another
/// network type (the actor-critic [`super::Mlp`]).
macro_rules! at_simd_level {
    ($net:expr, $method:ident($($arg:ident: $ty:ty),*)) => {
        $crate::nn::simd::at_simd_level!($crate::nn::QNet; $net, $method($($arg: $ty),*))
    };
    ($net_type:ty; $net:expr, $method:ident($($arg:ident: $ty:ty),*)) => {{
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx2,fma")]
        fn avx512(net: &$net_type, $($arg: $ty),*) {
            net.$method::<$crate::nn::kernels::Avx512>($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        fn avx2(net: &$net_type, $($arg: $ty),*) {
            net.$method::<$crate::nn::kernels::Avx2>($($arg),*)
        }
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "fma")]
        fn scalar_fma(net: &$net_type, $($arg: $ty),*) {
            net.$method::<$crate::nn::kernels::Scalar>($($arg),*)
        }
        match $crate::nn::simd_level() {
            // SAFETY (all three): a level is only selected when the CPU has its features
            // (`SimdLevel::detected`, `scalar_has_fma`).
            #[cfg(target_arch = "x86_64")]
            $crate::nn::SimdLevel::Avx512 => unsafe { avx512($net, $($arg),*) },
            #[cfg(target_arch = "x86_64")]
            $crate::nn::SimdLevel::Avx2 => unsafe { avx2($net, $($arg),*) },
            #[cfg(target_arch = "x86_64")]
            _ if $crate::nn::simd::scalar_has_fma() => unsafe { scalar_fma($net, $($arg),*) },
            _ => $net.$method::<$crate::nn::kernels::Scalar>($($arg),*),
        }
    }};
}

pub(crate) use at_simd_level;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cap_names_are_parsed_and_never_raise_the_level() {
        let detected = SimdLevel::detected();
        assert_eq!(SimdLevel::from_cap(None).unwrap(), detected);
        assert_eq!(
            SimdLevel::from_cap(Some("scalar")).unwrap(),
            SimdLevel::Scalar
        );
        assert_eq!(
            SimdLevel::from_cap(Some("AVX2")).unwrap(),
            SimdLevel::Avx2.min(detected)
        );
        assert_eq!(SimdLevel::from_cap(Some("avx512")).unwrap(), detected);
        let err = SimdLevel::from_cap(Some("sse9")).unwrap_err().to_string();
        assert!(err.contains("ARLD_SIMD") && err.contains("sse9"), "{err}");
    }
}
