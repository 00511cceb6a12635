//! What the importers share: the machine record a foreign file implies ([`machine`],
//! [`projector`]), the layer record of one image ([`layer`]), the images' figures
//! ([`images`]) and the job around the layers ([`Imported::job`]).
//!
//! An imported job's layer records come from its masks (lit box; area from the pixels lit
//! at least half, unless the file states it), so the executor's verification checks them
//! for what can be wrong with a foreign file (a mask missing, undecodable, of the wrong
//! size or colour type).

use super::archive::read::Archive;
use super::{ForeignEstimate, Format, Job, Request};
use crate::bundle::machine::{Dmd, Exposure, Projector, Resin, Shutter, Stage};
use crate::bundle::{
    Generator, Layer, Machine, Manifest, MaskRef, Mode, Placement, Settings, Source, Step, Totals,
};
use crate::error::Result;
use crate::units::{NonNegative, Positive};
use rayon::prelude::*;

/// A positive number as a record value (its stand-in when `v` is not one: the record is
/// validated in [`Imported::job`], which names the value out of range).
fn pos(v: f64) -> Positive {
    Positive::new(v).unwrap_or(Positive::new(1.0).expect("1 is positive"))
}

/// A projector showing images of `size_px` as they are (no offset, mirroring or
/// calibration), pixels `pixel_mm` wide.
pub(crate) fn projector(name: &str, size_px: (u32, u32), pixel_mm: f64) -> Projector {
    Projector {
        name: name.into(),
        width_px: size_px.0,
        height_px: size_px.1,
        pixel_mm: pos(pixel_mm),
        offset_px: [0, 0],
        mirror_x: false,
        mirror_y: false,
        calibration: None,
        wavelength_nm: None,
        power_setting: None,
    }
}

/// The machine a foreign file implies: a bottom-up stage homed at 0 traveling to
/// `travel_max_mm` at most `(speed, acceleration)` in `steps_per_mm`, no shutter or DMD
/// latency, `projectors`, the resin it names; `unstated` the keys the file does not
/// state (their values are stand-ins). The normal exposure is set by [`Imported::job`].
pub(crate) fn machine(
    (name, resin): (String, String),
    (travel_max_mm, speed, accel, steps_per_mm): (f64, f64, f64, f64),
    projectors: Vec<Projector>,
    unstated: &[&str],
) -> Machine {
    let zero = NonNegative::default();
    Machine {
        name,
        process: crate::profile::Process::BottomUp,
        stage: Stage {
            travel_min_mm: 0.0,
            travel_max_mm,
            home_mm: 0.0,
            max_speed_mm_s: pos(speed),
            max_accel_mm_s2: pos(accel),
            steps_per_mm: pos(steps_per_mm),
        },
        shutter: Shutter {
            open_s: zero,
            close_s: zero,
        },
        dmd: Dmd { load_s: zero },
        projector: projectors,
        exposure: Exposure { layer_s: zero },
        resin: Resin { name: resin },
        unstated: unstated.iter().map(|k| k.to_string()).collect(),
        sources: Default::default(),
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
                .read(name)
                .ok()
                .map(|b| (crate::digest::sha256_hex(&b), mask_figures(&b, buf)));
            fig.unwrap_or_default()
        })
        .collect()
}

/// The record of layer `index` of an imported job: its top at `z_mm`, cut at
/// `slice_z_mm`, `thickness_mm` thick, showing image `file` (`image` its figures) on
/// projector `k` of `machine` during the exposure of its `steps`, which take `time_s`.
/// Its box comes from the image's lit pixels placed as the projector shows them (offset,
/// mirroring undone); its area is `area_mm2` when the file states it, else the pixels
/// lit at least half times `pixel_area_mm2`.
pub(crate) fn layer(
    (index, (z_mm, slice_z_mm, thickness_mm)): (usize, (f64, f64, f64)),
    (file, image): (&str, &Image),
    (machine, k, pixel_area_mm2, area_mm2): (&Machine, usize, f64, Option<f64>),
    steps: Vec<Step>,
    time_s: f64,
) -> Layer {
    let fig = image.1.map(|(_, _, f)| f);
    let exposure_s = steps.iter().find_map(|s| match *s {
        Step::Expose { s } => Some(s),
        _ => None,
    });
    let p = &machine.projector[k];
    let (w, field_h) = (p.pixel_mm.get(), machine.field().height_px as f64);
    let flip = |a: u32, b: u32, n: u32, m: bool| if m { (n - b, n - a) } else { (a, b) };
    // Columns x/p, rows H − y/p in the field (the executor's convention).
    let bbox_mm = fig.and_then(|f| f.lit_box).map(|b| {
        let (c0, c1) = flip(b[0], b[2], p.width_px, p.mirror_x);
        let (r0, r1) = flip(b[1], b[3], p.height_px, p.mirror_y);
        let [ox, oy] = p.offset_px.map(f64::from);
        [
            [(ox + c0 as f64) * w, (field_h - oy - r1 as f64) * w],
            [(ox + c1 as f64) * w, (field_h - oy - r0 as f64) * w],
        ]
    });
    Layer {
        index: index as u64,
        z_mm,
        slice_z_mm,
        thickness_mm,
        mode: Mode::Layered,
        exposure_s: exposure_s.unwrap_or(0.0),
        area_mm2: area_mm2
            .unwrap_or_else(|| fig.map_or(0.0, |f| f.half_px as f64 * pixel_area_mm2)),
        // The file's images are not sections: no inscribed circle or islands to state.
        max_fill_distance_mm: None,
        islands: None,
        bbox_mm,
        masks: vec![MaskRef {
            file: file.into(),
            sha256: image.0.clone(),
            projector: k as u32,
            pixels: None,
        }],
        steps,
        time_s,
        cure: None,
        support_area_mm2: None,
    }
}

/// An imported job's layers and what the file says around them.
pub(crate) struct Imported {
    pub format: Format,
    /// Who wrote the file, e.g. "PrusaSlicer-2.5.0".
    pub generator: String,
    /// The imported file's SHA-256.
    pub sha256: String,
    /// The machine the file implies ([`machine`]).
    pub machine: Machine,
    /// Nominal layer height, mm.
    pub layer_height_mm: f64,
    pub layers: Vec<Layer>,
    /// The file's own total time estimate, if it has one (otherwise the sum of the
    /// layers' `time_s` is the job's).
    pub estimate: Option<ForeignEstimate>,
    /// The resin volume the file states, ml (otherwise the layers' areas give it).
    pub resin_ml: Option<f64>,
    /// The file states the layers' areas (otherwise they are estimates).
    pub stated_areas: bool,
    /// What the exposures ask of the light engines (control files).
    pub requests: Vec<Request>,
    /// The file asks to print under vacuum.
    pub vacuum: bool,
    /// What the reader did not take as stated (module docs of `formats`).
    pub notes: Vec<String>,
}

impl Imported {
    /// The job: a manifest as a bundle would have it, the archive's files as its files.
    /// A machine out of range is an error about entry `entry`, the machine named `what`.
    pub(crate) fn job(mut self, archive: Archive, (entry, what): (&str, &str)) -> Result<Job> {
        let path = archive.path().to_path_buf();
        let mut machine = self.machine;
        let last_s = self.layers.last().map_or(0.0, |l| l.exposure_s);
        machine.exposure.layer_s = NonNegative::new(last_s).unwrap_or_default();
        machine
            .validate()
            .map_err(|m| archive.error(Some(entry), format!("{what}: {m}")))?;
        let layers = self.layers;
        let time_sum: f64 = layers.iter().map(|l| l.time_s).sum();
        let areas_mm3: f64 = layers.iter().map(|l| l.area_mm2 * l.thickness_mm).sum();
        if !machine.states("projector[].pixel_mm") {
            self.notes.push("no pixel size stated (projector[].pixel_mm): layer areas and the resin volume are not measured; give it with --set projector.0.pixel_mm=MM".into());
        } else if !self.stated_areas {
            let what = match self.resin_ml {
                Some(_) => "layer areas are estimates",
                None => "layer areas and the resin volume are estimates",
            };
            self.notes
                .push(format!("{what}: the masks' pixels lit at least half"));
        }
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
                parts: None,
            },
            settings: Settings {
                layer_height_mm: self.layer_height_mm,
                binary: false,
                compensation: "off".into(),
                distortion: None,
                accuracy: None,
            },
            machine,
            totals: Totals {
                layers: layers.len() as u64,
                height_mm: layers.last().map_or(0.0, |l| l.z_mm),
                print_time_s: self.estimate.as_ref().map_or(time_sum, |e| e.print_time_s),
                exposure_s: layers.iter().map(|l| l.exposure_s).sum(),
                resin_volume_ml: self.resin_ml.unwrap_or(areas_mm3 / 1000.0),
                continuous_layers: None,
                all_layered_time_s: None,
            },
            warnings: Vec::new(),
            layers,
            optics: None,
            projector_optics: Vec::new(),
            supports: None,
        };
        Ok(Job {
            source: Box::new(archive.into_source("")),
            path,
            format: self.format,
            manifest,
            estimate: self.estimate,
            requests: self.requests,
            vacuum: self.vacuum,
            notes: self.notes,
        })
    }
}

/// The job `m` imported with pixels of another size: projector placements, layer boxes
/// and areas and the resin volume restated for pixels `pixel_mm` wide (the masks are the
/// same pixels, now known to be that size; an offset, a physical distance, is fewer or
/// more of them).
pub(crate) fn rescale(m: &mut Manifest, pixel_mm: f64) {
    let Some(old) = m.machine.projector.first().map(|p| p.pixel_mm.get()) else {
        return;
    };
    let f = pixel_mm / old;
    let before = m.machine.clone();
    for p in &mut m.machine.projector {
        p.pixel_mm = pos(pixel_mm);
        p.offset_px = p.offset_px.map(|o| (o as f64 / f).round() as u32);
    }
    let (h0, h1) = (
        before.field().height_px as f64,
        m.machine.field().height_px as f64,
    );
    for l in &mut m.layers {
        l.area_mm2 *= f * f;
        let k = l.masks.first().map_or(0, |k| k.projector as usize);
        let (Some(a), Some(b)) = (before.projector.get(k), m.machine.projector.get(k)) else {
            continue;
        };
        let [ax, ay] = a.offset_px.map(f64::from);
        let [bx, by] = b.offset_px.map(f64::from);
        // The same mask pixel, placed by the new offset in the new field.
        let x = |v: f64| (v / old - ax + bx) * pixel_mm;
        let y = |v: f64| (h1 - (h0 - v / old - ay + by)) * pixel_mm;
        if let Some(bb) = &mut l.bbox_mm {
            *bb = bb.map(|[u, v]| [x(u), y(v)]);
        }
    }
    m.totals.resin_volume_ml *= f * f;
    m.machine.unstated.retain(|k| k != "projector[].pixel_mm");
}

/// What a decoded mask shows: its lit pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct MaskFigures {
    /// Pixels of value 128 or more (lit at least half): the area's estimate, also of
    /// light-compensated masks, whose grays are not coverage.
    pub half_px: u64,
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
    let mut half = 0u64;
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
        let lit = &row[first..=last];
        half += lit.iter().filter(|&&v| v >= 128).count() as u64;
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
            half_px: half,
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
        assert_eq!((w, h, f.half_px, f.lit_box), (4, 3, 1, Some([1, 2, 2, 3])));
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
