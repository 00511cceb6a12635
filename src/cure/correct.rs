//! XY correction: move each drawn edge of a section by its own shift ([`EdgeShifts`],
//! from the layer's dose and the layers above, `shift.rs`), so the cured edge at the
//! layer's mid-plane lands on the section's edge.
//!
//! A pixel within reach of an edge gets its exact coverage changed by the difference
//! between the coverages of the pixel by its nearest edge's half-plane moved and not
//! moved ([`halfplane_coverage`]). Straight edges are then drawn exactly moved; pixels farther than the move from every
//! edge keep their exact coverage, so interiors stay flat. The light compensation maps the
//! corrected coverage to grays as it maps any coverage: one target dose for both.

use super::segments::Segments;
use super::shift::{EdgeProfile, EdgeShifts};
use super::{floor_index, index_f64, round_to_u8};
use crate::cure::model::CureModel;
use crate::raster::Mask;
use crate::raster::PixelBox;

/// The inward move of a prism's edges (every layer above lit alike, the normal dose)
/// that puts the cured edge on the section, px (negative: outward): the pixel-phase
/// averaged growth at the prism's threshold ([`EdgeProfile::growth`]; `profile`, the
/// model's PSF's).
pub fn edge_shift_px(model: &CureModel, profile: &EdgeProfile) -> f64 {
    profile.growth(model.edge_threshold())
}

/// Area of the unit pixel centred at the origin on the side `n·p ≤ u` of a line with
/// unit normal `n`.
pub fn halfplane_coverage(n: [f64; 2], u: f64) -> f64 {
    let (x, y) = (n[0].abs(), n[1].abs());
    let (a, b) = if x >= y { (x, y) } else { (y, x) };
    let h1 = 0.5 * (a - b);
    let h2 = 0.5 * (a + b);
    if u <= -h2 {
        0.0
    } else if u >= h2 {
        1.0
    } else if b < 1e-12 {
        (u + 0.5).clamp(0.0, 1.0)
    } else if u <= -h1 {
        (u + h2) * (u + h2) / (2.0 * a * b)
    } else if u <= h1 {
        b / (2.0 * a) + (u + h1) / a
    } else {
        1.0 - (h2 - u) * (h2 - u) / (2.0 * a * b)
    }
}

/// Moves the edges `segs` (a section's, [`Segments::simplified`]) of the coverage mask
/// `mask` (values = coverage × 255, zero outside `lit`) inward by `shifts` (outward where
/// negative); only pixels inside `lit` change, and only pixels inside `within` gain
/// coverage. A pixel takes the move of the nearest edge among those whose move reaches
/// it. Returns the number of pixels changed.
pub fn correct_coverage(
    mask: &mut Mask,
    lit: PixelBox,
    segs: &Segments,
    shifts: &EdgeShifts,
    within: PixelBox,
) -> usize {
    let (out, inward) = shifts.range();
    if (out == 0.0 && inward == 0.0) || lit.r0 >= lit.r1 || lit.c0 >= lit.c1 {
        return 0;
    }
    // Each edge reaches the pixels its move can change.
    let reach = |i: usize| std::f64::consts::FRAC_1_SQRT_2 + shifts.of_edge(i).abs();
    let w = mask.width as usize;
    let mut changed = 0;
    nearest_edges(segs, (lit, STRIP), reach, |(r, c, i), ahead| {
        super::prefetch(&mask.data, ahead.0 * w + ahead.1);
        let s = &segs.segs[i];
        let p = [index_f64(c) + 0.5, index_f64(r) + 0.5];
        // Signed distance of the centre outside the edge's line.
        let sd = (p[0] - s.a[0]) * s.n[0] + (p[1] - s.a[1]) * s.n[1];
        let shift = shifts.of_edge(i);
        let delta = halfplane_coverage(s.n, -(sd + shift)) - halfplane_coverage(s.n, -sd);
        if delta > 0.0 && !(within.rows().contains(&r) && within.cols().contains(&c)) {
            return;
        }
        let m = r * w + c;
        let v = round_to_u8(mask.data[m] as f64 + 255.0 * delta);
        if v != mask.data[m] {
            mask.data[m] = v;
            changed += 1;
        }
    });
    changed
}

/// Rows of a box whose pixels' nearest edges [`correct_coverage`] finds at a time (their
/// entries stay in cache).
const STRIP: usize = 16;

/// Calls `f((row, column, edge), ahead)` for every pixel of the box `lit` whose centre lies
/// within `reach_of(edge)` px of an edge of `segs`, with the nearest of those edges' index
/// (the first one at equal distances); only the pixels some edge comes near are visited, by
/// strips of `strip` rows (in the order edges first reach them in each). `ahead` is the
/// (row, column) of a pixel `f` will be called with [`AHEAD`] calls later (or its own), for
/// `f` to prefetch what it will read there.
pub(super) fn nearest_edges(
    segs: &Segments,
    (lit, strip): (PixelBox, usize),
    reach_of: impl Fn(usize) -> f64,
    mut f: impl FnMut((usize, usize, usize), (usize, usize)),
) {
    let (bw, strip) = (lit.c1 - lit.c0, strip.clamp(1, (lit.r1 - lit.r0).max(1)));
    BAND.with(|band| {
        let band = &mut *band.borrow_mut();
        let strips = (lit.r1 - lit.r0).div_ceil(strip);
        band.prepare(bw * strip, strips);
        // Each edge's rows within reach, listed in the strips they meet.
        for (i, s) in segs.segs.iter().enumerate() {
            let (reach, (a, b)) = (reach_of(i), (s.a[1], s.b[1]));
            // (Truncation floors the non-negative values: `floor` is a libm call.)
            let r0 = floor_index((a.min(b) - reach - 0.5).max(lit.r0 as f64));
            let r1 = ceil(a.max(b) + reach - 0.5).min(lit.r1);
            if r0 < r1 {
                for k in (r0 - lit.r0) / strip..(r1 - lit.r0).div_ceil(strip) {
                    band.strips[k].push((i as u32, r0 as u32, r1 as u32));
                }
            }
        }
        for k in 0..strips {
            let (s0, s1) = (lit.r0 + k * strip, (lit.r0 + (k + 1) * strip).min(lit.r1));
            for j in 0..band.strips[k].len() {
                let (i, r0, r1) = band.strips[k][j];
                let (i, s) = (i as usize, &segs.segs[i as usize]);
                let (reach, (a, b)) = (reach_of(i), (s.a, s.b));
                let (r2, (dx, dy)) = (reach * reach, (b[0] - a[0], b[1] - a[1]));
                let l2 = dx * dx + dy * dy;
                for r in (r0 as usize).max(s0)..(r1 as usize).min(s1) {
                    let v = index_f64(r) + 0.5;
                    // The part of the edge within `reach` of the row, then its columns.
                    let (t0, t1) = if dy.abs() > 1e-12 {
                        let (p, q) = ((v - reach - a[1]) / dy, (v + reach - a[1]) / dy);
                        (p.min(q).max(0.0), p.max(q).min(1.0))
                    } else {
                        (0.0, 1.0)
                    };
                    if t0 > t1 {
                        continue;
                    }
                    let (x0, x1) = (a[0] + t0 * dx, a[0] + t1 * dx);
                    let c0 = floor_index((x0.min(x1) - reach - 0.5).max(lit.c0 as f64));
                    let c1 = ceil(x0.max(x1) + reach - 0.5).min(lit.c1);
                    for c in c0..c1 {
                        let (wx, wy) = (index_f64(c) + 0.5 - a[0], v - a[1]);
                        let t = if l2 > 0.0 {
                            ((wx * dx + wy * dy) / l2).clamp(0.0, 1.0)
                        } else {
                            0.0
                        };
                        let (ex, ey) = (wx - t * dx, wy - t * dy);
                        let d2 = ex * ex + ey * ey;
                        if d2 < r2 {
                            band.offer([r - s0, c - lit.c0], bw, d2 as f32, i as u32);
                        }
                    }
                }
            }
            let at = |[r, c]: [u32; 2]| (r as usize + s0, c as usize + lit.c0);
            let touched = band.touched();
            for (j, &p) in touched.iter().enumerate() {
                let (_, i) = band.best[p[0] as usize * bw + p[1] as usize];
                let (r, c) = at(p);
                let ahead = touched.get(j + AHEAD).map_or((r, c), |&a| at(a));
                f((r, c, i as usize), ahead);
            }
            band.reset(bw);
        }
    })
}

/// How many pixels ahead [`nearest_edges`] tells its callback of: about the misses a core
/// keeps in flight.
const AHEAD: usize = 8;

/// ⌈x⌉ for x ≥ 0 (0 below).
#[inline]
fn ceil(x: f64) -> usize {
    let t = floor_index(x.max(0.0));
    t + (index_f64(t) < x) as usize
}

/// The nearest edge (squared distance, edge) of the pixels near the section's edges, kept per thread from layer
/// to layer (sized to the largest lit box seen; only the entries written are reset).
#[derive(Default)]
struct Band {
    best: Vec<(f32, u32)>,
    /// The entries of `best` written (row and column in the strip), in the order first
    /// written: the first `count` (room for every entry, so an offer writes its slot
    /// without a branch).
    touched: Vec<[u32; 2]>,
    count: usize,
    /// Per strip of rows, the edges that reach it and their rows.
    strips: Vec<Vec<(u32, u32, u32)>>,
}

impl Band {
    fn prepare(&mut self, n: usize, strips: usize) {
        if self.best.len() < n {
            self.best.resize(n, (f32::INFINITY, u32::MAX));
            // One more: an offer writes its entry past the last one before it counts it.
            self.touched.resize(n + 1, [0, 0]);
        }
        self.count = 0;
        self.strips
            .resize_with(strips.max(self.strips.len()), Vec::new);
        self.strips[..strips].iter_mut().for_each(Vec::clear);
    }

    /// Offers edge `i` at squared distance `d` to the entry of row and column `at` of a
    /// strip `bw` columns wide. Branch-free: whether an entry is new and whether an edge
    /// is nearer follow no pattern a CPU predicts.
    #[inline(always)]
    fn offer(&mut self, at: [usize; 2], bw: usize, d: f32, i: u32) {
        let slot = &mut self.best[at[0] * bw + at[1]];
        self.touched[self.count] = [at[0] as u32, at[1] as u32];
        self.count += (slot.1 == u32::MAX) as usize;
        let nearer = d < slot.0;
        *slot = (
            if nearer { d } else { slot.0 },
            if nearer { i } else { slot.1 },
        );
    }

    fn touched(&self) -> &[[u32; 2]] {
        &self.touched[..self.count]
    }

    /// Clears the entries written (of a strip `bw` columns wide).
    fn reset(&mut self, bw: usize) {
        for &[r, c] in &self.touched[..self.count] {
            self.best[r as usize * bw + c as usize] = (f32::INFINITY, u32::MAX);
        }
        self.count = 0;
    }
}

thread_local! {
    static BAND: std::cell::RefCell<Band> = std::cell::RefCell::new(Band::default());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halfplane_coverage_is_the_area() {
        // Brute force: count sub-points of the pixel on the side n·p ≤ u.
        let k = 400;
        for &(nx, ny) in &[(1.0, 0.0), (0.6, 0.8), (-0.28, 0.96), (1.0, -1.0)] {
            let l = f64::hypot(nx, ny);
            let n = [nx / l, ny / l];
            for &u in &[-0.8, -0.5, -0.3, -0.05, 0.0, 0.2, 0.45, 0.9] {
                let mut inside = 0;
                for i in 0..k {
                    for j in 0..k {
                        let x = (i as f64 + 0.5) / k as f64 - 0.5;
                        let y = (j as f64 + 0.5) / k as f64 - 0.5;
                        inside += (n[0] * x + n[1] * y <= u) as usize;
                    }
                }
                let want = inside as f64 / (k * k) as f64;
                let got = halfplane_coverage(n, u);
                assert!((got - want).abs() < 3e-3, "n {n:?} u {u}: {got} vs {want}");
            }
        }
    }

    /// [`nearest_edges`] against brute force over every pixel and edge: each pixel within
    /// reach of an edge is called once, with the nearest (the first at equal distances),
    /// and told of the pixel called [`AHEAD`] calls later; in boxes from a few pixels (every
    /// entry of the band touched) to a few dozen, strips of 1 to 5 rows.
    #[test]
    fn nearest_edges_match_brute_force() {
        let mut rnd = crate::test_support::xorshift(7);
        for case in 0..60 {
            let (w, h) = (1 + (rnd() * 30.0) as usize, 1 + (rnd() * 30.0) as usize);
            let lit = PixelBox::new(3, 3 + h, 5, 5 + w);
            let field_h = 40.0;
            // Random polygons around the box (build-plane mm at 1 mm pixels).
            let mut pt = || {
                [
                    3.0 + rnd() * (w as f64 + 4.0),
                    field_h - 1.0 - rnd() * (h as f64 + 4.0),
                ]
            };
            let contours: Vec<Vec<[f64; 2]>> = (0..1 + case % 3)
                .map(|_| (0..3 + case % 4).map(|_| pt()).collect())
                .collect();
            let segs = Segments::new(&contours, 1.0, field_h);
            let reach =
                |i: usize| 0.4 + (i % 4) as f64 * 0.6 + if case % 7 == 0 { 40.0 } else { 0.0 };
            let mut calls = Vec::new();
            nearest_edges(&segs, (lit, 1 + case % 5), reach, |(r, c, i), ahead| {
                calls.push(((r, c), i, ahead));
            });
            let mut want = std::collections::BTreeMap::new();
            for r in lit.rows() {
                for c in lit.cols() {
                    let p = [c as f64 + 0.5, r as f64 + 0.5];
                    let mut best: Option<(f32, usize)> = None;
                    for (i, s) in segs.segs.iter().enumerate() {
                        let (dx, dy) = (s.b[0] - s.a[0], s.b[1] - s.a[1]);
                        let (wx, wy) = (p[0] - s.a[0], p[1] - s.a[1]);
                        let l2 = dx * dx + dy * dy;
                        let t = if l2 > 0.0 {
                            ((wx * dx + wy * dy) / l2).clamp(0.0, 1.0)
                        } else {
                            0.0
                        };
                        let d2 = (wx - t * dx).powi(2) + (wy - t * dy).powi(2);
                        if d2 < reach(i) * reach(i) && best.is_none_or(|b| (d2 as f32) < b.0) {
                            best = Some((d2 as f32, i));
                        }
                    }
                    if let Some((_, i)) = best {
                        want.insert((r, c), i);
                    }
                }
            }
            let got: std::collections::BTreeMap<_, _> =
                calls.iter().map(|&(p, i, _)| (p, i)).collect();
            assert_eq!(got.len(), calls.len(), "case {case}: a pixel called twice");
            assert_eq!(got, want, "case {case}");
            if case % 7 == 0 {
                assert_eq!(calls.len(), w * h, "case {case}: every pixel");
            }
            // `ahead` is the pixel AHEAD calls later within the strip, else the pixel itself.
            let strip = 1 + case % 5;
            for (j, &(p, _, ahead)) in calls.iter().enumerate() {
                let later = calls.get(j + AHEAD).map(|c| c.0);
                let same_strip =
                    |q: (usize, usize)| (q.0 - lit.r0) / strip == (p.0 - lit.r0) / strip;
                match later.filter(|&q| same_strip(q)) {
                    Some(q) => assert_eq!(ahead, q, "case {case}"),
                    None => assert_eq!(ahead, p, "case {case}"),
                }
            }
        }
    }

    /// A rectangle's corrected coverage equals the exact coverage of the rectangle moved
    /// inward by the shift (drawn by the rasterizer), but for the pixels at its corners.
    #[test]
    fn a_straight_edge_moves_by_the_shift() {
        use crate::profile::Profile;
        use crate::raster::{Rasterizer, Scratch};
        let field = Profile::default_profile().field();
        let p = field.pixel_mm;
        let raster = Rasterizer::new(field);
        let rect =
            |x0: f64, y0: f64, x1: f64, y1: f64| vec![vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]];
        // Edges at fractions of a pixel; the shift 0.37 px.
        let (x0, y0, x1, y1) = (100.3 * p, 200.6 * p, 160.85 * p, 230.1 * p);
        let d = 0.37;
        let mut scratch = Scratch::default();
        let mut m = raster.coverage(&rect(x0, y0, x1, y1), &mut scratch);
        let lit = scratch.lit_box();
        let segs = Segments::simplified(&rect(x0, y0, x1, y1), p, m.height as f64, 0.01);
        let shifts = EdgeShifts::uniform(&segs, d);
        let all = PixelBox {
            r0: 0,
            r1: m.height as usize,
            c0: 0,
            c1: m.width as usize,
        };
        let changed = correct_coverage(&mut m, lit, &segs, &shifts, all);
        assert!(changed > 100, "{changed}");
        let mut s2 = Scratch::default();
        let want = raster.coverage(
            &rect(x0 + d * p, y0 + d * p, x1 - d * p, y1 - d * p),
            &mut s2,
        );
        let (c0, c1) = ((x0 / p) as usize, (x1 / p) as usize + 1);
        let r0 = field.height_px as usize - (y1 / p) as usize - 1;
        let r1 = field.height_px as usize - (y0 / p) as usize + 1;
        let mut worst = 0i32;
        for r in r0..r1 {
            for c in c0..c1 {
                let corner = (c <= c0 + 1 || c + 2 >= c1) && (r <= r0 + 1 || r + 2 >= r1);
                if !corner {
                    worst = worst.max(
                        (m.get(c as u32, r as u32) as i32 - want.get(c as u32, r as u32) as i32)
                            .abs(),
                    );
                }
            }
        }
        assert!(worst <= 1, "{worst}");
    }
}
