//! `--help` of each command (examples and that command's exit codes), `dmdsl completions`
//! and `dmdsl man`.

use crate::common::*;

/// `dmdsl ARGS --help` in a fresh directory: exit code 0, the text on stdout.
fn help(args: &[&str]) -> String {
    let dir = tempdir("help");
    let mut a = args.to_vec();
    a.push("--help");
    let o = run_in(&dir, &a);
    assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
    stdout(&o)
}

/// The lines of the section that starts with `title` (up to the next blank line).
fn section<'a>(text: &'a str, title: &str) -> Vec<&'a str> {
    let mut lines = text.lines().skip_while(|l| !l.starts_with(title));
    assert!(lines.next().is_some(), "no {title:?} in:\n{text}");
    lines.take_while(|l| !l.trim().is_empty()).collect()
}

#[test]
fn every_command_shows_examples_and_its_own_exit_codes() {
    // (command, a phrase only its exit codes have)
    let cases: &[(&[&str], &str)] = &[
        (&[], "interrupted"),
        (&["slice"], "the bundle was written"),
        (&["run"], "violations, bad masks or an injected fault"),
        (&["export"], "a plain .zip without --format"),
        (
            &["calibrate"],
            "the calibration (and its plots) were written",
        ),
        (&["distortion"], "the table was fitted"),
        (&["profile"], "unknown profile name"),
        (&["completions"], "the script was written"),
        (&["man"], "the page was written"),
    ];
    for (cmd, own) in cases {
        let text = help(cmd);
        let examples = section(&text, "Examples:");
        assert!((2..=4).contains(&examples.len()), "{cmd:?}: {examples:?}");
        for e in &examples {
            let e = e.trim_start();
            assert!(
                e.starts_with("dmdsl ") || e.starts_with("sudo "),
                "{cmd:?}: {e}"
            );
        }
        let exits = section(&text, "Exit codes");
        assert!(
            exits.iter().any(|l| l.trim_start().starts_with("0 ")),
            "{cmd:?}"
        );
        assert!(exits.join(" ").contains(own), "{cmd:?}: {exits:?}");
    }
    // Each command's exit codes are its own: calibrate's do not speak of bundles.
    let calibrate = section(&help(&["calibrate"]), "Exit codes").join(" ");
    assert!(!calibrate.contains("bundle"), "{calibrate}");
    let slice = section(&help(&["slice"]), "Exit codes").join(" ");
    assert!(!slice.contains("calibration"), "{slice}");
}

#[test]
fn binary_is_documented_as_coverage_with_compensation_applied() {
    let text = help(&["slice"]).replace('\n', " ");
    let words: Vec<&str> = text.split_whitespace().collect();
    let text = words.join(" ");
    assert!(text.contains("--binary Binary coverage"), "{text}");
    assert!(text.contains("compensation still applies"), "{text}");
}

#[test]
fn completions_for_each_shell() {
    let dir = tempdir("completions");
    for (shell, marker) in [
        ("bash", "_dmdsl()"),
        ("zsh", "#compdef dmdsl"),
        ("fish", "complete -c dmdsl"),
    ] {
        let o = run_in(&dir, &["completions", shell]);
        assert_eq!(o.status.code(), Some(0), "{shell}: {}", stderr(&o));
        let s = stdout(&o);
        assert!(s.contains(marker), "{shell}: {}", &s[..s.len().min(300)]);
        for cmd in [
            "slice",
            "run",
            "calibrate",
            "distortion",
            "profile",
            "export",
        ] {
            assert!(s.contains(cmd), "{shell} completion lacks {cmd}");
        }
        assert!(s.contains("layer-height"), "{shell}");
    }
    let o = run_in(&dir, &["completions", "tcsh"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn man_pages() {
    let dir = tempdir("man");
    let o = run_in(&dir, &["man"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let page = stdout(&o);
    assert!(
        page.contains(".TH dmdsl 1"),
        "{}",
        &page[..page.len().min(300)]
    );
    assert!(
        page.contains("slice") && page.contains("Exit codes"),
        "{page}"
    );
    let o = run_in(&dir, &["man", "slice"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let page = stdout(&o);
    assert!(
        page.contains(".TH dmdsl-slice 1"),
        "{}",
        &page[..page.len().min(300)]
    );
    assert!(page.contains("layer\\-height"), "{page}");
    let o = run_in(&dir, &["man", "nope"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("man nope: no such command"),
        "{}",
        stderr(&o)
    );
}
