//! Fuzz target: arld's readers of a run directory's summary.json, config.toml, eval.csv and queries.csv, as `arld report` reads them (see ../harness.rs).
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    harness::run_dir(data);
});
