//! Documents that quote the report. A file `NAME.in.md` in the report's output directory is written out as
//! `NAME.md` with every quote `{{FILE|SECTION|ROW|COLUMN ...}}` replaced by a cell of a table the report has
//! just written, so that a hand-written analysis (results/VERDICT.md) never repeats a number by hand: when the
//! runs change, its numbers change with them.
//!
//! A quote names:
//! - `FILE`: a markdown file of the output directory (`readings.md`, `ablations.md`, `claims.md`, ...);
//! - `SECTION`: the text of the heading the table stands under (`Acrobot-v1`), empty for a table above every
//!   heading;
//! - `ROW`: the row's first cell, whole, or its beginning followed by `...`; `a;b` names a row by its first two
//!   cells (report.md's "All configurations": `LunarLander-v2;DQfD;bootstrap;expert-weak`);
//! - `COLUMN`: the header of the column; `A/B` is the first column named `B` after the column named `A` (a
//!   table with several `p` columns: `first hit/p`); a header that holds a slash itself (`1/4 (750)`) is named
//!   whole. Under a heading with several tables, the rows are those of the tables that have the column.
//!
//! After these, in any order:
//! - a part of the cell: `value` (the text before a ` [` or ` (`), `interval` (the `[...]`) or `paren` (what
//!   is inside the `(...)`) or `nth:K` (the cell's K-th number, counting from 1, for a cell of prose); the
//!   whole cell without one; `hide` writes nothing, for a quote that is there for its checks; `as-p` writes a
//!   p-value as a sentence says it, `p = 0.047` or `p < 0.001`;
//! - checks the text around the quote relies on: `<0.05`, `<=X`, `>X`, `>=X` on the quoted number (`<0.001`
//!   in a table counts as below 0.001), `=TEXT` (the quoted text is TEXT) and `~TEXT` (it contains TEXT).
//!
//! A quote that names nothing, or names two things, is an error; so is a check that no longer holds, which is
//! how a regenerated table tells the writer which sentence to read again. Every failed quote of a document is
//! listed at once; the document is still written with the values, so that its difference shows what moved.

use anyhow::{Context, Result, bail};
use arld_core::files::write_atomic;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The suffix of a document to render; `NAME.in.md` becomes `NAME.md`.
pub const TEMPLATE_SUFFIX: &str = ".in.md";
/// The longest template or quoted file read (the report's are a few hundred kilobytes).
const MAX_QUOTED_BYTES: u64 = 64 << 20;

/// A table of a markdown file: the heading it stands under, its header and its rows of cells.
#[derive(Debug, Clone, PartialEq)]
struct Table {
    section: String,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

/// The cells of a markdown table line `| a | b |`, trimmed.
fn cells(line: &str) -> Vec<String> {
    let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
    inner.split('|').map(|c| c.trim().to_string()).collect()
}

fn is_separator(line: &str) -> bool {
    cells(line)
        .iter()
        .all(|c| !c.is_empty() && c.chars().all(|ch| matches!(ch, '-' | ':')))
}

/// Every table of a markdown text, with the heading above it.
fn tables(text: &str) -> Vec<Table> {
    let mut found = Vec::new();
    let mut section = String::new();
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i];
        if line.starts_with('#') {
            section = line.trim_start_matches('#').trim().to_string();
            i += 1;
        } else if line.starts_with('|') && lines.get(i + 1).is_some_and(|l| is_separator(l)) {
            let header = cells(line);
            let mut rows = Vec::new();
            i += 2;
            while i < lines.len() && lines[i].starts_with('|') {
                rows.push(cells(lines[i]));
                i += 1;
            }
            found.push(Table {
                section: section.clone(),
                header,
                rows,
            });
        } else {
            i += 1;
        }
    }
    found
}

/// Which part of a cell a quote takes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Part {
    Whole,
    Value,
    Interval,
    Paren,
    Nth(usize),
}

impl Part {
    /// The parts a template names by a word (`nth:K` carries a number).
    const NAMED: [Part; 3] = [Part::Value, Part::Interval, Part::Paren];
}

impl std::fmt::Display for Part {
    /// The part as a template spells it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Part::Whole => write!(f, "whole"),
            Part::Value => write!(f, "value"),
            Part::Interval => write!(f, "interval"),
            Part::Paren => write!(f, "paren"),
            Part::Nth(k) => write!(f, "nth:{k}"),
        }
    }
}

/// How the quoted text is written.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Shown {
    Written,
    /// Not at all: the quote is there for its checks.
    Hidden,
    /// As a p-value in a sentence: `p = 0.047`, `p < 0.001`.
    AsP,
}

impl Shown {
    fn write(self, value: &str) -> String {
        match self {
            Shown::Written => value.to_string(),
            Shown::Hidden => String::new(),
            Shown::AsP => match value.strip_prefix('<') {
                Some(bound) => format!("p < {bound}"),
                None => format!("p = {value}"),
            },
        }
    }
}

impl Part {
    fn take(self, cell: &str) -> Option<String> {
        let between = |open: char, close: char| {
            let start = cell.find(open)?;
            let end = start + cell[start..].find(close)?;
            Some((start, end))
        };
        match self {
            Part::Whole => Some(cell.to_string()),
            Part::Value => {
                let end = [" [", " ("]
                    .iter()
                    .filter_map(|s| cell.find(s))
                    .min()
                    .unwrap_or(cell.len());
                Some(cell[..end].trim().to_string())
            }
            Part::Interval => between('[', ']').map(|(s, e)| cell[s..=e].to_string()),
            Part::Paren => between('(', ')').map(|(s, e)| cell[s + 1..e].to_string()),
            Part::Nth(k) => numbers(cell).into_iter().nth(k.checked_sub(1)?),
        }
    }
}

/// The numbers of a text, in order: an optional `-` (not after a letter: `ADQN-B` has none), digits, and a
/// fractional part. A number after `<` keeps it, as a table writes a bound (`p < 0.001` gives `<0.001`).
fn numbers(text: &str) -> Vec<String> {
    let chars: Vec<char> = text.chars().collect();
    let mut found = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        if chars[i].is_ascii_digit() && (i == 0 || !chars[i - 1].is_alphanumeric()) {
            let negative =
                i > 0 && chars[i - 1] == '-' && (i == 1 || !chars[i - 2].is_alphanumeric());
            let start = if negative { i - 1 } else { i };
            while i < chars.len()
                && (chars[i].is_ascii_digit()
                    || (chars[i] == '.' && chars.get(i + 1).is_some_and(|c| c.is_ascii_digit())))
            {
                i += 1;
            }
            let before = chars[..start].iter().rev().find(|c| **c != ' ');
            let bound = if before == Some(&'<') { "<" } else { "" };
            found.push(format!(
                "{bound}{}",
                chars[start..i].iter().collect::<String>()
            ));
        } else {
            i += 1;
        }
    }
    found
}

/// A condition the text around a quote relies on.
#[derive(Debug, Clone, PartialEq)]
enum Check {
    Below(f64),
    AtMost(f64),
    Above(f64),
    AtLeast(f64),
    Equals(String),
    Contains(String),
}

impl Check {
    fn parse(text: &str) -> Result<Check> {
        let number = |t: &str| -> Result<f64> {
            t.trim()
                .parse()
                .with_context(|| format!("{t:?} is not a number"))
        };
        Ok(if let Some(rest) = text.strip_prefix("<=") {
            Check::AtMost(number(rest)?)
        } else if let Some(rest) = text.strip_prefix(">=") {
            Check::AtLeast(number(rest)?)
        } else if let Some(rest) = text.strip_prefix('<') {
            Check::Below(number(rest)?)
        } else if let Some(rest) = text.strip_prefix('>') {
            Check::Above(number(rest)?)
        } else if let Some(rest) = text.strip_prefix('=') {
            Check::Equals(rest.to_string())
        } else if let Some(rest) = text.strip_prefix('~') {
            Check::Contains(rest.to_string())
        } else {
            bail!(
                "{text:?} is neither a part (value, interval, paren) nor a check (<X, <=X, >X, >=X, =TEXT, ~TEXT)"
            )
        })
    }

    /// Whether `quoted` passes; a table's `<0.001` is a number below 0.001.
    fn holds(&self, quoted: &str) -> Result<bool> {
        // The quoted number, and whether the table gave it as a bound (`<0.001`).
        let number = || -> Result<(f64, bool)> {
            let (below, text) = match quoted.strip_prefix('<') {
                Some(rest) => (true, rest),
                None => (false, quoted),
            };
            let x = text
                .trim()
                .parse()
                .with_context(|| format!("the quoted {quoted:?} is not a number to check"))?;
            Ok((x, below))
        };
        Ok(match self {
            Check::Equals(expected) => quoted == expected,
            Check::Contains(part) => quoted.contains(part.as_str()),
            Check::Below(c) => {
                let (x, below) = number()?;
                x < *c || (below && x <= *c)
            }
            Check::AtMost(c) => number()?.0 <= *c,
            Check::Above(c) => {
                let (x, below) = number()?;
                !below && x > *c
            }
            Check::AtLeast(c) => {
                let (x, below) = number()?;
                !below && x >= *c
            }
        })
    }

    fn describe(&self) -> String {
        match self {
            Check::Below(c) => format!("< {c}"),
            Check::AtMost(c) => format!("<= {c}"),
            Check::Above(c) => format!("> {c}"),
            Check::AtLeast(c) => format!(">= {c}"),
            Check::Equals(t) => format!("= {t:?}"),
            Check::Contains(t) => format!("containing {t:?}"),
        }
    }
}

/// One quote, parsed.
#[derive(Debug, Clone, PartialEq)]
struct Quote {
    file: String,
    section: String,
    row: String,
    column: String,
    part: Part,
    shown: Shown,
    checks: Vec<Check>,
}

impl Quote {
    fn parse(text: &str) -> Result<Quote> {
        let fields: Vec<&str> = text.split('|').map(str::trim).collect();
        if fields.len() < 4 {
            bail!("a quote needs FILE|SECTION|ROW|COLUMN, then parts and checks");
        }
        let mut quote = Quote {
            file: fields[0].to_string(),
            section: fields[1].to_string(),
            row: fields[2].to_string(),
            column: fields[3].to_string(),
            part: Part::Whole,
            shown: Shown::Written,
            checks: Vec::new(),
        };
        for field in &fields[4..] {
            // A part named by a word is spelled as `Part`'s Display writes it (one owner of the spelling).
            if let Some(part) = Part::NAMED.into_iter().find(|p| p.to_string() == *field) {
                quote.part = part;
                continue;
            }
            match *field {
                "hide" => quote.shown = Shown::Hidden,
                "as-p" => quote.shown = Shown::AsP,
                nth if nth.starts_with("nth:") => {
                    let k = nth[4..]
                        .parse()
                        .ok()
                        .filter(|&k| k > 0)
                        .with_context(|| format!("{nth:?}: K counts from 1"))?;
                    quote.part = Part::Nth(k);
                }
                other => quote.checks.push(Check::parse(other)?),
            }
        }
        Ok(quote)
    }

    /// The column index `self.column` names in `header`.
    fn column_index(&self, header: &[String]) -> Result<usize> {
        // A header that holds a slash itself (effort.md's `1/4 (750)`) is named whole.
        if let Some(whole) = header.iter().position(|h| *h == self.column) {
            return Ok(whole);
        }
        let (after, name) = match self.column.split_once('/') {
            Some((a, n)) => (Some(a.trim()), n.trim()),
            None => (None, self.column.as_str()),
        };
        let start = match after {
            Some(a) => {
                header
                    .iter()
                    .position(|h| h == a)
                    .with_context(|| format!("no column {a:?} (the columns: {header:?})"))?
                    + 1
            }
            None => 0,
        };
        let index = header[start..]
            .iter()
            .position(|h| h == name)
            .with_context(|| format!("no column {:?} (the columns: {header:?})", self.column))?;
        Ok(start + index)
    }

    /// The quoted text, from the tables of `self.file`.
    fn resolve(&self, tables: &[Table]) -> Result<String> {
        let in_section: Vec<&Table> = tables
            .iter()
            .filter(|t| t.section == self.section)
            .collect();
        if in_section.is_empty() {
            bail!(
                "{} has no table under the heading {:?}",
                self.file,
                self.section
            );
        }
        let keys: Vec<&str> = self.row.split(';').map(str::trim).collect();
        let key_matches = |cell: &String, key: &str| match key.strip_suffix("...") {
            Some(prefix) => cell.starts_with(prefix),
            None => cell == key,
        };
        let row_matches = |row: &[String]| {
            row.len() >= keys.len() && row.iter().zip(&keys).all(|(c, k)| key_matches(c, k))
        };
        let mut found = Vec::new();
        // A heading can stand over several tables (effort.md's task sections): the rows are looked for in those
        // that have the column, and a column no table has is named in the error.
        let with_column: Vec<&Table> = in_section
            .iter()
            .copied()
            .filter(|t| self.column_index(&t.header).is_ok())
            .collect();
        if with_column.is_empty() {
            self.column_index(&in_section[0].header)?;
        }
        for table in with_column {
            for row in &table.rows {
                if row_matches(row) {
                    found.push((table, row));
                }
            }
        }
        let (table, row) = match found.as_slice() {
            [one] => *one,
            [] => bail!("no row {:?} under {:?}", self.row, self.section),
            _ => bail!(
                "{} rows {:?} under {:?}: name one",
                found.len(),
                self.row,
                self.section
            ),
        };
        let index = self.column_index(&table.header)?;
        let cell = row.get(index).with_context(|| {
            format!("row {:?} has no cell in column {:?}", self.row, self.column)
        })?;
        self.part
            .take(cell)
            .with_context(|| format!("the cell {cell:?} has no {} part", self.part))
    }
}

/// `text` with every quote replaced by what it names; the failed quotes as `line N: {{...}}: why`.
fn render(text: &str, dir: &Path) -> Result<(String, Vec<String>)> {
    let mut files: BTreeMap<String, Vec<Table>> = BTreeMap::new();
    let mut out = String::with_capacity(text.len());
    let mut failures = Vec::new();
    let mut rest = text;
    while let Some(start) = rest.find("{{") {
        out.push_str(&rest[..start]);
        let line = text.len() - rest.len() + start;
        let line_number = text[..line].matches('\n').count() + 1;
        let Some(len) = rest[start + 2..].find("}}") else {
            bail!("line {line_number}: a quote opened with {{{{ is never closed with }}}}");
        };
        let inner = &rest[start + 2..start + 2 + len];
        let outcome = Quote::parse(inner).and_then(|quote| {
            if !files.contains_key(&quote.file) {
                let path = dir.join(&quote.file);
                let content = arld_core::files::read_text_bounded(&path, MAX_QUOTED_BYTES)
                    .with_context(|| format!("cannot read {}", path.display()))?;
                files.insert(quote.file.clone(), tables(&content));
            }
            let value = quote.resolve(&files[&quote.file])?;
            let failed: Vec<String> = quote
                .checks
                .iter()
                .map(|c| c.holds(&value).map(|ok| (!ok).then(|| c.describe())))
                .collect::<Result<Vec<_>>>()?
                .into_iter()
                .flatten()
                .collect();
            Ok((value, failed, quote.shown))
        });
        match outcome {
            Ok((value, failed, shown)) => {
                if !failed.is_empty() {
                    failures.push(format!(
                        "line {line_number}: {{{{{inner}}}}} is now {value:?}, and the text relies on {}: read \
                         the sentence again",
                        failed.join(" and ")
                    ));
                }
                out.push_str(&shown.write(&value));
            }
            Err(err) => {
                failures.push(format!("line {line_number}: {{{{{inner}}}}}: {err:#}"));
                out.push_str("{{?}}");
            }
        }
        rest = &rest[start + 2 + len + 2..];
    }
    out.push_str(rest);
    Ok((out, failures))
}

/// Renders every `NAME.in.md` of `dir` to `NAME.md` and returns the files written. Fails, after writing every
/// document, when a quote names nothing or a check no longer holds, listing each such quote.
pub fn render_documents(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut templates: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.ends_with(TEMPLATE_SUFFIX))
        })
        .collect();
    templates.sort();
    let mut written = Vec::new();
    let mut problems = Vec::new();
    for template in templates {
        let name = template.file_name().and_then(|n| n.to_str()).unwrap_or("");
        let target = dir.join(format!(
            "{}.md",
            &name[..name.len() - TEMPLATE_SUFFIX.len()]
        ));
        let text = arld_core::files::read_text_bounded(&template, MAX_QUOTED_BYTES)
            .with_context(|| format!("cannot read {}", template.display()))?;
        let (rendered, failures) =
            render(&text, dir).with_context(|| format!("{}", template.display()))?;
        let banner = format!(
            "<!-- Written by `arld report` from {name}, whose quotes {{{{...}}}} name the cells of the report's \
             tables: edit that file. -->\n"
        );
        write_atomic(&target, format!("{banner}{rendered}").as_bytes())?;
        written.push(target);
        problems.extend(
            failures
                .into_iter()
                .map(|f| format!("{}: {f}", template.display())),
        );
    }
    if !problems.is_empty() {
        bail!(
            "{} quotes of the documents no longer hold (the documents are written with the new values):\n{}",
            problems.len(),
            problems.join("\n")
        );
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    const READINGS: &str = "intro\n\n### Acrobot-v1\n\n| method | first hit | p | final score | p |\n|---|---|---|---|---|\n\
        | GDQN-B | 2000 [2000, 34000] | 0.047 | -87.4 [-89.8, -85.6] | 0.409 |\n\
        | ADQN-B | 39000 (19/20) | - | -86.1 | - |\n\
        | DQfD-N | 50000 | <0.001 | -89.8 | 0.239 |\n\n| method | AUC |\n|---|---|\n| GDQN-B | 0.9 |\n\n### CartPole-v0\n\n| method | first hit |\n|---|---|\n| GDQN-B | 8000 |\n";

    fn rendered(template: &str) -> (String, Vec<String>) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("readings.md"), READINGS).unwrap();
        render(template, dir.path()).unwrap()
    }

    #[test]
    fn quotes_name_cells_and_their_parts() {
        let (text, failures) = rendered(
            "GDQN-B {{readings.md|Acrobot-v1|GDQN-B|first hit|value}} {{readings.md|Acrobot-v1|GDQN-B|p}} \
             {{readings.md|Acrobot-v1|GDQN-B|final score|nth:3}} {{readings.md|Acrobot-v1|GDQN-B;2000...|p}}\
             {{readings.md|Acrobot-v1|GDQN-B|p|hide|<0.05}} {{readings.md|Acrobot-v1|GDQN-B|first hit|interval}}, \
             p = {{readings.md|Acrobot-v1|GDQN-B|first hit/p|<0.05}}, final p {{readings.md|Acrobot-v1|GDQN-B|final score/p}}; \
             {{readings.md|Acrobot-v1|GDQN-B|p|as-p}}, {{readings.md|Acrobot-v1|DQfD-N|p|as-p}}; \
             {{readings.md|Acrobot-v1|ADQN...|first hit|paren}}; {{readings.md|Acrobot-v1|GDQN-B|AUC}}; CartPole {{readings.md|CartPole-v0|GDQN-B|first hit}}",
        );
        assert_eq!(failures, Vec::<String>::new());
        assert_eq!(
            text,
            "GDQN-B 2000 0.047 -85.6 0.047 [2000, 34000], p = 0.047, final p 0.409; p = 0.047, p < 0.001; 19/20; \
             0.9; CartPole 8000"
        );
    }

    #[test]
    fn a_check_that_no_longer_holds_is_reported_with_its_line() {
        let (text, failures) = rendered(
            "first\n{{readings.md|Acrobot-v1|GDQN-B|final score/p|<0.05}} and {{readings.md|Acrobot-v1|DQfD-N|first hit/p|<0.001}}.\
             {{readings.md|Acrobot-v1|GDQN-B|final score/p|hide|<0.05}}",
        );
        assert_eq!(text, "first\n0.409 and <0.001.");
        assert_eq!(failures.len(), 2, "{failures:?}");
        assert!(failures[0].starts_with("line 2:") && failures[0].contains("< 0.05"));
        assert!(
            failures[1].contains("is now \"0.409\""),
            "a hidden quote's failure shows its value"
        );
    }

    #[test]
    fn checks_read_a_tables_less_than_as_below() {
        let below = |q: &str, c: &str| Check::parse(c).unwrap().holds(q).unwrap();
        assert!(below("<0.001", "<0.001") && below("<0.001", "<0.05") && below("0.047", "<0.05"));
        assert!(!below("<0.001", ">=0.001") && !below("0.05", "<0.05") && below("0.05", ">=0.05"));
        assert!(below("0.108", ">0.05") && below("**reproduced**", "=**reproduced**"));
        assert!(below("a (GDQN); b (BDQN)", "~b (BDQN)") && !below("a (GDQN)", "~b"));
    }

    #[test]
    fn quotes_that_name_nothing_or_two_things_fail() {
        for (quote, why) in [
            ("{{readings.md|Acrobot-v1|XDQN|first hit}}", "no row"),
            ("{{readings.md|Acrobot-v1|GDQN-B|paper}}", "no column"),
            (
                "{{readings.md|MountainCar-v0|GDQN-B|first hit}}",
                "no table under",
            ),
            ("{{readings.md|Acrobot-v1|GDQN-B;2|p}}", "no row"),
            (
                "{{readings.md|Acrobot-v1|GDQN-B|first hit|nth:4}}",
                "has no nth:4 part",
            ),
            (
                "{{readings.md|Acrobot-v1|GDQN-B|first hit|nth:0}}",
                "K counts from 1",
            ),
            ("{{readings.md|Acrobot-v1|...|first hit}}", "3 rows"),
            ("{{missing.md|Acrobot-v1|GDQN-B|first hit}}", "cannot read"),
            (
                "{{readings.md|Acrobot-v1|GDQN-B|first hit|median}}",
                "neither a part",
            ),
            (
                "{{readings.md|Acrobot-v1|GDQN-B}}",
                "FILE|SECTION|ROW|COLUMN",
            ),
        ] {
            let (text, failures) = rendered(quote);
            assert_eq!(text, "{{?}}", "{quote}");
            assert!(
                failures.len() == 1 && failures[0].contains(why),
                "{quote}: {failures:?}"
            );
        }
    }

    #[test]
    fn a_header_holding_a_slash_is_named_whole() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("effort.md"),
            "### LunarLander-v2\n\n| rule | 1/4 (750) | 4 (12000) | 4 |\n|---|---|---|---|\n| paced | 0.868 (172500) | 0.885 (127500) | 7 |\n",
        )
        .unwrap();
        let (text, failures) = render(
            "{{effort.md|LunarLander-v2|paced|1/4 (750)|paren}} -> {{effort.md|LunarLander-v2|paced|4 (12000)|paren}}; \
             {{effort.md|LunarLander-v2|paced|4 (12000)/4}}",
            dir.path(),
        )
        .unwrap();
        assert_eq!(failures, Vec::<String>::new());
        assert_eq!(text, "172500 -> 127500; 7");
    }

    #[test]
    fn numbers_of_prose_keep_their_sign_but_not_a_names_hyphen() {
        assert_eq!(
            numbers("ADQN-B: final -202.2 vs 222.4 (p = 0.114); x2 -B 3."),
            ["-202.2", "222.4", "0.114", "3"]
        );
        assert_eq!(
            numbers("4 vs 1/4: AUC +0.167, p < 0.001"),
            ["4", "1", "4", "0.167", "<0.001"]
        );
    }

    #[test]
    fn an_unclosed_quote_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let err = render("a {{readings.md|x", dir.path()).unwrap_err();
        assert!(format!("{err:#}").contains("never closed"), "{err:#}");
    }

    #[test]
    fn documents_are_rendered_next_to_their_templates_and_failures_listed() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("readings.md"), READINGS).unwrap();
        std::fs::write(
            dir.path().join("NOTE.in.md"),
            "p = {{readings.md|Acrobot-v1|GDQN-B|final score/p|<0.05}}\n",
        )
        .unwrap();
        let err = render_documents(dir.path()).unwrap_err();
        assert!(format!("{err:#}").contains("NOTE.in.md: line 1"), "{err:#}");
        let written = std::fs::read_to_string(dir.path().join("NOTE.md")).unwrap();
        assert!(
            written.ends_with("p = 0.409\n")
                && written.starts_with("<!-- Written by `arld report`")
        );
    }
}
