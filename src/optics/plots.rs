//! The pictures `dmdsl calibrate` writes next to the calibration file (seeds/000 Fig. 3
//! and 4 style): measured and fitted irradiance per zone before and after zone
//! compensation, the zone grays, and S(g) with the data and the valid gray range.

use super::calib::FitResult;
use super::Compensator;
use crate::plot::{heatmap_png, Band, Chart, Heatmap, Series, Style};
use std::path::{Path, PathBuf};

const CELL_PX: u32 = 80;

fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "calibration".into());
    out.with_file_name(format!("{stem}-{suffix}.png"))
}

/// Zone (row from top, col) of build-plane point (x, y) on the compensator's zone grid.
fn zone_of(zone_mm: f64, rows: usize, cols: usize, x: f64, y: f64) -> Option<usize> {
    if x < 0.0 || y < 0.0 {
        return None;
    }
    let (c, rb) = ((x / zone_mm) as usize, (y / zone_mm) as usize);
    (c < cols && rb < rows).then(|| (rows - 1 - rb) * cols + c)
}

fn heat(
    title: String,
    unit: &str,
    cols: usize,
    rows: usize,
    values: Vec<f64>,
    lo: f64,
    hi: f64,
) -> Vec<u8> {
    heatmap_png(&Heatmap {
        title,
        unit: unit.into(),
        cols,
        rows,
        values,
        vmin: lo,
        vmax: hi,
        cell_px: CELL_PX,
        annotate: true,
    })
}

fn range(v: &[f64]) -> (f64, f64) {
    v.iter()
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

fn spread_pct(v: &[f64]) -> f64 {
    let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if f.is_empty() {
        return 0.0;
    }
    let (lo, hi) = range(&f);
    (hi - lo) / (f.iter().sum::<f64>() / f.len() as f64) * 100.0
}

/// The plot files (path, PNG bytes) for a fit, named after `out` (the calibration file).
pub fn calibration_plots(
    out: &Path,
    fit: &FitResult,
    zone: &Compensator,
    pixel: &Compensator,
) -> Vec<(PathBuf, Vec<u8>)> {
    let cal = &fit.calibration;
    let unit = cal.units.as_str();
    let zmm = cal.zone_mm.get();
    let pr = &zone.prediction;
    let (cols, rows) = pr.zone_grid;
    let nz = cols * rows;
    let s_max = pr.s_max;
    let target = pr.target;

    // Measured full-on irradiance per zone (mean of the measured positions in it).
    let mut msum = vec![0.0; nz];
    let mut mcnt = vec![0usize; nz];
    for z in &fit.zones {
        if let Some(i) = zone_of(zmm, rows, cols, z.x_mm, z.y_mm) {
            msum[i] += z.measured_p * s_max;
            mcnt[i] += 1;
        }
    }
    let measured: Vec<f64> = (0..nz)
        .map(|i| {
            if mcnt[i] > 0 {
                msum[i] / mcnt[i] as f64
            } else {
                f64::NAN
            }
        })
        .collect();
    let fitted: Vec<f64> = (0..nz).map(|i| pr.zone_p[i] * s_max).collect();
    // After zone compensation: each zone at its gray.
    // Effective S of each zone (a mixing zone's mean of its two grays).
    let gray_s: Vec<f64> = (0..nz).map(|i| pr.zone_after[i] / pr.zone_p[i]).collect();
    let pct = |v: f64| v / target * 100.0;
    let measured_after: Vec<f64> = (0..nz)
        .map(|i| pct(measured[i] / s_max * gray_s[i]))
        .collect();
    let fitted_after: Vec<f64> = pr.zone_after.iter().map(|&v| pct(v)).collect();
    let inside = |v: &[f64]| -> Vec<f64> {
        v.iter()
            .zip(&pr.zone_inside)
            .map(|(&x, &ins)| if ins { x } else { f64::NAN })
            .collect()
    };

    let (lo, hi) = range(&measured.iter().chain(&fitted).copied().collect::<Vec<_>>());
    let mut files = Vec::new();
    files.push((
        sibling(out, "measured"),
        heat(
            format!(
                "Measured irradiance, mirrors fully on ({unit}), spread {:.1} %",
                spread_pct(&measured)
            ),
            unit,
            cols,
            rows,
            measured.clone(),
            lo,
            hi,
        ),
    ));
    files.push((
        sibling(out, "fitted"),
        heat(
            format!(
                "Fitted P(x,y) zone means, fully on ({unit}), spread {:.1} %",
                pr.spreads.before_zone_pct
            ),
            unit,
            cols,
            rows,
            fitted,
            lo,
            hi,
        ),
    ));
    let band = (97.0, 103.0);
    files.push((
        sibling(out, "measured-compensated"),
        heat(
            format!(
                "Measured x S(zone gray), % of target, spread {:.2} %",
                spread_pct(&measured_after)
            ),
            "% of target",
            cols,
            rows,
            measured_after,
            band.0,
            band.1,
        ),
    ));
    files.push((
        sibling(out, "fitted-compensated"),
        heat(
            format!(
                "Fitted, zone compensation, % of target, spread {:.2} %",
                spread_pct(&inside(&fitted_after))
            ),
            "% of target",
            cols,
            rows,
            fitted_after,
            band.0,
            band.1,
        ),
    ));
    files.push((
        sibling(out, "zone-grays"),
        heat(
            format!("Zone grays (pixel value at full coverage), {zmm} mm zones"),
            "gray",
            cols,
            rows,
            pr.zone_gray.iter().map(|&g| g as f64).collect(),
            cal.response.valid_gray()[0] as f64,
            255.0,
        ),
    ));

    // S(g): fitted curve over the valid range, level values, individual readings.
    let [glo, ghi] = cal.response.valid_gray();
    let c = cal.response.curve();
    let curve: Vec<(f64, f64)> = (glo..=ghi).map(|g| (g as f64, c.eval(g as f64))).collect();
    let mut readings = Vec::new();
    let mut valid_pts = Vec::new();
    let mut excluded_pts = Vec::new();
    for l in &fit.levels {
        for &r in &l.points {
            readings.push((l.gray as f64, r / s_max));
        }
        if l.valid {
            valid_pts.push((l.gray as f64, l.s));
        } else {
            excluded_pts.push((l.gray as f64, l.s));
        }
    }
    let mut series = vec![
        Series {
            label: "readings / fitted P".into(),
            color: [170, 170, 170],
            style: Style::Points,
            points: readings,
        },
        Series {
            label: "S(g) fit".into(),
            color: [31, 119, 180],
            style: Style::Line,
            points: curve,
        },
        Series {
            label: "level values".into(),
            color: [214, 39, 40],
            style: Style::Points,
            points: valid_pts,
        },
    ];
    if !excluded_pts.is_empty() {
        series.push(Series {
            label: "excluded levels".into(),
            color: [255, 127, 14],
            style: Style::Points,
            points: excluded_pts,
        });
    }
    let [mlo, mhi] = cal.fit.as_ref().map_or([glo, ghi], |f| f.measured_gray);
    let mut bands = vec![Band {
        x0: mlo as f64,
        x1: mhi as f64,
        color: [44, 160, 44],
        label: "measured, monotone".into(),
    }];
    if glo < mlo {
        bands.push(Band {
            x0: glo as f64,
            x1: mlo as f64,
            color: [255, 187, 120],
            label: "interpolated to S(0) = 0".into(),
        });
    }
    let chart = Chart {
        title: format!(
            "Gray response S(g), valid {glo}..{ghi}, pixel mode spread {:.2} %",
            pixel.prediction.spreads.after_pixel_pct
        ),
        x_label: "pixel value g (255 = fully on)".into(),
        y_label: "S (1 at the brightest valid gray)".into(),
        width: 900,
        height: 600,
        series,
        bands,
    };
    files.push((sibling(out, "response"), chart.render_png()));
    files
}
