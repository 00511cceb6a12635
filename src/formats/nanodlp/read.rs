//! Reading a NanoDLP plate as a job (docs/EXECUTOR.md, "Imported jobs"): the images
//! `1.png … N.png` (or from `0.png`), each layer's steps the plate's (`Plate::layers`),
//! the display of `options.json` (or `slicer.json`). Without dmdsl's custom speed values
//! the moves are timed at 1 mm/s and 10 mm/s², `unstated`, with a note; what NanoDLP
//! computes while it prints (the `Dynamic…` fields, `TransitionalLayer`) is not
//! evaluated, and a note names it. A missing or mistyped setting is an error naming the
//! entry and the key.

use super::{Group, Plate, INFO, KEYS, OPTIONS, PLATE, PROFILE, SLICER, SPEEDS};
use crate::bundle::Layer;
use crate::error::Result;
use crate::formats::archive::read::Archive;
use crate::formats::imported::{self, Imported};
use crate::formats::{Format, Job};
use serde_json::{Map, Value};

/// The stand-ins for the speeds a plate without dmdsl's custom values does not state:
/// mm/s, mm/s².
const SPEED: [f64; 2] = [1.0, 10.0];

/// A JSON entry of the plate, read as an object.
fn entry(archive: &Archive, name: &str) -> Result<Option<Map<String, Value>>> {
    let Some(bytes) = archive.get(name)? else {
        return Ok(None);
    };
    match serde_json::from_slice::<Value>(bytes) {
        Ok(Value::Object(m)) => Ok(Some(m)),
        Ok(_) => Err(archive.error(Some(name), "is not a JSON object")),
        Err(e) => Err(archive.error(Some(name), format!("invalid JSON: {e}"))),
    }
}

/// Number `key` of entry `name` (`m`): finite and ≥ 0, or `default` when absent (an error
/// when there is none).
fn num(
    archive: &Archive,
    (name, m): (&str, &Map<String, Value>),
    key: &str,
    default: Option<f64>,
) -> Result<f64> {
    let v = match m.get(key) {
        None | Some(Value::Null) => {
            return default.ok_or_else(|| archive.error(Some(name), format!("missing key `{key}`")))
        }
        Some(v) => v,
    };
    let x = v
        .as_f64()
        .or_else(|| v.as_str().and_then(|s| s.trim().parse().ok()));
    x.filter(|x| x.is_finite() && *x >= 0.0)
        .ok_or_else(|| archive.error(Some(name), format!("`{key}` is {v}, not a number ≥ 0")))
}

/// The plate's layer settings from `profile` (`override.json`'s keys first); `false` when
/// it has no speeds of dmdsl's.
fn plate(archive: &Archive, profile: &Map<String, Value>) -> Result<(Plate, bool)> {
    let mut groups = [Group::default(); 2];
    let custom = profile.get("CustomValues").and_then(Value::as_object);
    let mut stated = true;
    for (gi, g) in groups.iter_mut().enumerate() {
        for (k, (bottom, other, unit)) in KEYS.iter().enumerate() {
            let key = if gi == 0 { bottom } else { other };
            let default = (k > 1).then_some(0.0);
            let v = num(archive, (PROFILE, profile), key, default)? / unit;
            // Durations in s, the thickness and the lift in mm.
            let (most, what) = if k == 1 || k == 2 {
                (1e4, "mm")
            } else {
                (1e6, "s")
            };
            if v > most {
                return Err(archive.error(
                    Some(PROFILE),
                    format!("`{key}` is {v:?} {what}, more than a machine's {most} {what}"),
                ));
            }
            g.set(k, v);
        }
        let prefix = if gi == 0 { "DmdslSupport" } else { "Dmdsl" };
        for (k, name) in SPEEDS.iter().enumerate() {
            let key = format!("{prefix}{name}");
            let v = match custom.and_then(|c| c.get(&key)) {
                None => None,
                Some(v) => Some(custom_speed(archive, &key, v, k % 2 == 1)?),
            };
            stated &= v.is_some();
            let slot = if k < 2 {
                &mut g.up[k]
            } else {
                &mut g.down[k - 2]
            };
            *slot = v.unwrap_or(SPEED[k % 2]);
        }
        if g.thickness_mm <= 0.0 {
            let key = if gi == 0 { "SupportDepth" } else { "Depth" };
            return Err(archive.error(
                Some(PROFILE),
                format!("`{key}` is 0: layers have no thickness"),
            ));
        }
    }
    let bottom = num(archive, (PROFILE, profile), "SupportLayerNumber", Some(0.0))? as usize;
    Ok((Plate { bottom, groups }, stated))
}

/// The custom value `key` of `profile.json` (`v`, a number as text): a speed in mm/s, or
/// with `accel` an acceleration in mm/s², within what a machine has.
fn custom_speed(archive: &Archive, key: &str, v: &Value, accel: bool) -> Result<f64> {
    let (unit, most) = if accel {
        ("mm/s²", 1e6)
    } else {
        ("mm/s", 1e4)
    };
    let x = v
        .as_str()
        .and_then(|s| s.trim().parse::<f64>().ok())
        .or_else(|| v.as_f64());
    x.filter(|x| (1e-6..=most).contains(x)).ok_or_else(|| {
        archive.error(
            Some(PROFILE),
            format!("`CustomValues.{key}` is {v}, not {unit} a machine has (1e-6 to {most})"),
        )
    })
}

/// The layer areas `info.json` states (mm², `None` for a layer it gives none), each a
/// number from 0 to `most`; no entry, no areas.
fn stated_areas(archive: &Archive, most: f64) -> Result<Option<Vec<Option<f64>>>> {
    let Some(bytes) = archive.get(INFO)? else {
        return Ok(None);
    };
    let Ok(Value::Array(layers)) = serde_json::from_slice::<Value>(bytes) else {
        return Err(archive.error(Some(INFO), "is not a JSON list of layers"));
    };
    let area = |(i, l): (usize, &Value)| {
        match l.get("TotalSolidArea") {
        None | Some(Value::Null) => Ok(None),
        Some(v) => match v.as_f64().filter(|a| (0.0..=most).contains(a)) {
            Some(a) => Ok(Some(a)),
            None => Err(archive.error(Some(INFO), format!("layer {i}: `TotalSolidArea` is {v}, not an area from 0 to the display's {most} mm²"))),
        },
    }
    };
    layers
        .iter()
        .enumerate()
        .map(area)
        .collect::<Result<_>>()
        .map(Some)
}

/// The notes of what NanoDLP computes while it prints and the reader does not.
fn dynamic(archive: &Archive, profile: &Map<String, Value>) -> Result<Vec<String>> {
    let mut notes = Vec::new();
    for key in [
        "DynamicCureTime",
        "DynamicSpeed",
        "DynamicLift",
        "DynamicWait",
    ] {
        if profile
            .get(key)
            .and_then(Value::as_str)
            .is_some_and(|s| !s.trim().is_empty())
        {
            notes.push(format!(
                "not evaluated: {key} (profile.json): the plate's static settings are used"
            ));
        }
    }
    let fade = num(archive, (PROFILE, profile), "TransitionalLayer", Some(0.0))?;
    if fade > 0.0 {
        notes.push(format!("not evaluated: TransitionalLayer {fade} (profile.json), NanoDLP's fade from the support cure time: those layers get CureTime"));
    }
    Ok(notes)
}

/// The layers' image names: `LayersCount` of them (`plate.json`), or as many as the
/// archive numbers in a row, from `0.png` or `1.png`.
fn layer_names(archive: &Archive, plate_json: &Map<String, Value>) -> Result<Vec<String>> {
    let n = num(archive, (PLATE, plate_json), "LayersCount", Some(0.0))? as usize;
    let first = usize::from(!archive.contains("0.png"));
    let n = if n > 0 {
        n
    } else {
        (first..)
            .take_while(|i| archive.contains(&format!("{i}.png")))
            .count()
    };
    if n == 0 || n as u64 > crate::formats::control::read::MAX_LAYERS {
        return Err(archive.error(
            Some(PLATE),
            format!(
                "`LayersCount` is {n}: a job has 1 to {} layers",
                crate::formats::control::read::MAX_LAYERS
            ),
        ));
    }
    Ok((first..first + n).map(|i| format!("{i}.png")).collect())
}

/// Imports the NanoDLP plate `archive` (SHA-256 `sha256`).
pub(crate) fn import(archive: Archive, sha256: &str) -> Result<Job> {
    let mut profile = entry(&archive, PROFILE)?.unwrap_or_default();
    if let Some(o) = entry(&archive, "override.json")? {
        profile.extend(o);
    }
    let plate_json = entry(&archive, PLATE)?.unwrap_or_default();
    let (opts_name, options) = match entry(&archive, OPTIONS)? {
        Some(o) => (OPTIONS, o),
        None => (
            SLICER,
            entry(&archive, SLICER)?.ok_or_else(|| {
                archive.error(
                    None,
                    format!("no `{OPTIONS}` (nor `{SLICER}`): the display is not stated"),
                )
            })?,
        ),
    };
    let (plate, speeds) = plate(&archive, &profile)?;
    let opt = |key: &str, default| num(&archive, (opts_name, &options), key, default);
    let size = (opt("PWidth", None)?, opt("PHeight", None)?);
    if !(1.0..=65536.0).contains(&size.0) || !(1.0..=65536.0).contains(&size.1) {
        return Err(archive.error(
            Some(opts_name),
            "`PWidth` × `PHeight` is not a display size in pixels (1 to 65536)",
        ));
    }
    let pixel = opt("XPixelSize", Some(0.0))?;
    let names = layer_names(&archive, &plate_json)?;
    let n = names.len();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let images = imported::images(&archive, &refs);
    let given = plate.layers(n);
    let mut unstated = vec!["stage.travel_max_mm", "stage.steps_per_mm"];
    if !speeds {
        unstated.extend(["stage.max_speed_mm_s", "stage.max_accel_mm_s2"]);
    }
    let pixel_stated = pixel > 0.0;
    if !pixel_stated {
        unstated.push("projector[].pixel_mm");
    }
    let pixel = if pixel > 0.0 { pixel } else { 0.001 };
    let mut display = imported::projector("display", (size.0 as u32, size.1 as u32), pixel);
    display.mirror_x = opt("ImageMirror", Some(0.0))? == 1.0;
    let top = given.iter().map(|l| l.0).fold(1.0, f64::max)
        + plate.groups.iter().map(|g| g.lift_mm).fold(0.0, f64::max);
    let fastest = |k: usize| {
        plate
            .groups
            .iter()
            .flat_map(|g| [g.up[k], g.down[k]])
            .fold(0.0, f64::max)
    };
    let stage = (
        top.min(1e4),
        fastest(0).min(1e4),
        fastest(1).min(1e6),
        10_000.0,
    );
    let resin = profile
        .get("Title")
        .and_then(Value::as_str)
        .unwrap_or_default()
        .to_string();
    let machine = imported::machine(
        ("nanodlp-import".into(), resin),
        stage,
        vec![display],
        &unstated,
    );
    // A display of unstated pixels is bounded by 1 m².
    let field = if pixel_stated {
        size.0 * size.1 * pixel * pixel
    } else {
        1e6
    };
    let info = stated_areas(&archive, crate::round::derived(field * 1.0001))?;
    let area = |i: usize| *info.as_ref()?.get(i)?;
    let mut layers: Vec<Layer> = Vec::with_capacity(n);
    for (i, (top, thickness, steps, time_s)) in given.into_iter().enumerate() {
        let place = (i, (top, top - thickness / 2.0, thickness));
        let on = (&machine, 0, pixel * pixel, area(i));
        layers.push(imported::layer(
            place,
            (&names[i], &images[i]),
            on,
            steps,
            time_s,
        ));
    }
    let mut notes = dynamic(&archive, &profile)?;
    if !speeds {
        notes.push("the plate states no stage speed (NanoDLP moves at the printer's own): moves are timed at 1 mm/s and 10 mm/s²".into());
    }
    let meta = entry(&archive, super::META)?.unwrap_or_default();
    let program = meta
        .get("Program")
        .and_then(Value::as_str)
        .unwrap_or("NanoDLP");
    let imported = Imported {
        format: Format::Nanodlp,
        generator: format!("NanoDLP plate ({program})"),
        sha256: sha256.into(),
        machine,
        layer_height_mm: plate.groups[1].thickness_mm,
        layers,
        estimate: None,
        resin_ml: None,
        stated_areas: info.is_some(),
        requests: Vec::new(),
        vacuum: false,
        notes,
    };
    imported.job(archive, (opts_name, "the display it describes"))
}
