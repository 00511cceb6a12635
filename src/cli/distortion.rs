//! `dmdsl distortion`: fit a lens distortion table and report its quality.

use crate::geometry::distortion::DistortionChoice;
use crate::profile::{self, Profile};
use clap::Args;
use std::path::PathBuf;

pub(crate) const DISTORTION_EXIT_HELP: &str = "Exit codes:
  0    the table was fitted (and the plot written)
  2    usage or input error (unreadable or malformed table, bad profile)";

#[derive(Args)]
pub(crate) struct DistortionArgs {
    /// The table: CSV x_mm,y_mm,seen_x_mm,seen_y_mm, one row per measured point: the
    /// uncorrected projector aimed at (x, y) and the light landed at (seen_x, seen_y), mm
    /// from the field's bottom-left corner.
    table: PathBuf,
    /// Machine profile whose projector field the table describes.
    #[arg(short, long, default_value = profile::DEFAULT_PROFILE)]
    profile: String,
    /// Write a heatmap of the correction over the field (gray: unreachable) to this
    /// picture, PNG or JPEG by its extension (.png, .jpg, .jpeg).
    #[arg(long, value_name = "FILE.png|FILE.jpg")]
    plot: Option<PathBuf>,
    /// Print the fit report as JSON on stdout.
    #[arg(long)]
    pub(crate) json: bool,
}

/// Runs `dmdsl distortion`.
pub(crate) fn distortion(a: DistortionArgs, quiet: bool) -> anyhow::Result<u8> {
    let plot_format = a.plot.as_deref().map(super::picture_format).transpose()?;
    let mut profile = Profile::resolve(&a.profile)?;
    let c = crate::geometry::distortion::for_job(&DistortionChoice::Table(a.table), &mut profile)?
        .expect("a table was given");
    let report = c.report();
    let (_, _, map) = c.field_map(1.0);
    let reachable = crate::round::derived(
        map.iter().filter(|v| v.is_finite()).count() as f64 / map.len() as f64,
    );
    if let (Some(p), Some(format)) = (&a.plot, plot_format) {
        let bytes = c.plot().render().encode(format);
        crate::output::write_atomic(p, &bytes)?;
    }
    if a.json {
        let v =
            serde_json::json!({ "ok": true, "report": report, "reachable_fraction": reachable });
        super::print_json(&v)?;
    } else if !quiet {
        println!("{}", report.summary());
        println!(
            "reachable: {:.1} % of the {:.2} x {:.2} mm field (1 mm cells)",
            reachable * 100.0,
            profile.field().width_mm(),
            profile.field().height_mm()
        );
    }
    Ok(0)
}
