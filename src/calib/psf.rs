//! The blur calibration (docs/CALIBRATION.md, "Blur"): the test job of lines and gaps 1 to
//! 8 px wide in X and in Y at five places of each projector's field ([`pattern`]), and the
//! fit of the point-spread function's σ to their printed widths under the cure model
//! ([`fit_psf`], predictions by [`printed_width_px`]).

use super::{push_box, stl_file, Sheet};
use crate::cure::width::{printed_width_px, Drawn, Straight};
use crate::cure::CureModel;
use crate::error::{Error, Result};
use crate::plot::{Chart, Panel, Series, Style};
use crate::profile::Profile;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The drawn widths, pixels.
pub const WIDTHS_PX: [u32; 8] = [1, 2, 3, 4, 5, 6, 7, 8];
/// Dark space between lines and between the parts of a cluster, pixels.
pub const SPACE_PX: u32 = 16;
/// Width of the lit blocks on either side of a gap, pixels.
pub const BLOCK_PX: u32 = 16;
/// Length of every line and gap, pixels.
pub const LENGTH_PX: u32 = 32;
/// Layers the lines and gaps are thick (on a base plate).
pub const FEATURE_LAYERS: u32 = 6;
/// Layers of the base plates under the clusters.
pub const BASE_LAYERS: u32 = 4;
/// Distance of the corner clusters' plates from the edges of the area, mm.
const INSET_MM: f64 = 2.0;
/// The σ bracket of the fit, pixels (the range a profile accepts).
pub const SIGMA_BRACKET: [f64; 2] = [0.05, 5.0];

/// One feature of the blur job.
#[derive(Debug, Clone, PartialEq)]
pub struct PsfFeature {
    /// Line or gap.
    pub kind: Drawn,
    /// The axis its width is measured along: `x` or `y`.
    pub axis: char,
    /// Where in the projector's area: `centre`, `top-left`, `top-right`, `bottom-left`,
    /// `bottom-right`.
    pub place: &'static str,
    /// Centre on the build plane, mm from the field's bottom-left corner.
    pub centre_mm: [f64; 2],
    /// The projector that draws it.
    pub projector: String,
    /// Drawn width, pixels.
    pub drawn_px: u32,
}

/// The blur job: its features and the part (binary STL in build-plane coordinates).
#[derive(Debug, Clone)]
pub struct PsfPattern {
    /// The features, cluster by cluster.
    pub features: Vec<PsfFeature>,
    /// Base plates and features, binary STL.
    pub stl: Vec<u8>,
    /// Layers of the base plates ([`BASE_LAYERS`]).
    pub base_layers: u32,
}

/// A rectangle of field pixels: columns `[0] .. [2]`, rows `[1] .. [3]` (ends exclusive).
type Rect = [i64; 4];

/// A feature of a cluster: kind, axis, drawn width (px), centre (px from the cluster's
/// top-left corner).
type ClusterFeature = (Drawn, char, u32, [f64; 2]);

/// One cluster's lit rectangles and features, in pixels from the cluster's top-left
/// corner, and its size.
fn cluster() -> (Vec<Rect>, Vec<ClusterFeature>, [i64; 2]) {
    let (s, b, l) = (SPACE_PX as i64, BLOCK_PX as i64, LENGTH_PX as i64);
    let (mut rects, mut feats) = (Vec::new(), Vec::new());
    // Along x: lines (top), gaps between blocks (below them); along y the same turned,
    // to the right. `put(along, across0, w)` makes a rectangle `w` wide along the axis.
    let mut comb = |axis: char, origin: [i64; 2], gaps: bool| -> i64 {
        let put = |a0: i64, a1: i64| match axis {
            'x' => [origin[0] + a0, origin[1], origin[0] + a1, origin[1] + l],
            _ => [origin[0], origin[1] + a0, origin[0] + l, origin[1] + a1],
        };
        let centre = |a: f64| match axis {
            'x' => [origin[0] as f64 + a, origin[1] as f64 + 0.5 * l as f64],
            _ => [origin[0] as f64 + 0.5 * l as f64, origin[1] as f64 + a],
        };
        let mut a = 0;
        if gaps {
            rects.push(put(0, b));
            a = b;
        }
        for (k, &w) in WIDTHS_PX.iter().enumerate() {
            let kind = if gaps { Drawn::Gap } else { Drawn::Line };
            feats.push((kind, axis, w, centre(a as f64 + 0.5 * w as f64)));
            let w = w as i64;
            if gaps {
                rects.push(put(a + w, a + w + b));
                a += w + b;
            } else {
                rects.push(put(a, a + w));
                a += w + if k + 1 < WIDTHS_PX.len() { s } else { 0 };
            }
        }
        a
    };
    let lines_x = comb('x', [0, 0], false);
    let gaps_x = comb('x', [0, l + s], true);
    let left = lines_x.max(gaps_x) + s;
    let lines_y = comb('y', [left, 0], false);
    let gaps_y = comb('y', [left + l + s, 0], true);
    let size = [left + 2 * l + s, (2 * l + s).max(lines_y).max(gaps_y)];
    (rects, feats, size)
}

/// Each projector's area for the job, in field pixels: its own pixels, less what another
/// projector also lights (the blended overlap), within its calibrated area when it has one.
fn areas(p: &Profile) -> Vec<Rect> {
    let f = p.field();
    let (px, h) = (f.pixel_mm, f.height_px as f64);
    let rect = |q: &crate::profile::Projector| {
        let [c, r] = q.offset_px.map(i64::from);
        [c, r, c + q.width_px as i64, r + q.height_px as i64]
    };
    let mut out = Vec::new();
    for (i, q) in p.projector.iter().enumerate() {
        let mut a = rect(q);
        for (j, o) in p.projector.iter().enumerate() {
            let o = rect(o);
            let (dx, dy) = (
                a[2].min(o[2]) - a[0].max(o[0]),
                a[3].min(o[3]) - a[1].max(o[1]),
            );
            if j == i || dx <= 0 || dy <= 0 {
                continue;
            }
            // Give up the overlap along the axis where it is narrower.
            let k = if dx <= dy { 0 } else { 1 };
            if o[k] > a[k] {
                a[k + 2] = a[k + 2].min(o[k]);
            } else {
                a[k] = a[k].max(o[k + 2]);
            }
        }
        if let Some(c) = &q.calibration {
            let [x0, y0, x1, y1] = c.field.area_mm;
            let up = |v: f64| (v - 1e-6).ceil() as i64;
            let down = |v: f64| (v + 1e-6).floor() as i64;
            let cal = [
                up(x0 / px),
                up(h - y1 / px),
                down(x1 / px),
                down(h - y0 / px),
            ];
            for k in 0..2 {
                (a[k], a[k + 2]) = (a[k].max(cal[k]), a[k + 2].min(cal[k + 2]));
            }
        }
        out.push(a);
    }
    out
}

/// The blur job for `p`: at the centre and the four corners of each projector's area
/// (`areas`), a cluster of lines and gaps of every width in [`WIDTHS_PX`], along x and
/// along y, [`FEATURE_LAYERS`] layers thick on a base plate [`BASE_LAYERS`] thick; every
/// edge on a pixel boundary. The job exposes every layer alike (the caller sets it).
pub fn pattern(p: &Profile) -> std::result::Result<PsfPattern, String> {
    let f = p.field();
    let (px, h) = (f.pixel_mm, f.height_px as i64);
    let (rects, feats, [cw, ch]) = cluster();
    let (s, inset) = (SPACE_PX as i64, (INSET_MM / px).ceil() as i64);
    let base_layers = BASE_LAYERS;
    let th = p.slicing.layer_height_mm.get();
    let (z0, z1) = (
        base_layers as f64 * th,
        (base_layers + FEATURE_LAYERS) as f64 * th,
    );
    let (mut features, mut stl) = (Vec::new(), Vec::new());
    let mm = |c: f64, r: f64| [c * px, (h as f64 - r) * px];
    for (q, a) in p.projector.iter().zip(areas(p)) {
        let (l, t) = (a[0] + inset + s, a[1] + inset + s);
        let (r, b) = (a[2] - inset - s - cw, a[3] - inset - s - ch);
        let places = [
            ("centre", [(a[0] + a[2] - cw) / 2, (a[1] + a[3] - ch) / 2]),
            ("top-left", [l, t]),
            ("top-right", [r, t]),
            ("bottom-left", [l, b]),
            ("bottom-right", [r, b]),
        ];
        // The plates (the cluster and a margin of SPACE_PX) must not touch.
        let plate = |o: [i64; 2]| [o[0] - s, o[1] - s, o[0] + cw + s, o[1] + ch + s];
        let apart = |u: Rect, v: Rect| u[2] < v[0] || v[2] < u[0] || u[3] < v[1] || v[3] < u[1];
        let fits = places.iter().enumerate().all(|(i, (_, o))| {
            let u = plate(*o);
            u[0] >= a[0]
                && u[1] >= a[1]
                && u[2] <= a[2]
                && u[3] <= a[3]
                && places[..i].iter().all(|(_, v)| apart(u, plate(*v)))
        });
        if !fits {
            return Err(format!(
                "blur job: projector {}'s area ({} x {} px) is too small for five clusters of {} x {} px",
                q.name,
                a[2] - a[0],
                a[3] - a[1],
                cw + 2 * s,
                ch + 2 * s
            ));
        }
        for (place, o) in places {
            let u = plate(o);
            let [x0, y1] = mm(u[0] as f64, u[1] as f64);
            let [x1, y0] = mm(u[2] as f64, u[3] as f64);
            push_box(&mut stl, [x0, y0, 0.0], [x1, y1, z0]);
            for r in &rects {
                let [x0, y1] = mm((o[0] + r[0]) as f64, (o[1] + r[1]) as f64);
                let [x1, y0] = mm((o[0] + r[2]) as f64, (o[1] + r[3]) as f64);
                push_box(&mut stl, [x0, y0, z0], [x1, y1, z1]);
            }
            features.extend(feats.iter().map(|&(kind, axis, w, c)| PsfFeature {
                kind,
                axis,
                place,
                centre_mm: mm(o[0] as f64 + c[0], o[1] as f64 + c[1]),
                projector: q.name.clone(),
                drawn_px: w,
            }));
        }
    }
    Ok(PsfPattern {
        features,
        stl: stl_file(stl),
        base_layers,
    })
}

/// The fit of one projector's σ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProjectorPsf {
    /// The projector's name (as the profile's `[[projector]]` says).
    pub name: String,
    /// The fitted σ, pixels.
    pub psf_sigma_px: f64,
    /// Its standard error, pixels.
    pub psf_sigma_se_px: f64,
    /// Measured features.
    pub measured: usize,
    /// RMS of the residuals, mm.
    pub residual_rms_mm: f64,
    /// Measured against predicted, feature by feature.
    pub residuals: Vec<PsfResidual>,
    /// The model's printed widths at the fitted σ.
    pub model: Vec<ModelWidth>,
}

/// One measured feature against the model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PsfResidual {
    /// The sheet's line.
    pub line: u64,
    /// The sheet's `feature`.
    pub feature: String,
    /// `line` or `gap`.
    pub kind: String,
    /// Drawn width, pixels.
    pub drawn_px: u32,
    /// Printed width, as measured, mm.
    pub printed_mm: f64,
    /// The model's printed width at the fitted σ, mm.
    pub predicted_mm: f64,
    /// Printed − predicted, mm.
    pub residual_mm: f64,
}

/// The model's printed widths of a line and a gap of one drawn width.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelWidth {
    /// Drawn width, pixels.
    pub drawn_px: u32,
    /// Drawn width, mm.
    pub drawn_mm: f64,
    /// A line's printed width, mm (0: it does not cure).
    pub line_mm: f64,
    /// A gap's printed width, mm (0: it closes).
    pub gap_mm: f64,
}

/// The blur calibration of a sheet: σ per projector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PsfFit {
    /// The sheet's file name.
    pub sheet: String,
    /// SHA-256 of the sheet.
    pub sheet_sha256: String,
    /// Layers thick the features' model takes them (the sheet's `layers`).
    pub layers: u32,
    /// One fit per projector of the sheet, in the sheet's order.
    pub projector: Vec<ProjectorPsf>,
}

/// A measured row: line, feature, kind, drawn px, layers, printed mm.
type Row = (u64, String, Drawn, u32, u32, f64);

/// The measured rows of `s`, by projector in the sheet's order.
fn measured_rows(s: &Sheet) -> Result<Vec<(String, Vec<Row>)>> {
    let mut groups: Vec<(String, Vec<Row>)> = Vec::new();
    for i in 0..s.rows() {
        let Some(printed) = s.num(i, "printed_mm", true)? else {
            continue;
        };
        let (kind, line) = s.text(i, "kind");
        let bad = |col: &str, what: String| {
            Error::input(&s.path, format!("line {line}, column {col}: {what}"))
        };
        let kind = match kind {
            "line" => Drawn::Line,
            "gap" => Drawn::Gap,
            k => return Err(bad("kind", format!("{k:?} is not line or gap"))),
        };
        let whole = |col: &str| -> Result<u32> {
            match s.num(i, col, true)? {
                Some(v) if (1.0..=10_000.0).contains(&v) && v.fract() == 0.0 => Ok(v as u32),
                _ => Err(bad(
                    col,
                    format!("{:?} is not a whole number of 1 or more", s.text(i, col).0),
                )),
            }
        };
        let (drawn, layers) = (whole("drawn_px")?, whole("layers")?);
        let name = s.text(i, "projector").0;
        if name.is_empty() {
            return Err(bad("projector", "empty (name the projector)".into()));
        }
        let row = (
            line,
            s.text(i, "feature").0.to_string(),
            kind,
            drawn,
            layers,
            printed,
        );
        match groups.iter_mut().find(|g| g.0 == name) {
            Some(g) => g.1.push(row),
            None => groups.push((name.to_string(), vec![row])),
        }
    }
    if groups.is_empty() {
        return Err(Error::input(
            &s.path,
            "no measured feature (printed_mm is empty on every line)",
        ));
    }
    Ok(groups)
}

/// The model's printed width of `kind` drawn `w` px wide, `layers` thick, at `sigma`, mm.
fn predict(model: &CureModel, sigma: f64, kind: Drawn, w: u32, layers: u32) -> f64 {
    let m = CureModel {
        sigma_px: sigma,
        ..*model
    };
    let f = Straight {
        kind,
        width_px: w,
        block_px: BLOCK_PX,
        layers,
    };
    printed_width_px(&m, &f) * model.pixel_mm
}

/// Fits σ per projector to the sheet's printed widths (rows with `printed_mm` empty are
/// skipped) under `model` (its σ is not used): least squares in mm, a scan of 33
/// log-spaced σ over [`SIGMA_BRACKET`] and golden-section search between the best one's
/// neighbours. Fewer than 3 measured rows of a projector, or a minimum at the bracket's
/// edge, is an error.
pub fn fit_psf(s: &Sheet, model: &CureModel) -> Result<PsfFit> {
    let groups = measured_rows(s)?;
    let mut out = Vec::new();
    let mut all_layers = Vec::new();
    for (name, rows) in groups {
        if rows.len() < 3 {
            return Err(Error::input(
                &s.path,
                format!(
                    "projector {name}: {} measured features (printed_mm), the fit needs at least 3",
                    rows.len()
                ),
            ));
        }
        all_layers.extend(rows.iter().map(|r| r.4));
        out.push(fit_one(s, model, name, &rows)?);
    }
    all_layers.sort_unstable();
    let layers = all_layers[all_layers.len() / 2];
    for p in &mut out {
        p.model = WIDTHS_PX
            .iter()
            .map(|&w| ModelWidth {
                drawn_px: w,
                drawn_mm: nm(w as f64 * model.pixel_mm),
                line_mm: nm(predict(model, p.psf_sigma_px, Drawn::Line, w, layers)),
                gap_mm: nm(predict(model, p.psf_sigma_px, Drawn::Gap, w, layers)),
            })
            .collect();
    }
    Ok(PsfFit {
        sheet: s.file_name(),
        sheet_sha256: s.sha256.clone(),
        layers,
        projector: out,
    })
}

/// The fit of one projector's rows.
fn fit_one(s: &Sheet, model: &CureModel, name: String, rows: &[Row]) -> Result<ProjectorPsf> {
    let ssr = |sigma: f64| -> f64 {
        let mut memo: Vec<((Drawn, u32, u32), f64)> = Vec::new();
        let mut sum = 0.0;
        for r in rows {
            let key = (r.2, r.3, r.4);
            let p = match memo.iter().find(|m| m.0 == key) {
                Some(m) => m.1,
                None => {
                    let p = predict(model, sigma, r.2, r.3, r.4);
                    memo.push((key, p));
                    p
                }
            };
            sum += (r.5 - p).powi(2);
        }
        sum
    };
    let [lo, hi] = SIGMA_BRACKET;
    const N: usize = 33;
    let grid: Vec<f64> = (0..N)
        .map(|k| lo * (hi / lo).powf(k as f64 / (N - 1) as f64))
        .collect();
    let scores: Vec<f64> = grid.iter().map(|&g| ssr(g)).collect();
    let k = (0..N)
        .min_by(|&a, &b| scores[a].total_cmp(&scores[b]))
        .expect("the grid has points");
    let edge = |sigma: f64| {
        Error::input(&s.path, format!("projector {name}: the best σ ({sigma:.3} px) is at the edge of the bracket {lo} to {hi} px: the printed widths do not fit the cure model (check the profile's resin and exposure, and the sheet)"))
    };
    if k == 0 || k == N - 1 {
        return Err(edge(grid[k]));
    }
    // To the search's tolerance: the file keeps what the fit knows, not its last digits.
    let sigma = crate::round::decimals(golden(&ssr, grid[k - 1], grid[k + 1], 1e-5), 5);
    if sigma <= lo * 1.001 || sigma >= hi * 0.999 {
        return Err(edge(sigma));
    }
    let n = rows.len() as f64;
    let pred: Vec<f64> = rows
        .iter()
        .map(|r| predict(model, sigma, r.2, r.3, r.4))
        .collect();
    let d = 0.01 * sigma;
    let jj: f64 = rows
        .iter()
        .map(|r| {
            (predict(model, sigma + d, r.2, r.3, r.4) - predict(model, sigma - d, r.2, r.3, r.4))
                / (2.0 * d)
        })
        .map(|j| j * j)
        .sum();
    let ss: f64 = rows.iter().zip(&pred).map(|(r, p)| (r.5 - p).powi(2)).sum();
    if jj <= 0.0 {
        return Err(Error::input(&s.path, format!("projector {name}: no measured width depends on σ near {sigma:.3} px (every line vanishes or every gap closes): σ is not determined")));
    }
    let residuals = rows
        .iter()
        .zip(&pred)
        .map(|(r, &p)| PsfResidual {
            line: r.0,
            feature: r.1.clone(),
            kind: match r.2 {
                Drawn::Line => "line",
                Drawn::Gap => "gap",
            }
            .into(),
            drawn_px: r.3,
            printed_mm: r.5,
            predicted_mm: nm(p),
            residual_mm: nm(r.5 - p),
        })
        .collect();
    Ok(ProjectorPsf {
        name,
        psf_sigma_px: sigma,
        psf_sigma_se_px: crate::round::significant((ss / (n - 1.0) / jj).sqrt(), 3),
        measured: rows.len(),
        residual_rms_mm: nm((ss / n).sqrt()),
        residuals,
        model: Vec::new(),
    })
}

/// A length in a fit file, mm: to 1 nm.
fn nm(x: f64) -> f64 {
    crate::round::decimals(x, 6)
}

/// The minimum of `f` in `[a, b]` by golden-section search, to `tol`.
fn golden(f: &impl Fn(f64) -> f64, mut a: f64, mut b: f64, tol: f64) -> f64 {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    while b - a > tol {
        if fc <= fd {
            (b, d, fd) = (d, c, fc);
            c = b - g * (b - a);
            fc = f(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

impl PsfFit {
    /// The chart: printed against drawn width, the measured points and the model's curves
    /// at the fitted σ, one panel per projector.
    pub fn chart(&self) -> Chart {
        let panels = self
            .projector
            .iter()
            .map(|p| {
                let px = self.pixel_mm();
                let pts = |k: &str| {
                    p.residuals
                        .iter()
                        .filter(|r| r.kind == k)
                        .map(|r| (r.drawn_px as f64 * px, r.printed_mm))
                        .collect::<Vec<_>>()
                };
                let curve = |g: fn(&ModelWidth) -> f64| {
                    p.model.iter().map(|m| (m.drawn_mm, g(m))).collect()
                };
                let drawn = p.model.iter().map(|m| (m.drawn_mm, m.drawn_mm)).collect();
                Panel {
                    y_label: format!(
                        "{}: printed width (mm), σ = {:.3} ± {:.3} px",
                        p.name, p.psf_sigma_px, p.psf_sigma_se_px
                    ),
                    series: vec![
                        Series::new("as drawn", [150, 150, 150], Style::Line, drawn),
                        Series::new(
                            "model: line",
                            [31, 119, 180],
                            Style::Line,
                            curve(|m| m.line_mm),
                        ),
                        Series::new(
                            "model: gap",
                            [44, 160, 44],
                            Style::Line,
                            curve(|m| m.gap_mm),
                        ),
                        Series::new("measured lines", [214, 39, 40], Style::Points, pts("line")),
                        Series::new("measured gaps", [148, 103, 189], Style::Points, pts("gap")),
                    ],
                    y_from_zero: true,
                    ..Default::default()
                }
            })
            .collect();
        Chart {
            title: format!("{}: printed against drawn width, {} layers thick, Gaussian PSF fitted under the cure model", self.sheet, self.layers),
            x_label: "drawn width (mm)".into(),
            x_whole: false,
            width: 1000,
            height: 300 + 400 * self.projector.len() as u32,
            panels,
        }
    }

    /// The pixel edge, mm, from the model's table.
    fn pixel_mm(&self) -> f64 {
        self.projector
            .first()
            .and_then(|p| p.model.first())
            .map_or(1.0, |m| m.drawn_mm / m.drawn_px as f64)
    }

    /// Reads a blur calibration file (as written by `dmdsl calibrate psf`) and sets each
    /// named projector's `psf_sigma_px` in `profile`, which then records the sheet.
    pub fn apply_file(path: &Path, profile: &mut Profile) -> Result<()> {
        let f: PsfFit = super::read_fit(path, "blur calibration")?;
        let source = format!("{} sha256:{}", f.sheet, f.sheet_sha256);
        for p in &f.projector {
            let Some(q) = profile.projector.iter_mut().find(|q| q.name == p.name) else {
                return Err(Error::input(
                    path,
                    format!("projector {} is not in profile {}", p.name, profile.name),
                ));
            };
            let [lo, hi] = SIGMA_BRACKET;
            let sigma = crate::units::Positive::new(p.psf_sigma_px)
                .filter(|s| (lo..=hi).contains(&s.get()))
                .ok_or_else(|| Error::input(path, format!("projector {}: psf_sigma_px = {} is not a point-spread width in pixels ({lo} to {hi})", p.name, p.psf_sigma_px)))?;
            (q.psf_sigma_px, q.psf_source) = (Some(sigma), Some(source.clone()));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_place_has_each_width_of_each_kind_on_both_axes() {
        let p = Profile::resolve("xu2010-topdown").unwrap();
        let pat = pattern(&p).unwrap();
        assert_eq!(pat.features.len(), 5 * 2 * 2 * WIDTHS_PX.len());
        for place in [
            "centre",
            "top-left",
            "top-right",
            "bottom-left",
            "bottom-right",
        ] {
            for kind in [Drawn::Line, Drawn::Gap] {
                for axis in ['x', 'y'] {
                    let mut w: Vec<u32> = pat
                        .features
                        .iter()
                        .filter(|f| f.place == place && f.kind == kind && f.axis == axis)
                        .map(|f| f.drawn_px)
                        .collect();
                    w.sort_unstable();
                    assert_eq!(w, WIDTHS_PX, "{place} {kind:?} {axis}");
                }
            }
        }
        // Inside the calibrated area (0..65 x 0..45 mm), 2 mm in.
        for f in &pat.features {
            let [x, y] = f.centre_mm;
            assert!(x > 2.0 && x < 63.0 && y > 2.0 && y < 43.0, "{f:?}");
        }
    }

    #[test]
    fn a_field_without_room_for_five_clusters_is_refused() {
        let mut p = Profile::resolve("bottom-up").unwrap();
        p.projector[0].width_px = 500;
        let e = pattern(&p).unwrap_err();
        assert!(e.contains("projector p0") && e.contains("too small"), "{e}");
    }

    #[test]
    fn golden_section_finds_the_minimum() {
        let x = golden(&|x: f64| (x - 0.83).powi(2) + 1.0, 0.5, 1.5, 1e-7);
        assert!((x - 0.83).abs() < 1e-6, "{x}");
    }
}
