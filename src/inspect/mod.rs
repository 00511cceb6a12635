//! `dmdsl inspect`: what a job holds, in numbers ([`summary`]) and pictures ([`sheet`],
//! [`chart`], [`crate::picture::preview()`]), read from the job alone ([`Bundle`]: any form
//! [`crate::formats::open`] reads, its files through a [`BundleSource`]); like the executor
//! it never uses the slicer or the planner.

pub mod chart;
pub mod marks;
pub mod sheet;
pub mod summary;

#[cfg(any(test, feature = "internals"))]
pub use crate::picture::preview;
pub use summary::summarize;

use crate::bundle::{BundleSource, Manifest, MANIFEST};
use crate::error::{Error, Result};
use crate::plot::text::{self, SMALL, TITLE};
use crate::plot::{Canvas, Format};
use crate::text::count;
use std::path::{Path, PathBuf};

/// Size of the `--preview` picture's image, px (a title band goes above it).
pub const PREVIEW_SIZE: (u32, u32) = (960, 720);

/// The `--preview` picture: [`crate::picture::preview()`] under a title saying what it shows, with the
/// largest region of each layer that rests on nothing below ringed ([`marks`]) and the
/// job's supports drawn.
pub fn preview_picture(b: &Bundle) -> Result<Canvas> {
    let (w, h) = PREVIEW_SIZE;
    let (img, proj) = crate::picture::preview_projected(&b.manifest, b.files.as_ref(), w, h)?;
    let regions = marks::regions(b)?;
    let rings = marks::largest_per_layer(b, &regions);
    let m = &b.manifest;
    let title = format!(
        "{}: the part as its masks build it ({}, {:.2} mm tall)",
        b.name(),
        count(m.layers.len() as u64, "layer", "layers"),
        m.totals.height_mm
    );
    let note = "Lit mask pixels stacked layer on layer, seen from the front right and above; \
                lines on the build plate every 10 mm.";
    let held = if m.supports.is_some() {
        " as large as a support head's contact"
    } else {
        ""
    };
    let mut lines = vec![note.to_string()];
    lines.push(match rings.len() as u64 {
        0 => format!("No region{held} rests on nothing below."),
        k => format!(
            "Red rings: regions{held} resting on nothing below, the largest of each of {} ({} of any size in all).",
            count(k, "layer", "layers"),
            count(regions.len() as u64, "region", "regions")
        ),
    });
    if let Some(s) = &m.supports {
        lines.push(format!(
            "Orange: the {}, each from its foot to its head's tip.",
            count(s.points.len() as u64, "support", "supports")
        ));
    }
    let pad = 12.0;
    let small = text::line_height(SMALL.size);
    let band = pad + text::line_height(TITLE.size) + 4.0 + lines.len() as f32 * small + 8.0;
    let mut c = Canvas::new(w, h + band.ceil() as u32, [255; 3]);
    c.draw_rgb(&img, 0, band.ceil() as i64);
    marks::draw(
        &mut c,
        &proj,
        band.ceil() as f64,
        &rings,
        m.supports.as_ref(),
    );
    c.text(pad, pad, &title, TITLE);
    let y = pad + text::line_height(TITLE.size) + 4.0;
    for (k, l) in lines.iter().enumerate() {
        c.text(pad, y + k as f32 * small, l, SMALL);
    }
    Ok(c)
}

/// Writes `canvas` to `path` in `format`, through a temporary sibling renamed into place.
pub fn write_picture(path: &Path, canvas: &Canvas, format: Format) -> Result<()> {
    crate::output::write_atomic(path, &canvas.encode(format))
}

/// A job opened for inspection.
pub struct Bundle {
    /// The job's path, as given.
    pub path: PathBuf,
    /// The form it came in (a bundle directory, a zipped bundle, an imported file).
    pub format: crate::formats::Format,
    /// Its manifest, checked.
    pub manifest: Manifest,
    /// Its files (masks, gray maps).
    pub files: Box<dyn BundleSource>,
    /// What its reader could not take as stated (an imported file's), one line each.
    pub notes: Vec<String>,
}

impl Bundle {
    /// Opens the job at `path` in any form [`crate::formats::open`] reads (a bundle
    /// directory, a zipped bundle, an SL1/SL1S file, an SLA control-file zip): reads and
    /// checks its manifest, including its machine record and the projector of every mask.
    pub fn open(path: &Path) -> Result<Bundle> {
        let job = crate::formats::open(path)?;
        let manifest = job.manifest;
        let bad = |msg: String| Error::Bundle {
            path: job.source.shown(MANIFEST),
            msg,
        };
        manifest
            .machine
            .validate()
            .map_err(|m| bad(format!("machine: {m}")))?;
        let projectors = manifest.machine.projector.len();
        for l in &manifest.layers {
            for m in &l.masks {
                if m.projector as usize >= projectors {
                    return Err(bad(format!(
                        "layer {}: mask {} is for projector {}, the machine has {projectors}",
                        l.index, m.file, m.projector
                    )));
                }
            }
        }
        Ok(Bundle {
            path: path.into(),
            format: job.format,
            manifest,
            files: job.source,
            notes: job.notes,
        })
    }

    /// The bundle's name for titles: its file name (`part.dmdjob`).
    pub fn name(&self) -> String {
        self.path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.path.display().to_string())
    }
}
