//! How counts, durations and numbers read in the lines dmdsl prints for people (messages,
//! errors, summaries): one rule each, so every line writes them alike.
//!
//! A number in a message never shows floating-point noise (13.333333333333334) nor hundreds
//! of digits (a tampered bundle's 1e300): [`number`] writes a value to 6 significant digits,
//! [`fixed`] and [`signed`] to a given number of decimals, both in scientific notation
//! where plain digits would run long.

/// `one` when `n` is 1, else `many` ("1 layer", "3 layers").
pub fn plural<'a>(n: u64, one: &'a str, many: &'a str) -> &'a str {
    if n == 1 {
        one
    } else {
        many
    }
}

/// `n` and the noun that goes with it: "1 layer", "2 layers".
pub fn count(n: u64, one: &str, many: &str) -> String {
    format!("{n} {}", plural(n, one, many))
}

/// A duration in seconds as hours, minutes and seconds, rounded to the second:
/// "1h02m03s" (negative durations as 0).
pub fn hms(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    format!("{}h{:02}m{:02}s", s / 3600, s / 60 % 60, s % 60)
}

/// A number for a message: 6 significant digits, written with as few as give them (`25`,
/// `0.9`, `13.3333`, `5.00125`), in scientific notation below 1e-4 and from 1e9 on
/// (`1e300`, `1.5e-7`); `-0` is `0`.
///
/// ```
/// assert_eq!(dmdsl::text::number(10.0), "10");
/// assert_eq!(dmdsl::text::number(40.0 / 3.0), "13.3333");
/// assert_eq!(dmdsl::text::number(0.1 + 0.2), "0.3");
/// assert_eq!(dmdsl::text::number(1e300), "1e300");
/// ```
pub fn number(v: f64) -> String {
    // `{:.5e}` rounds to 6 significant digits; read back, the value prints shortest.
    let r: f64 = format!("{v:.5e}").parse().unwrap_or(v);
    if r == 0.0 {
        "0".into()
    } else if (1e-4..1e9).contains(&r.abs()) {
        format!("{r}")
    } else {
        format!("{r:e}")
    }
}

/// `v` with `decimals` decimals (`0.9000`), in scientific notation from 1e9 on (never
/// hundreds of digits).
pub fn fixed(v: f64, decimals: usize) -> String {
    if v.is_finite() && v.abs() >= 1e9 {
        format!("{v:.4e}")
    } else {
        format!("{v:.decimals$}")
    }
}

/// [`fixed`] with its sign, `+` included: a change (`+2.04`, `-0.50`); a value that
/// rounds to zero is `0.00`, without a sign.
pub fn signed(v: f64, decimals: usize) -> String {
    if v.is_finite() && v.abs() >= 1e9 {
        format!("{v:+.4e}")
    } else {
        let s = format!("{v:+.decimals$}");
        match s[1..].bytes().all(|b| b == b'0' || b == b'.') {
            true => s[1..].to_string(),
            false => s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_durations() {
        assert_eq!(count(1, "layer", "layers"), "1 layer");
        assert_eq!(count(0, "layer", "layers"), "0 layers");
        assert_eq!(plural(2, "is", "are"), "are");
        assert_eq!(hms(0.4), "0h00m00s");
        assert_eq!(hms(-5.0), "0h00m00s");
        assert_eq!(hms(37858.4), "10h30m58s");
        assert_eq!(hms(3723.4), "1h02m03s");
    }

    #[test]
    fn numbers_are_short_and_free_of_noise() {
        for (v, want) in [
            (25.0, "25"),
            (0.9, "0.9"),
            (-0.0, "0"),
            (5.00125, "5.00125"),
            (0.00125, "0.00125"),
            (16.0 / 3.0, "5.33333"),
            (123456.789, "123457"),
            (999999.7, "1000000"),
            (1.23456789e-7, "1.23457e-7"),
            (-1e12, "-1e12"),
            (f64::INFINITY, "inf"),
        ] {
            assert_eq!(number(v), want, "{v}");
        }
        assert_eq!(fixed(500.0, 4), "500.0000");
        assert_eq!(fixed(-1e12, 3), "-1.0000e12");
        assert_eq!(fixed(1e300, 4), "1.0000e300");
        assert_eq!(signed(2.0444, 2), "+2.04");
        assert_eq!(signed(-0.001, 2), "0.00");
        assert_eq!(signed(0.004, 2), "0.00");
        assert_eq!(signed(-0.0, 0), "0");
        assert_eq!(signed(-0.006, 2), "-0.01");
        assert_eq!(signed(f64::INFINITY, 2), "+inf");
        assert_eq!(signed(2e300, 2), "+2.0000e300");
    }
}
