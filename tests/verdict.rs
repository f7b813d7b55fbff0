//! The committed verdict tables regenerate from the committed per-run data: one cell of
//! `results/readings.csv` recomputed directly from `results/evaluations.csv` with code independent of the
//! library's statistics, and the whole tables rebuilt by `arld report --from-evaluations`.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

fn results() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/results"))
}

/// Per seed, the (step, mean) curve of one configuration, straight from the CSV text.
fn curves(env: &str, method: &str, net: &str) -> BTreeMap<u64, Vec<(u64, f64)>> {
    let text = std::fs::read_to_string(results().join("evaluations.csv")).expect("evaluations.csv");
    let mut out: BTreeMap<u64, Vec<(u64, f64)>> = BTreeMap::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f[0] == env && f[1] == method && f[2] == net && f[3] == "default" {
            out.entry(f[4].parse().unwrap())
                .or_default()
                .push((f[5].parse().unwrap(), f[6].parse().unwrap()));
        }
    }
    out
}

fn middle(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

fn committed_row(env: &str, method: &str, net: &str) -> BTreeMap<String, String> {
    let text = std::fs::read_to_string(results().join("readings.csv")).expect("readings.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let row = lines
        .find(|l| l.starts_with(&format!("{env},{method},{net},")))
        .expect("the cell is in readings.csv");
    header
        .iter()
        .map(|h| h.to_string())
        .zip(row.split(',').map(str::to_string))
        .collect()
}

#[test]
fn acrobot_gdqn_cell_recomputed_from_the_raw_evaluations() {
    // GDQN-B on Acrobot: many seeds hit -100 at the first test and then collapse, so the readings differ.
    let (target, train_steps, k) = (-100.0, 200_000u64, 3usize);
    let curves = curves("Acrobot-v1", "gdqn", "bootstrap");
    assert_eq!(curves.len(), 20);
    let mut first = Vec::new();
    let mut held = Vec::new();
    for curve in curves.values() {
        let hit = curve
            .iter()
            .find(|p| p.1 >= target)
            .map_or(train_steps, |p| p.0);
        first.push(hit as f64);
        let mut sustained = train_steps;
        for i in 0..curve.len() {
            let end = (i + k).min(curve.len() - 1);
            if (i..=end).all(|j| curve[j].1 >= target) {
                sustained = curve[i].0;
                break;
            }
        }
        held.push(sustained as f64);
    }
    let row = committed_row("Acrobot-v1", "gdqn", "bootstrap");
    assert_eq!(row["seeds"], "20");
    assert_eq!(
        row["first_hit_median"].parse::<f64>().unwrap(),
        middle(first)
    );
    assert_eq!(
        row["sustained_median"].parse::<f64>().unwrap(),
        middle(held)
    );
}

#[test]
fn committed_verdict_tables_regenerate_byte_identically() {
    let out = tempfile::tempdir().unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_arld"))
        .args(["report", "--from-evaluations", "-o"])
        .arg(out.path())
        .arg(results().join("evaluations.csv"))
        .output()
        .expect("arld runs");
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    for name in ["readings.md", "readings.csv", "claims.md", "claims.csv"] {
        let fresh = std::fs::read(out.path().join(name)).unwrap();
        let committed = std::fs::read(results().join(name)).unwrap();
        assert!(
            fresh == committed,
            "results/{name} does not match a fresh computation"
        );
    }
}
