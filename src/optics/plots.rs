//! The pictures `dmdsl calibrate` writes next to the calibration file, in the style of
//! Figs. 3 and 4 of Xu et al. 2010 ("Novel stereolithography system employing digital
//! micro-mirror device", Chinese J. Lasers 37(7)): measured and fitted irradiance per zone
//! before and after zone compensation, the zone grays, and S(g) with the data and the valid
//! gray range.

use super::calib::FitResult;
use super::Compensator;
use super::Units;
use crate::plot::{Band, Chart, Format, Heatmap, Panel, Series, Style};
use std::path::{Path, PathBuf};

/// Edge of one zone's cell in the heatmaps, px.
const CELL_PX: f32 = 80.0;

/// The plot file `<stem of out>-<suffix>.png` beside the calibration file `out`.
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

/// An annotated heatmap PNG of per-zone values (row 0 = top) over the zone grid, in mm from
/// the field's bottom-left corner, on a colour scale from `range` widened to the values.
fn zone_heatmap(
    z: &ZoneValues,
    title: String,
    quantity: &str,
    values: Vec<f64>,
    range: [f64; 2],
    missing: &str,
) -> Vec<u8> {
    Heatmap {
        title,
        cols: z.cols,
        rows: z.rows,
        values,
        x_range: [0.0, z.cols as f64 * z.zone_mm],
        y_range: [0.0, z.rows as f64 * z.zone_mm],
        x_label: "x (mm)".into(),
        y_label: "y (mm)".into(),
        quantity: quantity.into(),
        range: Some(range),
        cell_px: CELL_PX,
        annotate: true,
        missing: missing.into(),
    }
    .render()
    .encode(Format::Png)
}

/// The colour bar's label for irradiance in `units`.
fn irradiance_label(units: Units) -> &'static str {
    match units {
        Units::MwCm2 => "irradiance (mW/cm²)",
        Units::Relative => "irradiance (relative units)",
    }
}

/// (smallest, largest) of the finite values of `v`.
fn range(v: &[f64]) -> (f64, f64) {
    v.iter()
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

/// (max − min) / mean of the finite values of `v`, %; 0 if there are none.
fn spread_pct(v: &[f64]) -> f64 {
    let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if f.is_empty() {
        return 0.0;
    }
    let (lo, hi) = range(&f);
    (hi - lo) / (f.iter().sum::<f64>() / f.len() as f64) * 100.0
}

/// The plot files (path, PNG bytes) for a fit, named after `out` (the calibration file):
/// measured and fitted full-on irradiance per zone (on one scale), both after zone
/// compensation (% of target; the fitted spread over the zones inside the calibrated
/// area), the zone grays and the response S(g).
pub fn calibration_plots(
    out: &Path,
    fit: &FitResult,
    zone: &Compensator,
    pixel: &Compensator,
) -> Vec<(PathBuf, Vec<u8>)> {
    let z = ZoneValues::new(fit, zone);
    let pr = &zone.prediction;
    let (lo, hi) = range(&[z.measured.clone(), z.fitted.clone()].concat());
    let irradiance = irradiance_label(z.units);
    let compensated = "irradiance (% of the target E*)";
    let inside: Vec<f64> = (z.fitted_after.iter().zip(&pr.zone_inside))
        .map(|(&x, &ins)| if ins { x } else { f64::NAN })
        .collect();
    let grays = pr.zone_gray.iter().map(|&g| g as f64).collect();
    let gray_range = [fit.calibration.response.valid_gray()[0] as f64, 255.0];
    let maps = [
        (
            "measured",
            format!(
                "Measured irradiance per zone at the brightest valid gray: spread {:.1} %",
                spread_pct(&z.measured)
            ),
            irradiance,
            z.measured.clone(),
            [lo, hi],
            "not measured",
        ),
        (
            "fitted",
            format!(
                "Fitted irradiance P(x, y) · S at the brightest valid gray, zone means: spread {:.1} %",
                pr.spreads.before_zone_pct
            ),
            irradiance,
            z.fitted.clone(),
            [lo, hi],
            "",
        ),
        (
            "measured-compensated",
            format!(
                "Measured × S(zone gray): irradiance after zone compensation, spread {:.2} %",
                spread_pct(&z.measured_after)
            ),
            compensated,
            z.measured_after.clone(),
            COMPENSATED_BAND_PCT,
            "not measured",
        ),
        (
            "fitted-compensated",
            format!(
                "Fitted irradiance after zone compensation: spread {:.2} % inside the calibrated area",
                spread_pct(&inside)
            ),
            compensated,
            z.fitted_after.clone(),
            COMPENSATED_BAND_PCT,
            "",
        ),
        (
            "zone-grays",
            format!(
                "Zone grays: the pixel value of a fully covered pixel, {} mm zones",
                z.zone_mm
            ),
            "pixel value (255 = mirror fully on)",
            grays,
            gray_range,
            "",
        ),
    ];
    let mut files: Vec<(PathBuf, Vec<u8>)> = maps
        .into_iter()
        .map(|(suffix, title, quantity, values, range, missing)| {
            let png = zone_heatmap(&z, title, quantity, values, range, missing);
            (sibling(out, suffix), png)
        })
        .collect();
    let response = response_chart(fit, pr.s_max, pixel.prediction.spreads.after_pixel_pct);
    files.push((sibling(out, "response"), response));
    files
}

/// Colours of the response chart: readings, excluded levels, the measured and the
/// interpolated gray ranges.
const GRAY: [u8; 3] = [170, 170, 170];
const ORANGE: [u8; 3] = [255, 127, 14];
const GREEN: [u8; 3] = [44, 160, 44];
const PEACH: [u8; 3] = [255, 187, 120];

/// The colour scale of the compensated heatmaps, % of target.
const COMPENSATED_BAND_PCT: [f64; 2] = [97.0, 103.0];

/// Per-zone values of a fit on the compensator's zone grid (row 0 = top): what the
/// heatmaps show.
struct ZoneValues {
    /// Irradiance units of the calibration.
    units: Units,
    /// Zone edge, mm.
    zone_mm: f64,
    /// Zone grid columns.
    cols: usize,
    /// Zone grid rows.
    rows: usize,
    /// Measured full-on irradiance (mean of the measured positions in the zone; NaN where
    /// none).
    measured: Vec<f64>,
    /// Fitted full-on irradiance, the zone mean of P · S at the brightest valid gray.
    fitted: Vec<f64>,
    /// Measured irradiance times S of the zone's gray after zone compensation, % of target.
    measured_after: Vec<f64>,
    /// Predicted irradiance after zone compensation, % of target.
    fitted_after: Vec<f64>,
}

impl ZoneValues {
    fn new(fit: &FitResult, zone: &Compensator) -> ZoneValues {
        let cal = &fit.calibration;
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
        // After zone compensation: each zone at the effective S of its gray (a mixing
        // zone's mean of its two grays).
        let pct = |v: f64| v / target * 100.0;
        let measured_after: Vec<f64> = (0..nz)
            .map(|i| pct(measured[i] / s_max * (pr.zone_after[i] / pr.zone_p[i])))
            .collect();
        let fitted_after: Vec<f64> = pr.zone_after.iter().map(|&v| pct(v)).collect();
        ZoneValues {
            units: cal.units,
            zone_mm: zmm,
            cols,
            rows,
            measured,
            fitted,
            measured_after,
            fitted_after,
        }
    }
}

/// S(g): the fitted curve over the valid range, the level values, the individual readings
/// (divided by `s_max` · the fitted P) and bands for the measured and the interpolated gray
/// ranges; the title gives the pixel mode's predicted spread.
fn response_chart(fit: &FitResult, s_max: f64, pixel_spread_pct: f64) -> Vec<u8> {
    let cal = &fit.calibration;
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
        Series::new("readings ÷ fitted P(x, y)", GRAY, Style::Points, readings),
        Series::new("S(g), fitted", [31, 119, 180], Style::Line, curve),
        Series::new("level values", [214, 39, 40], Style::Points, valid_pts),
    ];
    if !excluded_pts.is_empty() {
        series.push(Series::new(
            "excluded levels",
            ORANGE,
            Style::Points,
            excluded_pts,
        ));
    }
    let [mlo, mhi] = (cal.fit.as_ref().map_or([glo, ghi], |f| f.measured_gray)).map(f64::from);
    let mut bands = vec![Band::new(
        mlo,
        mhi,
        GREEN,
        "measured gray range (S monotone)",
    )];
    if f64::from(glo) < mlo {
        bands.push(Band::new(
            glo.into(),
            mlo,
            PEACH,
            "interpolated down to S(0) = 0",
        ));
    }
    Chart {
        title: format!(
            "Gray response S(g): valid {glo}–{ghi}, pixel mode spread {pixel_spread_pct:.2} %"
        ),
        x_label: "pixel value g (255 = mirror fully on)".into(),
        x_whole: false,
        width: 900,
        height: 600,
        panels: vec![Panel {
            y_label: "S(g), 1 at the brightest valid gray".into(),
            series,
            bands,
            y_from_zero: true,
        }],
    }
    .render()
    .encode(Format::Png)
}
