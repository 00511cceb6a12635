//! Calibrations, fields and random numbers shared by the module's unit tests.

use super::super::field::{FieldModel, Form, Poly};
use super::super::response::{Interpolation, Response};
use super::super::{Calibration, Dither, Mode, Units};
use crate::profile::Field;
use crate::units::{NonNegative, Positive};

/// Every compensation mode with every dithering that applies to it; pixel mode with error
/// diffusion last (its plate is not the gray map).
pub(super) const MODES: [(Mode, Dither); 5] = [
    (Mode::Zone, Dither::Auto),
    (Mode::Zone, Dither::On),
    (Mode::Zone, Dither::Off),
    (Mode::Pixel, Dither::Off),
    (Mode::Pixel, Dither::On),
];

/// A 40 × 30 mm field of 1 mm pixels; P = 1 + x/40 (x in mm), S(g) = (g/255)²
/// ([`response_s`]) measured 50..255 and anchored at 0.
pub(super) fn setup() -> (Calibration, Field) {
    let pts: Vec<[f64; 2]> = std::iter::once([0.0, 0.0])
        .chain(
            (50..=255)
                .step_by(5)
                .map(|g| [g as f64, (g as f64 / 255.0).powi(2)]),
        )
        .collect();
    let cal = Calibration {
        source: "test".into(),
        units: Units::Relative,
        zone_mm: Positive::new(5.0).unwrap(),
        field: FieldModel {
            origin_mm: [0.0, 0.0],
            length_unit_mm: Positive::new(40.0).unwrap(),
            scale: Positive::new(1.0).unwrap(),
            form: Form::Polynomial,
            coefficients: Poly::from_terms(1, &[1.0, 1.0, 0.0]),
            area_mm: [0.0, 0.0, 40.0, 30.0],
            polynomial_area_mm: None,
            extrapolate_mm: NonNegative::new(5.0).unwrap(),
        },
        response: Response::Table {
            interpolation: Interpolation::Spline,
            points: pts,
        },
        fit: None,
    };
    cal.validate().unwrap();
    (cal, field(40, 30, 1.0))
}

/// A field of `w` × `h` pixels of `pixel_mm`.
pub(super) fn field(w: u32, h: u32, pixel_mm: f64) -> Field {
    Field {
        width_px: w,
        height_px: h,
        pixel_mm,
    }
}

/// [`setup`]'s calibration measured on 40 × 26 mm only, over a 40 × 30 mm field of
/// 0.2 mm pixels (so the top of the field lies outside the calibrated area).
pub(super) fn small_setup() -> (Calibration, Field) {
    let (mut cal, _) = setup();
    cal.field.area_mm = [0.0, 0.0, 40.0, 26.0];
    (cal, field(200, 150, 0.2))
}

/// S(g) of [`setup`]'s calibration.
pub(super) fn response_s(g: u8) -> f64 {
    (g as f64 / 255.0).powi(2)
}

/// A tiny fixed-seed PRNG (xorshift), uniform in [0, 1).
pub(super) fn rng(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A random calibration field over a 40 × 30 mm area: every form, degrees 1 to
/// [`MAX_DEGREE`](crate::optics::field::MAX_DEGREE), sometimes a smaller polynomial
/// rectangle (linear continuation), sometimes one narrower than a pixel.
pub(super) fn random_field(rnd: &mut impl FnMut() -> f64, case: usize) -> FieldModel {
    let degree = 1 + case % crate::optics::field::MAX_DEGREE;
    let form = [Form::Polynomial, Form::Exponential, Form::InverseSquare][case % 3];
    let n = Poly::terms(degree);
    let mut coef: Vec<f64> = (0..n).map(|_| (rnd() - 0.5) * 0.2).collect();
    coef[0] = 1.0 + rnd();
    let area = [
        rnd() * 4.0,
        rnd() * 3.0,
        36.0 + rnd() * 4.0,
        26.0 + rnd() * 4.0,
    ];
    let poly_area = match case % 4 {
        0 => None,
        1 => Some([area[0] + 2.5, area[1] + 2.5, area[2] - 2.5, area[3] - 2.5]),
        2 => Some([20.01, area[1] + 1.0, 20.02, area[3] - 1.0]),
        _ => Some([area[0] + 1.0, 15.01, area[2] - 1.0, 15.02]),
    };
    FieldModel {
        origin_mm: [20.0 + rnd(), 15.0 + rnd()],
        length_unit_mm: Positive::new(10.0 + 20.0 * rnd()).unwrap(),
        scale: Positive::new(0.5 + rnd() * 1e-3).unwrap(),
        form,
        coefficients: Poly::from_terms(degree, &coef),
        area_mm: area,
        polynomial_area_mm: poly_area,
        extrapolate_mm: NonNegative::new(rnd() * 6.0).unwrap(),
    }
}
