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

/// The layers `a` to `b`: "layers 3–7", or "layer 3" when they are one.
///
/// ```
/// assert_eq!(dmdsl::text::layer_range(3, 7), "layers 3–7");
/// assert_eq!(dmdsl::text::layer_range(3, 3), "layer 3");
/// ```
pub fn layer_range(a: u64, b: u64) -> String {
    match a == b {
        true => format!("layer {a}"),
        false => format!("layers {a}–{b}"),
    }
}

/// The first `shown` of `items` joined by "; ", then how many more of the `total` there
/// are, in `one` / `many`: "layer 1 at …; layer 4 at …; 2 more layers".
///
/// ```
/// use dmdsl::text::first_of;
/// let items = ["a", "b", "c", "d"].map(String::from);
/// assert_eq!(first_of(items.clone(), (3, 4), ("layer", "layers")), "a; b; c; 1 more layer");
/// assert_eq!(first_of(items.clone(), (2, 9), ("layer", "layers")), "a; b; 7 more layers");
/// assert_eq!(first_of(items, (5, 4), ("layer", "layers")), "a; b; c; d");
/// ```
pub fn first_of(
    items: impl IntoIterator<Item = String>,
    (shown, total): (usize, usize),
    (one, many): (&str, &str),
) -> String {
    let mut at: Vec<String> = items.into_iter().take(shown).collect();
    if total > shown {
        let more = (total - shown) as u64;
        at.push(format!("{more} more {}", plural(more, one, many)));
    }
    at.join("; ")
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
