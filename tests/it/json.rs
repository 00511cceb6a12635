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

/// Significant digits of the shortest text that gives `x` back (as `serde_json` prints it).
fn digits(x: f64) -> usize {
    let s = format!("{:e}", x.abs());
    s.split('e')
        .next()
        .unwrap()
        .chars()
        .filter(char::is_ascii_digit)
        .count()
}

/// Every number in `v` with its path.
fn numbers(v: &Value, at: String, out: &mut Vec<(String, f64)>) {
    match v {
        Value::Object(o) => o
            .iter()
            .for_each(|(k, x)| numbers(x, format!("{at}.{k}"), out)),
        Value::Array(a) => a.iter().for_each(|x| numbers(x, format!("{at}[]"), out)),
        Value::Number(n) if n.is_f64() => out.push((at, n.as_f64().unwrap())),
        _ => {}
    }
}

#[test]
fn fresh_manifests_hold_no_float_noise_and_replay_clean() {
    let dir = tempdir("json-numbers");
    let whole = |x: f64, per: f64| ((x * per).round() - x * per).abs() < 1e-6;
    for part in ["cube10.stl", "cylinder_hole.stl", "island.stl"] {
        for profile in [
            "xu2010-topdown",
            "hybrid-bottomup",
            "bottom-up",
            "tiled-2x1",
        ] {
            let out = format!("{profile}.dmdjob");
            let f = fixture(part);
            let o = run_in(
                &dir,
                &[
                    "slice",
                    f.to_str().unwrap(),
                    "-p",
                    profile,
                    "-o",
                    &out,
                    "-q",
                ],
            );
            assert_eq!(o.status.code(), Some(0), "{part} {profile}: {}", stderr(&o));
            let text = std::fs::read_to_string(dir.join(&out).join("job.json")).unwrap();
            let job: Value = serde_json::from_str(&text).unwrap();
            // Float noise (0.30000000000000004) shows as 16 or 17 digits; nothing here
            // has more than 9.
            let mut all = Vec::new();
            numbers(&job, String::new(), &mut all);
            for (at, x) in &all {
                assert!(digits(*x) <= 9, "{part} {profile}: {at} = {x}");
            }
            // Stage positions are whole steps, times whole milliseconds.
            let spm = job["machine"]["stage"]["steps_per_mm"].as_f64().unwrap();
            for l in job["layers"].as_array().unwrap() {
                assert!(whole(l["z_mm"].as_f64().unwrap(), spm), "{l}");
                assert!(whole(l["time_s"].as_f64().unwrap(), 1000.0), "{l}");
                for s in l["steps"].as_array().unwrap() {
                    if let Some(to) = s["to_mm"].as_f64() {
                        assert!(whole(to, spm), "{part} {profile}: {s}");
                    }
                    if let Some(t) = s["s"].as_f64() {
                        assert!(whole(t, 1000.0), "{part} {profile}: {s}");
                    }
                }
            }
            let t = &job["totals"];
            assert!(whole(t["print_time_s"].as_f64().unwrap(), 1000.0), "{t}");
            // The rounded steps replay as estimated: no violation, and the job's time is the
            // estimate to its 1 ms rounding.
            let o = run_in(&dir, &["run", &out, "--json"]);
            let r: Value = serde_json::from_slice(&o.stdout).unwrap();
            assert_eq!(r["ok"], true, "{part} {profile}: {}", r["violations"]);
            let (total, est) = (
                r["total_s"].as_f64().unwrap(),
                r["estimate_s"].as_f64().unwrap(),
            );
            assert!(
                (total - est).abs() <= 0.0005 + 1e-9 * est,
                "{part} {profile}: {total} vs {est}"
            );
            for l in r["per_layer"].as_array().unwrap() {
                let (t, e) = (
                    l["time_s"].as_f64().unwrap(),
                    l["estimate_s"].as_f64().unwrap(),
                );
                assert!((t - e).abs() <= 0.0005 + 1e-9 * e, "{part} {profile}: {l}");
            }
        }
    }
}
