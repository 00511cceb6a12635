//! `slice --supports`: the placed part lifted by the pad and the elevation, its supports
//! generated (`crate::support`) and appended to its mesh, and their record.

use super::manifest::PlacedPart;
use crate::bundle::{self, SupportPad, SupportPoint};
use crate::error::{Error, Result};
use crate::profile::Profile;
use crate::round;
use crate::support::{self, Foot};
use crate::text::number;

/// Lifts `part` by whole layers, generates its supports (for a job whose cure correction
/// moves edges in: `corrected`) and appends them to its mesh, keeping the part's own mesh
/// report. Errors name the model: a lifted part beyond the stage's travel, a pad that does
/// not fit the field.
pub(super) fn add_supports(
    part: &mut PlacedPart,
    profile: &Profile,
    corrected: bool,
) -> Result<()> {
    let s = &profile.supports;
    let h = profile.slicing.layer_height_mm.get();
    let first = support::lift_layers(s, h);
    let lift = first as f64 * h;
    let error = |msg: String| Error::Job {
        path: part.path.into(),
        msg,
    };
    let top = part.mesh.bbox()[1][2] + lift;
    if top > profile.stage.travel_max_mm {
        return Err(error(format!(
            "with supports the part's top is at {} mm (lifted {} mm by the pad and the elevation), but the stage travels only to stage.travel_max_mm = {} mm",
            number(round::plane_mm(top)),
            number(round::plane_mm(lift)),
            number(profile.stage.travel_max_mm)
        )));
    }
    part.mesh.translate([0.0, 0.0, lift]);
    part.translate_mm[2] += lift;
    part.layers += first;
    if let Some((parts, _)) = part.plate.as_mut() {
        for p in parts {
            p.translate_mm[2] = round::plane_mm(p.translate_mm[2] + lift);
            for corner in &mut p.placed_bbox_mm {
                corner[2] = round::plane_mm(corner[2] + lift);
            }
        }
    }
    let field = profile.field();
    let g = support::generate(
        (&part.mesh, profile.accuracy.xy_offset_mm),
        field,
        (h, part.layers, first),
        (s, corrected),
    )
    .map_err(error)?;
    let plate = part.plate.as_ref().map(|p| &p.0[..]);
    let points = g
        .columns
        .iter()
        .map(|c| {
            let at = g.point_mm(c, &field);
            SupportPoint {
                at_mm: at.map(round::plane_mm),
                part: plate.and_then(|parts| super::plate::part_at(parts, [at[0], at[1]])),
                island: c.point.island,
                pillar_diameter_mm: round::plane_mm(c.pillar_diameter_mm),
                foot: match c.foot {
                    Foot::Pad => bundle::Foot::Pad,
                    Foot::Part(..) => bundle::Foot::Part,
                },
                foot_z_mm: round::plane_mm(c.foot_z(&g.shape)),
            }
        })
        .collect();
    part.supports = Some(bundle::Supports {
        head_front_diameter_mm: s.head_front_diameter_mm,
        head_penetration_mm: s.head_penetration_mm,
        head_length_mm: s.head_length_mm,
        lift_mm: round::plane_mm(lift),
        pad: SupportPad {
            thickness_mm: round::plane_mm(g.pad.thickness_mm),
            area_mm2: round::area_mm2(g.pad.top_area_mm2()),
            outline_mm: g.pad.top.iter().map(|p| p.map(round::plane_mm)).collect(),
        },
        points,
        volume_mm3: round::derived(g.mesh.report.volume_mm3),
    });
    let report = part.mesh.report.clone();
    part.support_edges = Some(part.mesh.edge_count as u32);
    part.mesh.append(&g.mesh);
    part.mesh.report = report;
    part.support_mesh = Some(g.mesh);
    Ok(())
}
