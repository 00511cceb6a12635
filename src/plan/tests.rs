//! Unit tests of the planner on synthetic layers.

use super::*;
use crate::motion::move_time;
use crate::profile::Profile;
use crate::round::StageGrid;

/// Half a step of the built-in profiles' stages (800 steps per mm), mm.
const HALF_STEP: f64 = 0.5 / 800.0 + 1e-12;

fn info(i: usize, h: f64, area: f64, fill: f64) -> LayerInfo {
    LayerInfo {
        index: i,
        // As the manifest records it (a whole number of steps for these layer heights).
        z_mm: crate::round::decimals((i + 1) as f64 * h, 9),
        thickness_mm: h,
        area_mm2: area,
        max_fill_distance_mm: fill,
        islands: 0,
        island_mm: None,
        island_part: None,
    }
}

/// `n` layers of height `h`, layer `i` of area and max fill distance `f(i)`.
fn layers_of(n: usize, h: f64, f: impl Fn(usize) -> (f64, f64)) -> Vec<LayerInfo> {
    (0..n).map(|i| info(i, h, f(i).0, f(i).1)).collect()
}

fn top(steps: &[Step]) -> f64 {
    steps
        .iter()
        .filter_map(|s| match *s {
            Step::Move { to_mm, .. } | Step::Sweep { to_mm, .. } => Some(to_mm),
            _ => None,
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Lift height of a layer: highest `to_mm` minus its exposure position.
fn lift(p: &LayerPlan, l: &LayerInfo) -> f64 {
    top(&p.steps) - l.z_mm
}

#[test]
fn top_down_dips_returns_waits_exposes() {
    let p = Profile::default_profile();
    let r = p.recoat.clone().unwrap();
    let h = 0.05;
    let layers = layers_of(4, h, |i| (50.0, 0.5 + i as f64));
    let plan = plan(&p, &layers).unwrap();
    for (l, lp) in layers.iter().zip(&plan.layers) {
        assert_eq!(lp.mode, Mode::Layered);
        let want_wait = round::time_s(r.wait_for(l.max_fill_distance_mm, h, 0.5).0);
        match lp.steps.as_slice() {
            [Step::Move { to_mm: d, .. }, Step::Move { to_mm: z, .. }, Step::Wait { s }, Step::Expose { s: e }] =>
            {
                assert!((d - l.z_mm - r.dip_mm.get()).abs() < HALF_STEP);
                assert_eq!(*z, l.z_mm);
                assert_eq!(*s, want_wait);
                assert_eq!(*e, round::time_s(p.exposure.layer_exposure_s(l.index)));
            }
            other => panic!("unexpected steps {other:?}"),
        }
    }
    // The wait grows with the flat extent, between the minimum and the cap.
    let waits: Vec<f64> = plan
        .layers
        .iter()
        .map(|lp| match lp.steps[2] {
            Step::Wait { s } => s,
            _ => unreachable!(),
        })
        .collect();
    assert_eq!(waits[0], r.wait_s.get());
    assert!(waits.windows(2).all(|w| w[1] >= w[0]));
    assert_eq!(waits[3], r.wait_max_s.get());
    let capped = plan
        .warnings
        .iter()
        .find(|w| w.code == "plan.wait-capped")
        .expect("capped");
    assert_eq!(capped.fields["wait_max_s"], r.wait_max_s.get());
    assert!(capped.fields["model_max_s"].as_f64().unwrap() > r.wait_max_s.get());
    assert_eq!(plan.all_layered_time_s, None);
    // Layer times and the total are each rounded to 1 ms.
    let sum: f64 = plan.layers.iter().map(|l| l.time_s).sum();
    assert!((plan.print_time_s - sum).abs() <= 0.0005 * (layers.len() + 1) as f64);
}

#[test]
fn bottom_up_two_stage_lift_scales_with_area() {
    let p = Profile::resolve("bottom-up").unwrap();
    let k = p.peel.clone().unwrap();
    let h = 0.05;
    let b = p.exposure.bottom_layers as usize;
    let areas = [300.0, 300.0, 300.0, 300.0, 100.0, 100.0, 800.0, 800.0, 10.0];
    let layers = layers_of(areas.len(), h, |i| (areas[i], 3.0));
    let plan = plan(&p, &layers).unwrap();
    assert!(matches!(plan.layers[0].steps[0], Step::Move { to_mm, .. } if to_mm == h));
    for i in 1..layers.len() {
        let (want_lift, want_v) = k.lift_for(areas[i - 1], i - 1 < b);
        let lp = &plan.layers[i];
        assert!(
            (lift(lp, &layers[i]) - want_lift).abs() < HALF_STEP,
            "layer {i}"
        );
        // wait after cure, slow stage, fast stage, retract, wait, expose
        match lp.steps.as_slice() {
            [Step::Wait { .. }, Step::Move {
                to_mm: s,
                speed_mm_s: v,
                ..
            }, Step::Move { speed_mm_s: f, .. }, Step::Move { to_mm: z, .. }, Step::Wait { .. }, Step::Expose { s: e }] =>
            {
                assert!((s - layers[i - 1].z_mm - k.slow_lift_mm.get()).abs() < HALF_STEP);
                assert_eq!(*v, round::derived(want_v));
                assert_eq!(*f, k.fast_speed_mm_s.get());
                assert_eq!(*z, layers[i].z_mm);
                assert_eq!(*e, round::time_s(p.exposure.layer_exposure_s(i)));
            }
            other => panic!("layer {i}: {other:?}"),
        }
    }
    // Larger peeled area: higher lift, slower first stage.
    let v = |i: usize| match plan.layers[i].steps[1] {
        Step::Move { speed_mm_s, .. } => speed_mm_s,
        _ => unreachable!(),
    };
    assert!(lift(&plan.layers[7], &layers[7]) > lift(&plan.layers[5], &layers[5]));
    assert!(v(7) < v(5));
}

#[test]
fn hybrid_modes_lifts_and_sweeps() {
    let p = Profile::resolve("hybrid-bottomup").unwrap();
    let hy = p.hybrid.clone().unwrap();
    let h = 0.1;
    let first_free = (p.exposure.bottom_layers + p.exposure.transition_layers) as usize;
    // Bottom/transition layers, then: continuous ×3, 5.0 (2 mm), 2.52 (continuous: within
    // tolerance), 7.5 (4 mm), 7.53 (8 mm), 1.0 ×2 (continuous), 31 (beyond table: 8 mm).
    let mut fills = vec![7.5; first_free];
    fills.extend([1.0, 2.0, 2.5, 5.0, 2.52, 7.5, 7.53, 1.0, 1.0, 31.0]);
    let layers = layers_of(fills.len(), h, |i| (100.0, fills[i]));
    let plan = plan(&p, &layers).unwrap();
    let modes: Vec<Mode> = plan.layers.iter().map(|l| l.mode).collect();
    use Mode::{Continuous as C, Layered as L};
    let mut want = vec![L; first_free];
    want.extend([C, C, C, L, C, L, L, C, C, L]);
    assert_eq!(modes, want);
    assert_eq!(plan.continuous_layers, 6);
    for (i, (l, lp)) in layers.iter().zip(&plan.layers).enumerate() {
        match lp.mode {
            Mode::Continuous => {
                let last = *lp.steps.last().unwrap();
                assert_eq!(
                    last,
                    Step::Sweep {
                        to_mm: l.z_mm,
                        speed_mm_s: 0.06
                    }
                );
                // The sweep's light time to 7 significant digits.
                assert!((lp.exposure_s - h / 0.06).abs() < 1e-6);
                // Inside a run a continuous slice is a single sweep; after a layered slice
                // an explicit settle wait comes first.
                if plan.layers[i - 1].mode == Mode::Continuous {
                    assert_eq!(lp.steps.len(), 1, "layer {i}");
                } else {
                    assert!(matches!(lp.steps[0], Step::Wait { s } if s == hy.switch_wait_s.get()));
                }
            }
            Mode::Layered if i > 0 => {
                let want_lift = if i - 1 < p.exposure.bottom_layers as usize {
                    hy.bottom_lift_mm
                        .get()
                        .max(hy.olh_for(l.max_fill_distance_mm).0)
                } else {
                    hy.olh_for(l.max_fill_distance_mm).0
                };
                assert!((lift(lp, l) - want_lift).abs() < HALF_STEP, "layer {i}");
                assert!(matches!(lp.steps.last(), Some(Step::Expose { .. })));
            }
            Mode::Layered => {}
        }
    }
    let lifts: Vec<f64> = (first_free..layers.len())
        .filter(|&i| plan.layers[i].mode == Mode::Layered)
        .map(|i| (lift(&plan.layers[i], &layers[i]) * 1e6).round() / 1e6)
        .collect();
    assert_eq!(lifts, vec![2.0, 4.0, 8.0, 8.0]);
    assert!(
        plan.warnings
            .iter()
            .any(|w| w.code == "plan.beyond-lift-table"
                && w.message.contains("beyond the lift table"))
    );
    // The all-layered comparison plan is slower.
    let all = plan.all_layered_time_s.unwrap();
    assert!(all > plan.print_time_s, "{all} vs {}", plan.print_time_s);
}

#[test]
fn out_of_travel_is_an_error_and_long_lifts_are_clamped() {
    let mut p = Profile::resolve("hybrid-bottomup").unwrap();
    p.stage.travel_max_mm = 1.5;
    let layers = layers_of(10, 0.1, |_| (400.0, 10.0));
    let plan = plan(&p, &layers).unwrap();
    assert!(plan.layers.iter().all(|l| top(&l.steps) <= 1.5));
    assert!(plan
        .warnings
        .iter()
        .any(|w| w.code == "plan.travel-clamped" && w.message.contains("shortened")));
    let layers = layers_of(20, 0.1, |_| (400.0, 10.0));
    let e = super::plan(&p, &layers).unwrap_err();
    assert!(
        e.contains("layer 15") && e.contains("outside the stage travel"),
        "{e}"
    );
}

/// An independent replay of the timing contract: one flat event list, absolute clock.
fn replay(p: &Profile, plans: &[LayerPlan]) -> f64 {
    let flat: Vec<(usize, Step)> = plans
        .iter()
        .enumerate()
        .flat_map(|(i, l)| l.steps.iter().map(move |s| (i, *s)))
        .collect();
    let (open, close, load) = (
        p.shutter.open_s.get(),
        p.shutter.close_s.get(),
        p.dmd.load_s.get(),
    );
    let mut clock = 0.0;
    let mut pos = p.stage.home_mm;
    let mut layer_start = 0.0;
    let mut cur = usize::MAX;
    let mut shutter_open = false;
    for (k, &(i, s)) in flat.iter().enumerate() {
        if i != cur {
            cur = i;
            layer_start = clock;
        }
        let ready = layer_start + load;
        match s {
            Step::Move {
                to_mm,
                speed_mm_s,
                accel_mm_s2,
            } => {
                assert!(!shutter_open);
                clock += move_time(to_mm - pos, speed_mm_s, accel_mm_s2);
                pos = to_mm;
            }
            Step::Wait { s } => clock += s,
            Step::Expose { s } => clock = clock.max(ready) + open + s + close,
            Step::Sweep { to_mm, speed_mm_s } => {
                if !shutter_open {
                    clock = clock.max(ready) + open;
                    shutter_open = true;
                }
                clock += (to_mm - pos).abs() / speed_mm_s;
                pos = to_mm;
                if !matches!(flat.get(k + 1), Some((_, Step::Sweep { .. }))) {
                    clock += close;
                    shutter_open = false;
                }
            }
        }
    }
    clock
}

#[test]
fn estimate_matches_an_independent_replay() {
    for name in crate::profile::builtin_names() {
        let p = Profile::resolve(name).unwrap();
        let h = p.slicing.layer_height_mm.get();
        let layers = layers_of(40, h, |i| {
            (20.0 * (i % 7) as f64, [1.0, 3.0, 6.0, 9.0][i / 10])
        });
        let plan = plan(&p, &layers).unwrap();
        let r = replay(&p, &plan.layers);
        // The estimate is the replay of the steps as written, to 1 ms.
        assert!(
            (plan.print_time_s - r).abs() <= 0.0005 + 1e-9 * r,
            "{name}: {} vs {r}",
            plan.print_time_s
        );
    }
}

#[test]
fn steps_hold_whole_stage_steps_and_whole_milliseconds() {
    let ms = |s: f64| ((s * 1000.0).round() - s * 1000.0).abs() < 1e-6;
    for name in crate::profile::builtin_names() {
        let p = Profile::resolve(name).unwrap();
        let grid = StageGrid::new(p.stage.steps_per_mm.get());
        let h = p.slicing.layer_height_mm.get();
        let layers = layers_of(40, h, |i| (17.3 * (i % 7) as f64 + 0.123, 0.37 * i as f64));
        let plan = plan(&p, &layers).unwrap();
        for lp in &plan.layers {
            for s in &lp.steps {
                match *s {
                    Step::Move { to_mm, .. } | Step::Sweep { to_mm, .. } => {
                        assert!(grid.is_whole(to_mm), "{name}: {s:?}");
                        assert!(format!("{to_mm}").len() <= 10, "{name}: {s:?}");
                    }
                    Step::Wait { s: t } | Step::Expose { s: t } => {
                        assert!(ms(t), "{name}: {s:?}")
                    }
                }
            }
            assert!(ms(lp.time_s), "{name}: {}", lp.time_s);
            if lp.mode == Mode::Layered {
                assert!(ms(lp.exposure_s), "{name}: {}", lp.exposure_s);
            }
        }
        assert!(ms(plan.print_time_s));
    }
}

#[test]
fn a_layer_height_of_a_half_step_keeps_sweep_runs_unbroken() {
    // 0.051875 mm = 41.5 steps of 1/800 mm: every other layer top lies on a half step,
    // where a top and the next layer's bottom computed apart can round to different steps.
    let p = Profile::resolve("hybrid-bottomup").unwrap();
    let h = 0.051875;
    let first_free = (p.exposure.bottom_layers + p.exposure.transition_layers) as usize;
    let layers = layers_of(first_free + 60, h, |_| (10.0, 1.0));
    let plan = plan(&p, &layers).unwrap();
    let grid = StageGrid::new(800.0);
    let mut light = 0.0;
    for (i, lp) in plan.layers.iter().enumerate().skip(first_free + 1) {
        assert_eq!(lp.mode, Mode::Continuous);
        assert_eq!(lp.steps.len(), 1, "layer {i}: {:?}", lp.steps);
        light += lp.exposure_s;
    }
    // The sweeps' light times add up to the distance swept, whole steps apart.
    let swept = grid.position(layers.last().unwrap().z_mm) - grid.position(layers[first_free].z_mm);
    assert!(
        (light - swept / 0.06).abs() < 1e-4,
        "{light} vs {}",
        swept / 0.06
    );
}

#[test]
fn a_job_within_its_bottom_and_transition_layers_is_warned() {
    // bottom-up: 4 bottom layers, then 4 ramping to the normal exposure.
    let p = Profile::resolve("bottom-up").unwrap();
    let (b, t) = (4, 4);
    assert_eq!(
        (p.exposure.bottom_layers, p.exposure.transition_layers),
        (b, t)
    );
    let code = "plan.bottom-layers-cover-job";
    let warned = |p: &Profile, n: usize| {
        let plan = plan(p, &layers_of(n, 0.05, |_| (100.0, 3.0))).unwrap();
        plan.warnings.into_iter().find(|w| w.code == code)
    };
    // Layer 8 is the first at the normal exposure: 9 layers reach it, 8 do not.
    assert!(warned(&p, 9).is_none());
    let w = warned(&p, 8).expect("8 layers never reach layer_s");
    assert_eq!(w.fields["layers_total"], 8);
    assert_eq!(w.fields["bottom_layers"], 4);
    assert_eq!(w.fields["transition_layers"], 4);
    assert!(
        w.message.contains("the last, on the ramp, is exposed"),
        "{}",
        w.message
    );
    let w = warned(&p, 3).expect("3 layers are all bottom layers");
    assert!(
        w.message.contains("every layer is exposed bottom_s"),
        "{}",
        w.message
    );
    let w = warned(&p, 1).expect("1 layer is a bottom layer");
    assert!(
        w.message
            .contains("1 layer: it is not exposed the normal layer_s")
            && w.message.contains("(it is exposed bottom_s"),
        "{}",
        w.message
    );
    // A profile whose bottom exposure is the normal one (a working-curve job) is not.
    let mut same = p.clone();
    same.exposure.bottom_s = same.exposure.layer_s;
    assert!(warned(&same, 3).is_none());
}
