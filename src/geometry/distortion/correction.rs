//! The fitted correction G (wanted build-plane point → point the projector must aim at):
//! polynomial + κ · residual interpolant, with its fit report and the bounds the warper
//! uses to skip refinement.

use super::polynomial::PolyMap;
use super::residual::{self, Tri};
use super::table::{Pair, Table};
use super::warp::Warper;
use super::{MIN_POINTS, SAG_PX};
use crate::bundle::FitReport;
use crate::error::{Error, Result};
use crate::slice::Contour;
use spade::Triangulation;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// The fitted correction G: wanted build-plane point → point the projector must aim at.
#[derive(Debug)]
pub struct Correction {
    pub(super) poly: PolyMap,
    pub(super) tri: Tri,
    /// Weight of the residual interpolant.
    pub(super) kappa: f64,
    pub(super) field_mm: [f64; 2],
    /// Sag tolerance, mm.
    pub(super) tol_mm: f64,
    /// Convex hull of the seen points, counter-clockwise.
    pub(super) hull: Vec<[f64; 2]>,
    /// Bound on |d²G/ds²| of the polynomial along any unit direction over the field, 1/mm.
    pub(super) curv: f64,
    /// Bound on the slope of the residual interpolant.
    pub(super) lip: f64,
    pub(super) extrapolated: AtomicU64,
    pub(super) report: FitReport,
}

impl Correction {
    /// Fits the correction of `table` for a projector field of `field_mm` (width, height) with
    /// pixels of `pixel_mm`.
    pub fn fit(table: &Table, field_mm: [f64; 2], pixel_mm: f64) -> Result<Correction> {
        check_points(table, field_mm)?;
        let Some((poly, loo)) = PolyMap::fit_best(&table.pairs) else {
            return Err(Error::input(
                &table.origin,
                "the seen points are collinear (or nearly): measure points spread over the field",
            ));
        };
        let (tri, resid) = residual::triangulate(table, &poly)?;
        if tri.num_inner_faces() == 0 {
            return Err(Error::input(
                &table.origin,
                "the seen points are collinear: measure points spread over the field",
            ));
        }
        let loo_r = residual::leave_one_out(&tri, table)?;
        let kappa = residual::weight(&loo, &loo_r);
        let cv: Vec<f64> = loo
            .iter()
            .zip(&loo_r)
            .map(|(e, r)| (e[0] - kappa * r[0]).hypot(e[1] - kappa * r[1]))
            .collect();
        check_agreement(table, &cv)?;
        let report = fit_report(table, &poly, kappa, &resid, &cv);
        let mut hull = residual::hull(&tri);
        if crate::slice::signed_area(&hull) < 0.0 {
            hull.reverse();
        }
        let curv = poly.curvature_bound(field_mm);
        let lip = residual::steepest_edge(&tri);
        let c = Correction {
            poly,
            tri,
            kappa,
            field_mm,
            tol_mm: SAG_PX * pixel_mm,
            hull,
            curv,
            // Sibson's interpolant can be steeper than its steepest Delaunay edge; margin 2.
            lip: 2.0 * lip,
            extrapolated: AtomicU64::new(0),
            report,
        };
        c.check_no_fold(&table.origin)?;
        Ok(c)
    }

    /// Refuses a correction that folds the field over: its Jacobian determinant must be
    /// positive everywhere on the field (sampled on [`FOLD_CELL_MM`] cells by central
    /// differences). A fold maps two build-plane points to one aim point, so warped sections
    /// turn inside out (negative areas); a mirrored table is the usual cause.
    fn check_no_fold(&self, origin: &Path) -> Result<()> {
        let [w, h] = self.field_mm;
        let (cols, rows) = (
            (w / FOLD_CELL_MM).ceil().max(1.0) as usize,
            (h / FOLD_CELL_MM).ceil().max(1.0) as usize,
        );
        let d = FOLD_STEP_MM;
        let mut warper = self.warper();
        let mut worst: Option<(f64, [f64; 2])> = None;
        for r in 0..rows {
            for c in 0..cols {
                let x = ((c as f64 + 0.5) * FOLD_CELL_MM).min(w);
                let y = ((r as f64 + 0.5) * FOLD_CELL_MM).min(h);
                let (xp, xm) = (warper.aim([x + d, y]), warper.aim([x - d, y]));
                let (yp, ym) = (warper.aim([x, y + d]), warper.aim([x, y - d]));
                let det = ((xp[0] - xm[0]) * (yp[1] - ym[1]) - (yp[0] - ym[0]) * (xp[1] - xm[1]))
                    / (4.0 * d * d);
                if det <= 0.0 && worst.is_none_or(|(v, _)| det < v) {
                    worst = Some((det, [x, y]));
                }
            }
        }
        match worst {
            None => Ok(()),
            Some((det, [x, y])) => Err(Error::input(
                origin,
                format!(
                    "the correction folds the field over (Jacobian determinant {det:.3} at ({x:.1}, {y:.1}) mm, must be > 0): is the table mirrored or are its columns swapped? A mirrored projector is set with mirror_x / mirror_y"
                ),
            )),
        }
    }

    /// Forgets the extrapolated points counted: the job's layers are warped again.
    pub fn reset_counts(&self) {
        self.extrapolated.store(0, Ordering::Relaxed);
    }

    /// The fit report (with the count of extrapolated points of the layers warped so far).
    pub fn report(&self) -> FitReport {
        let mut r = self.report.clone();
        r.extrapolated_points = self.extrapolated.load(Ordering::Relaxed);
        r.rounded()
    }

    /// A per-thread evaluator (holds the interpolation buffers).
    pub fn warper(&self) -> Warper<'_> {
        Warper::new(self)
    }

    /// Warps layer `layer`'s own section as its masks are drawn, counting its points
    /// outside the measured area into the report (so each layer counts once, whichever
    /// other layer warped its section to look at it): the warped section and that count.
    /// An unreachable point is an [`Error::Job`] naming the model, the layer and the point.
    pub fn warp_layer(
        &self,
        contours: &[Contour],
        model: &Path,
        layer: usize,
    ) -> Result<(Vec<Contour>, u64)> {
        self.warp(contours, model, layer, true)
    }

    /// Counts `n` extrapolated points of a layer into the report, as warping it did (a
    /// layer taken as an earlier pass of the job drew it).
    pub fn count_extrapolated(&self, n: u64) {
        self.extrapolated.fetch_add(n, Ordering::Relaxed);
    }

    /// Warps layer `layer`'s section for another layer or the prediction to look at: as
    /// [`warp_layer`](Self::warp_layer), without counting.
    pub fn warp_section(
        &self,
        contours: &[Contour],
        model: &Path,
        layer: usize,
    ) -> Result<Vec<Contour>> {
        self.warp(contours, model, layer, false).map(|(c, _)| c)
    }

    fn warp(
        &self,
        contours: &[Contour],
        model: &Path,
        layer: usize,
        counted: bool,
    ) -> Result<(Vec<Contour>, u64)> {
        let mut w = self.warper();
        let out = w.warp(contours).map_err(|u| Error::Job {
            path: model.into(),
            msg: format!(
                "layer {layer}: build-plane point ({:.3}, {:.3}) mm cannot be reached: with the distortion correction ({}) the projector would have to aim at ({:.3}, {:.3}) mm, outside its field 0..{} x 0..{} mm",
                u.target[0], u.target[1], self.report.source, u.aim[0], u.aim[1], self.field_mm[0], self.field_mm[1]
            ),
        });
        let n = w.extrapolated();
        if counted && out.is_ok() {
            self.count_extrapolated(n);
        }
        out.map(|c| (c, n))
    }
}

/// Checks the table before fitting: enough points, every aim point inside the projector
/// field, no seen point twice.
fn check_points(table: &Table, field_mm: [f64; 2]) -> Result<()> {
    let pairs = &table.pairs;
    let n = pairs.len();
    if n < MIN_POINTS {
        return Err(Error::input(
            &table.origin,
            format!("a distortion table needs at least {MIN_POINTS} points, found {n}"),
        ));
    }
    let eps = 1e-9;
    for p in pairs {
        if p.aim[0] < -eps
            || p.aim[1] < -eps
            || p.aim[0] > field_mm[0] + eps
            || p.aim[1] > field_mm[1] + eps
        {
            return Err(table.err(
                p.line,
                format!(
                    "x_mm,y_mm = ({}, {}) is outside the projector field 0..{} x 0..{} mm",
                    p.aim[0], p.aim[1], field_mm[0], field_mm[1]
                ),
            ));
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| {
        let (pa, pb) = (pairs[a].seen, pairs[b].seen);
        pa[0].total_cmp(&pb[0]).then(pa[1].total_cmp(&pb[1]))
    });
    for w in order.windows(2) {
        let (a, b) = (&pairs[w[0]], &pairs[w[1]]);
        if (a.seen[0] - b.seen[0]).abs() < 1e-9 && (a.seen[1] - b.seen[1]).abs() < 1e-9 {
            let (l0, l1) = (a.line.min(b.line), a.line.max(b.line));
            return Err(table.err(
                l1,
                format!(
                    "same seen point ({}, {}) as {} {l0}",
                    b.seen[0], b.seen[1], table.unit
                ),
            ));
        }
    }
    Ok(())
}

/// The most a table point may lie from where the rest of the table predicts it (its
/// leave-one-out error), mm. Measurement noise is hundredths of a millimetre and lens
/// distortion varies smoothly; a point this far off is mistyped or mis-measured, and fitting
/// it would bend the correction around it.
pub const MAX_POINT_ERROR_MM: f64 = 1.0;
/// Cell size of the fold check, mm.
const FOLD_CELL_MM: f64 = 1.0;
/// Half the difference step of the fold check's Jacobian, mm.
const FOLD_STEP_MM: f64 = 0.05;

/// Refuses a table whose points disagree: any point farther than [`MAX_POINT_ERROR_MM`]
/// from where the rest of the table predicts it (`cv`, per point), naming the worst three.
fn check_agreement(table: &Table, cv: &[f64]) -> Result<()> {
    let mut bad: Vec<usize> = (0..cv.len())
        .filter(|&i| cv[i].is_nan() || cv[i] > MAX_POINT_ERROR_MM)
        .collect();
    if bad.is_empty() {
        return Ok(());
    }
    bad.sort_by(|&a, &b| cv[b].total_cmp(&cv[a]));
    let worst: Vec<String> = bad
        .iter()
        .take(3)
        .map(|&i| format!("{} {} ({:.3} mm)", table.unit, table.pairs[i].line, cv[i]))
        .collect();
    Err(Error::input(
        &table.origin,
        format!(
            "{} more than {MAX_POINT_ERROR_MM} mm from where the rest of the table predicts {}, worst {}: a mistyped, duplicated or mis-measured point",
            crate::text::count(bad.len() as u64, "point lies", "points lie"),
            crate::text::plural(bad.len() as u64, "it", "them"),
            worst.join(", ")
        ),
    ))
}

/// RMS, largest value and its index.
fn rms_max(v: impl Iterator<Item = f64>) -> (f64, f64, usize) {
    let (mut s, mut mx, mut arg, mut k) = (0.0, -1.0, 0, 0);
    for (i, d) in v.enumerate() {
        s += d * d;
        if d > mx {
            mx = d;
            arg = i;
        }
        k += 1;
    }
    ((s / k.max(1) as f64).sqrt(), mx.max(0.0), arg)
}

/// The fit report: the polynomial's residuals `resid`, the combined model's leave-one-out
/// errors `cv` (per point), the largest correction.
fn fit_report(
    table: &Table,
    poly: &PolyMap,
    kappa: f64,
    resid: &[[f64; 2]],
    cv: &[f64],
) -> FitReport {
    let pairs: &[Pair] = &table.pairs;
    let at = |i: usize| format!("{} {}", table.unit, pairs[i].line);
    let (poly_rms, poly_max, poly_arg) = rms_max(resid.iter().map(|r| r[0].hypot(r[1])));
    let (cv_rms, cv_max, cv_arg) = rms_max(cv.iter().copied());
    let max_corr = pairs
        .iter()
        .map(|p| (p.aim[0] - p.seen[0]).hypot(p.aim[1] - p.seen[1]))
        .fold(0.0, f64::max);
    FitReport {
        source: table.source.clone(),
        sha256: table.sha256.clone(),
        points: pairs.len(),
        degree: poly.degree as u32,
        residual_weight: kappa,
        poly_rms_mm: poly_rms,
        poly_max_mm: poly_max,
        poly_max_at: at(poly_arg),
        cv_rms_mm: cv_rms,
        cv_max_mm: cv_max,
        cv_max_at: at(cv_arg),
        max_correction_mm: max_corr,
        extrapolated_points: 0,
    }
}
