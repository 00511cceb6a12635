//! `--json` outputs: every object carries `schema_version`, successes and failures alike;
//! a failure prints one JSON object on stdout beside its one-line stderr message.

use crate::common::*;
use serde_json::Value;

/// Runs `args` in a fresh directory; returns exit code, the one JSON object on stdout and
/// stderr.
fn failing(name: &str, args: &[&str]) -> (i32, Value, String) {
    let dir = tempdir(name);
    let o = run_in(&dir, args);
    let v: Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{e}: {} / {}", stdout(&o), stderr(&o)));
    (o.status.code().unwrap(), v, stderr(&o))
}

#[test]
fn failures_print_one_json_error_object() {
    let cases: &[(&[&str], &str, Option<&str>, &str)] = &[
        (
            &["slice", "nope.stl", "--json"],
            "io.not-found",
            Some("nope.stl"),
            "nope.stl: ",
        ),
        (
            &["run", "nope.dmdjob", "--json"],
            "io.not-found",
            Some("nope.dmdjob"),
            "nope.dmdjob: does not exist",
        ),
        (
            &["inspect", "nope.dmdjob", "--json"],
            "io.not-found",
            Some("nope.dmdjob"),
            "nope.dmdjob: does not exist",
        ),
        (
            &["inspect", "nope.dmdjob", "--json", "--chart", "c.gif"],
            "usage",
            None,
            "c.gif: cannot write pictures as .gif",
        ),
        (
            &["calibrate", "m.csv", "-o", "c.toml", "--json"],
            "io.not-found",
            Some("m.csv"),
            "m.csv: ",
        ),
        (
            &["distortion", "t.csv", "--json", "-p", "nope"],
            "profile.invalid",
            Some("nope"),
            "profile nope: ",
        ),
        (
            &["slice", "a.stl", "--json", "--dither", "sometimes"],
            "usage",
            None,
            "invalid value 'sometimes' for '--dither",
        ),
    ];
    for (args, code, file, message) in cases {
        let (exit, v, err) = failing("json-fail", args);
        assert_eq!(exit, 2, "{args:?}");
        assert_eq!(v["schema_version"], 1, "{args:?}");
        assert_eq!(v["ok"], false, "{args:?}");
        assert_eq!(v["error"]["code"], *code, "{args:?}: {v}");
        assert_eq!(v["error"]["file"].as_str(), *file, "{args:?}: {v}");
        let m = v["error"]["message"].as_str().unwrap();
        assert!(m.starts_with(message), "{args:?}: {m}");
        assert!(
            err.starts_with("dmdsl: error: ") || err.starts_with("error: "),
            "{err}"
        );
    }
}
