//! The machine the simulator drives, read from the manifest's machine record: stage
//! travel, speed and resolution, shutter latencies, DMD load time.

/// The simulated machine, taken from the manifest's machine record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Machine {
    /// Lowest allowed stage coordinate, mm.
    pub travel_min_mm: f64,
    /// Highest allowed stage coordinate, mm.
    pub travel_max_mm: f64,
    /// Where homing leaves the stage, mm.
    pub home_mm: f64,
    /// Stage speed limit, mm/s.
    pub max_speed_mm_s: f64,
    /// Stage acceleration limit, mm/s².
    pub max_accel_mm_s2: f64,
    /// Stage resolution, steps per mm.
    pub steps_per_mm: f64,
    /// Shutter opening latency, s.
    pub open_s: f64,
    /// Shutter closing latency, s.
    pub close_s: f64,
    /// DMD mask load time, s.
    pub load_s: f64,
}

impl Machine {
    /// The machine of a (validated) machine record.
    pub fn of(p: &crate::bundle::Machine) -> Machine {
        Machine {
            travel_min_mm: p.stage.travel_min_mm,
            travel_max_mm: p.stage.travel_max_mm,
            home_mm: p.stage.home_mm,
            max_speed_mm_s: p.stage.max_speed_mm_s.get(),
            max_accel_mm_s2: p.stage.max_accel_mm_s2.get(),
            steps_per_mm: p.stage.steps_per_mm.get(),
            open_s: p.shutter.open_s.get(),
            close_s: p.shutter.close_s.get(),
            load_s: p.dmd.load_s.get(),
        }
    }

    /// `mm` rounded to the nearest whole stage step.
    pub fn quantize(&self, mm: f64) -> f64 {
        (mm * self.steps_per_mm).round() / self.steps_per_mm
    }

    /// Half a stage step, mm: the largest distance between a target and where the stage
    /// can actually stop.
    pub fn half_step_mm(&self) -> f64 {
        0.5 / self.steps_per_mm
    }
}
