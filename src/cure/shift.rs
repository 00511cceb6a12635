//! How far each drawn edge of a layer moves so that the cured edge at its mid-plane lands
//! on the section (docs/CURE.md, "Correction"): the layer's own light, with its dose, and
//! the light of the layers above at the edge, from their exact sections.
//!
//! **The edge's profile.** Across a straight anti-aliased edge the light of one layer
//! depends on where the edge falls in its pixel. [`EdgeProfile`] tabulates, per σ, the
//! growth ḡ(y) of the cured edge beyond the drawn edge where the light falls to y, averaged
//! over the edge's position in its pixel (for an edge along the pixel grid; the light of a
//! lit half-plane and a partly lit pixel, in closed form), and its inverse P(u): the light
//! u px outside a drawn edge, as far as where edges cure goes (the pixel-phase average).
//!
//! **The shift.** The resin at a point of layer i's edge, at its mid-plane, gets its own
//! layer's light r_i·P(s) when the edge is drawn s px inside the section, and that of each
//! layer k above, w_k·P(s + d_k) with w_k = q^k·r_{i+k} and d_k the point's signed distance
//! outside layer i+k's section, the layers above taken as drawn with the same shift. The
//! layers beyond the look-ahead, up to the job's top, repeat the last one. The shift s
//! solves r_i·P(s) + Σ_k w_k·P(s + d_k) = T₀ (the mid-plane's threshold of one layer's own
//! light, [`CureModel::threshold`]); for a prism (every d_k = 0, infinitely many layers of
//! the normal dose) that is the pixel-phase average of −σₑ·Φ⁻¹(T). It is clamped to
//! [−[`OUT_PX`], the shift at which the layer's own light at the edge falls to
//! [`NEAR`]]: farther in, what cures at the section's edge is the
//! layers above's print-through, which no move of this layer's edge changes.

use super::check::NEAR;
use super::psf::{phi, Psf};
use super::segments::Segments;
use super::{floor_index, index_f64, CureModel};
use crate::raster::{Boxed, Mask, Rasterizer, Scratch};
use crate::slice::Contour;

/// Steps of the profile's table per pixel.
const STEPS: f64 = 256.0;
/// The profile's table spans ±this many pixels around the drawn edge.
const SPAN_PX: f64 = 6.0;
/// Positions of the edge in its pixel the profile averages over.
const PHASES: usize = 32;
/// The largest outward move of an edge, px: the executor allows a mask to light pixels
/// at most 1 px beyond the section's box.
pub const OUT_PX: f64 = 0.7;
/// Farther than this from another section's edges, a point is inside or outside it, px.
pub const REACH_PX: f64 = 3.5;
/// Distances to the sections above are rounded to this (px), so that equal stacks of
/// sections give equal shifts bit for bit.
const DISTANCE_STEP: f64 = 1.0 / 1024.0;
/// Layers above a layer whose sections its correction looks at.
pub const LOOK_AHEAD: usize = 6;
/// Layers above the look-ahead counted in its tail (q^64 ≈ 5·10⁻¹⁰ with the defaults).
const TAIL: usize = 64;
/// Layers above the look-ahead whose edges are extrapolated one by one (the rest of the
/// tail sits at their weighted mean).
const EXTRAPOLATED: usize = 4;
/// The moves are solved at every `COARSE`-th point of a contour, and at the points
/// between where two such moves differ by more than [`REFINE_PX`] (elsewhere
/// interpolated).
const COARSE: usize = 4;
/// See [`COARSE`].
const REFINE_PX: f64 = 0.05;

/// The light across a straight drawn edge, averaged over where the edge falls in its
/// pixel and, for edges along the pixel grid, where it does (see the module docs).
#[derive(Debug, Clone)]
pub struct EdgeProfile {
    /// P(u) at u = −SPAN_PX + k/STEPS.
    light: Vec<f64>,
    /// The light u px outside an edge along the pixel grid lighting its pixel by φ:
    /// `phased[j·U + k]` at φ = j/[`PHASES`], u = −SPAN_PX + k/[`PHASE_STEPS`].
    phased: Vec<f64>,
}

/// Steps per pixel of [`EdgeProfile`]'s table by phase.
const PHASE_STEPS: f64 = 64.0;

impl EdgeProfile {
    /// The profile of `psf`.
    pub fn new(psf: &Psf) -> EdgeProfile {
        let s = psf.sigma_px;
        // Per phase (where the edge falls in its pixel), the light of a half-plane lit up
        // to 0 and of the pixel [0, 1] lit by the phase, on a grid of x, decreasing.
        let (x0, dx, nx) = (
            -SPAN_PX - 2.0,
            1.0 / 128.0,
            ((2.0 * SPAN_PX + 5.0) * 128.0) as usize,
        );
        let xs: Vec<f64> = (0..nx).map(|k| x0 + k as f64 * dx).collect();
        let (a, b): (Vec<f64>, Vec<f64>) =
            xs.iter().map(|&x| (phi(x / s), phi((x - 1.0) / s))).unzip();
        // ḡ at lights y = Φ(z), z from 6 down to −6 (the growth increasing).
        let zs: Vec<f64> = (0..=384).map(|k| 6.0 - k as f64 / 32.0).collect();
        let ys: Vec<f64> = zs.iter().map(|&z| phi(z)).collect();
        let mut growth = vec![0.0; zs.len()];
        for k in 0..PHASES {
            let phase = (k as f64 + 0.5) / PHASES as f64;
            let light = |i: usize| 1.0 - a[i] + phase * (a[i] - b[i]);
            let mut i = 0;
            for (g, &y) in growth.iter_mut().zip(&ys) {
                while i + 2 < nx && light(i + 1) >= y {
                    i += 1;
                }
                let (l0, l1) = (light(i), light(i + 1));
                let t = if l0 > l1 {
                    ((l0 - y) / (l0 - l1)).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                *g += (xs[i] + t * dx - phase) / PHASES as f64;
            }
        }
        // P(u): the light y = Φ(z) whose growth is u (z interpolated in the table).
        let n = (2.0 * SPAN_PX * STEPS) as usize + 1;
        let mut j = 0;
        let light = (0..n)
            .map(|k| {
                let u = -SPAN_PX + k as f64 / STEPS;
                while j + 2 < growth.len() && growth[j + 1] < u {
                    j += 1;
                }
                let t = ((u - growth[j]) / (growth[j + 1] - growth[j])).clamp(0.0, 1.0);
                phi(zs[j] + t * (zs[j + 1] - zs[j]))
            })
            .collect();
        let nu = (2.0 * SPAN_PX * PHASE_STEPS) as usize + 1;
        let phased = (0..=PHASES)
            .flat_map(|j| {
                let phase = j as f64 / PHASES as f64;
                (0..nu).map(move |k| {
                    // From the partly lit pixel's far side (the edge falls `phase` into it).
                    let x = -SPAN_PX + k as f64 / PHASE_STEPS + phase;
                    1.0 - phi(x / s) + phase * (phi(x / s) - phi((x - 1.0) / s))
                })
            })
            .collect();
        EdgeProfile { light, phased }
    }

    /// The light, of a full pixel's, u px outside a drawn edge along the pixel grid that
    /// lights its pixel by `phase` (0 to 1).
    #[inline]
    pub fn light_at_phase(&self, u: f64, phase: f64) -> f64 {
        let nu = (2.0 * SPAN_PX * PHASE_STEPS) as usize + 1;
        let fu = ((u + SPAN_PX) * PHASE_STEPS).clamp(0.0, (nu - 1) as f64 - 1e-9);
        let fp = (phase * PHASES as f64).clamp(0.0, PHASES as f64 - 1e-9);
        let (k, j) = (floor_index(fu), floor_index(fp));
        let (tu, tp) = (fu - index_f64(k), fp - index_f64(j));
        let at = |j: usize, k: usize| self.phased[j * nu + k];
        let row = |j: usize| at(j, k) + tu * (at(j, k + 1) - at(j, k));
        row(j) + tp * (row(j + 1) - row(j))
    }

    /// P(u): the light, of a full pixel's, u px outside a drawn straight edge (negative
    /// inside), averaged over where the edge falls in its pixel.
    #[inline]
    pub fn light(&self, u: f64) -> f64 {
        let f = (u + SPAN_PX) * STEPS;
        if f <= 0.0 {
            return self.light[0];
        }
        let k = floor_index(f);
        if k + 1 >= self.light.len() {
            return *self.light.last().expect("a table");
        }
        let t = f - index_f64(k);
        self.light[k] + t * (self.light[k + 1] - self.light[k])
    }

    /// P(u) and its derivative.
    #[inline]
    pub fn light_slope(&self, u: f64) -> (f64, f64) {
        let f = ((u + SPAN_PX) * STEPS).clamp(0.0, index_f64(self.light.len() - 1) - 1e-9);
        let k = floor_index(f);
        let (a, b) = (self.light[k], self.light[k + 1]);
        (a + (f - index_f64(k)) * (b - a), (b - a) * STEPS)
    }

    /// ḡ(y): how far outside a drawn straight edge the light falls to `y` (of a full
    /// pixel's), averaged over where the edge falls in its pixel.
    pub fn growth(&self, y: f64) -> f64 {
        // P is decreasing: bisection over the table (40 halvings).
        let tol = 2.0 * SPAN_PX / 2f64.powi(40);
        bisect((-SPAN_PX, SPAN_PX), tol, |m| self.light(m) >= y)
    }

    /// The farthest inward move of an edge, px: where the layer's own light at the
    /// section's edge falls to [`NEAR`] (farther in, what cures there is the layers
    /// above's print-through).
    pub fn inward_limit_px(&self) -> f64 {
        self.growth(NEAR as f64)
    }
}

/// A section's coverage (anti-aliased, 0 to 255 a pixel) inside its lit box, read at any
/// point by bilinear interpolation between pixel centres: where it is one half, the
/// section's edge.
#[derive(Debug, Clone, Default)]
pub struct Coverage {
    /// The box's first column and row less one (the box is kept with a border of zeros).
    at: [f64; 2],
    /// Columns and rows kept, the border included.
    size: [usize; 2],
    /// The kept rows from `data[start]` on.
    data: Vec<u8>,
    start: usize,
}

/// Buffers of dropped coverages, for the next ones: a job draws thousands, each the size of
/// its section's box, and allocating each anew costs page faults on large fields.
static SPARE: std::sync::Mutex<Vec<Vec<u8>>> = std::sync::Mutex::new(Vec::new());

/// The spare buffers (also after a panic elsewhere: a buffer list stays consistent).
fn lock_spare() -> std::sync::MutexGuard<'static, Vec<Vec<u8>>> {
    SPARE.lock().unwrap_or_else(|p| p.into_inner())
}

impl Drop for Coverage {
    fn drop(&mut self) {
        let mut spare = lock_spare();
        if spare.len() < 8 && self.data.capacity() > 0 {
            spare.push(std::mem::take(&mut self.data));
        }
    }
}

/// Steps of the searches along a normal, px.
const STEP_PX: f64 = 1.0;

impl Coverage {
    /// The coverage mask `m` inside `lit` (zero outside it): what [`Coverage::draw`] draws,
    /// kept of a field-sized mask (its tests' reference).
    #[cfg(test)]
    pub fn of(m: &Mask, lit: crate::raster::PixelBox) -> Coverage {
        if lit.r0 >= lit.r1 || lit.c0 >= lit.c1 {
            return Coverage::default();
        }
        let w = m.width as usize;
        let size = [lit.c1 - lit.c0 + 2, lit.r1 - lit.r0 + 2];
        // Row by row, the border's zeros written with them (not the whole box zeroed first),
        // into the buffer of a coverage dropped before when there is one.
        let mut data = lock_spare().pop().unwrap_or_default();
        data.clear();
        data.reserve(size[0] * size[1]);
        data.resize(size[0] + 1, 0);
        for r in lit.rows() {
            data.extend_from_slice(&m.data[r * w..][lit.cols()]);
            data.extend_from_slice(&[0, 0]);
        }
        data.resize(size[0] * size[1], 0);
        Coverage {
            at: [lit.c0 as f64 - 1.0, lit.r0 as f64 - 1.0],
            size,
            data,
            start: 0,
        }
    }

    /// The coverage of the section `contours` drawn by `raster` straight into its box (the
    /// values of [`Rasterizer::coverage`]'s mask inside its lit box; the scratch is left as
    /// that call leaves it).
    pub fn draw(raster: &Rasterizer, contours: &[Contour], scratch: &mut Scratch) -> Coverage {
        let spare = lock_spare().pop().unwrap_or_default();
        let Boxed { data, lit } = raster.coverage_boxed(contours, scratch, spare);
        if lit.r0 >= lit.r1 || lit.c0 >= lit.c1 {
            // Nothing kept (the buffer goes back to the spares).
            return Coverage {
                data,
                ..Coverage::default()
            };
        }
        // The box's rows with their border start `lit.c0` bytes in (`Boxed`).
        Coverage {
            at: [lit.c0 as f64 - 1.0, lit.r0 as f64 - 1.0],
            size: [lit.c1 - lit.c0 + 2, lit.r1 - lit.r0 + 2],
            data,
            start: lit.c0,
        }
    }

    /// Writes the coverage mask it was made of back into `m`: every pixel of its lit box
    /// (`m` is zero outside that box).
    pub fn paint(&self, m: &mut Mask) {
        let (w, cols) = (m.width as usize, self.size[0].saturating_sub(2));
        let (c0, r0) = ((self.at[0] + 1.0) as usize, (self.at[1] + 1.0) as usize);
        for k in 0..self.size[1].saturating_sub(2) {
            m.data[(r0 + k) * w + c0..][..cols]
                .copy_from_slice(&self.data[self.start + (k + 1) * self.size[0] + 1..][..cols]);
        }
    }

    /// The coverage (0 to 1) at `p` (pixel coordinates).
    #[inline]
    pub fn value(&self, p: [f64; 2]) -> f64 {
        // Pixel centres at k + ½ (k counted from the border).
        let x = p[0] - 0.5 - self.at[0];
        let y = p[1] - 0.5 - self.at[1];
        if !(x >= 0.0 && y >= 0.0) {
            return 0.0;
        }
        let (cx, cy) = (floor_index(x), floor_index(y));
        if cx + 1 >= self.size[0] || cy + 1 >= self.size[1] {
            return 0.0;
        }
        let (fx, fy) = ((x - index_f64(cx)) as f32, (y - index_f64(cy)) as f32);
        let k = cy * self.size[0] + cx;
        let v = |k: usize| self.data[self.start + k] as f32;
        let (a, b) = (v(k), v(k + 1));
        let (c, d) = (v(k + self.size[0]), v(k + self.size[0] + 1));
        let top = a + fx * (b - a);
        ((top + fy * (c + fx * (d - c) - top)) * (1.0 / 255.0)) as f64
    }

    /// Prefetches what [`Coverage::value`] reads at `p` (a hint: no value changes).
    #[inline]
    pub fn prefetch(&self, p: [f64; 2]) {
        let x = p[0] - 0.5 - self.at[0];
        let y = p[1] - 0.5 - self.at[1];
        if x >= 0.0 && y >= 0.0 {
            let k = self.start + floor_index(y) * self.size[0] + floor_index(x);
            super::prefetch(&self.data, k);
            super::prefetch(&self.data, k + self.size[0]);
        }
    }

    /// The distance from `p` along the unit direction `dir` to where the coverage first
    /// crosses one half, if within `max` (steps of `STEP_PX`, the crossing interpolated).
    pub fn crossing(&self, p: [f64; 2], dir: [f64; 2], max: f64) -> Option<f64> {
        self.crossing_from((p, self.value(p)), dir, max)
    }

    /// [`Coverage::crossing`] from `p` whose coverage `v` is known.
    fn crossing_from(&self, (p, v): ([f64; 2], f64), dir: [f64; 2], max: f64) -> Option<f64> {
        let c0 = v - 0.5;
        let (mut t, mut c) = (0.0, c0);
        while t < max {
            let t1 = (t + STEP_PX).min(max);
            let c1 = self.value([p[0] + t1 * dir[0], p[1] + t1 * dir[1]]) - 0.5;
            if (c1 >= 0.0) != (c0 >= 0.0) {
                return Some(t + (t1 - t) * c / (c - c1));
            }
            (t, c) = (t1, c1);
        }
        None
    }

    /// The signed distance of `p` outside the section along the outward normal `n` (the
    /// nearest crossing of half coverage along it, either way), within `reach`: beyond,
    /// `reach` outside and `-reach` inside.
    pub fn distance_along(&self, p: [f64; 2], n: [f64; 2], reach: f64) -> f64 {
        let v = self.value(p);
        let inside = v >= 0.5;
        // Inside, the edge lies outward (+n); outside, inward (−n).
        let dir = if inside { n } else { [-n[0], -n[1]] };
        match self.crossing_from((p, v), dir, reach) {
            Some(t) if inside => -t,
            Some(t) => t,
            None if inside => -reach,
            None => reach,
        }
    }
}

/// What a layer's correction knows of its dose and of the layers above it.
#[derive(Clone)]
pub struct LookAhead<'a> {
    /// The layer's own dose ratio r_i.
    pub own: f64,
    /// The layers above, nearest first: their weights q^k·r_{i+k} and their sections'
    /// coverage.
    pub upper: &'a [(f64, &'a Coverage)],
    /// The weights of the next layers beyond them, whose edges continue the slope from
    /// the layer to the last of `upper`, one by one.
    pub tail: Vec<f64>,
    /// The weight of the layers beyond those up to the job's top, Σ q^k·r_{i+k}, whose
    /// edges continue the slope too (all of them at their weighted mean layer).
    pub rest: f64,
    /// That weighted mean layer, in layers above the last of `tail`.
    pub rest_at: f64,
    /// How much farther in than this layer's a straight wall's edge is drawn in each
    /// layer of `upper` and `tail` ([`wall_shifts`]), px: the layers above drawn with
    /// the same shift but for that.
    pub delta: Vec<f64>,
    /// The same for the layers of `rest`, their weighted mean.
    pub rest_delta: f64,
}

/// The moves of a straight wall's edges in each of a job's `layers` layers whose dose
/// ratios are `ratio(k)`, solved from the top layer down: layer i's r_i·P(s_i) +
/// Σ_k q^k·r_{i+k}·P(s_{i+k}) = T₀ (within the bounds of [`EdgeShifts::solve`]). The top
/// layers, with little light above them, move out; the bottom layers, overexposed, in.
pub fn wall_shifts(
    model: &CureModel,
    profile: &EdgeProfile,
    layers: usize,
    ratio: impl Fn(usize) -> f64,
) -> Vec<f64> {
    let q = (-model.layer_mm / model.dp_mm).exp();
    let t0 = model.threshold(0.5 * model.layer_mm, Some(0));
    let (lo, hi) = (-OUT_PX, profile.inward_limit_px());
    let mut s = vec![0.0; layers];
    for i in (0..layers).rev() {
        let above: f64 = (i + 1..layers.min(i + 1 + LOOK_AHEAD + TAIL))
            .map(|j| q.powi((j - i) as i32) * ratio(j) * profile.light(s[j]))
            .sum();
        let f = |x: f64| ratio(i) * profile.light(x) + above - t0;
        s[i] = if f(lo) <= 0.0 {
            lo
        } else if f(hi) >= 0.0 {
            hi
        } else {
            bisect((lo, hi), 1e-6, |m| f(m) >= 0.0)
        };
    }
    s
}

impl LookAhead<'_> {
    /// The look-ahead of layer `index` of a job of `layers` layers whose dose ratios are
    /// `ratio(k)`, with the sections of the layers above it `upper` (nearest first, at
    /// most [`LOOK_AHEAD`]); `walls`, the job's [`wall_shifts`] (empty: all alike).
    pub fn new<'a>(
        model: &CureModel,
        (index, layers): (usize, usize),
        (ratio, walls): (impl Fn(usize) -> f64, &[f64]),
        upper: &[&'a Coverage],
        pairs: &'a mut Vec<(f64, &'a Coverage)>,
    ) -> LookAhead<'a> {
        let q = (-model.layer_mm / model.dp_mm).exp();
        let above = layers - 1 - index;
        let w = |k: usize| q.powi(k as i32) * ratio(index + k);
        let k_up = upper.len().min(above);
        pairs.clear();
        pairs.extend((1..=k_up).map(w).zip(upper.iter().copied()));
        let last = above.min(k_up + TAIL);
        let x = EXTRAPOLATED.min(last - k_up);
        let rest: f64 = (k_up + x + 1..=last).map(w).sum();
        let delta = |k: usize| match walls.get(index + k) {
            Some(s) => s - walls[index],
            None => 0.0,
        };
        let mean = |f: &dyn Fn(usize) -> f64| {
            let m: f64 = (k_up + x + 1..=last).map(|k| w(k) * f(k)).sum();
            if rest > 0.0 {
                m / rest
            } else {
                0.0
            }
        };
        LookAhead {
            own: ratio(index),
            upper: pairs,
            tail: (k_up + 1..=k_up + x).map(w).collect(),
            rest,
            rest_at: mean(&|k| (k - k_up - x) as f64),
            delta: (1..=k_up + x).map(delta).collect(),
            rest_delta: mean(&delta),
        }
    }

    /// All the light's weights: the layer's own, the layers above's.
    pub fn total(&self) -> f64 {
        self.own
            + self.upper.iter().map(|u| u.0).sum::<f64>()
            + self.tail.iter().sum::<f64>()
            + self.rest
    }
}

/// The inward moves of a layer's drawn edges: solved at points spaced evenly along each
/// contour, each edge moved by the value at its middle (interpolated along the contour).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EdgeShifts {
    /// Per edge, px.
    edge: Vec<f64>,
    /// Every contour's moves at its points, px (what equal layers share).
    pub values: Vec<f64>,
}

impl EdgeShifts {
    /// The same move `shift` for every edge of `segs`.
    #[cfg(test)]
    pub fn uniform(segs: &Segments, shift: f64) -> EdgeShifts {
        EdgeShifts {
            edge: vec![shift; segs.segs.len()],
            values: vec![shift],
        }
    }

    /// The moves of the edges of `segs` (a layer's drawn section; `own`, its coverage),
    /// from `look`, at points at most `spacing` px apart along each contour.
    pub fn solve(
        model: &CureModel,
        profile: &EdgeProfile,
        (segs, own): (&Segments, &Coverage),
        look: &LookAhead,
        spacing: f64,
    ) -> EdgeShifts {
        let t0 = model.threshold(0.5 * model.layer_mm, Some(0));
        let bounds = (-OUT_PX, profile.inward_limit_px());
        let mut out = EdgeShifts::default();
        let mut at = Point {
            d: vec![0.0; look.upper.len()],
            ..Point::default()
        };
        // The last point solved and its move: neighbours on a prism's wall share them.
        let mut last: Option<(Point, f64)> = None;
        for c in 0..segs.starts.len() - 1 {
            let range = segs.starts[c]..segs.starts[c + 1];
            if range.is_empty() {
                continue;
            }
            let ss = &segs.segs[range];
            let len: Vec<f64> = ss
                .iter()
                .map(|s| (s.b[0] - s.a[0]).hypot(s.b[1] - s.a[1]))
                .collect();
            let total: f64 = len.iter().sum();
            let n = ((total / spacing).ceil() as usize).max(1);
            let first = out.values.len();
            // The points at (j + ½)·total/n along the contour.
            let starts: Vec<f64> = len
                .iter()
                .scan(0.0, |a, &l| {
                    let s = *a;
                    *a += l;
                    Some(s)
                })
                .collect();
            let point = |j: usize| {
                let pos = (j as f64 + 0.5) * total / n as f64;
                let i = starts.partition_point(|&a| a <= pos).saturating_sub(1);
                let arc = starts[i];
                let s = &ss[i];
                let f = if len[i] > 0.0 {
                    ((pos - arc) / len[i]).clamp(0.0, 1.0)
                } else {
                    0.5
                };
                (
                    [
                        s.a[0] + f * (s.b[0] - s.a[0]),
                        s.a[1] + f * (s.b[1] - s.a[1]),
                    ],
                    s.n,
                )
            };
            let mut solve_at = |j: usize, last: &mut Option<(Point, f64)>| {
                let (p, nrm) = point(j);
                at.measure(p, nrm, own, look);
                let v = match last.as_ref() {
                    Some((lp, v)) if *lp == at => *v,
                    _ => {
                        let start = last.as_ref().map(|l| l.1);
                        at.shift(profile, t0, look, start, bounds)
                    }
                };
                *last = Some((at.clone(), v));
                v
            };
            // Every COARSE-th point first, then the points between two that differ.
            let coarse: Vec<usize> = (0..n).step_by(COARSE).collect();
            let mut v = vec![f64::NAN; n];
            for &j in &coarse {
                v[j] = solve_at(j, &mut last);
            }
            for (k, &j0) in coarse.iter().enumerate() {
                let j1 = coarse.get(k + 1).copied().unwrap_or(n);
                let (v0, v1) = (v[j0], v[j1 % n]);
                let refine = (v0 - v1).abs() > REFINE_PX;
                for (j, x) in v.iter_mut().enumerate().take(j1).skip(j0 + 1) {
                    *x = if refine {
                        solve_at(j, &mut last)
                    } else {
                        v0 + (j - j0) as f64 / (j1 - j0) as f64 * (v1 - v0)
                    };
                }
            }
            out.values.extend_from_slice(&v);
            // Each edge's move: at its middle, between the points around it (the points
            // sit at j + ½ in units of their spacing; the contour closes).
            let v = &out.values[first..];
            let mut a = 0.0;
            for &l in &len {
                let x = (a + 0.5 * l) * n as f64 / total - 0.5 + n as f64;
                let (j, f) = (x as usize, x.fract());
                let (k0, k1) = (j % n, (j + 1) % n);
                out.edge.push(v[k0] + f * (v[k1] - v[k0]));
                a += l;
            }
        }
        out
    }

    /// Holds the edges flagged in `interior` in place (no move): edges inside the
    /// section bound nothing that cures ([`Segments::union_pieces`]); moved, they would
    /// draw a dark line through the material.
    pub fn hold(&mut self, interior: &[bool]) {
        for (e, _) in self.edge.iter_mut().zip(interior).filter(|(_, &i)| i) {
            *e = 0.0;
        }
    }

    /// The move of edge `i`, px.
    #[inline]
    pub fn of_edge(&self, i: usize) -> f64 {
        self.edge[i]
    }

    /// The largest move outward (negative) and inward, px.
    pub fn range(&self) -> (f64, f64) {
        self.edge
            .iter()
            .fold((0.0f64, 0.0f64), |(lo, hi), &v| (lo.min(v), hi.max(v)))
    }
}

/// What the move of an edge at one of its points depends on.
#[derive(Debug, Clone, Default, PartialEq)]
struct Point {
    /// The point's signed distance outside each section above, px (rounded).
    d: Vec<f64>,
    /// The width of the material behind it and of the gap before it, px (rounded; at
    /// most [`ACROSS_PX`]).
    across: [f64; 2],
    /// For an edge along the pixel grid, the point's coordinate along its outward normal
    /// (where the drawn edge falls in its pixel follows from it).
    grid: Option<f64>,
}

/// Widths of material and gaps are measured up to this, px: beyond, the far side's light
/// is negligible at the edge.
const ACROSS_PX: f64 = 5.0;

/// A value rounded to [`DISTANCE_STEP`].
fn rounded(x: f64) -> f64 {
    (x / DISTANCE_STEP).round() * DISTANCE_STEP
}

impl Point {
    /// The point `p` of an edge with outward normal `n` of a section whose coverage is
    /// `own`: its distances along the normal to the sections above's edges, the widths
    /// across it, its place in the pixel grid.
    fn measure(&mut self, p: [f64; 2], n: [f64; 2], own: &Coverage, look: &LookAhead) {
        // Every section's pixels around the point requested at once (each search below
        // would otherwise wait on memory in turn).
        for c in std::iter::once(own).chain(look.upper.iter().map(|u| u.1)) {
            for t in [0.0, 2.0, -2.0] {
                c.prefetch([p[0] + t * n[0], p[1] + t * n[1]]);
            }
        }
        // Relative to where the same measure puts the layer's own edge (half coverage
        // between pixel centres is off a drawn edge by up to 0.08 px, by its phase).
        let zero = own.distance_along(p, n, REACH_PX);
        for (dk, (_, up)) in self.d.iter_mut().zip(look.upper) {
            *dk = rounded((up.distance_along(p, n, REACH_PX) - zero).clamp(-REACH_PX, REACH_PX));
        }
        // Across the material behind the edge and the gap before it: from just inside
        // (outside) the edge to the next crossing of half coverage.
        let e = 0.25;
        for (k, sign) in [(0, -1.0), (1, 1.0)] {
            let from = [p[0] + sign * e * n[0], p[1] + sign * e * n[1]];
            let w = own
                .crossing(from, [sign * n[0], sign * n[1]], ACROSS_PX)
                .map_or(ACROSS_PX, |w| w + e);
            self.across[k] = rounded(w.min(ACROSS_PX));
        }
        self.grid = (n[0].abs().max(n[1].abs()) > 1.0 - 1e-12).then(|| n[0] * p[0] + n[1] * p[1]);
    }

    /// The move s within `[lo, hi]` solving Σ w·L(d + s) + (the far sides) = t0 (see the
    /// module docs), from `start` (the previous point's) on.
    fn shift(
        &self,
        profile: &EdgeProfile,
        t0: f64,
        look: &LookAhead,
        start: Option<f64>,
        (lo, hi): (f64, f64),
    ) -> f64 {
        // The slope from the layer to the last layer looked at, continued by the tail.
        let d = &self.d;
        let k = d.len();
        let slope = if k > 0 { d[k - 1] / k as f64 } else { 0.0 };
        let tail_at = |j: usize| slope * (k + 1 + j) as f64;
        let rest_at = slope * ((k + look.tail.len()) as f64 + look.rest_at);
        let total = look.total();
        let [behind, gap] = self.across;
        // The light of a layer whose section's edge lies `dk` inside the point, drawn `s`
        // inside it, and (of the pixel-phase averaged profile) its slope.
        let light = |dk: f64, s: f64| {
            let (l, dl) = profile.light_slope(dk + s);
            match self.grid {
                Some(t) => (
                    profile.light_at_phase(dk + s, (t - dk - s).rem_euclid(1.0)),
                    dl,
                ),
                None => (l, dl),
            }
        };
        // The light at the edge less t0, and its derivative in s.
        let f = |s: f64| {
            let mut acc = [0.0, 0.0];
            let mut add = |w: f64, (l, dl): (f64, f64)| {
                acc[0] += w * l;
                acc[1] += w * dl;
            };
            add(look.own, light(0.0, s));
            add(look.rest, light(rest_at + look.rest_delta, s));
            let delta = |k: usize| look.delta.get(k).copied().unwrap_or(0.0);
            for (k, (&(w, _), &dk)) in look.upper.iter().zip(d).enumerate() {
                add(w, light(dk + delta(k), s));
            }
            for (j, &w) in look.tail.iter().enumerate() {
                add(w, light(tail_at(j) + delta(k + j), s));
            }
            // The far side of the gap before the edge and of the material behind it.
            if gap < ACROSS_PX {
                let (l, dl) = profile.light_slope(-gap - s);
                add(total, (1.0 - l, -dl));
            }
            if behind < ACROSS_PX {
                let (l, dl) = profile.light_slope(behind - s);
                add(-total, (l, -dl));
            }
            (acc[0] - t0, acc[1])
        };
        // Newton's method from the start, while its steps stay inside [lo, hi].
        let mut s = start.unwrap_or(0.5 * (lo + hi)).clamp(lo, hi);
        for _ in 0..8 {
            let (v, dv) = f(s);
            if v.abs() < 1e-7 {
                return s;
            }
            if dv >= 0.0 {
                break;
            }
            let next = s - v / dv;
            if next < lo || next > hi {
                let end = if next < lo { lo } else { hi };
                let fe = f(end).0;
                if (end == lo && fe <= 0.0) || (end == hi && fe >= 0.0) {
                    return end;
                }
                break;
            }
            if (next - s).abs() < 1e-5 {
                return next;
            }
            s = next;
        }
        // Else bisection over [lo, hi].
        if f(lo).0 <= 0.0 {
            return lo;
        }
        if f(hi).0 >= 0.0 {
            return hi;
        }
        bisect((lo, hi), 1e-5, |m| f(m).0 >= 0.0)
    }
}

/// The midpoint of `[a, b]` halved, keeping the half where `up` holds at its low end,
/// until it is at most `tol` wide.
fn bisect((mut a, mut b): (f64, f64), tol: f64, up: impl Fn(f64) -> bool) -> f64 {
    while b - a > tol {
        let m = 0.5 * (a + b);
        (a, b) = if up(m) { (m, b) } else { (a, m) };
    }
    0.5 * (a + b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cure::psf::phi_inv;

    /// A coverage drawn straight into its box reads and paints as the one kept of the
    /// field-sized coverage mask: a ring, a section at the field's corner, none.
    #[test]
    fn a_coverage_drawn_into_its_box_is_the_one_kept_of_the_mask() {
        use crate::test_support::{closed, rect};
        let field = crate::profile::Profile::default_profile().field();
        let raster = Rasterizer::new(field);
        let ring = vec![
            closed(40, true, |a| [20.0 + 7.3 * a.cos(), 15.0 + 7.3 * a.sin()]),
            closed(40, false, |a| [20.0 + 3.1 * a.cos(), 15.0 + 3.1 * a.sin()]),
        ];
        let corner = vec![rect(-1.0, -1.0, 2.03, 1.51)];
        let mut scratch = Scratch::default();
        for shapes in [ring, corner, Vec::new()] {
            let mut plain = Scratch::default();
            let m = raster.coverage(&shapes, &mut plain);
            let kept = Coverage::of(&m, plain.lit_box());
            let drawn = Coverage::draw(&raster, &shapes, &mut scratch);
            // The ring spans columns 200..430 and rows 417..648, the corner's section
            // columns 0..32 and rows 744..768 (and beyond the field).
            for i in 0..340 {
                for j in 0..290 {
                    let p = [-2.0 + i as f64 * 1.37, 380.0 + j as f64 * 1.37];
                    assert_eq!(drawn.value(p), kept.value(p), "{p:?}");
                }
            }
            let (mut a, mut b) = (
                Mask::zeros(m.width, m.height),
                Mask::zeros(m.width, m.height),
            );
            drawn.paint(&mut a);
            kept.paint(&mut b);
            assert!(a == m && b == m);
        }
    }

    /// The profile against a brute-force average: edges at 1000 positions in their pixel,
    /// the light of each summed pixel by pixel, the crossing found on a fine grid.
    #[test]
    fn the_profile_is_the_phase_average_of_the_growth() {
        let psf = Psf { sigma_px: 0.5 };
        let p = EdgeProfile::new(&psf);
        for y in [0.05, 0.196, 0.5, 0.8] {
            let mut sum = 0.0;
            let n = 200;
            for k in 0..n {
                let e = 10.0 + (k as f64 + 0.5) / n as f64;
                let light = |x: f64| {
                    (0..30)
                        .map(|j| (e - j as f64).clamp(0.0, 1.0) * psf.axis_weight(x - j as f64))
                        .sum::<f64>()
                };
                let (mut lo, mut hi) = (e - 4.0, e + 4.0);
                for _ in 0..40 {
                    let mid = 0.5 * (lo + hi);
                    if light(mid) >= y {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                sum += lo - e;
            }
            let want = sum / n as f64;
            assert!(
                (p.growth(y) - want).abs() < 2e-3,
                "y {y}: {} vs {want}",
                p.growth(y)
            );
        }
        // With a wide PSF the edge is a smooth ramp: close to the closed form (the pixel's
        // box and the Gaussian are not quite a Gaussian).
        let wide = Psf { sigma_px: 1.5 };
        let p = EdgeProfile::new(&wide);
        let want = -wide.sigma_edge_px() * phi_inv(0.196);
        assert!((p.growth(0.196) - want).abs() < 0.03, "{}", p.growth(0.196));
    }

    /// A prism's shift is the growth at the prism's threshold; a layer with twice the
    /// dose moves further in (its own light is a third of what cures it: 0.1 px), the top
    /// layer (nothing above) out.
    #[test]
    fn a_prism_moves_by_the_growth_at_its_threshold() {
        let m = crate::cure::test_model();
        let p = EdgeProfile::new(&Psf { sigma_px: 0.5 });
        let t0 = m.threshold(0.5 * m.layer_mm, Some(0));
        let q = (-m.layer_mm / m.dp_mm).exp();
        let wide = Point {
            across: [ACROSS_PX; 2],
            ..Point::default()
        };
        let shift = |own: f64, rest: f64| {
            let look = LookAhead {
                own,
                upper: &[],
                tail: Vec::new(),
                rest,
                rest_at: 0.0,
                delta: Vec::new(),
                rest_delta: 0.0,
            };
            wide.shift(&p, t0, &look, None, (-OUT_PX, 1.3))
        };
        let s = shift(1.0, q / (1.0 - q));
        assert!((s - p.growth(m.edge_threshold())).abs() < 2e-3, "{s}");
        assert!(s > 0.5 && s < 0.6, "{s}");
        let s2 = shift(2.0, q / (1.0 - q));
        assert!(s2 > s + 0.07 && s2 < s + 0.15, "{s2} vs {s}");
        let s_top = shift(1.0, 0.0);
        assert!(s_top < 0.0 && s_top > -OUT_PX, "{s_top}");
        // Along the pixel grid, the move depends on where the edge falls in its pixel;
        // a prism's edge then cures where the exact light of its drawn edge says.
        for base in [0.1, 0.37, 0.5, 0.93] {
            let pt = Point {
                grid: Some(base + 20.0),
                ..wide.clone()
            };
            let look = LookAhead {
                own: 1.0,
                upper: &[],
                tail: Vec::new(),
                rest: q / (1.0 - q),
                rest_at: 0.0,
                delta: Vec::new(),
                rest_delta: 0.0,
            };
            let s = pt.shift(&p, t0, &look, None, (-OUT_PX, 1.3));
            // The drawn edge at base − s lights its pixel by φ = frac(base − s); the light
            // at the section's edge, s outside it: 1 − Φ(x/σ) + φ(Φ(x/σ) − Φ((x − 1)/σ)),
            // x = s + φ.
            let phase = (base - s).rem_euclid(1.0);
            let x = s + phase;
            let l = 1.0 - phi(x / 0.5) + phase * (phi(x / 0.5) - phi((x - 1.0) / 0.5));
            assert!(
                (l / (1.0 - q) - t0).abs() < 2e-3,
                "base {base}: {s}, light {l}"
            );
        }
    }
}
