//! `dmdsl slice` in scripts and CI: several parts per call, a part from stdin, output
//! directories, profile overrides on the command line and placement options.

use crate::common::*;
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output, Stdio};

/// The pixel edge of the default profile, mm.
const P: f32 = 65.0 / 1024.0;

/// Writes a box of `w` × `d` × `h` mm with its lowest corner at the origin.
fn write_box(path: &Path, w: f32, d: f32, h: f32) {
    write_stl(path, &box_tris([0.0; 3], [w, d, h]));
}

/// The JSON Lines of stdout, one object per line.
fn json_lines(o: &Output) -> Vec<Value> {
    stdout(o)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

/// The manifest of the bundle at `bundle`.
fn manifest(bundle: &Path) -> Value {
    let f = bundle.join("job.json");
    serde_json::from_slice(&std::fs::read(&f).unwrap_or_else(|e| panic!("{}: {e}", f.display())))
        .unwrap()
}

/// Layer `layer`'s mask of the bundle at `bundle`.
fn mask(bundle: &Path, layer: usize) -> Vec<u8> {
    let job = manifest(bundle);
    let f = job["layers"][layer]["masks"][0]["file"].as_str().unwrap();
    let (w, h, px) = read_gray(&bundle.join(f));
    assert_eq!((w, h), (1024, 768));
    px
}

/// The lit pixels of a 1024 × 768 mask: (count, columns c0..c1, rows from the bottom
/// b0..b1), the ranges end-exclusive.
fn lit(m: &[u8]) -> (usize, [usize; 2], [usize; 2]) {
    let (mut c, mut b, mut n) = ([usize::MAX, 0], [usize::MAX, 0], 0);
    for (i, &v) in m.iter().enumerate() {
        if v > 0 {
            let (col, bottom) = (i % 1024, 767 - i / 1024);
            n += 1;
            c = [c[0].min(col), c[1].max(col + 1)];
            b = [b[0].min(bottom), b[1].max(bottom + 1)];
        }
    }
    (n, c, b)
}

/// Runs `dmdsl` with `args` in `cwd`, the file `input` on its stdin.
fn run_with_stdin(cwd: &Path, args: &[&str], input: &Path) -> Output {
    Command::new(bin())
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::from(std::fs::File::open(input).unwrap()))
        .output()
        .expect("run dmdsl")
}

#[test]
fn several_parts_one_bundle_each_and_a_broken_part_fails_alone() {
    let dir = tempdir("batch-parts");
    write_box(&dir.join("a.stl"), 10.0, 8.0, 1.0);
    write_box(&dir.join("c.stl"), 6.0, 6.0, 0.5);
    std::fs::write(dir.join("bad.stl"), b"not a mesh").unwrap();
    let args = [
        "slice",
        "a.stl",
        "bad.stl",
        "missing.stl",
        "c.stl",
        "--output-dir",
        "out/jobs",
        "--compensation",
        "off",
    ];
    let mut json_args = args.to_vec();
    json_args.push("--json");
    let o = run_in(&dir, &json_args);
    // The worst of the parts: two could not be read.
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    // The good parts were written all the same, into the directory made for them.
    assert_eq!(
        manifest(&dir.join("out/jobs/a.dmdjob"))["source"]["file"],
        "a.stl"
    );
    assert_eq!(
        manifest(&dir.join("out/jobs/c.dmdjob"))["source"]["file"],
        "c.stl"
    );
    let written: Vec<_> = std::fs::read_dir(dir.join("out/jobs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(written.len(), 2, "{written:?}");
    // One JSON object per line and part, in order, told apart by `ok` and `error.code`.
    let lines = json_lines(&o);
    assert_eq!(lines.len(), 4, "{}", stdout(&o));
    let inputs: Vec<&str> = lines.iter().map(|l| l["input"].as_str().unwrap()).collect();
    assert_eq!(inputs, ["a.stl", "bad.stl", "missing.stl", "c.stl"]);
    for l in &lines {
        assert_eq!(l["schema_version"], 1, "{l}");
    }
    let (a, bad, missing, c) = (&lines[0], &lines[1], &lines[2], &lines[3]);
    for (l, bundle, layers) in [(a, "out/jobs/a.dmdjob", 20), (c, "out/jobs/c.dmdjob", 10)] {
        assert_eq!(l["ok"], true, "{l}");
        assert_eq!(l["bundle"], bundle, "{l}");
        assert_eq!(l["layers"], layers, "{l}");
        assert!(l["totals"]["print_time_s"].as_f64().unwrap() > 0.0, "{l}");
        assert!(l.get("error").is_none(), "{l}");
    }
    assert_eq!(bad["ok"], false);
    assert_eq!(bad["error"]["code"], "input.malformed", "{bad}");
    assert_eq!(bad["error"]["file"], "bad.stl", "{bad}");
    assert!(
        bad["error"]["message"]
            .as_str()
            .unwrap()
            .starts_with("bad.stl: "),
        "{bad}"
    );
    assert!(bad.get("bundle").is_none(), "{bad}");
    assert_eq!(missing["ok"], false);
    assert_eq!(missing["error"]["code"], "io.not-found", "{missing}");
    let err = stderr(&o);
    assert!(err.contains("dmdsl: error: bad.stl: "), "{err}");
    assert!(err.contains("dmdsl: error: missing.stl: "), "{err}");

    // Without --json: the summary line of each part written, an error line for each other.
    std::fs::remove_dir_all(dir.join("out")).unwrap();
    let o = run_in(&dir, &args);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let out = stdout(&o);
    let summaries: Vec<&str> = out.lines().collect();
    assert_eq!(summaries.len(), 2, "{out}");
    assert!(
        summaries[0].starts_with("out/jobs/a.dmdjob: 20 layers"),
        "{out}"
    );
    assert!(
        summaries[1].starts_with("out/jobs/c.dmdjob: 10 layers"),
        "{out}"
    );
    assert!(
        stderr(&o).contains("of 4 parts, 2 failed (see the error lines above); exit code 2"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_denied_warning_fails_its_part_with_exit_1() {
    let dir = tempdir("batch-denied");
    write_box(&dir.join("a.stl"), 10.0, 8.0, 1.0);
    let island = fixture("island.stl");
    let o = run_in(
        &dir,
        &[
            "slice",
            "a.stl",
            island.to_str().unwrap(),
            "--output-dir",
            "out",
            "-W",
            "plan.unsupported-islands=error",
            "--json",
        ],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let lines = json_lines(&o);
    assert_eq!(lines.len(), 2, "{}", stdout(&o));
    assert_eq!(lines[0]["ok"], true);
    assert_eq!(lines[1]["ok"], false);
    assert!(lines[1].get("error").is_none(), "{}", lines[1]);
    let denied: Vec<&Value> = lines[1]["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|w| w["severity"] == "error")
        .collect();
    assert_eq!(denied.len(), 1, "{}", lines[1]);
    assert_eq!(denied[0]["code"], "plan.unsupported-islands");
    // Both bundles are written.
    assert!(dir.join("out/a.dmdjob/job.json").is_file());
    assert!(dir.join("out/island.dmdjob/job.json").is_file());
}

#[test]
fn parts_that_would_share_a_bundle_and_o_with_several_parts_are_usage_errors() {
    let dir = tempdir("batch-usage");
    std::fs::create_dir_all(dir.join("x")).unwrap();
    std::fs::create_dir_all(dir.join("y")).unwrap();
    write_box(&dir.join("x/p.stl"), 5.0, 5.0, 1.0);
    write_box(&dir.join("y/p.stl"), 5.0, 5.0, 1.0);
    let cases: [(&[&str], &str); 4] = [
        (
            &["slice", "x/p.stl", "y/p.stl"],
            "dmdsl: error: x/p.stl and y/p.stl would both write p.dmdjob",
        ),
        (
            &["slice", "x/p.stl", "y/p.stl", "--output-dir", "o"],
            "x/p.stl and y/p.stl would both write o/p.dmdjob",
        ),
        (
            &[
                "slice",
                "x/p.stl",
                "y/p.stl",
                "-o",
                "o.dmdjob",
                "--position",
                "1,1",
            ],
            "--position places a single part; a plate's parts are arranged",
        ),
        (
            &["slice", "x/p.stl", "-o", "o.dmdjob", "--output-dir", "o"],
            "cannot be used with",
        ),
    ];
    for (args, expect) in cases {
        let o = run_in(&dir, args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
    }
    // Nothing was written.
    let mut left: Vec<_> = std::fs::read_dir(&*dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, ["x", "y"]);
}

#[test]
fn a_part_from_stdin_needs_o_and_makes_the_same_masks() {
    let dir = tempdir("batch-stdin");
    let cube = fixture("cube10.stl");
    // Binary STL from stdin into a directory that does not exist yet.
    let o = run_with_stdin(
        &dir,
        &["slice", "-", "-o", "new/deeper/s.dmdjob", "-q"],
        &cube,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let job = manifest(&dir.join("new/deeper/s.dmdjob"));
    assert_eq!(job["source"]["file"], "<stdin>");
    // The same part from its file: the same masks and the same SHA-256 of the model.
    let o = run_in(
        &dir,
        &["slice", cube.to_str().unwrap(), "-o", "f.dmdjob", "-q"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let from_file = manifest(&dir.join("f.dmdjob"));
    assert_eq!(job["source"]["sha256"], from_file["source"]["sha256"]);
    assert_eq!(job["layers"], from_file["layers"]);
    let masks = |b: &str| {
        tree(&dir.join(b))
            .into_iter()
            .filter(|(p, _)| p != "job.json")
            .collect::<Vec<_>>()
    };
    assert_eq!(masks("new/deeper/s.dmdjob"), masks("f.dmdjob"));

    // ASCII STL is told apart by its content.
    let o = run_with_stdin(
        &dir,
        &["slice", "-", "-o", "a.dmdjob", "--json"],
        &fixture("cylinder_hole.stl"),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["mesh"]["format"], "stl-ascii");

    // Garbage on stdin is an input error naming stdin.
    let junk = dir.join("junk.bin");
    std::fs::write(&junk, b"hello").unwrap();
    let o = run_with_stdin(&dir, &["slice", "-", "-o", "j.dmdjob"], &junk);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).starts_with("dmdsl: error: <stdin>: "),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("j.dmdjob").exists());

    // Without -o, or with other parts: refused before stdin is read.
    for args in [
        &["slice", "-"][..],
        &["slice", "-", "x.stl", "--output-dir", "o"],
    ] {
        let o = run_with_stdin(&dir, args, &cube);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(
            stderr(&o).contains("reading a part from stdin (-) needs -o PATH"),
            "{}",
            stderr(&o)
        );
    }
}

#[test]
fn output_to_stdout_is_refused_and_parent_directories_are_made() {
    let dir = tempdir("batch-out");
    let cube = fixture("cube10.stl");
    let cube = cube.to_str().unwrap();
    for (args, expect) in [
        (
            vec!["slice", cube, "-o", "-"],
            "dmdsl: error: -o -: writing a bundle to stdout is not supported; give a directory path",
        ),
        (
            vec!["slice", cube, "--output-dir", "-"],
            "dmdsl: error: --output-dir -: writing bundles to stdout is not supported",
        ),
    ] {
        let o = run_in(&dir, &args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).starts_with(expect), "{args:?}: {}", stderr(&o));
        assert_eq!(stderr(&o).lines().count(), 1, "{}", stderr(&o));
        assert!(!dir.join("-").exists());
    }
    // Missing parents of -o and --output-dir are created.
    let o = run_in(&dir, &["slice", cube, "-q", "-o", "a/b/c.dmdjob"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.join("a/b/c.dmdjob/job.json").is_file());
    let o = run_in(&dir, &["slice", cube, "-q", "--output-dir", "d/e"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.join("d/e/cube10.dmdjob/job.json").is_file());
    // A part that fails leaves no directory made for it behind.
    let o = run_in(&dir, &["slice", "nope.stl", "-o", "f/g/h.dmdjob"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(!dir.join("f").exists());
}

#[test]
fn set_overrides_profile_keys_and_refuses_what_a_profile_file_would() {
    let dir = tempdir("batch-set");
    let cube = fixture("cube10.stl");
    let cube = cube.to_str().unwrap();
    let o = run_in(
        &dir,
        &[
            "slice",
            cube,
            "-q",
            "-o",
            "s.dmdjob",
            "--compensation",
            "off",
            "--set",
            "exposure.layer_s=5",
            "--set",
            "resin.name=Test resin",
            "--set",
            "exposure.transition_layers=0",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let job = manifest(&dir.join("s.dmdjob"));
    assert_eq!(job["machine"]["exposure"]["layer_s"], 5.0);
    assert_eq!(job["machine"]["resin"]["name"], "Test resin");
    let last = job["layers"].as_array().unwrap().last().unwrap().clone();
    assert_eq!(last["exposure_s"], 5.0);

    for (set, expect) in [
        (
            "exposure.layr_s=5",
            "dmdsl: error: profile xu2010-topdown: --set exposure.layr_s=5: unknown field `layr_s`, expected one of",
        ),
        (
            "exposure.layer_s=fast",
            "dmdsl: error: profile xu2010-topdown: --set exposure.layer_s=fast: invalid type: string \"fast\"",
        ),
        (
            "exposure.layer_s=0",
            "dmdsl: error: profile xu2010-topdown: --set exposure.layer_s=0: must be a finite number > 0, got 0",
        ),
        (
            "projector.3.width_px=10",
            "dmdsl: error: profile xu2010-topdown: --set projector.3.width_px=10: `projector` is a list of 1 entry; name one by its index, 0 to 0, as in projector.0.width_px",
        ),
        ("exposure", "dmdsl: error: --set exposure: expected section.key=value"),
    ] {
        let o = run_in(&dir, &["slice", cube, "-o", "x.dmdjob", "--set", set, "--json"]);
        assert_eq!(o.status.code(), Some(2), "{set}");
        let err = stderr(&o);
        assert!(err.starts_with(expect), "{set}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        let code = if set.contains('=') { "profile.invalid" } else { "usage" };
        assert_eq!(v["error"]["code"], code, "{v}");
        assert!(!dir.join("x.dmdjob").exists());
    }
}

#[test]
fn exposure_and_bottom_layers_reach_the_manifest() {
    let dir = tempdir("batch-exposure");
    let cube = fixture("cube10.stl");
    let cube = cube.to_str().unwrap();
    let o = run_in(
        &dir,
        &[
            "slice",
            cube,
            "-q",
            "-o",
            "e.dmdjob",
            "--compensation",
            "off",
            "--exposure",
            "5.5",
            "--bottom-layers",
            "4",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let job = manifest(&dir.join("e.dmdjob"));
    assert_eq!(job["machine"]["exposure"]["layer_s"], 5.5);
    // The 4 bottom layers get the default profile's bottom exposure, the next does not.
    let bottom = dmdsl::Profile::default_profile().exposure.bottom_s.get();
    let times: Vec<f64> = job["layers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["exposure_s"].as_f64().unwrap())
        .collect();
    assert_eq!(times[..4], [bottom; 4]);
    assert_ne!(times[4], bottom);
    assert_eq!(*times.last().unwrap(), 5.5);

    for (args, expect) in [
        (
            ["--exposure", "-2"],
            "--exposure must be a number of seconds > 0, got -2",
        ),
        // Beyond any job's layers (their sum with the transition layers overflowed).
        (
            ["--bottom-layers", "4294967295"],
            "profile xu2010-topdown: --bottom-layers 4294967295: exposure.bottom_layers = 4294967295 is more layers than a job may have (1000000)",
        ),
        (
            ["--bottom-layers", "-1"],
            "--bottom-layers must be a whole number >= 0, got -1",
        ),
        (
            ["--exposure", "2e7"],
            "profile xu2010-topdown: --exposure 2e7: exposure.layer_s = 20000000.0 is not a duration",
        ),
    ] {
        let mut a = vec!["slice", cube, "-o", "x.dmdjob"];
        a.extend(args);
        let o = run_in(&dir, &a);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
        assert_eq!(stderr(&o).lines().count(), 1, "{args:?}: {}", stderr(&o));
        assert!(!dir.join("x.dmdjob").exists(), "{args:?}");
    }
}

/// Slices `part` in `dir` with `extra` into `out` (no compensation: masks are coverage).
fn slice_box(dir: &Path, part: &str, out: &str, extra: &[&str]) -> Output {
    let mut args = vec!["slice", part, "-q", "--compensation", "off", "-o", out];
    args.extend_from_slice(extra);
    run_in(dir, &args)
}

#[test]
fn rotate_turns_the_part_before_it_is_placed() {
    let dir = tempdir("batch-rotate");
    // 320 × 160 pixels, 1 mm tall: centred, its edges fall on pixel edges either way.
    write_box(&dir.join("b.stl"), 320.0 * P, 160.0 * P, 1.0);
    for (out, extra) in [
        ("plain.dmdjob", &[][..]),
        ("z.dmdjob", &["--rotate", "90"][..]),
        ("xyz.dmdjob", &["--rotate", "0,0,-90"][..]),
    ] {
        let o = slice_box(&dir, "b.stl", out, extra);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
    }
    let plain = lit(&mask(&dir.join("plain.dmdjob"), 0));
    assert_eq!(plain, (320 * 160, [352, 672], [304, 464]));
    // X and Y extents swap; the area stays.
    for b in ["z.dmdjob", "xyz.dmdjob"] {
        assert_eq!(
            lit(&mask(&dir.join(b), 0)),
            (320 * 160, [432, 592], [224, 544]),
            "{b}"
        );
    }
    let placement = &manifest(&dir.join("z.dmdjob"))["source"]["placement"];
    assert_eq!(placement["rotate_deg"], serde_json::json!([0.0, 0.0, 90.0]));
    assert_eq!(placement["mode"], "center");
    // Without a rotation or scale the record is as before.
    let placement = &manifest(&dir.join("plain.dmdjob"))["source"]["placement"];
    assert!(placement.get("rotate_deg").is_none() && placement.get("scale").is_none());

    // A turn about X stands the box up: 1 mm deep, 160 pixels (10.16 mm) tall.
    let o = slice_box(&dir, "b.stl", "x.dmdjob", &["--rotate", "90,0,0"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let job = manifest(&dir.join("x.dmdjob"));
    assert_eq!(job["layers"].as_array().unwrap().len(), 203);
    let (_, cols, _) = lit(&mask(&dir.join("x.dmdjob"), 0));
    assert_eq!(cols, [352, 672]);

    for bad in ["1,2", "x", "nan", "1,2,inf"] {
        let o = slice_box(&dir, "b.stl", "bad.dmdjob", &["--rotate", bad]);
        assert_eq!(o.status.code(), Some(2), "{bad}");
        assert!(
            stderr(&o).contains(
                "--rotate must be degrees about Z (DEG) or about X, Y and Z (X,Y,Z), got"
            ),
            "{bad}: {}",
            stderr(&o)
        );
    }
}

#[test]
fn scale_sizes_the_part() {
    let dir = tempdir("batch-scale");
    write_box(&dir.join("b.stl"), 160.0 * P, 80.0 * P, 1.0);
    for (out, extra) in [
        ("plain.dmdjob", &[][..]),
        ("two.dmdjob", &["--scale", "2"][..]),
        ("x2.dmdjob", &["--scale", "2,1,1"][..]),
    ] {
        let o = slice_box(&dir, "b.stl", out, extra);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
    }
    let area = |b: &str| {
        let job = manifest(&dir.join(b));
        let layers = job["layers"].as_array().unwrap().len();
        (lit(&mask(&dir.join(b), 0)).0, layers)
    };
    let (a, layers) = area("plain.dmdjob");
    assert_eq!((a, layers), (160 * 80, 20));
    // Scaling X alone doubles the area; scaling every axis doubles X, Y and the height.
    assert_eq!(area("x2.dmdjob"), (2 * a, layers));
    assert_eq!(area("two.dmdjob"), (4 * a, 2 * layers));
    let placement = &manifest(&dir.join("x2.dmdjob"))["source"]["placement"];
    assert_eq!(placement["scale"], serde_json::json!([2.0, 1.0, 1.0]));

    for bad in ["0", "-1", "nan", "inf", "1,1", "1,0,1", "two"] {
        let o = slice_box(&dir, "b.stl", "bad.dmdjob", &["--scale", bad]);
        assert_eq!(o.status.code(), Some(2), "{bad}");
        assert!(
            stderr(&o).contains("--scale must be a factor > 0 or three, FX,FY,FZ, got"),
            "{bad}: {}",
            stderr(&o)
        );
    }
    // Scaled beyond the field: the existing error.
    let o = slice_box(&dir, "b.stl", "big.dmdjob", &["--scale", "10"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("b.stl: part is 101.56"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn position_moves_the_part_on_the_field() {
    let dir = tempdir("batch-position");
    write_box(&dir.join("b.stl"), 160.0 * P, 80.0 * P, 1.0);
    let at = format!("{},{}", 160.0 * P, 120.0 * P);
    let o = slice_box(&dir, "b.stl", "p.dmdjob", &["--position", &at]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        lit(&mask(&dir.join("p.dmdjob"), 0)),
        (160 * 80, [80, 240], [80, 160])
    );
    let job = manifest(&dir.join("p.dmdjob"));
    let placement = &job["source"]["placement"];
    assert_eq!(placement["mode"], "position");
    assert_eq!(
        placement["position_mm"],
        serde_json::json!([160.0 * P as f64, 120.0 * P as f64])
    );
    // The lowest point still goes to z = 0.
    assert_eq!(job["layers"].as_array().unwrap().len(), 20);
    // Negative numbers are read as values; a part off the field is refused.
    for (pos, expect) in [
        (
            "-5,10",
            "b.stl: with --position -5,10 the part spans x -10.078..0.078, y 7.461..12.539 mm, outside the build field 0..65.000 x 0..48.750 mm",
        ),
        (
            "60,10",
            "outside the build field",
        ),
        ("1", "--position must be X,Y in mm"),
        ("1,nan", "--position must be X,Y in mm"),
    ] {
        let o = slice_box(&dir, "b.stl", "bad.dmdjob", &["--position", pos]);
        assert_eq!(o.status.code(), Some(2), "{pos}");
        assert!(stderr(&o).contains(expect), "{pos}: {}", stderr(&o));
        assert!(!dir.join("bad.dmdjob").exists());
    }
    let o = slice_box(
        &dir,
        "b.stl",
        "k.dmdjob",
        &["--position", "5,5", "--keep-position"],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
}

#[test]
fn a_negative_layer_height_is_reported_as_such() {
    let dir = tempdir("batch-negative");
    let cube = fixture("cube10.stl");
    for v in ["-1", "-0.05", "-inf"] {
        let o = run_in(
            &dir,
            &["slice", cube.to_str().unwrap(), "--layer-height", v],
        );
        assert_eq!(o.status.code(), Some(2), "{v}");
        assert_eq!(
            stderr(&o),
            format!(
                "dmdsl: error: --layer-height must be a number > 0, got {}\n",
                v.parse::<f64>().unwrap()
            )
        );
    }
}

#[test]
fn an_interrupt_stops_every_part_at_once() {
    let dir = tempdir("batch-ctrlc");
    let bunny = fixture("bunny00.stl");
    write_box(&dir.join("a.stl"), 5.0, 5.0, 1.0);
    let child = Command::new(bin())
        .args([
            "slice",
            bunny.to_str().unwrap(),
            "a.stl",
            "--layer-height",
            "0.002",
            "--output-dir",
            "out",
            "--json",
        ])
        .current_dir(&dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .stoppable()
        .spawn()
        .unwrap();
    let staging = || {
        std::fs::read_dir(dir.join("out")).is_ok_and(|d| {
            d.filter_map(|e| e.ok()).any(|e| {
                e.file_name()
                    .to_string_lossy()
                    .starts_with(".bunny00.dmdjob.tmp")
            })
        })
    };
    let t = std::time::Instant::now();
    while !staging() {
        assert!(t.elapsed().as_secs() < 60, "no staging directory appeared");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    signal(&child, "INT");
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(err.contains("interrupted; nothing was written"), "{err}");
    assert!(err.contains("the 1 part after it was not sliced"), "{err}");
    let lines = json_lines(&out);
    assert_eq!(lines.len(), 1, "{}", stdout(&out));
    assert_eq!(lines[0]["error"]["code"], "interrupted");
    // The directory made for the bundles is gone again, with everything in it.
    let left: Vec<_> = std::fs::read_dir(&*dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, ["a.stl"], "{left:?}");
}
