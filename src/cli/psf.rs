//! `dmdsl testjob psf` and `dmdsl calibrate psf`: the blur test job (lines and gaps 1 to
//! 8 px wide) with its measurement sheet, and the fit of the point-spread function's σ to
//! the filled-in sheet (docs/CALIBRATION.md, "Blur").

use crate::calib::psf::{self, PsfFit};
use crate::cure::width::Drawn;
use crate::error::Error;
use crate::profile::Profile;
use std::path::Path;

/// Writes the blur job and its sheet.
pub(crate) fn psf_job(output: &Path, profile: &str, quiet: bool) -> anyhow::Result<u8> {
    let mut p = Profile::resolve(profile)?;
    let pat = psf::pattern(&p).map_err(Error::Usage)?;
    // Every layer at the layer exposure, so the lines' and gaps' layers are exposed alike
    // in every form the job is written in (SL1 fades its first layers' exposure).
    p.exposure.bottom_s = p.exposure.layer_s;
    // A continuous slice is exposed for its sweep: make the sweep last `layer_s` too.
    let (layer_mm, layer_s) = (p.slicing.layer_height_mm.get(), p.exposure.layer_s.get());
    if let Some(h) = &mut p.hybrid {
        h.continuous_speed_mm_s =
            crate::units::Positive::new(layer_mm / layer_s).expect("a positive speed");
    }
    let px = p.field().pixel_mm;
    let mut o = crate::job::SliceOptions::new("psf.stl", output, p);
    o.input_bytes = Some(&pat.stl);
    o.placement = crate::job::PlacementMode::Keep;
    // The masks draw the lines and gaps exactly: their widths are what is fitted.
    o.cure.correction = Some(crate::cure::Correction::Off);
    let mut sheet = String::from(
        "feature,kind,axis,place,x_mm,y_mm,projector,drawn_px,drawn_mm,layers,printed_mm\n",
    );
    for (i, f) in pat.features.iter().enumerate() {
        let [x, y] = f.centre_mm;
        let kind = match f.kind {
            Drawn::Line => "line",
            Drawn::Gap => "gap",
        };
        sheet += &format!(
            "{},{kind},{},{},{x:.4},{y:.4},{},{},{:.4},{},\n",
            i + 1,
            f.axis,
            f.place,
            f.projector,
            f.drawn_px,
            f.drawn_px as f64 * px,
            psf::FEATURE_LAYERS
        );
    }
    let (s, sheet_path) = super::testjob::slice_with_sheet(&o, &sheet)?;
    if !quiet {
        super::print_warnings(&s.warnings, "");
        println!(
            "{}: {} layers ({} base, {} of lines and gaps); sheet {} ({} features)",
            s.bundle.display(),
            s.layers,
            pat.base_layers,
            psf::FEATURE_LAYERS,
            sheet_path.display(),
            pat.features.len()
        );
        println!("fill in printed_mm (each width where the feature meets its base plate), then `dmdsl calibrate psf`");
    }
    Ok(0)
}

/// Runs `dmdsl calibrate psf SHEET -o FILE`.
pub(crate) fn calibrate_psf(
    input: &Path,
    output: &Path,
    profile: &str,
    resin: Option<&Path>,
    quiet: bool,
) -> anyhow::Result<u8> {
    let mut p = Profile::resolve(profile)?;
    if let Some(r) = resin {
        crate::calib::ResinFit::apply_file(r, &mut p)?;
    }
    // The model's σ is what is fitted: any stands in.
    for q in &mut p.projector {
        q.psf_sigma_px = q
            .psf_sigma_px
            .or(crate::units::Positive::new(psf::SIGMA_BRACKET[0]));
    }
    let model = crate::cure::CureModel::from_profile(&p).expect("every projector has a σ");
    let required = [
        "feature",
        "kind",
        "projector",
        "drawn_px",
        "layers",
        "printed_mm",
    ];
    let sheet = crate::calib::Sheet::read(input, &required)?;
    let f = psf::fit_psf(&sheet, &model)?;
    let head = format!("# dmdsl blur calibration, fitted by `dmdsl calibrate psf {}` with profile {}:\n# the Gaussian point-spread function's sigma per projector, least squares of the printed\n# widths against the cure model's. Use it with `dmdsl slice --psf FILE`.\n", input.display(), p.name);
    let toml = head + &toml::to_string(&f).expect("fit serializes");
    let png = super::testjob::write_fit(output, toml, &f.chart())?;
    if !quiet {
        report(&f, output, &png);
    }
    Ok(0)
}

/// Prints the fit: σ, the residuals, the model's table.
fn report(f: &PsfFit, output: &Path, png: &Path) {
    for p in &f.projector {
        println!(
            "{}: projector {}: psf_sigma_px = {:.4} ± {:.4} px from {} measured features; residual RMS {:.4} mm",
            output.display(),
            p.name,
            p.psf_sigma_px,
            p.psf_sigma_se_px,
            p.measured,
            p.residual_rms_mm
        );
        for r in &p.residuals {
            println!(
                "  line {}: feature {} {} {} px: printed {:.4} mm, model {:.4} mm, residual {} mm",
                r.line,
                r.feature,
                r.kind,
                r.drawn_px,
                r.printed_mm,
                r.predicted_mm,
                crate::text::signed(r.residual_mm, 4)
            );
        }
        println!(
            "  model at σ = {:.4} px, {} layers: drawn px, drawn mm, line mm, gap mm",
            p.psf_sigma_px, f.layers
        );
        for m in &p.model {
            println!(
                "  {:>3} {:>8.4} {:>8.4} {:>8.4}",
                m.drawn_px, m.drawn_mm, m.line_mm, m.gap_mm
            );
        }
    }
    println!("plot: {}", png.display());
}
