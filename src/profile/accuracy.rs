//! The `[accuracy]` section: the dimensional correction a measured test part gives
//! (`dmdsl calibrate accuracy -o acc.toml`, applied with `slice --accuracy acc.toml` or
//! typed in; docs/CALIBRATION.md "Dimensions"), like PrusaSlicer's printer scaling and
//! absolute correction. Absent: no correction.

use serde::{Deserialize, Serialize};

/// The dimensional correction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Accuracy {
    /// Factors along the machine's X, Y and Z applied to the placed part (after `--scale`
    /// and `--rotate`, before it is put on the field): the inverse of the scale the machine
    /// prints at.
    #[serde(default = "unit_scale")]
    pub scale: [f64; 3],
    /// Every section of the part offset along its outward normals by this, mm (negative:
    /// inward): minus half the growth of an outer size the machine prints.
    #[serde(default)]
    pub xy_offset_mm: f64,
    /// The measurement sheet the values were fitted to (`dmdsl calibrate accuracy`: its
    /// name and SHA-256); without it they are typed in.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
}

/// No scale.
fn unit_scale() -> [f64; 3] {
    [1.0; 3]
}

/// The largest change of size a scale factor may make (1 ± this).
const SCALE_RANGE: f64 = 0.2;
/// The largest offset, mm.
const OFFSET_MAX_MM: f64 = 1.0;

impl Default for Accuracy {
    fn default() -> Self {
        Accuracy {
            scale: unit_scale(),
            xy_offset_mm: 0.0,
            source: None,
        }
    }
}

impl Accuracy {
    /// True when nothing is corrected.
    pub fn is_identity(&self) -> bool {
        self.scale == [1.0; 3] && self.xy_offset_mm == 0.0
    }

    /// Checks the values: factors within 1 ± 0.2, the offset within ±1 mm (a correction
    /// larger than that is a measuring mistake).
    pub fn validate(&self) -> std::result::Result<(), String> {
        for (axis, f) in ["X", "Y", "Z"].iter().zip(self.scale) {
            if !(f.is_finite() && (f - 1.0).abs() <= SCALE_RANGE) {
                return Err(format!(
                    "accuracy.scale's {axis} factor {f:?} is outside {}..{}",
                    1.0 - SCALE_RANGE,
                    1.0 + SCALE_RANGE
                ));
            }
        }
        let d = self.xy_offset_mm;
        if !(d.is_finite() && d.abs() <= OFFSET_MAX_MM) {
            return Err(format!(
                "accuracy.xy_offset_mm = {d:?} is outside -{OFFSET_MAX_MM}..{OFFSET_MAX_MM}"
            ));
        }
        Ok(())
    }
}
