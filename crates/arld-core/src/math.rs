//! The elementary functions (sin, cos, exp, log, pow, ...) of every computation in the process, correctly rounded,
//! except the single-precision sine and cosine of Box2D, which stay the C library's as in Gymnasium.
//!
//! Why: the C library's `sin` or `pow` is not one function. glibc picks an AVX2/FMA build or a baseline build of
//! each at load time, by CPU, and the two round differently on a small share of inputs (measured: 7 in 10,000
//! `sin` calls on uniform inputs in [-10, 10]; a run of Acrobot-v1 evaluates `sin`/`cos` millions of times). Other
//! glibc versions and other C libraries differ again. So the same seed gave different Acrobot-v1 runs on a CPU
//! without FMA, although the network's own arithmetic is the same everywhere (`nn::kernels`).
//!
//! What: every call of these functions in the final executable, ours, the standard library's (`f64::sin` lowers
//! to the C symbol `sin`) and `rand_distr`'s, is redirected at link time to the `__wrap_<name>` functions below:
//! `build.rs` passes the linker `--wrap=<name>` for every `__wrap_` function defined in this file (it reads them
//! from here, so this file is the only list). They call CORE-MATH (the `core-math` crate), whose results are
//! correctly rounded: the exact value rounded to nearest, one answer for each input on every CPU, compiler and
//! library. `tests/numerics.rs` checks that the executable imports none of the C library's versions but the
//! exception below, and that a CPU without AVX2/FMA (simulated with `GLIBC_TUNABLES`) gives the same bytes.
//!
//! The exception: `sinf`, `cosf` and `sincosf`, which only the bundled Box2D calls (LunarLander). Gymnasium's
//! Box2D calls glibc's, and CORE-MATH's differ from them on about 1.4% of inputs, enough for seeded LunarLander
//! episodes to leave Gymnasium's trace (`tests/conformance.rs`). glibc's two builds of these functions agree on
//! every float of magnitude below 17.25 (checked exhaustively with glibc 2.36; the first disagreement is
//! `cosf(17.278738)`, next to a zero of the cosine). So they are glibc's below `GLIBC_F32_TRIG_AGREES_BELOW`
//! and CORE-MATH's above: the same on every CPU, and Gymnasium's wherever Gymnasium's is the same on every CPU.
//! A C library other than glibc would change them, as it would change Gymnasium's.
//!
//! Cost: CORE-MATH is within a few nanoseconds of glibc per call (slower for `f64` `sin`/`cos`, about as fast
//! for `exp`/`log`/`pow`), well under one percent of a training step.
//!
//! Not covered: a call whose argument is a compile-time constant may be folded by the compiler with its own math
//! library; the training path has none (the tests use `black_box` for theirs).
//!
//! The functions are also callable from Rust by name (`math::sin(x)` is `x.sin()`), for code that wants to say it.

/// What a run's `summary.json` says of how its elementary functions were computed (`numerics`): correctly
/// rounded, by CORE-MATH (Box2D's `sinf`/`cosf` aside, see the module docs). Runs of arld before this module have no such field.
pub const NUMERICS: &str = "correctly-rounded";

/// For each `name` of a group `type, (arguments): names`: CORE-MATH's correctly rounded `name` of those
/// arguments, callable from Rust as `math::name` and exported as the C symbol `__wrap_<name>`, which `build.rs`
/// (reading these groups) has the linker call in place of the C library's `name`.
macro_rules! correctly_rounded {
    ($t:ty, $args:tt: $($name:ident)+) => {$(
        correctly_rounded!(@one $t, $args, $name);
    )+};
    (@one $t:ty, ($($arg:ident),+), $name:ident) => {
        #[doc = concat!("`", stringify!($name), "`, correctly rounded (CORE-MATH `cr_", stringify!($name), "`).")]
        #[unsafe(export_name = concat!("__wrap_", stringify!($name)))]
        pub extern "C" fn $name($($arg: $t),+) -> $t {
            core_math::$name($($arg),+)
        }
    };
}

correctly_rounded!(f64, (x): sin cos tan asin acos atan sinh cosh tanh exp exp2 expm1 log log2 log10 log1p cbrt);
correctly_rounded!(f32, (x): tanf asinf acosf atanf sinhf coshf tanhf expf exp2f expm1f logf log2f log10f log1pf cbrtf);
correctly_rounded!(f64, (x, y): pow atan2 hypot);
correctly_rounded!(f32, (x, y): powf atan2f hypotf);

/// `sincos` (LLVM merges a `sin` and a `cos` of one argument into it): both results correctly rounded, so the
/// same as the two calls.
///
/// # Safety
/// `s` and `c` must be valid for writes (the C library's contract).
#[doc(hidden)]
#[unsafe(no_mangle)]
pub unsafe extern "C" fn __wrap_sincos(x: f64, s: *mut f64, c: *mut f64) {
    // SAFETY: the caller passes two writable doubles.
    unsafe {
        *s = core_math::sin(x);
        *c = core_math::cos(x);
    }
}

/// Below this magnitude glibc's AVX2/FMA and baseline builds of `sinf`, `cosf` and `sincosf` give the same
/// result for every float (see the module docs).
pub(crate) const GLIBC_F32_TRIG_AGREES_BELOW: f32 = 17.25;

// The C library's own functions, which `--wrap` leaves reachable under these names.
#[cfg(target_os = "linux")]
unsafe extern "C" {
    fn __real_sinf(x: f32) -> f32;
    fn __real_cosf(x: f32) -> f32;
}

/// glibc's `f32` sine or cosine (`glibc`) where its builds agree, else CORE-MATH's (`correctly_rounded`).
#[cfg(target_os = "linux")]
#[inline(always)]
fn box2d_trig(
    x: f32,
    glibc: unsafe extern "C" fn(f32) -> f32,
    correctly_rounded: fn(f32) -> f32,
) -> f32 {
    if x.abs() < GLIBC_F32_TRIG_AGREES_BELOW {
        // SAFETY: glibc's sinf or cosf, a pure function of one float.
        unsafe { glibc(x) }
    } else {
        correctly_rounded(x)
    }
}

/// Box2D's single-precision sine (see the module docs).
#[cfg(target_os = "linux")]
#[doc(hidden)]
#[unsafe(no_mangle)]
pub extern "C" fn __wrap_sinf(x: f32) -> f32 {
    box2d_trig(x, __real_sinf, core_math::sinf)
}

/// Box2D's single-precision cosine (see the module docs).
#[cfg(target_os = "linux")]
#[doc(hidden)]
#[unsafe(no_mangle)]
pub extern "C" fn __wrap_cosf(x: f32) -> f32 {
    box2d_trig(x, __real_cosf, core_math::cosf)
}

/// `sincosf` (the compiler merges Box2D's `sinf` and `cosf` of one angle into it): the two functions above. glibc's
/// own `sincosf` gives the same results as its `sinf` and `cosf` on every float (checked with the same scan).
///
/// # Safety
/// `s` and `c` must be valid for writes (the C library's contract).
#[cfg(target_os = "linux")]
#[doc(hidden)]
#[unsafe(no_mangle)]
pub unsafe extern "C" fn __wrap_sincosf(x: f32, s: *mut f32, c: *mut f32) {
    // SAFETY: the caller passes two writable floats.
    unsafe {
        *s = __wrap_sinf(x);
        *c = __wrap_cosf(x);
    }
}

#[cfg(test)]
mod tests {
    /// Inputs where glibc's AVX2/FMA and baseline builds of `sin` disagree in the last bit, with the correctly
    /// rounded result computed independently (mpmath at 200 bits): each glibc build misses one of them.
    const SIN_CASES: [(u64, u64); 3] = [
        (0x3FE720DC197CADC0, 0x3FE52AAA0EBE1261),
        (0x3FD4CDB93F7440C0, 0x3FD4706E2F84D299),
        (0x400C4E79C1EEE890, 0xBFD8BAC82A7C7808),
    ];

    #[test]
    fn sin_is_correctly_rounded_where_the_c_librarys_builds_disagree() {
        for (x, want) in SIN_CASES {
            // black_box: a constant argument would be folded at compile time by the compiler's own libm.
            let x = std::hint::black_box(f64::from_bits(x));
            assert_eq!(super::sin(x).to_bits(), want, "math::sin({x:e})");
            // The standard library's sin is redirected here at link time (build.rs).
            assert_eq!(
                x.sin().to_bits(),
                want,
                "f64::sin({x:e}) is not the redirected one"
            );
        }
    }

    #[test]
    fn sincos_is_the_two_correctly_rounded_functions() {
        for i in 0..1000 {
            let x = std::hint::black_box((i as f64 - 500.0) * 0.0137);
            let (s, c) = x.sin_cos();
            assert_eq!(
                (s.to_bits(), c.to_bits()),
                (super::sin(x).to_bits(), super::cos(x).to_bits())
            );
        }
    }
}
