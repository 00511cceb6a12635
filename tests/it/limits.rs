//! Size limits that keep the project readable in a day: the README and the architecture
//! page stay short, no source file or function grows past what one reads at a sitting, and
//! `src/` as a whole does not grow past its budget.

use super::layers::{read_rs, strip};
use std::path::Path;

/// README.md, bytes.
const README_BYTES: usize = 15 * 1024;
/// docs/ARCHITECTURE.md, lines.
const ARCHITECTURE_LINES: usize = 150;
/// One file under `src/`, lines.
const FILE_LINES: usize = 1200;
/// One function under `src/`, lines from its signature to its closing brace.
const FN_LINES: usize = 120;
/// All of `src/`, lines.
const SRC_LINES: usize = 60_011;

/// Each function of `code` (already stripped of comments and literals) longer than
/// `limit` lines: (first line, name, lines).
fn long_functions(code: &str, limit: usize) -> Vec<(usize, String, usize)> {
    let lines: Vec<&str> = code.lines().collect();
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let Some(at) = fn_keyword(line) else { continue };
        let name: String = line[at + 3..]
            .trim_start()
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        let (mut depth, mut started) = (0i64, false);
        let mut end = None;
        'scan: for (j, l) in lines.iter().enumerate().skip(i) {
            let from = if j == i { at } else { 0 };
            for ch in l[from..].chars() {
                match ch {
                    '{' => (depth, started) = (depth + 1, true),
                    '}' => depth -= 1,
                    ';' if !started => break 'scan,
                    _ => {}
                }
                if started && depth == 0 {
                    end = Some(j);
                    break 'scan;
                }
            }
        }
        if let Some(j) = end.filter(|j| j - i + 1 > limit) {
            out.push((i + 1, name, j - i + 1));
        }
    }
    out
}

/// Where `line` has the keyword `fn` followed by a name (not `fn(` of a type).
fn fn_keyword(line: &str) -> Option<usize> {
    let b = line.as_bytes();
    (0..b.len().saturating_sub(3)).find(|&k| {
        &b[k..k + 3] == b"fn "
            && (k == 0 || !(b[k - 1].is_ascii_alphanumeric() || b[k - 1] == b'_'))
            && b[k + 3].is_ascii_alphabetic()
    })
}

#[test]
fn docs_and_sources_stay_within_their_sizes() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut over = Vec::new();
    let readme = std::fs::read(root.join("README.md")).unwrap().len();
    if readme > README_BYTES {
        over.push(format!(
            "README.md: {readme} bytes (at most {README_BYTES})"
        ));
    }
    let arch = std::fs::read_to_string(root.join("docs/ARCHITECTURE.md")).unwrap();
    if arch.lines().count() > ARCHITECTURE_LINES {
        let n = arch.lines().count();
        over.push(format!(
            "docs/ARCHITECTURE.md: {n} lines (at most {ARCHITECTURE_LINES})"
        ));
    }
    let mut files = Vec::new();
    read_rs(root, &root.join("src"), &mut files);
    let mut total = 0;
    for (path, text) in &files {
        let n = text.lines().count();
        total += n;
        if n > FILE_LINES {
            over.push(format!("{path}: {n} lines (at most {FILE_LINES})"));
        }
        for (line, name, n) in long_functions(&strip(text), FN_LINES) {
            over.push(format!(
                "{path}:{line}: fn {name} is {n} lines (at most {FN_LINES})"
            ));
        }
    }
    if total > SRC_LINES {
        over.push(format!("src/: {total} lines (at most {SRC_LINES})"));
    }
    assert!(over.is_empty(), "over the limits:\n{}", over.join("\n"));
}

#[test]
fn function_lengths_count_from_signature_to_closing_brace() {
    let code = "fn a() {\n    1\n}\nfn b(x: fn(u8)) -> u8 {\n    if x {\n        2\n    }\n}\n\
                trait T {\n    fn c(&self);\n}\n";
    let lens: Vec<(usize, String, usize)> = long_functions(code, 0);
    let got: Vec<(&str, usize)> = lens.iter().map(|(_, n, l)| (n.as_str(), *l)).collect();
    assert_eq!(got, [("a", 3), ("b", 5)]);
    assert_eq!(long_functions(code, 3).len(), 1);
}
