//! What `dmdsl run` finds wrong with a job: a [`Violation`] of a [`Kind`].
//!
//! Every kind has a stable name (what `--json` writes, e.g. `mask-checksum`) and a meaning;
//! [`Kind::ALL`] lists them in the order of the table in `docs/EXECUTOR.md` and of the
//! schema's enum (`docs/schemas/run-report.schema.json`), both checked against it by the
//! tests.

use super::sim::FaultKind;
use serde::Serialize;
use std::fmt;

/// One thing wrong with a job: a verification problem, a broken invariant or a fault.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Violation {
    /// Layer concerned (`None`: the whole job).
    pub layer: Option<usize>,
    /// Simulated time, s (for verification problems: when the layer starts).
    #[serde(serialize_with = "crate::round::six_opt")]
    pub time_s: Option<f64>,
    /// What is wrong, written as its name.
    pub kind: Kind,
    /// One line for people; names the file for mask problems.
    pub message: String,
    /// File concerned, relative to the bundle.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
}

/// The kinds: variant, name, meaning (the docs' table row). Each variant's doc is its
/// meaning.
macro_rules! kinds {
    ($($variant:ident $name:literal $meaning:literal,)*) => {
        /// What kind of thing is wrong with a job.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum Kind {
            $(#[doc = $meaning] $variant,)*
        }

        impl Kind {
            /// Every kind, in the order of the docs' table.
            pub const ALL: &'static [Kind] = &[$(Kind::$variant,)*];

            /// The stable name, as `--json` writes it.
            pub fn name(self) -> &'static str {
                match self {
                    $(Kind::$variant => $name,)*
                }
            }

            /// What it means, in one line.
            pub fn meaning(self) -> &'static str {
                match self {
                    $(Kind::$variant => $meaning,)*
                }
            }
        }
    };
}

kinds! {
    Manifest "manifest" "the structure of `job.json`: no layers, `totals.layers` not the number of records, an `index` out of order, not one mask per projector, a mask path outside the bundle (see Verify)",
    MaskMissing "mask-missing" "a mask file is missing or cannot be read",
    MaskChecksum "mask-checksum" "a mask file's SHA-256 differs from the manifest's",
    MaskDecode "mask-decode" "a mask file is not a PNG, its pixel data do not decode to the end, or its header declares more pixels than its bytes can hold",
    MaskFormat "mask-format" "a mask is not 8-bit grayscale of its projector's `width_px × height_px`",
    MaskContent "mask-content" "a layer's masks light pixels outside its section's box, any pixel for a layer without a section, or too few for its area (see \"Mask content\")",
    MaskShared "mask-shared" "a mask file named by two layer records (or two projectors of one layer)",
    MaskPixels "mask-pixels" "a mask's lit pixel count, lit box in the field, sum of grays or Adler-32 of its rows differs from its record (`masks[].pixels`, version 4): the mask was changed, or its projector's `offset_px` or mirroring",
    Settings "settings" "the settings disagree with the layers: `settings.layer_height_mm` with a layer's `thickness_mm`, `machine.exposure.layer_s` with the normal layers' exposure, `settings.compensation` with the light compensation records (native jobs)",
    OpticsFile "optics-file" "a gray map of the light compensation: missing, SHA-256 mismatch, not a PNG, not 8-bit gray of its projector's size, truncated, or a path outside the bundle",
    UnsupportedRegion "unsupported-region" "a job compiled with supports (`supports` in its manifest) has a region of a layer's lit pixels (on a corrected job: of what cures), as large as a support head's contact or larger, that rests on nothing in the layer below: it would print onto nothing (see \"Printability\")",
    Hardware "hardware" "an exposure asks what the printer's hardware description (`--machine hardware_config.json`) lacks: a light engine, a wavelength, a grayscale-correction image, the image's size, an XY stage for an image offset, a vacuum controller, the schema version (see \"Checking against the real machine\")",
    InvalidStep "invalid-step" "a step no machine can execute (speed or acceleration ≤ 0, negative wait or exposure); skipped",
    LightDuringMove "light-during-move" "light on in a segment that is not an `expose`/`sweep`, or while the stage moves in a layer whose `mode` is `layered`",
    Travel "travel" "a move or sweep starts or ends outside `[travel_min_mm, travel_max_mm]` (motion is monotonic, so the end points bound it)",
    Speed "speed" "a move's or sweep's commanded speed exceeds `max_speed_mm_s` (even if a short move would not reach it)",
    Accel "accel" "a move's commanded acceleration exceeds `max_accel_mm_s2`",
    Position "position" "an `expose` happens with the stage farther than half a step from the layer's `z_mm`; a layer's last `sweep` does not end at `z_mm`; or `z_mm` ≠ previous `z_mm` + `thickness_mm` (layer 0: its thickness) within 1e-6 mm",
    Dose "dose" "light time received ≠ `exposure_s` beyond 1e-6 relative (plus, for sweeps, the time of the sub-step rounding of their length)",
    Mask "mask" "light on before the layer's own mask is on the DMD",
    Estimate "estimate" "a layer's simulated time differs from its `time_s`, or the job's from `totals.print_time_s`, by more than 1 % (plus the time effect of step quantization, computed exactly against an unquantized shadow position)",
    Stall "stall" "injected fault: the stage stalled (also in `fault`)",
    Limit "limit" "injected fault: a limit switch tripped (also in `fault`)",
    ShutterStuck "shutter-stuck" "injected fault: the shutter stuck open (also in `fault`)",
    MaskLoad "mask-load" "injected fault: the DMD failed to load a mask (also in `fault`)",
}

impl From<FaultKind> for Kind {
    fn from(f: FaultKind) -> Kind {
        match f {
            FaultKind::Stall => Kind::Stall,
            FaultKind::Limit => Kind::Limit,
            FaultKind::ShutterStuck => Kind::ShutterStuck,
            FaultKind::MaskLoad => Kind::MaskLoad,
        }
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for Kind {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_kebab_case_and_serialized() {
        let mut seen = std::collections::HashSet::new();
        for k in Kind::ALL {
            assert!(seen.insert(k.name()), "{k} twice");
            let kebab = k.name().chars().all(|c| c.is_ascii_lowercase() || c == '-');
            assert!(kebab, "{k}");
            assert!(!k.meaning().is_empty() && !k.meaning().contains('|'), "{k}");
            assert_eq!(serde_json::to_value(k).unwrap(), k.name());
        }
    }
}
