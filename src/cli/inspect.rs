//! `dmdsl inspect`: a bundle's summary and pictures.

use crate::inspect::{self, sheet, Bundle};
use crate::plot::Format;
use clap::Args;
use std::path::{Path, PathBuf};

pub(crate) const INSPECT_EXIT_HELP: &str = "Exit codes:
  0    the bundle was read (and the pictures written)
  2    unreadable bundle, archive or mask, or usage error

The job may be a bundle directory, a zipped bundle (.dmdjob.zip), a PrusaSlicer .sl1/.sl1s
file or an SLA control-file zip. Pictures are PNG or JPEG by their extension (.png, .jpg,
.jpeg).";

#[derive(Args)]
pub(crate) struct InspectArgs {
    /// The job: a bundle directory (job.json and masks/), a zipped bundle (.dmdjob.zip), a
    /// PrusaSlicer .sl1/.sl1s file or an SLA control-file zip (found from the content).
    bundle: PathBuf,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub(crate) json: bool,
    /// Write a contact sheet: a grid of layer thumbnails (about 48 layers evenly spaced,
    /// or as --every and --layers choose).
    #[arg(long, value_name = "FILE.png")]
    contact_sheet: Option<PathBuf>,
    /// Write a chart of every layer's area, exposure, fill distance, time and islands
    /// against the layer number.
    #[arg(long, value_name = "FILE.png")]
    chart: Option<PathBuf>,
    /// Write a shaded picture of the part built from the masks.
    #[arg(long, value_name = "FILE.png")]
    preview: Option<PathBuf>,
    /// Contact sheet: every Nth layer (from the first of --layers).
    #[arg(long, value_name = "N")]
    every: Option<usize>,
    /// Contact sheet and chart: only layers A..B (inclusive, 0-based; also A.., ..B, A).
    #[arg(long, value_name = "A..B")]
    layers: Option<String>,
}

/// The format of picture `p`, if one was asked for.
fn format_of(p: &Option<PathBuf>) -> Result<Option<(PathBuf, Format)>, crate::Error> {
    p.as_ref()
        .map(|p| super::picture_format(p).map(|f| (p.clone(), f)))
        .transpose()
}

/// Runs `dmdsl inspect`.
pub(crate) fn inspect(a: InspectArgs, quiet: bool) -> anyhow::Result<u8> {
    let sheet_out = format_of(&a.contact_sheet)?;
    let chart_out = format_of(&a.chart)?;
    let preview_out = format_of(&a.preview)?;
    if a.every.is_some() && sheet_out.is_none() {
        return Err(crate::Error::Usage("--every applies to --contact-sheet".into()).into());
    }
    if a.layers.is_some() && sheet_out.is_none() && chart_out.is_none() {
        return Err(crate::Error::Usage(
            "--layers applies to --contact-sheet and --chart; give one of them".into(),
        )
        .into());
    }
    let b = Bundle::open(&a.bundle)?;
    let n = b.manifest.layers.len();
    let range = a
        .layers
        .as_deref()
        .map(|s| crate::exec::parse_layer_range(s, n))
        .transpose()?;
    let mut summary = inspect::summarize(&a.bundle.display().to_string(), &b.manifest);
    summary.format = b.format.name().into();
    summary.notes = b.notes.clone();
    let mut written = |path: &Path| summary.pictures.push(path.display().to_string());
    if let Some((path, format)) = &sheet_out {
        let layers = sheet::select_layers(n, range.clone(), a.every)?;
        let how = match (a.every, &range) {
            (Some(k), _) => format!("every {}", ordinal(k)),
            (None, Some(r)) if layers.len() == r.end() - r.start() + 1 => {
                crate::text::layer_range(*r.start() as u64, *r.end() as u64)
            }
            (None, _) if layers.len() == n => "every layer".into(),
            (None, _) => "evenly spaced".into(),
        };
        let c = sheet::contact_sheet(&b.name(), &b.manifest, b.files.as_ref(), &layers, &how)?;
        inspect::write_picture(path, &c, *format)?;
        written(path);
    }
    if let Some((path, format)) = &chart_out {
        let c = inspect::chart::layer_chart(&b.name(), &b.manifest, range.clone()).render();
        inspect::write_picture(path, &c, *format)?;
        written(path);
    }
    if let Some((path, format)) = &preview_out {
        let c = inspect::preview_picture(&b)?;
        inspect::write_picture(path, &c, *format)?;
        written(path);
    }
    if a.json {
        super::print_json(&summary)?;
    } else if !quiet {
        print!("{}", inspect::summary::render_human(&summary));
    }
    Ok(0)
}

/// "2nd", "10th", "layer" for 1.
fn ordinal(k: usize) -> String {
    if k == 1 {
        return "layer".into();
    }
    let suffix = match (k % 10, k % 100) {
        (1, r) if r != 11 => "st",
        (2, r) if r != 12 => "nd",
        (3, r) if r != 13 => "rd",
        _ => "th",
    };
    format!("{k}{suffix} layer")
}
