//! The contact sheet: a grid of layer thumbnails, each the layer's masks shrunk (gray on
//! black, as a projector shows them), cut to the part's footprint and labelled with the
//! layer number and height.

use crate::bundle::BundleSource;
use crate::bundle::Manifest;
use crate::error::{Error, Result};
use crate::picture::field::{layer_cells, part_crop};
use crate::plot::text::{self, Align, TextStyle, INK, SMALL, TITLE};
use crate::plot::Canvas;
use image::GrayImage;
use rayon::prelude::*;
use std::ops::RangeInclusive;

/// Thumbnails on a sheet when neither `--every` nor a short range says otherwise.
pub const DEFAULT_THUMBNAILS: usize = 48;
/// The most thumbnails a sheet holds.
pub const MAX_THUMBNAILS: usize = 2000;
/// Widest sheet, px (columns are added up to it).
const SHEET_MAX_W: u32 = 1600;
/// Space between thumbnails and around the sheet, px.
const GAP: u32 = 14;
/// The sheet's background: a faint blue, so a thumbnail's white (full light) stands out
/// from it and no thumbnail pixel (always a gray) is mistaken for it.
pub const BACKGROUND: [u8; 3] = [236, 240, 247];

/// The layers a sheet shows, out of `n`: those of `range` (all layers if none) that are
/// `every` apart from its first; without `every`, all of them when they are at most
/// [`DEFAULT_THUMBNAILS`], else that many evenly spaced, the first and last included.
/// Errors: more than [`MAX_THUMBNAILS`], or `every` = 0.
pub fn select_layers(
    n: usize,
    range: Option<RangeInclusive<usize>>,
    every: Option<usize>,
) -> Result<Vec<usize>> {
    if n == 0 {
        return Ok(Vec::new());
    }
    let r = range.unwrap_or(0..=n - 1);
    let (a, b) = (*r.start(), (*r.end()).min(n - 1));
    if a > b {
        return Ok(Vec::new());
    }
    let count = b - a + 1;
    let layers: Vec<usize> = match every {
        Some(0) => return Err(Error::Usage("--every 0: give a step of 1 or more".into())),
        Some(k) => (a..=b).step_by(k).collect(),
        None if count <= DEFAULT_THUMBNAILS => (a..=b).collect(),
        None => {
            let k = DEFAULT_THUMBNAILS;
            (0..k)
                .map(|i| a + ((i * (count - 1)) as f64 / (k - 1) as f64).round() as usize)
                .collect()
        }
    };
    if layers.len() > MAX_THUMBNAILS {
        return Err(Error::Usage(format!(
            "the contact sheet would show {} layers, at most {MAX_THUMBNAILS}: give a larger --every or a shorter --layers range",
            layers.len()
        )));
    }
    Ok(layers)
}

/// Edge of the box a thumbnail fits in, px: smaller as the sheet holds more of them.
fn thumb_edge(n: usize) -> u32 {
    match n {
        0..=48 => 176,
        49..=150 => 120,
        _ => 80,
    }
}

/// The contact sheet of `layers` of the bundle named `name`; `how` says how they were
/// chosen, for the title ("every 10th layer", "48 evenly spaced").
pub fn contact_sheet(
    name: &str,
    manifest: &Manifest,
    masks: &dyn BundleSource,
    layers: &[usize],
    how: &str,
) -> Result<Canvas> {
    let crop = part_crop(manifest);
    let edge = thumb_edge(layers.len());
    let (tw, th) = if crop.width() >= crop.height() {
        let th = (edge as u64 * crop.height() as u64 / crop.width() as u64).max(1) as u32;
        (edge, th)
    } else {
        let tw = (edge as u64 * crop.width() as u64 / crop.height() as u64).max(1) as u32;
        (tw, edge)
    };
    let thumbs: Vec<GrayImage> = crate::error::in_order(layers.par_iter().map(|&l| {
        let c = layer_cells(manifest, l, masks, crop, tw, th)?;
        Ok(GrayImage::from_raw(c.width, c.height, c.mean).expect("sizes agree"))
    }))?;
    let (tw, th) = thumbs.first().map_or((tw, th), |t| (t.width(), t.height()));

    let label_h = text::line_height(SMALL.size).ceil() as u32 + 4;
    let cell_w = tw.max(110) + GAP;
    let cell_h = th + label_h + GAP;
    let cols = ((SHEET_MAX_W - GAP) / cell_w).clamp(1, layers.len().max(1) as u32);
    let rows = (layers.len() as u32).div_ceil(cols).max(1);
    let title_h = text::line_height(TITLE.size).ceil() as u32;
    let note_h = text::line_height(SMALL.size).ceil() as u32;
    let top = GAP + title_h + 6 + 2 * (note_h + 2) + 10;
    let field = manifest.machine.field();
    let title = format!(
        "{name}: layer masks, {} of {} ({how})",
        layers.len(),
        crate::text::count(manifest.layers.len() as u64, "layer", "layers")
    );
    let p = field.pixel_mm;
    let note1 = if manifest.machine.projector.len() > 1 {
        "Each thumbnail is one layer's masks as the projectors show them, side by side at their offsets: gray on black, white = full light."
    } else {
        "Each thumbnail is one layer's mask as the projector shows it: gray on black, white = full light."
    };
    let zone = manifest
        .optics
        .as_ref()
        .or(manifest.projector_optics.first());
    let note1 = match zone.filter(|o| o.mode == "zone") {
        Some(o) => format!(
            "{note1} Faint squares inside the part: the light compensation's {} mm zones, each with its own gray.",
            crate::text::number(o.zone_mm)
        ),
        None => note1.to_owned(),
    };
    let note2 = format!(
        "Cut to the part: x {:.1}–{:.1} mm, y {:.1}–{:.1} mm of the {:.2} × {:.2} mm field; labels: layer number · height (z) of its top.",
        crop.x0 as f64 * p,
        crop.x1 as f64 * p,
        field.height_mm() - crop.y1 as f64 * p,
        field.height_mm() - crop.y0 as f64 * p,
        field.width_mm(),
        field.height_mm()
    );
    let width = (GAP + cols * cell_w)
        .max(2 * GAP + text::text_width(&title, TITLE.size).ceil() as u32)
        .max(2 * GAP + text::text_width(&note1, SMALL.size).ceil() as u32)
        .max(2 * GAP + text::text_width(&note2, SMALL.size).ceil() as u32);
    let height = top + rows * cell_h + GAP;
    let mut c = Canvas::new(width, height, BACKGROUND);
    c.text(GAP as f32, GAP as f32, &title, TITLE);
    let y1 = (GAP + title_h + 6) as f32;
    c.text(GAP as f32, y1, &note1, SMALL);
    c.text(GAP as f32, y1 + (note_h + 2) as f32, &note2, SMALL);
    let decimals = z_decimals(layers.iter().map(|&l| manifest.layers[l].z_mm));
    for (k, (thumb, &l)) in thumbs.iter().zip(layers).enumerate() {
        let (col, row) = (k as u32 % cols, k as u32 / cols);
        let x = GAP + col * cell_w + (cell_w - GAP - tw) / 2;
        let y = top + row * cell_h;
        c.draw_gray(thumb, x as i64, y as i64);
        let z = manifest.layers[l].z_mm;
        c.text(
            (x + tw / 2) as f32,
            (y + th + 3) as f32,
            &format!("layer {l} · {z:.decimals$} mm"),
            TextStyle::new(SMALL.size, INK).aligned(Align::Center),
        );
    }
    Ok(c)
}

/// Decimals (2 to 4) that write every height of `zs` (mm) exactly, or 4: 5 µm layers read
/// 0.005, 0.010, … instead of four labels of 0.01.
fn z_decimals(zs: impl Iterator<Item = f64> + Clone) -> usize {
    (2..=4)
        .find(|&d| {
            let scale = 10f64.powi(d as i32);
            zs.clone()
                .all(|z| ((z * scale).round() - z * scale).abs() < 1e-6)
        })
        .unwrap_or(4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_are_labelled_with_the_decimals_they_need() {
        assert_eq!(z_decimals([0.05, 0.1, 0.15].into_iter()), 2);
        assert_eq!(z_decimals([0.005, 0.01, 0.015].into_iter()), 3);
        assert_eq!(z_decimals([0.0125, 0.025].into_iter()), 4);
        assert_eq!(z_decimals([1.0 / 3.0].into_iter()), 4);
        assert_eq!(z_decimals(std::iter::empty()), 2);
    }

    #[test]
    fn layers_are_chosen_as_asked() {
        assert_eq!(
            select_layers(10, None, None).unwrap(),
            (0..10).collect::<Vec<_>>()
        );
        let d = select_layers(800, None, None).unwrap();
        assert_eq!(d.len(), DEFAULT_THUMBNAILS);
        assert_eq!((d[0], d[47]), (0, 799));
        assert_eq!(select_layers(800, Some(10..=20), None).unwrap().len(), 11);
        assert_eq!(
            select_layers(100, None, Some(25)).unwrap(),
            vec![0, 25, 50, 75]
        );
        assert_eq!(
            select_layers(100, Some(10..=30), Some(10)).unwrap(),
            vec![10, 20, 30]
        );
        assert!(select_layers(100, None, Some(0)).is_err());
        assert!(select_layers(5000, None, Some(1)).is_err());
    }
}
