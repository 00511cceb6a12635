//! The cured width of a long straight line or gap of whole pixels, as `slice --predict`
//! would find it: the feature's layers run through the engine ([`run_layers`]) from the
//! top down, and across the lowest layer's mid-plane the cured edges are where the
//! accumulated light, blurred by the PSF ([`predict::light`]), crosses the mid-plane's
//! threshold while the layer's own light is at least [`NEAR`] (docs/CURE.md). This is the
//! model `dmdsl calibrate psf` fits σ with (docs/CALIBRATION.md).

use super::check::{run_layers, NEAR};
use super::kernel::Irradiance;
use super::predict;
use super::psf::{AxisTable, Psf};
use super::CureModel;

/// What a straight feature draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Drawn {
    /// A lit line `width_px` wide, dark on both sides.
    Line,
    /// A dark gap `width_px` wide between two lit blocks `block_px` wide.
    Gap,
}

/// A long straight feature of whole pixels, its edges on pixel boundaries, `layers`
/// layers thick, every layer drawn alike at the normal layer's exposure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Straight {
    /// Line or gap.
    pub kind: Drawn,
    /// Drawn width, pixels.
    pub width_px: u32,
    /// Width of the lit blocks on either side of a gap, pixels (unused for a line).
    pub block_px: u32,
    /// Layers the feature is thick (at least 1).
    pub layers: u32,
}

/// The cured width, pixels, of `f` at the mid-plane of its lowest layer (the one with the
/// light of every other layer of the feature above it) under `model`. A line that does
/// not cure and a gap that closes have width 0; a gap whose blocks do not cure either,
/// the whole drawn width of blocks and gap.
pub fn printed_width_px(model: &CureModel, f: &Straight) -> f64 {
    let psf = Psf {
        sigma_px: model.sigma_px,
    };
    let reach = psf.reach_px().ceil() as usize + 2;
    let (w, b) = (f.width_px as usize, f.block_px as usize);
    let lit: Vec<(usize, usize)> = match f.kind {
        Drawn::Line => vec![(reach, reach + w)],
        Drawn::Gap => vec![(reach, reach + b), (reach + b + w, reach + 2 * b + w)],
    };
    let (c0, c1) = (lit[0].0, lit[lit.len() - 1].1);
    let (width, height) = (c1 + reach, 2 * reach + 1);
    // The layer's own relative irradiance over the whole image, and its lit box.
    let row: Vec<f32> = (0..width)
        .map(|c| f32::from(u8::from(lit.iter().any(|&(a, e)| (a..e).contains(&c)))))
        .collect();
    let own: Vec<f32> = (0..height).flat_map(|_| row.iter().copied()).collect();
    let irr = Irradiance {
        bbox: [c0, 0, c1, height],
        data: (0..height)
            .flat_map(|_| row[c0..c1].iter().copied())
            .collect(),
    };
    let layers = f.layers.max(1) as usize;
    let mut acc: Vec<f32> = Vec::new();
    let mut observe = |i: usize, e: &super::Engine, _: &Irradiance| {
        if i == 0 {
            let (px, scale) = e.irradiance();
            acc = px.iter().map(|v| v * scale).collect();
        }
    };
    run_layers(
        model,
        (width, height),
        &vec![1.0; layers],
        &|_| Ok(irr.clone()),
        (true, 0),
        &mut observe,
    )
    .expect("the layers' irradiance is at hand");
    let table = AxisTable::new(&psf);
    let mid = model.threshold(0.5 * model.layer_mm, Some(0));
    let y = reach as f64 + 0.5;
    let margin = |x: f64| {
        let a = predict::light(&acc, width, &psf, &table, [x, y]) - mid;
        a.min(predict::light(&own, width, &psf, &table, [x, y]) - f64::from(NEAR))
    };
    let (centre, half) = match f.kind {
        Drawn::Line => (reach as f64 + 0.5 * w as f64, 0.5 * w as f64),
        Drawn::Gap => ((reach + b) as f64 + 0.5 * w as f64, 0.5 * w as f64),
    };
    match f.kind {
        Drawn::Line => {
            if margin(centre) < 0.0 {
                return 0.0;
            }
            // Cured at the centre, not beyond the PSF's reach outside the line.
            let x = bisect(&margin, centre, centre + half + reach as f64 - 1.0);
            2.0 * (x - centre)
        }
        Drawn::Gap => {
            if margin(centre) >= 0.0 {
                return 0.0;
            }
            let block = centre - half - 0.5 * b as f64;
            if margin(block) < 0.0 {
                return (w + 2 * b) as f64;
            }
            let x = bisect(&margin, block, centre);
            2.0 * (centre - x)
        }
    }
}

/// The point between `a` (where `f` ≥ 0) and `b` (where `f` < 0) where `f` changes sign,
/// by bisection to 10⁻⁷ px.
fn bisect(f: &impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    while (b - a).abs() > 1e-7 {
        let m = 0.5 * (a + b);
        if f(m) >= 0.0 {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cure::psf::phi;

    fn model(sigma_px: f64) -> CureModel {
        CureModel {
            sigma_px,
            ..crate::cure::test_model()
        }
    }

    /// A wide line's edge against the closed form of a blurred step: its light at u px
    /// outside the edge is A·Φ(−u/σ), A the accumulated light of a full pixel, and the
    /// cured edge is where that equals the threshold T.
    #[test]
    fn a_wide_line_grows_as_a_blurred_step_does() {
        for sigma in [0.3, 0.8, 1.5] {
            let m = model(sigma);
            let layers = 6;
            let a = m.accumulation(Some(layers - 1));
            let t = m.threshold(0.5 * m.layer_mm, Some(0));
            let u = bisect(&|u: f64| a * phi(-u / sigma) - t, -5.0, 20.0);
            let f = Straight {
                kind: Drawn::Line,
                width_px: 40,
                block_px: 0,
                layers,
            };
            let got = printed_width_px(&m, &f);
            assert!(
                (got - (40.0 + 2.0 * u)).abs() < 2e-3,
                "σ {sigma}: {got} vs {u}"
            );
            let g = Straight {
                kind: Drawn::Gap,
                width_px: 40,
                block_px: 40,
                layers,
            };
            let got = printed_width_px(&m, &g);
            assert!(
                (got - (40.0 - 2.0 * u)).abs() < 2e-3,
                "σ {sigma}: {got} vs {u}"
            );
        }
    }

    #[test]
    fn narrow_gaps_close_and_narrow_lines_vanish() {
        let m = model(1.0);
        let gap = Straight {
            kind: Drawn::Gap,
            width_px: 1,
            block_px: 16,
            layers: 6,
        };
        assert_eq!(printed_width_px(&m, &gap), 0.0);
        let line = Straight {
            kind: Drawn::Line,
            width_px: 1,
            block_px: 0,
            layers: 1,
        };
        assert_eq!(printed_width_px(&model(2.0), &line), 0.0);
    }
}
