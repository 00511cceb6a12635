//! Distortion pre-warp from a measured correction table.
//!
//! A table row `x_mm,y_mm,seen_x_mm,seen_y_mm` says: light the *uncorrected* projector aimed
//! at build-plane point (x, y) (BRIEF §3 coordinates: mm from the field's bottom-left corner)
//! actually landed at (seen_x, seen_y). Read backwards, every row is a sample of the
//! correction we need, the map G from a wanted build-plane point to the point the projector
//! must aim at: G(seen) = (x, y). So G is fitted directly from the scattered pairs, no
//! inversion needed:
//!
//! 1. A least-squares polynomial in the normalized seen coordinates, total degree 1..=5,
//!    degree chosen by leave-one-out cross-validation (closed form from the hat matrix).
//!    This averages measurement noise (BRIEF §5).
//! 2. Plus `κ ×` a natural-neighbour interpolant (spade, Sibson weights) of the polynomial's
//!    residuals at the table points: it captures assembly errors no low-order formula
//!    describes (seeds/002). κ ∈ [0, 1] minimizes the leave-one-out error of the combined
//!    model, so pure noise gets κ ≈ 0 (not passed through) and real structure κ ≈ 1.
//!    Outside the convex hull of the seen points the residual of the nearest hull point is
//!    used (continuous; counted as extrapolated and warned about).
//!
//! Section contours are pre-warped vertex by vertex before rasterizing; each edge is first
//! cut into pieces of at most [`SEG_MM`] and then split at midpoints until the warped
//! midpoint lies within 0.05 px of the chord (the sag bound). A warped point outside the
//! projector's field is a target the projector cannot reach: an error naming the point.

use crate::bundle::FitReport;
use crate::error::{Error, Result};
use crate::profile::{DistortionConfig, Profile};
use crate::slice::Contour;
use nalgebra::{DMatrix, DVector};
use spade::handles::FixedVertexHandle;
use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Header line of a correction table (optional in the file).
pub const TABLE_HEADER: &str = "x_mm,y_mm,seen_x_mm,seen_y_mm";
/// Longest edge piece before adaptive refinement, mm.
pub const SEG_MM: f64 = 2.0;
/// Largest allowed distance between a warped edge and its chord, px.
pub const SAG_PX: f64 = 0.05;
/// Highest polynomial degree tried.
pub const MAX_DEGREE: usize = 5;
/// Fewest table points accepted.
pub const MIN_POINTS: usize = 6;

/// Which correction a job uses (the command line's `--distortion`).
#[derive(Debug, Clone, Default, PartialEq)]
pub enum DistortionChoice {
    /// The profile's `[distortion]`, if any.
    #[default]
    Profile,
    /// None, even if the profile has one (`--distortion off`).
    Off,
    /// This CSV table (overrides the profile's).
    Table(PathBuf),
}

/// Resolves and fits the correction of a job. On success the profile's `[distortion]` is
/// replaced by the table's points inline (or removed when off), so the manifest's machine is
/// self-contained.
pub fn for_job(choice: &DistortionChoice, profile: &mut Profile) -> Result<Option<Correction>> {
    let table = match choice {
        DistortionChoice::Off => {
            profile.distortion = None;
            return Ok(None);
        }
        DistortionChoice::Table(p) => Table::read(p)?,
        DistortionChoice::Profile => match &profile.distortion {
            None => return Ok(None),
            Some(DistortionConfig { table: Some(t), .. }) => Table::read(Path::new(t))?,
            Some(DistortionConfig {
                points: Some(p), ..
            }) => Table::inline(&profile.name, p),
            Some(_) => {
                return Err(Error::Profile {
                    origin: profile.name.clone(),
                    msg: "[distortion]: needs `table` or `points`".into(),
                })
            }
        },
    };
    if profile.projector.len() > 1 {
        return Err(Error::Profile {
            origin: profile.name.clone(),
            msg: format!(
                "a distortion table ({}) describes one projector's lens; profiles with {} projectors cannot use one",
                table.source,
                profile.projector.len()
            ),
        });
    }
    let field = profile.field();
    let c = Correction::fit(
        &table,
        [field.width_mm(), field.height_mm()],
        field.pixel_mm,
    )?;
    profile.distortion = Some(DistortionConfig {
        table: None,
        points: Some(table.points()),
    });
    Ok(Some(c))
}

/// Ratio of the exact polygon areas of the original and warped contours: scales an area
/// measured on the warped (projector-side) mask back to the build plane.
pub fn area_scale(original: &[Contour], warped: &[Contour]) -> f64 {
    let a: f64 = original.iter().map(crate::slice::signed_area).sum();
    let b: f64 = warped.iter().map(crate::slice::signed_area).sum();
    if b.abs() > 1e-12 {
        a / b
    } else {
        1.0
    }
}

/// One measured pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// Where the uncorrected projector was aimed, mm.
    pub aim: [f64; 2],
    /// Where the light landed, mm.
    pub seen: [f64; 2],
    /// 1-based line in the file (or index in the inline list).
    pub line: usize,
}

/// A parsed correction table and where it came from.
#[derive(Debug, Clone)]
pub struct Table {
    /// The file (or a label for inline points) named in errors.
    pub origin: PathBuf,
    /// "line" for files, "point" for inline profile points.
    pub unit: &'static str,
    /// Short source name for the manifest (file name, or "profile `<name>`").
    pub source: String,
    /// SHA-256 of the file bytes (or of the inline points as CSV text).
    pub sha256: String,
    /// The measured pairs.
    pub pairs: Vec<Pair>,
}

impl Table {
    /// Reads and parses a CSV table.
    pub fn read(path: &Path) -> Result<Table> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let text = std::str::from_utf8(&bytes)
            .map_err(|_| Error::input(path, "not UTF-8 text (expected a CSV table)"))?;
        let pairs = parse_csv(path, text)?;
        Ok(Table {
            origin: path.to_path_buf(),
            unit: "line",
            source: path
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            sha256: crate::digest::sha256_hex(&bytes),
            pairs,
        })
    }

    /// Table from a profile's inline points; `profile` names it in errors.
    pub fn inline(profile: &str, points: &[[f64; 4]]) -> Table {
        let mut csv = String::from(TABLE_HEADER);
        csv.push('\n');
        let pairs = points
            .iter()
            .enumerate()
            .map(|(i, r)| {
                csv.push_str(&format!("{},{},{},{}\n", r[0], r[1], r[2], r[3]));
                Pair {
                    aim: [r[0], r[1]],
                    seen: [r[2], r[3]],
                    line: i + 1,
                }
            })
            .collect();
        Table {
            origin: PathBuf::from(format!("profile {profile} [distortion].points")),
            unit: "point",
            source: format!("profile {profile}"),
            sha256: crate::digest::sha256_hex(csv.as_bytes()),
            pairs,
        }
    }

    /// The pairs as inline profile points.
    pub fn points(&self) -> Vec<[f64; 4]> {
        self.pairs
            .iter()
            .map(|p| [p.aim[0], p.aim[1], p.seen[0], p.seen[1]])
            .collect()
    }

    fn err(&self, line: usize, msg: impl std::fmt::Display) -> Error {
        Error::input(&self.origin, format!("{} {line}: {msg}", self.unit))
    }
}

/// Parses CSV text `x_mm,y_mm,seen_x_mm,seen_y_mm` (optional header, `#` comments, blank
/// lines). Errors name the file and line.
pub fn parse_csv(path: &Path, text: &str) -> Result<Vec<Pair>> {
    const NAMES: [&str; 4] = ["x_mm", "y_mm", "seen_x_mm", "seen_y_mm"];
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut pairs = Vec::new();
    let mut first = true;
    for (i, raw) in text.lines().enumerate() {
        let n = i + 1;
        let s = raw.split('#').next().unwrap_or("").trim();
        if s.is_empty() {
            continue;
        }
        let cols: Vec<&str> = s.split(',').map(str::trim).collect();
        let was_first = std::mem::replace(&mut first, false);
        if was_first && cols.iter().any(|c| c.parse::<f64>().is_err()) {
            if cols == NAMES {
                continue;
            }
            return Err(Error::input(
                path,
                format!("line {n}: expected the header {TABLE_HEADER} or 4 numbers, found `{s}`"),
            ));
        }
        if cols.len() != 4 {
            return Err(Error::input(
                path,
                format!(
                    "line {n}: expected 4 comma-separated columns ({TABLE_HEADER}), found {}",
                    cols.len()
                ),
            ));
        }
        let mut v = [0.0; 4];
        for (k, c) in cols.iter().enumerate() {
            v[k] = match c.parse::<f64>() {
                Ok(x) if x.is_finite() => x,
                _ => {
                    return Err(Error::input(
                        path,
                        format!(
                            "line {n}: column {} ({}): `{c}` is not a finite number",
                            k + 1,
                            NAMES[k]
                        ),
                    ))
                }
            };
        }
        pairs.push(Pair {
            aim: [v[0], v[1]],
            seen: [v[2], v[3]],
            line: n,
        });
    }
    Ok(pairs)
}

#[derive(Debug, Clone, Copy)]
struct Site {
    pos: Point2<f64>,
    r: [f64; 2],
}

impl HasPosition for Site {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.pos
    }
}

type Tri = DelaunayTriangulation<Site>;

/// Bivariate polynomial of total degree `degree` in normalized coordinates.
#[derive(Debug, Clone)]
struct Poly {
    degree: usize,
    center: [f64; 2],
    scale: [f64; 2],
    coef: [Vec<f64>; 2],
}

fn n_terms(d: usize) -> usize {
    (d + 1) * (d + 2) / 2
}

/// Monomials u^a v^b, a + b ≤ d, ordered by total degree.
fn basis(d: usize, u: f64, v: f64, out: &mut [f64]) {
    let mut pu = [1.0; MAX_DEGREE + 1];
    let mut pv = [1.0; MAX_DEGREE + 1];
    for k in 1..=d {
        pu[k] = pu[k - 1] * u;
        pv[k] = pv[k - 1] * v;
    }
    let mut i = 0;
    for t in 0..=d {
        for b in 0..=t {
            out[i] = pu[t - b] * pv[b];
            i += 1;
        }
    }
}

impl Poly {
    fn norm(&self, p: [f64; 2]) -> (f64, f64) {
        (
            (p[0] - self.center[0]) / self.scale[0],
            (p[1] - self.center[1]) / self.scale[1],
        )
    }

    fn eval(&self, p: [f64; 2]) -> [f64; 2] {
        let mut b = [0.0; 21];
        let (u, v) = self.norm(p);
        basis(self.degree, u, v, &mut b);
        let m = n_terms(self.degree);
        self.coef
            .each_ref()
            .map(|c| c.iter().zip(&b[..m]).map(|(c, x)| c * x).sum())
    }
}

/// Least-squares fit of degree `d`; returns the polynomial and the leave-one-out residuals
/// (target − prediction without that point), or None if the design is rank deficient or a
/// point has leverage 1.
fn fit_poly(
    d: usize,
    center: [f64; 2],
    scale: [f64; 2],
    pairs: &[Pair],
) -> Option<(Poly, Vec<[f64; 2]>)> {
    let n = pairs.len();
    let m = n_terms(d);
    if n < m + 1 {
        return None;
    }
    let mut x = DMatrix::<f64>::zeros(n, m);
    let mut b = [0.0; 21];
    for (i, p) in pairs.iter().enumerate() {
        let u = (p.seen[0] - center[0]) / scale[0];
        let v = (p.seen[1] - center[1]) / scale[1];
        basis(d, u, v, &mut b);
        for k in 0..m {
            x[(i, k)] = b[k];
        }
    }
    let qr = x.qr();
    let r = qr.r();
    let rmax = (0..m).map(|k| r[(k, k)].abs()).fold(0.0, f64::max);
    if (0..m).any(|k| r[(k, k)].abs() <= 1e-9 * rmax.max(1e-300)) {
        return None;
    }
    let q = qr.q();
    let qt = q.transpose();
    let solve = |k: usize| {
        let y = DVector::from_iterator(n, pairs.iter().map(|p| p.aim[k]));
        r.solve_upper_triangular(&(&qt * y))
            .map(|c| c.iter().copied().collect::<Vec<f64>>())
    };
    let coef = [solve(0)?, solve(1)?];
    let poly = Poly {
        degree: d,
        center,
        scale,
        coef,
    };
    let mut loo = Vec::with_capacity(n);
    for (i, p) in pairs.iter().enumerate() {
        let h: f64 = (0..m).map(|k| q[(i, k)] * q[(i, k)]).sum();
        if h >= 1.0 - 1e-9 {
            return None;
        }
        let f = poly.eval(p.seen);
        loo.push([(p.aim[0] - f[0]) / (1.0 - h), (p.aim[1] - f[1]) / (1.0 - h)]);
    }
    Some((poly, loo))
}

/// Residual at `p` by natural-neighbour interpolation; outside the convex hull, linear
/// interpolation on the nearest hull edge. Returns (value, extrapolated).
fn nn_resid(
    tri: &Tri,
    nn: &spade::NaturalNeighbor<'_, Tri>,
    buf: &mut Vec<(FixedVertexHandle, f64)>,
    p: [f64; 2],
) -> ([f64; 2], bool) {
    nn.get_weights(Point2::new(p[0], p[1]), buf);
    if !buf.is_empty() {
        let mut o = [0.0; 2];
        for &(h, w) in buf.iter() {
            let r = tri.vertex(h).data().r;
            o[0] += w * r[0];
            o[1] += w * r[1];
        }
        // On a straight stretch of the hull the weights can degenerate; the hull-edge rule
        // below gives the same (linear) value there.
        if o[0].is_finite() && o[1].is_finite() {
            return (o, false);
        }
    }
    let mut best = (f64::INFINITY, [0.0; 2]);
    for e in tri.convex_hull() {
        let a = *e.from().data();
        let b = *e.to().data();
        let (ax, ay) = (a.pos.x, a.pos.y);
        let (dx, dy) = (b.pos.x - ax, b.pos.y - ay);
        let l2 = dx * dx + dy * dy;
        let t = if l2 > 0.0 {
            (((p[0] - ax) * dx + (p[1] - ay) * dy) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (qx, qy) = (ax + t * dx - p[0], ay + t * dy - p[1]);
        let d2 = qx * qx + qy * qy;
        if d2 < best.0 {
            best = (
                d2,
                [
                    a.r[0] + t * (b.r[0] - a.r[0]),
                    a.r[1] + t * (b.r[1] - a.r[1]),
                ],
            );
        }
    }
    (best.1, best.0 > 1e-18)
}

/// The fitted correction G: wanted build-plane point → point the projector must aim at.
#[derive(Debug)]
pub struct Correction {
    poly: Poly,
    tri: Tri,
    kappa: f64,
    field_mm: [f64; 2],
    tol_mm: f64,
    /// Convex hull of the seen points, counter-clockwise.
    hull: Vec<[f64; 2]>,
    /// Bound on |d²G/ds²| of the polynomial along any unit direction over the field, 1/mm.
    curv: f64,
    /// Bound on the slope of the residual interpolant.
    lip: f64,
    extrapolated: AtomicU64,
    report: FitReport,
}

/// A point the projector cannot reach after correction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Unreachable {
    /// The wanted build-plane point, mm.
    pub target: [f64; 2],
    /// Where the projector would have to aim, mm.
    pub aim: [f64; 2],
}

impl Correction {
    /// Fits the correction of `table` for a projector field of `field_mm` (width, height) with
    /// pixels of `pixel_mm`.
    pub fn fit(table: &Table, field_mm: [f64; 2], pixel_mm: f64) -> Result<Correction> {
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
        // Normalize seen coordinates to [-1, 1] for a well-conditioned fit.
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in pairs {
            for k in 0..2 {
                lo[k] = lo[k].min(p.seen[k]);
                hi[k] = hi[k].max(p.seen[k]);
            }
        }
        let center = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        let scale = [
            ((hi[0] - lo[0]) / 2.0).max(1e-6),
            ((hi[1] - lo[1]) / 2.0).max(1e-6),
        ];
        // Degree by leave-one-out (PRESS); a degree must leave at least half the points as
        // redundancy.
        let mut best: Option<(f64, Poly, Vec<[f64; 2]>)> = None;
        for d in 1..=MAX_DEGREE {
            if n < 2 * n_terms(d) {
                break;
            }
            if let Some((poly, loo)) = fit_poly(d, center, scale, pairs) {
                let press: f64 = loo.iter().map(|e| e[0] * e[0] + e[1] * e[1]).sum();
                if best.as_ref().is_none_or(|b| press < b.0) {
                    best = Some((press, poly, loo));
                }
            }
        }
        let Some((_, poly, loo)) = best else {
            return Err(Error::input(
                &table.origin,
                "the seen points are collinear (or nearly): measure points spread over the field",
            ));
        };
        // Residuals of the full fit, triangulated at the seen points.
        let mut tri = Tri::new();
        let mut resid = Vec::with_capacity(n);
        let mut handles = Vec::with_capacity(n);
        for p in pairs {
            let f = poly.eval(p.seen);
            let r = [p.aim[0] - f[0], p.aim[1] - f[1]];
            resid.push(r);
            let h = tri
                .insert(Site {
                    pos: Point2::new(p.seen[0], p.seen[1]),
                    r,
                })
                .map_err(|e| table.err(p.line, format!("cannot triangulate this point: {e:?}")))?;
            handles.push(h);
        }
        if tri.num_inner_faces() == 0 {
            return Err(Error::input(
                &table.origin,
                "the seen points are collinear: measure points spread over the field",
            ));
        }
        // Leave-one-out residual interpolation: remove each point, interpolate the others'
        // residuals at its position, put it back.
        let mut loo_r = Vec::with_capacity(n);
        {
            let mut t = tri.clone();
            let mut buf = Vec::new();
            for p in pairs {
                let pos = Point2::new(p.seen[0], p.seen[1]);
                let h = t.locate_vertex(pos).map(|v| v.fix());
                let Some(h) = h else {
                    loo_r.push([0.0; 2]);
                    continue;
                };
                let site = t.remove(h);
                let v = if t.num_inner_faces() > 0 {
                    let nn = t.natural_neighbor();
                    nn_resid(&t, &nn, &mut buf, p.seen).0
                } else {
                    [0.0; 2]
                };
                loo_r.push(v);
                t.insert(site)
                    .map_err(|e| table.err(p.line, format!("cannot triangulate: {e:?}")))?;
            }
        }
        let (mut num, mut den) = (0.0, 0.0);
        for (e, r) in loo.iter().zip(&loo_r) {
            num += e[0] * r[0] + e[1] * r[1];
            den += r[0] * r[0] + r[1] * r[1];
        }
        let kappa = if den > 0.0 {
            (num / den).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let at = |i: usize| format!("{} {}", table.unit, pairs[i].line);
        let stats = |v: &mut dyn Iterator<Item = f64>| {
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
        };
        let (poly_rms, poly_max, poly_arg) = stats(&mut resid.iter().map(|r| r[0].hypot(r[1])));
        let (cv_rms, cv_max, cv_arg) = stats(
            &mut loo
                .iter()
                .zip(&loo_r)
                .map(|(e, r)| (e[0] - kappa * r[0]).hypot(e[1] - kappa * r[1])),
        );
        let max_corr = pairs
            .iter()
            .map(|p| (p.aim[0] - p.seen[0]).hypot(p.aim[1] - p.seen[1]))
            .fold(0.0, f64::max);
        let report = FitReport {
            source: table.source.clone(),
            sha256: table.sha256.clone(),
            points: n,
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
        };
        drop(handles);
        let mut hull: Vec<[f64; 2]> = tri
            .convex_hull()
            .map(|e| {
                let p = e.from().position();
                [p.x, p.y]
            })
            .collect();
        if ring_area(&hull) < 0.0 {
            hull.reverse();
        }
        let curv = curvature_bound(&poly, field_mm);
        let lip = tri
            .undirected_edges()
            .map(|e| {
                let [a, b] = e.vertices();
                let (a, b) = (a.data(), b.data());
                let d = (a.pos.x - b.pos.x).hypot(a.pos.y - b.pos.y);
                (a.r[0] - b.r[0]).hypot(a.r[1] - b.r[1]) / d.max(1e-9)
            })
            .fold(0.0, f64::max);
        Ok(Correction {
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
        })
    }

    /// The fit report (with the count of extrapolated points warped so far).
    pub fn report(&self) -> FitReport {
        let mut r = self.report.clone();
        r.extrapolated_points = self.extrapolated.load(Ordering::Relaxed);
        r
    }

    /// The correction magnitude |aim − target| (mm) over the field on cells of `cell_mm`,
    /// row-major with row 0 at the top (as the masks); NaN where the target cannot be reached.
    /// Returns (cols, rows, values).
    pub fn field_map(&self, cell_mm: f64) -> (usize, usize, Vec<f64>) {
        let cols = (self.field_mm[0] / cell_mm).ceil() as usize;
        let rows = (self.field_mm[1] / cell_mm).ceil() as usize;
        let mut w = self.warper();
        let mut v = Vec::with_capacity(cols * rows);
        for r in 0..rows {
            for c in 0..cols {
                let t = [
                    ((c as f64 + 0.5) * cell_mm).min(self.field_mm[0]),
                    (self.field_mm[1] - (r as f64 + 0.5) * cell_mm).max(0.0),
                ];
                let a = w.aim(t);
                v.push(if w.reach(t, a).is_ok() {
                    (a[0] - t[0]).hypot(a[1] - t[1])
                } else {
                    f64::NAN
                });
            }
        }
        (cols, rows, v)
    }

    /// Heatmap PNG of [`field_map`](Self::field_map) on 1 mm cells.
    pub fn plot_png(&self) -> Vec<u8> {
        let (cols, rows, values) = self.field_map(1.0);
        let vmax = values
            .iter()
            .filter(|v| v.is_finite())
            .fold(0.0, |a: f64, &b| a.max(b));
        crate::plot::heatmap_png(&crate::plot::Heatmap {
            title: format!(
                "{}: correction distance aim to target, mm (gray: unreachable)",
                self.report.source
            ),
            unit: "mm".into(),
            cols,
            rows,
            values,
            vmin: 0.0,
            vmax,
            cell_px: 8,
            annotate: false,
        })
    }

    /// A per-thread evaluator (holds the interpolation buffers).
    pub fn warper(&self) -> Warper<'_> {
        Warper {
            c: self,
            nn: self.tri.natural_neighbor(),
            buf: Vec::new(),
            extrapolated: 0,
        }
    }

    /// Warps a layer's contours; an unreachable point is an [`Error::Job`] naming the
    /// model, the layer and the point.
    pub fn warp_section(
        &self,
        contours: &[Contour],
        model: &Path,
        layer: usize,
    ) -> Result<Vec<Contour>> {
        let mut w = self.warper();
        let out = w.warp(contours).map_err(|u| Error::Job {
            path: model.into(),
            msg: format!(
                "layer {layer}: build-plane point ({:.3}, {:.3}) mm cannot be reached: with the distortion correction ({}) the projector would have to aim at ({:.3}, {:.3}) mm, outside its field 0..{} x 0..{} mm",
                u.target[0], u.target[1], self.report.source, u.aim[0], u.aim[1], self.field_mm[0], self.field_mm[1]
            ),
        });
        self.extrapolated
            .fetch_add(w.extrapolated, Ordering::Relaxed);
        out
    }
}

/// Evaluates a [`Correction`] (one per thread: it owns interpolation buffers).
pub struct Warper<'a> {
    c: &'a Correction,
    nn: spade::NaturalNeighbor<'a, Tri>,
    buf: Vec<(FixedVertexHandle, f64)>,
    extrapolated: u64,
}

impl Warper<'_> {
    /// Where the projector must aim so light lands at build-plane point `w`.
    pub fn aim(&mut self, w: [f64; 2]) -> [f64; 2] {
        let mut a = self.c.poly.eval(w);
        if self.c.kappa > 0.0 {
            let (r, ex) = nn_resid(&self.c.tri, &self.nn, &mut self.buf, w);
            a[0] += self.c.kappa * r[0];
            a[1] += self.c.kappa * r[1];
            self.extrapolated += ex as u64;
        } else {
            // Count extrapolation for the report even when the interpolant is off.
            self.extrapolated += !inside_convex(&self.c.hull, w) as u64;
        }
        a
    }

    /// True when the warped segment of build-plane length `len` provably stays within half
    /// the sag tolerance of its chord (no midpoint test needed).
    fn flat_enough(&self, len: f64) -> bool {
        self.c.curv * len * len / 8.0 + self.c.kappa * self.c.lip * len / 2.0 <= 0.5 * self.c.tol_mm
    }

    fn reach(&self, target: [f64; 2], a: [f64; 2]) -> std::result::Result<(), Unreachable> {
        let eps = 1e-9;
        let f = self.c.field_mm;
        if a[0] < -eps || a[1] < -eps || a[0] > f[0] + eps || a[1] > f[1] + eps {
            return Err(Unreachable { target, aim: a });
        }
        Ok(())
    }

    /// Pre-warps contours: every vertex through [`aim`](Self::aim), edges densified so the
    /// warped polyline stays within [`SAG_PX`] of the warped edge.
    pub fn warp(&mut self, contours: &[Contour]) -> std::result::Result<Vec<Contour>, Unreachable> {
        let mut out = Vec::with_capacity(contours.len());
        for c in contours {
            if c.is_empty() {
                continue;
            }
            let mut o: Contour = Vec::with_capacity(c.len() * 2);
            let first = self.aim(c[0]);
            let mut pa = first;
            for i in 0..c.len() {
                let a = c[i];
                let b = c[(i + 1) % c.len()];
                self.reach(a, pa)?;
                o.push(pa);
                let pb = if i + 1 == c.len() { first } else { self.aim(b) };
                let len = (b[0] - a[0]).hypot(b[1] - a[1]);
                let pieces = (len / SEG_MM).ceil().max(1.0) as usize;
                let mut qa = pa;
                for k in 1..=pieces {
                    let t1 = k as f64 / pieces as f64;
                    let t0 = (k - 1) as f64 / pieces as f64;
                    let s0 = lerp(a, b, t0);
                    let s1 = lerp(a, b, t1);
                    let qb = if k == pieces { pb } else { self.aim(s1) };
                    if !self.flat_enough(len / pieces as f64) {
                        self.refine(s0, s1, qa, qb, 0, &mut o)?;
                    }
                    if k < pieces {
                        self.reach(s1, qb)?;
                        o.push(qb);
                    }
                    qa = qb;
                }
                pa = pb;
            }
            out.push(o);
        }
        Ok(out)
    }

    /// Pushes the interior points of the warped segment s0→s1 (warped ends q0, q1).
    fn refine(
        &mut self,
        s0: [f64; 2],
        s1: [f64; 2],
        q0: [f64; 2],
        q1: [f64; 2],
        depth: u32,
        o: &mut Contour,
    ) -> std::result::Result<(), Unreachable> {
        if depth >= 12 {
            return Ok(());
        }
        let sm = lerp(s0, s1, 0.5);
        let qm = self.aim(sm);
        let chord = lerp(q0, q1, 0.5);
        if (qm[0] - chord[0]).hypot(qm[1] - chord[1]) <= self.c.tol_mm {
            return Ok(());
        }
        self.refine(s0, sm, q0, qm, depth + 1, o)?;
        self.reach(sm, qm)?;
        o.push(qm);
        self.refine(sm, s1, qm, q1, depth + 1, o)
    }
}

/// Signed area of a closed polygon (CCW positive).
fn ring_area(p: &[[f64; 2]]) -> f64 {
    let n = p.len();
    (0..n)
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

/// Point in (or on) a CCW convex polygon.
fn inside_convex(hull: &[[f64; 2]], q: [f64; 2]) -> bool {
    let n = hull.len();
    (0..n).all(|i| {
        let (a, b) = (hull[i], hull[(i + 1) % n]);
        (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) >= -1e-9
    })
}

/// Largest second directional derivative of the polynomial map over the field (plus a
/// 5 mm margin), from its Hessian on a 0.5 mm grid by central differences, with a 1.5×
/// safety factor: the sag of a warped segment of length L is at most curv · L² / 8.
fn curvature_bound(poly: &Poly, field_mm: [f64; 2]) -> f64 {
    let h = 0.05;
    let mut worst = 0.0f64;
    let (nx, ny) = (
        ((field_mm[0] + 10.0) / 0.5) as usize,
        ((field_mm[1] + 10.0) / 0.5) as usize,
    );
    for j in 0..=ny {
        for i in 0..=nx {
            let p = [-5.0 + i as f64 * 0.5, -5.0 + j as f64 * 0.5];
            let f = |dx: f64, dy: f64| poly.eval([p[0] + dx, p[1] + dy]);
            let c = f(0.0, 0.0);
            let (xp, xm, yp, ym) = (f(h, 0.0), f(-h, 0.0), f(0.0, h), f(0.0, -h));
            let (pp, pm, mp, mm) = (f(h, h), f(h, -h), f(-h, h), f(-h, -h));
            let mut s = 0.0;
            for k in 0..2 {
                let gxx = (xp[k] - 2.0 * c[k] + xm[k]) / (h * h);
                let gyy = (yp[k] - 2.0 * c[k] + ym[k]) / (h * h);
                let gxy = (pp[k] - pm[k] - mp[k] + mm[k]) / (4.0 * h * h);
                // Frobenius norm bounds the spectral norm.
                s += gxx * gxx + gyy * gyy + 2.0 * gxy * gxy;
            }
            worst = worst.max(s.sqrt());
        }
    }
    1.5 * worst
}

fn lerp(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: f64 = 65.0;
    const H: f64 = 48.75;
    const P: f64 = 65.0 / 1024.0;

    /// Tiny deterministic PRNG (xorshift64*), Gaussian by Box–Muller.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545F4914F6CDD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn gauss(&mut self) -> f64 {
            let u = self.next().max(1e-300);
            let v = self.next();
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    /// Forward map: barrel (k < 0) about the centre plus mild keystone, plus bumps.
    fn forward(p: [f64; 2], k: f64, bumps: f64) -> [f64; 2] {
        let (cx, cy) = (W / 2.0, H / 2.0);
        let (dx, dy) = (p[0] - cx, p[1] - cy);
        let r2 = (dx * dx + dy * dy) / (cx * cx + cy * cy);
        let s = 1.0 + k * r2;
        let key = 1.0 + 0.01 * dy / cy;
        // Local "assembly" errors: two Gaussian bumps of ~8 mm radius.
        let g = |c: [f64; 2]| {
            let d2 = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2);
            (-d2 / (2.0 * 8.0 * 8.0)).exp()
        };
        let bx = bumps * (g([20.0, 30.0]) - g([45.0, 15.0]));
        let by = bumps * (g([45.0, 15.0]) + 0.5 * g([15.0, 12.0]));
        [cx + dx * s * key + bx, cy + dy * s + by]
    }

    fn table(k: f64, bumps: f64, noise: f64, seed: u64) -> Table {
        let mut rng = Rng(seed);
        let mut pairs = Vec::new();
        let mut line = 1;
        for j in 0..=9 {
            for i in 0..=13 {
                let aim = [i as f64 * W / 13.0, j as f64 * H / 9.0];
                let s = forward(aim, k, bumps);
                line += 1;
                pairs.push(Pair {
                    aim,
                    seen: [s[0] + noise * rng.gauss(), s[1] + noise * rng.gauss()],
                    line,
                });
            }
        }
        Table {
            origin: "t.csv".into(),
            unit: "line",
            source: "t.csv".into(),
            sha256: String::new(),
            pairs,
        }
    }

    fn landing_error(c: &Correction, k: f64, bumps: f64) -> (f64, f64) {
        let mut w = c.warper();
        let (mut s, mut mx, mut n) = (0.0, 0.0f64, 0);
        for j in 0..20 {
            for i in 0..26 {
                let t = [6.0 + i as f64 * 2.1, 6.0 + j as f64 * 1.9];
                let l = forward(w.aim(t), k, bumps);
                let e = (l[0] - t[0]).hypot(l[1] - t[1]);
                s += e * e;
                mx = mx.max(e);
                n += 1;
            }
        }
        ((s / n as f64).sqrt(), mx)
    }

    #[test]
    fn csv_parsing_and_errors() {
        let p = Path::new("t.csv");
        let ok = parse_csv(
            p,
            "\u{feff}x_mm,y_mm,seen_x_mm,seen_y_mm\n# c\n1,2,3,4 # x\n\n5, 6 ,7,8\r\n",
        )
        .unwrap();
        assert_eq!(ok.len(), 2);
        assert_eq!(ok[1].aim, [5.0, 6.0]);
        assert_eq!(ok[1].line, 5);
        let e = parse_csv(p, "1,2,3,4\n1,2,3\n").unwrap_err().to_string();
        assert_eq!(e, "t.csv: line 2: expected 4 comma-separated columns (x_mm,y_mm,seen_x_mm,seen_y_mm), found 3");
        let e = parse_csv(p, "1,2,3,4\n1,2,x,4\n").unwrap_err().to_string();
        assert_eq!(
            e,
            "t.csv: line 2: column 3 (seen_x_mm): `x` is not a finite number"
        );
        let e = parse_csv(p, "a,b,c,d\n").unwrap_err().to_string();
        assert!(e.starts_with("t.csv: line 1: expected the header"), "{e}");
        let e = parse_csv(p, "1,2,3,4\n1,2,inf,4\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2: column 3"), "{e}");
    }

    #[test]
    fn fit_errors_name_the_line() {
        let mut t = table(0.0, 0.0, 0.0, 1);
        t.pairs.truncate(5);
        let e = Correction::fit(&t, [W, H], P).unwrap_err().to_string();
        assert!(e.contains("at least 6 points, found 5"), "{e}");
        let mut t = table(0.0, 0.0, 0.0, 1);
        t.pairs[7].aim = [70.0, 1.0];
        let e = Correction::fit(&t, [W, H], P).unwrap_err().to_string();
        assert_eq!(
            e,
            "t.csv: line 9: x_mm,y_mm = (70, 1) is outside the projector field 0..65 x 0..48.75 mm"
        );
        let mut t = table(0.0, 0.0, 0.0, 1);
        t.pairs[9].seen = t.pairs[3].seen;
        let e = Correction::fit(&t, [W, H], P).unwrap_err().to_string();
        assert!(e.starts_with("t.csv: line 11: same seen point"), "{e}");
        assert!(e.ends_with("as line 5"), "{e}");
        let mut t = table(0.0, 0.0, 0.0, 1);
        for (i, p) in t.pairs.iter_mut().enumerate() {
            p.seen = [i as f64, 2.0 * i as f64];
        }
        let e = Correction::fit(&t, [W, H], P).unwrap_err().to_string();
        assert!(e.contains("collinear"), "{e}");
    }

    #[test]
    fn exact_table_gives_exact_inverse() {
        // 1 % keystone only, no noise: a degree-5 polynomial inverts it to ~1e-9 mm.
        let t = table(0.0, 0.0, 0.0, 1);
        let c = Correction::fit(&t, [W, H], P).unwrap();
        let r = c.report();
        assert!(r.poly_max_mm < 1e-8 && r.cv_max_mm < 1e-8, "{r:?}");
        assert!(
            r.cv_rms_mm.is_finite() && r.residual_weight.is_finite(),
            "{r:?}"
        );
        let mut w = c.warper();
        for p in [[1.0, 1.0], [10.0, 7.5], [64.0, 48.0]] {
            let a = forward(w.aim(p), 0.0, 0.0);
            assert!(
                (a[0] - p[0]).abs() < 1e-7 && (a[1] - p[1]).abs() < 1e-7,
                "{p:?} -> {a:?}"
            );
        }
    }

    #[test]
    fn smooth_noisy_distortion_is_averaged_not_interpolated() {
        // Barrel + keystone (corners ~2 mm off), noise 0.01 mm, no assembly bumps: the
        // polynomial carries it; κ stays small because residuals are noise.
        let k = -0.05;
        let t = table(k, 0.0, 0.01, 7);
        let c = Correction::fit(&t, [W, H], P).unwrap();
        let r = c.report();
        assert!(r.max_correction_mm > 1.5, "{r:?}");
        assert!(r.residual_weight < 0.3, "{r:?}");
        let (rms, max) = landing_error(&c, k, 0.0);
        assert!(rms < 0.01 && max < 0.025, "rms {rms} max {max}");
        // Pure interpolation of the same table passes the noise through: worse.
        let mut pure = Correction::fit(&t, [W, H], P).unwrap();
        pure.kappa = 1.0;
        let (rms1, _) = landing_error(&pure, k, 0.0);
        assert!(rms1 > rms * 1.3, "interpolated {rms1} vs fitted {rms}");
    }

    #[test]
    fn assembly_errors_are_interpolated() {
        // Bumps of 0.15 mm the polynomial cannot describe: the residual interpolant picks
        // them up (κ near 1) and the landing error drops well below the polynomial's.
        let k = 0.04;
        let t = table(k, 0.15, 0.005, 3);
        let c = Correction::fit(&t, [W, H], P).unwrap();
        let r = c.report();
        assert!(r.residual_weight > 0.7, "{r:?}");
        let (rms, max) = landing_error(&c, k, 0.15);
        let mut poly_only = Correction::fit(&t, [W, H], P).unwrap();
        poly_only.kappa = 0.0;
        let (rms0, _) = landing_error(&poly_only, k, 0.15);
        assert!(
            rms < 0.6 * rms0,
            "with residual {rms}, polynomial only {rms0}"
        );
        assert!(max < 0.12, "max {max}");
    }

    #[test]
    fn densified_warp_stays_within_sag() {
        // With (κ ≈ 1) and without (κ = 0) the residual interpolant; long random edges (the
        // midpoint refinement) and short circle edges (the curvature-bound shortcut).
        for (k, bumps) in [(-0.06, 0.1), (0.08, 0.0)] {
            let t = table(k, bumps, 0.0, 5);
            let c = Correction::fit(&t, [W, H], P).unwrap();
            let mut rng = Rng(11);
            for n in 0..24 {
                let a = [8.0 + 49.0 * rng.next(), 8.0 + 32.0 * rng.next()];
                let contour: Contour = if n % 2 == 0 {
                    let b = [8.0 + 49.0 * rng.next(), 8.0 + 32.0 * rng.next()];
                    let m = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0 + 0.01];
                    vec![a, b, m]
                } else {
                    (0..64)
                        .map(|i| {
                            let t = i as f64 / 64.0 * std::f64::consts::TAU;
                            [a[0] + 3.0 * t.cos(), a[1] + 3.0 * t.sin()]
                        })
                        .collect()
                };
                let mut w = c.warper();
                let out = w.warp(std::slice::from_ref(&contour)).unwrap();
                let poly = &out[0];
                // Every point of every warped edge lies within SAG_PX of the polyline.
                for i in 0..contour.len() {
                    let (a, b) = (contour[i], contour[(i + 1) % contour.len()]);
                    for s in 0..=16 {
                        let q = w.aim(lerp(a, b, s as f64 / 16.0));
                        let d = (0..poly.len())
                            .map(|j| seg_dist(q, poly[j], poly[(j + 1) % poly.len()]))
                            .fold(f64::INFINITY, f64::min);
                        assert!(d <= SAG_PX * P * 1.01, "k {k}: sag {} px", d / P);
                    }
                }
            }
        }
    }

    fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let l2 = dx * dx + dy * dy;
        let t = if l2 > 0.0 {
            (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (a[0] + t * dx - p[0]).hypot(a[1] + t * dy - p[1])
    }

    #[test]
    fn unreachable_target_is_reported() {
        // Barrel: light is pulled towards the centre, so near the corners the projector would
        // have to aim outside its field.
        let t = table(-0.05, 0.0, 0.0, 1);
        let c = Correction::fit(&t, [W, H], P).unwrap();
        let sq = vec![[0.2, 0.2], [3.0, 0.2], [3.0, 3.0], [0.2, 3.0]];
        let e = c
            .warp_section(&[sq], Path::new("part.stl"), 4)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(
                "part.stl: layer 4: build-plane point (0.200, 0.200) mm cannot be reached"
            ),
            "{e}"
        );
        let ok = vec![[20.0, 20.0], [23.0, 20.0], [23.0, 23.0], [20.0, 23.0]];
        assert!(c.warp_section(&[ok], Path::new("part.stl"), 4).is_ok());
    }
}
