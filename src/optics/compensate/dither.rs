//! Error diffusion for pixel mode with `--dither on`: the quantization error of each
//! pixel (in irradiance) goes to its lit neighbours (Floyd–Steinberg, serpentine), row by
//! row within the layer, so the output does not depend on the thread count.

use super::{Compensator, Mask};

impl Compensator {
    /// Pixel mode with error diffusion over rows `r0..r1` of `m` (lit pixels only).
    pub(super) fn apply_dither(&self, m: &mut Mask, r0: usize, r1: usize) {
        let w = self.w;
        let lv = &self.levels;
        let s_max = lv.s_max();
        let top = lv.s.len() - 1;
        // Error (in units of E*) carried to the current and the next row; index c + 1.
        let mut cur = vec![0f32; w + 2];
        let mut next = vec![0f32; w + 2];
        let mut t = vec![0f32; w];
        for r in r0..r1 {
            let ltr = (r - r0).is_multiple_of(2);
            let base = r * w;
            // E*/P over the row's lit columns.
            let lit = |c: &usize| m.data[base + c] != 0;
            let (Some(a), Some(b)) = ((0..w).find(lit), (0..w).rfind(lit)) else {
                std::mem::swap(&mut cur, &mut next);
                next.fill(0.0);
                continue;
            };
            self.pixel_tables.target_over_p_in(r, a, &mut t[a..=b]);
            for k in 0..w {
                let c = if ltr { k } else { w - 1 - k };
                let i = base + c;
                let v = m.data[i];
                if v == 0 {
                    continue;
                }
                let ti = t[c] as f64;
                let d = v as f64 / 255.0 + cur[c + 1] as f64;
                let target = d * ti;
                let from = self.pixel_tables.level(self.gray_row(r)[c]);
                let idx = lv.nearest_from(from, target);
                m.data[i] = lv.gray[idx];
                if idx == top && target > s_max {
                    // Cannot reach the target here: do not push the deficit around.
                    continue;
                }
                let e = (d - lv.s[idx] / ti).clamp(-0.5, 0.5) as f32;
                // Forward neighbour on this row, three neighbours below (mirrored on
                // right-to-left rows); only lit pixels (coverage > 0) take a share.
                let (fwd, back): (isize, isize) = if ltr { (1, -1) } else { (-1, 1) };
                let cc = c as isize;
                let in_row = |x: isize| x >= 0 && (x as usize) < w;
                if in_row(cc + fwd) && m.data[(base as isize + cc + fwd) as usize] != 0 {
                    cur[(cc + fwd + 1) as usize] += e * (7.0 / 16.0);
                }
                if r + 1 < r1 {
                    let nb = (base + w) as isize;
                    for (dx, wgt) in [(back, 3.0f32), (0, 5.0), (fwd, 1.0)] {
                        let x = cc + dx;
                        if in_row(x) && m.data[(nb + x) as usize] != 0 {
                            next[(x + 1) as usize] += e * (wgt / 16.0);
                        }
                    }
                }
            }
            std::mem::swap(&mut cur, &mut next);
            next.fill(0.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{response_s as s, setup};
    use super::super::{Dither, Mode};
    use super::*;

    #[test]
    fn pixel_dither_is_deterministic_and_keeps_the_mean() {
        let (cal, field) = setup();
        let c = Compensator::new(&cal, &field, Mode::Pixel, Dither::On).unwrap();
        let mut a = Mask::zeros(40, 30);
        a.data.iter_mut().enumerate().for_each(|(i, v)| {
            *v = if i % 40 < 35 { 255 } else { 0 };
        });
        let mut b = a.clone();
        c.apply(&mut a);
        c.apply(&mut b);
        assert_eq!(a, b);
        // Mean delivered irradiance per lit pixel in units of E* stays close to 1.
        let p = |col: usize| 1.0 + (col as f64 + 0.5) / 40.0;
        let (mut sum, mut n) = (0.0, 0);
        for (i, &g) in a.data.iter().enumerate() {
            if i % 40 < 35 {
                sum += s(g) * p(i % 40) / c.prediction.target;
                n += 1;
            } else {
                assert_eq!(g, 0);
            }
        }
        assert!((sum / n as f64 - 1.0).abs() < 0.003, "{}", sum / n as f64);
    }
}
