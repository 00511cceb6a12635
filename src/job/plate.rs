//! Many parts on one build plate (`slice --plate`, `--copies`): each part read and turned
//! like a single part, repeated, laid out in rows on the field (inside the calibrated area
//! when they fit there) or kept where their files put them, and merged into one mesh that
//! the pipeline slices as one part.

use super::manifest::{file_name, PlacedPart};
use super::{place_mesh, read_model, PlacementMode, SliceOptions};
use crate::bundle::PlatePart;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::profile::Profile;
use crate::round;
use crate::text::number;
use rayon::prelude::*;
use std::path::PathBuf;

/// A plate: the parts after the job's input, and how they are laid out.
#[derive(Debug, Clone)]
pub struct Plate {
    /// The parts after [`SliceOptions::input`], in order.
    pub more: Vec<PathBuf>,
    /// Copies of each part, 1 to [`MAX_COPIES`].
    pub copies: usize,
    /// Gap between the arranged parts' XY boxes, mm (≥ 0).
    pub spacing_mm: f64,
}

/// The most copies of a part on one plate.
pub const MAX_COPIES: usize = 1000;

/// The default gap between arranged parts, mm.
pub const SPACING_MM: f64 = 3.0;

/// Tolerance of the fit and overlap checks, mm.
const EPS: f64 = 1e-9;

/// A box that does not fit the area: which one, along which axis, by how much.
#[derive(Debug, PartialEq)]
pub(super) struct Misfit {
    /// Index of the box.
    pub index: usize,
    /// 'X' or 'Y'.
    pub axis: char,
    /// How much more room the layout needs along `axis`, mm.
    pub missing_mm: f64,
}

/// Lower-left corners for boxes of `sizes` (XY, mm) laid in rows inside `area`
/// ([x0, y0, x1, y1] mm), `gap` apart: the tallest first, each row filled from the left
/// while it fits, rows stacked upwards, the whole block centred in the area.
pub(super) fn arrange(
    sizes: &[[f64; 2]],
    gap: f64,
    area: [f64; 4],
) -> std::result::Result<Vec<[f64; 2]>, Misfit> {
    let (w, h) = (area[2] - area[0], area[3] - area[1]);
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by(|&a, &b| sizes[b][1].total_cmp(&sizes[a][1]).then(a.cmp(&b)));
    let mut at = vec![[0.0; 2]; sizes.len()];
    // Each row: its boxes, its width and its height.
    let mut rows: Vec<(Vec<usize>, f64, f64)> = Vec::new();
    for &i in &order {
        let [sw, sh] = sizes[i];
        if sw > w + EPS {
            return Err(Misfit {
                index: i,
                axis: 'X',
                missing_mm: sw - w,
            });
        }
        match rows.last_mut() {
            Some((row, rw, rh)) if *rw + gap + sw <= w + EPS => {
                at[i][0] = *rw + gap;
                *rw += gap + sw;
                *rh = rh.max(sh);
                row.push(i);
            }
            _ => rows.push((vec![i], sw, sh)),
        }
    }
    let total_h = rows.iter().map(|r| r.2).sum::<f64>() + gap * rows.len().saturating_sub(1) as f64;
    if total_h > h + EPS {
        // The first row that reaches past the top.
        let mut y = 0.0;
        let over = rows.iter().find(|r| {
            y += r.2 + gap;
            y - gap > h + EPS
        });
        return Err(Misfit {
            index: over.map_or(order[0], |r| r.0[0]),
            axis: 'Y',
            missing_mm: total_h - h,
        });
    }
    let block_w = rows.iter().map(|r| r.1).fold(0.0, f64::max);
    let (ox, oy) = (area[0] + (w - block_w) / 2.0, area[1] + (h - total_h) / 2.0);
    let mut y = 0.0;
    for (row, _, rh) in rows {
        for i in row {
            at[i] = [ox + at[i][0], oy + y];
        }
        y += rh + gap;
    }
    Ok(at)
}

/// One part of the plate as read and turned: its file, hash, mesh and file-coordinate box.
struct Loaded {
    path: PathBuf,
    sha256: String,
    mesh: Mesh,
    bbox_in_file: [[f64; 3]; 2],
    /// Its box once turned, mm.
    bbox: [[f64; 3]; 2],
}

/// One copy of a part: which part, which copy, where it goes.
struct Instance {
    part: usize,
    copy: usize,
    translate: [f64; 3],
}

/// Reads every part of the plate (`first`: the job's input, already read), turns them by
/// the job's transform, lays out their copies and merges them into one mesh placed on the
/// field, with the number of layers it makes.
pub(super) fn place_plate<'a>(
    opts: &'a SliceOptions,
    plate: &Plate,
    profile: &Profile,
    first: (String, Mesh),
) -> Result<PlacedPart<'a>> {
    let rest: Vec<(String, Mesh)> =
        crate::error::in_order(plate.more.par_iter().map(|p| read_model(p, None)))?;
    let paths = std::iter::once(&opts.input).chain(&plate.more);
    let parts: Vec<Loaded> = paths
        .zip(std::iter::once(first).chain(rest))
        .map(|(path, (sha256, mut mesh))| {
            let bbox_in_file = mesh.bbox();
            opts.transform.apply(&mut mesh);
            mesh.scale_axes(profile.accuracy.scale);
            Loaded {
                path: path.clone(),
                sha256,
                bbox: mesh.bbox(),
                mesh,
                bbox_in_file,
            }
        })
        .collect();
    let instances = lay_out(&parts, plate, profile, opts.placement)?;
    let mut plate_mesh: Option<Mesh> = None;
    let mut records = Vec::with_capacity(instances.len());
    for inst in &instances {
        let part = &parts[inst.part];
        let mut copy = part.mesh.clone();
        copy.translate(inst.translate);
        match plate_mesh.as_mut() {
            None => plate_mesh = Some(copy),
            Some(m) => m.append(&copy),
        }
        records.push(record(part, inst, plate.copies));
    }
    let mut mesh = plate_mesh.expect("a plate has a part");
    // The tallest copy names the plate in the travel and layer-count checks.
    let tallest = records
        .iter()
        .zip(&instances)
        .max_by(|a, b| a.0.placed_bbox_mm[1][2].total_cmp(&b.0.placed_bbox_mm[1][2]))
        .map_or(&opts.input, |(_, i)| &parts[i.part].path);
    let h = profile.slicing.layer_height_mm.get();
    let (_, layers) = place_mesh(tallest, &mut mesh, profile, PlacementMode::Keep, h)?;
    let warnings = parts
        .iter()
        .flat_map(|p| {
            let name = file_name(&p.path);
            p.mesh.report.warnings().into_iter().map(move |mut w| {
                w.message = format!("{name}: {}", w.message);
                w
            })
        })
        .collect();
    Ok(PlacedPart {
        path: opts.input.as_path(),
        sha256: plate_sha256(&records),
        bbox_in_file: mesh.bbox(),
        mesh,
        transform: opts.transform,
        mode: PlacementMode::Keep,
        translate_mm: [0.0; 3],
        layers,
        plate: Some((records, warnings)),
        supports: None,
        support_edges: None,
        support_mesh: None,
    })
}

/// Where each copy of each part goes: laid out in rows ([`arrange`]) inside the
/// calibrated area when they fit there, else the field; or, with `Keep`, where the files
/// put them (one copy each, no two overlapping).
fn lay_out(
    parts: &[Loaded],
    plate: &Plate,
    profile: &Profile,
    mode: PlacementMode,
) -> Result<Vec<Instance>> {
    let boxes: Vec<[[f64; 3]; 2]> = parts.iter().map(|p| p.bbox).collect();
    let field = profile.field();
    let (fw, fh) = (field.width_mm(), field.height_mm());
    let usage = |m: String| Error::Usage(m);
    match mode {
        PlacementMode::At(_) => Err(usage(
            "--position places a single part; the parts of a plate are arranged on the field, or kept where their files put them with --keep-position".into(),
        )),
        PlacementMode::Keep if plate.copies > 1 => Err(usage(
            "--copies needs room to arrange the copies: it cannot be combined with --keep-position".into(),
        )),
        PlacementMode::Keep => {
            for (i, (p, b)) in parts.iter().zip(&boxes).enumerate() {
                super::placement::placement(&p.path, *b, fw, fh, PlacementMode::Keep)?;
                if let Some(j) = (0..i).find(|&j| overlap(&boxes[j], b)) {
                    return Err(Error::Job {
                        path: p.path.clone(),
                        msg: format!(
                            "with --keep-position its box overlaps that of {} on the build plane; move one of them in its file, or drop --keep-position to arrange them",
                            parts[j].path.display()
                        ),
                    });
                }
            }
            Ok((0..parts.len())
                .map(|part| Instance {
                    part,
                    copy: 1,
                    translate: [0.0; 3],
                })
                .collect())
        }
        PlacementMode::Center => {
            let n = parts.len() * plate.copies;
            let of = |k: usize| (k / plate.copies, k % plate.copies + 1);
            let sizes: Vec<[f64; 2]> = (0..n)
                .map(|k| {
                    let [lo, hi] = boxes[of(k).0];
                    [hi[0] - lo[0], hi[1] - lo[1]]
                })
                .collect();
            let calibrated = calibrated_area(profile);
            let corners = calibrated
                .and_then(|a| arrange(&sizes, plate.spacing_mm, a).ok())
                .map_or_else(|| arrange(&sizes, plate.spacing_mm, [0.0, 0.0, fw, fh]), Ok)
                .map_err(|m| misfit(m, parts, plate, fw, fh))?;
            Ok(corners
                .iter()
                .enumerate()
                .map(|(k, c)| {
                    let (part, copy) = of(k);
                    let lo = boxes[part][0];
                    Instance {
                        part,
                        copy,
                        translate: [c[0] - lo[0], c[1] - lo[1], -lo[2]],
                    }
                })
                .collect())
        }
    }
}

/// The error of a layout that does not fit the field.
fn misfit(m: Misfit, parts: &[Loaded], plate: &Plate, fw: f64, fh: f64) -> Error {
    let copies = plate.copies;
    let (part, copy) = (m.index / copies, m.index % copies + 1);
    let which = if copies > 1 {
        format!(" (copy {copy} of {copies})")
    } else {
        String::new()
    };
    Error::Job {
        path: parts[part].path.clone(),
        msg: format!(
            "the plate has no room for this part{which}: its {} parts, {} mm apart, need {} mm more in {} than the {} x {} mm field; use fewer copies, a smaller --spacing, or a second plate",
            parts.len() * copies,
            number(plate.spacing_mm),
            number(round::plane_mm(m.missing_mm)),
            m.axis,
            number(fw),
            number(fh),
        ),
    }
}

/// The calibrated area of a single projector's light field, where it has one.
fn calibrated_area(profile: &Profile) -> Option<[f64; 4]> {
    match &profile.projector[..] {
        [p] => p.calibration.as_ref().map(|c| c.field.area_mm),
        _ => None,
    }
}

/// True when two boxes' XY extents share more than an edge.
fn overlap(a: &[[f64; 3]; 2], b: &[[f64; 3]; 2]) -> bool {
    (0..2).all(|k| a[0][k] < b[1][k] - EPS && b[0][k] < a[1][k] - EPS)
}

/// The manifest's record of copy `inst` of `part`.
fn record(part: &Loaded, inst: &Instance, copies: usize) -> PlatePart {
    let [lo, hi] = part.bbox;
    let placed = [lo, hi].map(|c| [0, 1, 2].map(|k| round::plane_mm(c[k] + inst.translate[k])));
    PlatePart {
        file: file_name(&part.path),
        sha256: part.sha256.clone(),
        copy: inst.copy,
        copies,
        triangles: part.mesh.report.triangles_in_file,
        bbox_mm: part.bbox_in_file.map(|c| c.map(round::plane_mm)),
        translate_mm: inst.translate.map(round::plane_mm),
        placed_bbox_mm: placed,
    }
}

/// Which of a plate's `parts` the build-plane point `xy` (mm) concerns: the one whose
/// placed box holds it, else the one whose box is nearest (supports and widened features
/// reach a little beyond a part's box). `None` without parts.
pub(super) fn part_at(parts: &[PlatePart], xy: [f64; 2]) -> Option<usize> {
    let gap = |b: &[[f64; 3]; 2]| {
        let d = |k: usize| (b[0][k] - xy[k]).max(xy[k] - b[1][k]).max(0.0);
        d(0).hypot(d(1))
    };
    (0..parts.len())
        .min_by(|&a, &b| gap(&parts[a].placed_bbox_mm).total_cmp(&gap(&parts[b].placed_bbox_mm)))
}

/// A plate part as messages name it: its file, and which copy when there are several.
pub(super) fn part_name(p: &PlatePart) -> String {
    match p.copies {
        1 => p.file.clone(),
        n => format!("{} (copy {} of {n})", p.file, p.copy),
    }
}

/// The plate's hash: SHA-256 of its parts' hashes and names, one line per copy as the
/// manifest lists them (`<sha256>  <file>\n`, the form of `sha256sum`).
fn plate_sha256(records: &[PlatePart]) -> String {
    let lines: String = records
        .iter()
        .map(|r| format!("{}  {}\n", r.sha256, r.file))
        .collect();
    crate::bundle::sha256_hex(lines.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn overlaps(c: &[[f64; 2]], s: &[[f64; 2]], gap: f64) -> bool {
        (0..c.len()).any(|i| {
            (0..i).any(|j| {
                (0..2).all(|k| {
                    c[i][k] < c[j][k] + s[j][k] + gap - 1e-9
                        && c[j][k] < c[i][k] + s[i][k] + gap - 1e-9
                })
            })
        })
    }

    #[test]
    fn twelve_copies_fill_rows_without_overlap_inside_the_area() {
        let sizes = vec![[10.0, 8.0]; 12];
        let area = [0.0, 0.0, 65.0, 48.75];
        let c = arrange(&sizes, 3.0, area).unwrap();
        assert!(!overlaps(&c, &sizes, 3.0));
        for (p, s) in c.iter().zip(&sizes) {
            assert!(p[0] >= 0.0 && p[1] >= 0.0 && p[0] + s[0] <= 65.0 && p[1] + s[1] <= 48.75);
        }
        // Five fit a row of 65 mm (5·10 + 4·3 = 62), so three rows.
        let mut ys: Vec<f64> = c.iter().map(|p| p[1]).collect();
        ys.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        ys.sort_by(f64::total_cmp);
        ys.dedup();
        assert_eq!(ys.len(), 3);
    }

    #[test]
    fn a_layout_that_does_not_fit_names_a_box_and_what_is_missing() {
        let e = arrange(&[[70.0, 5.0]], 3.0, [0.0, 0.0, 65.0, 48.75]).unwrap_err();
        assert_eq!((e.index, e.axis), (0, 'X'));
        assert!((e.missing_mm - 5.0).abs() < 1e-9);
        let e = arrange(&[[40.0, 30.0], [40.0, 30.0]], 3.0, [0.0, 0.0, 65.0, 48.75]).unwrap_err();
        assert_eq!((e.index, e.axis), (1, 'Y'));
        assert!((e.missing_mm - (63.0 - 48.75)).abs() < 1e-9, "{e:?}");
    }

    #[test]
    fn a_point_names_the_part_whose_box_holds_it_or_the_nearest() {
        let part = |file: &str, copy: usize, x0: f64| PlatePart {
            file: file.into(),
            sha256: String::new(),
            copy,
            copies: 2,
            triangles: 12,
            bbox_mm: [[0.0; 3], [5.0, 5.0, 5.0]],
            translate_mm: [x0, 0.0, 0.0],
            placed_bbox_mm: [[x0, 10.0, 0.0], [x0 + 5.0, 15.0, 5.0]],
        };
        let parts = [part("a.stl", 1, 0.0), part("a.stl", 2, 10.0)];
        assert_eq!(part_at(&parts, [12.0, 12.0]), Some(1));
        assert_eq!(part_at(&parts, [2.0, 12.0]), Some(0));
        // Between the boxes, nearer the first; below the second.
        assert_eq!(part_at(&parts, [6.0, 12.0]), Some(0));
        assert_eq!(part_at(&parts, [13.0, 8.0]), Some(1));
        assert_eq!(part_at(&[], [0.0, 0.0]), None);
        assert_eq!(part_name(&parts[1]), "a.stl (copy 2 of 2)");
    }

    #[test]
    fn different_boxes_are_laid_tallest_first_and_centred() {
        let sizes = [[5.0, 5.0], [20.0, 12.0], [8.0, 3.0]];
        let c = arrange(&sizes, 2.0, [10.0, 10.0, 60.0, 40.0]).unwrap();
        assert!(!overlaps(&c, &sizes, 2.0));
        // One row 20 + 2 + 5 + 2 + 8 = 37 wide, 12 tall, centred in 50 x 30.
        assert_eq!(c[1], [10.0 + 6.5, 10.0 + 9.0]);
        assert_eq!(c[0], [10.0 + 6.5 + 22.0, 19.0]);
        assert_eq!(c[2], [10.0 + 6.5 + 29.0, 19.0]);
    }
}
