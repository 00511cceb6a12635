//! `dmdsl calibrate` and `slice --calibration/--compensation`, judged physically: synthetic
//! measurement sets from known P(x, y) and S(g) with 1.5 % noise are fitted, a plate
//! covering the field is sliced with the fitted calibration, the written mask PNGs are
//! decoded and the TRUE irradiance P·S of every pixel is evaluated.

use crate::common::*;
use crate::synthetic::*;
use std::path::{Path, PathBuf};

const PX: f64 = 0.0634765625;
const W: usize = 1024;
const H: usize = 768;

/// Measurements at the 13 × 9 zone centres (5 mm zones from the bottom-left corner).
fn write_measurements(path: &Path, p: FieldFn, s: ResponseFn, noise: f64, seed: u64) {
    let mut csv = String::from("x_mm,y_mm,gray,irradiance_mw_cm2\n");
    for (x, y, g, e) in centre_readings(p, s, noise, seed) {
        csv.push_str(&format!("{x},{y},{g},{e:.6e}\n"));
    }
    std::fs::write(path, csv).unwrap();
}

/// A 0.2 mm plate covering the whole 65 × 48.75 mm field (4 layers of 0.05 mm: 2 bottom
/// layers, 2 normal ones).
fn plate(dir: &Path) -> PathBuf {
    let p = dir.join("plate.stl");
    write_stl(&p, &box_tris([0.0, 0.0, 0.0], [65.0, 48.75, 0.2]));
    p
}

fn ok(o: &std::process::Output) {
    assert!(o.status.success(), "{}", stderr(o));
}

/// True irradiance of every pixel of a mask: (x, y, E).
fn true_irradiance(mask: &[u8], p: FieldFn, s: ResponseFn) -> Vec<(f64, f64, f64)> {
    (0..W * H)
        .map(|i| {
            let (r, c) = (i / W, i % W);
            let (x, y) = ((c as f64 + 0.5) * PX, (H as f64 - r as f64 - 0.5) * PX);
            let g = mask[i];
            let e = if g == 0 { 0.0 } else { p(x, y) * s(g as f64) };
            (x, y, e)
        })
        .collect()
}

/// P of `cal` (full-on irradiance) within 1 % of the truth `p · s255` on a 2.5 mm grid
/// over the calibrated area.
fn assert_p_recovered(cal: &dmdsl::optics::Calibration, p: FieldFn, s255: f64) {
    for i in 0..=26 {
        for j in 0..=18 {
            let (x, y) = (i as f64 * 2.5, j as f64 * 2.5);
            let want = p(x, y) * s255;
            let got = cal.field.eval(x, y);
            assert!(
                (got / want - 1.0).abs() < 0.01,
                "P({x}, {y}) = {got} vs {want}"
            );
        }
    }
}

fn calibrate(dir: &Path, p: FieldFn, s: ResponseFn, seed: u64) -> (PathBuf, serde_json::Value) {
    let m = dir.join("m.csv");
    write_measurements(&m, p, s, 0.015, seed);
    let o = run_in(
        dir,
        &[
            "calibrate",
            "m.csv",
            "-o",
            "cal.toml",
            "--json",
            "--no-plots",
        ],
    );
    ok(&o);
    (
        dir.join("cal.toml"),
        serde_json::from_slice(&o.stdout).unwrap(),
    )
}

fn slice_plate(dir: &Path, extra: &[&str]) -> (Vec<u8>, serde_json::Value) {
    let plate = plate(dir);
    let mut args = vec![
        "slice",
        plate.to_str().unwrap(),
        "-o",
        "p.dmdjob",
        "--keep-position",
        "-q",
        // The compensation of the exact coverage (the cure correction: tests/it/cure.rs).
        "--cure-correction",
        "off",
    ];
    args.extend_from_slice(extra);
    let o = run_in(dir, &args);
    ok(&o);
    let b = dir.join("p.dmdjob");
    let (w, h, px) = read_gray(&b.join("masks/00000.png"));
    assert_eq!((w as usize, h as usize), (W, H));
    let job = serde_json::from_slice(&std::fs::read(b.join("job.json")).unwrap()).unwrap();
    (px, job)
}

#[test]
fn fit_recovers_known_p_and_s_and_writes_plots() {
    let dir = tempdir("cal-recover");
    write_measurements(&dir.join("m.csv"), p_cubic, s_published, 0.015, 7);
    let o = run_in(&dir, &["calibrate", "m.csv", "-o", "cal.toml", "--json"]);
    ok(&o);
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // Residuals are the noise, nothing more.
    let rms = r["residual_rms_pct"].as_f64().unwrap();
    assert!((1.2..1.8).contains(&rms), "{rms}");
    assert_eq!(r["zones"], 117);
    assert_eq!(r["gray_levels"], 7);
    assert_eq!(r["measured_gray"], serde_json::json!([135, 255]));
    for p in r["plots"].as_array().unwrap() {
        let bytes = std::fs::read(dir.join(p.as_str().unwrap())).unwrap();
        assert!(bytes.starts_with(b"\x89PNG"), "{p}");
        // Each picture has its title and, but for the response chart, a colour bar: a
        // column running through the colour map from yellow (top) to dark violet.
        let img = image::load_from_memory(&bytes).unwrap().to_rgb8();
        let title = img
            .enumerate_pixels()
            .filter(|(_, y, px)| *y < 40 && px.0.iter().all(|&c| c < 110))
            .count();
        assert!(title > 100, "{p}: no title text");
        if !p.as_str().unwrap().ends_with("response.png") {
            let (yellow, violet) = (dmdsl::plot::colormap(1.0), dmdsl::plot::colormap(0.0));
            let bar = (0..img.width()).any(|x| {
                let col: Vec<[u8; 3]> = (0..img.height()).map(|y| img.get_pixel(x, y).0).collect();
                let near =
                    |a: [u8; 3], b: [u8; 3]| a.iter().zip(b).all(|(u, v)| u.abs_diff(v) < 12);
                let first = col.iter().position(|&c| near(c, yellow));
                let last = col.iter().rposition(|&c| near(c, violet));
                matches!((first, last), (Some(f), Some(l)) if l > f + 150)
            });
            assert!(bar, "{p}: no colour bar");
        }
    }
    assert_eq!(r["plots"].as_array().unwrap().len(), 6);
    let cal = dmdsl::optics::Calibration::read(&dir.join("cal.toml")).unwrap();
    let f = cal.fit.as_ref().unwrap();
    assert_eq!(
        f.degree, 3,
        "a cubic field is fitted with the paper's cubic"
    );
    // P is the irradiance at gray 255 (S normalised there): within 1 % everywhere inside.
    let s255 = s_published(255.0);
    assert_p_recovered(&cal, p_cubic, s255);
    // S relative to gray 255: within 1 % on the measured range.
    let c = cal.response.curve();
    for g in 135..=255 {
        let want = s_published(g as f64) / s255;
        let got = c.eval(g as f64);
        assert!((got / want - 1.0).abs() < 0.01, "S({g}) = {got} vs {want}");
    }
    // The file is usable as written (it round-trips through the loader above) and a
    // second run replaces it atomically.
    ok(&run_in(
        &dir,
        &["calibrate", "m.csv", "-o", "cal.toml", "-q", "--no-plots"],
    ));
}

#[test]
fn vignetting_is_fitted_with_the_cos4_form() {
    // (1 + r²/50²)⁻² is the cos⁴ law: 1/poly² with a quadratic poly fits it exactly, where
    // a polynomial or exp(polynomial) leaves a bias at the corners.
    let dir = tempdir("cal-cos4");
    write_measurements(&dir.join("m.csv"), p_vignette, s_gamma, 0.015, 11);
    ok(&run_in(
        &dir,
        &["calibrate", "m.csv", "-o", "cal.toml", "-q", "--no-plots"],
    ));
    let text = std::fs::read_to_string(dir.join("cal.toml")).unwrap();
    assert!(text.contains("1 / poly(u, v)²"), "{text}");
    let cal = dmdsl::optics::Calibration::read(&dir.join("cal.toml")).unwrap();
    let f = cal.fit.as_ref().unwrap();
    assert_eq!(f.form, dmdsl::optics::field::Form::InverseSquare);
    assert_eq!(f.degree, 2);
    assert_eq!(f.cv_inv_rms_pct.len(), 1, "{:?}", f.cv_inv_rms_pct);
    assert_p_recovered(&cal, p_vignette, s_gamma(255.0));
    // Hand-edited so that the polynomial crosses zero inside the area (P infinite there):
    // refused with a one-line error naming the file, exit 2, no bundle.
    let coef = text.find("[field.coefficients]").unwrap();
    let end = text[coef..].find("\n\n").map_or(text.len(), |e| coef + e);
    let bad = format!(
        "{}[field.coefficients]\nc = 0.1\nx = -1.0\n{}",
        &text[..coef],
        &text[end..]
    );
    std::fs::write(dir.join("bad.toml"), bad).unwrap();
    write_stl(
        &dir.join("b.stl"),
        &box_tris([0.0, 0.0, 0.0], [5.0, 5.0, 0.1]),
    );
    let o = run_in(&dir, &["slice", "b.stl", "--calibration", "bad.toml"]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(
        err.contains("bad.toml") && err.contains("changes sign") && err.lines().count() == 1,
        "{err}"
    );
    assert!(!dir.join("b.dmdjob").exists());
}

#[test]
fn zone_mode_flattens_true_zone_means() {
    for (k, (p, s)) in [
        (p_cubic as FieldFn, s_published as ResponseFn),
        (p_gauss, s_gamma),
        (p_published, s_published),
    ]
    .into_iter()
    .enumerate()
    {
        let dir = tempdir(&format!("cal-zone-{k}"));
        let (cal, _) = calibrate(&dir, p, s, 100 + k as u64);
        let (mask, job) = slice_plate(&dir, &["--calibration", cal.to_str().unwrap()]);
        assert_eq!(job["settings"]["compensation"], "zone");
        let e = true_irradiance(&mask, p, s);
        let (zone, _) = zone_and_pixel_spreads(e);
        assert!(zone <= 2.5, "case {k}: zone-mean spread {zone:.2} %");
        // Uncompensated, the same plate is far from flat.
        let (mask0, _) = slice_plate(&dir, &["--compensation", "off"]);
        let (zone0, _) = zone_and_pixel_spreads(true_irradiance(&mask0, p, s));
        assert!(zone0 > 30.0, "case {k}: {zone0}");
    }
}

#[test]
fn pixel_mode_flattens_true_pixels() {
    for (k, (p, s)) in [
        (p_cubic as FieldFn, s_gamma as ResponseFn),
        (p_gauss, s_published),
        (p_published, s_published),
    ]
    .into_iter()
    .enumerate()
    {
        let dir = tempdir(&format!("cal-pixel-{k}"));
        let (cal, _) = calibrate(&dir, p, s, 200 + k as u64);
        let (mask, job) = slice_plate(
            &dir,
            &[
                "--calibration",
                cal.to_str().unwrap(),
                "--compensation",
                "pixel",
            ],
        );
        assert_eq!(job["optics"]["mode"], "pixel");
        let e = true_irradiance(&mask, p, s);
        let (_, pixel) = zone_and_pixel_spreads(e);
        // 3 %, or 5 % where one gray step moves irradiance by more than 2 %.
        let coarse = mask
            .iter()
            .filter(|&&g| g > 0 && g < 255)
            .any(|&g| s(g as f64 + 1.0) / s(g as f64) - 1.0 > 0.02);
        let limit = if coarse { 5.0 } else { 3.0 };
        assert!(
            pixel <= limit,
            "case {k}: per-pixel spread {pixel:.2} % > {limit}"
        );
    }
}

#[test]
fn builtin_published_fit_flattens_the_published_model() {
    let dir = tempdir("cal-builtin");
    let (mask, job) = slice_plate(&dir, &[]);
    let o = &job["optics"];
    assert_eq!(o["mode"], "zone");
    assert_eq!(o["units"], "relative");
    assert_eq!(o["valid_gray"], serde_json::json!([121, 255]));
    assert_eq!(o["zone_grays"].as_array().unwrap().len(), 10);
    assert_eq!(o["zone_grays"][0].as_array().unwrap().len(), 13);
    assert!(o["exposure_rule"].as_str().unwrap().contains("relative"));
    assert!(o["dose_mj_cm2"].is_null());
    // The fixed profile exposure is kept (exposure at E*).
    assert_eq!(job["layers"][3]["exposure_s"], 8.0);
    // The gray map is in the bundle with its checksum.
    let map = std::fs::read(dir.join("p.dmdjob").join(o["gray_map"].as_str().unwrap())).unwrap();
    let sha = {
        use sha2::Digest;
        let d = sha2::Sha256::digest(&map);
        d.iter().map(|b| format!("{b:02x}")).collect::<String>()
    };
    assert_eq!(o["gray_map_sha256"], sha);
    // Physically: zone means of P·S under the published model within 4.5 %.
    let e = true_irradiance(&mask, p_published, s_published);
    let (zone, _) = zone_and_pixel_spreads(e);
    assert!(zone <= 4.5, "{zone}");
    assert!(o["predicted"]["after_zone_pct"].as_f64().unwrap() <= 4.5);
    // One gray step of the published S is 2–3 % here, so some zones mix two grays.
    let pred_before = o["predicted"]["before_zone_pct"].as_f64().unwrap();
    assert!(pred_before > 100.0, "{pred_before}");
}

#[test]
fn edge_pixels_get_the_inverse_response_of_their_coverage() {
    // A box whose left edge cuts pixel column 400 in half; built-in published fit.
    let dir = tempdir("cal-edge");
    let stl = dir.join("b.stl");
    let x0 = 400.5 * PX;
    write_stl(
        &stl,
        &box_tris([x0 as f32, 10.0, 0.0], [(x0 + 10.0) as f32, 20.0, 0.1]),
    );
    let o = run_in(
        &dir,
        &[
            "slice",
            "b.stl",
            "-o",
            "b.dmdjob",
            "--keep-position",
            "-q",
            "--dither",
            "off",
            "--cure-correction",
            "off",
        ],
    );
    ok(&o);
    let (_, _, px) = read_gray(&dir.join("b.dmdjob/masks/00000.png"));
    let job: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("b.dmdjob/job.json")).unwrap()).unwrap();
    let target = job["optics"]["target_irradiance"].as_f64().unwrap() * 1e8;
    // Row in the middle of the box (y = 15 mm); pixel 400 is half covered (value 128).
    let r = H - 1 - (15.0 / PX) as usize;
    let (edge, full) = (px[r * W + 400], px[r * W + 403]);
    // Zone mean of P over the zone's pixels, as the compensator computes it.
    let (zc, zr) = (((400.5 * PX) / 5.0) as usize, 3usize);
    assert_eq!(zc, ((403.5 * PX) / 5.0) as usize);
    let (mut sum, mut n) = (0.0, 0);
    for rr in 0..H {
        for c in 0..W {
            let (x, y) = ((c as f64 + 0.5) * PX, (H as f64 - rr as f64 - 0.5) * PX);
            if (x / 5.0) as usize == zc && (y / 5.0) as usize == zr {
                sum += p_published(x, y);
                n += 1;
            }
        }
    }
    let pz = sum / n as f64;
    let nearest = |t: f64| {
        std::iter::once(0u8)
            .chain(121..=255)
            .min_by(|&a, &b| {
                let sa = if a == 0 { 0.0 } else { s_published(a as f64) };
                let sb = if b == 0 { 0.0 } else { s_published(b as f64) };
                (sa - t).abs().total_cmp(&(sb - t).abs())
            })
            .unwrap()
    };
    assert_eq!(full, nearest(target / pz));
    assert_eq!(edge, nearest(128.0 / 255.0 * target / pz));
    // Not coverage × gray: half the irradiance is a much brighter gray than half the gray.
    assert!(
        edge as f64 > 0.5 * full as f64 + 30.0,
        "edge {edge}, full {full}"
    );
}

#[test]
fn absolute_calibration_sets_exposure_from_the_working_curve() {
    let dir = tempdir("cal-exposure");
    let (cal, _) = calibrate(&dir, p_cubic, s_gamma, 300);
    let (_, job) = slice_plate(&dir, &["--calibration", cal.to_str().unwrap()]);
    let o = &job["optics"];
    assert_eq!(o["units"], "mW/cm2");
    let e = o["target_irradiance"].as_f64().unwrap();
    let r = &serde_json::to_value(dmdsl::Profile::default_profile().resin).unwrap();
    let (ec, dp, oc) = (
        r["ec_mj_cm2"].as_f64().unwrap(),
        r["dp_mm"].as_f64().unwrap(),
        r["overcure_mm"].as_f64().unwrap(),
    );
    let t = ec / e * ((0.05 + oc) / dp).exp();
    // Exposures are commanded to 1 ms.
    let got = job["layers"][2]["exposure_s"].as_f64().unwrap();
    assert!((got - t).abs() <= 0.0005, "{got} vs {t}");
    assert!(
        ((got * 1000.0).round() - got * 1000.0).abs() < 1e-6,
        "{got}"
    );
    // Bottom layers keep the profile's 2 : 1 ratio; the dose is E*·t (6 significant
    // digits).
    assert!((job["layers"][0]["exposure_s"].as_f64().unwrap() - 2.0 * t).abs() <= 0.0015);
    assert!((o["dose_mj_cm2"].as_f64().unwrap() - e * got).abs() < 1e-5 * e * got);
    // The plate reaches the top 3.75 mm strip outside the measured area: that is reported;
    // the dose is plausible.
    let w = job["warnings"].to_string();
    assert!(w.contains("beyond the calibrated area"), "{w}");
    assert!(!w.contains("implausible"), "{w}");
}

#[test]
fn implausible_dose_warns() {
    // The published irradiances (µW/cm²) given as mW/cm²: 1000× too little light.
    let dir = tempdir("cal-dose");
    let m = dir.join("m.csv");
    write_measurements(&m, |x, y| p_published(x, y) * 5e-5, s_published, 0.01, 5);
    ok(&run_in(
        &dir,
        &["calibrate", "m.csv", "-o", "c.toml", "-q", "--no-plots"],
    ));
    let stl = dir.join("b.stl");
    write_stl(&stl, &box_tris([0.0, 0.0, 0.0], [5.0, 5.0, 0.1]));
    let o = run_in(&dir, &["slice", "b.stl", "--calibration", "c.toml"]);
    ok(&o);
    assert!(stderr(&o).contains("implausible"), "{}", stderr(&o));
}

#[test]
fn dithered_output_does_not_depend_on_thread_count() {
    let dir = tempdir("cal-threads");
    let stl = dir.join("b.stl");
    write_stl(&stl, &box_tris([0.0, 0.0, 0.0], [30.0, 20.0, 0.5]));
    let mut sums = Vec::new();
    for threads in ["1", "2"] {
        for (mode, dither) in [("pixel", "on"), ("zone", "on")] {
            let out = format!("t{threads}{mode}.dmdjob");
            let args = [
                "slice",
                "b.stl",
                "-o",
                &out,
                "-q",
                "--compensation",
                mode,
                "--dither",
                dither,
            ];
            let o = run_threads(&dir, &args, threads);
            ok(&o);
            sums.push(std::fs::read(dir.join(&out).join("job.json")).unwrap());
        }
    }
    assert_eq!(sums[0], sums[2]);
    assert_eq!(sums[1], sums[3]);
}

fn expect_error(dir: &Path, csv: &str, want: &str) {
    std::fs::write(dir.join("bad.csv"), csv).unwrap();
    let o = run_in(dir, &["calibrate", "bad.csv", "-o", "c.toml"]);
    assert_eq!(o.status.code(), Some(2), "{want}: {}", stderr(&o));
    let e = stderr(&o);
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(
        e.contains("bad.csv") && e.contains(want),
        "want {want:?} in {e}"
    );
    assert!(!dir.join("c.toml").exists());
}

#[test]
fn bad_measurements_are_one_line_errors_with_exit_2() {
    let dir = tempdir("cal-bad");
    let h = "x_mm,y_mm,gray,irradiance_mw_cm2\n";
    expect_error(
        &dir,
        "x_mm,y_mm,gray\n1,2,3\n",
        "line 1: missing column \"irradiance_mw_cm2\"",
    );
    expect_error(
        &dir,
        &format!("{h}1,2,255,1.0,7\n"),
        "line 2: expected 4 columns (x_mm,y_mm,gray,irradiance_mw_cm2), found 5",
    );
    expect_error(
        &dir,
        &format!("{h}1,2,255,abc\n"),
        "line 2, column irradiance_mw_cm2: \"abc\" is not a number",
    );
    expect_error(
        &dir,
        &format!("{h}1,2,255,1\n1,3,255,0\n"),
        "line 3, column irradiance_mw_cm2: must be > 0",
    );
    expect_error(&dir, &format!("{h}1,2,255,-2\n"), "must be > 0");
    // Too few zones: 9 positions for a 10-term cubic.
    let mut few = h.to_string();
    for i in 0..9 {
        for g in [255, 200, 150] {
            few.push_str(&format!(
                "{},{},{g},{}\n",
                5 * i,
                3 * (i % 3),
                1.0 + g as f64 / 255.0
            ));
        }
    }
    expect_error(&dir, &few, "only 9 distinct zone positions");
    // Too few gray levels.
    let mut two = h.to_string();
    for i in 0..13 {
        for j in 0..9 {
            for g in [255, 200] {
                two.push_str(&format!(
                    "{},{},{g},{}\n",
                    2.5 + 5.0 * i as f64,
                    2.5 + 5.0 * j as f64,
                    g as f64 / 255.0
                ));
            }
        }
    }
    expect_error(&dir, &two, "readings at only 2 pixel values (200, 255)");
    // Only full-on readings: P can be seen, S cannot; the message says how to measure it.
    let mut full = h.to_string();
    for i in 0..13 {
        for j in 0..9 {
            full.push_str(&format!(
                "{},{},255,{}\n",
                2.5 + 5.0 * i as f64,
                2.5 + 5.0 * j as f64,
                1.0 + 0.01 * (i + j) as f64
            ));
        }
    }
    expect_error(&dir, &full, "every reading is at gray 255");
    expect_error(&dir, &full, "pixel values below 255");
    // All zones on one line: y never varies, the cubic is undetermined.
    let mut line = h.to_string();
    for i in 0..13 {
        for g in [255, 200, 150] {
            line.push_str(&format!(
                "{},10,{g},{}\n",
                2.5 + 5.0 * i as f64,
                (1.0 + 0.01 * i as f64) * g as f64 / 255.0
            ));
        }
    }
    expect_error(&dir, &line, "ill-conditioned fit");
    // Inverted gray column (S rises as the pixel value falls): no monotone S.
    let mut inv = h.to_string();
    for i in 0..13 {
        for j in 0..9 {
            for g in [255, 200, 150, 100] {
                let (x, y) = (2.5 + 5.0 * i as f64, 2.5 + 5.0 * j as f64);
                inv.push_str(&format!(
                    "{x},{y},{g},{}\n",
                    p_cubic(x, y) * (2.0 - g as f64 / 255.0)
                ));
            }
        }
    }
    expect_error(&dir, &inv, "no monotone S fits the data");
    // Missing file.
    let o = run_in(&dir, &["calibrate", "nope.csv", "-o", "c.toml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("nope.csv"));
    // Sizes slice would refuse in the file it writes, refused before anything is written.
    let m = fixture("measurements.csv");
    for (flag, v) in [("--zone-mm", "1e9"), ("--extrapolate-mm", "1e300")] {
        let args = ["calibrate", m.to_str().unwrap(), "-o", "c.toml", flag, v];
        let o = run_in(&dir, &args);
        assert_eq!(o.status.code(), Some(2), "{flag}");
        let e = stderr(&o);
        let want = "is not a length a machine has (0.0 to 10000.0; check its unit)\n";
        assert!(
            e.starts_with(&format!("dmdsl: error: {flag} = ")) && e.ends_with(want),
            "{e}"
        );
        assert!(!dir.join("c.toml").exists() && !dir.join("c-response.png").exists());
    }
}

#[test]
fn compensation_flags_are_checked() {
    let dir = tempdir("cal-flags");
    let stl = dir.join("b.stl");
    write_stl(&stl, &box_tris([0.0, 0.0, 0.0], [5.0, 5.0, 0.1]));
    // --dither on without compensation.
    let o = run_in(
        &dir,
        &["slice", "b.stl", "--compensation", "off", "--dither", "on"],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--dither on needs compensation"));
    // A calibration file that is not one.
    std::fs::write(dir.join("c.toml"), "units = \"relative\"\n").unwrap();
    let o = run_in(&dir, &["slice", "b.stl", "--calibration", "c.toml"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("c.toml"), "{}", stderr(&o));
    // Off: plain coverage, no optics record.
    let o = run_in(
        &dir,
        &[
            "slice",
            "b.stl",
            "-q",
            "--compensation",
            "off",
            "--cure-correction",
            "off",
        ],
    );
    ok(&o);
    let job: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("b.dmdjob/job.json")).unwrap()).unwrap();
    assert_eq!(job["settings"]["compensation"], "off");
    assert!(job.get("optics").is_none());
    // A 5 mm square is about 78.8 px on a side: interior pixels are plain 255.
    let (_, _, px) = read_gray(&dir.join("b.dmdjob/masks/00000.png"));
    let full = px.iter().filter(|&&v| v == 255).count();
    assert!((77 * 77..=79 * 79).contains(&full), "{full}");
}
