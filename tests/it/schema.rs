//! The JSON Schemas of `docs/schemas/` against what `dmdsl` prints and writes: every
//! `--json` output and `job.json` of fresh jobs, checked with a small validator for the
//! subset of JSON Schema the files use. The validator is shown to reject documents that
//! break each keyword it checks, and real outputs made wrong on purpose.

use crate::common::*;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::Path;

/// The keywords the schema files may use; anything else is an error (so a schema cannot
/// say more than this validator checks).
const KEYWORDS: &[&str] = &[
    "$schema",
    "$id",
    "$defs",
    "$ref",
    "title",
    "description",
    "type",
    "properties",
    "required",
    "additionalProperties",
    "items",
    "enum",
    "minimum",
    "maximum",
    "minItems",
    "maxItems",
    "oneOf",
    // For the vendored control-file schema (fixtures/sla_control/schema_v5.json):
    "id",
    "default",
    "pattern",
    "allOf",
    "exclusiveMinimum",
];

/// Every schema of `docs/schemas/`, by file name.
pub(crate) struct Schemas(BTreeMap<String, Value>);

impl Schemas {
    pub(crate) fn load() -> Schemas {
        let dir = root().join("docs/schemas");
        let mut map = BTreeMap::new();
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if !name.ends_with(".schema.json") {
                continue;
            }
            let v: Value = serde_json::from_slice(&std::fs::read(&p).unwrap())
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            map.insert(name, v);
        }
        Schemas(map)
    }

    /// The errors of `doc` against the schema file `name` (empty: valid).
    fn errors(&self, name: &str, doc: &Value) -> Vec<String> {
        let schema = self
            .0
            .get(name)
            .unwrap_or_else(|| panic!("no schema {name}"));
        let mut errors = Vec::new();
        self.check(name, schema, doc, "$", &mut errors);
        errors
    }

    /// Panics with the errors unless `doc` is valid against schema file `name`.
    pub(crate) fn assert_valid(&self, name: &str, doc: &Value) {
        let e = self.errors(name, doc);
        assert!(
            e.is_empty(),
            "{name}: {} errors:\n{}",
            e.len(),
            e.join("\n")
        );
    }

    /// The schema a `$ref` names: `#/$defs/x` in `file`, or `other.schema.json#/$defs/x`.
    fn resolve<'a>(&'a self, file: &'a str, r: &str) -> (&'a str, &'a Value) {
        let (f, pointer) = r.split_once('#').unwrap_or_else(|| panic!("$ref {r}"));
        let f: &str = if f.is_empty() {
            file
        } else {
            self.0
                .get_key_value(f)
                .unwrap_or_else(|| panic!("$ref {r}"))
                .0
        };
        let target = self.0[f]
            .pointer(pointer)
            .unwrap_or_else(|| panic!("{file}: $ref {r} resolves to nothing"));
        (f, target)
    }

    fn check(&self, file: &str, s: &Value, v: &Value, at: &str, errors: &mut Vec<String>) {
        let s = s
            .as_object()
            .unwrap_or_else(|| panic!("{file}: schema at {at} is not an object"));
        for k in s.keys() {
            assert!(
                KEYWORDS.contains(&k.as_str()),
                "{file}: unsupported keyword {k} at {at}"
            );
        }
        if let Some(r) = s.get("$ref") {
            let (f, target) = self.resolve(file, r.as_str().unwrap());
            self.check(f, target, v, at, errors);
            return;
        }
        if let Some(t) = s.get("type") {
            let types: Vec<&str> = match t {
                Value::String(t) => vec![t.as_str()],
                Value::Array(ts) => ts.iter().map(|t| t.as_str().unwrap()).collect(),
                _ => panic!("{file}: type at {at}"),
            };
            if !types.iter().any(|t| is_type(v, t)) {
                errors.push(format!(
                    "{at}: {} is not of type {}",
                    short(v),
                    types.join(" or ")
                ));
                return;
            }
        }
        if let Some(e) = s.get("enum") {
            if !e.as_array().unwrap().contains(v) {
                errors.push(format!("{at}: {} is not one of {e}", short(v)));
            }
        }
        if let Some(x) = v.as_f64() {
            if let Some(m) = s.get("exclusiveMinimum").and_then(Value::as_f64) {
                if x <= m {
                    errors.push(format!("{at}: {x} is not above the exclusive minimum {m}"));
                }
            }
            if let Some(m) = s.get("minimum").and_then(Value::as_f64) {
                if x < m {
                    errors.push(format!("{at}: {x} is below the minimum {m}"));
                }
            }
            if let Some(m) = s.get("maximum").and_then(Value::as_f64) {
                if x > m {
                    errors.push(format!("{at}: {x} is above the maximum {m}"));
                }
            }
        }
        if let (Some(text), Some(p)) = (v.as_str(), s.get("pattern").and_then(Value::as_str)) {
            if !pattern_matches(p, text) {
                errors.push(format!("{at}: {} does not match {p}", short(v)));
            }
        }
        if let Some(all) = s.get("allOf") {
            for sub in all.as_array().unwrap() {
                self.check(file, sub, v, at, errors);
            }
        }
        if let Some(items) = v.as_array() {
            if let Some(n) = s.get("minItems").and_then(Value::as_u64) {
                if (items.len() as u64) < n {
                    errors.push(format!("{at}: {} items, fewer than {n}", items.len()));
                }
            }
            if let Some(n) = s.get("maxItems").and_then(Value::as_u64) {
                if items.len() as u64 > n {
                    errors.push(format!("{at}: {} items, more than {n}", items.len()));
                }
            }
            if let Some(item) = s.get("items") {
                for (i, x) in items.iter().enumerate() {
                    self.check(file, item, x, &format!("{at}[{i}]"), errors);
                }
            }
        }
        if let Some(o) = v.as_object() {
            let props = s.get("properties").and_then(Value::as_object);
            if let Some(req) = s.get("required") {
                for k in req.as_array().unwrap() {
                    let k = k.as_str().unwrap();
                    // (A `required`-only subschema of an `allOf` describes nothing itself.)
                    assert!(
                        props.is_none_or(|p| p.contains_key(k)),
                        "{file}: {at} requires {k}, which it does not describe"
                    );
                    if !o.contains_key(k) {
                        errors.push(format!("{at}: required {k} is missing"));
                    }
                }
            }
            for (k, x) in o {
                let at = format!("{at}.{k}");
                match (props.and_then(|p| p.get(k)), s.get("additionalProperties")) {
                    (Some(p), _) => self.check(file, p, x, &at, errors),
                    (None, Some(Value::Bool(false))) => {
                        errors.push(format!("{at}: not allowed (additionalProperties false)"))
                    }
                    (None, Some(extra @ Value::Object(_))) => {
                        self.check(file, extra, x, &at, errors)
                    }
                    (None, _) => {}
                }
            }
        }
        if let Some(alts) = s.get("oneOf") {
            let matching = alts
                .as_array()
                .unwrap()
                .iter()
                .filter(|alt| {
                    let mut e = Vec::new();
                    self.check(file, alt, v, at, &mut e);
                    e.is_empty()
                })
                .count();
            if matching != 1 {
                errors.push(format!(
                    "{at}: {} matches {matching} of the oneOf alternatives, not exactly one",
                    short(v)
                ));
            }
        }
    }
}

/// Whether `text` matches `pattern`, a regular expression of the small kind schemas here
/// use: `^` and `$` anchors, literal characters, `\\.` and `\\d` (anything else panics).
fn pattern_matches(pattern: &str, text: &str) -> bool {
    let p = pattern
        .strip_prefix('^')
        .and_then(|p| p.strip_suffix('$'))
        .unwrap_or_else(|| panic!("pattern {pattern}: only anchored patterns are supported"));
    let mut atoms: Vec<Option<char>> = Vec::new(); // None: a digit
    let mut chars = p.chars();
    while let Some(c) = chars.next() {
        match c {
            '\\' => match chars.next() {
                Some('d') => atoms.push(None),
                Some('.') => atoms.push(Some('.')),
                other => panic!("pattern {pattern}: escape {other:?} not supported"),
            },
            '.' | '*' | '+' | '?' | '[' | '(' | '{' | '|' => {
                panic!("pattern {pattern}: {c} not supported")
            }
            c => atoms.push(Some(c)),
        }
    }
    let t: Vec<char> = text.chars().collect();
    t.len() == atoms.len()
        && t.iter().zip(&atoms).all(|(c, a)| match a {
            None => c.is_ascii_digit(),
            Some(x) => c == x,
        })
}

fn is_type(v: &Value, t: &str) -> bool {
    match t {
        "object" => v.is_object(),
        "array" => v.is_array(),
        "string" => v.is_string(),
        "boolean" => v.is_boolean(),
        "null" => v.is_null(),
        "number" => v.is_number(),
        "integer" => v.is_i64() || v.is_u64(),
        _ => panic!("unknown type {t}"),
    }
}

/// `v` as text, cut short.
fn short(v: &Value) -> String {
    let s = v.to_string();
    if s.len() > 60 {
        format!(
            "{}…",
            &s[..s.char_indices().nth(57).map_or(s.len(), |(i, _)| i)]
        )
    } else {
        s
    }
}

/// The one JSON object `dmdsl ARGS` prints on stdout in `dir`, and the exit code.
fn json_of(dir: &Path, args: &[&str]) -> (i32, Value) {
    let o = run_in(dir, args);
    let v = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{args:?}: {e}: {} / {}", stdout(&o), stderr(&o)));
    (o.status.code().unwrap(), v)
}

fn read_json(p: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap()
}

/// Measurements at 13 × 9 zone centres and five grays of a smooth field.
fn write_measurements(p: &Path) {
    let mut csv = String::from("x_mm,y_mm,gray,irradiance_mw_cm2\n");
    for i in 0..13 {
        for j in 0..9 {
            let (x, y) = (2.5 + 5.0 * i as f64, 2.5 + 5.0 * j as f64);
            let p = 10.0 * (1.0 + 0.01 * x - 0.005 * y + 0.0001 * x * y);
            for g in [255, 223, 191, 159, 127] {
                let e = p * (g as f64 / 255.0).powf(1.5);
                csv.push_str(&format!("{x},{y},{g},{e:.6}\n"));
            }
        }
    }
    std::fs::write(p, csv).unwrap();
}

#[test]
fn the_validator_rejects_what_breaks_each_keyword() {
    let mut s = Schemas::load();
    s.0.insert(
        "t.schema.json".into(),
        json!({
            "type": "object",
            "additionalProperties": false,
            "required": ["n", "kind"],
            "properties": {
                "n": {"type": "integer", "minimum": 0, "maximum": 10},
                "kind": {"type": "string", "enum": ["a", "b"]},
                "xs": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
                "free": {"type": "object", "additionalProperties": {"type": "boolean"}},
                "either": {"oneOf": [{"type": "null"}, {"$ref": "#/$defs/thing"}]},
                "other": {"$ref": "error.schema.json#/properties/ok"}
            },
            "$defs": {"thing": {"type": "object", "required": ["id"], "properties": {"id": {"type": ["string", "null"]}}}}
        }),
    );
    let good = json!({"n": 3, "kind": "a", "xs": [1, 2.5], "free": {"x": true},
                      "either": {"id": null}, "other": false});
    s.assert_valid("t.schema.json", &good);
    let bad: &[(Value, &str)] = &[
        (json!({"kind": "a"}), "required n is missing"),
        (json!({"n": 3, "kind": "a", "z": 1}), "$.z: not allowed"),
        (json!({"n": 3.5, "kind": "a"}), "not of type integer"),
        (json!({"n": -1, "kind": "a"}), "below the minimum"),
        (json!({"n": 11, "kind": "a"}), "above the maximum"),
        (json!({"n": 1, "kind": "c"}), "not one of"),
        (
            json!({"n": 1, "kind": "a", "xs": [1, "2"]}),
            "$.xs[1]: \"2\" is not of type number",
        ),
        (json!({"n": 1, "kind": "a", "xs": [1]}), "fewer than 2"),
        (json!({"n": 1, "kind": "a", "xs": [1, 2, 3]}), "more than 2"),
        (
            json!({"n": 1, "kind": "a", "free": {"x": 1}}),
            "$.free.x: 1 is not of type boolean",
        ),
        (json!({"n": 1, "kind": "a", "either": {}}), "oneOf"),
        (json!({"n": 1, "kind": "a", "either": {"id": 5}}), "oneOf"),
        (
            json!({"n": 1, "kind": "a", "other": true}),
            "$.other: true is not one of [false]",
        ),
        (json!([1]), "is not of type object"),
    ];
    for (doc, want) in bad {
        let e = s.errors("t.schema.json", doc);
        assert!(
            e.iter().any(|e| e.contains(want)),
            "{doc}: want {want:?} in {e:?}"
        );
    }
}

#[test]
fn schema_files_use_only_checked_keywords_and_resolve() {
    let s = Schemas::load();
    let names: Vec<&str> = s.0.keys().map(String::as_str).collect();
    assert_eq!(
        names,
        [
            "calibrate-report.schema.json",
            "distortion-report.schema.json",
            "error.schema.json",
            "export-summary.schema.json",
            "inspect-summary.schema.json",
            "job.schema.json",
            "run-report.schema.json",
            "slice-part-line.schema.json",
            "slice-summary.schema.json"
        ]
    );
    /// Walks every subschema, checking keywords and `$ref`s.
    fn walk(s: &Schemas, file: &str, v: &Value) {
        let o = v.as_object().unwrap();
        for (k, x) in o {
            assert!(KEYWORDS.contains(&k.as_str()), "{file}: keyword {k}");
            match k.as_str() {
                "$ref" => {
                    s.resolve(file, x.as_str().unwrap());
                }
                "properties" | "$defs" => {
                    for sub in x.as_object().unwrap().values() {
                        walk(s, file, sub);
                    }
                }
                "items" => walk(s, file, x),
                "additionalProperties" if x.is_object() => walk(s, file, x),
                "oneOf" | "allOf" => x.as_array().unwrap().iter().for_each(|a| walk(s, file, a)),
                _ => {}
            }
        }
        // Every object schema says whether it allows more than it lists.
        if o.get("type").is_some_and(|t| t == "object") && o.contains_key("properties") {
            assert!(
                o.contains_key("additionalProperties"),
                "{file}: {}",
                short(v)
            );
        }
    }
    for (file, v) in &s.0 {
        walk(&s, file, v);
        // Every output but job.json carries schema_version (in each of its forms, for a
        // schema that is one of several).
        if file != "job.schema.json" {
            let forms = match v.get("oneOf") {
                Some(f) => f.as_array().unwrap().iter().collect(),
                None => vec![v],
            };
            for f in forms {
                assert!(
                    f["required"]
                        .as_array()
                        .is_some_and(|r| r.contains(&json!("schema_version"))),
                    "{file}"
                );
            }
        }
    }
}

/// Slices `part` with `args` in `dir` (as `out`), checks the summary and `job.json`
/// against their schemas, and returns the summary and the manifest.
fn slice_checked(s: &Schemas, dir: &Path, part: &Path, out: &str, args: &[&str]) -> (Value, Value) {
    let mut a = vec!["slice", part.to_str().unwrap(), "-o", out, "--json"];
    a.extend_from_slice(args);
    let (code, summary) = json_of(dir, &a);
    assert_eq!(code, 0, "{args:?}: {summary}");
    s.assert_valid("slice-summary.schema.json", &summary);
    let job = read_json(&dir.join(out).join("job.json"));
    s.assert_valid("job.schema.json", &job);
    (summary, job)
}

#[test]
fn every_json_output_matches_its_schema() {
    let s = Schemas::load();
    let dir = tempdir("schema-outputs");
    let cube = fixture("cube10.stl");
    let island = fixture("island.stl");
    // Each built-in profile, and the optional records: a distortion fit, a calibration
    // with absolute units (optics, dose), the hybrid process's totals, tiled projectors.
    write_measurements(&dir.join("m.csv"));
    let (code, cal) = json_of(
        &dir,
        &[
            "calibrate",
            "m.csv",
            "-o",
            "cal.toml",
            "--json",
            "--no-plots",
        ],
    );
    assert_eq!(code, 0, "{cal}");
    s.assert_valid("calibrate-report.schema.json", &cal);
    let lens = fixture("lens_table.csv");
    let lens = lens.to_str().unwrap();
    let jobs: &[(&Path, &str, &[&str])] = &[
        (&cube, "top.dmdjob", &["--distortion", lens]),
        (
            &cube,
            "cal.dmdjob",
            &["--calibration", "cal.toml", "--compensation", "pixel"],
        ),
        (&island, "hyb.dmdjob", &["-p", "hybrid-bottomup"]),
        (&cube, "bu.dmdjob", &["-p", "bottom-up", "--predict"]),
        (&cube, "tiled.dmdjob", &["-p", "tiled-2x1"]),
        (
            &cube,
            "acc.dmdjob",
            &[
                "--set",
                "accuracy.scale=[1.01, 0.99, 1.0]",
                "--set",
                "accuracy.xy_offset_mm=-0.02",
            ],
        ),
    ];
    for (part, out, args) in jobs {
        let (summary, job) = slice_checked(&s, &dir, part, out, args);
        assert_eq!(summary["ok"], true);
        let (code, report) = json_of(&dir, &["run", out, "--json"]);
        s.assert_valid("run-report.schema.json", &report);
        assert_eq!((code, &report["ok"]), (0, &json!(true)), "{out}: {report}");
        if out == &"top.dmdjob" {
            assert!(job["settings"]["distortion"].is_object());
        }
        if out == &"acc.dmdjob" {
            assert_eq!(job["settings"]["accuracy"]["source"], "typed in");
        }
        if out == &"cal.dmdjob" {
            assert!(
                job["optics"]["dose_mj_cm2"].is_number(),
                "{}",
                job["optics"]
            );
        }
    }
    // Jobs in one file: a zipped bundle, PrusaSlicer SL1/SL1S, an SLA control file.
    for f in [
        "zip/cube5.dmdjob.zip",
        "sl1/cube3mm.sl1",
        "sl1/cylinder_hole.sl1s",
        "control/channel.zip",
    ] {
        let p = fixture(f);
        let (code, report) = json_of(&dir, &["run", p.to_str().unwrap(), "--json"]);
        assert_eq!(code, 0, "{f}: {report}");
        s.assert_valid("run-report.schema.json", &report);
        let (code, summary) = json_of(&dir, &["inspect", p.to_str().unwrap(), "--json"]);
        assert_eq!(code, 0, "{f}: {summary}");
        s.assert_valid("inspect-summary.schema.json", &summary);
    }
    // inspect's summary, and run on another machine than the embedded one.
    let (code, summary) = json_of(
        &dir,
        &["inspect", "hyb.dmdjob", "--json", "--chart", "c.png"],
    );
    assert_eq!(code, 0, "{summary}");
    s.assert_valid("inspect-summary.schema.json", &summary);
    let (_, report) = json_of(
        &dir,
        &["run", "top.dmdjob", "--json", "--machine", "bottom-up"],
    );
    s.assert_valid("run-report.schema.json", &report);
    assert_eq!(report["machine"]["profile"], "bottom-up");
    // The cure from the masks (--cure), against the slicer's records.
    let (code, report) = json_of(&dir, &["run", "bu.dmdjob", "--json", "--cure"]);
    assert_eq!(code, 0, "{report}");
    s.assert_valid("run-report.schema.json", &report);
    assert!(report["cure"]["per_layer"][0]["slicer_diff_px"].is_number());
    // export, into each one-file form.
    for (out, format) in [
        ("top.dmdjob.zip", "dmdjob-zip"),
        ("top.sl1", "sl1"),
        ("top-control.zip", "sla-control"),
    ] {
        let (code, summary) = json_of(
            &dir,
            &[
                "export",
                "top.dmdjob",
                "-o",
                out,
                "--format",
                format,
                "--json",
            ],
        );
        assert_eq!(code, 0, "{summary}");
        s.assert_valid("export-summary.schema.json", &summary);
        assert_eq!(summary["format"], format);
    }
    // Several parts in one call: one line per part, a failure among them.
    std::fs::write(dir.join("bad.stl"), b"solid x\nfacet normal 0 0 1\n").unwrap();
    let o = run_in(
        &dir,
        &[
            "slice",
            cube.to_str().unwrap(),
            island.to_str().unwrap(),
            "bad.stl",
            "--output-dir",
            "many",
            "--json",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    let lines: Vec<Value> = stdout(&o)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 3);
    for l in &lines {
        s.assert_valid("slice-part-line.schema.json", l);
    }
    assert_eq!(
        lines.iter().map(|l| l["ok"] == true).collect::<Vec<_>>(),
        [true, true, false]
    );
    // slice and run report success under the same name: ok.
    // A run with a fault, an untriggered fault and a bad mask.
    std::fs::write(dir.join("bu.dmdjob/masks/00003.png"), b"not a png").unwrap();
    let (code, report) = json_of(
        &dir,
        &[
            "run",
            "bu.dmdjob",
            "--json",
            "--fault",
            "shutter-stuck@5",
            "--fault",
            "stall@9",
        ],
    );
    assert_eq!(code, 1);
    s.assert_valid("run-report.schema.json", &report);
    assert_eq!(report["untriggered_faults"], json!(["stall@9"]));
    assert!(
        report["violations"].as_array().unwrap().len() >= 2,
        "{report}"
    );
    // The distortion fit.
    let (code, d) = json_of(&dir, &["distortion", lens, "--json"]);
    assert_eq!(code, 0);
    s.assert_valid("distortion-report.schema.json", &d);
    // Failures of every command, and a command line clap refuses.
    let failures: &[&[&str]] = &[
        &["slice", "nope.stl", "--json"],
        &["run", "nope.dmdjob", "--json"],
        &["calibrate", "nope.csv", "-o", "c.toml", "--json"],
        &["distortion", "nope.csv", "--json"],
        &["slice", "m.csv", "--json"],
        &["run", "bu.dmdjob", "--json", "--fault", "stall@999"],
        &["slice", "a.stl", "--json", "--dither", "sometimes"],
        &["run", "truncated.zip", "--json"],
    ];
    std::fs::write(dir.join("truncated.zip"), b"PK\x03\x04 cut short").unwrap();
    for args in failures {
        let (code, e) = json_of(&dir, args);
        assert_eq!(code, 2, "{args:?}");
        s.assert_valid("error.schema.json", &e);
    }
    let (_, e) = json_of(&dir, &["run", "truncated.zip", "--json"]);
    assert_eq!(e["error"]["code"], "archive.invalid", "{e}");
}

#[test]
fn outputs_made_wrong_on_purpose_are_rejected() {
    let s = Schemas::load();
    let dir = tempdir("schema-wrong");
    let (summary, job) = slice_checked(
        &s,
        &dir,
        &fixture("cube10.stl"),
        "c.dmdjob",
        &["-p", "bottom-up"],
    );
    let (_, report) = json_of(&dir, &["run", "c.dmdjob", "--json"]);
    s.assert_valid("run-report.schema.json", &report);
    type Edit = fn(&mut Value);
    let wrong: &[(&str, &Value, Edit, &str)] = &[
        (
            "job.schema.json",
            &job,
            |j| j["layers"][3]["steps"][0]["kind"] = json!("jump"),
            "oneOf",
        ),
        (
            "job.schema.json",
            &job,
            |j| j["layers"][0]["z_mm"] = json!("0.05"),
            "not of type number",
        ),
        (
            "job.schema.json",
            &job,
            |j| j["layers"][2]["exposure_s"] = json!(-1.0),
            "below the minimum",
        ),
        (
            "job.schema.json",
            &job,
            |j| j["totals"]["eta_s"] = json!(1.0),
            "not allowed",
        ),
        (
            "job.schema.json",
            &job,
            |j| {
                j.as_object_mut().unwrap().remove("machine");
            },
            "required machine",
        ),
        (
            "job.schema.json",
            &job,
            |j| j["layers"][1]["mode"] = json!("hybrid"),
            "not one of",
        ),
        (
            "job.schema.json",
            &job,
            |j| j["version"] = json!(5),
            "not one of",
        ),
        (
            "job.schema.json",
            &job,
            |j| j["layers"][1]["masks"][0]["pixels"]["lit_px"] = json!(-3),
            "below the minimum",
        ),
        (
            "slice-summary.schema.json",
            &summary,
            |j| {
                j.as_object_mut().unwrap().remove("ok");
            },
            "required ok",
        ),
        (
            "slice-summary.schema.json",
            &summary,
            |j| j["success"] = json!(true),
            "not allowed",
        ),
        (
            "slice-summary.schema.json",
            &summary,
            |j| j["schema_version"] = json!(2),
            "not one of",
        ),
        (
            "run-report.schema.json",
            &report,
            |j| {
                j["violations"] =
                    json!([{"kind": "oops", "layer": 1, "time_s": 0.0, "message": ""}])
            },
            "not one of",
        ),
        (
            "run-report.schema.json",
            &report,
            |j| j["fault"] = json!("stall"),
            "oneOf",
        ),
    ];
    for (name, doc, edit, want) in wrong {
        let mut doc = (*doc).clone();
        edit(&mut doc);
        let e = s.errors(name, &doc);
        assert!(
            e.iter().any(|e| e.contains(want)),
            "{name}: want {want:?} in {e:?}"
        );
    }
}

/// The vendored control-file schema (`fixtures/sla_control/schema_v5.json`) loaded beside
/// the project's own.
fn with_control_schema() -> Schemas {
    let mut s = Schemas::load();
    let v: Value =
        serde_json::from_slice(&std::fs::read(fixture("sla_control/schema_v5.json")).unwrap())
            .unwrap();
    s.0.insert("schema_v5.json".into(), v);
    s
}

/// `print_settings.json` of the control-file zip at `p`.
fn control_settings(p: &Path) -> Value {
    let mut z = zip::ZipArchive::new(std::fs::File::open(p).unwrap()).unwrap();
    assert_eq!(z.name_for_index(0).unwrap().unwrap(), "print_settings.json");
    let mut text = String::new();
    std::io::Read::read_to_string(&mut z.by_index(0).unwrap(), &mut text).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn the_validator_checks_the_control_schemas_keywords() {
    assert!(pattern_matches("^5\\.\\d\\.\\d$", "5.0.0"));
    assert!(!pattern_matches("^5\\.\\d\\.\\d$", "5.0.10"));
    assert!(!pattern_matches("^5\\.\\d\\.\\d$", "4.0.0"));
    let s = with_control_schema();
    let base = json!({
        "Header": {"Schema version": "5.0.0", "Image directory": "slices"},
        "Default layer settings": {
            "Number of duplications": 1,
            "Position settings": {
                "Layer thickness (um)": 50, "Distance up (mm)": 5, "Initial wait (ms)": 0,
                "BP up speed (mm/sec)": 2, "BP up acceleration (mm/sec^2)": 50,
                "Up wait (ms)": 0, "BP down speed (mm/sec)": 1,
                "BP down acceleration (mm/sec^2)": 50, "Final wait (ms)": 0
            },
            "Image settings": {
                "Image file": "00000.png", "Layer exposure time (ms)": 8000,
                "Light engine": "p0", "Light engine power setting": 100,
                "Light engine wavelength (nm)": 365, "Relative focus position (um)": 0,
                "Wait before exposure (ms)": 0, "Wait after exposure (ms)": 0
            }
        },
        "Layers": [{"Image settings list": [{"Image file": "00000.png"}]}]
    });
    s.assert_valid("schema_v5.json", &base);
    let bad: &[(&str, Value, &str)] = &[
        ("/Header/Schema version", json!("0.1"), "does not match"),
        (
            "/Default layer settings/Position settings/Distance up (mm)",
            json!(0),
            "exclusive minimum",
        ),
        (
            "/Default layer settings/Image settings/Layer exposure time (ms)",
            json!(16000),
            "above the maximum",
        ),
    ];
    for (pointer, value, want) in bad {
        let mut doc = base.clone();
        *doc.pointer_mut(pointer).unwrap() = value.clone();
        let e = s.errors("schema_v5.json", &doc);
        assert!(e.iter().any(|e| e.contains(want)), "{pointer}: {e:?}");
    }
    let mut doc = base.clone();
    doc["Default layer settings"]["Position settings"]
        .as_object_mut()
        .unwrap()
        .remove("Up wait (ms)");
    let e = s.errors("schema_v5.json", &doc);
    assert!(
        e.iter().any(|e| e.contains("required Up wait (ms)")),
        "{e:?}"
    );
}

#[test]
fn exported_control_files_are_valid_against_the_standards_schema() {
    let s = with_control_schema();
    let d = tempdir("schema-control");
    // One projector (with a 16 s bottom exposure, split), and two tiled projectors.
    for (profile, name) in [("xu2010-topdown", "one.zip"), ("tiled-2x1", "two.zip")] {
        let o = run_in(
            &d,
            &[
                "slice",
                fixture("island.stl").to_str().unwrap(),
                "-p",
                profile,
                "-o",
                name,
                "--format",
                "sla-control",
                "-q",
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let v = control_settings(&d.join(name));
        s.assert_valid("schema_v5.json", &v);
    }
}
