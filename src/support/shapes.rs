//! The support structure as closed triangle meshes: each support a solid of revolution
//! (a regular polygon of [`SIDES`] sides per ring), the pad a loft between two offsets of
//! the convex hull of what stands on it.

use crate::mesh::{Mesh, Soup};

/// Sides of a support's cross-section.
pub const SIDES: usize = 16;
/// Segments of a full turn of the pad's rounded corners.
const PAD_TURN: usize = 32;

/// A ring of `n` points about (`x`, `y`) at radius `r` and height `z`, counter-clockwise
/// seen from +Z.
fn ring(x: f64, y: f64, r: f64, z: f64, n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            [x + r * a.cos(), y + r * a.sin(), z]
        })
        .collect()
}

/// The closed surface through `rings` (each counter-clockwise, the same number of points,
/// from the bottom up), capped at both ends, facets facing out.
fn loft(rings: &[Vec<[f64; 3]>]) -> Soup {
    let f = |p: [f64; 3]| p.map(|v| v as f32);
    let centre = |r: &[[f64; 3]]| {
        let n = r.len() as f64;
        let s = r
            .iter()
            .fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]]);
        s.map(|v| v / n)
    };
    let mut soup = Soup::new();
    let (bottom, top) = (&rings[0], &rings[rings.len() - 1]);
    let (cb, ct) = (centre(bottom), centre(top));
    let n = bottom.len();
    for i in 0..n {
        let j = (i + 1) % n;
        soup.push([f(cb), f(bottom[j]), f(bottom[i])]);
        soup.push([f(ct), f(top[i]), f(top[j])]);
        for w in rings.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            soup.push([f(a[i]), f(a[j]), f(b[j])]);
            soup.push([f(a[i]), f(b[j]), f(b[i])]);
        }
    }
    soup
}

/// A support's closed mesh: the solid of revolution of `rings` ((z, radius), bottom up)
/// about the vertical through (`x`, `y`).
pub fn revolved(x: f64, y: f64, rings: &[[f64; 2]]) -> Mesh {
    let rs: Vec<Vec<[f64; 3]>> = rings
        .iter()
        .map(|&[z, r]| ring(x, y, r, z, SIDES))
        .collect();
    Mesh::from_soup(&loft(&rs), "supports")
}

/// The convex hull of `pts`, counter-clockwise (Andrew's monotone chain; collinear points
/// dropped).
pub fn convex_hull(pts: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p = pts.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// The outline `d` beyond convex polygon `hull` (counter-clockwise), corners rounded: the
/// same number of points for any `d` > 0 of the same hull.
pub fn offset(hull: &[[f64; 2]], d: f64) -> Vec<[f64; 2]> {
    let step = std::f64::consts::TAU / PAD_TURN as f64;
    if hull.len() == 1 {
        return (0..PAD_TURN)
            .map(|i| {
                let a = step * i as f64;
                [hull[0][0] + d * a.cos(), hull[0][1] + d * a.sin()]
            })
            .collect();
    }
    let k = hull.len();
    let normal =
        |a: [f64; 2], b: [f64; 2]| (b[1] - a[1]).atan2(b[0] - a[0]) - std::f64::consts::FRAC_PI_2;
    let mut out = Vec::new();
    for i in 0..k {
        let (prev, v, next) = (hull[(i + k - 1) % k], hull[i], hull[(i + 1) % k]);
        let a0 = normal(prev, v);
        let sweep = (normal(v, next) - a0).rem_euclid(std::f64::consts::TAU);
        let steps = ((sweep / step).ceil() as usize).max(1);
        for j in 0..=steps {
            let a = a0 + sweep * j as f64 / steps as f64;
            out.push([v[0] + d * a.cos(), v[1] + d * a.sin()]);
        }
    }
    out
}

/// The pad's closed mesh: from `bottom` at z = 0 up to `top` at `height` (outlines of the
/// same number of points, counter-clockwise).
pub fn pad(bottom: &[[f64; 2]], top: &[[f64; 2]], height: f64) -> Mesh {
    let lift = |o: &[[f64; 2]], z: f64| o.iter().map(|p| [p[0], p[1], z]).collect::<Vec<_>>();
    Mesh::from_soup(&loft(&[lift(bottom, 0.0), lift(top, height)]), "supports")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn supports_and_pads_are_closed_with_the_volume_of_their_polygons() {
        let m = revolved(
            3.0,
            4.0,
            &[[1.0, 1.5], [2.0, 0.5], [6.0, 0.5], [7.0, 0.2], [7.2, 0.2]],
        );
        assert!(m.report.closed_manifold, "{:?}", m.report);
        assert_eq!(m.report.shells, 1);
        // Frusta of regular 16-gons: area = n/2 · r² · sin(2π/n).
        let k = SIDES as f64 / 2.0 * (std::f64::consts::TAU / SIDES as f64).sin();
        let frustum = |h: f64, a: f64, b: f64| h / 3.0 * k * (a * a + a * b + b * b);
        let want = frustum(1.0, 1.5, 0.5)
            + frustum(4.0, 0.5, 0.5)
            + frustum(1.0, 0.5, 0.2)
            + frustum(0.2, 0.2, 0.2);
        assert!(
            (m.report.volume_mm3 - want).abs() < 1e-4 * want,
            "{} {want}",
            m.report.volume_mm3
        );
        let hull = convex_hull(&[
            [0.0, 0.0],
            [4.0, 0.0],
            [4.0, 3.0],
            [0.0, 3.0],
            [2.0, 1.0],
            [2.0, 0.0],
        ]);
        assert_eq!(hull, vec![[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]);
        let (bottom, top) = (offset(&hull, 2.0), offset(&hull, 1.0));
        assert_eq!(bottom.len(), top.len());
        let p = pad(&bottom, &top, 1.0);
        assert!(p.report.closed_manifold, "{:?}", p.report);
        // Rounded rectangles: 12 + 2·7·d + π d² (the polygon's arcs a little less).
        let area = |d: f64| 12.0 + 14.0 * d + std::f64::consts::PI * d * d;
        assert!(p.report.volume_mm3 < (area(1.0) + area(2.0)) / 2.0 + 0.01);
        assert!(p.report.volume_mm3 > area(1.0));
        for single in [vec![[1.0, 1.0]], vec![[1.0, 1.0], [3.0, 1.0]]] {
            let h = convex_hull(&single);
            let (b, t) = (offset(&h, 1.5), offset(&h, 1.0));
            assert_eq!(b.len(), t.len());
            assert!(pad(&b, &t, 0.5).report.closed_manifold);
        }
    }
}
