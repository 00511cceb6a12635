//! Machine profiles: the projector(s), stage, shutter, DMD, exposure, resin and process
//! settings a job is compiled for, as TOML (built-ins compiled in from `profiles/*.toml`).
//! Every key is required and unknown keys are errors, so a typo never falls back to a
//! default. Besides the profile itself: the process sections ([`Recoat`], [`Peel`],
//! [`Hybrid`]), the lens correction table ([`DistortionConfig`]), the overlap ramp
//! ([`BlendCurve`]), a projector's light [`calibration`] and single-key changes
//! ([`Override`], `slice --set`). Uses only leaf modules; a job records the keys it runs by
//! (`bundle::Machine`).

mod accuracy;
mod blend;
pub mod calibration;
mod distortion;
mod overrides;
mod process;
mod supports;

pub use accuracy::Accuracy;
pub use blend::BlendCurve;
pub use calibration::Calibration;
pub use distortion::DistortionConfig;
pub use overrides::Override;
pub use process::{Hybrid, OlhStep, Peel, Recoat, WaitModel};
pub use supports::Supports;

use crate::error::{Error, Result};
use crate::units::{NonNegative, Positive};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The built-in profiles' TOML sources, `profiles/NAME.toml`, by name.
macro_rules! builtin {
    ($($name:literal),*) => {
        [$(($name, include_str!(concat!("../../profiles/", $name, ".toml")))),*]
    };
}

/// Built-in profiles: (name, TOML source).
pub const BUILTIN: &[(&str, &str)] = &builtin![
    "xu2010-topdown",
    "hybrid-bottomup",
    "bottom-up",
    "tiled-2x1"
];

/// Name of the profile used when `--profile` is not given.
pub const DEFAULT_PROFILE: &str = "xu2010-topdown";

/// How the machine forms layers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Process {
    /// Platform sinks into the vat; layers cure at the free resin surface (Xu et al. 2010).
    TopDown,
    /// Platform rises from a window; each layer is peeled off the window.
    BottomUp,
    /// Bottom-up over a liquid interface; continuous where resin can refill.
    Hybrid,
}

/// A complete machine profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// Short identifier.
    pub name: String,
    /// One-line description.
    pub description: String,
    /// Layer-forming process.
    pub process: Process,
    /// The projectors (one DMD each); at least one.
    pub projector: Vec<Projector>,
    /// Slicing settings.
    pub slicing: Slicing,
    /// Lift stage.
    pub stage: Stage,
    /// Exposure shutter.
    pub shutter: Shutter,
    /// DMD timing.
    pub dmd: Dmd,
    /// Exposure times.
    pub exposure: Exposure,
    /// Resin working-curve parameters.
    pub resin: Resin,
    /// Top-down recoat settings (required when `process = "top-down"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recoat: Option<Recoat>,
    /// Bottom-up peel settings (required when `process = "bottom-up"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peel: Option<Peel>,
    /// Hybrid continuous/layered settings (required when `process = "hybrid"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hybrid: Option<Hybrid>,
    /// Lens distortion correction table (docs/GEOMETRY.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<DistortionConfig>,
    /// Edge blending across projector overlaps (default: raised cosine; docs/GEOMETRY.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blend: Option<BlendCurve>,
    /// Supports, pad and elevation (off unless `enabled`; a profile without the section
    /// takes the defaults).
    #[serde(default)]
    pub supports: Supports,
    /// The dimensional correction (a profile without the section corrects nothing).
    #[serde(default, skip_serializing_if = "Accuracy::is_identity")]
    pub accuracy: Accuracy,
}

/// One DMD projector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Projector {
    /// Name, used for mask folders when several projectors tile the field.
    pub name: String,
    /// Mirror columns.
    pub width_px: u32,
    /// Mirror rows.
    pub height_px: u32,
    /// Edge of one (square) pixel on the build plane, mm.
    pub pixel_mm: Positive,
    /// Offset of this projector's top-left pixel in the field's pixel grid (col, row).
    pub offset_px: [u32; 2],
    /// Mirror the image left-right (applied last).
    pub mirror_x: bool,
    /// Mirror the image top-bottom (applied last).
    pub mirror_y: bool,
    /// Light-uniformity calibration of this projector (`[projector.calibration]`; see
    /// docs/CALIBRATION.md). Without one the projector's masks are not compensated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<Calibration>,
    /// Standard deviation of the projector's point-spread function on the build plane,
    /// pixels (a Gaussian; docs/CURE.md). Without it the job predicts and corrects no cure
    /// (profiles written before the key existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psf_sigma_px: Option<Positive>,
    /// The measurement sheet `psf_sigma_px` was fitted to (`dmdsl calibrate psf`: its name
    /// and SHA-256); without it σ is assumed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psf_source: Option<String>,
    /// The light engine's wavelength, nm, when the machine has a choice (the SLA
    /// control-file export writes it; without it, the schema's default 365 nm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wavelength_nm: Option<u32>,
    /// The light engine's power setting, 0 to 1000 (the control-file export writes it;
    /// without it, the schema's default 100).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub power_setting: Option<u32>,
}

/// The smallest pixel on the build plane a profile may give, mm (1 µm).
pub const PIXEL_MM_MIN: f64 = 0.001;
/// The largest pixel on the build plane a profile may give, mm.
pub const PIXEL_MM_MAX: f64 = 1.0;
/// The largest field, in pixels each way, that projectors and their offsets may span.
pub const FIELD_PX_MAX: u32 = 65536;

impl Projector {
    /// Checks that calibration `c` can be applied to this projector: valid in itself, and
    /// zones no smaller than a pixel (a zone grid finer than the pixels means nothing and
    /// would take memory without bound).
    pub fn check_calibration(&self, c: &Calibration) -> std::result::Result<(), String> {
        c.validate()
            .map_err(|m| format!("projector {} calibration: {m}", self.name))?;
        if c.zone_mm.get() < self.pixel_mm.get() {
            return Err(format!(
                "projector {} calibration: zone_mm = {:?} is smaller than a pixel ({:?} mm)",
                self.name,
                c.zone_mm.get(),
                self.pixel_mm.get()
            ));
        }
        Ok(())
    }
}

/// Slicing settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Slicing {
    /// Layer thickness, mm.
    pub layer_height_mm: Positive,
    /// Threshold coverage at 50 % instead of writing 8-bit anti-aliased coverage.
    pub binary: bool,
}

/// Lift stage limits and resolution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stage {
    /// Lowest allowed stage coordinate, mm.
    pub travel_min_mm: f64,
    /// Highest allowed stage coordinate, mm.
    pub travel_max_mm: f64,
    /// Where homing leaves the stage, mm.
    pub home_mm: f64,
    /// Speed limit, mm/s.
    pub max_speed_mm_s: Positive,
    /// Acceleration limit, mm/s².
    pub max_accel_mm_s2: Positive,
    /// Position resolution, steps (or encoder counts) per mm.
    pub steps_per_mm: Positive,
}

/// Exposure shutter timing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shutter {
    /// Opening latency, s.
    pub open_s: NonNegative,
    /// Closing latency, s.
    pub close_s: NonNegative,
}

/// DMD timing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dmd {
    /// Time to load one mask, s.
    pub load_s: NonNegative,
}

/// The most layers a job may have. At 1 µm layers that is a part 1 m tall; a larger count
/// comes from a far-off vertex or a mistyped layer height, and would write a mask per layer.
pub const MAX_LAYERS: usize = 1_000_000;

/// Exposure times.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Exposure {
    /// Normal layer exposure, s.
    pub layer_s: Positive,
    /// Number of bottom layers.
    pub bottom_layers: u32,
    /// Bottom layer exposure, s.
    pub bottom_s: Positive,
    /// Layers ramping linearly from `bottom_s` to `layer_s` after the bottom layers.
    pub transition_layers: u32,
}

impl Exposure {
    /// Exposure time of layer `index` from the bottom/transition/normal rule.
    pub fn layer_exposure_s(&self, index: usize) -> f64 {
        let b = self.bottom_layers as usize;
        let t = self.transition_layers as usize;
        if index < b {
            self.bottom_s.get()
        } else if index < b + t {
            let k = (index - b + 1) as f64 / (t + 1) as f64;
            self.bottom_s.get() + (self.layer_s.get() - self.bottom_s.get()) * k
        } else {
            self.layer_s.get()
        }
    }
}

/// Resin working-curve parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Resin {
    /// Resin name.
    pub name: String,
    /// Penetration depth Dp, mm.
    pub dp_mm: Positive,
    /// Critical energy Ec, mJ/cm².
    pub ec_mj_cm2: Positive,
    /// Cure depth beyond the layer thickness, mm.
    pub overcure_mm: NonNegative,
    /// Dynamic viscosity, Pa·s.
    pub viscosity_pa_s: Positive,
    /// The measurement sheet Dp was fitted to (`dmdsl calibrate resin`: its name and
    /// SHA-256); without it Dp is assumed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dp_source: Option<String>,
    /// The same for Ec (fitted only to absolute doses).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ec_source: Option<String>,
}

/// Size of the whole build field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Field {
    /// Field width in pixels (union of all projectors).
    pub width_px: u32,
    /// Field height in pixels.
    pub height_px: u32,
    /// Pixel edge, mm.
    pub pixel_mm: f64,
}

impl Field {
    /// Field width, mm.
    pub fn width_mm(&self) -> f64 {
        self.width_px as f64 * self.pixel_mm
    }
    /// Field height, mm.
    pub fn height_mm(&self) -> f64 {
        self.height_px as f64 * self.pixel_mm
    }
}

impl Profile {
    /// Loads a built-in profile by name or a TOML file by path.
    ///
    /// A value containing a path separator or ending in `.toml`, or naming an existing
    /// file, is read as a file; anything else must be a built-in name.
    pub fn resolve(name_or_path: &str) -> Result<Profile> {
        if let Some((_, src)) = BUILTIN.iter().find(|(n, _)| *n == name_or_path) {
            return Profile::from_toml(src, name_or_path);
        }
        let p = Path::new(name_or_path);
        if name_or_path.contains('/') || name_or_path.ends_with(".toml") || p.exists() {
            let src = crate::input::read_text(p, "profile")?;
            let mut profile = Profile::from_toml(&src, &p.display().to_string())?;
            // A distortion table is named relative to the profile file.
            if let Some(t) = profile.distortion.as_mut().and_then(|d| d.table.as_mut()) {
                if let Some(dir) = p.parent().filter(|_| Path::new(t.as_str()).is_relative()) {
                    *t = dir.join(&*t).to_string_lossy().into_owned();
                }
            }
            return Ok(profile);
        }
        Err(Error::Profile {
            origin: name_or_path.to_string(),
            msg: format!(
                "no built-in profile or file of that name (built-in: {})",
                builtin_names().join(", ")
            ),
        })
    }

    /// The built-in default profile.
    pub fn default_profile() -> Profile {
        Profile::resolve(DEFAULT_PROFILE).expect("built-in default profile is valid")
    }

    /// Parses and validates a profile from TOML text; `origin` names it in errors.
    pub fn from_toml(src: &str, origin: &str) -> Result<Profile> {
        let profile: Profile = toml::from_str(src).map_err(|e| Error::Profile {
            origin: origin.to_string(),
            msg: one_line(&e.to_string()),
        })?;
        profile.validate().map_err(|msg| Error::Profile {
            origin: origin.to_string(),
            msg,
        })?;
        Ok(profile)
    }

    /// The profile as TOML (used by `profile show` for files and in tests).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("profile serializes")
    }

    /// Checks the cross-field rules serde cannot express.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if self.projector.is_empty() {
            return Err("at least one [[projector]] is required".into());
        }
        let px = self.projector[0].pixel_mm.get();
        for p in &self.projector {
            let size = (p.width_px, p.height_px);
            check_projector(&p.name, size, p.pixel_mm.get(), p.offset_px)?;
            check_same_pixel(p.pixel_mm.get(), px)?;
            if let Some(c) = &p.calibration {
                p.check_calibration(c)?;
            }
            if let Some(s) = p
                .psf_sigma_px
                .map(|s| s.get())
                .filter(|s| !(0.05..=5.0).contains(s))
            {
                return Err(format!(
                    "projector {}: psf_sigma_px = {s:?} is not a point-spread width in pixels (0.05 to 5)",
                    p.name
                ));
            }
        }
        check_unit_ranges(&serde_json::to_value(self).map_err(|e| e.to_string())?, "")?;
        let s = &self.stage;
        let step_mm = 1.0 / s.steps_per_mm.get();
        if step_mm > self.slicing.layer_height_mm.get() {
            return Err(format!(
                "stage.steps_per_mm = {:?} gives steps of {} mm, coarser than the layer height ({:?} mm)",
                s.steps_per_mm.get(),
                crate::text::number(step_mm),
                self.slicing.layer_height_mm.get()
            ));
        }
        check_travel(s.travel_min_mm, s.travel_max_mm, s.home_mm)?;
        let e = &self.exposure;
        for (key, n) in [
            ("bottom_layers", e.bottom_layers),
            ("transition_layers", e.transition_layers),
        ] {
            if n as usize > MAX_LAYERS {
                return Err(format!(
                    "exposure.{key} = {n} is more layers than a job may have ({MAX_LAYERS})"
                ));
            }
        }
        if let Some(d) = &self.distortion {
            d.validate()?;
        }
        if let Some(b) = &self.blend {
            b.validate()?;
        }
        self.supports.validate()?;
        self.accuracy.validate()?;
        process::validate(self)
    }

    /// The build field covered by the union of the projectors.
    pub fn field(&self) -> Field {
        Field::spanning(
            self.projector
                .iter()
                .map(|p| (p.offset_px, p.width_px, p.height_px)),
            self.projector[0].pixel_mm.get(),
        )
    }
}

impl Field {
    /// The field spanned by projectors of `(offset_px, width_px, height_px)` with pixels
    /// `pixel_mm` wide.
    pub fn spanning(
        projectors: impl Iterator<Item = ([u32; 2], u32, u32)>,
        pixel_mm: f64,
    ) -> Field {
        let (mut width_px, mut height_px) = (0, 0);
        for ([x, y], w, h) in projectors {
            width_px = width_px.max(x + w);
            height_px = height_px.max(y + h);
        }
        Field {
            width_px,
            height_px,
            pixel_mm,
        }
    }
}

/// Checks one projector's size, pixel and offset (a profile's, or a job's machine record's).
pub(crate) fn check_projector(
    name: &str,
    (width_px, height_px): (u32, u32),
    pixel_mm: f64,
    offset_px: [u32; 2],
) -> std::result::Result<(), String> {
    if width_px == 0 || height_px == 0 {
        return Err(format!(
            "projector {name}: width_px and height_px must be > 0"
        ));
    }
    if width_px > 16384 || height_px > 16384 {
        return Err(format!("projector {name}: resolution above 16384 px"));
    }
    if !(PIXEL_MM_MIN..=PIXEL_MM_MAX).contains(&pixel_mm) {
        return Err(format!(
            "projector {name}: pixel_mm = {pixel_mm:?} is not a pixel size on the build plane ({PIXEL_MM_MIN} to {PIXEL_MM_MAX} mm; was it given in µm?)"
        ));
    }
    for (k, (off, size)) in [(offset_px[0], width_px), (offset_px[1], height_px)]
        .into_iter()
        .enumerate()
    {
        if u64::from(off) + u64::from(size) > u64::from(FIELD_PX_MAX) {
            return Err(format!(
                "projector {name}: offset_px[{k}] = {off} puts its pixels beyond the largest field ({FIELD_PX_MAX} px each way)"
            ));
        }
    }
    Ok(())
}

/// Checks that a projector's pixel is the first projector's.
pub(crate) fn check_same_pixel(pixel_mm: f64, first_mm: f64) -> std::result::Result<(), String> {
    if (pixel_mm - first_mm).abs() > 1e-12 {
        return Err("all projectors must have the same pixel_mm".into());
    }
    Ok(())
}

/// Checks a stage's travel and home: finite, the travel's ends in order, home inside.
pub(crate) fn check_travel(min: f64, max: f64, home: f64) -> std::result::Result<(), String> {
    if !(min.is_finite() && max.is_finite() && home.is_finite()) {
        return Err("stage travel and home must be finite numbers".into());
    }
    if min >= max {
        return Err("stage.travel_min_mm must be below stage.travel_max_mm".into());
    }
    if home < min || home > max {
        return Err("stage.home_mm must lie inside the stage travel".into());
    }
    Ok(())
}

/// Physical ranges of the quantities a profile holds, by the unit its key ends with (every
/// key carries its unit): durations, speeds, accelerations and lengths. A value outside is
/// a typo or a unit mix-up (µm for mm, ms for s), and would plan a job that overflows.
/// The longest duration a profile may give (a layer's exposure, a wait), s: about 11 days.
pub const MAX_DURATION_S: f64 = 1e6;

const UNIT_RANGES: [(&str, &str, f64, f64); 6] = [
    // (key suffix, what, smallest magnitude when not 0, largest magnitude)
    ("_pa_s", "a viscosity", 1e-6, 1e6),
    ("_mm_s2", "an acceleration", 1e-6, 1e6),
    ("_mm_s", "a speed", 1e-6, 1e4),
    ("steps_per_mm", "a stage resolution", 1e-3, 1e7),
    ("_s", "a duration", 0.0, MAX_DURATION_S),
    ("_mm", "a length", 0.0, 1e4),
];

/// Checks `f`, the value of key `key` (at dotted path `path`), against the range of the
/// unit the key names ([`UNIT_RANGES`]); a key of no unit passes.
pub(crate) fn check_unit(path: &str, key: &str, f: f64) -> std::result::Result<(), String> {
    let Some((_, what, lo, hi)) = UNIT_RANGES
        .iter()
        .find(|(suffix, ..)| key.ends_with(suffix))
    else {
        return Ok(());
    };
    let a = f.abs();
    if a > *hi || (a != 0.0 && a < *lo) {
        return Err(format!(
            "{path} = {f:?} is not {what} a machine has ({lo:?} to {hi:?}; check its unit)"
        ));
    }
    Ok(())
}

/// Checks every number of `v` (a profile as JSON) whose key names a unit in
/// [`UNIT_RANGES`]; `path` is the dotted key of `v`.
pub(crate) fn check_unit_ranges(
    v: &serde_json::Value,
    path: &str,
) -> std::result::Result<(), String> {
    use serde_json::Value;
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                if let Some(f) = x.as_f64() {
                    check_unit(&p, k, f)?;
                }
                check_unit_ranges(x, &p)?;
            }
            Ok(())
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                check_unit_ranges(x, &format!("{path}[{i}]"))?;
            }
            Ok(())
        }
        _ => Ok(()),
    }
}

/// Names of the built-in profiles.
pub fn builtin_names() -> Vec<&'static str> {
    BUILTIN.iter().map(|(n, _)| *n).collect()
}

/// TOML source of a built-in profile, with its comments.
pub fn builtin_source(name: &str) -> Option<&'static str> {
    BUILTIN.iter().find(|(n, _)| *n == name).map(|(_, s)| *s)
}

pub(crate) fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtins_parse_and_the_default_field_is_1024_by_768() {
        for (name, src) in BUILTIN {
            let p = Profile::from_toml(src, name).unwrap();
            assert_eq!(&p.name, name);
            // A profile survives a round trip through TOML unchanged.
            assert_eq!(Profile::from_toml(&p.to_toml(), name).unwrap(), p);
        }
        let d = Profile::default_profile();
        let f = d.field();
        assert_eq!((f.width_px, f.height_px), (1024, 768));
        assert_eq!(f.pixel_mm, 0.0634765625);
        assert_eq!(f.width_mm(), 65.0);
        assert_eq!(f.height_mm(), 48.75);
        assert_eq!(d.slicing.layer_height_mm.get(), 0.05);
        assert_eq!(d.exposure.layer_s.get(), 8.0);
    }

    #[test]
    fn unknown_keys_missing_and_out_of_range_values_are_one_line_errors() {
        let src = builtin_source(DEFAULT_PROFILE).unwrap();
        let err = |from: &str, to: &str| {
            let bad = src.replace(from, to);
            assert_ne!(bad, src);
            Profile::from_toml(&bad, "x.toml").unwrap_err().to_string()
        };
        let e = err("binary = false", "binary = false\nbinnary = true");
        assert!(e.contains("unknown field `binnary`"), "{e}");
        let e = err("layer_height_mm = 0.05\n", "");
        assert!(e.contains("missing field `layer_height_mm`"), "{e}");
        let e = err("layer_height_mm = 0.05", "layer_height_mm = 0.0");
        assert!(
            e.contains("must be a finite number > 0") && !e.contains('\n'),
            "{e}"
        );
        for bad in ["9.0", "0.01"] {
            let e = err("psf_sigma_px = 0.5", &format!("psf_sigma_px = {bad}"));
            let want = format!("psf_sigma_px = {bad} is not a point-spread width");
            assert!(e.contains(&want), "{e}");
        }
    }

    #[test]
    fn exposure_ramp() {
        let mut e = Profile::default_profile().exposure;
        e.bottom_layers = 2;
        e.transition_layers = 3;
        e.bottom_s = Positive::new(16.0).unwrap();
        e.layer_s = Positive::new(8.0).unwrap();
        let v: Vec<f64> = (0..6).map(|i| e.layer_exposure_s(i)).collect();
        assert_eq!(v, vec![16.0, 16.0, 14.0, 12.0, 10.0, 8.0]);
    }
}
