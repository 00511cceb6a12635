//! The supports a job was compiled with: every point with its head, pillar and foot, the
//! pad, the part's elevation and the structure's volume (docs/SUPPORTS.md).

use serde::{Deserialize, Serialize};

/// The supports of a job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Supports {
    /// Diameter of the heads where they touch the part, mm.
    pub head_front_diameter_mm: f64,
    /// How far the heads reach into the part, mm.
    pub head_penetration_mm: f64,
    /// Length of a head's cone, mm.
    pub head_length_mm: f64,
    /// How far the part was lifted (the pad's thickness and the elevation), mm.
    pub lift_mm: f64,
    /// The pad.
    pub pad: SupportPad,
    /// The points, bottom up.
    pub points: Vec<SupportPoint>,
    /// Volume of the structure (pad and supports, overlaps counted once per shell), mm³.
    pub volume_mm3: f64,
}

impl Supports {
    /// The area a support head touches, mm²: a disc of `head_front_diameter_mm`. A region
    /// of the masks this large or larger that rests on nothing below is an
    /// `unsupported-region` of `dmdsl run`; smaller ones are what the masks' edges leave
    /// (docs/EXECUTOR.md "Printability").
    pub fn head_contact_mm2(&self) -> f64 {
        std::f64::consts::PI * (self.head_front_diameter_mm / 2.0).powi(2)
    }
}

/// One support.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SupportPoint {
    /// Where its head touches the part: x, y on the build plane, z above it, mm.
    pub at_mm: [f64; 3],
    /// Whether it holds an island (else a surface facing down).
    pub island: bool,
    /// Its pillar's diameter, mm.
    pub pillar_diameter_mm: f64,
    /// What it stands on: `pad` or `part`.
    pub foot: Foot,
    /// Height of its foot, mm.
    pub foot_z_mm: f64,
    /// On a plate, which part it holds: an index into the source's `parts` (the part whose
    /// placed box holds the point, else the nearest).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part: Option<usize>,
}

/// What a support stands on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Foot {
    /// The pad.
    Pad,
    /// The part.
    Part,
}

/// The pad under the supports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SupportPad {
    /// Thickness, mm.
    pub thickness_mm: f64,
    /// Area of its top, mm².
    pub area_mm2: f64,
    /// Outline of its top on the build plane, counter-clockwise, mm.
    pub outline_mm: Vec<[f64; 2]>,
}
