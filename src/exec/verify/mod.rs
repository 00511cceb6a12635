//! Verification of a bundle before it is simulated: the manifest's own consistency, every
//! mask file (present, SHA-256 as recorded, decodable PNG of the projector's resolution
//! and bit depth, its own file), what each layer's masks show against the layer's record
//! (lit pixels where the section is, enough of them for its area), and the light
//! compensation's gray maps; for a native job, each mask against its own record (its lit
//! pixels, their box in the field and the sum of its grays: [`MaskPixels`]) and the
//! settings against the layers. All problems are collected, each naming its file and
//! layer. Files are read, hashed and decoded in parallel (rayon), one layer's masks per
//! task, so memory stays at a few masks per thread; a decoded mask leaves only its
//! [`MaskPixels`] behind, and the layer its lit runs on the field
//! ([`crate::bundle::regions`], for the printability pass, `exec::printable`).
//!
//! The parts: the manifest's structure and the run of the checks (here), each PNG file
//! (`files.rs`), what a layer's masks must show (`content.rs`) and the settings
//! (`settings.rs`).

mod content;
mod files;
mod settings;
#[cfg(test)]
mod test_support;

use super::{Kind, Violation};
use crate::bundle::machine::{Machine, Projector};
use crate::bundle::regions::{field_runs, lit_runs, placed as placed_runs, Placement, Run};
use crate::bundle::{BundleSource, Manifest, MaskPixels, MaskRef, MANIFEST};
use crate::text::count;
use content::ContentRule;
use files::{check_gray_maps, check_png, is_inside, PngCheck};
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// What verification found.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Verification {
    /// Mask files checked.
    pub masks: usize,
    /// Gray map files (light compensation) checked.
    pub gray_maps: usize,
    /// Bytes read.
    pub bytes: u64,
    /// Problems: the job's first, then by layer.
    pub problems: Vec<Violation>,
    /// Each layer's lit pixels on the field as runs ([`crate::bundle::regions`]); `None`
    /// for a layer whose masks did not all read and decode cleanly.
    pub runs: Vec<Option<Vec<Run>>>,
}

fn problem(layer: Option<usize>, kind: Kind, file: Option<&str>, message: String) -> Violation {
    Violation {
        layer,
        time_s: None,
        kind,
        message,
        file: file.map(str::to_string),
    }
}

/// A problem with `file` whose message reads "PATH: `msg`", PATH the bundle's `shown` (the
/// file itself, or job.json for what the manifest says of it).
fn problem_in(
    dir: &dyn BundleSource,
    layer: Option<usize>,
    kind: Kind,
    (file, shown): (&str, &str),
    msg: &str,
) -> Violation {
    let message = format!("{}: {msg}", dir.shown(shown).display());
    problem(layer, kind, Some(file), message)
}

/// Verifies the manifest's structure and every mask of the bundle at `dir` for the
/// machine the manifest embeds.
#[cfg(any(test, feature = "internals"))]
pub fn verify(dir: &Path, manifest: &Manifest) -> Verification {
    verify_source(
        &crate::bundle::DirSource::new(dir),
        manifest,
        &manifest.machine,
        true,
    )
}

/// Verifies the bundle whose files `dir` reads for `machine`, which may differ from the one the manifest
/// embeds (the machine the job will run on): masks must come one per projector of
/// `machine`, have its projectors' sizes, and show each layer's section where `machine`'s
/// projectors put it. How the masks were made (binary, compensated, tiled responses) is
/// read from the manifest (its settings and embedded machine), and so is where a mask's
/// record places its pixels.
///
/// A `native` job (a bundle dmdsl wrote, in either form) gives every layer its own mask
/// file (`mask-shared` otherwise) and a mask for each projector, and its settings must
/// agree with its layers (`settings`); an imported job's layers may share an image (the SLA
/// control file's duplications), a layer record may show one projector's image (the
/// control file exposes a layer's images in turn), and its settings are the importer's.
pub fn verify_source(
    dir: &dyn BundleSource,
    manifest: &Manifest,
    machine: &Machine,
    native: bool,
) -> Verification {
    let mut problems = Vec::new();
    let (refs, mut incomplete) = check_structure(dir, manifest, machine, !native, &mut problems);
    if native {
        settings::check(dir, manifest, &mut problems);
    }
    let projectors = &machine.projector;
    // One task per layer: its masks read, checked and decoded, then its lit runs on the
    // field (the projectors' masks placed and added up) once all of them decoded.
    let groups: Vec<&[(usize, &MaskRef)]> = refs.chunk_by(|a, b| a.0 == b.0).collect();
    let per_layer: Vec<(Vec<PngCheck>, Option<Vec<Run>>)> = groups
        .par_iter()
        .map_init(Vec::new, |bufs: &mut Vec<Vec<u8>>, group| {
            decode_layer(dir, group, projectors, bufs)
        })
        .collect();
    let mut runs: Vec<Option<Vec<Run>>> = vec![None; manifest.layers.len()];
    let mut bytes = 0;
    // The masks' lit pixels per layer (as field pixels), once every mask decoded cleanly.
    let mut lit: Vec<Option<(MaskPixels, Vec<&MaskRef>)>> = vec![None; manifest.layers.len()];
    // Masks against their records, after each layer's content.
    let mut records = Vec::new();
    for (group, (checks, layer_runs)) in groups.iter().zip(per_layer) {
        if let (Some(&(i, _)), Some(r)) = (group.first(), layer_runs) {
            runs[i] = Some(r);
        }
        for (&(i, m), c) in group.iter().zip(checks) {
            bytes += c.bytes;
            let clean = c.faults.is_empty();
            for (fault, msg) in c.faults {
                problems.push(problem(Some(i), fault.mask_kind(), Some(&m.file), msg));
            }
            let Some(px) = c.lit.filter(|_| clean) else {
                incomplete.insert(i);
                continue;
            };
            let made_by = manifest.machine.projector.get(m.projector as usize);
            records.extend(made_by.and_then(|p| against_record(dir, i, m, placed(px, p))));
            if !incomplete.contains(&i) {
                let px = placed(px, &projectors[m.projector as usize]);
                let slot = lit[i].get_or_insert_with(|| (MaskPixels::default(), Vec::new()));
                slot.0 = union(slot.0, px);
                slot.1.push(m);
            }
        }
    }
    for i in &incomplete {
        if let Some(r) = runs.get_mut(*i) {
            *r = None;
        }
    }
    let rule = ContentRule::of(manifest, machine, native);
    for (i, slot) in lit.iter().enumerate() {
        if let (Some((px, masks)), false) = (slot, incomplete.contains(&i)) {
            problems.extend(rule.check(dir, i, &manifest.layers[i], *px, masks));
        }
    }
    problems.extend(records);
    let gray_maps = check_gray_maps(dir, manifest, machine, &mut bytes, &mut problems);
    problems.sort_by_key(|p| p.layer.map_or(0, |l| l + 1));
    Verification {
        masks: refs.len(),
        gray_maps,
        bytes,
        problems,
        runs,
    }
}

/// Checks and decodes the masks of one layer (`group`, each with its layer) into `bufs`
/// (one buffer per mask, kept by the thread): each file's check, and the layer's lit runs
/// on the field when every mask decoded cleanly.
fn decode_layer(
    dir: &dyn BundleSource,
    group: &[(usize, &MaskRef)],
    projectors: &[Projector],
    bufs: &mut Vec<Vec<u8>>,
) -> (Vec<PngCheck>, Option<Vec<Run>>) {
    if bufs.len() < group.len() {
        bufs.resize_with(group.len(), Vec::new);
    }
    let checks: Vec<PngCheck> = group
        .iter()
        .zip(bufs.iter_mut())
        .map(|(&(i, m), buf)| {
            let proj = &projectors[m.projector as usize];
            check_png(
                dir,
                &m.file,
                &m.sha256,
                proj,
                &format!("layer {i}"),
                "mask",
                buf,
            )
        })
        .collect();
    let clean = checks
        .iter()
        .all(|c| c.faults.is_empty() && c.lit.is_some());
    if !clean {
        return (checks, None);
    }
    let runs = match (group, checks.first().and_then(|c| c.lit)) {
        // One mask: only its lit box.
        ([(_, m)], Some(px)) => {
            let at = Placement::of(&projectors[m.projector as usize]);
            let [c0, r0, c1, r1] = px.lit_box_px.map_or([0; 4], |b| b.map(|v| v as usize));
            placed_runs(lit_runs(at.size[0], &bufs[0], r0..r1, c0..c1), at)
        }
        _ => {
            let masks: Vec<(&[u8], Placement)> = group
                .iter()
                .zip(bufs.iter())
                .map(|(&(_, m), b)| {
                    let at = Placement::of(&projectors[m.projector as usize]);
                    (b.as_slice(), at)
                })
                .collect();
            field_runs(&masks)
        }
    };
    (checks, Some(runs))
}

/// The pixels of projector `p`'s mask with their box in the field.
fn placed(px: MaskPixels, p: &Projector) -> MaskPixels {
    px.placed(
        [p.width_px, p.height_px],
        p.offset_px,
        [p.mirror_x, p.mirror_y],
    )
}

/// The pixels of two masks together (pixels lit in both count twice; no checksum).
fn union(a: MaskPixels, b: MaskPixels) -> MaskPixels {
    let lit_box_px = match (a.lit_box_px, b.lit_box_px) {
        (Some(a), Some(b)) => Some([
            a[0].min(b[0]),
            a[1].min(b[1]),
            a[2].max(b[2]),
            a[3].max(b[3]),
        ]),
        (a, b) => a.or(b),
    };
    MaskPixels {
        lit_px: a.lit_px + b.lit_px,
        lit_box_px,
        gray_sum: a.gray_sum + b.gray_sum,
        adler32: 0,
    }
}

/// A lit box as the messages give it: `columns 3..9, rows 0..4` (inclusive), or `no pixel`.
fn box_text(b: Option<[u32; 4]>) -> String {
    match b {
        Some([c0, r0, c1, r1]) => format!("columns {c0}..{}, rows {r0}..{}", c1 - 1, r1 - 1),
        None => "no pixel".into(),
    }
}

/// A `mask-pixels` problem when mask `m` of layer `i`, whose pixels placed by the
/// projector that the job's machine record names are `px`, differs from its record.
fn against_record(
    dir: &dyn BundleSource,
    i: usize,
    m: &MaskRef,
    px: MaskPixels,
) -> Option<Violation> {
    let rec = m.pixels.filter(|r| *r != px)?;
    let core = |p: MaskPixels| (p.lit_px, p.lit_box_px, p.gray_sum);
    let only_adler = core(px) == core(rec);
    let text = |p: MaskPixels| {
        let b = box_text(p.lit_box_px);
        let sum = match only_adler {
            true => format!("Adler-32 of its rows {:08x}", p.adler32),
            false => format!("gray sum {}", p.gray_sum),
        };
        format!(
            "{} ({b} of the field), {sum}",
            count(p.lit_px, "lit pixel", "lit pixels")
        )
    };
    let msg = format!(
        "layer {i}: the mask shows {}, but job.json records {} (the mask, or its projector's offset_px or mirroring, is not what the job was made with)",
        text(px),
        text(rec)
    );
    Some(problem_in(
        dir,
        Some(i),
        Kind::MaskPixels,
        (&m.file, &m.file),
        &msg,
    ))
}

/// Every mask file the manifest names, with its layer.
type MaskFiles<'m> = Vec<(usize, &'m MaskRef)>;

/// Checks the manifest's structure against `machine` (see [`verify_source`]): the mask
/// files to read, and the layers whose masks cannot all be read as the projectors' (no
/// content check for them).
fn check_structure<'m>(
    dir: &dyn BundleSource,
    manifest: &'m Manifest,
    machine: &Machine,
    shared_masks: bool,
    problems: &mut Vec<Violation>,
) -> (MaskFiles<'m>, HashSet<usize>) {
    let mut add = |layer, kind, at, msg: &str| problems.push(problem_in(dir, layer, kind, at, msg));
    let (job, n) = ((MANIFEST, MANIFEST), manifest.layers.len());
    if n == 0 {
        add(None, Kind::Manifest, job, "the job has no layers");
    }
    if manifest.totals.layers != n as u64 {
        let records = crate::text::count(n as u64, "layer record", "layer records");
        let msg = format!(
            "totals.layers is {} but the manifest has {records}",
            manifest.totals.layers
        );
        add(None, Kind::Manifest, job, &msg);
    }
    let projectors = machine.projector.len();
    let (mut refs, mut incomplete) = (Vec::new(), HashSet::new());
    // Every mask file by its normalized path: the first layer and projector naming it.
    let mut owners: HashMap<PathBuf, (usize, u32)> = HashMap::new();
    for (i, l) in manifest.layers.iter().enumerate() {
        let at = Some(i);
        if l.index != i as u64 {
            add(
                at,
                Kind::Manifest,
                job,
                &format!("layer record {i} has index {}", l.index),
            );
        }
        let mut seen = HashSet::new();
        for m in &l.masks {
            let (f, k) = (m.file.as_str(), m.projector);
            if k as usize >= projectors {
                let msg = format!(
                    "layer {i}: mask for projector {k}, but the machine has {}",
                    count(projectors as u64, "projector", "projectors")
                );
                add(at, Kind::Manifest, (f, f), &msg);
                incomplete.insert(i);
                continue;
            }
            if !seen.insert(k) {
                add(
                    at,
                    Kind::Manifest,
                    (f, f),
                    &format!("layer {i}: second mask for projector {k}"),
                );
                incomplete.insert(i);
            }
            if !is_inside(f) {
                let msg =
                    format!("layer {i}: mask path {f:?} is not a relative path inside the bundle");
                add(at, Kind::Manifest, (f, MANIFEST), &msg);
                incomplete.insert(i);
                continue;
            }
            let key: PathBuf = Path::new(f).components().collect();
            match owners.get(&key) {
                Some(_) if shared_masks => {}
                Some(&(j, o)) => {
                    let other = if j == i {
                        format!("projector {o}'s mask of the same layer")
                    } else {
                        format!("layer {j}'s mask")
                    };
                    let msg = format!("layer {i}: the mask of projector {k} is the same file as {other}: every layer's mask has its own file");
                    add(at, Kind::MaskShared, (f, f), &msg);
                }
                None => {
                    owners.insert(key, (i, k));
                }
            }
            refs.push((i, m));
        }
        // An imported job exposes one image at a time (the control file's images of a
        // layer are exposed in turn): its records name one projector each.
        if seen.len() < projectors && !(shared_masks && seen.len() == 1) {
            let msg = format!(
                "layer {i} has masks for {} of the machine's {}",
                seen.len(),
                count(projectors as u64, "projector", "projectors")
            );
            add(at, Kind::Manifest, job, &msg);
            incomplete.insert(i);
        }
    }
    (refs, incomplete)
}

#[cfg(test)]
mod tests {
    use super::test_support::*;
    use super::*;
    use crate::bundle::{sha256_hex, Step};
    use crate::exec::testutil::manifest;
    use image::ExtendedColorType::{Rgb8, L8};

    #[test]
    fn every_mask_problem_is_found_and_named() {
        let dir = Scratch::new("files");
        let good = png(64, 48, L8);
        let mut truncated = good.clone();
        truncated.truncate(good.len() - 30);
        let files: Vec<Option<Vec<u8>>> = vec![
            Some(good.clone()),      // 0: fine
            Some(good.clone()),      // 1: bytes flipped after hashing
            None,                    // 2: missing
            Some(png(32, 48, L8)),   // 3: wrong size
            Some(png(64, 48, Rgb8)), // 4: colour
            Some(truncated),         // 5: truncated (hash matches)
        ];
        let mut layers = Vec::new();
        for (i, f) in files.iter().enumerate() {
            let mut l = blank_layer(i);
            (l.steps, l.time_s) = (vec![Step::Expose { s: 1.0 }], 1.1);
            // The section fills the field (the mask lights almost every pixel), its area
            // what the grays of `good` add up to.
            l.bbox_mm = Some([[0.0, 0.0], [64.0 * PX, 48.0 * PX]]);
            let sum: u32 = (0..64 * 48).map(|i| i % 251).sum();
            l.area_mm2 = sum as f64 / 255.0 * PX * PX;
            if let Some(b) = f {
                l.masks[0].sha256 = sha256_hex(b);
                let mut b = b.clone();
                if i == 1 {
                    let n = b.len();
                    b[n / 2..n / 2 + 8].iter_mut().for_each(|x| *x ^= 0xff);
                }
                std::fs::write(dir.join(&l.masks[0].file), b).unwrap();
            }
            layers.push(l);
        }
        // Layer 6 points outside the bundle; layer 7 has no mask.
        layers.push(blank_layer(6));
        layers[6].masks[0].file = "../escape.png".into();
        layers.push(blank_layer(7));
        layers[7].masks.clear();
        let v = verify(&dir, &manifest(small_profile(), layers));
        assert_eq!(v.masks, 6);
        let want = [
            (1, Kind::MaskChecksum),
            (1, Kind::MaskDecode),
            (2, Kind::MaskMissing),
            (3, Kind::MaskFormat),
            (4, Kind::MaskFormat),
            (5, Kind::MaskDecode),
            (6, Kind::Manifest),
            (7, Kind::Manifest),
        ];
        let want: Vec<_> = want.iter().map(|&(i, k)| (Some(i), k)).collect();
        assert_eq!(found(&v), want, "{:#?}", v.problems);
        says(&v, 0, "masks/00001.png: layer 1: SHA-256 mismatch");
        says(&v, 2, "masks/00002.png: layer 2: mask file is missing");
        says(&v, 3, "PNG is 32x48, projector p0 is 64x48");
        says(&v, 4, "expected 8-bit grayscale");
        says(&v, 6, "not a relative path inside the bundle");
        says(&v, 7, "masks for 0 of the machine's 1 projector");
        assert_eq!(v.problems[2].file.as_deref(), Some("masks/00002.png"));
    }

    #[test]
    fn a_mask_file_named_by_two_layers_is_found() {
        let dir = Scratch::new("shared");
        let png = lit_png(10, 5, 30, 15);
        let mut layers: Vec<_> = (0..3)
            .map(|i| layer_with(&dir, i, &png, BOX, 200.0))
            .collect();
        layers[2].masks[0].file = "masks//00000.png".into();
        let v = verify(&dir, &manifest(small_profile(), layers));
        assert_eq!(
            found(&v),
            vec![(Some(2), Kind::MaskShared)],
            "{:#?}",
            v.problems
        );
        says(
            &v,
            0,
            "masks//00000.png: layer 2: the mask of projector 0 is the same file as layer 0's mask",
        );
    }

    #[test]
    fn a_job_without_layers_is_a_manifest_problem() {
        let dir = Scratch::new("empty");
        let v = verify(&dir, &manifest(small_profile(), vec![]));
        assert_eq!(found(&v), vec![(None, Kind::Manifest)]);
        ends(&v, 0, "job.json: the job has no layers");
    }
}
