//! XY correction: move every edge of the drawn section by the offset that puts the
//! predicted cured edge at mid-layer on the section's edge.
//!
//! Across a straight anti-aliased edge the light is close to Φ(−s/σₑ) at signed distance
//! s outside it, σₑ = √(σ² + 1/12) ([`Psf::sigma_edge_px`]), so the cured edge lies at
//! s* = −σₑ·Φ⁻¹(T) for the mid-layer threshold T ([`CureModel::edge_threshold`]). The
//! correction draws the section moved inward by s* (outward where s* < 0): a pixel within
//! reach of an edge gets its exact coverage changed by the difference between the
//! coverages of the pixel by the edge's half-plane moved and not moved
//! ([`halfplane_coverage`]). Straight edges are then drawn exactly moved; pixels farther
//! than the move from every edge keep their exact coverage, so interiors stay flat. The
//! light compensation maps the corrected coverage to grays as it maps any coverage: one
//! target dose for both.

use super::dose::CureModel;
use super::psf::{phi_inv, Psf};
use super::segments::{point_segment_distance, Segments};
use crate::raster::Mask;
use crate::raster::PixelBox;
use crate::slice::Contour;

/// The inward move of the edges that puts the cured edge on the section, px (negative:
/// outward).
pub fn edge_shift_px(model: &CureModel) -> f64 {
    let psf = Psf {
        sigma_px: model.sigma_px,
    };
    let t = model.edge_threshold().clamp(1e-9, 1.0 - 1e-9);
    -psf.sigma_edge_px() * phi_inv(t)
}

/// Area of the unit pixel centred at the origin on the side `n·p ≤ u` of a line with
/// unit normal `n`.
pub fn halfplane_coverage(n: [f64; 2], u: f64) -> f64 {
    let (a, b) = {
        let (x, y) = (n[0].abs(), n[1].abs());
        if x >= y {
            (x, y)
        } else {
            (y, x)
        }
    };
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

/// Moves the edges of the coverage mask `mask` (values = coverage × 255, zero outside
/// `lit`) of the section `contours` (build-plane mm) inward by `shift_px`; only pixels
/// inside `lit` change. Returns the number of pixels changed.
pub fn correct_coverage(
    mask: &mut Mask,
    lit: PixelBox,
    contours: &[Contour],
    pixel_mm: f64,
    shift_px: f64,
) -> usize {
    if shift_px == 0.0 || lit.r0 >= lit.r1 || lit.c0 >= lit.c1 {
        return 0;
    }
    let segs = Segments::new(contours, pixel_mm, mask.height as f64);
    let reach = std::f64::consts::FRAC_1_SQRT_2 + shift_px.abs();
    let (bw, bh) = (lit.c1 - lit.c0, lit.r1 - lit.r0);
    // Nearest edge of each pixel of the box within reach: distance and edge.
    let mut best = vec![(f32::INFINITY, u32::MAX); bw * bh];
    for (i, s) in segs.segs.iter().enumerate() {
        let lo = |k: usize| (s.a[k].min(s.b[k]) - reach - 0.5).floor().max(0.0) as usize;
        let hi = |k: usize| (s.a[k].max(s.b[k]) + reach + 0.5).ceil().max(0.0) as usize;
        let (c0, c1) = (lo(0).max(lit.c0), hi(0).min(lit.c1));
        let (r0, r1) = (lo(1).max(lit.r0), hi(1).min(lit.r1));
        for r in r0..r1 {
            for c in c0..c1 {
                let p = [c as f64 + 0.5, r as f64 + 0.5];
                let d = point_segment_distance(p, s.a, s.b) as f32;
                let slot = &mut best[(r - lit.r0) * bw + (c - lit.c0)];
                if d < slot.0 {
                    *slot = (d, i as u32);
                }
            }
        }
    }
    let w = mask.width as usize;
    let mut changed = 0;
    for r in 0..bh {
        for c in 0..bw {
            let (d, i) = best[r * bw + c];
            if (d as f64) >= reach {
                continue;
            }
            let s = &segs.segs[i as usize];
            let p = [(c + lit.c0) as f64 + 0.5, (r + lit.r0) as f64 + 0.5];
            // Signed distance of the centre outside the edge's line.
            let sd = (p[0] - s.a[0]) * s.n[0] + (p[1] - s.a[1]) * s.n[1];
            let delta = halfplane_coverage(s.n, -(sd + shift_px)) - halfplane_coverage(s.n, -sd);
            let k = (r + lit.r0) * w + c + lit.c0;
            let v = (mask.data[k] as f64 + 255.0 * delta)
                .round()
                .clamp(0.0, 255.0) as u8;
            if v != mask.data[k] {
                mask.data[k] = v;
                changed += 1;
            }
        }
    }
    changed
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
}
