//! P, the calibration's field factor, at the pixel centres, row by row or for some
//! columns of a row from the model ([`FieldRows`], no w × h buffer): the set-up's pass
//! over the field ([`super::field_pass`]) and pixel mode's edge pixels read it.

#[cfg(target_arch = "x86_64")]
use super::kernels::horner_avx2;
use super::kernels::horner_f32;
use super::{Field, FieldModel, Form};

/// P at the pixel centres of the field, one row at a time (no w × h buffer): inside the
/// polynomial's rectangle Horner in u with the row's coefficients (in f64, rounded to f32,
/// times the scale in f32), elsewhere [`FieldModel::eval`] rounded to f32 (its linear
/// continuation, from gradients computed once per column or per row).
#[derive(Debug, Clone)]
pub(super) struct FieldRows {
    fm: FieldModel,
    h: usize,
    p: f64,
    /// Per column: the clamped x minus its nearest point of the rectangle, mm, and u
    /// there.
    dx: Vec<f64>,
    u: Vec<f64>,
    /// Whether every u is finite.
    finite_u: bool,
    /// The columns inside the rectangle: one contiguous run [ua, ub).
    ua: usize,
    ub: usize,
    /// Value and gradient of the polynomial along the rectangle's bottom and top edges,
    /// per column.
    edge: [Vec<[f64; 3]>; 2],
}

impl FieldRows {
    pub(super) fn new(fm: &FieldModel, field: &Field) -> FieldRows {
        let w = field.width_px as usize;
        let p = field.pixel_mm;
        let m = fm.extrapolate_mm.get();
        let [x0, _, x1, _] = fm.area_mm;
        let [px0, _, px1, _] = fm.polynomial_area_mm.unwrap_or(fm.area_mm);
        let s = 1.0 / fm.length_unit_mm.get();
        let (mut dx, mut u) = (Vec::with_capacity(w), Vec::with_capacity(w));
        for c in 0..w {
            let xc = ((c as f64 + 0.5) * p).clamp(x0 - m, x1 + m);
            let xp = xc.clamp(px0, px1);
            dx.push(xc - xp);
            u.push((xp - fm.origin_mm[0]) * s);
        }
        // Columns with xp == xc (dx == 0 also for xp == xc == −0.0, which cannot differ).
        let inside = |c: usize| {
            let xc = ((c as f64 + 0.5) * p).clamp(x0 - m, x1 + m);
            xc >= px0 && xc <= px1
        };
        let ua = (0..w).position(inside).unwrap_or(w);
        let ub = (0..w).rposition(inside).map_or(ua, |i| i + 1);
        debug_assert!((ua..ub).all(inside));
        let [_, py0, _, py1] = fm.polynomial_area_mm.unwrap_or(fm.area_mm);
        let edge = [py0, py1].map(|py| {
            let v = (py - fm.origin_mm[1]) * s;
            let grad = |&uc: &f64| {
                let (f, fu, fv) = fm.coefficients.eval_grad(uc, v);
                [f, fu, fv]
            };
            u.iter().map(grad).collect()
        });
        FieldRows {
            fm: fm.clone(),
            h: field.height_px as usize,
            p,
            dx,
            finite_u: u.iter().all(|x| x.is_finite()),
            u,
            ua,
            ub,
            edge,
        }
    }

    /// P at the pixel centres of image row `r` (row 0 = top) into `row` (`w` values).
    /// `AVX2`: true only where the CPU has AVX2 (inlined into [`sum_rows_avx2`](super::field_pass::sum_rows_avx2)); the
    /// same values either way.
    #[inline(always)]
    pub(super) fn row<const AVX2: bool>(&self, r: usize, row: &mut [f32]) {
        self.row_in::<AVX2>(r, 0, row)
    }

    /// P at the pixel centres of columns `c0..c0 + out.len()` of image row `r`: the values
    /// [`row`](Self::row) gives there (each column's value is computed on its own).
    #[inline(always)]
    pub(super) fn row_in<const AVX2: bool>(&self, r: usize, c0: usize, out: &mut [f32]) {
        let fm = &self.fm;
        let m = fm.extrapolate_mm.get();
        let [_, y0, _, y1] = fm.area_mm;
        let [_, py0, _, py1] = fm.polynomial_area_mm.unwrap_or(fm.area_mm);
        let s = 1.0 / fm.length_unit_mm.get();
        let c1 = c0 + out.len();
        // The columns of the rectangle among c0..c1.
        let (ua, ub) = (self.ua.clamp(c0, c1), self.ub.clamp(c0, c1));
        let (ua, ub) = (ua, ub.max(ua));
        let y = (self.h as f64 - r as f64 - 0.5) * self.p;
        let yc = y.clamp(y0 - m, y1 + m);
        let yp = yc.clamp(py0, py1);
        let v = (yp - fm.origin_mm[1]) * s;
        let dy = yc - yp;
        let (dx, u) = (&self.dx[c0..c1], &self.u[c0..c1]);
        if yp == yc {
            let a = fm.coefficients.in_u(v);
            let from_top = self.finite_u && a.last().is_some_and(|&c| c.is_finite() && c != 0.0);
            let (ia, ib) = (ua - c0, ub - c0);
            let seg = &mut out[ia..ib];
            let scf = fm.scale.get() as f32;
            // Separate passes: exp must not be evaluated (speculatively) for polynomials.
            let horner = |seg: &mut [f32], scale: f32| {
                #[cfg(target_arch = "x86_64")]
                if AVX2 {
                    // SAFETY: AVX2 is true only where the CPU has AVX2.
                    return unsafe { horner_avx2(seg, &u[ia..ib], &a, scale, from_top) };
                }
                horner_f32(seg, &u[ia..ib], &a, scale)
            };
            match fm.form {
                Form::Polynomial => horner(seg, scf),
                Form::Exponential => {
                    horner(seg, 1.0);
                    seg.iter_mut().for_each(|o| *o = scf * o.exp())
                }
                Form::InverseSquare => {
                    horner(seg, 1.0);
                    seg.iter_mut().for_each(|o| *o = scf / (*o * *o))
                }
            }
            // Left and right of the rectangle: one nearest point per side (both sides
            // in one run if the rectangle lies between two pixel centres).
            let mut g = (f64::NAN, [0.0; 3]);
            for c in (0..ia).chain(ib..out.len()) {
                if u[c].to_bits() != g.0.to_bits() {
                    let (f, fu, fv) = fm.coefficients.eval_grad(u[c], v);
                    g = (u[c], [f, fu, fv]);
                }
                out[c] = fm.continued(g.1, dx[c], dy) as f32;
            }
        } else {
            // Above or below the rectangle: the nearest point of each column is on its
            // top or bottom edge.
            let edge = &self.edge[(yp == py1) as usize][c0..c1];
            if fm.form == Form::Polynomial {
                // `continued` written out (the same operations; a loop the compiler
                // vectorizes): scale · max(f + (fu·dx + fv·dy)·s, f/10).
                let scale = fm.scale.get();
                for ((o, &[f, fu, fv]), &d) in out.iter_mut().zip(edge).zip(dx) {
                    let lin = f + (fu * d + fv * dy) * s;
                    *o = (scale * lin.max(0.1 * f)) as f32;
                }
            } else {
                for ((o, &g), &d) in out.iter_mut().zip(edge).zip(dx) {
                    *o = fm.continued(g, d, dy) as f32;
                }
            }
        }
    }
}

/// P at every pixel centre of the field (row-major, top row first); see [`FieldRows`].
#[cfg(test)]
pub(super) fn pixel_p(fm: &FieldModel, field: &Field) -> Vec<f32> {
    let w = field.width_px as usize;
    let rows = FieldRows::new(fm, field);
    let mut out = vec![0f32; w * field.height_px as usize];
    for (r, row) in out.chunks_exact_mut(w).enumerate() {
        rows.row::<false>(r, row);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::compensate::test_support::{self, random_field, rng};

    /// P at a pixel centre as the set-up defines it: inside the polynomial's rectangle
    /// Horner in u (f64) rounded to f32 and scaled in f32, elsewhere `eval` rounded to f32.
    fn p_reference(fm: &FieldModel, field: &Field, r: usize, c: usize) -> f32 {
        let p = field.pixel_mm;
        let (x, y) = (
            (c as f64 + 0.5) * p,
            (field.height_px as f64 - r as f64 - 0.5) * p,
        );
        let m = fm.extrapolate_mm.get();
        let [x0, y0, x1, y1] = fm.area_mm;
        let [px0, py0, px1, py1] = fm.polynomial_area_mm.unwrap_or(fm.area_mm);
        let (xc, yc) = (x.clamp(x0 - m, x1 + m), y.clamp(y0 - m, y1 + m));
        if !(xc >= px0 && xc <= px1 && yc >= py0 && yc <= py1) {
            return fm.eval(x, y) as f32;
        }
        let inv = 1.0 / fm.length_unit_mm.get();
        let a = fm.coefficients.in_u((yc - fm.origin_mm[1]) * inv);
        let u = (xc - fm.origin_mm[0]) * inv;
        let q = a.iter().rev().fold(0.0, |acc, k| acc * u + k) as f32;
        let scf = fm.scale.get() as f32;
        match fm.form {
            Form::Polynomial => q * scf,
            Form::Exponential => scf * q.exp(),
            Form::InverseSquare => scf / (q * q),
        }
    }

    #[test]
    fn field_rows_equal_the_definition_with_and_without_avx2() {
        let mut rnd = rng(0x9e37_79b9_7f4a_7c15);
        for case in 0..36 {
            let fm = random_field(&mut rnd, case);
            let field = test_support::field(61 + (case as u32 % 5) * 7, 47, 0.73);
            let (w, h) = (field.width_px as usize, field.height_px as usize);
            let rows = FieldRows::new(&fm, &field);
            let (mut a, mut b) = (vec![0f32; w], vec![0f32; w]);
            for r in 0..h {
                rows.row::<false>(r, &mut a);
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2.
                    unsafe { avx2_row(&rows, r, &mut b) };
                    assert_eq!(a, b, "case {case} row {r}: AVX2");
                }
                for (c, &v) in a.iter().enumerate() {
                    let want = p_reference(&fm, &field, r, c);
                    assert_eq!(v.to_bits(), want.to_bits(), "case {case} row {r} col {c}");
                }
                // Some columns, and each column alone: the row's values.
                let (c0, c1) = (r % w, (r * 7 + 5) % w + 1);
                rows.row_in::<false>(r, c0, &mut b[c0..c1.max(c0)]);
                assert_eq!(a[c0..c1.max(c0)], b[c0..c1.max(c0)], "case {case} row {r}");
                for c in 0..w {
                    rows.row_in::<false>(r, c, &mut b[c..c + 1]);
                }
                assert_eq!(a, b, "case {case} row {r}: one column at a time");
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn avx2_row(rows: &FieldRows, r: usize, out: &mut [f32]) {
        rows.row::<true>(r, out)
    }
}
