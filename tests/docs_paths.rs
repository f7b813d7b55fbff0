//! Every repository path the documents cite exists: the README, `docs/*.md` and every Markdown file under
//! `results/` are scanned for paths that start at one of the repository's top-level folders (`crates/...`,
//! `src/...`, `tests/...`, ...), and each must name a file or folder of the checkout, or something the checkout's
//! `.gitignore` says is made locally (a virtual environment, `node_modules`). A file that moved (as
//! `src/experiment/*.rs` did, under `crates/`) fails here, naming the document and line that cite it.

use std::path::{Path, PathBuf};

/// The top-level folders a cited path starts at.
const ROOTS: [&str; 13] = [
    "src", "crates", "tests", "docs", "results", "experts", "scripts", "bench", "benches",
    "examples", "python", "fuzz", "assets",
];

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Characters a cited path is made of (a path ends at the first other one: a space, a backtick, a brace, a glob).
fn in_path(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '/' | '-')
}

/// The repository paths cited on one line: tokens that start with `ROOT/` where no path character precedes them
/// (so `../results/x` and `runs/results/x` are not read as citations), without trailing punctuation.
fn cited(line: &str) -> Vec<String> {
    let mut paths = Vec::new();
    for (start, _) in line.char_indices() {
        if line[..start].chars().next_back().is_some_and(in_path) {
            continue;
        }
        let rest = &line[start..];
        if !ROOTS.iter().any(|r| rest.starts_with(&format!("{r}/"))) {
            continue;
        }
        let token: String = rest.chars().take_while(|&c| in_path(c)).collect();
        paths.push(token.trim_end_matches(['.', ',', '-']).to_string());
    }
    paths
}

/// The documents scanned: README.md, docs/*.md, results/**/*.md.
fn documents() -> Vec<PathBuf> {
    fn markdown_under(dir: &Path, recurse: bool, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() && recurse {
                markdown_under(&path, recurse, out);
            } else if path.extension().is_some_and(|e| e == "md") {
                out.push(path);
            }
        }
    }
    let mut docs = vec![root().join("README.md")];
    markdown_under(&root().join("docs"), false, &mut docs);
    markdown_under(&root().join("results"), true, &mut docs);
    docs.sort();
    docs
}

/// The checkout's `.gitignore` entries anchored at its root (`/bench/.venv`), as paths.
fn ignored() -> Vec<String> {
    std::fs::read_to_string(root().join(".gitignore"))
        .unwrap()
        .lines()
        .filter_map(|l| l.trim().strip_prefix('/'))
        .map(|l| l.trim_end_matches('/').to_string())
        .collect()
}

#[test]
fn the_scanner_reads_cited_paths_and_nothing_else() {
    assert_eq!(
        cited("see `crates/arld-lab/src/quote.rs`, and src/experiment/{quote,pack}.rs."),
        ["crates/arld-lab/src/quote.rs", "src/experiment/"]
    );
    assert_eq!(
        cited("[x](../results/effort.md) runs/results/a tests/data/*.jsonl"),
        ["tests/data/"]
    );
    assert!(cited("the results/ folder").iter().all(|p| p == "results/"));
}

#[test]
fn every_path_the_documents_cite_exists() {
    let ignored = ignored();
    let mut missing = Vec::new();
    let mut checked = 0;
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        for (number, line) in text.lines().enumerate() {
            for path in cited(line) {
                checked += 1;
                let made_locally = ignored.iter().any(|i| path.starts_with(i.as_str()));
                if !root().join(&path).exists() && !made_locally {
                    let doc = doc
                        .strip_prefix(root())
                        .unwrap_or(&doc)
                        .display()
                        .to_string();
                    missing.push(format!("{doc}:{}: {path}", number + 1));
                }
            }
        }
    }
    assert!(
        checked > 100,
        "only {checked} cited paths found: is the scanner broken?"
    );
    assert!(
        missing.is_empty(),
        "paths cited in the documents that do not exist:\n{}",
        missing.join("\n")
    );
}
