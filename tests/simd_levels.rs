//! The same seed at every instruction-set level this CPU offers (`ARLD_SIMD` = scalar, avx2, avx512) gives
//! byte-identical evaluation curves, query logs and weights, for a bootstrapped and a noisy run.

use std::path::Path;
use std::process::Command;

use arld::nn::{QNet, SimdLevel};

mod common;
use common::ARLD;

fn train(level: SimdLevel, net: &str, out: &Path) {
    let status = Command::new(ARLD)
        .env("ARLD_SIMD", level.name())
        .args([
            "train",
            "--env",
            "CartPole-v0",
            "--method",
            "adqn",
            "--net",
            net,
        ])
        .args(["--seed", "5", "--quiet", "--set", "train_steps=2500"])
        .args(["--set", "eval_period=500", "-o"])
        .arg(out)
        .status()
        .expect("the arld binary starts");
    assert!(status.success(), "arld train failed at {}", level.name());
}

#[test]
fn every_simd_level_gives_byte_identical_runs() {
    let detected = SimdLevel::detected();
    let levels: Vec<SimdLevel> = SimdLevel::ALL
        .into_iter()
        .filter(|&level| level <= detected)
        .collect();
    eprintln!(
        "levels on this CPU: {:?}",
        levels.iter().map(|l| l.name()).collect::<Vec<_>>()
    );
    let dir = tempfile::tempdir().unwrap();
    for net in ["bootstrap", "noisy"] {
        let mut reference: Option<(Vec<u8>, Vec<u8>, Vec<f32>)> = None;
        for &level in &levels {
            let out = dir.path().join(format!("{net}-{}", level.name()));
            train(level, net, &out);
            let eval = std::fs::read(out.join("eval.csv")).unwrap();
            let queries = std::fs::read(out.join("queries.csv")).unwrap();
            // Compare the tensors, not the file: safetensors' header order is not fixed.
            let (weights, _) = QNet::load(&out.join("weights.safetensors")).unwrap();
            let params = weights.parameters().to_vec();
            assert!(eval.len() > 30, "eval.csv holds evaluations");
            match &reference {
                None => reference = Some((eval, queries, params)),
                Some((e, q, p)) => {
                    let name = level.name();
                    assert!(e == &eval, "{net}: eval.csv differs at {name}");
                    assert!(q == &queries, "{net}: queries.csv differs at {name}");
                    let same = p.len() == params.len()
                        && p.iter()
                            .zip(&params)
                            .all(|(a, b)| a.to_bits() == b.to_bits());
                    assert!(same, "{net}: weights differ at {name}");
                }
            }
        }
    }
}

#[test]
fn an_unknown_level_is_a_clear_error() {
    let output = Command::new(ARLD)
        .env("ARLD_SIMD", "sse9")
        .args(["train", "--env", "CartPole-v0", "--print-config"])
        .output()
        .expect("the arld binary starts");
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("ARLD_SIMD") && stderr.contains("sse9"),
        "{stderr}"
    );
}
