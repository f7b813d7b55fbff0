//! The build's native parts: Box2D compiled with the system's C++ compiler, and the link-time redirection of the
//! C library's elementary functions to `src/math.rs` (see that module's docs).
//!
//! Box2D 2.3.1 comes with the `wrapped2d` crate, whose own build script would run CMake. `.cargo/config.toml`
//! sets `BOX2D_LIB_DIR` to `native/box2d-stub/`, an empty archive, so that script only compiles its C++
//! front end; this script compiles Box2D's sources from wrapped2d's package with the `cc` crate (`-O3 -DNDEBUG`,
//! what CMake's Release build used) and hands the archive to the linker after every Rust library, where the
//! front end's references to Box2D are resolved. A C++ compiler is all it needs.
//!
//! For every `__wrap_<name>` that `src/math.rs` defines (written out or by its macro), the linker gets
//! `--wrap=<name>` (every reference to `<name>`, from Rust, the standard library or the bundled Box2D, goes to
//! `__wrap_<name>`) and `--undefined=__wrap_<name>` (so the definition is taken from this crate's library whatever
//! the link order).
//! Every package of the workspace that links a program runs this same script (the command line, the web expert's and
//! the laboratory's tests, the Python extension, the fuzz targets): each finds `crates/arld-core/src/math.rs`, and
//! reuses the Box2D archive that arld-core's own run compiled (`links = "arld_box2d"`).
//!
//! It also records the git commit the build comes from as `ARLD_GIT_COMMIT` (read by `src/build_info.rs`): the
//! short hash of `HEAD`, with `-dirty` when tracked files differ from it; `unknown` outside a git checkout (a
//! source tarball) or without git. A build never fails for want of git. The variable `ARLD_GIT_COMMIT`, when
//! set, is taken as is (for builds from a tarball that know their commit). The script runs again when `HEAD`,
//! the branch it points to, the index or the sources change, so the commit is never stale.

use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    // The core package (`crates/arld-core`): this package, or the core of the workspace this package is in (the
    // command line at the root, the web expert and the laboratory beside it, the Python extension and the fuzz
    // targets one folder down).
    let manifest = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let core = [
        ".",
        "crates/arld-core",
        "../arld-core",
        "../crates/arld-core",
    ]
    .iter()
    .map(|place| Path::new(&manifest).join(place))
    .find(|dir| dir.join("src/math.rs").is_file() && dir.join("build.rs").is_file())
    .expect("build.rs finds arld-core's src/math.rs");
    let math = core.join("src/math.rs");
    println!("cargo:rerun-if-changed={}", math.display());
    println!("cargo:rerun-if-changed={}", core.join("build.rs").display());
    // The repository: the workspace's Cargo.lock and the git checkout.
    let root = core
        .parent()
        .and_then(Path::parent)
        .expect("arld-core is in the workspace's crates/ folder");
    println!("cargo:rustc-env=ARLD_GIT_COMMIT={}", git_commit(root));
    let box2d = compile_box2d(root);
    // For the build scripts of the packages that use arld-core (`DEP_ARLD_BOX2D_ARCHIVE`).
    if std::env::var_os("CARGO_MANIFEST_LINKS").is_some() {
        println!("cargo:archive={}", box2d.display());
    }
    let target_os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if target_os != "linux" {
        // `--wrap` is a GNU ld / lld option; elsewhere the platform's C library computes these functions.
        return;
    }
    // After every library on the command line (user link arguments come last), so the archive resolves the
    // references of wrapped2d's front end.
    println!("cargo:rustc-link-arg={}", box2d.display());
    println!("cargo:rustc-link-arg=-lstdc++");
    let source = std::fs::read_to_string(&math).expect("build.rs reads src/math.rs");
    for name in wrapped_names(&source) {
        println!("cargo:rustc-link-arg=-Wl,--wrap={name}");
        println!("cargo:rustc-link-arg=-Wl,--undefined=__wrap_{name}");
    }
}

/// The commit of the checkout at `root` (`282dfac1`, `282dfac1-dirty`), or `unknown`; prints the
/// `rerun-if-changed` lines that keep it current.
fn git_commit(root: &Path) -> String {
    println!("cargo:rerun-if-env-changed=ARLD_GIT_COMMIT");
    if let Ok(given) = std::env::var("ARLD_GIT_COMMIT")
        && !given.trim().is_empty()
    {
        return given.trim().to_string();
    }
    // Git's answer, or `None` when git is missing, fails, or `root` is no checkout.
    let git = |args: &[&str]| -> Option<String> {
        let out = Command::new("git")
            .arg("-C")
            .arg(root)
            .args(args)
            // `git status` must not rewrite the index: that would run this script again on the next build.
            .env("GIT_OPTIONAL_LOCKS", "0")
            .output()
            .ok()?;
        out.status
            .success()
            .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
    };
    // Only a checkout whose top is this package's root (not a tarball unpacked inside another repository).
    let top = git(&["rev-parse", "--show-toplevel"]).map(PathBuf::from);
    let same = |a: &Path, b: &Path| a.canonicalize().ok() == b.canonicalize().ok();
    if !top.is_some_and(|top| same(&top, root)) {
        return "unknown".to_string();
    }
    let Some(hash) = git(&["rev-parse", "--short=8", "HEAD"]).filter(|h| !h.is_empty()) else {
        return "unknown".to_string();
    };
    // HEAD, the branch it names (loose or packed), the index (commits, `git add`), and the tracked sources.
    let mut watched = vec![
        "HEAD".to_string(),
        "packed-refs".to_string(),
        "index".to_string(),
    ];
    if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"]) {
        watched.push(branch);
    }
    for name in watched {
        // Relative to `root` where git gives a relative path (`-C root`).
        if let Some(path) = git(&["rev-parse", "--git-path", &name]).map(|p| root.join(p))
            && path.exists()
        {
            println!("cargo:rerun-if-changed={}", path.display());
        }
    }
    for dir in ["src", "crates", "python/src", "Cargo.toml"] {
        if root.join(dir).exists() {
            println!("cargo:rerun-if-changed={}", root.join(dir).display());
        }
    }
    let dirty =
        git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
    if dirty { format!("{hash}-dirty") } else { hash }
}

/// Compiles Box2D's sources from the `wrapped2d` package into `OUT_DIR/libarld_box2d.a`; returns its path. The
/// archive of an earlier run of this script is kept when it was compiled from the same sources the same way
/// (the script runs again on every commit, and Box2D's sources do not change with arld's).
fn compile_box2d(root: &Path) -> PathBuf {
    // A package that uses arld-core links the archive that arld-core's run of this script compiled (`links`).
    println!("cargo:rerun-if-env-changed=DEP_ARLD_BOX2D_ARCHIVE");
    if let Some(archive) = std::env::var_os("DEP_ARLD_BOX2D_ARCHIVE").map(PathBuf::from)
        && archive.is_file()
    {
        return archive;
    }
    let out = std::env::var("OUT_DIR").expect("cargo sets OUT_DIR");
    let archive = Path::new(&out).join("libarld_box2d.a");
    let stamp_path = Path::new(&out).join("arld_box2d.stamp");
    let wrapped2d = wrapped2d_dir(root);
    let stamp = format!("{}\n-O3 -DNDEBUG v1\n", wrapped2d.display());
    if archive.is_file() && std::fs::read_to_string(&stamp_path).is_ok_and(|s| s == stamp) {
        return archive;
    }
    let root = wrapped2d.join("Box2D/Box2D");
    let mut sources = Vec::new();
    collect_cpp(&root.join("Box2D"), &mut sources);
    sources.sort();
    assert!(
        !sources.is_empty(),
        "no Box2D sources under {} (is the wrapped2d package complete?)",
        root.display()
    );
    cc::Build::new()
        .cpp(true)
        .include(&root)
        .files(&sources)
        .opt_level(3)
        .define("NDEBUG", None)
        .warnings(false)
        .cargo_metadata(false)
        .compile("arld_box2d");
    std::fs::write(&stamp_path, stamp).expect("build.rs writes its stamp into OUT_DIR");
    archive
}

fn collect_cpp(dir: &Path, into: &mut Vec<PathBuf>) {
    let entries =
        std::fs::read_dir(dir).unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()));
    for entry in entries {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            collect_cpp(&path, into);
        } else if path.extension().is_some_and(|ext| ext == "cpp") {
            into.push(path);
        }
    }
}

/// Where Cargo unpacked the `wrapped2d` package this build uses. In this order:
/// 1. `ARLD_BOX2D_SRC`, when set (a directory holding wrapped2d's package);
/// 2. Cargo's registry (`$CARGO_HOME/registry/src/*/wrapped2d-<version>`), at the version `Cargo.lock` pins: Cargo
///    downloads and unpacks every package a build compiles before it runs any build script;
/// 3. `cargo metadata`, for vendored or git sources. It is asked last because it resolves the whole workspace,
///    dev-dependencies included, which a plain `cargo build` never downloads: on a machine with an empty registry
///    `--offline` would fail there, so it runs online.
fn wrapped2d_dir(root: &Path) -> PathBuf {
    println!("cargo:rerun-if-env-changed=ARLD_BOX2D_SRC");
    if let Some(given) = std::env::var_os("ARLD_BOX2D_SRC").filter(|v| !v.is_empty()) {
        let dir = PathBuf::from(given);
        assert!(
            dir.join("Box2D/Box2D/Box2D").is_dir(),
            "ARLD_BOX2D_SRC={} holds no Box2D/Box2D/Box2D folder (it should name wrapped2d's package)",
            dir.display()
        );
        return dir;
    }
    if let Some(dir) = locked_version(root).and_then(|version| registry_dir(&version)) {
        return dir;
    }
    metadata_dir()
}

/// The version of `wrapped2d` that the workspace's `Cargo.lock` pins, if there is a lock file naming it.
fn locked_version(root: &Path) -> Option<String> {
    let lock = std::fs::read_to_string(root.join("Cargo.lock")).ok()?;
    let mut lines = lock.lines();
    while let Some(line) = lines.next() {
        if line.trim() == "name = \"wrapped2d\"" {
            let version = lines.next()?.trim().strip_prefix("version = ")?;
            return Some(version.trim_matches('"').to_string());
        }
    }
    None
}

/// `wrapped2d-<version>` in Cargo's registry sources, if it is unpacked there.
fn registry_dir(version: &str) -> Option<PathBuf> {
    let home = std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cargo")))?;
    let mut found: Vec<PathBuf> = std::fs::read_dir(home.join("registry/src"))
        .ok()?
        .filter_map(|entry| entry.ok())
        .map(|entry| entry.path().join(format!("wrapped2d-{version}")))
        .filter(|dir| dir.join("Box2D/Box2D/Box2D").is_dir())
        .collect();
    found.sort();
    found.into_iter().next()
}

/// Where `cargo metadata` says the `wrapped2d` package is (registry, vendored or git).
fn metadata_dir() -> PathBuf {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let manifest = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let out = Command::new(&cargo)
        .args(["metadata", "--format-version", "1"])
        .current_dir(&manifest)
        .output()
        .unwrap_or_else(|e| panic!("cannot run `{cargo} metadata` to find Box2D's sources: {e}"));
    assert!(
        out.status.success(),
        "`cargo metadata` failed while looking for Box2D's sources (set ARLD_BOX2D_SRC to wrapped2d's package \
         to skip it): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("`cargo metadata` prints JSON");
    let packages = meta["packages"]
        .as_array()
        .expect("`cargo metadata` lists packages");
    let wrapped2d = packages
        .iter()
        .find(|p| p["name"] == "wrapped2d")
        .expect("the wrapped2d package is among the dependencies");
    let path = wrapped2d["manifest_path"]
        .as_str()
        .expect("a package has a manifest path");
    Path::new(path)
        .parent()
        .expect("a manifest has a directory")
        .to_path_buf()
}

/// The `<name>` of every `fn __wrap_<name>` in `source` and of every name a `correctly_rounded!` group defines.
fn wrapped_names(source: &str) -> Vec<String> {
    let ident = |rest: &str| {
        rest.chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect::<String>()
    };
    // The functions written out, `fn __wrap_<name>`.
    let mut names: Vec<String> = source.split("fn __wrap_").skip(1).map(ident).collect();
    // The groups of the `correctly_rounded!` macro, one a line: `correctly_rounded!(type, (arguments): names);`.
    for line in source.lines() {
        if let Some(group) = line.trim().strip_prefix("correctly_rounded!(")
            && let Some((_, list)) = group.split_once("):")
        {
            names.extend(list.trim_end_matches(");").split_whitespace().map(ident));
        }
    }
    names.retain(|name| !name.is_empty());
    names.sort();
    names.dedup();
    names
}
