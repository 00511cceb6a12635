//! The contour offset of the dimensional correction (`[accuracy] xy_offset_mm`,
//! docs/CALIBRATION.md "Dimensions"): a section grown or shrunk by a distance along the
//! normal of every edge, as PrusaSlicer's absolute correction does.
//!
//! The contours are first united under the nonzero rule (overlapping shells, backwards
//! regions of a defective mesh: what the raster would light), then offset with mitred
//! corners, so that a square stays a square; a corner sharper than [`MITER_MIN_RAD`] is
//! bevelled. A part of the section thinner than twice an inward offset vanishes. Both steps
//! run on i_overlay's integer grid over the section's box (about 10⁻⁸ of its size), so the
//! points come back rounded to it.

use super::Contour;
use i_overlay::core::fill_rule::FillRule;
use i_overlay::float::simplify::SimplifyShape;
use i_overlay::mesh::float::outline::offset::OutlineOffset;
use i_overlay::mesh::float::style::{LineJoin, OutlineStyle};

/// Corners whose interior angle is below this are bevelled, not mitred, rad (about 6°:
/// a mitre there would reach far beyond the section).
pub const MITER_MIN_RAD: f64 = 0.1;

/// `contours` (a section's, filled by the nonzero rule) offset by `d_mm` along every edge's
/// outward normal (inward where negative): outer contours counter-clockwise, holes
/// clockwise. An offset of 0 returns the contours as they are.
pub fn offset(contours: &[Contour], d_mm: f64) -> Vec<Contour> {
    if d_mm == 0.0 || contours.is_empty() {
        return contours.to_vec();
    }
    debug_assert!(d_mm.is_finite());
    let united = contours.simplify_shape(FillRule::NonZero);
    let style = OutlineStyle::new(d_mm).line_join(LineJoin::Miter(MITER_MIN_RAD));
    united.outline(&style).into_iter().flatten().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slice::signed_area;

    fn square(x0: f64, y0: f64, s: f64) -> Contour {
        vec![[x0, y0], [x0 + s, y0], [x0 + s, y0 + s], [x0, y0 + s]]
    }

    fn area(c: &[Contour]) -> f64 {
        c.iter().map(signed_area).sum()
    }

    #[test]
    fn a_square_grows_and_shrinks_by_the_offset_on_every_side() {
        let s = vec![square(1.0, 2.0, 4.0)];
        for d in [0.25, -0.25, 0.013] {
            let o = offset(&s, d);
            assert_eq!(o.len(), 1);
            let w = 4.0 + 2.0 * d;
            assert!((area(&o) - w * w).abs() < 1e-6, "d {d}: area {}", area(&o));
            let (xs, ys): (Vec<f64>, Vec<f64>) = o[0].iter().map(|p| (p[0], p[1])).unzip();
            let lo = xs.iter().copied().fold(f64::MAX, f64::min);
            let hi = ys.iter().copied().fold(f64::MIN, f64::max);
            assert!((lo - (1.0 - d)).abs() < 1e-6 && (hi - (6.0 + d)).abs() < 1e-6);
        }
    }

    #[test]
    fn holes_move_the_other_way_and_overlapping_shells_unite_first() {
        // A 10 mm square with a 4 mm hole, and a second shell overlapping its corner.
        let mut hole = square(3.0, 3.0, 4.0);
        hole.reverse();
        let s = vec![square(0.0, 0.0, 10.0), hole, square(8.0, 8.0, 4.0)];
        let united = 100.0 - 16.0 + 16.0 - 4.0;
        assert!((area(&offset(&s, 1e-9)) - united).abs() < 1e-5);
        // Out by 0.5: the union of [−0.5, 10.5]² and [7.5, 12.5]² (121 + 25 − 9), less
        // the hole shrunk to [3.5, 6.5]².
        let o = offset(&s, 0.5);
        let want = 121.0 + 25.0 - 9.0 - 9.0;
        assert!((area(&o) - want).abs() < 1e-6, "{} vs {want}", area(&o));
        assert_eq!(o.iter().filter(|c| signed_area(c) < 0.0).count(), 1);
    }

    #[test]
    fn an_inward_offset_removes_what_is_thinner_than_twice_it() {
        let s = vec![
            square(0.0, 0.0, 10.0),
            vec![[20.0, 0.0], [20.4, 0.0], [20.4, 5.0], [20.0, 5.0]],
        ];
        let o = offset(&s, -0.25);
        assert_eq!(o.len(), 1);
        assert!((area(&o) - 9.5 * 9.5).abs() < 1e-6);
        assert_eq!(offset(&s, 0.0), s);
    }
}
