//! Layer exposure from the flattened irradiance (docs/CALIBRATION.md, "Exposure"): for an
//! absolute calibration the working curve (Jacobs) at the target irradiance E* replaces the
//! profile's `exposure.layer_s` (`bottom_s` keeps its ratio to it); a relative one (such as
//! Xu et al. 2010's published fit) takes the profile's exposure as the exposure at E*, with
//! no dose. [`resolve`] changes the job's copy of the profile before planning, so the
//! planner keeps calling [`crate::profile::Exposure::layer_exposure_s`].

use super::Units;
use crate::profile::{Profile, Resin};
use crate::text::{fixed, number};
use crate::units::Positive;
use crate::warning::Warning;

/// How a job's exposure was derived.
#[derive(Debug, Clone, PartialEq)]
pub struct ExposureDerivation {
    /// One-line description for the manifest.
    pub rule: String,
    /// Dose of a normal layer at E*, mJ/cm² (absolute calibrations).
    pub dose_mj_cm2: Option<f64>,
    /// Plausibility warnings.
    pub warnings: Vec<Warning>,
}

/// Working-curve exposure, s: time at irradiance `e_mw_cm2` to cure `thickness_mm` plus the
/// resin's overcure.
pub fn working_curve_s(resin: &Resin, e_mw_cm2: f64, thickness_mm: f64) -> f64 {
    resin.ec_mj_cm2.get() / e_mw_cm2
        * ((thickness_mm + resin.overcure_mm.get()) / resin.dp_mm.get()).exp()
}

/// Cure depth (mm) of dose `dose_mj_cm2` in `resin` (0 below the critical energy).
#[cfg(test)]
pub fn cure_depth_mm(resin: &Resin, dose_mj_cm2: f64) -> f64 {
    (resin.dp_mm.get() * (dose_mj_cm2 / resin.ec_mj_cm2.get()).ln()).max(0.0)
}

/// Resolves the job's exposure for a calibration in `units` with target irradiance
/// `target` and layer thickness `thickness_mm`, updating `profile.exposure` for absolute
/// calibrations (see the module docs).
pub fn resolve(
    profile: &mut Profile,
    units: Units,
    target: f64,
    thickness_mm: f64,
) -> ExposureDerivation {
    let resin = profile.resin.clone();
    let e = &mut profile.exposure;
    match units {
        Units::Relative => ExposureDerivation {
            rule: format!(
                "relative calibration: the profile's exposure ({} s per layer) is the exposure at E*; dose unknown",
                e.layer_s
            ),
            dose_mj_cm2: None,
            warnings: Vec::new(),
        },
        Units::MwCm2 => {
            // Exposures are commanded to 1 ms (crate::round::time_s).
            let t = crate::round::time_s(working_curve_s(&resin, target, thickness_mm));
            let ratio = e.bottom_s.get() / e.layer_s.get();
            let dose = target * t;
            let mut warnings = Vec::new();
            let depth = (thickness_mm + resin.overcure_mm.get()) / resin.dp_mm.get();
            if depth > 100f64.ln() {
                warnings.push(
                    Warning::new(
                        "exposure.implausible-dose",
                        format!(
                            "layer {} mm + overcure {} mm is {} Dp deep: the working curve asks {} mJ/cm² (> 100 Ec), implausible for resin {:?}",
                            number(thickness_mm), number(resin.overcure_mm.get()), fixed(depth, 1), fixed(dose, 0), resin.name
                        ),
                    )
                    .with("thickness_mm", thickness_mm)
                    .with("overcure_mm", resin.overcure_mm.get())
                    .with("depth_dp", depth)
                    .with("dose_mj_cm2", dose)
                    .with("resin", resin.name.clone()),
                );
            }
            if t > 600.0 {
                warnings.push(
                    Warning::new(
                        "exposure.too-long",
                        format!(
                            "at E* = {} mW/cm² resin {:?} (Ec {} mJ/cm²) needs {} s per layer: implausible",
                            number(target), resin.name, number(resin.ec_mj_cm2.get()), fixed(t, 0)
                        ),
                    )
                    .with("exposure_s", t)
                    .with("target_irradiance_mw_cm2", target)
                    .with("ec_mj_cm2", resin.ec_mj_cm2.get())
                    .with("resin", resin.name.clone()),
                );
            } else if t < 0.2 {
                warnings.push(
                    Warning::new(
                        "exposure.too-short",
                        format!(
                            "at E* = {} mW/cm² resin {:?} needs only {} s per layer, shorter than shutter timing allows to control",
                            number(target), resin.name, number(t)
                        ),
                    )
                    .with("exposure_s", t)
                    .with("target_irradiance_mw_cm2", target)
                    .with("resin", resin.name.clone()),
                );
            }
            match (
                Positive::new(t),
                Positive::new(crate::round::time_s(t * ratio)),
            ) {
                (Some(l), Some(b)) => {
                    e.layer_s = l;
                    e.bottom_s = b;
                }
                _ => warnings.push(
                    Warning::new(
                        "exposure.not-positive",
                        format!(
                            "working-curve exposure {} s is not a positive number: kept the profile's {} s",
                            number(t), number(e.layer_s.get())
                        ),
                    )
                    .with("exposure_s", if t.is_finite() { t.into() } else { serde_json::Value::Null })
                    .with("kept_s", e.layer_s.get()),
                ),
            }
            ExposureDerivation {
                rule: format!(
                    "working curve: t = (Ec/E*)·exp((Δz + overcure)/Dp) = ({}/{target:.6})·exp(({thickness_mm} + {})/{}) = {:.3} s; bottom layers × {ratio:.3}",
                    resin.ec_mj_cm2, resin.overcure_mm, resin.dp_mm, e.layer_s
                ),
                dose_mj_cm2: Some(dose),
                warnings,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn working_curve_cures_layer_plus_overcure() {
        let r = Profile::default_profile().resin;
        let t = working_curve_s(&r, 5.0, 0.05);
        let depth = cure_depth_mm(&r, 5.0 * t);
        assert!((depth - (0.05 + r.overcure_mm.get())).abs() < 1e-12);
        // Doubling irradiance halves the time.
        assert!((working_curve_s(&r, 10.0, 0.05) * 2.0 - t).abs() < 1e-12);
    }

    #[test]
    fn absolute_sets_exposure_relative_keeps_it() {
        let mut p = Profile::default_profile();
        let before = p.exposure.clone();
        let r = resolve(&mut p, Units::Relative, 123.0, 0.05);
        assert_eq!(p.exposure, before);
        assert!(r.dose_mj_cm2.is_none());
        let r = resolve(&mut p, Units::MwCm2, 5.0, 0.05);
        // Commanded to 1 ms.
        let t = crate::round::time_s(working_curve_s(&p.resin, 5.0, 0.05));
        assert_eq!(p.exposure.layer_s.get(), t);
        let ratio = before.bottom_s.get() / before.layer_s.get();
        assert!((p.exposure.bottom_s.get() - t * ratio).abs() <= 0.0005);
        assert!((r.dose_mj_cm2.unwrap() - 5.0 * t).abs() < 1e-9);
        assert!(r.warnings.is_empty(), "{:?}", r.warnings);
        // The published irradiance read as mW/cm² (really µW/cm²) is implausible.
        let mut p = Profile::default_profile();
        let r = resolve(&mut p, Units::MwCm2, 0.0028, 0.05);
        assert!(
            r.warnings
                .iter()
                .any(|w| w.code == "exposure.too-long" && w.message.contains("implausible")),
            "{:?}",
            r.warnings
        );
    }
}
