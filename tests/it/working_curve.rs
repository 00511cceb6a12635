//! `dmdsl testjob working-curve` and `dmdsl calibrate resin`: the test job's sheet, filled in
//! from a chosen working curve Cd = Dp·ln(E/Ec) with fixed-seed noise, is fitted back to
//! the chosen values; the job runs clean and exports; bad sheets are refused in one line
//! naming the file, line and column, with nothing written.

use crate::common::*;
use std::path::Path;

/// Normal deviates of standard deviation `sd` (xorshift64 and Box–Muller; fixed `seed`).
fn noise(seed: u64, sd: f64) -> impl FnMut() -> f64 {
    let mut s = seed.max(1);
    let mut u = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    move || sd * (-2.0 * (1.0 - u()).ln()).sqrt() * (std::f64::consts::TAU * u()).cos()
}

/// Fills the sheet's `cured_mm` from Cd = dp·ln(E/ec) plus noise, E the dose where the sheet
/// has one, else the exposure; windows below `ec` get 0 (nothing cured). Returns the
/// number of cured windows.
fn fill(path: &Path, dp: f64, ec: f64, sd: f64, seed: u64) -> usize {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let head = lines.next().unwrap();
    assert_eq!(
        head,
        "window,x_mm,y_mm,gray,exposure_s,dose_mj_cm2,cured_mm"
    );
    let (mut out, mut cured, mut n) = (format!("{head}\n"), 0, noise(seed, sd));
    for l in lines {
        let c: Vec<&str> = l.split(',').collect();
        assert_eq!((c.len(), c[6]), (7, ""), "{l}");
        let e: f64 = c[5].parse().or_else(|_| c[4].parse()).unwrap();
        let cd = dp * (e / ec).ln();
        let cd = if cd > 0.0 { (cd + n()).max(0.001) } else { 0.0 };
        cured += usize::from(cd > 0.0);
        out += &format!("{},{cd:.4}\n", c[..6].join(","));
    }
    std::fs::write(path, out).unwrap();
    cured
}

/// A key's number in the resin calibration TOML `text`.
fn key(text: &str, k: &str) -> f64 {
    let v: toml::Value = toml::from_str(text).unwrap();
    v[k].as_float().unwrap_or_else(|| panic!("{k} in {text}"))
}

fn ok(o: &std::process::Output) -> String {
    assert!(o.status.success(), "{}", stderr(o));
    stdout(o)
}

#[test]
fn relative_working_curve_is_fitted_back_and_the_job_runs_and_exports() {
    let dir = tempdir("wc-relative");
    // The default profile: a relative light calibration, so doses are exposure times at E*.
    let out = ok(&run_in(
        &dir,
        &["testjob", "working-curve", "-o", "wc.dmdjob"],
    ));
    assert!(out.contains("12 windows"), "{out}");
    let sheet = std::fs::read_to_string(dir.join("wc.csv")).unwrap();
    assert_eq!(sheet.lines().count(), 13);
    assert!(sheet.lines().skip(1).all(|l| l.ends_with(",,")), "{sheet}");
    ok(&run_in(&dir, &["run", "wc.dmdjob"]));
    ok(&run_in(&dir, &["export", "wc.dmdjob", "-o", "wc.sl1"]));
    assert_exports_to_control(&dir, "wc.dmdjob");
    let (dp, tc) = (0.12, 8.0);
    assert!(fill(&dir.join("wc.csv"), dp, tc, 0.004, 7) >= 8);
    let out = ok(&run_in(
        &dir,
        &["calibrate", "resin", "wc.csv", "-o", "resin.toml"],
    ));
    assert!(
        out.contains("Dp = ") && out.contains("critical exposure"),
        "{out}"
    );
    let t = std::fs::read_to_string(dir.join("resin.toml")).unwrap();
    assert_rounded_numbers(&t);
    let (fdp, ftc) = (key(&t, "dp_mm"), key(&t, "critical_exposure_s"));
    eprintln!("relative: Dp {fdp:.5} mm (chosen {dp}), Tc {ftc:.4} s (chosen {tc})");
    assert!((fdp - dp).abs() < 0.05 * dp, "Dp {fdp}");
    assert!((ftc - tc).abs() < 0.08 * tc, "Tc {ftc}");
    assert!(
        key(&t, "dp_se_mm") > 0.0 && key(&t, "residual_rms_mm") < 0.008,
        "{t}"
    );
    let png = std::fs::read(dir.join("resin.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG"));
    // The fitted Dp goes into a job; job.json says where it came from.
    let part = fixture("cube10.stl");
    let part = part.to_str().unwrap();
    ok(&run_in(
        &dir,
        &["slice", part, "-o", "c.dmdjob", "--resin", "resin.toml"],
    ));
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("c.dmdjob/job.json")).unwrap()).unwrap();
    let c = &j["cure"];
    assert_eq!(c["dp_mm"].as_f64().unwrap(), fdp);
    assert!(c["sources"]["dp_mm"]
        .as_str()
        .unwrap()
        .starts_with("wc.csv sha256:"));
    assert_eq!(c["sources"]["ec_mj_cm2"], "assumed");
    assert_eq!(c["sources"]["psf_sigma_px"], "assumed");
    // With the fitted Dp, the feature part's prediction is the one of Dp typed in.
    let typed = format!("resin.dp_mm={fdp}");
    let fitted = predicted_cure(&dir, "f.dmdjob", &["--resin", "resin.toml"]);
    assert_eq!(fitted, predicted_cure(&dir, "t.dmdjob", &["--set", &typed]));
    assert!(
        fitted["edge_error_px"]["mean"].as_f64().unwrap() < 0.05,
        "{fitted}"
    );
}

#[test]
fn absolute_working_curve_recovers_dp_and_ec() {
    let dir = tempdir("wc-absolute");
    let m = fixture("measurements.csv");
    let args = [
        "calibrate",
        m.to_str().unwrap(),
        "-o",
        "cal.toml",
        "--no-plots",
    ];
    ok(&run_in(&dir, &args));
    let args = [
        "testjob",
        "working-curve",
        "-o",
        "abs.sl1",
        "-p",
        "bottom-up",
        "--calibration",
        "cal.toml",
        "--windows",
        "10",
        "--exposure",
        "2..40",
    ];
    ok(&run_in(&dir, &args));
    ok(&run_in(&dir, &["run", "abs.sl1"]));
    let sheet = std::fs::read_to_string(dir.join("abs.csv")).unwrap();
    assert!(sheet
        .lines()
        .skip(1)
        .all(|l| !l.split(',').nth(5).unwrap().is_empty()));
    let (dp, ec) = (0.15, 8.0);
    assert!(fill(&dir.join("abs.csv"), dp, ec, 0.005, 11) >= 6);
    let out = ok(&run_in(
        &dir,
        &["calibrate", "resin", "abs.csv", "-o", "r.toml"],
    ));
    assert!(out.contains("mJ/cm²"), "{out}");
    let t = std::fs::read_to_string(dir.join("r.toml")).unwrap();
    let (fdp, fec) = (key(&t, "dp_mm"), key(&t, "ec_mj_cm2"));
    eprintln!("absolute: Dp {fdp:.5} mm (chosen {dp}), Ec {fec:.4} mJ/cm² (chosen {ec})");
    assert!((fdp - dp).abs() < 0.05 * dp, "Dp {fdp}");
    assert!((fec - ec).abs() < 0.1 * ec, "Ec {fec}");
    let part = fixture("cube10.stl");
    let args = [
        "slice",
        part.to_str().unwrap(),
        "-p",
        "bottom-up",
        "--resin",
        "r.toml",
    ];
    ok(&run_in(&dir, &args));
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("cube10.dmdjob/job.json")).unwrap())
            .unwrap();
    assert!(j["cure"]["sources"]["ec_mj_cm2"]
        .as_str()
        .unwrap()
        .starts_with("abs.csv sha256:"));
}

#[test]
fn bad_sheets_are_refused_in_one_line_naming_file_line_and_column() {
    let dir = tempdir("wc-bad");
    let head = "window,exposure_s,dose_mj_cm2,cured_mm\n";
    let good = "1,4,,0\n2,8,,0.1\n3,16,,0.2\n4,32,,0.3\n";
    let cases: &[(&str, String, &[&str])] = &[
        (
            "missing column",
            "window,exposure_s,dose_mj_cm2\n1,4,\n".into(),
            &["line 1", "cured_mm"],
        ),
        (
            "text",
            format!("{head}1,4,,0\n2,8,,thin\n"),
            &["line 3, column cured_mm", "thin"],
        ),
        (
            "negative",
            format!("{head}{good}5,64,,-0.1\n"),
            &["line 6, column cured_mm"],
        ),
        (
            "text exposure",
            format!("{head}1,4s,,0.1\n"),
            &["line 2, column exposure_s"],
        ),
        (
            "two cured",
            format!("{head}1,4,,0\n2,8,,\n3,16,,0.2\n4,32,,0.3\n"),
            &["2 cured windows"],
        ),
        (
            "Dp < 0",
            format!("{head}1,4,,0.3\n2,8,,0.2\n3,16,,0.1\n"),
            &["Dp", "not positive"],
        ),
        ("ragged", format!("{head}1,4,,0.1,9\n"), &["line 2"]),
    ];
    for (what, text, wants) in cases {
        std::fs::write(dir.join("s.csv"), text).unwrap();
        let o = run_in(&dir, &["calibrate", "resin", "s.csv", "-o", "r.toml"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{what}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{what}: {err}");
        assert!(err.contains("s.csv"), "{what}: {err}");
        for w in *wants {
            assert!(err.contains(w), "{what}: {w:?} not in {err}");
        }
        assert!(
            !dir.join("r.toml").exists() && !dir.join("r.png").exists(),
            "{what}"
        );
    }
    // The good sheet is fitted.
    std::fs::write(dir.join("s.csv"), format!("{head}{good}")).unwrap();
    ok(&run_in(
        &dir,
        &["calibrate", "resin", "s.csv", "-o", "r.toml"],
    ));
    // A bad range or count writes no job and no sheet, and says which it is.
    for (args, want) in [
        (
            ["--exposure", "9..3"],
            "working curve: exposures 9..3 s; give 0 < LO < HI",
        ),
        (
            ["--exposure", "1e-9..1e9"],
            "working curve: exposures 1e-9..1e9 s; the longest is the layer's exposure, at most 1000000 s",
        ),
        (
            ["--windows", "1"],
            "working curve: 1 window; give 2 to 64 windows",
        ),
    ] {
        let mut a = vec!["testjob", "working-curve", "-o", "w.dmdjob"];
        a.extend(args);
        let o = run_in(&dir, &a);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert_eq!(stderr(&o), format!("dmdsl: error: {want}\n"));
        assert!(!dir.join("w.dmdjob").exists() && !dir.join("w.csv").exists());
    }
}

/// The accuracy sheet filled from measured = scale·nominal ± offset (per axis; − for holes
/// and slots) plus noise; returns the errors written.
fn fill_accuracy(path: &Path, fit: [(f64, f64); 3], sd: f64) -> Vec<f64> {
    let mut n = noise(5, sd);
    fill_sheet(path, |sign, k, nominal| {
        fit[k].0 * nominal + sign * fit[k].1 + n()
    })
}

/// The accuracy sheet filled with `measured(sign, axis, nominal)` (sign −1 for holes and
/// slots, axis 0, 1, 2 for X, Y, Z); returns the errors written.
fn fill_sheet(path: &Path, mut measured: impl FnMut(f64, usize, f64) -> f64) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let head = lines.next().unwrap();
    assert_eq!(head, "feature,axis,nominal_mm,measured_mm,x_mm,y_mm");
    let (mut out, mut errors) = (format!("{head}\n"), Vec::new());
    for l in lines {
        let c: Vec<&str> = l.split(',').collect();
        let (k, nominal): (usize, f64) = ("XYZ".find(c[1]).unwrap(), c[2].parse().unwrap());
        let sign = if matches!(c[0], "hole" | "slot") {
            -1.0
        } else {
            1.0
        };
        let m = measured(sign, k, nominal);
        errors.push(m - nominal);
        out += &format!("{},{},{},{m:.4},{},{}\n", c[0], c[1], c[2], c[4], c[5]);
    }
    std::fs::write(path, out).unwrap();
    errors
}

#[test]
fn accuracy_part_runs_exports_and_its_sheet_is_fitted_back() {
    let dir = tempdir("accuracy");
    ok(&run_in(&dir, &["testjob", "accuracy", "-o", "acc.dmdjob"]));
    ok(&run_in(&dir, &["run", "acc.dmdjob"]));
    ok(&run_in(&dir, &["export", "acc.dmdjob", "-o", "acc.sl1"]));
    assert_exports_to_control(&dir, "acc.dmdjob");
    let sheet = std::fs::read_to_string(dir.join("acc.csv")).unwrap();
    for kind in ["pin", "wall", "hole", "slot", "step"] {
        assert!(sheet.lines().any(|l| l.starts_with(kind)), "{kind}");
    }
    let fit = [(1.01, 0.04), (0.995, -0.02), (1.02, 0.05)];
    let errors = fill_accuracy(&dir.join("acc.csv"), fit, 0.01);
    let out = ok(&run_in(
        &dir,
        &["calibrate", "accuracy", "acc.csv", "--tolerance", "0.1"],
    ));
    // The "all" line: n, mean, share within ±0.06 mm as the test counts them.
    let all: Vec<&str> = out
        .lines()
        .find(|l| l.starts_with("all"))
        .unwrap()
        .split_whitespace()
        .collect();
    let n = errors.len() as f64;
    let mean = errors.iter().sum::<f64>() / n;
    let within = 100.0 * errors.iter().filter(|e| e.abs() <= 0.06).count() as f64 / n;
    assert_eq!(all[1], errors.len().to_string(), "{out}");
    assert!(
        (all[2].parse::<f64>().unwrap() - mean).abs() < 1e-4,
        "{out}"
    );
    assert!(
        (all[4].trim_end_matches('%').parse::<f64>().unwrap() - within).abs() < 0.06,
        "{out}"
    );
    for (k, axis) in ["X", "Y", "Z"].iter().enumerate() {
        let l = out
            .lines()
            .find(|l| l.starts_with(&format!("{axis}: measured")))
            .unwrap();
        let w: Vec<&str> = l.split_whitespace().collect();
        let scale: f64 = w[3].trim_end_matches("·nominal").parse().unwrap();
        // "X: measured = 1.01000·nominal + 0.0400 mm (holes and slots: − 0.0400 mm), …"
        let sign = match w[4] {
            "+" => 1.0,
            "−" => -1.0,
            s => panic!("{s}: {l}"),
        };
        let offset: f64 = sign * w[5].parse::<f64>().unwrap();
        assert_eq!(l.contains("holes and slots"), *axis != "Z", "{l}");
        eprintln!(
            "{axis}: scale {scale:.5} (chosen {}), offset {offset:+.4} mm (chosen {})",
            fit[k].0, fit[k].1
        );
        assert!((scale - fit[k].0).abs() < 0.005, "{l}");
        assert!((offset - fit[k].1).abs() < 0.012, "{l}");
    }
    for (what, text, want) in [
        (
            "missing column",
            "feature,axis,nominal_mm\npin,X,1\n",
            "line 1",
        ),
        (
            "text",
            "feature,axis,nominal_mm,measured_mm\npin,X,1,1.0\npin,X,2,wide\n",
            "line 3, column measured_mm",
        ),
        (
            "negative",
            "feature,axis,nominal_mm,measured_mm\npin,X,1,-1\n",
            "line 2, column measured_mm",
        ),
        (
            "axis",
            "feature,axis,nominal_mm,measured_mm\npin,W,1,1\n",
            "line 2, column axis",
        ),
    ] {
        std::fs::write(dir.join("bad.csv"), text).unwrap();
        let o = run_in(&dir, &["calibrate", "accuracy", "bad.csv"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{what}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{what}: {err}");
        assert!(
            err.contains("bad.csv") && err.contains(want),
            "{what}: {err}"
        );
    }
}

/// The lit width of the middle row of `job`'s mask `layer`, px (coverage summed).
fn lit_width_px(job: &Path, layer: usize) -> f64 {
    let (w, h, px) = read_gray(&job.join(format!("masks/{layer:05}.png")));
    let (w, r) = (w as usize, h as usize / 2);
    px[r * w..(r + 1) * w]
        .iter()
        .map(|&v| v as f64 / 255.0)
        .sum()
}

#[test]
fn accuracy_correction_is_fitted_applied_recorded_and_refined() {
    let dir = tempdir("accuracy-correction");
    // The machine prints a designed size d as m·d ± g (− for holes and slots), Z as m·d.
    let (m, g) = ([1.008, 1.004, 0.99], 0.05);
    let print = |s: [f64; 3], c: f64| {
        move |sign: f64, k: usize, n: f64| {
            if k == 2 {
                m[2] * s[2] * n
            } else {
                m[k] * (s[k] * n + sign * 2.0 * c) + sign * g
            }
        }
    };
    ok(&run_in(&dir, &["testjob", "accuracy", "-o", "acc.dmdjob"]));
    fill_sheet(&dir.join("acc.csv"), print([1.0; 3], 0.0));
    let out = ok(&run_in(
        &dir,
        &["calibrate", "accuracy", "acc.csv", "-o", "corr.toml"],
    ));
    assert!(
        out.contains("corr.toml: dmdsl slice --accuracy corr.toml"),
        "{out}"
    );
    assert!(dir.join("corr.png").exists());
    let text = std::fs::read_to_string(dir.join("corr.toml")).unwrap();
    let v: toml::Value = toml::from_str(&text).unwrap();
    let scale: Vec<f64> = v["scale"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_float().unwrap())
        .collect();
    let offset = key(&text, "xy_offset_mm");
    // The correction that undoes the machine: 1/m, and edges in by g/(2m) (X and Y's mean).
    let want_offset = -(g / (2.0 * m[0]) + g / (2.0 * m[1])) / 2.0;
    for k in 0..3 {
        assert!((scale[k] - 1.0 / m[k]).abs() < 2e-4, "{k}: {text}");
    }
    assert!((offset - want_offset).abs() < 2e-4, "{text}");
    // Written to 1e-6 (1 nm for lengths): a Z printed without offset has none, not the
    // fit's rounding noise (3e-16).
    assert_eq!(v["z_offset_mm"].as_float(), Some(0.0), "{text}");
    assert_rounded_numbers(&text);

    // Applied by slice: a 10 × 6 × 4 mm box drawn scaled and offset, the job records it.
    let part = dir.join("box.stl");
    write_stl(&part, &box_tris([0.0, 0.0, 0.0], [10.0, 6.0, 4.0]));
    let flat = ["--compensation", "off", "--cure-correction", "off"];
    for (job, extra) in [
        ("plain.dmdjob", None),
        ("corrected.dmdjob", Some("corr.toml")),
    ] {
        let mut args = vec!["slice", "box.stl", "-o", job];
        args.extend(flat);
        if let Some(f) = extra {
            args.extend(["--accuracy", f]);
        }
        ok(&run_in(&dir, &args));
    }
    let manifest = |job: &str| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(dir.join(job).join("job.json")).unwrap()).unwrap()
    };
    let (plain, corrected) = (manifest("plain.dmdjob"), manifest("corrected.dmdjob"));
    assert!(plain["settings"].get("accuracy").is_none());
    let rec = &corrected["settings"]["accuracy"];
    let sha = v["sheet_sha256"].as_str().unwrap();
    assert_eq!(rec["source"], format!("acc.csv sha256:{sha}"), "{rec}");
    assert_eq!(rec["xy_offset_mm"].as_f64().unwrap(), offset);
    let px = plain["machine"]["projector"][0]["pixel_mm"]
        .as_f64()
        .unwrap();
    let layers = |j: &serde_json::Value| j["layers"].as_array().unwrap().len();
    assert_eq!(layers(&plain), 80);
    // A partial top layer is dropped.
    assert_eq!(layers(&corrected), (80.0 * scale[2]).floor() as usize);
    let want = (10.0 * scale[0] + 2.0 * offset) / px;
    let w0 = lit_width_px(&dir.join("plain.dmdjob"), 20);
    let w1 = lit_width_px(&dir.join("corrected.dmdjob"), 20);
    assert!((w0 - 10.0 / px).abs() < 0.01, "{w0}");
    assert!(
        (w1 - want).abs() < 0.01,
        "corrected width {w1} px, want {want}"
    );

    // Refined: the part printed with the correction, measured and fitted again with it,
    // gives the same correction (the machine's fixed point), composed with the printed one.
    ok(&run_in(
        &dir,
        &[
            "testjob",
            "accuracy",
            "-o",
            "acc2.dmdjob",
            "--accuracy",
            "corr.toml",
        ],
    ));
    let s = [scale[0], scale[1], scale[2]];
    fill_sheet(&dir.join("acc2.csv"), print(s, offset));
    ok(&run_in(
        &dir,
        &[
            "calibrate",
            "accuracy",
            "acc2.csv",
            "--accuracy",
            "corr.toml",
            "-o",
            "corr2.toml",
        ],
    ));
    let text2 = std::fs::read_to_string(dir.join("corr2.toml")).unwrap();
    let v2: toml::Value = toml::from_str(&text2).unwrap();
    for k in 0..3 {
        let s2 = v2["scale"][k].as_float().unwrap();
        assert!((s2 - scale[k]).abs() < 2e-4, "{k}: {text2}");
        let fitted = v2["fits"][k]["scale"].as_float().unwrap();
        assert!(
            (fitted - 1.0).abs() < 2e-4,
            "printed with the correction: {text2}"
        );
    }
    assert!(
        (key(&text2, "xy_offset_mm") - offset).abs() < 2e-4,
        "{text2}"
    );

    // A correction out of range or not one: one line naming the file, exit 2, no job.
    let mut range = v.as_table().unwrap().clone();
    range.insert(
        "scale".into(),
        toml::Value::try_from([1.5, 1.0, 1.0]).unwrap(),
    );
    for (what, body, want) in [
        ("range", toml::to_string(&range).unwrap(), "X factor 1.5"),
        ("toml", "scale = ".to_string(), "bad.toml"),
    ] {
        std::fs::write(dir.join("bad.toml"), body).unwrap();
        // Each command that reads a correction file: slice, the test part, the fit.
        let commands: [&[&str]; 3] = [
            &["slice", "box.stl", "-o", "bad.dmdjob"],
            &["testjob", "accuracy", "-o", "bad.dmdjob"],
            &["calibrate", "accuracy", "acc.csv", "-o", "bad-fit.toml"],
        ];
        for c in commands {
            let mut args = c.to_vec();
            args.extend(["--accuracy", "bad.toml"]);
            let o = run_in(&dir, &args);
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{what} {c:?}: {err}");
            assert_eq!(err.trim_end().lines().count(), 1, "{what} {c:?}: {err}");
            assert!(
                err.contains("bad.toml") && err.contains(want),
                "{what} {c:?}: {err}"
            );
            assert!(!dir.join("bad.dmdjob").exists(), "{what} {c:?}");
            assert!(!dir.join("bad.csv").exists(), "{what} {c:?}");
            assert!(!dir.join("bad-fit.toml").exists(), "{what} {c:?}");
        }
    }
    // A sheet whose fit asks for a correction out of range: one line naming the sheet,
    // exit 2, neither the file nor its plot written.
    fill_sheet(&dir.join("acc.csv"), |sign, _, n| 1.5 * n + sign * 0.01);
    let o = run_in(
        &dir,
        &["calibrate", "accuracy", "acc.csv", "-o", "wild.toml"],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("acc.csv") && err.contains("the fitted correction") && err.contains("factor"),
        "{err}"
    );
    assert!(!dir.join("wild.toml").exists() && !dir.join("wild.png").exists());
}
