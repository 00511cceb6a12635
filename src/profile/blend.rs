//! The `[blend]` section of a profile: the edge ramp projectors use across their overlaps.
//!
//! A [`BlendCurve`] is an edge ramp `F(t)`, `t` = distance from the projector's edge into
//! the overlap divided by the overlap width (0 at the edge, 1 where the overlap ends), F(0)
//! ≈ 0, F(1) = 1. The tiling (`geometry::blend`) turns the ramps into per-pixel irradiance
//! shares that sum to one (docs/GEOMETRY.md).

use serde::{Deserialize, Serialize};

/// Shape of the edge ramp across an overlap.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "curve", rename_all = "kebab-case", deny_unknown_fields)]
pub enum BlendCurve {
    /// F(t) = sin²(πt/2) = (1 − cos πt)/2: smooth at both ends (the default).
    #[default]
    RaisedCosine,
    /// F(t) = 3t² − 2t³.
    Smoothstep,
    /// F(t) = t.
    Linear,
    /// The "EEHM" curve of Zhang et al. 2024 (edge energy homogenization): a mix of the
    /// exponential (power) decay and the improved trigonometric decay. Its equations are images missing from the paper's text; this is
    /// the reconstruction documented in docs/GEOMETRY.md, with the paper's tuned parameters
    /// as defaults (α = 0.9, p = 0.75, λ = 1.25, β = 0.75, m = 1.1, n = 0.83). The pair is
    /// normalized to sum to one (the paper tuned its parameters by eye on its own projectors;
    /// dmdsl handles the response separately).
    Eehm {
        /// Power-decay value at the overlap's middle, α.
        #[serde(default = "d_alpha")]
        alpha: f64,
        /// Power-decay exponent p.
        #[serde(default = "d_p")]
        p: f64,
        /// Trigonometric exponent λ (replaces the square of sin²).
        #[serde(default = "d_lambda")]
        lambda: f64,
        /// Trigonometric argument exponent β.
        #[serde(default = "d_beta")]
        beta: f64,
        /// Mixing exponent m.
        #[serde(default = "d_m")]
        m: f64,
        /// Mixing share n of the power decay at the inner end.
        #[serde(default = "d_n")]
        n: f64,
    },
    /// No blending: every projector shows full coverage in the overlap (about 2× dose
    /// there). For comparisons only (scheme A of Zhang et al. 2024).
    None,
}

/// The EEHM parameters' defaults (the paper's tuned values), as serde's `default` takes them.
macro_rules! defaults {
    ($($name:ident = $value:expr),*) => { $(fn $name() -> f64 { $value })* };
}
defaults!(
    d_alpha = 0.9,
    d_p = 0.75,
    d_lambda = 1.25,
    d_beta = 0.75,
    d_m = 1.1,
    d_n = 0.83
);

impl BlendCurve {
    /// The curves whose ramps sum to one across an overlap without normalization.
    #[cfg(test)]
    pub(crate) const SYMMETRIC: [BlendCurve; 3] = [
        BlendCurve::RaisedCosine,
        BlendCurve::Smoothstep,
        BlendCurve::Linear,
    ];

    /// The EEHM curve with the paper's parameters (Zhang et al. 2024).
    pub fn eehm() -> Self {
        BlendCurve::Eehm {
            alpha: d_alpha(),
            p: d_p(),
            lambda: d_lambda(),
            beta: d_beta(),
            m: d_m(),
            n: d_n(),
        }
    }

    /// Checks parameter ranges; the message names the offending key.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if let BlendCurve::Eehm {
            alpha,
            p,
            lambda,
            beta,
            m,
            n,
        } = *self
        {
            let chk = |name: &str, v: f64, lo: f64, hi: f64| {
                if v.is_finite() && v > lo && v <= hi {
                    Ok(())
                } else {
                    Err(format!("[blend].{name} must be in ({lo}, {hi}], got {v}"))
                }
            };
            chk("alpha", alpha, 0.0, 1.0)?;
            chk("p", p, 0.0, 10.0)?;
            chk("lambda", lambda, 0.0, 10.0)?;
            chk("beta", beta, 0.0, 10.0)?;
            chk("m", m, 0.0, 10.0)?;
            if !(n.is_finite() && (0.0..=1.0).contains(&n)) {
                return Err(format!("[blend].n must be in [0, 1], got {n}"));
            }
        }
        Ok(())
    }

    /// The raw edge ramp F(t), t ∈ [0, 1] (clamped): 0 at the projector's edge, 1 where the
    /// overlap ends.
    pub fn ramp(&self, t: f64) -> f64 {
        let t = t.clamp(0.0, 1.0);
        match *self {
            BlendCurve::RaisedCosine => {
                let s = (std::f64::consts::FRAC_PI_2 * t).sin();
                s * s
            }
            BlendCurve::Smoothstep => t * t * (3.0 - 2.0 * t),
            BlendCurve::Linear => t,
            BlendCurve::None => 1.0,
            BlendCurve::Eehm {
                alpha,
                p,
                lambda,
                beta,
                m,
                n,
            } => {
                // Power ("exponential") decay, Bourke's edge-blend form: α at the middle.
                let e = if t < 0.5 {
                    alpha * (2.0 * t).powf(p)
                } else {
                    1.0 - (1.0 - alpha) * (2.0 - 2.0 * t).powf(p)
                };
                // Improved trigonometric decay: sin^λ(π/2 · t^β).
                let tr = (std::f64::consts::FRAC_PI_2 * t.powf(beta))
                    .sin()
                    .powf(lambda);
                // Trig dominates near the projector's edge, the power decay near the inner end.
                let s = n * t.powf(m);
                (1.0 - s) * tr + s * e
            }
        }
    }

    /// Irradiance shares (a, b) at position t across a two-projector seam: `a` for the
    /// projector whose edge is at t = 0 (it fades in), `b` for the other; a + b = 1 (except
    /// for [`BlendCurve::None`], where both are 1).
    pub fn pair(&self, t: f64) -> (f64, f64) {
        let a = self.ramp(t);
        let b = self.ramp(1.0 - t);
        if *self == BlendCurve::None {
            return (1.0, 1.0);
        }
        let s = a + b;
        if s <= 0.0 {
            (0.5, 0.5)
        } else {
            (a / s, b / s)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    const CURVES: [BlendCurve; 3] = BlendCurve::SYMMETRIC;

    #[test]
    fn ramps_go_from_zero_to_one_and_pairs_sum_to_one() {
        for c in CURVES.into_iter().chain([BlendCurve::eehm()]) {
            assert!(c.ramp(0.0).abs() < 1e-12, "{c:?}");
            assert!((c.ramp(1.0) - 1.0).abs() < 1e-12, "{c:?}");
            let mut prev = -1.0;
            for i in 0..=1000 {
                let t = i as f64 / 1000.0;
                let v = c.ramp(t);
                assert!(v >= prev - 1e-12, "{c:?} not monotone at {t}");
                prev = v;
                let (a, b) = c.pair(t);
                assert!((a + b - 1.0).abs() < 1e-12, "{c:?} at {t}");
            }
        }
        // The symmetric curves need no normalization.
        for c in CURVES {
            for i in 0..=100 {
                let t = i as f64 / 100.0;
                assert!((c.ramp(t) + c.ramp(1.0 - t) - 1.0).abs() < 1e-12, "{c:?}");
            }
        }
        // The EEHM curve does not sum to one raw (it was tuned by eye), so it is
        // normalized: the raw mid-overlap sum is well above 1.
        let e = BlendCurve::eehm();
        assert!(e.ramp(0.5) * 2.0 > 1.2, "{}", e.ramp(0.5));
        assert_eq!(BlendCurve::None.pair(0.3), (1.0, 1.0));
    }
}
