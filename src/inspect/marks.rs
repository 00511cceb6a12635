//! What `--preview` marks over the part: the regions of the layers that rest on nothing
//! below, found from the masks as `dmdsl run` finds them ([`crate::bundle::regions`]),
//! each layer's largest as a ring (for a job with supports, of those as large as a head's
//! contact); and the supports the job was compiled with (the
//! manifest's `supports`): each pillar from its foot up to its head's tip.

use super::Bundle;
use crate::bundle::regions::{field_runs, unsupported_regions, Placement, Region, Run};
use crate::bundle::Supports;
use crate::error::Result;
use crate::picture::{read_mask, Projection};
use crate::plot::Canvas;
use rayon::prelude::*;

/// Colour of the rings around the regions resting on nothing below.
pub const REGION: [u8; 3] = [215, 25, 60];
/// Colour of the supports.
pub const SUPPORT: [u8; 3] = [240, 150, 0];
/// The smallest ring radius, px.
const RING_MIN_PX: f64 = 6.0;

/// A layer's largest region resting on nothing below: its layer, the build-volume point
/// of its centre at the layer's bottom (mm) and its radius as a disc of its area (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mark {
    /// The layer.
    pub layer: usize,
    /// x, y of its centre and the layer's bottom, mm.
    pub at_mm: [f64; 3],
    /// √(area / π), mm.
    pub radius_mm: f64,
}

/// Every region of `b`'s layers that rests on nothing below, with its layer: each layer's
/// masks read (in parallel) into lit runs on the field, then compared with the layer
/// below's. Errors: a mask that cannot be read.
pub fn regions(b: &Bundle) -> Result<Vec<(usize, Region)>> {
    let m = &b.manifest;
    let runs: Vec<Option<Vec<Run>>> = crate::error::in_order(m.layers.par_iter().map(|l| {
        let mut images = Vec::with_capacity(l.masks.len());
        for mask in &l.masks {
            let p = &m.machine.projector[mask.projector as usize];
            let img = read_mask(b.files.as_ref(), &mask.file)?;
            if img.dimensions() != (p.width_px, p.height_px) {
                // A mask not of its projector's size is not placed (the preview
                // refuses it too).
                return Ok(None);
            }
            images.push((img.into_raw(), Placement::of(p)));
        }
        let masks: Vec<(&[u8], Placement)> =
            images.iter().map(|(d, at)| (d.as_slice(), *at)).collect();
        Ok(Some(field_runs(&masks)))
    }))?;
    Ok(unsupported_regions(&runs))
}

/// The largest region of each layer that has some, as a [`Mark`]; for a job with
/// supports, of the regions as large as a support head's contact (those `dmdsl run`
/// holds against it; smaller ones are what the masks' edges leave).
pub fn largest_per_layer(b: &Bundle, regions: &[(usize, Region)]) -> Vec<Mark> {
    let field = b.manifest.machine.field();
    let p = field.pixel_mm;
    let least = b
        .manifest
        .supports
        .as_ref()
        .map_or(0.0, |s| s.head_contact_mm2());
    let mut out: Vec<(Mark, u64)> = Vec::new();
    for &(layer, g) in regions.iter().filter(|(_, g)| g.area_mm2(p) >= least) {
        let l = &b.manifest.layers[layer];
        let [x, y] = g.at_mm(field.height_px, p);
        let mark = Mark {
            layer,
            at_mm: [x, y, l.z_mm - l.thickness_mm],
            radius_mm: (g.area_mm2(p) / std::f64::consts::PI).sqrt(),
        };
        match out.last_mut() {
            Some((last, px)) if last.layer == layer => {
                if g.pixels > *px {
                    (*last, *px) = (mark, g.pixels);
                }
            }
            _ => out.push((mark, g.pixels)),
        }
    }
    out.into_iter().map(|(m, _)| m).collect()
}

/// Draws `marks` as rings and `supports` (each pillar from its foot to its head's tip,
/// and the tip) over the preview whose projection is `proj`, drawn at row `top` of `c`.
pub fn draw(
    c: &mut Canvas,
    proj: &Projection,
    top: f64,
    marks: &[Mark],
    supports: Option<&Supports>,
) {
    let at = |q: [f64; 3]| {
        let (x, y) = proj.pixel_of(q);
        (x as f32, (y + top) as f32)
    };
    if let Some(s) = supports {
        let width = (0.4 * proj.scale()).clamp(1.0, 3.0) as f32;
        for pt in &s.points {
            let [x, y, z] = pt.at_mm;
            c.polyline(&[at([x, y, pt.foot_z_mm]), at([x, y, z])], SUPPORT, width);
            let (hx, hy) = at([x, y, z]);
            c.dot(hx, hy, width + 1.0, SUPPORT);
        }
    }
    for m in marks {
        let (cx, cy) = at(m.at_mm);
        let r = (m.radius_mm * proj.scale()).max(RING_MIN_PX) + 3.0;
        let ring: Vec<(f32, f32)> = (0..=32)
            .map(|k| {
                let a = k as f64 / 32.0 * std::f64::consts::TAU;
                (cx + (r * a.cos()) as f32, cy + (r * a.sin()) as f32)
            })
            .collect();
        c.polyline(&ring, REGION, 2.0);
    }
}
