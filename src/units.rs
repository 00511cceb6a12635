//! Newtypes for physical quantities that must be finite and strictly positive.
//!
//! A deserialized quantity is finite and in its range, so code that holds one never checks
//! it again.

use serde::{Deserialize, Serialize};
use std::fmt;

/// A finite, strictly positive `f64` (a length, a speed, a time that cannot be zero).
///
/// Deserializing a zero, negative, NaN or infinite value fails with a clear message,
/// so a profile can never carry a layer height of 0 or a NaN speed.
///
/// ```
/// use dmdsl::units::Positive;
/// assert_eq!(Positive::new(0.05).map(Positive::get), Some(0.05));
/// assert!(Positive::new(0.0).is_none());
/// assert!(Positive::new(f64::NAN).is_none());
/// ```
#[derive(Clone, Copy, PartialEq, PartialOrd, Serialize, Deserialize)]
#[serde(try_from = "f64", into = "f64")]
pub struct Positive(f64);

/// A finite, non-negative `f64` (a wait, a latency, an overcure that may be zero).
#[derive(Clone, Copy, PartialEq, PartialOrd, Default, Serialize, Deserialize)]
#[serde(try_from = "f64", into = "f64")]
pub struct NonNegative(f64);

/// The methods and conversions of the checked newtype `$t`: `v` is kept when it is finite
/// and `$ok(v)` (in words, `$rule`); `Debug` and `Display` show the bare number.
macro_rules! checked_f64 {
    ($t:ident, $ok:expr, $rule:literal) => {
        impl $t {
            #[doc = concat!("Wraps `v` if it is finite and ", $rule, ".")]
            pub fn new(v: f64) -> Option<Self> {
                let ok: fn(f64) -> bool = $ok;
                (v.is_finite() && ok(v)).then_some($t(v))
            }

            /// The wrapped value.
            #[inline]
            pub fn get(self) -> f64 {
                self.0
            }
        }

        impl TryFrom<f64> for $t {
            type Error = String;
            fn try_from(v: f64) -> Result<Self, String> {
                let msg = || format!(concat!("must be a finite number ", $rule, ", got {}"), v);
                $t::new(v).ok_or_else(msg)
            }
        }

        impl From<$t> for f64 {
            fn from(p: $t) -> f64 {
                p.0
            }
        }

        impl fmt::Debug for $t {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                fmt::Debug::fmt(&self.0, f)
            }
        }

        impl fmt::Display for $t {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                fmt::Display::fmt(&self.0, f)
            }
        }
    };
}

checked_f64!(Positive, |v| v > 0.0, "> 0");
checked_f64!(NonNegative, |v| v >= 0.0, ">= 0");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positive_rejects_zero_nan_inf_negative() {
        assert!(Positive::new(0.0).is_none());
        assert!(Positive::new(-1.0).is_none());
        assert!(Positive::new(f64::NAN).is_none());
        assert!(Positive::new(f64::INFINITY).is_none());
        assert_eq!(Positive::new(0.05).unwrap().get(), 0.05);
        assert!(NonNegative::new(0.0).is_some());
        assert!(NonNegative::new(-0.1).is_none());
    }
}
