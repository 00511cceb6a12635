//! The dimensional test part ([`accuracy_part`]), the report of its filled-in sheet
//! ([`accuracy`]: error statistics in Xu et al. 2010's terms and a fit per axis) and the
//! correction that undoes the fits ([`AccuracyFit`], the profile's `[accuracy]`;
//! docs/CALIBRATION.md "Dimensions").

use super::{push_box, push_frame, stl_file, Sheet};
use crate::error::{Error, Result};
use crate::plot::{Chart, Panel, Series, Style};
use crate::profile::{Accuracy, Profile};
use crate::round;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The sizes of the accuracy part's features, mm.
pub const ACCURACY_SIZES: [f64; 5] = [0.2, 0.5, 1.0, 2.0, 5.0];

/// One measurement of the accuracy part: a feature kind, the axis it is measured along, its
/// nominal size and where it is (its centre, mm).
#[derive(Debug, Clone, PartialEq)]
pub struct Feature {
    /// `pin`, `wall`, `hole`, `slot` or `step`.
    pub kind: &'static str,
    /// `X`, `Y` or `Z`.
    pub axis: char,
    /// Nominal size, mm.
    pub nominal_mm: f64,
    /// Centre on the build plane, mm.
    pub centre_mm: [f64; 2],
}

/// The accuracy part: one cluster in each half of the field, each with pins, walls, holes,
/// slots (in X and in Y) of every size in [`ACCURACY_SIZES`], 3 mm tall, and steps (in Z):
/// 3 × 3 mm blocks that tall. Every feature is closed shells that do not touch. Returns the features and
/// the part as binary STL.
pub fn accuracy_part(p: &Profile) -> std::result::Result<(Vec<Feature>, Vec<u8>), String> {
    let f = p.field();
    let (w, h, gap) = (f.width_mm(), f.height_mm(), 1.0);
    let (mut feats, mut stl) = (Vec::new(), Vec::new());
    for cx in [w / 4.0, 3.0 * w / 4.0] {
        let (x0, mut y) = (cx - 14.0, h / 2.0 + 20.5);
        let rows: [Row; 7] = [
            (
                "pin",
                &['X', 'Y'],
                |s| [s, s],
                |s| vec![[0., 0., 0., s, s, 3.]],
            ),
            (
                "wall",
                &['X'],
                |s| [s, 3.],
                |s| vec![[0., 0., 0., s, 3., 3.]],
            ),
            (
                "wall",
                &['Y'],
                |s| [3., s],
                |s| vec![[0., 0., 0., 3., s, 3.]],
            ),
            ("hole", &['X', 'Y'], |s| [s + 2., s + 2.], |_| Vec::new()),
            (
                "slot",
                &['X'],
                |s| [s + 3., 3.],
                |s| vec![[0., 0., 0., 1.5, 3., 3.], [1.5 + s, 0., 0., 3. + s, 3., 3.]],
            ),
            (
                "slot",
                &['Y'],
                |s| [3., s + 3.],
                |s| vec![[0., 0., 0., 3., 1.5, 3.], [0., 1.5 + s, 0., 3., 3. + s, 3.]],
            ),
            (
                "step",
                &['Z'],
                |_| [3., 3.],
                |s| vec![[0., 0., 0., 3., 3., s]],
            ),
        ];
        for (kind, axes, size, boxes) in rows {
            let depth = size(5.0)[1];
            y -= depth;
            let mut x = x0;
            for s in ACCURACY_SIZES {
                let [fw, fh] = size(s);
                if kind == "hole" {
                    push_frame(&mut stl, x, y, s);
                }
                for b in boxes(s) {
                    push_box(
                        &mut stl,
                        [x + b[0], y + b[1], b[2]],
                        [x + b[3], y + b[4], b[5]],
                    );
                }
                let centre_mm = [x + fw / 2.0, y + fh / 2.0];
                feats.extend(axes.iter().map(|&axis| Feature {
                    kind,
                    axis,
                    nominal_mm: s,
                    centre_mm,
                }));
                x += fw + gap;
            }
            if x > w || y < 0.0 {
                return Err(format!("accuracy part: profile {:?}'s {w} x {h} mm field is too small (the part needs 2 x 28 x 41 mm)", p.name));
            }
            y -= gap;
        }
    }
    Ok((feats, stl_file(stl)))
}

/// A row of the accuracy part: kind, axes, the footprint of size s, the boxes of size s
/// from the footprint's corner.
type Row = (
    &'static str,
    &'static [char],
    fn(f64) -> [f64; 2],
    fn(f64) -> Vec<[f64; 6]>,
);

/// A measured row of an accuracy sheet.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredRow {
    /// The feature kind (`pin`, `hole`, ...).
    pub kind: String,
    /// `X`, `Y` or `Z`.
    pub axis: char,
    /// Nominal size, mm.
    pub nominal_mm: f64,
    /// Measured size, mm.
    pub measured_mm: f64,
    /// +1 for outer sizes (pins, walls, steps), −1 for holes and slots (their edges move
    /// the other way).
    pub sign: f64,
}

/// The accuracy report of a sheet.
#[derive(Debug, Clone, PartialEq)]
pub struct AccuracyReport {
    /// Statistics: all, per axis, per kind.
    pub stats: Vec<ErrorStats>,
    /// A fit per axis with three rows or more and two sizes or more.
    pub fits: Vec<AxisFit>,
    /// The measured rows.
    pub rows: Vec<MeasuredRow>,
}

/// Error statistics of a group of measurements, mm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ErrorStats {
    /// The group: "all", an axis or a feature kind.
    pub group: String,
    /// Measurements.
    pub n: usize,
    /// Mean of measured − nominal, mm.
    pub mean_mm: f64,
    /// Its standard deviation (n − 1), mm.
    pub sd_mm: f64,
    /// Share within ±0.06 mm (Xu et al. 2010's figure), 0..1.
    pub within_006: f64,
    /// Share within the tolerance asked, 0..1.
    pub within_tolerance: f64,
}

/// An axis's fit measured = scale·nominal ± offset (+ for pins, walls and steps, − for holes
/// and slots: their edges move the other way).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxisFit {
    /// `X`, `Y` or `Z`.
    pub axis: char,
    /// Scale.
    pub scale: f64,
    /// Offset, mm (the growth of an outer size).
    pub offset_mm: f64,
    /// RMS of the fit's residuals, mm.
    pub residual_rms_mm: f64,
}

/// The accuracy report of a sheet: statistics (all, per axis, per kind) and a fit per axis
/// where the sheet has two sizes or more.
pub fn accuracy(s: &Sheet, tolerance: f64) -> Result<AccuracyReport> {
    let mut rows = Vec::new();
    for i in 0..s.rows() {
        let (kind, line) = s.text(i, "feature");
        let axis = s.text(i, "axis").0.to_ascii_uppercase();
        let Some(m) = s.num(i, "measured_mm", true)? else {
            continue;
        };
        let nominal = s.num(i, "nominal_mm", true)?.filter(|&v| v > 0.0);
        let Some(nominal) = nominal else {
            return Err(Error::input(&s.path, format!("line {line}, column nominal_mm: a measured feature needs a positive nominal size")));
        };
        let axis = match axis.as_str() {
            "X" | "Y" | "Z" => axis.chars().next().expect("one letter"),
            _ => {
                return Err(Error::input(
                    &s.path,
                    format!("line {line}, column axis: {axis:?} is not X, Y or Z"),
                ))
            }
        };
        rows.push(MeasuredRow {
            kind: kind.to_string(),
            axis,
            nominal_mm: nominal,
            measured_mm: m,
            sign: if matches!(kind, "hole" | "slot") {
                -1.0
            } else {
                1.0
            },
        });
    }
    if rows.is_empty() {
        return Err(Error::input(
            &s.path,
            "no measured feature (measured_mm is empty on every line)",
        ));
    }
    let stats = |group: &str, e: Vec<f64>| {
        let n = e.len() as f64;
        let mean = e.iter().sum::<f64>() / n;
        let sd = (e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
        let share = |t: f64| e.iter().filter(|v| v.abs() <= t + 1e-9).count() as f64 / n;
        ErrorStats {
            group: group.into(),
            n: e.len(),
            mean_mm: mean,
            sd_mm: sd,
            within_006: share(0.06),
            within_tolerance: share(tolerance),
        }
    };
    let err = |keep: &dyn Fn(&MeasuredRow) -> bool| {
        rows.iter()
            .filter(|r| keep(r))
            .map(|r| r.measured_mm - r.nominal_mm)
            .collect::<Vec<f64>>()
    };
    let mut out = vec![stats("all", err(&|_| true))];
    let mut groups: Vec<String> = ["X", "Y", "Z"].map(String::from).into();
    groups.extend(["pin", "wall", "hole", "slot", "step"].map(String::from));
    groups.extend(
        rows.iter()
            .map(|r| r.kind.clone())
            .filter(|k| !["pin", "wall", "hole", "slot", "step"].contains(&k.as_str())),
    );
    groups.dedup();
    for g in groups {
        let e = err(&|r| r.axis.to_string() == g || r.kind == g);
        if !e.is_empty() && !out.iter().any(|o| o.group == g) {
            out.push(stats(&g, e));
        }
    }
    let mut fits = Vec::new();
    for axis in ['X', 'Y', 'Z'] {
        let r: Vec<_> = rows.iter().filter(|r| r.axis == axis).collect();
        let a = nalgebra::DMatrix::from_fn(r.len(), 2, |i, j| [r[i].nominal_mm, r[i].sign][j]);
        let b = nalgebra::DVector::from_iterator(r.len(), r.iter().map(|r| r.measured_mm));
        let Some(x) = crate::polyfit::LeastSquares::new(a.clone())
            .filter(|_| r.len() >= 3)
            .filter(|l| l.full_rank(1e-9))
            .and_then(|l| l.solve(&b))
        else {
            continue;
        };
        let rms = ((&a * &x - &b).norm_squared() / r.len() as f64).sqrt();
        // To 1e-6 and 1 nm: a least-squares fit carries noise in its last digits (a zero
        // offset comes out as 1e-17), which the correction file would otherwise keep.
        fits.push(AxisFit {
            axis,
            scale: round::decimals(x[0], 6),
            offset_mm: round::decimals(x[1], 6),
            residual_rms_mm: round::decimals(rms, 6),
        });
    }
    Ok(AccuracyReport {
        stats: out,
        fits,
        rows,
    })
}

/// The dimensional correction of an accuracy sheet (`dmdsl calibrate accuracy -o`, read by
/// `slice --accuracy`): the fits and the profile's `[accuracy]` values that undo them,
/// composed with the correction the part was printed with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccuracyFit {
    /// The sheet's file name.
    pub sheet: String,
    /// SHA-256 of the sheet.
    pub sheet_sha256: String,
    /// The correction the test part was printed with.
    pub printed_with: Accuracy,
    /// The fit per axis (measured against nominal, as printed).
    pub fits: Vec<AxisFit>,
    /// `[accuracy] scale`: the correction's factors along X, Y and Z (an axis without a fit
    /// keeps the printed one's).
    pub scale: [f64; 3],
    /// `[accuracy] xy_offset_mm`: the offset of the sections, mm (the mean over the X and Y
    /// fits).
    pub xy_offset_mm: f64,
    /// The Z fit's offset, mm: reported, not corrected (see docs/CALIBRATION.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub z_offset_mm: Option<f64>,
}

impl AccuracyFit {
    /// The correction that undoes `fits` of `sheet`, whose part was printed with
    /// `printed_with`. With the machine printing a designed size d as m·d + g, and the part
    /// designed as S₀·n with its edges moved out by c₀ (the printed correction), the fit of
    /// measured against nominal n is s = m·S₀ and o = 2m·c₀ + g; the correction that makes
    /// m·S₁ = 1 and 2m·c₁ + g = 0 is S₁ = S₀/s and c₁ = c₀ − o·S₀/(2s).
    pub fn new(sheet: &Sheet, fits: Vec<AxisFit>, printed_with: &Accuracy) -> AccuracyFit {
        let mut scale = printed_with.scale;
        let mut offsets = Vec::new();
        let mut z_offset_mm = None;
        for f in &fits {
            let k = "XYZ".find(f.axis).unwrap_or(2);
            let s0 = printed_with.scale[k];
            scale[k] = round::decimals(s0 / f.scale, 6);
            if k < 2 {
                offsets.push(printed_with.xy_offset_mm - f.offset_mm * s0 / (2.0 * f.scale));
            } else {
                z_offset_mm = Some(f.offset_mm);
            }
        }
        let xy_offset_mm = if offsets.is_empty() {
            printed_with.xy_offset_mm
        } else {
            round::decimals(offsets.iter().sum::<f64>() / offsets.len() as f64, 6)
        };
        AccuracyFit {
            sheet: sheet.file_name(),
            sheet_sha256: sheet.sha256.clone(),
            printed_with: printed_with.clone(),
            fits,
            scale,
            xy_offset_mm,
            z_offset_mm,
        }
    }

    /// The profile's `[accuracy]` section this correction gives, its source the sheet.
    pub fn correction(&self) -> Accuracy {
        Accuracy {
            scale: self.scale,
            xy_offset_mm: self.xy_offset_mm,
            source: Some(format!("{} sha256:{}", self.sheet, self.sheet_sha256)),
        }
    }

    /// Reads a correction file (as written by `dmdsl calibrate accuracy -o`) and puts its
    /// correction in `profile`, which then records the sheet. A value out of the profile's
    /// range is an error naming the file.
    pub fn apply_file(path: &Path, profile: &mut Profile) -> Result<()> {
        let f: AccuracyFit = super::read_fit(path, "accuracy correction")?;
        let c = f.correction();
        c.validate().map_err(|m| Error::input(path, m))?;
        profile.accuracy = c;
        Ok(())
    }

    /// The chart of the error against the nominal size, one panel per axis fitted: the
    /// measured points (outer sizes and holes and slots apart) and the fitted line.
    pub fn chart(&self, rows: &[MeasuredRow]) -> Chart {
        let panels = self
            .fits
            .iter()
            .map(|f| {
                let (mut outer, mut inner) = (Vec::new(), Vec::new());
                for r in rows.iter().filter(|r| r.axis == f.axis) {
                    let p = (r.nominal_mm, r.measured_mm - r.nominal_mm);
                    if r.sign < 0.0 {
                        inner.push(p);
                    } else {
                        outer.push(p);
                    }
                }
                let hi = rows.iter().map(|r| r.nominal_mm).fold(0.0, f64::max);
                let line = |sign: f64| -> Vec<(f64, f64)> {
                    (0..=20)
                        .map(|k| hi * k as f64 / 20.0)
                        .map(|n| (n, (f.scale - 1.0) * n + sign * f.offset_mm))
                        .collect()
                };
                let mut series = vec![
                    Series::new("fit, outer sizes", [31, 119, 180], Style::Line, line(1.0)),
                    Series::new("pins, walls, steps", [31, 119, 180], Style::Points, outer),
                ];
                if !inner.is_empty() {
                    series.extend([
                        Series::new(
                            "fit, holes and slots",
                            [255, 127, 14],
                            Style::Line,
                            line(-1.0),
                        ),
                        Series::new("holes, slots", [214, 39, 40], Style::Points, inner),
                    ]);
                }
                Panel {
                    y_label: format!("{} error (mm)", f.axis),
                    series,
                    ..Default::default()
                }
            })
            .collect();
        Chart {
            title: format!(
                "{}: measured − nominal; correction scale {:.5}, {:.5}, {:.5}, xy offset {:+.4} mm",
                self.sheet, self.scale[0], self.scale[1], self.scale[2], self.xy_offset_mm
            ),
            x_label: "nominal size (mm)".into(),
            x_whole: false,
            width: 1000,
            height: 300 + 250 * self.fits.len() as u32,
            panels,
        }
    }
}
