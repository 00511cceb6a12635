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
        (&["testjob"], "the job and its sheet were written"),
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
            "testjob",
        ] {
            assert!(s.contains(cmd), "{shell} completion lacks {cmd}");
        }
        assert!(s.contains("layer-height"), "{shell}");
    }
    let o = run_in(&dir, &["completions", "tcsh"]);
    assert_eq!(o.status.code(), Some(2));
}

/// What bash completes for the words `line` (the last one being completed), in `dir`.
fn bash_completes(dir: &std::path::Path, script: &std::path::Path, line: &[&str]) -> Vec<String> {
    let words = line
        .iter()
        .map(|w| format!("'{w}'"))
        .collect::<Vec<_>>()
        .join(" ");
    let prog = format!(
        "source '{}'; COMP_WORDS=({words}); COMP_CWORD={}; COMP_LINE='{}'; COMP_POINT=${{#COMP_LINE}}; \
         _dmdsl dmdsl '{}' '{}'; printf '%s\\n' \"${{COMPREPLY[@]}}\"",
        script.display(),
        line.len() - 1,
        line.join(" "),
        line[line.len() - 1],
        line[line.len().saturating_sub(2)],
    );
    let o = std::process::Command::new("bash")
        .args(["--norc", "-c", &prog])
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(str::to_owned)
        .collect()
}

#[test]
fn bash_completes_profile_names_files_and_warning_rules() {
    let dir = tempdir("bash-completion");
    let o = run_in(&dir, &["completions", "bash"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let script = dir.join("dmdsl.bash");
    std::fs::write(&script, &o.stdout).unwrap();
    std::fs::write(dir.join("bottom-mine.toml"), "").unwrap();
    let got = bash_completes(&dir, &script, &["dmdsl", "slice", "part.stl", "-p", "bot"]);
    assert!(got.contains(&"bottom-up".to_owned()), "{got:?}");
    assert!(got.contains(&"bottom-mine.toml".to_owned()), "{got:?}");
    let got = bash_completes(&dir, &script, &["dmdsl", "profile", "show", "tiled"]);
    assert!(got.contains(&"tiled-2x1".to_owned()), "{got:?}");
    let got = bash_completes(
        &dir,
        &script,
        &["dmdsl", "slice", "part.stl", "-W", "plan.wait"],
    );
    assert!(
        got.contains(&"plan.wait-capped=allow".to_owned()),
        "{got:?}"
    );
    let got = bash_completes(
        &dir,
        &script,
        &["dmdsl", "export", "a.dmdjob", "--format", "sl"],
    );
    assert!(got.contains(&"sla-control".to_owned()), "{got:?}");
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
    assert!(page.contains("slice"), "{page}");
    // Examples and exit codes are sections of their own, set line by line as in --help.
    for section in [".SH \"EXAMPLES\"\n.nf\n", ".SH \"EXIT STATUS\"\n.nf\n"] {
        assert!(page.contains(section), "{section}: {page}");
    }
    assert!(!page.contains("EXTRA"), "{page}");
    let o = run_in(&dir, &["man", "slice"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let page = stdout(&o);
    assert!(
        page.contains(".TH dmdsl-slice 1"),
        "{}",
        &page[..page.len().min(300)]
    );
    assert!(page.contains("layer\\-height"), "{page}");
    assert!(
        page.contains("  dmdsl slice part.stl \\-o part.sl1 "),
        "an example line kept whole: {page}"
    );
    let o = run_in(&dir, &["man", "nope"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("man nope: no such command"),
        "{}",
        stderr(&o)
    );
}
