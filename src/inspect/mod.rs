//! `dmdsl inspect`: what a job bundle holds, in numbers and pictures, read from the bundle
//! alone (`job.json` through [`crate::bundle::Manifest`] and the mask PNGs).
//!
//! - [`reader`]: opening a bundle; masks come through the [`MaskReader`] trait, so another
//!   form of bundle only needs a reader.
//! - [`summary`]: layers, height, time, resin, warnings by code, per-layer extremes.
//! - [`sheet`]: the contact sheet of layer thumbnails.
//! - [`chart`]: per-layer figures in stacked panels.
//! - [`preview`](mod@preview): a shaded picture of the part built from the masks.
//! - [`field`]: a layer's masks back on the build plane, cut to the part and shrunk.
//!
//! Like the executor it never uses the slicer or the planner.

pub mod chart;
pub mod reader;
pub mod sheet;
pub mod summary;

pub use crate::picture::{field, preview};
pub use reader::{Bundle, DirMasks, MaskReader, SourceMasks};
pub use summary::{summarize, Summary};

use crate::error::Result;
use crate::plot::text::{self, SMALL, TITLE};
use crate::plot::{Canvas, Format};
use std::path::Path;

/// Size of the `--preview` picture's image, px (a title band goes above it).
pub const PREVIEW_SIZE: (u32, u32) = (960, 720);

/// The `--preview` picture: [`preview()`] under a title saying what it shows.
pub fn preview_picture(b: &Bundle) -> Result<Canvas> {
    let (w, h) = PREVIEW_SIZE;
    let img = preview(&b.manifest, b.masks.as_ref(), w, h)?;
    let m = &b.manifest;
    let title = format!(
        "{}: the part as its masks build it ({} layers, {:.2} mm tall)",
        b.name(),
        m.layers.len(),
        m.totals.height_mm
    );
    let note = "Lit mask pixels stacked layer on layer, seen from the front right and above; \
                lines on the build plate every 10 mm.";
    let pad = 12.0;
    let band = pad + text::line_height(TITLE.size) + 4.0 + text::line_height(SMALL.size) + 8.0;
    let mut c = Canvas::new(w, h + band.ceil() as u32, [255; 3]);
    c.draw_rgb(&img, 0, band.ceil() as i64);
    c.text(pad, pad, &title, TITLE);
    c.text(pad, pad + text::line_height(TITLE.size) + 4.0, note, SMALL);
    Ok(c)
}

/// Writes `canvas` to `path` in `format`, through a temporary sibling renamed into place.
pub fn write_picture(path: &Path, canvas: &Canvas, format: Format) -> Result<()> {
    crate::output::write_atomic(path, &canvas.encode(format))
}
