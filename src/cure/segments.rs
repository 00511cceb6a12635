//! A layer's section in pixel coordinates with a grid index of its edges: outward
//! normals, ray casts (feature widths) and nearest edges (the correction's band).

use crate::slice::Contour;

/// Edge of the grid's cells, pixels.
const CELL: f64 = 8.0;

/// One edge of the section, in field pixel coordinates (u = x/p, v = H − y/p: columns
/// right, rows down, as the rasterizer counts them).
#[derive(Debug, Clone, Copy)]
pub struct Segment {
    /// Start point.
    pub a: [f64; 2],
    /// End point.
    pub b: [f64; 2],
    /// Unit normal pointing out of the material.
    pub n: [f64; 2],
    /// Index of its contour.
    pub contour: u32,
}

/// A section's edges and the grid of cells they cross.
pub struct Segments {
    /// Every edge, contour by contour, in order.
    pub segs: Vec<Segment>,
    /// Index of each contour's first edge (and the total at the end).
    pub starts: Vec<usize>,
    /// Whether each contour is an outer boundary (counter-clockwise in mm).
    pub outer: Vec<bool>,
    origin: [f64; 2],
    cols: usize,
    rows: usize,
    cells: Vec<Vec<u32>>,
}

impl Segments {
    /// The edges of `contours` (build-plane mm) on a field `height_px` rows high of
    /// `pixel_mm` pixels.
    pub fn new(contours: &[Contour], pixel_mm: f64, height_px: f64) -> Segments {
        let s = 1.0 / pixel_mm;
        let px = |p: [f64; 2]| [p[0] * s, height_px - p[1] * s];
        let mut segs = Vec::new();
        let mut starts = Vec::with_capacity(contours.len() + 1);
        let mut outer = Vec::with_capacity(contours.len());
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for (ci, c) in contours.iter().enumerate() {
            starts.push(segs.len());
            outer.push(crate::slice::signed_area(c) > 0.0);
            for i in 0..c.len() {
                let (p, q) = (c[i], c[(i + 1) % c.len()]);
                let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
                let l = dx.hypot(dy);
                if l == 0.0 {
                    continue;
                }
                // Right of the direction of travel, in mm; v runs against y.
                let n = [dy / l, dx / l];
                let (a, b) = (px(p), px(q));
                for k in 0..2 {
                    lo[k] = lo[k].min(a[k]).min(b[k]);
                    hi[k] = hi[k].max(a[k]).max(b[k]);
                }
                segs.push(Segment {
                    a,
                    b,
                    n,
                    contour: ci as u32,
                });
            }
        }
        starts.push(segs.len());
        if segs.is_empty() {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        let cols = ((hi[0] - lo[0]) / CELL) as usize + 1;
        let rows = ((hi[1] - lo[1]) / CELL) as usize + 1;
        let mut cells = vec![Vec::new(); cols * rows];
        let mut me = Segments {
            segs: Vec::new(),
            starts,
            outer,
            origin: lo,
            cols,
            rows,
            cells: Vec::new(),
        };
        for (i, sg) in segs.iter().enumerate() {
            let (c0, r0) = me.cell(sg.a[0].min(sg.b[0]), sg.a[1].min(sg.b[1]));
            let (c1, r1) = me.cell(sg.a[0].max(sg.b[0]), sg.a[1].max(sg.b[1]));
            for r in r0..=r1 {
                for c in c0..=c1 {
                    cells[r * cols + c].push(i as u32);
                }
            }
        }
        me.segs = segs;
        me.cells = cells;
        me
    }

    fn cell(&self, u: f64, v: f64) -> (usize, usize) {
        let c = ((u - self.origin[0]) / CELL).max(0.0) as usize;
        let r = ((v - self.origin[1]) / CELL).max(0.0) as usize;
        (c.min(self.cols - 1), r.min(self.rows - 1))
    }

    /// Calls `f` with the index of every edge that may come within `d` of `p` (each once
    /// per cell it crosses: callers take minima).
    pub fn near(&self, p: [f64; 2], d: f64, mut f: impl FnMut(usize)) {
        if self.segs.is_empty() {
            return;
        }
        let (c0, r0) = self.cell(p[0] - d, p[1] - d);
        let (c1, r1) = self.cell(p[0] + d, p[1] + d);
        for r in r0..=r1 {
            for c in c0..=c1 {
                for &i in &self.cells[r * self.cols + c] {
                    f(i as usize);
                }
            }
        }
    }

    /// Distance from `p` along the unit direction `dir` to the first edge other than
    /// `skip`, if within `max`.
    pub fn ray(&self, p: [f64; 2], dir: [f64; 2], max: f64, skip: usize) -> Option<f64> {
        let mut best = f64::INFINITY;
        self.near(p, max, |i| {
            if i == skip {
                return;
            }
            let s = &self.segs[i];
            let e = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
            let den = dir[0] * e[1] - dir[1] * e[0];
            if den.abs() < 1e-15 {
                return;
            }
            let w = [s.a[0] - p[0], s.a[1] - p[1]];
            let t = (w[0] * e[1] - w[1] * e[0]) / den;
            let u = (w[0] * dir[1] - w[1] * dir[0]) / den;
            if t > 1e-9 && (-1e-12..=1.0 + 1e-12).contains(&u) && t < best {
                best = t;
            }
        });
        (best <= max).then_some(best)
    }
}

/// Distance from `p` to the segment `a`–`b`.
pub fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let e = [b[0] - a[0], b[1] - a[1]];
    let w = [p[0] - a[0], p[1] - a[1]];
    let l2 = e[0] * e[0] + e[1] * e[1];
    let t = if l2 > 0.0 {
        ((w[0] * e[0] + w[1] * e[1]) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (w[0] - t * e[0]).hypot(w[1] - t * e[1])
}
