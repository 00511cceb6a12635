//! Verification of a bundle before it is simulated: the manifest's own consistency, every
//! mask file (present, SHA-256 as recorded, decodable PNG of the projector's resolution
//! and bit depth, its own file), what each layer's masks show against the layer's record
//! (lit pixels where the section is, enough of them for its area), and the light
//! compensation's gray maps. All problems are collected, each naming its file and layer.
//! Files are read, hashed and decoded in parallel (rayon), one file per task, so memory
//! stays at a few masks per thread; a decoded mask leaves only its [`LitPixels`] behind.
//!
//! ## What a layer's masks must show
//! A mask is a top view of the build plane: build-plane point (x, y), measured in mm from
//! the field's bottom-left corner, lands in field column ⌊x/p⌋ and row H − 1 − ⌊y/p⌋ (p
//! the pixel edge, H the field's height in pixels); projector k shows field columns
//! `offset_px[0]..+width_px` and rows `offset_px[1]..+height_px`, mirrored last by its
//! `mirror_x`/`mirror_y`. A mask pixel is nonzero only where the section covers part of
//! it: anti-aliased coverage, binary masks (≥ 50 % coverage), compensated grays and tiled
//! shares all keep zero at zero. So per layer, with the lit boxes of its masks mapped into
//! the field and united (tiled projectors each light their share), `mask-content` is
//! reported when
//! * the layer has no section (`bbox_mm` null, `area_mm2` 0) and its masks light any
//!   pixel;
//! * lit pixels lie outside `bbox_mm` (converted to field pixels) by more than the
//!   tolerance: 1 px, plus `settings.distortion.max_correction_mm`/p + 1 px when the
//!   masks were pre-warped (a record with an area but no `bbox_mm`, from a bundle written
//!   before the box was recorded, is checked for its area only);
//! * the masks light too few pixels for the section. For masks whose values are coverage
//!   (anti-aliased, light compensation off, linear tiled responses) every pixel the
//!   section covers by 1/510 or more is lit, so at least 0.5 × `area_mm2`/p² − 4 pixels,
//!   and one for an area of a pixel or more. In every mode the pixels wholly inside the
//!   section's largest inscribed circle (radius `max_fill_distance_mm`, less the
//!   pre-warp's tolerance) are fully covered and lit: at least max(1, π(r/p − √2)²) of
//!   them once r ≥ √2·p, spanning 2(r/p − √2) px across.
//!
//! With the Z correction (`cure.held_back_layers` > 0) a layer's masks light only what the
//! layers below it also hold, so the last rule is not applied to such jobs.
//!
//! The lit box may fall short of `bbox_mm` by any amount: a sliver of the section thinner
//! than 1/510 of a pixel shows as 0, binary masks leave pixels below 50 % coverage dark
//! and compensated ones those below the lowest usable gray (thin walls, tips, a shorter
//! feature's top).

use super::Violation;
use crate::bundle::machine::{Machine, Projector};
use crate::bundle::{sha256_hex, BundleSource, DirSource, Layer, Manifest, MaskRef, MANIFEST};
use image::codecs::png::PngDecoder;
use image::{ColorType, ImageDecoder};
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::path::{Component, Path, PathBuf};

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

/// The nonzero pixels of an 8-bit gray image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LitPixels {
    /// Number of nonzero pixels.
    pub count: u64,
    /// Their bounding box `[c0, r0, c1, r1]` in the image's pixel coordinates (column,
    /// row from the top-left; the ends exclusive), `None` when no pixel is lit.
    pub bbox: Option<[u32; 4]>,
}

impl LitPixels {
    /// The nonzero pixels of a row-major image `width` pixels wide.
    pub fn of_gray8(width: u32, data: &[u8]) -> LitPixels {
        let mut lit = LitPixels::default();
        if width == 0 {
            return lit;
        }
        // Masks are mostly dark: a dark row costs one vectorized OR over it, a lit one a
        // search from either end and a count over its lit span.
        for (r, row) in data.chunks(width as usize).enumerate() {
            if !any_nonzero(row) {
                continue;
            }
            let first = first_nonzero(row).unwrap_or(0);
            let last = last_nonzero(row).unwrap_or(first);
            // Whole words from the one holding `first`: the bytes before it are zero.
            lit.count += count_nonzero(&row[first / 8 * 8..=last]);
            let (r, c0, c1) = (r as u32, first as u32, last as u32 + 1);
            lit.bbox = Some(match lit.bbox {
                None => [c0, r, c1, r + 1],
                Some([a0, b0, a1, _]) => [a0.min(c0), b0, a1.max(c1), r + 1],
            });
        }
        lit
    }

    /// Both sets of pixels (counts added: pixels lit in both count twice).
    pub fn union(self, other: LitPixels) -> LitPixels {
        LitPixels {
            count: self.count + other.count,
            bbox: match (self.bbox, other.bbox) {
                (Some(a), Some(b)) => Some([
                    a[0].min(b[0]),
                    a[1].min(b[1]),
                    a[2].max(b[2]),
                    a[3].max(b[3]),
                ]),
                (a, b) => a.or(b),
            },
        }
    }

    /// The pixels of projector `p`'s mask as field pixels: mirrored, then offset.
    pub fn in_field(self, p: &Projector) -> LitPixels {
        LitPixels {
            count: self.count,
            bbox: self.bbox.map(|[c0, r0, c1, r1]| {
                let (w, h) = (p.width_px, p.height_px);
                let (c0, c1) = if p.mirror_x {
                    (w.saturating_sub(c1), w.saturating_sub(c0))
                } else {
                    (c0, c1)
                };
                let (r0, r1) = if p.mirror_y {
                    (h.saturating_sub(r1), h.saturating_sub(r0))
                } else {
                    (r0, r1)
                };
                let [ox, oy] = p.offset_px;
                [c0 + ox, r0 + oy, c1 + ox, r1 + oy]
            }),
        }
    }
}

/// Whether any byte of `bytes` is nonzero (an OR over all of them, which vectorizes).
fn any_nonzero(bytes: &[u8]) -> bool {
    bytes.iter().fold(0u8, |a, &v| a | v) != 0
}

/// Index of the first nonzero byte of `row`: the first 32-byte block with one, then eight
/// bytes at a time.
fn first_nonzero(row: &[u8]) -> Option<usize> {
    let blocks = row.chunks_exact(32);
    let start = blocks
        .clone()
        .position(any_nonzero)
        .map_or(row.len() - blocks.remainder().len(), |k| k * 32);
    let rest = &row[start..];
    let words = rest.chunks_exact(8);
    let tail = words.remainder();
    for (k, w) in words.enumerate() {
        let w = u64::from_le_bytes(w.try_into().expect("8 bytes"));
        if w != 0 {
            return Some(start + k * 8 + w.trailing_zeros() as usize / 8);
        }
    }
    let at = row.len() - tail.len();
    tail.iter().position(|&v| v != 0).map(|i| at + i)
}

/// Index of the last nonzero byte of `row`: the last 32-byte block with one (counted from
/// the end), then eight bytes at a time.
fn last_nonzero(row: &[u8]) -> Option<usize> {
    let blocks = row.rchunks_exact(32);
    let end = blocks
        .clone()
        .position(any_nonzero)
        .map_or(blocks.remainder().len(), |k| row.len() - k * 32);
    let rest = &row[..end];
    let words = rest.rchunks_exact(8);
    let head = words.remainder();
    for (k, w) in words.enumerate() {
        let w = u64::from_le_bytes(w.try_into().expect("8 bytes"));
        if w != 0 {
            return Some(end - k * 8 - 1 - w.leading_zeros() as usize / 8);
        }
    }
    head.iter().rposition(|&v| v != 0)
}

/// Number of nonzero bytes in `bytes`, eight at a time: each word's nonzero bytes become
/// 1 in their byte (no carry crosses a byte), summed bytewise over up to 255 words, then
/// across the word.
fn count_nonzero(bytes: &[u8]) -> u64 {
    const LOW7: u64 = 0x7f7f_7f7f_7f7f_7f7f;
    const PAIRS: u64 = 0x00ff_00ff_00ff_00ff;
    let mut total = 0;
    for block in bytes.chunks(8 * 255) {
        let words = block.chunks_exact(8);
        let tail = words.remainder();
        let mut acc = 0u64;
        for w in words {
            let w = u64::from_le_bytes(w.try_into().expect("8 bytes"));
            acc += ((((w & LOW7) + LOW7) | w) & !LOW7) >> 7;
        }
        let pairs = (acc & PAIRS) + ((acc >> 8) & PAIRS);
        total += pairs.wrapping_mul(0x0001_0001_0001_0001) >> 48;
        total += tail.iter().filter(|&&v| v != 0).count() as u64;
    }
    total
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

/// Verifies the manifest's structure and every mask of the bundle at `dir` for the
/// machine the manifest embeds.
pub fn verify(dir: &Path, manifest: &Manifest) -> Verification {
    verify_on(dir, manifest, &manifest.machine)
}

/// [`verify_source`] for the bundle directory `dir`.
pub fn verify_on(dir: &Path, manifest: &Manifest, machine: &Machine) -> Verification {
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
    machine: &Machine,
    shared_masks: bool,
) -> Verification {
    let mut problems = Vec::new();
    let job = dir.shown(MANIFEST);
    let n = manifest.layers.len();
    if n == 0 {
        problems.push(problem(
            None,
            "manifest",
            Some(MANIFEST),
            format!("{}: the job has no layers", job.display()),
        ));
    }
    if manifest.totals.layers != n as u64 {
        problems.push(problem(
            None,
            "manifest",
            Some(MANIFEST),
            format!(
                "{}: totals.layers is {} but the manifest has {n} layer record{}",
                job.display(),
                manifest.totals.layers,
                if n == 1 { "" } else { "s" }
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
                "manifest",
                Some(MANIFEST),
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
                    "manifest",
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
                    "manifest",
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
                        "mask-shared",
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
                "manifest",
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

/// Checks the gray map of every light compensation record (`optics`,
/// `projector_optics`) like a mask, as `optics-file` problems; returns how many.
fn check_gray_maps(
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
    let mut found = Vec::new();
    let mut files = Vec::new();
    for o in &records {
        let file = o.gray_map.as_str();
        let what = format!("gray map of projector {}", o.projector);
        let Some(proj) = machine.projector.get(o.projector as usize) else {
            found.push(problem(
                None,
                "optics-file",
                Some(file),
                format!(
                    "{}: {what}: the machine has {} projector(s)",
                    dir.shown(file).display(),
                    machine.projector.len()
                ),
            ));
            continue;
        };
        if !is_inside(file) {
            found.push(problem(
                None,
                "optics-file",
                Some(file),
                format!(
                    "{}: {what}: path {file:?} is not a relative path inside the bundle",
                    dir.shown(MANIFEST).display()
                ),
            ));
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
            found.push(problem(None, "optics-file", Some(file), msg));
        }
    }
    problems.extend(found);
    files.len()
}

/// A relative path made only of normal components.
fn is_inside(rel: &str) -> bool {
    let p = Path::new(rel);
    !rel.is_empty() && p.components().all(|c| matches!(c, Component::Normal(_)))
}

/// What can be wrong with a PNG file of the bundle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FileFault {
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
    fn mask_kind(self) -> &'static str {
        match self {
            FileFault::Missing => "mask-missing",
            FileFault::Checksum => "mask-checksum",
            FileFault::Decode => "mask-decode",
            FileFault::Format => "mask-format",
        }
    }
}

/// One PNG file checked.
struct PngCheck {
    /// Bytes read.
    bytes: u64,
    /// What is wrong, with a message naming the file.
    faults: Vec<(FileFault, String)>,
    /// Its nonzero pixels, when it decoded.
    lit: Option<LitPixels>,
}

/// Checks one gray PNG of the bundle (`rel`): present, SHA-256 `sha256`, a PNG of
/// projector `proj`'s size in 8-bit gray whose pixel data decode to the end. Messages
/// read "PATH: `what`: ..."; `noun` names the file's role ("mask", "gray map").
fn check_png(
    dir: &dyn BundleSource,
    rel: &str,
    sha256: &str,
    proj: &Projector,
    what: &str,
    noun: &str,
    buf: &mut Vec<u8>,
) -> PngCheck {
    let path = dir.shown(rel);
    let shown = path.display();
    let mut out = PngCheck {
        bytes: 0,
        faults: Vec::new(),
        lit: None,
    };
    let bytes = match dir.read(rel) {
        Ok(b) => b,
        Err(e) => {
            let msg = if e.kind() == std::io::ErrorKind::NotFound {
                format!("{shown}: {what}: {noun} file is missing")
            } else {
                format!("{shown}: {what}: cannot read {noun}: {e}")
            };
            out.faults.push((FileFault::Missing, msg));
            return out;
        }
    };
    out.bytes = bytes.len() as u64;
    let sha = sha256_hex(&bytes);
    if !sha.eq_ignore_ascii_case(sha256) {
        out.faults.push((
            FileFault::Checksum,
            format!(
                "{shown}: {what}: SHA-256 mismatch (manifest {}, file {})",
                short(sha256),
                short(&sha)
            ),
        ));
    }
    let dec = match PngDecoder::new(std::io::Cursor::new(&bytes)) {
        Ok(d) => d,
        Err(e) => {
            out.faults.push((
                FileFault::Decode,
                format!("{shown}: {what}: not a decodable PNG: {e}"),
            ));
            return out;
        }
    };
    let (w, h) = dec.dimensions();
    let ct = dec.color_type();
    let mut format_ok = true;
    if ct != ColorType::L8 {
        format_ok = false;
        out.faults.push((
            FileFault::Format,
            format!("{shown}: {what}: PNG is {ct:?}, expected 8-bit grayscale (L8)"),
        ));
    }
    if (w, h) != (proj.width_px, proj.height_px) {
        format_ok = false;
        out.faults.push((
            FileFault::Format,
            format!(
                "{shown}: {what}: PNG is {w}x{h}, projector {} is {}x{}",
                proj.name, proj.width_px, proj.height_px
            ),
        ));
    }
    let most = crate::formats::DEFLATE_MAX_RATIO.saturating_mul(out.bytes);
    if format_ok && dec.total_bytes() > most {
        // A header of the projector's size on a file too small to hold its pixels (a
        // large imported display): refused before anything is allocated for them.
        out.faults.push((
            FileFault::Decode,
            format!(
                "{shown}: {what}: PNG declares {w}x{h} pixels, more than its {} bytes can hold",
                out.bytes
            ),
        ));
        return out;
    }
    if format_ok {
        // Decode the pixels: a PNG whose header is fine may still be truncated or corrupt.
        buf.resize(dec.total_bytes() as usize, 0);
        match dec.read_image(buf) {
            Ok(()) => out.lit = Some(LitPixels::of_gray8(w, buf)),
            Err(e) => out.faults.push((
                FileFault::Decode,
                format!("{shown}: {what}: PNG does not decode: {e}"),
            )),
        }
    }
    out
}

fn short(hex: &str) -> &str {
    hex.get(..12).unwrap_or(hex)
}

/// Lit pixels a section's masks may miss below half its area (coverage masks), px².
const AREA_SLACK_PX: f64 = 4.0;

/// How a job's masks must agree with its layer records (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
struct ContentRule {
    /// Pixel edge, mm.
    pixel_mm: f64,
    /// Field height, px.
    field_h_px: f64,
    /// How far the lit box may pass the section's box, px.
    tol_px: f64,
    /// How far the pre-warp may move the section, mm (0 without).
    warp_mm: f64,
    /// Mask values are coverage: every pixel the section covers noticeably is lit.
    coverage: bool,
    /// The Z correction held back downward-facing surfaces (`cure.held_back_layers` > 0):
    /// a layer's masks may light less than its section, down to nothing.
    held_back: bool,
}

impl ContentRule {
    /// The rule for `manifest`'s masks shown by `machine`.
    fn of(manifest: &Manifest, machine: &Machine) -> ContentRule {
        let field = machine.field();
        let p = field.pixel_mm;
        let warp_mm = manifest
            .settings
            .distortion
            .as_ref()
            .map_or(0.0, |d| d.max_correction_mm.max(0.0) + p);
        let made = &manifest.machine;
        let linear =
            made.projector.len() <= 1 || made.projector.iter().all(|p| p.calibration.is_none());
        ContentRule {
            pixel_mm: p,
            field_h_px: field.height_px as f64,
            tol_px: 1.0 + warp_mm / p,
            warp_mm,
            coverage: !manifest.settings.binary
                && manifest.settings.compensation == "off"
                && linear,
            held_back: manifest
                .cure
                .as_ref()
                .is_some_and(|c| c.held_back_layers > 0),
        }
    }

    /// The fewest lit pixels the masks of `layer` may have.
    fn min_lit(&self, layer: &Layer) -> f64 {
        let p = self.pixel_mm;
        let area_px = layer.area_mm2 / (p * p);
        let mut min: f64 = 0.0;
        if layer.area_mm2 <= 0.0 || self.held_back {
            // No section: nothing must be lit. Held back (`xyz`): a layer over nothing
            // lights only what its layers below also hold, possibly nothing.
            return min;
        }
        if self.coverage {
            if area_px >= 1.0 {
                min = 1.0;
            }
            min = min.max(0.5 * area_px - AREA_SLACK_PX);
        }
        // Pixels wholly inside the largest inscribed circle are fully covered.
        let r = (layer.max_fill_distance_mm - self.warp_mm) / p;
        if r >= std::f64::consts::SQRT_2 {
            let inner = self.inner_radius_px(layer);
            min = min.max((std::f64::consts::PI * inner * inner).max(1.0));
        }
        min
    }

    /// The radius of the circle, concentric with the section's largest inscribed circle
    /// (moved by the pre-warp), whose every pixel lies wholly inside the section, px (0
    /// when there is none).
    fn inner_radius_px(&self, layer: &Layer) -> f64 {
        let r = (layer.max_fill_distance_mm - self.warp_mm) / self.pixel_mm;
        (r - std::f64::consts::SQRT_2).max(0.0)
    }

    /// Checks layer `i`'s masks, whose lit pixels in field coordinates are `px`.
    fn check(
        &self,
        dir: &dyn BundleSource,
        i: usize,
        layer: &Layer,
        px: LitPixels,
        masks: &[&MaskRef],
    ) -> Option<Violation> {
        let file = masks.first()?.file.as_str();
        let files: Vec<&str> = masks.iter().map(|m| m.file.as_str()).collect();
        let shown = format!("{}", dir.shown(&files.join(", ")).display());
        let at = |msg: String| {
            Some(problem(
                Some(i),
                "mask-content",
                Some(file),
                format!("{shown}: layer {i}: {msg}"),
            ))
        };
        let lit_text = |b: [u32; 4]| {
            format!(
                "columns {}..{}, rows {}..{}",
                b[0],
                b[2] - 1,
                b[1],
                b[3] - 1
            )
        };
        if let (None, true, Some(b)) = (layer.bbox_mm, layer.area_mm2 <= 0.0, px.bbox) {
            return at(format!(
                "the layer has no section (bbox_mm null) but its masks light {} pixel(s) ({} of the field)",
                px.count,
                lit_text(b)
            ));
        }
        let min = self.min_lit(layer);
        let Some(b) = px.bbox else {
            if min < 1.0 {
                return None;
            }
            return at(format!(
                "the section's area is {:.3} mm² but its masks light no pixel",
                layer.area_mm2
            ));
        };
        let p = self.pixel_mm;
        let got = b.map(f64::from);
        // A section's box (bundles written before it was recorded have an area but none).
        if let Some(bb) = layer.bbox_mm {
            // The section's box in field pixel coordinates: columns x/p, rows H − y/p.
            let want = [
                bb[0][0] / p,
                self.field_h_px - bb[1][1] / p,
                bb[1][0] / p,
                self.field_h_px - bb[0][1] / p,
            ];
            let tol = self.tol_px + 1e-3;
            let outside = got[0] < want[0] - tol
                || got[1] < want[1] - tol
                || got[2] > want[2] + tol
                || got[3] > want[3] + tol;
            if outside {
                // The pixels the section's box touches.
                let touched = [
                    want[0].floor().max(0.0) as u32,
                    want[1].floor().max(0.0) as u32,
                    (want[2].ceil() as u32).max(1),
                    (want[3].ceil() as u32).max(1),
                ];
                let [[x0, y0], [x1, y1]] = bb;
                return at(format!(
                    "its masks light {} of the field, outside the section \
                     (bbox_mm [[{x0}, {y0}], [{x1}, {y1}]] covers {}; tolerance {:.1} px)",
                    lit_text(b),
                    lit_text(touched),
                    self.tol_px,
                ));
            }
        }
        // The pixels wholly inside the largest inscribed circle are lit: the lit box is at
        // least as wide and as high as the circle less a pixel diagonal on each side.
        let inner = 2.0 * (self.inner_radius_px(layer) - 1e-3);
        let (w, h) = (got[2] - got[0], got[3] - got[1]);
        if w < inner || h < inner {
            return at(format!(
                "its masks light {} of the field ({w}x{h} px), less than the section's largest inscribed circle (max_fill_distance_mm {}) leaves lit ({inner:.1} px across)",
                lit_text(b),
                layer.max_fill_distance_mm,
            ));
        }
        if (px.count as f64) < min {
            return at(format!(
                "its masks light {} pixel(s) ({:.3} mm²), too few for the section's area {:.3} mm² (at least {:.0} expected)",
                px.count,
                px.count as f64 * p * p,
                layer.area_mm2,
                min.ceil()
            ));
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bundle::{Mode, Step};
    use crate::exec::testutil::*;
    use crate::profile::Profile;
    use image::codecs::png::PngEncoder;
    use image::{ExtendedColorType, ImageEncoder};

    /// The default projector's pixel, mm.
    const PX: f64 = 0.0634765625;

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

    /// A `w`×`h` gray PNG with `f(column, row)` as pixel values.
    fn gray_png(w: u32, h: u32, f: impl Fn(u32, u32) -> u8) -> Vec<u8> {
        let px: Vec<u8> = (0..h)
            .flat_map(|r| (0..w).map(move |c| (c, r)))
            .map(|(c, r)| f(c, r))
            .collect();
        let mut out = Vec::new();
        PngEncoder::new(&mut out)
            .write_image(&px, w, h, ExtendedColorType::L8)
            .unwrap();
        out
    }

    /// Value `v` inside columns c0..c1, rows r0..r1 (ends exclusive), else 0.
    fn rect(c0: u32, r0: u32, c1: u32, r1: u32, v: u8) -> impl Fn(u32, u32) -> u8 {
        move |c, r| {
            if (c0..c1).contains(&c) && (r0..r1).contains(&r) {
                v
            } else {
                0
            }
        }
    }

    /// A scratch bundle directory with `masks/`.
    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("dmdsl-verify-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("masks")).unwrap();
        dir
    }

    /// Layer `i` (0.1 mm, one exposure) whose mask file holds `png`, with section box
    /// `bbox_px` = [c0, r0, c1, r1] in pixels of a 64×48 field (None: no section) and
    /// area `area_px` pixels.
    fn layer_with(
        dir: &Path,
        i: usize,
        png: &[u8],
        bbox_px: Option<[f64; 4]>,
        area_px: f64,
    ) -> Layer {
        let mut l = layer(
            i,
            0.1 * (i + 1) as f64,
            0.1,
            Mode::Layered,
            1.0,
            vec![],
            0.0,
        );
        std::fs::write(dir.join(&l.masks[0].file), png).unwrap();
        l.masks[0].sha256 = sha256_hex(png);
        // Rows count from the top: y = (48 − row)·p.
        l.bbox_mm = bbox_px
            .map(|[c0, r0, c1, r1]| [[c0 * PX, (48.0 - r1) * PX], [c1 * PX, (48.0 - r0) * PX]]);
        l.area_mm2 = area_px * PX * PX;
        l
    }

    fn small_profile() -> Profile {
        let mut p = profile();
        p.projector[0].width_px = 64;
        p.projector[0].height_px = 48;
        p
    }

    fn found(v: &Verification) -> Vec<(Option<usize>, &str)> {
        v.problems.iter().map(|p| (p.layer, p.kind)).collect()
    }

    #[test]
    fn first_and_last_nonzero_byte_and_their_count() {
        for n in [0, 1, 7, 8, 9, 16, 17, 31, 32, 33, 40, 64, 65, 100] {
            for a in 0..n {
                for b in a..n {
                    let mut row = vec![0u8; n];
                    row[a] = 3;
                    row[b] = 1;
                    assert_eq!(first_nonzero(&row), Some(a), "{n} {a} {b}");
                    assert_eq!(last_nonzero(&row), Some(b), "{n} {a} {b}");
                    assert!(any_nonzero(&row));
                    assert_eq!(count_nonzero(&row), 1 + (a != b) as u64);
                }
            }
            assert_eq!(first_nonzero(&vec![0; n]), None);
            assert_eq!(last_nonzero(&vec![0; n]), None);
            assert!(!any_nonzero(&vec![0; n]));
        }
        // Counts past a byte's and a block's capacity.
        let row: Vec<u8> = (0..5000u32).map(|i| (i % 7) as u8 * 40).collect();
        let naive = row.iter().filter(|&&v| v != 0).count() as u64;
        assert_eq!(count_nonzero(&row), naive);
        assert_eq!(count_nonzero(&[255; 4096]), 4096);
        assert_eq!(count_nonzero(&[1; 4097]), 4097);
    }

    #[test]
    fn lit_pixels_and_their_place_in_the_field() {
        let data: Vec<u8> = (0..6 * 4)
            .map(|i| [0, 0, 7, 0, 9, 0][i % 6] * (i / 6 % 2) as u8)
            .collect();
        // Rows 1 and 3 light columns 2 and 4.
        let lit = LitPixels::of_gray8(6, &data);
        assert_eq!(
            lit,
            LitPixels {
                count: 4,
                bbox: Some([2, 1, 5, 4])
            }
        );
        assert_eq!(LitPixels::of_gray8(6, &[0; 24]), LitPixels::default());
        let mut p = Machine::of(&small_profile()).projector.remove(0);
        p.width_px = 6;
        p.height_px = 4;
        p.offset_px = [100, 10];
        assert_eq!(lit.in_field(&p).bbox, Some([102, 11, 105, 14]));
        p.mirror_x = true;
        // Columns 2..5 of 6 mirrored are 1..4.
        assert_eq!(lit.in_field(&p).bbox, Some([101, 11, 104, 14]));
        p.mirror_y = true;
        // Rows 1..4 of 4 mirrored are 0..3.
        assert_eq!(lit.in_field(&p).bbox, Some([101, 10, 104, 13]));
        let u = lit.union(LitPixels {
            count: 1,
            bbox: Some([0, 3, 1, 9]),
        });
        assert_eq!(
            u,
            LitPixels {
                count: 5,
                bbox: Some([0, 1, 5, 9])
            }
        );
        assert_eq!(LitPixels::default().union(lit), lit);
    }

    #[test]
    fn masks_that_do_not_show_their_layer_are_found() {
        let dir = scratch("content");
        let white = gray_png(64, 48, |_, _| 255);
        let black = gray_png(64, 48, |_, _| 0);
        // A 20×10 px rectangle with anti-aliased (half-covered) edge pixels around it.
        let soft = gray_png(64, 48, |c, r| {
            let inside = |a: u32, lo: u32, hi: u32| (lo..hi).contains(&a);
            if inside(c, 10, 30) && inside(r, 5, 15) {
                255
            } else if inside(c, 9, 31) && inside(r, 4, 16) {
                128
            } else {
                0
            }
        });
        let section = Some([9.5, 4.5, 30.5, 15.5]);
        let area = 21.0 * 11.0;
        let layers = vec![
            // 0: as sliced.
            layer_with(&dir, 0, &soft, section, area),
            // 1: all white.
            layer_with(&dir, 1, &white, section, area),
            // 2: all black.
            layer_with(&dir, 2, &black, section, area),
            // 3: no section, lit.
            layer_with(&dir, 3, &soft, None, 0.0),
            // 4: no section, dark: fine.
            layer_with(&dir, 4, &black, None, 0.0),
            // 5: a 4×4 px patch inside the section's box.
            layer_with(
                &dir,
                5,
                &gray_png(64, 48, rect(12, 6, 16, 10, 255)),
                section,
                area,
            ),
            // 6: another layer's mask, moved: lit 3 px right of the section.
            layer_with(
                &dir,
                6,
                &gray_png(64, 48, rect(13, 5, 34, 15, 255)),
                section,
                area,
            ),
            // 7: a sliver too small to show: dark is fine.
            layer_with(&dir, 7, &black, Some([40.0, 40.0, 40.002, 41.0]), 0.002),
            // 8: lit within a pixel of the section's box: fine.
            layer_with(
                &dir,
                8,
                &gray_png(64, 48, rect(9, 4, 31, 16, 255)),
                section,
                area,
            ),
            // 9 and 10: an area but no box (bundles from before it was recorded): the
            // area is checked, the box cannot be.
            layer_with(&dir, 9, &soft, None, area),
            layer_with(&dir, 10, &black, None, area),
        ];
        let m = manifest(small_profile(), layers);
        let v = verify(&dir, &m);
        assert_eq!(
            found(&v),
            vec![
                (Some(1), "mask-content"),
                (Some(2), "mask-content"),
                (Some(3), "mask-content"),
                (Some(5), "mask-content"),
                (Some(6), "mask-content"),
                (Some(10), "mask-content"),
            ],
            "{:#?}",
            v.problems
        );
        let msg = |i: usize| v.problems[i].message.clone();
        assert!(msg(0).contains("masks/00001.png: layer 1: its masks light columns 0..63, rows 0..47 of the field, outside the section"), "{}", msg(0));
        assert!(
            msg(0).contains("covers columns 9..30, rows 4..15"),
            "{}",
            msg(0)
        );
        assert!(
            msg(1)
                .contains("layer 2: the section's area is 0.931 mm² but its masks light no pixel"),
            "{}",
            msg(1)
        );
        assert!(
            msg(2).contains(
                "layer 3: the layer has no section (bbox_mm null) but its masks light 264 pixel(s)"
            ),
            "{}",
            msg(2)
        );
        assert!(msg(3).contains("layer 5: its masks light 16 pixel(s) (0.064 mm²), too few for the section's area 0.931 mm² (at least 112 expected)"), "{}", msg(3));
        assert!(
            msg(4).contains("layer 6: its masks light columns 13..33, rows 5..14"),
            "{}",
            msg(4)
        );
        assert_eq!(v.problems[0].file.as_deref(), Some("masks/00001.png"));

        // Binary and compensated masks may leave thin parts dark: only the largest
        // inscribed circle's pixels must be lit.
        let mut m = m;
        m.settings.binary = true;
        let v = verify(&dir, &m);
        assert_eq!(
            found(&v),
            vec![
                (Some(1), "mask-content"),
                (Some(3), "mask-content"),
                (Some(6), "mask-content")
            ],
            "{:#?}",
            v.problems
        );
        // A section 11 px high holds a circle of 5.5 px: 4.1 px wholly lit around its centre.
        for l in &mut m.layers {
            l.max_fill_distance_mm = 5.5 * PX;
        }
        m.settings.binary = false;
        m.settings.compensation = "zone".into();
        let v = verify(&dir, &m);
        assert_eq!(
            found(&v),
            vec![
                (Some(1), "mask-content"),
                (Some(2), "mask-content"),
                (Some(3), "mask-content"),
                (Some(5), "mask-content"),
                (Some(6), "mask-content"),
                (Some(7), "mask-content"),
                (Some(10), "mask-content"),
            ],
            "{:#?}",
            v.problems
        );
        assert!(
            v.problems[3]
                .message
                .contains("(4x4 px), less than the section's largest inscribed circle"),
            "{}",
            v.problems[3].message
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_header_larger_than_its_file_can_hold_is_refused_before_decoding() {
        let dir = scratch("huge-header");
        // A 64 × 48 PNG whose header says 4096 × 4096 (its CRC recomputed), shown by a
        // projector of that size: 16 Mpx from about a hundred bytes.
        let mut b = png(64, 48, ExtendedColorType::L8);
        b[16..20].copy_from_slice(&4096u32.to_be_bytes());
        b[20..24].copy_from_slice(&4096u32.to_be_bytes());
        let crc = crc32fast::hash(&b[12..29]);
        b[29..33].copy_from_slice(&crc.to_be_bytes());
        let mut p = profile();
        p.projector[0].width_px = 4096;
        p.projector[0].height_px = 4096;
        let mut l = layer(0, 0.1, 0.1, Mode::Layered, 1.0, vec![], 0.0);
        std::fs::write(dir.join(&l.masks[0].file), &b).unwrap();
        l.masks[0].sha256 = sha256_hex(&b);
        let v = verify(&dir, &manifest(p, vec![l]));
        assert_eq!(found(&v), vec![(Some(0), "mask-decode")]);
        assert!(
            v.problems[0]
                .message
                .contains("declares 4096x4096 pixels, more than its"),
            "{}",
            v.problems[0].message
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn held_back_layers_may_light_less_than_their_section() {
        let dir = scratch("held");
        // A section of 200 px whose mask lights nothing: the first layer of an overhang
        // the Z correction holds back.
        let dark = gray_png(64, 48, |_, _| 0);
        let mut m = manifest(
            small_profile(),
            vec![layer_with(
                &dir,
                0,
                &dark,
                Some([10.0, 5.0, 30.0, 15.0]),
                200.0,
            )],
        );
        assert_eq!(found(&verify(&dir, &m)), vec![(Some(0), "mask-content")]);
        let cure = |held: u32| -> crate::bundle::Cure {
            serde_json::from_value(serde_json::json!({
                "psf_sigma_px": 0.5, "pixel_mm": PX, "dp_mm": 0.15, "ec_mj_cm2": 10.0,
                "overcure_mm": 0.03, "layer_mm": 0.1, "edge_threshold": 0.2,
                "correction": if held > 0 { "xyz" } else { "xy" }, "shift_px": 0.49,
                "print_through_mm": 0.2, "held_back_layers": held
            }))
            .unwrap()
        };
        m.cure = Some(cure(0));
        assert_eq!(found(&verify(&dir, &m)), vec![(Some(0), "mask-content")]);
        m.cure = Some(cure(4));
        assert_eq!(found(&verify(&dir, &m)), vec![]);
        // Light outside the section's box is still found.
        let outside = gray_png(64, 48, rect(40, 5, 50, 15, 255));
        m.layers = vec![layer_with(
            &dir,
            0,
            &outside,
            Some([10.0, 5.0, 30.0, 15.0]),
            200.0,
        )];
        assert_eq!(found(&verify(&dir, &m)), vec![(Some(0), "mask-content")]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn pre_warped_masks_may_move_by_the_largest_correction() {
        let dir = scratch("warp");
        // Lit 3 px right of the section: beyond 1 px, within 1 + 0.1 mm / p + 1 = 3.6 px.
        let moved = gray_png(64, 48, rect(13, 5, 33, 15, 255));
        let mut m = manifest(
            small_profile(),
            vec![layer_with(
                &dir,
                0,
                &moved,
                Some([10.0, 5.0, 30.0, 15.0]),
                200.0,
            )],
        );
        assert_eq!(found(&verify(&dir, &m)), vec![(Some(0), "mask-content")]);
        let fit: crate::bundle::FitReport = serde_json::from_value(serde_json::json!({
            "source": "lens.csv", "sha256": "", "points": 9, "degree": 2,
            "residual_weight": 0.0, "poly_rms_mm": 0.0, "poly_max_mm": 0.0,
            "poly_max_at": "", "cv_rms_mm": 0.0, "cv_max_mm": 0.0, "cv_max_at": "",
            "max_correction_mm": 0.1, "extrapolated_points": 0
        }))
        .unwrap();
        m.settings.distortion = Some(fit);
        assert_eq!(found(&verify(&dir, &m)), vec![]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn tiled_masks_show_their_share_of_the_layer() {
        let dir = scratch("tiled");
        std::fs::create_dir_all(dir.join("masks/p1")).unwrap();
        // Two 32×48 projectors side by side, the second mirrored in x; the section spans
        // columns 20..44 of the 64 px field.
        let mut p = small_profile();
        p.projector[0].width_px = 32;
        let mut p1 = p.projector[0].clone();
        p1.name = "p1".into();
        p1.offset_px = [32, 0];
        p1.mirror_x = true;
        p.projector.push(p1);
        let left = gray_png(32, 48, rect(20, 10, 32, 20, 255));
        // Field columns 32..44 are projector columns 20..32 once mirrored.
        let right = gray_png(32, 48, rect(20, 10, 32, 20, 255));
        let mut l = layer_with(&dir, 0, &left, Some([20.0, 10.0, 44.0, 20.0]), 240.0);
        l.masks.push(MaskRef {
            file: "masks/p1/00000.png".into(),
            sha256: sha256_hex(&right),
            projector: 1,
        });
        std::fs::write(dir.join("masks/p1/00000.png"), &right).unwrap();
        let mut m = manifest(p, vec![l]);
        assert_eq!(found(&verify(&dir, &m)), vec![]);
        // Unmirrored, the second projector's share lands at field columns 52..64.
        m.machine.projector[1].mirror_x = false;
        let v = verify(&dir, &m);
        assert_eq!(found(&v), vec![(Some(0), "mask-content")]);
        assert!(
            v.problems[0].message.contains(
                "masks/00000.png, masks/p1/00000.png: layer 0: its masks light columns 20..63"
            ),
            "{}",
            v.problems[0].message
        );
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
            vec![(Some(2), "mask-shared")],
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
        assert_eq!(found(&v), vec![(None, "manifest")]);
        assert!(v.problems[0]
            .message
            .ends_with("job.json: the job has no layers"));
        let _ = std::fs::remove_dir_all(&dir);
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
        let dir = scratch("gray-maps");
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
        let v = verify(&dir, &m);
        let got: Vec<(&str, Option<&str>)> = v
            .problems
            .iter()
            .map(|p| (p.kind, p.file.as_deref()))
            .collect();
        assert_eq!(
            got,
            vec![
                ("manifest", Some("job.json")),
                ("optics-file", Some("optics/p2-gray-map.png")),
                ("optics-file", Some("/etc/gray-map.png")),
                ("optics-file", Some("optics/p0-gray-map.png")),
                ("optics-file", Some("optics/p1-gray-map.png")),
                ("optics-file", Some("optics/missing.png")),
            ],
            "{:#?}",
            v.problems
        );
        assert_eq!(v.gray_maps, 4);
        let msg = |i: usize| v.problems[i].message.clone();
        assert!(
            msg(1).ends_with("gray map of projector 2: the machine has 2 projector(s)"),
            "{}",
            msg(1)
        );
        assert!(
            msg(2).contains("path \"/etc/gray-map.png\" is not a relative path inside the bundle"),
            "{}",
            msg(2)
        );
        assert!(msg(3).contains("optics/p0-gray-map.png: gray map of projector 0: SHA-256 mismatch (manifest 000000000000"), "{}", msg(3));
        assert!(msg(4).contains("optics/p1-gray-map.png: gray map of projector 1: PNG is 64x48, projector p1 is 32x48"), "{}", msg(4));
        assert!(
            msg(5)
                .ends_with("optics/missing.png: gray map of projector 0: gray map file is missing"),
            "{}",
            msg(5)
        );
        assert!(v.problems.iter().all(|p| p.layer.is_none()));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
