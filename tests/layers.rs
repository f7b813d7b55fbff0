//! The workspace's architecture, checked: imports only go down the layers (docs: the module list in
//! `crates/arld-core/src/lib.rs`) and no two source files depend on each other, directly or through others.
//!
//! The library is three crates, read here as one tree of modules: the core (`crates/arld-core`, whose top-level
//! modules are the lower layers), the web expert (`crates/arld-web`, the layer `web`) and the laboratory
//! (`crates/arld-lab`, the layer `lab`, the names the `arld` library gives them). Every `crate::…`,
//! `super::…`, `self::…`, `arld_core::…`, `arld_web::…` and `arld_lab::…` path in the library's code (comments
//! and `#[cfg(test)]` items left out, wherever they stand) is resolved to the source file it names. Two checks
//! follow: a path from one top-level module to another must go to a lower layer, and the graph of files must
//! have no cycle (a file's `mod` declarations are not uses; its `pub use` re-exports are). A `mod.rs` naming its
//! own children by relative paths (`pub use adam::Adam`) is not counted: that is how a folder re-exports its
//! parts, and the parts may use `super::`. Every module the core's `lib.rs` declares must have a layer.
//!
//! The library's two clients sit above every layer: the binary's command modules (`src/cli`, used from
//! `src/main.rs`; they name the library through the root package's `arld::…`, which re-exports the three
//! crates) and the Python bindings (`python/src`, which name the core by its own name, `arld_core::…`, and may
//! use the web expert but not the laboratory). They reach the library only through its public API and may use any of it; the
//! library never names them (no `crate::cli`, no `arld_python`). Within the binary, a command file
//! (`src/cli/train_cmd.rs`, ...) does not use another: what two commands share belongs in the library or in
//! `src/cli/mod.rs`. No source file pulls in another by `#[path]` or `include!`, which would pass code around
//! the module tree and this check.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The layers, bottom first. Modules of one layer may not use each other.
const LAYERS: [&[&str]; 9] = [
    &[
        "build_info",
        "errors",
        "files",
        "paper",
        "state",
        "interrupt",
        "math",
    ],
    // What a task and its actions are (uses `state` to store actions).
    &["task"],
    &["rng", "nn", "replay", "query", "dir_lock"],
    &["env", "agent"],
    &["expert"],
    &["tboard"],
    &["train"],
    // The crate arld-web.
    &["web"],
    // The crate arld-lab.
    &["lab"],
];

fn layer(module: &str) -> usize {
    LAYERS
        .iter()
        .position(|l| l.contains(&module))
        .unwrap_or_else(|| panic!("module {module} is in no layer; add it to LAYERS"))
}

/// Module path of a library source file: `src/train/run_dir.rs` -> [train, run_dir]; `mod.rs` names its folder.
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let relative = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = relative
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts
}

/// The library's code of a file: without comment lines and without the items marked `#[cfg(test)]` (a `mod
/// tests;` line, a `use` or a function, or a whole `mod tests { ... }`), wherever they stand.
fn code(text: &str) -> String {
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect();
    let mut kept = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if lines[i].trim() != "#[cfg(test)]" {
            kept.push(lines[i]);
            i += 1;
            continue;
        }
        // Skip the attribute, any further attributes, then the item: to its `;` or its closing brace.
        i += 1;
        while i < lines.len() && lines[i].trim_start().starts_with("#[") {
            i += 1;
        }
        let mut depth = 0i64;
        let mut opened = false;
        while i < lines.len() {
            let line = lines[i];
            i += 1;
            depth += braces(line);
            opened |= line.contains('{');
            if (opened && depth <= 0) || (!opened && line.trim_end().ends_with(';')) {
                break;
            }
        }
    }
    kept.join("\n")
}

/// Opening minus closing braces of a line, outside string and character literals.
fn braces(line: &str) -> i64 {
    let mut depth = 0;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' => {
                while let Some(s) = chars.next() {
                    match s {
                        '\\' => {
                            chars.next();
                        }
                        '"' => break,
                        _ => {}
                    }
                }
            }
            '\'' => {
                // A character literal ('{', '\'') or a lifetime ('a): skip a literal's closing quote.
                let rest: String = chars.clone().take(3).collect();
                if rest.starts_with('\\') {
                    chars.next();
                    chars.next();
                    chars.next();
                } else if rest.chars().nth(1) == Some('\'') {
                    chars.next();
                    chars.next();
                }
            }
            '{' => depth += 1,
            '}' => depth -= 1,
            _ => {}
        }
    }
    depth
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Every path that starts at `crate`, `super`, `self`, `arld` (the library, named from its clients) or one of the
/// library's crates (`arld_core`, `arld_web`, `arld_lab`), expanded
/// over `{…}` groups to their first segments, as (anchor, segments).
const ANCHORS: [&str; 7] = [
    "crate::",
    "super::",
    "self::",
    "arld::",
    "arld_core::",
    "arld_web::",
    "arld_lab::",
];

fn paths(code: &str) -> Vec<(String, Vec<String>)> {
    let chars: Vec<char> = code.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let at_word = i == 0 || !is_ident(chars[i - 1]);
        let anchor = ANCHORS
            .into_iter()
            .find(|a| at_word && chars[i..].iter().take(a.len()).collect::<String>() == *a);
        let Some(anchor) = anchor else {
            i += 1;
            continue;
        };
        // Back to the anchor's `::`, so that a group right after it (`arld_web::{Page, WebExpert}`) is read
        // as one.
        i += anchor.len() - 2;
        let mut segments = Vec::new();
        loop {
            let start = i;
            while i < chars.len() && is_ident(chars[i]) {
                i += 1;
            }
            if i > start {
                segments.push(chars[start..i].iter().collect::<String>());
            }
            if chars[i..].starts_with(&[':', ':']) {
                i += 2;
                if chars.get(i) == Some(&'{') {
                    // A group: each entry's first segment extends the path.
                    let close = (i..chars.len())
                        .find(|&k| chars[k] == '}')
                        .unwrap_or(chars.len());
                    let group: String = chars[i + 1..close].iter().collect();
                    for entry in group.split(',') {
                        let first: String =
                            entry.trim().chars().take_while(|&c| is_ident(c)).collect();
                        let mut s = segments.clone();
                        if !first.is_empty() && first != "self" {
                            s.push(first);
                        }
                        out.push((anchor.trim_end_matches("::").to_string(), s));
                    }
                    i = close;
                    segments.clear();
                    break;
                }
                continue;
            }
            break;
        }
        if !segments.is_empty() {
            out.push((anchor.trim_end_matches("::").to_string(), segments));
        }
    }
    out
}

/// The `.rs` files below `dir`, skipping the folders named in `skip`.
fn rust_files(dir: &Path, skip: &[&str]) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                if path
                    .file_name()
                    .is_some_and(|n| !skip.iter().any(|s| n == *s))
                {
                    stack.push(path);
                }
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// Which crate a source file belongs to, and so what its `crate::` names.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
enum Crate {
    Library,
    /// `src/main.rs` and `src/cli`: the `arld` binary.
    Binary,
    /// `python/src`: the bindings.
    Python,
}

/// A file of one of the crates: its module path within its crate (the crate root's is empty), prefixed with
/// the client's name for the clients (`cli::train_cmd`, `python`), so that no two files share a key.
struct SourceFile {
    krate: Crate,
    /// Module path within its crate: `src/train/run_dir.rs` -> [train, run_dir], `src/cli/train_cmd.rs` ->
    /// [cli, train_cmd], `src/main.rs` and `python/src/lib.rs` -> [].
    module: Vec<String>,
    path: PathBuf,
}

impl SourceFile {
    /// The file's node in the graph: the module path, with `main` / `python` in front for the clients.
    fn node(&self) -> Vec<String> {
        let client = match self.krate {
            Crate::Library => return self.module.clone(),
            Crate::Binary => "main",
            Crate::Python => "python",
        };
        std::iter::once(client.to_string())
            .chain(self.module.iter().cloned())
            .collect()
    }
}

/// The library's crates: folder, crate name, and the module its root is in the library's tree.
const LIBRARY_CRATES: [(&str, &str, &[&str]); 3] = [
    ("crates/arld-core/src", "arld_core", &[]),
    ("crates/arld-web/src", "arld_web", &["web"]),
    ("crates/arld-lab/src", "arld_lab", &["lab"]),
];

/// The library's module named by a path from the root package's `arld::…` (the binary's view): the laboratory
/// is `arld::lab`, the web expert `arld::expert::web`, the core's modules are at the top.
fn from_facade(segments: &[String]) -> Vec<String> {
    match segments {
        [expert, web, rest @ ..] if expert == "expert" && web == "web" => {
            std::iter::once("web".to_string())
                .chain(rest.iter().cloned())
                .collect()
        }
        _ => segments.to_vec(),
    }
}

/// A library file's use of `target` goes to a lower layer, or stays in its own top-level module.
fn check_layers(violations: &mut Vec<String>, file: &SourceFile, target: &[String]) {
    if file.krate != Crate::Library {
        return;
    }
    let (from, to) = (&file.module[0], &target[0]);
    if from != to && layer(to) >= layer(from) {
        violations.push(format!(
            "{} uses {} (not a lower layer)",
            file.module.join("::"),
            target.join("::")
        ));
    }
}

#[test]
fn imports_go_down_the_layers_and_no_file_depends_on_itself() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut sources = Vec::new();
    for (dir, _, prefix) in LIBRARY_CRATES {
        let src = root.join(dir);
        for path in rust_files(&src, &[]) {
            let within = if path == src.join("lib.rs") {
                // The core's root only declares the layers; the web expert's and the laboratory's are modules.
                if prefix.is_empty() {
                    continue;
                }
                vec![]
            } else {
                module_path(&src, &path)
            };
            let module: Vec<String> = prefix.iter().map(|p| p.to_string()).chain(within).collect();
            sources.push(SourceFile {
                krate: Crate::Library,
                module,
                path,
            });
        }
    }
    let src = root.join("src");
    for path in rust_files(&src, &[]) {
        let in_cli = path.starts_with(src.join("cli"));
        let krate = match path.file_name().and_then(|n| n.to_str()) {
            // The root package's library only re-exports the crates.
            Some("lib.rs") => continue,
            Some("main.rs") => Crate::Binary,
            _ if in_cli => Crate::Binary,
            _ => panic!("{} is neither the binary nor its commands", path.display()),
        };
        let module = if path == src.join("main.rs") {
            vec![]
        } else {
            module_path(&src, &path)
        };
        sources.push(SourceFile {
            krate,
            module,
            path,
        });
    }
    let python = root.join("python/src");
    for path in rust_files(&python, &[]) {
        let module = if path == python.join("lib.rs") {
            vec![]
        } else {
            module_path(&python, &path)
        };
        sources.push(SourceFile {
            krate: Crate::Python,
            module,
            path,
        });
    }
    let nodes: BTreeMap<(Crate, Vec<String>), Vec<String>> = sources
        .iter()
        .map(|f| ((f.krate, f.module.clone()), f.node()))
        .collect();
    // Every top-level module the core declares, and the two crates above it, has a layer, and the layers name
    // no module that is gone.
    let lib = std::fs::read_to_string(root.join("crates/arld-core/src/lib.rs")).unwrap();
    let mut declared: BTreeSet<String> = code(&lib)
        .lines()
        .filter_map(|l| {
            l.trim()
                .strip_prefix("pub mod ")
                .or(l.trim().strip_prefix("mod "))
        })
        .map(|l| l.trim_end_matches(';').trim().to_string())
        .collect();
    declared.extend(["web".to_string(), "lab".to_string()]);
    let layered: BTreeSet<String> = LAYERS
        .iter()
        .flat_map(|l| l.iter())
        .map(|m| m.to_string())
        .collect();
    assert_eq!(declared, layered, "the library's modules and LAYERS differ");
    for f in sources.iter().filter(|f| f.krate == Crate::Library) {
        assert!(
            layered.contains(&f.module[0]),
            "{} is in no layer; add it to LAYERS",
            f.module[0]
        );
    }
    // The longest prefix of `segments` that names a file of `krate`.
    let resolve = |krate: Crate, segments: &[String]| -> Option<Vec<String>> {
        (0..=segments.len())
            .rev()
            .map(|n| segments[..n].to_vec())
            .find(|p| nodes.contains_key(&(krate, p.clone())))
            .map(|p| nodes[&(krate, p)].clone())
    };
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    let mut violations = Vec::new();
    for file in &sources {
        let (module, node) = (&file.module, file.node());
        let shown = file.path.strip_prefix(root).unwrap().display().to_string();
        let text = code(&std::fs::read_to_string(&file.path).unwrap());
        for pulled in ["#[path", "include!("] {
            if text.contains(pulled) {
                violations.push(format!("{shown} pulls in source with {pulled}"));
            }
        }
        if file.krate == Crate::Library && text.contains("arld_python") {
            violations.push(format!("{shown} names the Python bindings"));
        }
        for (anchor, segments) in paths(&text) {
            if let Some((_, _, prefix)) = LIBRARY_CRATES.iter().find(|(_, name, _)| *name == anchor)
            {
                // One of the library's crates by name: from another crate, or from the bindings.
                let full: Vec<String> = prefix
                    .iter()
                    .map(|p| p.to_string())
                    .chain(segments)
                    .collect();
                if file.krate == Crate::Python && full[0] == "lab" {
                    violations.push(format!("{shown} uses the laboratory"));
                }
                if let Some(target) = resolve(Crate::Library, &full) {
                    check_layers(&mut violations, file, &target);
                    edges.entry(node.clone()).or_default().insert(target);
                }
                continue;
            }
            if anchor == "arld" {
                // The library as the binary sees it: the root package's re-exports. The library's crates and the
                // bindings name the crates they use by their own names.
                let full = match file.krate {
                    Crate::Binary => from_facade(&segments),
                    Crate::Library | Crate::Python => {
                        violations.push(format!("{shown} names the library as arld::"));
                        continue;
                    }
                };
                if let Some(target) = resolve(Crate::Library, &full) {
                    edges.entry(node.clone()).or_default().insert(target);
                }
                continue;
            }
            let mut full: Vec<String> = match anchor.as_str() {
                // The root of the file's crate: its first module in the library's tree (the core's is empty).
                "crate" if file.krate == Crate::Library => LIBRARY_CRATES
                    .iter()
                    .map(|(_, _, prefix)| prefix)
                    .find(|prefix| {
                        !prefix.is_empty() && module.first().is_some_and(|m| m == prefix[0])
                    })
                    .map(|prefix| prefix.iter().map(|p| p.to_string()).collect())
                    .unwrap_or_default(),
                "crate" => vec![],
                // `super` of a file is its folder's module; of a folder's mod.rs (whose module is the
                // folder), the folder's parent.
                "super" => module[..module.len().saturating_sub(1)].to_vec(),
                _ => module.clone(), // self
            };
            full.extend(segments);
            if file.krate == Crate::Library && full.first().is_some_and(|m| m == "cli") {
                violations.push(format!(
                    "{shown} uses the binary's cli::{}",
                    full[1..].join("::")
                ));
                continue;
            }
            let Some(target) = resolve(file.krate, &full) else {
                continue;
            };
            if target == node {
                continue;
            }
            match file.krate {
                Crate::Library => check_layers(&mut violations, file, &target),
                // Command files (main::cli::X) do not use each other; cli/mod.rs and main.rs are shared.
                Crate::Binary => {
                    if node.len() > 2 && target.len() > 2 && node[2] != target[2] {
                        violations.push(format!(
                            "{} uses {} (command files do not use each other)",
                            node[1..].join("::"),
                            target[1..].join("::")
                        ));
                    }
                }
                Crate::Python => {}
            }
            edges.entry(node.clone()).or_default().insert(target);
        }
    }
    assert!(
        violations.is_empty(),
        "imports that go up or sideways:\n{}",
        violations.join("\n")
    );

    // Cycles: depth-first search over files.
    fn visit(
        node: &Vec<String>,
        edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        state: &mut BTreeMap<Vec<String>, u8>,
        path: &mut Vec<Vec<String>>,
    ) -> Option<Vec<String>> {
        match state.get(node) {
            Some(2) => return None,
            Some(1) => {
                let start = path.iter().position(|p| p == node).unwrap();
                let mut cycle: Vec<String> = path[start..].iter().map(|p| p.join("::")).collect();
                cycle.push(node.join("::"));
                return Some(cycle);
            }
            _ => {}
        }
        state.insert(node.clone(), 1);
        path.push(node.clone());
        for next in edges.get(node).into_iter().flatten() {
            if let Some(cycle) = visit(next, edges, state, path) {
                return Some(cycle);
            }
        }
        path.pop();
        state.insert(node.clone(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for module in nodes.values() {
        if let Some(cycle) = visit(module, &edges, &mut state, &mut Vec::new()) {
            panic!("import cycle: {}", cycle.join(" -> "));
        }
    }
    // The check sees the crate: the training loop uses the agent, the report uses the sweep, and code after
    // a `#[cfg(test)]` item is read (Adam's use of the SIMD dispatch follows a test-only import).
    let path = |p: &[&str]| p.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    assert!(edges[&path(&["nn", "adam"])].contains(&path(&["nn", "simd"])));
    assert!(edges[&vec!["train".to_string()]].contains(&vec!["agent".to_string()]));
    assert!(
        edges[&vec!["lab".to_string(), "report".to_string()]]
            .contains(&vec!["lab".to_string(), "sweep".to_string()])
    );
    // ... across the crates: the web expert uses the core's experts, the laboratory the web expert ...
    assert!(edges[&path(&["web"])].contains(&path(&["expert"])));
    assert!(edges[&path(&["lab"])].contains(&path(&["web"])));
    // ... and its clients: the train command uses the training loop and the web expert's options, the bindings
    // the environments and the web expert.
    assert!(edges[&path(&["main", "cli", "train_cmd"])].contains(&path(&["train"])));
    assert!(edges[&path(&["python", "actions"])].contains(&path(&["env"])));
    assert!(edges[&path(&["python", "web"])].contains(&path(&["web"])));
}
