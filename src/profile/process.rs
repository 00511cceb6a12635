//! Process sections of a machine profile: `[recoat]` (top-down), `[peel]` (bottom-up) and
//! `[hybrid]` (model-guided hybrid continuous/layered printing). Like the rest of a profile
//! every key is required and unknown keys are errors; [`validate`] checks the rules serde
//! cannot express. The planner (`plan`) turns them into steps.

use super::{Process, Profile};
use crate::units::{NonNegative, Positive};
use serde::{Deserialize, Serialize};

/// How a top-down machine chooses its leveling wait.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WaitModel {
    /// Wait `wait_s` before every exposure.
    Fixed,
    /// Wait for the thin-film leveling time of the layer (see [`Recoat::leveling_time_s`]),
    /// at least `wait_s` and at most `wait_max_s`.
    Leveling,
}

/// Top-down recoat by natural leveling (as in Xu et al. 2010): after each exposure the stage dips
/// `dip_mm` deeper than the next layer so resin floods the part, comes back and waits for
/// the free surface to level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Recoat {
    /// How much deeper than the next layer the stage dips, mm.
    pub dip_mm: NonNegative,
    /// Speed of the dip, mm/s.
    pub dip_speed_mm_s: Positive,
    /// Speed of the return to the next layer, mm/s.
    pub return_speed_mm_s: Positive,
    /// Fixed wait, or the leveling model.
    pub wait_model: WaitModel,
    /// Fixed wait before exposure, s; with the leveling model, the shortest wait.
    pub wait_s: NonNegative,
    /// Longest leveling wait, s (the model's value is capped here, with a warning).
    pub wait_max_s: NonNegative,
    /// Surface tension of the resin, N/m (leveling model).
    pub surface_tension_n_m: Positive,
    /// Density of the resin, kg/m³ (leveling model).
    pub density_kg_m3: Positive,
    /// Wait this many leveling time constants (1: the disturbance decays to 1/e = 37 %;
    /// 2.3: to 10 %).
    pub leveling_efolds: Positive,
}

impl Recoat {
    /// Thin-film leveling time constant, s, of a film `film_mm` thick over a flat top whose
    /// largest inscribed radius is `fill_mm`, for a resin of viscosity `viscosity_pa_s`:
    /// τ = 3μ / (h³ k² (ρg + σk²)), k = 2π/λ, λ = 4·fill_mm (lubrication theory: the
    /// slowest disturbance that fits the flat top; docs/PLANNING.md, "Top-down natural
    /// leveling"). 0 when there is no flat top.
    pub fn leveling_time_s(&self, fill_mm: f64, film_mm: f64, viscosity_pa_s: f64) -> f64 {
        if fill_mm <= 0.0 || film_mm <= 0.0 {
            return 0.0;
        }
        let h = film_mm * 1e-3;
        let lambda = 4.0 * fill_mm * 1e-3;
        let k = std::f64::consts::TAU / lambda;
        let rho_g = self.density_kg_m3.get() * 9.81;
        let sigma = self.surface_tension_n_m.get();
        3.0 * viscosity_pa_s / (h * h * h * k * k * (rho_g + sigma * k * k))
    }

    /// The wait before exposing a layer: `(wait, uncapped model value)`, s.
    pub fn wait_for(&self, fill_mm: f64, film_mm: f64, viscosity_pa_s: f64) -> (f64, f64) {
        match self.wait_model {
            WaitModel::Fixed => (self.wait_s.get(), self.wait_s.get()),
            WaitModel::Leveling => {
                let raw = self.leveling_efolds.get()
                    * self.leveling_time_s(fill_mm, film_mm, viscosity_pa_s);
                let w = raw.max(self.wait_s.get()).min(self.wait_max_s.get());
                (w, raw)
            }
        }
    }
}

/// Generic bottom-up peel: after each layer the stage lifts the part off the window in two
/// stages (slow while it separates, fast after), waits, retracts to the next layer and
/// waits for the resin to settle. Lift height and slow speed scale with the area of the
/// layer being peeled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Peel {
    /// Lift height of a layer with no area, mm (above the next exposure position).
    pub lift_min_mm: Positive,
    /// Lift height of a layer of `full_lift_area_mm2` or more, mm; linear in area between.
    pub lift_max_mm: Positive,
    /// Area at which the lift reaches `lift_max_mm`, mm².
    pub full_lift_area_mm2: Positive,
    /// Length of the slow first stage, mm (from the exposure position).
    pub slow_lift_mm: NonNegative,
    /// Slow-stage speed of a layer of `slow_ref_area_mm2`, mm/s. Peel (squeeze-film) force
    /// grows with area² × speed, so the speed scales with (slow_ref_area / area)² to keep
    /// the force of the reference layer, between `slow_speed_min_mm_s` and
    /// `fast_speed_mm_s`.
    pub slow_speed_mm_s: Positive,
    /// Reference area of `slow_speed_mm_s`, mm².
    pub slow_ref_area_mm2: Positive,
    /// Lowest slow-stage speed, mm/s.
    pub slow_speed_min_mm_s: Positive,
    /// Speed of the second (fast) stage, mm/s.
    pub fast_speed_mm_s: Positive,
    /// Speed back down to the next layer, mm/s.
    pub retract_speed_mm_s: Positive,
    /// Wait after an exposure before the lift, s.
    pub wait_after_cure_s: NonNegative,
    /// Wait at the top of the lift, s.
    pub wait_after_lift_s: NonNegative,
    /// Wait after the retract before the exposure (resin settles), s.
    pub wait_before_cure_s: NonNegative,
    /// Lift height after a bottom layer, mm (at least the area rule's).
    pub bottom_lift_mm: Positive,
    /// Slow-stage speed after a bottom layer, mm/s (at most the area rule's).
    pub bottom_slow_speed_mm_s: Positive,
}

impl Peel {
    /// Lift height and slow-stage speed after peeling a layer of `area_mm2`;
    /// `bottom`: the peeled layer is a bottom layer.
    pub fn lift_for(&self, area_mm2: f64, bottom: bool) -> (f64, f64) {
        let f = (area_mm2 / self.full_lift_area_mm2.get()).clamp(0.0, 1.0);
        let mut lift =
            self.lift_min_mm.get() + (self.lift_max_mm.get() - self.lift_min_mm.get()) * f;
        let fast = self.fast_speed_mm_s.get();
        let mut v = if area_mm2 > 0.0 {
            let r = self.slow_ref_area_mm2.get() / area_mm2;
            (self.slow_speed_mm_s.get() * r * r).clamp(self.slow_speed_min_mm_s.get(), fast)
        } else {
            fast
        };
        if bottom {
            lift = lift.max(self.bottom_lift_mm.get());
            v = v.min(self.bottom_slow_speed_mm_s.get());
        }
        (lift, v)
    }
}

/// One row of the optimal-lift-height table: slices whose max fill distance is at most
/// `up_to_mm` (and above the previous row's) lift `lift_mm`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OlhStep {
    /// Upper end of the range (closed), mm.
    pub up_to_mm: Positive,
    /// Lift height, mm.
    pub lift_mm: Positive,
}

/// Model-guided hybrid continuous/layered printing: a slice prints continuously (the stage sweeps at
/// `continuous_speed_mm_s` while its mask is shown) when its max fill distance is at most
/// the maximum fillable distance `mfd_mm`; otherwise layered, lifting the optimal lift
/// height of its range (`[[hybrid.olh]]`) and coming back down to the next layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Hybrid {
    /// Maximum fillable distance, mm: slices up to it print continuously.
    pub mfd_mm: Positive,
    /// Tolerance of the comparisons with `mfd_mm` and the table's range ends, mm.
    pub tolerance_mm: NonNegative,
    /// Stage speed of continuous printing, mm/s (a slice is shown thickness/speed s).
    pub continuous_speed_mm_s: Positive,
    /// Speed of the lift of a layered slice, mm/s.
    pub lift_speed_mm_s: Positive,
    /// Speed back down to the next layer, mm/s.
    pub retract_speed_mm_s: Positive,
    /// Wait after a layered exposure before the next lift, s.
    pub wait_after_cure_s: NonNegative,
    /// Wait at the top of a lift, s.
    pub wait_after_lift_s: NonNegative,
    /// Wait after the retract before a layered exposure, s.
    pub wait_before_cure_s: NonNegative,
    /// Wait before a continuous run that follows a layered slice (the stage is still at the
    /// last exposure; resin settles before the sweep starts), s.
    pub switch_wait_s: NonNegative,
    /// Lift after a bottom layer, mm (at least the table's). Bottom and transition layers
    /// always print layered.
    pub bottom_lift_mm: Positive,
    /// Optimal lift heights by max fill distance, ascending.
    pub olh: Vec<OlhStep>,
}

impl Hybrid {
    /// True if a slice of max fill distance `fill_mm` prints continuously.
    pub fn continuous(&self, fill_mm: f64) -> bool {
        fill_mm <= self.mfd_mm.get() + self.tolerance_mm.get()
    }

    /// Optimal lift height for a layered slice of max fill distance `fill_mm`, and whether
    /// `fill_mm` lies beyond the table (then the last row's lift is used).
    pub fn olh_for(&self, fill_mm: f64) -> (f64, bool) {
        let tol = self.tolerance_mm.get();
        for r in &self.olh {
            if fill_mm <= r.up_to_mm.get() + tol {
                return (r.lift_mm.get(), false);
            }
        }
        let last = self.olh.last().expect("validated: olh is not empty");
        (last.lift_mm.get(), true)
    }
}

/// Checks the process sections of `p`: the one its process needs is present, no other,
/// speeds within the stage limit, tables ordered.
pub fn validate(p: &Profile) -> Result<(), String> {
    let vmax = p.stage.max_speed_mm_s.get();
    let speed = |name: &str, v: Positive| -> Result<(), String> {
        if v.get() > vmax {
            Err(format!(
                "{name} = {} exceeds stage.max_speed_mm_s = {vmax}",
                v.get()
            ))
        } else {
            Ok(())
        }
    };
    let sections = [
        ("recoat", p.recoat.is_some()),
        ("peel", p.peel.is_some()),
        ("hybrid", p.hybrid.is_some()),
    ];
    let (process, k) = match p.process {
        Process::TopDown => ("top-down", 0),
        Process::BottomUp => ("bottom-up", 1),
        Process::Hybrid => ("hybrid", 2),
    };
    let need = sections[k].0;
    if !sections[k].1 {
        return Err(format!("process \"{process}\" needs a [{need}] section"));
    }
    for (name, there) in sections {
        if there && name != need {
            return Err(format!(
                "[{name}] is not used by process \"{process}\" (it uses [{need}]); remove it"
            ));
        }
    }
    if let Some(r) = &p.recoat {
        speed("recoat.dip_speed_mm_s", r.dip_speed_mm_s)?;
        speed("recoat.return_speed_mm_s", r.return_speed_mm_s)?;
        if r.wait_model == WaitModel::Leveling && r.wait_max_s.get() < r.wait_s.get() {
            return Err("recoat.wait_max_s must be at least recoat.wait_s".into());
        }
    }
    if let Some(k) = &p.peel {
        speed("peel.slow_speed_mm_s", k.slow_speed_mm_s)?;
        speed("peel.fast_speed_mm_s", k.fast_speed_mm_s)?;
        speed("peel.retract_speed_mm_s", k.retract_speed_mm_s)?;
        speed("peel.bottom_slow_speed_mm_s", k.bottom_slow_speed_mm_s)?;
        if k.lift_min_mm.get() > k.lift_max_mm.get() {
            return Err("peel.lift_min_mm must not exceed peel.lift_max_mm".into());
        }
        if k.slow_speed_min_mm_s.get() > k.fast_speed_mm_s.get() {
            return Err("peel.slow_speed_min_mm_s must not exceed peel.fast_speed_mm_s".into());
        }
    }
    if let Some(h) = &p.hybrid {
        speed("hybrid.continuous_speed_mm_s", h.continuous_speed_mm_s)?;
        speed("hybrid.lift_speed_mm_s", h.lift_speed_mm_s)?;
        speed("hybrid.retract_speed_mm_s", h.retract_speed_mm_s)?;
        if h.olh.is_empty() {
            return Err("[hybrid] needs at least one [[hybrid.olh]] row".into());
        }
        let mut prev = h.mfd_mm.get();
        for (i, r) in h.olh.iter().enumerate() {
            if r.up_to_mm.get() <= prev {
                return Err(format!(
                    "hybrid.olh row {}: up_to_mm = {} must exceed {} (mfd_mm and the rows above, ascending)",
                    i + 1,
                    r.up_to_mm.get(),
                    prev
                ));
            }
            prev = r.up_to_mm.get();
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hybrid() -> Hybrid {
        Profile::resolve("hybrid-bottomup").unwrap().hybrid.unwrap()
    }

    #[test]
    fn olh_table_with_tolerance() {
        let h = hybrid();
        assert!(h.continuous(2.5));
        assert!(h.continuous(2.519));
        assert!(!h.continuous(2.521));
        assert_eq!(h.olh_for(2.6), (2.0, false));
        assert_eq!(h.olh_for(5.0), (2.0, false));
        assert_eq!(h.olh_for(5.015), (2.0, false));
        assert_eq!(h.olh_for(5.03), (4.0, false));
        assert_eq!(h.olh_for(7.5), (4.0, false));
        assert_eq!(h.olh_for(7.6), (8.0, false));
        assert_eq!(h.olh_for(30.0), (8.0, false));
        assert_eq!(h.olh_for(31.0), (8.0, true));
    }

    #[test]
    fn leveling_time_follows_formula() {
        let r = Profile::default_profile().recoat.unwrap();
        // h = 0.1 mm, λ = 20 mm (fill 5 mm), μ = 0.5 Pa·s, by hand:
        let (h, k) = (1e-4f64, std::f64::consts::TAU / 0.02);
        let want = 1.5
            / (h.powi(3)
                * k
                * k
                * (r.density_kg_m3.get() * 9.81 + r.surface_tension_n_m.get() * k * k));
        let got = r.leveling_time_s(5.0, 0.1, 0.5);
        assert!((got - want).abs() < 1e-9 * want, "{got} vs {want}");
        // Minutes for a 0.1 mm film over tens of mm.
        assert!(got > 60.0 && got < 3600.0, "{got}");
        // Grows with the flat extent and the viscosity, falls with the film thickness.
        assert!(r.leveling_time_s(6.0, 0.1, 0.5) > got);
        assert!(r.leveling_time_s(5.0, 0.1, 1.0) > got);
        assert!(r.leveling_time_s(5.0, 0.2, 0.5) < got);
        assert_eq!(r.leveling_time_s(0.0, 0.1, 0.5), 0.0);
    }

    #[test]
    fn wait_clamped_between_min_and_max() {
        let mut r = Profile::default_profile().recoat.unwrap();
        r.wait_model = WaitModel::Leveling;
        let (w, raw) = r.wait_for(0.01, 0.05, 0.5);
        assert_eq!(w, r.wait_s.get());
        assert!(raw < w);
        let (w, raw) = r.wait_for(20.0, 0.05, 0.5);
        assert_eq!(w, r.wait_max_s.get());
        assert!(raw > w);
        r.wait_model = WaitModel::Fixed;
        assert_eq!(r.wait_for(20.0, 0.05, 0.5).0, r.wait_s.get());
    }

    #[test]
    fn peel_scales_with_area() {
        let k = Profile::resolve("bottom-up").unwrap().peel.unwrap();
        let (l0, v0) = k.lift_for(0.0, false);
        let (l1, v1) = k.lift_for(k.slow_ref_area_mm2.get(), false);
        let (l2, v2) = k.lift_for(4.0 * k.slow_ref_area_mm2.get(), false);
        assert_eq!(l0, k.lift_min_mm.get());
        assert!(l1 > l0 && l2 > l1);
        assert_eq!(v0, k.fast_speed_mm_s.get());
        assert_eq!(v1, k.slow_speed_mm_s.get());
        // Double the area (area² force): a quarter of the speed, above the floor.
        let (_, v_half) = k.lift_for(2.0 * k.slow_ref_area_mm2.get(), false);
        assert!((v_half - (v1 / 4.0).max(k.slow_speed_min_mm_s.get())).abs() < 1e-12);
        assert!(v2 <= v_half);
        assert_eq!(k.lift_for(1e9, false).0, k.lift_max_mm.get());
        let (lb, vb) = k.lift_for(0.0, true);
        assert!(lb >= k.bottom_lift_mm.get() && vb <= k.bottom_slow_speed_mm_s.get());
    }

    #[test]
    fn validation_messages() {
        let src = crate::profile::builtin_source("hybrid-bottomup").unwrap();
        let bad = src.replacen("up_to_mm = 7.5", "up_to_mm = 4.0", 1);
        let e = Profile::from_toml(&bad, "x.toml").unwrap_err().to_string();
        assert!(e.contains("hybrid.olh row 2"), "{e}");
        let fast = src.replacen("lift_speed_mm_s = 5.0", "lift_speed_mm_s = 500.0", 1);
        let e = Profile::from_toml(&fast, "x.toml").unwrap_err().to_string();
        assert!(e.contains("exceeds stage.max_speed_mm_s"), "{e}");
        let wrong = src.replacen("process = \"hybrid\"", "process = \"bottom-up\"", 1);
        let e = Profile::from_toml(&wrong, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs a [peel] section"), "{e}");
    }
}
