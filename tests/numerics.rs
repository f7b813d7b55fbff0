//! The same numbers on any x86-64 CPU, beyond the network's arithmetic (`tests/simd_levels.rs`): the elementary
//! functions (`sin`, `exp`, `pow`, ...) of the environments, the replay and Box2D are arld's correctly rounded
//! ones (`src/math.rs`), never the C library's CPU-dependent builds.
//!
//! - The `arld` executable imports none of the functions that the C math library (`libm.so.6`) exports, except
//!   the exact ones (`sqrt`, `floor`, `fma`, ...), which have one correct result by definition, and Box2D's
//!   `sinf`/`cosf`/`sincosf`, kept for Gymnasium conformance (`src/math.rs` says why that is safe).
//! - A CPU without AVX2 and FMA, simulated on this one (glibc's `GLIBC_TUNABLES` switches its AVX2/FMA builds of
//!   the math functions off, and `ARLD_SIMD=scalar` the network's vector paths), trains byte-identical runs on
//!   Acrobot-v1 (`sin`/`cos` millions of times) and LunarLander-v2 (Box2D's `sinf`/`cosf`, noisy network).
//!   Before `src/math.rs`, Acrobot-v1 diverged here within 40k steps.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::ARLD;

/// glibc's switch for its AVX2/FMA function builds (names of glibc 2.33 on, and the older `_Usable` ones).
const NO_AVX2_FMA: &str = "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX2_Usable,-FMA_Usable";

/// Functions of the C math library whose result is exact (one correctly rounded answer by definition), or that
/// compute no value: importing them is harmless.
const EXACT: &[&str] = &[
    "sqrt",
    "fabs",
    "floor",
    "ceil",
    "trunc",
    "round",
    "roundeven",
    "rint",
    "nearbyint",
    "lrint",
    "llrint",
    "lround",
    "llround",
    "fmod",
    "remainder",
    "remquo",
    "ldexp",
    "scalbn",
    "scalbln",
    "frexp",
    "modf",
    "copysign",
    "fmax",
    "fmin",
    "fmaximum",
    "fminimum",
    "fdim",
    "fma",
    "nextafter",
    "nexttoward",
    "nextup",
    "nextdown",
    "ilogb",
    "logb",
    "nan",
    "signgam",
    "finite",
    "isinf",
    "isnan",
];

/// The C library's functions arld keeps on purpose (see `src/math.rs`).
const KEPT: &[&str] = &["sinf", "cosf", "sincosf"];

fn is_exact(symbol: &str) -> bool {
    let base = symbol.strip_prefix("__").unwrap_or(symbol);
    let base = base.strip_suffix("_finite").unwrap_or(base);
    base.starts_with("fe")
        || EXACT.iter().any(|e| {
            base == *e
                || base
                    .strip_prefix(e)
                    .is_some_and(|s| ["f", "l"].contains(&s))
        })
}

fn nm(args: &[&str], file: &Path) -> String {
    let out = Command::new("nm")
        .args(args)
        .arg(file)
        .output()
        .expect("`nm` (GNU binutils) runs; it comes with the C toolchain that builds Box2D");
    assert!(out.status.success(), "nm {file:?} failed");
    String::from_utf8(out.stdout).unwrap()
}

/// The C math library this test process loaded (the Rust standard library links it).
fn loaded_libm() -> PathBuf {
    let maps = std::fs::read_to_string("/proc/self/maps").expect("/proc/self/maps is readable");
    maps.lines()
        .filter_map(|line| line.split_whitespace().nth(5))
        .find(|path| {
            Path::new(path)
                .file_name()
                .is_some_and(|f| f.to_string_lossy().starts_with("libm.so"))
        })
        .map(PathBuf::from)
        .expect("this process has libm.so loaded")
}

#[test]
fn the_executable_takes_no_elementary_function_from_the_c_library() {
    let libm = loaded_libm();
    let exported: std::collections::BTreeSet<String> = nm(&["-D", "--defined-only"], &libm)
        .lines()
        .filter_map(|l| l.split_whitespace().nth(2))
        .map(|s| s.split('@').next().unwrap().to_string())
        .collect();
    assert!(
        exported.contains("sin") && exported.contains("powf"),
        "{libm:?} does not look like the C math library"
    );
    let binary = Path::new(ARLD);
    let imported: Vec<String> = nm(&["-D", "--undefined-only"], binary)
        .lines()
        .filter_map(|l| l.split_whitespace().last())
        .map(|s| s.split('@').next().unwrap().to_string())
        .filter(|s| exported.contains(s) && !is_exact(s) && !KEPT.contains(&s.as_str()))
        .collect();
    assert!(
        imported.is_empty(),
        "arld takes these from the C library, whose results depend on the CPU: {imported:?}; \
         add them to src/math.rs"
    );
}

/// One short training run; returns the bytes that must not depend on the CPU.
fn run(env: &str, net: &str, steps: u32, baseline_cpu: bool, out: &Path) -> Vec<(String, Vec<u8>)> {
    let mut cmd = Command::new(ARLD);
    if baseline_cpu {
        cmd.env("GLIBC_TUNABLES", NO_AVX2_FMA)
            .env("ARLD_SIMD", "scalar");
    } else {
        cmd.env_remove("GLIBC_TUNABLES").env_remove("ARLD_SIMD");
    }
    let status = cmd
        .args([
            "train", "--env", env, "--method", "adqn", "--net", net, "--seed", "3", "--quiet",
        ])
        .args([
            "--set",
            &format!("train_steps={steps}"),
            "--set",
            "eval_period=2000",
            "-o",
        ])
        .arg(out)
        .status()
        .expect("the arld binary starts");
    assert!(
        status.success(),
        "arld train {env} failed (baseline CPU: {baseline_cpu})"
    );
    let mut files = Vec::new();
    for name in ["eval.csv", "episodes.csv", "queries.csv"] {
        files.push((name.to_string(), std::fs::read(out.join(name)).unwrap()));
    }
    // The tensors, not the file: safetensors' header order is not fixed.
    let (net, _) = arld::nn::QNet::load(&out.join("weights.safetensors")).unwrap();
    let bytes = net
        .parameters()
        .iter()
        .flat_map(|p| p.to_le_bytes())
        .collect();
    files.push(("weights".to_string(), bytes));
    files
}

#[test]
fn a_cpu_without_avx2_and_fma_trains_byte_identical_runs() {
    let dir = tempfile::tempdir().unwrap();
    for (env, net, steps) in [
        ("Acrobot-v1", "bootstrap", 30_000),
        ("LunarLander-v2", "noisy", 12_000),
    ] {
        let here = run(
            env,
            net,
            steps,
            false,
            &dir.path().join(format!("{env}-here")),
        );
        let baseline = run(
            env,
            net,
            steps,
            true,
            &dir.path().join(format!("{env}-baseline")),
        );
        assert!(here[1].1.len() > 100, "{env}: episodes.csv holds episodes");
        for ((name, a), (_, b)) in here.iter().zip(&baseline) {
            assert!(a == b, "{env}: {name} differs on a CPU without AVX2/FMA");
        }
    }
}

/// Guards the test above against a switch that does nothing: on a CPU with FMA, glibc's own `sin` (here Python's
/// `math.sin`, which calls it) gives another last bit for this input once its FMA build is switched off.
#[test]
fn the_switch_really_changes_the_c_librarys_sin() {
    if !std::arch::is_x86_feature_detected!("fma") || !std::arch::is_x86_feature_detected!("avx2") {
        eprintln!("this CPU has no AVX2/FMA: glibc runs its baseline functions anyway");
        return;
    }
    let sin_hex = |tunables: Option<&str>| {
        let mut cmd = Command::new("python3");
        cmd.args([
            "-c",
            "import math; print(math.sin(float.fromhex('0x1.4cdb93f7440c0p-2')).hex())",
        ]);
        match tunables {
            Some(t) => cmd.env("GLIBC_TUNABLES", t),
            None => cmd.env_remove("GLIBC_TUNABLES"),
        };
        let out = cmd.output().expect(
            "python3 runs (it calls glibc's sin directly; `scripts/test --setup` installs it)",
        );
        assert!(out.status.success());
        String::from_utf8(out.stdout).unwrap().trim().to_string()
    };
    let default = sin_hex(None);
    let baseline = sin_hex(Some(NO_AVX2_FMA));
    assert_ne!(
        default, baseline,
        "GLIBC_TUNABLES={NO_AVX2_FMA} did not switch glibc's FMA build off, so the CPU comparison proves nothing"
    );
    // arld's own sin is the correctly rounded value (mpmath at 200 bits: 0x1.4706e2f84d299p-2).
    assert_eq!(
        arld::math::sin(f64::from_bits(0x3FD4CDB93F7440C0)).to_bits(),
        0x3FD4706E2F84D299
    );
}
