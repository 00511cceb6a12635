//! Reading an SLA control-file zip as a job (docs/EXECUTOR.md, "Imported jobs": the
//! checks, how settings resolve, the steps of a layer and the machine the file implies).
//!
//! The settings are expanded (`expr.rs`), validated against the standard's schema
//! (`schema.rs`), then checked for what the schema cannot say; the expansion and the layer
//! records are bounded ([`MAX_LAYERS`], `EXPANSION_BYTES`) before anything is made. Each
//! image is a layer record of its own, the first with the layer's thickness and position
//! steps, each further one 0 µm thick at the same height (the standard's "0 um layer").
//! What the file does not state (pixel size, stage limits and resolution) is an
//! `unstated` stand-in that no check is made against.

use super::expr::{resolve, Budget};
use super::Position;
use crate::bundle::{Layer, Step};
use crate::error::{Error, Result};
use crate::formats::archive::read::Archive;
use crate::formats::imported::{self, Imported};
use crate::formats::{Format, Job, Request};
use serde_json::{Map, Value};

/// The pixel size of a file that states none, mm (a stand-in: `unstated`).
const PIXEL_MM: f64 = 0.001;
/// Most layer records (exposures, duplications counted) a job may have: the zip reader's
/// bounds fit a job of 100,000 layers, and a count the file states is no cheaper to
/// follow than layers it holds.
pub const MAX_LAYERS: u64 = 100_000;
/// What the `${...}` expansion and the layer groups may make, bytes: this much plus
/// [`EXPANSION_FACTOR`] times the settings entry's size.
const EXPANSION_BYTES: u64 = 64 << 20;
/// See [`EXPANSION_BYTES`].
const EXPANSION_FACTOR: u64 = 16;
/// The keys of the imported machine the file does not state.
const UNSTATED: [&str; 4] = [
    "stage.travel_max_mm",
    "stage.max_speed_mm_s",
    "stage.max_accel_mm_s2",
    "stage.steps_per_mm",
];

/// The top-level `.json` entry that holds print settings (`Header` and `Default layer
/// settings`), `print_settings.json` first. (The standard allows one JSON file at the
/// top; [`import`] refuses an archive with more.)
pub(crate) fn settings_entry(archive: &Archive) -> Option<String> {
    let mut names: Vec<&String> = top_jsons(archive);
    names.sort_by_key(|n| n.as_str() != "print_settings.json");
    names
        .into_iter()
        .find(|n| {
            serde_json::from_slice::<Value>(archive.get(n).ok().flatten().unwrap_or_default())
                .ok()
                .and_then(|v| v.as_object().cloned())
                .is_some_and(|o| {
                    o.contains_key("Header") && o.contains_key("Default layer settings")
                })
        })
        .cloned()
}

/// The `.json` entries at the top of `archive`.
fn top_jsons(archive: &Archive) -> Vec<&String> {
    let json = |n: &&String| !n.contains('/') && n.to_ascii_lowercase().ends_with(".json");
    archive.names().iter().filter(json).collect()
}

/// One exposure of a layer: its image and what it asks of the light engine.
#[derive(Debug, Clone)]
struct Image {
    /// The entry in the archive.
    file: String,
    exposure_s: f64,
    before_s: f64,
    after_s: f64,
    engine: String,
    wavelength_nm: Option<u32>,
    power: Option<u32>,
    offset_um: [f64; 2],
    /// `Mirror image long axis`, `Mirror image short axis`.
    mirror: [bool; 2],
    gray_correction: bool,
    /// Where it is in the file: "Layers[3].Image settings list[1]".
    at: String,
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

/// The special techniques of the standard that are not simulated, by name, with where
/// they are asked for.
type Techniques = Vec<(&'static str, String)>;

/// Reads the settings JSON (validated against the schema, so its keys have their types).
struct Reader<'a> {
    archive: &'a Archive,
    entry: &'a str,
    root: Map<String, Value>,
}

/// The range of a setting by the unit its key ends with: (unit, smallest when not 0,
/// largest); the profile's ranges (`profile::UNIT_RANGES`) in the file's units.
const RANGES: [(&str, f64, f64); 5] = [
    ("(ms)", 0.0, 1e9),
    ("(mm)", 0.0, 1e4),
    ("(um)", 0.0, 1e7),
    ("(mm/sec)", 1e-6, 1e4),
    ("(mm/sec^2)", 1e-6, 1e6),
];

/// An object's entries (an empty map for anything else: the schema checked the types).
fn obj(v: Option<&Value>) -> Map<String, Value> {
    v.and_then(Value::as_object).cloned().unwrap_or_default()
}

/// The first of `maps` holding `key`.
fn get<'v>(maps: &[&'v Map<String, Value>], key: &str) -> Option<&'v Value> {
    maps.iter().find_map(|m| m.get(key))
}

/// True when `v.a.b` (a path of keys) is `true`.
fn enabled(v: &Map<String, Value>, path: &[&str]) -> bool {
    let mut at = v.get(path[0]);
    for k in &path[1..] {
        at = at.and_then(|x| x.get(k));
    }
    at == Some(&Value::Bool(true))
}

impl Reader<'_> {
    fn bad(&self, msg: String) -> Error {
        self.archive.error(Some(self.entry), msg)
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
            let m = self
                .root
                .get(table)
                .and_then(|t| t.get(&cur))
                .and_then(Value::as_object)
                .ok_or_else(|| self.bad(format!("{at}: `{cur}` is not in `{table}`")))?;
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

    /// The named settings `key` of `m` names in `table`, or none.
    fn uses(
        &self,
        m: &Map<String, Value>,
        key: &str,
        table: &str,
        at: &str,
    ) -> Result<Option<Map<String, Value>>> {
        match m.get(key).and_then(Value::as_str) {
            Some(n) if !n.is_empty() => self.named(table, n, at).map(Some),
            _ => Ok(None),
        }
    }

    /// Setting `key` from the first of `maps` that has it, as a number ≥ 0 (> 0 when
    /// `positive`; the schema allows 0 for speeds, which no move can have).
    fn num(
        &self,
        maps: &[&Map<String, Value>],
        key: &str,
        at: &str,
        positive: bool,
    ) -> Result<f64> {
        let v = get(maps, key)
            .ok_or_else(|| self.bad(format!("{at}: no `{key}` (nor in the defaults)")))?;
        let x = match v.as_f64() {
            Some(x) if x.is_finite() && x >= 0.0 && (!positive || x > 0.0) => x,
            _ => {
                return Err(self.bad(format!(
                    "{at}: `{key}` is {v}, not a {} number",
                    if positive { "positive" } else { "non-negative" }
                )))
            }
        };
        // What the schema leaves unbounded, bounded by what a machine has (as a profile's
        // keys are): a longer wait or move, or a slower one, never finishes a print.
        let (lo, hi) = RANGES
            .iter()
            .find(|(unit, ..)| key.ends_with(unit))
            .map_or((0.0, f64::MAX), |r| (r.1, r.2));
        if x > hi || (x > 0.0 && x < lo) {
            return Err(self.bad(format!(
                "{at}: `{key}` is {v}, not what a machine has ({} to {hi:e})",
                if lo > 0.0 {
                    format!("{lo:e}")
                } else {
                    "0".into()
                }
            )));
        }
        Ok(x)
    }

    /// The image `own` of a layer at `at`, over the layer's named default image settings
    /// `layer_img` and the defaults `dimg`; `dir` is the image directory.
    fn image(
        &self,
        own: &Map<String, Value>,
        (layer_img, dimg): (&Map<String, Value>, &Map<String, Value>),
        dir: &str,
        at: &str,
        notes: &mut Techniques,
    ) -> Result<Image> {
        // An image's own named settings replace the layer's named defaults.
        let named = self.uses(
            own,
            "Using named image settings",
            "Named image settings",
            at,
        )?;
        let maps = [own, named.as_ref().unwrap_or(layer_img), dimg];
        let ms = |key: &str| self.num(&maps, key, at, false).map(|v| v / 1000.0);
        let text = |key: &str| get(&maps, key).and_then(Value::as_str).unwrap_or_default();
        let int = |key: &str| get(&maps, key).and_then(Value::as_u64).map(|v| v as u32);
        let flag = |key: &str| get(&maps, key) == Some(&Value::Bool(true));
        let file = text("Image file");
        if file.is_empty() {
            return Err(self.bad(format!("{at}: no `Image file` (nor in the defaults)")));
        }
        // The older form names the wavelength with the engine: `visitech (405 nm)`.
        let label = text("Light engine").trim();
        let legacy = label.strip_suffix("nm)").and_then(|r| {
            let (name, nm) = r.rsplit_once('(')?;
            Some((name.trim(), nm.trim().parse::<u32>().ok()?))
        });
        let (engine, legacy_nm) = legacy.map_or((label, None), |(n, w)| (n, Some(w)));
        let special = get(&maps, "Special image techniques").map(|v| obj(Some(v)));
        for (name, path) in [
            ("0 um layer", ["0 um layer", "Enable 0 um layer"]),
            ("Print on film", ["Print on film", "Enable print on film"]),
        ] {
            if special.as_ref().is_some_and(|s| enabled(s, &path)) {
                notes.push((name, at.to_string()));
            }
        }
        let offset = |key: &str| get(&maps, key).and_then(Value::as_f64).unwrap_or(0.0);
        Ok(Image {
            file: match dir.trim_end_matches('/') {
                "" | "." => file.to_string(),
                d => format!("{d}/{file}"),
            },
            exposure_s: ms("Layer exposure time (ms)")?,
            before_s: ms("Wait before exposure (ms)")?,
            after_s: ms("Wait after exposure (ms)")?,
            engine: engine.to_string(),
            wavelength_nm: int("Light engine wavelength (nm)").or(legacy_nm),
            power: int("Light engine power setting"),
            offset_um: [offset("Image x offset (um)"), offset("Image y offset (um)")],
            mirror: [
                flag("Mirror image long axis"),
                flag("Mirror image short axis"),
            ],
            gray_correction: flag("Do grayscale correction"),
            at: at.to_string(),
        })
    }

    /// The layer `layer` (a `LAYER_BASE` object) at `at`, with the defaults.
    fn layer(
        &self,
        layer: &Map<String, Value>,
        at: &str,
        copies: u64,
        notes: &mut Techniques,
    ) -> Result<LayerSpec> {
        let defaults = obj(self.root.get("Default layer settings"));
        let (dpos, dimg) = (
            obj(defaults.get("Position settings")),
            obj(defaults.get("Image settings")),
        );
        let own_pos = obj(layer.get("Position settings"));
        let named_pos = self.uses(
            &own_pos,
            "Using named position settings",
            "Named position settings",
            at,
        )?;
        let named_pos = named_pos.unwrap_or_default();
        let pos = [&own_pos, &named_pos, &dpos];
        if get(&pos, "Special layer techniques")
            .is_some_and(|v| enabled(&obj(Some(v)), &["Squeeze out resin", "Enable squeeze"]))
        {
            notes.push(("Squeeze out resin", at.to_string()));
        }
        let layer_img = self
            .uses(
                layer,
                "Using named default image settings",
                "Named image settings",
                at,
            )?
            .unwrap_or_default();
        let dir = obj(self.root.get("Header"));
        let dir = dir
            .get("Image directory")
            .and_then(Value::as_str)
            .unwrap_or_default();
        // No list, or an empty one: one exposure of the default image.
        let list = match layer.get("Image settings list").and_then(Value::as_array) {
            Some(a) if !a.is_empty() => a.iter().map(|v| obj(Some(v))).collect(),
            _ => vec![Map::new()],
        };
        let images = list
            .iter()
            .enumerate()
            .map(|(k, own)| {
                let at = format!("{at}.Image settings list[{k}]");
                self.image(own, (&layer_img, &dimg), dir, &at, notes)
            })
            .collect::<Result<_>>()?;
        Ok(LayerSpec {
            position: Position::read(|key, positive| self.num(&pos, key, at, positive))?,
            images,
            copies,
            at: at.to_string(),
        })
    }

    /// Every layer of the file in print order (named groups were expanded by [`expand`]),
    /// and the special techniques they ask for.
    fn layers(&self) -> Result<(Vec<LayerSpec>, Techniques)> {
        let defaults = obj(self.root.get("Default layer settings"));
        let copies_of =
            |m: &Map<String, Value>| m.get("Number of duplications").and_then(Value::as_u64);
        let default_copies = copies_of(&defaults).unwrap_or(1);
        let items = self.root.get("Layers").and_then(Value::as_array);
        let mut notes = Vec::new();
        let mut out = Vec::new();
        for (k, item) in items.into_iter().flatten().enumerate() {
            let m = obj(Some(item));
            let copies = copies_of(&m).unwrap_or(default_copies);
            out.push(self.layer(&m, &format!("Layers[{k}]"), copies, &mut notes)?);
        }
        Ok((out, notes))
    }

    /// The pixel size dmdsl's export states in `Header.Comment` (`pixel_mm P`).
    fn pixel_mm(&self) -> Option<f64> {
        let comment = self.root.get("Header")?.get("Comment")?.as_str()?;
        let rest = &comment[comment.find("pixel_mm ")? + 9..];
        let text = rest
            .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == '-'))
            .next()?;
        text.parse()
            .ok()
            .filter(|p: &f64| p.is_finite() && *p > 0.0)
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

/// The settings of `archive` (entry `entry`, the only JSON at the top), expanded and
/// checked against the standard's schema.
fn settings<'a>(archive: &'a Archive, entry: &'a str) -> Result<Reader<'a>> {
    let jsons = top_jsons(archive);
    if jsons.len() > 1 {
        let names: Vec<&str> = jsons.iter().map(|s| s.as_str()).collect();
        return Err(archive.error(
            None,
            format!(
                "{} JSON files at the top ({}); the control-file standard allows one",
                jsons.len(),
                names.join(", ")
            ),
        ));
    }
    let root = match serde_json::from_slice::<Value>(archive.get(entry)?.unwrap_or_default()) {
        Ok(Value::Object(m)) => m,
        Ok(_) => return Err(archive.error(Some(entry), "is not a JSON object")),
        Err(e) => return Err(archive.error(Some(entry), format!("invalid JSON: {e}"))),
    };
    let mut r = Reader {
        archive,
        entry,
        root,
    };
    // The version first, as the standard's validator checks it: another major version
    // is another schema.
    let version = r.root.get("Header").and_then(|h| h.get("Schema version"));
    if !version
        .and_then(Value::as_str)
        .is_some_and(|v| v.starts_with("5."))
    {
        let v = version.map_or("none".into(), Value::to_string);
        return Err(r.bad(format!(
            "Header: `Schema version` is {v}; this reader reads schema 5.x.y"
        )));
    }
    let size = archive.get(entry)?.map_or(0, <[u8]>::len) as u64;
    let mut budget = Budget::new(EXPANSION_BYTES + EXPANSION_FACTOR * size);
    expand(&mut r.root, &mut budget).map_err(|m| r.bad(m))?;
    if let Some(problem) = super::schema::check(&Value::Object(r.root.clone())) {
        return Err(r.bad(problem));
    }
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

/// The projectors the exposures use: one per light engine, offset and mirroring, in the
/// order of first use ([`Image`] and the module docs), and each exposure's projector.
fn projectors(
    exposures: &[Exposure],
    sizes: &std::collections::HashMap<&str, imported::Image>,
    pixel_mm: f64,
) -> (Vec<crate::bundle::machine::Projector>, Vec<usize>) {
    let mut keys: Vec<(&str, [f64; 2], [bool; 2])> = Vec::new();
    let mut out: Vec<crate::bundle::machine::Projector> = Vec::new();
    let mut of = Vec::with_capacity(exposures.len());
    for e in exposures {
        let i = e.image;
        let key = (i.engine.as_str(), i.offset_um, i.mirror);
        if let Some(k) = keys.iter().position(|k| *k == key) {
            of.push(k);
            continue;
        }
        let size = sizes[i.file.as_str()].1.map_or((1, 1), |(w, h, _)| (w, h));
        // The engine's first placement is the engine; the others say how they differ.
        let mut name = i.engine.clone();
        if keys.iter().any(|k| k.0 == key.0) {
            let [x, y] = i.offset_um;
            name += &format!(" at ({x}, {y}) um");
            for (on, axis) in i.mirror.iter().zip(["long", "short"]) {
                if *on {
                    name += &format!(", mirrored along its {axis} axis");
                }
            }
        }
        let mut p = imported::projector(&name, size, pixel_mm);
        let px = |um: f64| (um / 1000.0 / pixel_mm).round().max(0.0) as u32;
        p.offset_px = i.offset_um.map(px);
        let long_x = size.0 >= size.1;
        (p.mirror_x, p.mirror_y) = match long_x {
            true => (i.mirror[0], i.mirror[1]),
            false => (i.mirror[1], i.mirror[0]),
        };
        (p.wavelength_nm, p.power_setting) = (i.wavelength_nm, i.power);
        of.push(out.len());
        keys.push(key);
        out.push(p);
    }
    (out, of)
}

/// The notes of what the file asks and the job does not simulate.
fn not_simulated(techniques: &Techniques, vacuum: bool) -> Vec<String> {
    let mut names: Vec<&str> = techniques.iter().map(|t| t.0).collect();
    names.dedup();
    let mut notes: Vec<String> = names
        .iter()
        .map(|name| {
            let at: Vec<&str> = techniques
                .iter()
                .filter(|t| t.0 == *name)
                .map(|t| t.1.as_str())
                .collect();
            format!(
                "not simulated: {name} ({}{})",
                at[0],
                match at.len() {
                    1 => String::new(),
                    k => format!(" and {} more", k - 1),
                }
            )
        })
        .collect();
    if vacuum {
        notes.push("not simulated: Print under vacuum (Special print techniques)".into());
    }
    notes
}

/// Imports the control-file zip `archive` whose settings are entry `entry`.
pub(crate) fn import(archive: Archive, entry: &str, sha256: &str) -> Result<Job> {
    let r = settings(&archive, entry)?;
    let (specs, techniques) = r.layers()?;
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
    if images.values().all(|i| i.1.is_none()) {
        return Err(archive.error(None, "no image of the job is present and decodable"));
    }
    let stated_pixel = r.pixel_mm();
    let pixel_mm = stated_pixel.unwrap_or(PIXEL_MM);
    let (projectors, of) = projectors(&exposures, &images, pixel_mm);
    // The stand-ins of what the file does not state: the job's own extremes.
    let (mut top, mut speed, mut accel, mut z) = (1.0f64, 1.0f64, 1.0f64, 0.0f64);
    for e in exposures.iter().filter(|e| e.first) {
        let p = &e.spec.position;
        z += p.thickness_mm;
        top = top.max(z + p.up_mm);
        speed = speed.max(p.up_speed).max(p.down_speed);
        accel = accel.max(p.up_accel).max(p.down_accel);
    }
    let mut unstated = UNSTATED.to_vec();
    if stated_pixel.is_none() {
        unstated.push("projector[].pixel_mm");
    }
    let design = |key: &str| {
        let v = r.root.get("Design").and_then(|d| d.get(key));
        v.and_then(Value::as_str).unwrap_or_default().to_string()
    };
    let limits = (top.min(1e4), speed.min(1e4), accel.min(1e6), 10_000.0);
    let name = ("sla-control-import".to_string(), design("Resin"));
    let machine = imported::machine(name, limits, projectors, &unstated);
    let mut layers: Vec<Layer> = Vec::with_capacity(exposures.len());
    let mut requests = Vec::with_capacity(exposures.len());
    let mut z = 0.0f64;
    for (i, e) in exposures.iter().enumerate() {
        let p = &e.spec.position;
        let thickness = if e.first { p.thickness_mm } else { 0.0 };
        let top = z + thickness;
        let last_of_layer = exposures.get(i + 1).is_none_or(|n| n.first);
        let (steps, time_s) = steps(e, (z, top), last_of_layer);
        let file = e.image.file.as_str();
        let place = (i, (top, top - thickness / 2.0, thickness));
        let image = &images[file];
        let on = (&machine, of[i], pixel_mm * pixel_mm, None);
        layers.push(imported::layer(place, (file, image), on, steps, time_s));
        let im = e.image;
        requests.push(Request {
            layer: i,
            at: im.at.clone(),
            file: file.to_string(),
            engine: im.engine.clone(),
            wavelength_nm: im.wavelength_nm,
            offset_um: im.offset_um,
            gray_correction: im.gray_correction,
            size_px: image.1.map(|(w, h, _)| (w, h)),
        });
        z = top;
    }
    let nominal = specs
        .first()
        .map_or(0.01f64, |s| s.position.thickness_mm)
        .max(1e-4);
    let generator = match design("Slicer") {
        s if s.is_empty() => "SLA control file v5".to_string(),
        s => format!("SLA control file v5 ({s})"),
    };
    let vacuum = enabled(
        &r.root,
        &[
            "Special print techniques",
            "Print under vacuum",
            "Enable vacuum",
        ],
    );
    let imported = Imported {
        format: Format::SlaControl,
        generator,
        sha256: sha256.into(),
        machine,
        layer_height_mm: nominal,
        layers,
        estimate: None,
        resin_ml: None,
        stated_areas: false,
        requests,
        vacuum,
        notes: not_simulated(&techniques, vacuum),
    };
    imported.job(archive, (entry, "the machine it implies"))
}

#[cfg(test)]
mod tests {
    use super::super::test_settings as settings;
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
            crate::formats::archive::read::read_zip(path, bytes, &Default::default()).unwrap();
        let entry = settings_entry(&archive).unwrap();
        import(archive, &entry, "0")
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
