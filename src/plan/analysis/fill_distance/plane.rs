//! Points, vectors and squares of the plane: the small helpers the edge index and the
//! covers share.

/// Squared distance between `a` and `b`.
#[inline]
pub(super) fn d2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

/// The unit vector along `v`, `None` for a zero or non-finite one.
#[inline]
pub(super) fn unit(v: [f64; 2]) -> Option<[f64; 2]> {
    let l = (v[0] * v[0] + v[1] * v[1]).sqrt();
    (l > 0.0 && l.is_finite()).then(|| [v[0] / l, v[1] / l])
}

/// `a × b`.
#[inline]
pub(super) fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// The corners of the square `[c ± h]`, counter-clockwise from the lowest x and y.
#[inline]
pub(super) fn corners(c: [f64; 2], h: f64) -> [[f64; 2]; 4] {
    [
        [c[0] - h, c[1] - h],
        [c[0] + h, c[1] - h],
        [c[0] + h, c[1] + h],
        [c[0] - h, c[1] + h],
    ]
}
