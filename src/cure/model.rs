//! Dose and cure in depth: the relative-dose convention, Beer–Lambert with the resin's
//! penetration depth Dp, cure where the dose accumulated over a layer's own exposure and
//! the following layers' reaches the critical energy Ec (Jacobs' working curve).
//!
//! Depths are measured down from the top of a layer (part frame: the side the following
//! layers are added on). A point `z` below the top of layer i, lit at relative irradiance
//! I by layer i and by its N following layers alike, gets
//! D(z) = I·D₀·Σ_{k=0..N} exp(−(z + k·h)/Dp), with D₀ = Ec·exp((h + overcure)/Dp) the dose a
//! fully lit interior pixel of a normal layer receives at its own surface (so a layer's own
//! exposure cures exactly h + overcure deep). The same holds for top-down and bottom-up
//! machines: in both the light of a new layer crosses it first and then the layers made
//! before it.

/// The inputs of the cure model for one job.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CureModel {
    /// PSF standard deviation, pixels.
    pub sigma_px: f64,
    /// Pixel edge on the build plane, mm.
    pub pixel_mm: f64,
    /// Penetration depth Dp, mm.
    pub dp_mm: f64,
    /// Critical energy Ec, mJ/cm².
    pub ec_mj_cm2: f64,
    /// Cure depth beyond the layer thickness, mm.
    pub overcure_mm: f64,
    /// Layer thickness h, mm.
    pub layer_mm: f64,
}

impl CureModel {
    /// The model for `profile` (its first projector's PSF, pixel and the resin), or `None`
    /// when the profile carries no PSF.
    pub fn from_profile(profile: &crate::profile::Profile) -> Option<CureModel> {
        let p = profile.projector.first()?;
        let sigma = profile
            .projector
            .iter()
            .map(|p| p.psf_sigma_px.map(|s| s.get()))
            .collect::<Option<Vec<f64>>>()?
            .into_iter()
            .fold(0.0, f64::max);
        Some(CureModel {
            sigma_px: sigma,
            pixel_mm: p.pixel_mm.get(),
            dp_mm: profile.resin.dp_mm.get(),
            ec_mj_cm2: profile.resin.ec_mj_cm2.get(),
            overcure_mm: profile.resin.overcure_mm.get(),
            layer_mm: profile.slicing.layer_height_mm.get(),
        })
    }

    /// D₀: the dose of a fully lit interior pixel at its layer's top, mJ/cm².
    pub fn full_dose_mj_cm2(&self) -> f64 {
        self.ec_mj_cm2 * ((self.layer_mm + self.overcure_mm) / self.dp_mm).exp()
    }

    /// Σ_{k=0..N} qᵏ, q = exp(−h/Dp): the dose of N following layers lit alike relative to
    /// the layer's own (`None`: infinitely many).
    pub fn accumulation(&self, following: Option<u32>) -> f64 {
        let q = (-self.layer_mm / self.dp_mm).exp();
        match following {
            None => 1.0 / (1.0 - q),
            Some(n) => (1.0 - q.powi(n as i32 + 1)) / (1.0 - q),
        }
    }

    /// The relative irradiance (of a fully lit interior pixel) a point `depth_mm` below a
    /// layer's top needs to cure, when the layer and its `following` layers light it alike.
    pub fn threshold(&self, depth_mm: f64, following: Option<u32>) -> f64 {
        self.ec_mj_cm2 / self.full_dose_mj_cm2() * (depth_mm / self.dp_mm).exp()
            / self.accumulation(following)
    }

    /// The relative irradiance at which the cured edge lies at mid-layer, a wall's layers
    /// lighting it alike (the following layers repeat the layer: vertical walls).
    pub fn edge_threshold(&self) -> f64 {
        self.threshold(0.5 * self.layer_mm, None)
    }

    /// Closed form of the print-through: how far below the first layer of a flat,
    /// fully lit downward-facing surface the resin cures, mm, with `following` layers lit
    /// above it (`None`: infinitely many): overcure + Dp·ln Σ_{k=0..N} qᵏ.
    pub fn print_through_mm(&self, following: Option<u32>) -> f64 {
        self.overcure_mm + self.dp_mm * self.accumulation(following).ln()
    }
}

/// The built-in default profile's model, for unit tests.
#[cfg(test)]
pub(crate) fn test_model() -> CureModel {
    CureModel {
        sigma_px: 0.5,
        pixel_mm: 0.0634765625,
        dp_mm: 0.15,
        ec_mj_cm2: 10.0,
        overcure_mm: 0.03,
        layer_mm: 0.05,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> CureModel {
        test_model()
    }

    /// The built-in profile's model is `test_model`.
    #[test]
    fn the_test_model_is_the_default_profiles() {
        let p = crate::profile::Profile::default_profile();
        assert_eq!(CureModel::from_profile(&p), Some(test_model()));
    }

    #[test]
    fn own_exposure_cures_layer_plus_overcure() {
        let m = model();
        // With no following layer a fully lit pixel cures exactly h + overcure deep.
        assert!((m.threshold(m.layer_mm + m.overcure_mm, Some(0)) - 1.0).abs() < 1e-12);
        assert!((m.print_through_mm(Some(0)) - m.overcure_mm).abs() < 1e-12);
    }

    /// Print-through by direct summation of every exposure's Beer–Lambert dose on a fine
    /// depth grid, against the closed form: within 5 % (here within the grid step).
    #[test]
    fn print_through_matches_a_summation_of_the_exposures() {
        let m = model();
        for n in [0u32, 1, 3, 10, 60] {
            // Layer 0 is the overhang's first layer; layers 1..=n follow above it. A point
            // z below layer 0's bottom lies z + h + k·h below layer k's top.
            let dz = 1e-5;
            let mut z = 0.0;
            let bottom = loop {
                let dose: f64 = (0..=n)
                    .map(|k| {
                        let depth = z + m.layer_mm + k as f64 * m.layer_mm;
                        m.full_dose_mj_cm2() * (-depth / m.dp_mm).exp()
                    })
                    .sum();
                if dose < m.ec_mj_cm2 {
                    break z;
                }
                z += dz;
            };
            let closed = m.print_through_mm(Some(n));
            assert!(
                (bottom - closed).abs() <= 0.05 * closed && (bottom - closed).abs() <= 2.0 * dz,
                "n {n}: summed {bottom} closed {closed}"
            );
        }
    }
}
