//! Which arld this is: its version and the git commit it was built from (`build.rs` finds the commit), as the
//! command line prints with `--version` and every run records in its `summary.json` and `failed.json`.

/// The package version (`Cargo.toml`).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The git commit the build comes from: a short hash, with `-dirty` when tracked files had changes, or
/// `unknown` when built outside a git checkout (e.g. from a source tarball).
pub const GIT_COMMIT: &str = env!("ARLD_GIT_COMMIT");

/// `VERSION (git GIT_COMMIT)`, e.g. `0.1.0 (git 282dfac1)`: what `arld --version` prints after the name.
pub const VERSION_LINE: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (git ",
    env!("ARLD_GIT_COMMIT"),
    ")"
);
