//! Every warning code raised by its trigger (small parts, `--set` on the built-in profiles,
//! fixtures): each message has no floating-point noise, no internal names, no plural slip,
//! and ends with its code's remedy (`warning::CODES`, the remedy column of
//! docs/WARNINGS.md). Errors about outputs name the path the user gave.

use crate::common::*;
use dmdsl::text::{count, fixed, hms, number, plural, signed};
use dmdsl::warning::{lookup, CODES};
use serde_json::Value;
use std::path::Path;

/// The warnings of `dmdsl ARGS --json` run in `dir` (which must succeed).
fn raised(dir: &Path, args: &[&str]) -> Vec<Value> {
    let mut a = args.to_vec();
    a.push("--json");
    let o = run_in(dir, &a);
    let v: Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{args:?}: {e}: {} / {}", stdout(&o), stderr(&o)));
    assert!(o.status.success(), "{args:?}: {v}");
    v["warnings"].as_array().cloned().unwrap_or_default()
}

/// Nouns whose plural a count must agree with.
const NOUNS: &[&str] = &[
    "layer",
    "feature",
    "contour",
    "pixel",
    "island",
    "point",
    "zone",
    "slice",
    "edge",
    "triangle",
    "projector",
    "step",
    "move",
    "image",
    "region",
];

/// What is wrong with `message` of code `code`, if anything.
fn problems(code: &str, message: &str) -> Vec<String> {
    let mut out = Vec::new();
    // Floating-point noise: a run of 5 or more decimals.
    let b = message.as_bytes();
    for (i, _) in message.match_indices('.') {
        let digits = b[i + 1..].iter().take_while(|c| c.is_ascii_digit()).count();
        if digits >= 5 && i > 0 && b[i - 1].is_ascii_digit() {
            out.push(format!(
                "float noise at {:?}",
                &message[i - 1..i + 1 + digits]
            ));
        }
    }
    // Internal names and Rust formatting.
    for bad in [
        "-import", ".tmp-", "Some(", "None", "NaN", "{", "}", "-0.00",
    ] {
        if message.contains(bad) {
            out.push(format!("internal text {bad:?}"));
        }
    }
    // Plurals: "1 layers", and a verb that does not agree.
    let words: Vec<&str> = message.split_whitespace().collect();
    for w in words.windows(2) {
        let n = w[0].trim_start_matches('(');
        let noun = w[1].trim_end_matches([',', ';', ':', ')']);
        if n == "1" && NOUNS.iter().any(|s| noun == format!("{s}s")) {
            out.push(format!("plural: {} {}", w[0], w[1]));
        }
        if n.parse::<u64>().is_ok_and(|k| k > 1) && NOUNS.contains(&noun) {
            out.push(format!("singular: {} {}", w[0], w[1]));
        }
    }
    for slip in [
        " it cure ",
        " it cure,",
        " they cures",
        " it need ",
        " they needs",
    ] {
        if message.contains(slip) {
            out.push(format!("grammar: {slip:?}"));
        }
    }
    // The remedy closes the message.
    let remedy = lookup(code).map_or("", |c| c.remedy);
    if remedy.is_empty() || !message.ends_with(&format!("; {remedy}")) {
        out.push(format!("does not end with the remedy {remedy:?}"));
    }
    out
}

/// Checks every warning of `ws` and that together they raise each of `codes`.
fn check(ws: &[Value], codes: &[&str]) {
    let mut bad = Vec::new();
    for w in ws {
        let (code, msg) = (w["code"].as_str().unwrap(), w["message"].as_str().unwrap());
        for p in problems(code, msg) {
            bad.push(format!("[{code}] {p}: {msg}"));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    for c in codes {
        assert!(
            ws.iter().any(|w| w["code"] == *c),
            "{c} not raised: {:?}",
            ws.iter().map(|w| &w["code"]).collect::<Vec<_>>()
        );
    }
}

/// Writes the parts the triggers slice into `dir`.
fn parts(dir: &Path) {
    write_stl(
        &dir.join("small.stl"),
        &box_tris([0.0; 3], [10.0, 10.0, 1.0]),
    );
    // One facet missing, one flipped: open and backwards edges, contours repaired.
    let mut t = box_tris([10.0, 10.0, 0.0], [20.0, 20.0, 1.0]);
    t.remove(7);
    t[4] = [t[4][0], t[4][2], t[4][1]];
    write_stl(&dir.join("broken.stl"), &t);
    // A facet twice (non-manifold edges) and one with a repeated corner.
    let mut t = box_tris([0.0; 3], [10.0, 10.0, 1.0]);
    t.push(t[0]);
    t.push([t[1][0], t[1][0], t[1][1]]);
    write_stl(&dir.join("odd.stl"), &t);
    let t: Vec<_> = box_tris([0.0; 3], [10.0, 10.0, 1.0])
        .into_iter()
        .map(|f| [f[0], f[2], f[1]])
        .collect();
    write_stl(&dir.join("inverted.stl"), &t);
    // 47 mm tall in y: past the default calibration's y 0..45 mm.
    write_stl(&dir.join("tall.stl"), &box_tris([0.0; 3], [5.0, 47.0, 1.0]));
    // Two blocks 0.03 mm apart: the gap cures across.
    let mut t = box_tris([0.0; 3], [5.0, 5.0, 0.5]);
    t.extend(box_tris([5.03, 0.0, 0.0], [10.0, 5.0, 0.5]));
    write_stl(&dir.join("slot.stl"), &t);
    write_stl(&dir.join("ring.stl"), &ring([20.0, 20.0], 5.0, 0.03, 0.3));
    // A 5 mm prism: the hybrid process prints it continuously.
    write_stl(&dir.join("prism.stl"), &box_tris([0.0; 3], [5.0, 5.0, 1.2]));
    // The lens table's corner x, y <= 30 mm: the small part reaches past it.
    let table = std::fs::read_to_string(fixture("lens_table.csv")).unwrap();
    let corner: Vec<&str> = (table.lines())
        .filter(|l| {
            let f: Vec<f64> = l.split(',').filter_map(|v| v.parse().ok()).collect();
            f.len() < 4 || (f[0] <= 30.0 && f[1] <= 30.0)
        })
        .collect();
    std::fs::write(dir.join("corner_lens.csv"), corner.join("\n") + "\n").unwrap();
}

/// A square ring, outer side `side` from corner `at`, walls `wall` wide, `h` tall.
fn ring(at: [f32; 2], side: f32, wall: f32, h: f32) -> Vec<[[f32; 3]; 3]> {
    let sq = |d: f32| {
        let (a, b) = (d, side - d);
        [[a, a], [b, a], [b, b], [a, b]].map(|[x, y]| [at[0] + x, at[1] + y])
    };
    let (o, i) = (sq(0.0), sq(wall));
    let p = |q: [f32; 2], z: f32| [q[0], q[1], z];
    let mut t = Vec::new();
    let mut quad = |a, b, c, d| t.extend([[a, b, c], [a, c, d]]);
    for k in 0..4 {
        let n = (k + 1) % 4;
        quad(p(o[k], h), p(o[n], h), p(i[n], h), p(i[k], h));
        quad(p(i[k], 0.0), p(i[n], 0.0), p(o[n], 0.0), p(o[k], 0.0));
        quad(p(o[k], 0.0), p(o[n], 0.0), p(o[n], h), p(o[k], h));
        quad(p(i[n], 0.0), p(i[k], 0.0), p(i[k], h), p(i[n], h));
    }
    t
}

const ABSOLUTE: &str = "projector.0.calibration.units=mW/cm2";

#[test]
fn mesh_plan_and_exposure_messages_name_a_remedy() {
    let dir = tempdir("messages-plan");
    parts(&dir);
    let mut ws = Vec::new();
    let broken = [
        "slice",
        "broken.stl",
        "-o",
        "b.dmdjob",
        "--layer-height",
        "0.1",
    ];
    ws.extend(raised(&dir, &broken));
    ws.extend(raised(&dir, &["slice", "odd.stl", "-o", "o.dmdjob"]));
    ws.extend(raised(&dir, &["slice", "inverted.stl", "-o", "i.dmdjob"]));
    let lens = ["--distortion", "corner_lens.csv"];
    ws.extend(raised(
        &dir,
        &[&["slice", "small.stl", "-o", "d.dmdjob"][..], &lens].concat(),
    ));
    let top = ["--set", "stage.travel_max_mm=3"];
    ws.extend(raised(
        &dir,
        &[&["slice", "small.stl", "-o", "t.dmdjob"][..], &top].concat(),
    ));
    ws.extend(raised(
        &dir,
        &[
            "slice",
            "small.stl",
            "-o",
            "h.dmdjob",
            "-p",
            "hybrid-bottomup",
            "--scale",
            "2",
            "--set",
            "hybrid.olh.2.up_to_mm=8",
        ],
    ));
    ws.extend(raised(
        &dir,
        &[
            "slice",
            "small.stl",
            "-o",
            "bl.dmdjob",
            "--bottom-layers",
            "100",
        ],
    ));
    let island = fixture("island.stl");
    ws.extend(raised(
        &dir,
        &["slice", island.to_str().unwrap(), "-o", "is.dmdjob"],
    ));
    // The executor finds the island in the masks.
    ws.extend(raised(&dir, &["run", "is.dmdjob"]));
    let deep = ["--set", ABSOLUTE, "--set", "resin.dp_mm=0.00001"];
    ws.extend(raised(
        &dir,
        &[&["slice", "small.stl", "-o", "e.dmdjob"][..], &deep].concat(),
    ));
    let bright = [
        "--set",
        ABSOLUTE,
        "--set",
        "projector.0.calibration.field.scale=1e4",
    ];
    ws.extend(raised(
        &dir,
        &[&["slice", "small.stl", "-o", "f.dmdjob"][..], &bright].concat(),
    ));
    check(&ws, PLAN_CODES);
}

/// The codes [`mesh_plan_and_exposure_messages_name_a_remedy`] raises.
const PLAN_CODES: &[&str] = &[
    "mesh.open-edges",
    "mesh.nonmanifold-edges",
    "mesh.backwards-edges",
    "mesh.degenerate-facets",
    "mesh.inverted-normals",
    "slice.contours-repaired",
    "distortion.extrapolated",
    "plan.wait-capped",
    "plan.travel-clamped",
    "plan.beyond-lift-table",
    "plan.bottom-layers-cover-job",
    "plan.unsupported-islands",
    "run.unsupported-regions",
    "exposure.implausible-dose",
    "exposure.too-long",
    "exposure.too-short",
    "exposure.not-positive",
];

#[test]
fn cure_optics_and_calibrate_messages_name_a_remedy() {
    let dir = tempdir("messages-optics");
    parts(&dir);
    let mut ws = Vec::new();
    let pin = fixture("thin_pin.stl");
    // As cure_widen.rs slices it: the top layer's pin vanishes, the others are widened.
    let pin = [
        "slice",
        pin.to_str().unwrap(),
        "-o",
        "p.dmdjob",
        "--keep-position",
        "--compensation",
        "off",
        "--predict",
        "--cure-correction",
        "xy",
    ];
    let widened = raised(&dir, &pin);
    let w = widened
        .iter()
        .find(|w| w["code"] == "cure.features-widened");
    let msg = w.expect("the pin is widened")["message"].as_str().unwrap();
    assert!(msg.contains("so that they cure"), "{msg}");
    assert!(
        !msg.contains("thin part"),
        "the pin's box shows its size: {msg}"
    );
    ws.extend(widened);
    // A 5 mm ring with 0.03 mm walls: its box does not say what is thin, the message does.
    let ring = [
        "slice",
        "ring.stl",
        "-o",
        "r.dmdjob",
        "--keep-position",
        "--compensation",
        "off",
    ];
    let ring = raised(
        &dir,
        &[&ring[..], &["--predict", "--cure-correction", "xy"]].concat(),
    );
    let w = ring.iter().find(|w| w["code"] == "cure.features-widened");
    let msg = w.expect("the ring is widened")["message"].as_str().unwrap();
    assert!(
        msg.contains("5 × 5 mm, its thin part 0.03 mm wide)"),
        "{msg}"
    );
    ws.extend(ring);
    // A pin like the one above in mid-air, over nothing: left as the correction draws it.
    let mut floating = box_tris([10.0, 10.0, 0.0], [14.0, 14.0, 1.0]);
    floating.extend(box_tris([20.0, 20.0, 1.0], [20.04, 20.04, 1.5]));
    write_stl(&dir.join("floating_pin.stl"), &floating);
    let args = [
        "slice",
        "floating_pin.stl",
        "-o",
        "f.dmdjob",
        "--compensation",
        "off",
    ];
    let on_nothing = raised(&dir, &[&args[..], &["--cure-correction", "xy"]].concat());
    let w = on_nothing
        .iter()
        .find(|w| w["code"] == "cure.features-on-nothing");
    let msg = w.expect("the pin is over nothing")["message"]
        .as_str()
        .unwrap();
    assert!(
        msg.contains(
            "rest on nothing in the layer below, so they were not drawn wider, in 10 layers"
        ),
        "{msg}"
    );
    ws.extend(on_nothing);
    let tab = fixture("tab2.stl");
    let tab = [
        "slice",
        tab.to_str().unwrap(),
        "-o",
        "t.dmdjob",
        "--cure-correction",
        "xyz",
    ];
    ws.extend(raised(&dir, &tab));
    let slot = [
        "slice",
        "slot.stl",
        "-o",
        "s.dmdjob",
        "--predict",
        "--cure-correction",
        "off",
    ];
    ws.extend(raised(&dir, &slot));
    // Turned, with binary masks: two layers the correction leaves unheld are drawn plain.
    let bunny = fixture("bunny00.stl");
    let turned = [bunny.to_str().unwrap(), "--supports", "--rotate", "60,0,20"];
    let turned = [&["slice"][..], &turned, &["--binary", "-o", "u.dmdjob"]].concat();
    ws.extend(raised(&dir, &turned));
    // Within the default 5 mm extrapolation: a note with the distance.
    let within = raised(&dir, &["slice", "tall.stl", "-o", "a.dmdjob"]);
    let note = within
        .iter()
        .find(|w| w["code"] == "optics.outside-calibrated-area");
    let note = note.expect("the tall part reaches outside");
    assert_eq!(note["severity"], "note", "{note}");
    let beyond = note["fields"]["beyond_mm"].as_f64().unwrap();
    // The part's top edge is at 47.875 mm; the farthest pixel centre half a pixel about it.
    assert!((beyond - 2.875).abs() < 0.04, "{note}");
    assert!(
        note["message"]
            .as_str()
            .unwrap()
            .contains("up to 2.89 mm beyond"),
        "{note}"
    );
    ws.extend(within);
    let margin = ["--set", "projector.0.calibration.field.extrapolate_mm=1"];
    ws.extend(raised(
        &dir,
        &[&["slice", "tall.stl", "-o", "b.dmdjob"][..], &margin].concat(),
    ));
    let dim = [
        "--set",
        "projector.0.calibration.field.coefficients.yyy=-2",
        "--set",
        "projector.0.calibration.field.coefficients.yy=20",
    ];
    ws.extend(raised(
        &dir,
        &[&["slice", "tall.stl", "-o", "c.dmdjob"][..], &dim].concat(),
    ));
    // Measurements: noisy (poor fit), high grays only, a field too steep to flatten.
    let csv = std::fs::read_to_string(fixture("measurements.csv")).unwrap();
    let rows: Vec<Vec<f64>> = (csv.lines())
        .filter_map(|l| l.split(',').map(|v| v.parse().ok()).collect())
        .collect();
    let write = |name: &str, f: &dyn Fn(usize, &[f64]) -> Option<f64>| {
        let mut s = String::from("x_mm,y_mm,gray,irradiance_mw_cm2\n");
        for (i, r) in rows.iter().enumerate() {
            if let Some(e) = f(i, r) {
                s += &format!("{},{},{},{e}\n", r[0], r[1], r[2]);
            }
        }
        std::fs::write(dir.join(name), s).unwrap();
    };
    write("noisy.csv", &|i, r| Some(r[3] * [0.5, 1.5, 1.0][i % 3]));
    write("high.csv", &|_, r| (r[2] >= 191.0).then_some(r[3]));
    write("steep.csv", &|_, r| Some(r[3] * (5.0 * r[0] / 65.0).exp()));
    for m in ["noisy", "high", "steep"] {
        let (i, o) = (format!("{m}.csv"), format!("{m}.toml"));
        ws.extend(raised(&dir, &["calibrate", &i, "-o", &o, "--no-plots"]));
    }
    check(&ws, OPTICS_CODES);
}

/// The codes [`cure_optics_and_calibrate_messages_name_a_remedy`] raises.
const OPTICS_CODES: &[&str] = &[
    "cure.features-vanish",
    "cure.features-widened",
    "cure.features-on-nothing",
    "cure.features-dropped",
    "cure.layers-uncorrected",
    "cure.features-merge",
    "optics.outside-calibrated-area",
    "optics.beyond-extrapolation",
    "optics.unreachable",
    "calibrate.poor-fit",
    "calibrate.low-grays-unmeasured",
    "calibrate.spread-remains",
];

#[test]
fn export_and_bundle_messages_name_a_remedy() {
    let dir = tempdir("messages-export");
    parts(&dir);
    let slice = |out: &str, more: &[&str]| {
        let o = run_in(
            &dir,
            &[&["slice", "small.stl", "-o", out, "-q"][..], more].concat(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
    };
    slice("td.dmdjob", &[]);
    slice("hy.dmdjob", &["-p", "hybrid-bottomup"]);
    slice("tl.dmdjob", &["-p", "tiled-2x1"]);
    slice(
        "mi.dmdjob",
        &["-p", "bottom-up", "--set", "projector.0.mirror_y=true"],
    );
    let o = run_in(
        &dir,
        &[
            "slice",
            "prism.stl",
            "-o",
            "pr.dmdjob",
            "-p",
            "hybrid-bottomup",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let channel = fixture("control/channel.zip");
    let channel = channel.to_str().unwrap();
    let mut ws = Vec::new();
    for (job, out, format) in [
        ("td.dmdjob", "td.sl1", None),
        ("td.dmdjob", "td.zip", Some("sla-control")),
        ("hy.dmdjob", "hy.zip", Some("sla-control")),
        ("tl.dmdjob", "tl.zip", Some("sla-control")),
        ("mi.dmdjob", "mi.nanodlp", None),
        (channel, "ch.sl1", None),
        (channel, "ch.nanodlp", None),
        ("pr.dmdjob", "pr.sl1", None),
    ] {
        let mut a = vec!["export", job, "-o", out];
        if let Some(f) = format {
            a.extend(["--format", f]);
        }
        ws.extend(raised(&dir, &a));
    }
    // A version 1 bundle's warnings were text: read as `bundle.uncoded`.
    let b = dir.join("td.dmdjob");
    let mut j: Value = serde_json::from_slice(&std::fs::read(b.join("job.json")).unwrap()).unwrap();
    for l in j["layers"].as_array_mut().unwrap() {
        l["masks"][0].as_object_mut().unwrap().remove("pixels");
    }
    j["machine"] = serde_json::to_value(dmdsl::Profile::default_profile()).unwrap();
    j["version"] = 1.into();
    j["warnings"] = serde_json::json!(["mesh has 3 open edges (holes)"]);
    std::fs::write(b.join("job.json"), serde_json::to_vec(&j).unwrap()).unwrap();
    let o = run_in(&dir, &["export", "td.dmdjob", "-o", "v4.dmdjob", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v4: Value =
        serde_json::from_slice(&std::fs::read(dir.join("v4.dmdjob/job.json")).unwrap()).unwrap();
    ws.extend(v4["warnings"].as_array().unwrap().iter().cloned());
    check(&ws, EXPORT_CODES);
}

/// The codes [`export_and_bundle_messages_name_a_remedy`] raises.
const EXPORT_CODES: &[&str] = &[
    "export.sl1-exposure",
    "export.sl1-layer-thickness",
    "export.sl1-continuous",
    "export.sl1-steps",
    "export.sl1-display",
    "export.control-assumed",
    "export.control-steps",
    "export.control-split-exposure",
    "export.control-sequential",
    "export.nanodlp-exposure",
    "export.nanodlp-layer-thickness",
    "export.nanodlp-steps",
    "export.nanodlp-mirror",
    "bundle.uncoded",
];

#[test]
fn the_message_tests_trigger_every_code() {
    let tested: Vec<&str> = [PLAN_CODES, OPTICS_CODES, EXPORT_CODES].concat();
    let all: Vec<&str> = CODES.iter().map(|c| c.code).collect();
    let mut sorted = tested.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert_eq!(sorted.len(), tested.len(), "a code listed twice");
    for c in &all {
        assert!(
            tested.contains(c),
            "{c} has no trigger in tests/it/messages.rs"
        );
    }
    assert_eq!(tested.len(), all.len());
    // The checks catch what they are for.
    let r = lookup("plan.travel-clamped").unwrap().remedy;
    let ok = format!("1 lift or dip was shortened to end at 2 mm; {r}");
    assert!(problems("plan.travel-clamped", &ok).is_empty());
    for bad in [
        format!("1 layers shortened to 13.333333333333334 mm; {r}"),
        format!("a feature drawn wider so it cure, in 2 layer; {r}"),
        "3 lifts shortened".to_string(),
        format!("sliced for sla-control-import from .x.dmdjob.tmp-12; {r}"),
    ] {
        assert!(!problems("plan.travel-clamped", &bad).is_empty(), "{bad}");
    }
}

#[test]
fn output_errors_name_the_path_given() {
    let dir = tempdir("messages-outputs");
    parts(&dir);
    std::fs::write(dir.join("ro"), "a file").unwrap();
    let o = run_in(&dir, &["slice", "small.stl", "-o", "ok.dmdjob", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let csv = fixture("measurements.csv");
    let cases: [(&[&str], &str); 7] = [
        (&["slice", "small.stl", "-o", "ro/x.dmdjob"], "ro/x.dmdjob"),
        (
            &["slice", "small.stl", "-o", "ro/x.dmdjob.zip"],
            "ro/x.dmdjob.zip",
        ),
        (&["slice", "small.stl", "-o", "ro/x.sl1"], "ro/x.sl1"),
        (
            &[
                "export",
                "ok.dmdjob",
                "-o",
                "ro/x.zip",
                "--format",
                "sla-control",
            ],
            "ro/x.zip",
        ),
        (
            &["export", "ok.dmdjob", "-o", "ro/x.nanodlp"],
            "ro/x.nanodlp",
        ),
        (&["run", "ok.dmdjob", "--trace", "ro/t.csv"], "ro/t.csv"),
        (
            &["calibrate", csv.to_str().unwrap(), "-o", "ro/c.toml"],
            "ro/c.toml",
        ),
    ];
    for (args, out) in cases {
        let o = run_in(&dir, args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(
            err.contains(&format!("{out}: ro is not a directory")),
            "{args:?}: {err}"
        );
        assert!(!err.contains(".tmp-"), "{args:?}: {err}");
    }
    // Nothing half-written is left.
    let left: Vec<String> = (dir.read_dir().unwrap())
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

// The one formatter every number in a message goes through (`dmdsl::text`).
#[test]
fn counts_and_durations() {
    assert_eq!(count(1, "layer", "layers"), "1 layer");
    assert_eq!(count(0, "layer", "layers"), "0 layers");
    assert_eq!(plural(2, "is", "are"), "are");
    assert_eq!(hms(0.4), "0h00m00s");
    assert_eq!(hms(-5.0), "0h00m00s");
    assert_eq!(hms(37858.4), "10h30m58s");
    assert_eq!(hms(3723.4), "1h02m03s");
}

#[test]
fn numbers_are_short_and_free_of_noise() {
    for (v, want) in [
        (25.0, "25"),
        (0.9, "0.9"),
        (-0.0, "0"),
        (5.00125, "5.00125"),
        (0.00125, "0.00125"),
        (16.0 / 3.0, "5.33333"),
        (123456.789, "123457"),
        (999999.7, "1000000"),
        (1.23456789e-7, "1.23457e-7"),
        (-1e12, "-1e12"),
        (f64::INFINITY, "inf"),
    ] {
        assert_eq!(number(v), want, "{v}");
    }
    assert_eq!(fixed(500.0, 4), "500.0000");
    assert_eq!(fixed(-1e12, 3), "-1.0000e12");
    assert_eq!(fixed(1e300, 4), "1.0000e300");
    assert_eq!(signed(2.0444, 2), "+2.04");
    assert_eq!(signed(-0.001, 2), "0.00");
    assert_eq!(signed(0.004, 2), "0.00");
    assert_eq!(signed(-0.0, 0), "0");
    assert_eq!(signed(-0.006, 2), "-0.01");
    assert_eq!(signed(f64::INFINITY, 2), "+inf");
    assert_eq!(signed(2e300, 2), "+2.0000e300");
}
