//! Opening a job in any form `dmdsl run` and `dmdsl inspect` accept, as a native
//! [`Manifest`] and a [`BundleSource`] for its files:
//!
//! * a bundle directory (`part.dmdjob/`);
//! * a zipped bundle (`part.dmdjob.zip`: the same files, `job.json` at the top, or all of
//!   them in one folder `NAME/` holding `NAME/job.json`);
//! * a PrusaSlicer SL1 / SL1S file ([`sl1`]): `config.ini`, `prusaslicer.ini` and one PNG a
//!   layer, turned into layers and steps that reproduce PrusaSlicer 2.5's print-time
//!   model on the machine the file describes;
//! * an SLA control-file standard zip, schema v5 ([`control`]): the print-settings JSON
//!   and `slices/`, turned into layers and steps from its position and image settings.
//!
//! The form is found from the content, not the extension: a directory is a bundle; a zip
//! holding `job.json` is a zipped bundle, one holding `config.ini` and `prusaslicer.ini`
//! is SL1, one holding a top-level `.json` with `Header` and `Design` objects is a
//! control file. Zips are read whole into memory by [`archive::read`], which
//! refuses anything unsafe; nothing is extracted.
//!
//! An imported job's layer records come from its masks (lit area and box), so the
//! executor's verification checks them for what can be wrong with a foreign file (a mask
//! missing, undecodable, of the wrong size or colour type); a missing setting or a file
//! that cannot be a job of the format is an error.

pub mod archive;
pub mod control;
mod format;
mod native;
pub mod sl1;

use crate::bundle::{
    BundleSource, DirSource, Generator, Layer, Machine, Manifest, MemSource, Placement, Settings,
    Source, Totals, MANIFEST,
};
use crate::error::{Error, Result};
use crate::warning::Warning;
use archive::read::{read_zip_bytes, Archive, Limits};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

pub use format::Format;

/// Where an imported job's total time estimate comes from, when not from dmdsl's planner.
#[derive(Debug, Clone, PartialEq)]
pub struct ForeignEstimate {
    /// Who made it and where it is, e.g. "PrusaSlicer printTime (config.ini)".
    pub source: String,
    /// The estimate, s (the manifest's `totals.print_time_s`).
    pub print_time_s: f64,
}

/// A job opened for the executor or `inspect`.
pub struct Job {
    /// The path as given.
    pub path: PathBuf,
    /// The form it came in.
    pub format: Format,
    /// The manifest (native, or built by the importer).
    pub manifest: Manifest,
    /// Its files.
    pub source: Box<dyn BundleSource>,
    /// The estimate the file carried, for imported jobs that carry one.
    pub estimate: Option<ForeignEstimate>,
}

impl std::fmt::Debug for Job {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Job")
            .field("path", &self.path)
            .field("format", &self.format)
            .field("layers", &self.manifest.layers.len())
            .finish_non_exhaustive()
    }
}

/// Opens the job at `path`: a bundle directory, or a file whose content says what it is
/// (see the module docs).
pub fn open(path: &Path) -> Result<Job> {
    let meta = std::fs::metadata(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            Error::io(
                path,
                std::io::Error::new(std::io::ErrorKind::NotFound, "does not exist"),
            )
        } else {
            Error::io(path, e)
        }
    })?;
    if meta.is_dir() {
        let manifest = Manifest::read(path)?;
        return Ok(Job {
            path: path.into(),
            format: Format::Dmdjob,
            manifest,
            source: Box::new(DirSource::new(path)),
            estimate: None,
        });
    }
    let limits = Limits::default();
    let bytes = crate::input::read_file(path, "job", limits.max_archive_bytes)?;
    if !archive::read::looks_like_zip(&bytes) {
        return Err(Error::Bundle {
            path: path.into(),
            msg: "not a job: neither a bundle directory nor a zip archive (a zipped bundle, an SL1/SL1S file or an SLA control-file zip)".into(),
        });
    }
    let archive = read_zip_bytes(path, &bytes, &limits)?;
    let sha256 = crate::digest::sha256_hex(&bytes);
    drop(bytes);
    if archive.get(MANIFEST).is_some() {
        return open_zipped_bundle(archive, "");
    }
    if let Some(dir) = bundle_folder(&archive) {
        return open_zipped_bundle(archive, &dir);
    }
    if archive.get(sl1::CONFIG).is_some() && archive.get(sl1::PRUSASLICER).is_some() {
        return sl1::import(archive, &sha256);
    }
    if let Some(name) = control::settings_entry(&archive) {
        return control::import(archive, &name, &sha256);
    }
    Err(archive.error(
        None,
        format!(
            "not a job: no `{MANIFEST}` (zipped bundle), no `{}` + `{}` (SL1/SL1S), no print-settings JSON (SLA control file) at the top of the archive",
            sl1::CONFIG,
            sl1::PRUSASLICER
        ),
    ))
}

/// The folder `NAME/` every entry of `archive` is in, when it holds `NAME/job.json` (a
/// bundle directory zipped with its folder).
fn bundle_folder(archive: &Archive) -> Option<String> {
    let first = archive.names().first()?;
    let dir = &first[..first.find('/')? + 1];
    (archive.get(&format!("{dir}{MANIFEST}")).is_some()
        && archive.names().iter().all(|n| n.starts_with(dir)))
    .then(|| dir.to_string())
}

/// A zipped bundle: its `job.json` read as a bundle directory's; `dir` is the folder the
/// bundle's files are in inside the archive (empty: at the top).
fn open_zipped_bundle(archive: Archive, dir: &str) -> Result<Job> {
    let path = archive.path().to_path_buf();
    let text = archive.get(&format!("{dir}{MANIFEST}")).unwrap_or_default();
    let manifest = Manifest::from_json(text, &path.join(dir).join(MANIFEST))?;
    let files = archive
        .into_files()
        .into_iter()
        .map(|(k, v)| (k[dir.len()..].to_string(), v))
        .collect();
    Ok(Job {
        source: Box::new(MemSource::new(&path.join(dir), files)),
        path,
        format: Format::DmdjobZip,
        manifest,
        estimate: None,
    })
}

/// The parts of a manifest every importer fills the same way.
pub(crate) struct ManifestParts {
    /// Who wrote the file, e.g. "PrusaSlicer-2.5.0".
    pub generator: String,
    /// The imported file's SHA-256.
    pub sha256: String,
    /// The machine the file implies.
    pub machine: crate::bundle::Machine,
    /// Nominal layer height, mm.
    pub layer_height_mm: f64,
    /// Whether the masks are binary.
    pub binary: bool,
    /// The layers.
    pub layers: Vec<Layer>,
    /// The file's own total time estimate, if it has one; otherwise the sum of the
    /// layers' `time_s`.
    pub print_time_s: Option<f64>,
}

/// What an importer knows of the machine a file implies.
pub(crate) struct Implied<'a> {
    /// The record's name, e.g. `sl1-import-sl1`.
    pub name: String,
    /// The resin the file names (empty when it names none).
    pub resin: String,
    /// The projector's name.
    pub projector: &'a str,
    /// The images' size, px.
    pub size_px: (u32, u32),
    /// Pixel edge, mm.
    pub pixel_mm: f64,
    /// Highest stage position, mm.
    pub travel_max_mm: f64,
    /// Stage speed limit, mm/s.
    pub max_speed_mm_s: f64,
    /// Stage acceleration limit, mm/s².
    pub max_accel_mm_s2: f64,
    /// Stage resolution, steps per mm.
    pub steps_per_mm: f64,
}

impl Implied<'_> {
    /// The machine record: a bottom-up stage from 0 (home) to `travel_max_mm`, no shutter
    /// or DMD latency, one projector showing the images as they are (no offset, mirroring
    /// or calibration); the normal exposure is the last layer's. The error names the value
    /// out of range.
    pub(crate) fn machine(self, layers: &[Layer]) -> std::result::Result<Machine, String> {
        use crate::bundle::machine::{Dmd, Exposure, Projector, Resin, Shutter, Stage};
        use crate::units::{NonNegative, Positive};
        let pos = |v: f64, what: &str| {
            Positive::new(v).ok_or_else(|| format!("{what} = {v} is not positive"))
        };
        let zero = NonNegative::default();
        let last_s = layers.last().map_or(0.0, |l| l.exposure_s);
        let m = Machine {
            name: self.name,
            process: crate::profile::Process::BottomUp,
            stage: Stage {
                travel_min_mm: 0.0,
                travel_max_mm: self.travel_max_mm,
                home_mm: 0.0,
                max_speed_mm_s: pos(self.max_speed_mm_s, "stage speed")?,
                max_accel_mm_s2: pos(self.max_accel_mm_s2, "stage acceleration")?,
                steps_per_mm: pos(self.steps_per_mm, "stage steps per mm")?,
            },
            shutter: Shutter {
                open_s: zero,
                close_s: zero,
            },
            dmd: Dmd { load_s: zero },
            projector: vec![Projector {
                name: self.projector.into(),
                width_px: self.size_px.0,
                height_px: self.size_px.1,
                pixel_mm: pos(self.pixel_mm, "pixel size")?,
                offset_px: [0, 0],
                mirror_x: false,
                mirror_y: false,
                calibration: None,
            }],
            exposure: Exposure {
                layer_s: NonNegative::new(last_s).unwrap_or(zero),
            },
            resin: Resin { name: self.resin },
        };
        m.validate()?;
        Ok(m)
    }
}

/// A manifest for an imported job at `path`.
pub(crate) fn manifest_of(path: &Path, p: ManifestParts) -> Manifest {
    let layers = p.layers;
    let height_mm = layers.last().map_or(0.0, |l| l.z_mm);
    let time_sum: f64 = layers.iter().map(|l| l.time_s).sum();
    let resin_mm3: f64 = layers.iter().map(|l| l.area_mm2 * l.thickness_mm).sum();
    let mut bbox_lo = [f64::INFINITY; 3];
    let mut bbox_hi = [f64::NEG_INFINITY; 3];
    for l in &layers {
        if let Some([[x0, y0], [x1, y1]]) = l.bbox_mm {
            bbox_lo = [
                bbox_lo[0].min(x0),
                bbox_lo[1].min(y0),
                bbox_lo[2].min(l.z_mm - l.thickness_mm),
            ];
            bbox_hi = [
                bbox_hi[0].max(x1),
                bbox_hi[1].max(y1),
                bbox_hi[2].max(l.z_mm),
            ];
        }
    }
    if bbox_lo[0] > bbox_hi[0] {
        bbox_lo = [0.0; 3];
        bbox_hi = [0.0; 3];
    }
    Manifest {
        cure: None,
        format: crate::bundle::FORMAT.into(),
        version: crate::bundle::VERSION,
        generator: Generator {
            name: p.generator,
            version: String::new(),
        },
        source: Source {
            file: path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            sha256: p.sha256,
            triangles: 0,
            bbox_mm: [bbox_lo, bbox_hi],
            placement: Placement {
                mode: "keep".into(),
                ..Placement::default()
            },
            mesh: crate::mesh::MeshReport::default(),
        },
        settings: Settings {
            layer_height_mm: p.layer_height_mm,
            binary: p.binary,
            compensation: "off".into(),
            distortion: None,
        },
        machine: p.machine,
        totals: Totals {
            layers: layers.len() as u64,
            height_mm,
            print_time_s: p.print_time_s.unwrap_or(time_sum),
            exposure_s: layers.iter().map(|l| l.exposure_s).sum(),
            resin_volume_ml: resin_mm3 / 1000.0,
            continuous_layers: None,
            all_layered_time_s: None,
        },
        warnings: Vec::new(),
        layers,
        optics: None,
        projector_optics: Vec::new(),
    }
}

/// What a decoded mask shows: its size and colour type, and its lit pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct MaskFigures {
    /// Sum of the pixel values / 255 (the lit area in pixels, coverage counted).
    pub coverage_px: f64,
    /// Lit box in pixels: [col0, row0, col1, row1) (None when nothing is lit).
    pub lit_box: Option<[u32; 4]>,
}

/// Most bytes deflate makes of one compressed byte (a run of 258-byte copies); a PNG's
/// pixels are at most this many times its size.
pub(crate) const DEFLATE_MAX_RATIO: u64 = 1032;

/// Decodes PNG `bytes` to 8-bit gray and measures it; `None` when it does not decode
/// (the executor's verification names that problem), also when its header declares more
/// pixels than its size can hold (nothing is allocated for them). `buf` is reused between
/// calls.
pub(crate) fn mask_figures(bytes: &[u8], buf: &mut Vec<u8>) -> Option<(u32, u32, MaskFigures)> {
    use image::ImageDecoder;
    let dec = image::codecs::png::PngDecoder::new(std::io::Cursor::new(bytes)).ok()?;
    let (w, h) = dec.dimensions();
    if dec.total_bytes() > DEFLATE_MAX_RATIO.saturating_mul(bytes.len() as u64) {
        return None;
    }
    if dec.color_type() == image::ColorType::L8 {
        buf.resize(dec.total_bytes() as usize, 0);
        dec.read_image(buf).ok()?;
    } else {
        // Another colour type (a problem the verification reports): measured as gray.
        *buf = image::load_from_memory_with_format(bytes, image::ImageFormat::Png)
            .ok()?
            .into_luma8()
            .into_raw();
    }
    let mut sum: u64 = 0;
    let mut b = [u32::MAX, u32::MAX, 0, 0];
    for (r, row) in buf.chunks_exact(w.max(1) as usize).enumerate() {
        // Most rows are dark: one vectorized OR over the row says so.
        if row.iter().fold(0u8, |a, &v| a | v) == 0 {
            continue;
        }
        let Some(first) = row.iter().position(|&v| v != 0) else {
            continue;
        };
        let last = row.iter().rposition(|&v| v != 0).unwrap_or(first);
        sum += u64::from(row[first..=last].iter().map(|&v| u32::from(v)).sum::<u32>());
        b = [
            b[0].min(first as u32),
            b[1].min(r as u32),
            b[2].max(last as u32 + 1),
            (r as u32 + 1),
        ];
    }
    let lit_box = (b[0] != u32::MAX).then_some(b);
    Some((
        w,
        h,
        MaskFigures {
            coverage_px: sum as f64 / 255.0,
            lit_box,
        },
    ))
}

/// The build-plane box (mm) of lit box `b` in a field `height_px` high with pixels
/// `pixel_mm` wide: columns x/p, rows H − y/p (the executor's convention).
pub(crate) fn bbox_mm(b: [u32; 4], height_px: u32, pixel_mm: f64) -> [[f64; 2]; 2] {
    let h = height_px as f64;
    [
        [b[0] as f64 * pixel_mm, (h - b[3] as f64) * pixel_mm],
        [b[2] as f64 * pixel_mm, (h - b[1] as f64) * pixel_mm],
    ]
}

/// The files of a bundle its manifest names, in the order the native forms store them:
/// every layer's masks, then the gray maps.
pub fn bundle_files(m: &Manifest) -> Vec<&str> {
    let mut files: Vec<&str> = m
        .layers
        .iter()
        .flat_map(|l| l.masks.iter().map(|k| k.file.as_str()))
        .collect();
    files.extend(m.optics.iter().map(|o| o.gray_map.as_str()));
    files.extend(m.projector_optics.iter().map(|o| o.gray_map.as_str()));
    files
}

/// Writes the job (`manifest` and its `files`) at `out` in `format`, atomically; returns
/// what the format could not carry. Nothing is left at `out` (nor beside it) on failure,
/// nor when `cancel` is set while it is written ([`crate::error::Error::Interrupted`]).
pub fn write(
    format: Format,
    manifest: &Manifest,
    files: &dyn BundleSource,
    out: &Path,
    cancel: Option<&AtomicBool>,
) -> Result<Vec<Warning>> {
    match format {
        Format::Dmdjob => native::write_dir(manifest, files, out, cancel).map(|()| Vec::new()),
        Format::DmdjobZip => native::write_zip(manifest, files, out, cancel).map(|()| Vec::new()),
        Format::Sl1 | Format::Sl1s => sl1::write::write(format, manifest, files, out, cancel),
        Format::SlaControl => control::write::write(manifest, files, out, cancel),
    }
}

/// Checks, before anything is written, that `format` can hold a job for `machine`:
/// SL1/SL1S hold one projector's masks. `out` names the output in the error.
/// A directory in the way of a one-file format is refused here too.
pub fn check_fits(format: Format, machine: &crate::bundle::Machine, out: &Path) -> Result<()> {
    if format.is_one_file() {
        archive::write::check_dest(out)?;
    }
    match format {
        Format::Sl1 | Format::Sl1s => sl1::write::check_projectors(machine.projector.len(), out),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 × 3 gray PNG, one pixel lit.
    fn png() -> Vec<u8> {
        let mut img = image::GrayImage::new(4, 3);
        img.put_pixel(1, 2, image::Luma([255]));
        let mut out = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
            .unwrap();
        out
    }

    #[test]
    fn a_mask_declaring_more_pixels_than_its_bytes_hold_is_not_decoded() {
        let mut buf = Vec::new();
        let good = png();
        let (w, h, f) = mask_figures(&good, &mut buf).unwrap();
        assert_eq!(
            (w, h, f.coverage_px, f.lit_box),
            (4, 3, 1.0, Some([1, 2, 2, 3]))
        );
        // The header (CRC right) says 2³¹ − 1 pixels square: nothing is allocated for it.
        let mut huge = good.clone();
        huge[16..24].copy_from_slice(&[0x7f, 0xff, 0xff, 0xff, 0x7f, 0xff, 0xff, 0xff]);
        let crc = crc32fast::hash(&huge[12..29]);
        huge[29..33].copy_from_slice(&crc.to_be_bytes());
        assert!(image::codecs::png::PngDecoder::new(std::io::Cursor::new(&huge)).is_ok());
        assert!(mask_figures(&huge, &mut buf).is_none());
        assert!(buf.capacity() < 1 << 20);
    }
}
