//! The control-file standard's description of a printer (`hardware_config.json`;
//! docs/EXECUTOR.md, "Checking against the real machine", says what is read and checked):
//! the build-platform axis, the light engines, whether an XY stage and a vacuum controller
//! exist, and the schema versions it reads. An engine's own mirroring is how the printer
//! shows every image, not a limit a job can break: it is not read.
//!
//! [`Hardware::machine`] is the machine record a job runs on there (the stage; the rest is
//! the job's own), and [`Hardware::check`] what a job asks that the printer lacks, each
//! finding naming the layer, the image and the description's key.

use crate::bundle::Machine;
use crate::error::{Error, Result};
use crate::formats::Request;
use crate::units::Positive;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The build-platform axis.
#[derive(Debug, Clone, PartialEq)]
struct Axis {
    /// Its controller's key and the axis's name, for messages (`galil`, `D`).
    controller: String,
    axis: String,
    travel_mm: f64,
    limits: [Option<f64>; 2],
    counts_per_mm: f64,
    speed: f64,
    accel: f64,
    /// Where a print starts (`bottom_position`).
    start: Option<f64>,
}

/// A light engine.
#[derive(Debug, Clone, PartialEq)]
struct Engine {
    name: String,
    resolution: (u32, u32),
    leds_nm: Vec<u32>,
    /// `grayscale_correction_image`, one per LED (empty: none).
    gray_images: Vec<String>,
}

/// A printer as its hardware description says it.
#[derive(Debug, Clone, PartialEq)]
pub struct Hardware {
    path: PathBuf,
    versions: Vec<String>,
    bp: Axis,
    engines: Vec<Engine>,
    /// The XY stage's controller and its X and Y travel, mm.
    xy: Option<(String, [Option<f64>; 2])>,
    vacuum: bool,
}

/// One thing a job asks that the printer lacks: the layer (none: the whole job), the
/// image and what, naming the description's key.
#[derive(Debug, Clone, PartialEq)]
pub struct Finding {
    /// The layer record.
    pub layer: Option<usize>,
    /// The image.
    pub file: Option<String>,
    /// One line.
    pub message: String,
}

/// Reads a description's keys, every error one line naming the file and the key.
struct Keys<'a> {
    path: &'a Path,
    root: &'a Value,
}

impl Keys<'_> {
    fn bad(&self, key: &str, what: &str) -> Error {
        Error::Bundle {
            path: self.path.into(),
            msg: format!("`{key}` {what}"),
        }
    }

    /// The value at dotted `key` (`galil.axes_speed.D`; a name may hold no dot).
    fn at(&self, path: &[&str]) -> Option<&Value> {
        path.iter().try_fold(self.root, |v, k| v.get(k))
    }

    fn num(&self, path: &[&str]) -> Result<f64> {
        let key = path.join(".");
        let v = self.at(path).ok_or_else(|| self.bad(&key, "is missing"))?;
        v.as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| self.bad(&key, &format!("is {v}, not a number")))
    }

    fn positive(&self, path: &[&str]) -> Result<f64> {
        let v = self.num(path)?;
        (v > 0.0)
            .then_some(v)
            .ok_or_else(|| self.bad(&path.join("."), &format!("is {v}, not positive")))
    }

    fn text(&self, path: &[&str]) -> Result<&str> {
        let key = path.join(".");
        let v = self.at(path).ok_or_else(|| self.bad(&key, "is missing"))?;
        v.as_str()
            .ok_or_else(|| self.bad(&key, &format!("is {v}, not text")))
    }

    /// A list at `path`, each item read by `item` (absent: empty).
    fn list<T>(&self, path: &[&str], item: impl Fn(&Value) -> Option<T>) -> Result<Vec<T>> {
        let key = path.join(".");
        match self.at(path) {
            None => Ok(Vec::new()),
            Some(Value::Array(a)) => a
                .iter()
                .map(|v| item(v).ok_or_else(|| self.bad(&key, &format!("holds {v}"))))
                .collect(),
            Some(v) => Err(self.bad(&key, &format!("is {v}, not a list"))),
        }
    }

    /// The build-platform axis (`stages.bp_stage` names its controller).
    fn axis(&self) -> Result<Axis> {
        let c = self.text(&["stages", "bp_stage"])?;
        let axis = match self.at(&[c, "default_axis"]) {
            Some(_) => self.text(&[c, "default_axis"])?.to_string(),
            None => self
                .list(&[c, "axes"], |v| v.as_str().map(String::from))?
                .into_iter()
                .next()
                .ok_or_else(|| self.bad(&format!("{c}.default_axis"), "is missing"))?,
        };
        let a = axis.as_str();
        let limit = |k: usize| -> Result<Option<f64>> {
            match self.at(&[c, "limits", a]).and_then(|l| l.get(k)) {
                None | Some(Value::Null) => Ok(None),
                Some(v) => v
                    .as_f64()
                    .filter(|x| x.is_finite())
                    .map(Some)
                    .ok_or_else(|| self.bad(&format!("{c}.limits.{a}"), &format!("holds {v}"))),
            }
        };
        let start = match self.at(&[c, "bottom_position"]) {
            None | Some(Value::Null) => None,
            Some(_) => Some(self.num(&[c, "bottom_position"])?),
        };
        Ok(Axis {
            travel_mm: self.positive(&[c, "axes_travel", a])?,
            limits: [limit(0)?, limit(1)?],
            counts_per_mm: self.positive(&[c, "axes_ctspmm", a])?,
            speed: self.positive(&[c, "axes_speed", a])?,
            accel: self.positive(&[c, "axes_acceleration", a])?,
            start,
            controller: c.into(),
            axis,
        })
    }

    fn engine(&self, name: &str) -> Result<Engine> {
        let px = |v: &Value| {
            v.as_u64()
                .filter(|&n| (1..=65536).contains(&n))
                .map(|n| n as u32)
        };
        let res = self.list(&[name, "resolution"], px)?;
        let [w, h] = res[..] else {
            return Err(self.bad(
                &format!("{name}.resolution"),
                "is not [width, height] in pixels",
            ));
        };
        let nm = |v: &Value| v.as_u64().and_then(|n| u32::try_from(n).ok());
        let text = |v: &Value| Some(v.as_str().unwrap_or_default().to_string());
        Ok(Engine {
            name: name.into(),
            resolution: (w, h),
            leds_nm: self.list(&[name, "leds_nm"], nm)?,
            gray_images: self.list(&[name, "grayscale_correction_image"], text)?,
        })
    }
}

impl Hardware {
    /// Reads the description at `path` (a JSON file of at most 16 MiB).
    pub fn read(path: &Path) -> Result<Hardware> {
        let bytes = crate::input::read_file(path, "hardware description", 16 << 20)?;
        let root: Value = serde_json::from_slice(&bytes).map_err(|e| Error::Bundle {
            path: path.into(),
            msg: format!("not JSON: {e}"),
        })?;
        Hardware::from_json(path, &root)
    }

    /// The description `root` read from `path`.
    pub fn from_json(path: &Path, root: &Value) -> Result<Hardware> {
        let k = Keys { path, root };
        if !root.is_object() {
            return Err(k.bad("", "is not a JSON object"));
        }
        let names = k.list(&["light_engines"], |v| v.as_str().map(String::from))?;
        let engines = names.iter().map(|n| k.engine(n)).collect::<Result<_>>()?;
        let xy = match k.at(&["stages", "xy_stage"]).and_then(Value::as_str) {
            Some(c) if !c.is_empty() => {
                let travel = |a: &str| k.at(&[c, "axes_travel", a]).and_then(Value::as_f64);
                Some((c.to_string(), [travel("X"), travel("Y")]))
            }
            _ => None,
        };
        Ok(Hardware {
            path: path.into(),
            versions: k.list(&["valid_schema_versions"], |v| v.as_str().map(String::from))?,
            bp: k.axis()?,
            engines,
            xy,
            vacuum: root.get("mks").is_some(),
        })
    }

    /// The description's name: its file name.
    pub fn name(&self) -> String {
        self.path.file_name().map_or_else(
            || self.path.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        )
    }

    /// The machine `job` (a job's record) runs on with this printer: the job's record with
    /// the build-platform axis as its stage, from `bottom_position` (or the lower limit)
    /// up to the upper limit (or the lower limit plus the axis's travel); the keys it
    /// states no longer `unstated`, and each one's source named for messages.
    pub fn machine(&self, job: &Machine) -> Result<Machine> {
        let a = &self.bp;
        let key = |what: &str| format!("{}.{what}.{}", a.controller, a.axis);
        let start = a.start.or(a.limits[0]).unwrap_or(0.0);
        let lo = a.limits[0].unwrap_or(start);
        let hi = a.limits[1].or(a.limits[0].map(|l| l + a.travel_mm));
        let hi = hi.unwrap_or(start + a.travel_mm);
        let mut m = job.clone();
        m.name = self.name();
        let s = &mut m.stage;
        let r = crate::round::derived;
        (s.travel_min_mm, s.travel_max_mm, s.home_mm) = (r(lo - start), r(hi - start), 0.0);
        let bad = |k: &str, v: f64| Error::Bundle {
            path: self.path.clone(),
            msg: format!("`{}` = {v} is not a limit a stage has", key(k)),
        };
        s.max_speed_mm_s = Positive::new(a.speed).ok_or_else(|| bad("axes_speed", a.speed))?;
        s.max_accel_mm_s2 =
            Positive::new(a.accel).ok_or_else(|| bad("axes_acceleration", a.accel))?;
        s.steps_per_mm =
            Positive::new(a.counts_per_mm).ok_or_else(|| bad("axes_ctspmm", a.counts_per_mm))?;
        let travel = format!(
            "{}.bottom_position up to {} or the lower limit + {}",
            a.controller,
            key("limits"),
            key("axes_travel")
        );
        for (k, v) in [
            ("stage.travel_min_mm", key("limits")),
            ("stage.travel_max_mm", travel),
            ("stage.max_speed_mm_s", key("axes_speed")),
            ("stage.max_accel_mm_s2", key("axes_acceleration")),
            ("stage.steps_per_mm", key("axes_ctspmm")),
        ] {
            m.unstated.retain(|u| u != k);
            m.sources.insert(k.into(), v);
        }
        m.validate().map_err(|msg| Error::Bundle {
            path: self.path.clone(),
            msg: format!("the build platform's axis: {msg}"),
        })?;
        Ok(m)
    }

    /// The engine a projector named `name` (the `k`-th) uses: the engine of that name, or
    /// the `k`-th (the standard's check takes the first when an image names none).
    pub fn engine_of(&self, name: &str, k: usize) -> Option<(&str, Option<u32>)> {
        let e = self
            .engines
            .iter()
            .find(|e| e.name == name)
            .or(self.engines.get(k))?;
        Some((&e.name, e.leds_nm.first().copied()))
    }

    /// Gives each projector of `m` (the record of a profile or a job) the light engine it
    /// uses ([`Hardware::engine_of`]): its name, and its first LED's wavelength when the
    /// projector states none.
    pub fn name_engines(
        &self,
        projectors: impl Iterator<Item = (String, Option<u32>)>,
    ) -> Vec<(String, Option<u32>)> {
        projectors
            .enumerate()
            .map(|(k, (name, nm))| match self.engine_of(&name, k) {
                Some((e, led)) => (e.to_string(), nm.or(led)),
                None => (name, nm),
            })
            .collect()
    }

    /// What the projectors of machine record `m` (a profile's, before a job is sliced for
    /// this printer) ask that the printer's light engines cannot do.
    pub fn check_projectors(&self, m: &Machine) -> Vec<String> {
        let mut out = Vec::new();
        for (k, p) in m.projector.iter().enumerate() {
            let um = p.pixel_mm.get() * 1000.0;
            let r = Request {
                layer: 0,
                at: String::new(),
                file: String::new(),
                engine: p.name.clone(),
                wavelength_nm: p.wavelength_nm,
                offset_um: p.offset_px.map(|o| o as f64 * um),
                gray_correction: false,
                size_px: Some((p.width_px, p.height_px)),
            };
            if let Some(why) = self.lacks(&r) {
                out.push(format!("projector[{k}] ({}): {why}", p.name));
            }
        }
        out
    }

    /// What the exposures `requests` (and a job printing under `vacuum`) ask that this
    /// printer lacks.
    pub fn check(&self, requests: &[Request], vacuum: bool) -> Vec<Finding> {
        let mut out = Vec::new();
        let job = |message: String| Finding {
            layer: None,
            file: None,
            message,
        };
        if !self.versions.is_empty() && !self.versions.iter().any(|v| v == "v5") {
            let versions = self.versions.join(", ");
            out.push(job(format!("the printer reads control files of schema {versions} (valid_schema_versions), not v5")));
        }
        if vacuum && !self.vacuum {
            out.push(job(
                "the job prints under vacuum, but the printer has no vacuum controller (mks)"
                    .into(),
            ));
        }
        for r in requests {
            if let Some(message) = self.lacks(r) {
                let at = if r.at.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", r.at)
                };
                out.push(Finding {
                    layer: Some(r.layer),
                    file: Some(r.file.clone()),
                    message: format!("layer {}{at}, image {}: {message}", r.layer, r.file),
                });
            }
        }
        out
    }

    /// What exposure `r` asks that the printer lacks, naming the key (the first such).
    fn lacks(&self, r: &Request) -> Option<String> {
        let names: Vec<&str> = self.engines.iter().map(|e| e.name.as_str()).collect();
        let Some(e) = self.engines.iter().find(|e| e.name == r.engine) else {
            let e = &r.engine;
            return Some(format!(
                "light engine '{e}' is not on this printer (light_engines: {})",
                names.join(", ")
            ));
        };
        let leds = || {
            e.leds_nm
                .iter()
                .map(u32::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        };
        let led = match r.wavelength_nm {
            Some(nm) => match e.leds_nm.iter().position(|&l| l == nm) {
                Some(i) => i,
                None => {
                    return Some(format!(
                        "light engine {} has no {nm} nm LED ({}.leds_nm: {})",
                        e.name,
                        e.name,
                        leds()
                    ))
                }
            },
            None => 0,
        };
        if r.gray_correction && e.gray_images.get(led).is_none_or(|i| i.is_empty()) {
            return Some(format!("grayscale correction, but light engine {} has no correction image for its LED {} ({}.grayscale_correction_image)", e.name, led, e.name));
        }
        if let Some((w, h)) = r.size_px.filter(|&s| s != e.resolution) {
            let (rw, rh) = e.resolution;
            return Some(format!(
                "the image is {w} × {h} px, light engine {} shows {rw} × {rh} ({}.resolution)",
                e.name, e.name
            ));
        }
        let [x, y] = r.offset_um;
        if x == 0.0 && y == 0.0 {
            return None;
        }
        let Some((c, travel)) = &self.xy else {
            return Some(format!("the image offset ({x}, {y}) µm needs an XY stage, and the printer has none (stages.xy_stage)"));
        };
        for (axis, v, t) in [("X", x, travel[0]), ("Y", y, travel[1])] {
            if t.is_some_and(|t| v.abs() / 1000.0 > t) {
                return Some(format!("the image offset {axis} {v} µm is beyond the XY stage's travel ({c}.axes_travel.{axis})"));
            }
        }
        None
    }
}
