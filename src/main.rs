//! The `arld` command-line tool: argument parsing and wiring only; the work is done by the library.
fn main() {}
