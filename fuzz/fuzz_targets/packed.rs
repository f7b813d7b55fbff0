//! Fuzz target: arld's readers of a packed task directory's tables and layout.json, as `arld runs unpack` and `arld report` read them (see ../harness.rs).
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    harness::packed(data);
});
