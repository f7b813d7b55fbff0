//! Fuzz target: the web expert's parser of the messages a page sends its server (see ../harness.rs).
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    harness::web(data);
});
