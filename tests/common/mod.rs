//! What the integration tests share: the `arld` binary they run, and reading what it printed. Each test file
//! that needs it says `mod common;`; not every file uses every item, hence the `dead_code` allowance.
#![allow(dead_code)]

use std::process::{Command, Output};

/// The `arld` binary Cargo built for these tests.
pub const ARLD: &str = env!("CARGO_BIN_EXE_arld");

/// Runs `arld` with `args` and waits for it.
pub fn arld(args: &[&str]) -> Output {
    Command::new(ARLD)
        .args(args)
        .output()
        .expect("the arld binary runs")
}

/// What a finished command printed on standard output.
pub fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// What a finished command printed on standard error.
pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}
