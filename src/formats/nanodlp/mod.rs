//! NanoDLP plates (`part.nanodlp`), the zip NanoDLP imports and exports (docs/FORMATS.md,
//! "nanodlp", names its entries and sources).
//!
//! A plate says a layer's steps as NanoDLP runs them (`Plate`): one set of settings for
//! the first `SupportLayerNumber` layers (the `Support…` keys) and one for the others.
//! Stage speeds are the printer's own, not the plate's: dmdsl records the job's as the
//! profile's custom values `Dmdsl…`, which NanoDLP keeps as variables and acts on only if
//! a code field uses them. [`mod@read`] imports a plate, `write.rs` writes a job as one and
//! says what it cannot carry.

pub mod read;
mod write;

pub(crate) use read::import;
pub(crate) use write::{cannot_carry, write};

use crate::bundle::Step;
use serde_json::{json, Map, Value};

/// The entries of a plate.
pub const META: &str = "meta.json";
/// See [`META`].
pub const PLATE: &str = "plate.json";
/// See [`META`].
pub const PROFILE: &str = "profile.json";
/// See [`META`].
pub const OPTIONS: &str = "options.json";
/// See [`META`]: `options.json` under the name UVtools reads.
pub const SLICER: &str = "slicer.json";
/// See [`META`].
pub const INFO: &str = "info.json";
/// See [`META`]: 200 × 100 px, as the documentation gives it.
pub const PREVIEW: &str = "3d.png";

/// True when `archive` holds a plate's `plate.json` and `profile.json`.
pub(crate) fn holds(archive: &super::archive::read::Archive) -> bool {
    archive.contains(PLATE) && archive.contains(PROFILE)
}

/// One set of a plate's layer settings: the support (bottom) layers' or the others'.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Group {
    cure_s: f64,
    thickness_mm: f64,
    /// The lift after the layer, mm, and the wait at its top, s.
    lift_mm: f64,
    top_wait_s: f64,
    before_s: f64,
    after_s: f64,
    /// The lift's and the move back's speed (mm/s) and acceleration (mm/s²).
    up: [f64; 2],
    down: [f64; 2],
}

/// The keys of a [`Group`] in `profile.json`, the bottom layers' first: (bottom, others,
/// unit: how many of the key's unit make the group's, e.g. µm per mm).
const KEYS: [(&str, &str, f64); 6] = [
    ("SupportCureTime", "CureTime", 1.0),
    ("SupportDepth", "Depth", 1000.0),
    ("SupportWaitHeight", "WaitHeight", 1.0),
    ("SupportTopWait", "TopWait", 1.0),
    ("SupportWaitBeforePrint", "WaitBeforePrint", 1.0),
    ("SupportWaitAfterPrint", "WaitAfterPrint", 1.0),
];

/// The custom values that carry a group's speeds (`Dmdsl…`, `DmdslSupport…`).
const SPEEDS: [&str; 4] = ["UpSpeed", "UpAccel", "DownSpeed", "DownAccel"];

impl Group {
    /// The values of [`KEYS`] in order, in the group's units.
    fn values(&self) -> [f64; 6] {
        let g = self;
        [
            g.cure_s,
            g.thickness_mm,
            g.lift_mm,
            g.top_wait_s,
            g.before_s,
            g.after_s,
        ]
    }

    fn set(&mut self, k: usize, v: f64) {
        let g = self;
        let slot = [
            &mut g.cure_s,
            &mut g.thickness_mm,
            &mut g.lift_mm,
            &mut g.top_wait_s,
            &mut g.before_s,
            &mut g.after_s,
        ];
        *slot.into_iter().nth(k).expect("a key of KEYS") = v;
    }
}

/// What a plate says of its layers.
#[derive(Debug, Clone, PartialEq)]
struct Plate {
    /// `SupportLayerNumber`.
    bottom: usize,
    /// The support layers' settings, then the others'.
    groups: [Group; 2],
}

/// One layer as a plate gives it: its top, thickness, steps and their time.
type PlateLayer = (f64, f64, Vec<Step>, f64);

impl Plate {
    fn group(&self, i: usize) -> &Group {
        &self.groups[usize::from(i >= self.bottom)]
    }

    /// The `n` layers as NanoDLP runs them: each one's lift of the layer below (none for
    /// the first, which moves from 0), the wait at its top, the move to the layer, the
    /// waits around the cure.
    fn layers(&self, n: usize) -> Vec<PlateLayer> {
        let mut z = 0.0f64;
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let g = self.group(i);
            let below = if i == 0 { g } else { self.group(i - 1) };
            let (top, mut at) = (z + g.thickness_mm, z);
            let (mut steps, mut t) = (Vec::new(), 0.0);
            let mut go = |steps: &mut Vec<Step>, t: &mut f64, to: f64, [v, a]: [f64; 2]| {
                steps.push(Step::Move {
                    to_mm: to,
                    speed_mm_s: v,
                    accel_mm_s2: a,
                });
                *t += crate::motion::move_time((to - at).abs(), v, a);
                at = to;
            };
            let wait = |steps: &mut Vec<Step>, t: &mut f64, s: f64| {
                if s > 0.0 {
                    steps.push(Step::Wait { s });
                    *t += s;
                }
            };
            if i > 0 && below.lift_mm > 0.0 {
                go(&mut steps, &mut t, z + below.lift_mm, below.up);
                wait(&mut steps, &mut t, below.top_wait_s);
            }
            go(&mut steps, &mut t, top, below.down);
            wait(&mut steps, &mut t, g.before_s);
            steps.push(Step::Expose { s: g.cure_s });
            t += g.cure_s;
            wait(&mut steps, &mut t, g.after_s);
            out.push((top, g.thickness_mm, steps, t));
            z = top;
        }
        out
    }

    /// The plate's keys of `profile.json`: the groups' settings (times s, thickness µm,
    /// lift mm) and, as custom values, their speeds.
    fn to_profile(&self) -> Map<String, Value> {
        let mut out = Map::new();
        let mut custom = Map::new();
        for (gi, g) in self.groups.iter().enumerate() {
            for ((bottom, other, unit), v) in KEYS.iter().zip(g.values()) {
                let key = if gi == 0 { bottom } else { other };
                out.insert(key.to_string(), json!(crate::round::derived(v * unit)));
            }
            let prefix = if gi == 0 { "DmdslSupport" } else { "Dmdsl" };
            for (name, v) in SPEEDS.iter().zip(g.up.iter().chain(&g.down)) {
                let v = crate::round::derived(*v).to_string();
                custom.insert(format!("{prefix}{name}"), Value::String(v));
            }
        }
        out.insert("SupportLayerNumber".into(), json!(self.bottom));
        out.insert("TransitionalLayer".into(), json!(0));
        out.insert("CustomValues".into(), Value::Object(custom));
        out
    }
}
