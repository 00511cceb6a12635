//! Calibration test jobs and their fits (docs/CALIBRATION.md): the working-curve windowpane
//! ([`working_curve`]), the measurement sheets the user fills in ([`Sheet`]) and the
//! least-squares fit of Jacobs' working curve Cd = Dp·ln(E/Ec) ([`fit_resin`]), the
//! accuracy part ([`accuracy_part`], [`fn@accuracy`]) and the blur job with the fit of the
//! point-spread function's σ ([`psf`]).

use crate::error::{Error, Result};
use crate::optics::Compensator;
use crate::optics::{Dither, Mode};
use crate::plot::{Chart, Panel, Series, Style};
use crate::profile::Profile;
use crate::raster::Mask;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub mod accuracy;
pub mod psf;

pub use accuracy::{accuracy, accuracy_part};

/// One window of the working-curve job.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    /// Centre, mm from the field's bottom-left corner.
    pub centre_mm: [f64; 2],
    /// The pixel value it is drawn with.
    pub gray: u8,
    /// Its dose as an exposure time at the brightest gray's irradiance, s.
    pub exposure_s: f64,
    /// Its dose, mJ/cm², where the light calibration is absolute.
    pub dose_mj_cm2: Option<f64>,
}

/// The working-curve job: windows one layer thick, each lit at its own gray level for the
/// layer's one exposure (`layer_s`); `dose` is the field's pixel value map.
#[derive(Debug, Clone)]
pub struct WorkingCurve {
    /// The windows, doses ascending.
    pub windows: Vec<Window>,
    /// The part: one box per window, binary STL in build-plane coordinates.
    pub stl: Vec<u8>,
    /// Pixel value of every field pixel (0 outside the windows).
    pub dose: Mask,
    /// The layer's exposure time (the longest window's), s.
    pub layer_s: f64,
}

/// The windowpane of `n` windows (2..=64) with a geometric series of exposures from `lo`
/// to `hi` s at the target irradiance E*. Gray levels come from the single projector's
/// calibrated response S(g) (the nearest level), and each window's exposure is expressed at
/// E*: t·P(x, y)·S(g)/E*; without a calibration, S is taken as linear in the pixel value
/// and P as flat.
pub fn working_curve(
    p: &Profile,
    n: usize,
    [lo, hi]: [f64; 2],
) -> std::result::Result<WorkingCurve, String> {
    if !(2..=64).contains(&n) {
        return Err(format!(
            "working curve: {}; give 2 to 64 windows",
            crate::text::count(n as u64, "window", "windows")
        ));
    }
    let (l, h) = (crate::text::number(lo), crate::text::number(hi));
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return Err(format!(
            "working curve: exposures {l}..{h} s; give 0 < LO < HI"
        ));
    }
    // The longest window's exposure is the layer's.
    if hi > crate::profile::MAX_DURATION_S {
        return Err(format!(
            "working curve: exposures {l}..{h} s; the longest is the layer's exposure, at most {} s",
            crate::text::number(crate::profile::MAX_DURATION_S)
        ));
    }
    let f = p.field();
    let (w, h) = (f.width_mm(), f.height_mm());
    let cols = ((n as f64 * w / h).sqrt().ceil() as usize).min(n);
    let rows = n.div_ceil(cols);
    let pitch = (0.8 * w / cols as f64).min(0.8 * h / rows as f64);
    let side = (0.6 * pitch).min(10.0);
    let cal = (p.projector.len() == 1)
        .then(|| p.projector[0].calibration.as_ref())
        .flatten();
    // The response's levels and the target irradiance E* a compensated job delivers.
    let light = match cal {
        Some(c) => {
            let comp = Compensator::new(c, &f, Mode::Zone, Dither::Auto)?;
            Some((c, c.response.levels(), comp.prediction.target))
        }
        None => None,
    };
    let th = p.slicing.layer_height_mm.get();
    let (mut windows, mut stl) = (Vec::with_capacity(n), Vec::new());
    let mut dose = Mask::zeros(f.width_px, f.height_px);
    for i in 0..n {
        let x = w / 2.0 + ((i % cols) as f64 - (cols - 1) as f64 / 2.0) * pitch;
        let y = h / 2.0 + ((rows - 1) as f64 / 2.0 - (i / cols) as f64) * pitch;
        let want = (lo.ln() + (hi / lo).ln() * i as f64 / (n - 1) as f64).exp() / hi;
        // The level whose irradiance at (x, y) is nearest `want`·E* (never mirror off), and
        // its irradiance relative to E*.
        let (gray, e) = match &light {
            Some((c, l, t)) => {
                let p = c.field.eval(x, y);
                let k = l.nearest(want * t / p).max(usize::from(l.gray[0] == 0));
                (l.gray[k], p * l.s[k] / t)
            }
            None => (
                (want * 255.0).round().max(1.0) as u8,
                (want * 255.0).round().max(1.0) / 255.0,
            ),
        };
        let absolute = light
            .as_ref()
            .filter(|l| l.0.units == crate::profile::calibration::Units::MwCm2);
        let dose_mj_cm2 = absolute.map(|l| hi * e * l.2);
        windows.push(Window {
            centre_mm: [x, y],
            gray,
            exposure_s: hi * e,
            dose_mj_cm2,
        });
        push_box(
            &mut stl,
            [x - side / 2.0, y - side / 2.0, 0.0],
            [x + side / 2.0, y + side / 2.0, th],
        );
        let px = f.pixel_mm;
        for r in 0..f.height_px as usize {
            let yr = (f.height_px as f64 - r as f64 - 0.5) * px;
            if (yr - y).abs() <= side / 2.0 + px {
                let c0 = ((x - side / 2.0) / px - 1.0).max(0.0) as usize;
                let c1 = (((x + side / 2.0) / px + 1.0) as usize).min(f.width_px as usize);
                dose.data[r * f.width_px as usize..][c0..c1].fill(gray);
            }
        }
    }
    Ok(WorkingCurve {
        windows,
        stl: stl_file(stl),
        dose,
        layer_s: hi,
    })
}

/// Appends the 12 triangles of the box from `a` to `b` (binary STL records).
fn push_box(out: &mut Vec<u8>, a: [f64; 3], b: [f64; 3]) {
    // Corner k has x of b when bit 0 is set, y when bit 1, z when bit 2; faces CCW outside.
    const FACES: [[usize; 4]; 6] = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let corner = |k: usize| [0, 1, 2].map(|d| if k >> d & 1 == 1 { b[d] } else { a[d] });
    FACES.iter().for_each(|q| push_quad(out, q.map(corner)));
}

/// Appends a square frame at (x, y): a hole of `s` in a wall 1 mm wide, 3 mm tall (one
/// closed shell: outer and inner walls, top and bottom rings).
fn push_frame(out: &mut Vec<u8>, x: f64, y: f64, s: f64) {
    let sq =
        |lo: f64, hi: f64| [[lo, lo], [hi, lo], [hi, hi], [lo, hi]].map(|[u, v]| [x + u, y + v]);
    let (o, i) = (sq(0.0, s + 2.0), sq(1.0, s + 1.0));
    let at = |p: [f64; 2], z: f64| [p[0], p[1], z];
    for k in 0..4 {
        let j = (k + 1) % 4;
        for q in [
            [at(o[k], 0.), at(o[j], 0.), at(o[j], 3.), at(o[k], 3.)],
            [at(i[j], 0.), at(i[k], 0.), at(i[k], 3.), at(i[j], 3.)],
            [at(o[k], 3.), at(o[j], 3.), at(i[j], 3.), at(i[k], 3.)],
            [at(o[j], 0.), at(o[k], 0.), at(i[k], 0.), at(i[j], 0.)],
        ] {
            push_quad(out, q);
        }
    }
}

/// Appends the planar quad `p` (counter-clockwise seen from outside) as two triangles.
fn push_quad(out: &mut Vec<u8>, p: [[f64; 3]; 4]) {
    let (u, v) = (
        [0, 1, 2].map(|d| p[1][d] - p[0][d]),
        [0, 1, 2].map(|d| p[2][d] - p[0][d]),
    );
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    let len = n.iter().map(|c| c * c).sum::<f64>().sqrt();
    for t in [[0, 1, 2], [0, 2, 3]] {
        let pts = t.iter().flat_map(|&k| p[k]);
        n.map(|c| c / len)
            .into_iter()
            .chain(pts)
            .for_each(|c| out.extend((c as f32).to_le_bytes()));
        out.extend([0, 0]);
    }
}

/// A measurement sheet (CSV with a header row) read whole; cells are looked up by column
/// name, and a bad cell is an error naming the file, its line and column.
#[derive(Debug)]
pub struct Sheet {
    /// The file.
    pub path: PathBuf,
    /// SHA-256 of its bytes.
    pub sha256: String,
    header: Vec<String>,
    rows: Vec<(u64, csv::StringRecord)>,
}

impl Sheet {
    /// Reads `path`, which must have the columns `required`.
    pub fn read(path: &Path, required: &[&str]) -> Result<Sheet> {
        let bytes = crate::input::read_file(path, "measurement sheet", 64 << 20)?;
        let bad = |e: csv::Error| {
            Error::input(
                path,
                format!("line {}: {e}", e.position().map_or(0, |p| p.line())),
            )
        };
        let mut r = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .from_reader(&bytes[..]);
        let header: Vec<String> = r
            .headers()
            .map_err(bad)?
            .iter()
            .map(str::to_string)
            .collect();
        if let Some(c) = required.iter().find(|c| !header.iter().any(|h| h == *c)) {
            return Err(Error::input(
                path,
                format!(
                    "line 1: no column {c} (the header has {})",
                    header.join(",")
                ),
            ));
        }
        let rows = r
            .records()
            .map(|x| x.map(|x| (x.position().map_or(0, |p| p.line()), x)))
            .collect::<std::result::Result<_, _>>();
        let sha256 = crate::digest::sha256_hex(&bytes);
        Ok(Sheet {
            path: path.into(),
            sha256,
            header,
            rows: rows.map_err(bad)?,
        })
    }

    /// The file's name (without its directory), as a fit records it.
    pub fn file_name(&self) -> String {
        self.path
            .file_name()
            .map_or(String::new(), |f| f.to_string_lossy().into())
    }

    /// The number of data rows.
    pub fn rows(&self) -> usize {
        self.rows.len()
    }

    /// Row `i`'s text in column `col` (empty when the row is short) and its line.
    pub fn text(&self, i: usize, col: &str) -> (&str, u64) {
        let k = self.header.iter().position(|h| h == col);
        (
            k.and_then(|k| self.rows[i].1.get(k)).unwrap_or(""),
            self.rows[i].0,
        )
    }

    /// Row `i`'s number in column `col`: `None` when empty; text, a non-finite number or a
    /// negative one where `non_negative` is an error.
    pub fn num(&self, i: usize, col: &str, non_negative: bool) -> Result<Option<f64>> {
        let (t, line) = self.text(i, col);
        let why = match t.parse::<f64>() {
            _ if t.is_empty() => return Ok(None),
            Ok(v) if v.is_finite() && (v >= 0.0 || !non_negative) => return Ok(Some(v)),
            Ok(_) => format!("{t} is negative or not finite"),
            Err(_) => format!("{t:?} is not a number"),
        };
        Err(Error::input(
            &self.path,
            format!("line {line}, column {col}: {why}"),
        ))
    }
}

/// The working-curve fit of a sheet.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResinFit {
    /// The sheet's file name.
    pub sheet: String,
    /// SHA-256 of the sheet.
    pub sheet_sha256: String,
    /// Penetration depth Dp, mm.
    pub dp_mm: f64,
    /// Standard error of Dp, mm.
    pub dp_se_mm: f64,
    /// Critical energy Ec, mJ/cm² (the sheet's doses are absolute).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ec_mj_cm2: Option<f64>,
    /// Critical exposure time at the brightest gray's irradiance, s (relative doses).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub critical_exposure_s: Option<f64>,
    /// Standard error of Ec or of the critical exposure time (same unit).
    pub critical_se: f64,
    /// Residuals (measured − fitted cure depth), mm: [line, dose, measured, residual].
    pub residuals: Vec<[f64; 4]>,
    /// RMS of the residuals, mm.
    pub residual_rms_mm: f64,
}

/// Fits Cd = Dp·ln(E/Ec) by least squares in ln E over the windows that cured (cured_mm >
/// 0); E is `dose_mj_cm2` when every such window has one, else `exposure_s`.
pub fn fit_resin(s: &Sheet) -> Result<ResinFit> {
    let mut pts = Vec::new();
    for i in 0..s.rows() {
        let cd = s.num(i, "cured_mm", true)?;
        let (t, d) = (
            s.num(i, "exposure_s", true)?,
            s.num(i, "dose_mj_cm2", true)?,
        );
        if let Some(cd) = cd.filter(|&c| c > 0.0) {
            pts.push((s.text(i, "window").1 as f64, t, d, cd));
        }
    }
    let absolute = pts.iter().all(|p| p.2.is_some());
    let mut xy = Vec::new();
    for &(line, t, d, cd) in &pts {
        match if absolute { d } else { t }.filter(|&e| e > 0.0) {
            Some(e) => xy.push((line, e, cd)),
            None => {
                return Err(Error::input(
                    &s.path,
                    format!(
                        "line {line}, column exposure_s: a cured window needs a positive exposure"
                    ),
                ))
            }
        }
    }
    let n = xy.len() as f64;
    let mx = xy.iter().map(|p| p.1.ln()).sum::<f64>() / n;
    let my = xy.iter().map(|p| p.2).sum::<f64>() / n;
    let sxx: f64 = xy.iter().map(|p| (p.1.ln() - mx).powi(2)).sum();
    let dp = xy.iter().map(|p| (p.1.ln() - mx) * (p.2 - my)).sum::<f64>() / sxx;
    if xy.len() < 3 || dp.is_nan() || dp <= 0.0 {
        let why = if xy.len() < 3 {
            format!(
                "{} cured windows (cured_mm > 0), the fit needs at least 3",
                xy.len()
            )
        } else {
            format!("the fit's Dp = {dp:.4} mm is not positive (cure depth must grow with dose)")
        };
        return Err(Error::input(&s.path, why));
    }
    let b = my - dp * mx;
    let lnc = -b / dp;
    let residuals: Vec<[f64; 4]> = xy
        .iter()
        .map(|&(l, e, cd)| [l, e, cd, cd - dp * (e.ln() - lnc)])
        .collect();
    let ss: f64 = residuals.iter().map(|r| r[3] * r[3]).sum();
    let s2 = if n > 2.0 { ss / (n - 2.0) } else { 0.0 };
    // Var(b) = s²(1/n + x̄²/Sxx), Cov(Dp, b) = −x̄ s²/Sxx; ln Ec = −b/Dp by the delta method.
    let (vd, vb, cov) = (s2 / sxx, s2 * (1.0 / n + mx * mx / sxx), -mx * s2 / sxx);
    let vl = vb / (dp * dp) + b * b * vd / dp.powi(4) - 2.0 * b * cov / dp.powi(3);
    let crit = crate::round::significant(lnc.exp(), 6);
    // Written to 6 significant digits (standard errors to 3, lengths to 1 nm), not with the
    // fit's rounding noise.
    let (sig, nm) = (crate::round::significant, |x| crate::round::decimals(x, 6));
    Ok(ResinFit {
        sheet: s.file_name(),
        sheet_sha256: s.sha256.clone(),
        dp_mm: sig(dp, 6),
        dp_se_mm: sig(vd.sqrt(), 3),
        ec_mj_cm2: absolute.then_some(crit),
        critical_exposure_s: (!absolute).then_some(crit),
        critical_se: sig(crit * vl.max(0.0).sqrt(), 3),
        residuals: residuals
            .iter()
            .map(|r| [r[0], r[1], r[2], nm(r[3])])
            .collect(),
        residual_rms_mm: nm((ss / n).sqrt()),
    })
}

impl ResinFit {
    /// The chart of the working curve: the measured points and the fitted line against ln E.
    pub fn chart(&self) -> Chart {
        let (unit, name) = match self.ec_mj_cm2 {
            Some(_) => ("mJ/cm²", "Ec"),
            None => ("s", "critical exposure"),
        };
        let pts: Vec<(f64, f64)> = self.residuals.iter().map(|r| (r[1].ln(), r[2])).collect();
        let c = self.ec_mj_cm2.or(self.critical_exposure_s).unwrap_or(1.0);
        let hi = pts.iter().map(|p| p.0).fold(f64::MIN, f64::max);
        let line = (0..=20)
            .map(|k| c.ln() + (hi - c.ln()) * k as f64 / 20.0)
            .map(|x| (x, self.dp_mm * (x - c.ln())))
            .collect();
        Chart {
            title: format!(
                "{}: working curve Cd = Dp·ln(E/Ec), Dp = {:.4} mm, {name} = {c:.4} {unit}",
                self.sheet, self.dp_mm,
            ),
            x_label: format!("ln(E / 1 {unit}), E = dose (as exposure time when in s)"),
            x_whole: false,
            width: 1000,
            height: 700,
            panels: vec![Panel {
                y_label: "cured thickness Cd (mm)".into(),
                series: vec![
                    Series::new("fit", [31, 119, 180], Style::Line, line),
                    Series::new("measured", [214, 39, 40], Style::Points, pts),
                ],
                y_from_zero: true,
                ..Default::default()
            }],
        }
    }

    /// Reads a resin calibration file (as written by `dmdsl calibrate resin`) and applies its
    /// Dp (and Ec, when absolute) to `profile`'s resin, which then records the sheet.
    pub fn apply_file(path: &Path, profile: &mut Profile) -> Result<()> {
        let f: ResinFit = read_fit(path, "resin calibration")?;
        let pos = |v: f64, k: &str| {
            crate::units::Positive::new(v)
                .ok_or_else(|| Error::input(path, format!("{k} = {v} is not positive")))
        };
        let source = Some(format!("{} sha256:{}", f.sheet, f.sheet_sha256));
        (profile.resin.dp_mm, profile.resin.dp_source) = (pos(f.dp_mm, "dp_mm")?, source.clone());
        if let Some(ec) = f.ec_mj_cm2 {
            (profile.resin.ec_mj_cm2, profile.resin.ec_source) = (pos(ec, "ec_mj_cm2")?, source);
        }
        Ok(())
    }
}

/// Reads a fit file `path` (a TOML `what`, as a `dmdsl calibrate` command writes it).
fn read_fit<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let src = crate::input::read_text(path, what)?;
    toml::from_str(&src).map_err(|e| Error::input(path, crate::profile::one_line(&e.to_string())))
}

/// Binary STL of `records` (50-byte triangle records).
fn stl_file(records: Vec<u8>) -> Vec<u8> {
    let mut out = b"dmdsl calibration test part".to_vec();
    out.resize(80, b' ');
    out.extend(((records.len() / 50) as u32).to_le_bytes());
    out.extend(records);
    out
}
