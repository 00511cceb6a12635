//! Event-based simulation of the machine a bundle was compiled for: the lift stage,
//! the exposure shutter and the DMD.
//!
//! The simulator follows the "Step semantics and timing contract" of [`crate::bundle`]
//! literally. It turns every step into one or more [`Segment`]s (a stretch of time with a
//! known stage motion, shutter state and light state), computed analytically from the
//! event times (no time stepping), and hands them in time order to [`Sink`]s: the
//! invariant checker, the CSV trace writer, the plot collector, the statistics. Nothing
//! is stored per segment, so a 10,000-layer job simulates in constant memory (one small
//! [`LayerRecord`] per layer is kept).
//!
//! Stage positions are quantized to the stage's `steps_per_mm`: every target is rounded
//! to the nearest step and the stage moves by whole steps, so a move's duration is that
//! of the quantized distance.
//!
//! Faults ([`FaultSpec`]) are injected here and handled as firmware must: the shutter is
//! closed (or, if it is stuck, the DMD is blanked), the stage stops where it is, and the
//! run ends with a [`FaultEvent`] naming the layer and the time.
//!
//! The parts: [`Machine`] (what is simulated, from the profile), [`Segment`] (a stretch
//! of the timeline and the stage kinematics inside it), the walk through the steps that
//! times them (`steps.rs`), and [`FaultSpec`] with the firmware's reaction to a fault
//! (`fault.rs`).

mod fault;
mod machine;
mod segment;
mod steps;
#[cfg(test)]
mod test_support;

pub use fault::{FaultEvent, FaultKind, FaultSpec};
pub use machine::Machine;
pub use segment::{Motion, SegKind, Segment, ShutterState};

use super::Violation;
use crate::bundle::Manifest;
use steps::Simulation;

/// Consumer of the simulated timeline.
pub trait Sink {
    /// Called for every segment, in time order.
    fn segment(&mut self, seg: &Segment);
    /// Called when a layer's steps are done (or the run was aborted during the layer).
    fn layer_end(&mut self, _rec: &LayerRecord) {}
}

/// What the simulation measured for one layer.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerRecord {
    /// Layer index.
    pub index: usize,
    /// Time the layer's steps start, s.
    pub start_s: f64,
    /// Simulated duration of the layer, s (to the start of the next layer).
    pub time_s: f64,
    /// Light-on time the layer's mask received, s.
    pub light_s: f64,
    /// Time the layer's mask was on the DMD.
    pub mask_ready_s: f64,
    /// Where the layer's last sweep ended, mm, if it has sweeps.
    pub last_sweep_end_mm: Option<f64>,
    /// How much position quantization changed the layer's duration, s (bound for comparing
    /// with the unquantized estimate).
    pub quantization_s: f64,
    /// How much position quantization changed the layer's light time, s.
    pub dose_quantization_s: f64,
    /// False if a fault ended the run during this layer.
    pub completed: bool,
}
impl LayerRecord {
    /// The record of layer `index` as its steps start at `start_s`: nothing measured yet.
    fn starting(index: usize, start_s: f64, mask_ready_s: f64) -> LayerRecord {
        LayerRecord {
            index,
            start_s,
            time_s: 0.0,
            light_s: 0.0,
            mask_ready_s,
            last_sweep_end_mm: None,
            quantization_s: 0.0,
            dose_quantization_s: 0.0,
            completed: false,
        }
    }
}

/// Result of a simulation.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// One record per simulated layer (fewer than the job's layers after a fault).
    pub layers: Vec<LayerRecord>,
    /// Simulated end of the job (or of the abort), s.
    pub total_s: f64,
    /// The fault that ended the run, if any.
    pub fault: Option<FaultEvent>,
    /// Injected faults that never triggered: a stuck shutter with no close after it, or any
    /// fault after the one that ended the run.
    pub untriggered: Vec<FaultSpec>,
    /// Steps that cannot be executed at all (non-positive speed, negative time); skipped.
    pub invalid_steps: Vec<Violation>,
}

/// Simulates the manifest's steps on its machine, feeding every segment to `sinks`.
pub fn simulate(manifest: &Manifest, faults: &[FaultSpec], sinks: &mut [&mut dyn Sink]) -> Outcome {
    let mut sim = Simulation::new(manifest, faults, sinks);
    sim.run();
    // The run ends at the first fault that triggers: every other one never did (its layer
    // was not reached, or nothing in the job set it off).
    let mut untriggered = faults.to_vec();
    if let Some(f) = &sim.fault {
        if let Some(i) = untriggered
            .iter()
            .position(|s| s.kind == f.kind && s.layer == f.layer)
        {
            untriggered.remove(i);
        }
    }
    Outcome {
        layers: sim.records,
        total_s: sim.t,
        fault: sim.fault,
        untriggered,
        invalid_steps: sim.invalid_steps,
    }
}
