//! The machine a job runs on, as the job records it ([`Machine`]): what the executor
//! simulates and verifies, and what `inspect` and the exporters read.
//!
//! The record holds the keys of the machine profile those readers use, under the same names
//! (`stage.max_speed_mm_s`, `projector[0].width_px`, …), and nothing else: a profile key
//! only the planner or the slicer reads (recoat, peel and hybrid planning, slicing, the
//! resin's working curve, exposure ramps, the calibration's field and fit, the
//! distortion table, blending, the point-spread width) is not part of the job format.
//! [`Machine::of`] takes a profile's keys by name, and so does the reader of version 1
//! and 2 manifests, which embedded the whole profile.

use crate::profile::calibration::response::Response;
use crate::profile::{Field, Process, Profile};
use crate::units::{NonNegative, Positive};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The machine of a job: made from the profile by [`Machine::of`], or by an importer from
/// what a foreign file says.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Machine {
    /// Name of the profile (or of the importer, e.g. `sl1-import-sl1`).
    pub name: String,
    /// How the machine forms layers.
    pub process: Process,
    /// The lift stage.
    pub stage: Stage,
    /// The exposure shutter.
    pub shutter: Shutter,
    /// The DMD.
    pub dmd: Dmd,
    /// The projectors (one DMD each); at least one.
    pub projector: Vec<Projector>,
    /// The exposure the job's cure figures are for.
    pub exposure: Exposure,
    /// The resin.
    pub resin: Resin,
    /// Keys whose values the record's source does not state (`stage.max_speed_mm_s`,
    /// `projector[].pixel_mm`: `[]` for every projector): a foreign file or a hardware
    /// description that gives no speed limit or pixel size. The value is a stand-in the
    /// simulation needs; no check is made against it, and reports say so.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unstated: Vec<String>,
    /// Where a key's value was read, for messages: record key → the key of the machine
    /// description (`stage.max_speed_mm_s` → `galil.axes_speed.D`). Not part of the job.
    #[serde(skip)]
    pub sources: BTreeMap<String, String>,
}

/// One projector: its mirrors, where they land on the build plane, and its light.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Projector {
    /// Name (mask folders and messages).
    pub name: String,
    /// Mirror columns.
    pub width_px: u32,
    /// Mirror rows.
    pub height_px: u32,
    /// Edge of one (square) pixel on the build plane, mm.
    pub pixel_mm: Positive,
    /// Offset of its top-left pixel in the field's pixel grid (col, row).
    pub offset_px: [u32; 2],
    /// The image is mirrored left-right.
    pub mirror_x: bool,
    /// The image is mirrored top-bottom.
    pub mirror_y: bool,
    /// The projector's light response, when calibrated: how its grays turn into light.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<Calibration>,
    /// The light engine's wavelength, nm, when stated (the SLA control file's `Light
    /// engine wavelength (nm)`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wavelength_nm: Option<u32>,
    /// The light engine's power setting, 0 to 1000, when stated (the control file's
    /// `Light engine power setting`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub power_setting: Option<u32>,
}

/// What a job keeps of a projector's light calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Relative irradiance by pixel value (docs/CALIBRATION.md).
    pub response: Response,
}

/// The lift stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    /// Position resolution, steps per mm.
    pub steps_per_mm: Positive,
}

/// The exposure shutter's latencies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Shutter {
    /// Opening latency, s.
    pub open_s: NonNegative,
    /// Closing latency, s.
    pub close_s: NonNegative,
}

/// The DMD's timing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dmd {
    /// Time to load one mask, s.
    pub load_s: NonNegative,
}

/// The normal layer's exposure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Exposure {
    /// Exposure of a normal layer, s: the dose `run --cure` scales each layer's by (an
    /// imported job, which has no cure record: its last layer's).
    pub layer_s: NonNegative,
}

/// The resin, by name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Resin {
    /// Resin name.
    pub name: String,
}

/// One key in which two machines differ, with both values as text.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Difference {
    /// Dotted key path, e.g. `stage.max_speed_mm_s` or `projector[0].width_px`.
    pub key: String,
    /// The value in the first machine (the job's).
    pub job: String,
    /// The value in the second machine.
    pub machine: String,
}

/// A profile key as the record's patterns name it: `projector.0.pixel_mm` is
/// `projector[].pixel_mm` (as in `unstated` and [`NOT_COMPARED`]).
fn key_pattern(key: &str) -> String {
    key.split('.')
        .fold(String::new(), |k, part| match part.parse::<u32>() {
            Ok(_) => k + "[]",
            Err(_) if k.is_empty() => part.to_string(),
            Err(_) => format!("{k}.{part}"),
        })
}

/// Keys [`Machine::differences`] leaves out (`[]` stands for every index): names, and what
/// the job was made for rather than what runs it (its process, resin, normal exposure and
/// its projectors' calibrations, which the executor takes from the job's own record).
const NOT_COMPARED: [&str; 7] = [
    "name",
    "process",
    "exposure",
    "resin",
    "unstated",
    "projector[].name",
    "projector[].calibration",
];

impl Machine {
    /// The record of `profile`: its keys of the record's names (the profile validated).
    pub fn of(profile: &Profile) -> Machine {
        let v = serde_json::to_value(profile).expect("a profile serializes");
        serde_json::from_value(v).expect("a profile holds every key of the machine record")
    }

    /// The build field covered by the union of the projectors.
    pub fn field(&self) -> Field {
        Field::spanning(
            self.projector
                .iter()
                .map(|p| (p.offset_px, p.width_px, p.height_px)),
            self.projector.first().map_or(0.0, |p| p.pixel_mm.get()),
        )
    }

    /// Checks what serde cannot: the rules of a profile for the keys the record holds
    /// (projectors, pixel sizes, stage travel, each key's unit range).
    pub fn validate(&self) -> std::result::Result<(), String> {
        let Some(first) = self.projector.first() else {
            return Err("at least one projector is required".into());
        };
        for p in &self.projector {
            let size = (p.width_px, p.height_px);
            crate::profile::check_projector(&p.name, size, p.pixel_mm.get(), p.offset_px)?;
            crate::profile::check_same_pixel(p.pixel_mm.get(), first.pixel_mm.get())?;
            if p.power_setting.is_some_and(|w| w > 1000) {
                return Err(format!("projector {}: power_setting is above 1000", p.name));
            }
            if let Some(c) = &p.calibration {
                c.response
                    .validate()
                    .map_err(|m| format!("projector {} calibration: {m}", p.name))?;
            }
        }
        let v = serde_json::to_value(self).map_err(|e| e.to_string())?;
        crate::profile::check_unit_ranges(&v, "")?;
        let s = &self.stage;
        crate::profile::check_travel(s.travel_min_mm, s.travel_max_mm, s.home_mm)
    }

    /// Every key in which `self` (the job's machine) and `other` differ, in record order,
    /// but for names and what the job was made for (`NOT_COMPARED`): each value (a list of
    /// numbers is one value), a list of records by index after its length. A value its
    /// record does not state (`unstated`) reads `not stated`.
    pub fn differences(&self, other: &Machine) -> Vec<Difference> {
        let tree = |m: &Machine| {
            let text = serde_json::to_string(m).expect("a machine record serializes");
            serde_json::from_str::<Tree>(&text).expect("JSON reads as a tree")
        };
        let mut out = Vec::new();
        walk(&tree(self), &tree(other), ("", ""), &mut out);
        for d in &mut out {
            for (m, v) in [(self, &mut d.job), (other, &mut d.machine)] {
                if !m.states(&d.key) {
                    *v = "not stated".into();
                }
            }
        }
        out.retain(|d| d.job != d.machine);
        out
    }

    /// False when the record's source does not state `key` (a dotted key; a projector's
    /// index is matched by `[]` in `unstated`).
    pub fn states(&self, key: &str) -> bool {
        let pattern: String = key
            .split('[')
            .enumerate()
            .map(|(i, part)| match (i, part.find(']')) {
                (0, _) | (_, None) => part.to_string(),
                (_, Some(j)) => format!("[]{}", &part[j + 1..]),
            })
            .collect();
        !self.unstated.iter().any(|k| *k == pattern || *k == key)
    }

    /// This record with `overrides` (`run --set`, profile key names: `projector.0.pixel_mm`)
    /// applied, read back and validated; the keys set are stated from then on. A key of
    /// what the job was made for (`NOT_COMPARED`: its exposure, resin, process, a
    /// projector's calibration) is refused: the executor takes those from the job.
    pub fn with_overrides(
        &self,
        overrides: &[crate::profile::Override],
    ) -> crate::error::Result<Machine> {
        let labels: Vec<&str> = overrides.iter().map(|o| o.label.as_str()).collect();
        let error = |msg: String| crate::error::Error::Profile {
            origin: self.name.clone(),
            msg: format!("{}: {msg}", labels.join(", ")),
        };
        for o in overrides {
            let pattern = key_pattern(&o.key);
            let of_job = |n: &&&str| pattern == ***n || pattern.starts_with(&format!("{n}."));
            if let Some(n) = NOT_COMPARED.iter().find(of_job) {
                return Err(crate::error::Error::Usage(format!(
                    "{}: {n} is the job's, not the machine's: the run takes it from the job (slice again to change it)",
                    o.label
                )));
            }
        }
        let mut table = toml::Table::try_from(self).map_err(|e| error(e.to_string()))?;
        for o in overrides {
            o.apply(&mut table).map_err(&error)?;
        }
        let mut m = Machine::deserialize(toml::Value::Table(table))
            .map_err(|e| error(e.message().to_string()))?;
        m.validate().map_err(&error)?;
        m.sources = self.sources.clone();
        for o in overrides {
            let key = key_pattern(&o.key);
            m.unstated.retain(|u| !u.starts_with(&key));
            m.sources.retain(|k, _| !k.starts_with(&o.key));
        }
        Ok(m)
    }

    /// How a message names record key `key`: the machine description's key it was read
    /// from (`sources`), or the record's own.
    pub fn label(&self, key: &str) -> String {
        self.sources.get(key).cloned().unwrap_or_else(|| key.into())
    }
}

/// A serialized record whose objects keep their keys in record order (a
/// `serde_json::Value` sorts them).
#[derive(PartialEq, Deserialize)]
#[serde(untagged)]
enum Tree {
    Object(#[serde(deserialize_with = "entries")] Vec<(String, Tree)>),
    List(Vec<Tree>),
    Value(serde_json::Value),
}

/// An object's entries in order.
fn entries<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<(String, Tree)>, D::Error> {
    struct Entries;
    impl<'de> serde::de::Visitor<'de> for Entries {
        type Value = Vec<(String, Tree)>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("an object")
        }
        fn visit_map<A: serde::de::MapAccess<'de>>(
            self,
            mut a: A,
        ) -> Result<Self::Value, A::Error> {
            let mut entries = Vec::new();
            while let Some(entry) = a.next_entry()? {
                entries.push(entry);
            }
            Ok(entries)
        }
    }
    d.deserialize_map(Entries)
}

impl Tree {
    /// The value as the summary shows it: numbers as the shortest decimal (`50`, `0.05`),
    /// a list of numbers as `[0, 0]`, text without quotes, a list of records by length.
    fn text(&self) -> String {
        use serde_json::Value;
        match self {
            Tree::Value(Value::Number(n)) if n.as_u64().is_none() => {
                format!("{}", n.as_f64().unwrap_or(f64::NAN))
            }
            Tree::Value(Value::String(s)) => s.clone(),
            Tree::Value(v) => v.to_string(),
            Tree::List(l) if l.iter().all(|t| matches!(t, Tree::Value(_))) => {
                let items: Vec<String> = l.iter().map(Tree::text).collect();
                format!("[{}]", items.join(", "))
            }
            Tree::List(l) => l.len().to_string(),
            Tree::Object(_) => "{…}".into(),
        }
    }
}

/// Compares `a` and `b` at `(key, pattern)`: the key path, and the path with `[]` for
/// indices.
fn walk(a: &Tree, b: &Tree, (key, pattern): (&str, &str), out: &mut Vec<Difference>) {
    if NOT_COMPARED.contains(&pattern) {
        return;
    }
    let records = |l: &[Tree]| l.iter().any(|t| matches!(t, Tree::Object(_)));
    // A list's length goes before its entries.
    let start = out.len();
    match (a, b) {
        (Tree::Object(x), Tree::Object(y)) => {
            let absent = Tree::Value("absent".into());
            let extra = y.iter().filter(|(k, _)| x.iter().all(|(j, _)| j != k));
            for (k, _) in x.iter().chain(extra) {
                let get = |o: &[(String, Tree)]| o.iter().position(|(j, _)| j == k);
                let u = get(x).map_or(&absent, |i| &x[i].1);
                let v = get(y).map_or(&absent, |i| &y[i].1);
                let (key, pattern) = match key {
                    "" => (k.clone(), k.clone()),
                    _ => (format!("{key}.{k}"), format!("{pattern}.{k}")),
                };
                walk(u, v, (&key, &pattern), out);
            }
            return;
        }
        (Tree::List(x), Tree::List(y)) if records(x) || records(y) => {
            let pattern = format!("{pattern}[]");
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                walk(u, v, (&format!("{key}[{i}]"), &pattern), out);
            }
            if x.len() == y.len() {
                return;
            }
        }
        _ if a == b => return,
        _ => {}
    }
    let d = Difference {
        key: key.into(),
        job: a.text(),
        machine: b.text(),
    };
    out.insert(start, d);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_record_is_the_profiles_keys_the_job_needs() {
        for name in crate::profile::builtin_names() {
            let p = Profile::resolve(name).unwrap();
            let m = Machine::of(&p);
            m.validate().unwrap();
            assert_eq!(m.field(), p.field());
            assert_eq!(m.stage.max_speed_mm_s, p.stage.max_speed_mm_s);
            assert_eq!(m.projector.len(), p.projector.len());
            let v = serde_json::to_value(&m).unwrap();
            for planner_only in ["slicing", "recoat", "peel", "hybrid", "description"] {
                assert!(v.get(planner_only).is_none(), "{name}: {planner_only}");
            }
            assert!(v["projector"][0].get("psf_sigma_px").is_none());
            assert!(v["resin"].get("dp_mm").is_none());
        }
        let cal = Machine::of(&Profile::default_profile()).projector[0].clone();
        let c = serde_json::to_value(cal.calibration.unwrap()).unwrap();
        assert_eq!(
            c.as_object().unwrap().keys().collect::<Vec<_>>(),
            ["response"]
        );
    }

    #[test]
    fn differences_name_key_and_both_values_of_what_runs_the_job() {
        let job = Profile::default_profile();
        let m = Machine::of(&job);
        assert!(m.differences(&m).is_empty());
        let mut real = job.clone();
        real.stage.max_speed_mm_s = Positive::new(2.5).unwrap();
        real.projector[0].mirror_y = true;
        real.projector[0].offset_px = [3, 0];
        real.projector[0].name = "renamed".into();
        real.projector[0].calibration = None;
        real.name = "renamed".into();
        real.exposure.layer_s = Positive::new(3.0).unwrap();
        let d = m.differences(&Machine::of(&real));
        let got: Vec<(&str, &str, &str)> = d
            .iter()
            .map(|d| (d.key.as_str(), d.job.as_str(), d.machine.as_str()))
            .collect();
        assert_eq!(
            got,
            vec![
                ("stage.max_speed_mm_s", "10", "2.5"),
                ("projector[0].offset_px", "[0, 0]", "[3, 0]"),
                ("projector[0].mirror_y", "false", "true"),
            ]
        );
        let tiled = Machine::of(&Profile::resolve("tiled-2x1").unwrap());
        let d = m.differences(&tiled);
        let count = d.iter().find(|d| d.key == "projector").unwrap();
        assert_eq!((count.job.as_str(), count.machine.as_str()), ("1", "2"));
    }

    #[test]
    fn a_record_breaking_a_profile_rule_is_refused() {
        let good = Machine::of(&Profile::default_profile());
        let mut m = good.clone();
        m.projector.clear();
        assert!(m.validate().unwrap_err().contains("at least one projector"));
        let mut m = good.clone();
        m.stage.home_mm = 500.0;
        assert!(m.validate().unwrap_err().contains("home_mm"));
        let mut m = good.clone();
        m.projector[0].width_px = 0;
        assert!(m.validate().unwrap_err().contains("width_px"));
        let mut m = good;
        m.stage.travel_max_mm = 1e9;
        assert!(m.validate().unwrap_err().contains("stage.travel_max_mm"));
    }
}
