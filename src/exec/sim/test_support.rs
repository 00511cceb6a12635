//! Jobs and a runner shared by the simulator's unit tests.

use super::{simulate, FaultKind, FaultSpec, Outcome};
use crate::bundle::{Manifest, Mode};
use crate::exec::testutil::{sweep_layers, two_layer_topdown, Collect};

/// Equal within 1e-9.
pub(super) fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

/// Two top-down layers, 0.5 mm: (dip, return, wait 10, expose 16 / 8).
pub(super) fn layered() -> Manifest {
    two_layer_topdown()
}

/// Simulates `m` with `faults` into a sink that keeps every segment and layer record.
pub(super) fn run_collecting(m: &Manifest, faults: &[FaultSpec]) -> (Outcome, Collect) {
    let mut c = Collect::default();
    let o = simulate(m, faults, &mut [&mut c]);
    (o, c)
}

/// Three layers of one 0.1 mm sweep each at 0.05 mm/s, in `mode`.
pub(super) fn sweeps(mode: Mode) -> Manifest {
    sweep_layers(mode, &[2.07, 2.0, 2.05])
}

/// Fault `kind` injected at `layer`.
pub(super) fn fault(kind: FaultKind, layer: usize) -> FaultSpec {
    FaultSpec { kind, layer }
}
