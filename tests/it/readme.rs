//! README.md stays true: every command in its `sh` blocks runs, in order, in one directory
//! (with the repository's `fixtures/` beside it) and exits 0; a `text` block right after a
//! one-command `sh` block is that command's output, and each of its lines must be found in
//! what the command printed (`…` stands for any text; a trailing elapsed time `(1.34 s)`
//! may differ). The set-up block's test command is the one `.ci/run` runs.

use crate::common::*;
use std::path::Path;

/// A fenced block of README.md: its info string and lines.
struct Block {
    lang: String,
    lines: Vec<String>,
}

fn blocks(text: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let mut cur: Option<Block> = None;
    for line in text.lines() {
        match (line.strip_prefix("```"), cur.take()) {
            (Some(lang), None) => {
                cur = Some(Block {
                    lang: lang.trim().to_string(),
                    lines: Vec::new(),
                })
            }
            (Some(_), Some(b)) => out.push(b),
            (None, Some(mut b)) => {
                b.lines.push(line.to_string());
                cur = Some(b);
            }
            (None, None) => {}
        }
    }
    assert!(cur.is_none(), "README.md: a code block is not closed");
    out
}

/// A command line of a `sh` block: the words after `dmdsl` (comments dropped) and the file
/// stdout is redirected to, if any.
fn command(line: &str) -> (Vec<String>, Option<String>) {
    let line = line.split(" #").next().unwrap_or("").trim();
    let rest = line
        .strip_prefix("dmdsl ")
        .unwrap_or_else(|| panic!("README.md: a sh block runs something other than dmdsl: {line}"));
    let (args, to) = match rest.split_once(" > ") {
        Some((a, f)) => (a, Some(f.trim().to_string())),
        None => (rest, None),
    };
    (args.split_whitespace().map(String::from).collect(), to)
}

/// `line` with a trailing elapsed time such as `(1.34 s)` replaced by `(…)`.
fn without_time(line: &str) -> String {
    if let Some(open) = line.rfind('(') {
        let inside = &line[open + 1..];
        if let Some(num) = inside.strip_suffix(" s)") {
            if num.parse::<f64>().is_ok() {
                return format!("{}(…)", &line[..open]);
            }
        }
    }
    line.to_string()
}

/// Whether an expected line (with `…` wildcards) matches a line of `output`.
fn found(expected: &str, output: &str) -> bool {
    let expected = without_time(expected);
    let parts: Vec<&str> = expected.split('…').collect();
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    output.lines().map(without_time).any(|line| {
        if parts.len() == 1 {
            return line == expected;
        }
        let Some(mut rest) = line.strip_prefix(first) else {
            return false;
        };
        for p in &parts[1..parts.len() - 1] {
            match rest.find(p) {
                Some(k) => rest = &rest[k + p.len()..],
                None => return false,
            }
        }
        rest.ends_with(last)
    })
}

fn run_block(dir: &Path, b: &Block, expected: Option<&Block>) {
    let cmds: Vec<&String> = b.lines.iter().filter(|l| !l.trim().is_empty()).collect();
    for line in &cmds {
        let (args, to) = command(line);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run_in(dir, &args);
        assert_eq!(
            o.status.code(),
            Some(0),
            "README.md: {line}\n{}",
            stderr(&o)
        );
        if let Some(f) = to {
            std::fs::write(dir.join(f), &o.stdout).unwrap();
        }
        if let (Some(e), 1) = (expected, cmds.len()) {
            let all = format!("{}{}", stderr(&o), stdout(&o));
            for want in e.lines.iter().filter(|l| !l.trim().is_empty()) {
                assert!(
                    found(want, &all),
                    "README.md: {line} printed no line like\n  {want}\nbut:\n{all}"
                );
            }
        }
    }
}

#[test]
fn readme_examples_run_and_print_what_it_shows() {
    let root = root();
    let text = std::fs::read_to_string(root.join("README.md")).unwrap();
    let dir = tempdir("readme");
    #[cfg(unix)]
    std::os::unix::fs::symlink(root.join("fixtures"), dir.join("fixtures")).unwrap();
    let bs = blocks(&text);
    let mut ran = 0;
    for (i, b) in bs.iter().enumerate() {
        if b.lang == "sh" {
            let next = bs.get(i + 1).filter(|n| n.lang == "text");
            run_block(&dir, b, next);
            ran += 1;
        }
    }
    assert!(ran >= 8, "README.md has {ran} sh blocks");
    for f in [
        "bunny00.dmdjob/masks/00300.png",
        "preview.png",
        "sheet.png",
        "cube.sl1",
        "cal.toml",
    ] {
        assert!(
            dir.join(f).is_file(),
            "README.md's examples did not write {f}"
        );
    }
}

#[test]
fn readme_set_up_is_two_commands_and_ci_runs_its_test_command() {
    let root = root();
    let text = std::fs::read_to_string(root.join("README.md")).unwrap();
    let set_up = text
        .split("## Set-up")
        .nth(1)
        .expect("README.md has a Set-up section");
    let b = &blocks(set_up)[0];
    let cmds: Vec<&str> = b
        .lines
        .iter()
        .map(|l| l.split(" #").next().unwrap().trim())
        .filter(|l| !l.is_empty())
        .collect();
    assert_eq!(cmds.len(), 2, "{cmds:?}");
    assert!(
        cmds[0].starts_with("cargo run --release -- slice "),
        "{cmds:?}"
    );
    let ci = std::fs::read_to_string(root.join(".ci/run")).unwrap();
    assert!(
        ci.lines().any(|l| l.trim() == cmds[1]),
        ".ci/run does not run README's test command {:?}",
        cmds[1]
    );
}

#[test]
fn the_output_matcher_takes_wildcards_and_times() {
    let out = "a.dmdjob: 3 layers (0.20 s)\nwarning: 2 things [x.y]\n";
    assert!(found("a.dmdjob: 3 layers (1.34 s)", out));
    assert!(found("warning: … [x.y]", out));
    assert!(!found("warning: … [x.z]", out));
    assert!(!found("a.dmdjob: 4 layers (0.20 s)", out));
    assert!(!found("3 layers", out));
}
