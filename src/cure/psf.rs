//! The projector's point-spread function: a Gaussian of standard deviation σ (pixels) on
//! the build plane, and the light a uniformly lit square pixel puts at a point (the pixel's
//! box convolved with the Gaussian, separable into one factor per axis).

/// The standard normal cumulative distribution Φ(x).
pub fn phi(x: f64) -> f64 {
    0.5 * erfc(-x / std::f64::consts::SQRT_2)
}

/// The inverse of [`phi`] for `p` in (0, 1) (bisection to 1e-12).
#[cfg(test)]
pub fn phi_inv(p: f64) -> f64 {
    let (mut lo, mut hi) = (-40.0f64, 40.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if phi(mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-12 {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// The complementary error function (W. J. Cody's rational Chebyshev approximations as
/// given by Numerical Recipes' `erfc`, fractional error below 1.2·10⁻⁷ everywhere).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let ans = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 {
        ans
    } else {
        2.0 - ans
    }
}

/// A Gaussian point-spread function of `sigma_px` pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Psf {
    /// Standard deviation, pixels.
    pub sigma_px: f64,
}

impl Psf {
    /// The fraction of a uniformly lit pixel spanning `[0, 1]` along one axis that the
    /// PSF puts at offset `x` along that axis: Φ(x/σ) − Φ((x − 1)/σ).
    #[inline]
    pub fn axis_weight(&self, x: f64) -> f64 {
        phi(x / self.sigma_px) - phi((x - 1.0) / self.sigma_px)
    }

    /// Distance (pixels, from a pixel's edge) beyond which its light is below 3·10⁻⁵ of
    /// its peak and is neglected by the fast evaluation: 4σ.
    pub fn reach_px(&self) -> f64 {
        4.0 * self.sigma_px
    }

    /// The pixels either side of a pixel whose light [`Psf::cures_in`] counts at its
    /// centre: ⌈4σ⌉ + 1.
    pub fn reach_whole_px(&self) -> usize {
        self.reach_px().ceil() as usize + 1
    }

    /// Whether each pixel of the window `rows` × `cols` (row-major) cures: the light of
    /// the pixels around it (`light(row, col)`, relative irradiance, asked from
    /// [`Psf::reach_whole_px`] before the window's first row and column to as far past
    /// its ends; `None` before row or column 0), blurred by the PSF and integrated over
    /// each lit pixel, reaches `t` at the pixel's centre.
    pub fn cures_in(
        &self,
        rows: std::ops::Range<usize>,
        cols: std::ops::Range<usize>,
        t: f32,
        light: impl Fn(Option<usize>, Option<usize>) -> f32,
    ) -> Vec<bool> {
        let r = self.reach_whole_px();
        let w: Vec<f32> = (0..=2 * r)
            .map(|k| self.axis_weight(k as f64 - r as f64 + 0.5) as f32)
            .collect();
        let (ww, wh) = (cols.len(), rows.len());
        let (pw, ph) = (ww + 2 * r, wh + 2 * r);
        let mut lit = vec![0f32; pw * ph];
        for y in 0..ph {
            let fr = (rows.start + y).checked_sub(r);
            for x in 0..pw {
                lit[y * pw + x] = light(fr, (cols.start + x).checked_sub(r));
            }
        }
        // Across, then down.
        let mut across = vec![0f32; ww * ph];
        for y in 0..ph {
            for x in 0..ww {
                across[y * ww + x] = (0..=2 * r).map(|d| w[d] * lit[y * pw + x + d]).sum();
            }
        }
        (0..wh)
            .flat_map(|y| (0..ww).map(move |x| (x, y)))
            .map(|(x, y)| {
                (0..=2 * r)
                    .map(|d| w[d] * across[(y + d) * ww + x])
                    .sum::<f32>()
                    >= t
            })
            .collect()
    }

    /// The standard deviation of the light across a straight anti-aliased edge: the PSF and
    /// a pixel's box (variance 1/12) together, √(σ² + 1/12).
    #[cfg(test)]
    pub fn sigma_edge_px(&self) -> f64 {
        (self.sigma_px * self.sigma_px + 1.0 / 12.0).sqrt()
    }
}

/// Steps of [`AxisTable`] per pixel.
const TABLE_STEPS: f64 = 1024.0;

/// [`Psf::axis_weight`] tabulated at 1/1024 px steps over the PSF's reach, read with
/// linear interpolation (within 3·10⁻⁷ of the function; 0 beyond the reach).
#[derive(Debug, Clone)]
pub struct AxisTable {
    lo: f64,
    values: Vec<f64>,
}

impl AxisTable {
    /// The table of `psf`.
    pub fn new(psf: &Psf) -> AxisTable {
        let lo = -psf.reach_px();
        let hi = 1.0 + psf.reach_px();
        let n = ((hi - lo) * TABLE_STEPS).ceil() as usize + 2;
        let values = (0..n)
            .map(|k| psf.axis_weight(lo + k as f64 / TABLE_STEPS))
            .collect();
        AxisTable { lo, values }
    }

    /// The weight at offset `x` (see [`Psf::axis_weight`]).
    #[inline]
    pub fn weight(&self, x: f64) -> f64 {
        let f = (x - self.lo) * TABLE_STEPS;
        if f < 0.0 {
            return 0.0;
        }
        let k = f as usize;
        if k + 1 >= self.values.len() {
            return 0.0;
        }
        let t = f - k as f64;
        self.values[k] + t * (self.values[k + 1] - self.values[k])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_follows_the_function() {
        let psf = Psf { sigma_px: 0.5 };
        let t = AxisTable::new(&psf);
        let mut worst = 0.0f64;
        for k in -3000..4000 {
            let x = k as f64 / 997.0;
            let want = if x < -psf.reach_px() || x > 1.0 + psf.reach_px() - 0.01 {
                continue;
            } else {
                psf.axis_weight(x)
            };
            worst = worst.max((t.weight(x) - want).abs());
        }
        assert!(worst < 3e-7, "{worst}");
    }

    #[test]
    fn phi_known_values_and_inverse() {
        assert!((phi(0.0) - 0.5).abs() < 1e-7);
        assert!((phi(1.0) - 0.841_344_746).abs() < 1e-7);
        assert!((phi(-1.959_963_985) - 0.025).abs() < 1e-7);
        for p in [0.01, 0.2, 0.5, 0.7, 0.99] {
            assert!((phi(phi_inv(p)) - p).abs() < 1e-9);
        }
    }

    #[test]
    fn a_pixel_spreads_all_its_light() {
        let psf = Psf { sigma_px: 0.5 };
        // Sum over a fine grid of the 1-D weight = 1 (the pixel's light, per unit length).
        let n = 20000;
        let s: f64 = (0..n)
            .map(|k| psf.axis_weight(-5.0 + 11.0 * (k as f64 + 0.5) / n as f64) * 11.0 / n as f64)
            .sum();
        assert!((s - 1.0).abs() < 1e-6, "{s}");
    }
}
