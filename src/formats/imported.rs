//! What the importers share: the machine record a foreign file implies ([`Implied`]), the
//! layer record of one image ([`layer`]), the images' figures ([`images`]) and the job
//! around the layers ([`Imported::job`]).
//!
//! An imported job's layer records come from its masks (lit area and box), so the
//! executor's verification checks them for what can be wrong with a foreign file (a mask
//! missing, undecodable, of the wrong size or colour type).

use super::archive::read::Archive;
use super::{ForeignEstimate, Format, Job};
use crate::bundle::machine::{Dmd, Exposure, Projector, Resin, Shutter, Stage};
use crate::bundle::{
    Generator, Layer, Machine, Manifest, MaskRef, MemSource, Mode, Placement, Settings, Source,
    Step, Totals,
};
use crate::error::Result;
use crate::units::{NonNegative, Positive};
use rayon::prelude::*;

/// What an importer knows of the machine a file implies (the rest is [`Implied::machine`]'s).
pub(crate) struct Implied<'a> {
    /// The record's name, e.g. `sl1-import-sl1`.
    pub name: String,
    /// The resin the file names (empty when it names none).
    pub resin: String,
    pub projector: &'a str,
    pub size_px: (u32, u32),
    pub pixel_mm: f64,
    pub travel_max_mm: f64,
    pub max_speed_mm_s: f64,
    pub max_accel_mm_s2: f64,
    pub steps_per_mm: f64,
}

impl Implied<'_> {
    /// The machine record: a bottom-up stage from 0 (home) to `travel_max_mm`, no shutter
    /// or DMD latency, one projector showing the images as they are (no offset, mirroring
    /// or calibration); the normal exposure is the last layer's. The error names the value
    /// out of range.
    fn machine(self, layers: &[Layer]) -> std::result::Result<Machine, String> {
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

/// One image of an imported job: its entry, SHA-256 (empty when absent) and, when it
/// decodes, its size and figures.
pub(crate) type Image = (String, Option<(u32, u32, MaskFigures)>);

/// The images `names` of `archive`, decoded in parallel.
pub(crate) fn images(archive: &Archive, names: &[&str]) -> Vec<Image> {
    names
        .par_iter()
        .map_init(Vec::new, |buf, name| {
            let fig = archive
                .get(name)
                .map(|b| (crate::digest::sha256_hex(b), mask_figures(b, buf)));
            fig.unwrap_or_default()
        })
        .collect()
}

/// The pixels of an imported job's images on the build plane: the images' height, px,
/// a pixel's edge along x, mm, and its area, mm².
#[derive(Debug, Clone, Copy)]
pub(crate) struct Grid {
    pub height_px: u32,
    pub pixel_mm: f64,
    pub pixel_area_mm2: f64,
}

/// The record of layer `index` of an imported job: its top at `z_mm`, cut at
/// `slice_z_mm`, `thickness_mm` thick, showing image `file` (`image` its figures) during the exposure of its `steps`, which
/// take `time_s`; area and box from the image's lit pixels on `grid`.
pub(crate) fn layer(
    index: usize,
    (z_mm, slice_z_mm, thickness_mm): (f64, f64, f64),
    (file, image): (&str, &Image),
    grid: Grid,
    steps: Vec<Step>,
    time_s: f64,
) -> Layer {
    let fig = image.1.map(|(_, _, f)| f);
    let exposure_s = steps.iter().find_map(|s| match *s {
        Step::Expose { s } => Some(s),
        _ => None,
    });
    let [w, h] = [grid.pixel_mm, grid.height_px as f64];
    Layer {
        index: index as u64,
        z_mm,
        slice_z_mm,
        thickness_mm,
        mode: Mode::Layered,
        exposure_s: exposure_s.unwrap_or(0.0),
        area_mm2: fig.map_or(0.0, |f| f.coverage_px * grid.pixel_area_mm2),
        max_fill_distance_mm: 0.0,
        islands: 0,
        // Columns x/p, rows H − y/p (the executor's convention).
        bbox_mm: fig.and_then(|f| f.lit_box).map(|b| {
            [
                [b[0] as f64 * w, (h - b[3] as f64) * w],
                [b[2] as f64 * w, (h - b[1] as f64) * w],
            ]
        }),
        masks: vec![MaskRef {
            file: file.into(),
            sha256: image.0.clone(),
            projector: 0,
        }],
        steps,
        time_s,
        cure: None,
    }
}

/// An imported job's layers and what the file says around them.
pub(crate) struct Imported<'a> {
    pub format: Format,
    /// Who wrote the file, e.g. "PrusaSlicer-2.5.0".
    pub generator: String,
    /// The imported file's SHA-256.
    pub sha256: String,
    pub machine: Implied<'a>,
    /// Nominal layer height, mm.
    pub layer_height_mm: f64,
    pub layers: Vec<Layer>,
    /// The file's own total time estimate, if it has one (otherwise the sum of the
    /// layers' `time_s` is the job's).
    pub estimate: Option<ForeignEstimate>,
}

impl Imported<'_> {
    /// The job: a manifest as a bundle would have it, the archive's files as its files.
    /// A machine out of range is an error about entry `entry`, the machine named `what`.
    pub(crate) fn job(self, archive: Archive, (entry, what): (&str, &str)) -> Result<Job> {
        let path = archive.path().to_path_buf();
        let machine = (self.machine)
            .machine(&self.layers)
            .map_err(|m| archive.error(Some(entry), format!("{what}: {m}")))?;
        let layers = self.layers;
        let time_sum: f64 = layers.iter().map(|l| l.time_s).sum();
        let resin_mm3: f64 = layers.iter().map(|l| l.area_mm2 * l.thickness_mm).sum();
        let bbox_mm = layers
            .iter()
            .filter_map(|l| {
                let [[x0, y0], [x1, y1]] = l.bbox_mm?;
                Some([[x0, y0, l.z_mm - l.thickness_mm], [x1, y1, l.z_mm]])
            })
            .reduce(|[a, b], [c, d]| {
                [
                    std::array::from_fn(|k| a[k].min(c[k])),
                    std::array::from_fn(|k| b[k].max(d[k])),
                ]
            })
            .unwrap_or([[0.0; 3]; 2]);
        let manifest = Manifest {
            cure: None,
            format: crate::bundle::FORMAT.into(),
            version: crate::bundle::VERSION,
            generator: Generator {
                name: self.generator,
                version: String::new(),
            },
            source: Source {
                file: path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
                sha256: self.sha256,
                triangles: 0,
                bbox_mm,
                placement: Placement {
                    mode: "keep".into(),
                    ..Placement::default()
                },
                mesh: Default::default(),
            },
            settings: Settings {
                layer_height_mm: self.layer_height_mm,
                binary: false,
                compensation: "off".into(),
                distortion: None,
            },
            machine,
            totals: Totals {
                layers: layers.len() as u64,
                height_mm: layers.last().map_or(0.0, |l| l.z_mm),
                print_time_s: self.estimate.as_ref().map_or(time_sum, |e| e.print_time_s),
                exposure_s: layers.iter().map(|l| l.exposure_s).sum(),
                resin_volume_ml: resin_mm3 / 1000.0,
                continuous_layers: None,
                all_layered_time_s: None,
            },
            warnings: Vec::new(),
            layers,
            optics: None,
            projector_optics: Vec::new(),
        };
        Ok(Job {
            source: Box::new(MemSource::new(&path, archive.into_files())),
            path,
            format: self.format,
            manifest,
            estimate: self.estimate,
        })
    }
}

/// What a decoded mask shows: its lit pixels.
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
