//! The `[distortion]` section of a profile: the measured lens correction table a job
//! pre-warps its sections with (fitted by `geometry::distortion`, docs/GEOMETRY.md).

use serde::{Deserialize, Serialize};

/// The `[distortion]` section of a profile: a table file (relative to the profile file) or
/// inline points `[x_mm, y_mm, seen_x_mm, seen_y_mm]`. Exactly one of the two.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DistortionConfig {
    /// CSV table, relative to the profile file's directory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<String>,
    /// Inline measured points `[x_mm, y_mm, seen_x_mm, seen_y_mm]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<Vec<[f64; 4]>>,
}

impl DistortionConfig {
    /// Checks that exactly one source is given and inline numbers are finite.
    pub fn validate(&self) -> std::result::Result<(), String> {
        match (&self.table, &self.points) {
            (Some(_), Some(_)) => Err("[distortion]: give `table` or `points`, not both".into()),
            (None, None) => Err("[distortion]: needs `table` or `points`".into()),
            (Some(t), None) if t.trim().is_empty() => Err("[distortion].table is empty".into()),
            (None, Some(p)) => {
                for (i, r) in p.iter().enumerate() {
                    if r.iter().any(|v| !v.is_finite()) {
                        return Err(format!("[distortion].points[{i}]: numbers must be finite"));
                    }
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }
}
