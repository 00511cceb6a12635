//! Verification of a bundle before it is simulated: the manifest's own consistency and
//! every mask file (present, SHA-256 as recorded, decodable PNG of the projector's
//! resolution and bit depth). All problems are collected, each naming its file and layer.
//! Files are read, hashed and decoded in parallel (rayon), one file per task, so memory
//! stays at a few masks per thread.

use super::Violation;
use crate::bundle::{sha256_hex, Manifest, MaskRef};
use image::codecs::png::PngDecoder;
use image::{ColorType, ImageDecoder};
use rayon::prelude::*;
use std::collections::HashSet;
use std::path::{Component, Path};

/// What verification found.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Verification {
    /// Mask files checked.
    pub masks: usize,
    /// Bytes read.
    pub bytes: u64,
    /// Problems, in layer order.
    pub problems: Vec<Violation>,
}

fn problem(
    layer: Option<usize>,
    kind: &'static str,
    file: Option<&str>,
    message: String,
) -> Violation {
    Violation {
        layer,
        time_s: None,
        kind,
        message,
        file: file.map(str::to_string),
    }
}

/// Verifies the manifest's structure and every mask of the bundle at `dir`.
pub fn verify(dir: &Path, manifest: &Manifest) -> Verification {
    let mut problems = Vec::new();
    let job = dir.join(crate::bundle::MANIFEST);
    let n = manifest.layers.len();
    if manifest.totals.layers != n as u64 {
        problems.push(problem(
            None,
            "manifest",
            Some(crate::bundle::MANIFEST),
            format!(
                "{}: totals.layers is {} but the manifest has {n} layer record{}",
                job.display(),
                manifest.totals.layers,
                if n == 1 { "" } else { "s" }
            ),
        ));
    }
    let projectors = &manifest.machine.projector;
    let mut refs: Vec<(usize, &MaskRef)> = Vec::new();
    for (i, l) in manifest.layers.iter().enumerate() {
        if l.index != i as u64 {
            problems.push(problem(
                Some(i),
                "manifest",
                Some(crate::bundle::MANIFEST),
                format!("{}: layer record {i} has index {}", job.display(), l.index),
            ));
        }
        let mut seen = HashSet::new();
        for m in &l.masks {
            if (m.projector as usize) >= projectors.len() {
                problems.push(problem(
                    Some(i),
                    "manifest",
                    Some(&m.file),
                    format!(
                        "{}: layer {i}: mask for projector {}, but the machine has {} projector(s)",
                        dir.join(&m.file).display(),
                        m.projector,
                        projectors.len()
                    ),
                ));
                continue;
            }
            if !seen.insert(m.projector) {
                problems.push(problem(
                    Some(i),
                    "manifest",
                    Some(&m.file),
                    format!(
                        "{}: layer {i}: second mask for projector {}",
                        dir.join(&m.file).display(),
                        m.projector
                    ),
                ));
            }
            if !is_inside(&m.file) {
                problems.push(problem(
                    Some(i),
                    "manifest",
                    Some(&m.file),
                    format!(
                        "{}: layer {i}: mask path {:?} is not a relative path inside the bundle",
                        job.display(),
                        m.file
                    ),
                ));
                continue;
            }
            refs.push((i, m));
        }
        if seen.len() < projectors.len() {
            problems.push(problem(
                Some(i),
                "manifest",
                Some(crate::bundle::MANIFEST),
                format!(
                    "{}: layer {i} has masks for {} of the machine's {} projector(s)",
                    job.display(),
                    seen.len(),
                    projectors.len()
                ),
            ));
        }
    }
    let per_file: Vec<(u64, Vec<Violation>)> = refs
        .par_iter()
        .map_init(Vec::new, |buf, &(i, m)| {
            check_mask(dir, manifest, i, m, buf)
        })
        .collect();
    let mut bytes = 0;
    for (b, p) in per_file {
        bytes += b;
        problems.extend(p);
    }
    problems.sort_by_key(|p| p.layer.map_or(0, |l| l + 1));
    Verification {
        masks: refs.len(),
        bytes,
        problems,
    }
}

/// A relative path made only of normal components.
fn is_inside(rel: &str) -> bool {
    let p = Path::new(rel);
    !rel.is_empty() && p.components().all(|c| matches!(c, Component::Normal(_)))
}

/// Checks one mask file; returns the bytes read and the problems found.
fn check_mask(
    dir: &Path,
    manifest: &Manifest,
    layer: usize,
    m: &MaskRef,
    buf: &mut Vec<u8>,
) -> (u64, Vec<Violation>) {
    let path = dir.join(&m.file);
    let shown = path.display();
    let mut out = Vec::new();
    let bytes = match std::fs::read(&path) {
        Ok(b) => b,
        Err(e) => {
            let msg = if e.kind() == std::io::ErrorKind::NotFound {
                format!("{shown}: layer {layer}: mask file is missing")
            } else {
                format!("{shown}: layer {layer}: cannot read mask: {e}")
            };
            out.push(problem(Some(layer), "mask-missing", Some(&m.file), msg));
            return (0, out);
        }
    };
    let sha = sha256_hex(&bytes);
    if !sha.eq_ignore_ascii_case(&m.sha256) {
        out.push(problem(
            Some(layer),
            "mask-checksum",
            Some(&m.file),
            format!(
                "{shown}: layer {layer}: SHA-256 mismatch (manifest {}, file {})",
                short(&m.sha256),
                short(&sha)
            ),
        ));
    }
    let proj = &manifest.machine.projector[m.projector as usize];
    let dec = match PngDecoder::new(std::io::Cursor::new(&bytes)) {
        Ok(d) => d,
        Err(e) => {
            out.push(problem(
                Some(layer),
                "mask-decode",
                Some(&m.file),
                format!("{shown}: layer {layer}: not a decodable PNG: {e}"),
            ));
            return (bytes.len() as u64, out);
        }
    };
    let (w, h) = dec.dimensions();
    let ct = dec.color_type();
    let mut format_ok = true;
    if ct != ColorType::L8 {
        format_ok = false;
        out.push(problem(
            Some(layer),
            "mask-format",
            Some(&m.file),
            format!("{shown}: layer {layer}: PNG is {ct:?}, expected 8-bit grayscale (L8)"),
        ));
    }
    if (w, h) != (proj.width_px, proj.height_px) {
        format_ok = false;
        out.push(problem(
            Some(layer),
            "mask-format",
            Some(&m.file),
            format!(
                "{shown}: layer {layer}: PNG is {w}x{h}, projector {} is {}x{}",
                proj.name, proj.width_px, proj.height_px
            ),
        ));
    }
    if format_ok {
        // Decode the pixels: a PNG whose header is fine may still be truncated or corrupt.
        buf.resize(dec.total_bytes() as usize, 0);
        if let Err(e) = dec.read_image(buf) {
            out.push(problem(
                Some(layer),
                "mask-decode",
                Some(&m.file),
                format!("{shown}: layer {layer}: PNG does not decode: {e}"),
            ));
        }
    }
    (bytes.len() as u64, out)
}

fn short(hex: &str) -> &str {
    hex.get(..12).unwrap_or(hex)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundle::{Mode, Step};
    use crate::exec::testutil::*;
    use image::codecs::png::PngEncoder;
    use image::{ExtendedColorType, ImageEncoder};

    fn png(w: u32, h: u32, ct: ExtendedColorType) -> Vec<u8> {
        let ch = if ct == ExtendedColorType::Rgb8 { 3 } else { 1 };
        let px: Vec<u8> = (0..w * h * ch).map(|i| (i % 251) as u8).collect();
        let mut out = Vec::new();
        PngEncoder::new(&mut out)
            .write_image(&px, w, h, ct)
            .unwrap();
        out
    }

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
        let got: Vec<(Option<usize>, &str)> =
            v.problems.iter().map(|p| (p.layer, p.kind)).collect();
        assert_eq!(
            got,
            vec![
                (Some(1), "mask-checksum"),
                (Some(1), "mask-decode"),
                (Some(2), "mask-missing"),
                (Some(3), "mask-format"),
                (Some(4), "mask-format"),
                (Some(5), "mask-decode"),
                (Some(6), "manifest"),
                (Some(7), "manifest"),
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
}
