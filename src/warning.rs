//! Warnings a script can act on: each has a stable code, a severity and its figures as
//! fields, beside the one-line message people read.
//!
//! Codes are `area.kebab-name` (e.g. `mesh.degenerate-facets`, `plan.wait-capped`) and never
//! change meaning once released; the message may be reworded. The figures a message quotes
//! are also in `fields`, so a script never parses the message. Every code this build can
//! raise is listed in [`CODES`] with its severity and meaning (the table of
//! `docs/WARNINGS.md`); making a warning with a code not listed there is a bug, caught by a
//! debug assertion.

use serde::{Deserialize, Serialize};

/// How much a warning matters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Severity {
    /// Worth knowing; the job is as asked.
    Note,
    /// The job may not print as the user expects.
    Warning,
    /// Treated as a failure (a warning raised by `--deny-warnings` or `-W CODE=error`).
    Error,
}

/// One warning.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Warning {
    /// Stable code, `area.kebab-name`.
    pub code: String,
    /// How much it matters.
    pub severity: Severity,
    /// One line for people.
    pub message: String,
    /// The figures the message quotes, by name (with their unit in the name, e.g.
    /// `wait_s`).
    #[serde(default, skip_serializing_if = "serde_json::Map::is_empty")]
    pub fields: serde_json::Map<String, serde_json::Value>,
}

/// A code this build can raise.
#[derive(Debug, Clone, Copy)]
pub struct Code {
    /// The code, `area.kebab-name`.
    pub code: &'static str,
    /// Its severity.
    pub severity: Severity,
    /// What it means.
    pub meaning: &'static str,
    /// Its figures (`fields`), comma-separated.
    pub fields: &'static str,
    /// What to do about it: the last clause of every message of the code.
    pub remedy: &'static str,
}

const fn code(
    code: &'static str,
    severity: Severity,
    fields: &'static str,
    meaning: &'static str,
    remedy: &'static str,
) -> Code {
    Code {
        code,
        severity,
        meaning,
        fields,
        remedy,
    }
}

use Severity::{Note, Warning as Warn};

/// Every code this build can raise (documented in `docs/WARNINGS.md`, in this order): code,
/// severity, figures and, on the next line, meaning and remedy.
#[rustfmt::skip]
pub const CODES: &[Code] = &[
    code("mesh.open-edges", Warn, "open_edges",
        "the mesh has edges with one facet (holes); open section contours are closed or dropped by the repair rule", "close the holes in the CAD tool or a mesh repairer, then check the repaired layers (`dmdsl inspect`)"),
    code("mesh.nonmanifold-edges", Warn, "nonmanifold_edges",
        "the mesh has edges shared by more than two facets", "repair the mesh (separate the touching shells) in the CAD tool or a mesh repairer"),
    code("mesh.backwards-edges", Warn, "backwards_edges",
        "facets are inconsistently oriented; each contour takes the orientation most of its segments agree with", "repair the mesh (orient its facets consistently), then check the layers (`dmdsl inspect`)"),
    code("mesh.degenerate-facets", Note, "degenerate_facets",
        "facets with a repeated corner (removed) or zero area (kept); the solid is unchanged", "nothing to do (a mesh repairer removes them)"),
    code("mesh.inverted-normals", Note, "volume_mm3",
        "the normals point inwards (negative volume); the slicer flips the orientation", "nothing to do (a mesh exported with outward normals does not raise it)"),
    code("slice.contours-repaired", Warn, "layers, closed, dropped",
        "layers had open contours: chains were joined or closed, or dropped", "repair the mesh and check the repaired layers with `dmdsl inspect`"),
    code("distortion.extrapolated", Warn, "points, table",
        "warped points lie outside the area the distortion table measured; their correction is extrapolated", "measure the distortion table over the whole area the part uses, or place the part inside the measured area"),
    code("plan.wait-capped", Note, "layers, layers_total, wait_max_s, model_max_s, model_max_layer, flat_patch_mm",
        "the thin-film leveling model asks a longer wait than the profile's recoat.wait_max_s on some layers; they wait the cap", "level large flat layers with a recoater blade or a sweep, print thicker layers (the time falls with the cube of the thickness), or raise recoat.wait_max_s if the machine can wait that long"),
    code("plan.travel-clamped", Warn, "moves, travel_max_mm",
        "lifts or dips were shortened to end at the top of the stage travel", "check that the shortened moves still separate and recoat the layers; lower the lift or dip, or give the machine's real stage.travel_max_mm"),
    code("plan.beyond-lift-table", Warn, "slices, max_fill_distance_mm, table_max_mm, lift_mm",
        "slices have a max fill distance beyond the hybrid lift table; they use its last row's lift", "add a [[hybrid.olh]] row that reaches this fill distance"),
    code("plan.bottom-layers-cover-job", Warn, "bottom_layers, transition_layers, layers_total",
        "the profile's bottom and transition layers reach past the job's last layer: no layer is exposed the normal layer_s", "lower exposure.bottom_layers (--bottom-layers) and exposure.transition_layers to the layers that should bond to the build platform"),
    code("plan.unsupported-islands", Warn, "islands, layers, first_layer, largest_mm",
        "regions of a layer rest on nothing in the layer below and need supports (largest_mm: per layer with islands, its largest island as [layer, x, y, area], mm and mm²)", "slice with --supports to hold them, or orient the part so that they rest on the layer below"),
    code("run.unsupported-regions", Warn, "regions, layers, first_layer, largest_mm",
        "regions of a layer's masks rest on nothing in the layer below, in a job without supports (`dmdsl run`, from the masks; largest_mm: per layer with such regions, its largest as [layer, x, y, area], mm and mm²)", "add supports under these regions (`dmdsl slice --supports`), or orient the part so that they rest on the layer below"),
    code("exposure.implausible-dose", Warn, "thickness_mm, overcure_mm, depth_dp, dose_mj_cm2, resin",
        "the working curve asks more than 100 Ec to cure the layer and its overcure", "check the resin's working curve (Dp, Ec), the layer height and the overcure"),
    code("exposure.too-long", Warn, "exposure_s, target_irradiance_mw_cm2, ec_mj_cm2, resin",
        "the working-curve exposure is over 600 s per layer: check the calibration's units and the resin", "check the calibration's units (µW or mW per cm²) and the resin's Ec"),
    code("exposure.too-short", Warn, "exposure_s, target_irradiance_mw_cm2, resin",
        "the working-curve exposure is under 0.2 s per layer, shorter than the shutter can control", "check the calibration's units (µW or mW per cm²); if they are right, dim the light so that the shutter can time the exposure"),
    code("exposure.not-positive", Warn, "exposure_s, kept_s",
        "the working-curve exposure is not a positive number; the profile's exposure is kept", "check the resin's working curve and the calibration"),
    code("cure.features-vanish", Warn, "features, layers, first_layer, x_mm, y_mm, width_mm, height_mm",
        "the cure model predicts that features of these layers cure nowhere (too narrow for the blur and dose); they will be missing from the part", "widen these features in the model or raise the exposure"),
    code("cure.features-widened", Warn, "features, layers, first_layer, x_mm, y_mm, width_mm, height_mm, wall_mm",
        "the xy correction drew features too thin to cure wider (their uncorrected coverage, then up to 1 px outward) so that they cure: they come out at the smallest size the machine makes, larger than the part's (wall_mm: the width of a ring's walls or a slanted bar, which the box does not show; else 0)", "nothing to do if the larger size is acceptable; otherwise these features are too fine for the machine: widen them in the model"),
    code("cure.features-on-nothing", Warn, "features, layers, first_layer, x_mm, y_mm, width_mm, height_mm",
        "the xy correction left features too thin to cure as it drew them, not wider, because they rest on nothing in the layer below (widened, they would cure loose; the sections do not light them, so no support reaches them): they will be missing from the part", "thicken these features in the model so that they are lit, or give them something to rest on"),
    code("cure.features-dropped", Warn, "features, pixels, layers, first_layer, x_mm, y_mm, width_mm, height_mm, held_back_layers",
        "the xyz correction leaves out flat features over nothing thinner than its held-back layers plus one (a tab, a thin plate): they will be missing from the part", "use --cure-correction xy, or make these features thicker"),
    code("cure.layers-uncorrected", Warn, "layers, first_layer, uncorrected, windows, whole",
        "in a job with supports, the correction moved in or broke up the first layers of thin features so that regions of them or of the layer above would rest on nothing: these layers (uncorrected: their indices) are drawn without it in windows around those regions (windows: how many), or whole where a window does not hold them (whole: those layers), their edges there where the section's are (outside by the cure's growth, a fraction of a pixel)", "nothing to do if the size there is acceptable; otherwise thicken the thin features in the model, or orient the part so that they do not start over supports"),
    code("cure.features-merge", Warn, "contours, layers, first_layer",
        "the cure model predicts that cure reaches across gaps of these layers (slots or holes narrower than the blur): neighbouring features join", "widen the gaps in the model or lower the exposure"),
    code("optics.outside-calibrated-area", Note, "layers, area_mm, beyond_mm, extrapolate_mm",
        "layers reach outside the calibrated area, at most the calibration's extrapolate_mm beyond it: compensation there extrapolates the calibration", "to make the light there measured, calibrate the machine's own field with `dmdsl calibrate`, or place the part inside the calibrated area"),
    code("optics.beyond-extrapolation", Warn, "layers, area_mm, beyond_mm, extrapolate_mm",
        "layers reach farther outside the calibrated area than the calibration's extrapolate_mm: the light there is unknown and compensated as if it were the light at that margin", "to make the light there measured, calibrate the machine's own field with `dmdsl calibrate`, or place the part inside the calibrated area"),
    code("optics.unreachable", Warn, "count, unit",
        "zones or pixels outside the calibrated area cannot reach the target irradiance even fully on", "calibrate the machine's own field with `dmdsl calibrate`, or place the part inside the calibrated area"),
    code("calibrate.poor-fit", Warn, "residual_rms_pct, degree, form",
        "the model P(x, y)·S(g) does not describe the measurements well (residual RMS over 3 %)", "check the measurements for outliers, or try another --degree"),
    code("calibrate.low-grays-unmeasured", Warn, "lowest_gray, lowest_measured_gray",
        "zone compensation needs grays below the lowest measured one, where S is interpolated", "measure lower grays"),
    code("calibrate.spread-remains", Warn, "mode, after_zone_pct, after_pixel_pct",
        "a compensation mode leaves a large predicted spread: the valid gray range cannot flatten the field", "use the other compensation mode, or measure a wider gray range"),
    code("export.sl1-exposure", Warn, "layers, first_layer, job_s, sl1_s, max_difference_s",
        "SL1 exposes layers 0-2 for expTimeFirst and fades over numFade layers to expTime; layers whose exposure the scheme cannot give get the scheme's", "give the profile exposures the SL1 scheme can carry, or keep the bundle to run the job as planned"),
    code("export.sl1-layer-thickness", Warn, "layers, layer_height_mm",
        "SL1 has one layer height; layers of another thickness are written at it", "slice with one layer height for an SL1"),
    code("export.sl1-continuous", Warn, "layers",
        "SL1 prints every layer stopped; continuous (swept) layers become stationary exposures of the same length", "slice with a layered profile (e.g. bottom-up) for an SL1"),
    code("export.sl1-steps", Note, "steps, print_time_s",
        "SL1 carries no stage steps: the printer tilts its vat between layers instead of the job's planned steps", "nothing to do: the printer plans its own moves"),
    code("export.sl1-display", Warn, "width_px, height_px, printer",
        "the masks' size is not the display of the printer the file is named for: slicers and viewers open it, the printer refuses it", "slice with a profile of that printer's display, or export for the printer the masks fit"),
    code("export.control-assumed", Note, "power_setting, wavelength_nm",
        "the control file needs a light engine power setting and wavelength the profile does not give: the schema's defaults are written", "give the projector's power_setting and wavelength_nm (profile or --machine) to write the machine's own"),
    code("export.control-steps", Warn, "layers, first_layer",
        "layers have steps the control file's move-away, move-back sequence cannot say (sweeps, several moves); they get the nearest such sequence", "check these layers' moves on the machine, or slice with a profile whose layers have one move away and back"),
    code("export.control-split-exposure", Note, "layers, max_ms",
        "layers are exposed longer than the schema's 10 000 ms per image: each is exposed as several equal exposures of its image", "nothing to do: each layer gets the same dose"),
    code("export.control-sequential", Warn, "projectors",
        "the control file exposes a layer's images one after another: a job of several projectors is exposed projector by projector, each image for the layer's exposure (the same dose, the light on that much longer)", "nothing to do if the longer light-on time is acceptable; otherwise run the bundle with `dmdsl run`"),
    code("export.nanodlp-exposure", Warn, "layers, first_layer, max_difference_s",
        "a NanoDLP plate gives the bottom layers one cure time and the others another; layers whose exposure differs get the plate's", "give the profile one exposure for the bottom layers and one for the others, or keep the bundle to run the job as planned"),
    code("export.nanodlp-layer-thickness", Warn, "layers, first_layer",
        "a NanoDLP plate has one thickness for the bottom layers and one for the others; layers of another thickness are written at it", "slice with one layer height for the bottom layers and one for the others"),
    code("export.nanodlp-steps", Warn, "layers, first_layer",
        "a NanoDLP plate says per layer a lift, a wait after it, the move back and waits around the cure, one set for the bottom layers and one for the others; layers whose steps differ (sweeps, several moves, other speeds) get the plate's", "check these layers' moves on the printer, or keep the bundle to run the job as planned"),
    code("export.nanodlp-mirror", Warn, "",
        "a NanoDLP plate mirrors images left-right only (ImageMirror): the projector's top-bottom mirroring is not carried", "set the top-bottom mirroring in the printer's display settings"),
    code("bundle.uncoded", Warn, "",
        "a warning read from a version 1 bundle, which stored warnings as text without a code", "slice the model again to get coded warnings"),
];

/// The registered code `code`, if any.
pub fn lookup(code: &str) -> Option<&'static Code> {
    CODES.iter().find(|c| c.code == code)
}

impl Warning {
    /// A warning of code `code` with the severity [`CODES`] gives it; its message is
    /// `message` and, after a semicolon, the code's remedy.
    pub fn new(code: &str, message: impl Into<String>) -> Warning {
        let registered = lookup(code);
        debug_assert!(
            registered.is_some(),
            "warning code {code} is not in warning::CODES"
        );
        let mut message = message.into();
        if let Some(c) = registered {
            message = format!("{message}; {}", c.remedy);
        }
        Warning {
            code: code.into(),
            severity: registered.map_or(Severity::Warning, |c| c.severity),
            message,
            fields: serde_json::Map::new(),
        }
    }

    /// A warning of code `code` with severity [`Severity::Note`] (for codes registered as
    /// notes, the same as [`new`](Self::new)).
    pub fn note(code: &str, message: impl Into<String>) -> Warning {
        Warning {
            severity: Severity::Note,
            ..Warning::new(code, message)
        }
    }

    /// The same warning with the figure `name` = `value`.
    pub fn with(mut self, name: &str, value: impl Into<serde_json::Value>) -> Warning {
        let mut value = value.into();
        // A figure that is not a whole number: 6 significant digits (crate::round).
        if let Some(x) = value.as_f64().filter(|_| value.is_f64()) {
            value = crate::round::derived(x).into();
        }
        self.fields.insert(name.into(), value);
        self
    }
}

/// What the command line does with warnings of a code: `-W CODE=error|warn|allow`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Silence: the warning is not reported.
    Allow,
    /// Report it as a warning (a note named by its code becomes a warning).
    Warn,
    /// Report it as an error: the command exits with code 1.
    Error,
}

/// Which warnings a rule names.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Pattern {
    /// Every code (`all`).
    All,
    /// Every code of an area (`mesh`, or `mesh.*`).
    Area(String),
    /// One code.
    Code(String),
}

impl Pattern {
    /// More specific patterns win: a code over an area over `all`.
    fn specificity(&self) -> u8 {
        match self {
            Pattern::All => 0,
            Pattern::Area(_) => 1,
            Pattern::Code(_) => 2,
        }
    }

    fn matches(&self, code: &str) -> bool {
        match self {
            Pattern::All => true,
            Pattern::Area(a) => code.split_once('.').is_some_and(|(area, _)| area == a),
            Pattern::Code(c) => c == code,
        }
    }
}

/// The command line's rules for warnings (`--deny-warnings`, `--strict`, `-W CODE=ACTION`).
///
/// For each warning the most specific matching rule applies (a code over an area over
/// `all`; among equally specific rules the last one). A rule naming an area or `all`
/// turns warnings into errors but leaves notes alone (notes are information): only a rule
/// naming the code makes a note an error or a warning. `allow` silences notes too.
#[derive(Debug, Clone, Default)]
pub struct Policy {
    rules: Vec<(Pattern, Action)>,
}

impl Policy {
    /// `--deny-warnings`: every warning of severity warning becomes an error (`all=error`).
    pub fn deny_warnings(&mut self) {
        self.rules.push((Pattern::All, Action::Error));
    }

    /// Adds a rule `CODE=ACTION`: CODE a code of [`CODES`], an area (`mesh` or `mesh.*`) or
    /// `all`; ACTION `error` (or `deny`), `warn` or `allow`. The error is one line.
    pub fn add(&mut self, rule: &str) -> Result<(), String> {
        let (name, action) = rule.split_once('=').ok_or_else(|| {
            format!(
                "-W {rule}: expected CODE=error|warn|allow, e.g. -W plan.unsupported-islands=error"
            )
        })?;
        let action = match action {
            "error" | "deny" => Action::Error,
            "warn" | "warning" => Action::Warn,
            "allow" => Action::Allow,
            other => {
                return Err(format!(
                    "-W {rule}: unknown action {other:?}; use error, warn or allow"
                ))
            }
        };
        let area = |a: &str| {
            CODES
                .iter()
                .any(|c| c.code.split_once('.').map(|p| p.0) == Some(a))
        };
        let pattern = match name.strip_suffix(".*").unwrap_or(name) {
            "all" | "*" => Pattern::All,
            c if lookup(c).is_some() => Pattern::Code(c.into()),
            a if area(a) => Pattern::Area(a.into()),
            _ => {
                let codes: Vec<&str> = CODES.iter().map(|c| c.code).collect();
                return Err(format!(
                    "-W {rule}: unknown warning code {name:?}; known codes: {}",
                    codes.join(", ")
                ));
            }
        };
        self.rules.push((pattern, action));
        Ok(())
    }

    /// The action for `w`, if a rule applies to it.
    fn action(&self, w: &Warning) -> Option<Action> {
        let mut best: Option<&(Pattern, Action)> = None;
        for r in &self.rules {
            let applies = r.0.matches(&w.code)
                && (matches!(r.0, Pattern::Code(_))
                    || r.1 == Action::Allow
                    || w.severity >= Severity::Warning);
            if applies && best.is_none_or(|b| r.0.specificity() >= b.0.specificity()) {
                best = Some(r);
            }
        }
        best.map(|r| r.1)
    }

    /// The warnings as reported under these rules: allowed ones left out, the others with
    /// their severity as the rules set it ([`Severity::Error`] for denied ones).
    pub fn apply(&self, warnings: &[Warning]) -> Vec<Warning> {
        warnings
            .iter()
            .filter_map(|w| {
                let severity = match self.action(w) {
                    None => w.severity,
                    Some(Action::Allow) => return None,
                    Some(Action::Warn) => Severity::Warning,
                    Some(Action::Error) => Severity::Error,
                };
                Some(Warning {
                    severity,
                    ..w.clone()
                })
            })
            .collect()
    }
}

/// True when any of `warnings` has severity [`Severity::Error`].
pub fn any_error(warnings: &[Warning]) -> bool {
    warnings.iter().any(|w| w.severity == Severity::Error)
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} [{}]", self.message, self.code)
    }
}
