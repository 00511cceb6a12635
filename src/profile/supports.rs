//! The `[supports]` section: where support points go, the shape of heads, pillars and
//! the pad, and the part's elevation (docs/SUPPORTS.md). Off in the built-in profiles;
//! `slice --supports` turns it on.

use serde::{Deserialize, Serialize};

/// Support generation settings. The defaults are PrusaSlicer's SLA defaults where it has
/// the same setting (head front diameter 0.4 mm, head width 1 mm, pillar 1 mm, elevation
/// 5 mm, pad 1 mm), but for the penetration: 0 (docs/SUPPORTS.md says why).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Supports {
    /// Generate supports (`slice --supports` sets it).
    pub enabled: bool,
    /// Diameter of a head where it touches the part, mm.
    pub head_front_diameter_mm: f64,
    /// How far a head reaches into the part (and a foot into the layer it stands on, at
    /// most ¾ of it), mm.
    pub head_penetration_mm: f64,
    /// Length of a head's cone from the contact to the pillar's diameter, mm.
    pub head_length_mm: f64,
    /// Diameter of a pillar up to `pillar_max_length_mm`, mm.
    pub pillar_diameter_mm: f64,
    /// Longest pillar of `pillar_diameter_mm`; a longer one is thickened by the square root
    /// of its length over this (Euler buckling at the same load), mm.
    pub pillar_max_length_mm: f64,
    /// Diameter of the cone a pillar stands on where it meets the pad, mm.
    pub base_diameter_mm: f64,
    /// Height of that cone, mm.
    pub base_height_mm: f64,
    /// A surface facing down at less than this angle from the horizontal needs supports
    /// (its self-supporting distance per layer is the layer height / tan(angle)), degrees.
    pub critical_angle_deg: f64,
    /// Spacing of the points under a surface that faces down: one per `spacing_mm` ×
    /// `spacing_mm`, every point of the surface within `spacing_mm` / √2 of one, mm.
    pub spacing_mm: f64,
    /// Gap between the pad's top and the part's lowest point, mm; 0 puts the part on the
    /// pad.
    pub elevation_mm: f64,
    /// Thickness of the pad under the pillars, mm.
    pub pad_thickness_mm: f64,
    /// How far the pad's top reaches beyond the pillars' bases (and the part on it), mm.
    pub pad_margin_mm: f64,
    /// Slope of the pad's edge from the horizontal (90: vertical), degrees.
    pub pad_wall_slope_deg: f64,
}

impl Default for Supports {
    fn default() -> Self {
        Supports {
            enabled: false,
            head_front_diameter_mm: 0.4,
            head_penetration_mm: 0.0,
            head_length_mm: 1.0,
            pillar_diameter_mm: 1.0,
            pillar_max_length_mm: 15.0,
            base_diameter_mm: 3.0,
            base_height_mm: 1.0,
            critical_angle_deg: 45.0,
            spacing_mm: 3.0,
            elevation_mm: 5.0,
            pad_thickness_mm: 1.0,
            pad_margin_mm: 1.0,
            pad_wall_slope_deg: 45.0,
        }
    }
}

impl Supports {
    /// Checks every value's range; the message names the key.
    pub fn validate(&self) -> std::result::Result<(), String> {
        let ranges: [(&str, f64, f64, f64); 13] = [
            (
                "head_front_diameter_mm",
                self.head_front_diameter_mm,
                0.01,
                10.0,
            ),
            ("head_penetration_mm", self.head_penetration_mm, 0.0, 5.0),
            ("head_length_mm", self.head_length_mm, 0.05, 20.0),
            ("pillar_diameter_mm", self.pillar_diameter_mm, 0.05, 20.0),
            (
                "pillar_max_length_mm",
                self.pillar_max_length_mm,
                1.0,
                1000.0,
            ),
            ("base_diameter_mm", self.base_diameter_mm, 0.05, 50.0),
            ("base_height_mm", self.base_height_mm, 0.0, 20.0),
            ("critical_angle_deg", self.critical_angle_deg, 1.0, 89.0),
            ("spacing_mm", self.spacing_mm, 0.2, 100.0),
            ("elevation_mm", self.elevation_mm, 0.0, 100.0),
            ("pad_thickness_mm", self.pad_thickness_mm, 0.05, 20.0),
            ("pad_margin_mm", self.pad_margin_mm, 0.0, 50.0),
            ("pad_wall_slope_deg", self.pad_wall_slope_deg, 10.0, 90.0),
        ];
        for (key, v, lo, hi) in ranges {
            if !(lo..=hi).contains(&v) {
                return Err(format!(
                    "supports.{key} = {v:?} is outside {}..{}",
                    crate::text::number(lo),
                    crate::text::number(hi)
                ));
            }
        }
        if self.head_front_diameter_mm > self.pillar_diameter_mm {
            return Err(format!(
                "supports.head_front_diameter_mm = {:?} is wider than supports.pillar_diameter_mm = {:?}",
                self.head_front_diameter_mm, self.pillar_diameter_mm
            ));
        }
        if self.base_diameter_mm < self.pillar_diameter_mm {
            return Err(format!(
                "supports.base_diameter_mm = {:?} is narrower than supports.pillar_diameter_mm = {:?}",
                self.base_diameter_mm, self.pillar_diameter_mm
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_each_range_names_its_key() {
        Supports::default().validate().unwrap();
        let s = Supports {
            spacing_mm: 0.0,
            ..Supports::default()
        };
        assert_eq!(
            s.validate().unwrap_err(),
            "supports.spacing_mm = 0.0 is outside 0.2..100"
        );
        let s = Supports {
            head_front_diameter_mm: 2.0,
            ..Supports::default()
        };
        assert!(s
            .validate()
            .unwrap_err()
            .contains("wider than supports.pillar_diameter_mm"));
        let s = Supports {
            elevation_mm: f64::NAN,
            ..Supports::default()
        };
        assert!(s
            .validate()
            .unwrap_err()
            .starts_with("supports.elevation_mm = NaN"));
    }
}
