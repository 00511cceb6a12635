//! The open SLA 3D printer control-file standard, schema v5 (public repository
//! `3D-Printing-for-Microfluidics/3D_printer_json_print_file`, CC BY 4.0; the schema is
//! vendored as `fixtures/sla_control/schema_v5.json`): a zip with one print-settings JSON
//! at the top (`print_settings.json`) and the images under its `Header."Image directory"`
//! (`slices/`).
//!
//! Both directions map a layer's planned steps to and from its "Position settings"
//! (`Position`): waits before the first move, a move up by `Distance up`, waits, a move
//! back down onto the layer (the previous top + its thickness), waits; and each image
//! exposed for its `Layer exposure time (ms)`. [`mod@read`] imports a file (with
//! `expr.rs`'s `${...}` evaluator), `write.rs` writes a job as one, and what the file cannot
//! say of a job is `cannot_carry`'s.

mod expr;
pub mod hardware;
pub mod read;
mod schema;
mod write;

pub(crate) use read::{import, settings_entry};
pub(crate) use write::{position, write};

use crate::bundle::Manifest;
use crate::text::plural;
use crate::warning::Warning;
use serde_json::{json, Value};

/// The schema version written in the header.
pub const SCHEMA_VERSION: &str = "5.0.0";
/// The settings file's name in the zip.
pub const SETTINGS: &str = "print_settings.json";
/// The image directory in the zip.
pub const IMAGES: &str = "slices";
/// The longest exposure of one image the schema allows, ms.
const EXPOSURE_MAX_MS: i64 = 10_000;
/// The schema's defaults for what a dmdsl profile does not say.
const POWER_SETTING: i64 = 100;
const WAVELENGTH_NM: i64 = 365;

/// A layer's "Position settings", in mm and s (the keys are [`Position::to_json`]'s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Position {
    pub(crate) thickness_mm: f64,
    pub(crate) up_mm: f64,
    pub(crate) initial_s: f64,
    pub(crate) up_speed: f64,
    pub(crate) up_accel: f64,
    pub(crate) up_wait_s: f64,
    pub(crate) down_speed: f64,
    pub(crate) down_accel: f64,
    pub(crate) final_s: f64,
}

impl Position {
    /// The settings read by `num(key, positive)` (a number ≥ 0, or > 0 when `positive`).
    fn read<E>(num: impl Fn(&str, bool) -> Result<f64, E>) -> Result<Position, E> {
        let ms = |key: &str| num(key, false).map(|v| v / 1000.0);
        Ok(Position {
            thickness_mm: num("Layer thickness (um)", false)? / 1000.0,
            up_mm: num("Distance up (mm)", true)?,
            initial_s: ms("Initial wait (ms)")?,
            up_speed: num("BP up speed (mm/sec)", true)?,
            up_accel: num("BP up acceleration (mm/sec^2)", true)?,
            up_wait_s: ms("Up wait (ms)")?,
            down_speed: num("BP down speed (mm/sec)", true)?,
            down_accel: num("BP down acceleration (mm/sec^2)", true)?,
            final_s: ms("Final wait (ms)")?,
        })
    }

    /// The settings as the file writes them (whole ms; whole numbers without a fraction).
    fn to_json(self) -> Value {
        let ms = |s: f64| n((s * 1000.0).round());
        json!({
            "Layer thickness (um)": n(self.thickness_mm * 1000.0),
            "Distance up (mm)": n(self.up_mm),
            "Initial wait (ms)": ms(self.initial_s),
            "BP up speed (mm/sec)": n(self.up_speed),
            "BP up acceleration (mm/sec^2)": n(self.up_accel),
            "Up wait (ms)": ms(self.up_wait_s),
            "BP down speed (mm/sec)": n(self.down_speed),
            "BP down acceleration (mm/sec^2)": n(self.down_accel),
            "Final wait (ms)": ms(self.final_s),
        })
    }
}

/// A number as JSON: a whole number without a fraction.
fn n(v: f64) -> Value {
    let v = crate::round::derived(v);
    if v.fract() == 0.0 && v.abs() < 1e15 {
        json!(v as i64)
    } else {
        json!(v)
    }
}

/// What a control file cannot carry of `m`, in the order the exporter reports it: the
/// power and wavelength it assumes for projectors that state none, the images of several
/// projectors exposed one after another, layers whose steps are not the standard's
/// sequence, exposures split to stay within the schema's limit.
pub(crate) fn cannot_carry(m: &Manifest) -> Vec<Warning> {
    let mut warnings = Vec::new();
    let projectors = &m.machine.projector;
    let mut assumed = Vec::new();
    if projectors.iter().any(|p| p.power_setting.is_none()) {
        assumed.push(format!(
            "light engine power setting {POWER_SETTING} (projector.N.power_setting)"
        ));
    }
    if projectors.iter().any(|p| p.wavelength_nm.is_none()) {
        assumed.push(format!(
            "wavelength {WAVELENGTH_NM} nm (projector.N.wavelength_nm, or --machine HARDWARE.json)"
        ));
    }
    if !assumed.is_empty() {
        warnings.push(
            Warning::new(
                "export.control-assumed",
                format!(
                    "the machine does not state every projector's light engine settings: the control file has the schema's defaults for them, {}",
                    assumed.join(", ")
                ),
            )
            .with("power_setting", POWER_SETTING)
            .with("wavelength_nm", WAVELENGTH_NM),
        );
    }
    if projectors.len() > 1 {
        let k = projectors.len() as u64;
        warnings.push(
            Warning::new(
                "export.control-sequential",
                format!("the control file exposes a layer's images one after another: the {k} projectors' images are exposed in turn, each for the layer's exposure (the same dose, {k} times the light-on time)"),
            )
            .with("projectors", k),
        );
    }
    let (mut misfits, mut splits) = (Vec::new(), 0u64);
    let stage = &m.machine.stage;
    let limits = (stage.max_speed_mm_s.get(), stage.max_accel_mm_s2.get());
    let mut at = stage.home_mm;
    for l in &m.layers {
        if !write::position(l, at, limits).1 {
            misfits.push(l.index);
        }
        at = l.z_mm;
        splits += u64::from(write::split(write::light_ms(l, at)).len() > 1);
    }
    if let Some(&first) = misfits.first() {
        let k = misfits.len() as u64;
        warnings.push(
            Warning::new(
                "export.control-steps",
                format!(
                    "{k} {} steps the control file's move-away, move-back sequence cannot say (first: layer {first}); {} the nearest such sequence",
                    plural(k, "layer has", "layers have"),
                    plural(k, "it gets", "they get")
                ),
            )
            .with("layers", k)
            .with("first_layer", first),
        );
    }
    if splits > 0 {
        warnings.push(
            Warning::new(
                "export.control-split-exposure",
                format!(
                    "{splits} {} exposed longer than the schema's {EXPOSURE_MAX_MS} ms per image: each is exposed as several equal exposures of its image",
                    plural(splits, "layer is", "layers are")
                ),
            )
            .with("layers", splits)
            .with("max_ms", EXPOSURE_MAX_MS),
        );
    }
    warnings
}

/// Settings of the standard with the usual defaults (image `a.png`, light engine `e`), a
/// layer group `g` of two layers and `layers`.
#[cfg(test)]
fn test_settings(layers: Value) -> Value {
    json!({
        "Header": {"Schema version": "5.0.0", "Image directory": "slices"},
        "Default layer settings": {
            "Number of duplications": 1,
            "Position settings": {
                "Layer thickness (um)": 10, "Distance up (mm)": 0.3,
                "Initial wait (ms)": 0, "BP up speed (mm/sec)": 2,
                "BP up acceleration (mm/sec^2)": 20, "Up wait (ms)": 0,
                "BP down speed (mm/sec)": 1, "BP down acceleration (mm/sec^2)": 10,
                "Final wait (ms)": 0
            },
            "Image settings": {
                "Image file": "a.png", "Layer exposure time (ms)": 100,
                "Light engine": "e", "Light engine power setting": 100,
                "Light engine wavelength (nm)": 365, "Relative focus position (um)": 0,
                "Wait before exposure (ms)": 0, "Wait after exposure (ms)": 0
            }
        },
        "Named layer groups": {"g": [{}, {}]},
        "Layers": layers
    })
}
