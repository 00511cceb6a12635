//! Hand-written manifests and a collecting sink, for the executor's tests and benchmarks
//! (`benches/exec.rs`): jobs whose every step and estimate a test states itself.

use super::sim::{LayerRecord, Segment, Sink};
use crate::bundle::*;
use crate::profile::Profile;

/// The default profile (open/close 0.05 s, load 0.02 s, 10 mm/s, 50 mm/s², 800 steps/mm,
/// travel 0..120, home 0).
pub fn profile() -> Profile {
    Profile::default_profile()
}

/// A layer record with no mask files.
pub fn layer(
    index: usize,
    z_mm: f64,
    thickness_mm: f64,
    mode: Mode,
    exposure_s: f64,
    steps: Vec<Step>,
    time_s: f64,
) -> Layer {
    Layer {
        index: index as u64,
        z_mm,
        slice_z_mm: z_mm - thickness_mm / 2.0,
        thickness_mm,
        mode,
        exposure_s,
        area_mm2: 1.0,
        masks: vec![MaskRef {
            file: format!("masks/{index:05}.png"),
            sha256: String::new(),
            projector: 0,
            pixels: None,
        }],
        steps,
        time_s,
        max_fill_distance_mm: Some(0.0),
        islands: Some(0),
        bbox_mm: None,
        cure: None,
        support_area_mm2: None,
    }
}

/// A manifest around `layers`; totals from the layers.
pub fn manifest(machine: Profile, layers: Vec<Layer>) -> Manifest {
    let h = layers.first().map_or(0.1, |l| l.thickness_mm);
    Manifest {
        format: FORMAT.into(),
        version: VERSION,
        generator: Generator::current(),
        source: Source {
            file: "test.stl".into(),
            sha256: String::new(),
            triangles: 12,
            bbox_mm: [[0.0; 3], [1.0; 3]],
            placement: Placement {
                mode: "keep".into(),
                translate_mm: [0.0; 3],
                ..Default::default()
            },
            mesh: Default::default(),
            parts: None,
        },
        settings: Settings {
            layer_height_mm: h,
            binary: false,
            compensation: "off".into(),
            distortion: None,
            accuracy: None,
        },
        machine: Machine::of(&machine),
        totals: Totals {
            layers: layers.len() as u64,
            height_mm: layers.last().map_or(0.0, |l| l.z_mm),
            print_time_s: layers.iter().map(|l| l.time_s).sum(),
            exposure_s: layers.iter().map(|l| l.exposure_s).sum(),
            resin_volume_ml: 0.0,
            continuous_layers: None,
            all_layered_time_s: None,
        },
        cure: None,
        warnings: vec![],
        layers,
        optics: None,
        projector_optics: Vec::new(),
        supports: None,
    }
}

/// The `cure` record of the unit tests' model ([`crate::cure::test_model`]) with the
/// correction `correction`.
#[cfg(test)]
pub fn cure_record(correction: &str) -> Cure {
    let m = crate::cure::test_model();
    Cure {
        psf_sigma_px: m.sigma_px,
        pixel_mm: m.pixel_mm,
        dp_mm: m.dp_mm,
        ec_mj_cm2: m.ec_mj_cm2,
        sources: Default::default(),
        overcure_mm: m.overcure_mm,
        layer_mm: m.layer_mm,
        edge_threshold: m.edge_threshold(),
        correction: correction.into(),
        shift_px: 0.49,
        print_through_mm: m.print_through_mm(None),
        held_back_layers: 0,
        uncorrected_layers: Vec::new(),
        uncorrected_windows: Vec::new(),
        predicted: None,
        dropped: None,
    }
}

/// Records everything it is fed.
#[derive(Debug, Default)]
pub struct Collect {
    /// Segments in order.
    pub segs: Vec<Segment>,
    /// Layer records in order.
    pub layers: Vec<LayerRecord>,
}

impl Sink for Collect {
    fn segment(&mut self, seg: &Segment) {
        self.segs.push(*seg);
    }
    fn layer_end(&mut self, rec: &LayerRecord) {
        self.layers.push(rec.clone());
    }
}

/// A `move` step.
pub fn move_to(to_mm: f64, speed_mm_s: f64, accel_mm_s2: f64) -> Step {
    Step::Move {
        to_mm,
        speed_mm_s,
        accel_mm_s2,
    }
}

/// A `sweep` step.
pub fn sweep_to(to_mm: f64, speed_mm_s: f64) -> Step {
    Step::Sweep { to_mm, speed_mm_s }
}

/// Moves of the default top-down recoat for a layer at `z` (dip 5 mm at 2 mm/s, return
/// at 1 mm/s, 50 mm/s²), a wait and an exposure.
pub fn recoat_steps(z: f64, wait_s: f64, expose_s: f64) -> Vec<Step> {
    vec![
        move_to(z + 5.0, 2.0, 50.0),
        move_to(z, 1.0, 50.0),
        Step::Wait { s: wait_s },
        Step::Expose { s: expose_s },
    ]
}

/// Two top-down layers of 0.5 mm: dip, return, wait 10 s, expose 16 s then 8 s.
pub fn two_layer_topdown() -> Manifest {
    let l = |i: usize, exposure_s: f64, time_s: f64| {
        let z = 0.5 * (i + 1) as f64;
        let steps = recoat_steps(z, 10.0, exposure_s);
        layer(i, z, 0.5, Mode::Layered, exposure_s, steps, time_s)
    };
    manifest(profile(), vec![l(0, 16.0, 33.91), l(1, 8.0, 25.91)])
}

/// Layers of one 0.1 mm sweep each at 0.05 mm/s (2 s of light), in `mode`, layer i
/// estimated to take `times[i]`.
pub fn sweep_layers(mode: Mode, times: &[f64]) -> Manifest {
    let l = |(i, &t): (usize, &f64)| {
        let z = 0.1 * (i + 1) as f64;
        layer(i, z, 0.1, mode, 2.0, vec![sweep_to(z, 0.05)], t)
    };
    manifest(profile(), times.iter().enumerate().map(l).collect())
}
