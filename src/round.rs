//! Rounding of the numbers dmdsl writes (`job.json`, the `--json` outputs); docs/JSON.md,
//! "Numbers", lists what each quantity is rounded to and why.
//!
//! Every number a bundle records is rounded to what it means before it is used and
//! written. A value rounded here is the nearest `f64` to a decimal of few digits, so Rust
//! and `serde_json` print it as that decimal, and parsing the printed text gives the same
//! `f64` back.

/// 10⁰ … 10²², every one exactly representable as an `f64`.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Integers up to this magnitude are exact in an `f64` (2⁵³).
const EXACT_INT: f64 = 9_007_199_254_740_992.0;

/// `x` rounded to `places` decimal places (at most 22): the nearest `f64` to that decimal.
/// Values too large for the rounding to matter, NaN and infinities come back unchanged.
///
/// ```
/// assert_eq!(dmdsl::round::decimals(0.1 + 0.2, 3), 0.3);
/// assert_eq!(dmdsl::round::decimals(2.0004999, 3), 2.0);
/// ```
pub fn decimals(x: f64, places: u32) -> f64 {
    let p = POW10[places.min(22) as usize];
    let scaled = x * p;
    if !scaled.is_finite() || scaled.abs() >= EXACT_INT {
        return x;
    }
    // `+ 0.0` turns a rounded -0.0 into 0.0.
    scaled.round() / p + 0.0
}

/// `x` rounded to `digits` significant digits (1 to 17).
///
/// ```
/// assert_eq!(dmdsl::round::significant(624.9904531591078, 6), 624.990);
/// assert_eq!(dmdsl::round::significant(3.2418008582492144e-6, 6), 3.24180e-6);
/// assert_eq!(dmdsl::round::significant(66989.52031366112, 3), 67000.0);
/// ```
pub fn significant(x: f64, digits: u32) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let digits = digits.clamp(1, 17) as i32;
    let exponent = x.abs().log10().floor() as i32;
    let places = digits - 1 - exponent;
    if (0..=22).contains(&places) {
        decimals(x, places as u32)
    } else if (-22..0).contains(&places) {
        let p = POW10[(-places) as usize];
        (x / p).round() * p + 0.0
    } else {
        // Beyond the table (below 1e-22 or above 1e22): let the formatter round.
        format!("{:.*e}", (digits - 1) as usize, x)
            .parse()
            .unwrap_or(x)
    }
}

/// A time in seconds: to 1 ms, and to 3 significant digits below 0.1 s (so that a short
/// time keeps 0.5 % or better). A positive time stays positive.
///
/// ```
/// assert_eq!(dmdsl::round::time_s(75.68499999999999), 75.685);
/// assert_eq!(dmdsl::round::time_s(0.0123456), 0.0123);
/// ```
pub fn time_s(x: f64) -> f64 {
    if x.abs() >= 0.1 {
        decimals(x, 3)
    } else {
        significant(x, 3)
    }
}

/// A length on the build plane (a bounding box, a fill distance), mm: to 1 µm.
pub fn plane_mm(x: f64) -> f64 {
    decimals(x, 3)
}

/// A length on the build plane that is a lower bound (a fill distance, never above the
/// exact value): down to 1 µm, taking a value within 1e-9 mm below a whole µm as that µm.
pub fn plane_mm_down(x: f64) -> f64 {
    let scaled = x * 1000.0;
    if !scaled.is_finite() || scaled.abs() >= EXACT_INT {
        return x;
    }
    (scaled + 1e-6).floor() / 1000.0 + 0.0
}

/// A section's area, mm²: to 9 significant digits (the coverage it comes from is exact to
/// far below a pixel).
pub fn area_mm2(x: f64) -> f64 {
    significant(x, 9)
}

/// A derived quantity (an area, a volume, an irradiance, a spread, a fit error): to 6
/// significant digits.
pub fn derived(x: f64) -> f64 {
    significant(x, 6)
}

/// A wall-clock duration measured while running, s: to 1 µs.
pub fn elapsed_s(x: f64) -> f64 {
    decimals(x, 6)
}

/// The stage's grid: positions that are a whole number of its steps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageGrid {
    /// Steps per mm.
    steps_per_mm: f64,
}

impl StageGrid {
    /// The grid of a stage with `steps_per_mm` steps per mm (finite and > 0).
    pub fn new(steps_per_mm: f64) -> StageGrid {
        StageGrid { steps_per_mm }
    }

    /// The whole number of steps nearest to `mm`.
    pub fn steps(&self, mm: f64) -> f64 {
        (mm * self.steps_per_mm).round()
    }

    /// `mm` moved to the nearest whole step, written with the fewest decimals (at most 9)
    /// that give that step to a millionth of a step: with 800 steps per mm, 0.15 and
    /// 5.00125 mm; with 3 steps per mm, 0.3333333 mm. Rounding the result to the grid
    /// again (as the executor does) gives the same step.
    ///
    /// ```
    /// let g = dmdsl::round::StageGrid::new(800.0);
    /// assert_eq!(g.position(3.0 * 0.05), 0.15);
    /// assert_eq!(g.position(0.1234), 0.12375);
    /// ```
    pub fn position(&self, mm: f64) -> f64 {
        self.at_step(self.steps(mm)).unwrap_or(mm)
    }

    /// The highest whole step at or below `mm` (to a millionth of a step), written as
    /// [`position`](Self::position) writes it.
    pub fn position_at_most(&self, mm: f64) -> f64 {
        self.at_step((mm * self.steps_per_mm + 1e-6).floor())
            .unwrap_or(mm)
    }

    /// Step `k` in mm, with the fewest decimals that give it to a millionth of a step;
    /// `None` if it is not a finite number.
    fn at_step(&self, k: f64) -> Option<f64> {
        let exact = k / self.steps_per_mm;
        if !exact.is_finite() {
            return None;
        }
        let short = (0..=9)
            .map(|d| decimals(exact, d))
            .find(|v| (v * self.steps_per_mm - k).abs() <= 1e-6);
        Some(short.unwrap_or(exact))
    }

    /// True if `mm` is a whole number of steps (to a millionth of a step).
    pub fn is_whole(&self, mm: f64) -> bool {
        let s = mm * self.steps_per_mm;
        (s - s.round()).abs() <= 1e-6
    }
}

/// Serializes a figure of a report to 6 decimals (1 µs, 1 nm, 1e-6 %): sums over a
/// simulation carry floating-point noise in their last digits.
pub fn six<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_f64(decimals(*v, 6))
}

/// [`six`] for an optional figure.
pub fn six_opt<S: serde::Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
    match v {
        Some(v) => six(v, s),
        None => s.serialize_none(),
    }
}

/// [`six`] for a pair of figures.
pub fn six_pair<S: serde::Serializer>(v: &[f64; 2], s: S) -> Result<S::Ok, S::Error> {
    serde::Serialize::serialize(&[decimals(v[0], 6), decimals(v[1], 6)], s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Significant digits of the shortest text that gives `x` back.
    fn digits(x: f64) -> usize {
        let s = format!("{:e}", x.abs());
        let mantissa = s.split('e').next().unwrap();
        mantissa.chars().filter(|c| c.is_ascii_digit()).count()
    }

    #[test]
    fn decimals_print_short() {
        let mut x = 0.0;
        for i in 1..=1000 {
            x += 0.05;
            let r = decimals(x, 3);
            assert!((r - i as f64 * 0.05).abs() < 1e-9);
            assert!(format!("{r}").len() <= 8, "{r}");
        }
        assert_eq!(decimals(-0.0001, 3).to_bits(), 0.0f64.to_bits());
        assert!(decimals(f64::NAN, 3).is_nan());
        assert_eq!(decimals(1e300, 3), 1e300);
    }

    #[test]
    fn significant_digits() {
        for &x in &[
            624.9904531591078,
            15.624761328977556,
            3.2418008582492144e-6,
            156.58719083200953,
            1.2e-30,
            7.77e25,
            -0.33333333333333,
        ] {
            let r = significant(x, 6);
            assert!(digits(r) <= 6, "{x} -> {r}");
            assert!(((r - x) / x).abs() <= 5e-6, "{x} -> {r}");
        }
        assert_eq!(significant(0.0, 6), 0.0);
        assert_eq!(significant(999999.7, 6), 1e6);
    }

    #[test]
    fn lower_bounds_round_down() {
        assert_eq!(plane_mm_down(9.994645874763657), 9.994);
        assert_eq!(plane_mm_down(12.499999999999), 12.5);
        assert_eq!(plane_mm_down(12.5), 12.5);
        assert_eq!(plane_mm_down(0.0), 0.0);
        assert_eq!(area_mm2(103.1494140625), 103.149414);
    }

    #[test]
    fn times_keep_their_precision() {
        assert_eq!(time_s(8.0), 8.0);
        assert_eq!(time_s(37858.50000000009), 37858.5);
        assert_eq!(time_s(0.0004), 0.0004);
        assert!(time_s(1e-9) > 0.0);
        for t in [0.01, 0.05, 0.0999, 0.1, 0.1004, 1.0, 12.3456] {
            assert!((time_s(t) - t).abs() <= 0.005 * t, "{t}");
        }
    }

    #[test]
    fn positions_are_whole_steps_with_few_decimals() {
        let g = StageGrid::new(800.0);
        for i in 0..20_000 {
            let x = (i + 1) as f64 * 0.05 + 5.0;
            let p = g.position(x);
            assert!(g.is_whole(p), "{x} -> {p}");
            assert!((p - x).abs() <= 0.5 / 800.0 + 1e-12);
            assert!(format!("{p}").len() <= 12, "{p}");
            // The executor's quantization gives the same value.
            assert_eq!((p * 800.0).round() / 800.0, p);
        }
        let g = StageGrid::new(3.0);
        let p = g.position(0.3);
        assert_eq!(g.steps(p), 1.0);
        assert!((p - 1.0 / 3.0).abs() < 1e-6 && digits(p) <= 9, "{p}");
        assert_eq!(g.position_at_most(0.5), 0.3333333);
        let g = StageGrid::new(800.0);
        assert_eq!(g.position_at_most(7.0004), 7.0);
        assert_eq!(g.position_at_most(7.0), 7.0);
        let fine = StageGrid::new(1e7);
        assert_eq!(fine.position(0.123456789), 0.1234568);
    }
}
