//! Each PNG file of the bundle on its own: the masks and the light compensation's gray
//! maps, present, as recorded (SHA-256), and decodable PNGs of their projector's size.

use super::{problem, problem_in};
use crate::bundle::machine::{Machine, Projector};
use crate::bundle::{sha256_hex, BundleSource, Manifest, MaskPixels, MANIFEST};
use crate::exec::{Kind, Violation};
use crate::text::count;
use image::codecs::png::PngDecoder;
use image::{ColorType, ImageDecoder};
use rayon::prelude::*;
use std::path::{Component, Path};

/// Checks the gray map of every light compensation record (`optics`,
/// `projector_optics`) like a mask, as `optics-file` problems; returns how many.
pub(super) fn check_gray_maps(
    dir: &dyn BundleSource,
    manifest: &Manifest,
    machine: &Machine,
    bytes: &mut u64,
    problems: &mut Vec<Violation>,
) -> usize {
    let records: Vec<_> = manifest
        .optics
        .iter()
        .chain(&manifest.projector_optics)
        .collect();
    let mut files = Vec::new();
    for o in &records {
        let file = o.gray_map.as_str();
        let what = format!("gray map of projector {}", o.projector);
        let mut bad = |shown, msg: String| {
            problems.push(problem_in(dir, None, Kind::OpticsFile, (file, shown), &msg));
        };
        let Some(proj) = machine.projector.get(o.projector as usize) else {
            let k = machine.projector.len();
            bad(
                file,
                format!(
                    "{what}: the machine has {}",
                    count(k as u64, "projector", "projectors")
                ),
            );
            continue;
        };
        if !is_inside(file) {
            bad(
                MANIFEST,
                format!("{what}: path {file:?} is not a relative path inside the bundle"),
            );
            continue;
        }
        files.push((file, o.gray_map_sha256.as_str(), proj, what));
    }
    let checked: Vec<PngCheck> = files
        .par_iter()
        .map_init(Vec::new, |buf, (file, sha, proj, what)| {
            check_png(dir, file, sha, proj, what, "gray map", buf)
        })
        .collect();
    for ((file, ..), c) in files.iter().zip(checked) {
        *bytes += c.bytes;
        for (_, msg) in c.faults {
            problems.push(problem(None, Kind::OpticsFile, Some(file), msg));
        }
    }
    files.len()
}

/// A relative path made only of normal components.
pub(super) fn is_inside(rel: &str) -> bool {
    let p = Path::new(rel);
    !rel.is_empty() && p.components().all(|c| matches!(c, Component::Normal(_)))
}

/// What can be wrong with a PNG file of the bundle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum FileFault {
    /// Missing or unreadable.
    Missing,
    /// SHA-256 differs from the manifest's.
    Checksum,
    /// Not a PNG, or its pixel data does not decode.
    Decode,
    /// Not 8-bit gray, or not the projector's size.
    Format,
}

impl FileFault {
    /// The violation kind of this fault in a mask file.
    pub(super) fn mask_kind(self) -> Kind {
        match self {
            FileFault::Missing => Kind::MaskMissing,
            FileFault::Checksum => Kind::MaskChecksum,
            FileFault::Decode => Kind::MaskDecode,
            FileFault::Format => Kind::MaskFormat,
        }
    }
}

/// One PNG file checked.
pub(super) struct PngCheck {
    /// Bytes read.
    pub(super) bytes: u64,
    /// What is wrong, with a message naming the file.
    pub(super) faults: Vec<(FileFault, String)>,
    /// Its pixels (the box in its own pixels), when it decoded.
    pub(super) lit: Option<MaskPixels>,
}

/// Checks one gray PNG of the bundle (`rel`): present, SHA-256 `sha256`, a PNG of
/// projector `proj`'s size in 8-bit gray whose pixel data decode to the end. Messages
/// read "PATH: `what`: ..."; `noun` names the file's role ("mask", "gray map").
pub(super) fn check_png(
    dir: &dyn BundleSource,
    rel: &str,
    sha256: &str,
    proj: &Projector,
    what: &str,
    noun: &str,
    buf: &mut Vec<u8>,
) -> PngCheck {
    let shown = dir.shown(rel);
    let mut faults = Vec::new();
    let mut fault =
        |f, msg: String| faults.push((f, format!("{}: {what}: {msg}", shown.display())));
    let bytes = match dir.read(rel) {
        Ok(b) => b,
        Err(e) => {
            let msg = match e.kind() {
                std::io::ErrorKind::NotFound => format!("{noun} file is missing"),
                _ => format!("cannot read {noun}: {e}"),
            };
            fault(FileFault::Missing, msg);
            return PngCheck {
                bytes: 0,
                faults,
                lit: None,
            };
        }
    };
    let n = bytes.len() as u64;
    let sha = sha256_hex(&bytes);
    if !sha.eq_ignore_ascii_case(sha256) {
        let (want, got) = (short(sha256), short(&sha));
        fault(
            FileFault::Checksum,
            format!("SHA-256 mismatch (manifest {want}, file {got})"),
        );
    }
    let dec = match PngDecoder::new(std::io::Cursor::new(&bytes)) {
        Ok(d) => d,
        Err(e) => {
            fault(FileFault::Decode, format!("not a decodable PNG: {e}"));
            return PngCheck {
                bytes: n,
                faults,
                lit: None,
            };
        }
    };
    let ((w, h), ct, size) = (
        dec.dimensions(),
        dec.color_type(),
        (proj.width_px, proj.height_px),
    );
    if ct != ColorType::L8 {
        fault(
            FileFault::Format,
            format!("PNG is {ct:?}, expected 8-bit grayscale (L8)"),
        );
    }
    if (w, h) != size {
        let msg = format!(
            "PNG is {w}x{h}, projector {} is {}x{}",
            proj.name, size.0, size.1
        );
        fault(FileFault::Format, msg);
    }
    let format_ok = ct == ColorType::L8 && (w, h) == size;
    let mut lit = None;
    if format_ok && dec.total_bytes() > crate::formats::DEFLATE_MAX_RATIO.saturating_mul(n) {
        // A header of the projector's size on a file too small to hold its pixels (a
        // large imported display): refused before anything is allocated for them.
        let msg = format!("PNG declares {w}x{h} pixels, more than its {n} bytes can hold");
        fault(FileFault::Decode, msg);
    } else if format_ok {
        // Decode the pixels: a PNG whose header is fine may still be truncated or corrupt.
        buf.resize(dec.total_bytes() as usize, 0);
        match dec.read_image(buf) {
            Ok(()) => lit = Some(MaskPixels::of_gray8(w, buf)),
            Err(e) => fault(FileFault::Decode, format!("PNG does not decode: {e}")),
        }
    }
    PngCheck {
        bytes: n,
        faults,
        lit,
    }
}

fn short(hex: &str) -> &str {
    hex.get(..12).unwrap_or(hex)
}

#[cfg(test)]
mod tests {
    use super::super::test_support::*;
    use super::super::verify;
    use super::*;
    use crate::exec::testutil::manifest;

    #[test]
    fn a_header_larger_than_its_file_can_hold_is_refused_before_decoding() {
        let dir = Scratch::new("huge-header");
        // A 64 × 48 PNG whose header says 4096 × 4096 (its CRC recomputed), shown by a
        // projector of that size: 16 Mpx from about a hundred bytes.
        let mut b = png(64, 48, image::ExtendedColorType::L8);
        b[16..20].copy_from_slice(&4096u32.to_be_bytes());
        b[20..24].copy_from_slice(&4096u32.to_be_bytes());
        let crc = crc32fast::hash(&b[12..29]);
        b[29..33].copy_from_slice(&crc.to_be_bytes());
        let mut p = small_profile();
        (p.projector[0].width_px, p.projector[0].height_px) = (4096, 4096);
        let v = verify(
            &dir,
            &manifest(p, vec![layer_with(&dir, 0, &b, None, 1.0 / PX / PX)]),
        );
        assert_eq!(found(&v), vec![(Some(0), Kind::MaskDecode)]);
        says(&v, 0, "declares 4096x4096 pixels, more than its");
    }

    /// A light compensation record of projector `k` whose gray map is `file`.
    fn optics(k: u32, file: &str, sha256: &str) -> crate::bundle::Optics {
        serde_json::from_value(serde_json::json!({
            "mode": "zone", "dither": "auto", "mixed_zones": 0, "projector": k,
            "calibration": "test", "units": "relative", "target_irradiance": 1.0,
            "mean_irradiance": 1.0, "throughput": 1.0,
            "calibrated_area_mm": [0.0, 0.0, 1.0, 1.0], "valid_gray": [121, 255],
            "zone_mm": 5.0, "zone_grays": [], "gray_map": file, "gray_map_sha256": sha256,
            "predicted": {"before_zone_pct": 0.0, "before_pixel_pct": 0.0,
                          "after_zone_pct": 0.0, "after_pixel_pct": 0.0},
            "zones_outside": 0, "pixels_outside": 0, "unreachable": 0, "layers_outside": 0,
            "exposure_rule": "test", "dose_mj_cm2": null
        }))
        .unwrap()
    }

    #[test]
    fn every_projectors_gray_map_is_verified() {
        let dir = Scratch::new("gray-maps");
        std::fs::create_dir_all(dir.join("optics")).unwrap();
        let mut p = small_profile();
        let mut p1 = p.projector[0].clone();
        p1.name = "p1".into();
        p1.width_px = 32;
        p.projector.push(p1);
        let map = gray_png(64, 48, |_, _| 200);
        std::fs::write(dir.join("optics/p0-gray-map.png"), &map).unwrap();
        std::fs::write(dir.join("optics/p1-gray-map.png"), &map).unwrap();
        let mut m = manifest(p, vec![]);
        m.totals.layers = 0;
        let sha = sha256_hex(&map);
        m.projector_optics = vec![
            optics(0, "optics/p0-gray-map.png", &sha),
            // Projector 1 is 32 px wide.
            optics(1, "optics/p1-gray-map.png", &sha),
            optics(2, "optics/p2-gray-map.png", &sha),
            optics(0, "/etc/gray-map.png", &sha),
            optics(0, "optics/missing.png", &sha),
        ];
        m.optics = Some(optics(0, "optics/p0-gray-map.png", &"0".repeat(64)));
        m.settings.compensation = "zone".into();
        let v = verify(&dir, &m);
        let got: Vec<(Kind, Option<&str>)> = v
            .problems
            .iter()
            .map(|p| (p.kind, p.file.as_deref()))
            .collect();
        let want = vec![
            (Kind::Manifest, Some("job.json")),
            (Kind::OpticsFile, Some("optics/p2-gray-map.png")),
            (Kind::OpticsFile, Some("/etc/gray-map.png")),
            (Kind::OpticsFile, Some("optics/p0-gray-map.png")),
            (Kind::OpticsFile, Some("optics/p1-gray-map.png")),
            (Kind::OpticsFile, Some("optics/missing.png")),
        ];
        assert_eq!(got, want, "{:#?}", v.problems);
        assert_eq!(v.gray_maps, 4);
        ends(
            &v,
            1,
            "gray map of projector 2: the machine has 2 projectors",
        );
        says(
            &v,
            2,
            "path \"/etc/gray-map.png\" is not a relative path inside the bundle",
        );
        says(&v, 3, "optics/p0-gray-map.png: gray map of projector 0: SHA-256 mismatch (manifest 000000000000");
        says(
            &v,
            4,
            "optics/p1-gray-map.png: gray map of projector 1: PNG is 64x48, projector p1 is 32x48",
        );
        ends(
            &v,
            5,
            "optics/missing.png: gray map of projector 0: gray map file is missing",
        );
        assert!(v.problems.iter().all(|p| p.layer.is_none()));
    }
}
