//! The synthetic held-out calibration sweep, through the library's stages: known P and S,
//! 1.5 % noise at the 13 × 9 zone centres and 7 gray levels, fitted by [`fit`], then a
//! plate covering the field is compensated and the TRUE irradiance P·S of every pixel is
//! judged (zone-mean and per-pixel spread over the calibrated area).
//! `cargo test --release --test it calibrate_sweep::sweep_report -- --ignored --nocapture`
//! prints the full table (docs/CALIBRATION.md).

use crate::synthetic::*;
use dmdsl::optics::calib::{fit, FitOptions, Reading};
use dmdsl::optics::{Calibration, Compensator, Dither, Mode, Units};
use dmdsl::profile::Field;
use std::path::Path;

/// A lens-like field that none of the fitted forms matches exactly: cos³-type falloff
/// about an off-centre axis, a tilt and a faint ripple, about 2.2 : 1 (a check that the
/// cos⁴ form is not chosen where it does not belong). Only the sweep report uses it.
fn p_lens(x: f64, y: f64) -> f64 {
    let r2 = (x - 38.0).powi(2) + (y - 20.0).powi(2);
    (1.0 + r2 / 3600.0).powf(-1.5)
        * (1.0 + 0.005 * (x - 32.5))
        * (1.0 + 0.01 * (x / 9.0).sin() * (y / 13.0).cos())
}

fn readings(p: FieldFn, s: ResponseFn, noise: f64, seed: u64) -> Vec<Reading> {
    centre_readings(p, s, noise, seed)
        .into_iter()
        .enumerate()
        .map(|(k, (x_mm, y_mm, g, irradiance))| Reading {
            line: k as u64 + 2,
            x_mm,
            y_mm,
            gray: g as u8,
            irradiance,
        })
        .collect()
}

fn field(step: usize) -> Field {
    Field {
        width_px: 1024 / step as u32,
        height_px: 768 / step as u32,
        pixel_mm: 0.0634765625 * step as f64,
    }
}

fn calibrate(p: FieldFn, s: ResponseFn, seed: u64, f: &Field) -> Calibration {
    fit_readings(&readings(p, s, 0.015, seed), f)
}

/// The calibration `dmdsl calibrate` fits to `r` (5 mm zones, 5 mm extrapolation).
fn fit_readings(r: &[Reading], f: &Field) -> Calibration {
    let opts = FitOptions {
        units: Units::MwCm2,
        zone_mm: 5.0,
        extrapolate_mm: 5.0,
        field_mm: (f.width_mm(), f.height_mm()),
        degree: None,
    };
    fit(r, Path::new("m.csv"), &opts).unwrap().calibration
}

/// (zone-mean spread, per-pixel spread) of the true irradiance of the plate mask over the
/// calibrated 65 × 45 mm area.
fn judge(mask: &[u8], f: &Field, p: FieldFn, s: ResponseFn) -> (f64, f64) {
    let (w, h, px) = (f.width_px as usize, f.height_px as usize, f.pixel_mm);
    zone_and_pixel_spreads(mask.iter().enumerate().map(|(i, &g)| {
        let (r, c) = (i / w, i % w);
        let (x, y) = ((c as f64 + 0.5) * px, (h as f64 - r as f64 - 0.5) * px);
        let e = if g == 0 { 0.0 } else { p(x, y) * s(g as f64) };
        (x, y, e)
    }))
}

/// The plate mask: every pixel fully covered.
fn plate(c: &Compensator, f: &Field) -> Vec<u8> {
    let mut m = dmdsl::raster::Mask {
        width: f.width_px,
        height: f.height_px,
        data: vec![255; (f.width_px * f.height_px) as usize],
    };
    c.apply(&mut m);
    m.data
}

/// The per-pixel limit the calibration is held to (docs/CALIBRATION.md): 3 %, or 5 %
/// where one gray step of the mask moves irradiance by more than 2 %.
fn pixel_limit(mask: &[u8], s: ResponseFn) -> f64 {
    let coarse = mask
        .iter()
        .any(|&g| g > 0 && g < 255 && s(g as f64 + 1.0) / s(g as f64) - 1.0 > 0.02);
    if coarse {
        5.0
    } else {
        3.0
    }
}

/// Held-out sets (one fixed seed each, none used to tune the method): every zone-mode
/// zone-mean spread within 2.5 % and every pixel-mode per-pixel spread within its
/// limit (3 %, or 5 % where one gray step moves irradiance by more than 2 %).
/// Quarter-resolution field (0.254 mm pixels) to keep the debug build fast.
#[test]
fn held_out_sets_are_flattened_within_the_calibration_limits() {
    let f = field(4);
    // Four of the eight field × response pairs (fits are slow in a debug build); the
    // ignored `sweep_report` runs all eight with three seeds each.
    let cases: [(FieldFn, ResponseFn); 4] = [
        (p_cubic, s_published),
        (p_gauss, s_gamma),
        (p_published, s_gamma),
        (p_vignette, s_gamma),
    ];
    for (k, (p, s)) in cases.into_iter().enumerate() {
        let cal = calibrate(p, s, 5000 + k as u64, &f);
        let cz = Compensator::new(&cal, &f, Mode::Zone, Dither::Auto).unwrap();
        let (zone, _) = judge(&plate(&cz, &f), &f, p, s);
        assert!(zone <= 2.5, "set {k}: zone-mean spread {zone:.2} % > 2.5 %");
        let cp = Compensator::new(&cal, &f, Mode::Pixel, Dither::Off).unwrap();
        let mask = plate(&cp, &f);
        let (_, pixel) = judge(&mask, &f, p, s);
        let limit = pixel_limit(&mask, s);
        assert!(
            pixel <= limit,
            "set {k}: per-pixel spread {pixel:.2} % > {limit} %"
        );
        // The model's own prediction agrees with the truth to within the fit's error.
        let pred = cp.prediction.spreads.after_pixel_pct;
        assert!(pred <= limit, "set {k}: predicted {pred:.2} %");
    }
}

#[test]
#[ignore]
fn sweep_report() {
    let fields: [(&str, FieldFn); 5] = [
        ("cubic", p_cubic),
        ("gauss", p_gauss),
        ("published", p_published),
        ("vignette", p_vignette),
        ("lens", p_lens),
    ];
    let resps: [(&str, ResponseFn); 2] = [("published", s_published), ("gamma", s_gamma)];
    let step: usize = std::env::var("SWEEP_STEP")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let f = field(step);
    for (pn, p) in fields {
        for (sn, s) in resps {
            for seed in 0..3u64 {
                let t = std::time::Instant::now();
                let cal = calibrate(p, s, 1000 + seed, &f);
                let fs = cal.fit.as_ref().unwrap();
                // Model error of P over the area (normalised).
                let mut ratios = Vec::new();
                for i in 0..=130 {
                    for j in 0..=90 {
                        let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
                        ratios.push(cal.field.eval(x, y) / p(x, y));
                    }
                }
                let perr = spread(&ratios);
                let tfit = t.elapsed().as_secs_f64();
                // Noise-free fit: model bias alone.
                let cal0 = fit_readings(&readings(p, s, 0.0, 1), &f);
                let mut r0 = Vec::new();
                for i in 0..=130 {
                    for j in 0..=90 {
                        let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
                        r0.push(cal0.field.eval(x, y) / p(x, y));
                    }
                }
                let bias = spread(&r0);
                // Quantization alone: true P and S, nearest level per pixel.
                let q = {
                    let (w, h, px) = (f.width_px as usize, f.height_px as usize, f.pixel_mm);
                    let mut pts = Vec::new();
                    for r in 0..h {
                        for c in 0..w {
                            let (x, y) = ((c as f64 + 0.5) * px, (h as f64 - r as f64 - 0.5) * px);
                            if y <= 45.0 {
                                pts.push(p(x, y));
                            }
                        }
                    }
                    let pmin = pts.iter().cloned().fold(f64::INFINITY, f64::min);
                    let lv: Vec<f64> = (1..=255).map(|g| s(g as f64)).collect();
                    let e: Vec<f64> = pts
                        .iter()
                        .map(|&pv| {
                            let t = pmin * s(255.0) / pv;
                            let best = lv
                                .iter()
                                .cloned()
                                .min_by(|a, b| (a - t).abs().total_cmp(&(b - t).abs()))
                                .unwrap();
                            best * pv
                        })
                        .collect();
                    spread(&e)
                };
                let cz = Compensator::new(&cal, &f, Mode::Zone, Dither::Auto).unwrap();
                let (zz, _) = judge(&plate(&cz, &f), &f, p, s);
                let cp = Compensator::new(&cal, &f, Mode::Pixel, Dither::Off).unwrap();
                let (_, pp) = judge(&plate(&cp, &f), &f, p, s);
                println!(
                    "{pn:9} {sn:9} seed {seed}: {:?} deg {} P-err {perr:.2} % (bias {bias:.2}, quant {q:.2}) zone {zz:.2} % pixel {pp:.2} % (fit {tfit:.2}s total {:.2}s)",
                    fs.form,
                    fs.degree,
                    t.elapsed().as_secs_f64()
                );
            }
        }
    }
}
