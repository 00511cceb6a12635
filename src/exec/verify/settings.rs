//! A native job's settings against its layers: what the slicer wrote together must agree,
//! so a setting changed on its own (the layer height, the normal exposure, the light
//! compensation) is a `settings` problem.
//!
//! * Every layer is `settings.layer_height_mm` thick (a layer 0 mm thick is a further
//!   exposure of the layer below, as a job imported from a control file that shows a
//!   layer's images in turn carries them, and is left out of these rules).
//! * The layered layers are exposed `machine.exposure.layer_s` once the bottom layers and
//!   the ramp after them are over: the last layered exposure is `layer_s`, unless the
//!   job ends on its ramp (the last two differ, the last one nearer `layer_s`) or has only
//!   bottom layers (all alike).
//! * `settings.compensation` is `off` exactly when no light compensation record
//!   (`optics`, `projector_optics`) is there, and otherwise every record's mode.

use super::problem_in;
use crate::bundle::{BundleSource, Manifest, Mode, MANIFEST};
use crate::exec::{Kind, Violation};
use crate::text::number;

/// Exposures and thicknesses are written to 1 ms and 1e-9 mm at most.
const EXPOSURE_TOL_S: f64 = 5e-4 + 1e-9;
const THICKNESS_TOL_MM: f64 = 1e-9;

/// Adds a `settings` problem, naming `job.json`, for each rule `m` breaks.
pub(super) fn check(dir: &dyn BundleSource, m: &Manifest, problems: &mut Vec<Violation>) {
    let job = (MANIFEST, MANIFEST);
    let mut add = |msg: String| problems.push(problem_in(dir, None, Kind::Settings, job, &msg));
    let h = m.settings.layer_height_mm;
    let thick = m
        .layers
        .iter()
        .enumerate()
        .filter(|(_, l)| l.thickness_mm > 0.0);
    let mut other = thick.filter(|(_, l)| (l.thickness_mm - h).abs() > THICKNESS_TOL_MM);
    if let Some((i, l)) = other.next() {
        let more = other.count();
        let (h, t) = (number(h), number(l.thickness_mm));
        add(format!("settings.layer_height_mm is {h} mm, but layer {i} is {t} mm thick (thickness_mm) and {more} more differ"));
    }
    if let Some(msg) = normal_exposure(m) {
        add(msg);
    }
    let c = m.settings.compensation.as_str();
    let records: Vec<_> = m.optics.iter().chain(&m.projector_optics).collect();
    let msg = match (c, records.iter().find(|o| o.mode != c)) {
        ("off" | "dose", Some(o)) => Some(format!(
            "settings.compensation is {c}, but the job records the {} compensation of projector {}",
            o.mode, o.projector
        )),
        ("zone" | "pixel", _) if records.is_empty() => Some(format!(
            "settings.compensation is {c}, but the job has no light compensation record (optics)"
        )),
        ("zone" | "pixel", Some(o)) => Some(format!(
            "settings.compensation is {c}, but the compensation of projector {} is {}",
            o.projector, o.mode
        )),
        ("off" | "zone" | "pixel" | "dose", _) => None,
        _ => Some(format!(
            "settings.compensation is {c:?}: off, zone, pixel or dose"
        )),
    };
    if let Some(msg) = msg {
        add(msg);
    }
}

/// What is wrong with `machine.exposure.layer_s` against the layered layers' exposures
/// (see the module docs), if anything.
fn normal_exposure(m: &Manifest) -> Option<String> {
    let layer_s = m.machine.exposure.layer_s.get();
    let layered = m.layers.iter().enumerate();
    let e: Vec<(usize, f64)> = layered
        .filter(|(_, l)| l.mode == Mode::Layered && l.thickness_mm > 0.0)
        .map(|(i, l)| (i, l.exposure_s))
        .collect();
    let [.., (_, before), (j, v)] = e[..] else {
        return None;
    };
    let at_normal = (v - layer_s).abs() <= EXPOSURE_TOL_S;
    let ramping =
        (v - before).abs() > EXPOSURE_TOL_S && (v - before).signum() == (layer_s - v).signum();
    let bottom_only = e.iter().all(|x| (x.1 - v).abs() <= EXPOSURE_TOL_S);
    (!(at_normal || ramping || bottom_only)).then(|| {
        let (s, v) = (number(layer_s), number(v));
        format!("machine.exposure.layer_s is {s} s, but the job's normal layers are exposed {v} s (layer {j}: exposure_s)")
    })
}

#[cfg(test)]
mod tests {
    use super::super::test_support::*;
    use super::super::verify;
    use crate::exec::testutil::{manifest, two_layer_topdown};
    use crate::exec::Kind;
    use crate::units::NonNegative;

    #[test]
    fn settings_changed_on_their_own_are_found() {
        let dir = Scratch::new("settings");
        let only = |m: &crate::bundle::Manifest| {
            let v = verify(&dir, m);
            let p: Vec<_> = v
                .problems
                .into_iter()
                .filter(|p| p.kind == Kind::Settings)
                .collect();
            p.into_iter().map(|p| p.message).collect::<Vec<_>>()
        };
        // Layers 16 s, 8 s on a machine whose normal exposure is 8 s.
        let fine = two_layer_topdown();
        assert_eq!(only(&fine), Vec::<String>::new());
        let mut m = fine.clone();
        m.settings.layer_height_mm = 0.25;
        let e = only(&m);
        assert_eq!(e.len(), 1);
        assert!(e[0].ends_with("job.json: settings.layer_height_mm is 0.25 mm, but layer 0 is 0.5 mm thick (thickness_mm) and 1 more differ"), "{e:?}");
        // 8 s after 16 s is on a ramp towards 4 s: fine; alike after a ramp, it is not.
        m = fine.clone();
        m.machine.exposure.layer_s = NonNegative::new(4.0).unwrap();
        assert_eq!(only(&m), Vec::<String>::new());
        m.machine.exposure.layer_s = NonNegative::new(20.0).unwrap();
        assert!(only(&m)[0].contains("machine.exposure.layer_s is 20 s, but the job's normal layers are exposed 8 s (layer 1"));
        let mut three = fine.clone();
        three.layers.push(three.layers[1].clone());
        three.layers[2].index = 2;
        three.machine.exposure.layer_s = NonNegative::new(4.0).unwrap();
        assert_eq!(only(&three).len(), 1);
        // A job of bottom layers only says nothing of the normal exposure.
        three.layers[0].exposure_s = 8.0;
        assert_eq!(only(&three), Vec::<String>::new());
        m = fine.clone();
        m.settings.compensation = "zone".into();
        assert!(only(&m)[0].contains(
            "settings.compensation is zone, but the job has no light compensation record"
        ));
        m.settings.compensation = "bright".into();
        assert!(
            only(&m)[0].contains("settings.compensation is \"bright\": off, zone, pixel or dose")
        );
        // A further exposure of a layer (0 mm thick, another exposure time) is no layer of
        // the height's or the exposure's rules.
        let mut again = fine.clone();
        again.layers.push(again.layers[1].clone());
        (again.layers[2].index, again.layers[2].thickness_mm) = (2, 0.0);
        again.layers[2].exposure_s = 3.0;
        assert_eq!(only(&again), Vec::<String>::new());
        let _ = manifest;
    }
}
