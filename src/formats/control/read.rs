//! Reading an SLA control-file zip as a job.
//!
//! ## What is read
//! `Header` (`Schema version` 5.x.y, `Image directory`), `Default layer settings`
//! (`Number of duplications`, `Position settings`, `Image settings`), `Named position
//! settings`, `Named image settings`, `Named layer groups` and `Layers` (each item a layer
//! or a `Using named layer group` call, with its `Number of duplications`). A layer's
//! position setting is its own key, else that of its `Using named position settings`,
//! else the default; an image's setting is its own key, else its `Using named image
//! settings` (without one, the layer's `Using named default image settings`), else the
//! default.
//! Named settings may inherit from other named settings (a circle is an error). `${...}`
//! expressions over `Variables` are evaluated first, as the standard's validator does
//! (named layer groups with their call's variables; `expr.rs`). `Design` and
//! `Special print techniques` are information only. A setting that is still not a
//! number where a number is needed is an error naming the entry and the key. A job of more
//! than [`MAX_LAYERS`] layer records (duplications and group calls counted) is refused
//! before any is made, and so are
//! settings whose expansion makes more than 64 MiB plus 16 times the entry's size (text
//! interpolation and group calls repeat what they name).
//!
//! ## Steps
//! Every layer (each duplication counted) is: `Initial wait`, a move up by `Distance up`
//! at the up speed and acceleration, `Up wait`, a move down to the layer's top (the
//! previous top + `Layer thickness`) at the down speed and acceleration, then for each
//! image `Wait before exposure`, the exposure, `Wait after exposure`, and last `Final
//! wait`. A layer of several images becomes one layer record per image: the first with
//! the layer's thickness and its position steps, each further image a record of
//! thickness 0 at the same height (the standard's "0 um layer"), so every exposure keeps
//! its own mask and time. The light engine's power, wavelength, focus, image offsets and
//! mirroring and the special techniques are not simulated.
//!
//! ## The machine
//! The standard does not give the pixel size: the projector is the first image's size in
//! pixels with 7.6 µm pixels (the light engine of the BYU high-resolution printers the
//! standard was written for); the stage travels 0–90 mm (the standard's build-platform
//! limit) at up to 800 mm/min (the standard's limit; a faster move is a `speed`
//! violation), accelerating as fast as the file asks, in 0.1 µm steps.

use super::expr::{resolve, Budget};
use super::Position;
use crate::bundle::{Layer, Step};
use crate::error::{Error, Result};
use crate::formats::archive::read::Archive;
use crate::formats::imported::{self, Grid, Implied, Imported};
use crate::formats::{Format, Job};
use serde_json::{Map, Value};

/// Pixel size assumed for the images, mm.
pub const PIXEL_MM: f64 = 0.0076;
/// The build platform's speed limit in the standard (800 mm/min), mm/s.
const BP_MAX_SPEED_MM_S: f64 = 800.0 / 60.0;
/// The build platform's highest position, mm.
const TRAVEL_MAX_MM: f64 = 90.0;
/// The least acceleration limit of the imported stage (the file's fastest if faster), mm/s².
const MIN_ACCEL_MM_S2: f64 = 20.0;
/// Most layer records (exposures, duplications counted) a job may have: the zip reader's
/// bounds fit a job of 100,000 layers, and a count the file states is no cheaper to
/// follow than layers it holds.
pub const MAX_LAYERS: u64 = 100_000;
/// What the `${...}` expansion and the layer groups may make, bytes: this much plus
/// [`EXPANSION_FACTOR`] times the settings entry's size.
const EXPANSION_BYTES: u64 = 64 << 20;
/// See [`EXPANSION_BYTES`].
const EXPANSION_FACTOR: u64 = 16;

/// The top-level `.json` entry that holds print settings (`Header` and `Default layer
/// settings`), `print_settings.json` first. (The standard allows one JSON file at the
/// top; [`import`] refuses an archive with more.)
pub(crate) fn settings_entry(archive: &Archive) -> Option<String> {
    let mut names: Vec<&String> = archive
        .names()
        .iter()
        .filter(|n| !n.contains('/') && n.to_ascii_lowercase().ends_with(".json"))
        .collect();
    names.sort_by_key(|n| n.as_str() != "print_settings.json");
    names
        .into_iter()
        .find(|n| {
            serde_json::from_slice::<Value>(archive.get(n).unwrap_or_default())
                .ok()
                .and_then(|v| v.as_object().cloned())
                .is_some_and(|o| {
                    o.contains_key("Header") && o.contains_key("Default layer settings")
                })
        })
        .cloned()
}

/// Settings keys of the top level (the schema's `additionalProperties: false`).
const TOP_KEYS: &[&str] = &[
    "Header",
    "Design",
    "Default layer settings",
    "Variables",
    "Named position settings",
    "Named image settings",
    "Named layer groups",
    "Special print techniques",
    "Layers",
];

/// One exposure of a layer.
#[derive(Debug, Clone)]
struct Image {
    file: String,
    exposure_s: f64,
    before_s: f64,
    after_s: f64,
}

/// One layer as the file describes it (before duplication).
#[derive(Debug, Clone)]
struct LayerSpec {
    position: Position,
    images: Vec<Image>,
    copies: u64,
    /// Where it is in the file, for messages: "Layers[3]".
    at: String,
}

/// Reads the settings JSON with the keys and types this reader relies on checked.
struct Reader<'a> {
    archive: &'a Archive,
    entry: &'a str,
    root: Map<String, Value>,
}

impl Reader<'_> {
    fn bad(&self, msg: String) -> Error {
        self.archive.error(Some(self.entry), msg)
    }

    fn object<'v>(&self, v: &'v Value, at: &str) -> Result<&'v Map<String, Value>> {
        v.as_object()
            .ok_or_else(|| self.bad(format!("{at} is not an object")))
    }

    /// Named settings `name` of `table`, merged with the named settings it inherits from
    /// (its own `Using named ...` key, followed to the root; its own keys win).
    fn named(&self, table: &str, name: &str, at: &str) -> Result<Map<String, Value>> {
        let parent_key = if table == "Named position settings" {
            "Using named position settings"
        } else {
            "Using named image settings"
        };
        let mut out = Map::new();
        let mut chain: Vec<String> = Vec::new();
        let mut cur = name.to_string();
        loop {
            if chain.contains(&cur) {
                return Err(self.bad(format!(
                    "{at}: `{table}` inherit in a circle: {} -> {cur}",
                    chain.join(" -> ")
                )));
            }
            let v = self
                .root
                .get(table)
                .and_then(|t| t.get(&cur))
                .ok_or_else(|| self.bad(format!("{at}: `{cur}` is not in `{table}`")))?;
            let m = self.object(v, &format!("{table}.{cur}"))?;
            for (k, v) in m {
                out.entry(k.clone()).or_insert_with(|| v.clone());
            }
            chain.push(cur);
            match m.get(parent_key).and_then(Value::as_str) {
                Some(p) if !p.is_empty() => cur = p.to_string(),
                _ => break,
            }
        }
        Ok(out)
    }

    /// Setting `key` from the first of `maps` that has it, as a number ≥ 0 (> 0 when
    /// `positive`).
    fn num(
        &self,
        maps: &[&Map<String, Value>],
        key: &str,
        at: &str,
        positive: bool,
    ) -> Result<f64> {
        let v = maps
            .iter()
            .find_map(|m| m.get(key))
            .ok_or_else(|| self.bad(format!("{at}: no `{key}` (nor in the defaults)")))?;
        match v.as_f64() {
            Some(x) if x.is_finite() && x >= 0.0 && (!positive || x > 0.0) => Ok(x),
            _ => Err(self.bad(format!(
                "{at}: `{key}` is {v}, not a {} number",
                if positive { "positive" } else { "non-negative" }
            ))),
        }
    }

    fn string<'v>(&self, maps: &[&'v Map<String, Value>], key: &str, at: &str) -> Result<&'v str> {
        let v = maps
            .iter()
            .find_map(|m| m.get(key))
            .ok_or_else(|| self.bad(format!("{at}: no `{key}` (nor in the defaults)")))?;
        v.as_str()
            .ok_or_else(|| self.bad(format!("{at}: `{key}` is {v}, not a string")))
    }

    fn copies(&self, m: &Map<String, Value>, at: &str) -> Result<Option<u64>> {
        match m.get("Number of duplications") {
            None => Ok(None),
            Some(v) => match v.as_u64() {
                Some(n) if n >= 1 => Ok(Some(n)),
                _ => Err(self.bad(format!(
                    "{at}: `Number of duplications` is {v}, not a whole number ≥ 1"
                ))),
            },
        }
    }

    /// The layer `layer` (a `LAYER_BASE` object) at `at`, with the defaults.
    fn layer(&self, layer: &Map<String, Value>, at: &str, copies: u64) -> Result<LayerSpec> {
        let defaults = self.object(
            &self.root["Default layer settings"],
            "`Default layer settings`",
        )?;
        let dpos = self.object(
            defaults.get("Position settings").unwrap_or(&Value::Null),
            "`Default layer settings.Position settings`",
        )?;
        let dimg = self.object(
            defaults.get("Image settings").unwrap_or(&Value::Null),
            "`Default layer settings.Image settings`",
        )?;
        let empty = Map::new();
        let own_pos = match layer.get("Position settings") {
            Some(v) => self.object(v, &format!("{at}.Position settings"))?,
            None => &empty,
        };
        let named_pos = match own_pos
            .get("Using named position settings")
            .and_then(Value::as_str)
        {
            Some(n) if !n.is_empty() => self.named("Named position settings", n, at)?,
            _ => Map::new(),
        };
        let pos = [own_pos, &named_pos, dpos];
        let layer_img = match layer
            .get("Using named default image settings")
            .and_then(Value::as_str)
        {
            Some(n) if !n.is_empty() => self.named("Named image settings", n, at)?,
            _ => Map::new(),
        };
        // No list, or an empty one: one exposure of the default image.
        let list: Vec<&Map<String, Value>> = match layer.get("Image settings list") {
            None => vec![&empty],
            Some(Value::Array(a)) if a.is_empty() => vec![&empty],
            Some(Value::Array(a)) => a
                .iter()
                .enumerate()
                .map(|(k, v)| self.object(v, &format!("{at}.Image settings list[{k}]")))
                .collect::<Result<_>>()?,
            Some(v) => {
                return Err(self.bad(format!("{at}: `Image settings list` is {v}, not a list")))
            }
        };
        let dir = self.string(
            &[self.object(&self.root["Header"], "`Header`")?],
            "Image directory",
            "Header",
        )?;
        let mut images = Vec::with_capacity(list.len());
        for (k, own) in list.into_iter().enumerate() {
            let at = format!("{at}.Image settings list[{k}]");
            // An image's own named settings replace the layer's named defaults.
            let named = match own
                .get("Using named image settings")
                .and_then(Value::as_str)
            {
                Some(n) if !n.is_empty() => self.named("Named image settings", n, &at)?,
                _ => layer_img.clone(),
            };
            let maps = [own, &named, dimg];
            let ms = self.num(&maps, "Layer exposure time (ms)", &at, false)?;
            if ms > 10_000.0 {
                return Err(self.bad(format!(
                    "{at}: `Layer exposure time (ms)` is {ms}, above the schema's 10000"
                )));
            }
            let file = self.string(&maps, "Image file", &at)?;
            let rel = if dir.is_empty() || dir == "." {
                file.to_string()
            } else {
                format!("{}/{file}", dir.trim_end_matches('/'))
            };
            images.push(Image {
                file: rel,
                exposure_s: ms / 1000.0,
                before_s: self.num(&maps, "Wait before exposure (ms)", &at, false)? / 1000.0,
                after_s: self.num(&maps, "Wait after exposure (ms)", &at, false)? / 1000.0,
            });
        }
        Ok(LayerSpec {
            position: Position::read(|key, positive| self.num(&pos, key, at, positive))?,
            images,
            copies,
            at: at.to_string(),
        })
    }

    /// Every layer of the file in print order (named groups were expanded by [`expand`]).
    fn layers(&self) -> Result<Vec<LayerSpec>> {
        let defaults = self.object(
            &self.root["Default layer settings"],
            "`Default layer settings`",
        )?;
        let default_copies = self
            .copies(defaults, "Default layer settings")?
            .ok_or_else(|| {
                self.bad("`Default layer settings` has no `Number of duplications`".into())
            })?;
        let items = match self.root.get("Layers") {
            None => return Ok(Vec::new()),
            Some(Value::Array(a)) => a,
            Some(v) => return Err(self.bad(format!("`Layers` is {v}, not a list"))),
        };
        let mut out = Vec::new();
        for (k, item) in items.iter().enumerate() {
            let at = format!("Layers[{k}]");
            let m = self.object(item, &at)?;
            let copies = self.copies(m, &at)?.unwrap_or(default_copies);
            out.push(self.layer(m, &at, copies)?);
        }
        Ok(out)
    }
}

/// Expands what the standard's tools expand before validating: calls of named layer
/// groups (each group's layers repeated `Number of duplications` times, their `${...}`
/// evaluated over the global `Variables` overridden by the call's), then every `${...}`
/// left, over the global `Variables`.
fn expand(root: &mut Map<String, Value>, budget: &mut Budget) -> std::result::Result<(), String> {
    let vars = |v: Option<&Value>| -> std::result::Result<Map<String, Value>, String> {
        match v {
            None => Ok(Map::new()),
            Some(Value::Object(m)) => Ok(m.clone()),
            Some(v) => Err(format!("`Variables` is {v}, not an object")),
        }
    };
    let globals = vars(root.get("Variables"))?;
    if let Some(Value::Array(items)) = root.get("Layers") {
        let mut out = Vec::with_capacity(items.len());
        for (k, item) in items.iter().enumerate() {
            let Some(name) = item.get("Using named layer group") else {
                out.push(item.clone());
                continue;
            };
            let at = format!("Layers[{k}]");
            let name = name
                .as_str()
                .ok_or(format!("{at}: `Using named layer group` is not a string"))?;
            let group = root
                .get("Named layer groups")
                .and_then(|g| g.get(name))
                .and_then(Value::as_array)
                .ok_or(format!(
                    "{at}: no layer group `{name}` in `Named layer groups`"
                ))?;
            let mut scoped = globals.clone();
            scoped.extend(vars(item.get("Variables"))?);
            let scoped = match resolve(&Value::Object(scoped.clone()), &scoped, budget) {
                Ok(Value::Object(m)) => m,
                Ok(_) => scoped,
                Err(e) => return Err(format!("{at}: Variables: {e}")),
            };
            let copies = match item.get("Number of duplications") {
                None => 1,
                Some(v) => v.as_u64().filter(|&n| n >= 1).ok_or(format!(
                    "{at}: `Number of duplications` is {v}, not a whole number ≥ 1"
                ))?,
            };
            let layers: Vec<Value> = group
                .iter()
                .map(|l| resolve(l, &scoped, budget))
                .collect::<std::result::Result<_, _>>()
                .map_err(|e| format!("Named layer groups.{name}: {e}"))?;
            let total = (layers.len() as u64)
                .saturating_mul(copies)
                .saturating_add(out.len() as u64);
            if total > MAX_LAYERS {
                return Err(format!(
                    "{at}: {copies} duplications of layer group `{name}` ({} layers) make more than the {MAX_LAYERS} layers a job may have",
                    layers.len()
                ));
            }
            // The copies cost what the group's layers do, once a copy.
            let size: u64 = layers
                .iter()
                .map(|l| l.to_string().len() as u64)
                .sum::<u64>();
            budget.take(size.saturating_mul(copies - 1))?;
            for _ in 0..copies {
                out.extend(layers.iter().cloned());
            }
        }
        root.insert("Layers".into(), Value::Array(out));
    }
    let resolved = resolve(&Value::Object(std::mem::take(root)), &globals, budget)?;
    if let Value::Object(m) = resolved {
        *root = m;
    }
    Ok(())
}

/// Checks the top level and the header: the keys and types this reader relies on.
fn check_top(r: &Reader) -> Result<()> {
    for k in r.root.keys() {
        if !TOP_KEYS.contains(&k.as_str()) {
            return Err(r.bad(format!(
                "unknown top-level key `{k}` (schema v5 allows {})",
                TOP_KEYS.join(", ")
            )));
        }
    }
    let header = r.object(&r.root["Header"], "`Header`")?;
    let version = r.string(&[header], "Schema version", "Header")?;
    let v5 = version.len() == 5 && {
        let b = version.as_bytes();
        b[0] == b'5'
            && b[1] == b'.'
            && b[2].is_ascii_digit()
            && b[3] == b'.'
            && b[4].is_ascii_digit()
    };
    if !v5 {
        return Err(r.bad(format!(
            "Header: `Schema version` is {version:?}; this reader reads schema 5.x.y"
        )));
    }
    r.string(&[header], "Image directory", "Header")?;
    Ok(())
}

/// The settings of `archive` (entry `entry`, the only JSON at the top), checked and with
/// their `${...}` and layer groups expanded.
fn settings<'a>(archive: &'a Archive, entry: &'a str) -> Result<Reader<'a>> {
    let jsons: Vec<&str> = archive
        .names()
        .iter()
        .filter(|n| !n.contains('/') && n.to_ascii_lowercase().ends_with(".json"))
        .map(String::as_str)
        .collect();
    if jsons.len() > 1 {
        return Err(archive.error(
            None,
            format!(
                "{} JSON files at the top ({}); the control-file standard allows one",
                jsons.len(),
                jsons.join(", ")
            ),
        ));
    }
    let root = match serde_json::from_slice::<Value>(archive.get(entry).unwrap_or_default()) {
        Ok(Value::Object(m)) => m,
        Ok(_) => return Err(archive.error(Some(entry), "is not a JSON object")),
        Err(e) => return Err(archive.error(Some(entry), format!("invalid JSON: {e}"))),
    };
    let mut r = Reader {
        archive,
        entry,
        root,
    };
    check_top(&r)?;
    let size = archive.get(entry).map_or(0, <[u8]>::len) as u64;
    let mut budget = Budget::new(EXPANSION_BYTES + EXPANSION_FACTOR * size);
    expand(&mut r.root, &mut budget).map_err(|m| r.bad(m))?;
    Ok(r)
}

/// One exposure of the job: an image of a layer (each duplication counted).
struct Exposure<'a> {
    spec: &'a LayerSpec,
    image: &'a Image,
    /// The layer's first image (the one its position settings move the stage for).
    first: bool,
}

/// Every exposure of the layers `specs`, refused before any is made when there are more
/// than [`MAX_LAYERS`] or none.
fn exposures<'a>(r: &Reader, specs: &'a [LayerSpec]) -> Result<Vec<Exposure<'a>>> {
    let mut exposures = Vec::new();
    for s in specs {
        if s.images.is_empty() {
            return Err(r.bad(format!("{}: the layer has no image", s.at)));
        }
        let total = (s.images.len() as u64)
            .saturating_mul(s.copies)
            .saturating_add(exposures.len() as u64);
        if total > MAX_LAYERS {
            return Err(r.bad(format!(
                "{}: {} duplications of {} make more than the {MAX_LAYERS} layer records a job may have",
                s.at,
                s.copies,
                crate::text::count(s.images.len() as u64, "image", "images")
            )));
        }
        for _ in 0..s.copies {
            for (k, image) in s.images.iter().enumerate() {
                exposures.push(Exposure {
                    spec: s,
                    image,
                    first: k == 0,
                });
            }
        }
    }
    if exposures.is_empty() {
        return Err(r.bad("`Layers` is empty: the job has no layer".into()));
    }
    Ok(exposures)
}

/// The steps of exposure `e` of a layer from `z` to `top` (module docs) and their time.
fn steps(e: &Exposure, (z, top): (f64, f64), last_of_layer: bool) -> (Vec<Step>, f64) {
    let (s, p) = (e.spec, &e.spec.position);
    let mut steps = Vec::new();
    let mut time_s = 0.0;
    let wait = |steps: &mut Vec<Step>, t: &mut f64, s: f64| {
        if s > 0.0 {
            steps.push(Step::Wait { s });
            *t += s;
        }
    };
    if e.first {
        wait(&mut steps, &mut time_s, p.initial_s);
        let up = z + p.up_mm;
        steps.push(Step::Move {
            to_mm: up,
            speed_mm_s: p.up_speed,
            accel_mm_s2: p.up_accel,
        });
        time_s += crate::motion::move_time(p.up_mm, p.up_speed, p.up_accel);
        wait(&mut steps, &mut time_s, p.up_wait_s);
        steps.push(Step::Move {
            to_mm: top,
            speed_mm_s: p.down_speed,
            accel_mm_s2: p.down_accel,
        });
        time_s += crate::motion::move_time(up - top, p.down_speed, p.down_accel);
    }
    wait(&mut steps, &mut time_s, e.image.before_s);
    steps.push(Step::Expose {
        s: e.image.exposure_s,
    });
    time_s += e.image.exposure_s;
    wait(&mut steps, &mut time_s, e.image.after_s);
    if last_of_layer {
        wait(&mut steps, &mut time_s, s.position.final_s);
    }
    (steps, time_s)
}

/// Imports the control-file zip `archive` whose settings are entry `entry`.
pub(crate) fn import(archive: Archive, entry: &str, sha256: &str) -> Result<Job> {
    let r = settings(&archive, entry)?;
    let specs = r.layers()?;
    let exposures = exposures(&r, &specs)?;
    // Decode each distinct image once.
    let mut files: Vec<&str> = exposures.iter().map(|e| e.image.file.as_str()).collect();
    files.sort_unstable();
    files.dedup();
    let images: std::collections::HashMap<&str, imported::Image> = files
        .iter()
        .copied()
        .zip(imported::images(&archive, &files))
        .collect();
    let (w_px, h_px) = exposures
        .iter()
        .find_map(|e| images[e.image.file.as_str()].1.map(|(w, h, _)| (w, h)))
        .ok_or_else(|| archive.error(None, "no image of the job is present and decodable"))?;
    let grid = Grid {
        height_px: h_px,
        pixel_mm: PIXEL_MM,
        pixel_area_mm2: PIXEL_MM * PIXEL_MM,
    };
    let mut layers: Vec<Layer> = Vec::with_capacity(exposures.len());
    let (mut z, mut max_accel) = (0.0f64, 1.0f64);
    for (i, e) in exposures.iter().enumerate() {
        let p = &e.spec.position;
        let thickness = if e.first { p.thickness_mm } else { 0.0 };
        let top = z + thickness;
        let last_of_layer = exposures.get(i + 1).is_none_or(|n| n.first);
        let (steps, time_s) = steps(e, (z, top), last_of_layer);
        if e.first {
            max_accel = max_accel.max(p.up_accel).max(p.down_accel);
        }
        let file = e.image.file.as_str();
        let place = (top, top - thickness / 2.0, thickness);
        let image = (file, &images[file]);
        layers.push(imported::layer(i, place, image, grid, steps, time_s));
        z = top;
    }
    let nominal = specs
        .first()
        .map_or(0.01f64, |s| s.position.thickness_mm)
        .max(1e-4);
    let design = |key: &str| {
        let v = r.root.get("Design").and_then(|d| d.get(key));
        v.and_then(Value::as_str).unwrap_or_default().to_string()
    };
    let generator = match design("Slicer") {
        s if s.is_empty() => "SLA control file v5".to_string(),
        s => format!("SLA control file v5 ({s})"),
    };
    let imported = Imported {
        format: Format::SlaControl,
        generator,
        sha256: sha256.into(),
        machine: Implied {
            name: "sla-control-import".into(),
            resin: design("Resin"),
            projector: "light-engine",
            size_px: (w_px, h_px),
            pixel_mm: PIXEL_MM,
            travel_max_mm: TRAVEL_MAX_MM,
            // The standard's build-platform limit: a move the file asks faster is a `speed`
            // violation.
            max_speed_mm_s: BP_MAX_SPEED_MM_S,
            max_accel_mm_s2: max_accel.max(MIN_ACCEL_MM_S2),
            steps_per_mm: 10_000f64.max(1.0 / nominal),
        },
        layer_height_mm: nominal,
        layers,
        estimate: None,
    };
    imported.job(archive, (entry, "the machine it implies"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;
    use std::io::Write;

    /// Imports a control-file zip of `settings` and one 4 × 3 image `slices/a.png`.
    fn import_settings(settings: &Value) -> Result<Job> {
        let mut img = image::GrayImage::new(4, 3);
        img.put_pixel(1, 1, image::Luma([255]));
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        let opts = zip::write::SimpleFileOptions::default();
        w.start_file("print_settings.json", opts).unwrap();
        w.write_all(&serde_json::to_vec(settings).unwrap()).unwrap();
        w.start_file("slices/a.png", opts).unwrap();
        w.write_all(&png).unwrap();
        let bytes = w.finish().unwrap().into_inner();
        let path = std::path::Path::new("job.zip");
        let archive =
            crate::formats::archive::read::read_zip_bytes(path, &bytes, &Default::default())
                .unwrap();
        let entry = settings_entry(&archive).unwrap();
        import(archive, &entry, "0")
    }

    fn settings(layers: Value) -> Value {
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
                    "Wait before exposure (ms)": 0, "Wait after exposure (ms)": 0
                }
            },
            "Named layer groups": {"g": [{}, {}]},
            "Layers": layers
        })
    }

    #[test]
    fn duplications_past_the_layer_bound_are_refused_before_anything_is_made() {
        let job = import_settings(&settings(json!([
            {"Number of duplications": 3},
            {"Using named layer group": "g", "Number of duplications": 2}
        ])))
        .unwrap();
        assert_eq!(job.manifest.layers.len(), 3 + 4);
        for (layers, what) in [
            (
                json!([{"Number of duplications": u64::MAX}]),
                "Layers[0]: 18446744073709551615 duplications of 1 image make more than the 100000 layer records",
            ),
            (
                json!([{}, {"Using named layer group": "g", "Number of duplications": 50_000}]),
                "Layers[1]: 50000 duplications of layer group `g` (2 layers) make more than the 100000 layers",
            ),
        ] {
            let e = import_settings(&settings(layers)).unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
            assert!(e.contains("job.zip") && e.contains("print_settings.json"), "{e}");
        }
    }

    #[test]
    fn text_interpolation_that_repeats_a_large_variable_is_refused() {
        // 100 KB of variable named 1000 times: 100 MB of text from a 110 KB file.
        let mut s = settings(json!([{}]));
        s["Variables"] = json!({"big": "x".repeat(100_000)});
        s["Design"] = json!({"Purpose": "${big}".repeat(1000)});
        let e = import_settings(&s).unwrap_err().to_string();
        assert!(e.contains("the settings expand to more than"), "{e}");
        // Its own name inside it (text interpolating itself) too, without hanging.
        s["Design"] = json!({});
        s["Variables"] = json!({"big": format!("x{}", "${big}".repeat(20_000))});
        s["Layers"] = json!([{"Using named layer group": "g"}]);
        let e = import_settings(&s).unwrap_err().to_string();
        assert!(e.contains("more than"), "{e}");
        // A group of large layers called many times.
        s["Variables"] = json!({});
        s["Named layer groups"] = json!({"g": [{"Comment": "y".repeat(100_000)}]});
        s["Layers"] = json!([{"Using named layer group": "g", "Number of duplications": 5000}]);
        let e = import_settings(&s).unwrap_err().to_string();
        assert!(e.contains("the settings expand to more than"), "{e}");
    }
}
