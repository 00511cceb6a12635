//! Verification of a bundle before it is simulated: the manifest's own consistency, every
//! mask file (present, SHA-256 as recorded, decodable PNG of the projector's resolution
//! and bit depth, its own file), what each layer's masks show against the layer's record
//! (lit pixels where the section is, enough of them for its area), and the light
//! compensation's gray maps. All problems are collected, each naming its file and layer.
//! Files are read, hashed and decoded in parallel (rayon), one file per task, so memory
//! stays at a few masks per thread; a decoded mask leaves only its [`LitPixels`] behind.
//!
//! The parts: the manifest's structure and the run of the checks (here), each PNG file
//! (`files.rs`), the lit pixels of a decoded mask (`lit.rs`) and what a layer's masks must
//! show (`content.rs`).

mod content;
mod files;
mod lit;
#[cfg(test)]
mod test_support;

pub use lit::LitPixels;

use super::{Kind, Violation};
use crate::bundle::{BundleSource, DirSource, Manifest, MaskRef, MANIFEST};
use crate::profile::Profile;
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

/// Verifies the manifest's structure and every mask of the bundle at `dir` for the
/// machine the manifest embeds.
pub fn verify(dir: &Path, manifest: &Manifest) -> Verification {
    verify_on(dir, manifest, &manifest.machine)
}

/// [`verify_source`] for the bundle directory `dir`.
pub fn verify_on(dir: &Path, manifest: &Manifest, machine: &Profile) -> Verification {
    verify_source(&DirSource::new(dir), manifest, machine, false)
}

/// Verifies the bundle whose files `dir` reads for `machine`, which may differ from the one the manifest
/// embeds (the machine the job will run on): masks must come one per projector of
/// `machine`, have its projectors' sizes, and show each layer's section where `machine`'s
/// projectors put it. How the masks were made (binary, compensated, tiled responses) is
/// read from the manifest (its settings and embedded machine).
///
/// `shared_masks` allows layers to name the same mask file (jobs imported from formats
/// where layers share images, such as the SLA control file's duplications); a native
/// bundle gives every layer its own file, so there it is a `mask-shared` problem.
pub fn verify_source(
    dir: &dyn BundleSource,
    manifest: &Manifest,
    machine: &Profile,
    shared_masks: bool,
) -> Verification {
    let mut problems = Vec::new();
    let job = dir.shown(MANIFEST);
    let n = manifest.layers.len();
    if n == 0 {
        problems.push(problem(
            None,
            Kind::Manifest,
            Some(MANIFEST),
            format!("{}: the job has no layers", job.display()),
        ));
    }
    if manifest.totals.layers != n as u64 {
        problems.push(problem(
            None,
            Kind::Manifest,
            Some(MANIFEST),
            format!(
                "{}: totals.layers is {} but the manifest has {}",
                job.display(),
                manifest.totals.layers,
                crate::text::count(n as u64, "layer record", "layer records")
            ),
        ));
    }
    let projectors = &machine.projector;
    let mut refs: Vec<(usize, &MaskRef)> = Vec::new();
    // Layers whose masks cannot all be read as the projectors': no content check.
    let mut incomplete: HashSet<usize> = HashSet::new();
    // Every mask file by its normalized path: the first layer and projector naming it.
    let mut owners: HashMap<PathBuf, (usize, u32)> = HashMap::new();
    for (i, l) in manifest.layers.iter().enumerate() {
        if l.index != i as u64 {
            problems.push(problem(
                Some(i),
                Kind::Manifest,
                Some(MANIFEST),
                format!("{}: layer record {i} has index {}", job.display(), l.index),
            ));
        }
        let mut seen = HashSet::new();
        for m in &l.masks {
            if (m.projector as usize) >= projectors.len() {
                problems.push(problem(
                    Some(i),
                    Kind::Manifest,
                    Some(&m.file),
                    format!(
                        "{}: layer {i}: mask for projector {}, but the machine has {} projector(s)",
                        dir.shown(&m.file).display(),
                        m.projector,
                        projectors.len()
                    ),
                ));
                incomplete.insert(i);
                continue;
            }
            if !seen.insert(m.projector) {
                problems.push(problem(
                    Some(i),
                    Kind::Manifest,
                    Some(&m.file),
                    format!(
                        "{}: layer {i}: second mask for projector {}",
                        dir.shown(&m.file).display(),
                        m.projector
                    ),
                ));
                incomplete.insert(i);
            }
            if !is_inside(&m.file) {
                problems.push(problem(
                    Some(i),
                    Kind::Manifest,
                    Some(&m.file),
                    format!(
                        "{}: layer {i}: mask path {:?} is not a relative path inside the bundle",
                        job.display(),
                        m.file
                    ),
                ));
                incomplete.insert(i);
                continue;
            }
            let key: PathBuf = Path::new(&m.file).components().collect();
            match owners.get(&key) {
                Some(_) if shared_masks => {}
                Some(&(j, k)) => {
                    let other = if j == i {
                        format!("projector {k}'s mask of the same layer")
                    } else {
                        format!("layer {j}'s mask")
                    };
                    problems.push(problem(
                        Some(i),
                        Kind::MaskShared,
                        Some(&m.file),
                        format!(
                            "{}: layer {i}: the mask of projector {} is the same file as {other}: every layer's mask has its own file",
                            dir.shown(&m.file).display(),
                            m.projector,
                        ),
                    ));
                }
                None => {
                    owners.insert(key, (i, m.projector));
                }
            }
            refs.push((i, m));
        }
        if seen.len() < projectors.len() {
            problems.push(problem(
                Some(i),
                Kind::Manifest,
                Some(MANIFEST),
                format!(
                    "{}: layer {i} has masks for {} of the machine's {} projector(s)",
                    job.display(),
                    seen.len(),
                    projectors.len()
                ),
            ));
            incomplete.insert(i);
        }
    }
    let per_file: Vec<PngCheck> = refs
        .par_iter()
        .map_init(Vec::new, |buf, &(i, m)| {
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
    let mut bytes = 0;
    // The masks' lit pixels per layer (as field pixels), once every mask decoded cleanly.
    let mut lit: Vec<Option<(LitPixels, Vec<&MaskRef>)>> = vec![None; n];
    for (&(i, m), c) in refs.iter().zip(per_file) {
        bytes += c.bytes;
        let clean = c.faults.is_empty();
        for (fault, msg) in c.faults {
            problems.push(problem(Some(i), fault.mask_kind(), Some(&m.file), msg));
        }
        match c.lit.filter(|_| clean) {
            Some(px) if !incomplete.contains(&i) => {
                let px = px.in_field(&projectors[m.projector as usize]);
                let slot = lit[i].get_or_insert_with(|| (LitPixels::default(), Vec::new()));
                slot.0 = slot.0.union(px);
                slot.1.push(m);
            }
            _ => {
                incomplete.insert(i);
            }
        }
    }
    let rule = ContentRule::of(manifest, machine);
    for (i, slot) in lit.iter().enumerate() {
        if let (Some((px, masks)), false) = (slot, incomplete.contains(&i)) {
            problems.extend(rule.check(dir, i, &manifest.layers[i], *px, masks));
        }
    }
    let gray_maps = check_gray_maps(dir, manifest, machine, &mut bytes, &mut problems);
    problems.sort_by_key(|p| p.layer.map_or(0, |l| l + 1));
    Verification {
        masks: refs.len(),
        gray_maps,
        bytes,
        problems,
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::*;
    use super::*;
    use crate::bundle::{sha256_hex, Mode, Step};
    use crate::exec::testutil::*;
    use image::ExtendedColorType;

    #[test]
    fn every_mask_problem_is_found_and_named() {
        let dir = std::env::temp_dir().join(format!("dmdsl-verify-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("masks")).unwrap();
        let mut p = profile();
        p.projector[0].width_px = 64;
        p.projector[0].height_px = 48;
        let good = png(64, 48, ExtendedColorType::L8);
        let mut truncated = good.clone();
        truncated.truncate(good.len() - 30);
        let files: Vec<Option<Vec<u8>>> = vec![
            Some(good.clone()),                         // 0: fine
            Some(good.clone()),                         // 1: bytes flipped after hashing
            None,                                       // 2: missing
            Some(png(32, 48, ExtendedColorType::L8)),   // 3: wrong size
            Some(png(64, 48, ExtendedColorType::Rgb8)), // 4: colour
            Some(truncated),                            // 5: truncated (hash matches)
        ];
        let mut layers = Vec::new();
        for (i, f) in files.iter().enumerate() {
            let mut l = layer(
                i,
                0.1 * (i + 1) as f64,
                0.1,
                Mode::Layered,
                1.0,
                vec![Step::Expose { s: 1.0 }],
                1.1,
            );
            let name = format!("masks/{i:05}.png");
            // The section fills the field (the mask lights almost every pixel).
            l.bbox_mm = Some([[0.0, 0.0], [64.0 * PX, 48.0 * PX]]);
            l.area_mm2 = 64.0 * 48.0 * PX * PX;
            if let Some(b) = f {
                l.masks[0].sha256 = sha256_hex(b);
                let mut b = b.clone();
                if i == 1 {
                    let n = b.len();
                    for x in &mut b[n / 2..n / 2 + 8] {
                        *x ^= 0xff;
                    }
                }
                std::fs::write(dir.join(&name), b).unwrap();
            }
            layers.push(l);
        }
        // Layer 6 points outside the bundle; layer 7 has no mask.
        let mut l6 = layer(6, 0.7, 0.1, Mode::Layered, 1.0, vec![], 0.0);
        l6.masks[0].file = "../escape.png".into();
        let mut l7 = layer(7, 0.8, 0.1, Mode::Layered, 1.0, vec![], 0.0);
        l7.masks.clear();
        layers.push(l6);
        layers.push(l7);
        let m = manifest(p, layers);
        let v = verify(&dir, &m);
        assert_eq!(v.masks, 6);
        assert_eq!(
            found(&v),
            vec![
                (Some(1), Kind::MaskChecksum),
                (Some(1), Kind::MaskDecode),
                (Some(2), Kind::MaskMissing),
                (Some(3), Kind::MaskFormat),
                (Some(4), Kind::MaskFormat),
                (Some(5), Kind::MaskDecode),
                (Some(6), Kind::Manifest),
                (Some(7), Kind::Manifest),
            ],
            "{:#?}",
            v.problems
        );
        let msg = |i: usize| v.problems[i].message.clone();
        assert!(
            msg(0).contains("masks/00001.png: layer 1: SHA-256 mismatch"),
            "{}",
            msg(0)
        );
        assert!(msg(2).contains("masks/00002.png: layer 2: mask file is missing"));
        assert!(msg(3).contains("PNG is 32x48, projector p0 is 64x48"));
        assert!(msg(4).contains("expected 8-bit grayscale"));
        assert!(msg(6).contains("not a relative path inside the bundle"));
        assert!(msg(7).contains("masks for 0 of the machine's 1 projector"));
        assert_eq!(v.problems[2].file.as_deref(), Some("masks/00002.png"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_mask_file_named_by_two_layers_is_found() {
        let dir = scratch("shared");
        let png = gray_png(64, 48, rect(10, 5, 30, 15, 255));
        let section = Some([10.0, 5.0, 30.0, 15.0]);
        let mut l2 = layer_with(&dir, 2, &png, section, 200.0);
        l2.masks[0].file = "masks//00000.png".into();
        let m = manifest(
            small_profile(),
            vec![
                layer_with(&dir, 0, &png, section, 200.0),
                layer_with(&dir, 1, &png, section, 200.0),
                l2,
            ],
        );
        let v = verify(&dir, &m);
        assert_eq!(
            found(&v),
            vec![(Some(2), Kind::MaskShared)],
            "{:#?}",
            v.problems
        );
        assert!(
            v.problems[0].message.contains("masks//00000.png: layer 2: the mask of projector 0 is the same file as layer 0's mask"),
            "{}",
            v.problems[0].message
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_job_without_layers_is_a_manifest_problem() {
        let dir = scratch("empty");
        let v = verify(&dir, &manifest(small_profile(), vec![]));
        assert_eq!(found(&v), vec![(None, Kind::Manifest)]);
        assert!(v.problems[0]
            .message
            .ends_with("job.json: the job has no layers"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
