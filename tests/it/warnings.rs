//! Warning codes: the table in `docs/WARNINGS.md` lists exactly the codes the library can
//! raise (`dmdsl::warning::CODES`), with their severity, figures, meaning and remedy.

use crate::common::*;
use dmdsl::warning::{any_error, lookup, Policy, Severity, Warning, CODES};
use serde_json::Value;

/// The table's row for each code, as `docs/WARNINGS.md` must have it.
fn expected_rows() -> Vec<String> {
    CODES
        .iter()
        .map(|c| {
            let severity = match c.severity {
                Severity::Note => "note",
                Severity::Warning => "warning",
                Severity::Error => "error",
            };
            let fields = if c.fields.is_empty() {
                String::from("–")
            } else {
                c.fields
                    .split(", ")
                    .map(|f| format!("`{f}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            format!(
                "| `{}` | {severity} | {fields} | {} | {} |",
                c.code, c.meaning, c.remedy
            )
        })
        .collect()
}

#[test]
fn docs_table_lists_every_code() {
    let doc = std::fs::read_to_string(root().join("docs/WARNINGS.md")).unwrap();
    let rows: Vec<&str> = doc.lines().filter(|l| l.starts_with("| `")).collect();
    let want = expected_rows();
    assert_eq!(
        rows,
        want,
        "docs/WARNINGS.md's table must be:\n{}",
        want.join("\n")
    );
}

/// A 10 × 10 × 5 mm box with one facet missing and one flipped: open and backwards edges.
fn broken_box(dir: &std::path::Path) {
    let mut t = box_tris([10.0, 10.0, 0.0], [20.0, 20.0, 5.0]);
    t.remove(7);
    let f = t[4];
    t[4] = [f[0], f[2], f[1]];
    write_stl(&dir.join("broken.stl"), &t);
}

/// `dmdsl slice broken.stl --json` with `args`: exit code, the JSON record.
fn slice_json(dir: &std::path::Path, args: &[&str]) -> (i32, Value) {
    let mut a = vec![
        "slice",
        "broken.stl",
        "-o",
        "b.dmdjob",
        "--layer-height",
        "0.1",
    ];
    a.extend_from_slice(args);
    a.push("--json");
    let o = run_in(dir, &a);
    let v: Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{e}: {} / {}", stdout(&o), stderr(&o)));
    (o.status.code().unwrap(), v)
}

fn by_code(v: &Value) -> Vec<(String, String)> {
    v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| {
            (
                w["code"].as_str().unwrap().to_string(),
                w["severity"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

#[test]
fn warnings_carry_codes_and_the_command_line_denies_or_allows_them() {
    let dir = tempdir("warn-policy");
    broken_box(&dir);
    let pair = |c: &str, s: &str| (c.to_string(), s.to_string());
    // As raised: codes, severities, figures; the manifest has the same objects.
    let (code, v) = slice_json(&dir, &[]);
    assert_eq!(code, 0);
    assert_eq!(v["ok"], true);
    assert_eq!(v["schema_version"], 1);
    let raised = by_code(&v);
    assert!(
        raised.contains(&pair("mesh.open-edges", "warning")),
        "{raised:?}"
    );
    assert!(
        raised.contains(&pair("mesh.backwards-edges", "warning")),
        "{raised:?}"
    );
    assert!(
        raised.contains(&pair("plan.wait-capped", "note")),
        "{raised:?}"
    );
    let w = &v["warnings"].as_array().unwrap()[0];
    assert_eq!(w["fields"]["open_edges"], 3, "{w}");
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("b.dmdjob/job.json")).unwrap()).unwrap();
    assert_eq!(job["warnings"], v["warnings"]);
    assert_eq!(job["version"], 4);

    // --strict = -W mesh=error: the mesh warnings fail (exit 1, bundle written); the
    // manifest keeps what the compiler found.
    std::fs::remove_dir_all(dir.join("b.dmdjob")).unwrap();
    let (code, v) = slice_json(&dir, &["--strict"]);
    assert_eq!(code, 1);
    assert_eq!(v["ok"], false);
    let strict = by_code(&v);
    assert!(
        strict.contains(&pair("mesh.open-edges", "error")),
        "{strict:?}"
    );
    assert!(
        strict.contains(&pair("slice.contours-repaired", "warning")),
        "{strict:?}"
    );
    assert!(
        strict.contains(&pair("plan.wait-capped", "note")),
        "{strict:?}"
    );
    let job2: Value =
        serde_json::from_slice(&std::fs::read(dir.join("b.dmdjob/job.json")).unwrap()).unwrap();
    assert_eq!(job2["warnings"], job["warnings"]);

    // A code beats an area: --strict with the two mesh codes allowed passes.
    let (code, v) = slice_json(
        &dir,
        &[
            "--strict",
            "-W",
            "mesh.open-edges=allow",
            "-W",
            "mesh.backwards-edges=warn",
        ],
    );
    assert_eq!(code, 0, "{v}");
    let allowed = by_code(&v);
    assert!(!allowed.iter().any(|(c, _)| c == "mesh.open-edges"));
    assert!(allowed.contains(&pair("mesh.backwards-edges", "warning")));

    // --deny-warnings fails on warnings; a note fails only when named.
    let (code, _) = slice_json(&dir, &["--deny-warnings"]);
    assert_eq!(code, 1);
    let (code, v) = slice_json(&dir, &["-W", "all=allow"]);
    assert_eq!((code, by_code(&v)), (0, vec![]));
    let (code, v) = slice_json(&dir, &["-W", "all=allow", "-W", "plan.wait-capped=error"]);
    assert_eq!(code, 1);
    assert_eq!(by_code(&v), vec![pair("plan.wait-capped", "error")]);

    // Human output: one line per warning, with its code; the denial says why it exits 1.
    let o = run_in(
        &dir,
        &[
            "slice",
            "broken.stl",
            "-o",
            "b.dmdjob",
            "--layer-height",
            "0.1",
            "--strict",
        ],
    );
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        e.contains("dmdsl: error: mesh has 3 open edges (holes); open section contours are closed or dropped; close the holes in the CAD tool or a mesh repairer, then check the repaired layers (`dmdsl inspect`) [mesh.open-edges]"),
        "{e}"
    );
    assert!(
        e.contains("dmdsl: note: natural leveling takes longer"),
        "{e}"
    );
}

#[test]
fn bad_warning_rules_are_usage_errors_listing_the_codes() {
    let dir = tempdir("warn-bad-rule");
    broken_box(&dir);
    let o = run_in(
        &dir,
        &[
            "slice",
            "broken.stl",
            "-W",
            "mesh.open-edge=error",
            "--json",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["ok"], false);
    assert_eq!(v["error"]["code"], "usage");
    let m = v["error"]["message"].as_str().unwrap();
    assert!(
        m.contains("unknown warning code \"mesh.open-edge\"; known codes: mesh.open-edges"),
        "{m}"
    );
    assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
    assert!(!dir.join("broken.dmdjob").exists());
}

#[test]
fn json_shape_keeps_code_severity_and_fields() {
    let w = Warning::new("plan.travel-clamped", "3 lifts shortened")
        .with("layers", 3)
        .with("wait_max_s", 60.0);
    let v = serde_json::to_value(&w).unwrap();
    assert_eq!(v["code"], "plan.travel-clamped");
    assert_eq!(v["severity"], "warning");
    assert_eq!(v["fields"]["layers"], 3);
    assert_eq!(v["fields"]["wait_max_s"], 60.0);
    let back: Warning = serde_json::from_value(v).unwrap();
    assert_eq!(back, w);
    let n = serde_json::to_value(Warning::new("mesh.degenerate-facets", "x")).unwrap();
    assert_eq!(n["severity"], "note");
    assert!(n.get("fields").is_none());
    assert_eq!(
        Warning::new("plan.travel-clamped", "m").to_string(),
        format!(
            "m; {} [plan.travel-clamped]",
            lookup("plan.travel-clamped").unwrap().remedy
        ),
        "people see the code to allow or deny it"
    );
}

#[test]
fn policy_most_specific_rule_wins_and_notes_need_their_code() {
    let ws = vec![
        Warning::new("mesh.open-edges", "a"),
        Warning::new("mesh.degenerate-facets", "b"),
        Warning::new("plan.unsupported-islands", "c"),
        Warning::new("plan.wait-capped", "d"),
    ];
    // The severity each of `ws` is reported with, in order ("-": left out).
    let sev = |p: &Policy| -> Vec<String> {
        let mut out = p.apply(&ws).into_iter().peekable();
        let got: Vec<String> = (ws.iter())
            .map(|w| match out.next_if(|o| o.code == w.code) {
                Some(o) => format!("{:?}", o.severity).to_lowercase(),
                None => "-".into(),
            })
            .collect();
        assert!(out.next().is_none(), "reported in the order raised");
        got
    };
    // No rules: as raised.
    assert_eq!(
        sev(&Policy::default()),
        ["warning", "note", "warning", "note"]
    );
    // --deny-warnings: warnings fail, notes stay notes.
    let mut p = Policy::default();
    p.deny_warnings();
    assert_eq!(sev(&p), ["error", "note", "error", "note"]);
    // A code beats an area beats all, whatever the order; allow silences.
    p.add("plan.unsupported-islands=allow").unwrap();
    p.add("mesh=warn").unwrap();
    p.add("plan.wait-capped=error").unwrap();
    assert_eq!(sev(&p), ["warning", "note", "-", "error"]);
    assert!(any_error(&p.apply(&ws)));
    // Equally specific: the last rule wins; `mesh.*` is the area.
    let mut p = Policy::default();
    p.add("mesh.*=error").unwrap();
    p.add("mesh=allow").unwrap();
    assert_eq!(sev(&p), ["-", "-", "warning", "note"]);
    // Bad rules are one-line errors naming the rule.
    let err = |rule: &str| Policy::default().add(rule).unwrap_err();
    assert!(err("mesh.open-edge=error").contains("unknown warning code \"mesh.open-edge\""));
    assert!(err("mesh.open-edges=fatal").contains("unknown action"));
    assert!(err("mesh.open-edges").contains("expected CODE="));
}

#[test]
fn codes_are_unique_and_well_formed() {
    let mut seen = std::collections::HashSet::new();
    for c in CODES {
        assert!(seen.insert(c.code), "{} twice", c.code);
        let (area, name) = c.code.split_once('.').expect("area.name");
        let kebab = |s: &str| {
            !s.is_empty()
                && s.chars()
                    .all(|ch| ch.is_ascii_lowercase() || ch.is_ascii_digit() || ch == '-')
        };
        assert!(kebab(area) && kebab(name), "{}", c.code);
        assert!(c.severity != Severity::Error, "{}", c.code);
        assert!(
            !c.remedy.is_empty() && !c.remedy.ends_with('.'),
            "{}",
            c.code
        );
    }
}
