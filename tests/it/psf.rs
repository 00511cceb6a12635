//! `dmdsl testjob psf` and `dmdsl calibrate psf`: the blur job runs clean and exports; its
//! sheet, filled in from a chosen σ by an evaluation of the cure model written here (the
//! Gaussian-blurred line profile integrated numerically, the dose of every layer summed
//! by Beer–Lambert, the working curve's threshold), with fixed-seed noise, is fitted back
//! to that σ; `slice --psf` records the sheet; bad sheets are refused in one line naming
//! the file, line and column, with nothing written.

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

/// The cure model's inputs as the profile states them.
#[derive(Clone, Copy)]
struct Resin {
    dp: f64,
    ec: f64,
    overcure: f64,
    layer: f64,
    pixel: f64,
}

fn resin(dir: &Path, profile: &str) -> Resin {
    let o = run_in(dir, &["profile", "show", profile]);
    let v: toml::Value = toml::from_str(&stdout(&o)).unwrap();
    let f = |t: &toml::Value, k: &str| t[k].as_float().unwrap();
    Resin {
        dp: f(&v["resin"], "dp_mm"),
        ec: f(&v["resin"], "ec_mj_cm2"),
        overcure: f(&v["resin"], "overcure_mm"),
        layer: f(&v["slicing"], "layer_height_mm"),
        pixel: f(&v["projector"][0], "pixel_mm"),
    }
}

/// The light at `x` (px) of the lit intervals `lit` blurred by a Gaussian of `sigma` px:
/// the Gaussian integrated over each interval by Simpson's rule (2000 steps per interval).
fn blurred(lit: &[(f64, f64)], sigma: f64, x: f64) -> f64 {
    let g = |t: f64| (-(x - t).powi(2) / (2.0 * sigma * sigma)).exp();
    let mut sum = 0.0;
    for &(a, b) in lit {
        let n = 2000;
        let h = (b - a) / n as f64;
        let mut s = g(a) + g(b);
        for k in 1..n {
            s += g(a + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        sum += s * h / 3.0;
    }
    sum / (sigma * std::f64::consts::TAU.sqrt())
}

/// The printed width (px) of a line or gap `w` px wide (a gap between lit blocks 16 px
/// wide), `layers` thick, at the mid-plane of its lowest layer: the dose there is the sum
/// over the feature's layers of D₀·I(x)·exp(−(h/2 + k·h)/Dp), D₀ = Ec·exp((h + overcure)/Dp)
/// (a layer's own exposure cures h + overcure deep), and the resin cures where it reaches Ec.
fn width(r: Resin, sigma: f64, kind: &str, w: f64, layers: u32) -> f64 {
    let lit: Vec<(f64, f64)> = match kind {
        "line" => vec![(0.0, w)],
        _ => vec![(-16.0, 0.0), (w, w + 16.0)],
    };
    let d0 = r.ec * ((r.layer + r.overcure) / r.dp).exp();
    let cures = |x: f64| {
        let i = blurred(&lit, sigma, x);
        let dose: f64 = (0..layers)
            .map(|k| d0 * i * (-(0.5 * r.layer + k as f64 * r.layer) / r.dp).exp())
            .sum();
        dose >= r.ec
    };
    let centre = 0.5 * w;
    // `a` on the side that cures, `b` on the side that does not.
    let (mut a, mut b) = match kind {
        "line" if !cures(centre) => return 0.0,
        "line" => (centre, centre + 0.5 * w + 12.0 * sigma + 2.0),
        _ if cures(centre) => return 0.0,
        _ => (-8.0, centre),
    };
    for _ in 0..50 {
        let m = 0.5 * (a + b);
        if cures(m) {
            a = m;
        } else {
            b = m;
        }
    }
    2.0 * (0.5 * (a + b) - centre).abs()
}

/// Fills `printed_mm` from `sigma` (per projector) plus noise (0 stays 0: a line that did
/// not cure, a gap that closed); returns how many rows were filled.
fn fill(path: &Path, r: Resin, sigma: &dyn Fn(&str) -> f64, sd: f64, seed: u64) -> usize {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let head = lines.next().unwrap();
    assert_eq!(
        head,
        "feature,kind,axis,place,x_mm,y_mm,projector,drawn_px,drawn_mm,layers,printed_mm"
    );
    let (mut out, mut n, mut rows) = (format!("{head}\n"), noise(seed, sd), 0);
    let mut memo: Vec<((String, String, u32), f64)> = Vec::new();
    for l in lines {
        let c: Vec<&str> = l.split(',').collect();
        assert_eq!((c.len(), c[10]), (11, ""), "{l}");
        let (w, layers): (u32, u32) = (c[7].parse().unwrap(), c[9].parse().unwrap());
        let key = (c[1].to_string(), c[6].to_string(), w);
        let px = match memo.iter().find(|m| m.0 == key) {
            Some(m) => m.1,
            None => {
                let v = width(r, sigma(c[6]), c[1], w as f64, layers);
                memo.push((key, v));
                v
            }
        };
        let mm = if px > 0.0 {
            (px * r.pixel + n()).max(0.001)
        } else {
            0.0
        };
        out += &format!("{},{mm:.4}\n", c[..10].join(","));
        rows += 1;
    }
    std::fs::write(path, out).unwrap();
    rows
}

fn ok(o: &std::process::Output) -> String {
    assert!(o.status.success(), "{}", stderr(o));
    stdout(o)
}

/// The fitted σ and its standard error of projector `name` in the blur calibration TOML.
fn sigma_of(text: &str, name: &str) -> (f64, f64) {
    let v: toml::Value = toml::from_str(text).unwrap();
    let p = v["projector"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"].as_str() == Some(name))
        .unwrap_or_else(|| panic!("{name} in {text}"));
    (
        p["psf_sigma_px"].as_float().unwrap(),
        p["psf_sigma_se_px"].as_float().unwrap(),
    )
}

#[test]
fn blur_job_runs_exports_and_its_sheet_is_fitted_back_to_sigma() {
    let dir = tempdir("psf");
    let out = ok(&run_in(&dir, &["testjob", "psf", "-o", "psf.dmdjob"]));
    assert!(out.contains("160 features"), "{out}");
    ok(&run_in(&dir, &["run", "psf.dmdjob"]));
    ok(&run_in(&dir, &["export", "psf.dmdjob", "-o", "psf.sl1"]));
    assert_exports_to_control(&dir, "psf.dmdjob");
    let sheet = std::fs::read_to_string(dir.join("psf.csv")).unwrap();
    for want in [
        ",line,x,centre,",
        ",gap,y,bottom-right,",
        ",line,y,top-left,",
    ] {
        assert!(sheet.contains(want), "{want}");
    }
    // Every layer is exposed alike on every profile (the model's assumption): bottom
    // layers and a hybrid profile's continuous sweeps included.
    for (p, job) in [
        ("xu2010-topdown", "psf.dmdjob"),
        ("bottom-up", "b.dmdjob"),
        ("hybrid-bottomup", "h.dmdjob"),
    ] {
        if job != "psf.dmdjob" {
            ok(&run_in(&dir, &["testjob", "psf", "-o", job, "-p", p]));
            ok(&run_in(&dir, &["run", job]));
        }
        let j: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join(job).join("job.json")).unwrap())
                .unwrap();
        let layers = j["layers"].as_array().unwrap();
        assert_eq!(layers.len(), 10, "{p}");
        let t = |l: &serde_json::Value| l["exposure_s"].as_f64().unwrap();
        assert!(
            layers.iter().all(|l| t(l) == t(&layers[0])),
            "{p}: {layers:?}"
        );
    }
    drawn_as_the_sheet_says(
        &dir.join("psf.dmdjob/masks/00005.png"),
        &sheet,
        0.0634765625,
    );
    let r = resin(&dir, "xu2010-topdown");
    let chosen = 0.8;
    assert_eq!(fill(&dir.join("psf.csv"), r, &|_| chosen, 0.004, 3), 160);
    let out = ok(&run_in(
        &dir,
        &["calibrate", "psf", "psf.csv", "-o", "psf.toml"],
    ));
    assert!(
        out.contains("psf_sigma_px = ") && out.contains("residual"),
        "{out}"
    );
    let t = std::fs::read_to_string(dir.join("psf.toml")).unwrap();
    assert_rounded_numbers(&t);
    let (sigma, se) = sigma_of(&t, "p0");
    eprintln!("σ {sigma:.4} ± {se:.4} px (chosen {chosen})");
    assert!((sigma - chosen).abs() < 0.01, "σ {sigma}");
    assert!(se > 0.0 && se < 0.01, "se {se}");
    let png = std::fs::read(dir.join("psf.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG"));
    // The fitted σ goes into a job; job.json says where it came from.
    let part = fixture("cube10.stl");
    let args = [
        "slice",
        part.to_str().unwrap(),
        "-o",
        "c.dmdjob",
        "--psf",
        "psf.toml",
        "--predict",
    ];
    ok(&run_in(&dir, &args));
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("c.dmdjob/job.json")).unwrap()).unwrap();
    let c = &j["cure"];
    assert!((c["psf_sigma_px"].as_f64().unwrap() - sigma).abs() < 1e-9);
    assert!(c["sources"]["psf_sigma_px"]
        .as_str()
        .unwrap()
        .starts_with("psf.csv sha256:"));
    assert_eq!(c["sources"]["dp_mm"], "assumed");
    // With the fitted σ, the feature part's prediction is the one of σ typed in, and the
    // corrected edges land within a few hundredths of a pixel.
    let typed = format!("projector.0.psf_sigma_px={sigma}");
    let fitted = predicted_cure(&dir, "f.dmdjob", &["--psf", "psf.toml"]);
    assert_eq!(fitted, predicted_cure(&dir, "t.dmdjob", &["--set", &typed]));
    let mean = fitted["edge_error_px"]["mean"].as_f64().unwrap();
    assert!(mean < 0.05, "{fitted}");
}

/// Every feature of `sheet` is drawn in the layer's mask `png` as wide as the sheet says:
/// the run of lit (line) or dark (gap) pixels through its centre, along its axis, is
/// `drawn_px` long (an edge off the pixel grid would light one more pixel partly).
fn drawn_as_the_sheet_says(png: &Path, sheet: &str, px: f64) {
    let (w, h, m) = read_gray(png);
    let at = |c: i64, r: i64| m[(r * w as i64 + c) as usize];
    for l in sheet.lines().skip(1) {
        let c: Vec<&str> = l.split(',').collect();
        let (x, y): (f64, f64) = (c[4].parse().unwrap(), c[5].parse().unwrap());
        let (col, row) = ((x / px).floor() as i64, (h as f64 - y / px).floor() as i64);
        let lit = c[1] == "line";
        let step = if c[2] == "x" { [1, 0] } else { [0, 1] };
        let run = |dir: i64| {
            (1..)
                .take_while(|&k| (at(col + dir * k * step[0], row + dir * k * step[1]) > 0) == lit)
                .count()
        };
        assert_eq!((at(col, row) > 0), lit, "{l}");
        let n = 1 + run(1) + run(-1);
        assert_eq!(n.to_string(), c[7], "{l}");
    }
}

#[test]
fn tiled_blur_job_fits_each_projector() {
    let dir = tempdir("psf-tiled");
    let args = ["testjob", "psf", "-o", "t.dmdjob", "-p", "tiled-2x1"];
    assert!(ok(&run_in(&dir, &args)).contains("320 features"));
    ok(&run_in(&dir, &["run", "t.dmdjob"]));
    let r = resin(&dir, "tiled-2x1");
    let sigma = |p: &str| if p == "p0" { 0.6 } else { 1.2 };
    fill(&dir.join("t.csv"), r, &sigma, 0.004, 9);
    let args = [
        "calibrate",
        "psf",
        "t.csv",
        "-o",
        "t.toml",
        "-p",
        "tiled-2x1",
    ];
    ok(&run_in(&dir, &args));
    let t = std::fs::read_to_string(dir.join("t.toml")).unwrap();
    for p in ["p0", "p1"] {
        let (s, se) = sigma_of(&t, p);
        eprintln!("{p}: σ {s:.4} ± {se:.4} px (chosen {})", sigma(p));
        assert!((s - sigma(p)).abs() < 0.02, "{p}: σ {s}");
    }
    // Each projector gets its own σ; the job's cure model takes the largest.
    let part = fixture("cube10.stl");
    let args = [
        "slice",
        part.to_str().unwrap(),
        "-p",
        "tiled-2x1",
        "--psf",
        "t.toml",
        "-o",
        "c.dmdjob",
    ];
    ok(&run_in(&dir, &args));
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("c.dmdjob/job.json")).unwrap()).unwrap();
    assert!((j["cure"]["psf_sigma_px"].as_f64().unwrap() - sigma_of(&t, "p1").0).abs() < 1e-9);
    assert!(j["cure"]["sources"]["psf_sigma_px"]
        .as_str()
        .unwrap()
        .starts_with("t.csv sha256:"));
}

#[test]
fn bad_blur_sheets_are_refused_in_one_line_naming_file_line_and_column() {
    let dir = tempdir("psf-bad");
    let head = "feature,kind,axis,place,x_mm,y_mm,projector,drawn_px,drawn_mm,layers,printed_mm\n";
    let row = |f: u32, kind: &str, w: &str, printed: &str| {
        format!("{f},{kind},x,centre,10,10,p0,{w},0.1,6,{printed}\n")
    };
    let good = [
        row(1, "line", "2", "0.21"),
        row(2, "line", "4", "0.33"),
        row(3, "gap", "4", "0.19"),
        row(4, "gap", "8", "0.44"),
    ]
    .concat();
    let cases: &[(&str, String, &[&str])] = &[
        (
            "missing column",
            "feature,kind,projector,drawn_px,layers\n1,line,p0,2,6\n".into(),
            &["line 1", "printed_mm"],
        ),
        (
            "text in a number",
            format!("{head}{good}{}", row(5, "line", "3", "wide")),
            &["line 6, column printed_mm", "wide"],
        ),
        (
            "negative width",
            format!("{head}{good}{}", row(5, "line", "3", "-0.2")),
            &["line 6, column printed_mm", "negative"],
        ),
        (
            "negative drawn width",
            format!("{head}{}", row(1, "line", "-2", "0.2")),
            &["line 2, column drawn_px"],
        ),
        (
            "fractional drawn width",
            format!("{head}{}", row(1, "line", "2.5", "0.2")),
            &["line 2, column drawn_px", "whole number"],
        ),
        (
            "kind",
            format!("{head}{}", row(1, "slot", "2", "0.2")),
            &["line 2, column kind", "slot"],
        ),
        (
            "too few rows",
            format!(
                "{head}{}{}{}",
                row(1, "line", "2", "0.2"),
                row(2, "line", "4", "0.3"),
                row(3, "gap", "4", "")
            ),
            &["p0", "2 measured", "at least 3"],
        ),
        (
            "bracket edge",
            format!(
                "{head}{}{}{}",
                row(1, "line", "4", "0.1"),
                row(2, "line", "6", "0.2"),
                row(3, "line", "8", "0.3")
            ),
            &["edge of the bracket"],
        ),
    ];
    for (what, text, wants) in cases {
        std::fs::write(dir.join("s.csv"), text).unwrap();
        let o = run_in(&dir, &["calibrate", "psf", "s.csv", "-o", "p.toml"]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{what}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{what}: {err}");
        assert!(err.contains("s.csv"), "{what}: {err}");
        for w in *wants {
            assert!(err.contains(w), "{what}: {w:?} not in {err}");
        }
        assert!(
            !dir.join("p.toml").exists() && !dir.join("p.png").exists(),
            "{what}"
        );
    }
    // The good sheet is fitted, and a blur file naming a projector the profile lacks is
    // refused by `slice --psf`.
    std::fs::write(dir.join("s.csv"), format!("{head}{good}")).unwrap();
    ok(&run_in(
        &dir,
        &["calibrate", "psf", "s.csv", "-o", "p.toml"],
    ));
    let t = std::fs::read_to_string(dir.join("p.toml")).unwrap();
    std::fs::write(dir.join("q.toml"), t.replace("\"p0\"", "\"p7\"")).unwrap();
    let part = fixture("cube10.stl");
    let o = run_in(
        &dir,
        &[
            "slice",
            part.to_str().unwrap(),
            "--psf",
            "q.toml",
            "-o",
            "c.dmdjob",
        ],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("q.toml") && err.contains("p7"), "{err}");
    assert!(!dir.join("c.dmdjob").exists());
}
