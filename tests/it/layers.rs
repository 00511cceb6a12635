//! Module layers: the library's top-level modules depend on each other one way only.
//!
//! The layer table lives in `docs/ARCHITECTURE.md`, section "Module layers"; this test
//! reads it from there (so the picture and the check cannot drift apart). It then reads
//! every `src/**/*.rs` file, leaves out comments, string and character literals,
//! `#[cfg(test)]` items and test-only files (modules declared `#[cfg(test)] mod name;`),
//! collects the `crate::` paths of what is left (`use crate::{a, b::c}` groups, inline
//! `crate::x::y`, and `super::` paths that climb to the crate root) and asserts
//! (a) that the top-level modules have no cycle and (b) that every edge goes to a lower
//! layer (and, for a module whose row says "only", to one of the modules it lists).
//! The binary (`src/main.rs`) and the crate root (`src/lib.rs`) are not modules of a layer.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A dependency of one top-level module on another, and the first file that makes it.
type Graph = BTreeMap<String, BTreeMap<String, String>>;

/// `src` with comments, string literals and character literals blanked out (newlines are
/// kept; lifetimes are left alone).
pub(super) fn strip(src: &str) -> String {
    let c: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    while i < c.len() {
        if c[i] == '/' && peek(&c, i + 1) == '/' {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if c[i] == '/' && peek(&c, i + 1) == '*' {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && peek(&c, i + 1) == '*' {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && peek(&c, i + 1) == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if c[i] == '\n' {
                        out.push('\n');
                    }
                    i += 1;
                }
            }
            out.push(' ');
        } else if let Some(skip) = (i == 0 || !is_ident(c[i - 1]))
            .then(|| raw_string_len(&c[i..]))
            .flatten()
        {
            i += skip;
            out.push_str("\"\"");
        } else if c[i] == '"' {
            i += 1;
            while i < c.len() && c[i] != '"' {
                i += if c[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("\"\"");
        } else if c[i] == '\'' && peek(&c, i + 1) == '\\' {
            // An escaped character: skip the escape's first character, then to the quote.
            i += 3;
            while i < c.len() && c[i] != '\'' {
                i += 1;
            }
            i += 1;
            out.push_str("' '");
        } else if c[i] == '\'' && peek(&c, i + 2) == '\'' {
            i += 3;
            out.push_str("' '");
        } else {
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

/// The character at `i`, or NUL past the end.
fn peek(c: &[char], i: usize) -> char {
    c.get(i).copied().unwrap_or('\0')
}

/// Length of a raw string literal (`r"…"`, `r#"…"#`, `br"…"`) starting at `c[0]`.
fn raw_string_len(c: &[char]) -> Option<usize> {
    let start = match c {
        ['r', '"' | '#', ..] => 1,
        ['b', 'r', '"' | '#', ..] => 2,
        _ => return None,
    };
    let hashes = c[start..].iter().take_while(|&&x| x == '#').count();
    if c.get(start + hashes) != Some(&'"') {
        return None;
    }
    let mut i = start + hashes + 1;
    while i < c.len() {
        if c[i] == '"'
            && c[i + 1..]
                .iter()
                .take(hashes)
                .filter(|&&x| x == '#')
                .count()
                == hashes
        {
            return Some(i + 1 + hashes);
        }
        i += 1;
    }
    Some(c.len())
}

/// Where the item following an attribute that ends at `from` ends: after its `;`, or after
/// the `}` matching its first `{`, whichever comes first (further attributes skipped). A
/// field, a struct literal's field or an argument ends at its `,` or at the bracket that
/// closes what holds it.
fn item_end(code: &[u8], mut from: usize) -> usize {
    let mut depth = 0usize;
    while from < code.len() {
        match code[from] {
            b'#' if depth == 0 && code.get(from + 1) == Some(&b'[') => {
                // Another attribute of the same item.
                let mut d = 0usize;
                while from < code.len() {
                    match code[from] {
                        b'[' => d += 1,
                        b']' => {
                            d -= 1;
                            if d == 0 {
                                break;
                            }
                        }
                        _ => {}
                    }
                    from += 1;
                }
            }
            b';' | b',' if depth == 0 => return from + 1,
            b'}' | b')' | b']' if depth == 0 => return from,
            b'{' | b'(' | b'[' => depth += 1,
            b'}' => {
                depth -= 1;
                if depth == 0 {
                    return from + 1;
                }
            }
            b')' | b']' => depth -= 1,
            _ => {}
        }
        from += 1;
    }
    code.len()
}

const CFG_TEST: &str = "#[cfg(test)]";

/// Stripped code without its `#[cfg(test)]` items.
fn without_test_items(code: &str) -> String {
    let mut out = String::with_capacity(code.len());
    let mut rest = code;
    while let Some(k) = rest.find(CFG_TEST) {
        out.push_str(&rest[..k]);
        let end = item_end(rest.as_bytes(), k + CFG_TEST.len());
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// Names of the modules that stripped `code` declares as `#[cfg(test)] mod name;` (their
/// files are test code).
fn test_modules(code: &str) -> Vec<String> {
    let mut names = Vec::new();
    for (k, _) in code.match_indices(CFG_TEST) {
        let end = item_end(code.as_bytes(), k + CFG_TEST.len());
        let item = &code[k + CFG_TEST.len()..end];
        if item.trim_end().ends_with(';') {
            if let Some(m) = item.split_whitespace().skip_while(|w| *w != "mod").nth(1) {
                names.push(m.trim_end_matches(';').to_string());
            }
        }
    }
    names
}

/// The modules `text` (a crate root, comments stripped) declares: `mod name;`, with any
/// visibility or attributes before it.
fn declared_modules(text: &str) -> Vec<String> {
    let mut out: Vec<String> = text
        .split([';', '{', '}'])
        .filter_map(|stmt| {
            let words: Vec<&str> = stmt.split_whitespace().collect();
            match words.as_slice() {
                [.., "mod", name] => Some(first_ident(name)),
                _ => None,
            }
        })
        .filter(|name| !name.is_empty())
        .collect();
    // The stage modules, declared through the crate's `stages!(a, b, …)` macro.
    for list in text.split("stages!(").skip(1) {
        let list = list.split(')').next().unwrap_or("");
        out.extend(list.split(',').map(first_ident).filter(|n| !n.is_empty()));
    }
    out
}

/// The module path of a file under `src/` (`optics/calib.rs` → [optics, calib]); empty for
/// the crate root and the binary.
fn module_path(rel: &str) -> Vec<String> {
    let rel = rel.trim_end_matches(".rs");
    let mut parts: Vec<String> = rel.split('/').map(String::from).collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    if parts == ["lib"] || parts == ["main"] {
        parts.clear();
    }
    parts
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// The first identifier of `s` (after spaces).
fn first_ident(s: &str) -> String {
    s.trim_start()
        .chars()
        .take_while(|&c| is_ident(c))
        .collect()
}

/// The names a path continues with after `crate::` at `s`: one name, or each element's
/// first name in a `{…}` group.
fn names_after(s: &str) -> Vec<String> {
    let s = s.trim_start();
    let Some(group) = s.strip_prefix('{') else {
        return vec![first_ident(s)];
    };
    let mut names = Vec::new();
    let (mut depth, mut start) = (0usize, 0usize);
    for (k, ch) in group.char_indices() {
        match ch {
            '{' => depth += 1,
            '}' if depth == 0 => {
                names.push(first_ident(&group[start..k]));
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                names.push(first_ident(&group[start..k]));
                start = k + 1;
            }
            _ => {}
        }
    }
    names.retain(|n| !n.is_empty() && n != "self");
    names
}

/// The root-level names (top-level modules or root re-exports) that the non-test `code` of
/// the module at `path` names: `crate::` paths and `super::` paths that reach the root.
fn root_names(code: &str, path: &[String]) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let starts_path = |k: usize| {
        let before = code[..k].chars().next_back();
        !before.is_some_and(|c| is_ident(c) || c == ':')
    };
    for (k, _) in code.match_indices("crate::") {
        let k = if code[..k].ends_with('$') { k - 1 } else { k };
        if starts_path(k) {
            let at = code[k..].find("crate::").unwrap() + k + "crate::".len();
            out.extend(names_after(&code[at..]));
        }
    }
    for (k, _) in code.match_indices("super::") {
        if !starts_path(k) {
            continue;
        }
        let mut at = k;
        let mut ups = 0;
        while code[at..].starts_with("super::") {
            at += "super::".len();
            ups += 1;
        }
        if ups == path.len() {
            out.extend(names_after(&code[at..]));
        }
    }
    out
}

/// Top-level module → the modules it uses (with the first file that does), from the
/// crate's files `(path under src/, text)`. Names the crate root re-exports (`pub use
/// error::{Error, Result}` in `lib.rs`) count as their module. Errors name what cannot
/// be attributed to a module.
fn graph(files: &[(String, String)]) -> Result<Graph, String> {
    let code: Vec<(String, Vec<String>, String)> = files
        .iter()
        .map(|(rel, text)| (rel.clone(), module_path(rel), strip(text)))
        .collect();
    // The library's top-level modules are the ones `lib.rs` declares; files of other
    // modules (the binary's, under `main.rs`) are not part of the library's layers.
    let tops: BTreeSet<String> = code
        .iter()
        .filter(|(rel, _, _)| rel == "lib.rs")
        .flat_map(|(_, _, text)| declared_modules(text))
        .collect();
    let mut reexport: BTreeMap<String, String> = BTreeMap::new();
    let mut test_only: Vec<Vec<String>> = Vec::new();
    for (rel, path, text) in &code {
        if rel == "lib.rs" {
            for stmt in text.split(';') {
                if let Some(r) = stmt.trim().strip_prefix("pub use ") {
                    let module = first_ident(r);
                    let rest = &r[module.len()..].trim_start_matches(':');
                    for name in names_after(rest) {
                        reexport.insert(name, module.clone());
                    }
                }
            }
        }
        for m in test_modules(text) {
            let mut p = path.clone();
            p.push(m);
            test_only.push(p);
        }
    }
    let mut g = Graph::new();
    for (rel, path, text) in &code {
        let Some(top) = path.first().filter(|t| tops.contains(*t)) else {
            continue;
        };
        if test_only.iter().any(|t| path.starts_with(t)) {
            continue;
        }
        g.entry(top.clone()).or_default();
        for name in root_names(&without_test_items(text), path) {
            let to = if tops.contains(&name) {
                name
            } else if let Some(m) = reexport.get(&name) {
                m.clone()
            } else {
                return Err(format!(
                    "src/{rel}: crate::{name} is not a module of the crate"
                ));
            };
            if &to != top {
                g.get_mut(top)
                    .unwrap()
                    .entry(to)
                    .or_insert_with(|| format!("src/{rel}"));
            }
        }
    }
    Ok(g)
}

/// A cycle of the graph (first module repeated at the end), if there is one.
fn find_cycle(g: &Graph) -> Option<Vec<String>> {
    // 0 unseen, 1 on the current path, 2 done.
    fn visit(
        m: &str,
        g: &Graph,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(m.to_string(), 1);
        stack.push(m.to_string());
        for to in g.get(m).into_iter().flat_map(|e| e.keys()) {
            match state.get(to).copied().unwrap_or(0) {
                1 => {
                    let k = stack.iter().position(|s| s == to).unwrap();
                    let mut cycle = stack[k..].to_vec();
                    cycle.push(to.clone());
                    return Some(cycle);
                }
                0 => {
                    if let Some(c) = visit(to, g, state, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        state.insert(m.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for m in g.keys() {
        if state.get(m).copied().unwrap_or(0) == 0 {
            if let Some(c) = visit(m, g, &mut state, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

/// The layer table: each module's layer and, where its row says "only", the modules it
/// may use.
#[derive(Debug, Default, PartialEq)]
struct Layers {
    layer: BTreeMap<String, u32>,
    only: BTreeMap<String, BTreeSet<String>>,
}

/// The backticked names of a table cell.
fn backticked(cell: &str) -> BTreeSet<String> {
    cell.split('`')
        .skip(1)
        .step_by(2)
        .map(String::from)
        .collect()
}

/// Reads the table of the "## Module layers" section of `markdown`: rows
/// `| layer | modules | may use |`.
fn parse_layers(markdown: &str) -> Result<Layers, String> {
    let section = markdown
        .split("\n## ")
        .find(|s| s.starts_with("Module layers"))
        .ok_or("no \"## Module layers\" section")?;
    let mut t = Layers::default();
    for row in section.lines().filter(|l| l.starts_with('|')) {
        let cells: Vec<&str> = row.trim_matches('|').split('|').map(str::trim).collect();
        let Ok(layer) = cells[0].parse::<u32>() else {
            continue;
        };
        let (modules, uses) = (cells.get(1), cells.get(2));
        let modules = backticked(modules.ok_or(format!("row {row:?}: no modules"))?);
        for m in &modules {
            if t.layer.insert(m.clone(), layer).is_some() {
                return Err(format!("module {m} is in two rows"));
            }
            if let Some(u) = uses.filter(|u| u.starts_with("only")) {
                t.only.insert(m.clone(), backticked(u));
            }
        }
    }
    if t.layer.is_empty() {
        return Err("the \"Module layers\" table has no rows".into());
    }
    Ok(t)
}

/// Every module missing from the table and every edge the table does not allow.
fn violations(g: &Graph, t: &Layers) -> Vec<String> {
    let mut v = Vec::new();
    for m in g.keys() {
        if !t.layer.contains_key(m) {
            v.push(format!("module {m} is not in the layer table"));
        }
    }
    for m in t.layer.keys() {
        if !g.contains_key(m) {
            v.push(format!("the layer table names {m}, which is not a module"));
        }
    }
    for (from, edges) in g {
        for (to, file) in edges {
            let (Some(&lf), Some(&lt)) = (t.layer.get(from), t.layer.get(to)) else {
                continue;
            };
            if lt >= lf {
                v.push(format!(
                    "{from} (layer {lf}) uses {to} (layer {lt}) in {file}: dependencies must point to a lower layer"
                ));
            } else if t.only.get(from).is_some_and(|only| !only.contains(to)) {
                v.push(format!(
                    "{from} uses {to} in {file}, which is not among the modules it may use"
                ));
            }
        }
    }
    v
}

/// Every `.rs` file under `dir`, as (path relative to `root`, text).
pub(super) fn read_rs(root: &Path, dir: &Path, out: &mut Vec<(String, String)>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            read_rs(root, &p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            let rel = p
                .strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            out.push((rel, std::fs::read_to_string(&p).unwrap()));
        }
    }
}

fn edges(g: &Graph) -> String {
    g.iter()
        .map(|(m, e)| {
            format!(
                "{m} -> {}",
                e.keys().cloned().collect::<Vec<_>>().join(", ")
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn top_level_modules_form_layers_without_cycles() {
    let root = super::common::root();
    let src = root.join("src");
    let mut files = Vec::new();
    read_rs(&src, &src, &mut files);
    let g = graph(&files).unwrap();
    eprintln!("module graph (non-test crate:: paths):\n{}", edges(&g));
    // The reader sees the crate: the pipeline and the executor both use the bundle.
    assert!(g.len() >= 15, "{}", edges(&g));
    assert!(g["job"].contains_key("bundle") && g["exec"].contains_key("bundle"));
    if let Some(c) = find_cycle(&g) {
        panic!("module cycle: {}\n{}", c.join(" -> "), edges(&g));
    }
    let docs = std::fs::read_to_string(root.join("docs/ARCHITECTURE.md")).unwrap();
    let layers = parse_layers(&docs).unwrap();
    let v = violations(&g, &layers);
    assert!(v.is_empty(), "{}", v.join("\n"));
}

/// The files `list`, with a `lib.rs` declaring every top-level module when `list` has none.
fn files(list: &[(&str, &str)]) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = list
        .iter()
        .map(|(p, t)| (p.to_string(), t.to_string()))
        .collect();
    if !out.iter().any(|(p, _)| p == "lib.rs") {
        let decls: BTreeSet<String> = out
            .iter()
            .filter_map(|(p, _)| module_path(p).first().map(|m| format!("pub mod {m};")))
            .collect();
        out.push(("lib.rs".into(), decls.into_iter().collect()));
    }
    out
}

fn names(g: &Graph, m: &str) -> Vec<String> {
    g[m].keys().cloned().collect()
}

#[test]
fn paths_are_found_in_groups_inline_and_through_super_but_not_in_tests_comments_or_strings() {
    let fs = files(&[
        ("lib.rs", "pub mod a; pub mod b; pub mod c; pub mod d; pub mod e;\npub mod f; pub mod h; pub mod i; pub mod t;\npub use f::{Error, Result};"),
        (
            "a/mod.rs",
            r##"//! Uses [`crate::t`] in a doc comment only.
use crate::{b, c::d::X, d::{Y, z::W}};
use super::i::Q;
mod inner;
#[cfg(test)]
mod tests_file;
/* crate::t in a block comment */
fn go() -> crate::Result<()> {
    let s = "crate::t";
    let c = '{';
    let _ = crate::h::run(b'x', r#"crate::t"#);
    #[cfg(test)]
    crate::t::only_in_tests();
    Ok(())
}
#[cfg(test)]
mod tests {
    use crate::t;
    fn f() { let x = '}'; let y = '\''; let z: [u8; 2] = [b'{', b'\\']; }
}
#[cfg(test)]
const T: [u8; 1] = [crate::t::ONE];
struct S {
    n: u8,
    #[cfg(test)]
    k: crate::t::K,
}
fn s() -> S {
    S { #[cfg(test)] k: crate::t::K, n: 1 }
}
"##,
        ),
        ("a/inner.rs", "use super::super::e::Z;\nuse super::go;"),
        ("a/tests_file.rs", "use crate::t::Helper;"),
        ("b.rs", ""),
        ("c/mod.rs", ""),
        ("d.rs", ""),
        ("e.rs", ""),
        ("f.rs", ""),
        ("h.rs", ""),
        ("i.rs", ""),
        ("t.rs", ""),
        ("main.rs", "use crate::a;"),
        ("cli/mod.rs", "use crate::a;"),
    ]);
    let g = graph(&fs).unwrap();
    assert_eq!(names(&g, "a"), ["b", "c", "d", "e", "f", "h", "i"]);
    assert!(g["t"].is_empty() && g["b"].is_empty());
    assert!(!g.contains_key("main") && !g.contains_key("cli"));
    let e = graph(&files(&[("a.rs", "use crate::nowhere::X;")])).unwrap_err();
    assert_eq!(e, "src/a.rs: crate::nowhere is not a module of the crate");
}

#[test]
fn a_cycle_is_found() {
    let g = graph(&files(&[
        ("a.rs", "use crate::b::X;"),
        ("b.rs", "pub fn f() { crate::c::g() }"),
        ("c/mod.rs", "use crate::{a::Y, d};"),
        ("d.rs", ""),
    ]))
    .unwrap();
    assert_eq!(find_cycle(&g).unwrap(), ["a", "b", "c", "a"]);
    let acyclic = graph(&files(&[
        ("a.rs", "use crate::b::X;"),
        ("b.rs", "use crate::c::X;"),
        ("c.rs", ""),
    ]))
    .unwrap();
    assert_eq!(find_cycle(&acyclic), None);
}

#[test]
fn edges_up_or_outside_an_only_list_break_the_layers() {
    let docs = "# X\n\n## Module layers\n\ntext\n\n| layer | modules | may use |\n|---|---|---|\n| 0 | `low`, `other` | nothing |\n| 1 | `mid` | lower layers |\n| 2 | `top` | only `mid` |\n\n## Next\n| 9 | `not_a_layer_row` | |\n";
    let t = parse_layers(docs).unwrap();
    assert_eq!(t.layer.len(), 4);
    assert_eq!(t.only["top"], BTreeSet::from(["mid".to_string()]));
    let ok = graph(&files(&[
        ("low.rs", ""),
        ("other.rs", ""),
        ("mid.rs", "use crate::low::X;"),
        ("top.rs", "use crate::mid::X;"),
    ]))
    .unwrap();
    assert_eq!(violations(&ok, &t), Vec::<String>::new());
    let bad = graph(&files(&[
        ("low.rs", "use crate::mid::X;"),
        ("other.rs", "use crate::low::X;"),
        ("mid.rs", ""),
        ("top.rs", "use crate::low::X;"),
        ("new.rs", ""),
    ]))
    .unwrap();
    assert_eq!(
        violations(&bad, &t),
        [
            "module new is not in the layer table",
            "low (layer 0) uses mid (layer 1) in src/low.rs: dependencies must point to a lower layer",
            "other (layer 0) uses low (layer 0) in src/other.rs: dependencies must point to a lower layer",
            "top uses low in src/top.rs, which is not among the modules it may use",
        ]
    );
    assert!(parse_layers("## Module layers\nno table\n").is_err());
}
