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

impl Positive {
    /// Wraps `v` if it is finite and > 0.
    pub fn new(v: f64) -> Option<Self> {
        (v.is_finite() && v > 0.0).then_some(Positive(v))
    }

    /// The wrapped value.
    #[inline]
    pub fn get(self) -> f64 {
        self.0
    }
}

impl TryFrom<f64> for Positive {
    type Error = String;
    fn try_from(v: f64) -> Result<Self, String> {
        Positive::new(v).ok_or_else(|| format!("must be a finite number > 0, got {v}"))
    }
}

impl From<Positive> for f64 {
    fn from(p: Positive) -> f64 {
        p.0
    }
}

impl fmt::Debug for Positive {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.0, f)
    }
}

impl fmt::Display for Positive {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}

/// A finite, non-negative `f64` (a wait, a latency, an overcure that may be zero).
#[derive(Clone, Copy, PartialEq, PartialOrd, Default, Serialize, Deserialize)]
#[serde(try_from = "f64", into = "f64")]
pub struct NonNegative(f64);

impl NonNegative {
    /// Wraps `v` if it is finite and >= 0.
    pub fn new(v: f64) -> Option<Self> {
        (v.is_finite() && v >= 0.0).then_some(NonNegative(v))
    }

    /// The wrapped value.
    #[inline]
    pub fn get(self) -> f64 {
        self.0
    }
}

impl TryFrom<f64> for NonNegative {
    type Error = String;
    fn try_from(v: f64) -> Result<Self, String> {
        NonNegative::new(v).ok_or_else(|| format!("must be a finite number >= 0, got {v}"))
    }
}

impl From<NonNegative> for f64 {
    fn from(p: NonNegative) -> f64 {
        p.0
    }
}

impl fmt::Debug for NonNegative {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.0, f)
    }
}

impl fmt::Display for NonNegative {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}

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
