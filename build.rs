//! Link-time redirection of the C library's elementary functions to `src/math.rs` (see that module's docs).
//!
//! For every `extern "C" fn __wrap_<name>` defined in `src/math.rs`, the linker gets `--wrap=<name>` (every
//! reference to `<name>`, from Rust, the standard library or the bundled Box2D, goes to `__wrap_<name>`) and
//! `--undefined=__wrap_<name>` (so the definition is taken from this crate's library whatever the link order).
//! The Python extension (`python/Cargo.toml`) runs this same script, so both find `src/math.rs` next to it.

use std::path::Path;

fn main() {
    // `src/math.rs` of this package, or of its parent for the Python extension (`python/`).
    let manifest = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let math = [".", ".."]
        .iter()
        .map(|up| Path::new(&manifest).join(up).join("src/math.rs"))
        .find(|path| path.is_file())
        .expect("build.rs finds arld's src/math.rs");
    println!("cargo:rerun-if-changed={}", math.display());
    println!("cargo:rerun-if-changed=build.rs");
    let target_os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if target_os != "linux" {
        // `--wrap` is a GNU ld / lld option; elsewhere the platform's C library computes these functions.
        return;
    }
    let source = std::fs::read_to_string(&math).expect("build.rs reads src/math.rs");
    for name in wrapped_names(&source) {
        println!("cargo:rustc-link-arg=-Wl,--wrap={name}");
        println!("cargo:rustc-link-arg=-Wl,--undefined=__wrap_{name}");
    }
}

/// The `<name>` of every `fn __wrap_<name>` in `source`, also those a macro defines (`/ __wrap_<name> =`).
fn wrapped_names(source: &str) -> Vec<String> {
    let mut names: Vec<String> = source
        .split("__wrap_")
        .skip(1)
        .map(|rest| {
            rest.chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect::<String>()
        })
        .filter(|name| !name.is_empty() && name != "name")
        .collect();
    names.sort();
    names.dedup();
    names
}
