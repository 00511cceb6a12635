//! What cures, not only what is drawn (docs/CURE.md): one cure model and one engine,
//! below both the slicer (`job`, which corrects its masks with it and predicts their cure)
//! and the executor (`exec`, whose `run --cure` evaluates a bundle's masks with it).
//!
//! * The model: the Gaussian point-spread function (`psf.rs`), the dose convention,
//!   Beer–Lambert in depth and Jacobs' working curve (`model.rs`).
//! * The engine: every layer's relative irradiance blurred (`kernel.rs`) and summed from
//!   the top layer down with each layer's dose (`engine.rs`, driven by `check.rs`), its
//!   islands (`islands.rs`, also the planner's counter), the job's figures (`report.rs`).
//! * Against the exact sections (the slicer's): a section's edges with a grid index
//!   (`segments.rs`), the cured edge along their normals (`predict.rs`), each drawn
//!   edge's move from the layer's dose and the layers above (`shift.rs`), the XY
//!   correction of the coverage (`correct.rs`), narrow features drawn back and wider
//!   until they cure (`widen.rs`), the flat features the Z correction drops
//!   (`held_back.rs`), pictures (`plots.rs`); the cured width of a straight line or
//!   gap (`width.rs`, what `dmdsl calibrate psf` fits σ with).
//!
//! Like every algorithm stage it takes inputs and returns values; `job` and `exec` read
//! and record them.

pub mod check;
pub mod correct;
pub mod engine;
pub mod held_back;
pub mod islands;
pub mod kernel;
pub mod loose;
pub mod model;
pub mod plots;
pub mod predict;
pub mod psf;
pub mod report;
pub mod segments;
pub mod shift;
pub mod widen;
pub mod width;

/// ⌊x⌋ of a non-negative `x` as an index (`x as usize` below 2⁶³, in fewer instructions:
/// x86-64 converts floats to signed integers), 0 for NaN; the hot loops' conversion.
#[inline(always)]
pub(crate) fn floor_index(x: f64) -> usize {
    x as i64 as usize
}

/// `i as f64` for an index below 2⁶³, through `i64` (one instruction on x86-64; from
/// usize, a longer sequence); the hot loops' conversion.
#[inline(always)]
pub(crate) fn index_f64(i: usize) -> f64 {
    i as i64 as f64
}

/// Asks the CPU to bring the cache line holding `data[i]` (none past the end) in ahead of
/// its use: the loops that read scattered pixels of large boxes (the band of edge pixels
/// the correction moves, the samples along edge normals) otherwise wait on memory for most
/// of their time. A hint only: it changes no value.
#[inline(always)]
pub(crate) fn prefetch(data: &[u8], i: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(b) = data.get(i) {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        // SAFETY: a prefetch has no architectural effect, and the address is an element
        // of `data`.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(std::ptr::from_ref(b).cast()) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (data, i);
}

/// `x.round().clamp(0.0, 255.0) as u8`, without the libm call `f64::round` is on the
/// baseline x86-64 target: truncation through `i64` (saturating) and the exact fractional
/// part against one half (half away from zero, as `round`; a negative value clamps to 0
/// either way, NaN gives 0 as `as u8` does).
#[inline(always)]
pub(crate) fn round_to_u8(x: f64) -> u8 {
    let t = x as i64;
    let up = (x - t as f64 >= 0.5) as i64;
    t.saturating_add(up).clamp(0, 255) as u8
}

pub use check::run_layers;
pub use correct::{correct_coverage, edge_shift_px};
pub use engine::Engine;
pub use kernel::Irradiance;
#[cfg(test)]
pub(crate) use model::test_model;
pub use model::CureModel;
pub use predict::LayerCure;
pub use psf::Psf;
pub use report::{summarize, CureCheck};

use serde::{Deserialize, Serialize};

/// The correction a job applies to its masks (`slice --cure-correction`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Correction {
    /// Masks are the exact sections.
    Off,
    /// Edges moved so the cured edge at mid-layer lands on the section's.
    Xy,
    /// XY, and the first layers of downward-facing surfaces held back by the
    /// print-through.
    Xyz,
}

impl Correction {
    /// The mode as the command line and the manifest write it.
    pub fn as_str(self) -> &'static str {
        match self {
            Correction::Off => "off",
            Correction::Xy => "xy",
            Correction::Xyz => "xyz",
        }
    }
}

#[cfg(test)]
mod tests {
    /// `round_to_u8` is `round().clamp(0, 255) as u8` on halves, ±0, NaN, ±∞, values past
    /// 2⁶³ and fixed-seed values (any bit pattern, and the range the correction meets).
    #[test]
    fn round_to_u8_is_round_then_clamp() {
        let mut vals = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            0.49999999999999994,
            1.5,
            2.5,
            254.5,
            255.49999999999997,
            255.5,
            -0.7,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            2f64.powi(63),
            2f64.powi(53) + 1.0,
        ];
        let mut s = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..100_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            vals.push(f64::from_bits(s));
            vals.push((s % 1_000_000) as f64 / 1000.0 - 300.0);
            vals.push((s % 2048) as f64 * 0.25 - 256.0);
        }
        for x in vals {
            assert_eq!(
                super::round_to_u8(x),
                x.round().clamp(0.0, 255.0) as u8,
                "{x}"
            );
        }
    }

    /// `floor_index` is `as usize` for every non-negative value below 2⁶³ (whole, halves,
    /// just below a whole, large), and 0 for NaN; `index_f64` is `as f64`.
    #[test]
    fn floor_index_and_index_f64_are_the_usize_conversions() {
        let values = [
            0.0,
            0.3,
            1.0,
            1.0 - 1e-16,
            2.5,
            767.999_999,
            3e9,
            2f64.powi(53) + 2.0,
        ];
        for x in values.into_iter().chain((0..1000).map(|k| k as f64 * 0.37)) {
            assert_eq!(super::floor_index(x), x as usize, "{x}");
            assert_eq!(super::index_f64(x as usize), x as usize as f64, "{x}");
        }
        assert_eq!(super::floor_index(f64::NAN), 0);
    }
}
