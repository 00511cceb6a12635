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

/// The title of the `--preview` picture of the job `m` named `name`.
fn preview_title(name: &str, m: &crate::bundle::Manifest) -> String {
    let what = match &m.source.parts {
        Some(parts) if parts.len() > 1 => "the parts as their masks build them",
        _ => "the part as its masks build it",
    };
    let (n, tall) = (m.layers.len() as u64, m.totals.height_mm);
    format!(
        "{name}: {what} ({}, {tall:.2} mm tall)",
        count(n, "layer", "layers")
    )
}

/// The `--preview` picture: [`crate::picture::preview()`] under a title saying what it shows, with the
/// largest region of each layer that rests on nothing below ringed ([`marks`]) and the
/// job's supports drawn.
pub fn preview_picture(b: &Bundle) -> Result<Canvas> {
    let (w, h) = PREVIEW_SIZE;
    let (img, proj) = crate::picture::preview_projected(&b.manifest, b.files.as_ref(), w, h)?;
    let regions = marks::regions(b)?;
    let rings = marks::largest_per_layer(b, &regions);
    let m = &b.manifest;
    let title = preview_title(&b.name(), m);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_preview_title_counts_parts_and_layers() {
        let mut m = crate::exec::testutil::two_layer_topdown();
        m.totals.height_mm = 0.1;
        assert_eq!(
            preview_title("a.dmdjob", &m),
            "a.dmdjob: the part as its masks build it (2 layers, 0.10 mm tall)"
        );
        m.layers.truncate(1);
        let copy = |copy| crate::bundle::PlatePart {
            file: "a.stl".into(),
            sha256: String::new(),
            copy,
            copies: 2,
            triangles: 12,
            bbox_mm: [[0.0; 3], [1.0; 3]],
            translate_mm: [0.0; 3],
            placed_bbox_mm: [[0.0; 3], [1.0; 3]],
        };
        m.source.parts = Some(vec![copy(1), copy(2)]);
        assert_eq!(
            preview_title("a.dmdjob", &m),
            "a.dmdjob: the parts as their masks build them (1 layer, 0.10 mm tall)"
        );
    }
}
